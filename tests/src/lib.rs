//! Tests that cross the firmware and the host live here (tests/tests); tests of one crate live with that crate.
//! The QEMU launcher is the product's own (`nusense_hil::emulator`), so the tests start the board exactly as
//! `nusense hil --emulated` does.
