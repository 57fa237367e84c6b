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
    assert!(text.contains("DFU bootloader"), "{text}");
    // The flash it prints must leave the saved configuration alone: the vector table at the start of flash, the code
    // from where the linker script puts it, past the configuration's sectors, and nothing else written.
    let memory_x = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../../memory.x")).unwrap();
    let code_start = memory_x
        .lines()
        .find_map(|line| line.strip_prefix("_config_sectors_end = ")?.strip_suffix(';'))
        .expect("memory.x names _config_sectors_end");
    let flashes: Vec<&str> = text
        .lines()
        .map(str::trim)
        .filter(|line| line.starts_with("dfu-util"))
        .collect();
    assert_eq!(
        flashes,
        [
            "dfu-util -a 0 -s 0x08000000 -D vectors.bin".to_owned(),
            format!("dfu-util -a 0 -s {code_start}:leave -D code.bin")
        ],
        "{text}"
    );
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
