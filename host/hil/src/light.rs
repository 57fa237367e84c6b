//! The light the LED strings really give, as an instrument outside the board would see it: what the camera check
//! compares with the currents the board reports, so a board whose measurement (or telemetry) is wrong cannot
//! pass on its own word.
//!
//! - the virtual board: the simulated plant's true currents ([`nusense_board::virtual_board::LedCurrents`]);
//! - the QEMU image: the plant's true currents, which the image writes on its second serial port (USART2) as
//!   lines `L uptime top right bottom left` (board time in microseconds, currents in microamps), a channel its
//!   `Controller` never reads;
//! - a real board: nothing here; the camera itself looks at the pad.

use std::io::{BufRead, BufReader};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Condvar, Mutex};
use std::time::{Duration, Instant};

/// One line of the light channel: the true currents (mA; Top, Right, Bottom, Left) at a board time (us).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LightReading {
    pub uptime_us: u64,
    pub currents_ma: [f32; 4],
}

/// How long [`LightMeter::since`] waits for the board's clock to pass the time asked for. Only a silent channel
/// (a dead emulator) runs into it: the image writes a line every 20 ms of its own time, however slowly that runs.
pub const LIGHT_PATIENCE: Duration = Duration::from_secs(60);

type Latest = Arc<(Mutex<Option<LightReading>>, Condvar)>;

/// The latest true currents from the QEMU image's USART2, read on a thread for as long as the meter lives.
pub struct LightMeter {
    latest: Latest,
    stop: Arc<AtomicBool>,
}

impl LightMeter {
    /// Starts reading the pty at `path` (raw, so the lines arrive as written).
    pub fn open(path: &str) -> Result<Self, serialport::Error> {
        let port = serialport::new(path, 115_200)
            .timeout(Duration::from_millis(100))
            .open_native()?;
        let latest: Latest = Arc::new((Mutex::new(None), Condvar::new()));
        let stop = Arc::new(AtomicBool::new(false));
        let (seen, stopping) = (latest.clone(), stop.clone());
        std::thread::Builder::new()
            .name("qemu light meter".into())
            .spawn(move || {
                let mut lines = BufReader::new(port);
                let mut line = String::new();
                while !stopping.load(Ordering::Relaxed) {
                    line.clear();
                    match lines.read_line(&mut line) {
                        Ok(0) => return,
                        Ok(_) => {
                            if let Some(reading) = parse_light_line(&line) {
                                let (lock, arrived) = &*seen;
                                *lock.lock().unwrap_or_else(|p| p.into_inner()) = Some(reading);
                                arrived.notify_all();
                            }
                        }
                        Err(error) if error.kind() == std::io::ErrorKind::TimedOut => {}
                        Err(_) => return,
                    }
                }
            })
            .map_err(|error| serialport::Error::new(serialport::ErrorKind::Io(error.kind()), error.to_string()))?;
        Ok(Self { latest, stop })
    }

    /// The true currents in mA (Top, Right, Bottom, Left), once the first line has arrived.
    pub fn currents_ma(&self) -> Option<[f32; 4]> {
        latest(&self.latest).map(|reading| reading.currents_ma)
    }

    /// The first reading at or after board time `uptime_us`, waiting for it (at most [`LIGHT_PATIENCE`]).
    pub fn since(&self, uptime_us: u64) -> Option<LightReading> {
        since(&self.latest, uptime_us, LIGHT_PATIENCE)
    }

    /// A handle for the simulated camera: with a board time, the light at or after it (see [`Self::since`]);
    /// without, the latest.
    pub fn source(&self) -> impl Fn(Option<u64>) -> Option<[f32; 4]> + Send + 'static {
        let latest = self.latest.clone();
        move |uptime_us| match uptime_us {
            Some(uptime_us) => since(&latest, uptime_us, LIGHT_PATIENCE).map(|reading| reading.currents_ma),
            None => self::latest(&latest).map(|reading| reading.currents_ma),
        }
    }
}

fn latest(latest: &Latest) -> Option<LightReading> {
    *latest.0.lock().unwrap_or_else(|p| p.into_inner())
}

/// The light of board time `uptime_us` or later: the reader thread takes lines as they come, and the host may
/// ask before the line describing that moment has arrived (the two serial ports are read on different threads,
/// and a loaded machine delays either), so the latest line is not yet the one asked for.
fn since(latest: &Latest, uptime_us: u64, patience: Duration) -> Option<LightReading> {
    let (lock, arrived) = &**latest;
    let deadline = Instant::now() + patience;
    let mut reading = lock.lock().unwrap_or_else(|p| p.into_inner());
    loop {
        if let Some(found) = *reading {
            if found.uptime_us >= uptime_us {
                return Some(found);
            }
        }
        let left = deadline.saturating_duration_since(Instant::now());
        if left.is_zero() {
            return None;
        }
        reading = arrived.wait_timeout(reading, left).unwrap_or_else(|p| p.into_inner()).0;
    }
}

impl Drop for LightMeter {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
    }
}

/// `L 2500000 100123 99876 100001 0` -> board time in us, currents in mA.
fn parse_light_line(line: &str) -> Option<LightReading> {
    let mut fields = line.trim().split(' ');
    if fields.next()? != "L" {
        return None;
    }
    let uptime_us = fields.next()?.parse::<u64>().ok()?;
    let mut currents_ma = [0.0; 4];
    for current in &mut currents_ma {
        *current = fields.next()?.parse::<u32>().ok()? as f32 / 1000.0;
    }
    fields
        .next()
        .is_none()
        .then_some(LightReading { uptime_us, currents_ma })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn light_lines_are_parsed_in_milliamps() {
        assert_eq!(
            parse_light_line("L 2500000 100123 99876 100001 0\n"),
            Some(LightReading {
                uptime_us: 2_500_000,
                currents_ma: [100.123, 99.876, 100.001, 0.0]
            })
        );
        assert_eq!(parse_light_line("L 1 2 3 4"), None);
        assert_eq!(parse_light_line("L 1 2 3 4 5 6"), None);
        assert_eq!(parse_light_line("X 1 2 3 4 5"), None);
        assert_eq!(parse_light_line("L 1 2 x 4 5"), None);
    }

    #[test]
    fn the_light_of_a_board_time_waits_for_its_line() {
        let latest: Latest = Arc::new((Mutex::new(None), Condvar::new()));
        let store = |uptime_us: u64, ma: f32| {
            *latest.0.lock().unwrap() = Some(LightReading {
                uptime_us,
                currents_ma: [ma; 4],
            });
            latest.1.notify_all();
        };
        store(1_000, 100.0);
        assert_eq!(
            since(&latest, 1_000, Duration::ZERO).map(|r| r.currents_ma[0]),
            Some(100.0)
        );
        // The line for a later moment has not come: not the old light, but nothing (or the new line once it comes).
        assert_eq!(since(&latest, 2_000, Duration::from_millis(10)), None);
        std::thread::scope(|scope| {
            let waiting = scope.spawn(|| since(&latest, 2_000, Duration::from_secs(60)));
            std::thread::sleep(Duration::from_millis(20));
            store(1_500, 100.0);
            store(2_000, 25.0);
            assert_eq!(waiting.join().unwrap().map(|r| r.currents_ma[0]), Some(25.0));
        });
    }
}
