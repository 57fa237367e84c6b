//! The paper's experiments as reports from recordings, and the simulated sessions that exercise them.
//!
//! A lab records its sensor with `nusense record` (frames and readings in MCAP) next to a force/torque log, and
//! each experiment of the paper becomes a command: [`calibration`] (time offset by cross-correlation, force fit
//! with intervals), [`hysteresis`] (loading/unloading loops), [`repeatability`] (repeated touches),
//! [`localisation`] (touches at known targets) and [`damage`] (an intact and a damaged pad compared). Each
//! gives a [`Report`]:
//! Markdown with tables, SVG plots and JSON. [`session`] scripts the same experiments on the simulator, with their
//! ground truth, so that every report is checked end to end without hardware.

pub mod calibration;
pub mod damage;
pub mod hysteresis;
pub mod localisation;
pub mod plot;
pub mod recording;
pub mod repeatability;
pub mod report;
pub mod segment;
pub mod session;
pub mod stats;

pub use recording::{load_readings, SessionReading};
pub use report::{Report, ReportError};
