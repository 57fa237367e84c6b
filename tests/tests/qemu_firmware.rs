//! The real ARM firmware image under QEMU (b-l475e-iot01a), driven by the host's own device code over the pty
//! QEMU makes of USART1: handshake, LED commands, telemetry, and the regulator converging on the simulated plant.
//!
//! Builds the image first if needed (Debian's cross toolchain; see firmware/README.md). Fails, never skips, when
//! the toolchain or QEMU is missing.

use std::io::Write;
use std::path::Path;
use std::time::{Duration, Instant};

use nusense_board::{BoardLink, LinkOptions};
use nusense_hil::emulator::{QemuBoard, QemuImage, QemuOptions};
use nusense_protocol::{Channel, Side, Telemetry, PROTOCOL_VERSION};

fn options() -> LinkOptions {
    // Emulated time runs close to real time, but the first replies may wait for QEMU's start-up.
    LinkOptions {
        timeout: Duration::from_millis(1_000),
        retries: 3,
        baud: 115_200,
    }
}

/// The same launcher `nusense hil --emulated` uses: builds the image if needed, kills QEMU on drop.
fn start_board() -> QemuBoard {
    let images =
        QemuImage::find_images_workspace(Path::new(env!("CARGO_MANIFEST_DIR"))).unwrap_or_else(|e| panic!("{e}"));
    let image = QemuImage::build(&images).unwrap_or_else(|e| panic!("{e}"));
    QemuBoard::start(&image, &QemuOptions::default()).unwrap_or_else(|e| panic!("{e}"))
}

/// Telemetry until the board's own clock has advanced `board_span_us` past the first frame. Board time, not wall
/// time: on a loaded machine the emulator runs slower than real time. `wall_limit` only stops a dead link.
fn collect_telemetry(link: &mut BoardLink, board_span_us: u64, wall_limit: Duration) -> Vec<Telemetry> {
    let deadline = Instant::now() + wall_limit;
    let mut frames: Vec<Telemetry> = Vec::new();
    while Instant::now() < deadline {
        if let Some(t) = link.next_telemetry(Duration::from_millis(100)).expect("link alive") {
            frames.push(t);
            if t.uptime_us - frames[0].uptime_us >= board_span_us {
                break;
            }
        }
    }
    frames
}

#[test]
fn firmware_under_qemu_handshakes_regulates_and_streams() {
    let mut board = start_board();
    let mut link = BoardLink::open(board.pty_path(), options()).expect("handshake with the QEMU board");
    assert_eq!(link.device_protocol_version(), PROTOCOL_VERSION);

    let info = link.info().unwrap();
    assert_eq!(info.board_id.as_str(), "qemu-l475");
    assert_eq!(info.channel_count, 4);
    assert_eq!(info.max_current_ma, 120);
    let rtt = link.ping(0xC0FFEE).unwrap();
    println!(
        "QEMU board: firmware {} ({}), ping {rtt:?}",
        info.firmware_version, info.git_hash
    );

    link.set_ramp(50).unwrap();
    link.stream_telemetry(10).unwrap();
    let lit_at = Instant::now();
    link.set_led(Channel::All, 100, true).unwrap();
    let frames = collect_telemetry(&mut link, 1_500_000, Duration::from_secs(60));
    let span_us = frames.last().map_or(0, |t| t.uptime_us) - frames.first().map_or(0, |t| t.uptime_us);
    assert!(
        span_us >= 1_500_000,
        "telemetry stopped after {span_us} us of board time ({} frames)",
        frames.len()
    );
    let gaps: Vec<u64> = frames
        .windows(2)
        .map(|w| w[1].uptime_us.saturating_sub(w[0].uptime_us))
        .collect();
    // The median, because a starved emulator delays single frames (the cadence then resumes from the late one).
    let mut sorted_gaps = gaps.clone();
    sorted_gaps.sort_unstable();
    let median_gap = sorted_gaps[sorted_gaps.len() / 2] as f64;
    assert!(
        (9_000.0..=11_000.0).contains(&median_gap),
        "median telemetry period {median_gap} us"
    );

    // Convergence in board time: from the first frame where the setpoint is in force to the first frame after
    // which every channel stays within +/- 2 % of 100 mA.
    let start = frames
        .iter()
        .find(|t| t.channels.iter().all(|c| c.enabled))
        .expect("LEDs enabled")
        .uptime_us;
    let inside = |t: &Telemetry| t.channels.iter().all(|c| (c.measured_ma - 100.0).abs() <= 2.0);
    let last_outside = frames.iter().rposition(|t| !inside(t));
    let settled = match last_outside {
        None => frames.first(),
        Some(i) => frames.get(i + 1),
    }
    .expect("the regulator settles within 2 % and stays there");
    let peak = frames
        .iter()
        .flat_map(|t| t.channels.iter().map(|c| c.measured_ma))
        .fold(0.0f32, f32::max);
    println!(
        "QEMU regulator: within 100 mA +/- 2 % {:.1} ms after the setpoint (ramp 50 ms), peak {peak:.2} mA, \
         {} frames over {:.2} s of board time ({:.2} s wall), median period {:.2} ms",
        (settled.uptime_us - start) as f64 / 1e3,
        frames.len(),
        span_us as f64 / 1e6,
        lit_at.elapsed().as_secs_f64(),
        median_gap / 1e3
    );
    assert!(
        settled.uptime_us - start < 1_000_000,
        "settling took {} us",
        settled.uptime_us - start
    );
    assert!(peak <= 120.0 * 1.02, "peak {peak} mA");
    let last = frames.last().unwrap();
    for ch in &last.channels {
        assert_eq!(ch.setpoint_ma, 100);
        assert!(!ch.faults.any(), "{ch:?}");
        assert!(ch.duty > 0.2 && ch.duty < 0.9, "duty {}", ch.duty);
    }
    assert!(last.supply_mv > 4_500 && last.temperature_c > 20.0);

    // Setpoints are clamped whatever the host sends; one channel can be switched off alone.
    link.set_led(Channel::One(Side::Left), 60_000, true).unwrap();
    link.set_led(Channel::One(Side::Top), 100, false).unwrap();
    link.stream_telemetry(0).unwrap();
    std::thread::sleep(Duration::from_millis(300));
    let status = link.status().unwrap();
    assert_eq!(status.channels[Side::Left.index()].setpoint_ma, 120);
    assert!(
        (status.channels[Side::Left.index()].measured_ma - 120.0).abs() < 2.4,
        "{:?}",
        status.channels[3]
    );
    assert!(!status.channels[Side::Top.index()].enabled);
    assert!(status.channels[Side::Top.index()].measured_ma < 1.0);
    assert_eq!(status.telemetry_period_ms, 0);

    assert!(board.is_running(), "QEMU still running at the end");
}

#[test]
fn firmware_under_qemu_survives_garbage_and_counts_it() {
    let mut board = start_board();
    // Wait until the firmware listens (bytes sent while QEMU boots the image may be lost, which would not test it).
    drop(BoardLink::open(board.pty_path(), options()).expect("first handshake"));
    // Line noise before anyone talks properly: a damaged frame, a frame longer than any message, stray zeros.
    {
        let mut port = serialport::new(board.pty_path(), 115_200)
            .timeout(Duration::from_millis(200))
            .open_native()
            .expect("open the QEMU pty");
        let mut noise = vec![0x11, 0x22, 0x33, 0x00];
        noise.extend(std::iter::repeat_n(0x5A, 600));
        noise.extend([0x00, 0x00, 0x00]);
        port.write_all(&noise).unwrap();
        port.flush().unwrap();
        std::thread::sleep(Duration::from_millis(300));
    }
    let mut link = BoardLink::open(board.pty_path(), options()).expect("handshake after the noise");
    let counters = link.status().unwrap().counters;
    println!("board-side counters after the noise: {counters:?}");
    assert!(counters.bad_cobs + counters.bad_crc >= 1, "{counters:?}");
    assert!(counters.oversize >= 1, "{counters:?}");
    // The two Hellos; a status reports the frames received before the chunk that asked for it.
    assert!(counters.frames_ok >= 2, "{counters:?}");
    link.ping(7).expect("the link still works after the noise");
    assert!(board.is_running());
}

#[test]
fn firmware_under_qemu_restores_the_saved_config_after_reset() {
    let board = start_board();
    let mut link = BoardLink::open(board.pty_path(), options()).expect("handshake");
    link.set_ramp(20).unwrap();
    link.set_led(Channel::One(Side::Right), 80, true).unwrap();
    link.save_config().expect("SaveConfig is acknowledged once stored");
    link.set_led(Channel::One(Side::Right), 40, true).unwrap();
    link.reset().expect("Reset is acknowledged before the reboot");
    drop(link);
    std::thread::sleep(Duration::from_millis(500));
    let mut link = BoardLink::open(board.pty_path(), options()).expect("handshake after the reset");
    let status = link.status().unwrap();
    let right = status.channels[Side::Right.index()];
    // 80, not the unsaved 40: the board rebooted and restored what SaveConfig stored.
    assert_eq!((right.setpoint_ma, right.enabled), (80, true), "{right:?}");
    assert_eq!(status.ramp_ms, 20);
}
