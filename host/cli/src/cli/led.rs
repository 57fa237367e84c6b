//! `nusense led`: set the LED current of one side or all sides.

use std::process::ExitCode;
use std::time::{Duration, Instant};

use anyhow::bail;
use nusense_protocol::{Channel, ChannelState, Side, Status};
use serde::Serialize;

use super::devices::BoardArgs;
use super::info::describe_faults;

#[derive(Clone, Copy, Debug, clap::ValueEnum)]
pub enum SideArg {
    Top,
    Right,
    Bottom,
    Left,
    All,
}

impl SideArg {
    fn channel(self) -> Channel {
        match self {
            SideArg::Top => Channel::One(Side::Top),
            SideArg::Right => Channel::One(Side::Right),
            SideArg::Bottom => Channel::One(Side::Bottom),
            SideArg::Left => Channel::One(Side::Left),
            SideArg::All => Channel::All,
        }
    }

    fn sides(self) -> Vec<Side> {
        match self.channel() {
            Channel::One(side) => vec![side],
            Channel::All => Side::ALL.to_vec(),
        }
    }
}

#[derive(clap::Args)]
pub struct Args {
    #[command(flatten)]
    pub board: BoardArgs,
    /// Which string(s) of LEDs.
    #[arg(long, value_enum)]
    pub side: SideArg,
    /// Current in mA (the board clamps it to its hard limit, 120 mA).
    #[arg(long, value_name = "N", required_unless_present = "off")]
    pub ma: Option<u16>,
    /// Switch the string(s) off (keeps the setpoint).
    #[arg(long)]
    pub off: bool,
    /// Report right away instead of waiting for the soft-start ramp to finish.
    #[arg(long)]
    pub no_wait: bool,
    /// Print JSON instead of text.
    #[arg(long)]
    pub json: bool,
}

#[derive(Serialize)]
struct Report {
    port: String,
    requested_ma: Option<u16>,
    enabled: bool,
    /// The board lowered the request to its hard limit.
    clamped: bool,
    /// Per side set by this command.
    channels: Vec<SideReport>,
}

#[derive(Serialize)]
struct SideReport {
    side: String,
    #[serde(flatten)]
    state: ChannelState,
}

pub fn run(args: Args) -> anyhow::Result<ExitCode> {
    let enabled = !args.off;
    let mut board = args.board.open()?;
    let current_ma = match (args.ma, enabled) {
        (Some(ma), _) => ma,
        // --off alone keeps the board's setpoint: ask for it.
        (None, false) => {
            let status = board.link.status()?;
            args.side
                .sides()
                .first()
                .map(|side| status.channels[side.index()].setpoint_ma)
                .unwrap_or(0)
        }
        (None, true) => bail!("--ma N is required unless --off is given"),
    };
    board.link.set_led(args.side.channel(), current_ma, enabled)?;
    let status = if args.no_wait {
        board.link.status()?
    } else {
        settle(&mut board.link, args.side, enabled)?
    };
    let channels: Vec<SideReport> = args
        .side
        .sides()
        .into_iter()
        .map(|side| SideReport {
            side: side.to_string(),
            state: status.channels[side.index()],
        })
        .collect();
    let clamped = args
        .ma
        .is_some_and(|asked| channels.iter().any(|c| c.state.setpoint_ma < asked));
    let report = Report {
        port: board.port.clone(),
        requested_ma: args.ma,
        enabled,
        clamped,
        channels,
    };
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        if report.clamped {
            println!("note: the board clamped {} mA to its hard limit", current_ma);
        }
        for side in &report.channels {
            let state = side.state;
            let setting = if state.enabled {
                format!("{} mA", state.setpoint_ma)
            } else {
                "off".to_owned()
            };
            println!(
                "{:<7} {:>7}  measured {:>6.1} mA  duty {:>3.0}%  faults: {}",
                side.side,
                setting,
                state.measured_ma,
                state.duty * 100.0,
                describe_faults(state.faults)
            );
        }
    }
    Ok(ExitCode::SUCCESS)
}

/// Polls the status until the addressed channels are within 2 % of their setpoint (or dark when switched off),
/// at most the ramp time plus a second.
fn settle(link: &mut nusense_board::BoardLink, side: SideArg, enabled: bool) -> anyhow::Result<Status> {
    let mut status = link.status()?;
    let deadline = Instant::now() + Duration::from_millis(u64::from(status.ramp_ms)) + Duration::from_secs(1);
    let settled = |status: &Status| {
        side.sides().iter().all(|s| {
            let channel = status.channels[s.index()];
            let target = if enabled { f32::from(channel.setpoint_ma) } else { 0.0 };
            channel.faults.any() || (channel.measured_ma - target).abs() <= (target * 0.02).max(1.0)
        })
    };
    while !settled(&status) && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(20));
        status = link.status()?;
    }
    Ok(status)
}
