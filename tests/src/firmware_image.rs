//! The firmware images for integration tests: builds them with Debian's cross toolchain (the same command as
//! firmware/README.md) and starts the QEMU one behind a pseudo-terminal.
//!
//! A missing toolchain or QEMU is an error that says what to install, never a silently skipped test.

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::Duration;

/// The firmware workspace (firmware/images) of this repository.
pub fn images_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../firmware/images")
}

const TARGET: &str = "thumbv7em-none-eabihf";
const DEBIAN_CARGO: &str = "/usr/bin/cargo";
const DEBIAN_RUSTC: &str = "/usr/bin/rustc";
const RUST_SRC: &str = "/usr/lib/rustlib/src/rust/library";
const LINKER: &str = "/usr/bin/ld.lld-22";
const QEMU: &str = "qemu-system-arm";

#[derive(Debug, thiserror::Error)]
pub enum FirmwareImageError {
    #[error("firmware toolchain missing: {what} not found (run `scripts/setup test`, see shared/TOOLCHAIN.md)")]
    ToolchainMissing { what: &'static str },
    #[error("could not run {command}: {source}")]
    Spawn {
        command: String,
        source: std::io::Error,
    },
    #[error("building firmware image `{package}` failed ({status}):\n{stderr_tail}")]
    BuildFailed {
        package: String,
        status: std::process::ExitStatus,
        stderr_tail: String,
    },
    #[error("the build succeeded but {0} is missing")]
    ElfMissing(PathBuf),
    #[error("QEMU did not announce its serial pty within {0:?} (output so far: {1:?})")]
    NoPty(Duration, String),
}

/// Builds firmware/images in release mode (incremental: quick when nothing changed) and returns the path of
/// `package`'s ELF. The whole images workspace is built, exactly as `firmware/build-images` does: Cargo unifies
/// features across it, so building one image alone would produce a different binary and make the two commands
/// rebuild each other's output.
pub fn build_image(package: &str) -> Result<PathBuf, FirmwareImageError> {
    for (path, what) in [
        (
            DEBIAN_CARGO,
            "Debian's cargo (/usr/bin/cargo, package cargo-web)",
        ),
        (
            DEBIAN_RUSTC,
            "Debian's rustc (/usr/bin/rustc, package rustc-web)",
        ),
        (
            RUST_SRC,
            "the Rust standard library sources (package rust-web-src)",
        ),
        (LINKER, "ld.lld-22 (package lld-22)"),
    ] {
        if !Path::new(path).exists() {
            return Err(FirmwareImageError::ToolchainMissing { what });
        }
    }
    let dir = images_dir();
    let target_dir = dir.join("target");
    let path = std::env::var_os("PATH").unwrap_or_default();
    let mut paths = vec![PathBuf::from("/usr/bin")];
    paths.extend(std::env::split_paths(&path));
    let mut command = Command::new(DEBIAN_CARGO);
    command
        .current_dir(&dir)
        .args(["build", "--release"])
        // The outer `cargo test` (rustup's) leaves variables that would send the inner build to the wrong
        // compiler or directory.
        .env_remove("RUSTUP_TOOLCHAIN")
        .env_remove("RUSTFLAGS")
        .env_remove("CARGO_ENCODED_RUSTFLAGS")
        .env_remove("CARGO_BUILD_TARGET")
        .env_remove("RUSTC_WRAPPER")
        .env_remove("RUSTC_WORKSPACE_WRAPPER")
        .env("RUSTC", DEBIAN_RUSTC)
        .env("RUSTDOC", "/usr/bin/rustdoc")
        .env("CARGO_TARGET_DIR", &target_dir)
        .env("RUSTC_BOOTSTRAP", "1")
        .env("PATH", std::env::join_paths(paths).unwrap_or(path))
        .stdout(Stdio::null())
        .stderr(Stdio::piped());
    let output = command
        .output()
        .map_err(|source| FirmwareImageError::Spawn {
            command: format!("{DEBIAN_CARGO} build"),
            source,
        })?;
    if !output.status.success() {
        let stderr = String::from_utf8_lossy(&output.stderr);
        let lines: Vec<&str> = stderr.lines().collect();
        let tail = lines[lines.len().saturating_sub(40)..].join("\n");
        return Err(FirmwareImageError::BuildFailed {
            package: package.to_owned(),
            status: output.status,
            stderr_tail: tail,
        });
    }
    let elf = target_dir.join(TARGET).join("release").join(package);
    if elf.is_file() {
        Ok(elf)
    } else {
        Err(FirmwareImageError::ElfMissing(elf))
    }
}

/// The QEMU image (board `b-l475e-iot01a`).
pub fn qemu_image() -> Result<PathBuf, FirmwareImageError> {
    build_image("nusense-qemu-l475")
}

/// The real board's image (STM32F411CEU6).
pub fn f411_image() -> Result<PathBuf, FirmwareImageError> {
    build_image("nusense-f411")
}

/// A running `qemu-system-arm -M b-l475e-iot01a` with USART1 on a pty. Killed when dropped, so a failing test
/// never leaves an emulator behind.
pub struct QemuBoard {
    child: Child,
    pty: String,
}

impl QemuBoard {
    pub fn start(elf: &Path) -> Result<Self, FirmwareImageError> {
        let mut child = Command::new(QEMU)
            .args([
                "-M",
                "b-l475e-iot01a",
                "-nographic",
                "-monitor",
                "none",
                "-serial",
                "pty",
                "-kernel",
            ])
            .arg(elf)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .map_err(|source| match source.kind() {
                std::io::ErrorKind::NotFound => FirmwareImageError::ToolchainMissing {
                    what: "qemu-system-arm 10 (bookworm-backports package qemu-system-arm)",
                },
                _ => FirmwareImageError::Spawn {
                    command: QEMU.to_owned(),
                    source,
                },
            })?;
        // QEMU prints "char device redirected to /dev/pts/N (label serial0)" on stderr or stdout, depending on
        // the version; read both on threads so a silent QEMU cannot hang the test.
        let (found_tx, found_rx) = mpsc::channel::<String>();
        for stream in [
            child
                .stdout
                .take()
                .map(|s| Box::new(s) as Box<dyn std::io::Read + Send>),
            child
                .stderr
                .take()
                .map(|s| Box::new(s) as Box<dyn std::io::Read + Send>),
        ]
        .into_iter()
        .flatten()
        {
            let found_tx = found_tx.clone();
            std::thread::spawn(move || {
                for line in BufReader::new(stream).lines().map_while(Result::ok) {
                    let _ = found_tx.send(line);
                }
            });
        }
        drop(found_tx);
        let wait = Duration::from_secs(10);
        let deadline = std::time::Instant::now() + wait;
        let mut seen = String::new();
        let mut board = QemuBoard {
            child,
            pty: String::new(),
        };
        while let Some(left) = deadline.checked_duration_since(std::time::Instant::now()) {
            match found_rx.recv_timeout(left) {
                Ok(line) => {
                    if let Some(pty) = pty_in(&line) {
                        board.pty = pty;
                        return Ok(board);
                    }
                    seen.push_str(&line);
                    seen.push('\n');
                }
                Err(_) => break,
            }
        }
        Err(FirmwareImageError::NoPty(wait, seen))
    }

    /// The pseudo-terminal QEMU connected USART1 to.
    pub fn pty(&self) -> &str {
        &self.pty
    }

    /// Whether the emulator is still running.
    pub fn is_running(&mut self) -> bool {
        matches!(self.child.try_wait(), Ok(None))
    }
}

impl Drop for QemuBoard {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn pty_in(line: &str) -> Option<String> {
    let start = line.find("/dev/pts/")?;
    let rest = &line[start..];
    let end = rest
        .find(|c: char| c.is_whitespace() || c == ')')
        .unwrap_or(rest.len());
    Some(rest[..end].to_owned())
}

#[cfg(test)]
mod tests {
    #[test]
    fn finds_the_pty_in_qemus_announcement() {
        assert_eq!(
            super::pty_in("char device redirected to /dev/pts/7 (label serial0)").as_deref(),
            Some("/dev/pts/7")
        );
        assert_eq!(super::pty_in("qemu-system-arm: warning: nothing"), None);
    }
}
