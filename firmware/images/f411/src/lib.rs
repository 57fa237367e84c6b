//! The STM32F411 glue of the NUSense LED/controller board, as a library so that the on-target tests
//! (tests/on_target.rs) exercise the same code the firmware runs.
#![no_std]

pub mod board;
pub mod clock;
pub mod dfu;
pub mod flash;
