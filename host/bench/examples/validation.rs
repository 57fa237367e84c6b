//! Issue 12's table alone (every estimator mode on the validation set), without building the whole `nusense`
//! command: `cargo run --release -p nusense-bench --example validation -- [quick|full] [OUT.json]`.

use nusense_bench::report::validation_markdown;
use nusense_bench::validation::{estimator_modes, run_validation};
use nusense_sim::validation::Profile;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let profile = match args.next().as_deref() {
        Some("full") => Profile::Full,
        _ => Profile::Quick,
    };
    let started = std::time::Instant::now();
    let report = run_validation(profile, 7, &estimator_modes(), &mut |step: &str| eprintln!("{step}"))?;
    println!("{}", validation_markdown(&report));
    println!("run time: {:.0} s", started.elapsed().as_secs_f64());
    if let Some(path) = args.next() {
        std::fs::write(path, serde_json::to_string_pretty(&report)?)?;
    }
    Ok(())
}
