//! `nusense report KIND RECORDING.mcap`: the paper's experiments from recordings (Markdown, SVG plots, JSON),
//! and `nusense sim session KIND`: the simulated sessions that exercise them.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{bail, Context};
use clap::ValueEnum;
use indicatif::{ProgressBar, ProgressStyle};
use nusense_experiments::calibration::{self, CalibrationOptions};
use nusense_experiments::hysteresis::{self, Clock};
use nusense_experiments::session::{write_session, SessionKind, SessionOptions};
use nusense_experiments::{damage, load_readings, localisation, repeatability};

/// The paper's experiments: each has a report and a simulated session.
#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum Kind {
    /// Readings against a force/torque log (--ft): clock offset, force line with intervals, residuals.
    Calibration,
    /// Loading/unloading cycles in the force log (--ft): the loop and the hysteresis error, % of full scale.
    Hysteresis,
    /// Repeated touches: peak force reading and location per touch, spread and drift.
    Repeatability,
    /// Touches at the targets of --targets, in order: error per target, bias, RMSE, map.
    Localisation,
    /// RECORDING on a damaged pad against --intact: coverage, lattice points lost, change per touch.
    Damage,
}

#[derive(clap::Args, Debug)]
pub struct Args {
    #[arg(value_enum)]
    pub kind: Kind,
    /// The recording (MCAP with readings, from `nusense record` or `nusense sim session`).
    pub recording: PathBuf,
    /// Force/torque log (CSV: a time column and fx, fy, fz); calibration and hysteresis.
    #[arg(long, value_name = "FT.csv")]
    pub ft: Option<PathBuf>,
    /// Targets (CSV with x_mm, y_mm), in the order they were touched; localisation.
    #[arg(long, value_name = "T.csv")]
    pub targets: Option<PathBuf>,
    /// The same session on the intact pad; damage.
    #[arg(long, value_name = "INTACT.mcap")]
    pub intact: Option<PathBuf>,
    /// Hysteresis: the F/T clock minus the camera clock, s, known from outside this recording (hardware sync, or
    /// the calibration report on the same rig). Without it the offset is cross-correlated, which takes the pad's
    /// lag for clock offset and shows a smaller loop than the pad has.
    #[arg(long, value_name = "SECONDS", allow_hyphen_values = true)]
    pub clock_offset: Option<f64>,
    /// Output folder for report.md, report.json and the plots.
    #[arg(long, default_value = "report")]
    pub out: PathBuf,
    /// Largest clock offset searched between camera and F/T log, s.
    #[arg(long, default_value_t = 2.0)]
    pub max_lag: f64,
    /// Calibration: pairs below this reference force are not fitted, N.
    #[arg(long, default_value_t = 1.0)]
    pub min_force: f64,
    /// Print the report's JSON instead of a summary.
    #[arg(long)]
    pub json: bool,
}

pub fn run(args: Args) -> anyhow::Result<ExitCode> {
    let source = args.recording.display().to_string();
    let (readings, without) =
        load_readings(&args.recording).with_context(|| format!("reading {}", args.recording.display()))?;
    if without > 0 && !args.json {
        eprintln!("nusense report: {without} frames of {source} have no estimate (skipped)");
    }
    let needs = |option: &Option<PathBuf>, flag: &str| -> anyhow::Result<PathBuf> {
        match option {
            Some(path) => Ok(path.clone()),
            None => bail!("the {:?} report needs {flag}", args.kind),
        }
    };
    let report = match args.kind {
        Kind::Calibration => {
            let forces = calibration::load_force_log(&needs(&args.ft, "--ft FT.csv")?)?;
            let options = CalibrationOptions {
                max_lag_s: args.max_lag,
                min_force_n: args.min_force,
                ..Default::default()
            };
            calibration::report(&readings, &forces, &options, &source)?
        }
        Kind::Hysteresis => {
            let forces = calibration::load_force_log(&needs(&args.ft, "--ft FT.csv")?)?;
            let clock = match args.clock_offset {
                Some(offset_s) => Clock::Given(offset_s),
                None => Clock::CrossCorrelation {
                    max_lag_s: args.max_lag,
                },
            };
            hysteresis::report(&readings, &forces, clock, &source)?
        }
        Kind::Repeatability => repeatability::report(&readings, &source)?,
        Kind::Localisation => {
            let targets = localisation::load_targets(&needs(&args.targets, "--targets T.csv")?)?;
            localisation::report(&readings, &targets, &source)?
        }
        Kind::Damage => {
            let intact_path = needs(&args.intact, "--intact INTACT.mcap")?;
            let (intact, _) =
                load_readings(&intact_path).with_context(|| format!("reading {}", intact_path.display()))?;
            damage::report(&intact, &readings, &intact_path.display().to_string(), &source)?
        }
    };
    let files = report.write(&args.out)?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report.json)?);
    } else {
        println!("{} report of {source} ({} readings):", report.kind, readings.len());
        for file in files {
            println!("  {}", file.display());
        }
    }
    Ok(ExitCode::SUCCESS)
}

#[derive(clap::Args, Debug)]
pub struct SessionArgs {
    #[arg(value_enum)]
    pub kind: Kind,
    /// Output folder: the recording(s), ft.csv, truth.json (and targets.csv for localisation).
    #[arg(long)]
    pub out: PathBuf,
    /// The documentation's session (320 x 240, 15 fps, 10 repetitions) instead of the short one of the tests.
    #[arg(long)]
    pub example: bool,
    #[arg(long)]
    pub seed: Option<u64>,
    /// Print the ground truth as JSON.
    #[arg(long)]
    pub json: bool,
}

pub fn simulate(args: SessionArgs) -> anyhow::Result<ExitCode> {
    let mut options = if args.example {
        SessionOptions::example()
    } else {
        SessionOptions::short()
    };
    if let Some(seed) = args.seed {
        options.seed = seed;
    }
    let kind = match args.kind {
        Kind::Calibration => SessionKind::Calibration,
        Kind::Hysteresis => SessionKind::Hysteresis,
        Kind::Repeatability => SessionKind::Repeatability,
        Kind::Localisation => SessionKind::Localisation,
        Kind::Damage => SessionKind::Damage,
    };
    let progress = if args.json {
        ProgressBar::hidden()
    } else {
        ProgressBar::new(0)
    };
    progress.set_style(ProgressStyle::with_template(
        "{msg} {bar:40} {pos}/{len} frames ({eta})",
    )?);
    progress.set_message(format!("{:?} session", args.kind));
    let files = write_session(kind, &options, &args.out, &mut |done, total| {
        progress.set_length(total as u64);
        progress.set_position(done as u64);
    })
    .with_context(|| format!("writing the session into {}", args.out.display()))?;
    progress.finish_and_clear();
    if args.json {
        println!("{}", serde_json::to_string_pretty(&files.truth_data)?);
    } else {
        for path in [
            Some(&files.recording),
            files.intact.as_ref(),
            Some(&files.ft_log),
            files.targets.as_ref(),
            Some(&files.truth),
        ]
        .into_iter()
        .flatten()
        {
            println!("{}", path.display());
        }
    }
    Ok(ExitCode::SUCCESS)
}
