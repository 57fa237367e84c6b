//! NUSense host library.
