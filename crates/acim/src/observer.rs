//! Reduced-order linear observer of q-axis current, rotor speed and load torque
//! (paper eq. 10-12), with gains by pole placement on the error dynamics (eq. 14).
//!
//! ## Model (re-derived with this library's conventions)
//!
//! In field orientation (eq. 9b, amplitude-invariant scaling, friction B kept apart from
//! the load):
//!
//! ```text
//! sigma Ls di_sq/dt = v_sq - Rseq i_sq - sigma Ls w_s i_sd - p lambda_r Omega
//! J dOmega/dt       = k_t i_sq - B Omega - T_L,          k_t = 1.5 p lambda_r
//! dT_L/dt           = 0                                   (eq. 10)
//! ```
//!
//! The observer (eq. 12) copies this model and adds K1, K2, K3 times the current error
//! e = i_sq_hat - i_sq. The error dynamics (eq. 14, with the 1.5 and the friction) are
//!
//! ```text
//! de/dt      = a e - b Omega~            a = -Rseq/(sigma Ls) + K1, b = p lambda_r/(sigma Ls)
//! dOmega~/dt = c e - f Omega~ - d T~     c = k_t/J + K2,  f = B/J,  d = 1/J
//! dT~/dt     = K3 e
//! ```
//!
//! with characteristic polynomial s^3 + (f - a) s^2 + (b c - a f) s - b d K3. Matching
//! (s + p1)(s + p2)(s + p3) = s^3 + c2 s^2 + c1 s + c0 gives, in closed form,
//!
//! ```text
//! a  = f - c2                     ->  K1 = a + Rseq/(sigma Ls)
//! c  = (c1 + a f)/b               ->  K2 = (c1 + a f) sigma Ls/(p lambda_r) - 1.5 p lambda_r/J
//! K3 = -c0 J/b                    ->  K3 = -c0 J sigma Ls/(p lambda_r)
//! ```
//!
//! (With B = 0 and no 1.5 this is the design notes' s^3 - a s^2 + b c s - b d K3.)
//!
//! ## Following the flux and the resistance cheaply
//!
//! b, K2 and K3 depend on lambda_r. The step receives 1/lambda_r, which the flux model
//! computes anyway for the slip law (eq. 8), so K2 = g2/lambda_r - (1.5 p/J) lambda_r and
//! K3 = g3/lambda_r cost three multiplications and the poles stay where they were placed
//! at every flux level. K1 enters only as K1 e - (Rseq/(sigma Ls)) i_sq_hat =
//! a e - (Rseq/(sigma Ls)) i_sq, so the step uses the measured i_sq in the resistive term
//! and an updated Rseq (from the stator-resistance estimator) needs no re-design.
//!
//! ## Discretisation
//!
//! Forward Euler at the control period Ts: the discrete error matrix is I + Ts A, whose
//! eigenvalues are 1 - Ts p_i. [`ObserverConfig::new`] therefore requires 0 < p_i Ts < 1
//! and [`ObserverConfig::discrete_stable`] checks the discrete characteristic polynomial
//! built from the actual gains with Jury's test.

use crate::frames::{AlphaBeta, Dq};
use crate::math::is_finite;
use crate::num::Num;
use crate::num::PerUnitBases;
use crate::num::Units;
use crate::params::MachineParams;

/// The three requested observer poles, given as positive rates p_i (rad/s): the
/// continuous error dynamics have eigenvalues -p1, -p2, -p3.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ObserverPoles {
    /// First pole rate, rad/s.
    pub p1: f32,
    /// Second pole rate, rad/s.
    pub p2: f32,
    /// Third pole rate, rad/s.
    pub p3: f32,
}

impl ObserverPoles {
    /// The project default: 120, 160 and 200 rad/s, several times faster than the speed
    /// loop and below the electrical pole Rseq/(sigma Ls) = 466 rad/s of Table 1, so the
    /// observer filters current noise and its Euler discretisation at 5 kHz is accurate
    /// (p Ts <= 0.04).
    pub const DEFAULT: Self = Self {
        p1: 120.0,
        p2: 160.0,
        p3: 200.0,
    };

    /// Coefficients (c2, c1, c0) of (s + p1)(s + p2)(s + p3) = s^3 + c2 s^2 + c1 s + c0.
    pub fn polynomial(&self) -> (f32, f32, f32) {
        let (p1, p2, p3) = (self.p1, self.p2, self.p3);
        (p1 + p2 + p3, p1 * p2 + p1 * p3 + p2 * p3, p1 * p2 * p3)
    }
}

/// Why an observer design was rejected.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ObserverDesignError {
    /// A pole rate is not finite and positive.
    PoleNotPositive,
    /// A pole rate times Ts is 1 or more: Euler at this period would not be accurate or
    /// stable.
    PoleTooFast,
    /// The control period is not finite and positive.
    BadPeriod,
}

/// Precomputed observer coefficients (configuration).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ObserverConfig {
    /// Control period Ts, s.
    pub ts: f32,
    /// 1/(sigma Ls), 1/H.
    pub inv_transient_inductance: f32,
    /// Pole pairs p.
    pub pole_pairs: f32,
    /// 1.5 p / J: torque per (flux x current) over inertia, 1/(kg m^2).
    pub torque_per_inertia: f32,
    /// 1/J, 1/(kg m^2).
    pub inv_inertia: f32,
    /// B/J, 1/s.
    pub friction_rate: f32,
    /// a = B/J - (p1 + p2 + p3), 1/s: the diagonal of the current-error dynamics.
    pub a: f32,
    /// K2 numerator: (c1 + a f) sigma Ls / p; K2 = g2/lambda_r - (1.5 p/J) lambda_r.
    pub g2: f32,
    /// K3 numerator: -c0 J sigma Ls / p; K3 = g3/lambda_r.
    pub g3: f32,
    /// The requested poles.
    pub poles: ObserverPoles,
    /// The coefficients of the step (all times Ts).
    pub coeffs: ObserverCoeffs<f32>,
}

/// The coefficients of one observer step (eq. 12), all multiplied by Ts; in fixed point
/// they also carry the per-unit base conversions (see [`crate::fixed`]).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ObserverCoeffs<N: Num = f32> {
    /// Ts a (current error -> current).
    pub ts_a: N::Gain,
    /// Ts/(sigma Ls): volts -> current.
    pub ts_inv_l: N::Gain,
    /// Ts p/(sigma Ls): (flux x speed) -> current.
    pub ts_p_inv_l: N::Gain,
    /// Ts: (stator frequency x current) -> current.
    pub ts: N::Gain,
    /// Ts 1.5 p/J: (flux x current) -> speed.
    pub ts_torque_per_inertia: N::Gain,
    /// Ts/J: torque -> speed.
    pub ts_inv_inertia: N::Gain,
    /// Ts B/J (speed -> speed).
    pub ts_friction_rate: N::Gain,
    /// Ts g2: (current / flux) -> speed.
    pub ts_g2: N::Gain,
    /// Ts g3: (current / flux) -> torque.
    pub ts_g3: N::Gain,
}

impl ObserverConfig {
    /// Designs the observer for the controller's machine model `m` (its J and B are the
    /// ones the observer assumes) at period `ts` (s).
    pub fn new(
        m: &MachineParams,
        poles: ObserverPoles,
        ts: f32,
    ) -> Result<Self, ObserverDesignError> {
        if !(is_finite(ts) && ts > 0.0) {
            return Err(ObserverDesignError::BadPeriod);
        }
        for p in [poles.p1, poles.p2, poles.p3] {
            if !(is_finite(p) && p > 0.0) {
                return Err(ObserverDesignError::PoleNotPositive);
            }
            if p * ts >= 1.0 {
                return Err(ObserverDesignError::PoleTooFast);
            }
        }
        let (c2, c1, c0) = poles.polynomial();
        let sigma_ls = m.transient_inductance();
        let pp = m.pole_pairs_f32();
        let j = m.inertia();
        let f = m.viscous_friction() / j;
        let a = f - c2;
        let g2 = (c1 + a * f) * sigma_ls / pp;
        let g3 = -c0 * j * sigma_ls / pp;
        Ok(Self {
            ts,
            inv_transient_inductance: 1.0 / sigma_ls,
            pole_pairs: pp,
            torque_per_inertia: 1.5 * pp / j,
            inv_inertia: 1.0 / j,
            friction_rate: f,
            a,
            g2,
            g3,
            poles,
            coeffs: ObserverCoeffs {
                ts_a: ts * a,
                ts_inv_l: ts / sigma_ls,
                ts_p_inv_l: ts * pp / sigma_ls,
                ts,
                ts_torque_per_inertia: ts * 1.5 * pp / j,
                ts_inv_inertia: ts / j,
                ts_friction_rate: ts * f,
                ts_g2: ts * g2,
                ts_g3: ts * g3,
            },
        })
    }

    /// Gains (K1, K2, K3) at rotor flux `rotor_flux` (Wb > 0) and equivalent resistance
    /// `equivalent_resistance` Rseq (ohm), in the paper's form (eq. 12). Units: 1/s, rad/(s^2 A), N m/(s A).
    pub fn gains(&self, rotor_flux: f32, equivalent_resistance: f32) -> (f32, f32, f32) {
        let inv = 1.0 / rotor_flux;
        (
            self.a + equivalent_resistance * self.inv_transient_inductance,
            self.g2 * inv - self.torque_per_inertia * rotor_flux,
            self.g3 * inv,
        )
    }

    /// Continuous error-dynamics characteristic polynomial (q2, q1, q0) of
    /// s^3 + q2 s^2 + q1 s + q0, rebuilt from the gains at `rotor_flux` (eq. 14).
    pub fn error_polynomial(&self, rotor_flux: f32, equivalent_resistance: f32) -> (f32, f32, f32) {
        let (k1, k2, k3) = self.gains(rotor_flux, equivalent_resistance);
        let a = -equivalent_resistance * self.inv_transient_inductance + k1;
        let b = self.pole_pairs * rotor_flux * self.inv_transient_inductance;
        let c = self.torque_per_inertia * rotor_flux + k2;
        let f = self.friction_rate;
        let d = self.inv_inertia;
        (f - a, b * c - a * f, -b * d * k3)
    }

    /// Discrete characteristic polynomial z^3 + a2 z^2 + a1 z + a0 of the Euler error
    /// matrix I + Ts A at `rotor_flux`, from the gains.
    pub fn discrete_polynomial(
        &self,
        rotor_flux: f32,
        equivalent_resistance: f32,
    ) -> (f32, f32, f32) {
        let (q2, q1, q0) = self.error_polynomial(rotor_flux, equivalent_resistance);
        let t = self.ts;
        (
            -3.0 + q2 * t,
            3.0 - 2.0 * q2 * t + q1 * t * t,
            -1.0 + q2 * t - q1 * t * t + q0 * t * t * t,
        )
    }

    /// Jury's stability test on the discrete error dynamics at `rotor_flux`: true when all
    /// three eigenvalues of I + Ts A lie strictly inside the unit circle.
    pub fn discrete_stable(&self, rotor_flux: f32, equivalent_resistance: f32) -> bool {
        let (a2, a1, a0) = self.discrete_polynomial(rotor_flux, equivalent_resistance);
        jury_cubic(a2, a1, a0)
    }
}

/// Jury's test for z^3 + a2 z^2 + a1 z + a0: all roots strictly inside the unit circle.
pub fn jury_cubic(a2: f32, a1: f32, a0: f32) -> bool {
    let p1 = 1.0 + a2 + a1 + a0;
    let pm1 = -1.0 + a2 - a1 + a0;
    p1 > 0.0 && pm1 < 0.0 && a0.abs() < 1.0 && (a0 * a0 - 1.0).abs() > (a0 * a2 - a1).abs()
}

/// Measured and model inputs of one observer step.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ObserverInputs<N = f32> {
    /// Measured i_sq, A.
    pub i_sq: N,
    /// Measured i_sd, A.
    pub i_sd: N,
    /// Stator frequency w_s (of the rotor-flux frame), rad/s electrical.
    pub stator_frequency: N,
    /// q voltage applied over the period, V.
    pub v_sq: N,
    /// Rotor flux lambda_r, Wb.
    pub rotor_flux: N,
    /// 1/lambda_r (guarded), 1/Wb.
    pub inv_rotor_flux: N,
    /// Rseq = Rs_hat + R_R, ohm.
    pub equivalent_resistance: N,
    /// Added to the q-axis error in the speed and load updates, A (far side).
    pub far_side_error: N,
}

/// Observer state: the estimates.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ReducedOrderObserver<N = f32> {
    /// i_sq_hat, A.
    pub current_estimate: N,
    /// Omega_hat, rad/s mechanical.
    pub speed_estimate: N,
    /// T_L_hat, N m.
    pub load_torque_estimate: N,
}

impl<N: Num> ReducedOrderObserver<N> {
    /// All estimates zero.
    pub fn new() -> Self {
        Self::default()
    }

    /// Restarts from a known state (e.g. after magnetizing: the measured i_sq, speed 0).
    pub fn reset(&mut self, i_sq: N, speed: N, load_torque: N) {
        self.current_estimate = i_sq;
        self.speed_estimate = speed;
        self.load_torque_estimate = load_torque;
    }

    /// One forward-Euler step of eq. (12), with Ts folded into the precomputed
    /// coefficients. About 20 multiply-adds, no division.
    #[inline(always)]
    pub fn update(&mut self, cfg: &ObserverCoeffs<N>, u: &ObserverInputs<N>) {
        let e = self.current_estimate - u.i_sq;
        let lambda = u.rotor_flux;
        let w = self.speed_estimate;
        // Ts [a e + (v_sq - Rseq i_sq - p lambda Omega_hat)/(sigma Ls) - w_s i_sd]
        let di = N::gain(cfg.ts_a, e)
            + N::gain(cfg.ts_inv_l, u.v_sq - u.equivalent_resistance * u.i_sq)
            - N::gain_mul(cfg.ts_p_inv_l, lambda, w)
            - N::gain_mul(cfg.ts, u.stator_frequency, u.i_sd);
        let e_per_flux = u.inv_rotor_flux * (e + u.far_side_error);
        // Ts [(1.5 p lambda i_hat - T_hat - B Omega_hat)/J + K2 e] with
        // K2 = g2/lambda - (1.5 p/J) lambda: the two torque terms combine to
        // (1.5 p lambda/J)(i_hat - e) = (1.5 p lambda/J) i_sq
        let dw = N::gain_mul(cfg.ts_torque_per_inertia, lambda, u.i_sq)
            - N::gain(cfg.ts_inv_inertia, self.load_torque_estimate)
            - N::gain(cfg.ts_friction_rate, w)
            + N::gain(cfg.ts_g2, e_per_flux);
        // Ts K3 e
        let dt = N::gain(cfg.ts_g3, e_per_flux);
        self.current_estimate = self.current_estimate + di;
        self.speed_estimate = w + dw;
        self.load_torque_estimate = self.load_torque_estimate + dt;
    }
}

/// What any speed observer may need from one step of the cascade (each implementation
/// reads its fields; all are computed by the cascade anyway). Voltages are those applied
/// over the past period (the previous step's command); flux quantities are the flux
/// model's state before this step's update.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SpeedObserverInputs<N = f32> {
    /// Measured stator current, stationary frame, A.
    pub i_ab: AlphaBeta<N>,
    /// Measured stator current, rotor-flux frame, A.
    pub i_dq: Dq<N>,
    /// Applied stator voltage, stationary frame, V.
    pub v_ab: AlphaBeta<N>,
    /// Applied stator voltage, rotor-flux frame, V.
    pub v_dq: Dq<N>,
    /// Stator frequency w_s of the frame, rad/s electrical.
    pub stator_frequency: N,
    /// Model rotor flux lambda_r, Wb.
    pub rotor_flux: N,
    /// 1 / max(lambda_r, guard), 1/Wb.
    pub inv_rotor_flux: N,
    /// Rseq = Rs_hat + R_R, ohm.
    pub equivalent_resistance: N,
    /// True while the drive builds the flux at standstill (frame held).
    pub magnetizing: bool,
    /// The frame is held at rest (magnetizing, no flying start), at the angle of
    /// `frame`: the rotor flux builds along it.
    pub frame_held: bool,
    /// sin/cos of the frame's angle at this sample.
    pub frame: crate::frames::SinCosValue<N>,
    /// Added to the q-axis error in the speed and load updates, A (far side).
    pub far_side_error: N,
}

/// What a speed observer gives the cascade.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SpeedEstimate<N = f32> {
    /// Omega_hat, rad/s mechanical.
    pub speed: N,
    /// T_L_hat, N m (0 for observers without a load model).
    pub load_torque: N,
    /// The observer's estimate of i_sq, A (the measured i_sq for observers without one).
    pub current: N,
}

/// The seam for the speed estimator of the cascade: the paper's reduced-order observer
/// ([`ReducedOrderObserver`]) and the full-order adaptive baseline
/// ([`crate::full_order::FullOrder`]) both implement it, and [`crate::Drive`] takes one
/// as a type parameter (zero cost in the interrupt: static dispatch, inlined).
pub trait SpeedObserver<N: Num = f32> {
    /// Whether the observer takes the far-side term (`SpeedObserverInputs::far_side_error`).
    /// The drive enters the far-side mode, which releases the regeneration limit, only
    /// with an observer that does: without the term nothing would hold the point beyond
    /// the unobservable line.
    fn far_side_term(&self) -> bool;
    /// Whether the drive corrects the rotor-flux model's frame with the d-axis residual
    /// (the orientation correction, [`crate::orientation`]): the paper's observer needs
    /// it; an observer that estimates the flux itself gives a speed that does not depend
    /// on the frame, and the correction would be a second, competing speed path.
    #[inline(always)]
    fn orientation_correction(&self) -> bool {
        true
    }
    /// Whether the drive applies its low-frequency regeneration limit
    /// ([`LoopSettings::regen_min_frequency`](crate::LoopSettings::regen_min_frequency)) with this observer: off for an
    /// observer whose gain is designed stable while regenerating near zero stator
    /// frequency.
    #[inline(always)]
    fn regeneration_limit(&self) -> bool {
        true
    }
    /// Whether the running Rs law adapts at any stator frequency above its low gate (the
    /// paper's observer, eq. 19-20), or only below
    /// [`crate::rs_estimator::RsRunningConfig::max_frequency`], where the resistive drop
    /// is observable against inductance errors (Rs/L_M).
    #[inline(always)]
    fn rs_running_at_speed(&self) -> bool {
        true
    }
    /// Whether the observer estimates the rotor-flux angle itself and the drive's frame
    /// follows it ([`SpeedObserver::frame_pull`]): the rotor-flux model's angle is then
    /// locked to the observer's, so that the model's own orientation errors (a speed
    /// estimate's lag through 1/tau_r, an R_R error) do not reach the field orientation.
    #[inline(always)]
    fn frame_lock(&self) -> bool {
        false
    }
    /// With [`SpeedObserver::frame_lock`]: the frequency (rad/s electrical) to add to the
    /// rotor-flux model's frame frequency so that it follows the observer's angle, given
    /// the model's frame at this sample (`model`), before this step's update.
    #[inline(always)]
    fn frame_pull(&self, model: &crate::frames::SinCosValue<N>) -> N {
        let _ = model;
        N::ZERO
    }
    /// One step. `coeffs` are the reduced-order observer's design (eq. 12, 14) built with
    /// the drive's; another observer holds its own design and may ignore them.
    fn update(
        &mut self,
        coeffs: &ObserverCoeffs<N>,
        x: &SpeedObserverInputs<N>,
    ) -> SpeedEstimate<N>;
    /// Back to the initial state (a start command).
    fn reset(&mut self);
    /// Called when magnetizing ends, with the measured i_sq: speed control starts from
    /// the speed the rotor turns at (0 at rest, the preset speed on a flying start).
    fn start_running(&mut self, i_sq: N);
    /// While magnetizing: the rotor turns at `speed` (rad/s), measured by the flying
    /// start's speed search ([`crate::speed_search`]); the estimate holds it until speed
    /// control starts.
    fn preset_speed(&mut self, speed: N);
    /// The last estimate.
    fn estimate(&self) -> SpeedEstimate<N>;
}

impl<N: Num> SpeedObserver<N> for ReducedOrderObserver<N> {
    #[inline(always)]
    fn far_side_term(&self) -> bool {
        true
    }
    /// Eq. (12); skipped while magnetizing (the observer assumes a settled flux, paper
    /// section 4).
    #[inline(always)]
    fn update(
        &mut self,
        coeffs: &ObserverCoeffs<N>,
        x: &SpeedObserverInputs<N>,
    ) -> SpeedEstimate<N> {
        if !x.magnetizing {
            ReducedOrderObserver::update(
                self,
                coeffs,
                &ObserverInputs {
                    i_sq: x.i_dq.q,
                    i_sd: x.i_dq.d,
                    stator_frequency: x.stator_frequency,
                    v_sq: x.v_dq.q,
                    rotor_flux: x.rotor_flux,
                    inv_rotor_flux: x.inv_rotor_flux,
                    equivalent_resistance: x.equivalent_resistance,
                    far_side_error: x.far_side_error,
                },
            );
        } else {
            // magnetizing: marked cold, the running periods fall through
            core::hint::cold_path();
        }
        SpeedObserver::estimate(self)
    }
    fn reset(&mut self) {
        *self = Self::new();
    }
    #[inline(always)]
    fn start_running(&mut self, i_sq: N) {
        ReducedOrderObserver::reset(self, i_sq, self.speed_estimate, N::ZERO);
    }
    #[inline(always)]
    fn preset_speed(&mut self, speed: N) {
        self.speed_estimate = speed;
    }
    #[inline(always)]
    fn estimate(&self) -> SpeedEstimate<N> {
        SpeedEstimate {
            speed: self.speed_estimate,
            load_torque: self.load_torque_estimate,
            current: self.current_estimate,
        }
    }
}

impl ObserverConfig {
    /// The step's coefficients (eq. 12, [`ObserverConfig::coeffs`]) in the arithmetic `N`
    /// with the bases `b`: currents of I_base, speed of Omega_base (mechanical), load of
    /// T_base, voltage of V_base, flux of lambda_base, w_s of the electrical frequency
    /// base. `None` if a gain is not representable.
    pub fn convert<N: Num + Units>(&self, b: &PerUnitBases) -> Option<ObserverCoeffs<N>> {
        let c = &self.coeffs;
        let g = N::gain_from_f32;
        Some(ObserverCoeffs {
            ts_a: g(c.ts_a)?,
            ts_inv_l: g(c.ts_inv_l * b.voltage / b.current)?,
            ts_p_inv_l: g(c.ts_p_inv_l * b.flux * b.speed / b.current)?,
            ts: g(c.ts * b.frequency)?,
            ts_torque_per_inertia: g(c.ts_torque_per_inertia * b.flux * b.current / b.speed)?,
            ts_inv_inertia: g(c.ts_inv_inertia * b.torque / b.speed)?,
            ts_friction_rate: g(c.ts_friction_rate)?,
            ts_g2: g(c.ts_g2 * b.current / (b.flux * b.speed))?,
            ts_g3: g(c.ts_g3 * b.current / (b.flux * b.torque))?,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn cfg() -> (MachineParams, ObserverConfig) {
        let m = MachineParams::paper_table1();
        let c = ObserverConfig::new(&m, ObserverPoles::DEFAULT, 200e-6).unwrap();
        (m, c)
    }

    #[test]
    fn rejects_bad_designs() {
        let m = MachineParams::paper_table1();
        let mut p = ObserverPoles::DEFAULT;
        p.p2 = -1.0;
        assert_eq!(
            ObserverConfig::new(&m, p, 200e-6),
            Err(ObserverDesignError::PoleNotPositive)
        );
        p.p2 = 6000.0;
        assert_eq!(
            ObserverConfig::new(&m, p, 200e-6),
            Err(ObserverDesignError::PoleTooFast)
        );
        assert_eq!(
            ObserverConfig::new(&m, ObserverPoles::DEFAULT, 0.0),
            Err(ObserverDesignError::BadPeriod)
        );
    }

    /// The far-side term enters the speed and load updates as an
    /// addition to the q-axis error, and not the current model: one step with
    /// `far_side_error` x moves Omega_hat and T_L_hat as one with the current estimate x
    /// higher would, and leaves i_sq_hat's update alone.
    #[test]
    fn far_side_error_enters_the_speed_and_load_updates_only() {
        let (m, c) = cfg();
        let lambda = m.rotor_flux_for(1.5);
        let u = ObserverInputs {
            i_sq: 1.0,
            i_sd: 1.5,
            stator_frequency: -6.0,
            v_sq: 20.0,
            rotor_flux: lambda,
            inv_rotor_flux: 1.0 / lambda,
            equivalent_resistance: m.equivalent_resistance(),
            far_side_error: 0.0,
        };
        let start = |i: f32| {
            let mut o = ReducedOrderObserver::new();
            o.reset(i, 10.0, -2.0);
            o
        };
        let x = 0.05;
        let (mut plain, mut far, mut shifted) = (start(1.0), start(1.0), start(1.0 + x));
        plain.update(&c.coeffs, &u);
        far.update(
            &c.coeffs,
            &ObserverInputs {
                far_side_error: x,
                ..u
            },
        );
        shifted.update(&c.coeffs, &u);
        assert_eq!(far.current_estimate, plain.current_estimate);
        assert!((far.speed_estimate - shifted.speed_estimate).abs() < 1e-4);
        assert!((far.load_torque_estimate - shifted.load_torque_estimate).abs() < 1e-5);
        assert!((far.speed_estimate - plain.speed_estimate).abs() > 1e-3);
    }

    /// The plant (9b)+(10) accelerating under a constant torque current against a load:
    /// with exact parameters the estimates lock onto the moving speed and the load.
    #[test]
    fn tracks_an_accelerating_machine() {
        let (m, c) = cfg();
        let lambda = m.rotor_flux_for(1.5);
        let equivalent_resistance = m.equivalent_resistance();
        let sl = m.transient_inductance();
        let ts = 200e-6;
        let (i_sq, i_sd, tl) = (2.0f32, 1.5f32, 1.2f32);
        let mut w = 0.0f32;
        let mut obs = ReducedOrderObserver::new();
        for _ in 0..(0.3 / ts) as usize {
            let ws = 2.0 * w + m.referred_rotor_resistance() * i_sq / lambda;
            // the voltage that holds di_sq/dt = 0 in eq. (9b)
            let v = equivalent_resistance * i_sq + sl * ws * i_sd + 2.0 * lambda * w;
            obs.update(
                &c.coeffs,
                &ObserverInputs {
                    i_sq,
                    i_sd,
                    stator_frequency: ws,
                    v_sq: v,
                    rotor_flux: lambda,
                    inv_rotor_flux: 1.0 / lambda,
                    equivalent_resistance,
                    far_side_error: 0.0,
                },
            );
            let te = m.torque_constant(lambda) * i_sq;
            w += ts * (te - m.viscous_friction() * w - tl) / m.inertia();
        }
        assert!(w > 50.0, "plant should accelerate, w = {w}");
        assert!(
            (obs.speed_estimate - w).abs() < 0.05,
            "{} vs {w}",
            obs.speed_estimate
        );
        assert!(
            (obs.load_torque_estimate - tl).abs() < 0.01,
            "{}",
            obs.load_torque_estimate
        );
    }

    #[test]
    fn default_design_is_discrete_stable_and_places_poles() {
        let (m, c) = cfg();
        let equivalent_resistance = m.equivalent_resistance();
        let (c2, c1, c0) = ObserverPoles::DEFAULT.polynomial();
        let (q2, q1, q0) = c.error_polynomial(m.rotor_flux_for(1.5), equivalent_resistance);
        assert!((q2 - c2).abs() < 1e-3 * c2);
        assert!((q1 - c1).abs() < 1e-3 * c1);
        assert!((q0 - c0).abs() < 1e-3 * c0);
        assert!(c.discrete_stable(m.rotor_flux_for(1.5), equivalent_resistance));
    }

    #[test]
    fn jury_matches_known_polynomials() {
        // (z - 0.5)(z - 0.2)(z + 0.3): stable
        let (r1, r2, r3) = (0.5f32, 0.2f32, -0.3f32);
        let a2 = -(r1 + r2 + r3);
        let a1 = r1 * r2 + r1 * r3 + r2 * r3;
        let a0 = -r1 * r2 * r3;
        assert!(jury_cubic(a2, a1, a0));
        // (z - 1.1)(z - 0.2)(z - 0.1): unstable
        let (r1, r2, r3) = (1.1f32, 0.2f32, 0.1f32);
        assert!(!jury_cubic(
            -(r1 + r2 + r3),
            r1 * r2 + r1 * r3 + r2 * r3,
            -r1 * r2 * r3
        ));
        // complex pair of modulus 1.05 and a real root 0.5: unstable
        let (re, im, r) = (0.0f32, 1.05f32, 0.5f32);
        let m2 = re * re + im * im;
        assert!(!jury_cubic(-(2.0 * re + r), m2 + 2.0 * re * r, -m2 * r));
    }

    proptest! {
        /// Eigenvalues of the error dynamics (as the coefficients of their characteristic
        /// polynomial) equal the requested poles at any flux, and the Euler discretisation
        /// at 5 kHz is stable, over a grid of flux levels, speeds and pole choices.
        #[test]
        fn poles_placed_and_discrete_stable_over_operating_points(
            flux_frac in 0.1f32..1.2,
            p1 in 20.0f32..2000.0, p2 in 20.0f32..2000.0, p3 in 20.0f32..2000.0,
            rs_scale in 0.5f32..1.6,
        ) {
            let m = MachineParams::paper_table1();
            let poles = ObserverPoles { p1, p2, p3 };
            let c = ObserverConfig::new(&m, poles, 200e-6).unwrap();
            let lambda = flux_frac * m.rotor_flux_for(1.5);
            let equivalent_resistance = m.stator_resistance() * rs_scale + m.referred_rotor_resistance();
            let (c2, c1, c0) = poles.polynomial();
            let (q2, q1, q0) = c.error_polynomial(lambda, equivalent_resistance);
            prop_assert!((q2 - c2).abs() <= 1e-4 * c2);
            prop_assert!((q1 - c1).abs() <= 1e-3 * c1);
            prop_assert!((q0 - c0).abs() <= 1e-3 * c0);
            prop_assert!(c.discrete_stable(lambda, equivalent_resistance));
        }

        /// The step itself (not only the polynomial) contracts the error: from any initial
        /// error, after 0.3 s at fixed operating point (speed and frequency vary), the
        /// error has decayed by the slowest pole's factor.
        #[test]
        fn step_contracts_error_at_any_speed(
            speed in -160.0f32..160.0, i_sq in -4.0f32..4.0,
            e0 in -50.0f32..50.0, t0 in -3.0f32..3.0,
        ) {
            let m = MachineParams::paper_table1();
            let c = ObserverConfig::new(&m, ObserverPoles::DEFAULT, 200e-6).unwrap();
            let lambda = m.rotor_flux_for(1.5);
            let equivalent_resistance = m.equivalent_resistance();
            let i_sd = 1.5;
            let kt = m.torque_constant(lambda);
            let load = kt * i_sq - m.viscous_friction() * speed;
            let ws = 2.0 * speed + m.referred_rotor_resistance() * i_sq / lambda;
            let v = equivalent_resistance * i_sq + m.transient_inductance() * ws * i_sd + 2.0 * lambda * speed;
            let mut obs = ReducedOrderObserver::new();
            obs.reset(i_sq, speed + e0, load + t0);
            let u = ObserverInputs { i_sq, i_sd, stator_frequency: ws, v_sq: v, rotor_flux: lambda,
                inv_rotor_flux: 1.0 / lambda, equivalent_resistance, far_side_error: 0.0 };
            for _ in 0..1500 { obs.update(&c.coeffs, &u); }
            prop_assert!((obs.speed_estimate - speed).abs() < 0.05 * (1.0 + e0.abs() + t0.abs()));
            prop_assert!((obs.load_torque_estimate - load).abs() < 0.01 * (1.0 + e0.abs() + t0.abs()));
        }
    }
}
