//! The board's firmware logic running on the host (placeholder while nusense-firmware-core lands).
