//! Closed current loop of one LED string: a soft-start ramp on the reference, then an integral controller on the
//! PWM duty.
//!
//! The plant seen from the duty is nearly static (PWM-averaged current = duty x on-current; the sense filter is
//! 200 us), so an integral controller alone gives a first-order closed loop: no overshoot, zero steady-state error,
//! and it tracks the slow drift of the LED forward voltage as the board warms. Its gain per step is bounded by
//! capping the step length, so a late control step (a busy executor, an emulator) can never make it oscillate.

/// Integral gain in duty per (mA x s). At the nominal on-current (~190 mA at full duty) a 1 kHz loop moves 0.3 of
/// the remaining error per step: a closed-loop time constant of about 3 ms, and stable (no ringing) for plant
/// gains up to three times nominal.
pub const INTEGRAL_GAIN_PER_MA_S: f32 = 1.6;
/// Largest current sample the integrator believes (a shorted string draws about 500 mA).
const MEASUREMENT_BOUND_MA: f32 = 10_000.0;
/// Longest step the integrator takes at once, whatever the real interval.
pub const MAX_STEP_US: u32 = 2_000;

/// One channel's loop state.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ChannelRegulator {
    /// Ramped reference the loop follows.
    reference_ma: f32,
    duty: f32,
}

impl ChannelRegulator {
    pub const fn new() -> Self {
        Self {
            reference_ma: 0.0,
            duty: 0.0,
        }
    }

    /// Channel off: the next start ramps again from zero.
    pub fn reset(&mut self) {
        *self = Self::new();
    }

    /// One control step. `target_ma` is the (clamped, derated) setpoint, `measured_ma` the current seen now,
    /// `dt_us` the time since the previous step. Returns the duty to apply, in 0..=1.
    ///
    /// The reference rises at `target / ramp` (the soft start: 0 to the setpoint in `ramp_ms`) and falls at once:
    /// a lower current is always safe.
    pub fn step(&mut self, target_ma: f32, ramp_ms: u16, measured_ma: f32, dt_us: u32) -> f32 {
        let target_ma = if target_ma.is_finite() { target_ma.max(0.0) } else { 0.0 };
        let dt_us = dt_us.min(MAX_STEP_US) as f32;
        if ramp_ms == 0 || self.reference_ma >= target_ma {
            self.reference_ma = target_ma;
        } else {
            let rise = target_ma * dt_us / (f32::from(ramp_ms) * 1_000.0);
            self.reference_ma = (self.reference_ma + rise).min(target_ma);
        }
        // A non-finite sample carries no information: hold the duty rather than integrate it.
        if measured_ma.is_finite() {
            // No string carries a negative current or more than a short circuit does: bounding the sample keeps
            // the arithmetic finite whatever a broken ADC path reports.
            let measured_ma = measured_ma.clamp(0.0, MEASUREMENT_BOUND_MA);
            let error = self.reference_ma - measured_ma;
            self.duty = (self.duty + INTEGRAL_GAIN_PER_MA_S * error * dt_us * 1e-6).clamp(0.0, 1.0);
        }
        if target_ma == 0.0 {
            self.duty = 0.0;
        }
        self.duty
    }

    pub fn reference_ma(&self) -> f32 {
        self.reference_ma
    }

    pub fn duty(&self) -> f32 {
        self.duty
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reference_ramps_up_in_ramp_time_and_drops_at_once() {
        let mut r = ChannelRegulator::new();
        for _ in 0..25 {
            r.step(100.0, 50, 0.0, 1_000);
        }
        assert!(
            (r.reference_ma() - 50.0).abs() < 1e-3,
            "half way after half the ramp: {}",
            r.reference_ma()
        );
        for _ in 0..30 {
            r.step(100.0, 50, 0.0, 1_000);
        }
        assert_eq!(r.reference_ma(), 100.0);
        r.step(40.0, 50, 0.0, 1_000);
        assert_eq!(r.reference_ma(), 40.0);
    }

    #[test]
    fn duty_stays_in_range_and_ignores_nan() {
        let mut r = ChannelRegulator::new();
        for _ in 0..1000 {
            assert!((0.0..=1.0).contains(&r.step(120.0, 0, 0.0, 1_000)));
        }
        assert_eq!(r.duty(), 1.0);
        assert_eq!(r.step(120.0, 0, f32::NAN, 1_000), 1.0);
        assert_eq!(r.step(f32::NAN, 0, 10.0, 1_000), 0.0);
    }
}
