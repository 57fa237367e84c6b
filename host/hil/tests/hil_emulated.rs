//! `nusense hil --emulated` as a test: the check suite against the real ARM firmware image under QEMU
//! (b-l475e-iot01a, USART1 on a pty) with the simulated camera fed by the board's measured currents.
//! QEMU is started and killed by `nusense_hil::emulator::QemuBoard` (on drop, also when an assertion fails).

use nusense_hil::emulator::QemuOptions;
use nusense_hil::{run_suite, HilOptions, HilTarget, Verdict, TIMING_CHECKS};

#[test]
fn every_functional_hil_check_passes_against_the_qemu_firmware_image() {
    let target = HilTarget::Emulated {
        elf: None,
        build: true,
        qemu: QemuOptions::default(),
    };
    let mut running = target
        .start()
        .expect("the QEMU image builds and QEMU starts (see firmware/README.md)");
    assert!(
        running.camera.is_some(),
        "emulated mode looks through the simulated camera"
    );
    let report = run_suite(&mut running, &HilOptions::quick(), &mut |result| {
        eprintln!("{} {:<18} {}", result.verdict.label(), result.name, result.summary)
    });
    drop(running);
    // Timing verdicts (telemetry rate and jitter, latency) depend on how much CPU QEMU gets: on a loaded CI
    // machine they are measured and printed, not asserted (no timed asserts), unless NUSENSE_HIL_STRICT is set
    // (a quiet machine, or a release check).
    let strict = std::env::var_os("NUSENSE_HIL_STRICT").is_some();
    let failed: Vec<String> = report
        .checks
        .iter()
        .filter(|c| c.verdict != Verdict::Pass && (strict || !TIMING_CHECKS.contains(&c.name)))
        .map(|c| format!("{} {}: {}", c.verdict.label(), c.name, c.summary))
        .collect();
    assert!(failed.is_empty(), "{}\n{}", report.summary_line(), failed.join("\n"));
    assert_eq!(report.checks.len(), 8);
    let telemetry = report.check("telemetry_rate").expect("telemetry check");
    assert!(
        telemetry.details["frames"].as_u64().is_some_and(|n| n > 2),
        "{}",
        telemetry.summary
    );
    // The numbers behind the verdicts are there for the JSON output.
    let latency = report.check("latency").expect("latency check");
    assert!(latency.details["p50_ms"].as_f64().is_some_and(|p| p > 0.0));
    assert!(latency.details["p99_ms"].as_f64() >= latency.details["p50_ms"].as_f64());
    let ramp = report.check("led_ramp").expect("ramp check");
    assert_eq!(
        ramp.details["steps"].as_array().map(Vec::len),
        Some(HilOptions::quick().setpoints_ma.len())
    );
}
