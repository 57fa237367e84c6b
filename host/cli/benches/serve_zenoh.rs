//! Readings through Zenoh from `nusense serve --sim --sensors N --zenoh` (the real binary) to a subscriber in this
//! process (a separate Zenoh session in a separate process from the daemon): readings per second, latency from
//! each frame's capture timestamp to its reading's arrival (decoding, estimation and Zenoh included), frames
//! captured but not delivered, and the daemon's CPU (its /proc/PID/stat) per sensor, for 1, 4 and 16 sensors;
//! then where each reading's latency went, from the reading's own times: queued for the estimator, decoding and
//! estimating, and from the reading being ready to its arrival here.
//!
//!     cargo bench -p nusense --bench serve_zenoh -- [--seconds S] [--sensors 1,4,16] [--size 320x240]
//!         [--fps 15] [--json FILE]
//!
//! The daemon's CPU includes rendering and JPEG-encoding the simulated frames, which a real camera does itself.

#[path = "../tests/serve/daemon.rs"]
mod daemon;

use std::collections::BTreeMap;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use daemon::{zenoh_client, Daemon, Options};
use nusense_capture::unix_time_us;
use nusense_daemon::pipeline::summarise;
use serde_json::{json, Value};

/// CPU time the process has used so far (user + system), seconds.
fn cpu_seconds(pid: u32) -> f64 {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).expect("the daemon's /proc stat");
    // Fields after the command name (which may hold spaces) start at field 3; utime and stime are fields 14, 15.
    let after_name = &stat[stat.rfind(')').expect("stat format") + 2..];
    let fields: Vec<&str> = after_name.split_whitespace().collect();
    let ticks: u64 = fields[11].parse::<u64>().unwrap() + fields[12].parse::<u64>().unwrap();
    // SAFETY: sysconf has no preconditions.
    let per_second = unsafe { libc::sysconf(libc::_SC_CLK_TCK) } as f64;
    ticks as f64 / per_second
}

/// CPU time each of the process's threads has used so far, seconds, summed by thread name with the digits left
/// out (`capture`, `estimator`, tokio's workers, Zenoh's `rx-3`, `tx-0`...): where the daemon's CPU goes.
fn cpu_by_thread(pid: u32) -> BTreeMap<String, f64> {
    let mut by_name = BTreeMap::new();
    let Ok(tasks) = std::fs::read_dir(format!("/proc/{pid}/task")) else {
        return by_name;
    };
    // SAFETY: sysconf has no preconditions.
    let per_second = unsafe { libc::sysconf(libc::_SC_CLK_TCK) } as f64;
    for task in tasks.filter_map(Result::ok) {
        let Ok(stat) = std::fs::read_to_string(task.path().join("stat")) else {
            continue;
        };
        let (Some(open), Some(close)) = (stat.find('('), stat.rfind(')')) else {
            continue;
        };
        let name: String = stat[open + 1..close].chars().filter(|c| !c.is_ascii_digit()).collect();
        let fields: Vec<&str> = stat[close + 2..].split_whitespace().collect();
        let ticks: u64 = fields[11].parse::<u64>().unwrap_or(0) + fields[12].parse::<u64>().unwrap_or(0);
        *by_name.entry(name).or_insert(0.0) += ticks as f64 / per_second;
    }
    by_name
}

/// CPU time every process of the machine has used so far (the `cpu` line of /proc/stat, idle and iowait left out),
/// seconds: with the daemon's and this process's own taken off, what the machine's other users (other builds) took.
fn machine_busy_seconds() -> f64 {
    let stat = std::fs::read_to_string("/proc/stat").expect("/proc/stat");
    let fields: Vec<u64> = stat
        .lines()
        .next()
        .expect("the cpu line")
        .split_whitespace()
        .skip(1)
        .map(|f| f.parse().unwrap())
        .collect();
    // user nice system idle iowait irq softirq steal: busy is all but idle (3) and iowait (4).
    let busy: u64 = fields
        .iter()
        .take(8)
        .enumerate()
        .filter(|(i, _)| *i != 3 && *i != 4)
        .map(|(_, t)| t)
        .sum();
    // SAFETY: sysconf has no preconditions.
    busy as f64 / unsafe { libc::sysconf(libc::_SC_CLK_TCK) } as f64
}

struct Arrival {
    serial: String,
    frame_id: u64,
    /// Capture timestamp to arrival here.
    latency_ms: f64,
    /// Of which: waiting in the daemon for the estimator (the reading's `queue_ms`)...
    queue_ms: f64,
    /// ...decoding and estimating (its `latency_ms` less `queue_ms`)...
    process_ms: f64,
    /// ...and from the reading being ready to its arrival here: serialising, Zenoh, this subscriber.
    delivery_ms: f64,
    estimated: bool,
}

struct Settings {
    seconds: f64,
    sensors: Vec<u16>,
    width: u32,
    height: u32,
    fps: f64,
    json: Option<String>,
}

fn settings() -> Settings {
    let mut settings = Settings {
        seconds: 30.0,
        sensors: vec![1, 4, 16],
        width: 320,
        height: 240,
        fps: 15.0,
        json: None,
    };
    let mut args = std::env::args().skip(1).filter(|a| a != "--bench");
    while let Some(arg) = args.next() {
        let mut value = || args.next().unwrap_or_else(|| panic!("{arg} needs a value"));
        match arg.as_str() {
            "--seconds" => settings.seconds = value().parse().expect("--seconds S"),
            "--sensors" => {
                settings.sensors = value()
                    .split(',')
                    .map(|n| n.parse().expect("--sensors 1,4,16"))
                    .collect()
            }
            "--size" => {
                let size = value();
                let (w, h) = size.split_once('x').expect("--size WxH");
                settings.width = w.parse().expect("width");
                settings.height = h.parse().expect("height");
            }
            "--fps" => settings.fps = value().parse().expect("--fps F"),
            "--json" => settings.json = Some(value()),
            other => panic!("unknown argument {other}"),
        }
    }
    settings
}

async fn measure(settings: &Settings, sensors: u16) -> Value {
    let daemon = Daemon::start(
        Options::sim(settings.width, settings.height, settings.fps)
            .arg("--sensors")
            .arg(sensors.to_string())
            .arg("--zenoh")
            .arg("tcp/127.0.0.1:0"),
    );
    let session = zenoh_client(daemon.zenoh_endpoint()).await;
    let arrivals: Arc<Mutex<Vec<Arrival>>> = Arc::default();
    let sink = arrivals.clone();
    let subscriber = session
        .declare_subscriber("nusense/*/reading")
        .callback(move |sample| {
            let arrived = unix_time_us();
            let Ok(reading) = serde_json::from_slice::<Value>(&sample.payload().to_bytes()) else {
                return;
            };
            let serial = sample
                .key_expr()
                .as_str()
                .split('/')
                .nth(1)
                .unwrap_or_default()
                .to_owned();
            let since = |field: &str| arrived.saturating_sub(reading[field].as_u64().unwrap_or(arrived)) as f64 / 1e3;
            let queue_ms = reading["queue_ms"].as_f64().unwrap_or(f64::NAN);
            sink.lock().unwrap().push(Arrival {
                serial,
                frame_id: reading["frame_id"].as_u64().unwrap_or_default(),
                latency_ms: since("capture_time_us"),
                queue_ms,
                process_ms: reading["latency_ms"].as_f64().unwrap_or(f64::NAN) - queue_ms,
                delivery_ms: since("processed_time_us"),
                estimated: reading["estimate"].is_object(),
            });
        })
        .await
        .expect("subscribe");
    // Warm-up: every sensor has a rest frame and measures.
    let deadline = Instant::now() + Duration::from_secs(180);
    loop {
        let measuring: std::collections::HashSet<String> = arrivals
            .lock()
            .unwrap()
            .iter()
            .filter(|a| a.estimated)
            .map(|a| a.serial.clone())
            .collect();
        if measuring.len() == usize::from(sensors) {
            break;
        }
        assert!(
            Instant::now() < deadline,
            "only {} of {sensors} sensors measure after 180 s\n{}",
            measuring.len(),
            daemon.log()
        );
        tokio::time::sleep(Duration::from_millis(200)).await;
    }
    tokio::time::sleep(Duration::from_secs(3)).await;
    arrivals.lock().unwrap().clear();
    let load_before = std::fs::read_to_string("/proc/loadavg").unwrap_or_default();
    let cpu_before = cpu_seconds(daemon.pid());
    let threads_before = cpu_by_thread(daemon.pid());
    let own_before = cpu_seconds(std::process::id());
    let machine_before = machine_busy_seconds();
    let started = Instant::now();
    tokio::time::sleep(Duration::from_secs_f64(settings.seconds)).await;
    let cpu = cpu_seconds(daemon.pid()) - cpu_before;
    let threads_after = cpu_by_thread(daemon.pid());
    let own = cpu_seconds(std::process::id()) - own_before;
    let machine = machine_busy_seconds() - machine_before;
    let elapsed = started.elapsed().as_secs_f64();
    let window = std::mem::take(&mut *arrivals.lock().unwrap());
    let load = std::fs::read_to_string("/proc/loadavg").unwrap_or_default();
    drop(subscriber);
    session.close().await.ok();
    let status = daemon.stop_with(libc::SIGTERM);
    assert!(status.success(), "{status:?}");

    let mut frames: BTreeMap<&str, (u64, u64, usize)> = BTreeMap::new();
    for arrival in &window {
        let entry = frames.entry(&arrival.serial).or_insert((u64::MAX, 0, 0));
        entry.0 = entry.0.min(arrival.frame_id);
        entry.1 = entry.1.max(arrival.frame_id);
        entry.2 += 1;
    }
    let captured: u64 = frames.values().map(|(first, last, _)| last - first + 1).sum();
    let latency = summarise(window.iter().map(|a| a.latency_ms).collect());
    let part = |of: fn(&Arrival) -> f64| {
        let summary = summarise(window.iter().map(of).collect());
        json!({ "p50": summary.p50, "p99": summary.p99 })
    };
    let cpu_cores = cpu / elapsed;
    let threads: serde_json::Map<String, Value> = threads_after
        .iter()
        .map(|(name, after)| {
            let used = after - threads_before.get(name).copied().unwrap_or(0.0);
            (name.clone(), json!(used / elapsed))
        })
        .filter(|(_, cores)| cores.as_f64().unwrap() >= 0.005)
        .collect();
    json!({
        "sensors": sensors,
        "sensors_heard": frames.len(),
        "offered_fps_per_sensor": settings.fps,
        "readings": window.len(),
        "readings_per_s": window.len() as f64 / elapsed,
        "readings_per_s_per_sensor": window.len() as f64 / elapsed / f64::from(sensors),
        "with_estimate": window.iter().filter(|a| a.estimated).count(),
        "frames_not_delivered": captured.saturating_sub(window.len() as u64),
        "frames_captured_in_window": captured,
        "latency_ms": { "p50": latency.p50, "p99": latency.p99, "max": latency.max },
        "queue_ms": part(|a| a.queue_ms),
        "process_ms": part(|a| a.process_ms),
        "delivery_ms": part(|a| a.delivery_ms),
        "daemon_cpu_cores": cpu_cores,
        "daemon_cpu_percent_per_sensor": cpu_cores * 100.0 / f64::from(sensors),
        "daemon_cpu_cores_by_thread": threads,
        "subscriber_cpu_cores": own / elapsed,
        "others_cpu_cores": ((machine - cpu - own) / elapsed).max(0.0),
        "seconds": elapsed,
        "loadavg_before": load_before.split_whitespace().take(3).collect::<Vec<_>>().join(" "),
        "loadavg_after": load.split_whitespace().take(3).collect::<Vec<_>>().join(" "),
    })
}

fn main() {
    let settings = settings();
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .unwrap();
    let cores = std::thread::available_parallelism().map_or(0, |n| n.get());
    println!(
        "nusense serve --zenoh: simulated sensors at {}x{}, {} fps each, {} s per row, {cores} cores",
        settings.width, settings.height, settings.fps, settings.seconds
    );
    println!("| sensors | readings/s | per sensor | not delivered | p50 ms | p99 ms | max ms | daemon CPU | CPU/sensor | others' CPU | load after |");
    println!("|--------:|-----------:|-----------:|--------------:|-------:|-------:|-------:|-----------:|-----------:|------------:|:-----------|");
    let mut rows = Vec::new();
    for &sensors in &settings.sensors {
        let row = runtime.block_on(measure(&settings, sensors));
        println!(
            "| {:>7} | {:>10.1} | {:>10.1} | {:>13} | {:>6.1} | {:>6.1} | {:>6.1} | {:>9.0} % | {:>9.1} % | {:>10.0} % | {} |",
            sensors,
            row["readings_per_s"].as_f64().unwrap(),
            row["readings_per_s_per_sensor"].as_f64().unwrap(),
            format!(
                "{} of {}",
                row["frames_not_delivered"], row["frames_captured_in_window"]
            ),
            row["latency_ms"]["p50"].as_f64().unwrap(),
            row["latency_ms"]["p99"].as_f64().unwrap(),
            row["latency_ms"]["max"].as_f64().unwrap(),
            row["daemon_cpu_cores"].as_f64().unwrap() * 100.0,
            row["daemon_cpu_percent_per_sensor"].as_f64().unwrap(),
            row["others_cpu_cores"].as_f64().unwrap() * 100.0,
            row["loadavg_after"].as_str().unwrap(),
        );
        rows.push(row);
    }
    println!();
    println!("Where the latency goes (p50 / p99 ms of each part, per reading):");
    println!("| sensors | queued for the estimator | decode + estimate | ready to arrival (Zenoh) |");
    println!("|--------:|-------------------------:|------------------:|-------------------------:|");
    for row in &rows {
        let part = |name: &str| {
            format!(
                "{:.1} / {:.1}",
                row[name]["p50"].as_f64().unwrap(),
                row[name]["p99"].as_f64().unwrap()
            )
        };
        println!(
            "| {:>7} | {:>24} | {:>17} | {:>24} |",
            row["sensors"],
            part("queue_ms"),
            part("process_ms"),
            part("delivery_ms")
        );
    }
    println!();
    println!("The daemon's CPU by thread (% of one core; `capture` renders and JPEG-encodes the simulated frames):");
    for row in &rows {
        let mut threads: Vec<(&String, f64)> = row["daemon_cpu_cores_by_thread"]
            .as_object()
            .unwrap()
            .iter()
            .map(|(name, cores)| (name, cores.as_f64().unwrap() * 100.0))
            .collect();
        threads.sort_by(|a, b| b.1.total_cmp(&a.1));
        let listed: Vec<String> = threads.iter().map(|(name, pct)| format!("{name} {pct:.0}")).collect();
        println!("- {} sensors: {}", row["sensors"], listed.join(", "));
    }
    if let Some(path) = &settings.json {
        let report = json!({
            "command": "cargo bench -p nusense --bench serve_zenoh",
            "width": settings.width,
            "height": settings.height,
            "fps": settings.fps,
            "cores": cores,
            "rows": rows,
        });
        std::fs::write(path, serde_json::to_string_pretty(&report).unwrap() + "\n").expect("write the JSON");
    }
}
