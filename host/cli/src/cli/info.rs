//! `nusense info`: a board's identity, status and link health.

use std::process::ExitCode;

use nusense_board::LinkStats;
use nusense_protocol::{DeviceInfo, Side, Status};
use serde::Serialize;

use super::devices::BoardArgs;

#[derive(clap::Args)]
pub struct Args {
    #[command(flatten)]
    pub board: BoardArgs,
    /// Print JSON instead of text.
    #[arg(long)]
    pub json: bool,
}

#[derive(Serialize)]
struct Report {
    port: String,
    virtual_board: bool,
    /// USB serial number: hex of the MCU unique id.
    serial_number: String,
    info: DeviceInfo,
    status: Status,
    ping_ms: f64,
    /// The host side of the link: framing errors, stale replies, retries.
    host_link: LinkStats,
}

pub fn run(args: Args) -> anyhow::Result<ExitCode> {
    let mut board = args.board.open()?;
    let info = board.link.info()?;
    let status = board.link.status()?;
    let ping = board.link.ping(0x1AF0)?;
    let report = Report {
        port: board.port.clone(),
        virtual_board: board.virtual_board.is_some(),
        serial_number: info.mcu_uid.iter().map(|byte| format!("{byte:02X}")).collect(),
        info,
        status,
        ping_ms: ping.as_secs_f64() * 1e3,
        host_link: board.link.stats(),
    };
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print_report(&report);
    }
    Ok(ExitCode::SUCCESS)
}

fn print_report(report: &Report) {
    let info = &report.info;
    let status = &report.status;
    let kind = if report.virtual_board { " (virtual board)" } else { "" };
    println!("Board on {}{kind}", report.port);
    println!("  board id          {}", info.board_id);
    println!("  serial number     {}", report.serial_number);
    println!("  firmware          {} ({})", info.firmware_version, info.git_hash);
    println!("  protocol          {}", info.protocol_version);
    println!(
        "  channels          {} x max {} mA",
        info.channel_count, info.max_current_ma
    );
    println!("  uptime            {:.1} s", status.uptime_us as f64 / 1e6);
    println!("  temperature       {:.1} °C", status.temperature_c);
    println!("  supply            {} mV", status.supply_mv);
    println!("  ramp              {} ms", status.ramp_ms);
    println!(
        "  USB power         {:?}, LED budget {} mA in total (at most {} mA)",
        status.power, status.current_budget_ma, info.max_total_current_ma
    );
    let timing = status.loop_timing;
    println!(
        "  control loop      {:.1} us mean, {}-{} us over the last {} steps",
        timing.period_mean_us, timing.period_min_us, timing.period_max_us, timing.steps
    );
    let period = status.telemetry_period_ms;
    println!(
        "  telemetry         {}",
        if period == 0 {
            "off".to_owned()
        } else {
            format!("every {period} ms")
        }
    );
    println!("  ping              {:.2} ms", report.ping_ms);
    println!(
        "  {:<8} {:>9} {:>12} {:>6}  faults",
        "LED", "setpoint", "measured", "duty"
    );
    for side in Side::ALL {
        let channel = &status.channels[side.index()];
        let setpoint = if channel.enabled {
            format!("{} mA", channel.setpoint_ma)
        } else {
            "off".to_owned()
        };
        println!(
            "  {:<8} {:>9} {:>9.1} mA {:>5.0}%  {}",
            side.to_string(),
            setpoint,
            channel.measured_ma,
            channel.duty * 100.0,
            describe_faults(channel.faults)
        );
    }
    let board = status.counters;
    let host = report.host_link;
    println!(
        "  board received    {} frames ok; dropped {} bad COBS, {} bad CRC, {} oversize, {} undecodable",
        board.frames_ok, board.bad_cobs, board.bad_crc, board.oversize, board.unknown_tag
    );
    println!(
        "  host received     {} frames ok; dropped {} bad COBS, {} bad CRC, {} oversize, {} undecodable; {} stale \
         replies, {} unexpected replies, {} timeouts, {} retries",
        host.wire.frames_ok,
        host.wire.bad_cobs,
        host.wire.bad_crc,
        host.wire.oversize,
        host.wire.unknown_tag,
        host.stale_replies,
        host.unexpected_replies,
        host.timeouts,
        host.retries
    );
}

pub(crate) fn describe_faults(faults: nusense_protocol::FaultFlags) -> String {
    let names = [
        (faults.open_string, "open string"),
        (faults.over_current, "over-current"),
        (faults.over_temperature, "over-temperature"),
        (faults.under_voltage, "under-voltage"),
    ];
    let active: Vec<&str> = names.iter().filter(|(on, _)| *on).map(|(_, name)| *name).collect();
    if active.is_empty() {
        "none".to_owned()
    } else {
        active.join(", ")
    }
}
