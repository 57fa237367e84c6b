//! What the daemon crate's tests share: the `nusense` binary (for tests that run `nusense record`).
//! The tests of `nusense serve` itself live in host/cli/tests/serve, where cargo builds the binary for them.

/// The `nusense` binary of this build (another package's binary, so cargo does not hand it to these tests):
/// next to the test executable's target directory, built on demand.
pub fn nusense_binary() -> std::path::PathBuf {
    static BUILT: std::sync::OnceLock<std::path::PathBuf> = std::sync::OnceLock::new();
    BUILT
        .get_or_init(|| {
            let exe = std::env::current_exe().expect("test executable");
            // target/<profile>/deps/<test> -> target/<profile>
            let profile_dir = exe
                .parent()
                .and_then(|deps| deps.parent())
                .expect("target dir")
                .to_path_buf();
            let target_dir = profile_dir.parent().expect("target root").to_path_buf();
            let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
            let status = std::process::Command::new(cargo)
                .args(["build", "-p", "nusense", "--bin", "nusense"])
                .arg("--target-dir")
                .arg(&target_dir)
                .status()
                .expect("run cargo build");
            assert!(status.success(), "cargo build -p nusense failed");
            target_dir.join("debug").join("nusense")
        })
        .clone()
}
