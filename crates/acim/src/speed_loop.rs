//! The speed controller's design: i_sq* from the speed error and, optionally, from
//! feed-forwards, designed from the inertia J, the torque constant k_t = 1.5 p lambda_ref
//! and one bandwidth alpha (rad/s), the same in rad/s at every control rate.
//!
//! The mechanical plant (eq. 9b with Te = k_t i_sq) is J dOmega/dt = k_t i_sq - B Omega -
//! T_L. Two designs:
//!
//! - **PI on the estimated speed** (the paper's Fig. 1; without the feed-forward):
//!   kp = 2 alpha J / k_t, ki = alpha^2 J / k_t. The loop's characteristic polynomial is
//!   J (s + alpha)^2, a double pole at alpha; the loop is of type 2, so a ramp is followed
//!   without a steady lag, and a load step T slows the rotor by at most T / (e J alpha)
//!   (the peak of T t e^(-alpha t) / J). (The paper defaults' 12.5 rad/s are the gains of
//!   the project's earlier design, kp = 25 J / k_t with its PI zero at 6.25 rad/s.)
//! - **Two degrees of freedom with the observer's load estimate** (`feedforward`): the
//!   torque current is the reference feed-forward (the ramp's slope times J / k_t and the
//!   friction at the reference, B Omega* / k_t), the load feed-forward T_L_hat / k_t
//!   (eq. 12's load-torque estimate, the paper's reason for estimating T_L) and the
//!   proportional feedback kp = 2 alpha J / k_t, with no integral: in steady state the
//!   observer's current error is zero, so T_L_hat = k_t i_sq - B Omega_hat and the
//!   feed-forward alone holds the load; the observer's load state is the loop's integral
//!   action. A second integrator beside it charges while the estimate catches up with a
//!   load step and then overshoots: on motulator's 2.2 kW machine at 750 rpm, a
//!   rated-load step gave 41 rpm over and 0.25 s back within 1 % with ki = alpha^2 J /
//!   k_t, 3 rpm and 0.10 s without. With a correct model the observer's error dynamics
//!   (eq. 14) do not depend on the current it is fed (separation); an inertia error makes
//!   T_L_hat carry (J - J_hat) dOmega/dt, which turns the plant the feedback sees into
//!   J_hat, the inertia it is designed for. A resistance error is different: it biases
//!   the speed estimate by -dR i_sq / (p lambda_r), a path from the current back to the
//!   feedback, and on the paper's machine (R_s 10.5 ohm) +50 % R_s without the
//!   estimator lost control with the feed-forward where the PI holds it: the
//!   feed-forward is for a drive that estimates R_s (the nameplate path's default).
//!
//! The design is f32 SI; each arithmetic converts it with its bases (`SpeedLoopConfig::convert`).

use crate::config::{DriveConfig, RsEstimationMode};
use crate::field_weakening::FieldWeakeningOutput;
use crate::num::Num;
use crate::num::PerUnitBases;
use crate::num::Units;
use crate::params::MachineParams;
use crate::pi::{PiConfig, PiController};

/// The far-side transit: with [`EstimationSettings::far_side_gain`](crate::EstimationSettings::far_side_gain) on, the
/// regeneration limit is released while the load torque estimate puts the speed target's
/// operating point at least this far beyond the line w_s = 0, Hz (the observable
/// bound, |f_s| >= 1 Hz).
pub const FAR_SIDE_ENTER_HZ: f32 = 1.0;
/// ... and applies again once that point comes within this of the line, Hz (the start of
/// the orientation correction's fade, where the far-side term is off).
pub const FAR_SIDE_LEAVE_HZ: f32 = 0.5;
/// Torque held at the voltage or bus limit: the speed reference stays within this
/// fraction of `max_speed` of the speed estimate (the reachable speed is held and
/// reported instead of a growing speed error).
pub const FW_HOLD_BAND_FRACTION: f32 = 0.01;
/// The telemetry's `speed_target_limited` stays set this many speed-loop time constants
/// after the hold last bound: the hold binds only in the steps where the speed PI sits at
/// its limit, which flickers at the reachable speed, and a report that flickers with it
/// (a third of the steps, measured) says less than it knows.
pub const FW_REPORT_SPEED_LOOP_CONSTANTS: f32 = 2.5;

/// The speed controller's coefficients (configuration, apart from state).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SpeedLoopConfig<N: Num = f32> {
    /// The disturbance PI on the speed error (A per rad/s, and per rad/s per step), with
    /// the q-current limit (A).
    pub pi: PiConfig<N>,
    /// J / (k_t Ts): the ramp's speed change per step (rad/s) -> torque current (A);
    /// zero without the feed-forward (as the two below).
    pub acceleration_feedforward: N::Gain,
    /// B / k_t: the speed reference (rad/s) -> the torque current of the friction (A).
    pub friction_feedforward: N::Gain,
    /// 1 / k_t: the load-torque estimate (N m) -> torque current (A).
    pub load_feedforward: N::Gain,
    /// Whether the feed-forwards are on (the three gains above are zero otherwise, and
    /// the step skips them).
    pub feedforward: bool,
    /// Speed reference change per step, rad/s.
    pub ramp_step: N,
    /// 1 / (p lambda_ref), rad/s per V: the no-load speed whose back-EMF p Omega lambda_ref
    /// equals a voltage; with the voltage limit, the fastest reachable speed (without
    /// field weakening).
    pub speed_per_volt: N::Gain,
    /// The low-frequency regeneration limit's w_min, rad/s electrical (0: off).
    pub regen_min_frequency: N,
    /// lambda_ref / R_R, A per rad/s electrical (torque current per slip frequency).
    pub regen_current_per_frequency: N::Gain,
    /// 1.5 p lambda_ref^2 / R_R, N m per rad/s electrical: the torque whose slip is one
    /// rad/s (the far-side transit; 0 when [`EstimationSettings::far_side_gain`](crate::EstimationSettings::far_side_gain) is 0).
    pub far_side_torque_per_frequency: N::Gain,
    /// The far-side transit enters beyond this stator frequency, rad/s electrical (0: no
    /// transit; [`FAR_SIDE_ENTER_HZ`]).
    pub far_side_enter: N,
    /// ... and leaves within this one, rad/s electrical ([`FAR_SIDE_LEAVE_HZ`]).
    pub far_side_leave: N,
    /// The speed hold's band around the speed, rad/s mechanical
    /// ([`FW_HOLD_BAND_FRACTION`] max_speed).
    pub hold_band: N,
    /// Steps the target stays reported as limited after the hold last bound
    /// ([`FW_REPORT_SPEED_LOOP_CONSTANTS`] / (speed bandwidth Ts)).
    pub report_steps: u32,
}

impl SpeedLoopConfig<f32> {
    /// No reference limits (no ramp, no regeneration limit, no far-side transit, no hold):
    /// [`Self::with_reference_limits`] sets them.
    const NO_LIMITS: Self = Self {
        pi: PiConfig {
            kp: 0.0,
            ki_ts: 0.0,
            out_min: 0.0,
            out_max: 0.0,
        },
        acceleration_feedforward: 0.0,
        friction_feedforward: 0.0,
        load_feedforward: 0.0,
        feedforward: false,
        ramp_step: 0.0,
        speed_per_volt: 0.0,
        regen_min_frequency: 0.0,
        regen_current_per_frequency: 0.0,
        far_side_torque_per_frequency: 0.0,
        far_side_enter: 0.0,
        far_side_leave: 0.0,
        hold_band: 0.0,
        report_steps: 0,
    };

    /// This design with the reference's limits for the settings `cfg` at the flux
    /// reference `flux_reference` (Wb), updated every `ts` (s, the slow period): the
    /// ramp, the reachable speed, the regeneration limit, the far-side transit and the
    /// speed hold.
    pub fn with_reference_limits(
        mut self,
        cfg: &DriveConfig,
        flux_reference: f32,
        ts: f32,
    ) -> Self {
        let m = cfg.machine;
        let pp = m.pole_pairs_f32();
        self.ramp_step = cfg.loops.speed_ramp * ts;
        self.speed_per_volt = 1.0 / (pp * flux_reference);
        self.regen_min_frequency = cfg.loops.regen_min_frequency;
        self.regen_current_per_frequency = flux_reference / m.referred_rotor_resistance();
        self.far_side_torque_per_frequency = if cfg.estimation.far_side_gain > 0.0 {
            1.5 * pp * flux_reference * flux_reference / m.referred_rotor_resistance()
        } else {
            0.0
        };
        // the transit needs the Rs estimate kept while running: with Rs held 20 % high
        // the far side at 15-30 rpm is unstable with the far-side term
        // (docs/robustness.md, "The far-side mode")
        self.far_side_enter = if cfg.estimation.far_side_gain > 0.0
            && cfg.estimation.rs_estimation
            && cfg.estimation.rs_estimation_mode == RsEstimationMode::Running
        {
            2.0 * core::f32::consts::PI * FAR_SIDE_ENTER_HZ
        } else {
            0.0
        };
        self.far_side_leave = 2.0 * core::f32::consts::PI * FAR_SIDE_LEAVE_HZ;
        self.hold_band = FW_HOLD_BAND_FRACTION * cfg.limits.max_speed;
        self.report_steps =
            (FW_REPORT_SPEED_LOOP_CONSTANTS / (cfg.loops.speed_bandwidth * ts)) as u32;
        self
    }

    /// The design for `bandwidth` (rad/s) at rotor flux `rotor_flux` (Wb), period `ts`
    /// (s), q-current limit `current_limit` (A): the PI with its double pole at the
    /// bandwidth, or (`feedforward`) the two-degree-of-freedom loop (module docs).
    pub fn new(
        m: &MachineParams,
        rotor_flux: f32,
        bandwidth: f32,
        ts: f32,
        current_limit: f32,
        feedforward: bool,
    ) -> Self {
        // k_t > 0 for any valid design (the flux reference is positive); the floor only
        // keeps a degenerate input finite
        let kt = m.torque_constant(rotor_flux).max(1e-6);
        let j_over_kt = m.inertia() / kt;
        // kp = 2 alpha J / k_t and ki = alpha^2 J / k_t = kp (2 alpha) / 4, written in the
        // earlier design's order of operations (J w / k_t, kp w / 4 with w = 2 alpha) so
        // that its gains come out bit for bit at the paper defaults
        let w = 2.0 * bandwidth;
        let kp = m.inertia() * w / kt;
        if feedforward {
            Self {
                // the observer's load state is the integral action
                pi: PiConfig::new(kp, 0.0, ts, current_limit),
                acceleration_feedforward: j_over_kt / ts,
                friction_feedforward: m.viscous_friction() / kt,
                load_feedforward: 1.0 / kt,
                feedforward: true,
                ..Self::NO_LIMITS
            }
        } else {
            Self {
                pi: PiConfig::new(kp, kp * w * 0.25, ts, current_limit),
                acceleration_feedforward: 0.0,
                friction_feedforward: 0.0,
                load_feedforward: 0.0,
                feedforward: false,
                ..Self::NO_LIMITS
            }
        }
    }
}

/// This step's signals the speed loop reads (SI in f32, per unit in fixed point).
#[derive(Clone, Copy, Debug)]
pub struct SpeedLoopInputs<N: Num> {
    /// p: mechanical speed -> electrical frequency.
    pub pole_pairs: N::Gain,
    /// Omega_hat, rad/s mechanical.
    pub speed: N,
    /// T_L_hat, N m.
    pub load_torque: N,
    /// The field weakening's flux current and torque-current limits this step.
    pub limits: FieldWeakeningOutput<N>,
    /// Field weakening is on: the reachable speed is found by the hold, not from the
    /// voltage.
    pub fw_enabled: bool,
    /// The flux is weakened (or not settled back since): the ramp's slope is not fed
    /// forward and the loop's gains are scaled by lambda_ref / lambda_r.
    pub fw_active: bool,
    /// lambda_ref, Wb, and 1 / lambda_r, 1/Wb (that scaling).
    pub flux_reference: N,
    /// 1 / lambda_r, 1/Wb.
    pub inv_rotor_flux: N,
    /// The current loops' steady voltage limit, V (the reachable speed without field
    /// weakening).
    pub voltage_limit: N,
    /// The observer has a far-side term and the inverter's voltage error is known (the
    /// start test identified it, or the tracker has adapted long enough to be trusted).
    pub inverter_error_known: bool,
    /// The observer needs the low-frequency regeneration limit.
    pub regeneration_limit: bool,
    /// The short-time overload rating's factor on the torque-current limits (None: off).
    pub rating: Option<N>,
    /// z^-1: the q current loop was at its voltage limit in the last step.
    pub q_saturated: bool,
}

/// The speed loop's state: target, ramped reference, the PI, the hold's report and the
/// far-side mode.
#[derive(Clone, Copy, Debug)]
pub struct SpeedLoop<N> {
    /// The speed target, rad/s (within its limit: the command's).
    pub speed_target: N,
    /// The ramped speed reference, rad/s.
    pub speed_reference: N,
    /// The speed PI.
    pub pi: PiController<N>,
    /// The target is beyond the reachable speed (reported in the telemetry).
    pub target_limited: bool,
    /// The speed reference moved this step towards its target (a ramp; not the
    /// regeneration limit's hold, which moves it with the speed).
    pub ramping: bool,
    /// Steps the target stays reported as limited since the hold last bound.
    pub limited_hold: u32,
    /// The far-side mode: the regeneration limit released and the observer's far-side
    /// term on.
    pub far_side: bool,
    /// The last step's i_sq*, A.
    pub i_sq_ref: N,
}

impl<N: Num> Default for SpeedLoop<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<N: Num> SpeedLoop<N> {
    /// At rest: zero target and reference, integral zero.
    pub fn new() -> Self {
        Self {
            speed_target: N::ZERO,
            speed_reference: N::ZERO,
            pi: PiController::new(),
            target_limited: false,
            ramping: false,
            limited_hold: 0,
            far_side: false,
            i_sq_ref: N::ZERO,
        }
    }

    /// Whether the PI is at its limit.
    #[inline(always)]
    pub fn saturated(&self) -> bool {
        self.pi.saturated()
    }

    /// One running step: the ramp towards the target (limited to the reachable speed
    /// without field weakening), the far-side mode, the regeneration limit, the overload
    /// rating, the hold at the voltage or regeneration limit, the feed-forwards and the
    /// PI. Returns i_sq*, A.
    #[inline(always)]
    pub fn update(&mut self, cfg: &SpeedLoopConfig<N>, x: &SpeedLoopInputs<N>) -> N {
        let fw = x.limits;
        let target = if x.fw_enabled {
            // (the target is within speed_target_limit already): the reachable speed
            // depends on the load and is found by holding the reference below
            self.speed_target
        } else {
            // a target beyond the no-load speed the steady voltage reaches (back-EMF
            // p Omega lambda_ref = V_steady) is limited to it and reported in the telemetry
            let reach = N::gain(cfg.speed_per_volt, x.voltage_limit);
            self.speed_target.clamp(-reach, reach)
        };
        self.target_limited = target != self.speed_target;
        let dv = (target - self.speed_reference).clamp(-cfg.ramp_step, cfg.ramp_step);
        self.speed_reference = self.speed_reference + dv;
        self.ramping = dv != N::ZERO;
        // the ramp's slope, fed forward: zero where the hold below moves the reference
        // instead, and in field weakening (the torque the voltage leaves is the hold's to
        // share out: with the slope's torque on top, braking from 3000 rpm ran into the
        // current-regulation trip)
        let mut slope = if x.fw_active { N::ZERO } else { dv };
        let speed = x.speed;
        // the far-side mode: the braking torque the target needs, -sign(target) T_L_hat,
        // against the torque whose slip puts w_s = p Omega* + slip beyond the line by
        // `far_side_enter` (entering) or within `far_side_leave` of it (leaving); only
        // with the inverter's voltage error known. In it the regeneration limit is
        // released (the transit) and the observer takes the far-side term
        self.far_side = if cfg.far_side_enter > N::ZERO
            && self.speed_target != N::ZERO
            && x.inverter_error_known
        {
            let braking = if self.speed_target > N::ZERO {
                -x.load_torque
            } else {
                x.load_torque
            };
            let line = N::gain(x.pole_pairs, self.speed_target.abs());
            let margin = if self.far_side {
                cfg.far_side_leave
            } else {
                cfg.far_side_enter
            };
            braking >= N::gain(cfg.far_side_torque_per_frequency, line + margin)
        } else {
            false
        };
        let (i_sq_min, i_sq_max, regen_limited) =
            if x.regeneration_limit && cfg.regen_min_frequency > N::ZERO && !self.far_side {
                regen_limit(cfg, x.pole_pairs, self.speed_target, speed, fw)
            } else {
                (fw.i_sq_min, fw.i_sq_max, false)
            };
        // the short-time overload rating: on the measured current, the torque-current
        // limits fold back to the continuous current when it is spent
        let (i_sq_min, i_sq_max) = match x.rating {
            Some(rating) => (i_sq_min * rating, i_sq_max * rating),
            None => (i_sq_min, i_sq_max),
        };
        // the speed PI at its limit, or its torque current beyond what the voltage left
        // to the q loop drives (the q loop at its limit: at the field-weakening onset the
        // trim lowers the flux over tens of ms, and with overmodulation the reserve runs
        // out, while the ramp goes on)
        let short = self.pi.saturated() || x.q_saturated;
        // the regeneration limit holds the torque only when the drive brakes (its last
        // torque current against the speed): a motoring drive at its limit, e.g. a locked
        // rotor, is the stall detector's case, with the reference kept
        let braking = regen_limited && ((speed > N::ZERO) == (self.i_sq_ref < N::ZERO));
        if (fw.torque_limited || braking) && short {
            // (at a limit: marked cold, the regulating loop falls through)
            core::hint::cold_path();
            // the torque is at the voltage (or bus) limit, or at the low-frequency
            // regeneration limit: the speed the drive reaches there is the reachable
            // speed; hold the reference within a band of it (no growing speed error, no
            // overload trip) and report it
            let band = cfg.hold_band;
            let held = self.speed_reference.clamp(speed - band, speed + band);
            slope = N::ZERO;
            // reported when the hold binds, and whenever the regeneration limit holds the
            // torque: the speed then settles above the target, inside the band or not
            if held != self.speed_reference || braking {
                self.limited_hold = cfg.report_steps;
            }
            // at the regeneration limit the reference follows the speed and the torque
            // is the limit's, a slow function of the speed: not a ramp (the inverter
            // tracker's gate; with it shut there, a drive held by the limit never learnt
            // the inverter error the far-side mode needs)
            if braking {
                self.ramping = false;
            }
            self.speed_reference = held;
        }
        // reported while the hold binds and for a few speed-loop time constants after
        // (the speed PI's saturation flickers at the reachable speed)
        self.target_limited = self.target_limited || self.limited_hold > 0;
        self.limited_hold = self.limited_hold.saturating_sub(1);
        let error = self.speed_reference - speed;
        // the feed-forwards: the torque currents that accelerate the rotor along the ramp,
        // overcome the friction at the reference and hold the observer's load-torque
        // estimate; torques over k_t at lambda_ref, scaled like the error below
        let feedforward = if cfg.feedforward {
            N::gain(cfg.acceleration_feedforward, slope)
                + N::gain(cfg.friction_feedforward, self.speed_reference)
                + N::gain(cfg.load_feedforward, x.load_torque)
        } else {
            N::ZERO
        };
        // the torque per ampere is 1.5 p lambda_r and the PI is designed at lambda_ref:
        // while the flux is weakened its error and feed-forward are scaled by
        // lambda_ref/lambda_r, so the loop keeps its bandwidth and damping as the flux
        // falls (unscaled, at a sixth of the flux the ramp lagged 79 rpm in
        // fw-braking-3000 and the speed overshot 3000 rpm by 78 rpm); the error, not the
        // output, is scaled: the torque current does not jump with the flux estimate
        // (lambda_r >= the flux model's floor)
        let (error, feedforward) = if x.fw_active {
            let scale = x.flux_reference * x.inv_rotor_flux;
            (error * scale, feedforward * scale)
        } else {
            (error, feedforward)
        };
        let i_sq_ref = self
            .pi
            .update_with_limits(&cfg.pi, error, feedforward, i_sq_min, i_sq_max);
        self.i_sq_ref = i_sq_ref;
        i_sq_ref
    }
}

/// The torque-current limits with the low-frequency regeneration limit
/// ([`LoopSettings::regen_min_frequency`](crate::LoopSettings::regen_min_frequency), off at 0): while the speed target has the
/// sign of the speed estimate (holding a speed; a zero or opposite target is a transit,
/// through zero to a stop or a reversal, which must cross the line), the braking side is
/// limited to
/// (p |Omega_hat| - w_min) lambda_ref / R_R (>= 0), which keeps
/// w_s = p Omega + R_R i_sq / lambda at least w_min on the rotor's side of zero. Returns
/// the limits and whether the regeneration limit is tighter than the others.
#[inline(always)]
fn regen_limit<N: Num>(
    cfg: &SpeedLoopConfig<N>,
    pole_pairs: N::Gain,
    target: N,
    speed: N,
    fw: FieldWeakeningOutput<N>,
) -> (N, N, bool) {
    let (lo, hi) = (fw.i_sq_min, fw.i_sq_max);
    let w = N::gain(pole_pairs, speed.abs()) - cfg.regen_min_frequency;
    let w = if w > N::ZERO { w } else { N::ZERO };
    let i = N::gain(cfg.regen_current_per_frequency, w);
    if speed > N::ZERO && target > N::ZERO && lo < -i {
        (-i, hi, true)
    } else if speed < N::ZERO && target < N::ZERO && hi > i {
        (lo, i, true)
    } else {
        (lo, hi, false)
    }
}

impl SpeedLoopConfig<f32> {
    /// This design in the arithmetic `N` with the bases `b`, for a machine of `pole_pairs`
    /// and the rotor-flux reference `flux_reference` (Wb); fails naming the setting the
    /// value that does not fit depends on.
    pub fn convert<N: Num + Units>(
        &self,
        b: &PerUnitBases,
        pole_pairs: f32,
        flux_reference: f32,
    ) -> Result<SpeedLoopConfig<N>, &'static str> {
        let g = crate::num::gain_in::<N>;
        let bandwidth = "loops.speed_bandwidth";
        Ok(SpeedLoopConfig {
            pi: self.pi.convert(b.speed, b.current).ok_or(bandwidth)?,
            acceleration_feedforward: g(
                self.acceleration_feedforward * b.speed / b.current,
                bandwidth,
            )?,
            friction_feedforward: g(self.friction_feedforward * b.speed / b.current, bandwidth)?,
            load_feedforward: g(self.load_feedforward * b.torque / b.current, bandwidth)?,
            feedforward: self.feedforward,
            ramp_step: N::from_f32(self.ramp_step / b.speed),
            // 1/(p lambda_ref) in the order the design has always converted it
            speed_per_volt: g(
                b.voltage / (pole_pairs * flux_reference * b.speed),
                "loops.flux_current",
            )?,
            regen_min_frequency: N::from_f32(self.regen_min_frequency / b.frequency),
            regen_current_per_frequency: g(
                self.regen_current_per_frequency * b.frequency / b.current,
                "loops.regen_min_frequency",
            )?,
            far_side_torque_per_frequency: g(
                self.far_side_torque_per_frequency * b.frequency / b.torque,
                "estimation.far_side_gain",
            )?,
            far_side_enter: N::from_f32(self.far_side_enter / b.frequency),
            far_side_leave: N::from_f32(self.far_side_leave / b.frequency),
            hold_band: N::checked_from_f32(self.hold_band / b.speed).ok_or("limits.max_speed")?,
            report_steps: self.report_steps,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The paper defaults' 12.5 rad/s give the earlier design's gains exactly.
    #[test]
    fn the_paper_defaults_keep_their_gains() {
        let m = MachineParams::paper_table1();
        let flux = m.rotor_flux_for(1.5);
        let kt = m.torque_constant(flux);
        let c = SpeedLoopConfig::new(&m, flux, 12.5, 200e-6, 4.4, false);
        let kp = m.inertia() * 25.0 / kt;
        assert_eq!(c.pi.kp, kp);
        assert_eq!(c.pi.ki_ts, kp * 25.0 * 0.25 * 200e-6);
    }

    /// Without the load feed-forward, kp and ki place both closed-loop poles of
    /// J s^2 + k_t (kp s + ki) at -alpha; with it the proportional gain is the same and
    /// the observer's load state integrates.
    #[test]
    fn the_loop_has_a_double_pole_at_the_bandwidth() {
        let m = MachineParams::paper_table1();
        let flux = m.rotor_flux_for(1.5);
        let kt = m.torque_constant(flux);
        let (alpha, ts) = (40.0, 200e-6);
        let c = SpeedLoopConfig::new(&m, flux, alpha, ts, 4.4, false);
        // s^2 + (k_t kp / J) s + k_t ki / J = (s + alpha)^2
        let a1 = kt * c.pi.kp / m.inertia();
        let a0 = kt * (c.pi.ki_ts / ts) / m.inertia();
        assert!((a1 - 2.0 * alpha).abs() < 1e-3 * alpha, "{a1}");
        assert!((a0 - alpha * alpha).abs() < 1e-3 * alpha * alpha, "{a0}");
        assert_eq!(c.load_feedforward, 0.0);
        assert_eq!(c.acceleration_feedforward, 0.0);
        assert_eq!(c.friction_feedforward, 0.0);
        let ff = SpeedLoopConfig::new(&m, flux, alpha, ts, 4.4, true);
        assert!((ff.load_feedforward * kt - 1.0).abs() < 1e-6);
        // the ramp's step dv over Ts times J / k_t; the friction B / k_t
        assert!((ff.acceleration_feedforward * ts * kt / m.inertia() - 1.0).abs() < 1e-5);
        assert!((ff.friction_feedforward * kt / m.viscous_friction() - 1.0).abs() < 1e-5);
        assert_eq!(ff.pi.kp, c.pi.kp);
        assert_eq!(ff.pi.ki_ts, 0.0);
    }

    fn block_inputs(d: &crate::design::DriveDesign, speed: f32, load: f32) -> SpeedLoopInputs<f32> {
        SpeedLoopInputs {
            pole_pairs: d.pole_pairs,
            speed,
            load_torque: load,
            limits: FieldWeakeningOutput {
                i_sd_ref: d.cascade.i_sd_ref,
                i_sq_min: d.speed_loop.pi.out_min,
                i_sq_max: d.speed_loop.pi.out_max,
                torque_limited: false,
            },
            fw_enabled: true,
            fw_active: false,
            flux_reference: d.flux_reference,
            inv_rotor_flux: 1.0 / d.flux_reference,
            voltage_limit: 180.0,
            inverter_error_known: false,
            regeneration_limit: true,
            rating: None,
            q_saturated: false,
        }
    }

    #[test]
    fn the_reference_ramps_by_one_step_per_period() {
        let d = crate::design::DriveDesign::new(crate::DriveConfig::paper_defaults()).unwrap();
        let c = &d.speed_loop;
        let mut s = SpeedLoop::<f32>::new();
        s.speed_target = 100.0;
        s.update(c, &block_inputs(&d, 0.0, 0.0));
        assert_eq!(s.speed_reference, c.ramp_step);
        assert!(s.ramping);
        s.speed_target = 0.5 * c.ramp_step;
        s.update(c, &block_inputs(&d, 0.0, 0.0));
        assert_eq!(s.speed_reference, 0.5 * c.ramp_step);
    }

    #[test]
    fn the_regeneration_limit_bounds_braking_near_zero_frequency() {
        let mut cfg = crate::DriveConfig::paper_defaults();
        cfg.loops.regen_min_frequency = 2.0 * core::f32::consts::PI * 1.5;
        let d = crate::design::DriveDesign::new(cfg).unwrap();
        let c = &d.speed_loop;
        let w_min = c.regen_min_frequency / d.pole_pairs; // rad/s mechanical
        let target = 0.5 * w_min;
        let run = |speed: f32, limit: bool| {
            let mut s = SpeedLoop::<f32>::new();
            s.speed_target = target;
            s.speed_reference = target;
            let x = SpeedLoopInputs {
                regeneration_limit: limit,
                ..block_inputs(&d, speed, 0.0)
            };
            s.update(c, &x)
        };
        // turning forward below w_min, a speed error that asks for braking gets no
        // braking current (w_s stays on the rotor's side of zero)
        assert_eq!(run(0.8 * w_min, true), 0.0);
        // above it at most (p |Omega| - w_min) lambda_ref / R_R
        let i = run(1.5 * w_min, true);
        let bound = c.regen_current_per_frequency * (0.5 * c.regen_min_frequency);
        assert!(i < 0.0 && -i <= bound * 1.0001, "{i} {bound}");
        // without the limit the same errors brake harder
        assert!(run(0.8 * w_min, false) < 0.0);
        assert!(run(1.5 * w_min, false) < i);
        // motoring is not limited
        assert!(run(0.0, true) > 0.0);
    }
}
