//! `nusense bootloader` against the virtual board, which runs the real firmware logic: the board must acknowledge
//! EnterBootloader (and then reboot, as the real board jumps to its ROM bootloader).

use std::process::Command;

#[test]
fn virtual_board_acknowledges_enter_bootloader() {
    let out = Command::new(env!("CARGO_BIN_EXE_nusense"))
        .args(["bootloader", "--virtual"])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("DFU bootloader") && text.contains("dfu-util"), "{text}");
}

#[test]
fn missing_port_is_a_clear_error() {
    let out = Command::new(env!("CARGO_BIN_EXE_nusense"))
        .args(["bootloader", "--port", "/dev/nonexistent-nusense-board"])
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("/dev/nonexistent-nusense-board"), "{err}");
}
