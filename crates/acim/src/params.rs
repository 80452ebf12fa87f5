//! Machine parameters (paper section 2b, Table 1) and the quantities derived from them.
//!
//! All values are SI: ohm, henry, kg m^2, N m s/rad. The derived quantities follow the
//! design notes (section 2): sigma = 1 - Lm^2/(Ls Lr), tau_r = Lr/Rr,
//! Rseq = Rs + (Lm/Lr)^2 Rr, and the inverse-Gamma magnetising inductance
//! L_M = (1 - sigma) Ls = Lm^2/Lr, which is the `(1 - sigma) Ls` of eqs. (4), (8), (13).

use crate::math::is_finite;
use crate::num::{Num, PerUnitBases, Units};

/// Why a set of machine parameters was rejected by [`MachineParams::new`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ParamError {
    /// A value that must be finite and strictly positive is not (the field is named).
    NotPositive(&'static str),
    /// A value that must be finite and non-negative is not (the field is named).
    Negative(&'static str),
    /// Lm^2 >= Ls Lr: the leakage factor sigma would be zero or negative, which no real
    /// machine has.
    NoLeakage,
    /// The pole-pair count must be between 1 and 32.
    PolePairs,
}

impl core::fmt::Display for ParamError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            ParamError::NotPositive(name) => {
                write!(f, "{name} must be finite and > 0")
            }
            ParamError::Negative(name) => write!(f, "{name} must be finite and >= 0"),
            ParamError::NoLeakage => {
                write!(f, "mutual inductance too large: need Lm^2 < Ls*Lr")
            }
            ParamError::PolePairs => write!(f, "pole_pairs must be in 1..=32"),
        }
    }
}

/// Electrical and mechanical parameters of an induction machine (paper Table 1, eq. 1-3).
///
/// Construct with [`MachineParams::new`], which validates them; the fields are read-only
/// through accessors so that a validated value cannot be made non-physical afterwards.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct MachineParams {
    stator_resistance: f32,
    rotor_resistance: f32,
    stator_inductance: f32,
    rotor_inductance: f32,
    mutual_inductance: f32,
    pole_pairs: u8,
    inertia: f32,
    viscous_friction: f32,
}

/// Raw, unvalidated machine data: the argument of [`MachineParams::new`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MachineData {
    /// Stator resistance Rs, ohm.
    pub stator_resistance: f32,
    /// Rotor resistance Rr (referred to the stator), ohm.
    pub rotor_resistance: f32,
    /// Stator self-inductance Ls, H.
    pub stator_inductance: f32,
    /// Rotor self-inductance Lr, H.
    pub rotor_inductance: f32,
    /// Mutual inductance Lm, H.
    pub mutual_inductance: f32,
    /// Pole pairs p.
    pub pole_pairs: u8,
    /// Rotor plus load inertia J, kg m^2.
    pub inertia: f32,
    /// Viscous friction coefficient B, N m s/rad (may be zero).
    pub viscous_friction: f32,
}

/// A machine in inverse-Gamma form: the argument of [`MachineParams::from_inverse_gamma`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct InverseGamma {
    /// Stator resistance Rs, ohm.
    pub stator_resistance: f32,
    /// Rotor resistance R_R = Rr (Lm/Lr)^2, ohm.
    pub rotor_resistance: f32,
    /// Leakage inductance L_sigma = sigma Ls, H.
    pub leakage_inductance: f32,
    /// Magnetizing inductance L_M = Lm^2 / Lr, H.
    pub magnetizing_inductance: f32,
    /// Pole pairs p.
    pub pole_pairs: u8,
    /// Inertia J, kg m^2.
    pub inertia: f32,
    /// Viscous friction B, N m s/rad.
    pub viscous_friction: f32,
}

fn positive(v: f32, name: &'static str) -> Result<f32, ParamError> {
    if is_finite(v) && v > 0.0 {
        Ok(v)
    } else {
        Err(ParamError::NotPositive(name))
    }
}

impl MachineParams {
    /// Validates raw data: every value finite, resistances/inductances/inertia > 0,
    /// friction >= 0, 1 <= p <= 32 and Lm^2 < Ls Lr (sigma > 0).
    pub fn new(d: MachineData) -> Result<Self, ParamError> {
        let rs = positive(d.stator_resistance, "stator_resistance")?;
        let rr = positive(d.rotor_resistance, "rotor_resistance")?;
        let ls = positive(d.stator_inductance, "stator_inductance")?;
        let lr = positive(d.rotor_inductance, "rotor_inductance")?;
        let lm = positive(d.mutual_inductance, "mutual_inductance")?;
        let j = positive(d.inertia, "inertia")?;
        if !(is_finite(d.viscous_friction) && d.viscous_friction >= 0.0) {
            return Err(ParamError::Negative("viscous_friction"));
        }
        if d.pole_pairs == 0 || d.pole_pairs > 32 {
            return Err(ParamError::PolePairs);
        }
        // sigma must be clearly positive; a relative margin keeps 1/(sigma Ls) finite.
        if lm * lm >= ls * lr * (1.0 - 1e-6) {
            return Err(ParamError::NoLeakage);
        }
        Ok(Self {
            stator_resistance: rs,
            rotor_resistance: rr,
            stator_inductance: ls,
            rotor_inductance: lr,
            mutual_inductance: lm,
            pole_pairs: d.pole_pairs,
            inertia: j,
            viscous_friction: d.viscous_friction,
        })
    }

    /// The paper's Table 1 machine (750 W, 4 poles, 230 V, 3.3 A, 1500 rpm) with the
    /// project's documented mechanical defaults: J = [`DEFAULT_INERTIA`],
    /// B = [`DEFAULT_VISCOUS_FRICTION`] (the paper gives neither).
    pub fn paper_table1() -> Self {
        Self {
            stator_resistance: 10.5,
            rotor_resistance: 8.4,
            stator_inductance: 0.56,
            rotor_inductance: 0.56,
            mutual_inductance: 0.54,
            pole_pairs: 2,
            inertia: DEFAULT_INERTIA,
            viscous_friction: DEFAULT_VISCOUS_FRICTION,
        }
    }

    /// A machine given in the inverse-Gamma form the drive uses (Rs, R_R, L_sigma, L_M;
    /// what terminal measurements identify), as the exact T-model equivalent
    /// Ls = Lr = L_M + L_sigma, Lm = sqrt(L_M Lr), Rr = R_R Lr / L_M (terminal
    /// measurements cannot separate Ls from Lr; any split gives the same terminal
    /// behaviour).
    pub fn from_inverse_gamma(g: InverseGamma) -> Result<Self, ParamError> {
        let l_m = positive(g.magnetizing_inductance, "magnetizing_inductance")?;
        let l_s = positive(g.leakage_inductance, "leakage_inductance")?;
        let r_r = positive(g.rotor_resistance, "rotor_resistance")?;
        let l = l_m + l_s;
        Self::new(MachineData {
            stator_resistance: g.stator_resistance,
            rotor_resistance: r_r * l / l_m,
            stator_inductance: l,
            rotor_inductance: l,
            mutual_inductance: crate::math::sqrt(l_m * l),
            pole_pairs: g.pole_pairs,
            inertia: g.inertia,
            viscous_friction: g.viscous_friction,
        })
    }

    /// The raw data of these parameters, e.g. to change one field and re-validate.
    pub fn data(&self) -> MachineData {
        MachineData {
            stator_resistance: self.stator_resistance,
            rotor_resistance: self.rotor_resistance,
            stator_inductance: self.stator_inductance,
            rotor_inductance: self.rotor_inductance,
            mutual_inductance: self.mutual_inductance,
            pole_pairs: self.pole_pairs,
            inertia: self.inertia,
            viscous_friction: self.viscous_friction,
        }
    }

    /// Stator resistance Rs, ohm.
    pub fn stator_resistance(&self) -> f32 {
        self.stator_resistance
    }
    /// Rotor resistance Rr, ohm.
    pub fn rotor_resistance(&self) -> f32 {
        self.rotor_resistance
    }
    /// Stator inductance Ls, H.
    pub fn stator_inductance(&self) -> f32 {
        self.stator_inductance
    }
    /// Rotor inductance Lr, H.
    pub fn rotor_inductance(&self) -> f32 {
        self.rotor_inductance
    }
    /// Mutual inductance Lm, H.
    pub fn mutual_inductance(&self) -> f32 {
        self.mutual_inductance
    }
    /// Pole pairs p.
    pub fn pole_pairs(&self) -> u8 {
        self.pole_pairs
    }
    /// Pole pairs p as f32.
    pub fn pole_pairs_f32(&self) -> f32 {
        self.pole_pairs as f32
    }
    /// Inertia J, kg m^2.
    pub fn inertia(&self) -> f32 {
        self.inertia
    }
    /// Viscous friction B, N m s/rad.
    pub fn viscous_friction(&self) -> f32 {
        self.viscous_friction
    }

    /// Leakage factor sigma = 1 - Lm^2/(Ls Lr) (section 2b), dimensionless, in (0, 1).
    pub fn sigma(&self) -> f32 {
        1.0 - self.mutual_inductance * self.mutual_inductance
            / (self.stator_inductance * self.rotor_inductance)
    }
    /// Transient (leakage) inductance sigma Ls, H.
    pub fn transient_inductance(&self) -> f32 {
        self.sigma() * self.stator_inductance
    }
    /// Rotor time constant tau_r = Lr/Rr, s.
    pub fn rotor_time_constant(&self) -> f32 {
        self.rotor_inductance / self.rotor_resistance
    }
    /// Rotor resistance referred to the inverse-Gamma model, R_R = (Lm/Lr)^2 Rr, ohm.
    pub fn referred_rotor_resistance(&self) -> f32 {
        let k = self.mutual_inductance / self.rotor_inductance;
        k * k * self.rotor_resistance
    }
    /// Equivalent stator resistance Rseq = Rs + (Lm/Lr)^2 Rr (section 2b), ohm.
    pub fn equivalent_resistance(&self) -> f32 {
        self.stator_resistance + self.referred_rotor_resistance()
    }
    /// Inverse-Gamma magnetising inductance L_M = (1 - sigma) Ls = Lm^2/Lr, H:
    /// the factor of i_sd in the flux model (13) and of i_sq in the slip law (8).
    pub fn magnetizing_inductance(&self) -> f32 {
        self.mutual_inductance * self.mutual_inductance / self.rotor_inductance
    }
    /// Transient stator time constant sigma tau_s = sigma Ls / Rseq, s.
    pub fn transient_time_constant(&self) -> f32 {
        self.transient_inductance() / self.equivalent_resistance()
    }
    /// Steady rotor flux lambda_r (Wb, referred to the stator) produced by a d-axis
    /// current i_sd (A): lambda_r = L_M i_sd (eq. 13 at equilibrium).
    pub fn rotor_flux_for(&self, i_sd: f32) -> f32 {
        self.magnetizing_inductance() * i_sd
    }
    /// Torque constant at rotor flux `rotor_flux` (Wb): k_t = 1.5 p lambda_r, N m/A, so that
    /// Te = k_t i_sq in field orientation (eq. 3 with amplitude-invariant scaling).
    pub fn torque_constant(&self, rotor_flux: f32) -> f32 {
        1.5 * self.pole_pairs_f32() * rotor_flux
    }
}

/// Default inertia, kg m^2 (not given by the paper; the bench had variable inertia disks).
pub const DEFAULT_INERTIA: f32 = 0.01;
/// Default viscous friction, N m s/rad. With zero friction and zero load the scheme's
/// orientation is only neutrally stable (design notes).
pub const DEFAULT_VISCOUS_FRICTION: f32 = 2e-3;
/// Default DC-bus voltage, V (rectified 230 V mains).
pub const DEFAULT_DC_BUS: f32 = 325.0;
/// Default d-axis (flux) current reference, A peak.
pub const DEFAULT_FLUX_CURRENT: f32 = 1.5;
/// Default stator current limit, A peak (3.3 A rms rated current).
pub const DEFAULT_CURRENT_LIMIT: f32 = 4.67;
/// Default control (sampling and PWM) period, s: 5 kHz as in the paper.
pub const DEFAULT_CONTROL_PERIOD: f32 = 200e-6;

/// The machine model's constants the control step multiplies by (the inverse-Gamma
/// model, design notes section 1), designed once in SI ([`ModelGains::new`]) and
/// converted to the drive's arithmetic ([`ModelGains::convert`]).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ModelGains<N: Num = f32> {
    /// sigma Ls (L_sigma), H: (frequency x current) -> voltage.
    pub transient_inductance: N::Gain,
    /// Ts^2 / (12 sigma Ls), A / (rad/s x V): frequency -> admittance. The voltage is
    /// held constant in the stationary frame over each period (a staircase) while the
    /// machine's back-EMF turns smoothly, so the stator current carries a ripple that is
    /// quadratic in time within the period; sampled at the period boundary it reads
    /// Delta i = -j w_s Ts^2 v / (12 sigma Ls) away from the fundamental (the ripple's
    /// mean over the period is zero: sigma Ls d(Delta i)/dt = -j w_s (t - t_mid) v).
    /// Negligible at low frequency, it is 2 % of i_sd at twice base speed in field
    /// weakening (i_sd small, v large), where it made the flux model read 1 % high and
    /// the speed estimate 1.2 % low. The sense stage removes it.
    pub sample_ripple: N::Gain,
    /// R_R = (Lm/Lr)^2 Rr, ohm.
    pub referred_rotor_resistance: N,
    /// 1 / tau_r, 1/s: flux -> voltage (lambda_r / tau_r).
    pub inv_rotor_time_constant: N::Gain,
    /// p: mechanical speed -> electrical frequency.
    pub pole_pairs: N::Gain,
    /// p: (speed x flux) -> voltage (the back-EMF p Omega lambda_r).
    pub back_emf: N::Gain,
    /// 1.5 p: (flux x current) -> torque (Te = 1.5 p lambda_r i_sq).
    pub torque_factor: N::Gain,
}

impl ModelGains<f32> {
    /// The gains of machine `m` at the control period `ts` (s).
    pub fn new(m: &MachineParams, ts: f32) -> Self {
        let pp = m.pole_pairs_f32();
        Self {
            transient_inductance: m.transient_inductance(),
            sample_ripple: ts * ts / (12.0 * m.transient_inductance()),
            referred_rotor_resistance: m.referred_rotor_resistance(),
            inv_rotor_time_constant: 1.0 / m.rotor_time_constant(),
            pole_pairs: pp,
            back_emf: pp,
            torque_factor: 1.5 * pp,
        }
    }

    /// These gains in the arithmetic `N` with the bases `b`; `None` if one is not
    /// representable.
    pub fn convert<N: Num + Units>(&self, b: &PerUnitBases) -> Option<ModelGains<N>> {
        let g = N::gain_from_f32;
        Some(ModelGains {
            transient_inductance: g(
                self.transient_inductance * b.frequency * b.current / b.voltage
            )?,
            sample_ripple: g(self.sample_ripple * b.frequency * b.voltage / b.current)?,
            referred_rotor_resistance: N::checked_from_f32(
                self.referred_rotor_resistance / b.resistance(),
            )?,
            inv_rotor_time_constant: g(self.inv_rotor_time_constant * b.flux / b.voltage)?,
            pole_pairs: g(self.pole_pairs * b.speed / b.frequency)?,
            back_emf: g(self.back_emf * b.speed * b.flux / b.voltage)?,
            torque_factor: g(self.torque_factor * b.flux * b.current / b.torque)?,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: f32, b: f32, rel: f32) -> bool {
        (a - b).abs() <= rel * b.abs()
    }

    #[test]
    fn table1_derived_values_match_design_notes() {
        let m = MachineParams::paper_table1();
        // design notes section 4: L_M = 0.52071 H, sigma Ls = 0.03929 H, R_R = 7.8107 ohm
        assert!(close(m.magnetizing_inductance(), 0.52071, 1e-4));
        assert!(close(m.transient_inductance(), 0.03929, 1e-3));
        assert!(close(m.referred_rotor_resistance(), 7.8107, 1e-4));
        assert!(close(m.equivalent_resistance(), 18.3107, 1e-4));
        assert!(close(m.rotor_time_constant(), 0.0666667, 1e-4));
        assert!(close(m.sigma(), 1.0 - 0.54 * 0.54 / (0.56 * 0.56), 1e-5));
        assert!(close(m.torque_constant(1.0), 3.0, 1e-6));
        assert_eq!(MachineParams::new(m.data()), Ok(m));
    }

    #[test]
    fn rejects_non_physical_input() {
        let base = MachineParams::paper_table1().data();
        let mut d = base;
        d.stator_resistance = 0.0;
        assert_eq!(
            MachineParams::new(d),
            Err(ParamError::NotPositive("stator_resistance"))
        );
        d = base;
        d.rotor_inductance = f32::NAN;
        assert_eq!(
            MachineParams::new(d),
            Err(ParamError::NotPositive("rotor_inductance"))
        );
        d = base;
        d.inertia = f32::INFINITY;
        assert_eq!(
            MachineParams::new(d),
            Err(ParamError::NotPositive("inertia"))
        );
        d = base;
        d.viscous_friction = -1e-3;
        assert_eq!(
            MachineParams::new(d),
            Err(ParamError::Negative("viscous_friction"))
        );
        d = base;
        d.mutual_inductance = 0.56;
        assert_eq!(MachineParams::new(d), Err(ParamError::NoLeakage));
        d = base;
        d.pole_pairs = 0;
        assert_eq!(MachineParams::new(d), Err(ParamError::PolePairs));
        d = base;
        d.viscous_friction = 0.0;
        assert!(MachineParams::new(d).is_ok());
    }
}
