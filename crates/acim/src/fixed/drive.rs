//! The sensorless IFOC drive in fixed point: the running path of [`crate::drive::Drive`]
//! (its module docs describe the cascade, the states, the orientation correction and the
//! timing convention; this file follows them step for step) on Q7.24 per-unit samples.
//!
//! Same cascade, same order: fault checks, Clarke/Park, observer (eq. 12), Rs estimator
//! (eq. 19-20) with its residual filter, orientation correction, flux model and slip law
//! (eq. 13, 8), estimator plausibility, speed ramp and PI with the current circle,
//! d/q current PIs with decoupling feed-forward (eq. 9a, 9b) and the voltage circle,
//! inverse Park at the advanced angle and SVPWM with bus and dead-time compensation.
//! Same states: `Idle -> Magnetizing -> Running`, any -> `Fault` (switches off in the same
//! step), `Fault -> Idle` only by [`FixedDrive::reset_fault`]; with Rs estimation on,
//! magnetizing also waits for the standstill Rs identification (settled residual for
//! 50 ms, at most `rs_identification_timeout`).
//!
//! Differences from the f32 drive, all deliberate:
//! - no open-loop V/f mode (`FixedDrive::start_open_loop` does not exist; commissioning
//!   runs in f32);
//! - samples are integers, so there is no non-finite input inside the step: the
//!   simulator boundary ([`FixedDrive::step_si`]) reports a NaN/inf sample as
//!   `NonFiniteInput`, like the f32 drive, and a saturated ADC code is an over-current;
//! - the voltage acts at the angle advanced by 1.5 periods, taken from the sin/cos table
//!   directly (exact rotation; the f32 drive uses a series for the small rotation and
//!   clamps the lead to 0.3 rad, which it never reaches below 2000 rpm);
//! - duties leave as Q15 (`u16`, 32768 = 1.0), ready for a timer compare register.
//!
//! Configuration: [`FixedDrive::new`] takes the same [`DriveConfig`] as the f32 drive and
//! builds the same [`DriveDesign`] (validated once, every derived constant computed once);
//! [`FixedDrive::from_design`] converts that design with the per-unit bases, checking that
//! the configured ranges fit them. Nothing is designed twice and no derived constant is
//! copied by hand: the 20 ms residual filter, the settle thresholds, the implausibility
//! time and the correction limit come from the design; the Q7.24 literals below are the
//! design module's named fractions ([`crate::design::STALL_SPEED_FRACTION`],
//! [`crate::svpwm::VOLTAGE_MARGIN`]) in Q7.24, checked by a test.

use super::flux::{angle_gain, FixedFluxConfig, FixedFluxModel};
use super::observer::{FixedObserver, FixedObserverConfig, FixedObserverInputs};
use super::pi::{FixedPiConfig, FixedPiController};
use super::q::{clamp, from_q24, mul, reciprocal, to_q24, Gain, ONE};
use super::rs_estimator::{FixedRsConfig, FixedRsEstimator, FixedRsInputs};
use super::svpwm::{modulate, FixedSvpwmConfig};
use super::trig::{
    angle_to_rad, clarke_three, clarke_two, inverse_clarke, inverse_park, park, sin_cos, FixedDq,
};
use super::PerUnitBases;
use crate::design::DriveDesign;
use crate::drive::{
    CommandError, ConfigError, CurrentSensing, DriveConfig, DriveInputs, DriveState,
    DriveTelemetry, FaultReason, NoProbe, PwmOutput, StepProbe, StepRegion, Supervisor,
};
use crate::frames::Dq;
use crate::math::{is_finite, sqrt};
use crate::svpwm::{INV_SQRT3, VOLTAGE_MARGIN};

/// Largest |signal| in pu the configuration may ask for (limits, trips, references): 2 pu
/// leaves 64x before Q7.24 saturates (module docs, headroom).
const MAX_CONFIGURED_PU: f32 = 2.0;

/// Why a fixed-point drive configuration was rejected.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum FixedConfigError {
    /// The f32 drive rejects the configuration.
    Drive(ConfigError),
    /// The named quantity does not fit the per-unit bases (above 2 pu, or a coefficient
    /// beyond the gain range).
    NotRepresentable(&'static str),
}

impl core::fmt::Display for FixedConfigError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            FixedConfigError::Drive(e) => write!(f, "{e}"),
            FixedConfigError::NotRepresentable(name) => {
                write!(f, "fixed point: {name} does not fit the per-unit bases")
            }
        }
    }
}

/// Samples of one control step, Q7.24 pu.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FixedInputs {
    /// Phase currents a, b, c, current pu (c ignored with two-phase sensing).
    pub phase_currents: [i32; 3],
    /// DC-bus voltage, voltage pu.
    pub dc_bus: i32,
}

/// PWM command of one step.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FixedPwm {
    /// High-side duties a, b, c, Q15 (0 .. 32768 = always on; 16384 when disabled).
    pub duties: [u16; 3],
    /// False: all six switches off.
    pub enabled: bool,
}

impl FixedPwm {
    /// All switches off.
    pub const OFF: Self = Self {
        duties: [16384; 3],
        enabled: false,
    };
}

/// What the last step computed, Q7.24 pu (see [`DriveTelemetry`] for the meaning).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FixedTelemetry {
    /// Ramped speed reference, speed pu.
    pub speed_reference: i32,
    /// Omega_hat, speed pu.
    pub speed_estimate: i32,
    /// T_L_hat, torque pu.
    pub load_torque_estimate: i32,
    /// 1.5 p lambda_r i_sq, torque pu.
    pub torque_estimate: i32,
    /// Measured dq currents, current pu.
    pub current: FixedDq,
    /// dq current references, current pu.
    pub current_reference: FixedDq,
    /// dq voltage command, voltage pu.
    pub voltage: FixedDq,
    /// lambda_r, flux pu.
    pub rotor_flux: i32,
    /// Rs_hat, resistance pu.
    pub stator_resistance_estimate: i32,
    /// Frame angle of this step's samples, turn fraction.
    pub angle: u32,
    /// w_s, frequency pu.
    pub stator_frequency: i32,
    /// Whether the modulator limited the voltage.
    pub voltage_saturated: bool,
}

/// 0.98/sqrt(3): the voltage circle inside the hexagon, as a fraction of V_dc (Q7.24).
const V_MAX_PER_BUS: i32 = 9_492_603;
/// sqrt(3) in Q7.24 (the chord of the q-voltage limit).
const SQRT3: i32 = 29_058_991;
/// 0.1 in Q7.24 (stall: speed below 10 % of the reference).
const STALL_FRACTION: i32 = 1_677_722;

/// The fixed-point sensorless IFOC drive.
#[derive(Clone, Debug)]
pub struct FixedDrive {
    cfg: DriveConfig,
    bases: PerUnitBases,
    // precomputed configuration (Q7.24 pu or gains)
    pi_d: FixedPiConfig,
    pi_q: FixedPiConfig,
    pi_speed: FixedPiConfig,
    flux_cfg: FixedFluxConfig,
    obs_cfg: FixedObserverConfig,
    rs_cfg: FixedRsConfig,
    pwm_cfg: FixedSvpwmConfig,
    i_sd_ref: i32,
    settled_flux: i32,
    referred_rotor_resistance: i32,
    /// (frequency pu x current pu) -> voltage pu: sigma Ls w_base I_base / V_base.
    sigma_ls: Gain,
    /// flux pu -> voltage pu: lambda_base / (tau_r V_base).
    flux_over_tau_r: Gain,
    /// (speed pu x flux pu) -> voltage pu: p Omega_base lambda_base / V_base.
    back_emf: Gain,
    /// speed pu -> electrical frequency pu: p Omega_base / w_base.
    speed_to_frequency: Gain,
    /// (flux pu x current pu) -> torque pu: 1.5 p lambda_base I_base / T_base.
    torque_factor: Gain,
    /// frequency pu -> angle counts of the 1.5-period voltage lead.
    lead_angle: Gain,
    /// 1/(0.98/sqrt(3)): 1/V_dc -> 1/v_max.
    inv_v_max_per_inv_bus: Gain,
    ramp_step: i32,
    /// (fade x volts pu) -> frequency pu: k V_base / (lambda_ref w_base).
    orientation_gain_per_flux: Gain,
    orientation_fade_start: i32,
    /// frequency pu -> fade fraction: w_base / (fade upper - fade lower).
    orientation_inv_fade_width: Gain,
    orientation_limit: i32,
    overcurrent_trip: i32,
    dc_bus_min: i32,
    dc_bus_max: i32,
    max_speed: i32,
    max_load_torque: i32,
    speed_target_limit: i32,
    stall_steps: u32,
    rs_timeout_steps: u32,
    rs_settle_steps: u32,
    implausible_limit: u32,
    residual_filter: Gain,
    rs_settled_error: i32,
    // state
    sup: Supervisor,
    speed_target: i32,
    speed_reference: i32,
    speed_ctl: FixedPiController,
    d_ctl: FixedPiController,
    q_ctl: FixedPiController,
    flux: FixedFluxModel,
    observer: FixedObserver,
    rs: FixedRsEstimator,
    applied_voltage: FixedDq,
    stall_counter: u32,
    implausible_steps: u32,
    magnetizing_steps: u32,
    rs_settled_steps: u32,
    filtered_residual: i32,
    telemetry: FixedTelemetry,
}

/// `x / base` in Q7.24 if |x/base| <= 2 pu.
fn pu(x: f32, base: f32, name: &'static str) -> Result<i32, FixedConfigError> {
    let v = x / base;
    if is_finite(v) && v.abs() <= MAX_CONFIGURED_PU {
        Ok(to_q24(v))
    } else {
        Err(FixedConfigError::NotRepresentable(name))
    }
}

fn gain(x: f32, name: &'static str) -> Result<Gain, FixedConfigError> {
    Gain::from_f32(x).ok_or(FixedConfigError::NotRepresentable(name))
}

impl FixedDrive {
    /// Validates `cfg` (as the f32 drive does, plus the fit to `bases`), designs every
    /// block with the f32 design functions and converts the coefficients; an idle drive.
    pub fn new(cfg: DriveConfig, bases: PerUnitBases) -> Result<Self, FixedConfigError> {
        Self::from_design(
            &DriveDesign::new(cfg).map_err(FixedConfigError::Drive)?,
            bases,
        )
    }

    /// Converts the f32 design (validated once, every derived constant computed once) to
    /// Q7.24 with `bases`, checking that every configured range fits them; an idle drive.
    pub fn from_design(
        design: &DriveDesign,
        bases: PerUnitBases,
    ) -> Result<Self, FixedConfigError> {
        let d = design;
        let cfg = d.config;
        let b = bases;
        let m = cfg.machine;
        let ts = d.ts;
        let i_d = d.i_sd_ref;
        let flux_reference = d.flux_reference;
        let (pi_current, pi_speed, obs, flux_cfg, rs_cfg, pwm) =
            (d.pi_d, d.pi_speed, d.observer, d.flux, d.rs, d.pwm);
        let pp = d.pole_pairs;
        // range checks: everything the drive compares against or limits to must fit
        pu(cfg.overcurrent_trip, b.current, "overcurrent_trip")?;
        pu(cfg.current_limit, b.current, "current_limit")?;
        pu(cfg.dc_bus_max, b.voltage, "dc_bus_max")?;
        pu(cfg.max_speed, b.speed, "max_speed")?;
        pu(
            cfg.max_speed * pp * 1.25,
            b.frequency,
            "max_speed (stator frequency)",
        )?;
        pu(1.2 * flux_reference, b.flux, "flux reference")?;
        pu(
            cfg.max_load_torque_estimate,
            b.torque,
            "max_load_torque_estimate",
        )?;
        pu(
            m.torque_constant(flux_reference) * cfg.current_limit,
            b.torque,
            "torque at the current limit",
        )?;
        pu(
            2.5 * m.stator_resistance() + m.referred_rotor_resistance(),
            b.resistance(),
            "Rseq",
        )?;
        // the reciprocal's domain: at least 2^-6 pu
        if cfg.dc_bus_min / b.voltage < 0.02 || flux_cfg.min_flux / b.flux < 0.02 {
            return Err(FixedConfigError::NotRepresentable(
                "dc_bus_min or flux guard",
            ));
        }
        let missing = FixedConfigError::NotRepresentable;
        Ok(Self {
            pi_d: FixedPiConfig::from_f32(&pi_current, b.current, b.voltage)
                .ok_or(missing("current PI"))?,
            pi_q: FixedPiConfig::from_f32(&pi_current, b.current, b.voltage)
                .ok_or(missing("current PI"))?,
            pi_speed: FixedPiConfig::from_f32(&pi_speed, b.speed, b.current)
                .ok_or(missing("speed PI"))?,
            flux_cfg: FixedFluxConfig::from_f32(&flux_cfg, &b).ok_or(missing("flux model"))?,
            obs_cfg: FixedObserverConfig::from_f32(&obs, &b).ok_or(missing("observer"))?,
            rs_cfg: FixedRsConfig::from_f32(&rs_cfg, &b).ok_or(missing("Rs estimator"))?,
            pwm_cfg: FixedSvpwmConfig::from_f32(&pwm, &b).ok_or(missing("svpwm"))?,
            i_sd_ref: pu(i_d, b.current, "flux_current")?,
            settled_flux: pu(d.settled_flux, b.flux, "flux reference")?,
            referred_rotor_resistance: pu(m.referred_rotor_resistance(), b.resistance(), "R_R")?,
            sigma_ls: gain(
                m.transient_inductance() * b.frequency * b.current / b.voltage,
                "sigma Ls",
            )?,
            flux_over_tau_r: gain(b.flux / (m.rotor_time_constant() * b.voltage), "1/tau_r")?,
            back_emf: gain(pp * b.speed * b.flux / b.voltage, "back-EMF")?,
            speed_to_frequency: gain(pp * b.speed / b.frequency, "pole pairs")?,
            torque_factor: gain(1.5 * pp * b.flux * b.current / b.torque, "torque factor")?,
            lead_angle: angle_gain(b.frequency * ts * cfg.delay_periods)
                .ok_or(missing("delay_periods"))?,
            inv_v_max_per_inv_bus: gain(1.0 / (VOLTAGE_MARGIN * INV_SQRT3), "voltage limit")?,
            ramp_step: to_q24(d.ramp_step / b.speed),
            orientation_gain_per_flux: gain(
                d.orientation.gain_per_flux * b.voltage / b.frequency,
                "orientation_gain",
            )?,
            orientation_fade_start: pu(d.orientation.fade_start, b.frequency, "orientation_fade")?,
            orientation_inv_fade_width: gain(
                b.frequency / (cfg.orientation_fade.1 - cfg.orientation_fade.0),
                "orientation_fade",
            )?,
            orientation_limit: pu(d.orientation.limit, b.frequency, "max_speed")?,
            overcurrent_trip: pu(cfg.overcurrent_trip, b.current, "overcurrent_trip")?,
            dc_bus_min: pu(cfg.dc_bus_min, b.voltage, "dc_bus_min")?,
            dc_bus_max: pu(cfg.dc_bus_max, b.voltage, "dc_bus_max")?,
            max_speed: pu(cfg.max_speed, b.speed, "max_speed")?,
            max_load_torque: pu(cfg.max_load_torque_estimate, b.torque, "max_load_torque")?,
            speed_target_limit: pu(d.speed_target_limit, b.speed, "max_speed")?,
            stall_steps: d.limits.stall_steps,
            rs_timeout_steps: d.magnetizing.rs_timeout_steps,
            rs_settle_steps: d.magnetizing.rs_settle_steps,
            implausible_limit: d.limits.implausible_steps,
            residual_filter: gain(d.magnetizing.residual_filter, "control_period")?,
            rs_settled_error: pu(d.magnetizing.rs_settled_error, b.current, "flux_current")?,
            sup: Supervisor::new(),
            speed_target: 0,
            speed_reference: 0,
            speed_ctl: FixedPiController::new(),
            d_ctl: FixedPiController::new(),
            q_ctl: FixedPiController::new(),
            flux: FixedFluxModel::new(),
            observer: FixedObserver::new(),
            rs: FixedRsEstimator::new(pu(cfg.rs_initial, b.resistance(), "rs_initial")?),
            applied_voltage: FixedDq::default(),
            stall_counter: 0,
            implausible_steps: 0,
            magnetizing_steps: 0,
            rs_settled_steps: 0,
            filtered_residual: 0,
            telemetry: FixedTelemetry {
                stator_resistance_estimate: to_q24(cfg.rs_initial / b.resistance()),
                ..FixedTelemetry::default()
            },
            cfg,
            bases,
        })
    }

    /// The configuration the drive was built with (SI).
    pub fn config(&self) -> &DriveConfig {
        &self.cfg
    }
    /// The per-unit bases.
    pub fn bases(&self) -> &PerUnitBases {
        &self.bases
    }
    /// Present state.
    pub fn state(&self) -> DriveState {
        self.sup.state()
    }
    /// The fault that stopped the drive, if any.
    pub fn fault(&self) -> Option<FaultReason> {
        self.sup.fault()
    }
    /// What the last step computed (Q7.24 pu).
    pub fn telemetry(&self) -> &FixedTelemetry {
        &self.telemetry
    }

    /// Sets the speed target (Q7.24 speed pu), limited to +/- 90 % of `max_speed`.
    pub fn set_speed_target(&mut self, speed: i32) {
        self.speed_target = clamp(speed, -self.speed_target_limit, self.speed_target_limit);
    }

    /// Idle -> Magnetizing: resets every controller and estimator and starts building flux.
    pub fn start(&mut self) -> Result<(), CommandError> {
        self.sup.start(DriveState::Magnetizing)?;
        self.reset_dynamic_state();
        Ok(())
    }

    /// Any active state -> Idle (switches off at once); a faulted drive stays faulted.
    pub fn stop(&mut self) {
        self.sup.stop();
    }

    /// Fault -> Idle.
    pub fn reset_fault(&mut self) -> Result<(), CommandError> {
        self.sup.reset_fault()
    }

    /// Forces a fault from outside (hardware break, missed deadline).
    pub fn trip(&mut self, reason: FaultReason) -> FixedPwm {
        self.enter_fault(reason)
    }

    fn reset_dynamic_state(&mut self) {
        self.speed_reference = 0;
        self.speed_ctl.reset();
        self.d_ctl.reset();
        self.q_ctl.reset();
        self.flux = FixedFluxModel::new();
        self.observer = FixedObserver::new();
        self.rs = FixedRsEstimator::new(self.rs.stator_resistance_estimate);
        self.applied_voltage = FixedDq::default();
        self.stall_counter = 0;
        self.implausible_steps = 0;
        self.magnetizing_steps = 0;
        self.rs_settled_steps = 0;
        self.filtered_residual = 0;
    }

    fn enter_fault(&mut self, reason: FaultReason) -> FixedPwm {
        self.sup.trip(reason);
        self.applied_voltage = FixedDq::default();
        FixedPwm::OFF
    }

    /// Checks on the raw samples: over-current (a saturated ADC code is one) and bus limits.
    #[inline(always)]
    fn check_inputs(&self, inp: &FixedInputs) -> Option<FaultReason> {
        let [a, b, c_meas] = inp.phase_currents;
        let c = match self.cfg.current_sensing {
            CurrentSensing::TwoPhase => 0i32.saturating_sub(a).saturating_sub(b),
            CurrentSensing::ThreePhase => c_meas,
        };
        let trip = self.overcurrent_trip;
        if a.saturating_abs() > trip || b.saturating_abs() > trip || c.saturating_abs() > trip {
            return Some(FaultReason::OverCurrent);
        }
        if inp.dc_bus > self.dc_bus_max {
            return Some(FaultReason::DcBusOverVoltage);
        }
        if inp.dc_bus < self.dc_bus_min {
            return Some(FaultReason::DcBusUnderVoltage);
        }
        None
    }

    /// One control step: per-unit samples in, Q15 duties out. Never panics; integer
    /// arithmetic saturates.
    #[inline]
    pub fn step(&mut self, inp: &FixedInputs) -> FixedPwm {
        self.step_probed(inp, &mut NoProbe)
    }

    /// [`FixedDrive::step`] with `probe` called around each [`StepRegion`] (cycle bench).
    #[inline(always)]
    pub fn step_probed<P: StepProbe>(&mut self, inp: &FixedInputs, probe: &mut P) -> FixedPwm {
        match self.sup.state() {
            DriveState::Fault => return FixedPwm::OFF,
            DriveState::Idle | DriveState::OpenLoop => {
                return match self.check_inputs(inp) {
                    Some(FaultReason::OverCurrent) => self.enter_fault(FaultReason::OverCurrent),
                    _ => FixedPwm::OFF,
                };
            }
            _ => {}
        }
        probe.begin(StepRegion::FaultChecks);
        let bad = self.check_inputs(inp);
        probe.end(StepRegion::FaultChecks);
        if let Some(reason) = bad {
            return self.enter_fault(reason);
        }
        let [a, b, c] = inp.phase_currents;

        // 2. Clarke and Park at the frame angle of the samples
        probe.begin(StepRegion::ClarkePark);
        let i_ab = match self.cfg.current_sensing {
            CurrentSensing::TwoPhase => clarke_two(a, b),
            CurrentSensing::ThreePhase => clarke_three(a, b, c),
        };
        let sample_angle = self.flux.angle;
        let sc = sin_cos(sample_angle);
        let i = park(i_ab, sc);
        probe.end(StepRegion::ClarkePark);
        let magnetizing = self.sup.state() == DriveState::Magnetizing;

        // 3. observer (eq. 12) with the voltage applied over the past period
        probe.begin(StepRegion::ObserverReduced);
        let rseq = self
            .rs
            .stator_resistance_estimate
            .saturating_add(self.referred_rotor_resistance);
        if !magnetizing {
            self.observer.update(
                &self.obs_cfg,
                &FixedObserverInputs {
                    i_sq: i.q,
                    i_sd: i.d,
                    stator_frequency: self.flux.stator_frequency,
                    v_sq: self.applied_voltage.q,
                    rotor_flux: self.flux.rotor_flux,
                    inv_rotor_flux: self.flux.inv_rotor_flux,
                    equivalent_resistance: rseq,
                },
            );
        }
        let speed_est = self.observer.speed_estimate;
        probe.end(StepRegion::ObserverReduced);

        // 4. stator resistance (eq. 19-20) and the 20 ms residual filter
        probe.begin(StepRegion::RsEstimator);
        let flux_settled = self.flux.rotor_flux >= self.settled_flux;
        let ws_prev = self.flux.stator_frequency;
        self.rs.update(
            &self.rs_cfg,
            &FixedRsInputs {
                i_sd: i.d,
                i_sq: i.q,
                v_sd: self.applied_voltage.d,
                stator_frequency: ws_prev,
                flux_settled,
            },
        );
        let rs_hat = self.rs.stator_resistance_estimate;
        self.filtered_residual = self.filtered_residual.saturating_add(
            self.residual_filter
                .apply(self.rs.current_error.saturating_sub(self.filtered_residual)),
        );
        probe.end(StepRegion::RsEstimator);

        // orientation correction (drive.rs module docs): dw = -k sign(w_s) r_d / lambda_ref,
        // faded in between the two fade frequencies, bounded
        probe.begin(StepRegion::FluxSlip);
        let mut correction = 0;
        if !magnetizing && flux_settled {
            let fade = clamp(
                self.orientation_inv_fade_width.apply(
                    ws_prev
                        .saturating_abs()
                        .saturating_sub(self.orientation_fade_start),
                ),
                0,
                ONE,
            );
            let r_d = mul(rs_hat, self.rs.current_error);
            let signed = if ws_prev >= 0 {
                0i32.saturating_sub(r_d)
            } else {
                r_d
            };
            correction = clamp(
                self.orientation_gain_per_flux.apply(mul(fade, signed)),
                -self.orientation_limit,
                self.orientation_limit,
            );
        }

        // 5. flux model, slip and angle (eq. 13, 8) with p Omega_hat: sensorless
        self.flux.update(
            &self.flux_cfg,
            i.d,
            i.q,
            self.speed_to_frequency
                .apply(speed_est)
                .saturating_add(correction),
            magnetizing,
        );
        let ws = self.flux.stator_frequency;
        let lambda = self.flux.rotor_flux;
        probe.end(StepRegion::FluxSlip);

        // estimator plausibility (integers cannot be non-finite): Rs at a bound faults at
        // once, an implausible load estimate after 20 ms, over-speed at once
        if self.cfg.rs_estimation && self.rs.at_bound {
            return self.enter_fault(FaultReason::EstimatorOutOfRange);
        }
        self.implausible_steps =
            if self.observer.load_torque_estimate.saturating_abs() > self.max_load_torque {
                self.implausible_steps.saturating_add(1)
            } else {
                0
            };
        if self.implausible_steps > self.implausible_limit {
            return self.enter_fault(if self.speed_ctl.saturated() {
                FaultReason::Stall
            } else {
                FaultReason::EstimatorOutOfRange
            });
        }
        if speed_est.saturating_abs() > self.max_speed {
            return self.enter_fault(FaultReason::OverSpeed);
        }

        // 6. references
        probe.begin(StepRegion::SpeedPi);
        let (i_sd_ref, i_sq_ref);
        if magnetizing {
            i_sd_ref = self.i_sd_ref;
            i_sq_ref = 0;
            self.magnetizing_steps = self.magnetizing_steps.saturating_add(1);
            self.rs_settled_steps =
                if self.filtered_residual.saturating_abs() < self.rs_settled_error {
                    self.rs_settled_steps.saturating_add(1)
                } else {
                    0
                };
            // standstill Rs identification: wait for 50 ms of settled residual
            let rs_done = !self.cfg.rs_estimation
                || self.rs_settled_steps > self.rs_settle_steps
                || self.magnetizing_steps > self.rs_timeout_steps;
            if flux_settled && rs_done {
                self.sup.magnetized();
                self.observer.reset(i.q, 0, 0);
                self.speed_ctl.reset();
            }
        } else {
            let dv = clamp(
                self.speed_target.saturating_sub(self.speed_reference),
                -self.ramp_step,
                self.ramp_step,
            );
            self.speed_reference = self.speed_reference.saturating_add(dv);
            i_sd_ref = self.i_sd_ref;
            i_sq_ref = self.speed_ctl.update(
                &self.pi_speed,
                self.speed_reference.saturating_sub(speed_est),
                0,
            );
            let stalled = self.speed_ctl.saturated()
                && speed_est.saturating_abs()
                    < mul(STALL_FRACTION, self.speed_reference.saturating_abs());
            self.stall_counter = if stalled {
                self.stall_counter.saturating_add(1)
            } else {
                0
            };
            if self.stall_counter > self.stall_steps {
                return self.enter_fault(FaultReason::Stall);
            }
        }
        probe.end(StepRegion::SpeedPi);

        // 7. current PIs with decoupling feed-forward (eq. 9a, 9b); the bus was checked
        // against dc_bus_min: one reciprocal per step, shared with the modulator
        probe.begin(StepRegion::CurrentPi);
        let inv_vdc = reciprocal(inp.dc_bus);
        let v_max = mul(inp.dc_bus, V_MAX_PER_BUS);
        let inv_v_max = self.inv_v_max_per_inv_bus.apply(inv_vdc);
        let ff_d = mul(
            rs_hat.saturating_add(self.referred_rotor_resistance),
            i_sd_ref,
        )
        .saturating_sub(self.flux_over_tau_r.apply(lambda))
        .saturating_sub(self.sigma_ls.apply(mul(ws, i_sq_ref)));
        let ff_q = mul(
            rs_hat.saturating_add(self.referred_rotor_resistance),
            i_sq_ref,
        )
        .saturating_add(self.sigma_ls.apply(mul(ws, i_sd_ref)))
        .saturating_add(self.back_emf.apply(mul(speed_est, lambda)));
        let v_d = self.d_ctl.update_with_limits(
            &self.pi_d,
            i_sd_ref.saturating_sub(i.d),
            ff_d,
            -v_max,
            v_max,
        );
        // q limit on the circle with d priority, without a square root (as in f32): the
        // Taylor bound v_max - v_d^2/(2 v_max) while |v_d| <= v_max/2, the chord beyond
        let ad = v_d.saturating_abs();
        let v_q_max = if ad <= v_max >> 1 {
            v_max.saturating_sub(mul(mul(v_d, v_d) >> 1, inv_v_max))
        } else {
            mul(SQRT3, v_max.saturating_sub(ad))
        };
        let v_q = self.q_ctl.update_with_limits(
            &self.pi_q,
            i_sq_ref.saturating_sub(i.q),
            ff_q,
            -v_q_max,
            v_q_max,
        );
        let v = FixedDq { d: v_d, q: v_q };
        probe.end(StepRegion::CurrentPi);

        // 8. inverse Park at the angle the voltage will act at, then SVPWM
        probe.begin(StepRegion::Svpwm);
        let lead = self.lead_angle.apply(ws);
        let rot = sin_cos(sample_angle.wrapping_add(lead as u32));
        let v_ab = inverse_park(v, rot);
        let i_ref_abc = inverse_clarke(inverse_park(
            FixedDq {
                d: i_sd_ref,
                q: i_sq_ref,
            },
            rot,
        ));
        let m = modulate(&self.pwm_cfg, v_ab, inp.dc_bus, inv_vdc, i_ref_abc);
        probe.end(StepRegion::Svpwm);
        self.applied_voltage = v;

        self.telemetry = FixedTelemetry {
            speed_reference: self.speed_reference,
            speed_estimate: speed_est,
            load_torque_estimate: self.observer.load_torque_estimate,
            torque_estimate: self.torque_factor.apply(mul(lambda, i.q)),
            current: i,
            current_reference: FixedDq {
                d: i_sd_ref,
                q: i_sq_ref,
            },
            voltage: v,
            rotor_flux: lambda,
            stator_resistance_estimate: rs_hat,
            angle: sample_angle,
            stator_frequency: ws,
            voltage_saturated: m.saturated,
        };
        let [da, db, dc] = m.duties;
        FixedPwm {
            duties: [duty_q15(da), duty_q15(db), duty_q15(dc)],
            enabled: true,
        }
    }

    // ---- simulator boundary (f32 <-> per unit); not for the control interrupt ----

    /// Sets the speed target in rad/s mechanical (boundary conversion).
    pub fn set_speed_target_si(&mut self, speed: f32) -> Result<(), CommandError> {
        if !is_finite(speed) {
            return Err(CommandError::NotFinite);
        }
        let limit = 0.9 * self.cfg.max_speed;
        let s = if speed > limit {
            limit
        } else if speed < -limit {
            -limit
        } else {
            speed
        };
        self.set_speed_target(to_q24(s / self.bases.speed));
        Ok(())
    }

    /// Converts SI samples to per unit, runs [`FixedDrive::step`] and converts the duties
    /// back. A non-finite sample (only possible at this boundary) faults the drive with
    /// `NonFiniteInput`, as the f32 drive does.
    pub fn step_si(&mut self, inp: &DriveInputs) -> PwmOutput {
        let [a, b, c] = inp.phase_currents;
        let finite = is_finite(a) && is_finite(b) && is_finite(c) && is_finite(inp.dc_bus);
        if !finite {
            return if self.sup.state() == DriveState::Fault {
                PwmOutput::OFF
            } else {
                self.enter_fault(FaultReason::NonFiniteInput);
                PwmOutput::OFF
            };
        }
        let ib = 1.0 / self.bases.current;
        let out = self.step(&FixedInputs {
            phase_currents: [to_q24(a * ib), to_q24(b * ib), to_q24(c * ib)],
            dc_bus: to_q24(inp.dc_bus / self.bases.voltage),
        });
        if !out.enabled {
            return PwmOutput::OFF;
        }
        let [da, db, dc] = out.duties;
        let k = 1.0 / 32768.0;
        PwmOutput {
            duties: [da as f32 * k, db as f32 * k, dc as f32 * k],
            enabled: true,
        }
    }

    /// The last step's telemetry in SI units (boundary conversion).
    pub fn telemetry_si(&self) -> DriveTelemetry {
        let t = &self.telemetry;
        let b = &self.bases;
        let dq = |v: FixedDq, base: f32| Dq {
            d: from_q24(v.d) * base,
            q: from_q24(v.q) * base,
        };
        DriveTelemetry {
            speed_reference: from_q24(t.speed_reference) * b.speed,
            speed_estimate: from_q24(t.speed_estimate) * b.speed,
            load_torque_estimate: from_q24(t.load_torque_estimate) * b.torque,
            torque_estimate: from_q24(t.torque_estimate) * b.torque,
            current: dq(t.current, b.current),
            current_reference: dq(t.current_reference, b.current),
            voltage: dq(t.voltage, b.voltage),
            rotor_flux: from_q24(t.rotor_flux) * b.flux,
            stator_resistance_estimate: from_q24(t.stator_resistance_estimate) * b.resistance(),
            angle: angle_to_rad(t.angle),
            stator_frequency: from_q24(t.stator_frequency) * b.frequency,
            voltage_saturated: t.voltage_saturated,
        }
    }

    /// The q-current limit sqrt(I_max^2 - i_sd*^2), A (as the f32 drive reports it).
    pub fn torque_current_limit_si(&self) -> f32 {
        let (i_max, i_d) = (self.cfg.current_limit, self.cfg.flux_current);
        sqrt(i_max * i_max - i_d * i_d)
    }
}

/// A Q7.24 duty in [0, 1.0] as Q15 (32768 = 1.0), rounded.
#[inline(always)]
fn duty_q15(d: i32) -> u16 {
    let q = clamp(d, 0, ONE).saturating_add(1 << 8) >> 9;
    q as u16
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::design::STALL_SPEED_FRACTION;

    /// The Q7.24 literals are the design's named fractions, to the last code.
    #[test]
    fn literals_are_the_design_constants() {
        // the two irrational literals were computed from the exact values (0.98/sqrt 3 is
        // 9 492 603.5 codes, sqrt 3 is 29 058 990.9); the f32 constants land one code away
        assert_eq!(V_MAX_PER_BUS + 1, to_q24(VOLTAGE_MARGIN * INV_SQRT3));
        assert_eq!(SQRT3 - 1, to_q24(1.732_050_8));
        assert_eq!(STALL_FRACTION, to_q24(STALL_SPEED_FRACTION));
    }

    /// The fixed drive is built from the same design as the f32 drive: a setting the
    /// design rejects is rejected with the same error.
    #[test]
    fn rejects_what_the_design_rejects() {
        let mut c = DriveConfig::paper_defaults();
        c.speed_bandwidth = 900.0;
        let bases = PerUnitBases::PAPER;
        assert_eq!(
            FixedDrive::new(c, bases).err(),
            Some(FixedConfigError::Drive(DriveDesign::new(c).unwrap_err()))
        );
    }

    use proptest::prelude::*;

    fn drive() -> FixedDrive {
        FixedDrive::new(DriveConfig::paper_defaults(), PerUnitBases::PAPER).unwrap()
    }

    /// Any Q7.24 current code, with the extremes (a saturated ADC maps to them) often.
    fn any_code() -> impl Strategy<Value = i32> {
        prop_oneof![
            4 => -to_q24(1.0)..to_q24(1.0),
            1 => Just(i32::MAX),
            1 => Just(i32::MIN),
            1 => any::<i32>(),
        ]
    }

    fn any_bus_code() -> impl Strategy<Value = i32> {
        prop_oneof![
            4 => to_q24(0.45)..to_q24(1.05),
            1 => any::<i32>(),
        ]
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]
        /// The fixed-point twin of the f32 drive's `never_emits_bad_duty`: whatever the
        /// samples, the duties are in 0 ..= 32768 (Q15 of 1.0), a disabled output is the
        /// neutral 16384, a fault keeps the switches off, and an over-range current faults.
        #[test]
        fn never_emits_bad_duty(
            samples in proptest::collection::vec((any_code(), any_code(), any_code(), any_bus_code()), 1..400),
            target in -to_q24(0.2)..to_q24(0.2),
        ) {
            let mut d = drive();
            d.set_speed_target(target);
            d.start().unwrap();
            let trip = to_q24(DriveConfig::paper_defaults().overcurrent_trip / PerUnitBases::PAPER.current);
            for (a, b, c, bus) in samples {
                let was = d.state();
                let out = d.step(&FixedInputs { phase_currents: [a, b, c], dc_bus: bus });
                prop_assert!(out.duties.iter().all(|&x| x <= 32768));
                if !out.enabled { prop_assert_eq!(out.duties, [16384; 3]); }
                if d.state() == DriveState::Fault { prop_assert!(!out.enabled); }
                let over = a.saturating_abs() > trip || b.saturating_abs() > trip
                    || a.saturating_add(b).saturating_abs() > trip;
                if over && was != DriveState::Fault {
                    prop_assert_eq!(d.fault(), Some(FaultReason::OverCurrent));
                    prop_assert_eq!(d.state(), DriveState::Fault);
                }
            }
        }
    }
}
