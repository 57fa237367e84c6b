//! `nusense serve` as users run it: the real binary on a loopback port, driven over HTTP and WebSocket (and by
//! headless Chromium for the dashboard). One test binary, so the workspace links it once.

mod api;
mod browser;
mod corrupt;
mod daemon;
mod lifecycle;
mod load;
mod paired_sensors;
mod replay;
mod ros2;
mod security;
mod zenoh_sensors;
