//! `nusense bench`: every estimator variant's speed against its error on the paper's sweeps, and every estimator
//! mode on the validation set (issue 12's figures), written as markdown tables, JSON and a Pareto plot (SVG); and
//! camera bytes to reading per mode and decode scale (decode.md, decode.json).

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Context;
use nusense_bench::decode::{run_decode_bench, DecodeBenchOptions};
use nusense_bench::{find_real_pair, report, run_bench, BenchOptions};

#[derive(clap::Args)]
pub struct Args {
    /// Folder for bench.md, bench.json and pareto.svg.
    #[arg(long, value_name = "DIR", default_value = "bench-out")]
    out: PathBuf,
    /// CI-sized run: half-size frames, a quarter of each sweep, one timing pass, and the quick validation set
    /// (1024x768) instead of the full one (2048x1536).
    #[arg(long)]
    quick: bool,
    /// Folder with the real pair (reference_fisheye.jpg, touch_fisheye.jpg); by default the copy the repository
    /// ships (host/estimator/tests/data/real), else shared/data/real next to or above it.
    #[arg(long, value_name = "DIR")]
    real: Option<PathBuf>,
    /// Print the results as JSON on stdout as well.
    #[arg(long)]
    json: bool,
    /// Only the bytes-to-reading tables (decode.md, decode.json), not the estimator variants.
    #[arg(long, conflicts_with = "skip_decode")]
    decode_only: bool,
    /// Only the estimator variants, not the bytes-to-reading tables.
    #[arg(long)]
    skip_decode: bool,
}

pub fn run(args: Args) -> anyhow::Result<ExitCode> {
    let mut options = if args.quick {
        BenchOptions::quick()
    } else {
        BenchOptions::full()
    };
    let cwd = std::env::current_dir().context("cannot read the current directory")?;
    options.real_dir = match args.real {
        Some(dir) => Some(dir),
        None => find_real_pair(&cwd),
    };
    if options.real_dir.is_none() {
        eprintln!("nusense bench: the real pair was not found (pass --real DIR); its columns stay empty");
    }
    std::fs::create_dir_all(&args.out).with_context(|| format!("cannot create {}", args.out.display()))?;
    let write = |name: &str, text: &str| {
        let path = args.out.join(name);
        std::fs::write(&path, text).with_context(|| format!("cannot write {}", path.display()))
    };
    let bar = indicatif::ProgressBar::new_spinner();
    bar.enable_steady_tick(std::time::Duration::from_millis(200));
    if !args.skip_decode {
        let mut decode_options = if args.quick {
            DecodeBenchOptions::quick()
        } else {
            DecodeBenchOptions::full()
        };
        decode_options.real_dir = options.real_dir.clone();
        let decode = run_decode_bench(&decode_options, &mut |step: &str| bar.set_message(step.to_owned()))
            .context("the bytes-to-reading benchmark could not run")?;
        let markdown = nusense_bench::decode::markdown(&decode, &report::Machine::this());
        write("decode.md", &markdown)?;
        write("decode.json", &serde_json::to_string_pretty(&decode)?)?;
        if args.json {
            println!("{}", serde_json::to_string(&decode)?);
        } else {
            bar.suspend(|| println!("{markdown}"));
        }
        if args.decode_only {
            bar.finish_and_clear();
            println!("written: {}", args.out.join("{decode.md,decode.json}").display());
            return Ok(ExitCode::SUCCESS);
        }
    }
    let report = run_bench(&options, &mut |step: &str| bar.set_message(step.to_owned()))
        .context("the benchmark could not run")?;
    bar.finish_and_clear();

    let markdown = report::markdown(&report);
    write("bench.md", &markdown)?;
    write("bench.json", &serde_json::to_string_pretty(&report)?)?;
    write("pareto.svg", &report::pareto_svg(&report))?;
    if args.json {
        println!("{}", serde_json::to_string(&report)?);
    } else {
        println!("{markdown}");
        println!(
            "written: {}",
            args.out.join("{bench.md,bench.json,pareto.svg}").display()
        );
    }
    Ok(ExitCode::SUCCESS)
}
