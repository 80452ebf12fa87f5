//! Rotor-resistance adaptation from speed transients: the slip law's
//! R_R (eq. 8) and the observer's Rseq (eq. 12) corrected from how the estimated speed
//! moved against the mechanical model when the torque current changed.
//!
//! ## Why a steady state cannot tell R_R, and a transient can
//!
//! In the inverse-Gamma model the slip law is `w_slip = R_R i_sq / lambda_r` and the
//! q-axis equation the observer copies (eq. 9b) carries `Rseq = Rs + R_R`. With the
//! orientation held (the d-axis residual of eq. 20 has no R_R in steady state, design
//! notes section 3), an error `dR = R_R_hat - R_R` puts the observer's speed off by the
//! slip error:
//!
//! ```text
//! p Omega_hat = p Omega - dR i_sq / lambda_r
//! ```
//!
//! and the stator sees only `w_s = p Omega_hat + w_slip_hat = p Omega + w_slip`: no stator
//! quantity at one operating point separates (Omega, R_R) from (Omega_hat, R_R_hat)
//! (docs/robustness.md, "Rotor resistance"). Across a change of i_sq the relation still
//! holds (the observer's poles, 120-200 rad/s, are faster than the speed loop moves the
//! current), so the estimated speed moves by `-dR di/(p lambda_r)` more than the rotor
//! did (`di` the torque current's change). The rotor's own speed change is what the
//! mechanical model integrates from the torque, with the load torque as it was before the
//! transient (`T_L0`, the steady torque balance):
//!
//! ```text
//! M(t) = (1/J) integral_{t0}^{t} (1.5 p lambda_r i_sq - B Omega_hat - T_L0) dt
//! D(t) = Omega_hat(t) - Omega_hat(t0) - M(t)  =  -dR di(t) / (p lambda_r) - gamma M(t)
//! ```
//!
//! ## Why J is estimated with it
//!
//! `gamma` is the model's relative error in torque per inertia, `(1 + k)/(1 + e_J) - 1`
//! for a torque-constant error `k` and an inertia error `e_J`. Over a window that starts
//! at a ramp, `di` and `M` grow together (`M = kt T di / J` for a window of length `T`), so
//! a fit of `D` on `di` alone reads `gamma` as a resistance: measured on the paper's
//! machine with the first version of this module (a 0.15 s window, J taken as known),
//! J 2 % high or low gave R_R_hat +11 % / -8 % and J 5 % high +25 %; the commissioning
//! finds J within -1.4 % to +9.3 % (docs/any-motor.md). The two terms have different
//! shapes in time, though: the slip error follows the current at once, the model error
//! grows with the integral of the torque change. At the ramp's end the current returns
//! while `M` keeps the speed change. A least-squares fit of `D_k = u di_k + v M_k` over
//! a window that holds the ramp's start, its run and its end separates them:
//! `dR = -p lambda_r u`, `gamma = -v` (reported; the observer's J is not changed).
//!
//! ## When it measures
//!
//! A window opens when the speed reference starts a ramp after [`RR_QUIET_TIME`] of a
//! steady reference and a steady torque current, with |w_s| at least
//! [`RR_MIN_FREQUENCY_HZ`]. It runs through the ramp and [`RR_SETTLE_TIME`] beyond its end,
//! at most [`RR_WINDOW_TIME`], sampling `(di, M, D)` every [`RR_DECIMATION`] steps. It is
//! dropped if |w_s| falls below the limit (near `w_s = 0` the speed is not observable),
//! if field weakening moves the flux or speed control stops. At its end it updates the
//! estimate by a share of the fit (the running mean of the windows, at least
//! [`RR_STEP_FRACTION`]), within [`RR_BOUNDS`] of the configured
//! R_R, if the torque current moved by at least [`RR_MIN_CURRENT_CHANGE`] of the flux
//! current, the two regressors are not near proportional (the determinant at least
//! [`RR_MIN_DECORRELATION`] of the diagonal's product), `|gamma|` is at most
//! [`RR_MAX_MODEL_ERROR`] and the fit's residual at most [`RR_MAX_FIT_RMS`].
//!
//! ## What it assumes (and what breaks it)
//!
//! - The load torque holds over the window. A load change inside it (a load step, or a
//!   fan's torque changing with the speed) adds a speed excess the fit shares between
//!   `gamma` and `dR`. This is why the adaptation is off by default
//!   ([`TrackerSettings::rr_adaptation`](crate::TrackerSettings::rr_adaptation)).
//! - A stator-resistance error enters the q-axis equation as an R_R error does: the fit
//!   finds `dR + dRs` (the running Rs law keeps `dRs` small where it adapts).
//! - The flux model's `tau_r` keeps the configured R_R (it matters in flux transients only).
//!
//! In fixed point the sums are Q7.24 per unit and the 2 x 2 solve runs once per window in
//! f32 ([`Units::to_f32`]; software floating point on a core without an FPU).

use crate::num::DivSqrt;
use crate::num::Num;
use crate::num::PerUnitBases;
use crate::num::Units;
use crate::observer::ObserverCoeffs;

/// The reference and the torque current must have been steady this long before a ramp
/// opens a window, s (the observer and the speed loop settled: several of the speed
/// loop's time constants at 25 rad/s).
pub const RR_QUIET_TIME: f32 = 0.5;
/// The window runs this long beyond the ramp's end, s: the speed loop has taken the
/// acceleration current back (about 4 / 25 rad/s) while `M` keeps the speed change.
pub const RR_SETTLE_TIME: f32 = 0.25;
/// The longest window, s.
pub const RR_WINDOW_TIME: f32 = 0.8;
/// A window shorter than this is dropped, s.
pub const RR_MIN_WINDOW_TIME: f32 = 0.3;
/// One sample of the fit every this many steps (the sums stay in the fixed-point range).
pub const RR_DECIMATION: u32 = 4;
/// The smallest peak torque-current change a window may use, as a fraction of the flux
/// current: the speed estimate's noise over it is the resistance estimate's noise.
pub const RR_MIN_CURRENT_CHANGE: f32 = 0.1;
/// The fit's determinant must be at least this fraction of `sum(di^2) sum(M^2)`
/// (the regressors' correlation at most 0.97).
pub const RR_MIN_DECORRELATION: f32 = 0.05;
/// A window whose torque-per-inertia error `|gamma|` exceeds this is dropped (a load
/// change, not a J error).
pub const RR_MAX_MODEL_ERROR: f32 = 0.25;
/// A window whose fit leaves a residual above this (RMS, rad/s mechanical; 1.9 rpm) is
/// dropped: something the two regressors do not explain moved the speed. Measured on the
/// paper's machine: the paper scenarios' 10 mA rms sensor noise leaves 0.4-0.9 rpm, a load
/// step of 0.3 N m inside a window 6-52 rpm (measured without noise).
pub const RR_MAX_FIT_RMS: f32 = 0.2;
/// The smallest fraction of a window's estimate applied: the n-th window since power-up
/// applies `max(1/n, RR_STEP_FRACTION)` of what it found (the running mean of the windows,
/// then an exponential average over about four, so the estimate still follows a rotor
/// warming up).
pub const RR_STEP_FRACTION: f32 = 0.25;
/// R_R_hat stays within these multiples of the configured R_R.
pub const RR_BOUNDS: (f32, f32) = (0.5, 2.0);
/// Windows open and run from this stator frequency up, Hz.
pub const RR_MIN_FREQUENCY_HZ: f32 = 2.0;
/// The torque current's low-pass time constant, s (the observer's slowest pole, 1/120 s:
/// the speed estimate lags the current by about this).
pub const RR_CURRENT_FILTER_TIME: f32 = 1.0 / 120.0;
/// The slow low-pass against which the torque current counts as steady, s.
pub const RR_STEADY_FILTER_TIME: f32 = 0.1;

/// The adaptation's design (immutable; [`crate::design::DriveDesign`] builds it).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct RrEstimatorConfig<N: Num = f32> {
    /// Adapt at all ([`TrackerSettings::rr_adaptation`](crate::TrackerSettings::rr_adaptation)).
    pub enabled: bool,
    /// [`RR_QUIET_TIME`] in steps.
    pub quiet_steps: u32,
    /// [`RR_SETTLE_TIME`] in steps.
    pub settle_steps: u32,
    /// [`RR_WINDOW_TIME`] in steps.
    pub window_steps: u32,
    /// [`RR_MIN_WINDOW_TIME`] in steps.
    pub min_window_steps: u32,
    /// `Ts / RR_CURRENT_FILTER_TIME`.
    pub current_filter: N::Gain,
    /// `Ts / RR_STEADY_FILTER_TIME`.
    pub steady_filter: N::Gain,
    /// The torque current counts as steady within this of its slow low-pass, A.
    pub steady_band: N,
    /// The smallest usable peak torque-current change, A.
    pub min_current_change: N,
    /// Windows run from this |w_s| up, rad/s electrical.
    pub min_frequency: N,
    /// `dR i_sq / lambda_r` (ohm A / Wb) -> rad/s electrical: 1 in SI.
    pub slip_gain: N::Gain,
    /// The bounds of `dR = R_R_hat - R_R`, ohm.
    pub bounds: (N, N),
    /// The configured R_R, ohm.
    pub referred_rotor_resistance: N,
    /// Pole pairs p.
    pub pole_pairs: f32,
    /// SI per unit of this arithmetic's current (1 in f32; the current base in Q7.24), A.
    pub current_unit: f32,
    /// The same for speed, rad/s.
    pub speed_unit: f32,
    /// The same for flux, Wb.
    pub flux_unit: f32,
    /// The same for resistance, ohm.
    pub resistance_unit: f32,
    /// A sum at or beyond this (in this arithmetic's units) drops the window: in Q7.24
    /// it may have saturated (`f32::MAX` in f32).
    pub sum_limit: f32,
}

impl RrEstimatorConfig<f32> {
    /// The design for period `ts` (s), pole pairs `p`, the configured R_R (ohm) and the
    /// flux current (A).
    pub fn new(
        enabled: bool,
        ts: f32,
        p: f32,
        referred_rotor_resistance: f32,
        flux_current: f32,
    ) -> Self {
        Self {
            enabled,
            quiet_steps: (RR_QUIET_TIME / ts) as u32,
            settle_steps: (RR_SETTLE_TIME / ts) as u32,
            window_steps: (RR_WINDOW_TIME / ts) as u32,
            min_window_steps: (RR_MIN_WINDOW_TIME / ts) as u32,
            current_filter: (ts / RR_CURRENT_FILTER_TIME).min(1.0),
            steady_filter: (ts / RR_STEADY_FILTER_TIME).min(1.0),
            steady_band: crate::rs_estimator::RUNNING_STEADY_TORQUE_FRACTION * flux_current.abs(),
            min_current_change: RR_MIN_CURRENT_CHANGE * flux_current.abs(),
            min_frequency: 2.0 * core::f32::consts::PI * RR_MIN_FREQUENCY_HZ,
            slip_gain: 1.0,
            bounds: (
                (RR_BOUNDS.0 - 1.0) * referred_rotor_resistance,
                (RR_BOUNDS.1 - 1.0) * referred_rotor_resistance,
            ),
            referred_rotor_resistance,
            pole_pairs: p,
            current_unit: 1.0,
            speed_unit: 1.0,
            flux_unit: 1.0,
            resistance_unit: 1.0,
            sum_limit: f32::MAX,
        }
    }
}

/// The fit's running sums over one window (this arithmetic's units).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct Sums<N> {
    aa: N,
    ab: N,
    bb: N,
    ad: N,
    bd: N,
    dd: N,
    n: u32,
}

/// The adaptation's state. `resistance_error` persists from start to start (like the Rs
/// estimate); the window does not.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RrEstimator<N: Num = f32> {
    /// `dR = R_R_hat - R_R` (configured), ohm: its slip is added to the slip law's.
    pub resistance_error: N,
    /// `R_R_hat`, ohm: the observer's Rseq is `Rs_hat + R_R_hat` (kept as a sum so that
    /// the observer reads one value, the configured R_R while nothing was adapted).
    pub referred_resistance: N,
    /// Windows that updated the estimate since power-up.
    pub updates: u32,
    /// Windows whose fit was rejected (module docs, "When it measures").
    pub rejected: u32,
    /// The last solved window's torque-per-inertia error `gamma` (module docs), 1.
    pub last_model_error: f32,
    /// The last solved window's resistance error `dR`, ohm.
    pub last_window_error: f32,
    /// The last solved window's fit residual, RMS, rad/s mechanical.
    pub last_fit_rms: f32,
    /// The torque current's filters and the steadiness that opens a window.
    filters: Filters<N>,
    /// The open window's state and sums.
    window: Window<N>,
}

/// The torque current's filters and the steadiness judged from them (what may open a
/// window).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct Filters<N> {
    /// i_sq low-passed over [`RR_CURRENT_FILTER_TIME`], A.
    current: N,
    /// That low-passed again over [`RR_STEADY_FILTER_TIME`], A.
    current_slow: N,
    /// Steps with a steady reference and torque current (saturating).
    quiet: u32,
    /// The reference ramped at the last step.
    was_ramping: bool,
}

/// The open window: where it started, the mechanical model since, and the fit's sums.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct Window<N> {
    /// Steps into the open window (0: none open).
    steps: u32,
    /// Steps of the open window since the ramp ended.
    settled: u32,
    /// Omega_hat at the window's start, rad/s.
    speed0: N,
    /// The filtered i_sq at the window's start, A.
    current0: N,
    /// `Ts (1.5 p lambda i_sq0 - B Omega_hat0) / J`: the load torque's share per step, rad/s.
    load0: N,
    /// The mechanical model's speed change since the window opened, `M`, rad/s.
    model: N,
    /// The largest |di| in the window, A.
    peak: N,
    /// The fit's running sums over the window.
    sums: Sums<N>,
}

/// The adaptation's state in SI, for telemetry and reports.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RrReport {
    /// R_R_hat, the referred rotor resistance the drive uses, ohm.
    pub estimate: f32,
    /// Windows that updated it.
    pub updates: u32,
    /// Windows whose fit was rejected.
    pub rejected: u32,
    /// The last solved window's `gamma`, 1.
    pub last_model_error: f32,
    /// The last solved window's resistance error `dR`, ohm.
    pub last_window_error: f32,
    /// The last solved window's fit residual, RMS, rad/s mechanical.
    pub last_fit_rms: f32,
}

impl<N: Num + DivSqrt + Units + DivSqrt + Units> RrEstimator<N> {
    /// The state in SI: `configured` the configured R_R (ohm), `resistance_unit` ohm per
    /// unit of this arithmetic's resistance.
    pub fn report(&self, configured: f32, resistance_unit: f32) -> RrReport {
        RrReport {
            estimate: configured + self.resistance_error.to_f32() * resistance_unit,
            updates: self.updates,
            rejected: self.rejected,
            last_model_error: self.last_model_error,
            last_window_error: self.last_window_error,
            last_fit_rms: self.last_fit_rms,
        }
    }
}

/// What the adaptation reads each step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RrInputs<N> {
    /// Omega_hat after this step's observer update, rad/s mechanical.
    pub speed: N,
    /// Measured i_sq, A.
    pub i_sq: N,
    /// Model rotor flux lambda_r, Wb.
    pub rotor_flux: N,
    /// w_s of the frame, rad/s electrical.
    pub stator_frequency: N,
    /// The speed reference is ramping towards its target.
    pub ramping: bool,
    /// Speed control runs with a settled flux and no field weakening.
    pub usable: bool,
}

impl<N: Num + DivSqrt + Units + DivSqrt + Units> RrEstimator<N> {
    /// No adaptation yet: `R_R_hat` the configured `cfg.referred_rotor_resistance`.
    pub fn new(cfg: &RrEstimatorConfig<N>) -> Self {
        Self {
            referred_resistance: cfg.referred_rotor_resistance,
            ..Self::default()
        }
    }

    /// Back to no open window, keeping the estimate (a start).
    pub fn restart(&mut self) {
        *self = Self {
            resistance_error: self.resistance_error,
            referred_resistance: self.referred_resistance,
            updates: self.updates,
            rejected: self.rejected,
            last_model_error: self.last_model_error,
            last_window_error: self.last_window_error,
            last_fit_rms: self.last_fit_rms,
            ..Self::default()
        };
    }

    /// The slip the estimate adds to eq. (8)'s, `dR i_sq / lambda_r`, rad/s electrical
    /// (`inv_rotor_flux` the flux model's guarded 1/lambda_r).
    #[inline(always)]
    pub fn extra_slip(&self, cfg: &RrEstimatorConfig<N>, i_sq: N, inv_rotor_flux: N) -> N {
        N::gain_mul(cfg.slip_gain, self.resistance_error, i_sq * inv_rotor_flux)
    }

    /// One step (`obs` the observer's coefficients: its Ts 1.5 p/J and Ts B/J).
    #[inline(always)]
    pub fn update(&mut self, cfg: &RrEstimatorConfig<N>, obs: &ObserverCoeffs<N>, u: &RrInputs<N>) {
        if !cfg.enabled {
            return;
        }
        if !(u.usable && u.speed.is_finite() && u.i_sq.is_finite() && u.rotor_flux.is_finite()) {
            self.restart();
            return;
        }
        let quiet_before = self.filters.quiet;
        self.filters.current =
            self.filters.current + N::gain(cfg.current_filter, u.i_sq - self.filters.current);
        self.filters.current_slow = self.filters.current_slow
            + N::gain(
                cfg.steady_filter,
                self.filters.current - self.filters.current_slow,
            );
        let steady = !u.ramping
            && (self.filters.current - self.filters.current_slow).abs() <= cfg.steady_band;
        self.filters.quiet = if steady {
            self.filters.quiet.saturating_add(1)
        } else {
            0
        };
        let fast_enough = u.stator_frequency.abs() >= cfg.min_frequency;
        if self.window.steps > 0 {
            if fast_enough {
                self.sample(cfg, obs, u);
            } else {
                self.window.steps = 0;
            }
        } else if u.ramping
            && !self.filters.was_ramping
            && quiet_before >= cfg.quiet_steps
            && fast_enough
        {
            // the window opens: the load torque is the steady torque balance's
            self.window.steps = 1;
            self.window.settled = 0;
            self.window.speed0 = u.speed;
            self.window.current0 = self.filters.current;
            self.window.model = N::ZERO;
            self.window.peak = N::ZERO;
            self.window.sums = Sums::default();
            self.window.load0 = N::gain_mul(
                obs.ts_torque_per_inertia,
                u.rotor_flux,
                self.filters.current,
            ) - N::gain(obs.ts_friction_rate, u.speed);
        }
        self.filters.was_ramping = u.ramping;
    }

    /// A step of the open window: the model's speed change, a sample of the fit every
    /// [`RR_DECIMATION`] steps, and the window's end.
    #[inline(always)]
    fn sample(&mut self, cfg: &RrEstimatorConfig<N>, obs: &ObserverCoeffs<N>, u: &RrInputs<N>) {
        self.window.model = self.window.model
            + N::gain_mul(obs.ts_torque_per_inertia, u.rotor_flux, u.i_sq)
            - N::gain(obs.ts_friction_rate, u.speed)
            - self.window.load0;
        self.window.steps += 1;
        let di = self.filters.current - self.window.current0;
        let m = self.window.model;
        if di.abs() > self.window.peak {
            self.window.peak = di.abs();
        }
        if self.window.steps.is_multiple_of(RR_DECIMATION) {
            let d = (u.speed - self.window.speed0) - m;
            let s = &mut self.window.sums;
            s.aa = s.aa + di * di;
            s.ab = s.ab + di * m;
            s.bb = s.bb + m * m;
            s.ad = s.ad + di * d;
            s.bd = s.bd + m * d;
            s.dd = s.dd + d * d;
            s.n += 1;
        }
        if !u.ramping {
            self.window.settled += 1;
        }
        if self.window.settled > cfg.settle_steps || self.window.steps > cfg.window_steps {
            if self.window.steps > cfg.min_window_steps
                && self.window.peak >= cfg.min_current_change
            {
                self.close(cfg, u.rotor_flux);
            }
            self.window.steps = 0;
        }
    }

    /// The window's end: the least-squares fit of `D = u di + v M` (module docs), solved
    /// once in f32; a fraction of the resistance error it finds is taken off. Inlined:
    /// the firmware's interrupt calls nothing outside CCM SRAM (firmware/check.sh).
    #[inline(always)]
    fn close(&mut self, cfg: &RrEstimatorConfig<N>, rotor_flux: N) {
        let (cu, su) = (cfg.current_unit, cfg.speed_unit);
        let s = self.window.sums;
        let raw = [s.aa, s.ab, s.bb, s.ad, s.bd, s.dd];
        if raw
            .iter()
            .any(|x| x.is_nan() || x.to_f32().abs() >= cfg.sum_limit)
        {
            return;
        }
        let aa = s.aa.to_f32() * cu * cu;
        let ab = s.ab.to_f32() * cu * su;
        let bb = s.bb.to_f32() * su * su;
        let ad = s.ad.to_f32() * cu * su;
        let bd = s.bd.to_f32() * su * su;
        let dd = s.dd.to_f32() * su * su;
        let det = aa * bb - ab * ab;
        // det > 0.05 aa bb > 0 and n >= 1: the divisions' divisors cannot vanish
        if !(det > RR_MIN_DECORRELATION * aa * bb && aa > 0.0 && bb > 0.0 && s.n > 0) {
            self.rejected = self.rejected.saturating_add(1);
            return;
        }
        let inv = 1.0 / det;
        let u = (bb * ad - ab * bd) * inv;
        let v = (aa * bd - ab * ad) * inv;
        let gamma = -v;
        let error = -cfg.pole_pairs * rotor_flux.to_f32() * cfg.flux_unit * u;
        // the residual's sum of squares, sum (D - u di - v M)^2 at the optimum
        let rss = dd - u * ad - v * bd;
        let rms = crate::math::sqrt(rss / s.n as f32);
        self.last_model_error = gamma;
        self.last_window_error = error;
        self.last_fit_rms = rms;
        if !(crate::math::is_finite(error)
            && gamma.abs() <= RR_MAX_MODEL_ERROR
            && rms <= RR_MAX_FIT_RMS)
        {
            self.rejected = self.rejected.saturating_add(1);
            return;
        }
        let (lo, hi) = cfg.bounds;
        // updates + 1 >= 1: no vanishing divisor
        let fraction = (1.0 / (self.updates as f32 + 1.0)).max(RR_STEP_FRACTION);
        let step = N::from_f32(fraction * error / cfg.resistance_unit);
        self.resistance_error = (self.resistance_error - step).clamp(lo, hi);
        self.referred_resistance = cfg.referred_rotor_resistance + self.resistance_error;
        self.updates = self.updates.saturating_add(1);
    }
}

impl RrEstimatorConfig<f32> {
    /// This design in the arithmetic `N` with the bases `b`: its slip term takes
    /// `resistance x current / flux` to a frequency; its once-per-window solve converts
    /// the sums to SI with the bases. `None` if a gain is not representable.
    pub fn convert<N: Num + Units>(&self, b: &PerUnitBases) -> Option<RrEstimatorConfig<N>> {
        let r = b.resistance();
        Some(RrEstimatorConfig {
            enabled: self.enabled,
            quiet_steps: self.quiet_steps,
            settle_steps: self.settle_steps,
            window_steps: self.window_steps,
            min_window_steps: self.min_window_steps,
            current_filter: N::gain_from_f32(self.current_filter)?,
            steady_filter: N::gain_from_f32(self.steady_filter)?,
            steady_band: N::from_f32(self.steady_band / b.current),
            min_current_change: N::from_f32(self.min_current_change / b.current),
            min_frequency: N::from_f32(self.min_frequency / b.frequency),
            slip_gain: N::gain_from_f32(self.slip_gain * r * b.current / (b.flux * b.frequency))?,
            bounds: (
                N::from_f32(self.bounds.0 / r),
                N::from_f32(self.bounds.1 / r),
            ),
            referred_rotor_resistance: N::from_f32(self.referred_rotor_resistance / r),
            pole_pairs: self.pole_pairs,
            current_unit: b.current,
            speed_unit: b.speed,
            flux_unit: b.flux,
            resistance_unit: r,
            sum_limit: N::SUM_LIMIT,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fixed::{PerUnitBases, Q24};
    use crate::observer::{ObserverConfig, ObserverPoles};
    use crate::params::MachineParams;

    const TS: f32 = 2.0e-4;

    /// What a synthetic run converts: SI -> this arithmetic's signal.
    #[derive(Clone, Copy)]
    enum Unit {
        Current,
        Speed,
        Flux,
        Frequency,
    }

    /// A speed ramp from 500 rpm under 1.5 N m seen by the adaptation: the rotor follows
    /// the mechanics with the true J (the model's J over `1 + j_error`), the torque
    /// current moves by -0.23 A over a 0.2 s ramp from 1 s (time constant 40 ms, then back), and the
    /// observer's speed is off by the slip error of `R_R_hat - R_R`, `R_R_hat` the configured
    /// R_R plus the estimate and `R_R` the configured plus `r_true` (module docs), lagging
    /// the current by the observer's 1/120 s. `load_step`: (time, N m) added to the load.
    fn synthetic<N: Num + DivSqrt + Units + DivSqrt + Units>(
        cfg: &RrEstimatorConfig<N>,
        obs: &ObserverCoeffs<N>,
        to_n: &dyn Fn(f32, Unit) -> N,
        r_true: f32,
        j_error: f32,
        load_step: Option<(f32, f32)>,
    ) -> RrEstimator<N> {
        let m = MachineParams::paper_table1();
        let p = m.pole_pairs_f32();
        let lambda = m.rotor_flux_for(1.5);
        let kt = 1.5 * p * lambda;
        let j = m.inertia() / (1.0 + j_error);
        let b = m.viscous_friction();
        let mut w = 500.0 * crate::math::RPM_TO_RAD_S;
        let i0 = (1.5 + b * w) / kt;
        let mut i_lag = i0;
        let mut est = RrEstimator::<N>::new(cfg);
        let res_unit = cfg.resistance_unit;
        for k in 0..(1.8 / TS) as usize {
            let t = k as f32 * TS;
            let shape = if t < 1.0 {
                0.0
            } else if t < 1.2 {
                1.0 - (-(t - 1.0) / 0.04).exp()
            } else {
                (1.0 - (-0.2f32 / 0.04).exp()) * (-(t - 1.2) / 0.04).exp()
            };
            let i = i0 - 0.23 * shape;
            let load = 1.5 + load_step.map_or(0.0, |(at, dt)| if t >= at { dt } else { 0.0 });
            w += TS * (kt * i - b * w - load) / j;
            i_lag += TS * 120.0 * (i - i_lag);
            let r_hat_minus_r = est.resistance_error.to_f32() * res_unit - r_true;
            let speed = w - r_hat_minus_r * i_lag / (p * lambda);
            est.update(
                cfg,
                obs,
                &RrInputs {
                    speed: to_n(speed, Unit::Speed),
                    i_sq: to_n(i, Unit::Current),
                    rotor_flux: to_n(lambda, Unit::Flux),
                    stator_frequency: to_n(p * w + 10.0, Unit::Frequency),
                    ramping: (1.0..1.2).contains(&t),
                    usable: true,
                },
            );
        }
        est
    }

    fn f32_design() -> (RrEstimatorConfig, ObserverCoeffs) {
        let m = MachineParams::paper_table1();
        let cfg = RrEstimatorConfig::new(true, TS, 2.0, m.referred_rotor_resistance(), 1.5);
        let obs = ObserverConfig::new(&m, ObserverPoles::DEFAULT, TS).unwrap();
        (cfg, obs.coeffs)
    }

    #[test]
    fn one_ramp_finds_the_rotor_resistance_whatever_the_inertia_error() {
        let (cfg, obs) = f32_design();
        let id = |x: f32, _: Unit| x;
        let r_r = MachineParams::paper_table1().referred_rotor_resistance();
        for r_true in [-0.3 * r_r, 0.0, 0.3 * r_r] {
            for j_error in [-0.1, 0.0, 0.1] {
                let e = synthetic(&cfg, &obs, &id, r_true, j_error, None);
                assert_eq!((e.updates, e.rejected), (1, 0), "{r_true} {j_error}");
                assert!(
                    (e.resistance_error - r_true).abs() < 0.02 * r_r,
                    "R_R error {r_true}, J error {j_error}: found {}",
                    e.resistance_error
                );
                // the model's J is (1 + j_error) times the rotor's: its torque per
                // inertia is off by gamma = 1 / (1 + j_error) - 1
                let gamma = 1.0 / (1.0 + j_error) - 1.0;
                assert!(
                    (e.last_model_error - gamma).abs() < 0.02,
                    "{}",
                    e.last_model_error
                );
            }
        }
    }

    #[test]
    fn a_load_step_inside_the_window_is_rejected() {
        let (cfg, obs) = f32_design();
        let id = |x: f32, _: Unit| x;
        for at in [1.05, 1.15, 1.3] {
            for dt in [-0.3, 0.1, 0.3] {
                let e = synthetic(&cfg, &obs, &id, 1.0, 0.0, Some((at, dt)));
                assert_eq!((e.updates, e.rejected), (0, 1), "{dt} N m at {at} s");
                assert_eq!(e.resistance_error, 0.0);
            }
        }
    }

    #[test]
    fn the_q24_adaptation_matches() {
        let (cfg, _) = f32_design();
        let b = PerUnitBases::PAPER;
        let cfg = cfg.convert::<crate::fixed::Q24>(&b).unwrap();
        let m = MachineParams::paper_table1();
        let obs_cfg = ObserverConfig::new(&m, ObserverPoles::DEFAULT, TS).unwrap();
        let obs = obs_cfg.convert::<crate::fixed::Q24>(&b).unwrap();
        let q = |x: f32, u: Unit| {
            Q24::from_f32(
                x / match u {
                    Unit::Current => b.current,
                    Unit::Speed => b.speed,
                    Unit::Flux => b.flux,
                    Unit::Frequency => b.frequency,
                },
            )
        };
        let r_r = m.referred_rotor_resistance();
        for r_true in [-0.3 * r_r, 0.3 * r_r] {
            let e = synthetic(&cfg, &obs, &q, r_true, 0.05, None);
            assert_eq!(e.updates, 1);
            let found = e.resistance_error.to_f32() * b.resistance();
            assert!((found - r_true).abs() < 0.02 * r_r, "{r_true}: {found}");
        }
    }

    #[test]
    fn off_below_the_frequency_and_on_bad_input_nothing_moves() {
        let (cfg, obs) = f32_design();
        let mut e = RrEstimator::default();
        let bad = RrInputs {
            speed: f32::NAN,
            i_sq: 1.0,
            rotor_flux: 0.78,
            stator_frequency: 100.0,
            ramping: true,
            usable: true,
        };
        for k in 0..20_000 {
            e.update(
                &cfg,
                &obs,
                &RrInputs {
                    ramping: k % 3000 < 1000,
                    ..bad
                },
            );
            e.update(
                &cfg,
                &obs,
                &RrInputs {
                    speed: 1.0,
                    stator_frequency: 5.0,
                    ramping: k % 3000 < 1000,
                    ..bad
                },
            );
        }
        assert_eq!((e.updates, e.rejected, e.resistance_error), (0, 0, 0.0));
        let off = RrEstimatorConfig {
            enabled: false,
            ..cfg
        };
        let id = |x: f32, _: Unit| x;
        let e = synthetic(&off, &obs, &id, 1.0, 0.0, None);
        assert_eq!((e.updates, e.resistance_error), (0, 0.0));
    }
}
