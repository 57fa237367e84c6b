//! Puts the repository's memory.x (the one description of the STM32F411CEU6's memory) where the linker finds it,
//! and adds defmt's linker script.
use std::{env, fs, path::PathBuf};

fn main() {
    let manifest = PathBuf::from(env::var_os("CARGO_MANIFEST_DIR").unwrap());
    let memory_x = manifest.join("../../../memory.x");
    let out = PathBuf::from(env::var_os("OUT_DIR").unwrap());
    fs::copy(&memory_x, out.join("memory.x")).expect("memory.x at the repository root");
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rerun-if-changed={}", memory_x.display());
    println!("cargo:rustc-link-arg-bins=-Tdefmt.x");
}
