//! The Python client (clients/python), as `scripts/setup test` installed it into the project's .venv: its types
//! checked with `mypy --strict`, and its pytest suite run with this build's `nusense` binary in `NUSENSE_BIN`, so
//! that the suite's tests of the real daemon start it (never a build of their own).

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn client_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../clients/python")
}

fn venv_python() -> PathBuf {
    let python = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../.venv/bin/python");
    assert!(
        python.exists(),
        "{} is missing: `scripts/setup test` creates it and installs the Python client into it",
        python.display()
    );
    python
}

fn run(args: &[&str]) -> Output {
    let output = Command::new(venv_python())
        .args(args)
        .current_dir(client_dir())
        .env("NUSENSE_BIN", env!("CARGO_BIN_EXE_nusense"))
        .env("PYTHONDONTWRITEBYTECODE", "1")
        .output()
        .expect("run the .venv's python");
    println!("{}", String::from_utf8_lossy(&output.stdout));
    eprintln!("{}", String::from_utf8_lossy(&output.stderr));
    output
}

#[test]
fn the_python_client_type_checks() {
    let cache = Path::new(env!("CARGO_TARGET_TMPDIR")).join("mypy-cache");
    let output = run(&["-m", "mypy", "--cache-dir", cache.to_str().unwrap()]);
    assert!(
        output.status.success(),
        "mypy --strict found errors in clients/python (above)"
    );
}

#[test]
fn the_python_client_suite_passes_with_nothing_skipped() {
    let output = run(&["-m", "pytest", "-q", "-p", "no:cacheprovider", "-rs", "tests"]);
    assert!(output.status.success(), "the Python client's tests failed (above)");
    let summary = String::from_utf8_lossy(&output.stdout);
    let last = summary
        .lines()
        .rev()
        .find(|l| !l.trim().is_empty())
        .unwrap_or_default()
        .to_owned();
    assert!(
        last.contains(" passed") && !last.contains("skipped"),
        "every test of the Python client must run here: {last}"
    );
}
