//! Reduced-order flux observer with speed adaptation, in estimated rotor-flux coordinates
//! (Hinkkanen, Harnefors and Luomi, "Reduced-order flux observers with stator-resistance
//! adaptation for speed-sensorless induction motor drives", IEEE Trans. Power Electron.
//! 25(5), 2010; the form and default gain are those of motulator's `im` observer, Aalto
//! Electric Drives, documented at <https://aalto-electric-drives.github.io/motulator/>).
//!
//! The paper's observer (eq. 12, [`crate::observer`]) estimates speed from the q-axis
//! current error in the frame the rotor-flux model (eq. 8, 13) defines, so near zero stator
//! frequency while regenerating its error dynamics lose their stability (the drive keeps
//! a regeneration limit for that region). This observer estimates the rotor flux itself,
//! blending the voltage model and the current model with a speed-dependent complex gain
//! chosen so that the estimation-error dynamics stay stable in every quadrant, including
//! regeneration at low stator frequency (the stability map and the sampled-loop test below
//! show it on the linearised loop). It gives the cascade the speed; the frame of the field
//! orientation stays the flux model's (the observer's flux and angle are its own).
//!
//! ## Model (inverse-Gamma, amplitude-invariant; this crate's conventions)
//!
//! With `L_sigma = sigma Ls`, `L_M = Lm^2/Lr`, `R_R = (Lm/Lr)^2 Rr`, `alpha = R_R/L_M =
//! 1/tau_r`, `w_m = p Omega` (rad/s electrical) and `psi_R = (Lm/Lr) psi_r` (the crate's
//! `lambda_r`), in stator coordinates
//!
//! ```text
//! d psi_s/dt = u_s - Rs i_s,          psi_s = L_sigma i_s + psi_R
//! d psi_R/dt = R_R i_s - (alpha - j w_m) psi_R
//! ```
//!
//! so the rotor flux's rate of change has two expressions: the voltage model
//! `v = u_s - Rs i_s - L_sigma di_s/dt` and the current model `v_r = R_R i_s - (alpha -
//! j w_m) psi_R`.
//!
//! ## Observer
//!
//! In coordinates aligned with the estimate (`psi_R_hat` real, the frame turning at
//! `w_s`), with `x = v_r_hat - v` and the gain `k`:
//!
//! ```text
//! d psi_R_hat/dt + j w_s psi_R_hat = v + k x + k conj(x) = v + 2 k Re(x)
//! ```
//!
//! The real part integrates the flux magnitude; the imaginary part, which must be zero in
//! the aligned frame, gives the frame's frequency `w_s` in closed form (no algebraic loop:
//! `v` contains `-j w_s L_sigma i_s`):
//!
//! ```text
//! w_s = [Im v_s + 2 Im(k) (R_R i_d - alpha psi_R_hat - Re v_s)]
//!       / [psi_R_hat + L_sigma (i_d + 2 Im(k) i_q)]        v_s = u - Rs i - L_sigma di/dt
//! ```
//!
//! The speed follows the flux frequency less the slip with the bandwidth `alpha_o`:
//! `dw_m_hat/dt = alpha_o (w_s - R_R i_q/psi_R_hat - w_m_hat)`.
//!
//! ## Gain
//!
//! `k = (g0 alpha + g1 |w_m_hat|)/(alpha - j w_m_hat)` (motulator's sensorless default,
//! `g0 = 0.5`, `g1 = 0.2`): at standstill it is a real blend of the two models; as the
//! speed rises the voltage model takes over and the gain's phase turns with the speed,
//! which keeps the error dynamics away from the unstable region of the regenerating mode
//! (Hinkkanen et al. 2010, section IV; see `stability_map` below and the tests).
//!
//! ## Load torque
//!
//! The cascade's load-torque feed-forward wants `T_L_hat`: a second-order mechanical
//! observer `J dOmega_hat/dt = T_e - T_L_hat - B Omega_hat + J l1 (Omega_a - Omega_hat)`,
//! `dT_L_hat/dt = -J l2 (Omega_a - Omega_hat)` runs on the adapted speed `Omega_a =
//! w_m_hat/p` and the cascade's torque `T_e = 1.5 p lambda_r i_q`, its error poles a
//! double pole at `load_bandwidth` (l1 = 2 a, l2 = a^2).
//!
//! `lambda_r` is the drive's rotor-flux model (eq. 13), the flux the speed loop's torque
//! constant and its load feed-forward `T_L_hat / (1.5 p lambda_r)` use, not this
//! observer's `psi_R_hat`: the speed loop has no integral of its own (the load estimate
//! is its integral action, `crate::speed_loop`), so in steady state the feed-forward must
//! give back exactly the torque current the load observer saw. With `psi_R_hat` there, a
//! controller L_M 15 % high (the model flux at the reference, the machine's 13 % below:
//! the observer sees the true one) left 13 % of the torque current to the proportional
//! gain, a steady speed error of 23 rpm at 750 rpm and rated load on motulator's 2.2 kW
//! machine with the estimate right on the rotor. The load estimate is then the torque
//! the model's flux would give: the true load with exact parameters, off by the flux's
//! ratio with an L_M error (as the paper's observer's).
//!
//! ## High stator frequency
//!
//! Two additions to the published design keep the observer in the closed loop at high
//! stator frequency:
//! - the speed adaptation's bandwidth falls as `(s0/s)^2` above a discretisation
//!   sensitivity `s = |w_m_hat| Ts psi_n/psi_R_hat` of [`SENSITIVITY_LIMIT`] (the sampled
//!   voltage model answers a torque-current transient near the stator frequency with a
//!   spurious speed swing that grows with `s`, and the speed loop closes it into a limit
//!   cycle);
//! - the drive's rotor-flux model frame is locked onto this observer's angle from
//!   [`FRAME_LOCK_FROM`] Rs/L_M of stator frequency on ([`crate::observer::SpeedObserver::frame_lock`]).
//!
//! With both, and the currents taken at the period's middle (Discretisation, below), every
//! field-weakening scenario of the paper's and the 2.2 kW machine holds to twice base
//! speed (`tests/flux_observer.rs`); without the schedule `fw-braking-3000` trips, without
//! the lock the reversals to 3000 rpm do. What is left of the discretisation: the flux and
//! the frame are advanced over the next period with the past period's increments (forward
//! Euler, a period's lag in a transient), which a step evaluated in the sampled stator
//! frame would remove.
//!
//! ## Low-speed regeneration and the stator resistance
//!
//! The gain keeps the error dynamics stable while regenerating near zero stator frequency
//! *with the model's parameters right*; there the voltage model carries the speed
//! information only through `Rs i` against a back-EMF of a few volts, and a small Rs error
//! moves the equilibrium far. Measured on motulator's 2.2 kW machine (ideal plant, the
//! peer benchmark's cases `regen-100-45`, rated overhauling load at 45 rpm, stator
//! frequency -0.3 Hz, and `regen-25-15`, a quarter of it at 15 rpm, +0.06 Hz), Rs fixed
//! in the controller (`--set drive.observer=flux --set drive.estimation.rs_estimation=false
//! --set drive.estimation.rs_initial_ohm=R` on `benches/peer/peer.py`'s generated files):
//! Rs exact, held within 0.8 and 0.3 rpm; +0.35 %, 15 and 7 rpm off; +1.1 % and +-5 %, lost
//! (faults `Overload`/`CurrentSensor` after the rotor runs away, or 25 rpm off). motulator
//! 0.5's observer, the same structure and gain, on the same cases: +1.1 % and +5 % lost
//! (the estimate 90-156 rpm off), -5 % diverged. No observer of this class holds these
//! points without Rs known to a fraction of a per cent; with the drive's running Rs law
//! (the default: it adapts in the regenerating mode as well, down to zero stator
//! frequency with this observer, `crate::rs_estimator`, "Down to zero stator frequency")
//! the peer benchmark's regenerating rows hold within its 30 rpm, up to 9 rpm off (half
//! the rated load at 30 rpm; 15.5 rpm at rated load and 45 rpm while the law stopped at
//! 1 Hz). Holding Rs
//! fixed while regenerating at low stator frequency (where Rs and the speed are not
//! observable together) was tried: the limit cycles at 60-75 rpm went (9 rpm peak to
//! peak -> 0.1-1.8), but the rated-load points moved further off (rated load at 45 rpm: 11.6 -> 14.8 rpm off)
//! and two parameter-error cases (L_M -15 %, R_R +30 %, regenerating at 75 rpm) were no
//! longer held: the law had been absorbing those errors into Rs. Not kept.
//!
//! ## Discretisation
//!
//! Forward Euler at Ts, the current's derivative as a backward difference in the
//! observer's frame over the past period, the voltage that acted over that same period
//! (the command of two steps ago: a command is applied over the period after the next
//! sample), taken at the period's mean frame angle (half the frame's turn back: without
//! it a 4 rpm bias at 750 rpm on the 2.2 kW machine), and the current's other terms (the
//! resistive drop, the current model, the rotation's `w_s L_sigma i`, the slip) at the
//! period's middle too, the mean of its two samples: every term of the voltage and current
//! models then belongs to the same period. (Taken at the period's end, they answered a
//! torque-current swing near the stator frequency with a speed swing three times larger
//! at 1.7 x base speed, `tests::the_speed_response_to_torque_current_stays_bounded_at_high_speed`,
//! which the speed loop closed into growing oscillations: the 37 kW machine tripped at
//! 1500 rpm, the paper's machine from its nameplate at 1640 rpm.) The
//! frame kept as a unit vector rotated by `w_s Ts` with a fifth-order series and one
//! renormalisation step (no trigonometric call). Every division is by a quantity bounded
//! away from zero (`alpha^2 + w^2 >= alpha^2`, the flux and the denominator of `w_s` are
//! guarded); a non-finite sample keeps the last state.

use crate::math::{clamp, is_finite};
use crate::params::MachineParams;

/// Flux (Wb) below which the frame's frequency and the slip are not defined (the
/// observer then holds the adapted speed as the frame's frequency): about 1 % of any
/// industrial machine's rated rotor flux.
pub const FLUX_FLOOR: f32 = 0.01;

/// The discretisation sensitivity `s = |w_m_hat| Ts psi_n/psi_R_hat` above which the
/// speed adaptation's bandwidth is reduced, as `alpha_o (s0/s)^2`.
///
/// Why: the forward-Euler voltage model, evaluated once per period in a frame that turns
/// by `w_s Ts`, answers a torque-current transient near the stator frequency (the
/// stator frame's slow mode, which the gain damps least at high speed) with a spurious
/// speed swing. Measured on the sampled observer with exact machine signals
/// (`tests::the_speed_response_to_torque_current_stays_bounded_at_high_speed`), the swing
/// per ampere grows with `s` (with the currents at the period's end: twice the speed at
/// the same flux, twice the swing; a quarter of the period, a fifth) and, in field
/// weakening, faster. The speed loop and the load observer's feed-forward close that
/// swing into a loop whose gain is the adaptation's bandwidth times it: on the 2.2 kW
/// machine above 2200 rpm (1.5 x base speed, `s` = 0.16 at 5 kHz) a limit cycle at about
/// 1.2 x the stator frequency grew to +-40 rpm; with the currents at the period's middle
/// the paper's machine still tripped braking from 3000 rpm. Scaling the bandwidth by
/// `(s0/s)^2` holds that gain near its value at `s0` as the sensitivity grows. Below `s0` the
/// observer is the published design: at 5 kHz and rated flux `s0` is reached at
/// 650 rad/s electrical, above the base speed of 50 and 60 Hz machines; in field
/// weakening sooner, at higher PWM rates later.
pub const SENSITIVITY_LIMIT: f32 = 0.13;

/// Bandwidth of the drive frame's lock onto the observer's flux angle, rad/s (80 Hz:
/// above the speed adaptation's 40 Hz, a tenth of a 5 kHz period's step).
pub const FRAME_BANDWIDTH: f32 = 500.0;

/// The frame lock acts from this many times Rs/L_M of stator frequency (full at twice
/// that). At w_s = Rs/L_M the resistive drop on the flux current equals the flux's
/// back-EMF: well above it the observer's angle is the voltage model's, which carries
/// no rotor-model error (the model's frame lags a speed estimate's error through
/// 1/tau_r: on the 2.2 kW machine reversing at 3000 rpm it lost the rotor without the
/// lock); below it the observer's angle leans on the same rotor model with its gain's
/// current-model share, and an L_M error there turns it faster than the model's own
/// frame (L_M -15 % regenerating rated load at 75 rpm: the locked frame drifted to
/// -30 degrees and tripped; unlocked it holds).
pub const FRAME_LOCK_FROM: f32 = 3.0;

/// Design choices of the flux observer.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FluxObserverDesign {
    /// Speed-adaptation bandwidth alpha_o, rad/s.
    pub speed_bandwidth: f32,
    /// Gain's standstill part g0 (times alpha): the current model's share at zero speed.
    pub gain_standstill: f32,
    /// Gain's speed part g1 (times |w_m_hat|).
    pub gain_speed: f32,
    /// Load-torque observer's double pole, rad/s.
    pub load_bandwidth: f32,
    /// Speed clamp, rad/s mechanical.
    pub max_speed: f32,
    /// The rated rotor flux psi_R (L_M times the flux current), Wb: the reference of the
    /// speed adaptation's schedule at high stator frequency (`sensitivity_limit`).
    pub nominal_flux: f32,
    /// The discretisation sensitivity |w_m_hat| Ts psi_n/psi_R_hat above which the speed
    /// adaptation's bandwidth falls as its inverse square (0: never).
    pub sensitivity_limit: f32,
    /// Bandwidth of the lock of the drive's frame onto the observer's flux angle, rad/s.
    pub frame_bandwidth: f32,
    /// The fastest the adapted speed may move, rad/s^2 mechanical (0: unbounded): a
    /// bound on what the rotor can do ([`MAX_ACCELERATION_OVER_TORQUE`]), so that a
    /// current sample the applied voltage cannot explain (a sensor failing) does not
    /// kick the speed estimate, and the speed loop with it, faster than the rotor moves.
    pub max_acceleration: f32,
}

/// The adapted speed's rate bound is this multiple of the drive's largest torque
/// (`1.5 p L_M i_sd* I_limit`, the flux current against the whole current limit) over
/// the controller's J: the rotor's acceleration with a load as large as that torque
/// opposing or driving it, times two for a controller J up to twice the rotor's.
///
/// Why: the voltage model takes the current's derivative, `L_sigma di/dt`. A current
/// channel that fails (reading 0 A, or stuck) steps the measured current by up to the
/// whole load current in one period with no voltage to drive it: on the 37 kW machine at
/// 500 rpm, all channels dead at 28 A of flux current, the frame frequency took a
/// 100 rad/s kick and the adapted speed jumped 30 rpm in the one step; the speed loop
/// answered with a 96 A torque-current reference, and the control monitor named the
/// failed sensing `CurrentRegulation` 1 ms later, before the sensor check could name the
/// channel. The rotor of that machine moves at most 1 rpm in a period.
pub const MAX_ACCELERATION_OVER_TORQUE: f32 = 4.0;

impl FluxObserverDesign {
    /// The defaults: alpha_o = 2 pi 40 rad/s, g0 = 0.5, g1 = 0.2 (motulator's sensorless
    /// defaults), the load observer at alpha_o/2, the speed clamped at twice the drive's
    /// `max_speed` (rad/s mechanical: an overspeed stays visible), the rated rotor flux
    /// `nominal_flux` (Wb) and the adaptation's schedule from [`SENSITIVITY_LIMIT`].
    pub fn defaults(max_speed: f32, nominal_flux: f32) -> Self {
        let alpha_o = 2.0 * core::f32::consts::PI * 40.0;
        // bound set by the drive (`FluxObserver::new`), which knows the current limit
        Self {
            speed_bandwidth: alpha_o,
            gain_standstill: 0.5,
            gain_speed: 0.2,
            load_bandwidth: 0.5 * alpha_o,
            max_speed: 2.0 * max_speed,
            nominal_flux,
            sensitivity_limit: SENSITIVITY_LIMIT,
            frame_bandwidth: FRAME_BANDWIDTH,
            max_acceleration: 0.0,
        }
    }
}

/// Why a flux-observer design was rejected.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum FluxObserverDesignError {
    /// The period is not finite and positive.
    BadPeriod,
    /// A bandwidth, gain or the speed clamp is not finite and positive (g1 may be 0).
    BadGain,
    /// A bandwidth times Ts is 0.5 or more: Euler at this period would not be accurate.
    TooFast,
}

/// Precomputed constants of the flux observer (configuration).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FluxObserverConfig {
    /// Control period Ts, s.
    pub ts: f32,
    /// 1/Ts, 1/s.
    pub inv_ts: f32,
    /// Ts/2, s.
    pub half_ts: f32,
    /// Pole pairs p.
    pub pole_pairs: f32,
    /// 1/p.
    pub inv_pole_pairs: f32,
    /// L_sigma = sigma Ls, H.
    pub l_sigma: f32,
    /// R_R, ohm.
    pub r_r: f32,
    /// alpha = R_R/L_M, 1/s.
    pub alpha: f32,
    /// alpha^2, 1/s^2.
    pub alpha_sq: f32,
    /// g0 alpha, 1/s.
    pub g0_alpha: f32,
    /// g1.
    pub g1: f32,
    /// Ts alpha_o.
    pub ts_alpha_o: f32,
    /// Ts psi_n, Wb s: the sensitivity's scale.
    pub ts_nominal_flux: f32,
    /// s0, the sensitivity limit.
    pub sensitivity_limit: f32,
    /// The frame lock's bandwidth, rad/s.
    pub frame_bandwidth: f32,
    /// The stator frequency from which the frame lock fades in (full at twice it), rad/s
    /// electrical: [`FRAME_LOCK_FROM`] Rs/L_M.
    pub frame_lock_frequency: f32,
    /// Flux below which the slip and w_s fall back (no division), Wb.
    pub flux_floor: f32,
    /// 1.5 p Ts/J: torque (flux x current) to speed per step, 1/(kg m^2) s.
    pub ts_torque_per_inertia: f32,
    /// Ts/J, s/(kg m^2).
    pub ts_inv_inertia: f32,
    /// Ts B/J.
    pub ts_friction_rate: f32,
    /// Ts l1 = Ts 2 a.
    pub ts_l1: f32,
    /// Ts J l2 = Ts J a^2, N m s/rad per step.
    pub ts_j_l2: f32,
    /// Speed clamp, rad/s electrical.
    pub max_speed_elec: f32,
    /// The adapted speed's largest change per step, rad/s electrical (infinite: none).
    pub max_speed_step_elec: f32,
    /// The design it was built from.
    pub design: FluxObserverDesign,
}

impl FluxObserverConfig {
    /// Designs the observer for the controller's machine model `m` at period `ts` (s).
    pub fn new(
        m: &MachineParams,
        design: FluxObserverDesign,
        ts: f32,
    ) -> Result<Self, FluxObserverDesignError> {
        if !(is_finite(ts) && ts > 0.0) {
            return Err(FluxObserverDesignError::BadPeriod);
        }
        let d = design;
        let positive = |x: f32| is_finite(x) && x > 0.0;
        if !(positive(d.speed_bandwidth)
            && positive(d.gain_standstill)
            && is_finite(d.gain_speed)
            && d.gain_speed >= 0.0
            && positive(d.load_bandwidth)
            && positive(d.max_speed)
            && is_finite(d.nominal_flux)
            && d.nominal_flux >= 0.0
            && is_finite(d.sensitivity_limit)
            && d.sensitivity_limit >= 0.0
            && is_finite(d.frame_bandwidth)
            && d.frame_bandwidth >= 0.0
            && is_finite(d.max_acceleration)
            && d.max_acceleration >= 0.0)
        {
            return Err(FluxObserverDesignError::BadGain);
        }
        if d.speed_bandwidth * ts >= 0.5
            || 2.0 * d.load_bandwidth * ts >= 0.5
            || d.frame_bandwidth * ts >= 0.5
        {
            return Err(FluxObserverDesignError::TooFast);
        }
        let pp = m.pole_pairs_f32();
        let r_r = m.referred_rotor_resistance();
        let alpha = r_r / m.magnetizing_inductance();
        let j = m.inertia();
        let a = d.load_bandwidth;
        Ok(Self {
            ts,
            inv_ts: 1.0 / ts,
            half_ts: 0.5 * ts,
            pole_pairs: pp,
            inv_pole_pairs: 1.0 / pp,
            l_sigma: m.transient_inductance(),
            r_r,
            alpha,
            alpha_sq: alpha * alpha,
            g0_alpha: d.gain_standstill * alpha,
            g1: d.gain_speed,
            ts_alpha_o: ts * d.speed_bandwidth,
            ts_nominal_flux: ts * d.nominal_flux,
            sensitivity_limit: d.sensitivity_limit,
            frame_bandwidth: d.frame_bandwidth,
            frame_lock_frequency: FRAME_LOCK_FROM * m.stator_resistance()
                / m.magnetizing_inductance(),
            flux_floor: FLUX_FLOOR,
            ts_torque_per_inertia: ts * 1.5 * pp / j,
            ts_inv_inertia: ts / j,
            ts_friction_rate: ts * m.viscous_friction() / j,
            ts_l1: ts * 2.0 * a,
            ts_j_l2: ts * j * a * a,
            max_speed_elec: d.max_speed * pp,
            max_speed_step_elec: if d.max_acceleration > 0.0 {
                d.max_acceleration * pp * ts
            } else {
                f32::INFINITY
            },
            design,
        })
    }

    /// The observer gain k(w_m_hat) = (g0 alpha + g1 |w|)/(alpha - j w) as (Re, Im), for
    /// `w` in rad/s electrical.
    #[inline(always)]
    pub fn gain(&self, w: f32) -> (f32, f32) {
        let num = self.g0_alpha + self.g1 * w.abs();
        // alpha^2 + w^2 >= alpha^2 > 0
        let s = num / (self.alpha_sq + w * w);
        (s * self.alpha, s * w)
    }
}

/// Flux-observer state.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FluxObserverState {
    /// psi_R_hat, Wb (real: the frame is aligned with it).
    pub flux: f32,
    /// cos of the estimated flux angle.
    pub cos: f32,
    /// sin of the estimated flux angle.
    pub sin: f32,
    /// w_m_hat, rad/s electrical (the adapted speed).
    pub speed_elec: f32,
    /// The frame's frequency w_s of the last step, rad/s electrical.
    pub stator_frequency: f32,
    /// Stator current in the observer's frame at the last step, A (d, q).
    pub last_current: (f32, f32),
    /// The voltage command of the last step, stationary frame, V (alpha, beta): the one
    /// applied over the period this step's current difference spans.
    pub last_voltage: (f32, f32),
    /// Mechanical observer's speed Omega_hat, rad/s mechanical.
    pub model_speed: f32,
    /// T_L_hat, N m.
    pub load_torque: f32,
}

impl Default for FluxObserverState {
    fn default() -> Self {
        Self::new()
    }
}

impl FluxObserverState {
    /// No flux, angle 0, at rest.
    pub const fn new() -> Self {
        Self {
            flux: 0.0,
            cos: 1.0,
            sin: 0.0,
            speed_elec: 0.0,
            stator_frequency: 0.0,
            last_current: (0.0, 0.0),
            last_voltage: (0.0, 0.0),
            model_speed: 0.0,
            load_torque: 0.0,
        }
    }

    /// The adapted speed, rad/s mechanical.
    pub fn speed(&self, cfg: &FluxObserverConfig) -> f32 {
        self.speed_elec * cfg.inv_pole_pairs
    }

    /// One step: `u` the stator voltage commanded at the last step (in the drive's
    /// timing, applied over the period from this sample to the next: the observer keeps
    /// it for the next step, and uses the one before, which acted over the past period)
    /// and `i` the current sampled now, both stationary alpha-beta (V, A), `rs` the
    /// stator resistance the observer assumes (ohm; the running estimate), `torque_flux`
    /// the flux of the cascade's torque constant (Wb; the drive's rotor-flux model, which
    /// the speed loop's load feed-forward divides by: see "Load torque").
    /// Out of line (`inline(never)`): inlined into the drive's step it added 4.5 KB to
    /// the firmware's CCM SRAM code (27976 -> 32440 B of 32768; the self-test build
    /// overflowed it), out of line 0.35 KB.
    #[inline(never)]
    pub fn update(
        &mut self,
        cfg: &FluxObserverConfig,
        u: (f32, f32),
        i: (f32, f32),
        rs: f32,
        torque_flux: f32,
    ) {
        let (c, s) = (self.cos, self.sin);
        // into the estimated rotor-flux frame: x e^{-j theta}
        let i_d = c * i.0 + s * i.1;
        let i_q = c * i.1 - s * i.0;
        // the voltage that acted over the past period, (k-1, k), the interval of the
        // current's difference: the command given one step ago (the command of a step is
        // applied over the period after the next sample), its mean in this frame
        // e^{j w_s Ts/2} e^{-j theta} u to first order in the frame's turn over the period
        let u_past = self.last_voltage;
        self.last_voltage = u;
        let h = cfg.half_ts * self.stator_frequency;
        let (u_d0, u_q0) = (c * u_past.0 + s * u_past.1, c * u_past.1 - s * u_past.0);
        let u_d = u_d0 - h * u_q0;
        let u_q = u_q0 + h * u_d0;
        let psi = self.flux;
        let w = self.speed_elec;
        // voltage model without the frame's rotation: v_s = u - Rs i - L_sigma di/dt
        let did = (i_d - self.last_current.0) * cfg.inv_ts;
        let diq = (i_q - self.last_current.1) * cfg.inv_ts;
        let (im_d, im_q) = (
            0.5 * (i_d + self.last_current.0),
            0.5 * (i_q + self.last_current.1),
        );
        let vs_d = u_d - rs * im_d - cfg.l_sigma * did;
        let vs_q = u_q - rs * im_q - cfg.l_sigma * diq;
        let (k_re, k_im) = cfg.gain(w);
        // Re of the current model less the voltage model's real part (w_s-free)
        let r0 = cfg.r_r * im_d - cfg.alpha * psi - vs_d;
        let den = psi + cfg.l_sigma * (im_d + 2.0 * k_im * im_q);
        let ws = if den > cfg.flux_floor {
            (vs_q + 2.0 * k_im * r0) / den
        } else {
            w
        };
        // the full real parts with w_s: v = v_s - j w_s L_sigma i
        let v_d = vs_d + ws * cfg.l_sigma * im_q;
        let x_d = r0 - ws * cfg.l_sigma * im_q;
        let d_psi = v_d + 2.0 * k_re * x_d;
        let slip = if psi > cfg.flux_floor {
            cfg.r_r * im_q / psi
        } else {
            0.0
        };
        // the adaptation's bandwidth, reduced as (s0/s)^2 above the sensitivity limit
        // (SENSITIVITY_LIMIT): s psi = |w| Ts psi_n against s0 psi, the division only by
        // a sensitivity above a positive limit
        let sens = w.abs() * cfg.ts_nominal_flux;
        let limit = cfg.sensitivity_limit * psi;
        let ts_alpha = if sens > limit && limit > 0.0 {
            let r = limit / sens;
            cfg.ts_alpha_o * r * r
        } else {
            cfg.ts_alpha_o
        };
        let step = cfg.max_speed_step_elec;
        let new_w = clamp(
            w + clamp(ts_alpha * (ws - slip - w), -step, step),
            -cfg.max_speed_elec,
            cfg.max_speed_elec,
        );
        let new_psi = (psi + cfg.ts * d_psi).max(0.0);
        // the frame turns by delta = w_s Ts: e^{j delta} by its series, then one Newton
        // step back onto the unit circle
        let delta = ws * cfg.ts;
        let d2 = delta * delta;
        let cd = 1.0 - 0.5 * d2 * (1.0 - d2 * (1.0 / 12.0));
        let sd = delta * (1.0 - d2 * (1.0 / 6.0) * (1.0 - d2 * 0.05));
        let nc = c * cd - s * sd;
        let ns = s * cd + c * sd;
        let norm = 1.5 - 0.5 * (nc * nc + ns * ns);
        // the load observer on the adapted speed
        let speed_a = new_w * cfg.inv_pole_pairs;
        let e = speed_a - self.model_speed;
        let model_speed = self.model_speed + cfg.ts_torque_per_inertia * torque_flux * i_q
            - cfg.ts_inv_inertia * self.load_torque
            - cfg.ts_friction_rate * self.model_speed
            + cfg.ts_l1 * e;
        let load = self.load_torque - cfg.ts_j_l2 * e;
        if is_finite(new_psi + new_w + nc + ns + model_speed + load + i_d + i_q) {
            self.flux = new_psi;
            self.cos = nc * norm;
            self.sin = ns * norm;
            self.speed_elec = new_w;
            self.stator_frequency = ws;
            // the current in this step's frame: the next step's difference in the
            // estimated-flux coordinates (their derivative, the rotation apart)
            self.last_current = (i_d, i_q);
            self.model_speed = model_speed;
            self.load_torque = load;
        }
    }
}

/// The flux observer as the cascade's speed observer ([`crate::observer::SpeedObserver`]):
/// design and state together, so that `Drive<_, f32, FluxObserver>` runs it in the closed
/// loop. It runs from the first magnetizing step on the measured alpha-beta current and
/// the alpha-beta voltage commanded for the past period (with the frame held at rest its
/// flux estimate is the drive's flux model in that frame; on a flying start it builds its
/// own);
/// its speed is held while magnetizing at the speed the rotor turns at (0 at rest, the
/// speed search's on a flying start). It follows the running Rs estimate (from
/// `equivalent_resistance - R_R`).
#[derive(Clone, Debug)]
pub struct FluxObserver {
    cfg: FluxObserverConfig,
    state: FluxObserverState,
    /// The speed held while magnetizing, rad/s electrical.
    preset_elec: f32,
}

impl FluxObserver {
    /// Designs the observer for the controller's machine `m` at period `ts` (s) with
    /// [`FluxObserverDesign::defaults`], the speed clamp `max_speed` (rad/s mechanical) and
    /// the drive's flux current `flux_current` (A peak, i_sd*: the rated flux is L_M
    /// i_sd*) and the adapted speed's rate bound from the current limit `current_limit`
    /// (A peak, [`MAX_ACCELERATION_OVER_TORQUE`]).
    pub fn new(
        m: &MachineParams,
        ts: f32,
        max_speed: f32,
        flux_current: f32,
        current_limit: f32,
    ) -> Result<Self, FluxObserverDesignError> {
        let nominal_flux = m.magnetizing_inductance() * flux_current;
        let mut design = FluxObserverDesign::defaults(max_speed, nominal_flux);
        // the drive's largest torque, 1.5 p psi_n I_limit, over J (J > 0: MachineParams)
        let torque = 1.5 * m.pole_pairs_f32() * nominal_flux * current_limit;
        design.max_acceleration = MAX_ACCELERATION_OVER_TORQUE * torque / m.inertia();
        Self::with_design(m, design, ts)
    }
    /// Designs the observer with `design`.
    pub fn with_design(
        m: &MachineParams,
        design: FluxObserverDesign,
        ts: f32,
    ) -> Result<Self, FluxObserverDesignError> {
        Ok(Self {
            cfg: FluxObserverConfig::new(m, design, ts)?,
            state: FluxObserverState::new(),
            preset_elec: 0.0,
        })
    }
    /// The design in use.
    pub fn config(&self) -> &FluxObserverConfig {
        &self.cfg
    }
    /// The observer state.
    pub fn state(&self) -> &FluxObserverState {
        &self.state
    }
}

impl crate::observer::SpeedObserver for FluxObserver {
    /// No far-side term: the gain keeps the regenerating region stable by itself.
    #[inline(always)]
    fn far_side_term(&self) -> bool {
        false
    }
    /// The observer estimates the flux and the speed in its own frame.
    #[inline(always)]
    fn orientation_correction(&self) -> bool {
        false
    }
    /// The gain is stable while regenerating (module docs).
    #[inline(always)]
    fn regeneration_limit(&self) -> bool {
        false
    }
    /// Rs adapts at low stator frequency only, where it is observable.
    #[inline(always)]
    fn rs_running_at_speed(&self) -> bool {
        false
    }
    /// The drive's frame follows this observer's flux angle.
    #[inline(always)]
    fn frame_lock(&self) -> bool {
        true
    }
    /// `frame_bandwidth` times sin(theta_observer - theta_model) (rad/s electrical): a
    /// phase-locked loop that holds the model's frame on the observer's where the
    /// observer's angle is the voltage model's ([`FRAME_LOCK_FROM`]); none before the
    /// observer has a flux.
    #[inline(always)]
    fn frame_pull(&self, model: &crate::frames::SinCosValue<f32>) -> f32 {
        let ws = self.state.stator_frequency.abs();
        let w1 = self.cfg.frame_lock_frequency;
        if self.state.flux <= self.cfg.flux_floor || ws <= w1 {
            return 0.0;
        }
        // faded in from w1 to 2 w1 (w1 = 3 Rs/L_M > 0: MachineParams takes Rs, L_M > 0)
        let weight = ((ws - w1) / w1).min(1.0);
        let (c, s) = (self.state.cos, self.state.sin);
        weight * self.cfg.frame_bandwidth * (s * model.cos - c * model.sin)
    }
    #[inline(always)]
    fn update(
        &mut self,
        _coeffs: &crate::observer::ObserverCoeffs<f32>,
        x: &crate::observer::SpeedObserverInputs,
    ) -> crate::observer::SpeedEstimate {
        // (R_R of the same machine model as the drive's design)
        let rs = x.equivalent_resistance - self.cfg.r_r;
        self.state.update(
            &self.cfg,
            (x.v_ab.alpha, x.v_ab.beta),
            (x.i_ab.alpha, x.i_ab.beta),
            rs,
            x.rotor_flux,
        );
        if x.magnetizing {
            // the rotor speed is known while the flux builds: adaptation starts with
            // speed control
            self.state.speed_elec = self.preset_elec;
            self.state.model_speed = self.preset_elec * self.cfg.inv_pole_pairs;
            self.state.load_torque = 0.0;
        }
        if x.frame_held {
            // at rest with the frame held the rotor flux builds along the frame, at the
            // rate of the current model (no rotation: the voltage model adds nothing but
            // its Rs error): the estimate is the drive's flux model in that frame. Left
            // to the voltage model while Rs was still being identified, the estimate was
            // drained by the resistance error (Rs +20 % on the 0.18 kW machine: 7.7 V
            // against the flux) and turned away from the frame, and at the handover the
            // adapted speed ran off at its rate bound (-460 rpm in 10 ms, the rotor
            // driven to +270 rpm, LossOfControl)
            self.state.flux = x.rotor_flux.max(0.0);
            self.state.cos = x.frame.cos;
            self.state.sin = x.frame.sin;
            self.state.stator_frequency = 0.0;
            // the current in that frame, for the next step's difference
            self.state.last_current = (x.i_dq.d, x.i_dq.q);
        }
        crate::observer::SpeedEstimate {
            speed: self.state.speed(&self.cfg),
            load_torque: self.state.load_torque,
            current: x.i_dq.q,
        }
    }
    fn reset(&mut self) {
        self.state = FluxObserverState::new();
        self.preset_elec = 0.0;
    }
    fn start_running(&mut self, _i_sq: f32) {
        self.state.load_torque = 0.0;
    }
    fn preset_speed(&mut self, speed: f32) {
        self.preset_elec = speed * self.cfg.pole_pairs;
    }
    #[inline(always)]
    fn estimate(&self) -> crate::observer::SpeedEstimate {
        crate::observer::SpeedEstimate {
            speed: self.state.speed(&self.cfg),
            load_torque: self.state.load_torque,
            current: 0.0,
        }
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use crate::frames::FastSinCos;
    use crate::params::{InverseGamma, MachineParams};

    const TS: f32 = 200e-6;

    /// motulator's 2.2 kW machine (inverse-Gamma data of its example) and the paper's.
    fn machines() -> [(MachineParams, f32, f32); 2] {
        let m2k2 = MachineParams::from_inverse_gamma(InverseGamma {
            stator_resistance: 3.7,
            rotor_resistance: 2.1,
            leakage_inductance: 0.021,
            magnetizing_inductance: 0.224,
            pole_pairs: 2,
            inertia: 0.015,
            viscous_friction: 0.0,
        })
        .unwrap();
        // (machine, rated flux Wb, rated torque current A)
        [
            (m2k2, 0.95, 5.1),
            (
                MachineParams::paper_table1(),
                MachineParams::paper_table1().rotor_flux_for(1.5),
                2.6,
            ),
        ]
    }

    /// The steady state at electrical rotor speed `w_m` with rotor flux `psi` and torque
    /// current `i_q`: (i_d, w_s, u_d, u_q) in the flux frame.
    fn steady(m: &MachineParams, psi: f32, i_q: f32, w_m: f32) -> (f32, f32, f32, f32) {
        let i_d = psi / m.magnetizing_inductance();
        let ws = w_m + m.referred_rotor_resistance() * i_q / psi;
        let ls = m.transient_inductance();
        let rs = m.stator_resistance();
        // u = Rs i + j w_s (L_sigma i + psi)
        (
            i_d,
            ws,
            rs * i_d - ws * ls * i_q,
            rs * i_q + ws * (ls * i_d + psi),
        )
    }

    fn rotate(x: (f32, f32), angle: f32) -> (f32, f32) {
        let sc = FastSinCos::eval(angle);
        (sc.cos * x.0 - sc.sin * x.1, sc.sin * x.0 + sc.cos * x.1)
    }

    /// Runs the observer on the exact sampled signals of a steady operating point (the
    /// drive's timing: the command given at a sample acts over the next period), from the
    /// true state disturbed by `(flux fraction, angle rad, speed rad/s)`; returns the
    /// largest |speed error| (rad/s electrical) in each tenth of `seconds`.
    fn run(
        m: &MachineParams,
        psi: f32,
        i_q: f32,
        w_m: f32,
        disturbance: (f32, f32, f32),
        seconds: f32,
    ) -> [f32; 10] {
        let cfg =
            FluxObserverConfig::new(m, FluxObserverDesign::defaults(400.0, 0.95), TS).unwrap();
        let (i_d, ws, u_d, u_q) = steady(m, psi, i_q, w_m);
        let mut s = FluxObserverState::new();
        s.flux = psi * (1.0 + disturbance.0);
        let sc = FastSinCos::eval(disturbance.1);
        (s.cos, s.sin) = (sc.cos, sc.sin);
        s.speed_elec = w_m + disturbance.2;
        s.stator_frequency = ws;
        s.last_current = (i_d, i_q);
        s.last_voltage = rotate((u_d, u_q), -0.5 * ws * TS);
        let n = (seconds / TS) as usize;
        let mut worst = [0.0f32; 10];
        let mut theta = 0.0f32;
        // the mean of a vector turning at w_s over a period is its mid value shrunk by
        // sinc(w_s Ts/2)
        let shrink = 1.0 - (0.5 * ws * TS) * (0.5 * ws * TS) / 6.0;
        for k in 0..n {
            let u = rotate((shrink * u_d, shrink * u_q), theta + 0.5 * ws * TS);
            let i = rotate((i_d, i_q), theta);
            s.update(&cfg, u, i, m.stator_resistance(), psi);
            let e = (s.speed_elec - w_m).abs();
            let slot = (10 * k / n).min(9);
            worst[slot] = worst[slot].max(if e.is_finite() { e } else { f32::MAX });
            theta = crate::math::wrap_angle(theta + ws * TS);
        }
        worst
    }

    /// The sampled loop, linearised in effect: small disturbances of the flux, the angle
    /// and the speed die away at every operating point of a grid over the four
    /// quadrants, motoring and regenerating with half and rated torque current, on both
    /// machines: at least 5 rad/s from w_s = 0 the last tenth of 4 s holds less than 2 %
    /// of the initial speed error. At w_s = +-1 rad/s (where the paper's observer needs
    /// the regeneration limit; at w_s = 0 the speed is unobservable for any sensorless
    /// estimator) the slowest mode is slow: after 4 s within 25 % of the initial error,
    /// and where it is not falling (the far side, the field turning against the rotor,
    /// at rated regenerating torque) growing at most 20 %/s (measured 12 %/s on the
    /// 2.2 kW machine): the closed loop's speed control moves the point, and the drive
    /// holds it (the regenerating cases of `tests/flux_observer.rs`).
    #[test]
    fn small_disturbances_die_away_in_every_quadrant() {
        for (m, psi, i_rated) in machines() {
            let r_r = m.referred_rotor_resistance();
            let w_rated = 2.0 * core::f32::consts::PI * 50.0;
            for frac in [-1.0f32, -0.5, 0.5, 1.0] {
                let i_q = frac * i_rated;
                let slip = r_r * i_q / psi;
                for w in [-1.0f32, -0.3, -0.1, 0.0, 0.1, 0.3, 1.0] {
                    let w = w * w_rated;
                    if (w + slip).abs() < 5.0 {
                        continue;
                    }
                    let worst = run(&m, psi, i_q, w, (0.01, 0.01, 2.0), 4.0);
                    assert!(
                        worst[9] < 0.04,
                        "R_R {r_r}: w_m {w} rad/s, i_q {i_q} A (w_s {}): {worst:?}",
                        w + slip
                    );
                }
                // w_s = +-1 rad/s: at w_s = 0 the speed is unobservable for any
                // sensorless estimator, and the slowest mode is slow next to it
                for ws in [-1.0f32, 1.0] {
                    let w = ws - slip;
                    let worst = run(&m, psi, i_q, w, (0.01, 0.01, 2.0), 4.0);
                    let label = std::format!("R_R {r_r}: w_m {w} rad/s, i_q {i_q} A (w_s {ws})");
                    // slow next to the line, on either side: after 4 s within 25 % of
                    // the initial error, and any growth slower than 20 %/s
                    let rate = (worst[9] / worst[1]).ln() / (0.8 * 4.0);
                    assert!(worst[9] < 0.5 && rate < 0.2, "{label}: {worst:?}");
                }
            }
        }
    }

    /// Large initial errors (10 % flux, 0.2 rad, 5 % of the rated speed) at the
    /// regenerating points of the peer benchmark (15-75 rpm with 25-100 % of rated load on
    /// the 2.2 kW machine) away from w_s = 0 (2 rad/s on the near side, 5 on the far
    /// side): the observer finds the true
    /// state again (the speed error below 0.5 rad/s electrical and still falling after
    /// 4 s).
    #[test]
    fn recovers_from_large_errors_while_regenerating_at_low_speed() {
        let (m, psi, i_rated) = machines()[0];
        let w_rated = 2.0 * core::f32::consts::PI * 50.0;
        for rpm in [15.0f32, 30.0, 45.0, 75.0] {
            let w = rpm * crate::math::RPM_TO_RAD_S * 2.0;
            for load in [0.25f32, 0.5, 1.0] {
                let ws = w - m.referred_rotor_resistance() * load * i_rated / psi;
                if ws.abs() < 2.0 || (ws * w < 0.0 && ws.abs() < 5.0) {
                    // 15 rpm at 25 % load: w_s = 0.3 rad/s, on the unobservable line; at
                    // half load -2.5 rad/s, on its weakly unstable far side (above)
                    continue;
                }
                for sign in [-1.0f32, 1.0] {
                    let worst = run(
                        &m,
                        psi,
                        -load * i_rated,
                        w,
                        (-0.1 * sign, 0.2 * sign, 0.05 * w_rated * sign),
                        4.0,
                    );
                    assert!(
                        worst[9] < 0.5 && worst[9] <= worst[3] + 1e-3,
                        "{rpm} rpm, {load} load: {worst:?}"
                    );
                }
            }
        }
    }

    /// The speed estimate's swing per ampere of a torque-current oscillation at `f_p` Hz
    /// (rad/s electrical per A, the amplitude of the fitted sine), the machine turning at
    /// `w_m` (rad/s electrical) with the flux `psi` (Wb) and torque current `i_q` (A):
    /// exact signals of the machine's equations integrated finely over each period (the
    /// period's mean voltage, the current sampled at its ends), fed in the drive's timing.
    fn speed_swing(
        cfg: &FluxObserverConfig,
        m: &MachineParams,
        psi: f32,
        i_q: f32,
        w_m: f32,
        f_p: f32,
    ) -> f64 {
        let ts = cfg.ts as f64;
        let sub = 40usize;
        let h = ts / sub as f64;
        let (rs, ls) = (
            m.stator_resistance() as f64,
            m.transient_inductance() as f64,
        );
        let r_r = m.referred_rotor_resistance() as f64;
        let alpha = r_r / m.magnetizing_inductance() as f64;
        let (wm, iq0) = (w_m as f64, i_q as f64);
        let id0 = psi as f64 / m.magnetizing_inductance() as f64;
        let ws0 = wm + r_r * iq0 / psi as f64;
        let (a, wp) = (0.2f64, 2.0 * core::f64::consts::PI * f_p as f64);
        // the current: (i_d + j i_q(t)) e^{j w_s t}, i_q(t) = i_q + a sin(w_p t)
        let cur = |t: f64| {
            let iq = iq0 + a * (wp * t).sin();
            let (c, s) = ((ws0 * t).cos(), (ws0 * t).sin());
            (c * id0 - s * iq, s * id0 + c * iq)
        };
        let mut flux = (psi as f64, 0.0f64);
        let mut st = FluxObserverState::new();
        st.flux = psi;
        st.speed_elec = w_m;
        st.stator_frequency = ws0 as f32;
        st.last_current = (id0 as f32, iq0 as f32);
        let n = (2.0 / ts) as usize;
        let (mut sc, mut cc, mut count) = (0.0f64, 0.0f64, 0usize);
        for k in 0..n {
            let t = k as f64 * ts;
            let (i0, i1) = (cur(t), cur(t + ts));
            let (start, mut mean) = (flux, (0.0, 0.0));
            for j in 0..sub {
                let i = cur(t + (j as f64 + 0.5) * h);
                mean = (mean.0 + i.0 / sub as f64, mean.1 + i.1 / sub as f64);
                // d psi_R/dt = R_R i - (alpha - j w_m) psi_R
                let d = (
                    r_r * i.0 - alpha * flux.0 - wm * flux.1,
                    r_r * i.1 - alpha * flux.1 + wm * flux.0,
                );
                flux = (flux.0 + h * d.0, flux.1 + h * d.1);
            }
            // the period's mean voltage: Rs i + L_sigma di/dt + d psi_R/dt
            let u = (
                rs * mean.0 + ls * (i1.0 - i0.0) / ts + (flux.0 - start.0) / ts,
                rs * mean.1 + ls * (i1.1 - i0.1) / ts + (flux.1 - start.1) / ts,
            );
            if k == 0 {
                st.last_voltage = (u.0 as f32, u.1 as f32);
            }
            st.update(
                cfg,
                (u.0 as f32, u.1 as f32),
                (i0.0 as f32, i0.1 as f32),
                rs as f32,
                psi,
            );
            if t > 1.0 {
                let e = st.speed_elec as f64 - wm;
                sc += e * (wp * t).sin();
                cc += e * (wp * t).cos();
                count += 1;
            }
        }
        let (sc, cc) = (2.0 * sc / count as f64, 2.0 * cc / count as f64);
        (sc * sc + cc * cc).sqrt() / a
    }

    /// The largest [`speed_swing`] over torque-current frequencies from 0.4 to 1.9 times
    /// the stator frequency (where the response peaks).
    fn peak_swing(cfg: &FluxObserverConfig, m: &MachineParams, psi: f32, w_m: f32) -> f64 {
        (0..6)
            .map(|j| {
                speed_swing(
                    cfg,
                    m,
                    psi,
                    1.0,
                    w_m,
                    w_m / core::f32::consts::TAU * (0.4 + 0.3 * j as f32),
                )
            })
            .fold(0.0, f64::max)
    }

    /// The speed adaptation's schedule (`SENSITIVITY_LIMIT`): on the 2.2 kW machine at
    /// 5 kHz, the speed estimate's swing per ampere of torque-current oscillation, times
    /// the adaptation's bandwidth (the adapted speed's swing), stays within twice its
    /// value at base speed (rated flux) up to twice base speed in field weakening (half
    /// the flux): measured 0.31 -> 0.37 rad/s per A (1.2 x). Without the schedule (s0 = 0)
    /// it grows 3.6 x there (to 1.11: the field-weakening braking of the paper's machine
    /// then trips); at base speed the schedule leaves the published design alone (the
    /// same swing with and without it). With the currents at the period's end instead of
    /// its middle the swings were 0.78 and 3.96 (5 x).
    #[test]
    fn the_speed_response_to_torque_current_stays_bounded_at_high_speed() {
        let (m, psi, _) = machines()[0];
        let base = 2.0 * 2.0 * core::f32::consts::PI * 25.0; // 1500 rpm, 2 pole pairs
        let points = [(psi, base), (0.5 * psi, 2.0 * base)];
        let design = FluxObserverDesign::defaults(400.0, psi);
        let with = FluxObserverConfig::new(&m, design, TS).unwrap();
        let without = FluxObserverConfig::new(
            &m,
            FluxObserverDesign {
                sensitivity_limit: 0.0,
                ..design
            },
            TS,
        )
        .unwrap();
        // (the swing is the adapted speed's: the schedule's bandwidth is in it)
        let base_gain = peak_swing(&with, &m, points[0].0, points[0].1);
        let base_unscheduled = peak_swing(&without, &m, points[0].0, points[0].1);
        let fw_with = peak_swing(&with, &m, points[1].0, points[1].1);
        let fw_without = peak_swing(&without, &m, points[1].0, points[1].1);
        assert_eq!(base_gain, base_unscheduled, "untouched at base speed");
        assert!(fw_with < 2.0 * base_gain, "{base_gain} -> {fw_with}");
        assert!(
            fw_without > 3.0 * base_gain,
            "{base_gain} -> {fw_without} unscheduled"
        );
    }

    #[test]
    fn rejects_bad_designs() {
        let m = MachineParams::paper_table1();
        let d = FluxObserverDesign::defaults(300.0, 0.95);
        assert_eq!(
            FluxObserverConfig::new(&m, d, 0.0),
            Err(FluxObserverDesignError::BadPeriod)
        );
        let mut b = d;
        b.speed_bandwidth = f32::NAN;
        assert_eq!(
            FluxObserverConfig::new(&m, b, TS),
            Err(FluxObserverDesignError::BadGain)
        );
        let mut b = d;
        b.gain_speed = -0.1;
        assert_eq!(
            FluxObserverConfig::new(&m, b, TS),
            Err(FluxObserverDesignError::BadGain)
        );
        assert_eq!(
            FluxObserverConfig::new(&m, d, 5e-3),
            Err(FluxObserverDesignError::TooFast)
        );
    }

    /// The gain: real (g0) at standstill, its phase turning with the speed, bounded.
    #[test]
    fn gain_is_a_blend_at_rest_and_turns_with_the_speed() {
        let m = MachineParams::paper_table1();
        let c = FluxObserverConfig::new(&m, FluxObserverDesign::defaults(300.0, 0.95), TS).unwrap();
        assert_eq!(c.gain(0.0), (0.5, 0.0));
        let (re, im) = c.gain(300.0);
        assert!(re > 0.0 && im > 0.0);
        let (re2, im2) = c.gain(-300.0);
        assert_eq!((re, -im), (re2, im2));
        for w in [-1e4f32, -10.0, 10.0, 1e4] {
            let (re, im) = c.gain(w);
            assert!(re.is_finite() && im.is_finite() && (re * re + im * im) < 1.0);
        }
    }

    /// A non-finite sample keeps the last state; nothing non-finite comes out.
    #[test]
    fn a_nan_sample_keeps_the_state() {
        let (m, psi, _) = machines()[0];
        let cfg =
            FluxObserverConfig::new(&m, FluxObserverDesign::defaults(300.0, 0.95), TS).unwrap();
        let mut s = FluxObserverState::new();
        s.flux = psi;
        s.speed_elec = 100.0;
        let before = s;
        s.update(&cfg, (10.0, 0.0), (f32::NAN, 1.0), 3.7, 1.0);
        assert_eq!(s.flux, before.flux);
        assert_eq!(s.speed_elec, before.speed_elec);
        assert!(s.cos.is_finite() && s.sin.is_finite() && s.load_torque.is_finite());
    }

    /// A current sample the voltage cannot have driven (every channel failing to 0 A at
    /// a running point) moves the adapted speed by at most the rotor's bound per step
    /// ([`MAX_ACCELERATION_OVER_TORQUE`]); without the bound the one step kicks it by
    /// several times that (the voltage model's L_sigma di/dt).
    #[test]
    fn a_current_step_without_voltage_moves_the_speed_at_most_as_the_rotor_can() {
        let (m, psi, i_q) = machines()[0];
        let w_m = 2.0 * 78.5; // 750 rpm, rad/s electrical
        let (i_d, ws, u_d, u_q) = steady(&m, psi, i_q, w_m);
        let step_after_fault = |max_acceleration: f32| {
            let mut design = FluxObserverDesign::defaults(400.0, psi);
            design.max_acceleration = max_acceleration;
            let cfg = FluxObserverConfig::new(&m, design, TS).unwrap();
            let mut s = FluxObserverState::new();
            (s.flux, s.speed_elec, s.stator_frequency) = (psi, w_m, ws);
            s.last_current = (i_d, i_q);
            s.last_voltage = (u_d, u_q);
            s.update(&cfg, (u_d, u_q), (i_d, i_q), m.stator_resistance(), psi);
            let before = s.speed_elec;
            s.update(&cfg, (u_d, u_q), (0.0, 0.0), m.stator_resistance(), psi);
            ((s.speed_elec - before).abs(), cfg.max_speed_step_elec)
        };
        // the drive's bound: 4 x (1.5 p psi_n I_limit) / J with a 10.6 A limit
        let bound = MAX_ACCELERATION_OVER_TORQUE * 1.5 * 2.0 * psi * 10.6 / m.inertia();
        let (kick, step) = step_after_fault(bound);
        assert!((step - bound * 2.0 * TS).abs() < 1e-4, "{step}");
        assert!(kick <= step + 1e-4, "{kick} > {step}");
        let (free, _) = step_after_fault(0.0);
        assert!(
            free > 3.0 * step,
            "unbounded kick {free} against the bound {step}"
        );
    }
}
