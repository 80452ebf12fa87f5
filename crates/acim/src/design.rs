//! Configuration and design: the user's settings ([`DriveConfig`]) and the one immutable
//! [`DriveDesign`] derived from them outside the interrupt.
//!
//! Every derived constant of the cascade (gains, reciprocals, limits, step counts) is
//! computed once here, validated once, and read by the stages of the f32 drive and by the
//! fixed-point drive's conversion; nothing is re-derived inline. A rejected setting names
//! the field and the rule it broke ([`ConfigError`]). A new design can be built in the
//! background and swapped in between two steps ([`crate::Drive::set_design`]).

use crate::flux::FluxModelConfig;
use crate::gain_calibration::GainCalibrationConfig;
use crate::inverter_tracker::InverterTrackerConfig;
use crate::math::{is_finite, sqrt};
use crate::num::{Angles, Arithmetic, Num, PerUnitBases, Units};
use crate::observer::{ObserverCoeffs, ObserverConfig};
use crate::offset_tracker::OffsetTrackerConfig;
use crate::params::ModelGains;
use crate::rr_estimator::RrEstimatorConfig;
use crate::rs_estimator::{RsEstimatorConfig, RsRunningConfig};
use crate::sensor_check::{SensorCheckConfig, SensorCheckError};
use crate::speed_loop::SpeedLoopConfig;
use crate::speed_search::{SpeedSearchDesign, SpeedSearchSpec};
use crate::svpwm::{linear_limit, SvpwmConfig};
use crate::thermal::ThermalConfig;

pub use crate::config::*;
use crate::config::{check, positive};
pub use crate::current_loop::{CurrentLoopConfig, OVERMODULATION_RESERVE_TIME};
pub use crate::field_weakening::{
    FieldWeakeningDesign, FLUX_OPT_FALL_TAU_R, FLUX_OPT_MIN_FRACTION, FW_MIN_FLUX_FRACTION,
    FW_MIN_FREQUENCY_FRACTION, FW_TRIM_BANDWIDTH, FW_TRIM_GATE, FW_VOLTAGE_FRACTION,
    OVC_END_FRACTION, OVC_START_FRACTION,
};
pub use crate::inverter_test::{
    InverterTestDesign, INVERTER_TEST_FILTER_TIME, INVERTER_TEST_LEVELS, INVERTER_TEST_LEVEL_TIME,
    INVERTER_TEST_MAX_DUTY, INVERTER_TEST_MIN_BANDS, INVERTER_TEST_SETTLE_TIME, INVERTER_TEST_TIME,
};
pub use crate::orientation::OrientationDesign;
pub use crate::speed_loop::{
    FAR_SIDE_ENTER_HZ, FAR_SIDE_LEAVE_HZ, FW_HOLD_BAND_FRACTION, FW_REPORT_SPEED_LOOP_CONSTANTS,
};
pub use crate::start_sequence::MagnetizingDesign;
pub use crate::supervisor::SupervisionLimits;
pub use crate::svpwm::FW_TRIM_FRACTION;

/// Overload: the speed loop settles in this many of its time constants (1 /
/// speed_bandwidth); torque at the limit with a large speed error beyond that is a fault
/// (the nameplate's [`LimitSettings::overload_time`](crate::LimitSettings::overload_time); the default's 0.2 s is 2.5 of the
/// default 12.5 rad/s).
pub const OVERLOAD_SPEED_LOOP_CONSTANTS: f32 = 10.0;
/// Overload: the speed error counts beyond this fraction of the reference.
pub const OVERLOAD_FRACTION: f32 = 0.5;
/// The far-side gain rises with the load as c max(1, |i_sq| / (2 i_sd*)), that is with the
/// slip once tau_r |w_slip| passes 2, as the orientation gain does: without it the
/// linearised loop is unstable on the far side at 60-120 rpm beyond 8 N m (120 rpm / 9 N m:
/// +2.2/s; the sampled loop a limit cycle, 70-154 rpm); with it stable up to 10 N m.
pub const FAR_SIDE_LOAD_FRACTION: f32 = 0.5;
/// Largest accepted [`EstimationSettings::far_side_gain`](crate::EstimationSettings::far_side_gain).
pub const MAX_FAR_SIDE_GAIN: f32 = 10.0;
/// Under load the orientation gain is at least this multiple of the stability bound
/// tau_r |w_slip| (README, "Beyond the paper: holding orientation").
pub const ORIENTATION_GAIN_MARGIN: f32 = 1.25;
/// Speed targets are limited to this fraction of `max_speed` (the over-speed trip keeps
/// a margin above any commanded speed).
pub const SPEED_TARGET_FRACTION: f32 = 0.9;
/// Stall: the speed estimate stays below this fraction of the reference while the speed
/// PI is saturated.
pub const STALL_SPEED_FRACTION: f32 = 0.1;
/// The orientation correction is bounded by this fraction of p max_speed: a correction
/// beyond the rotor-frequency range means a wrong model.
pub const ORIENTATION_LIMIT_FRACTION: f32 = 0.25;
/// An implausible load estimate must persist this long before it faults, s (a current
/// transient, e.g. a short, must trip on over-current first).
pub const IMPLAUSIBLE_TIME: f32 = 0.02;
/// Standstill Rs identification: the residual must stay settled this long, s.
pub const RS_SETTLE_TIME: f32 = 0.05;
/// Time constant of the low-pass of the d-axis current-model error, s.
pub const RESIDUAL_FILTER_TIME: f32 = 0.02;
/// The Rs identification counts as settled when the filtered |error| is below this
/// fraction of i_sd* (|Rs_hat - Rs| below about the same fraction).
pub const RS_SETTLED_FRACTION: f32 = 0.003;
/// The control monitor's leaky means span this many current-loop time constants
/// (1 / current_bandwidth): long enough that a reference step (settled in about 3) does
/// not count, short enough to detect within tens of milliseconds.
pub const MONITOR_FILTER_LOOP_CONSTANTS: f32 = 10.0;
/// Current regulation fails when the mean |i* - i| exceeds this fraction of i_sd*: a dead
/// sensor or an open phase leaves at least the whole i_sd* unmet.
pub const CURRENT_ERROR_FRACTION: f32 = 0.5;
/// Three shunts: the mean |a + b + c| may reach this fraction of the over-current trip
/// (gain and offset errors of a few per cent of full scale).
pub const CURRENT_SUM_FRACTION: f32 = 0.05;
/// The model may be off by this fraction of the stator resistance (the paper's fig. 8:
/// +50 %, without the estimator) at the full current limit before the voltage residual
/// counts as lost control.
pub const RESIDUAL_RS_TOLERANCE: f32 = 0.5;
/// ... plus this fraction of the linear voltage limit at the highest bus (inverter
/// non-linearity, flux and inductance errors).
pub const RESIDUAL_VOLTAGE_FRACTION: f32 = 0.05;
/// The q integral's steady part (its leaky mean) counts only beyond this fraction of the
/// back-EMF at the rated rotor flux, |w_s| lambda_r: the part of the back-EMF an
/// inductance error leaves to the current loops' integrals (the feed-forward of eq. 9b
/// holds w_s lambda_hat, the machine's flux is off by the error: with L_M 15 % low, the
/// class the drive is designed to hold, 1/0.85 - 1 = 17.6 %); what moves around that
/// steady part counts in full, so a fault's residual is judged as before. Without it
/// the 37 kW machine (Rs 0.087 ohm: the constant part of the limit is 29 V) with L_M
/// 15 % low tripped `LossOfControl` at 820 rpm of a ramp to 900 with the speed estimate
/// on the rotor and the orientation within 0.3 degrees (its residual, 28.5 V, was 17.7 %
/// of the model's back-EMF). The fault scenarios' times move by at most 1 ms (open phase
/// 6.0 -> 6.4 ms, the short with the 1 kHz slow task 10.0 -> 11.0 ms); allowing it on
/// the whole |I_q| instead delayed them up to 5 ms.
pub const RESIDUAL_FLUX_FRACTION: f32 = 0.2;
/// The idle offset measurement: the first samples with the switches off over this time
/// are averaged with equal weights (the mean, the best estimate of a constant offset
/// under white noise: 10 mA of noise leaves 0.45 mA); the offsets count as settled
/// then, s.
pub const OFFSET_MEASUREMENT_TIME: f32 = 0.1;
/// After the measurement, the idle means follow a drift as leaky means over this time, s
/// (10 mA of noise leaves 0.32 mA).
pub const OFFSET_FILTER_TIME: f32 = 0.1;
/// Idle samples within this time of a switch-off are not taken: the stator current
/// decays through the free-wheeling diodes first (within a millisecond), s.
pub const OFFSET_SWITCH_OFF_SKIP_TIME: f32 = 0.002;
/// Time constant of the running offset check's leaky mean of the alpha-beta current, s:
/// long against the electrical period, so that the AC current averages out.
pub const RUNNING_OFFSET_FILTER_TIME: f32 = 2.0;
/// A channel whose idle offset exceeds this fraction of the over-current trip is a
/// sensor fault (2 % of an 8 A trip: 0.16 A, some 30 LSB of a 12-bit +/-10 A channel).
pub const OFFSET_FRACTION: f32 = 0.02;
/// The speed-oscillation check's block, s ([`crate::supervisor::SpeedOscillation`]): long
/// against the speed loop's settling (a load step's dip recovers within one block) and
/// the slowest limit cycle seen (1-4 Hz at 60-120 rpm).
pub const OSCILLATION_BLOCK_TIME: f32 = 1.0;
/// The speed-oscillation check's low-pass time constant on the estimate's error, s (the
/// simulator's verdict averages over 10 ms too).
pub const OSCILLATION_FILTER_TIME: f32 = 0.01;
/// The speed estimate's largest swing around a steady reference, fraction of `max_speed`
/// (0.02: 40 rpm for the paper drive's 2000 rpm), after the 10 ms filter. In steady
/// operation the filtered estimate swings a few rpm (the full-order observer's noisier
/// one some 20); the limit cycles of a drifting current offset at 60-120 rpm swing it
/// 50-165 rpm while the true speed swings 20-100 rpm.
pub const OSCILLATION_FRACTION: f32 = 0.02;
/// Magnetizing gives up after this many rotor time constants beyond the standstill Rs
/// identification's own timeout (the flux settles in about 3).
pub const MAGNETIZING_TIMEOUT_TAU_R: f32 = 10.0;
/// After a switch-off the rotor flux decays with tau_r (open stator: d lambda_r/dt =
/// -lambda_r / tau_r, eq. 13 with i_sd = 0); a start is refused until this many rotor
/// time constants have passed, leaving exp(-5) = 0.7 % of the flux. A start into the
/// remaining flux of a turning rotor meets a back-EMF the flying start's speed search
/// (which assumes the flux builds from zero) and the current-response check cannot
/// explain. Industrial drives have the same wait (e.g. Siemens' motor de-excitation time,
/// p0347).
pub const DEMAGNETIZE_TAU_R: f32 = 5.0;

/// Open-loop V/f constants.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VfDesign<N: Num = f32> {
    /// Voltage per electrical frequency, V per rad/s.
    pub volts_per_rad_s: N::Gain,
    /// Low-frequency boost, V.
    pub boost: N,
}

/// The cascade's own settings the step reads, beside its blocks' designs: designed in
/// [`DriveDesign::new`], converted by [`CascadeDesign::convert`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CascadeDesign<N: Num + Angles = f32> {
    /// i_sd*, A.
    pub i_sd_ref: N,
    /// Flux above which it counts as settled, Wb.
    pub settled_flux: N,
    /// Largest |speed target|, rad/s.
    pub speed_target_limit: N,
    /// Initial Rs estimate R0, ohm.
    pub rs_initial: N,
    /// The voltage lead of the inverse Park (delay compensation).
    pub lead: N::Lead,
    /// Open-loop V/f (commissioning).
    pub vf: VfDesign<N>,
    /// Slow periods at a zero target and reference before the zero-speed policy acts
    /// (>= 1).
    pub zero_dwell_steps: u32,
    /// [`ZeroSpeedPolicy::Stop`] (false: `Hold`).
    pub zero_speed_stop: bool,
    /// Control periods per slow period (>= 1; [`LoopSettings::slow_period`](crate::LoopSettings::slow_period)).
    pub slow_divider: u32,
    /// 1 / `slow_divider`: the per-period weight of the slow task's means, and the step
    /// of its current reference's ramp.
    pub inv_slow_divider: N::Gain,
}

impl CascadeDesign<f32> {
    /// These settings in the arithmetic `N` with the bases `b`; fails naming the setting
    /// the value depends on.
    pub fn convert<N: Num + Units + Angles>(
        &self,
        b: &PerUnitBases,
    ) -> Result<CascadeDesign<N>, &'static str> {
        let pu = crate::num::signal_in::<N>;
        let g = crate::num::gain_in::<N>;
        Ok(CascadeDesign {
            i_sd_ref: pu(self.i_sd_ref, b.current, "loops.flux_current")?,
            settled_flux: pu(self.settled_flux, b.flux, "loops.flux_current")?,
            speed_target_limit: pu(self.speed_target_limit, b.speed, "limits.max_speed")?,
            rs_initial: pu(self.rs_initial, b.resistance(), "estimation.rs_initial")?,
            lead: N::lead(self.lead.0, self.lead.1, b).ok_or("inverter.delay_periods")?,
            vf: VfDesign {
                volts_per_rad_s: g(
                    self.vf.volts_per_rad_s * b.frequency / b.voltage,
                    "vf.volts_per_rad_s",
                )?,
                boost: pu(self.vf.boost, b.voltage, "vf.boost")?,
            },
            zero_dwell_steps: self.zero_dwell_steps,
            zero_speed_stop: self.zero_speed_stop,
            slow_divider: self.slow_divider,
            inv_slow_divider: g(self.inv_slow_divider, "loops.slow_period")?,
        })
    }
}

/// What the control step reads, in the arithmetic `N`: every gain, reciprocal and limit
/// of the cascade. Built once from a [`DriveDesign`] by [`DriveCoeffs::new`]: each block converts
/// its own design (the identity for f32 SI; a conversion with the per-unit bases in
/// fixed point, which checks that every value fits).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DriveCoeffs<N: Arithmetic = f32> {
    /// The cascade's own settings ([`CascadeDesign`]).
    pub cascade: CascadeDesign<N>,
    /// The current loop (d/q PIs, overmodulation reserve).
    pub current_loop: CurrentLoopConfig<N>,
    /// Speed loop: the disturbance PI and the feed-forwards.
    pub speed_loop: SpeedLoopConfig<N>,
    /// The short-time overload rating's I^2 t model.
    pub thermal: ThermalConfig<N>,
    /// Flux model and slip law (eq. 13, 8).
    pub flux: FluxModelConfig<N>,
    /// Reduced-order observer step (eq. 12).
    pub observer: ObserverCoeffs<N>,
    /// Rs estimator (eq. 19-20).
    pub rs: RsEstimatorConfig<N>,
    /// Modulator.
    pub pwm: SvpwmConfig<N>,
    /// The machine model's gains (sigma Ls, the sample ripple, R_R, 1/tau_r, p, 1.5 p).
    pub model: ModelGains<N>,
    /// Orientation correction.
    pub orientation: OrientationDesign<N>,
    /// Magnetizing sequence.
    pub magnetizing: MagnetizingDesign<N>,
    /// What the supervisor judges against.
    pub limits: SupervisionLimits<N>,
    /// Field weakening and over-voltage control.
    pub fw: FieldWeakeningDesign<N>,
    // the additions last, so that the default path's field offsets stay as they were
    /// The running Rs law ([`crate::rs_estimator`], "While running").
    pub rs_running: RsRunningConfig<N>,
    /// The inverter test at start ([`StartSettings::inverter_identification`](crate::StartSettings::inverter_identification)).
    pub inverter_test: InverterTestDesign<N>,
    /// The running offset tracker ([`TrackerSettings::offset_tracking`](crate::TrackerSettings::offset_tracking)).
    pub offset_tracker: OffsetTrackerConfig<N>,
    /// The running inverter-error tracker ([`TrackerSettings::inverter_tracking`](crate::TrackerSettings::inverter_tracking)).
    pub inverter_tracker: InverterTrackerConfig<N>,
    /// The current-sensor gain calibration ([`StartSettings::current_gain_calibration`](crate::StartSettings::current_gain_calibration)).
    pub gain_calibration: GainCalibrationConfig<N>,
    /// The rotor-resistance adaptation ([`TrackerSettings::rr_adaptation`](crate::TrackerSettings::rr_adaptation)).
    pub rr: RrEstimatorConfig<N>,
    /// Dead or stuck current sensors ([`LimitSettings::sensor_check`](crate::LimitSettings::sensor_check)).
    pub sensor_check: SensorCheckConfig<N>,
}

/// Every derived constant of the drive, built once from a [`DriveConfig`] (outside the
/// interrupt) and never changed while it is in use. Read by the stages of the cascade;
/// the fixed-point drive converts it with its per-unit bases.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DriveDesign {
    /// The settings this design was built from.
    pub config: DriveConfig,
    /// Control period Ts, s.
    pub ts: f32,
    /// The cascade's own settings: the flux current and its settled threshold, the speed
    /// target's limit, R0, the lead, V/f, the zero-speed policy, the slow task's divider.
    pub cascade: CascadeDesign,
    /// The slow period, s: `slow_divider` Ts. The speed loop, field weakening, the
    /// thermal model and the slow supervision's counts are designed for it.
    pub slow_ts: f32,
    /// The current loop ([`crate::current_loop`]).
    pub current_loop: CurrentLoopConfig,
    /// Speed loop (J, k_t at the flux reference; [`crate::speed_loop`]).
    pub speed_loop: SpeedLoopConfig,
    /// The short-time overload rating ([`crate::thermal`]).
    pub thermal: ThermalConfig,
    /// Flux model and slip law (eq. 13, 8).
    pub flux: FluxModelConfig,
    /// Reduced-order observer (eq. 12, 14).
    pub observer: ObserverConfig,
    /// Rs estimator (eq. 19-20).
    pub rs: RsEstimatorConfig,
    /// The running Rs law.
    pub rs_running: RsRunningConfig,
    /// Modulator (SVPWM with dead-time compensation).
    pub pwm: SvpwmConfig,
    /// q-current limit sqrt(I_max^2 - i_sd*^2), A.
    pub i_sq_limit: f32,
    /// Rotor-flux reference L_M i_sd*, Wb.
    pub flux_reference: f32,
    /// The machine model's gains (sigma Ls, the sample ripple, R_R, 1/tau_r, p, 1.5 p).
    pub model: ModelGains,
    /// p.
    pub pole_pairs: f32,
    /// The inverter test at start.
    pub inverter_test: InverterTestDesign,
    /// The running current-sensor offset tracker.
    pub offset_tracker: OffsetTrackerConfig,
    /// The running inverter-error tracker.
    pub inverter_tracker: InverterTrackerConfig,
    /// The current-sensor gain calibration at start.
    pub gain_calibration: GainCalibrationConfig,
    /// The rotor-resistance adaptation.
    pub rr_estimator: RrEstimatorConfig,
    /// The dead or stuck current-sensor check.
    pub sensor_check: SensorCheckConfig,
    /// Orientation correction.
    pub orientation: OrientationDesign,
    /// Magnetizing sequence.
    pub magnetizing: MagnetizingDesign,
    /// What the supervisor judges against.
    pub limits: SupervisionLimits,
    /// Field weakening and over-voltage control.
    pub field_weakening: FieldWeakeningDesign,
}

impl DriveDesign {
    /// Validates `cfg` and derives every constant. Errors name the field and the rule.
    pub fn new(cfg: DriveConfig) -> Result<Self, ConfigError> {
        let ts = positive(cfg.loops.control_period, "loops.control_period")?;
        check(
            ts <= MAX_CONTROL_PERIOD,
            "loops.control_period",
            "at most 10 ms (MAX_CONTROL_PERIOD)",
        )?;
        check(
            ts >= MIN_CONTROL_PERIOD,
            "loops.control_period",
            "at least 20 us (MIN_CONTROL_PERIOD)",
        )?;
        check(
            cfg.machine.rotor_time_constant() >= MIN_ROTOR_TIME_CONSTANT_PERIODS * ts,
            "machine",
            "rotor time constant Lr/Rr must span at least 5 control periods \
             (MIN_ROTOR_TIME_CONSTANT_PERIODS)",
        )?;
        check(
            cfg.machine.rotor_time_constant() <= MAX_ROTOR_TIME_CONSTANT,
            "machine",
            "rotor time constant Lr/Rr must be at most 10 s (MAX_ROTOR_TIME_CONSTANT)",
        )?;
        let i_max = positive(cfg.limits.current_limit, "limits.current_limit")?;
        let i_d = positive(cfg.loops.flux_current, "loops.flux_current")?;
        check(
            i_d < i_max,
            "loops.flux_current",
            "must be below current_limit",
        )?;
        positive(cfg.limits.overcurrent_trip, "limits.overcurrent_trip")?;
        check(
            cfg.limits.overcurrent_trip >= i_max,
            "limits.overcurrent_trip",
            "must be at least current_limit",
        )?;
        check(
            cfg.limits.overcurrent_trip <= MAX_TRIP_OVER_LIMIT * i_max,
            "limits.overcurrent_trip",
            "must be at most 3 x current_limit (MAX_TRIP_OVER_LIMIT)",
        )?;
        positive(cfg.limits.dc_bus_min, "limits.dc_bus_min")?;
        positive(cfg.limits.dc_bus_max, "limits.dc_bus_max")?;
        check(
            cfg.limits.dc_bus_max > cfg.limits.dc_bus_min,
            "limits.dc_bus_max",
            "must be above dc_bus_min",
        )?;
        positive(cfg.limits.max_speed, "limits.max_speed")?;
        positive(cfg.loops.speed_ramp, "loops.speed_ramp")?;
        positive(cfg.loops.current_bandwidth, "loops.current_bandwidth")?;
        positive(cfg.loops.speed_bandwidth, "loops.speed_bandwidth")?;
        check(
            cfg.limits.continuous_current == 0.0
                || (is_finite(cfg.limits.continuous_current)
                    && cfg.limits.continuous_current > cfg.loops.flux_current),
            "limits.continuous_current",
            "0 (no fold-back) or finite and above flux_current",
        )?;
        positive(cfg.limits.overload_duration, "limits.overload_duration")?;
        check(
            is_finite(cfg.limits.overload_time) && cfg.limits.overload_time >= ts,
            "limits.overload_time",
            "finite and at least one control period",
        )?;
        check(
            cfg.loops.current_bandwidth * ts <= MAX_CURRENT_BANDWIDTH_PERIODS,
            "loops.current_bandwidth",
            "times control_period at most 0.5 (MAX_CURRENT_BANDWIDTH_PERIODS)",
        )?;
        check(
            cfg.loops.speed_bandwidth * MIN_LOOP_SEPARATION <= cfg.loops.current_bandwidth,
            "loops.speed_bandwidth",
            "at most a quarter of current_bandwidth (MIN_LOOP_SEPARATION)",
        )?;
        check(
            cfg.loops.slow_period == 0.0
                || (is_finite(cfg.loops.slow_period)
                    && cfg.loops.slow_period >= MIN_SLOW_PERIOD
                    && cfg.loops.slow_period <= MAX_SLOW_PERIOD),
            "loops.slow_period",
            "0 (every stage every control period) or 0.5 to 2 ms (MIN_SLOW_PERIOD, \
             MAX_SLOW_PERIOD)",
        )?;
        // a whole number of control periods, at least one (a control period above the
        // slow period runs everything at the control rate)
        let slow_divider = slow_divider(cfg.loops.slow_period, ts);
        let slow_ts = slow_divider as f32 * ts;
        check(
            slow_divider == 1
                || cfg.loops.speed_bandwidth * slow_ts <= MAX_SPEED_BANDWIDTH_SLOW_PERIODS,
            "loops.speed_bandwidth",
            "times the slow period at most 0.1 (MAX_SPEED_BANDWIDTH_SLOW_PERIODS): lower \
             it or shorten slow_period",
        )?;
        positive(cfg.estimation.rs_initial, "estimation.rs_initial")?;
        positive(
            cfg.estimation.rs_convergence_time,
            "estimation.rs_convergence_time",
        )?;
        check(
            is_finite(cfg.estimation.far_side_gain)
                && (0.0..=MAX_FAR_SIDE_GAIN).contains(&cfg.estimation.far_side_gain),
            "estimation.far_side_gain",
            "must be in 0 ..= 10 (MAX_FAR_SIDE_GAIN)",
        )?;
        check(
            is_finite(cfg.inverter.dead_time)
                && cfg.inverter.dead_time >= 0.0
                && cfg.inverter.dead_time < MAX_DEAD_TIME_FRACTION * ts,
            "inverter.dead_time",
            "must be >= 0 and below 10 % of control_period (MAX_DEAD_TIME_FRACTION)",
        )?;
        check(
            is_finite(cfg.inverter.device_drop)
                && (0.0..=MAX_DEVICE_DROP).contains(&cfg.inverter.device_drop),
            "inverter.device_drop",
            "must be in 0 ..= 20 V (MAX_DEVICE_DROP)",
        )?;
        positive(
            cfg.inverter.dead_time_current_band,
            "inverter.dead_time_current_band",
        )?;
        let tol = positive(cfg.start.flux_tolerance, "start.flux_tolerance")?;
        check(
            tol < MAX_FLUX_TOLERANCE,
            "start.flux_tolerance",
            "must be below 0.5 (MAX_FLUX_TOLERANCE)",
        )?;
        check(
            is_finite(cfg.inverter.delay_periods)
                && (0.0..=MAX_DELAY_PERIODS).contains(&cfg.inverter.delay_periods),
            "inverter.delay_periods",
            "must be in 0 ..= 3 periods (MAX_DELAY_PERIODS)",
        )?;
        positive(
            cfg.estimation.rs_max_frequency,
            "estimation.rs_max_frequency",
        )?;
        positive(
            cfg.start.rs_identification_timeout,
            "start.rs_identification_timeout",
        )?;
        check(
            cfg.start.rs_standstill_identification
                || cfg.estimation.rs_estimation_mode == RsEstimationMode::Running,
            "start.rs_standstill_identification",
            "may be off only with rs_estimation_mode Running (the standstill mode has no \
             other law)",
        )?;
        check(
            is_finite(cfg.estimation.orientation_gain)
                && (0.0..=MAX_ORIENTATION_GAIN).contains(&cfg.estimation.orientation_gain),
            "estimation.orientation_gain",
            "must be in 0 ..= 50 (MAX_ORIENTATION_GAIN)",
        )?;
        let (fa, fb) = cfg.estimation.orientation_fade;
        check(
            is_finite(fa) && is_finite(fb) && fa >= 0.0 && fb > fa,
            "estimation.orientation_fade",
            "must be finite with 0 <= lower < upper",
        )?;
        positive(cfg.limits.stall_time, "limits.stall_time")?;
        positive(cfg.zero_speed.dwell, "zero_speed.dwell")?;
        check(
            is_finite(cfg.loops.regen_min_frequency)
                && cfg.loops.regen_min_frequency >= 0.0
                && cfg.loops.regen_min_frequency
                    <= 0.5 * cfg.limits.max_speed * cfg.machine.pole_pairs_f32(),
            "loops.regen_min_frequency",
            "must be in 0 ..= p max_speed / 2 rad/s (0: off)",
        )?;
        positive(
            cfg.limits.max_load_torque_estimate,
            "limits.max_load_torque_estimate",
        )?;
        positive(cfg.vf.volts_per_rad_s, "vf.volts_per_rad_s")?;
        check(
            is_finite(cfg.vf.boost) && cfg.vf.boost >= 0.0,
            "vf.boost",
            "must be finite and >= 0",
        )?;

        let m = cfg.machine;
        let flux_reference = m.rotor_flux_for(i_d);
        let base_speed =
            linear_limit(cfg.limits.dc_bus_max) / (m.pole_pairs_f32() * flux_reference);
        check(
            cfg.limits.max_speed <= MAX_SPEED_OVER_BASE * base_speed,
            "limits.max_speed",
            "must be at most 3 x the base speed the bus drives, linear limit at dc_bus_max \
             / (p lambda_ref) (MAX_SPEED_OVER_BASE)",
        )?;
        let i_sq_limit = sqrt(i_max * i_max - i_d * i_d);
        let observer = ObserverConfig::new(&m, cfg.estimation.observer_poles, ts)
            .map_err(ConfigError::Observer)?;
        // the voltage limit of the current PIs follows the bus at run time; these static
        // limits only bound the integrators before the first step
        let v_static = linear_limit(cfg.limits.dc_bus_max);
        let mut rs = RsEstimatorConfig::new(&m, ts, cfg.estimation.rs_convergence_time, i_d);
        rs.adapt = cfg.estimation.rs_estimation;
        rs.max_stator_frequency = cfg.estimation.rs_max_frequency;
        let mut rs_running = RsRunningConfig::new(
            ts,
            cfg.estimation.rs_convergence_time,
            i_d,
            m.rotor_time_constant(),
        );
        rs_running.enabled = cfg.estimation.rs_estimation_mode == RsEstimationMode::Running;
        rs_running.standstill = cfg.start.rs_standstill_identification;
        rs_running.max_frequency = (crate::rs_estimator::RUNNING_MAX_FREQUENCY_FACTOR
            * m.stator_resistance()
            / m.magnetizing_inductance())
        .max(rs_running.min_frequency);
        rs_running.inductance_gate = crate::rs_estimator::inductance_gate(m.stator_resistance());
        let rs_running = rs_running.on_slow_ticks(slow_divider, ts, m.rotor_time_constant());
        let pp = m.pole_pairs_f32();
        // below the Rs gate's frequency the rotor counts as at rest: there the standstill
        // sequence (frame held, Rs identification) applies
        let search = SpeedSearchDesign::new(&SpeedSearchSpec {
            enabled: cfg.start.flying_start,
            control_period: ts,
            rotor_time_constant: m.rotor_time_constant(),
            referred_rotor_resistance: m.referred_rotor_resistance(),
            i_sd_ref: i_d,
            current_bandwidth: cfg.loops.current_bandwidth,
            pole_pairs: pp,
            max_speed: cfg.limits.max_speed,
            standstill_frequency: cfg.estimation.rs_max_frequency,
        });
        let Some(search) = search else {
            return Err(ConfigError::Invalid {
                field: "start.flying_start",
                rule: "needs p max_speed control_period <= pi/4 (the speed search resolves \
                       at most a quarter turn per period); switch it off or shorten the period",
            });
        };
        // the inverter test at start, where the flux current's levels allow it
        let inverter_test_on = cfg.start.inverter_identification
            && cfg.loops.flux_current
                >= INVERTER_TEST_MIN_BANDS * cfg.inverter.dead_time_current_band;
        let search_steps = if cfg.start.flying_start {
            search.decision_step() as f32
        } else {
            0.0
        };
        // the control monitor's and the running offset check's leaky means, per control
        // period (their slow task's gains per slow period)
        let monitor_filter =
            (ts * cfg.loops.current_bandwidth / MONITOR_FILTER_LOOP_CONSTANTS).min(1.0);
        let running_offset_filter = (ts / RUNNING_OFFSET_FILTER_TIME).min(1.0);
        Ok(Self {
            config: cfg,
            ts,
            cascade: CascadeDesign {
                i_sd_ref: i_d,
                settled_flux: flux_reference * (1.0 - tol),
                speed_target_limit: SPEED_TARGET_FRACTION * cfg.limits.max_speed,
                rs_initial: cfg.estimation.rs_initial,
                lead: (ts, cfg.inverter.delay_periods),
                vf: VfDesign {
                    volts_per_rad_s: cfg.vf.volts_per_rad_s,
                    boost: cfg.vf.boost,
                },
                zero_dwell_steps: ((cfg.zero_speed.dwell / slow_ts) as u32).max(1),
                zero_speed_stop: cfg.zero_speed.policy == ZeroSpeedPolicy::Stop,
                slow_divider,
                inv_slow_divider: 1.0 / slow_divider as f32,
            },
            slow_ts,
            current_loop: CurrentLoopConfig::new(&cfg, v_static),
            speed_loop: SpeedLoopConfig::new(
                &m,
                flux_reference,
                cfg.loops.speed_bandwidth,
                slow_ts,
                i_sq_limit,
                cfg.loops.load_torque_feedforward,
            )
            .with_reference_limits(&cfg, flux_reference, slow_ts),
            thermal: ThermalConfig::new(
                cfg.limits.current_limit,
                cfg.limits.continuous_current,
                cfg.limits.overload_duration,
                i_d,
                slow_ts,
            ),
            flux: FluxModelConfig::new(&m, ts, flux_reference),
            observer,
            rs,
            rs_running,
            pwm: SvpwmConfig::new(
                cfg.inverter.dead_time,
                ts,
                cfg.inverter.device_drop,
                cfg.inverter.dead_time_current_band,
            ),
            i_sq_limit,
            flux_reference,
            model: ModelGains::new(&m, ts),
            pole_pairs: pp,
            inverter_test: InverterTestDesign::new(
                inverter_test_on,
                ts,
                i_d,
                m.stator_resistance(),
            ),
            // with a slow task the tracker adapts once per slow period, on its mean
            offset_tracker: OffsetTrackerConfig {
                large_turn: slow_divider > 1,
                ..OffsetTrackerConfig::new(
                    cfg.trackers.offset_tracking,
                    slow_ts,
                    m.stator_resistance(),
                    OFFSET_FRACTION * cfg.limits.overcurrent_trip,
                    i_d,
                    m.rotor_time_constant(),
                )
            },
            // the tracker moves the voltage error the Rs estimate carries (as an apparent
            // resistance) into the correction: only with the running Rs law, which takes
            // it back out of the estimate (crate::inverter_tracker, "Gates")
            inverter_tracker: InverterTrackerConfig::new(
                cfg.trackers.inverter_tracking
                    && cfg.estimation.rs_estimation
                    && cfg.estimation.rs_estimation_mode == RsEstimationMode::Running,
                ts,
                i_d,
                cfg.loops.current_bandwidth,
            ),
            gain_calibration: GainCalibrationConfig::new(
                cfg.start.current_gain_calibration
                    && cfg.inverter.current_sensing == CurrentSensing::TwoPhase,
                ts,
                m.stator_resistance(),
                i_d,
            ),
            rr_estimator: RrEstimatorConfig::new(
                cfg.trackers.rr_adaptation,
                ts,
                m.pole_pairs_f32(),
                m.referred_rotor_resistance(),
                i_d,
            ),
            sensor_check: SensorCheckConfig {
                enabled: cfg.limits.sensor_check,
                ..SensorCheckConfig::new(&m, ts, i_max).map_err(|e| ConfigError::Invalid {
                    field: match e {
                        SensorCheckError::ControlPeriod => "loops.control_period",
                        SensorCheckError::CurrentLimit => "limits.current_limit",
                        SensorCheckError::Inductance => "machine",
                    },
                    rule: "the current-sensor check needs it positive and finite",
                })?
            },
            orientation: OrientationDesign {
                gain_per_flux: cfg.estimation.orientation_gain / flux_reference,
                // k(i_sq) = max(k, margin |i_sq| / i_sd*) = k max(1, c |i_sq|); the
                // paper's scheme (k = 0) stays uncorrected at any load
                load_factor_per_current: if cfg.estimation.orientation_gain > 0.0 {
                    ORIENTATION_GAIN_MARGIN / (cfg.estimation.orientation_gain * i_d)
                } else {
                    0.0
                },
                fade_start: fa,
                inv_fade_width: 1.0 / (fb - fa),
                limit: ORIENTATION_LIMIT_FRACTION * cfg.limits.max_speed * pp,
                far_side_gain: cfg.estimation.far_side_gain,
                far_side_load_factor: FAR_SIDE_LOAD_FRACTION / i_d,
            },
            magnetizing: MagnetizingDesign {
                identify_rs: cfg.estimation.rs_estimation && cfg.start.rs_standstill_identification,
                // counted from the start; with the inverter test the identification
                // begins after the search and the test, and keeps its own time after them
                rs_timeout_steps: (cfg.start.rs_identification_timeout / ts
                    + if inverter_test_on {
                        INVERTER_TEST_TIME / ts + search_steps
                    } else {
                        0.0
                    }) as u32,
                rs_settle_steps: (RS_SETTLE_TIME / ts) as u32,
                rs_settled_error: RS_SETTLED_FRACTION * i_d,
                residual_filter: (ts / RESIDUAL_FILTER_TIME).min(1.0),
                search,
            },
            field_weakening: FieldWeakeningDesign::new(&cfg, base_speed, slow_ts),
            limits: SupervisionLimits {
                current_sensing: cfg.inverter.current_sensing,
                overcurrent_trip: cfg.limits.overcurrent_trip,
                dc_bus_min: cfg.limits.dc_bus_min,
                dc_bus_max: cfg.limits.dc_bus_max,
                max_speed: cfg.limits.max_speed,
                max_load_torque: cfg.limits.max_load_torque_estimate,
                implausible_steps: (IMPLAUSIBLE_TIME / slow_ts) as u32,
                stall_steps: (cfg.limits.stall_time / slow_ts) as u32,
                overload_steps: (cfg.limits.overload_time / slow_ts) as u32,
                overload_fraction: OVERLOAD_FRACTION,
                overload_speed_floor: OVERLOAD_FRACTION * 100.0 * crate::math::RPM_TO_RAD_S,
                blind_frequency: fa,
                blind_steps: (m.rotor_time_constant() / slow_ts) as u32,
                stall_fraction: STALL_SPEED_FRACTION,
                rs_bound_faults: cfg.estimation.rs_estimation,
                monitor_filter,
                slow_monitor_filter: per_slow_period(monitor_filter, slow_divider),
                current_error_limit: CURRENT_ERROR_FRACTION * i_d,
                current_sum_limit: CURRENT_SUM_FRACTION * cfg.limits.overcurrent_trip,
                model_residual_limit: RESIDUAL_RS_TOLERANCE * m.stator_resistance() * i_max
                    + RESIDUAL_VOLTAGE_FRACTION * v_static,
                residual_per_frequency: RESIDUAL_FLUX_FRACTION * m.rotor_flux_for(i_d),
                demagnetize_steps: (DEMAGNETIZE_TAU_R * m.rotor_time_constant() / ts) as u32,
                offset_filter: (ts / OFFSET_FILTER_TIME).min(1.0),
                // rounded: 0.1 s / 0.2 ms is 499.99.. in f32
                offset_settle_steps: ((OFFSET_MEASUREMENT_TIME / ts + 0.5) as u32).max(1),
                offset_skip_steps: ((OFFSET_SWITCH_OFF_SKIP_TIME / ts + 0.5) as u32).max(1),
                oscillation_steps: ((OSCILLATION_BLOCK_TIME / slow_ts + 0.5) as u32).max(1),
                oscillation_filter: (slow_ts / OSCILLATION_FILTER_TIME).min(1.0),
                oscillation_check: cfg.limits.speed_oscillation_check,
                oscillation_swing: OSCILLATION_FRACTION * cfg.limits.max_speed,
                offset_limit: OFFSET_FRACTION * cfg.limits.overcurrent_trip,
                running_offset_filter,
                slow_running_offset_filter: per_slow_period(running_offset_filter, slow_divider),
                running_offset_min_frequency: 4.0 * i_max
                    / (OFFSET_FRACTION * cfg.limits.overcurrent_trip * RUNNING_OFFSET_FILTER_TIME),
                impedance_resistance: (1.0 + RESIDUAL_RS_TOLERANCE) * m.stator_resistance()
                    + m.referred_rotor_resistance(),
                impedance_inductance: m.stator_inductance(),
                impedance_voltage_floor: m.stator_resistance() * i_max,
                // the inverter test runs after the search, and the Rs identification
                // after both with its own timeout
                magnetizing_timeout_steps: ((if cfg.estimation.rs_estimation {
                    cfg.start.rs_identification_timeout
                } else {
                    0.0
                } + if inverter_test_on {
                    INVERTER_TEST_TIME
                } else {
                    0.0
                } + MAGNETIZING_TIMEOUT_TAU_R
                    * m.rotor_time_constant())
                    / ts
                    + search_steps) as u32,
            },
        })
    }

    /// This design's step coefficients in the arithmetic `N` (`bases`: `()` for f32 SI,
    /// the per-unit bases in fixed point).
    pub fn coeffs<N: Arithmetic>(&self, bases: &N::Bases) -> Result<DriveCoeffs<N>, ConfigError> {
        DriveCoeffs::new(self, bases)
    }

    /// This design with another orientation gain (run-time tuning, built outside the
    /// interrupt). Rejects non-finite values and values outside 0 ..= 50.
    pub fn with_orientation_gain(&self, gain: f32) -> Result<Self, ConfigError> {
        let mut cfg = self.config;
        cfg.estimation.orientation_gain = gain;
        Self::new(cfg)
    }
}

impl<N: Arithmetic> DriveCoeffs<N> {
    /// The step coefficients of `design` in the arithmetic `N` (`bases`: `()` for f32
    /// SI, the per-unit bases in fixed point): each block converts its own design
    /// ([`crate::num::Units`]); in fixed point every value the drive compares against or
    /// limits to must fit its per-unit range, and a failure names the setting. Out of
    /// line: design-time code (inlined into the firmware's constructor, its field copies
    /// cost 7 KB of flash).
    #[inline(never)]
    pub fn new(design: &DriveDesign, bases: &N::Bases) -> Result<Self, ConfigError> {
        let d = design;
        let b = &N::unit_bases(bases);
        let cfg = d.config;
        let m = cfg.machine;
        let pp = d.pole_pairs;
        let named = |field: &'static str| ConfigError::Invalid {
            field,
            rule: "does not fit the per-unit bases (above 2 pu, or a gain beyond 2^30)",
        };
        let pu =
            |x: f32, base: f32, field| crate::num::signal_in::<N>(x, base, field).map_err(named);
        // range checks: everything the drive compares against or limits to must fit
        pu(
            cfg.limits.overcurrent_trip,
            b.current,
            "limits.overcurrent_trip",
        )?;
        pu(cfg.limits.current_limit, b.current, "limits.current_limit")?;
        pu(cfg.limits.dc_bus_max, b.voltage, "limits.dc_bus_max")?;
        pu(cfg.limits.max_speed, b.speed, "limits.max_speed")?;
        pu(
            cfg.limits.max_speed * pp * 1.25,
            b.frequency,
            "limits.max_speed",
        )?;
        pu(1.2 * d.flux_reference, b.flux, "loops.flux_current")?;
        pu(
            cfg.limits.max_load_torque_estimate,
            b.torque,
            "limits.max_load_torque_estimate",
        )?;
        pu(
            m.torque_constant(d.flux_reference) * cfg.limits.current_limit,
            b.torque,
            "limits.current_limit",
        )?;
        pu(
            2.5 * m.stator_resistance() + m.referred_rotor_resistance(),
            b.resistance(),
            "machine",
        )?;
        // the reciprocals' domain
        if cfg.limits.dc_bus_min / b.voltage < N::RECIP_FLOOR {
            return Err(named("limits.dc_bus_min"));
        }
        if d.flux.min_flux / b.flux < N::RECIP_FLOOR {
            return Err(named("loops.flux_current"));
        }
        Ok(DriveCoeffs {
            cascade: d.cascade.convert(b).map_err(named)?,
            current_loop: d
                .current_loop
                .convert(b)
                .ok_or_else(|| named("loops.current_bandwidth"))?,
            speed_loop: d
                .speed_loop
                .convert(b, pp, d.flux_reference)
                .map_err(named)?,
            thermal: d.thermal.convert(b.current).map_err(named)?,
            flux: d.flux.convert(b).ok_or_else(|| named("machine"))?,
            observer: d
                .observer
                .convert(b)
                .ok_or_else(|| named("estimation.observer_poles"))?,
            rs: d
                .rs
                .convert(b)
                .ok_or_else(|| named("estimation.rs_convergence_time"))?,
            pwm: d
                .pwm
                .convert(b)
                .ok_or_else(|| named("inverter.dead_time_current_band"))?,
            model: d.model.convert(b).ok_or_else(|| named("machine"))?,
            orientation: d
                .orientation
                .convert(b, cfg.estimation.orientation_fade)
                .map_err(named)?,
            magnetizing: d.magnetizing.convert(b).map_err(named)?,
            limits: d.limits.convert(b).map_err(named)?,
            fw: d.field_weakening.convert(b).map_err(named)?,
            rs_running: d
                .rs_running
                .convert(b)
                .ok_or_else(|| named("estimation.rs_convergence_time"))?,
            offset_tracker: d
                .offset_tracker
                .convert(b)
                .ok_or_else(|| named("limits.overcurrent_trip"))?,
            inverter_tracker: d
                .inverter_tracker
                .convert(b)
                .ok_or_else(|| named("loops.flux_current"))?,
            gain_calibration: d.gain_calibration.convert(b).map_err(named)?,
            rr: d
                .rr_estimator
                .convert(b)
                .ok_or_else(|| named("machine.rotor_resistance"))?,
            sensor_check: d.sensor_check.convert(b).ok_or_else(|| named("machine"))?,
            inverter_test: d.inverter_test.convert(b).map_err(named)?,
        })
    }
}

/// A first-order low-pass's gain `g` per control period as its gain over `periods` of
/// them: 1 - (1 - g)^periods (the same time constant sampled once per slow period).
pub fn per_slow_period(g: f32, periods: u32) -> f32 {
    let mut keep = 1.0f32;
    for _ in 0..periods {
        keep *= 1.0 - g;
    }
    1.0 - keep
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::params::MachineParams;

    fn field(cfg: DriveConfig) -> Option<&'static str> {
        DriveDesign::new(cfg).err().map(|e| e.field())
    }

    /// the Rs-while-running, zero-speed stop and inverter test are accepted in every
    /// build (the firmware compiles the same step as the simulator); Rs tracked while
    /// running is the default.
    #[test]
    fn robust_settings_are_accepted_in_every_build() {
        let c = DriveConfig::paper_defaults();
        assert!(
            c.estimation.rs_estimation
                && c.estimation.rs_estimation_mode == RsEstimationMode::Running
        );
        let mut z = DriveConfig::paper_defaults();
        z.zero_speed.policy = ZeroSpeedPolicy::Stop;
        let mut i = DriveConfig::paper_defaults();
        i.start.inverter_identification = false;
        assert_eq!(field(c), None);
        assert_eq!(field(z), None);
        assert_eq!(field(i), None);
        // the inverter test is on by default; a flux current too small for its levels
        // leaves it out of the design instead of rejecting the configuration
        assert!(c.start.inverter_identification);
        assert!(DriveDesign::new(c).unwrap().inverter_test.level_steps > 0);
        assert_eq!(DriveDesign::new(i).unwrap().inverter_test.level_steps, 0);
        let mut small = DriveConfig::paper_defaults();
        small.loops.flux_current =
            0.9 * INVERTER_TEST_MIN_BANDS * small.inverter.dead_time_current_band;
        assert_eq!(field(small), None);
        assert_eq!(
            DriveDesign::new(small).unwrap().inverter_test.level_steps,
            0
        );
        // the standstill mode has no other Rs law: it cannot be switched off there
        let mut s = DriveConfig::paper_defaults();
        s.estimation.rs_estimation_mode = RsEstimationMode::Standstill;
        s.start.rs_standstill_identification = false;
        assert_eq!(field(s), Some("start.rs_standstill_identification"));
        // the regeneration limit is in every build (a protection)
        let mut r = DriveConfig::paper_defaults();
        assert_eq!(field(r), None);
        r.loops.regen_min_frequency = 0.0;
        assert_eq!(field(r), None);
        r.loops.regen_min_frequency = -1.0;
        assert_eq!(field(r), Some("loops.regen_min_frequency"));
    }

    /// The running Rs law's band with the flux observer reaches Rs/L_M, and at least its
    /// low gate's 1 Hz (`acim::rs_estimator`, "Down to zero stator frequency"): the
    /// paper's machine (Rs/L_M 3.2 Hz) keeps its own; with a tenth of its Rs (0.32 Hz)
    /// the band reaches 1 Hz.
    #[test]
    fn the_running_rs_band_reaches_at_least_its_low_gate() {
        let c = DriveConfig::paper_defaults();
        let m = c.machine;
        let d = DriveDesign::new(c).unwrap();
        let own = m.stator_resistance() / m.magnetizing_inductance();
        assert!(own > d.rs_running.min_frequency);
        assert!((d.rs_running.max_frequency - own).abs() < 1e-3 * own);
        let mut low = c;
        let mut data = m.data();
        data.stator_resistance *= 0.1;
        low.machine = MachineParams::new(data).unwrap();
        let d = DriveDesign::new(low).unwrap();
        assert_eq!(d.rs_running.max_frequency, d.rs_running.min_frequency);
    }

    /// Protections cannot be switched off by configuration, and errors name the field
    /// that is wrong: a trip far above the current limit, a speed limit the bus
    /// could never reach, a rotor time constant near the period, a tiny period.
    #[test]
    fn physics_bounds_name_the_field() {
        assert_eq!(field(DriveConfig::paper_defaults()), None);
        let mut c = DriveConfig::paper_defaults();
        c.limits.overcurrent_trip = 1e30;
        assert_eq!(field(c), Some("limits.overcurrent_trip"));
        let mut c = DriveConfig::paper_defaults();
        c.limits.max_speed = 1e30;
        assert_eq!(field(c), Some("limits.max_speed"));
        let mut c = DriveConfig::paper_defaults();
        let mut data = c.machine.data();
        data.rotor_resistance = data.rotor_inductance / (2.0 * c.loops.control_period);
        c.machine = MachineParams::new(data).unwrap();
        assert_eq!(field(c), Some("machine"));
        // a rotor time constant of days: magnetizing would never time out
        let mut c = DriveConfig::paper_defaults();
        let mut data = c.machine.data();
        data.rotor_resistance = 1e-7;
        c.machine = MachineParams::new(data).unwrap();
        assert_eq!(field(c), Some("machine"));
        data.rotor_resistance = data.rotor_inductance / MAX_ROTOR_TIME_CONSTANT;
        c.machine = MachineParams::new(data).unwrap();
        assert_eq!(field(c), None);
        let d = DriveDesign::new(c).unwrap();
        assert!(
            (d.limits.magnetizing_timeout_steps as f32) * c.loops.control_period
                <= 2.0 * MAGNETIZING_TIMEOUT_TAU_R * MAX_ROTOR_TIME_CONSTANT
        );
        let mut c = DriveConfig::paper_defaults();
        c.loops.control_period = 5e-6;
        assert_eq!(field(c), Some("loops.control_period"), "not dead_time");
    }
}
