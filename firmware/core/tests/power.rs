//! What the board may draw from USB, and when it talks: the total current budget, LEDs off until the port is
//! configured and while it is suspended, telemetry only while a host has the port open, and the control loop's
//! timing in telemetry.

mod common;

use common::{Bench, STEP_US};
use nusense_firmware_core::limits::{MAX_CURRENT_MA, MAX_TOTAL_CURRENT_MA};
use nusense_firmware_core::{BoardConfig, Controller, PowerState};
use nusense_protocol::{Channel, Reply, RequestBody, Side, PROTOCOL_VERSION};

fn all_on(bench: &mut Bench, ma: u16) {
    let r = bench.request(RequestBody::SetLed {
        channel: Channel::All,
        current_ma: ma,
        enabled: true,
    });
    assert_eq!(r.result, Ok(Reply::Ack));
}

fn total(currents: [f32; 4]) -> f32 {
    currents.iter().sum()
}

#[test]
fn the_default_budget_keeps_the_board_within_what_usb_grants() {
    let mut bench = Bench::connected();
    all_on(&mut bench, 500);
    bench.run_ms(300);
    let currents = bench.true_current_ma();
    let share = f32::from(MAX_TOTAL_CURRENT_MA) / 4.0;
    for current in currents {
        assert!((current - share).abs() < 0.02 * share, "{currents:?}, share {share} mA");
    }
    assert!(
        total(currents) <= f32::from(MAX_TOTAL_CURRENT_MA) * 1.01,
        "{currents:?}"
    );
    // The setpoints stay what the host asked for (clamped per channel); only the regulation target is scaled.
    match bench.request(RequestBody::GetStatus).result {
        Ok(Reply::Status(status)) => {
            assert!(status.channels.iter().all(|c| c.setpoint_ma == MAX_CURRENT_MA));
            assert_eq!(status.current_budget_ma, MAX_TOTAL_CURRENT_MA);
            assert_eq!(status.power, PowerState::Configured);
        }
        other => panic!("{other:?}"),
    }
}

#[test]
fn a_lower_budget_scales_every_lit_string_in_proportion() {
    let mut bench = Bench::connected();
    bench.request(RequestBody::SetLed {
        channel: Channel::One(Side::Top),
        current_ma: 120,
        enabled: true,
    });
    bench.request(RequestBody::SetLed {
        channel: Channel::One(Side::Bottom),
        current_ma: 60,
        enabled: true,
    });
    assert_eq!(
        bench.request(RequestBody::SetCurrentBudget { total_ma: 90 }).result,
        Ok(Reply::Ack)
    );
    bench.run_ms(300);
    let i = bench.true_current_ma();
    assert!((i[0] - 60.0).abs() < 1.5 && (i[2] - 30.0).abs() < 1.0, "{i:?}");
    assert_eq!(i[1], 0.0);
    // Within budget nothing is scaled; a budget above the maximum is clamped to it.
    bench.request(RequestBody::SetCurrentBudget { total_ma: u16::MAX });
    assert_eq!(bench.controller.config().current_budget_ma, MAX_TOTAL_CURRENT_MA);
    bench.run_ms(300);
    let i = bench.true_current_ma();
    assert!((i[0] - 120.0).abs() < 2.4 && (i[2] - 60.0).abs() < 1.2, "{i:?}");
    // The budget is part of what SaveConfig stores.
    bench.request(RequestBody::SetCurrentBudget { total_ma: 200 });
    assert_eq!(bench.controller.config().current_budget_ma, 200);
}

#[test]
fn leds_stay_off_until_usb_is_configured_and_while_it_is_suspended() {
    let config = BoardConfig {
        enabled: [true; 4],
        ..BoardConfig::default()
    };
    // A board that boots with its LEDs saved on: nothing lights before the host configures the device.
    let mut controller = Controller::new(common::identity(), config);
    assert_eq!(controller.power_state(), PowerState::Unconfigured);
    let m = Default::default();
    for step in 1..=200u64 {
        assert_eq!(controller.control_step(step * STEP_US, &m), [0.0; 4]);
    }
    let mut bench = Bench::around(controller);
    bench.run_ms(200);
    let lit = bench.true_current_ma();
    assert!(lit.iter().all(|&i| (i - 100.0).abs() < 2.0), "{lit:?}");

    bench.controller.set_power_state(PowerState::Suspended);
    bench.run_ms(2);
    assert_eq!(bench.controller.duty(), [0.0; 4]);
    assert!(bench.true_current_ma().iter().all(|&i| i == 0.0));
    bench.run_ms(50);
    assert!(bench.true_current_ma().iter().all(|&i| i == 0.0));

    // Resumed: back on with the soft start, never a jump to the old duty.
    bench.controller.set_power_state(PowerState::Configured);
    bench.run_ms(10);
    let ramping = bench.true_current_ma();
    assert!(ramping.iter().all(|&i| i > 0.0 && i < 40.0), "{ramping:?}");
    bench.run_ms(200);
    assert!(bench.true_current_ma().iter().all(|&i| (i - 100.0).abs() < 2.0));
}

#[test]
fn telemetry_flows_only_while_a_host_has_the_port_open() {
    let mut bench = Bench::connected();
    assert_eq!(
        bench.request(RequestBody::StreamTelemetry { period_ms: 10 }).result,
        Ok(Reply::Ack)
    );
    // The first frame goes out at the next step, then one every 10 ms.
    bench.run_ms(100);
    assert_eq!(bench.telemetry.len(), 11);

    // DTR drops: the stream stops at once and does not resume by itself.
    bench.controller.set_host_present(false);
    bench.telemetry.clear();
    bench.run_ms(100);
    assert!(bench.telemetry.is_empty());
    bench.controller.set_host_present(true);
    bench.run_ms(100);
    assert!(bench.telemetry.is_empty(), "a new session asks for its own stream");
    // ... and must shake hands first.
    assert_eq!(
        bench.request(RequestBody::StreamTelemetry { period_ms: 10 }).result,
        Err(nusense_protocol::DeviceError::NotHandshaken)
    );
    bench.handshake();
    assert_eq!(
        bench.request(RequestBody::StreamTelemetry { period_ms: 10 }).result,
        Ok(Reply::Ack)
    );
    bench.run_ms(50);
    assert_eq!(bench.telemetry.len(), 6);
    let hello = bench.request(RequestBody::Hello {
        protocol_version: PROTOCOL_VERSION,
    });
    assert!(hello.result.is_ok());
}

#[test]
fn telemetry_reports_the_loop_period_since_the_previous_frame() {
    let mut bench = Bench::connected();
    bench.request(RequestBody::StreamTelemetry { period_ms: 10 });
    bench.run_ms(30);
    let frame = bench.telemetry.last().unwrap().loop_timing;
    assert_eq!(frame.steps, 10);
    assert_eq!((frame.period_min_us, frame.period_max_us), (1_000, 1_000));
    assert_eq!(frame.period_mean_us, 1_000.0);

    // One late step (a stalled loop) shows as the maximum and in the mean of its window only.
    bench.telemetry.clear();
    bench.now_us += 700;
    bench.run_ms(10);
    let late = bench.telemetry[0].loop_timing;
    assert_eq!((late.period_min_us, late.period_max_us), (1_000, 1_700));
    assert!((late.period_mean_us - 1_070.0).abs() < 0.01, "{late:?}");
    bench.telemetry.clear();
    bench.run_ms(10);
    assert_eq!(bench.telemetry[0].loop_timing.period_max_us, 1_000);
}

#[test]
fn outputs_held_off_for_a_flash_erase_come_back_with_a_soft_start() {
    let mut bench = Bench::connected();
    all_on(&mut bench, 100);
    bench.run_ms(200);
    bench.controller.hold_outputs_off(true);
    bench.run_ms(1);
    assert_eq!(bench.controller.duty(), [0.0; 4]);
    bench.run_ms(20);
    assert!(bench.true_current_ma().iter().all(|&i| i == 0.0));
    bench.controller.hold_outputs_off(false);
    bench.run_ms(10);
    let ramping = bench.true_current_ma();
    assert!(ramping.iter().all(|&i| i > 0.0 && i < 40.0), "{ramping:?}");
}
