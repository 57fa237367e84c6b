//! The bytes-to-reading tables alone (what `nusense bench --decode-only` prints), without building the whole
//! `nusense` command: `cargo run --release -p nusense-bench --example decode -- [quick|full] [OUT_DIR]`.

use nusense_bench::decode::{markdown, run_decode_bench, DecodeBenchOptions};
use nusense_bench::{find_real_pair, report::Machine};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let mut options = match args.next().as_deref() {
        Some("full") => DecodeBenchOptions::full(),
        _ => DecodeBenchOptions::quick(),
    };
    options.real_dir = find_real_pair(&std::env::current_dir()?);
    let report = run_decode_bench(&options, &mut |step: &str| eprintln!("{step}"))?;
    let table = markdown(&report, &Machine::this());
    println!("{table}");
    if let Some(dir) = args.next() {
        let dir = std::path::Path::new(&dir);
        std::fs::create_dir_all(dir)?;
        std::fs::write(dir.join("decode.md"), &table)?;
        std::fs::write(dir.join("decode.json"), serde_json::to_string_pretty(&report)?)?;
    }
    Ok(())
}
