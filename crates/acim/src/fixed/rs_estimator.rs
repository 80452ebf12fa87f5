//! Online stator-resistance estimator (eq. 19-20, sign corrected as in
//! [`crate::rs_estimator`]) in Q7.24, converted from [`RsEstimatorConfig`].
//!
//! Current model (eq. 20): sigma Ls d i_sd_hat/dt = v_sd - Rs_hat i_sd_hat plus
//! sigma Ls w_s i_sq. Adaptation (corrected eq. 19): Rs_hat += alpha Ts sign(i_sd) e,
//! e = i_sd_hat - i_sd, only inside the gate (adaptation enabled, flux settled,
//! |i_sd| >= min, |i_sq| <= max, |w_s| <= max), clamped to [min, max] with the bound
//! reported. Units: Rs_hat in Q7.24 of R_base = V_base/I_base (10.5 ohm = 0.2625 pu),
//! currents of I_base, v_sd of V_base, w_s of the electrical frequency base.
//!
//! Resolution: the adaptation integrates in Q1.30 (6 more fraction bits than the Q7.24
//! output, range [-2, 2) pu = +/-80 ohm; the configuration keeps the clamp band below
//! that), so it stops moving only once alpha Ts |e| < 1/2 LSB of Q1.30, i.e.
//! |e| < 2.7e-6 A: an Rs error below 3e-5 ohm. (Integrating in Q7.24 would stop at
//! |e| = 1.7e-4 A, 1.8e-3 ohm at 15.75 ohm.)

use super::q::{clamp, mul, to_q24, Gain};
use super::PerUnitBases;
use crate::rs_estimator::RsEstimatorConfig;

/// 2^6: Q1.30 over Q7.24.
const EXTRA: f32 = 64.0;
/// Bits between Q1.30 and Q7.24.
const EXTRA_BITS: u32 = 6;

/// f32 pu to Q1.30 if |x| < 2 (configuration only).
fn to_q30(x: f32) -> Option<i32> {
    if crate::math::is_finite(x) && x.abs() < 1.99 {
        Some(to_q24(x * EXTRA))
    } else {
        None
    }
}

/// Estimator coefficients and gate in per unit.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FixedRsConfig {
    /// Ts/(sigma Ls) V_base/I_base: volts pu -> current pu.
    pub ts_over_transient_inductance: Gain,
    /// Ts w_base: (frequency pu x current pu) -> current pu.
    pub ts_frequency: Gain,
    /// alpha Ts I_base/R_base 2^6: current pu (Q7.24) -> resistance pu per step in Q1.30.
    pub alpha_ts_q30: Gain,
    /// Lower clamp, resistance pu in Q1.30.
    pub min_resistance_q30: i32,
    /// Upper clamp, resistance pu in Q1.30.
    pub max_resistance_q30: i32,
    /// Gate: |i_sd| at least this, current pu.
    pub min_flux_current: i32,
    /// Gate: |i_sq| at most this, current pu.
    pub max_torque_current: i32,
    /// Gate: |w_s| at most this, frequency pu.
    pub max_stator_frequency: i32,
    /// Whether the resistance adapts (the current model always runs).
    pub adapt: bool,
}

impl FixedRsConfig {
    /// Converts `cfg` with `bases`; `None` if a coefficient is not representable.
    pub fn from_f32(cfg: &RsEstimatorConfig, bases: &PerUnitBases) -> Option<Self> {
        let r_base = bases.resistance();
        Some(Self {
            ts_over_transient_inductance: Gain::from_f32(
                cfg.ts_over_transient_inductance * bases.voltage / bases.current,
            )?,
            ts_frequency: Gain::from_f32(cfg.ts * bases.frequency)?,
            alpha_ts_q30: Gain::from_f32(cfg.alpha_ts * bases.current / r_base * EXTRA)?,
            min_resistance_q30: to_q30(cfg.min_resistance / r_base)?,
            max_resistance_q30: to_q30(cfg.max_resistance / r_base)?,
            min_flux_current: to_q24(cfg.min_flux_current / bases.current),
            max_torque_current: to_q24(cfg.max_torque_current / bases.current),
            max_stator_frequency: to_q24(cfg.max_stator_frequency / bases.frequency),
            adapt: cfg.adapt,
        })
    }
}

/// Inputs of one estimator step, Q7.24 pu.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FixedRsInputs {
    /// Measured i_sd, current pu.
    pub i_sd: i32,
    /// Measured i_sq, current pu.
    pub i_sq: i32,
    /// Commanded v_sd over the period, voltage pu.
    pub v_sd: i32,
    /// Stator frequency w_s, frequency pu.
    pub stator_frequency: i32,
    /// Flux within tolerance of its reference.
    pub flux_settled: bool,
}

/// Estimator state.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FixedRsEstimator {
    /// Rs_hat, resistance pu in Q1.30 (the integrator).
    resistance_q30: i32,
    /// Rs_hat, resistance pu (Q7.24, rounded from the integrator).
    pub stator_resistance_estimate: i32,
    /// i_sd_hat of eq. (20), current pu.
    pub current_estimate: i32,
    /// Whether the last step adapted.
    pub adapting: bool,
    /// i_sd_hat - i_sd at the last step, current pu.
    pub current_error: i32,
    /// Whether the estimate sits at a clamp bound.
    pub at_bound: bool,
}

impl FixedRsEstimator {
    /// Starts from `r0` (resistance pu, Q7.24; at most 2 pu).
    pub const fn new(r0: i32) -> Self {
        let r0 = if r0 > (1 << 25) - 1 {
            (1 << 25) - 1
        } else if r0 < -(1 << 25) {
            -(1 << 25)
        } else {
            r0
        };
        Self {
            resistance_q30: r0 << EXTRA_BITS,
            stator_resistance_estimate: r0,
            current_estimate: 0,
            adapting: false,
            current_error: 0,
            at_bound: false,
        }
    }

    /// One step: the gated adaptation (corrected eq. 19), then the Euler update of eq. (20)
    /// with the resistance of the start of the step (as in f32). Returns Rs_hat.
    #[inline]
    pub fn update(&mut self, cfg: &FixedRsConfig, u: &FixedRsInputs) -> i32 {
        let rs = self.stator_resistance_estimate;
        let e = self.current_estimate.saturating_sub(u.i_sd);
        self.current_error = e;
        self.adapting = cfg.adapt
            && u.flux_settled
            && u.i_sd.saturating_abs() >= cfg.min_flux_current
            && u.i_sq.saturating_abs() <= cfg.max_torque_current
            && u.stator_frequency.saturating_abs() <= cfg.max_stator_frequency;
        if self.adapting {
            let step = cfg.alpha_ts_q30.apply(e);
            let signed = if u.i_sd >= 0 {
                step
            } else {
                0i32.saturating_sub(step)
            };
            let next = clamp(
                self.resistance_q30.saturating_add(signed),
                cfg.min_resistance_q30,
                cfg.max_resistance_q30,
            );
            self.at_bound = next <= cfg.min_resistance_q30 || next >= cfg.max_resistance_q30;
            self.resistance_q30 = next;
            // to Q7.24, rounded (|next| < 2^31 - 2^5: no overflow)
            self.stator_resistance_estimate =
                next.saturating_add(1 << (EXTRA_BITS - 1)) >> EXTRA_BITS;
        }
        let resistive = u.v_sd.saturating_sub(mul(rs, self.current_estimate));
        let di = cfg
            .ts_over_transient_inductance
            .apply(resistive)
            .saturating_add(cfg.ts_frequency.apply(mul(u.stator_frequency, u.i_sq)));
        self.current_estimate = self.current_estimate.saturating_add(di);
        self.stator_resistance_estimate
    }
}
