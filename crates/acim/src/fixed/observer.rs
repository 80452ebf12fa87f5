//! Reduced-order observer of i_sq, speed and load torque (eq. 12, gains by pole placement
//! on eq. 14) in Q7.24: the structure of [`crate::observer`] term for term, its
//! coefficients (already multiplied by Ts) converted from [`ObserverConfig`].
//!
//! One forward-Euler step, e = i_sq_hat - i_sq:
//!
//! ```text
//! di = Ts a e + Ts/(sigma Ls) (v_sq - Rseq i_sq) - Ts p/(sigma Ls) lambda Omega_hat - Ts w_s i_sd
//! dW = Ts 1.5p/J lambda i_sq - Ts/J T_hat - Ts B/J Omega_hat + Ts g2 (e/lambda)
//! dT = Ts g3 (e/lambda)
//! ```
//!
//! K2 = g2/lambda - (1.5 p/J) lambda and K3 = g3/lambda follow the flux through
//! 1/lambda_r from the flux model, so the poles stay placed at every flux level. Per unit:
//! currents of I_base, speed of Omega_base (mechanical), load of T_base, voltage of
//! V_base, Rseq of R_base = V_base/I_base (so Rseq i_sq is volts pu), flux of lambda_base,
//! w_s of the electrical frequency base. Eleven multiplies of 32x32->64 bits, no division.

use super::q::{mul, Gain};
use super::PerUnitBases;
use crate::observer::ObserverConfig;

/// Observer coefficients in per unit (all include Ts).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FixedObserverConfig {
    /// Ts a, dimensionless (current error -> current).
    pub ts_a: Gain,
    /// Ts/(sigma Ls) V_base/I_base: volts pu -> current pu.
    pub ts_inv_l: Gain,
    /// Ts p/(sigma Ls) lambda_base Omega_base/I_base: (flux pu x speed pu) -> current pu.
    pub ts_p_inv_l: Gain,
    /// Ts w_base: (frequency pu x current pu) -> current pu.
    pub ts_frequency: Gain,
    /// Ts 1.5 p/J lambda_base I_base/Omega_base: (flux pu x current pu) -> speed pu.
    pub ts_torque_per_inertia: Gain,
    /// Ts/J T_base/Omega_base: torque pu -> speed pu.
    pub ts_inv_inertia: Gain,
    /// Ts B/J, dimensionless (speed -> speed).
    pub ts_friction_rate: Gain,
    /// Ts g2 I_base/(lambda_base Omega_base): (current pu / flux pu) -> speed pu.
    pub ts_g2: Gain,
    /// Ts g3 I_base/(lambda_base T_base): (current pu / flux pu) -> torque pu.
    pub ts_g3: Gain,
}

impl FixedObserverConfig {
    /// Converts the f32 design `cfg` with `bases`; `None` if a coefficient is not
    /// representable.
    pub fn from_f32(cfg: &ObserverConfig, bases: &PerUnitBases) -> Option<Self> {
        let ts = cfg.ts;
        let b = bases;
        let g = Gain::from_f32;
        Some(Self {
            ts_a: g(ts * cfg.a)?,
            ts_inv_l: g(ts * cfg.inv_transient_inductance * b.voltage / b.current)?,
            ts_p_inv_l: g(
                ts * cfg.pole_pairs * cfg.inv_transient_inductance * b.flux * b.speed / b.current,
            )?,
            ts_frequency: g(ts * b.frequency)?,
            ts_torque_per_inertia: g(ts * cfg.torque_per_inertia * b.flux * b.current / b.speed)?,
            ts_inv_inertia: g(ts * cfg.inv_inertia * b.torque / b.speed)?,
            ts_friction_rate: g(ts * cfg.friction_rate)?,
            ts_g2: g(ts * cfg.g2 * b.current / (b.flux * b.speed))?,
            ts_g3: g(ts * cfg.g3 * b.current / (b.flux * b.torque))?,
        })
    }
}

/// Inputs of one observer step, Q7.24 pu.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FixedObserverInputs {
    /// Measured i_sq, current pu.
    pub i_sq: i32,
    /// Measured i_sd, current pu.
    pub i_sd: i32,
    /// Stator frequency w_s, electrical frequency pu.
    pub stator_frequency: i32,
    /// q voltage applied over the period, voltage pu.
    pub v_sq: i32,
    /// Rotor flux lambda_r, flux pu.
    pub rotor_flux: i32,
    /// 1/lambda_r (guarded), per flux pu.
    pub inv_rotor_flux: i32,
    /// Rseq = Rs_hat + R_R, resistance pu.
    pub equivalent_resistance: i32,
}

/// Observer state, Q7.24 pu.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FixedObserver {
    /// i_sq_hat, current pu.
    pub current_estimate: i32,
    /// Omega_hat, mechanical speed pu.
    pub speed_estimate: i32,
    /// T_L_hat, torque pu.
    pub load_torque_estimate: i32,
}

impl FixedObserver {
    /// All estimates zero.
    pub const fn new() -> Self {
        Self {
            current_estimate: 0,
            speed_estimate: 0,
            load_torque_estimate: 0,
        }
    }

    /// Restarts from a known state (Q7.24 pu).
    pub fn reset(&mut self, i_sq: i32, speed: i32, load_torque: i32) {
        self.current_estimate = i_sq;
        self.speed_estimate = speed;
        self.load_torque_estimate = load_torque;
    }

    /// One forward-Euler step of eq. (12) (see the module docs).
    #[inline(always)]
    pub fn update(&mut self, cfg: &FixedObserverConfig, u: &FixedObserverInputs) {
        let e = self.current_estimate.saturating_sub(u.i_sq);
        let lambda = u.rotor_flux;
        let w = self.speed_estimate;
        let resistive = u.v_sq.saturating_sub(mul(u.equivalent_resistance, u.i_sq));
        let di = cfg
            .ts_a
            .apply(e)
            .saturating_add(cfg.ts_inv_l.apply(resistive))
            .saturating_sub(cfg.ts_p_inv_l.apply(mul(lambda, w)))
            .saturating_sub(cfg.ts_frequency.apply(mul(u.stator_frequency, u.i_sd)));
        let e_per_flux = mul(u.inv_rotor_flux, e);
        let dw = cfg
            .ts_torque_per_inertia
            .apply(mul(lambda, u.i_sq))
            .saturating_sub(cfg.ts_inv_inertia.apply(self.load_torque_estimate))
            .saturating_sub(cfg.ts_friction_rate.apply(w))
            .saturating_add(cfg.ts_g2.apply(e_per_flux));
        let dt = cfg.ts_g3.apply(e_per_flux);
        self.current_estimate = self.current_estimate.saturating_add(di);
        self.speed_estimate = w.saturating_add(dw);
        self.load_torque_estimate = self.load_torque_estimate.saturating_add(dt);
    }
}
