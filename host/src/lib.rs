//! NUSense host library.
pub mod device;
pub mod virtual_board;
