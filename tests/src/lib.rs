//! Helpers shared by the integration tests live beside them (tests/tests/*_common); the QEMU launcher is
//! the product's own (`nusense::emulator`), so the tests start the board exactly as `nusense hil --emulated` does.
