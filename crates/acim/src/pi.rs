//! Discrete PI controller with output limits, anti-windup and bumpless reset (the current
//! and speed regulators of paper Fig. 1 and Fig. 5), and gain design from a bandwidth.
//!
//! Form, at the control period Ts (backward-rectangle integral):
//! `u[k] = clamp(ff + kp e[k] + I[k])`, `I[k] = I[k-1] + ki Ts e[k]`, except that the
//! integral does not move past the value that puts the output on the limit it is moving
//! toward (conditional integration, in its continuous form: on the step where the output
//! reaches a limit the integral integrates up to the limit, not all or nothing), and the
//! integral itself is kept inside the output limits, so it cannot wind up.
//!
//! Why the continuous form: an all-or-nothing rule ("integrate unless saturated and
//! pushing further") makes the state a discontinuous function of the inputs. Two
//! arithmetics (f32 and Q7.24), or two runs whose inputs differ in the last bit, then
//! take different branches on the step the output touches its limit and their integrals
//! drift apart by a whole ki Ts e each time (8 % seen in the f32/fixed equivalence test
//! over 200 000 cases). With the integral clamped to the headroom instead, the state is a
//! continuous function of the inputs and the two stay within their rounding.

use crate::num::Num;
use crate::num::Units;
use crate::params::MachineParams;

/// Gains and limits of one PI controller (configuration, apart from state). Designed in
/// f32 SI ([`PiConfig::current_loop`], [`crate::speed_loop::SpeedLoopConfig`]); the fixed-point copy is
/// converted from it.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PiConfig<N: Num = f32> {
    /// Proportional gain (output unit per error unit).
    pub kp: N::Gain,
    /// Integral gain times the control period, ki*Ts (output unit per error unit per step).
    pub ki_ts: N::Gain,
    /// Lower output limit.
    pub out_min: N,
    /// Upper output limit.
    pub out_max: N,
}

impl PiConfig<f32> {
    /// Gains from kp and ki (1/s) at period `ts` (s), with symmetric limits +/- `limit`.
    pub fn new(kp: f32, ki: f32, ts: f32, limit: f32) -> Self {
        Self {
            kp,
            ki_ts: ki * ts,
            out_min: -limit.abs(),
            out_max: limit.abs(),
        }
    }

    /// Current-loop design (d or q axis) for a closed-loop bandwidth `bandwidth` (rad/s):
    /// the decoupled plant of eq. (9a)/(9b) is 1/(sigma Ls s + Rseq); a PI zero at
    /// Rseq/(sigma Ls) cancels its pole, leaving a first-order loop with crossover at the
    /// bandwidth: kp = sigma Ls wc (V/A), ki = Rseq wc (V/(A s)), so ki/kp = Rseq/(sigma Ls).
    pub fn current_loop(m: &MachineParams, bandwidth: f32, ts: f32, voltage_limit: f32) -> Self {
        let kp = m.transient_inductance() * bandwidth;
        let ki = m.equivalent_resistance() * bandwidth;
        Self::new(kp, ki, ts, voltage_limit)
    }
}

/// State of one PI controller.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PiController<N = f32> {
    integral: N,
    saturated: bool,
}

impl<N: Num> PiController<N> {
    /// A controller at rest (zero integral).
    pub fn new() -> Self {
        Self {
            integral: N::ZERO,
            saturated: false,
        }
    }

    /// One step with the configured limits; see [`PiController::update_with_limits`].
    #[inline(always)]
    pub fn update(&mut self, cfg: &PiConfig<N>, error: N, feedforward: N) -> N {
        self.update_with_limits(cfg, error, feedforward, cfg.out_min, cfg.out_max)
    }

    /// One step with limits given for this step (`lo <= hi`, e.g. a voltage limit that
    /// follows the DC bus). Returns `clamp(ff + kp e + I, lo, hi)`. A non-finite error or
    /// feed-forward cannot poison the state: the integral stays finite and in range.
    #[inline(always)]
    pub fn update_with_limits(
        &mut self,
        cfg: &PiConfig<N>,
        error: N,
        feedforward: N,
        lo: N,
        hi: N,
    ) -> N {
        let p = N::gain(cfg.kp, error);
        let candidate = self.integral + N::gain(cfg.ki_ts, error);
        let unsat = feedforward + p + candidate;
        let out;
        // (the limits' arms marked cold: the output in range falls through)
        if unsat > hi {
            core::hint::cold_path();
            out = hi;
            // moving back toward the range: integrate; pushing further: the integral goes
            // no further than the value that puts the output on the limit (it stays if it
            // is already beyond), so the state is continuous across the limit
            self.integral = if error < N::ZERO {
                candidate
            } else {
                let room = hi - feedforward - p;
                if room > self.integral {
                    room
                } else {
                    self.integral
                }
            };
            self.saturated = true;
        } else if unsat < lo {
            core::hint::cold_path();
            out = lo;
            self.integral = if error > N::ZERO {
                candidate
            } else {
                let room = lo - feedforward - p;
                if room < self.integral {
                    room
                } else {
                    self.integral
                }
            };
            self.saturated = true;
        } else {
            // also catches NaN (all comparisons false): the integral clamp below maps it
            // into range
            self.integral = candidate;
            self.saturated = false;
            // in range unless NaN (an infinity took a branch above): one self-comparison
            // instead of the two of a clamp; a NaN in f32 is mapped into range here
            out = if unsat.is_nan() {
                core::hint::cold_path();
                unsat.into_range(lo, hi)
            } else {
                unsat
            };
        }
        self.integral = self.integral.clamp(lo, hi);
        out
    }

    /// Bumpless reset: sets the integral so that, with zero error and feed-forward
    /// `feedforward`, the next output equals `output`.
    pub fn reset_to(&mut self, cfg: &PiConfig<N>, output: N, feedforward: N) {
        self.integral = (output - feedforward).clamp(cfg.out_min, cfg.out_max);
        self.saturated = false;
    }

    /// Resets the integral to zero.
    pub fn reset(&mut self) {
        *self = Self::new();
    }

    /// Present integral term (output units).
    pub fn integral(&self) -> N {
        self.integral
    }

    /// Whether the last output was at a limit.
    pub fn saturated(&self) -> bool {
        self.saturated
    }
}

impl PiConfig<f32> {
    /// This design in the arithmetic `N`: the error in units of `error_base`, the output
    /// in units of `output_base` (SI values; 1 and 1 for f32). `None` if a gain is not
    /// representable.
    pub fn convert<N: Num + Units>(
        &self,
        error_base: f32,
        output_base: f32,
    ) -> Option<PiConfig<N>> {
        let k = error_base / output_base;
        Some(PiConfig {
            kp: N::gain_from_f32(self.kp * k)?,
            ki_ts: N::gain_from_f32(self.ki_ts * k)?,
            out_min: N::from_f32(self.out_min / output_base),
            out_max: N::from_f32(self.out_max / output_base),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn current_loop_design_cancels_the_electrical_pole() {
        let m = MachineParams::paper_table1();
        let c = PiConfig::current_loop(&m, 1000.0, 200e-6, 180.0);
        let ki = c.ki_ts / 200e-6;
        assert!((ki / c.kp - m.equivalent_resistance() / m.transient_inductance()).abs() < 1e-2);
        assert!((c.kp - m.transient_inductance() * 1000.0).abs() < 1e-4);
    }

    #[test]
    fn first_order_plant_tracks_step_without_overshoot_past_limit() {
        // plant: sigma Ls di/dt = v - Rseq i, Euler at 20 us, controller at 200 us
        let m = MachineParams::paper_table1();
        let cfg = PiConfig::current_loop(&m, 1000.0, 200e-6, 300.0);
        let mut pi = PiController::new();
        let mut i = 0.0f32;
        let mut peak = 0.0f32;
        for _ in 0..200 {
            let v = pi.update(&cfg, 2.0 - i, 0.0);
            for _ in 0..10 {
                i += 20e-6 * (v - m.equivalent_resistance() * i) / m.transient_inductance();
            }
            peak = peak.max(i);
        }
        assert!((i - 2.0).abs() < 1e-3, "settled at {i}");
        assert!(peak < 2.3, "overshoot {peak}");
    }

    #[test]
    fn bumpless_reset_gives_requested_output() {
        let cfg = PiConfig::new(0.5, 10.0, 1e-3, 5.0);
        let mut pi = PiController::new();
        pi.reset_to(&cfg, 3.0, 1.0);
        assert!((pi.update(&cfg, 0.0, 1.0) - 3.0).abs() < 1e-6);
    }

    #[test]
    fn non_finite_inputs_do_not_poison_state() {
        let cfg = PiConfig::new(1.0, 100.0, 1e-3, 5.0);
        let mut pi = PiController::new();
        for e in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
            let u = pi.update(&cfg, e, 0.0);
            assert!(u.is_finite() && u.abs() <= 5.0);
            assert!(pi.integral().is_finite());
        }
    }

    proptest! {
        #[test]
        fn output_stays_in_limits_and_recovers_without_windup(
            kp in 0.0f32..50.0, ki in 0.0f32..5000.0, limit in 0.1f32..500.0,
            errors in proptest::collection::vec(-1e4f32..1e4, 1..200),
            ff in -1e3f32..1e3,
        ) {
            let cfg = PiConfig::new(kp, ki, 1e-4, limit);
            let mut pi = PiController::new();
            for e in &errors {
                let u = pi.update(&cfg, *e, ff);
                prop_assert!(u >= -limit && u <= limit);
                prop_assert!(pi.integral().abs() <= limit);
            }
            // long saturation high, then a reversed error: without windup the output
            // leaves the upper limit as soon as the proportional part reverses.
            for _ in 0..10_000 { pi.update(&cfg, 1e3, 0.0); }
            let u = pi.update(&cfg, -1.0, 0.0);
            prop_assert!(u <= limit);
            // the integral never exceeded the limit, so after at most
            // 2*limit/(ki_ts*1) + 1 steps of unit negative error the output is below zero
            if ki > 1.0 {
                let n = (2.0 * limit / (cfg.ki_ts)) as usize + 2;
                let mut last = u;
                for _ in 0..n.min(2_000_000) { last = pi.update(&cfg, -1.0, 0.0); }
                prop_assert!(last < 0.0 || n > 2_000_000);
            }
        }
    }
}
