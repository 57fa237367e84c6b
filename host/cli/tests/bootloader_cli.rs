//! `nusense bootloader` against the virtual board, which runs the real firmware logic: the board must acknowledge
//! EnterBootloader (and then reboot, as the real board jumps to its ROM bootloader).

use std::process::Command;

/// The flash commands the board's memory layout asks for: the vector table at the start of flash, the code from where
/// the linker script puts it, past the saved configuration's sectors, and nothing else written.
fn expected_flashes() -> [String; 2] {
    let memory_x = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../../memory.x")).unwrap();
    let code_start = memory_x
        .lines()
        .find_map(|line| line.strip_prefix("_config_sectors_end = ")?.strip_suffix(';'))
        .expect("memory.x names _config_sectors_end");
    [
        "dfu-util -a 0 -s 0x08000000 -D vectors.bin".to_owned(),
        format!("dfu-util -a 0 -s {code_start}:leave -D code.bin"),
    ]
}

fn bootloader(extra: &[&str]) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_nusense"))
        .args(["bootloader", "--virtual"])
        .args(extra)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    String::from_utf8_lossy(&out.stdout).into_owned()
}

#[test]
fn virtual_board_acknowledges_enter_bootloader() {
    let text = bootloader(&[]);
    assert!(text.contains("DFU bootloader"), "{text}");
    let flashes: Vec<&str> = text
        .lines()
        .map(str::trim)
        .filter(|line| line.starts_with("dfu-util"))
        .collect();
    assert_eq!(flashes, expected_flashes(), "{text}");
}

#[test]
fn json_gives_the_port_and_the_same_flash_commands() {
    let text = bootloader(&["--json"]);
    let message: serde_json::Value = serde_json::from_str(&text).unwrap_or_else(|e| panic!("{e}: {text}"));
    assert!(message["port"].as_str().is_some_and(|port| !port.is_empty()), "{text}");
    let flashes: Vec<&str> = message["flash"]
        .as_array()
        .expect("a list of flash commands")
        .iter()
        .filter_map(|c| c.as_str())
        .collect();
    assert_eq!(flashes, expected_flashes(), "{text}");
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
