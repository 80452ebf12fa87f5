//! Online stator-resistance estimator (paper section 6, eq. 19-20), with the sign corrected.
//!
//! A d-axis current model with the estimated resistance (eq. 20, where the paper's text
//! writes Rs_hat; it is valid only with settled flux, when lambda_r/tau_r cancels the rotor
//! part of Rseq in eq. 15):
//!
//! ```text
//! sigma Ls d i_sd_hat/dt = -Rs_hat i_sd_hat + sigma Ls w_s i_sq + v_sd
//! ```
//!
//! ## Sign (derived here; the printed eq. 18-19 are wrong)
//!
//! Subtracting the true steady d-axis equation 0 = -Rs i_sd + sigma Ls w_s i_sq + v_sd with
//! e = i_sd_hat - i_sd gives sigma Ls de/dt = -(Rs_hat - Rs) i_sd_hat - Rs e (paper eq. A7),
//! so at equilibrium Rs_hat - Rs = -Rs e / i_sd_hat. An estimate too large makes e < 0 (for
//! i_sd > 0), so the converging law is
//!
//! ```text
//! Rs_hat = R0 + integral(alpha sign(i_sd) e dt)
//! ```
//!
//! The paper's eq. (19), Rs_hat = R0 - integral(alpha e dt), has the opposite sign and
//! diverges with its own error definition (design notes, section 3).
//!
//! ## Gain from a convergence time
//!
//! With the current model much faster than the adaptation, e = i_sd (Rs - Rs_hat)/Rs_hat,
//! so d(Rs_hat)/dt = alpha |i_sd| (Rs - Rs_hat)/Rs_hat: a first-order convergence with time
//! constant tau = Rs / (alpha |i_sd|). [`RsEstimatorConfig::new`] takes tau and the flux
//! current and sets alpha = Rs_nominal / (tau |i_sd*|) (ohm per A per s).
//!
//! ## Gating and clamping
//!
//! Adaptation runs only where eq. (20) holds and the d-axis is informative: flux settled
//! (the caller's `flux_settled`; the drive uses its `flux_tolerance`), |i_sd| above
//! `min_flux_current`, |i_sq| below `max_torque_current`, |w_s| below
//! `max_stator_frequency` (at high frequency the sigma Ls w_s i_sq term and voltage errors
//! dominate v_sd). The estimate is clamped to
//! [`min_resistance`, `max_resistance`]; reaching a bound is reported so the drive can
//! raise an "estimator out of range" fault.

use crate::num::Num;
use crate::params::MachineParams;

/// Configuration of the stator-resistance estimator (designed in f32 SI; in fixed point
/// the gains carry the per-unit base conversions and the clamps are in the finer
/// integrator format, [`Num::Fine`]).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct RsEstimatorConfig<N: Num = f32> {
    /// Control period Ts, s: (stator frequency x current) -> current.
    pub ts: N::Gain,
    /// Ts/(sigma Ls), s/H.
    pub ts_over_transient_inductance: N::Gain,
    /// Adaptation gain alpha times Ts, ohm per A per step.
    pub alpha_ts: N::Gain,
    /// Lower clamp of the estimate, ohm.
    pub min_resistance: N::Fine,
    /// Upper clamp of the estimate, ohm.
    pub max_resistance: N::Fine,
    /// Adapt only with |i_sd| at least this, A.
    pub min_flux_current: N,
    /// Adapt only with |i_sq| at most this, A.
    pub max_torque_current: N,
    /// Adapt only with |w_s| at most this, rad/s electrical.
    pub max_stator_frequency: N,
    /// Whether the resistance adapts at all (the current model of eq. 20 always runs: the
    /// drive's orientation correction uses its error).
    pub adapt: bool,
}

impl RsEstimatorConfig<f32> {
    /// Design for machine `m` (nominal Rs), period `ts` (s), a convergence time constant
    /// `tau` (s) at flux current `flux_current` (A). Band: 0.5 to 2.5 times nominal Rs
    /// (copper from -50 C to well past insulation class limits; a bound reached means a
    /// wrong model, not a hot motor).
    pub fn new(m: &MachineParams, ts: f32, tau: f32, flux_current: f32) -> Self {
        let rs = m.stator_resistance();
        let alpha = rs / (tau.max(ts) * flux_current.abs().max(1e-3));
        Self {
            ts,
            ts_over_transient_inductance: ts / m.transient_inductance(),
            alpha_ts: alpha * ts,
            min_resistance: 0.5 * rs,
            max_resistance: 2.5 * rs,
            min_flux_current: 0.5 * flux_current.abs(),
            max_torque_current: 2.0 * flux_current.abs(),
            max_stator_frequency: 2.0 * core::f32::consts::PI * 40.0,
            adapt: true,
        }
    }

    /// Adaptation gain alpha, ohm/(A s).
    pub fn alpha(&self) -> f32 {
        self.alpha_ts / self.ts
    }
}

/// Measured and commanded quantities for one estimator step.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct RsEstimatorInputs<N = f32> {
    /// Measured i_sd, A.
    pub i_sd: N,
    /// Measured i_sq, A.
    pub i_sq: N,
    /// Commanded v_sd over the period, V.
    pub v_sd: N,
    /// Stator frequency w_s (of the rotor-flux frame), rad/s electrical.
    pub stator_frequency: N,
    /// Whether the flux model reports a settled flux (within tolerance of its reference).
    pub flux_settled: bool,
}

/// State of the stator-resistance estimator.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct RsEstimator<N: Num = f32> {
    /// The integrator of eq. (19) ([`Num::Fine`]: the estimate itself in f32).
    resistance: N::Fine,
    /// Rs_hat, ohm.
    pub stator_resistance_estimate: N,
    /// i_sd_hat of eq. (20), A.
    pub current_estimate: N,
    /// Whether the last step adapted (inside the gate).
    pub adapting: bool,
    /// i_sd_hat - i_sd at the last step, A: in steady state r_d / Rs_hat, where r_d is the
    /// d-axis voltage residual of the field-oriented model.
    pub current_error: N,
    /// Whether the estimate sits at a clamp bound.
    pub at_bound: bool,
}

impl<N: Num> RsEstimator<N> {
    /// Starts from an initial resistance `r0` (ohm) (eq. 19's R0).
    pub fn new(r0: N) -> Self {
        let resistance = N::to_fine(r0);
        Self {
            resistance,
            stator_resistance_estimate: N::from_fine(resistance),
            current_estimate: N::ZERO,
            current_error: N::ZERO,
            adapting: false,
            at_bound: false,
        }
    }

    /// One step: Euler update of eq. (20) and, inside the gate, of the corrected eq. (19).
    #[inline]
    pub fn update(&mut self, cfg: &RsEstimatorConfig<N>, u: &RsEstimatorInputs<N>) -> N {
        let rs = self.stator_resistance_estimate;
        let e = self.current_estimate - u.i_sd;
        self.current_error = e.finite_or(N::ZERO);
        self.adapting = cfg.adapt
            && u.flux_settled
            && u.i_sd.abs() >= cfg.min_flux_current
            && u.i_sq.abs() <= cfg.max_torque_current
            && u.stator_frequency.abs() <= cfg.max_stator_frequency;
        if self.adapting && e.is_finite() {
            let (next, at_bound) = N::fine_step(
                self.resistance,
                cfg.alpha_ts,
                e,
                u.i_sd >= N::ZERO,
                cfg.min_resistance,
                cfg.max_resistance,
            );
            self.resistance = next;
            self.at_bound = at_bound;
            self.stator_resistance_estimate = N::from_fine(next);
        }
        // sigma Ls di_hat/dt = -Rs_hat i_hat + sigma Ls w_s i_sq + v_sd (eq. 20)
        let di = N::gain(
            cfg.ts_over_transient_inductance,
            u.v_sd - rs * self.current_estimate,
        ) + N::gain_mul(cfg.ts, u.stator_frequency, u.i_sq);
        let next_i = self.current_estimate + di;
        // keep the model finite; a bad sample resets it to the measurement
        self.current_estimate = next_i.finite_or(u.i_sd.finite_or(N::ZERO));
        self.stator_resistance_estimate
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Steady d-axis with true Rs = 10.5 ohm; the estimator starts at 15.75 ohm (+50 %,
    /// paper Fig. 9) and must reach 2 % of 10.5 within 1 s with tau = 0.2 s.
    #[test]
    fn converges_from_plus_50_percent() {
        let m = MachineParams::paper_table1();
        let ts = 200e-6;
        let cfg = RsEstimatorConfig::new(&m, ts, 0.2, 1.5);
        let mut est = RsEstimator::new(15.75);
        let (i_sd, i_sq, ws) = (1.5f32, 1.0f32, 2.0 * 52.36 + 10.0);
        // the true steady d-axis voltage
        let v_sd = 10.5 * i_sd - m.transient_inductance() * ws * i_sq;
        let u = RsEstimatorInputs {
            i_sd,
            i_sq,
            v_sd,
            stator_frequency: ws,
            flux_settled: true,
        };
        let mut t_reach = None;
        for k in 0..(2.0 / ts) as usize {
            let r = est.update(&cfg, &u);
            if t_reach.is_none() && (r - 10.5).abs() < 0.02 * 10.5 {
                t_reach = Some(k as f32 * ts);
            }
        }
        let t = t_reach.expect("never reached 2 %");
        assert!(t < 1.0, "took {t} s");
        assert!(
            (est.stator_resistance_estimate - 10.5).abs() < 0.01,
            "{}",
            est.stator_resistance_estimate
        );
        assert!(!est.at_bound);
    }

    /// The paper's printed sign (eq. 19: minus) diverges: checked by running the same loop
    /// with the sign flipped through a negative flux current's mirror image.
    #[test]
    fn printed_sign_would_diverge_and_gate_holds_estimate() {
        let m = MachineParams::paper_table1();
        let ts = 200e-6;
        let cfg = RsEstimatorConfig::new(&m, ts, 0.2, 1.5);
        // paper's law: Rs_hat -= alpha e Ts
        let (mut r, mut ih) = (15.75f32, 0.0f32);
        let v_sd = 10.5 * 1.5;
        for _ in 0..(2.0 / ts) as usize {
            let e = ih - 1.5;
            let di = cfg.ts_over_transient_inductance * (v_sd - r * ih);
            r = (r - cfg.alpha_ts * e).clamp(cfg.min_resistance, cfg.max_resistance);
            ih += di;
        }
        assert!(r >= cfg.max_resistance - 1e-3, "printed sign ended at {r}");

        // outside the gate (flux not settled) the estimate is held
        let mut est = RsEstimator::new(15.75);
        let u = RsEstimatorInputs {
            i_sd: 1.5,
            i_sq: 0.0,
            v_sd,
            stator_frequency: 0.0,
            flux_settled: false,
        };
        for _ in 0..5000 {
            est.update(&cfg, &u);
        }
        assert_eq!(est.stator_resistance_estimate, 15.75);
        assert!(!est.adapting);
        // negative flux current: the sign follows sign(i_sd)
        let mut est = RsEstimator::new(8.0);
        let u = RsEstimatorInputs {
            i_sd: -1.5,
            i_sq: 0.0,
            v_sd: -v_sd,
            stator_frequency: 0.0,
            flux_settled: true,
        };
        for _ in 0..10_000 {
            est.update(&cfg, &u);
        }
        assert!((est.stator_resistance_estimate - 10.5).abs() < 0.05);
    }

    #[test]
    fn clamps_and_survives_nan() {
        let m = MachineParams::paper_table1();
        let cfg = RsEstimatorConfig::new(&m, 200e-6, 0.2, 1.5);
        let mut est = RsEstimator::new(10.5);
        // a voltage implying 100 ohm drives it to the upper bound, not beyond
        let u = RsEstimatorInputs {
            i_sd: 1.5,
            i_sq: 0.0,
            v_sd: 150.0,
            stator_frequency: 0.0,
            flux_settled: true,
        };
        for _ in 0..50_000 {
            est.update(&cfg, &u);
        }
        assert!(est.at_bound);
        assert!(est.stator_resistance_estimate <= cfg.max_resistance);
        let u = RsEstimatorInputs {
            i_sd: f32::NAN,
            i_sq: 0.0,
            v_sd: f32::NAN,
            stator_frequency: 0.0,
            flux_settled: true,
        };
        let r = est.update(&cfg, &u);
        assert!(r.is_finite() && est.current_estimate.is_finite());
    }
}
