//! The closed loop: any [`Controller`] (the real `acim::Drive`, f32 or fixed point, with
//! either observer) against the `acim-plant` model, one control period at a time, seeing
//! only the sampled currents and bus voltage.
//!
//! Timing per period k (matching the firmware): the plant is sampled at the period
//! boundary (PWM centre of the low-side-on interval), the drive computes duties, and those
//! duties are applied over the next period: the plant's [`PwmPreload`] is the one timing
//! model (a switch-off acts at once).

use crate::scenario::{
    Arithmetic, ControlMode, ModulationKind, ObserverKind, Scenario, ScenarioError, Validated,
};
use acim::fixed::FixedDrive;
use acim::frames::FastSinCos;
use acim::full_order::FullOrder;
use acim::math::RAD_S_TO_RPM;
use acim::observer::ReducedOrderObserver;
use acim::{Controller, DriveDesign, Overmodulation, Svpwm};
use acim::{Drive, DriveInputs, DriveState, FaultReason};
use acim_plant::{
    BusSensorConfig, BusVoltageSensor, CurrentSensorConfig, CurrentSensors, DcLink, FaultInjector,
    FaultPlan, InductionMachine, Inverter, InverterConfig, LoadTorque, Plant, PwmMode, PwmPreload,
};
use serde::Serialize;

const SQRT_3: f32 = 1.732_050_8;

/// A modulation index at (or, by rounding, just under) the current loops' voltage limit,
/// [`acim::svpwm::VOLTAGE_MARGIN`] of the linear limit, counts as saturated.
const SATURATED_MODULATION: f32 = acim::svpwm::VOLTAGE_MARGIN * 0.999;
/// The same with overmodulation, whose limit is the six-step fundamental 2 V_dc/pi.
const SATURATED_OVERMODULATION: f32 = acim::svpwm::SIX_STEP * SQRT_3 * 0.999;

/// The CSV header: the required columns first, then extra ones.
pub const CSV_HEADER: &str = "t_s,speed_ref_rpm,speed_rpm,speed_est_rpm,load_torque_nm,load_torque_est_nm,torque_nm,i_sd_a,i_sq_a,i_sd_ref_a,i_sq_ref_a,rotor_flux_est,stator_resistance_est_ohm,v_sd_v,v_sq_v,state,dc_bus_v,rotor_flux_true,orientation_error_deg,pwm_enabled,i_phase_peak_a,current_error_a,model_residual_v,stator_frequency_hz,voltage_saturated,modulation_index,state_name,fault_reason,speed_target_limited,speed_target_rpm,i_phase_peak_switching_a,hardware_trip";

/// One recorded control step.
#[derive(Clone, Copy, Debug, Default, Serialize)]
pub struct Row {
    /// Time, s.
    pub t_s: f32,
    /// Ramped speed reference, rpm.
    pub speed_ref_rpm: f32,
    /// True speed, rpm.
    pub speed_rpm: f32,
    /// Estimated speed, rpm.
    pub speed_est_rpm: f32,
    /// True load torque, N m.
    pub load_torque_nm: f32,
    /// Estimated load torque, N m.
    pub load_torque_est_nm: f32,
    /// True electromagnetic torque, N m.
    pub torque_nm: f32,
    /// Measured i_sd in the controller's frame, A.
    pub i_sd_a: f32,
    /// Measured i_sq in the controller's frame, A.
    pub i_sq_a: f32,
    /// i_sd reference, A.
    pub i_sd_ref_a: f32,
    /// i_sq reference, A.
    pub i_sq_ref_a: f32,
    /// Model rotor flux, Wb.
    pub rotor_flux_est: f32,
    /// Rs estimate, ohm.
    pub stator_resistance_est_ohm: f32,
    /// v_sd command, V.
    pub v_sd_v: f32,
    /// v_sq command, V.
    pub v_sq_v: f32,
    /// Drive state code (0 idle, 1 magnetizing, 2 running, 3 open loop, 4 fault).
    pub state: u8,
    /// True DC bus, V.
    pub dc_bus_v: f32,
    /// True rotor flux amplitude (inverse-Gamma), Wb.
    pub rotor_flux_true: f32,
    /// Controller angle minus true flux angle, degrees electrical.
    pub orientation_error_deg: f32,
    /// PWM outputs enabled.
    pub pwm_enabled: bool,
    /// Largest |true phase current| at the sampling instant, A.
    pub i_phase_peak_a: f32,
    /// The drive's control monitor: mean |i* - i|, A.
    pub current_error_a: f32,
    /// The drive's control monitor: mean current-loop integral (model residual), V.
    pub model_residual_v: f32,
    /// The drive's stator frequency w_s / 2 pi, Hz (electrical).
    pub stator_frequency_hz: f32,
    /// Whether the voltage command is limited this step: at the current loops' limit
    /// (98 % of V_dc / sqrt 3, `acim::svpwm::VOLTAGE_MARGIN`; with overmodulation the
    /// six-step fundamental 2 V_dc/pi) or cut by the modulator (with overmodulation: the
    /// command beyond the inscribed circle, phases clamped).
    pub voltage_saturated: bool,
    /// Modulation index |v_dq| / (V_dc / sqrt 3) of the command, with the measured bus
    /// (1 = the linear limit of space-vector modulation).
    pub modulation_index: f32,
    /// The fault that stopped the drive, while it is in the fault state.
    #[serde(skip)]
    pub fault: Option<FaultReason>,
    /// The user's speed target is not what the drive runs to: beyond what it can reach
    /// (voltage, torque or bus; the reference is held at the reachable speed, the drive's
    /// telemetry), or beyond its speed limit (clamped to +/- 90 % of `max_speed`).
    pub speed_target_limited: bool,
    /// The speed target as the scenario gave it (before any clamp or ramp), rpm.
    pub speed_target_rpm: f32,
    /// Largest |true phase current| while the gates were on over the period that follows
    /// this step (checked at every integration sub-step, so it sees what the samples at
    /// the period boundary miss), A.
    pub i_phase_peak_switching_a: f32,
    /// Time over that period with the gates on and the true current above the drive's
    /// trip level, s (not a CSV column: the metrics sum it).
    #[serde(skip)]
    pub above_trip_switching_s: f32,
    /// The hardware over-current comparator has opened the gates (latched) by the end of
    /// the period that follows this step.
    pub hardware_trip: bool,
}

/// A speed target the drive clamped to its limit (`SPEED_TARGET_FRACTION` of
/// `max_speed`).
#[derive(Clone, Copy, Debug, Default, Serialize, PartialEq)]
pub struct TargetClamp {
    /// When the target was given, s.
    pub t_s: f32,
    /// The target as given, rpm.
    pub target_rpm: f32,
    /// What the drive runs to instead, rpm.
    pub limited_to_rpm: f32,
}

/// The drive state's name for a state code of [`Row::state`].
pub fn state_name(code: u8) -> &'static str {
    match code {
        0 => "idle",
        1 => "magnetizing",
        2 => "running",
        3 => "open-loop",
        4 => "fault",
        _ => "unknown",
    }
}

/// A fault reason's name as the CSV and JSON write it (its Rust variant name).
pub fn fault_name(f: FaultReason) -> String {
    format!("{f:?}")
}

impl Row {
    /// CSV line for this row (same column order as [`CSV_HEADER`]).
    pub fn csv(&self) -> String {
        format!(
            "{:.5},{:.3},{:.3},{:.3},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{:.5},{:.4},{:.3},{:.3},{},{:.2},{:.5},{:.3},{},{:.3},{:.4},{:.3},{:.4},{},{:.4},{},{},{},{:.3},{:.3},{}",
            self.t_s,
            self.speed_ref_rpm,
            self.speed_rpm,
            self.speed_est_rpm,
            self.load_torque_nm,
            self.load_torque_est_nm,
            self.torque_nm,
            self.i_sd_a,
            self.i_sq_a,
            self.i_sd_ref_a,
            self.i_sq_ref_a,
            self.rotor_flux_est,
            self.stator_resistance_est_ohm,
            self.v_sd_v,
            self.v_sq_v,
            self.state,
            self.dc_bus_v,
            self.rotor_flux_true,
            self.orientation_error_deg,
            self.pwm_enabled as u8,
            self.i_phase_peak_a,
            self.current_error_a,
            self.model_residual_v,
            self.stator_frequency_hz,
            self.voltage_saturated as u8,
            self.modulation_index,
            state_name(self.state),
            self.fault.map(fault_name).unwrap_or_default(),
            self.speed_target_limited as u8,
            self.speed_target_rpm,
            self.i_phase_peak_switching_a,
            self.hardware_trip as u8,
        )
    }
}

/// How often [`run_with_progress`] reports, control steps (0.5 s at 5 kHz).
pub const PROGRESS_EVERY: usize = 2500;

/// Result of a run: every control step and how it ended.
#[derive(Clone, Debug)]
pub struct RunResult {
    /// The scenario as run (overrides applied).
    pub scenario: Scenario,
    /// One row per control step.
    pub rows: Vec<Row>,
    /// Fault that stopped the drive, if any.
    pub fault: Option<FaultReason>,
    /// Time of the fault, s.
    pub fault_time_s: Option<f32>,
    /// Final drive state.
    pub final_state: DriveState,
    /// Whether the PWM outputs were off at the end.
    pub switches_off_at_end: bool,
    /// The flying start's speed search at its decision (absent when it did not run).
    pub search: Option<SearchRecord>,
    /// The drive configuration as run.
    pub config: acim::DriveConfig,
    /// The inverter test at start and the running tracker's correction at the end, when
    /// the drive runs either (`drive.start.inverter_identification`, `drive.trackers.inverter_tracking`).
    pub inverter_test: Option<InverterTestRecord>,
    /// The rotor-resistance adaptation at the end, when the drive runs it
    /// (`drive.trackers.rr_adaptation`).
    pub rotor_resistance: Option<RotorResistanceRecord>,
    /// The current sensors' gain correction at the end, g_a / g_b as the drive calibrated
    /// it (1: not calibrated; `drive.start.current_gain_calibration`).
    pub current_gain_correction: f32,
    /// Speed targets the drive clamped to its limit, in time order.
    pub target_clamps: Vec<TargetClamp>,
    /// The hardware over-current comparator's trip, if it fired.
    pub hardware_trip: Option<HardwareTripRecord>,
}

/// When the plant's hardware over-current comparator opened the gates.
#[derive(Serialize, Clone, Copy, Debug, PartialEq)]
pub struct HardwareTripRecord {
    /// Its level, A.
    pub level_a: f32,
    /// The true current crossed the level, s.
    pub crossing_s: f32,
    /// The gates went off, s.
    pub off_s: f32,
    /// The largest |true phase current| then, A.
    pub current_a: f32,
}

/// The rotor-resistance adaptation at the end of a run.
#[derive(Serialize, Clone, Debug, PartialEq)]
pub struct RotorResistanceRecord {
    /// R_R_hat, the referred rotor resistance the drive uses at the end, ohm.
    pub estimate_ohm: f32,
    /// The plant's referred rotor resistance at the end, ohm.
    pub true_ohm: f32,
    /// The controller's configured R_R, ohm.
    pub configured_ohm: f32,
    /// Windows that updated the estimate.
    pub updates: u32,
    /// Windows whose fit was rejected.
    pub rejected: u32,
    /// The last solved window's torque-per-inertia model error gamma, %.
    pub last_model_error_pct: f32,
    /// The last solved window's fit residual, RMS, rpm.
    pub last_fit_rms_rpm: f32,
}

/// The inverter test at start: what the drive identified.
#[derive(Serialize, Clone, Debug, PartialEq)]
pub struct InverterTestRecord {
    /// The last test's outcome (`Identified`, `Skipped`, `Rejected`, ...).
    pub outcome: String,
    /// The dead time the drive compensates at the end of the run, us (configured plus the
    /// correction of the test and of the running tracker, the configured device drop
    /// counted as known).
    pub dead_time_us: f32,
    /// Whether the running tracker could adapt the correction (`drive.trackers.inverter_tracking`
    /// with the running Rs law).
    pub tracked: bool,
    /// The plant inverter's dead time, us.
    pub true_dead_time_us: f32,
    /// The dead time the drive was configured with, us.
    pub configured_dead_time_us: f32,
}

/// The flying start's speed search at its decision.
#[derive(Serialize, Clone, Copy, Debug, PartialEq)]
pub struct SearchRecord {
    /// Time of the decision, s.
    pub t_s: f32,
    /// The speed the search measured, rpm.
    pub measured_rpm: f32,
    /// The true rotor speed at the decision, rpm.
    pub true_rpm: f32,
}

/// The scenario's plant (machine, inverter, sensors), for tools that run their own loop
/// (`examples/step_response.rs`).
pub fn build_plant_pub(sc: &Scenario, v: &Validated) -> Plant {
    build_plant(sc, v)
}

pub(crate) fn build_plant(sc: &Scenario, v: &Validated) -> Plant {
    let inv = Inverter::new(
        InverterConfig {
            dead_time: sc.inverter.dead_time_s,
            pwm_period: v.drive.loops.control_period,
            device_drop: sc.inverter.device_drop_v,
            ..InverterConfig::default()
        },
        sc.bus_v(),
    );
    let mut cs = CurrentSensorConfig::default();
    cs.adc.bits = sc.sensors.adc_bits;
    cs.adc.full_scale = v
        .board
        .map_or(sc.sensors.full_scale_a, |b| b.current_full_scale_a);
    cs.channels = v.channels;
    cs.gain_error = sc.sensors.gain_error;
    cs.offset = sc.sensors.offset_a;
    cs.noise_std = sc.sensors.noise_a;
    let mut bs = BusSensorConfig::default();
    bs.adc.bits = sc.sensors.bus_adc_bits;
    if let Some(b) = v.board {
        bs.adc.full_scale = b.bus_full_scale_v;
    }
    let mut plant = Plant::new(
        InductionMachine::new(v.plant),
        inv,
        CurrentSensors::new(cs, sc.seed),
        BusVoltageSensor::new(bs, sc.seed.wrapping_add(0x5eed)),
    );
    plant.set_substeps(sc.inverter.substeps);
    if sc.inverter.hardware_trip {
        plant.set_comparator(Some(acim_plant::ComparatorConfig {
            level: sc
                .inverter
                .hardware_trip_a
                .unwrap_or_else(|| acim::hardware_trip::hardware_trip_level(&v.drive)),
            delay: sc.inverter.hardware_trip_delay_s,
        }));
    }
    // measure the time the true current spends above the drive's trip while switching
    plant.set_watch_level(v.drive.limits.overcurrent_trip);
    if let Some(sat) = sc.saturation {
        plant
            .machine_mut()
            .set_saturation(Some(acim_plant::Saturation {
                beta: sat.beta_per_wb,
                exponent: sat.exponent,
            }));
    }
    plant.set_mode(if sc.inverter.switching {
        PwmMode::Switched
    } else {
        PwmMode::Averaged
    });
    plant
}

/// The scenario's DC link (stiff when its capacitance is 0).
pub(crate) fn build_dc_link(sc: &Scenario) -> DcLink {
    DcLink::new(
        sc.bus_v(),
        sc.dc_link.capacitance_f,
        sc.dc_link.source_resistance_ohm,
    )
    .with_ripple(sc.dc_link.ripple_fraction, sc.dc_link.ripple_hz)
}

/// The scenario's injected faults.
pub(crate) fn fault_plan(sc: &Scenario) -> FaultPlan {
    let f = &sc.faults;
    FaultPlan {
        bus_sag_at_s: f.bus_sag_at_s,
        bus_sag_to_v: f.bus_sag_to_v,
        locked_rotor_at_s: f.locked_rotor_at_s,
        phase_short_at_s: f.phase_short_at_s,
        nan_sample_at_s: f.nan_sample_at_s,
        open_phase_at_s: f.open_phase_at_s,
        open_phase: f.open_phase,
        current_sensor_stuck_at_s: f.current_sensor_stuck_at_s,
        current_sensor_stuck_channel: f.current_sensor_stuck_channel,
        current_sensor_stuck_value_a: f.current_sensor_stuck_value_a,
        current_sensors_zero_at_s: f.current_sensors_zero_at_s,
        current_sensor_offset_drift_a_per_s: f.current_sensor_offset_drift_a_per_s,
        current_sensor_offset_change_a: f.current_sensor_offset_change_a,
        current_sensor_offset_change_at_s: f.current_sensor_offset_change_at_s,
        current_sensor_offset_change_ramp_s: f.current_sensor_offset_change_ramp_s,
    }
}

pub(crate) fn wrap_deg(x: f32) -> f32 {
    let mut d = x.to_degrees() % 360.0;
    if d > 180.0 {
        d -= 360.0;
    } else if d < -180.0 {
        d += 360.0;
    }
    d
}

/// The drive under test, chosen at run time (`drive.arithmetic`, `drive.observer`): an
/// f32 drive with either speed observer, or the fixed-point drive behind its SI boundary.
/// The loop itself only sees [`Controller`].
pub fn build_drive(sc: &Scenario, v: &Validated) -> Result<Box<dyn Controller>, ScenarioError> {
    let bad = |field: &'static str| {
        move |e: acim::ConfigError| ScenarioError {
            field: field.into(),
            allowed: format!("{e}"),
        }
    };
    // unset: the configuration's choice (`estimation.observer`, resolved at validation)
    let observer = sc
        .drive
        .observer
        .unwrap_or(match v.drive.estimation.observer {
            acim::ObserverChoice::Reduced => ObserverKind::Reduced,
            acim::ObserverChoice::Flux => ObserverKind::Flux,
        });
    Ok(match (sc.drive.arithmetic, observer) {
        (Arithmetic::F32, ObserverKind::Reduced)
            if sc.drive.modulation == ModulationKind::Overmodulation =>
        {
            let design = DriveDesign::new(v.drive).map_err(bad("drive"))?;
            let d: Drive<FastSinCos, f32, ReducedOrderObserver, Overmodulation> =
                Drive::with_parts(
                    design,
                    (),
                    FastSinCos,
                    ReducedOrderObserver::new(),
                    Overmodulation,
                )
                .map_err(bad("drive"))?;
            Box::new(d)
        }
        // the drive the board runs: the observer chosen by the configuration
        // (`estimation.observer`, set from `drive.observer` at validation)
        (Arithmetic::F32, ObserverKind::Reduced | ObserverKind::Flux) => {
            Box::new(Drive::new(v.drive).map_err(bad("drive"))?)
        }
        (Arithmetic::F32, ObserverKind::FullOrder) => {
            let design = DriveDesign::new(v.drive).map_err(bad("drive"))?;
            let observer =
                FullOrder::new(&v.drive.machine, v.drive.loops.control_period).map_err(|e| {
                    ScenarioError {
                        field: "drive.observer".into(),
                        allowed: format!("a valid full-order design ({e:?})"),
                    }
                })?;
            let d: Drive<FastSinCos, f32, FullOrder> =
                Drive::with_parts(design, (), FastSinCos, observer, Svpwm).map_err(bad("drive"))?;
            Box::new(d)
        }
        (Arithmetic::Fixed, ObserverKind::Reduced) => {
            Box::new(FixedDrive::with_bases(v.drive, v.bases).map_err(bad("drive.arithmetic"))?)
        }
        (Arithmetic::Fixed, ObserverKind::FullOrder) => {
            return Err(ScenarioError {
                field: "drive.observer".into(),
                allowed: "\"full-order\" runs in f32 only".into(),
            })
        }
        (Arithmetic::Fixed, ObserverKind::Flux) => {
            return Err(ScenarioError {
                field: "drive.observer".into(),
                allowed: "\"flux\" runs in f32 only".into(),
            })
        }
    })
}

/// The time the drive is powered, switches off, before a scenario's t = 0, s: the
/// library's switches-off offset measurement ([`acim::design::OFFSET_MEASUREMENT_TIME`]),
/// which every start waits for. A real drive is
/// powered before its start command; with it a start at t = 0 switches at once, as the
/// scenarios' timelines (and the paper's figures) assume.
pub const POWER_UP_S: f32 = acim::design::OFFSET_MEASUREMENT_TIME;

/// The power-up before t = 0 ([`POWER_UP_S`]): the drive steps with the switches off on
/// the sensors' readings of the plant, which stands still in time (its rotor at the
/// scenario's initial speed, no flux, no current), so only the sensors' offsets and noise
/// reach the drive. Nothing is recorded.
pub(crate) fn power_up<C: Controller + ?Sized>(
    plant: &mut Plant,
    drive: &mut C,
    dc_link: &DcLink,
    ts: f32,
) {
    plant.set_dc_bus(dc_link.bus_voltage());
    let steps = (POWER_UP_S / ts).round() as usize;
    for _ in 0..steps {
        let meas = plant.sample();
        drive.step(&DriveInputs {
            phase_currents: meas.phase_currents,
            dc_bus: meas.dc_bus,
        });
    }
}

/// Runs a scenario to its end (or, after a fault, on with the switches off so the
/// result shows the machine coasting).
pub fn run(sc: &Scenario) -> Result<RunResult, ScenarioError> {
    run_with_progress(sc, &mut |_, _| {})
}

/// [`run`], calling `progress(done, total)` (control steps) every
/// [`PROGRESS_EVERY`] steps and once at the end.
pub fn run_with_progress(
    sc: &Scenario,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<RunResult, ScenarioError> {
    let v = sc.validate()?;
    let mut plant = build_plant(sc, &v);
    let mut drive = build_drive(sc, &v)?;
    let ts = v.drive.loops.control_period;
    let n = (sc.duration_s / ts).round() as usize;
    let mut rows = Vec::with_capacity(n);

    let mut speed_points = sc.speed_profile.clone();
    speed_points.sort_by(|a, b| a.t_s.total_cmp(&b.t_s));
    let mut load_points = sc.load_profile.clone();
    load_points.sort_by(|a, b| a.t_s.total_cmp(&b.t_s));
    let (mut si, mut li) = (0usize, 0usize);
    let mut load = LoadTorque::None;

    plant
        .machine_mut()
        .set_speed(sc.start.initial_speed_rpm * acim::math::RPM_TO_RAD_S);
    let start_step = (sc.start.at_s / ts).round() as usize;
    let saturated_modulation = match sc.drive.modulation {
        ModulationKind::Linear => SATURATED_MODULATION,
        ModulationKind::Overmodulation => SATURATED_OVERMODULATION,
    };
    let start = |drive: &mut Box<dyn Controller>| {
        match sc.drive.mode {
            ControlMode::Sensorless => drive.start(),
            ControlMode::Vf => drive.start_open_loop(),
        }
        .map_err(|e| ScenarioError {
            field: "drive.mode".into(),
            allowed: format!("{e:?}"),
        })
    };
    let mut dc_link = build_dc_link(sc);
    power_up(&mut plant, drive.as_mut(), &dc_link, ts);
    if start_step == 0 {
        start(&mut drive)?;
    }

    let mut pwm = PwmPreload::new();
    let mut faults = FaultInjector::new(fault_plan(sc));
    let mut fault_time = None;
    let mut search = None;
    let target_limit_rpm =
        acim::design::SPEED_TARGET_FRACTION * v.drive.limits.max_speed * acim::math::RAD_S_TO_RPM;
    let mut target_clamps = Vec::new();
    let mut user_target_rpm = 0.0f32;
    let plant_nominal = v.plant.data();
    let mut plant_factors = (1.0f32, 1.0f32);
    let mut hardware_trip = None;

    for k in 0..n {
        if k % PROGRESS_EVERY == 0 {
            progress(k, n);
        }
        let t = k as f32 * ts;
        if k == start_step && k > 0 {
            start(&mut drive)?;
        }
        while si < speed_points.len() && speed_points[si].t_s <= t + 0.5 * ts {
            let rpm = speed_points[si].rpm;
            let _ = drive.set_speed_target(rpm * acim::math::RPM_TO_RAD_S);
            // the drive clamps a target beyond its limit: report it, never silently
            if rpm.abs() > target_limit_rpm {
                target_clamps.push(TargetClamp {
                    t_s: speed_points[si].t_s,
                    target_rpm: rpm,
                    limited_to_rpm: rpm.clamp(-target_limit_rpm, target_limit_rpm),
                });
            }
            user_target_rpm = rpm;
            si += 1;
        }
        while li < load_points.len() && load_points[li].t_s <= t + 0.5 * ts {
            load = load_points[li].load();
            li += 1;
        }
        faults.begin_period(t, &mut plant, &mut dc_link);
        let bus_v = dc_link.bus_voltage();
        // thermal drift of the real machine (`[[plant_changes]]`)
        let factors = crate::scenario::plant_factors(&sc.plant_changes, t);
        if factors != plant_factors {
            plant_factors = factors;
            let mut d = plant_nominal;
            d.stator_resistance *= factors.0;
            d.rotor_resistance *= factors.1;
            if let Ok(p) = acim::params::MachineParams::new(d) {
                plant.machine_mut().set_params(p);
            }
        }
        // the bus of the period that starts now, which the sensor reads at its start
        plant.set_dc_bus(bus_v);

        // sample at the period boundary
        let mut meas = plant.sample();
        faults.corrupt_sample(t, &mut meas);
        let out = drive.step(&DriveInputs {
            phase_currents: meas.phase_currents,
            dc_bus: meas.dc_bus,
        });
        if search.is_none() && drive.telemetry().search_speed != 0.0 {
            search = Some(SearchRecord {
                t_s: t,
                measured_rpm: drive.telemetry().search_speed * RAD_S_TO_RPM,
                true_rpm: plant.machine().speed() * RAD_S_TO_RPM,
            });
        }
        if drive.state() == DriveState::Fault && fault_time.is_none() {
            fault_time = Some(t);
        }

        // record the state at the sampling instant
        let tel = drive.telemetry();
        let modulation = if meas.dc_bus > 0.0 {
            (tel.voltage.d * tel.voltage.d + tel.voltage.q * tel.voltage.q).sqrt() * SQRT_3
                / meas.dc_bus
        } else {
            0.0
        };
        let m = plant.machine();
        let lam = m.lambda_r();
        let flux_angle = lam.beta.atan2(lam.alpha);
        rows.push(Row {
            t_s: t,
            speed_ref_rpm: tel.speed_reference * RAD_S_TO_RPM,
            speed_rpm: m.speed() * RAD_S_TO_RPM,
            speed_est_rpm: tel.speed_estimate * RAD_S_TO_RPM,
            load_torque_nm: load.torque(m.speed()),
            load_torque_est_nm: tel.load_torque_estimate,
            torque_nm: m.torque(),
            i_sd_a: tel.current.d,
            i_sq_a: tel.current.q,
            i_sd_ref_a: tel.current_reference.d,
            i_sq_ref_a: tel.current_reference.q,
            rotor_flux_est: tel.rotor_flux,
            stator_resistance_est_ohm: tel.stator_resistance_estimate,
            v_sd_v: tel.voltage.d,
            v_sq_v: tel.voltage.q,
            state: drive.state().code(),
            dc_bus_v: bus_v,
            rotor_flux_true: (lam.alpha * lam.alpha + lam.beta * lam.beta).sqrt(),
            orientation_error_deg: if drive.state() == DriveState::Running {
                wrap_deg(tel.angle - flux_angle)
            } else {
                0.0
            },
            pwm_enabled: out.enabled,
            i_phase_peak_a: m
                .phase_currents()
                .iter()
                .fold(0.0f32, |a, x| a.max(x.abs())),
            current_error_a: tel.current_error,
            model_residual_v: tel.model_residual,
            stator_frequency_hz: tel.stator_frequency * (1.0 / acim::math::TAU),
            voltage_saturated: tel.voltage_saturated || modulation >= saturated_modulation,
            modulation_index: modulation,
            fault: if drive.state() == DriveState::Fault {
                drive.fault()
            } else {
                None
            },
            speed_target_limited: tel.speed_target_limited
                || user_target_rpm.abs() > target_limit_rpm,
            speed_target_rpm: user_target_rpm,
            // filled in once the period has run
            i_phase_peak_switching_a: 0.0,
            above_trip_switching_s: 0.0,
            hardware_trip: false,
        });

        // apply: a switch-off acts at once, new duties from the next period
        let applied = faults.inverter_command(pwm.advance(out));
        plant.set_dc_bus(bus_v);
        plant.run_pwm_period(applied, load);
        dc_link.step(plant.last_period().dc_current, ts);
        let report = plant.last_period();
        if let Some(row) = rows.last_mut() {
            row.i_phase_peak_switching_a = report.switching_peak_a;
            row.above_trip_switching_s = report.switching_above_watch_s;
            row.hardware_trip = plant.comparator_trip().is_some();
        }
        // the comparator fired in this period: the break input tells the drive (the
        // firmware reads the timer's break flag; the trip path is the same)
        if let (None, Some(trip)) = (hardware_trip, plant.comparator_trip()) {
            hardware_trip = Some(HardwareTripRecord {
                level_a: plant.comparator().map_or(0.0, |c| c.level),
                crossing_s: t + trip.crossing_s,
                off_s: t + trip.off_s,
                current_a: trip.current_a,
            });
            drive.trip(FaultReason::HardwareBreak);
        }
    }
    progress(n, n);
    Ok(RunResult {
        scenario: sc.clone(),
        rows,
        fault: drive.fault(),
        fault_time_s: fault_time,
        final_state: drive.state(),
        switches_off_at_end: !pwm.preloaded().enabled,
        search,
        config: v.drive,
        inverter_test: (v.drive.start.inverter_identification
            || v.drive.trackers.inverter_tracking)
            .then(|| {
                let (outcome, dead_time) = drive.inverter_test();
                InverterTestRecord {
                    outcome: format!("{outcome:?}"),
                    dead_time_us: dead_time * 1e6,
                    true_dead_time_us: sc.inverter.dead_time_s * 1e6,
                    configured_dead_time_us: v.drive.inverter.dead_time * 1e6,
                    tracked: v.drive.trackers.inverter_tracking
                        && v.drive.estimation.rs_estimation
                        && v.drive.estimation.rs_estimation_mode == acim::RsEstimationMode::Running,
                }
            }),
        current_gain_correction: drive.current_gain_correction(),
        target_clamps,
        hardware_trip,
        rotor_resistance: v.drive.trackers.rr_adaptation.then(|| {
            let r = drive.rotor_resistance();
            RotorResistanceRecord {
                estimate_ohm: r.estimate,
                true_ohm: plant_referred_rotor_resistance_at_end(sc),
                configured_ohm: v.drive.machine.referred_rotor_resistance(),
                updates: r.updates,
                rejected: r.rejected,
                last_model_error_pct: 100.0 * r.last_model_error,
                last_fit_rms_rpm: r.last_fit_rms * 30.0 / core::f32::consts::PI,
            }
        }),
    })
}

/// The plant's referred rotor resistance `(Lm/Lr)^2 Rr` at the scenario's end, ohm.
fn plant_referred_rotor_resistance_at_end(sc: &Scenario) -> f32 {
    let p = &sc.plant;
    let (_, rr) = crate::scenario::plant_factors(&sc.plant_changes, sc.duration_s);
    (p.lm_h / p.lr_h) * (p.lm_h / p.lr_h) * p.rr_ohm * rr
}
