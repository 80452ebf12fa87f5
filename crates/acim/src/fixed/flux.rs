//! Rotor-flux model (eq. 13), slip law and frame angle (eq. 8) in Q7.24, converted from
//! [`crate::flux::FluxModelConfig`].
//!
//! Eq. (13), exact for a constant i_sd over a period:
//! lambda\[k+1\] = lambda\[k\] + g (L_M i_sd - lambda\[k\]), g = 1 - e^(-Ts/tau_r).
//! Eq. (8): w_s = p Omega + (L_M/tau_r) i_sq / lambda_r, theta_s\[k+1\] = theta_s\[k\] + w_s Ts.
//! The divisor is max(lambda_r, lambda_min) (lambda_min = 10 % of nominal, as in f32) and
//! 1/lambda_r comes from [`super::q::reciprocal`] (relative error ~1e-8). Units: flux in
//! Q7.24 of the flux base, currents of the current base, frequencies of the electrical
//! frequency base; the angle is a wrapping turn fraction ([`super::trig::Angle`]).
//!
//! Resolution: the flux update stops moving once g |L_M i_sd - lambda| < 1/2 LSB, i.e.
//! within 1/(2g) = 167 LSB = 1.0e-5 pu of its target (f32: 2e-5 Wb).

use super::q::{mul, reciprocal, to_q24, Gain, FRAC_BITS};
use super::trig::Angle;
use super::PerUnitBases;
use crate::flux::FluxModelConfig;

/// Flux-model and slip-law coefficients in per unit.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FixedFluxConfig {
    /// g = 1 - e^(-Ts/tau_r), dimensionless.
    pub blend: Gain,
    /// L_M: current pu -> flux pu (L_M I_base / lambda_base).
    pub magnetizing_inductance: Gain,
    /// Slip gain L_M/tau_r: (i_sq pu x 1/lambda pu) -> frequency pu
    /// (R_R I_base / (lambda_base w_base)).
    pub slip_gain: Gain,
    /// Smallest flux used as a divisor, Q7.24 flux pu.
    pub min_flux: i32,
    /// Angle counts per step per frequency pu, as a gain on the Q7.24 frequency:
    /// w_base Ts 2^32 / (2 pi) / 2^24.
    pub angle_per_step: Gain,
}

impl FixedFluxConfig {
    /// Converts `cfg` with `bases`; `None` if a coefficient is not representable.
    pub fn from_f32(cfg: &FluxModelConfig, bases: &PerUnitBases) -> Option<Self> {
        Some(Self {
            blend: Gain::from_f32(cfg.blend)?,
            magnetizing_inductance: Gain::from_f32(
                cfg.magnetizing_inductance * bases.current / bases.flux,
            )?,
            slip_gain: Gain::from_f32(
                cfg.slip_gain * bases.current / (bases.flux * bases.frequency),
            )?,
            min_flux: to_q24(cfg.min_flux / bases.flux),
            angle_per_step: angle_gain(bases.frequency * cfg.ts)?,
        })
    }
}

/// Gain from a Q7.24 frequency (pu) to angle counts for an angle of `rad_per_pu` radians
/// per 1.0 pu.
pub(crate) fn angle_gain(rad_per_pu: f32) -> Option<Gain> {
    Gain::from_f32(rad_per_pu * super::trig::COUNTS_PER_RAD / (1u32 << FRAC_BITS) as f32)
}

/// Flux-model state.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FixedFluxModel {
    /// lambda_r, Q7.24 flux pu.
    pub rotor_flux: i32,
    /// 1 / max(lambda_r, lambda_min), Q7.24 per flux pu.
    pub inv_rotor_flux: i32,
    /// Slip frequency, Q7.24 frequency pu.
    pub slip_frequency: i32,
    /// Stator frequency w_s, Q7.24 frequency pu.
    pub stator_frequency: i32,
    /// Frame angle theta_s, turn fraction.
    pub angle: Angle,
}

impl FixedFluxModel {
    /// Zero flux, angle 0.
    pub const fn new() -> Self {
        Self {
            rotor_flux: 0,
            inv_rotor_flux: 0,
            slip_frequency: 0,
            stator_frequency: 0,
            angle: 0,
        }
    }

    /// One step (same order as [`crate::flux::FluxModel::update`]): slip from the present
    /// flux and i_sq (eq. 8), w_s = `rotor_speed_elec` + slip (both Q7.24 frequency pu)
    /// unless `hold_angle`, the angle advance, then the flux update (eq. 13) with i_sd.
    #[inline(always)]
    pub fn update(
        &mut self,
        cfg: &FixedFluxConfig,
        i_sd: i32,
        i_sq: i32,
        rotor_speed_elec: i32,
        hold_angle: bool,
    ) {
        let divisor = if self.rotor_flux > cfg.min_flux {
            self.rotor_flux
        } else {
            cfg.min_flux
        };
        self.inv_rotor_flux = reciprocal(divisor);
        self.slip_frequency = cfg.slip_gain.apply(mul(i_sq, self.inv_rotor_flux));
        self.stator_frequency = if hold_angle {
            0
        } else {
            rotor_speed_elec.saturating_add(self.slip_frequency)
        };
        // a signed increment added modulo one turn: the intended wrap of an angle
        let step = cfg.angle_per_step.apply(self.stator_frequency);
        self.angle = self.angle.wrapping_add(step as u32);
        let target = cfg.magnetizing_inductance.apply(i_sd);
        let delta = cfg.blend.apply(target.saturating_sub(self.rotor_flux));
        self.rotor_flux = self.rotor_flux.saturating_add(delta);
    }
}
