//! The light the LED strings really give, as an instrument outside the board would see it: what the camera check
//! compares with the currents the board reports, so a board whose measurement (or telemetry) is wrong cannot
//! pass on its own word.
//!
//! - the virtual board: the simulated plant's true currents ([`nusense_board::virtual_board::LedCurrents`]);
//! - the QEMU image: the plant's true currents, which the image writes on its second serial port (USART2) as
//!   lines `L top right bottom left` in microamps, a channel its `Controller` never reads;
//! - a real board: nothing here; the camera itself looks at the pad.

use std::io::{BufRead, BufReader};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

/// The latest true currents from the QEMU image's USART2, read on a thread for as long as the meter lives.
pub struct LightMeter {
    latest: Arc<Mutex<Option<[f32; 4]>>>,
    stop: Arc<AtomicBool>,
}

impl LightMeter {
    /// Starts reading the pty at `path` (raw, so the lines arrive as written).
    pub fn open(path: &str) -> Result<Self, serialport::Error> {
        let port = serialport::new(path, 115_200)
            .timeout(Duration::from_millis(100))
            .open_native()?;
        let latest = Arc::new(Mutex::new(None));
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
                            if let Some(currents) = parse_light_line(&line) {
                                *seen.lock().unwrap_or_else(|p| p.into_inner()) = Some(currents);
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
        *self.latest.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// A handle for the simulated camera.
    pub fn source(&self) -> impl Fn() -> Option<[f32; 4]> + Send + 'static {
        let latest = self.latest.clone();
        move || *latest.lock().unwrap_or_else(|p| p.into_inner())
    }
}

impl Drop for LightMeter {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
    }
}

/// `L 100123 99876 100001 0` -> mA.
fn parse_light_line(line: &str) -> Option<[f32; 4]> {
    let mut fields = line.trim().split(' ');
    if fields.next()? != "L" {
        return None;
    }
    let mut currents = [0.0; 4];
    for current in &mut currents {
        *current = fields.next()?.parse::<u32>().ok()? as f32 / 1000.0;
    }
    fields.next().is_none().then_some(currents)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn light_lines_are_parsed_in_milliamps() {
        assert_eq!(
            parse_light_line("L 100123 99876 100001 0\n"),
            Some([100.123, 99.876, 100.001, 0.0])
        );
        assert_eq!(parse_light_line("L 1 2 3"), None);
        assert_eq!(parse_light_line("L 1 2 3 4 5"), None);
        assert_eq!(parse_light_line("X 1 2 3 4"), None);
        assert_eq!(parse_light_line("L 1 2 x 4"), None);
    }
}
