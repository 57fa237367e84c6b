//! The regulator against the simulated LED plant: convergence from cold, no excursion above the hard limit,
//! setpoint clamping, tracking as the board warms.

mod common;

use common::{Bench, STEP_US};
use nusense_firmware_core::limits::{DEFAULT_RAMP_MS, MAX_CURRENT_MA};
use nusense_protocol::{Channel, Reply, RequestBody, Side};

/// Stated settling time: from a cold, dark board to within +/- 2 % of 100 mA in the default 50 ms soft start plus
/// 50 ms. (The loop's own time constant is ~3 ms; the ramp dominates.)
const SETTLE_BUDGET_MS: u64 = DEFAULT_RAMP_MS as u64 + 50;

fn enable_all(bench: &mut Bench, ma: u16) {
    let r = bench.request(RequestBody::SetLed {
        channel: Channel::All,
        current_ma: ma,
        enabled: true,
    });
    assert_eq!(r.result, Ok(Reply::Ack));
}

fn enable_off(bench: &mut Bench, sides: [Side; 2]) {
    for side in sides {
        let r = bench.request(RequestBody::SetLed {
            channel: Channel::One(side),
            current_ma: 0,
            enabled: false,
        });
        assert_eq!(r.result, Ok(Reply::Ack));
    }
}

/// Two opposite strings at `ma`: at the per-string hard limit the four together would exceed the USB budget,
/// which scales them all down (tests/power.rs), so the per-string limit is tested on two.
fn enable_two(bench: &mut Bench, ma: u16) {
    for side in [Side::Top, Side::Bottom] {
        let r = bench.request(RequestBody::SetLed {
            channel: Channel::One(side),
            current_ma: ma,
            enabled: true,
        });
        assert_eq!(r.result, Ok(Reply::Ack));
    }
}

/// Time (ms) until every enabled channel's true current enters and stays within +/- `band` of `target` for the
/// rest of a `window_ms` run, and the largest current seen on any channel on the way.
fn settle(bench: &mut Bench, target: f32, band: f32, window_ms: u64) -> (Option<u64>, f32) {
    let mut settled_at = None;
    let mut peak = 0.0f32;
    let enabled = bench.controller.config().enabled;
    for step in 1..=window_ms * 1_000 / STEP_US {
        bench.step();
        let currents = bench.true_current_ma();
        peak = currents.iter().copied().fold(peak, f32::max);
        let inside = currents
            .iter()
            .zip(enabled)
            .filter(|(_, on)| *on)
            .all(|(&c, _)| (c - target).abs() <= band * target);
        match (inside, settled_at) {
            (true, None) => settled_at = Some(step * STEP_US / 1_000),
            (false, Some(_)) => settled_at = None,
            _ => {}
        }
    }
    (settled_at, peak)
}

#[test]
fn converges_from_cold_to_100_ma_within_2_percent_without_overshoot() {
    let mut bench = Bench::connected();
    enable_all(&mut bench, 100);
    let (settled_ms, peak) = settle(&mut bench, 100.0, 0.02, 1_000);
    let settled_ms = settled_ms.expect("regulator settles within 2 %");
    println!("settled to 100 mA +/- 2 % after {settled_ms} ms (budget {SETTLE_BUDGET_MS} ms), peak {peak:.2} mA");
    assert!(settled_ms <= SETTLE_BUDGET_MS, "settled after {settled_ms} ms");
    assert!(peak <= 102.0, "overshoot to {peak} mA");
    // The firmware's own view agrees with the plant.
    let status = match bench.request(RequestBody::GetStatus).result {
        Ok(Reply::Status(s)) => s,
        other => panic!("status: {other:?}"),
    };
    for ch in status.channels {
        assert!((ch.measured_ma - 100.0).abs() < 3.0, "reported {ch:?}");
        assert!(ch.duty > 0.2 && ch.duty < 0.9);
    }
}

#[test]
fn never_exceeds_the_limit_during_the_ramp_even_without_soft_start() {
    for ramp_ms in [0u16, 10, DEFAULT_RAMP_MS, 500] {
        let mut bench = Bench::connected();
        assert_eq!(
            bench.request(RequestBody::SetRamp { ms: ramp_ms }).result,
            Ok(Reply::Ack)
        );
        enable_two(&mut bench, MAX_CURRENT_MA);
        let (settled, peak) = settle(&mut bench, f32::from(MAX_CURRENT_MA), 0.02, u64::from(ramp_ms) + 200);
        println!("ramp {ramp_ms} ms to 120 mA: settled at {settled:?} ms, peak {peak:.2} mA");
        assert!(
            peak <= f32::from(MAX_CURRENT_MA) * 1.01,
            "ramp {ramp_ms} ms: peak {peak} mA"
        );
        assert!(settled.is_some(), "ramp {ramp_ms} ms: did not settle");
    }
}

#[test]
fn soft_start_takes_the_ramp_time() {
    let mut bench = Bench::connected();
    assert_eq!(bench.request(RequestBody::SetRamp { ms: 200 }).result, Ok(Reply::Ack));
    enable_all(&mut bench, 100);
    bench.run_ms(100);
    let half_way = bench.true_current_ma()[0];
    assert!(
        (40.0..60.0).contains(&half_way),
        "half way through the ramp: {half_way} mA"
    );
    bench.run_ms(150);
    assert!((bench.true_current_ma()[0] - 100.0).abs() < 2.0);
}

#[test]
fn setpoints_above_the_limit_are_clamped() {
    for asked in [121u16, 500, u16::MAX] {
        let mut bench = Bench::connected();
        enable_all(&mut bench, asked);
        assert_eq!(bench.controller.config().setpoints_ma, [MAX_CURRENT_MA; 4]);
        enable_two(&mut bench, asked);
        enable_off(&mut bench, [Side::Right, Side::Left]);
        bench.run_ms(300);
        let currents = bench.true_current_ma();
        for side in [Side::Top, Side::Bottom] {
            let c = currents[side.index()];
            assert!((c - 120.0).abs() <= 2.4, "asked {asked} mA, got {c} mA");
        }
    }
}

#[test]
fn tracks_the_led_as_the_board_warms() {
    let mut bench = Bench::connected();
    enable_all(&mut bench, 100);
    bench.run_ms(200);
    // A warm board lowers the LED forward voltage: the same duty would give more current.
    bench.plant.set_board_temperature_c(55.0);
    let mut worst = 0.0f32;
    for _ in 0..300 {
        bench.step();
        worst = bench
            .true_current_ma()
            .iter()
            .fold(worst, |w, c| w.max((c - 100.0).abs()));
    }
    assert!((bench.true_current_ma()[0] - 100.0).abs() < 2.0);
    println!("worst deviation after a 30 K step in board temperature: {worst:.2} mA");
    assert!(worst < 15.0);
}

#[test]
fn one_channel_is_regulated_independently_of_the_others() {
    let mut bench = Bench::connected();
    let top = nusense_protocol::Side::Top;
    let r = bench.request(RequestBody::SetLed {
        channel: Channel::One(top),
        current_ma: 60,
        enabled: true,
    });
    assert_eq!(r.result, Ok(Reply::Ack));
    bench.run_ms(200);
    let i = bench.true_current_ma();
    assert!((i[0] - 60.0).abs() < 1.2, "top {}", i[0]);
    assert_eq!(&i[1..], &[0.0, 0.0, 0.0]);
}
