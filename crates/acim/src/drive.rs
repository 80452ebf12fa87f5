//! The sensorless IFOC drive: one type that owns the blocks and runs one control step,
//! phase currents and DC bus in, PWM duties out (paper Fig. 1 and 5).
//!
//! ## The cascade, each step (order matters)
//!
//! 1. Fault checks on the raw inputs (non-finite, over-current, bus limits): a fault turns
//!    all switches off in this same step.
//! 2. Clarke (two or three currents) and Park at the frame angle theta_s\[k\].
//! 3. Reduced-order observer (eq. 12) with the voltage applied over the past period and the
//!    frame frequency: i_sq_hat, speed Omega_hat, load T_L_hat.
//! 4. Stator-resistance estimator (eq. 19-20, corrected sign), feeding Rs_hat to the observer
//!    (through Rseq) and to the current controllers' feed-forward.
//! 5. Flux model (eq. 13), slip law and frame angle (eq. 8) with p Omega_hat: sensorless.
//! 6. Speed reference ramp, speed PI -> i_sq*, limited so that |i_s| <= I_max with d-axis
//!    priority; flux reference -> i_sd*.
//! 7. d/q current PIs with decoupling feed-forward (eq. 9a, 9b), voltage limited to the
//!    linear range of the modulator (d-axis priority).
//! 8. Inverse Park at theta_s advanced by the computation and PWM delay, then SVPWM with bus
//!    and dead-time compensation.
//!
//! ## States
//!
//! `Idle -> Magnetizing -> Running`, `Idle -> OpenLoop` (V/f commissioning), any -> `Fault`.
//! Magnetizing builds the flux at zero torque with the frame held (the observer assumes a
//! settled flux, paper section 4) until the model flux is within tolerance of its reference.
//! `Fault` is left only by [`Drive::reset_fault`], to `Idle`.
//!
//! ## Beyond the paper: orientation correction
//!
//! The paper's orientation mode s^2 + s/tau_r + w_s w_slip = 0 (x = lambda_d - lambda_hat,
//! y = lambda_q) is neutral at zero torque and unstable in regeneration. The steady d-axis
//! residual r_d = (Rs - Rs_hat) i_sd - w_s y, which the eq. (20) current model already
//! integrates (its error is r_d/Rs_hat), drives a frame-frequency correction
//! dw = -k sign(w_s) r_d / lambda_ref. The mode becomes
//! s^2 + s(1/tau_r + k|w_s|) + k|w_s|/tau_r + w_s w_slip = 0, stable in regeneration for
//! k > tau_r |w_slip|. It fades in between `orientation_fade` (no information at w_s = 0),
//! and Rs adapts only below `rs_max_frequency`, where the orientation part of r_d
//! vanishes. `orientation_gain = 0` is the paper's scheme. Derivation, the measured
//! stability map and before/after figures: `docs/orientation-stability.md`.
//!
//! ## Timing convention
//!
//! Duties computed at step k are applied over the next PWM period (k+1 .. k+2), as with
//! preloaded compare registers; the voltage the plant saw over (k .. k+1) is the command of
//! step k-1, which is what the observer and the Rs estimator use.

use crate::flux::{FluxModel, FluxModelConfig};
use crate::frames::{
    clarke_three, clarke_two, inverse_clarke, inverse_park, park, AlphaBeta, Dq, FastSinCos,
    SinCos, SinCosValue,
};
use crate::math::{clamp, is_finite, sqrt, wrap_angle_step};
use crate::observer::{
    ObserverConfig, ObserverDesignError, ObserverInputs, ObserverPoles, ReducedOrderObserver,
};
use crate::params::{self, MachineParams};
use crate::pi::{PiConfig, PiController};
use crate::rs_estimator::{RsEstimator, RsEstimatorConfig, RsEstimatorInputs};
use crate::svpwm::{linear_limit, modulate, modulate_with_inverse, SvpwmConfig};

/// How many phase currents are measured.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum CurrentSensing {
    /// Phases a and b measured; c = -a - b.
    TwoPhase,
    /// All three measured; the zero-sequence part is rejected.
    ThreePhase,
}

/// Open-loop V/f commissioning settings.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct VfConfig {
    /// Voltage per electrical frequency, V peak per rad/s (230 V rms line at 50 Hz:
    /// 187.8 V / 314.16 rad/s = 0.598).
    pub volts_per_rad_s: f32,
    /// Low-frequency boost added to the voltage magnitude, V peak.
    pub boost: f32,
}

/// Complete drive configuration (all user-facing settings; nothing here changes at run
/// time). Units SI, speeds mechanical rad/s.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DriveConfig {
    /// The controller's machine model (may differ from the real machine).
    pub machine: MachineParams,
    /// Control and PWM period, s.
    pub control_period: f32,
    /// d-axis (flux) current reference i_sd*, A peak.
    pub flux_current: f32,
    /// Stator current vector limit I_max, A peak.
    pub current_limit: f32,
    /// Phase current trip level, A (any phase above it faults).
    pub overcurrent_trip: f32,
    /// Lowest DC-bus voltage while active, V.
    pub dc_bus_min: f32,
    /// Highest DC-bus voltage, V.
    pub dc_bus_max: f32,
    /// Over-speed trip on the estimated speed, rad/s.
    pub max_speed: f32,
    /// Speed reference slew rate (trapezoid ramps), rad/s^2.
    pub speed_ramp: f32,
    /// Current-loop bandwidth, rad/s.
    pub current_bandwidth: f32,
    /// Speed-loop bandwidth, rad/s.
    pub speed_bandwidth: f32,
    /// Observer poles (rates, rad/s).
    pub observer_poles: ObserverPoles,
    /// Whether the stator-resistance estimator adapts.
    pub rs_estimation: bool,
    /// Initial stator-resistance estimate R0, ohm (eq. 19).
    pub rs_initial: f32,
    /// Convergence time constant of the Rs estimator, s.
    pub rs_convergence_time: f32,
    /// Rs adapts only below this |w_s|, rad/s electrical: there the d-axis residual is
    /// dominated by the resistance error (its orientation part grows with w_s).
    pub rs_max_frequency: f32,
    /// With Rs estimation on, magnetizing also waits (at standstill, where the d-axis
    /// residual is purely the resistance error) until the Rs estimate has settled, for at
    /// most this long, s.
    pub rs_identification_timeout: f32,
    /// Orientation-correction gain k (dimensionless, 0 = the paper's scheme unchanged):
    /// the frame frequency gets -k sign(w_s) r_d / lambda_ref. Regeneration is stable for
    /// k > tau_r |w_slip| (see module docs).
    pub orientation_gain: f32,
    /// The correction fades in between these |w_s|, rad/s electrical (lower, upper).
    pub orientation_fade: (f32, f32),
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
    /// Flux within this fraction of its reference counts as settled.
    pub flux_tolerance: f32,
    /// Delay between sampling and the centre of the period the voltage is applied in, in
    /// control periods (1.5 for preloaded compare registers).
    pub delay_periods: f32,
    /// Fault when the speed PI has been at its limit with |Omega_hat| below 10 % of the
    /// reference for this long, s (locked rotor / stall).
    pub stall_time: f32,
    /// Largest plausible |T_L_hat|, N m (beyond it: estimator out of range).
    pub max_load_torque_estimate: f32,
    /// V/f mode settings.
    pub vf: VfConfig,
}

impl DriveConfig {
    /// The project's documented defaults for the paper's machine (Table 1): 5 kHz, 1.5 A
    /// flux current, 4.67 A limit, 325 V bus, 1.5 us dead time.
    pub fn paper_defaults() -> Self {
        let machine = MachineParams::paper_table1();
        Self {
            machine,
            control_period: params::DEFAULT_CONTROL_PERIOD,
            flux_current: params::DEFAULT_FLUX_CURRENT,
            current_limit: params::DEFAULT_CURRENT_LIMIT,
            overcurrent_trip: 8.0,
            dc_bus_min: 200.0,
            dc_bus_max: 400.0,
            max_speed: 2000.0 * crate::math::RPM_TO_RAD_S,
            speed_ramp: 500.0 * crate::math::RPM_TO_RAD_S,
            current_bandwidth: 1000.0,
            speed_bandwidth: 25.0,
            observer_poles: ObserverPoles::DEFAULT,
            rs_estimation: false,
            rs_initial: machine.stator_resistance(),
            rs_convergence_time: 0.2,
            rs_max_frequency: 2.0 * core::f32::consts::PI * 1.5,
            rs_identification_timeout: 1.5,
            orientation_gain: 2.0,
            orientation_fade: (
                2.0 * core::f32::consts::PI * 0.5,
                2.0 * core::f32::consts::PI * 1.5,
            ),
            dead_time: 1.5e-6,
            device_drop: 1.0,
            dead_time_current_band: 0.05,
            current_sensing: CurrentSensing::TwoPhase,
            flux_tolerance: 0.02,
            delay_periods: 1.5,
            stall_time: 1.0,
            max_load_torque_estimate: 15.0,
            vf: VfConfig {
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
    /// The named field is not finite and positive (or not in its documented range).
    OutOfRange(&'static str),
    /// The observer design failed.
    Observer(ObserverDesignError),
}

impl core::fmt::Display for ConfigError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            ConfigError::OutOfRange(name) => write!(f, "drive config: {name} out of range"),
            ConfigError::Observer(e) => write!(f, "observer design: {e:?}"),
        }
    }
}

/// Operating state of the drive.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum DriveState {
    /// Switches off, waiting for a start command.
    Idle,
    /// Building the rotor flux at zero torque, frame held.
    Magnetizing,
    /// Sensorless speed control.
    Running,
    /// Open-loop V/f (commissioning).
    OpenLoop,
    /// Switches off after a fault, until [`Drive::reset_fault`].
    Fault,
}

impl DriveState {
    /// Small integer code for logs and CSV files: 0 idle, 1 magnetizing, 2 running,
    /// 3 open loop, 4 fault.
    pub fn code(self) -> u8 {
        match self {
            DriveState::Idle => 0,
            DriveState::Magnetizing => 1,
            DriveState::Running => 2,
            DriveState::OpenLoop => 3,
            DriveState::Fault => 4,
        }
    }
}

/// Why the drive faulted.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum FaultReason {
    /// A phase current exceeded the trip level (or an ADC saturated).
    OverCurrent,
    /// DC bus above its maximum (e.g. regenerative braking without a chopper).
    DcBusOverVoltage,
    /// DC bus below its minimum while active.
    DcBusUnderVoltage,
    /// Estimated speed beyond the over-speed limit.
    OverSpeed,
    /// A current or bus sample was NaN or infinite.
    NonFiniteInput,
    /// An estimator left its plausible range (Rs at a clamp bound, observer non-finite or
    /// load estimate implausible).
    EstimatorOutOfRange,
    /// The hardware break input (gate-driver fault, external over-current) fired.
    HardwareBreak,
    /// The control step did not finish before the next conversion.
    DeadlineMissed,
    /// Torque at its limit with no speed for `stall_time`, or a load estimate beyond the
    /// plausible range while the torque is at its limit: locked rotor or overload.
    Stall,
}

/// Commands refused by the drive.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum CommandError {
    /// The command does not apply in the present state (e.g. start while faulted).
    WrongState(DriveState),
    /// The value is not finite.
    NotFinite,
    /// The value is outside its documented range.
    OutOfRange,
}

/// The drive's state machine and fault latch, shared by the f32 [`Drive`] and the
/// fixed-point drive so that both obey the same commands: start only from `Idle`, stop to
/// `Idle` unless faulted, the first fault reason latched until a deliberate reset.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Supervisor {
    state: DriveState,
    fault: Option<FaultReason>,
}

impl Default for Supervisor {
    fn default() -> Self {
        Self::new()
    }
}

impl Supervisor {
    /// Idle, no fault.
    pub const fn new() -> Self {
        Self {
            state: DriveState::Idle,
            fault: None,
        }
    }
    /// Present state.
    #[inline(always)]
    pub fn state(&self) -> DriveState {
        self.state
    }
    /// The latched fault, if any.
    pub fn fault(&self) -> Option<FaultReason> {
        self.fault
    }
    /// Idle -> `to` (`Magnetizing` or `OpenLoop`); any other state refuses.
    pub fn start(&mut self, to: DriveState) -> Result<(), CommandError> {
        if self.state != DriveState::Idle {
            return Err(CommandError::WrongState(self.state));
        }
        self.state = to;
        Ok(())
    }
    /// Any active state -> Idle; a faulted drive stays faulted.
    pub fn stop(&mut self) {
        if self.state != DriveState::Fault {
            self.state = DriveState::Idle;
        }
    }
    /// Fault -> Idle, clearing the latched reason.
    pub fn reset_fault(&mut self) -> Result<(), CommandError> {
        if self.state != DriveState::Fault {
            return Err(CommandError::WrongState(self.state));
        }
        self.fault = None;
        self.state = DriveState::Idle;
        Ok(())
    }
    /// Enters Fault; the first reason is kept.
    pub fn trip(&mut self, reason: FaultReason) {
        self.state = DriveState::Fault;
        if self.fault.is_none() {
            self.fault = Some(reason);
        }
    }
    /// Magnetizing -> Running (flux settled).
    pub fn magnetized(&mut self) {
        if self.state == DriveState::Magnetizing {
            self.state = DriveState::Running;
        }
    }
}

/// Samples of one control step.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct DriveInputs {
    /// Phase currents a, b, c (A); with two-phase sensing c is ignored.
    pub phase_currents: [f32; 3],
    /// DC-bus voltage, V.
    pub dc_bus: f32,
}

/// PWM command of one step.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PwmOutput {
    /// High-side duties of phases a, b, c in [0, 1] (0.5 when disabled).
    pub duties: [f32; 3],
    /// False: all six switches off (timer main output disabled).
    pub enabled: bool,
}

impl PwmOutput {
    /// All switches off.
    pub const OFF: Self = Self {
        duties: [0.5; 3],
        enabled: false,
    };
}

/// What the last step computed, for telemetry and evaluation.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct DriveTelemetry {
    /// Ramped speed reference, rad/s.
    pub speed_reference: f32,
    /// Estimated speed Omega_hat, rad/s.
    pub speed_estimate: f32,
    /// Estimated load torque T_L_hat, N m.
    pub load_torque_estimate: f32,
    /// Estimated electromagnetic torque 1.5 p lambda_r i_sq, N m.
    pub torque_estimate: f32,
    /// Measured dq currents, A.
    pub current: Dq,
    /// dq current references, A.
    pub current_reference: Dq,
    /// dq voltage command, V.
    pub voltage: Dq,
    /// Model rotor flux lambda_r, Wb.
    pub rotor_flux: f32,
    /// Stator-resistance estimate, ohm.
    pub stator_resistance_estimate: f32,
    /// Frame angle theta_s used for this step's samples (Park), rad electrical.
    pub angle: f32,
    /// Frame frequency w_s, rad/s electrical.
    pub stator_frequency: f32,
    /// Whether the modulator limited the voltage.
    pub voltage_saturated: bool,
}

/// Regions of the control step, reported to a [`StepProbe`] (cycle benchmarks).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum StepRegion {
    /// Checks on the raw samples.
    FaultChecks,
    /// sin/cos of the frame angle, Clarke and Park.
    ClarkePark,
    /// Reduced-order observer (eq. 12).
    ObserverReduced,
    /// Stator-resistance estimator (eq. 19-20) and its residual filter.
    RsEstimator,
    /// Orientation correction, flux model, slip law and angle (eq. 13, 8).
    FluxSlip,
    /// Speed ramp, speed PI and stall detection.
    SpeedPi,
    /// d/q current PIs with feed-forward and voltage limit.
    CurrentPi,
    /// Inverse Park with delay compensation and SVPWM.
    Svpwm,
}

/// Instrumentation hooks around the regions of [`Drive::step_probed`]. The plain
/// [`Drive::step`] uses [`NoProbe`], whose empty hooks compile away.
pub trait StepProbe {
    /// Called just before `region` runs.
    fn begin(&mut self, region: StepRegion);
    /// Called just after `region` ran.
    fn end(&mut self, region: StepRegion);
}

/// The probe that does nothing.
#[derive(Clone, Copy, Debug, Default)]
pub struct NoProbe;

impl StepProbe for NoProbe {
    #[inline(always)]
    fn begin(&mut self, _: StepRegion) {}
    #[inline(always)]
    fn end(&mut self, _: StepRegion) {}
}

/// The sensorless IFOC drive. `S` supplies sin/cos (software by default, CORDIC on the G4).
#[derive(Clone, Debug)]
pub struct Drive<S: SinCos = FastSinCos> {
    cfg: DriveConfig,
    // precomputed configuration
    pi_d: PiConfig,
    pi_q: PiConfig,
    pi_speed: PiConfig,
    flux_cfg: FluxModelConfig,
    obs_cfg: ObserverConfig,
    rs_cfg: RsEstimatorConfig,
    pwm_cfg: SvpwmConfig,
    i_sd_ref: f32,
    i_sq_limit: f32,
    flux_reference: f32,
    settled_flux: f32,
    sigma_ls: f32,
    referred_rotor_resistance: f32,
    inv_rotor_time_constant: f32,
    pole_pairs: f32,
    torque_factor: f32,
    ramp_step: f32,
    orientation_gain_per_flux: f32,
    orientation_fade_start: f32,
    orientation_inv_fade_width: f32,
    orientation_limit: f32,
    overcurrent_trip: f32,
    stall_steps: u32,
    rs_timeout_steps: u32,
    rs_settle_steps: u32,
    implausible_limit: u32,
    residual_filter: f32,
    rs_settled_error: f32,
    // state
    sup: Supervisor,
    speed_target: f32,
    speed_reference: f32,
    speed_ctl: PiController,
    d_ctl: PiController,
    q_ctl: PiController,
    flux: FluxModel,
    observer: ReducedOrderObserver,
    rs: RsEstimator,
    applied_voltage: Dq,
    stall_counter: u32,
    implausible_steps: u32,
    magnetizing_steps: u32,
    rs_settled_steps: u32,
    filtered_residual: f32,
    vf_angle: f32,
    vf_frequency: f32,
    telemetry: DriveTelemetry,
    sincos: S,
}

fn positive(v: f32, name: &'static str) -> Result<f32, ConfigError> {
    if is_finite(v) && v > 0.0 {
        Ok(v)
    } else {
        Err(ConfigError::OutOfRange(name))
    }
}

impl Drive<FastSinCos> {
    /// A drive with the software sin/cos.
    pub fn new(cfg: DriveConfig) -> Result<Self, ConfigError> {
        Self::with_sincos(cfg, FastSinCos)
    }
}

impl<S: SinCos> Drive<S> {
    /// Validates `cfg`, precomputes every gain and reciprocal, and returns an idle drive.
    pub fn with_sincos(cfg: DriveConfig, sincos: S) -> Result<Self, ConfigError> {
        let ts = positive(cfg.control_period, "control_period")?;
        if ts > 0.01 {
            return Err(ConfigError::OutOfRange("control_period"));
        }
        let i_max = positive(cfg.current_limit, "current_limit")?;
        let i_d = positive(cfg.flux_current, "flux_current")?;
        if i_d >= i_max {
            return Err(ConfigError::OutOfRange("flux_current"));
        }
        positive(cfg.overcurrent_trip, "overcurrent_trip")?;
        if cfg.overcurrent_trip < i_max {
            return Err(ConfigError::OutOfRange("overcurrent_trip"));
        }
        positive(cfg.dc_bus_min, "dc_bus_min")?;
        positive(cfg.dc_bus_max, "dc_bus_max")?;
        if cfg.dc_bus_max <= cfg.dc_bus_min {
            return Err(ConfigError::OutOfRange("dc_bus_max"));
        }
        positive(cfg.max_speed, "max_speed")?;
        positive(cfg.speed_ramp, "speed_ramp")?;
        positive(cfg.current_bandwidth, "current_bandwidth")?;
        positive(cfg.speed_bandwidth, "speed_bandwidth")?;
        if cfg.current_bandwidth * ts > 0.5 {
            return Err(ConfigError::OutOfRange("current_bandwidth"));
        }
        if cfg.speed_bandwidth * 4.0 > cfg.current_bandwidth {
            return Err(ConfigError::OutOfRange("speed_bandwidth"));
        }
        positive(cfg.rs_initial, "rs_initial")?;
        positive(cfg.rs_convergence_time, "rs_convergence_time")?;
        if !(is_finite(cfg.dead_time) && cfg.dead_time >= 0.0 && cfg.dead_time < 0.1 * ts) {
            return Err(ConfigError::OutOfRange("dead_time"));
        }
        if !(is_finite(cfg.device_drop) && (0.0..=20.0).contains(&cfg.device_drop)) {
            return Err(ConfigError::OutOfRange("device_drop"));
        }
        positive(cfg.dead_time_current_band, "dead_time_current_band")?;
        let tol = positive(cfg.flux_tolerance, "flux_tolerance")?;
        if tol >= 0.5 {
            return Err(ConfigError::OutOfRange("flux_tolerance"));
        }
        if !(is_finite(cfg.delay_periods) && (0.0..=3.0).contains(&cfg.delay_periods)) {
            return Err(ConfigError::OutOfRange("delay_periods"));
        }
        positive(cfg.rs_max_frequency, "rs_max_frequency")?;
        positive(cfg.rs_identification_timeout, "rs_identification_timeout")?;
        if !(is_finite(cfg.orientation_gain) && (0.0..=50.0).contains(&cfg.orientation_gain)) {
            return Err(ConfigError::OutOfRange("orientation_gain"));
        }
        let (fa, fb) = cfg.orientation_fade;
        if !(is_finite(fa) && is_finite(fb) && fa >= 0.0 && fb > fa) {
            return Err(ConfigError::OutOfRange("orientation_fade"));
        }
        positive(cfg.stall_time, "stall_time")?;
        positive(cfg.max_load_torque_estimate, "max_load_torque_estimate")?;
        positive(cfg.vf.volts_per_rad_s, "vf.volts_per_rad_s")?;
        if !(is_finite(cfg.vf.boost) && cfg.vf.boost >= 0.0) {
            return Err(ConfigError::OutOfRange("vf.boost"));
        }

        let m = cfg.machine;
        let flux_reference = m.rotor_flux_for(i_d);
        let i_sq_limit = sqrt(i_max * i_max - i_d * i_d);
        let obs_cfg =
            ObserverConfig::new(&m, cfg.observer_poles, ts).map_err(ConfigError::Observer)?;
        // the voltage limit of the current PIs follows the bus at run time; these static
        // limits only bound the integrators before the first step
        let v_static = linear_limit(cfg.dc_bus_max);
        let mut rs_cfg = RsEstimatorConfig::new(&m, ts, cfg.rs_convergence_time, i_d);
        rs_cfg.adapt = cfg.rs_estimation;
        rs_cfg.max_stator_frequency = cfg.rs_max_frequency;
        Ok(Self {
            pi_d: PiConfig::current_loop(&m, cfg.current_bandwidth, ts, v_static),
            pi_q: PiConfig::current_loop(&m, cfg.current_bandwidth, ts, v_static),
            pi_speed: PiConfig::speed_loop(&m, flux_reference, cfg.speed_bandwidth, ts, i_sq_limit),
            flux_cfg: FluxModelConfig::new(&m, ts, flux_reference),
            obs_cfg,
            rs_cfg,
            pwm_cfg: SvpwmConfig::new(
                cfg.dead_time,
                ts,
                cfg.device_drop,
                cfg.dead_time_current_band,
            ),
            i_sd_ref: i_d,
            i_sq_limit,
            flux_reference,
            settled_flux: flux_reference * (1.0 - tol),
            sigma_ls: m.transient_inductance(),
            referred_rotor_resistance: m.referred_rotor_resistance(),
            inv_rotor_time_constant: 1.0 / m.rotor_time_constant(),
            pole_pairs: m.pole_pairs_f32(),
            torque_factor: 1.5 * m.pole_pairs_f32(),
            ramp_step: cfg.speed_ramp * ts,
            orientation_gain_per_flux: cfg.orientation_gain / flux_reference,
            orientation_fade_start: cfg.orientation_fade.0,
            orientation_inv_fade_width: 1.0 / (cfg.orientation_fade.1 - cfg.orientation_fade.0),
            // a correction beyond the rotor-frequency range means a wrong model: bound it
            orientation_limit: 0.25 * cfg.max_speed * m.pole_pairs_f32(),
            overcurrent_trip: cfg.overcurrent_trip,
            stall_steps: (cfg.stall_time / ts) as u32,
            rs_timeout_steps: (cfg.rs_identification_timeout / ts) as u32,
            rs_settle_steps: (0.05 / ts) as u32,
            implausible_limit: (0.02 / ts) as u32,
            // 20 ms low-pass of the d-axis current-model error
            residual_filter: (ts / 0.02).min(1.0),
            // |error| below 0.3 % of i_sd* means |Rs_hat - Rs| below about 0.3 %
            rs_settled_error: 0.003 * i_d,
            sup: Supervisor::new(),
            speed_target: 0.0,
            speed_reference: 0.0,
            speed_ctl: PiController::new(),
            d_ctl: PiController::new(),
            q_ctl: PiController::new(),
            flux: FluxModel::new(),
            observer: ReducedOrderObserver::new(),
            rs: RsEstimator::new(cfg.rs_initial),
            applied_voltage: Dq::default(),
            stall_counter: 0,
            implausible_steps: 0,
            magnetizing_steps: 0,
            rs_settled_steps: 0,
            filtered_residual: 0.0,
            vf_angle: 0.0,
            vf_frequency: 0.0,
            telemetry: DriveTelemetry {
                stator_resistance_estimate: cfg.rs_initial,
                ..DriveTelemetry::default()
            },
            sincos,
            cfg,
        })
    }

    /// The configuration the drive was built with.
    pub fn config(&self) -> &DriveConfig {
        &self.cfg
    }
    /// Present state.
    pub fn state(&self) -> DriveState {
        self.sup.state()
    }
    /// The fault that stopped the drive, if any.
    pub fn fault(&self) -> Option<FaultReason> {
        self.sup.fault()
    }
    /// Quantities computed by the last step.
    pub fn telemetry(&self) -> &DriveTelemetry {
        &self.telemetry
    }
    /// The q-current limit sqrt(I_max^2 - i_sd*^2), A.
    pub fn torque_current_limit(&self) -> f32 {
        self.i_sq_limit
    }
    /// Rotor-flux reference L_M i_sd*, Wb.
    pub fn flux_reference(&self) -> f32 {
        self.flux_reference
    }
    /// Precomputed observer design.
    pub fn observer_config(&self) -> &ObserverConfig {
        &self.obs_cfg
    }

    /// Sets the speed target (rad/s mechanical); the reference ramps to it at
    /// `speed_ramp`. Clamped to +/- 90 % of `max_speed`.
    pub fn set_speed_target(&mut self, speed: f32) -> Result<(), CommandError> {
        if !is_finite(speed) {
            return Err(CommandError::NotFinite);
        }
        let lim = 0.9 * self.cfg.max_speed;
        self.speed_target = clamp(speed, -lim, lim);
        Ok(())
    }

    /// Idle -> Magnetizing: resets every controller and estimator and starts building flux.
    pub fn start(&mut self) -> Result<(), CommandError> {
        self.sup.start(DriveState::Magnetizing)?;
        self.reset_dynamic_state();
        Ok(())
    }

    /// Idle -> OpenLoop: V/f at the electrical frequency p * speed target.
    pub fn start_open_loop(&mut self) -> Result<(), CommandError> {
        self.sup.start(DriveState::OpenLoop)?;
        self.reset_dynamic_state();
        Ok(())
    }

    /// Any active state -> Idle, switches off at once (the machine coasts). A faulted drive
    /// stays faulted.
    pub fn stop(&mut self) {
        self.sup.stop();
    }

    /// Fault -> Idle: the deliberate reset after the cause has been dealt with.
    pub fn reset_fault(&mut self) -> Result<(), CommandError> {
        self.sup.reset_fault()
    }

    /// Changes the orientation-correction gain k at run time (outside the interrupt:
    /// tuning or analysis; 0 restores the paper's scheme). Rejects non-finite or negative
    /// values and values above 50, keeping the old gain.
    pub fn set_orientation_gain(&mut self, gain: f32) -> Result<(), CommandError> {
        if !is_finite(gain) {
            return Err(CommandError::NotFinite);
        }
        if !(0.0..=50.0).contains(&gain) {
            return Err(CommandError::OutOfRange);
        }
        self.cfg.orientation_gain = gain;
        self.orientation_gain_per_flux = gain / self.flux_reference;
        Ok(())
    }

    /// Forces a fault from outside (e.g. the hardware break input or a missed deadline).
    pub fn trip(&mut self, reason: FaultReason) -> PwmOutput {
        self.enter_fault(reason)
    }

    fn reset_dynamic_state(&mut self) {
        self.speed_reference = 0.0;
        self.speed_ctl.reset();
        self.d_ctl.reset();
        self.q_ctl.reset();
        self.flux = FluxModel::new();
        self.observer = ReducedOrderObserver::new();
        self.rs = RsEstimator::new(self.rs.stator_resistance_estimate);
        self.applied_voltage = Dq::default();
        self.stall_counter = 0;
        self.implausible_steps = 0;
        self.magnetizing_steps = 0;
        self.rs_settled_steps = 0;
        self.filtered_residual = 0.0;
        self.vf_angle = 0.0;
        self.vf_frequency = 0.0;
    }

    fn enter_fault(&mut self, reason: FaultReason) -> PwmOutput {
        self.sup.trip(reason);
        self.applied_voltage = Dq::default();
        PwmOutput::OFF
    }

    /// Checks on the raw samples, before anything uses them.
    fn check_inputs(&self, inp: &DriveInputs) -> Option<FaultReason> {
        let [a, b, c_meas] = inp.phase_currents;
        let c = match self.cfg.current_sensing {
            CurrentSensing::TwoPhase => -a - b,
            CurrentSensing::ThreePhase => c_meas,
        };
        // fast path: five comparisons, each false for NaN, so a good sample costs only
        // these; the reason of a bad one is sorted out below
        let trip = self.overcurrent_trip;
        if a.abs() <= trip
            && b.abs() <= trip
            && c.abs() <= trip
            && inp.dc_bus <= self.cfg.dc_bus_max
            && inp.dc_bus >= self.cfg.dc_bus_min
        {
            return None;
        }
        self.classify_bad_inputs(a, b, c, inp.dc_bus)
    }

    #[cold]
    #[inline(never)]
    fn classify_bad_inputs(&self, a: f32, b: f32, c: f32, dc_bus: f32) -> Option<FaultReason> {
        let inp = DriveInputs {
            phase_currents: [a, b, c],
            dc_bus,
        };
        if !(is_finite(a) && is_finite(b) && is_finite(c) && is_finite(inp.dc_bus)) {
            return Some(FaultReason::NonFiniteInput);
        }
        let trip = self.overcurrent_trip;
        if a.abs() > trip || b.abs() > trip || c.abs() > trip {
            return Some(FaultReason::OverCurrent);
        }
        if inp.dc_bus > self.cfg.dc_bus_max {
            return Some(FaultReason::DcBusOverVoltage);
        }
        if inp.dc_bus < self.cfg.dc_bus_min {
            return Some(FaultReason::DcBusUnderVoltage);
        }
        None
    }

    /// One control step: samples in, PWM command out. Never panics and never returns a
    /// non-finite or out-of-range duty: bad input faults the drive (switches off) instead.
    #[inline]
    pub fn step(&mut self, inp: &DriveInputs) -> PwmOutput {
        self.step_probed(inp, &mut NoProbe)
    }

    /// [`Drive::step`] with `probe` called around each [`StepRegion`] of a running step
    /// (the regions do not cover the state machine's bookkeeping, the estimator
    /// plausibility checks and the telemetry record, which the whole step includes).
    #[inline(always)]
    pub fn step_probed<P: StepProbe>(&mut self, inp: &DriveInputs, probe: &mut P) -> PwmOutput {
        match self.sup.state() {
            DriveState::Fault => return PwmOutput::OFF,
            DriveState::Idle => {
                // a non-finite or over-current sample while idle is still a fault; bus
                // limits apply only when the drive is about to switch
                return match self.check_inputs(inp) {
                    Some(r @ (FaultReason::NonFiniteInput | FaultReason::OverCurrent)) => {
                        self.enter_fault(r)
                    }
                    _ => PwmOutput::OFF,
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
        if self.sup.state() == DriveState::OpenLoop {
            let (i_ab, phase_currents) = match self.cfg.current_sensing {
                CurrentSensing::TwoPhase => (clarke_two(a, b), [a, b, -a - b]),
                CurrentSensing::ThreePhase => (clarke_three(a, b, c), [a, b, c]),
            };
            return self.step_open_loop(i_ab, inp.dc_bus, phase_currents);
        }

        probe.begin(StepRegion::ClarkePark);
        let i_ab = match self.cfg.current_sensing {
            CurrentSensing::TwoPhase => clarke_two(a, b),
            CurrentSensing::ThreePhase => clarke_three(a, b, c),
        };
        let ts = self.cfg.control_period;
        let sample_angle = self.flux.angle;
        let sc = self.sincos.sin_cos(sample_angle);
        let i = park(i_ab, sc);
        probe.end(StepRegion::ClarkePark);
        let magnetizing = self.sup.state() == DriveState::Magnetizing;

        // 3. observer (eq. 12), with the voltage applied over the past period
        probe.begin(StepRegion::ObserverReduced);
        let rseq = self.rs.stator_resistance_estimate + self.referred_rotor_resistance;
        if !magnetizing {
            self.observer.update(
                &self.obs_cfg,
                &ObserverInputs {
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

        // 4. stator resistance (eq. 19-20): the current model of eq. (20) runs every step
        // (its error is the d-axis residual), the resistance adapts only inside its gate
        probe.begin(StepRegion::RsEstimator);
        let flux_settled = self.flux.rotor_flux >= self.settled_flux;
        let ws_prev = self.flux.stator_frequency;
        self.rs.update(
            &self.rs_cfg,
            &RsEstimatorInputs {
                i_sd: i.d,
                i_sq: i.q,
                v_sd: self.applied_voltage.d,
                stator_frequency: ws_prev,
                flux_settled,
            },
        );
        let rs_hat = self.rs.stator_resistance_estimate;
        self.filtered_residual +=
            self.residual_filter * (self.rs.current_error - self.filtered_residual);
        probe.end(StepRegion::RsEstimator);

        probe.begin(StepRegion::FluxSlip);
        // orientation correction (beyond the paper, see module docs): in field orientation
        // the steady d-axis residual is r_d = Rs_hat e_d = -w_s lambda_q, so
        // dw = -k sign(w_s) r_d / lambda_ref turns the frame toward the flux; it fades in
        // above the Rs-estimation band, where r_d is dominated by orientation.
        let mut correction = 0.0;
        if !magnetizing && flux_settled {
            let w = clamp(
                (ws_prev.abs() - self.orientation_fade_start) * self.orientation_inv_fade_width,
                0.0,
                1.0,
            );
            let r_d = rs_hat * self.rs.current_error;
            let signed = if ws_prev >= 0.0 { -r_d } else { r_d };
            correction = clamp(
                self.orientation_gain_per_flux * w * signed,
                -self.orientation_limit,
                self.orientation_limit,
            );
        }

        // 5. flux model, slip and angle (eq. 13, 8), sensorless: p Omega_hat
        self.flux.update(
            &self.flux_cfg,
            i.d,
            i.q,
            self.pole_pairs * speed_est + correction,
            magnetizing,
        );
        let ws = self.flux.stator_frequency;
        let lambda = self.flux.rotor_flux;
        probe.end(StepRegion::FluxSlip);

        // estimator plausibility: a non-finite state faults at once; an implausible load
        // estimate must persist for 20 ms (a current transient, e.g. a short, must trip on
        // over-current first), and while the torque is at its limit it means a stall
        if !(is_finite(speed_est)
            && is_finite(self.observer.load_torque_estimate)
            && is_finite(self.observer.current_estimate))
            || (self.cfg.rs_estimation && self.rs.at_bound)
        {
            return self.enter_fault(FaultReason::EstimatorOutOfRange);
        }
        self.implausible_steps =
            if self.observer.load_torque_estimate.abs() > self.cfg.max_load_torque_estimate {
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
        if speed_est.abs() > self.cfg.max_speed {
            return self.enter_fault(FaultReason::OverSpeed);
        }

        // 6. references
        probe.begin(StepRegion::SpeedPi);
        let (i_sd_ref, i_sq_ref);
        if magnetizing {
            i_sd_ref = self.i_sd_ref;
            i_sq_ref = 0.0;
            self.magnetizing_steps = self.magnetizing_steps.saturating_add(1);
            self.rs_settled_steps = if self.filtered_residual.abs() < self.rs_settled_error {
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
                self.observer.reset(i.q, 0.0, 0.0);
                self.speed_ctl.reset();
            }
        } else {
            let dv = clamp(
                self.speed_target - self.speed_reference,
                -self.ramp_step,
                self.ramp_step,
            );
            self.speed_reference += dv;
            i_sd_ref = self.i_sd_ref;
            i_sq_ref = self
                .speed_ctl
                .update(&self.pi_speed, self.speed_reference - speed_est, 0.0);
            // stall: torque at its limit while the speed stays near zero
            let stalled =
                self.speed_ctl.saturated() && speed_est.abs() < 0.1 * self.speed_reference.abs();
            self.stall_counter = if stalled { self.stall_counter + 1 } else { 0 };
            if self.stall_counter > self.stall_steps {
                return self.enter_fault(FaultReason::Stall);
            }
        }
        probe.end(StepRegion::SpeedPi);

        // 7. current PIs with decoupling feed-forward (eq. 9a, 9b)
        probe.begin(StepRegion::CurrentPi);
        // the bus was checked against dc_bus_min > 0 above: one division per step, shared
        // by the voltage limit and the modulator
        let inv_vdc = 1.0 / inp.dc_bus;
        let v_max = linear_limit(inp.dc_bus) * 0.98;
        let inv_v_max = inv_vdc * (1.0 / (0.98 * 0.577_350_26));
        let ff_d = rs_hat * i_sd_ref + self.referred_rotor_resistance * i_sd_ref
            - lambda * self.inv_rotor_time_constant
            - ws * self.sigma_ls * i_sq_ref;
        let ff_q = (rs_hat + self.referred_rotor_resistance) * i_sq_ref
            + ws * self.sigma_ls * i_sd_ref
            + self.pole_pairs * speed_est * lambda;
        let v_d = self
            .d_ctl
            .update_with_limits(&self.pi_d, i_sd_ref - i.d, ff_d, -v_max, v_max);
        // q limit on the circle |v| <= v_max with d priority, sqrt(v_max^2 - v_d^2), without
        // a square root: the Taylor bound v_max - v_d^2/(2 v_max) while |v_d| <= v_max/2
        // (at most 1 % above the circle there), the chord sqrt(3) (v_max - |v_d|) beyond
        // (inside the circle, zero when v_d is at its limit)
        let ad = v_d.abs();
        let v_q_max = if ad <= 0.5 * v_max {
            v_max - 0.5 * v_d * v_d * inv_v_max
        } else {
            1.732_050_8 * (v_max - ad)
        };
        let v_q =
            self.q_ctl
                .update_with_limits(&self.pi_q, i_sq_ref - i.q, ff_q, -v_q_max, v_q_max);
        let v = Dq { d: v_d, q: v_q };
        probe.end(StepRegion::CurrentPi);

        // 8. inverse Park at the angle the voltage will act at, then SVPWM
        probe.begin(StepRegion::Svpwm);
        let lead = ws * ts * self.cfg.delay_periods;
        let rot = small_rotation(sc, lead);
        let v_ab = inverse_park(v, rot);
        // dead-time compensation needs the current sign while the voltage acts: predict it
        // from the current reference at the same (advanced) angle, which is noise-free and
        // not 1.5 periods old like the samples
        let i_ref_abc = inverse_clarke(inverse_park(
            Dq {
                d: i_sd_ref,
                q: i_sq_ref,
            },
            rot,
        ));
        let m = modulate_with_inverse(&self.pwm_cfg, v_ab, inp.dc_bus, inv_vdc, i_ref_abc);
        probe.end(StepRegion::Svpwm);
        self.applied_voltage = v;

        self.telemetry = DriveTelemetry {
            speed_reference: self.speed_reference,
            speed_estimate: speed_est,
            load_torque_estimate: self.observer.load_torque_estimate,
            torque_estimate: self.torque_factor * lambda * i.q,
            current: i,
            current_reference: Dq {
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
        PwmOutput {
            duties: m.duties,
            enabled: true,
        }
    }

    fn step_open_loop(&mut self, i_ab: AlphaBeta, dc_bus: f32, currents: [f32; 3]) -> PwmOutput {
        let ts = self.cfg.control_period;
        let dv = clamp(
            self.speed_target - self.speed_reference,
            -self.ramp_step,
            self.ramp_step,
        );
        self.speed_reference += dv;
        self.vf_frequency = self.pole_pairs * self.speed_reference;
        let mag = clamp(
            self.cfg.vf.boost + self.cfg.vf.volts_per_rad_s * self.vf_frequency.abs(),
            0.0,
            linear_limit(dc_bus),
        );
        let sc = self.sincos.sin_cos(self.vf_angle);
        let v = Dq { d: mag, q: 0.0 };
        let v_ab = inverse_park(v, sc);
        let m = modulate(&self.pwm_cfg, v_ab, dc_bus, currents);
        self.vf_angle = wrap_angle_step(self.vf_angle + self.vf_frequency * ts);
        self.telemetry = DriveTelemetry {
            speed_reference: self.speed_reference,
            current: park(i_ab, sc),
            voltage: v,
            angle: self.vf_angle,
            stator_frequency: self.vf_frequency,
            stator_resistance_estimate: self.rs.stator_resistance_estimate,
            voltage_saturated: m.saturated,
            ..DriveTelemetry::default()
        };
        PwmOutput {
            duties: m.duties,
            enabled: true,
        }
    }
}

/// sin/cos of (theta + delta) from sin/cos of theta and a small delta (|delta| < 0.3 rad)
/// by the angle-sum formula with 3rd/4th-order series for delta (error < 2e-5 at 0.3 rad,
/// < 1e-7 at the 0.1 rad of 1500 rpm and 1.5 periods).
#[inline]
fn small_rotation(sc: SinCosValue, delta: f32) -> SinCosValue {
    let d = clamp(delta, -0.3, 0.3);
    let d2 = d * d;
    let sd = d * (1.0 - d2 * (1.0 / 6.0));
    let cd = 1.0 - d2 * (0.5 - d2 * (1.0 / 24.0));
    SinCosValue {
        sin: sc.sin * cd + sc.cos * sd,
        cos: sc.cos * cd - sc.sin * sd,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn drive() -> Drive {
        Drive::new(DriveConfig::paper_defaults()).unwrap()
    }

    fn idle_inputs() -> DriveInputs {
        DriveInputs {
            phase_currents: [0.0; 3],
            dc_bus: 325.0,
        }
    }

    #[test]
    fn config_validation_names_the_field() {
        let mut c = DriveConfig::paper_defaults();
        c.control_period = 0.0;
        assert_eq!(
            Drive::new(c).err(),
            Some(ConfigError::OutOfRange("control_period"))
        );
        let mut c = DriveConfig::paper_defaults();
        c.flux_current = 5.0;
        assert_eq!(
            Drive::new(c).err(),
            Some(ConfigError::OutOfRange("flux_current"))
        );
        let mut c = DriveConfig::paper_defaults();
        c.dc_bus_max = 100.0;
        assert_eq!(
            Drive::new(c).err(),
            Some(ConfigError::OutOfRange("dc_bus_max"))
        );
        let mut c = DriveConfig::paper_defaults();
        c.observer_poles.p1 = f32::NAN;
        assert_eq!(
            Drive::new(c).err(),
            Some(ConfigError::Observer(ObserverDesignError::PoleNotPositive))
        );
        let mut c = DriveConfig::paper_defaults();
        c.speed_bandwidth = 900.0;
        assert_eq!(
            Drive::new(c).err(),
            Some(ConfigError::OutOfRange("speed_bandwidth"))
        );
    }

    #[test]
    fn idle_keeps_switches_off_and_start_magnetizes_at_zero_torque() {
        let mut d = drive();
        assert_eq!(d.step(&idle_inputs()), PwmOutput::OFF);
        assert_eq!(d.state(), DriveState::Idle);
        d.start().unwrap();
        assert_eq!(
            d.start(),
            Err(CommandError::WrongState(DriveState::Magnetizing))
        );
        let out = d.step(&idle_inputs());
        assert!(out.enabled);
        assert_eq!(d.state(), DriveState::Magnetizing);
        assert_eq!(d.telemetry().current_reference.q, 0.0);
        assert_eq!(d.telemetry().current_reference.d, 1.5);
        // voltage on the d axis pushes current into the (held) frame
        assert!(d.telemetry().voltage.d > 0.0);
        assert_eq!(d.telemetry().angle, 0.0);
    }

    /// Synthetic inputs: feed back the commanded d current as if the machine followed it;
    /// the flux model settles and the state machine moves to Running.
    #[test]
    fn magnetizing_ends_when_flux_is_settled() {
        let mut d = drive();
        d.start().unwrap();
        let mut steps = 0;
        while d.state() == DriveState::Magnetizing && steps < 20_000 {
            d.step(&DriveInputs {
                phase_currents: [1.5, -0.75, -0.75],
                dc_bus: 325.0,
            });
            steps += 1;
        }
        assert_eq!(d.state(), DriveState::Running);
        // about ln(1/0.02) = 3.9 rotor time constants of 66.7 ms
        let t = steps as f32 * 200e-6;
        assert!((0.2..0.35).contains(&t), "magnetizing took {t} s");
    }

    #[test]
    fn faults_switch_off_in_the_same_step_and_need_a_reset() {
        let cases: [(DriveInputs, FaultReason); 5] = [
            (
                DriveInputs {
                    phase_currents: [9.0, 0.0, -9.0],
                    dc_bus: 325.0,
                },
                FaultReason::OverCurrent,
            ),
            (
                DriveInputs {
                    phase_currents: [f32::NAN, 0.0, 0.0],
                    dc_bus: 325.0,
                },
                FaultReason::NonFiniteInput,
            ),
            (
                DriveInputs {
                    phase_currents: [0.0; 3],
                    dc_bus: f32::INFINITY,
                },
                FaultReason::NonFiniteInput,
            ),
            (
                DriveInputs {
                    phase_currents: [0.0; 3],
                    dc_bus: 450.0,
                },
                FaultReason::DcBusOverVoltage,
            ),
            (
                DriveInputs {
                    phase_currents: [0.0; 3],
                    dc_bus: 150.0,
                },
                FaultReason::DcBusUnderVoltage,
            ),
        ];
        for (inp, reason) in cases {
            let mut d = drive();
            d.start().unwrap();
            assert!(d.step(&idle_inputs()).enabled);
            assert_eq!(d.step(&inp), PwmOutput::OFF);
            assert_eq!(d.state(), DriveState::Fault);
            assert_eq!(d.fault(), Some(reason));
            // stays off with good input until reset
            assert_eq!(d.step(&idle_inputs()), PwmOutput::OFF);
            assert_eq!(d.start(), Err(CommandError::WrongState(DriveState::Fault)));
            d.reset_fault().unwrap();
            assert_eq!(d.state(), DriveState::Idle);
            assert_eq!(d.fault(), None);
            d.start().unwrap();
        }
    }

    #[test]
    fn rejects_non_finite_speed_target_and_limits_it() {
        let mut d = drive();
        assert_eq!(d.set_orientation_gain(-1.0), Err(CommandError::OutOfRange));
        assert_eq!(
            d.set_orientation_gain(f32::NAN),
            Err(CommandError::NotFinite)
        );
        assert_eq!(d.set_orientation_gain(0.0), Ok(()));
        assert_eq!(d.config().orientation_gain, 0.0);
        assert_eq!(d.set_speed_target(f32::NAN), Err(CommandError::NotFinite));
        d.set_speed_target(1e6).unwrap();
        assert!(d.speed_target <= 0.9 * d.config().max_speed);
    }

    #[test]
    fn current_limit_circle_with_d_priority() {
        let d = drive();
        let iq = d.torque_current_limit();
        assert!((iq * iq + 1.5 * 1.5 - 4.67 * 4.67).abs() < 1e-3);
    }

    #[test]
    fn open_loop_vf_rotates_the_voltage() {
        let mut d = drive();
        d.set_speed_target(50.0).unwrap();
        d.start_open_loop().unwrap();
        let mut last = 0.0;
        for _ in 0..5000 {
            let out = d.step(&idle_inputs());
            assert!(out.enabled);
            assert!(out.duties.iter().all(|x| (0.0..=1.0).contains(x)));
            last = d.telemetry().stator_frequency;
        }
        // ramped to p * 50 rad/s after 50 / (500 rpm/s) = 0.95 s
        assert!((last - 100.0).abs() < 1e-3, "{last}");
        assert!((d.telemetry().voltage.d - (8.0 + 0.598 * 100.0)).abs() < 0.5);
    }

    #[test]
    fn small_rotation_matches_direct_evaluation() {
        for &th in &[0.0f32, 1.0, -2.5, 3.0] {
            for &dl in &[0.0f32, 0.01, -0.1, 0.2] {
                let r = small_rotation(FastSinCos::eval(th), dl);
                let e = FastSinCos::eval(th + dl);
                assert!((r.sin - e.sin).abs() < 2e-5 && (r.cos - e.cos).abs() < 2e-5);
            }
        }
    }

    fn any_current() -> impl Strategy<Value = f32> {
        prop_oneof![
            -12.0f32..12.0,
            Just(f32::NAN),
            Just(f32::INFINITY),
            Just(f32::NEG_INFINITY),
            Just(10.0f32), // a saturated 10 A full-scale ADC
            Just(-10.0f32),
            Just(0.0f32),
        ]
    }

    fn any_bus() -> impl Strategy<Value = f32> {
        prop_oneof![
            0.0f32..600.0,
            Just(f32::NAN),
            Just(f32::NEG_INFINITY),
            Just(325.0f32),
        ]
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(48))]
        /// Whatever the limits, the speed demand and the samples, the current reference
        /// stays inside the circle |i*| <= I_max (d axis first).
        #[test]
        fn current_reference_never_exceeds_the_limit(
            flux_current in 0.3f32..3.0,
            extra in 0.05f32..5.0,
            target in -300.0f32..300.0,
            samples in proptest::collection::vec((-6.0f32..6.0, -6.0f32..6.0), 1..300),
        ) {
            let mut c = DriveConfig::paper_defaults();
            c.flux_current = flux_current;
            c.current_limit = flux_current + extra;
            c.overcurrent_trip = 2.0 * c.current_limit + 12.0;
            c.speed_ramp = 1e6; // a step: a large target saturates the speed PI at once
            let mut d = Drive::new(c).unwrap();
            d.set_speed_target(target).unwrap();
            d.start().unwrap();
            // magnetize (frame held at 0: i_a = i_d, i_b = -i_d/2) until speed control runs
            let mut n = 0;
            while d.state() == DriveState::Magnetizing && n < 20_000 {
                let i = flux_current;
                d.step(&DriveInputs { phase_currents: [i, -0.5 * i, -0.5 * i], dc_bus: 325.0 });
                n += 1;
            }
            prop_assert_eq!(d.state(), DriveState::Running);
            let lim = c.current_limit * (1.0 + 1e-5);
            let mut at_limit = false;
            for (a, b) in samples {
                d.step(&DriveInputs { phase_currents: [a, b, -a - b], dc_bus: 325.0 });
                let r = d.telemetry().current_reference;
                let mag = (r.d * r.d + r.q * r.q).sqrt();
                prop_assert!(mag <= lim, "{r:?} vs {lim}");
                at_limit |= mag > 0.999 * c.current_limit;
            }
            // the property is exercised: large targets drive the reference to the circle
            if target.abs() > 250.0 {
                prop_assert!(at_limit);
            }
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]
        /// Whatever the samples, the duties are finite and in [0, 1], and a disabled output
        /// is the neutral 0.5; a fault keeps the switches off.
        #[test]
        fn never_emits_bad_duty(
            samples in proptest::collection::vec((any_current(), any_current(), any_current(), any_bus()), 1..400),
            target in -400.0f32..400.0,
            vf in any::<bool>(),
        ) {
            let mut d = drive();
            d.set_speed_target(target).unwrap();
            if vf { d.start_open_loop().unwrap(); } else { d.start().unwrap(); }
            for (a, b, c, bus) in samples {
                let out = d.step(&DriveInputs { phase_currents: [a, b, c], dc_bus: bus });
                prop_assert!(out.duties.iter().all(|x| x.is_finite() && (0.0..=1.0).contains(x)));
                if !out.enabled { prop_assert_eq!(out.duties, [0.5; 3]); }
                if d.state() == DriveState::Fault { prop_assert!(!out.enabled); }
                let bad = !(a.is_finite() && b.is_finite() && bus.is_finite());
                if bad { prop_assert_eq!(d.state(), DriveState::Fault); }
                let t = d.telemetry();
                prop_assert!(t.speed_estimate.is_finite() && t.rotor_flux.is_finite());
            }
        }
    }
}
