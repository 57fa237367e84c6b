//! Puts the repository's memory.x (the one description of the STM32F411CEU6's memory) where the linker finds it,
//! adds defmt's linker script, and records the git commit for `GetInfo`.
use std::{env, fs, path::PathBuf, process::Command};

fn main() {
    let manifest = PathBuf::from(env::var_os("CARGO_MANIFEST_DIR").unwrap());
    let memory_x = manifest.join("../../../memory.x");
    let out = PathBuf::from(env::var_os("OUT_DIR").unwrap());
    fs::copy(&memory_x, out.join("memory.x")).expect("memory.x at the repository root");
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rerun-if-changed={}", memory_x.display());
    println!("cargo:rustc-link-arg-bins=-Tdefmt.x");
    // The on-target tests: defmt's symbols and embedded-test's table of tests.
    println!("cargo:rustc-link-arg-tests=-Tdefmt.x");
    println!("cargo:rustc-link-arg-tests=-Tembedded-test.x");
    println!("cargo::rustc-check-cfg=cfg(rust_analyzer)");

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
