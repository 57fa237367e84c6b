//! What the recording tests share: the `nusense` binary, `nusense record` on the simulator, and the reference
//! Python MCAP reader (`mcap_check.py` beside this file, run by the project's .venv).

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

/// The simulator's frame size in every recording these tests make: small, so that they spend their time on the
/// recorder rather than on rendering.
pub const WIDTH: u32 = 320;
pub const HEIGHT: u32 = 240;

/// The `nusense` binary of this build.
pub fn nusense() -> Command {
    Command::new(env!("CARGO_BIN_EXE_nusense"))
}

/// `nusense record PATH --sim` at [`WIDTH`] x [`HEIGHT`], then `extra`; its standard output discarded.
pub fn record_command(path: &Path, extra: &[&str]) -> Command {
    let mut command = nusense();
    command
        .arg("record")
        .arg(path)
        .args(["--sim", "--width", &WIDTH.to_string(), "--height", &HEIGHT.to_string()])
        .args(extra)
        .stdout(Stdio::null());
    command
}

fn python() -> PathBuf {
    let venv = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../.venv/bin/python");
    assert!(
        venv.exists(),
        "{} is missing: `scripts/setup test` creates it (the reference Python MCAP reader)",
        venv.display()
    );
    venv
}

/// One JSON report per file from the reference Python reader, run as its own process; with `decode`, every
/// message is also decoded against the schema stored in its file.
pub fn python_reports(files: &[PathBuf], decode: bool) -> HashMap<PathBuf, serde_json::Value> {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/recordings/mcap_check.py");
    let mut command = Command::new(python());
    command.arg(script);
    if decode {
        command.arg("--decode");
    }
    let output = command.args(files).output().expect("run the Python reader");
    assert!(
        output.status.success(),
        "python: {}",
        String::from_utf8_lossy(&output.stderr)
    );
    String::from_utf8(output.stdout)
        .unwrap()
        .lines()
        .map(|line| {
            let report: serde_json::Value = serde_json::from_str(line).unwrap();
            (PathBuf::from(report["path"].as_str().unwrap()), report)
        })
        .collect()
}
