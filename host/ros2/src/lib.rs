//! NUSense readings as ROS 2 topics without a ROS installation or a bridge (`nusense serve --ros2`): a ROS 2
//! node over DDS/RTPS written in Rust (`ros2-client` on RustDDS), which a stock ROS 2 installation with its
//! default middleware discovers like any other node.
//!
//! `messages` turns a reading into ROS 2 messages (hardware-free, tested against golden bytes of the real ROS 2
//! types); `settings` reads the ROS environment (`ROS_DOMAIN_ID`, discovery range); `node` is the DDS glue
//! that publishes every reading of a pipeline. docs/integrations/ros2.md is the user's side of it.

mod messages;
mod node;
mod settings;

pub use node::{Ros2Error, Ros2Out, Topics};
pub use settings::{sensor_token, DiscoveryRange, Ros2Settings, SettingsError};
