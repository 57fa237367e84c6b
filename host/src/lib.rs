//! NUSense host library.
pub mod device;
pub mod virtual_board;
pub mod emulator;
pub mod hil;
pub mod bench;
