//! The f32 SI design converted to Q7.24 per unit: every coefficient of the cascade
//! ([`DriveCoeffs<Q24>`]) from the one [`DriveDesign`], with range checks.
//!
//! The designs stay single-sourced in f32 (`PiConfig::current_loop`, `ObserverConfig::new`,
//! `FluxModelConfig::new`, `RsEstimatorConfig::new`, `SvpwmConfig::new` and
//! [`DriveDesign::new`]); here each coefficient is only rescaled by its per-unit bases.
//! Gains ([`Gain`]) carry the base factors of their input and output; limits and
//! references must fit 2 pu (64x below saturation, module docs) or the conversion fails
//! naming the quantity.

use super::q::{to_q24, Gain, Q24};
use super::trig::COUNTS_PER_RAD;
use super::PerUnitBases;
use crate::current_loop::CurrentLoopConfig;
use crate::design::{
    ConfigError, DriveCoeffs, DriveDesign, FieldWeakeningDesign, InverterTestDesign,
    MagnetizingDesign, OrientationDesign, SupervisionLimits, VfDesign,
};
use crate::flux::FluxModelConfig;
use crate::gain_calibration::GainCalibrationConfig;
use crate::inverter_tracker::InverterTrackerConfig;
use crate::math::is_finite;
use crate::observer::{ObserverCoeffs, ObserverConfig};
use crate::offset_tracker::OffsetTrackerConfig;
use crate::pi::PiConfig;
use crate::rr_estimator::RrEstimatorConfig;
use crate::rs_estimator::{RsEstimatorConfig, RsRunningConfig};
use crate::sensor_check::SensorCheckConfig;
use crate::speed_loop::SpeedLoopConfig;
use crate::svpwm::SvpwmConfig;
use crate::thermal::ThermalConfig;

/// Largest |signal| in pu the configuration may ask for (limits, trips, references): 2 pu
/// leaves 64x before Q7.24 saturates (module docs, headroom).
const MAX_CONFIGURED_PU: f32 = 2.0;

/// Extra fraction bits of the Rs integrator ([`crate::num::Num::Fine`], Q1.30).
const RS_EXTRA: f32 = 64.0;

fn not_representable(field: &'static str) -> ConfigError {
    ConfigError::Invalid {
        field,
        rule: "does not fit the per-unit bases (above 2 pu, or a gain beyond 2^30)",
    }
}

/// `x / base` in Q7.24 if |x/base| <= 2 pu.
fn pu(x: f32, base: f32, field: &'static str) -> Result<Q24, ConfigError> {
    let v = x / base;
    if is_finite(v) && v.abs() <= MAX_CONFIGURED_PU {
        Ok(Q24(to_q24(v)))
    } else {
        Err(not_representable(field))
    }
}

fn gain(x: f32, field: &'static str) -> Result<Gain, ConfigError> {
    Gain::from_f32(x).ok_or(not_representable(field))
}

/// Gain from a Q7.24 frequency (pu) to angle counts for an angle of `rad_per_pu` radians
/// per 1.0 pu.
pub(crate) fn angle_gain(rad_per_pu: f32) -> Option<Gain> {
    Gain::from_f32(rad_per_pu * COUNTS_PER_RAD / (1u32 << super::q::FRAC_BITS) as f32)
}

/// A PI designed in SI with the error's base `error_base` and the output's base
/// `output_base`. `None` if a gain is not representable.
pub fn pi(cfg: &PiConfig, error_base: f32, output_base: f32) -> Option<PiConfig<Q24>> {
    let k = error_base / output_base;
    Some(PiConfig {
        kp: Gain::from_f32(cfg.kp * k)?,
        ki_ts: Gain::from_f32(cfg.ki_ts * k)?,
        out_min: Q24(to_q24(cfg.out_min / output_base)),
        out_max: Q24(to_q24(cfg.out_max / output_base)),
    })
}

/// The speed loop: the PI from speed to current, the ramp's step (speed), the load
/// estimate (torque) to current, and the reference's limits; fails naming the setting
/// each depends on.
pub fn speed_loop(d: &DriveDesign, b: &PerUnitBases) -> Result<SpeedLoopConfig<Q24>, ConfigError> {
    let cfg = &d.speed_loop;
    let bandwidth = || not_representable("speed_bandwidth");
    Ok(SpeedLoopConfig {
        pi: pi(&cfg.pi, b.speed, b.current).ok_or_else(bandwidth)?,
        acceleration_feedforward: Gain::from_f32(
            cfg.acceleration_feedforward * b.speed / b.current,
        )
        .ok_or_else(bandwidth)?,
        friction_feedforward: Gain::from_f32(cfg.friction_feedforward * b.speed / b.current)
            .ok_or_else(bandwidth)?,
        load_feedforward: Gain::from_f32(cfg.load_feedforward * b.torque / b.current)
            .ok_or_else(bandwidth)?,
        feedforward: cfg.feedforward,
        ramp_step: Q24(to_q24(cfg.ramp_step / b.speed)),
        // 1/(p lambda_ref) in the order the design has always converted it
        speed_per_volt: gain(
            b.voltage / (d.pole_pairs * d.flux_reference * b.speed),
            "flux_current",
        )?,
        regen_min_frequency: Q24(to_q24(cfg.regen_min_frequency / b.frequency)),
        regen_current_per_frequency: gain(
            cfg.regen_current_per_frequency * b.frequency / b.current,
            "regen_min_frequency",
        )?,
        far_side_torque_per_frequency: gain(
            cfg.far_side_torque_per_frequency * b.frequency / b.torque,
            "far_side_gain",
        )?,
        far_side_enter: Q24(to_q24(cfg.far_side_enter / b.frequency)),
        far_side_leave: Q24(to_q24(cfg.far_side_leave / b.frequency)),
        hold_band: pu(cfg.hold_band, b.speed, "max_speed")?,
        report_steps: cfg.report_steps,
    })
}

/// The flux model and slip law.
pub fn flux(cfg: &FluxModelConfig, b: &PerUnitBases) -> Option<FluxModelConfig<Q24>> {
    Some(FluxModelConfig {
        blend: Gain::from_f32(cfg.blend)?,
        magnetizing_inductance: Gain::from_f32(cfg.magnetizing_inductance * b.current / b.flux)?,
        slip_gain: Gain::from_f32(cfg.slip_gain * b.current / (b.flux * b.frequency))?,
        min_flux: Q24(to_q24(cfg.min_flux / b.flux)),
        ts: angle_gain(b.frequency * cfg.ts)?,
    })
}

/// The observer step (eq. 12): currents of I_base, speed of Omega_base (mechanical), load
/// of T_base, voltage of V_base, Rseq of R_base = V_base/I_base, flux of lambda_base, w_s
/// of the electrical frequency base.
pub fn observer(cfg: &ObserverConfig, b: &PerUnitBases) -> Option<ObserverCoeffs<Q24>> {
    let ts = cfg.ts;
    let g = Gain::from_f32;
    Some(ObserverCoeffs {
        ts_a: g(ts * cfg.a)?,
        ts_inv_l: g(ts * cfg.inv_transient_inductance * b.voltage / b.current)?,
        ts_p_inv_l: g(
            ts * cfg.pole_pairs * cfg.inv_transient_inductance * b.flux * b.speed / b.current,
        )?,
        ts: g(ts * b.frequency)?,
        ts_torque_per_inertia: g(ts * cfg.torque_per_inertia * b.flux * b.current / b.speed)?,
        ts_inv_inertia: g(ts * cfg.inv_inertia * b.torque / b.speed)?,
        ts_friction_rate: g(ts * cfg.friction_rate)?,
        ts_g2: g(ts * cfg.g2 * b.current / (b.flux * b.speed))?,
        ts_g3: g(ts * cfg.g3 * b.current / (b.flux * b.torque))?,
    })
}

/// The flying start's speed search: voltages of V_base in, speeds of Omega_base out; the
/// normalised covariance and the arc tangent's argument are dimensionless.
fn search(
    d: &crate::speed_search::SpeedSearchDesign,
    b: &PerUnitBases,
) -> Result<crate::speed_search::SpeedSearchDesign<Q24>, ConfigError> {
    let c = |x: f32| Q24(to_q24(x));
    Ok(crate::speed_search::SpeedSearchDesign {
        enabled: d.enabled,
        begin_step: d.begin_step,
        block_len: d.block_len,
        pairs: d.pairs,
        sample_gain: gain(d.sample_gain * b.voltage, "flux_current")?,
        pair_weight: gain(d.pair_weight, "machine")?,
        signal_floor: c(d.signal_floor),
        speed_per_rad: gain(d.speed_per_rad / b.speed, "control_period")?,
        standstill_speed: pu(d.standstill_speed, b.speed, "rs_max_frequency")?,
        max_speed: pu(d.max_speed, b.speed, "max_speed")?,
        atan: d.atan.map(c),
    })
}

/// A resistance in the Rs integrator's Q1.30 (below 2 pu).
fn to_q30(x: f32) -> Option<i32> {
    if is_finite(x) && x.abs() < 1.99 {
        Some(to_q24(x * RS_EXTRA))
    } else {
        None
    }
}

/// The Rs estimator; its clamps in the integrator's Q1.30.
pub fn rs_estimator(cfg: &RsEstimatorConfig, b: &PerUnitBases) -> Option<RsEstimatorConfig<Q24>> {
    let r_base = b.resistance();
    Some(RsEstimatorConfig {
        ts: Gain::from_f32(cfg.ts * b.frequency)?,
        ts_over_transient_inductance: Gain::from_f32(
            cfg.ts_over_transient_inductance * b.voltage / b.current,
        )?,
        alpha_ts: Gain::from_f32(cfg.alpha_ts * b.current / r_base * RS_EXTRA)?,
        min_resistance: to_q30(cfg.min_resistance / r_base)?,
        max_resistance: to_q30(cfg.max_resistance / r_base)?,
        min_flux_current: Q24(to_q24(cfg.min_flux_current / b.current)),
        max_torque_current: Q24(to_q24(cfg.max_torque_current / b.current)),
        max_stator_frequency: Q24(to_q24(cfg.max_stator_frequency / b.frequency)),
        adapt: cfg.adapt,
    })
}

/// The running Rs law; its input is a voltage: ohm per V per step.
pub fn rs_running(cfg: &RsRunningConfig, b: &PerUnitBases) -> Option<RsRunningConfig<Q24>> {
    Some(RsRunningConfig {
        enabled: cfg.enabled,
        standstill: cfg.standstill,
        alpha_ts: Gain::from_f32(cfg.alpha_ts * b.voltage / b.resistance() * RS_EXTRA)?,
        min_frequency: Q24(to_q24(cfg.min_frequency / b.frequency)),
        min_torque_current: Q24(to_q24(cfg.min_torque_current / b.current)),
        flux_voltage: Gain::from_f32(cfg.flux_voltage * b.frequency * b.flux / b.voltage)?,
        steady_filter: Gain::from_f32(cfg.steady_filter)?,
        steady_band: Q24(to_q24(cfg.steady_band / b.current)),
        max_frequency: Q24(to_q24(cfg.max_frequency / b.frequency)),
    })
}

/// The running offset tracker: its offset gain takes a voltage into the finer integrator
/// format of a current.
pub fn offset_tracker(
    cfg: &OffsetTrackerConfig,
    b: &PerUnitBases,
) -> Option<OffsetTrackerConfig<Q24>> {
    let limit = <Q24 as crate::num::FineIntegrator>::to_fine(Q24(to_q24(cfg.bounds.1 / b.current)));
    Some(OffsetTrackerConfig {
        enabled: cfg.enabled,
        fundamental_gain: Gain::from_f32(cfg.fundamental_gain)?,
        offset_gain: Gain::from_f32(cfg.offset_gain * b.voltage / b.current * RS_EXTRA)?,
        far_side_offset_gain: Gain::from_f32(
            cfg.far_side_offset_gain * b.voltage / b.current * RS_EXTRA,
        )?,
        frequency_filter: Gain::from_f32(cfg.frequency_filter)?,
        ts: Gain::from_f32(cfg.ts * b.frequency)?,
        one_sixth: Gain::from_f32(cfg.one_sixth)?,
        min_frequency: Q24(to_q24(cfg.min_frequency / b.frequency)),
        far_side_min_frequency: Q24(to_q24(cfg.far_side_min_frequency / b.frequency)),
        holdoff_steps: cfg.holdoff_steps,
        steady_filter: Gain::from_f32(cfg.steady_filter)?,
        steady_band: Q24(to_q24(cfg.steady_band / b.current)),
        residual_limit: Q24(to_q24(cfg.residual_limit / b.voltage)),
        floor_rise: Q24(to_q24(cfg.floor_rise / b.voltage)),
        bounds: (-limit, limit),
    })
}

/// The running inverter-error tracker: its rate needs no scaling (the per-unit bases of
/// `x (y - b) / (V_dc |i_ref|^2)` cancel: the step is a duty either way); its current
/// floor is in current pu squared.
pub fn inverter_tracker(
    cfg: &InverterTrackerConfig,
    b: &PerUnitBases,
) -> Option<InverterTrackerConfig<Q24>> {
    Some(InverterTrackerConfig {
        enabled: cfg.enabled,
        dc_filter: Gain::from_f32(cfg.dc_filter)?,
        rate: Gain::from_f32(cfg.rate)?,
        current_floor: Q24(to_q24(cfg.current_floor / (b.current * b.current))),
        min_frequency: Q24(to_q24(cfg.min_frequency / b.frequency)),
        max_frequency: Q24(to_q24(cfg.max_frequency / b.frequency)),
        limit: Q24(to_q24(cfg.limit)),
        holdoff_steps: cfg.holdoff_steps,
        trust_steps: cfg.trust_steps,
    })
}

/// The current-sensor check: its gains rescaled by the bases of what they multiply.
pub fn sensor_check(cfg: &SensorCheckConfig, b: &PerUnitBases) -> Option<SensorCheckConfig<Q24>> {
    let change_threshold = cfg.change_threshold / b.current;
    if !(is_finite(change_threshold) && change_threshold.abs() <= MAX_CONFIGURED_PU) {
        return None;
    }
    Some(SensorCheckConfig {
        // volt -> current increment
        ts_over_sigma_ls: Gain::from_f32(cfg.ts_over_sigma_ls * b.voltage / b.current)?,
        // current -> voltage
        r_sigma: Gain::from_f32(cfg.r_sigma * b.current / b.voltage)?,
        // (frequency x current) -> voltage
        sigma_ls: Gain::from_f32(cfg.sigma_ls * b.frequency * b.current / b.voltage)?,
        // flux -> voltage
        rr_over_lm: Gain::from_f32(cfg.rr_over_lm * b.flux / b.voltage)?,
        // (mechanical speed x flux) -> voltage
        back_emf: Gain::from_f32(cfg.back_emf * b.speed * b.flux / b.voltage)?,
        window_gain: Gain::from_f32(cfg.window_gain)?,
        enabled: cfg.enabled,
        window: cfg.window,
        change_threshold: Q24(to_q24(change_threshold)),
        // dimensionless
        response_ratio: Gain::from_f32(cfg.response_ratio)?,
        astray_ratio: Gain::from_f32(cfg.astray_ratio)?,
        still_threshold: Q24(to_q24(cfg.still_threshold / b.current)),
        bias_gain: Gain::from_f32(cfg.bias_gain)?,
        resistance_allowance: Gain::from_f32(cfg.resistance_allowance)?,
    })
}

/// The rotor-resistance adaptation: its slip term takes `resistance pu x current pu /
/// flux pu` to a frequency in pu; its once-per-window solve converts the per-unit sums
/// to SI with the bases.
pub fn rr_estimator(cfg: &RrEstimatorConfig, b: &PerUnitBases) -> Option<RrEstimatorConfig<Q24>> {
    let r = b.resistance();
    Some(RrEstimatorConfig {
        enabled: cfg.enabled,
        quiet_steps: cfg.quiet_steps,
        settle_steps: cfg.settle_steps,
        window_steps: cfg.window_steps,
        min_window_steps: cfg.min_window_steps,
        current_filter: Gain::from_f32(cfg.current_filter)?,
        steady_filter: Gain::from_f32(cfg.steady_filter)?,
        steady_band: Q24(to_q24(cfg.steady_band / b.current)),
        min_current_change: Q24(to_q24(cfg.min_current_change / b.current)),
        min_frequency: Q24(to_q24(cfg.min_frequency / b.frequency)),
        slip_gain: Gain::from_f32(cfg.slip_gain * r * b.current / (b.flux * b.frequency))?,
        bounds: (Q24(to_q24(cfg.bounds.0 / r)), Q24(to_q24(cfg.bounds.1 / r))),
        referred_rotor_resistance: Q24(to_q24(cfg.referred_rotor_resistance / r)),
        pole_pairs: cfg.pole_pairs,
        current_unit: b.current,
        speed_unit: b.speed,
        flux_unit: b.flux,
        resistance_unit: r,
        // Q7.24 saturates at 128 pu
        sum_limit: 100.0,
    })
}

/// The modulator (duties are dimensionless; voltages of V_base, currents of I_base).
pub fn svpwm(cfg: &SvpwmConfig, b: &PerUnitBases) -> Option<SvpwmConfig<Q24>> {
    Some(SvpwmConfig {
        dead_time_duty: Q24(to_q24(cfg.dead_time_duty)),
        device_drop: Q24(to_q24(cfg.device_drop / b.voltage)),
        inv_current_band: Gain::from_f32(cfg.inv_current_band * b.current)?,
        min_bus_voltage: Q24(to_q24(cfg.min_bus_voltage / b.voltage)),
        // dimensionless
        voltage_limit_per_inv_bus: Gain::from_f32(cfg.voltage_limit_per_inv_bus)?,
    })
}

/// The whole cascade's coefficients; fails naming the first quantity that does not fit.
pub fn coeffs(d: &DriveDesign, b: &PerUnitBases) -> Result<DriveCoeffs<Q24>, ConfigError> {
    let cfg = d.config;
    let m = cfg.machine;
    let ts = d.ts;
    let pp = d.pole_pairs;
    let flux_reference = d.flux_reference;
    // range checks: everything the drive compares against or limits to must fit
    pu(cfg.overcurrent_trip, b.current, "overcurrent_trip")?;
    pu(cfg.current_limit, b.current, "current_limit")?;
    pu(cfg.dc_bus_max, b.voltage, "dc_bus_max")?;
    pu(cfg.max_speed, b.speed, "max_speed")?;
    pu(cfg.max_speed * pp * 1.25, b.frequency, "max_speed")?;
    pu(1.2 * flux_reference, b.flux, "flux_current")?;
    pu(
        cfg.max_load_torque_estimate,
        b.torque,
        "max_load_torque_estimate",
    )?;
    pu(
        m.torque_constant(flux_reference) * cfg.current_limit,
        b.torque,
        "current_limit",
    )?;
    pu(
        2.5 * m.stator_resistance() + m.referred_rotor_resistance(),
        b.resistance(),
        "machine",
    )?;
    // the reciprocal's domain: at least 2^-6 pu
    if cfg.dc_bus_min / b.voltage < 0.02 {
        return Err(not_representable("dc_bus_min"));
    }
    if d.flux.min_flux / b.flux < 0.02 {
        return Err(not_representable("flux_current"));
    }
    let missing = not_representable;
    let pi_current =
        pi(&d.current_loop.pi_d, b.current, b.voltage).ok_or(missing("current_bandwidth"))?;
    Ok(DriveCoeffs {
        current_loop: CurrentLoopConfig {
            pi_d: pi_current,
            pi_q: pi_current,
            overmodulation_reserve_steps: d.current_loop.overmodulation_reserve_steps,
        },
        speed_loop: speed_loop(d, b)?,
        thermal: ThermalConfig {
            heat_gain: gain(
                d.thermal.heat_gain * b.current * b.current,
                "overload_duration",
            )?,
            continuous_squared: pu(
                d.thermal.continuous_squared,
                b.current * b.current,
                "continuous_current",
            )?,
            continuous_ratio: pu(d.thermal.continuous_ratio, 1.0, "continuous_current")?,
            release: pu(d.thermal.release, 1.0, "overload_duration")?,
            enabled: d.thermal.enabled,
        },
        flux: flux(&d.flux, b).ok_or(missing("machine"))?,
        observer: observer(&d.observer, b).ok_or(missing("observer_poles"))?,
        rs: rs_estimator(&d.rs, b).ok_or(missing("rs_convergence_time"))?,
        pwm: svpwm(&d.pwm, b).ok_or(missing("dead_time_current_band"))?,
        rs_initial: pu(cfg.rs_initial, b.resistance(), "rs_initial")?,
        i_sd_ref: pu(d.i_sd_ref, b.current, "flux_current")?,
        settled_flux: pu(d.settled_flux, b.flux, "flux_current")?,
        transient_inductance: gain(
            m.transient_inductance() * b.frequency * b.current / b.voltage,
            "machine",
        )?,
        sample_ripple: gain(
            d.sample_ripple * b.frequency * b.voltage / b.current,
            "machine",
        )?,
        referred_rotor_resistance: pu(m.referred_rotor_resistance(), b.resistance(), "machine")?,
        inv_rotor_time_constant: gain(b.flux / (m.rotor_time_constant() * b.voltage), "machine")?,
        pole_pairs: gain(pp * b.speed / b.frequency, "machine")?,
        back_emf: gain(pp * b.speed * b.flux / b.voltage, "machine")?,
        torque_factor: gain(1.5 * pp * b.flux * b.current / b.torque, "machine")?,
        speed_target_limit: pu(d.speed_target_limit, b.speed, "max_speed")?,
        lead: angle_gain(b.frequency * ts * cfg.delay_periods).ok_or(missing("delay_periods"))?,
        orientation: OrientationDesign {
            gain_per_flux: gain(
                d.orientation.gain_per_flux * b.voltage / b.frequency,
                "orientation_gain",
            )?,
            load_factor_per_current: gain(
                d.orientation.load_factor_per_current * b.current,
                "orientation_gain",
            )?,
            fade_start: pu(d.orientation.fade_start, b.frequency, "orientation_fade")?,
            inv_fade_width: gain(
                b.frequency / (cfg.orientation_fade.1 - cfg.orientation_fade.0),
                "orientation_fade",
            )?,
            limit: pu(d.orientation.limit, b.frequency, "max_speed")?,
            far_side_gain: gain(d.orientation.far_side_gain, "far_side_gain")?,
            far_side_load_factor: gain(
                d.orientation.far_side_load_factor * b.current,
                "far_side_gain",
            )?,
        },
        magnetizing: MagnetizingDesign {
            identify_rs: d.magnetizing.identify_rs,
            rs_timeout_steps: d.magnetizing.rs_timeout_steps,
            rs_settle_steps: d.magnetizing.rs_settle_steps,
            rs_settled_error: pu(d.magnetizing.rs_settled_error, b.current, "flux_current")?,
            residual_filter: gain(d.magnetizing.residual_filter, "control_period")?,
            search: search(&d.magnetizing.search, b)?,
        },
        limits: SupervisionLimits {
            current_sensing: d.limits.current_sensing,
            overcurrent_trip: pu(cfg.overcurrent_trip, b.current, "overcurrent_trip")?,
            dc_bus_min: pu(cfg.dc_bus_min, b.voltage, "dc_bus_min")?,
            dc_bus_max: pu(cfg.dc_bus_max, b.voltage, "dc_bus_max")?,
            max_speed: pu(cfg.max_speed, b.speed, "max_speed")?,
            max_load_torque: pu(
                cfg.max_load_torque_estimate,
                b.torque,
                "max_load_torque_estimate",
            )?,
            implausible_steps: d.limits.implausible_steps,
            stall_steps: d.limits.stall_steps,
            overload_steps: d.limits.overload_steps,
            overload_fraction: Q24(to_q24(d.limits.overload_fraction)),
            overload_speed_floor: pu(d.limits.overload_speed_floor, b.speed, "speed_bandwidth")?,
            blind_frequency: pu(d.limits.blind_frequency, b.frequency, "orientation_fade")?,
            blind_steps: d.limits.blind_steps,
            stall_fraction: Q24(to_q24(d.limits.stall_fraction)),
            rs_bound_faults: d.limits.rs_bound_faults,
            monitor_filter: gain(d.limits.monitor_filter, "current_bandwidth")?,
            current_error_limit: pu(d.limits.current_error_limit, b.current, "flux_current")?,
            current_sum_limit: pu(d.limits.current_sum_limit, b.current, "overcurrent_trip")?,
            model_residual_limit: pu(d.limits.model_residual_limit, b.voltage, "dc_bus_max")?,
            magnetizing_timeout_steps: d.limits.magnetizing_timeout_steps,
            demagnetize_steps: d.limits.demagnetize_steps,
            offset_filter: gain(d.limits.offset_filter, "control_period")?,
            offset_settle_steps: d.limits.offset_settle_steps,
            offset_skip_steps: d.limits.offset_skip_steps,
            oscillation_steps: d.limits.oscillation_steps,
            oscillation_filter: gain(d.limits.oscillation_filter, "control_period")?,
            oscillation_check: d.limits.oscillation_check,
            oscillation_swing: pu(d.limits.oscillation_swing, b.speed, "max_speed")?,
            offset_limit: pu(d.limits.offset_limit, b.current, "overcurrent_trip")?,
            running_offset_filter: gain(d.limits.running_offset_filter, "control_period")?,
            running_offset_min_frequency: pu(
                d.limits.running_offset_min_frequency,
                b.frequency,
                "overcurrent_trip",
            )?,
            impedance_resistance: pu(
                d.limits.impedance_resistance,
                b.resistance(),
                "machine.stator_resistance",
            )?,
            impedance_inductance: gain(
                d.limits.impedance_inductance * b.frequency * b.current / b.voltage,
                "machine.stator_inductance",
            )?,
            impedance_voltage_floor: pu(
                d.limits.impedance_voltage_floor,
                b.voltage,
                "current_limit",
            )?,
        },
        vf: VfDesign {
            volts_per_rad_s: gain(
                cfg.vf.volts_per_rad_s * b.frequency / b.voltage,
                "vf.volts_per_rad_s",
            )?,
            boost: pu(cfg.vf.boost, b.voltage, "vf.boost")?,
        },
        fw: field_weakening(&d.field_weakening, b)?,
        rs_running: rs_running(&d.rs_running, b).ok_or(missing("rs_convergence_time"))?,
        offset_tracker: offset_tracker(&d.offset_tracker, b).ok_or(missing("overcurrent_trip"))?,
        inverter_tracker: inverter_tracker(&d.inverter_tracker, b)
            .ok_or(missing("flux_current"))?,
        gain_calibration: GainCalibrationConfig {
            enabled: d.gain_calibration.enabled,
            filter: gain(d.gain_calibration.filter * RS_EXTRA, "control_period")?,
            // the finer format's whole range, +/-2 pu
            fine_bounds: (
                <Q24 as crate::num::FineIntegrator>::to_fine(Q24(-(1 << 25))),
                <Q24 as crate::num::FineIntegrator>::to_fine(Q24((1 << 25) - 1)),
            ),
            min_voltage: pu(d.gain_calibration.min_voltage, b.voltage, "flux_current")?,
            ratio_scale: gain(
                0.5 * b.voltage / d.gain_calibration.min_voltage,
                "current_gain_calibration",
            )?,
            sqrt3: gain(d.gain_calibration.sqrt3, "current_gain_calibration")?,
            // dimensionless
            bounds: (
                Q24(to_q24(d.gain_calibration.bounds.0)),
                Q24(to_q24(d.gain_calibration.bounds.1)),
            ),
        },
        rr: rr_estimator(&d.rr_estimator, b).ok_or(missing("machine.rotor_resistance"))?,
        sensor_check: sensor_check(&d.sensor_check, b).ok_or(missing("machine"))?,
        zero_dwell_steps: d.zero_dwell_steps,
        zero_speed_stop: d.zero_speed_stop,
        slow_divider: d.slow_divider,
        inv_slow_divider: gain(1.0 / d.slow_divider as f32, "slow_period")?,
        inverter_test: InverterTestDesign {
            level_steps: d.inverter_test.level_steps,
            settle_steps: d.inverter_test.settle_steps,
            levels: [
                pu(d.inverter_test.levels[0], b.current, "flux_current")?,
                pu(d.inverter_test.levels[1], b.current, "flux_current")?,
                pu(d.inverter_test.levels[2], b.current, "flux_current")?,
            ],
            tolerances: [
                pu(d.inverter_test.tolerances[0], b.current, "flux_current")?,
                pu(d.inverter_test.tolerances[1], b.current, "flux_current")?,
                pu(d.inverter_test.tolerances[2], b.current, "flux_current")?,
            ],
            filter: gain(d.inverter_test.filter, "control_period")?,
            // dimensionless: voltage in, voltage out
            error_weights: [
                gain(d.inverter_test.error_weights[0], "inverter_identification")?,
                gain(d.inverter_test.error_weights[1], "inverter_identification")?,
                gain(d.inverter_test.error_weights[2], "inverter_identification")?,
            ],
            // 1/A: V_base y w / R_base = y (w I_base) in resistance per unit
            slope_weights: [
                gain(d.inverter_test.slope_weights[0] * b.current, "flux_current")?,
                gain(d.inverter_test.slope_weights[1] * b.current, "flux_current")?,
                gain(d.inverter_test.slope_weights[2] * b.current, "flux_current")?,
            ],
            resistance_window: (
                pu(
                    d.inverter_test.resistance_window.0,
                    b.resistance(),
                    "inverter_identification",
                )?,
                pu(
                    d.inverter_test.resistance_window.1,
                    b.resistance(),
                    "inverter_identification",
                )?,
            ),
            max_duty: Q24(to_q24(d.inverter_test.max_duty)),
        },
    })
}

/// Field weakening and over-voltage control: voltages of V_base, currents of
/// I_base, frequencies of w_base; flux linkage V/w comes out of the Q7.24 ratio in
/// V_base/w_base. The frequency floor must be inside the reciprocal's domain (2^-6 pu).
fn field_weakening(
    f: &FieldWeakeningDesign,
    b: &PerUnitBases,
) -> Result<FieldWeakeningDesign<Q24>, ConfigError> {
    if f.min_frequency / b.frequency < 0.02 {
        return Err(not_representable("max_speed"));
    }
    Ok(FieldWeakeningDesign {
        enabled: f.enabled,
        voltage_fraction: gain(f.voltage_fraction, "field_weakening")?,
        min_frequency: pu(f.min_frequency, b.frequency, "max_speed")?,
        min_flux_current: pu(f.min_flux_current, b.current, "flux_current")?,
        current_limit: pu(f.current_limit, b.current, "current_limit")?,
        inv_stator_inductance: gain(
            f.inv_stator_inductance * b.voltage / (b.frequency * b.current),
            "machine",
        )?,
        stator_inductance: gain(
            f.stator_inductance * b.frequency * b.current / b.voltage,
            "machine",
        )?,
        flux_voltage: gain(f.flux_voltage * b.frequency * b.flux / b.voltage, "machine")?,
        trim_gain: gain(
            f.trim_gain * b.voltage / (b.frequency * b.current),
            "field_weakening",
        )?,
        trim_gate: gain(f.trim_gate, "field_weakening")?,
        trim_fraction: gain(f.trim_fraction, "field_weakening")?,
        rated_linkage: pu(f.rated_linkage, b.flux, "flux_current")?,
        flux_reference: pu(f.flux_reference, b.flux, "flux_current")?,
        overvoltage_control: f.overvoltage_control,
        flux_optimisation: f.flux_optimisation,
        optimum_ratio: gain(f.optimum_ratio, "machine")?,
        optimum_min_current: pu(f.optimum_min_current, b.current, "flux_current")?,
        optimum_fall: gain(f.optimum_fall, "machine")?,
        regen_start: pu(f.regen_start, b.voltage, "dc_bus_max")?,
        inv_regen_band: gain(f.inv_regen_band * b.voltage, "dc_bus_max")?,
    })
}

impl crate::design::DesignArithmetic for Q24 {
    fn coeffs(design: &DriveDesign, bases: &PerUnitBases) -> Result<DriveCoeffs<Q24>, ConfigError> {
        coeffs(design, bases)
    }
}
