//! PI controller in Q7.24 (the current and speed regulators of paper Fig. 1 and 5): the
//! same form, limits and anti-windup as [`crate::pi`], gains converted from its
//! [`PiConfig`] design.
//!
//! `u[k] = clamp(ff + kp e[k] + I[k], lo, hi)`, `I[k] = I[k-1] + ki Ts e[k]` unless the
//! output is saturated and the error pushes further into the limit (conditional
//! integration); the integral itself stays inside [lo, hi]. Error and output are Q7.24 pu
//! of their own bases (current PIs: error in I_base, output in V_base; speed PI: error in
//! Omega_base, output in I_base); every sum saturates.

use super::q::{clamp, to_q24, Gain};
use crate::pi::PiConfig;

/// Gains and limits of one PI controller, converted from an f32 [`PiConfig`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FixedPiConfig {
    /// kp in output pu per error pu.
    pub kp: Gain,
    /// ki Ts in output pu per error pu per step.
    pub ki_ts: Gain,
    /// Lower output limit, Q7.24 output pu.
    pub out_min: i32,
    /// Upper output limit, Q7.24 output pu.
    pub out_max: i32,
}

impl FixedPiConfig {
    /// Converts `cfg` (SI) with the error's base `error_base` and the output's base
    /// `output_base` (SI units of 1 pu). `None` if a gain is not representable.
    pub fn from_f32(cfg: &PiConfig, error_base: f32, output_base: f32) -> Option<Self> {
        let k = error_base / output_base;
        Some(Self {
            kp: Gain::from_f32(cfg.kp * k)?,
            ki_ts: Gain::from_f32(cfg.ki_ts * k)?,
            out_min: to_q24(cfg.out_min / output_base),
            out_max: to_q24(cfg.out_max / output_base),
        })
    }
}

/// State of one fixed-point PI controller.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FixedPiController {
    integral: i32,
    saturated: bool,
}

impl FixedPiController {
    /// At rest (zero integral).
    pub const fn new() -> Self {
        Self {
            integral: 0,
            saturated: false,
        }
    }

    /// One step with the configured limits.
    #[inline(always)]
    pub fn update(&mut self, cfg: &FixedPiConfig, error: i32, feedforward: i32) -> i32 {
        self.update_with_limits(cfg, error, feedforward, cfg.out_min, cfg.out_max)
    }

    /// One step with limits for this step (`lo <= hi`). Returns
    /// `clamp(ff + kp e + I, lo, hi)`, Q7.24 output pu.
    #[inline(always)]
    pub fn update_with_limits(
        &mut self,
        cfg: &FixedPiConfig,
        error: i32,
        feedforward: i32,
        lo: i32,
        hi: i32,
    ) -> i32 {
        let p = cfg.kp.apply(error);
        let candidate = self.integral.saturating_add(cfg.ki_ts.apply(error));
        let unsat = feedforward.saturating_add(p).saturating_add(candidate);
        let out;
        if unsat > hi {
            out = hi;
            if error < 0 {
                self.integral = candidate;
            }
            self.saturated = true;
        } else if unsat < lo {
            out = lo;
            if error > 0 {
                self.integral = candidate;
            }
            self.saturated = true;
        } else {
            self.integral = candidate;
            out = unsat;
            self.saturated = false;
        }
        self.integral = clamp(self.integral, lo, hi);
        out
    }

    /// Resets the integral to zero.
    pub fn reset(&mut self) {
        *self = Self::new();
    }

    /// Present integral term, Q7.24 output pu.
    pub fn integral(&self) -> i32 {
        self.integral
    }

    /// Whether the last output was at a limit.
    pub fn saturated(&self) -> bool {
        self.saturated
    }
}
