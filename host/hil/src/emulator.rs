//! The QEMU firmware image as a board: builds (or finds) the `nusense-qemu-l475` ELF, starts
//! `qemu-system-arm -M b-l475e-iot01a -nographic -monitor none -serial pty -kernel ELF`, reads the pty QEMU made
//! for USART1 from its start-up message, and stops QEMU when the [`QemuBoard`] is dropped (also on panics and
//! early returns), so no emulator outlives the command or test that started it.
//!
//! `nusense hil --emulated` and the QEMU integration tests (tests/tests/qemu_firmware.rs) both start the board
//! through it, so they run the image the same way.

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::sync::{Arc, Mutex};
use std::time::Duration;

/// Cargo package (and binary) name of the emulated board image.
pub const QEMU_IMAGE_PACKAGE: &str = "nusense-qemu-l475";
/// The QEMU machine the image is built for.
pub const QEMU_MACHINE: &str = "b-l475e-iot01a";
const TARGET_TRIPLE: &str = "thumbv7em-none-eabihf";
/// Debian's cargo (package cargo-web): the rustup toolchains have no thumbv7em standard library.
const DEBIAN_CARGO: &str = "/usr/bin/cargo";

#[derive(Debug, thiserror::Error)]
pub enum EmulatorError {
    #[error(
        "cannot find the firmware images workspace (firmware/images/Cargo.toml) above {searched_from}; \
         run from the repository or pass the ELF path explicitly"
    )]
    NoImagesWorkspace { searched_from: String },
    #[error("cannot run `{command}` to build the QEMU image: {source}")]
    BuildSpawn {
        command: String,
        #[source]
        source: std::io::Error,
    },
    #[error("building the QEMU image failed ({status}); cargo said:\n{stderr_tail}")]
    BuildFailed { status: String, stderr_tail: String },
    #[error("the QEMU image {path} does not exist (build it with `cd firmware/images && PATH=/usr/bin:$PATH RUSTC_BOOTSTRAP=1 cargo build --release`)")]
    NoImage { path: PathBuf },
    #[error("cannot start {program}: {source} (`scripts/setup test` installs QEMU 10)")]
    QemuSpawn {
        program: String,
        #[source]
        source: std::io::Error,
    },
    #[error("QEMU did not report the ptys of both serial ports (board link, true currents); gave up after {waited:?} (it exited, or hung); it said:\n{output}")]
    NoPty { waited: Duration, output: String },
}

/// Where the QEMU image comes from.
#[derive(Clone, Debug)]
pub struct QemuImage {
    pub elf: PathBuf,
}

impl QemuImage {
    /// The images workspace (`firmware/images`) above `start`, or above this crate's source as a fallback.
    pub fn find_images_workspace(start: &Path) -> Result<PathBuf, EmulatorError> {
        let compiled_in = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
        start
            .ancestors()
            .chain(compiled_in.ancestors())
            .map(|dir| dir.join("firmware").join("images"))
            .find(|images| images.join("Cargo.toml").is_file())
            .ok_or_else(|| EmulatorError::NoImagesWorkspace {
                searched_from: start.display().to_string(),
            })
    }

    /// Where cargo puts the release ELF of the QEMU image in `images_workspace`.
    pub fn elf_path(images_workspace: &Path) -> PathBuf {
        images_workspace
            .join("target")
            .join(TARGET_TRIPLE)
            .join("release")
            .join(QEMU_IMAGE_PACKAGE)
    }

    /// An ELF that already exists.
    pub fn at(elf: impl Into<PathBuf>) -> Result<Self, EmulatorError> {
        let elf = elf.into();
        if elf.is_file() {
            Ok(Self { elf })
        } else {
            Err(EmulatorError::NoImage { path: elf })
        }
    }

    /// The image already built in `images_workspace`, without building.
    pub fn prebuilt(images_workspace: &Path) -> Result<Self, EmulatorError> {
        Self::at(Self::elf_path(images_workspace))
    }

    /// Builds the images workspace with Debian's cargo and build-std (quick when nothing changed) and returns
    /// the QEMU image. The whole workspace is built, as `firmware/build-images` does: Cargo unifies features
    /// across it, so building one image alone would give a different binary and the two commands would keep
    /// rebuilding each other's output. The images keep their own target directory whatever CARGO_TARGET_DIR the
    /// caller has, so the ELF is where [`Self::elf_path`] says.
    pub fn build(images_workspace: &Path) -> Result<Self, EmulatorError> {
        let inherited = std::env::var_os("PATH").unwrap_or_default();
        let mut paths = vec![PathBuf::from("/usr/bin")];
        paths.extend(std::env::split_paths(&inherited));
        let mut command = Command::new(DEBIAN_CARGO);
        command
            .args(["build", "--release"])
            .current_dir(images_workspace)
            .env("PATH", std::env::join_paths(paths).unwrap_or(inherited))
            .env("RUSTC", "/usr/bin/rustc")
            .env("RUSTDOC", "/usr/bin/rustdoc")
            .env("RUSTC_BOOTSTRAP", "1")
            .env("CARGO_TARGET_DIR", images_workspace.join("target"))
            // Left by an outer `cargo test`/`cargo run` of the host workspace (rustup's); they would send the
            // inner build to the wrong compiler, flags or target.
            .env_remove("RUSTUP_TOOLCHAIN")
            .env_remove("RUSTC_WRAPPER")
            .env_remove("RUSTC_WORKSPACE_WRAPPER")
            .env_remove("RUSTFLAGS")
            .env_remove("CARGO_ENCODED_RUSTFLAGS")
            .env_remove("CARGO_BUILD_TARGET")
            .stdout(Stdio::null())
            .stderr(Stdio::piped());
        let describe = format!("cd {} && {DEBIAN_CARGO} build --release", images_workspace.display());
        let output = command.output().map_err(|source| EmulatorError::BuildSpawn {
            command: describe,
            source,
        })?;
        if !output.status.success() {
            let stderr = String::from_utf8_lossy(&output.stderr);
            let lines: Vec<&str> = stderr.lines().collect();
            let tail = lines[lines.len().saturating_sub(30)..].join("\n");
            return Err(EmulatorError::BuildFailed {
                status: output.status.to_string(),
                stderr_tail: tail,
            });
        }
        Self::prebuilt(images_workspace)
    }
}

/// Options for starting QEMU.
#[derive(Clone, Debug)]
pub struct QemuOptions {
    /// The emulator binary.
    pub program: PathBuf,
    /// How long to wait for QEMU to announce its ptys. QEMU that fails to start exits, and that is reported as soon
    /// as its output closes; only a QEMU that hangs without a word waits this long. On a loaded machine a healthy
    /// start took over 10 s (three emulators starting at nice 19 beside four busy loops).
    pub start_timeout: Duration,
}

impl Default for QemuOptions {
    fn default() -> Self {
        Self {
            program: PathBuf::from("qemu-system-arm"),
            start_timeout: Duration::from_secs(120),
        }
    }
}

/// A running emulated board. Its USART1 (the board's link) is the pty at [`Self::pty_path`], its USART2 (the
/// simulated strings' true currents, see [`crate::light::LightMeter`]) the one at [`Self::light_pty_path`];
/// dropping it stops QEMU.
pub struct QemuBoard {
    child: Child,
    pty_path: String,
    light_pty_path: String,
    output: Arc<Mutex<Vec<String>>>,
}

/// Lines of QEMU's own output kept for error messages.
const KEPT_OUTPUT_LINES: usize = 50;

impl QemuBoard {
    pub fn start(image: &QemuImage, options: &QemuOptions) -> Result<Self, EmulatorError> {
        let mut child = Command::new(&options.program)
            .args([
                "-M",
                QEMU_MACHINE,
                "-nographic",
                "-monitor",
                "none",
                "-serial",
                "pty",
                "-serial",
                "pty",
                "-kernel",
            ])
            .arg(&image.elf)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .map_err(|source| EmulatorError::QemuSpawn {
                program: options.program.display().to_string(),
                source,
            })?;

        // QEMU announces the pty on stderr (some versions on stdout); both are drained for the emulator's whole
        // life so that it never blocks on a full pipe.
        let output = Arc::new(Mutex::new(Vec::new()));
        let (found_tx, found_rx) = mpsc::channel::<(String, String)>();
        if let Some(stderr) = child.stderr.take() {
            drain(stderr, output.clone(), found_tx.clone());
        }
        if let Some(stdout) = child.stdout.take() {
            drain(stdout, output.clone(), found_tx);
        }
        let board_output = output.clone();
        let mut board = Self {
            child,
            pty_path: String::new(),
            light_pty_path: String::new(),
            output,
        };
        let started = std::time::Instant::now();
        let deadline = started + options.start_timeout;
        while board.pty_path.is_empty() || board.light_pty_path.is_empty() {
            let left = deadline.saturating_duration_since(std::time::Instant::now());
            match found_rx.recv_timeout(left) {
                Ok((path, label)) if label == "serial0" => board.pty_path = path,
                Ok((path, label)) if label == "serial1" => board.light_pty_path = path,
                Ok(_) => {}
                Err(_) => break,
            }
        }
        match (board.pty_path.is_empty(), board.light_pty_path.is_empty()) {
            (false, false) => Ok(board),
            _ => {
                // QEMU may have exited with an error message; give the drain threads a moment to collect it.
                let _ = board.child.kill();
                let _ = board.child.wait();
                std::thread::sleep(Duration::from_millis(50));
                let output = board_output.lock().unwrap_or_else(|p| p.into_inner()).join("\n");
                Err(EmulatorError::NoPty {
                    waited: started.elapsed(),
                    output,
                })
            }
        }
    }

    /// The pty slave QEMU connected to the board's USART1; open it like any serial device.
    pub fn pty_path(&self) -> &str {
        &self.pty_path
    }

    /// The pty of USART2, where the image reports its simulated strings' true currents.
    pub fn light_pty_path(&self) -> &str {
        &self.light_pty_path
    }

    /// QEMU's process id.
    pub fn pid(&self) -> u32 {
        self.child.id()
    }

    /// True while QEMU is still running.
    pub fn is_running(&mut self) -> bool {
        matches!(self.child.try_wait(), Ok(None))
    }

    /// What QEMU printed so far (the last lines).
    pub fn output(&self) -> String {
        self.output.lock().unwrap_or_else(|p| p.into_inner()).join("\n")
    }
}

impl Drop for QemuBoard {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// The pty path in a QEMU start-up line such as `char device redirected to /dev/pts/3 (label serial0)`.
pub fn parse_pty_line(line: &str) -> Option<String> {
    let rest = &line[line.find("redirected to ")? + "redirected to ".len()..];
    let path = rest.split_whitespace().next()?;
    path.starts_with("/dev/").then(|| path.to_owned())
}

/// The label of such a line (`serial0`, `serial1`, ...).
fn parse_pty_label(line: &str) -> Option<String> {
    let rest = &line[line.find("(label ")? + "(label ".len()..];
    Some(rest.trim_end_matches(')').trim().to_owned())
}

fn drain(
    stream: impl std::io::Read + Send + 'static,
    output: Arc<Mutex<Vec<String>>>,
    found: mpsc::Sender<(String, String)>,
) {
    let spawned = std::thread::Builder::new().name("qemu output".into()).spawn(move || {
        for line in BufReader::new(stream).lines() {
            let Ok(line) = line else { break };
            if let (Some(path), Some(label)) = (parse_pty_line(&line), parse_pty_label(&line)) {
                let _ = found.send((path, label));
            }
            let mut kept = output.lock().unwrap_or_else(|p| p.into_inner());
            if kept.len() == KEPT_OUTPUT_LINES {
                kept.remove(0);
            }
            kept.push(line);
        }
    });
    if let Err(error) = spawned {
        tracing::warn!(target: "nusense_hil::emulator", %error, "cannot watch QEMU's output");
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pty_path_is_parsed_from_the_qemu_start_line() {
        assert_eq!(
            parse_pty_line("char device redirected to /dev/pts/7 (label serial0)").as_deref(),
            Some("/dev/pts/7")
        );
        assert_eq!(
            parse_pty_label("char device redirected to /dev/pts/8 (label serial1)").as_deref(),
            Some("serial1")
        );
        assert_eq!(parse_pty_line("qemu-system-arm: warning: nothing"), None);
        assert_eq!(parse_pty_line("redirected to nowhere"), None);
    }

    #[test]
    fn a_missing_image_is_a_typed_error() {
        let error = QemuImage::at("/nonexistent/nusense-qemu-l475").unwrap_err();
        assert!(matches!(error, EmulatorError::NoImage { .. }));
    }

    #[test]
    fn the_images_workspace_is_found_from_inside_the_repository() {
        let images = QemuImage::find_images_workspace(Path::new(env!("CARGO_MANIFEST_DIR"))).unwrap();
        assert!(images.join("Cargo.toml").is_file());
        assert!(QemuImage::elf_path(&images).ends_with("thumbv7em-none-eabihf/release/nusense-qemu-l475"));
    }
}
