//! The user's settings ([`DriveConfig`]): what a drive engineer configures, validated by
//! [`crate::design::DriveDesign::new`], which derives every constant of the cascade from
//! them. A rejected setting names the field and the rule it broke ([`ConfigError`]).
//!
//! A leaf of the crate: the blocks' design functions read it, and it reads only the
//! machine model ([`crate::params`]) and the observer's pole choice.

use crate::math::is_finite;
use crate::observer::{ObserverDesignError, ObserverPoles};
use crate::params::{self, MachineParams};

/// How many phase currents are measured.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum CurrentSensing {
    /// Phases a and b measured; c = -a - b.
    TwoPhase,
    /// All three measured; the zero-sequence part is rejected.
    ThreePhase,
}

/// When the stator-resistance estimator adapts (with `rs_estimation` on).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum RsEstimationMode {
    /// The eq. (19) law below `rs_max_frequency` only, where the orientation part of the
    /// d-axis residual vanishes: in practice the standstill identification before the
    /// speed ramp (the earlier behaviour).
    Standstill,
    /// The standstill identification, then adaptation while running, motoring and
    /// regenerating, from the q-axis and d-axis residuals together
    /// ([`crate::rs_estimator`], "While running"): from 1 Hz with torque current (the
    /// default: a motor's Rs rises 30-40 % from cold to hot, and the standstill value
    /// alone then leaves the speed estimate tens of rpm off, docs/robustness.md).
    #[default]
    Running,
}

/// What the drive does with a held zero speed target. Speed
/// reversals pass through zero as before with either policy: only a target of zero,
/// reached by the ramp and held for `zero_speed_dwell`, counts.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ZeroSpeedPolicy {
    /// Keep the flux and control zero speed (the earlier behaviour; the paper's
    /// trapezoids, figs. 10-12, hold zero this way). At zero stator frequency speed and
    /// orientation are unobservable (design notes, section 10): the rotor may creep under
    /// sensor offsets and load while the estimate reads 0.
    Hold,
    /// Ramp down, then switch off (to `Idle`) once the reference has been zero for
    /// `zero_speed_dwell`: no operation on the unobservable line (the default). Only
    /// after the drive was commanded to turn since its start: started with a zero
    /// target, it waits magnetized for one (and reports the hold, as `Hold` does).
    #[default]
    Stop,
}

/// Open-loop V/f commissioning settings.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct VfSettings {
    /// Voltage per electrical frequency, V peak per rad/s (230 V rms line at 50 Hz:
    /// 187.8 V / 314.16 rad/s = 0.598).
    pub volts_per_rad_s: f32,
    /// Low-frequency boost added to the voltage magnitude, V peak.
    pub boost: f32,
}

/// The power stage as the controller sees it: dead-time and device-drop compensation, the measured phases, the sampling-to-voltage delay.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct InverterSettings {
    /// Inverter dead time, s (compensated).
    pub dead_time: f32,
    /// Inverter device on-state drop, V (compensated with the dead time).
    pub device_drop: f32,
    /// Current band of the dead-time compensation's linearised sign, A: the current
    /// below which the inverter's dead-time error is proportional to the current (device
    /// capacitances); a property of the power stage, to be measured at commissioning.
    /// Default 50 mA, the inverter model's default. At 60 rpm, where the back-EMF is only
    /// about 10 V, a mismatch shows as speed-estimate spikes at each current zero crossing.
    pub dead_time_current_band: f32,
    /// Measured phases.
    pub current_sensing: CurrentSensing,
    /// Delay between sampling and the centre of the period the voltage is applied in, in
    /// control periods (1.5 for preloaded compare registers).
    pub delay_periods: f32,
}

/// Limits and protections: current, bus, speed and the supervision that faults beyond them.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct LimitSettings {
    /// Stator current vector limit I_max, A peak.
    pub current_limit: f32,
    /// The machine's continuous (rated) current I_c, A peak: a `current_limit` above it is
    /// a short-time overload rating, allowed for `overload_duration` before the limit
    /// folds back to I_c ([`crate::thermal`]); 0 (the default) or at or above
    /// `current_limit`: no fold-back, the limit is the continuous rating.
    pub continuous_current: f32,
    /// How long `current_limit` may be drawn before the fold-back (I^2 t), s.
    pub overload_duration: f32,
    /// How long the torque may stay at its limit with the speed far from its reference
    /// (more than half of it, and 50 rpm) before the drive faults `Overload`, s: the load
    /// is then beyond what the machine can give.
    pub overload_time: f32,
    /// Phase current trip level, A (any phase above it faults).
    pub overcurrent_trip: f32,
    /// Lowest DC-bus voltage while active, V.
    pub dc_bus_min: f32,
    /// Highest DC-bus voltage, V.
    pub dc_bus_max: f32,
    /// Over-speed trip on the estimated speed, rad/s.
    pub max_speed: f32,
    /// Fault when the speed PI has been at its limit with |Omega_hat| below 10 % of the
    /// reference for this long, s (locked rotor / stall).
    pub stall_time: f32,
    /// Largest plausible |T_L_hat|, N m (beyond it: estimator out of range).
    pub max_load_torque_estimate: f32,
    /// Dead or stuck current-sensor detection while switching (on by default): each
    /// channel's movement over a 1.6 ms window against the current the stator equation
    /// predicts for the applied voltage ([`crate::sensor_check`]); a channel that does not
    /// follow is a `CurrentSensor` fault.
    pub sensor_check: bool,
    /// The limit-cycle check (on by default): the speed estimate swinging around a steady
    /// reference by more than 2 % of `max_speed` peak to peak in three 1 s blocks in a
    /// row is a `SpeedOscillation` fault ([`crate::supervisor::SpeedOscillation`]).
    pub speed_oscillation_check: bool,
}

/// The control loops: rates, the flux current, the current and speed loops, the speed ramp and the regeneration limit.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct LoopSettings {
    /// Control and PWM period, s.
    pub control_period: f32,
    /// The slow task's period, s: 0.5-2 ms ([`TYPICAL_SLOW_PERIOD`], 1 ms, by default)
    /// runs the speed loop, field weakening and the slow supervision (stall, overload,
    /// blind, estimate plausibility, limit cycle, zero-speed policy) once per slow
    /// period, rounded to a whole number of control periods (at least one), and the
    /// current loop, the estimators and the fast protections every control period
    /// (`crate::drive`, "Two rates"); 0 runs every stage every control period.
    pub slow_period: f32,
    /// d-axis (flux) current reference i_sd*, A peak.
    pub flux_current: f32,
    /// Current-loop bandwidth, rad/s.
    pub current_bandwidth: f32,
    /// Speed-loop bandwidth, rad/s: both poles of the speed loop (J s^2 + k_t (kp s + ki)
    /// = J (s + alpha)^2, [`crate::speed_loop`]).
    pub speed_bandwidth: f32,
    /// Speed reference slew rate (trapezoid ramps), rad/s^2.
    pub speed_ramp: f32,
    /// The speed loop's two-degree-of-freedom design: the observer's load-torque estimate,
    /// the ramp's acceleration and the friction fed forward, proportional feedback
    /// ([`crate::speed_loop`]; default off: the paper's PI; the nameplate path's default
    /// on).
    pub load_torque_feedforward: bool,
    /// Low-frequency regeneration limit, rad/s electrical; 0 = off. While
    /// the drive holds a speed target of the rotor's sign, the regenerative torque current
    /// is limited so that the stator frequency w_s = p Omega + R_R i_sq / lambda stays on
    /// the rotor's side of the unobservable line w_s = 0 by at least this much:
    /// |i_sq| <= (p |Omega_hat| - w_min) lambda_ref / R_R. An overhauling load larger than
    /// that raises the speed until the operating point is observable again (the reachable
    /// speed, held and reported), instead of letting the estimates drift along the line
    /// while the rotor runs away. Transits (a zero target or one of the other sign: stops,
    /// reversals) are not limited: they cross the line at the ramp's pace. Default 1.5 Hz,
    /// the upper end of `orientation_fade`, where the orientation correction that holds
    /// regeneration stable (k > tau_r |w_slip|) is at full strength. Measured without the
    /// limit (`acim-sim overhauling`): 6-8 N m at 60 rpm oscillated between 0 and 300 rpm
    /// with no fault; 7 N m at 120 rpm ran away to 4 500 rpm while switching. Its cost: a
    /// target below w_min / p (45 rpm on the paper machine) cannot be braked while held.
    /// 2 Hz was tried: the robustness matrix with the standstill Rs estimator did better
    /// near the line (9 of 14 low-frequency cases against 4), but the 60 rpm trapezoid of
    /// fig 12 then estimated 4.2 rpm wrong (4 is its bound) and the any-motor 3 %
    /// trapezoid 7-14 rpm (1.2-3.4 at 1.5 Hz).
    pub regen_min_frequency: f32,
}

/// Which speed observer the f32 drive runs ([`EstimationSettings::observer`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ObserverChoice {
    /// The paper's reduced-order observer of i_sq, speed and load torque (eq. 12), with
    /// the orientation correction, the far-side mode and the regeneration limit around it.
    #[default]
    Reduced,
    /// The reduced-order flux observer with speed adaptation and a gain stable while
    /// regenerating ([`crate::flux_observer`]): no regeneration limit, the running Rs law
    /// at low stator frequency only, the drive's frame locked onto its flux angle.
    Flux,
}

/// The estimators: the observer, the stator-resistance estimator, the orientation correction and the far-side mode.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct EstimationSettings {
    /// The speed observer of the f32 drive ([`crate::speed_observer::DriveObserver`]): the
    /// paper's reduced-order observer (the paper's settings, [`DriveConfig::paper_defaults`]),
    /// or the flux observer with speed adaptation ([`crate::flux_observer`]; the
    /// configuration from a nameplate, [`crate::nameplate::drive_config`]). The
    /// fixed-point drive runs the paper's only.
    pub observer: ObserverChoice,
    /// Observer poles (rates, rad/s).
    pub observer_poles: ObserverPoles,
    /// Whether the stator-resistance estimator adapts (default on; the paper's figs. 6-8
    /// and 10-12 run without it).
    pub rs_estimation: bool,
    /// When Rs adapts (with `rs_estimation`): standstill only, or also while running
    /// (the default).
    pub rs_estimation_mode: RsEstimationMode,
    /// Initial stator-resistance estimate R0, ohm (eq. 19).
    pub rs_initial: f32,
    /// Convergence time constant of the Rs estimator, s.
    pub rs_convergence_time: f32,
    /// Rs adapts only below this |w_s|, rad/s electrical: there the d-axis residual is
    /// dominated by the resistance error (its orientation part grows with w_s).
    pub rs_max_frequency: f32,
    /// Orientation-correction gain k (dimensionless, 0 = the paper's scheme unchanged):
    /// the stator frequency gets -k sign(w_s) r_d / lambda_ref. Regeneration is stable for
    /// k > tau_r |w_slip| (see [`crate::orientation`]). This is the gain at light load;
    /// under load the drive raises it to [`ORIENTATION_GAIN_MARGIN`](crate::design::ORIENTATION_GAIN_MARGIN) tau_r |w_slip| =
    /// [`ORIENTATION_GAIN_MARGIN`](crate::design::ORIENTATION_GAIN_MARGIN) |i_sq| / i_sd* (the slip law w_slip = i_sq /
    /// (tau_r i_sd*)), so the condition holds at every torque up to the current limit.
    pub orientation_gain: f32,
    /// The correction fades in between these |w_s|, rad/s electrical (lower, upper).
    pub orientation_fade: (f32, f32),
    /// The far-side mode ([`FAR_SIDE_GAIN`] by default, 0 = off): the
    /// gain c (dimensionless) of a term the observer's speed and load updates (eq. 12) take
    /// on the far side of the unobservable line, where the stator frequency turns against
    /// the speed estimate: the q-axis error e minus c max(1, |i_sq| / (2 i_sd*)) times the
    /// eq. (20) d-axis current-model error, faded in with |w_s| like the orientation
    /// correction (the rotated adaptation error of Kubota and Hinkkanen's regenerating
    /// stabilisation, in this observer's terms). The mode is on while the load-torque
    /// estimate puts the speed target's operating point [`FAR_SIDE_ENTER_HZ`](crate::design::FAR_SIDE_ENTER_HZ) beyond the
    /// line (off within [`FAR_SIDE_LEAVE_HZ`](crate::design::FAR_SIDE_LEAVE_HZ)), with the Rs estimator in the running mode
    /// and with the inverter's voltage error known: identified by the start test at this
    /// start, or tracked while running for [`crate::inverter_tracker::INVERTER_TRACKER_TRUST`]
    /// ([`TrackerSettings::inverter_tracking`](crate::TrackerSettings::inverter_tracking)); in it the
    /// regeneration limit is released, so the drive crosses the line to hold the target
    /// (the transit). c and the load scheduling come from the linearised loop's maps
    /// (`acim_sim::linear`; docs/robustness.md, "The far-side mode").
    pub far_side_gain: f32,
}

/// The start sequence: flying start, the identification steps while magnetizing and when the flux counts as settled.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct StartSettings {
    /// Flying start: magnetizing first measures the rotor speed from the voltage the
    /// current loops apply ([`crate::speed_search`]) and catches a turning rotor instead
    /// of braking it with DC. Needs p `max_speed` `control_period` <= pi/4.
    pub flying_start: bool,
    /// Inverter voltage-error identification at every start (on by
    /// default): the first [`INVERTER_TEST_TIME`](crate::design::INVERTER_TEST_TIME) of magnetizing holds the d-axis current at
    /// three levels ([`INVERTER_TEST_LEVELS`](crate::design::INVERTER_TEST_LEVELS) of `flux_current`) with the frame held on phase
    /// a, and a straight-line fit of the d-axis voltage the current loop needed (the rotor
    /// flux's rate of change from the flux model taken out) against the current gives the
    /// voltage error the configured `dead_time` and `device_drop` leave uncompensated (the
    /// intercept; see [`InverterTestDesign`](crate::design::InverterTestDesign)). It is then compensated with the configured
    /// part. Needs a rotor at rest (skipped on a flying start) and `flux_current` of at
    /// least [`INVERTER_TEST_MIN_BANDS`](crate::design::INVERTER_TEST_MIN_BANDS) times `dead_time_current_band`: with less, the
    /// design leaves the test out (the lowest level's phase currents would sit inside the
    /// band, where the fit's sign pattern does not hold) and the outcome stays `NotRun`.
    pub inverter_identification: bool,
    /// Current-sensor gain calibration at every start from rest (on by default; two-phase
    /// sensing only): the b channel's gain relative to a's, identified from the beta
    /// voltage while magnetizing with the frame held, equalizes the a and b samples (their
    /// mean gain kept) from the handover ([`crate::gain_calibration`]).
    pub current_gain_calibration: bool,
    /// With `rs_estimation` in the running mode: whether Rs is also identified at standstill
    /// while magnetizing (default true; magnetizing then waits for it). False: Rs converges
    /// only while turning, from `rs_initial` (the fig 9 variant). The standstill
    /// mode has no other law and needs it.
    pub rs_standstill_identification: bool,
    /// With Rs estimation on, magnetizing also waits (at standstill, where the d-axis
    /// residual is purely the resistance error) until the Rs estimate has settled, for at
    /// most this long, s.
    pub rs_identification_timeout: f32,
    /// Flux within this fraction of its reference counts as settled.
    pub flux_tolerance: f32,
}

/// What the drive tracks while running: the current sensors' offsets, the inverter's voltage error, the rotor resistance.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct TrackerSettings {
    /// Running current-sensor offset tracking (on by default): the
    /// offsets' drift after the start's switches-off measurement, estimated from the DC
    /// part of the stator voltage while |w_s| >= 1.5 Hz (in the far-side mode from 0.5 Hz,
    /// ten times slower) and subtracted ([`crate::offset_tracker`]); an estimate at
    /// `offset_limit` is a current-sensor fault.
    pub offset_tracking: bool,
    /// Inverter voltage-error tracking while running (online part):
    /// the error the compensation leaves, from the sixth-harmonic pattern it puts into the
    /// current loops' command across the current, which a resistance error cannot make
    /// ([`crate::inverter_tracker`]); it adapts the start test's correction while
    /// 1 Hz <= |f_s| and 6 |w_s| <= `current_bandwidth`.
    pub inverter_tracking: bool,
    /// Rotor-resistance adaptation from speed transients (off by
    /// default): over each speed ramp from a steady point (its start, its run and 0.25 s
    /// beyond its end, at most 0.8 s), the speed the observer moved beyond what the
    /// mechanical model integrates is fitted as the slip law's R_R error times the
    /// torque-current change plus a torque-per-inertia error times the model's speed
    /// change ([`crate::rr_estimator`]). Assumes the load torque holds over the window.
    pub rr_adaptation: bool,
}

/// Above base speed and near the bus limit: field weakening, over-voltage control, light-load flux optimisation.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FieldWeakeningSettings {
    /// Field weakening above base speed ([`FieldWeakeningDesign`](crate::design::FieldWeakeningDesign)): the flux
    /// reference and the torque-current limit follow the voltage the bus supplies at the
    /// present stator frequency. Off: the flux stays at `flux_current` and speed targets
    /// are limited to the no-load base speed (the earlier behaviour).
    pub enabled: bool,
    /// Over-voltage control: above [`OVC_START_FRACTION`](crate::design::OVC_START_FRACTION) of `dc_bus_max` the
    /// regenerative torque current is reduced linearly to zero at [`OVC_END_FRACTION`](crate::design::OVC_END_FRACTION),
    /// so braking without a brake resistor cannot pump the bus to its trip. Off by
    /// default: the fault scenarios test the trip itself.
    pub overvoltage_control: bool,
    /// Light-load flux optimisation (off by default): below the torque
    /// where the copper-loss optimum needs the rated flux, the flux current follows
    /// i_sd* = sqrt((Rs + R_R) / Rs) |i_sq*| (the minimum of 1.5 (Rs |i_s|^2 + R_R i_sq^2)
    /// at a given torque 1.5 p L_M i_sd i_sq, steady state), floored at
    /// [`FLUX_OPT_MIN_FRACTION`](crate::design::FLUX_OPT_MIN_FRACTION) of `flux_current`; it rises at once with the torque
    /// current and falls with [`FLUX_OPT_FALL_TAU_R`](crate::design::FLUX_OPT_FALL_TAU_R) rotor time constants.
    pub flux_optimisation: bool,
}

/// What a held zero speed target does.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ZeroSpeedSettings {
    /// Held zero speed target: switch off (`Stop`, default) or keep the flux (`Hold`).
    pub policy: ZeroSpeedPolicy,
    /// With `ZeroSpeedPolicy::Stop`: the reference stays at zero this long before the
    /// switches turn off, s.
    pub dwell: f32,
}

/// Complete drive configuration (all user-facing settings; nothing here changes at run
/// time), in ten groups. Units SI, speeds mechanical rad/s. A rejected setting names its
/// field by its path, e.g. `loops.speed_bandwidth` ([`ConfigError`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DriveConfig {
    /// The controller's machine model (may differ from the real machine).
    pub machine: MachineParams,
    /// The power stage as the controller sees it.
    pub inverter: InverterSettings,
    /// Limits and protections.
    pub limits: LimitSettings,
    /// The control loops and their rates.
    pub loops: LoopSettings,
    /// The estimators.
    pub estimation: EstimationSettings,
    /// The start sequence.
    pub start: StartSettings,
    /// What is tracked while running.
    pub trackers: TrackerSettings,
    /// Field weakening, over-voltage control and flux optimisation.
    pub field_weakening: FieldWeakeningSettings,
    /// A held zero speed target.
    pub zero_speed: ZeroSpeedSettings,
    /// V/f mode settings.
    pub vf: VfSettings,
}

impl DriveConfig {
    /// The project's documented defaults for the paper's machine (Table 1): 5 kHz, 1.5 A
    /// flux current, 4.67 A limit, 325 V bus, 1.5 us dead time.
    pub fn paper_defaults() -> Self {
        let machine = MachineParams::paper_table1();
        Self {
            machine,
            inverter: InverterSettings {
                dead_time: 1.5e-6,
                device_drop: 1.0,
                dead_time_current_band: 0.05,
                current_sensing: CurrentSensing::TwoPhase,
                delay_periods: 1.5,
            },
            limits: LimitSettings {
                current_limit: params::DEFAULT_CURRENT_LIMIT,
                continuous_current: 0.0,
                overload_duration: DEFAULT_OVERLOAD_DURATION,
                overload_time: 0.2,
                overcurrent_trip: 8.0,
                dc_bus_min: 200.0,
                dc_bus_max: 400.0,
                max_speed: 2000.0 * crate::math::RPM_TO_RAD_S,
                stall_time: 1.0,
                max_load_torque_estimate: 15.0,
                sensor_check: true,
                speed_oscillation_check: true,
            },
            loops: LoopSettings {
                control_period: params::DEFAULT_CONTROL_PERIOD,
                slow_period: TYPICAL_SLOW_PERIOD,
                flux_current: params::DEFAULT_FLUX_CURRENT,
                current_bandwidth: 1000.0,
                speed_bandwidth: 12.5,
                speed_ramp: 500.0 * crate::math::RPM_TO_RAD_S,
                load_torque_feedforward: false,
                // the orientation correction's fade-in end (doc above)
                regen_min_frequency: 2.0 * core::f32::consts::PI * 1.5,
            },
            estimation: EstimationSettings {
                observer: ObserverChoice::Reduced,
                observer_poles: ObserverPoles::DEFAULT,
                rs_estimation: true,
                rs_estimation_mode: RsEstimationMode::Running,
                rs_initial: machine.stator_resistance(),
                rs_convergence_time: 0.2,
                rs_max_frequency: 2.0 * core::f32::consts::PI * 1.5,
                orientation_gain: 2.0,
                orientation_fade: (
                    2.0 * core::f32::consts::PI * 0.5,
                    2.0 * core::f32::consts::PI * 1.5,
                ),
                far_side_gain: FAR_SIDE_GAIN,
            },
            start: StartSettings {
                flying_start: true,
                inverter_identification: true,
                current_gain_calibration: true,
                rs_standstill_identification: true,
                rs_identification_timeout: 1.5,
                flux_tolerance: 0.02,
            },
            trackers: TrackerSettings {
                offset_tracking: true,
                inverter_tracking: true,
                rr_adaptation: false,
            },
            field_weakening: FieldWeakeningSettings {
                enabled: true,
                overvoltage_control: false,
                flux_optimisation: false,
            },
            zero_speed: ZeroSpeedSettings {
                policy: ZeroSpeedPolicy::Stop,
                dwell: 0.5,
            },
            vf: VfSettings {
                volts_per_rad_s: 187.8 / 314.16,
                boost: 8.0,
            },
        }
    }
}

/// Why a drive configuration was rejected.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ConfigError {
    /// `field` breaks `rule` (both human-readable, e.g. `"loops.speed_bandwidth"` and
    /// `"at most a quarter of current_bandwidth"`).
    Invalid {
        /// The offending field of [`DriveConfig`] (dotted for nested fields).
        field: &'static str,
        /// The rule it broke.
        rule: &'static str,
    },
    /// The observer design failed.
    Observer(ObserverDesignError),
}

impl ConfigError {
    /// The field the error is about (`"estimation.observer_poles"` for a failed observer design).
    pub fn field(&self) -> &'static str {
        match self {
            ConfigError::Invalid { field, .. } => field,
            ConfigError::Observer(_) => "estimation.observer_poles",
        }
    }
}

impl core::fmt::Display for ConfigError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            ConfigError::Invalid { field, rule } => write!(f, "drive config: {field}: {rule}"),
            ConfigError::Observer(e) => write!(f, "observer design: {e:?}"),
        }
    }
}

impl core::error::Error for ConfigError {}

/// The rules, named once: each check below returns the field and the rule it broke.
pub(crate) fn check(ok: bool, field: &'static str, rule: &'static str) -> Result<(), ConfigError> {
    if ok {
        Ok(())
    } else {
        Err(ConfigError::Invalid { field, rule })
    }
}

pub(crate) const POSITIVE: &str = "must be finite and > 0";

pub(crate) fn positive(v: f32, field: &'static str) -> Result<f32, ConfigError> {
    check(is_finite(v) && v > 0.0, field, POSITIVE)?;
    Ok(v)
}

/// Longest control period accepted, s (100 Hz: slower is not a current loop).
pub const MAX_CONTROL_PERIOD: f32 = 10e-3;
/// Shortest control period, s (50 kHz: below it no step fits a Cortex-M4 and the dead
/// time would eat the period).
pub const MIN_CONTROL_PERIOD: f32 = 20e-6;
/// The slow task's default period, s (1 kHz, as production drives run their speed loop).
pub const TYPICAL_SLOW_PERIOD: f32 = 1e-3;
/// Shortest slow-task period accepted, s (2 kHz).
pub const MIN_SLOW_PERIOD: f32 = 0.5e-3;
/// Longest slow-task period accepted, s (500 Hz).
pub const MAX_SLOW_PERIOD: f32 = 2e-3;
/// Largest speed-loop bandwidth x slow period (rad): the sampled speed loop's output
/// reaches the current loop over one slow period, which costs the crossover (about twice
/// the bandwidth) that many radians of phase (0.1: 11 degrees at most).
pub const MAX_SPEED_BANDWIDTH_SLOW_PERIODS: f32 = 0.1;
/// Control periods per slow period: `slow_period` / `control_period` rounded, at least
/// one (both s, `control_period` positive; a `slow_period` of 0 gives one:
/// [`LoopSettings::slow_period`](crate::LoopSettings::slow_period)).
pub fn slow_divider(slow_period: f32, control_period: f32) -> u32 {
    ((slow_period / control_period + 0.5) as u32).max(1)
}

/// The over-current trip may be at most this multiple of `current_limit`: a trip far
/// above the regulated current protects nothing (it is a protection switched off by
/// configuration).
pub const MAX_TRIP_OVER_LIMIT: f32 = 3.0;
/// `max_speed` may be at most this multiple of the base speed the bus can drive,
/// linear limit at `dc_bus_max` / (p lambda_ref): beyond it the over-speed trip could
/// never fire.
pub const MAX_SPEED_OVER_BASE: f32 = 3.0;
/// The rotor time constant must span at least this many control periods: the discrete
/// flux model (eq. 13) diverges when tau_r approaches the period.
pub const MIN_ROTOR_TIME_CONSTANT_PERIODS: f32 = 5.0;
/// Longest rotor time constant accepted, s: magnetizing gives up after
/// [`MAGNETIZING_TIMEOUT_TAU_R`](crate::design::MAGNETIZING_TIMEOUT_TAU_R) of them and a restart waits [`DEMAGNETIZE_TAU_R`](crate::design::DEMAGNETIZE_TAU_R) of them,
/// so a longer one (a rotor resistance orders of magnitude too small) would leave the
/// drive magnetizing for hours (the step count saturating at days) instead of faulting.
/// Large industrial machines reach a few seconds.
pub const MAX_ROTOR_TIME_CONSTANT: f32 = 10.0;
/// Largest current-loop bandwidth x period: beyond 0.5 the discrete PI with a one-period
/// delay loses its phase margin.
pub const MAX_CURRENT_BANDWIDTH_PERIODS: f32 = 0.5;
/// The current loop must be at least this many times faster than the speed loop (cascade
/// separation).
pub const MIN_LOOP_SEPARATION: f32 = 4.0;
/// Largest dead time as a fraction of the period (the compensation is a duty offset).
pub const MAX_DEAD_TIME_FRACTION: f32 = 0.1;
/// Largest device drop accepted, V.
pub const MAX_DEVICE_DROP: f32 = 20.0;
/// Largest flux tolerance (fraction of the reference).
pub const MAX_FLUX_TOLERANCE: f32 = 0.5;
/// Largest sampling-to-voltage delay, periods.
pub const MAX_DELAY_PERIODS: f32 = 3.0;
/// Largest orientation-correction gain.
pub const MAX_ORIENTATION_GAIN: f32 = 50.0;
/// The default time the overload limit may be drawn, s (the common 150 % for 60 s rating
/// of industrial drives).
pub const DEFAULT_OVERLOAD_DURATION: f32 = 60.0;
/// The far-side gain's default ([`EstimationSettings::far_side_gain`](crate::EstimationSettings::far_side_gain)): the value that leaves the
/// fewest unstable points in the linearised loop's maps (`acim_sim::linear`, docs/robustness.md).
pub const FAR_SIDE_GAIN: f32 = 1.5;
