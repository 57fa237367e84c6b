//! Throughput of telemetry frames: encode (postcard + CRC + COBS), decode (stream decoder), and both.
//! The host must keep up with a board streaming at 1 kHz with lots of headroom; the target is
//! >= 2 million encode+decode round trips per second on one core.
//!
//!     cargo bench -p nusense-protocol --bench telemetry
//!
//! On Linux the times are this thread's CPU time (CLOCK_THREAD_CPUTIME_ID), not wall time: the
//! machine is shared, and "per second on one core" means per second the core actually spent on it.

use criterion::measurement::{Measurement, ValueFormatter, WallTime};
use criterion::{black_box, criterion_group, criterion_main, Criterion, Throughput};
use nusense_protocol::framing::{encode, FrameDecoder, MAX_FRAME_LEN};
use nusense_protocol::*;

const FRAMES: usize = 1000;

/// Realistic values: a few mA of noise, mid duties, non-trivial counters (varints of several bytes).
fn telemetry(i: usize) -> BoardMessage {
    let mut channels = [ChannelState::default(); CHANNEL_COUNT];
    for (c, channel) in channels.iter_mut().enumerate() {
        channel.setpoint_ma = 100 + 10 * c as u16;
        channel.measured_ma = 99.7 + 10.0 * c as f32 + (i % 7) as f32 * 0.01;
        channel.duty = 0.42 + 0.01 * c as f32;
        channel.enabled = true;
    }
    BoardMessage::Telemetry(Telemetry {
        uptime_us: 1_000_000 + 1000 * i as u64,
        channels,
        temperature_c: 31.5,
        supply_mv: 5003,
        counters: LinkCounters {
            frames_ok: 10_000 + i as u32,
            ..LinkCounters::default()
        },
        loop_timing: LoopTiming {
            steps: 20,
            period_mean_us: 500.1,
            period_min_us: 497,
            period_max_us: 504,
        },
    })
}

/// Nanoseconds this thread has run on a CPU (Linux); wall time elsewhere.
struct ThreadCpuTime;

#[cfg(all(target_os = "linux", target_pointer_width = "64"))]
fn now_ns() -> u64 {
    #[repr(C)]
    struct Timespec {
        tv_sec: i64,
        tv_nsec: i64,
    }
    extern "C" {
        fn clock_gettime(clock: i32, tp: *mut Timespec) -> i32;
    }
    const CLOCK_THREAD_CPUTIME_ID: i32 = 3;
    let mut t = Timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: `t` is a valid, writable timespec (64-bit Linux layout) and the clock id is a constant.
    let rc = unsafe { clock_gettime(CLOCK_THREAD_CPUTIME_ID, &mut t) };
    assert_eq!(rc, 0, "clock_gettime(CLOCK_THREAD_CPUTIME_ID) failed");
    t.tv_sec as u64 * 1_000_000_000 + t.tv_nsec as u64
}

#[cfg(not(all(target_os = "linux", target_pointer_width = "64")))]
fn now_ns() -> u64 {
    std::time::UNIX_EPOCH.elapsed().unwrap_or_default().as_nanos() as u64
}

impl Measurement for ThreadCpuTime {
    type Intermediate = u64;
    type Value = u64;
    fn start(&self) -> u64 {
        now_ns()
    }
    fn end(&self, start: u64) -> u64 {
        now_ns().saturating_sub(start)
    }
    fn add(&self, a: &u64, b: &u64) -> u64 {
        a + b
    }
    fn zero(&self) -> u64 {
        0
    }
    fn to_f64(&self, value: &u64) -> f64 {
        *value as f64
    }
    fn formatter(&self) -> &dyn ValueFormatter {
        // Values are nanoseconds, exactly what wall time's formatter expects.
        WallTime.formatter()
    }
}

fn benches(c: &mut Criterion<ThreadCpuTime>) {
    let messages: Vec<BoardMessage> = (0..FRAMES).map(telemetry).collect();
    let stream: Vec<u8> = messages
        .iter()
        .flat_map(|m| {
            let mut buf = [0u8; MAX_FRAME_LEN];
            encode(m, &mut buf).unwrap().to_vec()
        })
        .collect();
    println!("telemetry frame: {} bytes", stream.len() / FRAMES);

    let mut group = c.benchmark_group("telemetry");
    group.throughput(Throughput::Elements(FRAMES as u64));
    group.bench_function("encode", |b| {
        let mut buf = [0u8; MAX_FRAME_LEN];
        b.iter(|| {
            for m in &messages {
                black_box(encode(black_box(m), &mut buf).unwrap().len());
            }
        })
    });
    group.bench_function("decode", |b| {
        b.iter(|| {
            let mut decoder: FrameDecoder = FrameDecoder::new();
            let mut ok = 0usize;
            decoder.feed::<BoardMessage>(black_box(&stream), |m| ok += m.is_ok() as usize);
            assert_eq!(ok, FRAMES);
        })
    });
    group.bench_function("encode+decode", |b| {
        let mut buf = [0u8; MAX_FRAME_LEN];
        let mut decoder: FrameDecoder = FrameDecoder::new();
        b.iter(|| {
            let mut ok = 0usize;
            for m in &messages {
                let frame = encode(black_box(m), &mut buf).unwrap();
                decoder.feed::<BoardMessage>(frame, |m| ok += m.is_ok() as usize);
            }
            assert_eq!(ok, FRAMES);
        })
    });
    group.finish();
}

criterion_group! {
    name = telemetry_benches;
    config = Criterion::default().with_measurement(ThreadCpuTime);
    targets = benches
}
criterion_main!(telemetry_benches);
