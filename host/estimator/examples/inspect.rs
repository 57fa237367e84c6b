//! Prints what the estimator sees on a pair of frames: `cargo run --release --example inspect -- REF FRAME [fast|paper] [REPEATS]`.

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    if args.len() < 3 {
        return Err("usage: inspect REF FRAME [fast|paper]".into());
    }
    let mode: nusense_estimator::Mode = args.get(3).map(String::as_str).unwrap_or("fast").parse()?;
    let reference = image::open(&args[1])?.to_rgb8();
    let frame = image::open(&args[2])?.to_rgb8();
    let started = std::time::Instant::now();
    let mut estimator = nusense_estimator::Estimator::new(Default::default(), mode, &reference)?;
    println!("reference: {:.1} ms", started.elapsed().as_secs_f64() * 1e3);
    let lattice = estimator.reference_lattice();
    println!(
        "reference squares {} corners {}",
        lattice.squares_found(),
        lattice.corners_found()
    );
    let repeats: usize = args.get(4).map(|s| s.parse()).transpose()?.unwrap_or(1);
    let started = std::time::Instant::now();
    let mut reading = estimator.estimate(&frame)?;
    for _ in 1..repeats {
        reading = estimator.estimate(&frame)?;
    }
    let per_frame = started.elapsed().as_secs_f64() * 1e3 / repeats as f64;
    reading.shear_field.clear();
    println!("{reading:?}");
    println!("{per_frame:.3} ms per frame (wall clock, {repeats} frames)");
    Ok(())
}
