//! Renders the rest frame and a 6 N sphere press at a given size into a folder, for a quick look:
//! `cargo run --release -p nusense-sim --example snapshot -- OUT_DIR [WIDTH HEIGHT [REPEATS]]`; with REPEATS,
//! renders the press that many more times (for `perf stat` on a busy machine, where wall time says little).
use nusense_sim::{Contact, Renderer, Scene, SensorModel};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let out = std::path::PathBuf::from(args.first().map(String::as_str).unwrap_or("."));
    let width = args.get(1).map(|s| s.parse()).transpose()?.unwrap_or(2048);
    let height = args.get(2).map(|s| s.parse()).transpose()?.unwrap_or(width * 3 / 4);
    std::fs::create_dir_all(&out)?;
    let start = std::time::Instant::now();
    let renderer = Renderer::new(SensorModel::real(width, height))?;
    println!("precompute {:.2} s", start.elapsed().as_secs_f64());
    let scenes = [
        ("rest", Scene::rest()),
        ("press", Scene::with_contact(Contact::sphere(5.0, [-1.5, 0.5], 6.0))),
        (
            "edge",
            Scene::with_contact(Contact::edge(20.0, 1.0, 30.0, [0.0, 0.0], 8.0)),
        ),
    ];
    for (name, scene) in scenes {
        let start = std::time::Instant::now();
        let (frame, truth) = renderer.render(&scene, [100.0; 4], 1)?;
        println!(
            "{name}: {:.1} ms, max corner displacement {:.3} mm",
            start.elapsed().as_secs_f64() * 1e3,
            truth.max_corner_displacement_mm()
        );
        frame.save(out.join(format!("{name}.png")))?;
    }
    let repeats: u64 = args.get(3).map(|s| s.parse()).transpose()?.unwrap_or(0);
    if repeats > 0 {
        let press = Scene::with_contact(Contact::sphere(5.0, [-1.5, 0.5], 6.0));
        let start = std::time::Instant::now();
        for seed in 0..repeats {
            renderer.render(&press, [100.0; 4], seed)?;
        }
        println!(
            "{repeats} presses: {:.1} ms per frame (wall)",
            start.elapsed().as_secs_f64() * 1e3 / repeats as f64
        );
    }
    Ok(())
}
