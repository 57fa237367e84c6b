//! The host's device code against the firmware's logic over a real pseudo-terminal: the same serial stack a
//! USB board goes through (open, raw mode, exclusive access, close, reopen), with the virtual board on the
//! other side.

use std::io::Write;
use std::time::{Duration, Instant};

use nusense_board::virtual_board::{VirtualBoard, VirtualBoardOptions};
use nusense_board::{BoardEvent, BoardLink, BoardTarget, LinkOptions, SupervisedLink, SupervisorOptions};
use nusense_protocol::{Channel, Side, Telemetry, PROTOCOL_VERSION};

fn options() -> LinkOptions {
    LinkOptions {
        timeout: Duration::from_millis(250),
        retries: 2,
        baud: 115_200,
    }
}

/// Telemetry until `done` holds for one frame or `limit` passes; returns the last frame seen.
fn telemetry_until(link: &mut BoardLink, limit: Duration, done: impl Fn(&Telemetry) -> bool) -> Telemetry {
    let deadline = Instant::now() + limit;
    let mut last = None;
    while Instant::now() < deadline {
        if let Some(telemetry) = link.next_telemetry(Duration::from_millis(50)).unwrap() {
            let finished = done(&telemetry);
            last = Some(telemetry);
            if finished {
                break;
            }
        }
    }
    last.expect("no telemetry arrived")
}

fn percentile(sorted: &[Duration], p: f64) -> Duration {
    sorted[((sorted.len() - 1) as f64 * p).round() as usize]
}

#[test]
fn handshake_and_info_over_a_pty() {
    let board = VirtualBoard::spawn_pty().unwrap();
    let mut link = BoardLink::open(board.path(), options()).unwrap();
    assert_eq!(link.device_protocol_version(), PROTOCOL_VERSION);
    let info = link.info().unwrap();
    assert_eq!(info.protocol_version, PROTOCOL_VERSION);
    assert_eq!(usize::from(info.channel_count), 4);
    assert!(info.max_current_ma >= 100);
    let serial: String = info.mcu_uid.iter().map(|byte| format!("{byte:02X}")).collect();
    assert_eq!(serial, board.serial_number());
}

#[test]
fn telemetry_shows_the_regulator_converging_near_the_setpoint() {
    let board = VirtualBoard::spawn_pty().unwrap();
    let mut link = BoardLink::open(board.path(), options()).unwrap();
    link.set_ramp(20).unwrap();
    link.stream_telemetry(10).unwrap();
    // From dark: the virtual board boots lit, so switch off and wait for the strings to go dark first.
    link.set_led(Channel::All, 100, false).unwrap();
    let dark = telemetry_until(&mut link, Duration::from_secs(3), |t| {
        t.channels.iter().all(|c| c.measured_ma < 1.0)
    });
    assert!(
        dark.channels.iter().all(|c| c.measured_ma < 1.0 && !c.enabled),
        "{dark:?}"
    );
    let asked = Instant::now();
    link.set_led(Channel::All, 100, true).unwrap();
    let within_2_percent = |t: &Telemetry| t.channels.iter().all(|c| (c.measured_ma - 100.0).abs() <= 2.0);
    // Convergence is judged on several consecutive frames, not one lucky sample.
    let mut in_band = 0;
    let deadline = Instant::now() + Duration::from_secs(5);
    while in_band < 5 && Instant::now() < deadline {
        let telemetry = telemetry_until(&mut link, Duration::from_secs(1), |_| true);
        in_band = if within_2_percent(&telemetry) { in_band + 1 } else { 0 };
    }
    assert_eq!(in_band, 5, "the board did not settle within 2 % of 100 mA");
    println!(
        "converged to 100 mA +/- 2 % (5 frames in a row) {:?} after SetLed",
        asked.elapsed()
    );
    let (steps_before, since) = (board.control_steps(), Instant::now());
    std::thread::sleep(Duration::from_millis(500));
    let rate = (board.control_steps() - steps_before) as f64 / since.elapsed().as_secs_f64();
    println!("virtual board control loop: {rate:.0} steps/s (nominal 1000)");
    assert!(rate > 0.0);
    let telemetry = telemetry_until(&mut link, Duration::from_secs(1), |_| true);
    assert!(telemetry
        .channels
        .iter()
        .all(|c| c.enabled && c.setpoint_ma == 100 && c.duty > 0.0 && c.duty < 1.0));
    assert!(telemetry.channels.iter().all(|c| !c.faults.any()), "{telemetry:?}");
    // The camera-side view of the plant agrees with what the board measures.
    for current in board.led_currents_ma() {
        assert!((current - 100.0).abs() <= 3.0, "{:?}", board.led_currents_ma());
    }
}

#[test]
fn an_over_limit_request_is_clamped_to_the_hard_limit() {
    let board = VirtualBoard::spawn_pty().unwrap();
    let mut link = BoardLink::open(board.path(), options()).unwrap();
    let limit = link.info().unwrap().max_current_ma;
    link.set_ramp(10).unwrap();
    link.stream_telemetry(5).unwrap();
    link.set_led(Channel::One(Side::Right), 5_000, true).unwrap();
    let mut peak: f32 = 0.0;
    let deadline = Instant::now() + Duration::from_millis(800);
    while Instant::now() < deadline {
        if let Some(telemetry) = link.next_telemetry(Duration::from_millis(50)).unwrap() {
            peak = peak.max(telemetry.channels[Side::Right.index()].measured_ma);
        }
    }
    let status = link.status().unwrap();
    let right = status.channels[Side::Right.index()];
    assert_eq!(right.setpoint_ma, limit);
    assert!(
        (right.measured_ma - f32::from(limit)).abs() <= f32::from(limit) * 0.03,
        "{right:?}"
    );
    // A little sensing noise may show above the limit, never a real overshoot.
    assert!(
        peak <= f32::from(limit) * 1.03,
        "peak {peak} mA over the {limit} mA limit"
    );
}

#[test]
fn the_port_can_be_closed_and_reopened_many_times() {
    let board = VirtualBoard::spawn_pty().unwrap();
    {
        let mut link = BoardLink::open(board.path(), options()).unwrap();
        link.set_led(Channel::One(Side::Left), 80, true).unwrap();
        // Left streaming when closed: the board must neither stall nor send it to the next session.
        link.stream_telemetry(5).unwrap();
    }
    std::thread::sleep(Duration::from_millis(100));
    for round in 0..5 {
        let mut link = BoardLink::open(board.path(), options()).unwrap();
        let status = link.status().unwrap();
        assert_eq!(status.channels[Side::Left.index()].setpoint_ma, 80, "round {round}");
        assert_eq!(status.telemetry_period_ms, 0, "a new session starts without streaming");
        link.ping(round).unwrap();
        assert_eq!(link.stats().stale_replies, 0);
    }
    // The first close was long enough for the board to see the hang-up; back-to-back reopens may not be.
    assert!(board.host_sessions() >= 2);
}

#[test]
fn garbage_written_to_the_port_is_counted_by_the_board_and_survived() {
    let board = VirtualBoard::spawn_pty().unwrap();
    {
        let mut raw = serialport::new(board.path(), 115_200).open_native().unwrap();
        raw.write_all(&[0x42; 700]).unwrap();
        raw.write_all(&[0x00, 0x03, 0x11, 0x22, 0x00, 0x05, 0x01, 0x02, 0x03, 0x04, 0x00])
            .unwrap();
        raw.flush().unwrap();
        std::thread::sleep(Duration::from_millis(50));
    }
    let mut link = BoardLink::open(board.path(), options()).unwrap();
    let counters = link.status().unwrap().counters;
    assert!(
        counters.oversize + counters.bad_cobs + counters.bad_crc >= 2,
        "{counters:?}"
    );
    link.ping(1).unwrap();
}

#[test]
fn ping_round_trip_over_the_pty() {
    let board = VirtualBoard::spawn_pty().unwrap();
    let mut link = BoardLink::open(board.path(), options()).unwrap();
    let mut round_trips: Vec<Duration> = (0..300).map(|nonce| link.ping(nonce).unwrap()).collect();
    round_trips.sort();
    println!(
        "ping round trip over the pty (300 pings): p50 {:?}, p99 {:?}, max {:?}",
        percentile(&round_trips, 0.50),
        percentile(&round_trips, 0.99),
        round_trips[round_trips.len() - 1]
    );
    assert_eq!(link.stats().retries, 0);
}

#[test]
fn the_supervised_link_reconnects_after_an_unplug() {
    let dir = tempfile::tempdir().unwrap();
    let link_path = dir.path().join("nusense-virtual");
    let mut board = VirtualBoard::spawn_pty_with(VirtualBoardOptions {
        link_path: Some(link_path.clone()),
        ..Default::default()
    })
    .unwrap();
    let supervisor_options = SupervisorOptions {
        telemetry_period_ms: 10,
        ..Default::default()
    };
    let link = SupervisedLink::spawn(BoardTarget::Path(board.path().to_owned()), supervisor_options);
    let events = link.subscribe();
    assert!(
        link.wait_connected(Duration::from_secs(3)),
        "{:?}",
        link.state().last_error
    );
    link.set_led(Channel::One(Side::Top), 90, true).unwrap();
    wait_for(&events, |event| matches!(event, BoardEvent::Telemetry(_)));

    let mut reconnects = Vec::new();
    for _ in 0..3 {
        board.unplug();
        wait_for(&events, |event| matches!(event, BoardEvent::Disconnected { .. }));
        // Unplugged for a while, so the supervisor is in its slowest backoff when the board returns.
        std::thread::sleep(Duration::from_millis(1200));
        board.replug().unwrap();
        let replugged = Instant::now();
        wait_for(&events, |event| matches!(event, BoardEvent::Connected { .. }));
        reconnects.push(replugged.elapsed());
        // The setpoint asked for before the unplug is back on the freshly booted board.
        wait_for(
            &events,
            |event| matches!(event, BoardEvent::Telemetry(t) if t.channels[Side::Top.index()].setpoint_ma == 90 && t.channels[Side::Top.index()].enabled),
        );
    }
    println!("supervised link back after replug: {reconnects:?}");
    assert!(
        reconnects.iter().all(|elapsed| *elapsed < Duration::from_secs(2)),
        "{reconnects:?}"
    );
    assert_eq!(link.state().connects, 4);
}

fn wait_for(events: &std::sync::mpsc::Receiver<BoardEvent>, what: impl Fn(&BoardEvent) -> bool) -> BoardEvent {
    let deadline = Instant::now() + Duration::from_secs(5);
    loop {
        let left = deadline.saturating_duration_since(Instant::now());
        let event = events
            .recv_timeout(left)
            .expect("the expected board event did not come");
        if what(&event) {
            return event;
        }
    }
}

/// A host that stops reading while the board streams at its fastest: the pty and the board's telemetry queue
/// fill, telemetry is dropped, and a request sent afterwards is still answered at the first attempt, because
/// replies leave on their own queue ahead of telemetry.
#[test]
fn a_reply_survives_a_telemetry_flood() {
    let board = VirtualBoard::spawn_pty().unwrap();
    let mut link = BoardLink::open(board.path(), options()).unwrap();
    link.stream_telemetry(nusense_firmware_core::limits::MIN_TELEMETRY_PERIOD_MS)
        .unwrap();
    let flood = Duration::from_secs(4);
    std::thread::sleep(flood);
    let dropped = board.telemetry_dropped();
    let nonce = 0xF100D;
    let rtt = link.ping(nonce).expect("the reply gets through the flood");
    let stats = link.stats();
    let backlog = link.drain_telemetry().count();
    println!(
        "after {flood:?} unread at {} ms: board dropped {dropped} telemetry frames; the pong came after {backlog} \
         queued frames, {rtt:?}, {} retries",
        nusense_firmware_core::limits::MIN_TELEMETRY_PERIOD_MS,
        stats.retries
    );
    assert!(
        dropped > 0,
        "the flood must overflow the board's telemetry queue to test anything"
    );
    assert_eq!((stats.retries, stats.timeouts), (0, 0));
    // What was buffered reached the host in order and undamaged; the board's backlog was bounded.
    assert_eq!(
        stats.wire.bad_crc + stats.wire.bad_cobs + stats.wire.oversize + stats.wire.unknown_tag,
        0
    );
    assert!(backlog < 4 * 1000 / nusense_firmware_core::limits::MIN_TELEMETRY_PERIOD_MS as usize);
}

/// DTR: closing the port stops the stream; a new session gets telemetry only when it asks for it.
#[test]
fn closing_the_port_stops_telemetry_until_the_next_session_asks() {
    let board = VirtualBoard::spawn_pty().unwrap();
    let mut link = BoardLink::open(board.path(), options()).unwrap();
    link.stream_telemetry(10).unwrap();
    assert!(link.next_telemetry(Duration::from_millis(500)).unwrap().is_some());
    drop(link);
    std::thread::sleep(Duration::from_millis(100));
    let mut link = BoardLink::open(board.path(), options()).unwrap();
    assert_eq!(link.status().unwrap().telemetry_period_ms, 0);
    assert!(link.next_telemetry(Duration::from_millis(300)).unwrap().is_none());
    link.stream_telemetry(10).unwrap();
    assert!(link.next_telemetry(Duration::from_millis(500)).unwrap().is_some());
}
