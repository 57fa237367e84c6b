//! Recordings as users make them, with the real `nusense` binary (the one cargo built for these tests):
//! `nusense record`, `replay`, `record --recover` and `serve --foxglove`. Every file is read by the `mcap` crate
//! here and by the reference Python reader in a process of its own. One test binary, so the workspace links it
//! once.

mod crash;
mod foxglove_channels;
mod support;
