//! Each fault case against the simulated plant: detected, the channel switched off in time, latched and reported
//! until ClearFaults, detected again if it is still there.

mod common;

use common::{Bench, STEP_US};
use nusense_firmware_core::limits::{DERATE_START_C, SHUTDOWN_C};
use nusense_firmware_core::plant::StringFault;
use nusense_protocol::{Channel, DeviceError, FaultFlags, Reply, RequestBody, Side, Status};

fn lit_bench() -> Bench {
    let mut bench = Bench::connected();
    let r = bench.request(RequestBody::SetLed {
        channel: Channel::All,
        current_ma: 100,
        enabled: true,
    });
    assert_eq!(r.result, Ok(Reply::Ack));
    bench.run_ms(200);
    bench
}

fn status(bench: &mut Bench) -> Status {
    match bench.request(RequestBody::GetStatus).result {
        Ok(Reply::Status(s)) => s,
        other => panic!("status: {other:?}"),
    }
}

fn flags(bench: &mut Bench) -> [FaultFlags; 4] {
    status(bench).channels.map(|c| c.faults)
}

#[test]
fn shorted_string_is_switched_off_within_1_ms() {
    let mut bench = lit_bench();
    bench.plant.set_fault(Side::Right.index(), StringFault::Shorted);
    let mut off_after_us = None;
    for step in 1..=10u64 {
        let duty = bench.step();
        if duty[1] == 0.0 {
            off_after_us = Some(step * STEP_US);
            break;
        }
    }
    let off_after_us = off_after_us.expect("the shorted channel is switched off");
    println!("over-current: channel off {off_after_us} us after the short");
    assert!(off_after_us <= 1_000);
    bench.step();
    assert_eq!(bench.true_current_ma()[1], 0.0);
    let f = flags(&mut bench);
    assert!(f[1].over_current && !f[1].open_string);
    assert!(
        !f[0].any() && !f[2].any() && !f[3].any(),
        "other channels unaffected: {f:?}"
    );
    // The others keep regulating.
    bench.run_ms(50);
    assert!((bench.true_current_ma()[0] - 100.0).abs() < 2.0);
}

#[test]
fn open_string_is_detected_and_the_channel_stops() {
    let mut bench = lit_bench();
    bench.plant.set_fault(Side::Bottom.index(), StringFault::Open);
    let mut detected_ms = None;
    for ms in 1..=200u64 {
        bench.step();
        if bench.controller.status(bench.now_us).channels[2].faults.open_string {
            detected_ms = Some(ms);
            break;
        }
    }
    let detected_ms = detected_ms.expect("open string detected");
    println!("open string detected after {detected_ms} ms");
    assert_eq!(bench.controller.duty()[2], 0.0);
    let f = flags(&mut bench);
    assert!(f[2].open_string && !f[2].over_current && !f[0].any());
}

#[test]
fn faults_are_latched_until_cleared_and_come_back_if_still_present() {
    let mut bench = lit_bench();
    bench.plant.set_fault(0, StringFault::Open);
    bench.run_ms(100);
    assert!(flags(&mut bench)[0].open_string);

    // The wire is repaired, but the fault stays latched and the channel stays off.
    bench.plant.set_fault(0, StringFault::None);
    bench.run_ms(100);
    assert!(flags(&mut bench)[0].open_string);
    assert_eq!(bench.true_current_ma()[0], 0.0);
    let refused = bench.request(RequestBody::SetLed {
        channel: Channel::One(Side::Top),
        current_ma: 90,
        enabled: true,
    });
    assert_eq!(refused.result, Err(DeviceError::FaultActive { channel: Side::Top }));
    let refused_all = bench.request(RequestBody::SetLed {
        channel: Channel::All,
        current_ma: 90,
        enabled: true,
    });
    assert_eq!(refused_all.result, Err(DeviceError::FaultActive { channel: Side::Top }));
    // Switching a faulted channel off is always allowed.
    let off = bench.request(RequestBody::SetLed {
        channel: Channel::One(Side::Top),
        current_ma: 90,
        enabled: false,
    });
    assert_eq!(off.result, Ok(Reply::Ack));
    let on = bench.request(RequestBody::SetLed {
        channel: Channel::One(Side::Top),
        current_ma: 100,
        enabled: true,
    });
    assert!(on.result.is_err());

    assert_eq!(bench.request(RequestBody::ClearFaults).result, Ok(Reply::Ack));
    let on = bench.request(RequestBody::SetLed {
        channel: Channel::One(Side::Top),
        current_ma: 100,
        enabled: true,
    });
    assert_eq!(on.result, Ok(Reply::Ack));
    bench.run_ms(200);
    assert!(!flags(&mut bench)[0].any());
    assert!((bench.true_current_ma()[0] - 100.0).abs() < 2.0);

    // Still broken after clearing: found again.
    bench.plant.set_fault(0, StringFault::Open);
    bench.run_ms(100);
    assert_eq!(bench.request(RequestBody::ClearFaults).result, Ok(Reply::Ack));
    bench.run_ms(100);
    assert!(flags(&mut bench)[0].open_string);
}

#[test]
fn over_temperature_derates_then_switches_off() {
    let mut bench = lit_bench();
    let derate_c = (DERATE_START_C + SHUTDOWN_C) / 2.0;
    bench.plant.set_ambient_c(derate_c);
    bench.plant.set_board_temperature_c(derate_c);
    bench.run_ms(200);
    let currents = bench.true_current_ma();
    // Half way through the derating band: 75 % of the setpoint.
    for c in currents {
        assert!((c - 75.0).abs() < 3.0, "derated current {c} mA");
    }
    let f = flags(&mut bench);
    assert!(f.iter().all(|f| f.over_temperature));
    assert!(
        bench.controller.duty().iter().all(|&d| d > 0.0),
        "still lit while derating"
    );

    bench.plant.set_ambient_c(SHUTDOWN_C + 5.0);
    bench.plant.set_board_temperature_c(SHUTDOWN_C + 5.0);
    bench.run_ms(20);
    assert_eq!(bench.true_current_ma(), [0.0; 4]);

    // Cooled down: still off until the host clears the fault.
    bench.plant.set_ambient_c(25.0);
    bench.plant.set_board_temperature_c(25.0);
    bench.run_ms(100);
    assert_eq!(bench.true_current_ma(), [0.0; 4]);
    assert!(flags(&mut bench).iter().all(|f| f.over_temperature));
    assert_eq!(bench.request(RequestBody::ClearFaults).result, Ok(Reply::Ack));
    bench.run_ms(200);
    assert!((bench.true_current_ma()[3] - 100.0).abs() < 2.0);
    assert!(!flags(&mut bench)[3].any());
}

#[test]
fn under_voltage_switches_the_lit_channels_off() {
    let mut bench = Bench::connected();
    let r = bench.request(RequestBody::SetLed {
        channel: Channel::One(Side::Left),
        current_ma: 100,
        enabled: true,
    });
    assert_eq!(r.result, Ok(Reply::Ack));
    bench.run_ms(200);
    bench.plant.set_supply_nominal_mv(3_900.0);
    bench.run_ms(20);
    assert_eq!(bench.true_current_ma()[3], 0.0);
    let f = flags(&mut bench);
    assert!(f[3].under_voltage && !f[3].open_string, "{:?}", f[3]);
    assert!(!f[0].any(), "a dark channel is not flagged");
}

#[test]
fn a_short_supply_dip_is_ridden_through() {
    let mut bench = lit_bench();
    bench.plant.set_supply_nominal_mv(4_000.0);
    bench.run_ms(2);
    bench.plant.set_supply_nominal_mv(5_000.0);
    bench.run_ms(50);
    assert!(flags(&mut bench).iter().all(|f| !f.any()));
    assert!((bench.true_current_ma()[0] - 100.0).abs() < 2.0);
}

#[test]
fn a_healthy_board_raises_no_fault_in_a_long_run() {
    let mut bench = lit_bench();
    let r = bench.request(RequestBody::SetLed {
        channel: Channel::All,
        current_ma: 120,
        enabled: true,
    });
    assert_eq!(r.result, Ok(Reply::Ack));
    bench.run_ms(5_000);
    assert!(flags(&mut bench).iter().all(|f| !f.any()), "{:?}", flags(&mut bench));
}
