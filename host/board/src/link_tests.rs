//! BoardLink against a scripted board on an in-memory pipe: every way the line can misbehave.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use nusense_protocol::framing::{self, FrameDecoder, MAX_FRAME_LEN};
use nusense_protocol::*;

use super::*;

/// Encodes one board message as a frame.
fn frame(message: &BoardMessage) -> Vec<u8> {
    let mut buf = [0u8; MAX_FRAME_LEN];
    framing::encode(message, &mut buf).unwrap().to_vec()
}

fn reply(seq: Seq, reply: Reply) -> Vec<u8> {
    frame(&BoardMessage::Response(Response { seq, result: Ok(reply) }))
}

fn refusal(seq: Seq, error: DeviceError) -> Vec<u8> {
    frame(&BoardMessage::Response(Response {
        seq,
        result: Err(error),
    }))
}

fn telemetry(uptime_us: u64) -> Telemetry {
    Telemetry {
        uptime_us,
        ..Telemetry::default()
    }
}

fn info() -> DeviceInfo {
    DeviceInfo {
        protocol_version: PROTOCOL_VERSION,
        firmware_version: "0.1.0".try_into().unwrap(),
        git_hash: "abc123".try_into().unwrap(),
        board_id: "fake".try_into().unwrap(),
        mcu_uid: [7; 12],
        channel_count: CHANNEL_COUNT as u8,
        max_current_ma: 120,
        max_total_current_ma: 440,
    }
}

/// The usual answer of a healthy board to `request`.
fn healthy_answer(request: &Request) -> Vec<u8> {
    let answer = match request.body {
        RequestBody::Hello { .. } => Reply::Hello {
            protocol_version: PROTOCOL_VERSION,
            schema: SCHEMA_FINGERPRINT,
        },
        RequestBody::GetInfo => Reply::Info(info()),
        RequestBody::GetStatus => Reply::Status(Status::default()),
        RequestBody::Ping { nonce } => Reply::Pong { nonce },
        _ => Reply::Ack,
    };
    reply(request.seq, answer)
}

type Handler = Box<dyn FnMut(&Request, &mut dyn FnMut(&[u8])) + Send>;

/// A board scripted by `handler`, on the far end of a pipe; optionally streams telemetry on its own.
struct FakeBoard {
    requests: Arc<Mutex<Vec<Request>>>,
    /// Every byte the host sent, frames and keepalives alike.
    raw: Arc<Mutex<Vec<u8>>>,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
}

impl FakeBoard {
    fn start(handler: Handler, telemetry_every: Option<Duration>) -> (Self, PipeEnd) {
        let (host, board) = memory_pipe("fake board");
        (Self::start_on(board, handler, telemetry_every), host)
    }

    fn start_on(mut board: PipeEnd, mut handler: Handler, telemetry_every: Option<Duration>) -> Self {
        let requests = Arc::new(Mutex::new(Vec::new()));
        let raw = Arc::new(Mutex::new(Vec::new()));
        let stop = Arc::new(AtomicBool::new(false));
        let (seen, seen_raw, stopping) = (requests.clone(), raw.clone(), stop.clone());
        let thread = std::thread::spawn(move || {
            let mut decoder: FrameDecoder = FrameDecoder::new();
            let mut buf = [0u8; 256];
            let started = Instant::now();
            let mut next_telemetry = started;
            while !stopping.load(Ordering::Relaxed) {
                let n = match board.read_timeout(&mut buf, Duration::from_millis(1)) {
                    Ok(n) => n,
                    Err(_) => return,
                };
                seen_raw.lock().unwrap().extend_from_slice(&buf[..n]);
                let mut received = Vec::new();
                decoder.feed::<Request>(&buf[..n], |request| received.extend(request.ok()));
                for request in received {
                    seen.lock().unwrap().push(request.clone());
                    let mut out = Vec::new();
                    handler(&request, &mut |bytes: &[u8]| out.extend_from_slice(bytes));
                    if board.write_all_bytes(&out).is_err() {
                        return;
                    }
                }
                if let Some(period) = telemetry_every {
                    if Instant::now() >= next_telemetry {
                        next_telemetry += period;
                        let uptime = started.elapsed().as_micros() as u64;
                        if board
                            .write_all_bytes(&frame(&BoardMessage::Telemetry(telemetry(uptime))))
                            .is_err()
                        {
                            return;
                        }
                    }
                }
            }
        });
        Self {
            requests,
            raw,
            stop,
            thread: Some(thread),
        }
    }

    fn healthy() -> (Self, PipeEnd) {
        Self::start(Box::new(|request, send| send(&healthy_answer(request))), None)
    }

    fn requests(&self) -> Vec<Request> {
        self.requests.lock().unwrap().clone()
    }
}

impl Drop for FakeBoard {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

fn quick() -> LinkOptions {
    LinkOptions {
        timeout: Duration::from_millis(40),
        retries: 2,
        baud: 115_200,
    }
}

#[test]
fn handshake_then_info_status_and_ping() {
    let (board, host) = FakeBoard::healthy();
    let mut link = BoardLink::over(Box::new(host), quick()).unwrap();
    assert_eq!(link.device_protocol_version(), PROTOCOL_VERSION);
    assert_eq!(link.info().unwrap(), info());
    assert_eq!(link.status().unwrap(), Status::default());
    link.ping(42).unwrap();
    let bodies: Vec<RequestBody> = board.requests().into_iter().map(|request| request.body).collect();
    assert_eq!(
        bodies,
        vec![
            RequestBody::Hello {
                protocol_version: PROTOCOL_VERSION
            },
            RequestBody::GetInfo,
            RequestBody::GetStatus,
            RequestBody::Ping { nonce: 42 }
        ]
    );
    // Every request carries its own sequence number.
    let seqs: Vec<Seq> = board.requests().iter().map(|request| request.seq).collect();
    assert!(
        seqs.windows(2).all(|pair| pair[1] == pair[0].wrapping_add(1)),
        "{seqs:?}"
    );
    assert_eq!(link.counters().frames_ok, 4);
}

#[test]
fn a_newer_board_is_refused_in_plain_words() {
    let (_board, host) = FakeBoard::start(
        Box::new(|request, send| {
            send(&reply(
                request.seq,
                Reply::Hello {
                    protocol_version: PROTOCOL_VERSION + 1,
                    schema: 0,
                },
            ))
        }),
        None,
    );
    let error = BoardLink::over(Box::new(host), quick())
        .err()
        .expect("a version mismatch must fail the open");
    let text = error.to_string();
    assert!(
        matches!(error, LinkError::VersionMismatch { device, host } if device == PROTOCOL_VERSION + 1 && host == PROTOCOL_VERSION)
    );
    assert!(
        text.contains(&format!("board speaks protocol version {}", PROTOCOL_VERSION + 1)),
        "{text}"
    );
    assert!(
        text.contains(&format!("this host speaks version {PROTOCOL_VERSION}")),
        "{text}"
    );
    assert!(text.contains("update the host software"), "{text}");
}

#[test]
fn a_board_that_refuses_our_version_is_reported_as_a_mismatch() {
    let (_board, host) = FakeBoard::start(
        Box::new(|request, send| {
            send(&refusal(
                request.seq,
                DeviceError::VersionMismatch {
                    device: 0,
                    host: PROTOCOL_VERSION,
                },
            ))
        }),
        None,
    );
    let error = BoardLink::over(Box::new(host), quick()).err().unwrap();
    assert!(error.to_string().contains("update the board's firmware"), "{error}");
}

#[test]
fn silence_is_a_timeout_after_the_configured_retries() {
    let (board, host) = FakeBoard::start(
        Box::new(|request, send| {
            if matches!(request.body, RequestBody::Hello { .. }) {
                send(&healthy_answer(request));
            }
        }),
        None,
    );
    let mut link = BoardLink::over(Box::new(host), quick()).unwrap();
    let started = Instant::now();
    let error = link.ping(1).unwrap_err();
    assert!(matches!(error, LinkError::Timeout), "{error}");
    assert!(started.elapsed() >= quick().timeout * 3);
    let stats = link.stats();
    assert_eq!((stats.timeouts, stats.retries), (3, 2));
    // Three attempts, each with its own sequence number.
    let pings: Vec<Seq> = board
        .requests()
        .iter()
        .filter(|r| matches!(r.body, RequestBody::Ping { .. }))
        .map(|r| r.seq)
        .collect();
    assert_eq!(pings.len(), 3);
    assert!(pings[0] != pings[1] && pings[1] != pings[2]);
}

#[test]
fn no_answer_to_hello_says_what_to_check() {
    let (_board, host) = FakeBoard::start(Box::new(|_, _| {}), None);
    let error = BoardLink::over(Box::new(host), quick()).err().unwrap();
    assert!(matches!(error, LinkError::NoHandshake { .. }), "{error}");
    assert!(error.to_string().contains("firmware running"), "{error}");
}

#[test]
fn a_late_reply_is_dropped_as_stale_and_the_retry_answered() {
    // The board sits on the first Ping and answers it only when the retry arrives, then answers the retry.
    let mut held: Option<Request> = None;
    let (_board, host) = FakeBoard::start(
        Box::new(move |request, send| match request.body {
            RequestBody::Ping { .. } if held.is_none() => held = Some(request.clone()),
            RequestBody::Ping { .. } => {
                send(&healthy_answer(held.as_ref().unwrap()));
                send(&healthy_answer(request));
            }
            _ => send(&healthy_answer(request)),
        }),
        None,
    );
    let mut link = BoardLink::over(Box::new(host), quick()).unwrap();
    link.ping(9).unwrap();
    let stats = link.stats();
    assert_eq!((stats.stale_replies, stats.timeouts, stats.retries), (1, 1, 1));
}

#[test]
fn garbage_on_the_line_is_counted_and_survived() {
    let (_board, host) = FakeBoard::start(
        Box::new(|request, send| {
            if matches!(request.body, RequestBody::GetInfo) {
                // Line noise, a frame with a damaged byte, a frame that is not a board message, a runaway frame.
                send(&[0x13, 0x37, 0xFF, 0x00]);
                let mut damaged = healthy_answer(request);
                damaged[2] ^= 0x40;
                send(&damaged);
                let mut not_a_message = [0u8; MAX_FRAME_LEN];
                send(framing::encode(&[0xFFu8; 32], &mut not_a_message).unwrap());
                send(&[0x55; 3 * MAX_FRAME_LEN]);
                send(&[0x00]);
            }
            send(&healthy_answer(request));
        }),
        None,
    );
    let mut link = BoardLink::over(Box::new(host), quick()).unwrap();
    assert_eq!(link.info().unwrap(), info());
    let counters = link.counters();
    let dropped = counters.bad_cobs + counters.bad_crc + counters.unknown_tag + counters.oversize;
    assert_eq!(dropped, 4, "{counters:?}");
    assert_eq!(counters.oversize, 1, "{counters:?}");
    assert_eq!(counters.unknown_tag, 1, "{counters:?}");
    assert_eq!(counters.frames_ok, 2);
    // Still in step afterwards.
    link.ping(3).unwrap();
    assert_eq!(link.stats().retries, 0);
}

#[test]
fn a_reply_split_into_single_bytes_is_reassembled() {
    let (_board, host) = FakeBoard::start(
        Box::new(|request, send| {
            for byte in healthy_answer(request) {
                send(&[byte]);
            }
        }),
        None,
    );
    let mut link = BoardLink::over(Box::new(host), quick()).unwrap();
    assert_eq!(link.info().unwrap(), info());
}

#[test]
fn telemetry_between_replies_is_queued_in_order() {
    let uptime = Arc::new(Mutex::new(0u64));
    let (_board, host) = FakeBoard::start(
        Box::new(move |request, send| {
            if !matches!(request.body, RequestBody::Hello { .. }) {
                for _ in 0..3 {
                    let mut next = uptime.lock().unwrap();
                    *next += 1000;
                    send(&frame(&BoardMessage::Telemetry(telemetry(*next))));
                }
            }
            send(&healthy_answer(request));
        }),
        None,
    );
    let mut link = BoardLink::over(Box::new(host), quick()).unwrap();
    link.stream_telemetry(1).unwrap();
    link.set_led(Channel::All, 100, true).unwrap();
    let mut uptimes = Vec::new();
    while let Some(telemetry) = link.next_telemetry(Duration::from_millis(5)).unwrap() {
        uptimes.push(telemetry.uptime_us);
    }
    assert_eq!(uptimes, (1..=6).map(|i| i * 1000).collect::<Vec<u64>>());
    assert_eq!(link.stats().telemetry_received, 6);
}

#[test]
fn streamed_telemetry_arrives_without_requests() {
    let (_board, host) = FakeBoard::start(
        Box::new(|request, send| send(&healthy_answer(request))),
        Some(Duration::from_millis(2)),
    );
    let mut link = BoardLink::over(Box::new(host), quick()).unwrap();
    let first = link
        .next_telemetry(Duration::from_millis(200))
        .unwrap()
        .expect("telemetry");
    let second = link
        .next_telemetry(Duration::from_millis(200))
        .unwrap()
        .expect("telemetry");
    assert!(second.uptime_us > first.uptime_us);
}

#[test]
fn a_refusal_is_a_device_error_with_the_reason() {
    let (_board, host) = FakeBoard::start(
        Box::new(|request, send| match request.body {
            RequestBody::SetLed { .. } => send(&refusal(request.seq, DeviceError::BadArgument(Argument::CurrentMa))),
            _ => send(&healthy_answer(request)),
        }),
        None,
    );
    let mut link = BoardLink::over(Box::new(host), quick()).unwrap();
    let error = link.set_led(Channel::One(Side::Left), 5000, true).unwrap_err();
    assert!(
        matches!(error, LinkError::Device(DeviceError::BadArgument(Argument::CurrentMa))),
        "{error}"
    );
    // A refusal is an answer: no retry.
    assert_eq!(link.stats().retries, 0);
}

#[test]
fn a_wrong_kind_of_reply_is_reported() {
    let (_board, host) = FakeBoard::start(
        Box::new(|request, send| match request.body {
            RequestBody::GetStatus => send(&reply(request.seq, Reply::Ack)),
            _ => send(&healthy_answer(request)),
        }),
        None,
    );
    let mut link = BoardLink::over(Box::new(host), quick()).unwrap();
    let error = link.status().unwrap_err();
    assert!(
        matches!(
            error,
            LinkError::UnexpectedReply {
                request: "GetStatus",
                ..
            }
        ),
        "{error}"
    );
}

#[test]
fn an_unplugged_board_is_a_disconnect_not_a_timeout() {
    let (board, host) = FakeBoard::healthy();
    let mut link = BoardLink::over(Box::new(host), quick()).unwrap();
    drop(board);
    let error = link.info().unwrap_err();
    assert!(error.is_disconnect(), "{error}");
}

#[test]
fn leftovers_of_a_previous_session_are_discarded_on_open() {
    let (host, mut board_end) = memory_pipe("leftovers");
    // A reply and telemetry from before this host opened the line.
    board_end.write_all_bytes(&reply(0, Reply::Ack)).unwrap();
    board_end
        .write_all_bytes(&frame(&BoardMessage::Telemetry(telemetry(1))))
        .unwrap();
    let _board = FakeBoard::start_on(
        board_end,
        Box::new(|request, send| send(&healthy_answer(request))),
        None,
    );
    let mut link = BoardLink::over(Box::new(host), quick()).unwrap();
    assert_eq!(link.next_telemetry(Duration::from_millis(10)).unwrap(), None);
    assert_eq!(link.stats().stale_replies, 0);
}

mod supervised {
    use super::*;

    fn fast_supervisor() -> SupervisorOptions {
        SupervisorOptions {
            link: quick(),
            telemetry_period_ms: 2,
            backoff_min: Duration::from_millis(5),
            backoff_max: Duration::from_millis(40),
            silence_limit: Duration::from_millis(100),
        }
    }

    /// Each connect plugs in a fresh fake board; the test can unplug the current one.
    struct Bench {
        current: Arc<Mutex<Option<FakeBoard>>>,
        plugged: Arc<AtomicBool>,
    }

    impl Bench {
        fn new() -> Self {
            Self {
                current: Arc::new(Mutex::new(None)),
                plugged: Arc::new(AtomicBool::new(true)),
            }
        }

        fn connector(&self) -> impl FnMut() -> Result<BoardLink, LinkError> + Send + 'static {
            let (current, plugged) = (self.current.clone(), self.plugged.clone());
            move || {
                if !plugged.load(Ordering::Relaxed) {
                    return Err(LinkError::NoBoardFound {
                        vid: USB_VID,
                        pid: USB_PID,
                        serial_number: None,
                    });
                }
                let (board, host) = FakeBoard::start(
                    Box::new(|request, send| send(&healthy_answer(request))),
                    Some(Duration::from_millis(2)),
                );
                *current.lock().unwrap() = Some(board);
                BoardLink::over(Box::new(host), quick())
            }
        }

        fn unplug(&self) {
            self.plugged.store(false, Ordering::Relaxed);
            self.current.lock().unwrap().take();
        }

        fn replug(&self) {
            self.plugged.store(true, Ordering::Relaxed);
        }

        fn requests(&self) -> Vec<Request> {
            self.current
                .lock()
                .unwrap()
                .as_ref()
                .map(FakeBoard::requests)
                .unwrap_or_default()
        }
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

    #[test]
    fn reconnects_after_an_unplug_and_reapplies_the_led_setpoints() {
        let bench = Bench::new();
        let link = SupervisedLink::spawn_with(bench.connector(), "fake".into(), fast_supervisor());
        let events = link.subscribe();
        assert!(link.wait_connected(Duration::from_secs(2)));
        wait_for(&events, |event| matches!(event, BoardEvent::Telemetry(_)));
        link.set_led(Channel::One(Side::Right), 80, true).unwrap();

        bench.unplug();
        wait_for(&events, |event| matches!(event, BoardEvent::Disconnected { .. }));
        assert!(!link.is_connected());
        assert!(matches!(
            link.set_led(Channel::All, 10, true),
            Err(LinkError::NotConnected)
        ));

        bench.replug();
        let replugged = Instant::now();
        wait_for(&events, |event| matches!(event, BoardEvent::Connected { .. }));
        assert!(replugged.elapsed() < Duration::from_secs(2));
        wait_for(&events, |event| matches!(event, BoardEvent::Telemetry(_)));
        let state = link.state();
        assert_eq!(state.connects, 2);
        assert!(state.telemetry.is_some());
        assert!(bench.requests().iter().any(|request| request.body
            == RequestBody::SetLed {
                channel: Channel::One(Side::Right),
                current_ma: 80,
                enabled: true
            }));
    }

    #[test]
    fn a_board_that_goes_silent_is_noticed_and_replaced() {
        let bench = Bench::new();
        let mut options = fast_supervisor();
        options.telemetry_period_ms = 0;
        let link = SupervisedLink::spawn_with(
            {
                let (current, mut connects) = (bench.current.clone(), 0);
                move || {
                    connects += 1;
                    // The first board answers nothing after the set-up: hung firmware.
                    let hang_after_setup = connects == 1;
                    let mut answered = 0;
                    let (board, host) = FakeBoard::start(
                        Box::new(move |request, send| {
                            answered += 1;
                            if !hang_after_setup || answered <= 3 {
                                send(&healthy_answer(request));
                            }
                        }),
                        None,
                    );
                    *current.lock().unwrap() = Some(board);
                    BoardLink::over(Box::new(host), quick())
                }
            },
            "fake".into(),
            options,
        );
        let events = link.subscribe();
        wait_for(&events, |event| matches!(event, BoardEvent::Disconnected { .. }));
        wait_for(&events, |event| matches!(event, BoardEvent::Connected { .. }));
        assert_eq!(link.state().connects, 2);
    }
}

#[test]
fn a_board_of_the_same_version_with_other_message_types_is_refused_naming_both() {
    let (_board, host) = FakeBoard::start(
        Box::new(|request, send| {
            send(&reply(
                request.seq,
                Reply::Hello {
                    protocol_version: PROTOCOL_VERSION,
                    schema: SCHEMA_FINGERPRINT ^ 1,
                },
            ))
        }),
        None,
    );
    let error = BoardLink::over(Box::new(host), quick())
        .err()
        .expect("a schema mismatch fails the open");
    assert!(
        matches!(error, LinkError::SchemaMismatch { version, device, host }
            if version == PROTOCOL_VERSION && device == SCHEMA_FINGERPRINT ^ 1 && host == SCHEMA_FINGERPRINT),
        "{error:?}"
    );
    let text = error.to_string();
    assert!(text.contains(&format!("protocol version {PROTOCOL_VERSION}")), "{text}");
    assert!(text.contains(&format!("{:016x}", SCHEMA_FINGERPRINT ^ 1)), "{text}");
    assert!(text.contains(&format!("{SCHEMA_FINGERPRINT:016x}")), "{text}");
}

/// One of each thing that can go wrong on the line, each in its own counter.
#[test]
fn every_kind_of_wire_error_is_counted_in_its_own_counter() {
    let (_board, host) = FakeBoard::start(
        Box::new(|request, send| match request.body {
            RequestBody::GetInfo => {
                // COBS whose code byte points past the end of the frame.
                send(&[0x05, 0x01, 0x00]);
                let mut damaged = healthy_answer(request);
                damaged[2] ^= 0x40;
                send(&damaged);
                let mut not_a_message = [0u8; MAX_FRAME_LEN];
                send(framing::encode(&[0xFFu8; 32], &mut not_a_message).unwrap());
                send(&[0x55; 3 * MAX_FRAME_LEN]);
                send(&[0x00]);
                // A reply to nobody, then the real one.
                send(&reply(request.seq.wrapping_sub(100), Reply::Ack));
                send(&healthy_answer(request));
            }
            // The right request, the wrong answer.
            RequestBody::GetStatus => send(&reply(request.seq, Reply::Pong { nonce: 1 })),
            // Silence: a timeout (no retries in this test).
            RequestBody::Ping { .. } => {}
            _ => send(&healthy_answer(request)),
        }),
        None,
    );
    let options = LinkOptions { retries: 0, ..quick() };
    let mut link = BoardLink::over(Box::new(host), options).unwrap();
    assert_eq!(link.info().unwrap(), info());
    assert!(matches!(link.status(), Err(LinkError::UnexpectedReply { .. })));
    assert!(matches!(link.ping(5), Err(LinkError::Timeout)));
    let stats = link.stats();
    let wire = stats.wire;
    assert_eq!(
        (wire.bad_cobs, wire.bad_crc, wire.unknown_tag, wire.oversize),
        (1, 1, 1, 1),
        "{stats:?}"
    );
    assert_eq!(
        (
            stats.stale_replies,
            stats.unexpected_replies,
            stats.timeouts,
            stats.retries
        ),
        (1, 1, 1, 0),
        "{stats:?}"
    );
    // Hello, the stale reply, Info, the wrong-kind reply.
    assert_eq!(wire.frames_ok, 4, "{stats:?}");
}

/// A save may take as long as a flash erase: longer than an ordinary request may. Its retry carries the same
/// request id, so the board can tell it from a new save.
#[test]
fn a_save_waits_for_the_erase_and_its_retry_repeats_the_request_id() {
    let slow = quick().timeout * 3;
    let (board, host) = FakeBoard::start(
        Box::new(move |request, send| {
            if matches!(request.body, RequestBody::SaveConfig { .. }) {
                std::thread::sleep(slow);
            }
            send(&healthy_answer(request));
        }),
        None,
    );
    let mut link = BoardLink::over(Box::new(host), quick()).unwrap();
    link.save_config()
        .expect("a save slower than the ordinary timeout still succeeds");
    assert_eq!(link.stats().retries, 0);

    // A board that misses the first attempt: the retry comes with the same id, after the long timeout.
    let attempts = Arc::new(Mutex::new(0));
    let counted = attempts.clone();
    let (board2, host) = FakeBoard::start(
        Box::new(move |request, send| {
            if matches!(request.body, RequestBody::SaveConfig { .. }) {
                let mut n = counted.lock().unwrap();
                *n += 1;
                if *n == 1 {
                    return;
                }
            }
            send(&healthy_answer(request));
        }),
        None,
    );
    let mut link = BoardLink::over(Box::new(host), quick()).unwrap();
    let started = Instant::now();
    link.save_config().unwrap();
    assert!(started.elapsed() >= Duration::from_millis(u64::from(SAVE_CONFIG_REPLY_WITHIN_MS)));
    let ids: Vec<u32> = board2
        .requests()
        .iter()
        .filter_map(|r| match r.body {
            RequestBody::SaveConfig { request_id } => Some(request_id),
            _ => None,
        })
        .collect();
    assert_eq!(ids.len(), 2);
    assert_eq!(ids[0], ids[1]);
    // A new save is a new id.
    let first_id = board
        .requests()
        .iter()
        .find_map(|r| match r.body {
            RequestBody::SaveConfig { request_id } => Some(request_id),
            _ => None,
        })
        .unwrap();
    assert_ne!(first_id, ids[0]);
}

/// On a link without DTR the board takes a long silence as a closed port: a host that only reads telemetry
/// still sends a lone 0x00 every second.
#[test]
fn a_host_that_only_reads_keeps_the_link_alive() {
    let (board, host) = FakeBoard::start(
        Box::new(|request, send| send(&healthy_answer(request))),
        Some(Duration::from_millis(20)),
    );
    let mut link = BoardLink::over(Box::new(host), quick()).unwrap();
    let sent_after_open = board.raw.lock().unwrap().len();
    let started = Instant::now();
    while started.elapsed() < Duration::from_millis(2_300) {
        link.next_telemetry(Duration::from_millis(50)).unwrap();
    }
    let raw = board.raw.lock().unwrap();
    let keepalives = &raw[sent_after_open..];
    assert!(
        (2..=3).contains(&keepalives.len()) && keepalives.iter().all(|&b| b == 0),
        "{keepalives:?}"
    );
}
