//! Classical full-order adaptive speed observer (Kubota, Matsuse and Nakano, "DSP-based
//! speed adaptive flux observer of induction motor", IEEE Trans. Ind. Appl. 29(2), 1993;
//! Kubota and Matsuse, IEEE TIA 30(5), 1994): the baseline the paper's reduced-order
//! observer is compared with (paper section 1: 8 us against about 30 us on a TMS320C31).
//!
//! It is not used by [`crate::drive::Drive`]; it exists to be benchmarked side by side with
//! [`crate::observer::ReducedOrderObserver`] and as a reference estimator in tests.
//!
//! ## Model (stationary alpha-beta frame, this crate's conventions)
//!
//! Complex notation `x = x_alpha + j x_beta`; amplitude-invariant currents (peak phase
//! values); `lambda = (Lm/Lr) psi_r` is the inverse-Gamma rotor flux of the rest of the
//! crate; `w = p Omega` is the electrical rotor speed; `L_sigma = sigma Ls`,
//! `R_R = (Lm/Lr)^2 Rr`, `Rseq = Rs + R_R`, `tau_r = Lr/Rr` (so `L_M/tau_r = R_R`).
//! Eq. (1) of the paper in the stationary frame then reads
//!
//! ```text
//! di/dt      = a11 i + a12 lambda + v/L_sigma     a11 = -Rseq/L_sigma
//!                                                 a12 = (1/tau_r - j w)/L_sigma
//! dlambda/dt = a21 i + a22 lambda                 a21 = R_R,  a22 = -1/tau_r + j w
//! ```
//!
//! (the same equations as the plant model in the `acim-plant` crate, written for lambda).
//!
//! ## Observer (Kubota 1993, eq. 7 there)
//!
//! A copy of the model at the estimated speed `w_hat`, corrected by the current error
//! `e = i_hat - i` through the gain `G = (g_i, g_lambda)`:
//!
//! ```text
//! di_hat/dt      = a11 i_hat + a12(w_hat) lambda_hat + v/L_sigma + g_i e
//! dlambda_hat/dt = a21 i_hat + a22(w_hat) lambda_hat + g_lambda e
//! ```
//!
//! ### Gain: observer poles k times the motor's (Kubota's rule)
//!
//! The error dynamics (at the right speed) have the matrix `[[a11 + g_i, a12],
//! [a21 + g_lambda, a22]]`. Matching its characteristic polynomial to the motor's with both
//! roots scaled by `k >= 1` (sum `k (a11 + a22)`, product `k^2 (a11 a22 - a12 a21)`), and
//! using `a22/a12 = -L_sigma`, gives in closed form
//!
//! ```text
//! g_i      = (k - 1)(a11 + a22)
//!          = (k - 1)(-Rseq/L_sigma - 1/tau_r)      + j (k - 1) w_hat
//! g_lambda = (k - 1)(L_sigma/tau_r - k Rseq + (k + 1) R_R) - j (k - 1) L_sigma w_hat
//! ```
//!
//! Both are affine in `w_hat`: the real parts and the factors of `w_hat` are precomputed,
//! so the gain "matrix" costs two multiplications per step.
//!
//! ### Speed adaptation (Kubota 1993, eq. 12; Lyapunov/Popov derivation)
//!
//! With `e_i = i - i_hat` (measured minus estimated) the adaptation law is a PI on the
//! cross product of the current error and the estimated flux:
//!
//! ```text
//! eps   = e_i_alpha lambda_hat_beta - e_i_beta lambda_hat_alpha
//! w_hat = K_P eps + K_I integral(eps dt)
//! ```
//!
//! A speed error `w - w_hat > 0` drives `-j (w - w_hat) lambda/L_sigma` into the current
//! error, whose cross product with `lambda_hat` is positive: the law raises `w_hat`.
//! The gains are given normalised by the nominal flux, `K = k_n / lambda_nom^2`, so that
//! `k_n` is in rad/s per (A/Wb) and the loop gain is independent of the flux level chosen
//! (no division at run time: `1/lambda_nom^2` is a configuration constant).
//!
//! ## Discretisation
//!
//! One step per control period Ts (200 us): `x\[k+1\]` from `x\[k\]`, the voltage `v\[k\]`
//! applied over (k, k+1) (the previous command, as for the reduced-order observer) and
//! the current `i\[k\]` sampled at k. Plain forward Euler showed a speed bias of about 1 %
//! at 500 rpm against the motor model (the back-EMF and the flux input were taken at the
//! start of a period over which they rotate by w Ts), shrinking linearly with Ts. The step
//! is therefore Euler with three cheap corrections, all with precomputed coefficients:
//!
//! * the two diagonal decays are integrated exactly (zero-order hold): `e^(-Ts Rseq/L_sigma)`
//!   and `e^(-Ts/tau_r)`, with the matching steps `h_i = (1 - e^(-Ts Rseq/L_sigma))
//!   L_sigma/Rseq` and `h_l = tau_r (1 - e^(-Ts/tau_r))` in place of Ts for the other terms;
//! * the flux in the back-EMF and in the flux rotation is taken at mid-period along its
//!   rotation, `lambda_m = (1 + j w_hat Ts/2) lambda_hat` (second order in w Ts);
//! * the flux equation uses the mean of the current estimates at k and k+1 (trapezoid).
//!
//! With these, the bias against the motor model is below 0.1 % at 60 and 500 rpm. The
//! discrete error matrix (known speed) is evaluated by
//! [`FullOrderConfig::discrete_spectral_radius`]; its largest eigenvalue modulus is within 2e-3 of
//! `e^(Ts k mu_i)` (mu_i the motor's) from standstill to 3000 rpm and [`FullOrderConfig::new`]
//! rejects a design whose spectral radius at the speed clamp is not below 0.9999.
//!
//! ## Cost (why it is the heavier observer)
//!
//! Per step: 4 states plus the speed integrator, about 45 multiply-adds, no division, no
//! square root, no trigonometry. The reduced-order observer of eq. (12) needs about 20.
//! Kept `#[inline]` like the other blocks of the step.

use crate::math::{clamp, is_finite};
use crate::params::MachineParams;

/// Design choices of the full-order observer.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FullOrderDesign {
    /// Pole ratio k >= 1: observer poles are k times the motor's (Kubota's rule).
    pub pole_ratio: f32,
    /// Normalised proportional adaptation gain k_p,n (rad/s electrical per A/Wb times
    /// Wb^2): K_P = k_p,n / lambda_nom^2.
    pub speed_kp: f32,
    /// Normalised integral adaptation gain k_i,n (rad/s^2 electrical per A/Wb times Wb^2):
    /// K_I = k_i,n / lambda_nom^2.
    pub speed_ki: f32,
    /// Nominal rotor flux lambda_nom (Wb) used to normalise the adaptation gains.
    pub nominal_flux: f32,
    /// Clamp of the estimated speed, rad/s mechanical (keeps the state bounded if the
    /// inputs are nonsense).
    pub max_speed: f32,
}

impl FullOrderDesign {
    /// Defaults for the paper's machine: k = 1.2 and adaptation gains k_p,n = 60,
    /// k_i,n = 40 000, tuned against the motor model (tests below): from a wrong initial
    /// speed the estimate is within 1 % after about 0.3 s at 60 and 500 rpm. Larger pole
    /// ratios slow the low-speed convergence (k = 1.5, 1.7) and, with these adaptation
    /// gains, k >= 2 made the adaptation loop diverge in simulation: the speed-error to
    /// `eps` transfer depends on G, and Kubota's Lyapunov argument does not fix k.
    pub fn paper_defaults(m: &MachineParams) -> Self {
        Self {
            pole_ratio: 1.2,
            speed_kp: 60.0,
            speed_ki: 40_000.0,
            nominal_flux: m.rotor_flux_for(crate::params::DEFAULT_FLUX_CURRENT),
            max_speed: 4000.0 * crate::math::RPM_TO_RAD_S,
        }
    }
}

/// Why a full-order observer design was rejected.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum FullOrderDesignError {
    /// The control period is not finite and positive.
    BadPeriod,
    /// The pole ratio is not finite or below 1.
    BadPoleRatio,
    /// An adaptation gain is negative or not finite, or the nominal flux or speed clamp
    /// is not positive.
    BadGain,
    /// The Euler discretisation is unstable (or too close to the unit circle) at the speed
    /// clamp: a shorter period or a smaller pole ratio is needed.
    Unstable,
}

/// Precomputed coefficients (configuration) of the full-order observer: every product with
/// Ts and every reciprocal is formed here, none in the step.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FullOrderConfig {
    /// Control period Ts, s.
    pub ts: f32,
    /// Pole pairs p.
    pub pole_pairs: f32,
    /// 1/p.
    pub inv_pole_pairs: f32,
    /// Integration step of the current equation, h_i = (1 - e^(-Ts Rseq/L_sigma)) L_sigma/Rseq, s.
    pub h_i: f32,
    /// Integration step of the flux equation, h_l = tau_r (1 - e^(-Ts/tau_r)), s.
    pub h_l: f32,
    /// e^(-Ts Rseq/L_sigma): current self term.
    pub c_ii: f32,
    /// h_i/(L_sigma tau_r): flux to current.
    pub c_il: f32,
    /// h_i/L_sigma: voltage and speed-voltage to current.
    pub c_iv: f32,
    /// e^(-Ts/tau_r): flux self term.
    pub c_ll: f32,
    /// h_l R_R / 2: current (mean of k and k+1) to flux.
    pub c_li: f32,
    /// Ts/2, s.
    pub half_ts: f32,
    /// h_i Re(g_i).
    pub g_i_re: f32,
    /// h_i (k - 1): h_i Im(g_i) = g_i_im_w * w_hat.
    pub g_i_im_w: f32,
    /// h_l Re(g_lambda).
    pub g_l_re: f32,
    /// -h_l (k - 1) L_sigma: h_l Im(g_lambda) = g_l_im_w * w_hat.
    pub g_l_im_w: f32,
    /// K_P, rad/s electrical per (A Wb).
    pub kp: f32,
    /// K_I Ts, rad/s electrical per (A Wb) per step.
    pub ki_ts: f32,
    /// Speed clamp, rad/s electrical.
    pub max_speed_elec: f32,
    /// The design it was built from.
    pub design: FullOrderDesign,
}

impl FullOrderConfig {
    /// Designs the observer for the controller's machine model `m` at period `ts` (s).
    pub fn new(
        m: &MachineParams,
        design: FullOrderDesign,
        ts: f32,
    ) -> Result<Self, FullOrderDesignError> {
        if !(is_finite(ts) && ts > 0.0) {
            return Err(FullOrderDesignError::BadPeriod);
        }
        let k = design.pole_ratio;
        if !(is_finite(k) && k >= 1.0) {
            return Err(FullOrderDesignError::BadPoleRatio);
        }
        let ok_gain = |g: f32| is_finite(g) && g >= 0.0;
        if !(ok_gain(design.speed_kp)
            && ok_gain(design.speed_ki)
            && is_finite(design.nominal_flux)
            && design.nominal_flux > 0.0
            && is_finite(design.max_speed)
            && design.max_speed > 0.0)
        {
            return Err(FullOrderDesignError::BadGain);
        }
        let ls = m.transient_inductance();
        let equivalent_resistance = m.equivalent_resistance();
        let rr = m.referred_rotor_resistance();
        let inv_tr = 1.0 / m.rotor_time_constant();
        let inv_ls = 1.0 / ls;
        let a11 = -equivalent_resistance * inv_ls;
        let pp = m.pole_pairs_f32();
        let inv_l2 = 1.0 / (design.nominal_flux * design.nominal_flux);
        // exponential (ZOH-exact) integration of the two diagonal decays, Euler for the
        // rest: h_i = (1 - e^(a11 Ts))/(-a11) replaces Ts in the current equation,
        // h_l = tau_r (1 - e^(-Ts/tau_r)) in the flux equation
        let d_i = crate::flux::one_minus_exp_neg_small(-a11 * ts);
        let d_l = crate::flux::one_minus_exp_neg_small(ts * inv_tr);
        let h_i = d_i / -a11;
        let h_l = d_l / inv_tr;
        let cfg = Self {
            ts,
            pole_pairs: pp,
            inv_pole_pairs: 1.0 / pp,
            h_i,
            h_l,
            c_ii: 1.0 - d_i,
            c_il: h_i * inv_ls * inv_tr,
            c_iv: h_i * inv_ls,
            c_ll: 1.0 - d_l,
            c_li: 0.5 * h_l * rr,
            half_ts: 0.5 * ts,
            g_i_re: h_i * (k - 1.0) * (a11 - inv_tr),
            g_i_im_w: h_i * (k - 1.0),
            g_l_re: h_l * (k - 1.0) * (ls * inv_tr - k * equivalent_resistance + (k + 1.0) * rr),
            g_l_im_w: -h_l * (k - 1.0) * ls,
            kp: design.speed_kp * inv_l2,
            ki_ts: design.speed_ki * inv_l2 * ts,
            max_speed_elec: design.max_speed * pp,
            design,
        };
        if cfg.discrete_spectral_radius(design.max_speed) >= 0.9999 {
            return Err(FullOrderDesignError::Unstable);
        }
        Ok(cfg)
    }

    /// Largest modulus of the eigenvalues of the discrete error matrix of the step (the
    /// map from (i_hat - i, lambda_hat - lambda)\[k\] to \[k+1\] with the speed known) at the
    /// mechanical speed `speed` (rad/s): a configuration-time check on the 2x2 complex
    /// matrix.
    pub fn discrete_spectral_radius(&self, speed: f32) -> f32 {
        let w = speed * self.pole_pairs;
        // discrete error matrix, complex entries (re, im), exactly as `update` computes
        let rot = (1.0, self.half_ts * w); // lambda_m = rot lambda
        let m11 = (self.c_ii + self.g_i_re, self.g_i_im_w * w);
        let m12 = cmul((self.c_il, -self.c_iv * w), rot);
        // flux row: c_ll + j h_l w rot, plus c_li (e_i + e_i\[k+1\]) and the gain
        let m21 = (
            self.c_li * (1.0 + m11.0) + self.g_l_re,
            self.c_li * m11.1 + self.g_l_im_w * w,
        );
        let jr = cmul((0.0, self.h_l * w), rot);
        let m22 = (
            self.c_ll + jr.0 + self.c_li * m12.0,
            jr.1 + self.c_li * m12.1,
        );
        // eigenvalues of M: z^2 - tr z + det = 0
        let tr = (m11.0 + m22.0, m11.1 + m22.1);
        let det = csub(cmul(m11, m22), cmul(m12, m21));
        let disc = csub(cmul(tr, tr), (4.0 * det.0, 4.0 * det.1));
        let r = csqrt(disc);
        let mut worst = 0.0f32;
        for z in [
            (0.5 * (tr.0 + r.0), 0.5 * (tr.1 + r.1)),
            (0.5 * (tr.0 - r.0), 0.5 * (tr.1 - r.1)),
        ] {
            let mag2 = z.0 * z.0 + z.1 * z.1;
            if mag2 > worst {
                worst = mag2;
            }
        }
        crate::math::sqrt(worst)
    }
}

fn cmul(a: (f32, f32), b: (f32, f32)) -> (f32, f32) {
    (a.0 * b.0 - a.1 * b.1, a.0 * b.1 + a.1 * b.0)
}

fn csub(a: (f32, f32), b: (f32, f32)) -> (f32, f32) {
    (a.0 - b.0, a.1 - b.1)
}

fn csqrt(a: (f32, f32)) -> (f32, f32) {
    let m = crate::math::sqrt(a.0 * a.0 + a.1 * a.1);
    let re = crate::math::sqrt(0.5 * (m + a.0));
    let im = crate::math::sqrt(0.5 * (m - a.0));
    (re, if a.1 < 0.0 { -im } else { im })
}

/// Observer state: estimated stator current, rotor flux (alpha-beta) and speed.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FullOrderObserver {
    /// i_alpha_hat, A.
    pub i_alpha: f32,
    /// i_beta_hat, A.
    pub i_beta: f32,
    /// lambda_alpha_hat, Wb (inverse-Gamma rotor flux).
    pub flux_alpha: f32,
    /// lambda_beta_hat, Wb.
    pub flux_beta: f32,
    /// Integral part of the speed adaptation, rad/s electrical.
    pub speed_integral: f32,
    /// Estimated electrical speed w_hat, rad/s.
    pub speed_elec: f32,
}

impl FullOrderObserver {
    /// All estimates zero.
    pub const fn new() -> Self {
        Self {
            i_alpha: 0.0,
            i_beta: 0.0,
            flux_alpha: 0.0,
            flux_beta: 0.0,
            speed_integral: 0.0,
            speed_elec: 0.0,
        }
    }

    /// Starts from a given speed (rad/s mechanical), zero flux and current.
    pub fn with_speed(cfg: &FullOrderConfig, speed: f32) -> Self {
        let w = speed * cfg.pole_pairs;
        Self {
            speed_integral: w,
            speed_elec: w,
            ..Self::new()
        }
    }

    /// Estimated mechanical speed Omega_hat, rad/s.
    #[inline]
    pub fn speed(&self, cfg: &FullOrderConfig) -> f32 {
        self.speed_elec * cfg.inv_pole_pairs
    }

    /// One step (see the module documentation, "Discretisation"): `v_alpha`, `v_beta` (V)
    /// the voltage applied over the coming period, `i_alpha`, `i_beta` (A) the current
    /// sampled now. Returns the estimated mechanical speed (rad/s). About 45
    /// multiply-adds, no division. A non-finite input
    /// cannot poison the state: the step is dropped and the state kept.
    #[inline]
    pub fn update(
        &mut self,
        cfg: &FullOrderConfig,
        v_alpha: f32,
        v_beta: f32,
        i_alpha: f32,
        i_beta: f32,
    ) -> f32 {
        let w = self.speed_elec;
        let (ia, ib, la, lb) = (self.i_alpha, self.i_beta, self.flux_alpha, self.flux_beta);
        // e = i_hat - i
        let ea = ia - i_alpha;
        let eb = ib - i_beta;
        // flux at mid-period along its rotation, lambda_m = (1 + j w Ts/2) lambda_hat, and
        // the speed voltage w lambda_m (second-order accurate for the rotating terms)
        let lam_a = la - cfg.half_ts * (w * lb);
        let lam_b = lb + cfg.half_ts * (w * la);
        let wla = w * lam_b;
        let wlb = w * lam_a;
        // imaginary parts of h g_i and h g_lambda
        let gim = cfg.g_i_im_w * w;
        let glm = cfg.g_l_im_w * w;
        // current: e^(a11 Ts) i + h_i ((lambda_m/tau_r - j w lambda_m + v)/L_sigma + g_i e)
        let na = cfg.c_ii * ia + cfg.c_il * lam_a + cfg.c_iv * (v_alpha + wla) + cfg.g_i_re * ea
            - gim * eb;
        let nb = cfg.c_ii * ib
            + cfg.c_il * lam_b
            + cfg.c_iv * (v_beta - wlb)
            + cfg.g_i_re * eb
            + gim * ea;
        // flux: e^(-Ts/tau_r) lambda + h_l (R_R (i_hat\[k\] + i_hat\[k+1\])/2 + j w lambda_m
        //       + g_lambda e)
        let fa = cfg.c_ll * la + cfg.c_li * (ia + na) - cfg.h_l * wla + cfg.g_l_re * ea - glm * eb;
        let fb = cfg.c_ll * lb + cfg.c_li * (ib + nb) + cfg.h_l * wlb + cfg.g_l_re * eb + glm * ea;
        // adaptation: eps = (i - i_hat) x lambda_hat = -ea lb + eb la
        let eps = eb * la - ea * lb;
        let integral = clamp(
            self.speed_integral + cfg.ki_ts * eps,
            -cfg.max_speed_elec,
            cfg.max_speed_elec,
        );
        let speed = clamp(
            integral + cfg.kp * eps,
            -cfg.max_speed_elec,
            cfg.max_speed_elec,
        );
        // a non-finite sample (or state) would poison everything: keep the last state
        if is_finite(na + nb + fa + fb + eps) {
            self.i_alpha = na;
            self.i_beta = nb;
            self.flux_alpha = fa;
            self.flux_beta = fb;
            self.speed_integral = integral;
            self.speed_elec = speed;
        }
        self.speed_elec * cfg.inv_pole_pairs
    }
}

/// The full-order adaptive observer as the cascade's speed observer
/// ([`crate::observer::SpeedObserver`]): its design and state together, so that
/// `Drive<_, f32, FullOrder>` runs the paper's baseline in the closed loop. It runs from
/// the first magnetizing step (it estimates the flux itself) on the measured alpha-beta
/// current and the alpha-beta voltage commanded for the past period, with its speed held
/// until magnetizing ends at the speed the rotor turns at (zero at rest, the speed
/// search's measurement on a flying start); it has no load model (the load estimate is 0). Its design uses the
/// controller's machine model as built: unlike the reduced-order observer it does not
/// follow the Rs estimate.
#[derive(Clone, Debug)]
pub struct FullOrder {
    cfg: FullOrderConfig,
    state: FullOrderObserver,
    /// The speed held while magnetizing, rad/s electrical.
    preset_elec: f32,
}

impl FullOrder {
    /// Designs the observer for the controller's machine `m` at period `ts` (s) with the
    /// defaults of [`FullOrderDesign::paper_defaults`].
    pub fn new(m: &MachineParams, ts: f32) -> Result<Self, FullOrderDesignError> {
        Self::with_design(m, FullOrderDesign::paper_defaults(m), ts)
    }
    /// Designs the observer with `design`.
    pub fn with_design(
        m: &MachineParams,
        design: FullOrderDesign,
        ts: f32,
    ) -> Result<Self, FullOrderDesignError> {
        Ok(Self {
            cfg: FullOrderConfig::new(m, design, ts)?,
            state: FullOrderObserver::new(),
            preset_elec: 0.0,
        })
    }
    /// The design in use.
    pub fn config(&self) -> &FullOrderConfig {
        &self.cfg
    }
    /// The observer state.
    pub fn state(&self) -> &FullOrderObserver {
        &self.state
    }
}

impl crate::observer::SpeedObserver for FullOrder {
    /// The full-order observer has no far-side term (nor a load-torque estimate), so the
    /// drive keeps the regeneration limit with it.
    #[inline(always)]
    fn far_side_term(&self) -> bool {
        false
    }
    #[inline(always)]
    fn update(
        &mut self,
        _coeffs: &crate::observer::ObserverCoeffs<f32>,
        x: &crate::observer::SpeedObserverInputs,
    ) -> crate::observer::SpeedEstimate {
        let mut speed = self.state.update(
            &self.cfg,
            x.v_ab.alpha,
            x.v_ab.beta,
            x.i_ab.alpha,
            x.i_ab.beta,
        );
        if x.magnetizing {
            // the rotor speed is known while the flux builds (0 at rest, the speed
            // search's on a flying start): the adaptation starts with speed control
            self.state.speed_integral = self.preset_elec;
            self.state.speed_elec = self.preset_elec;
            speed = self.state.speed(&self.cfg);
        }
        crate::observer::SpeedEstimate {
            speed,
            load_torque: 0.0,
            current: x.i_dq.q,
        }
    }
    fn reset(&mut self) {
        self.state = FullOrderObserver::new();
        self.preset_elec = 0.0;
    }
    fn start_running(&mut self, _i_sq: f32) {}
    fn preset_speed(&mut self, speed: f32) {
        self.preset_elec = speed * self.cfg.pole_pairs;
    }
    #[inline(always)]
    fn estimate(&self) -> crate::observer::SpeedEstimate {
        crate::observer::SpeedEstimate {
            speed: self.state.speed(&self.cfg),
            load_torque: 0.0,
            current: 0.0,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const TS: f32 = 200e-6;

    fn cfg(m: &MachineParams) -> FullOrderConfig {
        FullOrderConfig::new(m, FullOrderDesign::paper_defaults(m), TS).unwrap()
    }

    #[test]
    fn rejects_bad_designs() {
        let m = MachineParams::paper_table1();
        let d = FullOrderDesign::paper_defaults(&m);
        assert_eq!(
            FullOrderConfig::new(&m, d, 0.0),
            Err(FullOrderDesignError::BadPeriod)
        );
        let mut b = d;
        b.pole_ratio = 0.5;
        assert_eq!(
            FullOrderConfig::new(&m, b, TS),
            Err(FullOrderDesignError::BadPoleRatio)
        );
        let mut b = d;
        b.speed_ki = f32::NAN;
        assert_eq!(
            FullOrderConfig::new(&m, b, TS),
            Err(FullOrderDesignError::BadGain)
        );
        // Euler at a 5 ms period with k = 4 is unstable
        let mut b = d;
        b.pole_ratio = 4.0;
        assert_eq!(
            FullOrderConfig::new(&m, b, 5e-3),
            Err(FullOrderDesignError::Unstable)
        );
    }

    /// The poles are k times the motor's: at several speeds the discrete spectral radius
    /// equals max |1 + Ts k mu_i|, with mu_i from the motor matrix (f64 reference).
    #[test]
    fn poles_are_k_times_the_motors_and_euler_is_stable() {
        let m = MachineParams::paper_table1();
        let c = cfg(&m);
        let k = c.design.pole_ratio as f64;
        let ls = m.transient_inductance() as f64;
        let equivalent_resistance = m.equivalent_resistance() as f64;
        let rr = m.referred_rotor_resistance() as f64;
        let itr = 1.0 / m.rotor_time_constant() as f64;
        for rpm in [0.0f64, 60.0, 500.0, 1500.0, 3000.0] {
            let w = 2.0 * rpm * core::f64::consts::PI / 30.0;
            // motor: s^2 - (a11 + a22) s + (a11 a22 - a12 a21), complex
            let a11 = (-equivalent_resistance / ls, 0.0);
            let a12 = (itr / ls, -w / ls);
            let a21 = (rr, 0.0);
            let a22 = (-itr, w);
            let mul = |a: (f64, f64), b: (f64, f64)| (a.0 * b.0 - a.1 * b.1, a.0 * b.1 + a.1 * b.0);
            let tr = (a11.0 + a22.0, a11.1 + a22.1);
            let p = mul(a11, a22);
            let q = mul(a12, a21);
            let det = (p.0 - q.0, p.1 - q.1);
            let tt = mul(tr, tr);
            let disc = (tt.0 - 4.0 * det.0, tt.1 - 4.0 * det.1);
            let mag = (disc.0 * disc.0 + disc.1 * disc.1).sqrt();
            let r = (
                (0.5 * (mag + disc.0)).sqrt(),
                (0.5 * (mag - disc.0)).sqrt().copysign(disc.1),
            );
            let mut expect = 0.0f64;
            for s in [
                (0.5 * (tr.0 + r.0), 0.5 * (tr.1 + r.1)),
                (0.5 * (tr.0 - r.0), 0.5 * (tr.1 - r.1)),
            ] {
                // |e^(Ts k mu)|: the step is ZOH-exact on the diagonal, Euler elsewhere
                expect = expect.max((TS as f64 * k * s.0).exp());
            }
            let got = c.discrete_spectral_radius((rpm * core::f64::consts::PI / 30.0) as f32);
            assert!(
                (got as f64 - expect).abs() < 3e-3,
                "{rpm} rpm: {got} vs {expect}"
            );
            assert!(got < 0.999, "{rpm} rpm: {got}");
        }
    }

    #[test]
    fn non_finite_input_keeps_the_state() {
        let m = MachineParams::paper_table1();
        let c = cfg(&m);
        let mut obs = FullOrderObserver::with_speed(&c, 10.0);
        let before = obs;
        let s = obs.update(&c, f32::NAN, 0.0, 0.0, 0.0);
        assert_eq!(obs, before);
        assert!((s - 10.0).abs() < 1e-4);
        obs.update(&c, 0.0, 0.0, f32::INFINITY, 0.0);
        assert_eq!(obs, before);
    }
}
