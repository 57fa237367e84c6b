//! A simulated LED board: four strings of white 3528 LEDs, each switched by a low-side MOSFET and measured over a
//! sense resistor ([`crate::analog`]), fed from a supply with source resistance, on a board that warms up.
//!
//! Used by the core's tests, by the QEMU image in place of PWM and ADC, and by the host's virtual board. It models
//! what the regulator and the fault monitor must cope with: the LED forward voltage (threshold plus dynamic
//! resistance, falling as the board warms), the PWM-averaged current seen through the sense filter, supply sag
//! under load, measurement noise, and injected faults (open or shorted string, supply dip, hot board).

use nusense_protocol::CHANNEL_COUNT;

use crate::analog::{SENSE_FILTER_TAU_US, SENSE_OHM, SUPPLY_DIVIDER_RATIO, SUPPLY_NOMINAL_MV};
use crate::controller::Measurements;

/// Electrical and thermal parameters. `Default` is the NUSense LED board.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlantParams {
    /// LED forward voltage extrapolated to zero current, at 25 degC.
    pub led_threshold_mv: f32,
    /// LED dynamic resistance above the threshold.
    pub led_dynamic_ohm: f32,
    /// Forward voltage change with temperature (negative: a warm LED conducts more).
    pub led_threshold_mv_per_c: f32,
    pub mosfet_on_ohm: f32,
    pub sense_ohm: f32,
    pub sense_filter_tau_us: f32,
    pub supply_nominal_mv: f32,
    /// Supply source resistance (cable, connector, polyfuse): the supply sags with the total current.
    pub supply_source_ohm: f32,
    pub ambient_c: f32,
    /// Board-to-ambient thermal resistance and time constant.
    pub thermal_k_per_w: f32,
    pub thermal_tau_s: f32,
    /// Standard deviation of the noise on each reading (the current noise includes the PWM ripple left after the
    /// sense filter and the oversampling of the real board).
    pub current_noise_ma: f32,
    pub supply_noise_mv: f32,
    pub temperature_noise_c: f32,
    /// What each string's sense path reads per mA that really flows: 1 for a correct sense resistor and ADC, 0.8
    /// for one that reads 20 % low (a wrong resistor fitted, a drifted reference). The regulator trusts the
    /// reading, so such a string carries more than it reports: what an outside measurement (the hil camera
    /// check) must catch.
    pub sense_gain: [f32; CHANNEL_COUNT],
}

impl Default for PlantParams {
    fn default() -> Self {
        Self {
            led_threshold_mv: 2_750.0,
            led_dynamic_ohm: 2.0,
            led_threshold_mv_per_c: -2.0,
            mosfet_on_ohm: 0.05,
            sense_ohm: SENSE_OHM,
            sense_filter_tau_us: SENSE_FILTER_TAU_US,
            supply_nominal_mv: SUPPLY_NOMINAL_MV,
            supply_source_ohm: 0.3,
            ambient_c: 25.0,
            thermal_k_per_w: 10.0,
            thermal_tau_s: 60.0,
            current_noise_ma: 0.4,
            supply_noise_mv: 5.0,
            temperature_noise_c: 0.3,
            sense_gain: [1.0; CHANNEL_COUNT],
        }
    }
}

/// A fault injected into one string.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum StringFault {
    #[default]
    None,
    /// Broken wire or dead LED: no current whatever the duty.
    Open,
    /// The LED is shorted: only the sense resistor and the MOSFET limit the current.
    Shorted,
}

/// The simulated board.
#[derive(Clone, Debug)]
pub struct LedPlant {
    params: PlantParams,
    faults: [StringFault; CHANNEL_COUNT],
    /// Sense voltage after the RC filter, as current (mA).
    filtered_ma: [f32; CHANNEL_COUNT],
    /// PWM-averaged current actually flowing (mA).
    average_ma: [f32; CHANNEL_COUNT],
    supply_mv: f32,
    board_c: f32,
    rng: XorShift,
}

impl LedPlant {
    /// A cold board (at ambient), LEDs off.
    pub fn new(params: PlantParams, noise_seed: u64) -> Self {
        Self {
            params,
            faults: [StringFault::None; CHANNEL_COUNT],
            filtered_ma: [0.0; CHANNEL_COUNT],
            average_ma: [0.0; CHANNEL_COUNT],
            supply_mv: params.supply_nominal_mv,
            board_c: params.ambient_c,
            rng: XorShift::new(noise_seed),
        }
    }

    pub fn params(&self) -> &PlantParams {
        &self.params
    }

    /// Applies `duty` (0..=1 per channel; anything else, NaN included, is clamped) for `dt_us` and returns what
    /// the board's ADC reads at the end of that interval.
    pub fn step(&mut self, duty: [f32; CHANNEL_COUNT], dt_us: u32) -> Measurements {
        let dt_us = dt_us as f32;
        let p = self.params;
        let mut total_ma = 0.0;
        for (ch, &d) in duty.iter().enumerate() {
            let d = clamp_unit(d);
            let on_ma = self.on_current_ma(ch);
            self.average_ma[ch] = d * on_ma;
            total_ma += self.average_ma[ch];
            let alpha = 1.0 - libm::expf(-dt_us / p.sense_filter_tau_us);
            self.filtered_ma[ch] += (self.average_ma[ch] - self.filtered_ma[ch]) * alpha;
        }
        self.supply_mv = (p.supply_nominal_mv - total_ma * p.supply_source_ohm).max(0.0);

        // All power drawn from the supply by the strings ends up as heat on the board (the light is a small part).
        let power_w = total_ma * self.supply_mv * 1e-6;
        let target_c = p.ambient_c + power_w * p.thermal_k_per_w;
        let alpha = 1.0 - libm::expf(-dt_us * 1e-6 / p.thermal_tau_s.max(1e-3));
        self.board_c += (target_c - self.board_c) * alpha;

        let mut current_ma = [0.0; CHANNEL_COUNT];
        for (ch, out) in current_ma.iter_mut().enumerate() {
            *out = (self.filtered_ma[ch] * p.sense_gain[ch] + self.rng.gaussian() * p.current_noise_ma).max(0.0);
        }
        Measurements {
            current_ma,
            supply_mv: (self.supply_mv + self.rng.gaussian() * p.supply_noise_mv).max(0.0),
            temperature_c: self.board_c + self.rng.gaussian() * p.temperature_noise_c,
        }
    }

    /// Current while the MOSFET conducts: supply = LED(threshold + dynamic) + MOSFET + sense resistor.
    fn on_current_ma(&self, ch: usize) -> f32 {
        let p = &self.params;
        let threshold_mv = p.led_threshold_mv + p.led_threshold_mv_per_c * (self.board_c - 25.0);
        let (threshold_mv, led_ohm) = match self.faults[ch] {
            StringFault::None => (threshold_mv, p.led_dynamic_ohm),
            StringFault::Open => return 0.0,
            StringFault::Shorted => (0.0, 0.0),
        };
        ((self.supply_mv - threshold_mv) / (led_ohm + p.mosfet_on_ohm + p.sense_ohm)).max(0.0)
    }

    /// The PWM-averaged current each string actually carries (no filter, no noise): what the camera sees.
    pub fn true_current_ma(&self) -> [f32; CHANNEL_COUNT] {
        self.average_ma
    }

    pub fn board_temperature_c(&self) -> f32 {
        self.board_c
    }

    /// The supply voltage (no noise) and what the supply divider pin reads.
    pub fn supply_mv(&self) -> f32 {
        self.supply_mv
    }

    pub fn divider_pin_mv(&self) -> f32 {
        self.supply_mv / SUPPLY_DIVIDER_RATIO
    }

    pub fn set_fault(&mut self, channel: usize, fault: StringFault) {
        if let Some(f) = self.faults.get_mut(channel) {
            *f = fault;
        }
    }

    /// A weaker or stronger supply (e.g. a long USB cable, a bench supply turned down).
    pub fn set_supply_nominal_mv(&mut self, mv: f32) {
        if mv.is_finite() {
            self.params.supply_nominal_mv = mv.max(0.0);
        }
    }

    /// Moves the ambient temperature; the board follows with its thermal time constant.
    pub fn set_ambient_c(&mut self, celsius: f32) {
        if celsius.is_finite() {
            self.params.ambient_c = celsius;
        }
    }

    /// Forces the board temperature now (a hot enclosure, a heat gun).
    pub fn set_board_temperature_c(&mut self, celsius: f32) {
        if celsius.is_finite() {
            self.board_c = celsius;
        }
    }
}

fn clamp_unit(x: f32) -> f32 {
    if x.is_nan() {
        0.0
    } else {
        x.clamp(0.0, 1.0)
    }
}

/// Small deterministic noise source (xorshift64*), so runs are reproducible from a seed without an RNG crate.
#[derive(Clone, Debug)]
struct XorShift(u64);

impl XorShift {
    fn new(seed: u64) -> Self {
        Self(seed ^ 0x9E37_79B9_7F4A_7C15 | 1)
    }

    fn next_u64(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }

    fn uniform(&mut self) -> f32 {
        (self.next_u64() >> 40) as f32 / (1u64 << 24) as f32
    }

    /// Approximately standard normal: the sum of four uniforms, scaled to unit variance.
    fn gaussian(&mut self) -> f32 {
        let sum: f32 = (0..4).map(|_| self.uniform()).sum();
        (sum - 2.0) * libm::sqrtf(3.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn full_duty_drives_more_than_the_limit_so_the_regulator_has_headroom() {
        let mut plant = LedPlant::new(PlantParams::default(), 1);
        for _ in 0..20 {
            plant.step([1.0; 4], 1000);
        }
        let i = plant.true_current_ma()[0];
        assert!(i > 150.0 && i < 250.0, "full-duty current {i} mA");
    }

    #[test]
    fn faults_change_the_current() {
        let mut plant = LedPlant::new(PlantParams::default(), 1);
        plant.set_fault(0, StringFault::Open);
        plant.set_fault(1, StringFault::Shorted);
        plant.step([0.5; 4], 1000);
        let i = plant.true_current_ma();
        assert_eq!(i[0], 0.0);
        assert!(i[1] > 2.0 * i[2], "shorted {} vs healthy {}", i[1], i[2]);
    }

    #[test]
    fn nan_duty_is_treated_as_off() {
        let mut plant = LedPlant::new(PlantParams::default(), 1);
        let m = plant.step([f32::NAN, f32::INFINITY, -1.0, 0.0], 1000);
        assert_eq!(plant.true_current_ma()[0], 0.0);
        assert!(m.current_ma.iter().all(|c| c.is_finite()));
    }
}
