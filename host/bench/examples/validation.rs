//! Issue 12's table alone (every estimator mode on the validation set), without building the whole `nusense`
//! command: `cargo run --release -p nusense-bench --example validation -- [quick|full] [OUT.json]`.
//!
//! For a look case by case: `NUSENSE_VALIDATION_CASES=CASES.jsonl` writes every mode's reading of every case (its
//! JSON, pressure map included) beside the case's truth, one line each, and `NUSENSE_VALIDATION_MODES=inverse,fast`
//! runs those modes only (the table's speed-up column then needs `paper` among them).
//! `NUSENSE_VALIDATION_CONFIG=SENSOR.toml` starts every mode's sensor config from that file instead of the defaults
//! (an option measured on the set; the calibration the set fits is applied on top of it, as for the defaults).

use std::io::Write;

use nusense_bench::report::validation_markdown;
use nusense_bench::validation::{base_config_from_env, estimator_modes, run_validation_with};
use nusense_estimator::Mode;
use nusense_sim::validation::Profile;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let profile = match args.next().as_deref() {
        Some("full") => Profile::Full,
        _ => Profile::Quick,
    };
    let modes = match std::env::var("NUSENSE_VALIDATION_MODES") {
        Ok(list) => list.split(',').map(str::parse).collect::<Result<Vec<Mode>, _>>()?,
        Err(_) => estimator_modes(),
    };
    let mut cases = match std::env::var_os("NUSENSE_VALIDATION_CASES") {
        Some(path) => Some(std::io::BufWriter::new(std::fs::File::create(path)?)),
        None => None,
    };
    let base = base_config_from_env()?;
    let mut written = Ok(());
    let started = std::time::Instant::now();
    let report = run_validation_with(
        profile,
        7,
        &modes,
        &base,
        &mut |step: &str| eprintln!("{step}"),
        &mut |record| {
            if let (Some(out), Ok(())) = (cases.as_mut(), &written) {
                written = serde_json::to_writer(&mut *out, record)
                    .map_err(std::io::Error::from)
                    .and_then(|()| writeln!(out));
            }
        },
    )?;
    written?;
    if let Some(mut out) = cases {
        out.flush()?;
    }
    println!("{}", validation_markdown(&report));
    println!("run time: {:.0} s", started.elapsed().as_secs_f64());
    if let Some(path) = args.next() {
        std::fs::write(path, serde_json::to_string_pretty(&report)?)?;
    }
    Ok(())
}
