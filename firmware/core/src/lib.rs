//! Everything the NUSense LED/controller board decides, with no hardware in it: the current regulator, the fault
//! monitor, command dispatch over the protocol's framing, telemetry scheduling and the configuration blob kept in
//! flash. The board images (firmware/images) only move bytes and samples between this crate and the peripherals,
//! so the same logic runs on the STM32F411, under QEMU and in the host's virtual board, and is tested here.
//!
//! - [`limits`]: the electrical limits and fault thresholds, in one place.
//! - [`regulator`]: soft-start ramp and closed current loop per channel.
//! - [`faults`]: open string, over-current, over-temperature, under-voltage; latched until cleared.
//! - [`controller`]: the [`Controller`] the board glue drives.
//! - [`config`]: [`BoardConfig`] and its flash record.
//! - [`store`]: the two-sector, power-cut-safe record store over any `embedded-storage` NOR flash.
//! - [`link`]: host presence on links without DTR.
//! - [`plant`]: a simulated LED string board for tests, QEMU and the virtual board.
#![cfg_attr(not(test), no_std)]

pub mod analog;
pub mod config;
pub mod controller;
pub mod faults;
pub mod identity;
pub mod limits;
pub mod link;
pub mod plant;
pub mod regulator;
pub mod store;

pub use config::{BoardConfig, ConfigRecord, RecordError};
pub use controller::{Action, Controller, Measurements};
pub use identity::Identity;
pub use nusense_protocol::{PowerState, CHANNEL_COUNT};
pub use store::{ConfigStore, RamFlash, StoreError};
