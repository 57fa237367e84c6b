//! Puts this board's memory.x where cortex-m-rt's link.x finds it, and records the git commit for `GetInfo`.
use std::{env, fs, path::PathBuf, process::Command};

fn main() {
    let manifest = PathBuf::from(env::var_os("CARGO_MANIFEST_DIR").unwrap());
    let out = PathBuf::from(env::var_os("OUT_DIR").unwrap());
    fs::copy(manifest.join("memory.x"), out.join("memory.x")).expect("qemu-l475/memory.x");
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rerun-if-changed=memory.x");
    // defmt's symbols (see the defmt-rtt dependency in Cargo.toml).
    println!("cargo:rustc-link-arg-bins=-Tdefmt.x");

    let hash = Command::new("git")
        .args(["rev-parse", "--short=12", "HEAD"])
        .current_dir(&manifest)
        .output()
        .ok()
        .filter(|o| o.status.success())
        .and_then(|o| String::from_utf8(o.stdout).ok())
        .map(|s| s.trim().to_owned())
        .unwrap_or_else(|| "unknown".to_owned());
    println!("cargo:rustc-env=NUSENSE_GIT_HASH={hash}");
}
