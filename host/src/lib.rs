//! NUSense host library.
pub mod device;
pub mod virtual_board;
pub mod api;
pub mod capture;
pub mod dashboard;
pub mod pipeline;
pub mod record;
pub mod emulator;
pub mod hil;
pub mod bench;
