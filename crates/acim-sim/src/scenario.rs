//! Scenario description: plant, controller model, drive settings, inverter, sensors, DC
//! link, speed and load profiles, injected faults and metric windows. Read from TOML
//! (`scenarios/example.toml` documents every field) or taken from the built-in list.

use acim::{MachineData, MachineParams};
use acim_plant::{CurrentChannels, LoadTorque};
use serde::{Deserialize, Serialize};

/// An error in a scenario, naming the field and the allowed range.
#[derive(Debug, Clone, PartialEq)]
pub struct ScenarioError {
    /// Dotted field path, e.g. `plant.rs_ohm`.
    pub field: String,
    /// What is allowed.
    pub allowed: String,
}

impl std::fmt::Display for ScenarioError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "scenario field `{}`: {}", self.field, self.allowed)
    }
}

impl std::error::Error for ScenarioError {}

fn err<T>(field: &str, allowed: &str) -> Result<T, ScenarioError> {
    Err(ScenarioError {
        field: field.to_string(),
        allowed: allowed.to_string(),
    })
}

/// Scenario names become output file names: 1-100 characters from `A-Z a-z 0-9 - _ .`,
/// not starting with `.` (so no path separators, no `..`, no hidden files).
pub fn check_name(name: &str) -> Result<(), ScenarioError> {
    let ok = !name.is_empty()
        && name.len() <= 100
        && !name.starts_with('.')
        && name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.'));
    if ok {
        Ok(())
    } else {
        err(
            "name",
            &format!(
                "must be 1-100 characters of letters, digits, '-', '_' and '.', not starting with '.' (it names the output files), got {name:?}"
            ),
        )
    }
}

/// Applies one `key=value` override to the scenario's TOML value.
fn apply_override(v: &mut toml::Value, s: &str) -> Result<(), ScenarioError> {
    let Some((key, val)) = s.split_once('=') else {
        return err(
            s,
            "override must be key=value, e.g. drive.estimation.rs_estimation=true",
        );
    };
    let key = key.trim();
    if key.is_empty() || key.split('.').any(|p| p.trim().is_empty()) {
        return err(
            s,
            "override needs a dotted field name before '=', e.g. sensors.adc_bits=8",
        );
    }
    let parsed: toml::Value = toml::from_str::<toml::Table>(&format!("x = {}", val.trim()))
        .ok()
        .and_then(|t| t.get("x").cloned())
        .unwrap_or_else(|| toml::Value::String(val.trim().to_string()));
    let mut cur = v;
    let parts: Vec<&str> = key.split('.').collect();
    for (i, part) in parts.iter().enumerate() {
        let Some(table) = cur.as_table_mut() else {
            return err(key, "is not a field of the scenario");
        };
        if i + 1 == parts.len() {
            table.insert(part.to_string(), parsed.clone());
            break;
        }
        cur = table
            .entry(part.to_string())
            .or_insert_with(|| toml::Value::Table(Default::default()));
    }
    Ok(())
}

fn check_range(field: &str, v: f32, lo: f32, hi: f32) -> Result<(), ScenarioError> {
    if v.is_finite() && v >= lo && v <= hi {
        Ok(())
    } else {
        err(field, &format!("must be a number in [{lo}, {hi}], got {v}"))
    }
}

/// Electrical and mechanical machine data (plant or controller model).
#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct MachineSpec {
    /// Stator resistance, ohm.
    pub rs_ohm: f32,
    /// Rotor resistance, ohm.
    pub rr_ohm: f32,
    /// Stator inductance, H.
    pub ls_h: f32,
    /// Rotor inductance, H.
    pub lr_h: f32,
    /// Mutual inductance, H.
    pub lm_h: f32,
    /// Pole pairs.
    pub pole_pairs: u8,
    /// Inertia, kg m^2.
    pub inertia_kgm2: f32,
    /// Viscous friction, N m s/rad.
    pub friction_nms: f32,
}

impl Default for MachineSpec {
    fn default() -> Self {
        let d = MachineParams::paper_table1().data();
        Self {
            rs_ohm: d.stator_resistance,
            rr_ohm: d.rotor_resistance,
            ls_h: d.stator_inductance,
            lr_h: d.rotor_inductance,
            lm_h: d.mutual_inductance,
            pole_pairs: d.pole_pairs,
            inertia_kgm2: d.inertia,
            friction_nms: d.viscous_friction,
        }
    }
}

impl MachineSpec {
    fn params(&self, prefix: &str) -> Result<MachineParams, ScenarioError> {
        check_range(&format!("{prefix}.rs_ohm"), self.rs_ohm, 1e-3, 1e3)?;
        check_range(&format!("{prefix}.rr_ohm"), self.rr_ohm, 1e-3, 1e3)?;
        check_range(&format!("{prefix}.ls_h"), self.ls_h, 1e-5, 100.0)?;
        check_range(&format!("{prefix}.lr_h"), self.lr_h, 1e-5, 100.0)?;
        check_range(&format!("{prefix}.lm_h"), self.lm_h, 1e-5, 100.0)?;
        check_range(
            &format!("{prefix}.inertia_kgm2"),
            self.inertia_kgm2,
            1e-6,
            1e3,
        )?;
        check_range(
            &format!("{prefix}.friction_nms"),
            self.friction_nms,
            0.0,
            10.0,
        )?;
        if !(1..=32).contains(&self.pole_pairs) {
            return err(
                &format!("{prefix}.pole_pairs"),
                "must be an integer in [1, 32]",
            );
        }
        MachineParams::new(MachineData {
            stator_resistance: self.rs_ohm,
            rotor_resistance: self.rr_ohm,
            stator_inductance: self.ls_h,
            rotor_inductance: self.lr_h,
            mutual_inductance: self.lm_h,
            pole_pairs: self.pole_pairs,
            inertia: self.inertia_kgm2,
            viscous_friction: self.friction_nms,
        })
        .or_else(|e| err(&format!("{prefix}.lm_h"), &format!("{e}")))
    }
}

/// Controller mode.
#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq, Eq, Default)]
#[serde(rename_all = "kebab-case")]
pub enum ControlMode {
    /// Sensorless IFOC (the paper's scheme; the default).
    #[default]
    Sensorless,
    /// Open-loop V/f.
    Vf,
}

/// Arithmetic of the drive: the f32 `acim::Drive` or the fixed-point
/// `acim::fixed::FixedDrive` (per unit, Q7.24; converted at the simulator boundary).
#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq, Eq, Default)]
#[serde(rename_all = "kebab-case")]
pub enum Arithmetic {
    /// f32 SI (the default).
    #[default]
    F32,
    /// Fixed point, per unit (Q7.24): the same cascade, sensorless or V/f.
    Fixed,
}

/// The drive's speed observer: the paper's reduced-order observer (eq. 12) or the
/// full-order adaptive observer it is compared with (`acim::full_order`, f32 only).
#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq, Eq, Default)]
#[serde(rename_all = "kebab-case")]
pub enum ObserverKind {
    /// Reduced-order observer of i_sq, speed and load torque (the default).
    #[default]
    Reduced,
    /// Full-order adaptive (Kubota-type) observer, the paper's baseline.
    FullOrder,
    /// Reduced-order flux observer with speed adaptation and a gain stable while
    /// regenerating (`acim::flux_observer`, f32 only).
    Flux,
}

/// The drive's modulator (`acim::Modulator`).
#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq, Eq, Default)]
#[serde(rename_all = "kebab-case")]
pub enum ModulationKind {
    /// SVPWM within 98 % of the inscribed circle (`acim::Svpwm`, the default).
    #[default]
    Linear,
    /// Overmodulation through to six-step with fundamental gain compensation
    /// (`acim::Overmodulation`, f32 only): the current loops' reserve above the linear
    /// limit the field weakening holds.
    Overmodulation,
}

/// When the Rs estimator adapts (`acim::RsEstimationMode`).
#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq, Eq, Default)]
#[serde(rename_all = "kebab-case")]
pub enum RsMode {
    /// Standstill identification only.
    Standstill,
    /// Also while running (the default).
    #[default]
    Running,
}

impl RsMode {
    fn mode(self) -> acim::RsEstimationMode {
        match self {
            RsMode::Standstill => acim::RsEstimationMode::Standstill,
            RsMode::Running => acim::RsEstimationMode::Running,
        }
    }
}

/// A held zero speed target (`acim::ZeroSpeedPolicy`).
#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq, Eq, Default)]
#[serde(rename_all = "kebab-case")]
pub enum ZeroSpeed {
    /// Keep the flux, control zero speed (the paper's trapezoids, figs. 10-12).
    Hold,
    /// Switch off after the dwell (the default).
    #[default]
    Stop,
}

/// Drive (controller) settings: the kind of control at the top of `[drive]`, the
/// settings in the groups of `acim::DriveConfig` (`[drive.limits]`, `[drive.loops]`, ...).
/// A group key written flat in `[drive]` (the earlier layout) is still read, with a
/// deprecation note ([`regroup_drive`]).
#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq, Default)]
#[serde(deny_unknown_fields, default)]
pub struct DriveSpec {
    /// Sensorless IFOC or open-loop V/f.
    pub mode: ControlMode,
    /// "f32" or "fixed".
    pub arithmetic: Arithmetic,
    /// "reduced" (the paper's observer), "full-order" (the baseline, f32 only) or "flux"
    /// (the reduced-order flux observer, f32 only). Unset: the configuration's own
    /// choice, the flux observer for a drive configured from `[nameplate]` in f32
    /// (`acim::nameplate::drive_config`), the paper's observer otherwise (the paper's
    /// settings, and the fixed-point drive, which runs only the paper's).
    pub observer: Option<ObserverKind>,
    /// "linear" (the default) or "overmodulation" (through to six-step, f32 only).
    pub modulation: ModulationKind,
    /// The inverter as the drive compensates it (`acim::InverterSettings`).
    pub inverter: DriveInverterSpec,
    /// Limits and protections (`acim::LimitSettings`).
    pub limits: LimitSpec,
    /// The control loops and their rates (`acim::LoopSettings`).
    pub loops: LoopSpec,
    /// The estimators (`acim::EstimationSettings`).
    pub estimation: EstimationSpec,
    /// The start sequence (`acim::StartSettings`).
    pub start: DriveStartSpec,
    /// What the drive tracks while running (`acim::TrackerSettings`).
    pub trackers: TrackerSpec,
    /// Field weakening, over-voltage control, flux optimisation (`acim::FieldWeakeningSettings`).
    pub field_weakening: FieldWeakeningSpec,
    /// A held zero speed target (`acim::ZeroSpeedSettings`).
    pub zero_speed: ZeroSpeedSpec,
}

/// The inverter as the drive compensates it (`acim::InverterSettings`).
#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct DriveInverterSpec {
    /// Dead time the drive compensates, s.
    pub dead_time_comp_s: f32,
    /// Device drop the drive compensates, V.
    pub device_drop_comp_v: f32,
}

impl Default for DriveInverterSpec {
    fn default() -> Self {
        let d = acim::DriveConfig::paper_defaults();
        Self {
            dead_time_comp_s: d.inverter.dead_time,
            device_drop_comp_v: d.inverter.device_drop,
        }
    }
}

/// Limits and protections (`acim::LimitSettings`).
#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct LimitSpec {
    /// Stator current limit, A peak.
    pub current_limit_a: f32,
    /// The machine's continuous current, A peak (absent: the current limit, no
    /// fold-back); a current limit above it folds back after `overload_duration_s`.
    pub continuous_current_a: Option<f32>,
    /// How long the current limit may be drawn before it folds back, s (default 60).
    pub overload_duration_s: Option<f32>,
    /// Torque at its limit with the speed far from its reference this long faults
    /// `Overload`, s (default 0.2; from the nameplate: five speed-loop time constants).
    pub overload_time_s: Option<f32>,
    /// Phase over-current trip, A.
    pub overcurrent_trip_a: f32,
    /// Bus under-voltage trip, V.
    pub dc_bus_min_v: f32,
    /// Bus over-voltage trip, V.
    pub dc_bus_max_v: f32,
    /// Over-speed trip, rpm (the drive's default, 2000 rpm, when absent); speed targets
    /// are limited to 90 % of it.
    pub max_speed_rpm: Option<f32>,
    /// Stall (locked rotor) detection time, s.
    pub stall_time_s: f32,
    /// Dead or stuck current-sensor detection while switching (default true;
    /// `DriveConfig.limits.sensor_check`).
    pub sensor_check: bool,
    /// The limit-cycle check (default true; `DriveConfig.limits.speed_oscillation_check`).
    pub speed_oscillation_check: bool,
}

impl Default for LimitSpec {
    fn default() -> Self {
        let d = acim::DriveConfig::paper_defaults();
        Self {
            current_limit_a: d.limits.current_limit,
            continuous_current_a: None,
            overload_duration_s: None,
            overload_time_s: None,
            overcurrent_trip_a: d.limits.overcurrent_trip,
            dc_bus_min_v: d.limits.dc_bus_min,
            dc_bus_max_v: d.limits.dc_bus_max,
            max_speed_rpm: None,
            stall_time_s: d.limits.stall_time,
            sensor_check: d.limits.sensor_check,
            speed_oscillation_check: d.limits.speed_oscillation_check,
        }
    }
}

/// The control loops and their rates (`acim::LoopSettings`).
#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct LoopSpec {
    /// Control period, s.
    pub control_period_s: f32,
    /// The slow task's period (speed loop, field weakening, slow supervision), s:
    /// 0.5-2 ms (`DriveConfig.loops.slow_period`).
    pub slow_period_s: f32,
    /// Flux current reference, A peak.
    pub flux_current_a: f32,
    /// Current-loop bandwidth, rad/s.
    pub current_bandwidth_rad_s: f32,
    /// Speed-loop bandwidth, rad/s.
    pub speed_bandwidth_rad_s: f32,
    /// Speed reference ramp, rpm/s.
    pub speed_ramp_rpm_s: f32,
    /// The two-degree-of-freedom speed loop (the observer's load estimate, the ramp and
    /// the friction fed forward; `acim::speed_loop`); absent: off, on from a nameplate.
    pub load_torque_feedforward: Option<bool>,
    /// Low-frequency regeneration limit: the stator frequency kept on the rotor's side of
    /// zero while holding a regenerating point, Hz electrical (0: off; 1.5 by default).
    pub regen_min_frequency_hz: f32,
}

impl Default for LoopSpec {
    fn default() -> Self {
        let d = acim::DriveConfig::paper_defaults();
        Self {
            control_period_s: d.loops.control_period,
            slow_period_s: d.loops.slow_period,
            flux_current_a: d.loops.flux_current,
            current_bandwidth_rad_s: d.loops.current_bandwidth,
            speed_bandwidth_rad_s: d.loops.speed_bandwidth,
            speed_ramp_rpm_s: d.loops.speed_ramp * acim::math::RAD_S_TO_RPM,
            load_torque_feedforward: None,
            regen_min_frequency_hz: d.loops.regen_min_frequency / acim::math::TAU,
        }
    }
}

/// The estimators (`acim::EstimationSettings`).
#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct EstimationSpec {
    /// Observer pole rates, rad/s.
    pub observer_poles_rad_s: [f32; 3],
    /// Stator-resistance estimator on (the drive's default; the paper's figs. 6-8 and
    /// 10-12 set it off).
    pub rs_estimation: bool,
    /// When Rs adapts: "standstill" (identification before the ramp only) or "running"
    /// (the default: also while turning).
    pub rs_estimation_mode: RsMode,
    /// Initial Rs estimate, ohm (the controller model's Rs when absent).
    pub rs_initial_ohm: Option<f32>,
    /// Rs estimator convergence time constant, s.
    pub rs_convergence_time_s: f32,
    /// Orientation-correction gain at light load (0: the paper's scheme unchanged); under
    /// load the drive raises it to 1.25 |i_sq| / i_sd*.
    pub orientation_gain: f32,
    /// Far-side gain of the observer's speed update (0: off), dimensionless.
    pub far_side_gain: f32,
}

impl Default for EstimationSpec {
    fn default() -> Self {
        let d = acim::DriveConfig::paper_defaults();
        Self {
            observer_poles_rad_s: [
                d.estimation.observer_poles.p1,
                d.estimation.observer_poles.p2,
                d.estimation.observer_poles.p3,
            ],
            rs_estimation: d.estimation.rs_estimation,
            rs_estimation_mode: match d.estimation.rs_estimation_mode {
                acim::RsEstimationMode::Standstill => RsMode::Standstill,
                acim::RsEstimationMode::Running => RsMode::Running,
            },
            rs_initial_ohm: None,
            rs_convergence_time_s: d.estimation.rs_convergence_time,
            orientation_gain: d.estimation.orientation_gain,
            far_side_gain: d.estimation.far_side_gain,
        }
    }
}

/// The start sequence (`acim::StartSettings`).
#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct DriveStartSpec {
    /// Identify the inverter's voltage error at every start (0.45 s of magnetizing;
    /// `DriveConfig.start.inverter_identification`; on by default, off in the paper's
    /// figs. 6-8 and 10-12).
    pub inverter_identification: bool,
    /// Calibrate the current sensors' relative gain at every start from rest (default true;
    /// `DriveConfig.start.current_gain_calibration`; the paper's scheme sets it off).
    pub current_gain_calibration: bool,
    /// With the running Rs mode: identify Rs at standstill too (default true); false: Rs
    /// converges only while turning (`DriveConfig.start.rs_standstill_identification`).
    pub rs_standstill_identification: bool,
    /// The standstill Rs identification waits at most this long, s (the drive's default
    /// when absent; 0.001 s in effect switches it off).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub rs_identification_timeout_s: Option<f32>,
}

impl Default for DriveStartSpec {
    fn default() -> Self {
        let d = acim::DriveConfig::paper_defaults();
        Self {
            inverter_identification: d.start.inverter_identification,
            current_gain_calibration: d.start.current_gain_calibration,
            rs_standstill_identification: d.start.rs_standstill_identification,
            rs_identification_timeout_s: None,
        }
    }
}

/// What the drive tracks while running (`acim::TrackerSettings`).
#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct TrackerSpec {
    /// Track the current-sensor offsets' drift while turning (default true;
    /// `DriveConfig.trackers.offset_tracking`; the paper's scheme sets it off).
    pub offset_tracking: bool,
    /// Track the inverter's voltage error while turning, from its sixth harmonic
    /// (`DriveConfig.trackers.inverter_tracking`; the paper's scheme sets it off).
    pub inverter_tracking: bool,
    /// Rotor-resistance adaptation at the start of speed ramps (item 7;
    /// `DriveConfig.trackers.rr_adaptation`, off by default: it assumes the load holds).
    pub rr_adaptation: bool,
}

impl Default for TrackerSpec {
    fn default() -> Self {
        let d = acim::DriveConfig::paper_defaults();
        Self {
            offset_tracking: d.trackers.offset_tracking,
            inverter_tracking: d.trackers.inverter_tracking,
            rr_adaptation: d.trackers.rr_adaptation,
        }
    }
}

/// Field weakening, over-voltage control, flux optimisation (`acim::FieldWeakeningSettings`).
#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct FieldWeakeningSpec {
    /// Field weakening above base speed.
    pub enabled: bool,
    /// Over-voltage control: regenerative torque reduced near the bus trip.
    pub overvoltage_control: bool,
    /// Light-load flux optimisation: the flux lowered to the copper-loss optimum at light
    /// load (off by default).
    pub flux_optimisation: bool,
}

impl Default for FieldWeakeningSpec {
    fn default() -> Self {
        let d = acim::DriveConfig::paper_defaults();
        Self {
            enabled: d.field_weakening.enabled,
            overvoltage_control: d.field_weakening.overvoltage_control,
            flux_optimisation: d.field_weakening.flux_optimisation,
        }
    }
}

/// A held zero speed target (`acim::ZeroSpeedSettings`).
#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct ZeroSpeedSpec {
    /// A held zero speed target: "hold" (default: flux kept) or "stop" (switch off after
    /// `zero_speed_dwell_s`).
    pub policy: ZeroSpeed,
    /// The dwell at a zero reference before "stop" switches off, s.
    pub dwell_s: f32,
}

impl Default for ZeroSpeedSpec {
    fn default() -> Self {
        let d = acim::DriveConfig::paper_defaults();
        Self {
            policy: match d.zero_speed.policy {
                acim::ZeroSpeedPolicy::Hold => ZeroSpeed::Hold,
                acim::ZeroSpeedPolicy::Stop => ZeroSpeed::Stop,
            },
            dwell_s: d.zero_speed.dwell,
        }
    }
}

/// Each `[drive]` key of a group: (flat key of the earlier layout, group, key in the
/// group).
pub const DRIVE_GROUP_KEYS: [(&str, &str, &str); 40] = [
    ("dead_time_comp_s", "inverter", "dead_time_comp_s"),
    ("device_drop_comp_v", "inverter", "device_drop_comp_v"),
    ("current_limit_a", "limits", "current_limit_a"),
    ("continuous_current_a", "limits", "continuous_current_a"),
    ("overload_duration_s", "limits", "overload_duration_s"),
    ("overload_time_s", "limits", "overload_time_s"),
    ("overcurrent_trip_a", "limits", "overcurrent_trip_a"),
    ("dc_bus_min_v", "limits", "dc_bus_min_v"),
    ("dc_bus_max_v", "limits", "dc_bus_max_v"),
    ("max_speed_rpm", "limits", "max_speed_rpm"),
    ("stall_time_s", "limits", "stall_time_s"),
    ("sensor_check", "limits", "sensor_check"),
    (
        "speed_oscillation_check",
        "limits",
        "speed_oscillation_check",
    ),
    ("control_period_s", "loops", "control_period_s"),
    ("slow_period_s", "loops", "slow_period_s"),
    ("flux_current_a", "loops", "flux_current_a"),
    (
        "current_bandwidth_rad_s",
        "loops",
        "current_bandwidth_rad_s",
    ),
    ("speed_bandwidth_rad_s", "loops", "speed_bandwidth_rad_s"),
    ("speed_ramp_rpm_s", "loops", "speed_ramp_rpm_s"),
    (
        "load_torque_feedforward",
        "loops",
        "load_torque_feedforward",
    ),
    ("regen_min_frequency_hz", "loops", "regen_min_frequency_hz"),
    ("observer_poles_rad_s", "estimation", "observer_poles_rad_s"),
    ("rs_estimation", "estimation", "rs_estimation"),
    ("rs_estimation_mode", "estimation", "rs_estimation_mode"),
    ("rs_initial_ohm", "estimation", "rs_initial_ohm"),
    (
        "rs_convergence_time_s",
        "estimation",
        "rs_convergence_time_s",
    ),
    ("orientation_gain", "estimation", "orientation_gain"),
    ("far_side_gain", "estimation", "far_side_gain"),
    (
        "inverter_identification",
        "start",
        "inverter_identification",
    ),
    (
        "current_gain_calibration",
        "start",
        "current_gain_calibration",
    ),
    (
        "rs_standstill_identification",
        "start",
        "rs_standstill_identification",
    ),
    (
        "rs_identification_timeout_s",
        "start",
        "rs_identification_timeout_s",
    ),
    ("offset_tracking", "trackers", "offset_tracking"),
    ("inverter_tracking", "trackers", "inverter_tracking"),
    ("rr_adaptation", "trackers", "rr_adaptation"),
    ("field_weakening", "field_weakening", "enabled"),
    (
        "overvoltage_control",
        "field_weakening",
        "overvoltage_control",
    ),
    ("flux_optimisation", "field_weakening", "flux_optimisation"),
    ("zero_speed_policy", "zero_speed", "policy"),
    ("zero_speed_dwell_s", "zero_speed", "dwell_s"),
];

/// Moves each `[drive]` key of the earlier flat layout into its group
/// ([`DRIVE_GROUP_KEYS`]: `drive.current_limit_a` becomes `drive.limits.current_limit_a`)
/// and returns a deprecation note per key moved. A key given both ways is an error: the
/// two could disagree.
pub fn regroup_drive(v: &mut toml::Value) -> Result<Vec<String>, ScenarioError> {
    let mut notes = Vec::new();
    let Some(drive) = v.get_mut("drive").and_then(|d| d.as_table_mut()) else {
        return Ok(notes);
    };
    for (flat, group, key) in DRIVE_GROUP_KEYS {
        // `field_weakening` is both a flat key (a bool) and a group (a table)
        let Some(value) = drive.get(flat).filter(|x| !x.is_table()).cloned() else {
            continue;
        };
        drive.remove(flat);
        let table = drive
            .entry(group)
            .or_insert_with(|| toml::Value::Table(Default::default()));
        let Some(table) = table.as_table_mut() else {
            return err(&format!("drive.{group}"), "must be a table of settings");
        };
        if table.contains_key(key) {
            return err(
                &format!("drive.{flat}"),
                &format!("is also given as drive.{group}.{key}: keep only the grouped key"),
            );
        }
        table.insert(key.to_string(), value);
        notes.push(format!(
            "drive.{flat} is deprecated: write it as drive.{group}.{key} ([drive.{group}] {key})"
        ));
    }
    Ok(notes)
}

/// The text of a scenario file with each flat `[drive]` key written as the dotted key of
/// its group on the same line (`flux_current_a = 1.5` -> `loops.flux_current_a = 1.5`):
/// the parser's errors then keep the user's line numbers and text.
fn regroup_drive_text(text: &str) -> String {
    let mut in_drive = false;
    let mut out = String::with_capacity(text.len() + 64);
    for line in text.lines() {
        if let Some(h) = header_name(line) {
            in_drive = h == "drive" && !line.trim_start().starts_with("[[");
        }
        let t = line.trim_start();
        let moved = in_drive
            .then(|| {
                DRIVE_GROUP_KEYS.iter().find_map(|(flat, group, key)| {
                    let rest = t.strip_prefix(flat)?;
                    rest.trim_start()
                        .starts_with('=')
                        .then(|| format!("{group}.{key}{rest}"))
                })
            })
            .flatten();
        match moved {
            Some(m) => out += &m,
            None => out += line,
        }
        out.push('\n');
    }
    out
}

/// Inverter settings of the plant.
#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct InverterSpec {
    /// Dead time, s.
    pub dead_time_s: f32,
    /// Device on-state drop, V.
    pub device_drop_v: f32,
    /// Switching-level PWM (ripple) instead of period averages.
    pub switching: bool,
    /// RK4 sub-steps per control period.
    pub substeps: u32,
    /// The hardware over-current comparator on the true phase currents, which opens all
    /// six switches (latched) and tells the drive (`HardwareBreak`); on by default.
    pub hardware_trip: bool,
    /// Its level, A (phase peak); absent: the drive's design level
    /// (`acim::hardware_trip::hardware_trip_level`: the software trip level).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub hardware_trip_a: Option<f32>,
    /// From the crossing to the gates off, s (comparator, break filter, gate drivers).
    pub hardware_trip_delay_s: f32,
}

impl Default for InverterSpec {
    fn default() -> Self {
        Self {
            dead_time_s: 1.5e-6,
            device_drop_v: 1.0,
            switching: false,
            substeps: 5,
            hardware_trip: true,
            hardware_trip_a: None,
            hardware_trip_delay_s: acim::hardware_trip::HARDWARE_TRIP_DELAY,
        }
    }
}

/// Sensor settings of the plant.
#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct SensorSpec {
    /// Current ADC resolution, bits (8 like the paper's bench, 12 like the G4).
    pub adc_bits: u8,
    /// Current ADC full scale, +/- A.
    pub full_scale_a: f32,
    /// Current noise standard deviation, A.
    pub noise_a: f32,
    /// Relative gain error per channel.
    pub gain_error: [f32; 3],
    /// Offset per channel, A.
    pub offset_a: [f32; 3],
    /// Measured phases: 2 or 3.
    pub channels: u8,
    /// Bus ADC resolution, bits.
    pub bus_adc_bits: u8,
}

impl Default for SensorSpec {
    fn default() -> Self {
        Self {
            adc_bits: 12,
            full_scale_a: 10.0,
            noise_a: 0.0,
            gain_error: [0.0; 3],
            offset_a: [0.0; 3],
            channels: 2,
            bus_adc_bits: 12,
        }
    }
}

/// The plant's DC bus without a `[board]` or `[dc_link] source_v`, V (230 V mains,
/// rectified: the paper's machine).
pub const DEFAULT_BUS_V: f32 = 325.0;

/// The board's bus and the plant's supply may differ by this fraction before the
/// simulator warns (a rounding of the same number is no difference).
pub const BUS_MISMATCH_FRACTION: f32 = 0.01;

/// DC link: a diode-rectifier source behind a resistance, feeding a capacitor. With
/// `capacitance_f = 0` the bus is stiff (equal to the source). The rectifier cannot take
/// energy back, so regeneration charges the capacitor (the over-voltage fault case).
#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct DcLinkSpec {
    /// Source (rectified mains) voltage, V. Absent: the board's `dc_bus_v` (one source for
    /// the bus: the plant runs on the bus the drive was configured for), or
    /// [`DEFAULT_BUS_V`] without a `[board]`. Set it only to simulate a supply other than
    /// the board's rating; the simulator then warns of the difference
    /// ([`Validated::warnings`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub source_v: Option<f32>,
    /// Bus capacitance, F (0: stiff bus).
    pub capacitance_f: f32,
    /// Source resistance, ohm.
    pub source_resistance_ohm: f32,
    /// Ripple on the source as a fraction of `source_v` (0.1: +/-10 %; 0: none).
    pub ripple_fraction: f32,
    /// Ripple frequency, Hz (100: a single-phase rectifier on 50 Hz mains).
    pub ripple_hz: f32,
}

impl Default for DcLinkSpec {
    fn default() -> Self {
        Self {
            source_v: None,
            capacitance_f: 0.0,
            source_resistance_ohm: 1.0,
            ripple_fraction: 0.0,
            ripple_hz: 100.0,
        }
    }
}

/// A speed-target change at `t_s`: the drive ramps to `rpm`.
#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct SpeedPoint {
    /// Time, s.
    pub t_s: f32,
    /// Target speed, rpm.
    pub rpm: f32,
}

/// Load kinds.
#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq, Eq)]
#[serde(rename_all = "kebab-case")]
pub enum LoadKind {
    /// No load.
    None,
    /// Opposes motion (powder brake).
    Passive,
    /// Constant sign (can drive the machine: regeneration).
    Active,
}

/// A load change at `t_s`.
#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct LoadPoint {
    /// Time, s.
    pub t_s: f32,
    /// Load kind.
    pub kind: LoadKind,
    /// Torque, N m (positive opposes forward rotation for `active`).
    #[serde(default)]
    pub torque_nm: f32,
}

impl LoadPoint {
    /// The model's load.
    pub fn load(&self) -> LoadTorque {
        match self.kind {
            LoadKind::None => LoadTorque::None,
            LoadKind::Passive => LoadTorque::Passive {
                torque: self.torque_nm,
            },
            LoadKind::Active => LoadTorque::Active {
                torque: self.torque_nm,
            },
        }
    }
}

/// A change of the real machine's resistances over time (thermal drift),
/// relative to the `[plant]` values: from `t_s` the factors move linearly, over `ramp_s`
/// (0: a step), from those in effect before (1 at the start) to `rs_factor` and
/// `rr_factor`. The controller is not told.
#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct PlantChange {
    /// Start of the change, s.
    pub t_s: f32,
    /// Duration of the linear ramp, s (0: a step).
    #[serde(default)]
    pub ramp_s: f32,
    /// Stator resistance at the end of the change over `plant.rs_ohm` (1: unchanged).
    #[serde(default = "unit_factor")]
    pub rs_factor: f32,
    /// Rotor resistance at the end of the change over `plant.rr_ohm` (1: unchanged).
    #[serde(default = "unit_factor")]
    pub rr_factor: f32,
}

fn unit_factor() -> f32 {
    1.0
}

/// The plant's (Rs, Rr) factors at time `t` (s) under the changes `changes`, which
/// [`Scenario::validate`] has checked to be in time order and not overlapping.
pub fn plant_factors(changes: &[PlantChange], t: f32) -> (f32, f32) {
    let (mut rs, mut rr) = (1.0f32, 1.0f32);
    for c in changes {
        if t < c.t_s {
            break;
        }
        let x = if c.ramp_s > 0.0 {
            ((t - c.t_s) / c.ramp_s).clamp(0.0, 1.0)
        } else {
            1.0
        };
        rs += (c.rs_factor - rs) * x;
        rr += (c.rr_factor - rr) * x;
    }
    (rs, rr)
}

/// A controller parameter change at run time is not modelled; faults are injected into
/// the plant or its sensors.
#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq, Default)]
#[serde(deny_unknown_fields, default)]
pub struct FaultSpec {
    /// Phase-a low-side switch fails short at this time (leg held at DC-), s.
    pub phase_short_at_s: Option<f32>,
    /// The bus source drops to `bus_sag_to_v` at this time, s.
    pub bus_sag_at_s: Option<f32>,
    /// Source voltage after the sag, V.
    pub bus_sag_to_v: f32,
    /// The rotor locks at this time, s.
    pub locked_rotor_at_s: Option<f32>,
    /// One phase-a current sample is NaN at this time, s.
    pub nan_sample_at_s: Option<f32>,
    /// Motor phase `open_phase` opens at this time (it carries no current from then), s.
    pub open_phase_at_s: Option<f32>,
    /// The phase that opens, 0..=2 (a, b, c).
    pub open_phase: usize,
    /// Current channel `current_sensor_stuck_channel` sticks at this time, s.
    pub current_sensor_stuck_at_s: Option<f32>,
    /// The stuck channel, 0..=2.
    pub current_sensor_stuck_channel: usize,
    /// The value the stuck channel reads, A (default: its last value).
    pub current_sensor_stuck_value_a: Option<f32>,
    /// Every current channel reads its zero-current code from this time, s.
    pub current_sensors_zero_at_s: Option<f32>,
    /// Offset drift of channel a from the start, A/s.
    pub current_sensor_offset_drift_a_per_s: f32,
    /// Offsets added to the current channels from `current_sensor_offset_change_at_s`
    /// (after the start's offset measurement), reached linearly over
    /// `current_sensor_offset_change_ramp_s`, A.
    pub current_sensor_offset_change_a: [f32; 3],
    /// When the offset change starts, s.
    pub current_sensor_offset_change_at_s: Option<f32>,
    /// The offset change's ramp, s (0: a step).
    pub current_sensor_offset_change_ramp_s: f32,
}

/// When the drive is started, and how the machine turns before it (a flying start when
/// the rotor turns at the start command).
#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq, Default)]
#[serde(deny_unknown_fields, default)]
pub struct StartSpec {
    /// The start command, s: until then the switches are off and the machine coasts
    /// (the drive measures its current-sensor offsets meanwhile).
    pub at_s: f32,
    /// Rotor speed at t = 0, rpm (the machine unexcited: no rotor flux).
    pub initial_speed_rpm: f32,
}

/// The motor's nameplate (rms line values, as printed): with it the drive's ratings come
/// from `acim::nameplate` instead of `[drive]` (see [`Scenario::nameplate`]).
#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct NameplateSpec {
    /// Rated output power, W.
    pub power_w: f32,
    /// Rated line-to-line voltage, V rms.
    pub voltage_v: f32,
    /// Rated current, A rms.
    pub current_a: f32,
    /// Rated frequency, Hz.
    pub frequency_hz: f32,
    /// Rated speed, rpm (optional).
    #[serde(default)]
    pub speed_rpm: Option<f32>,
    /// Rated power factor (optional).
    #[serde(default)]
    pub power_factor: Option<f32>,
    /// Pole pairs (optional when the speed is given).
    #[serde(default)]
    pub pole_pairs: Option<u8>,
    /// Rated torque, N m (informative: the drive derives it from power and speed).
    #[serde(default)]
    pub torque_nm: Option<f32>,
}

/// The power board (with `[nameplate]`): bus, sensing full scales, PWM.
#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct BoardSpec {
    /// Nominal DC bus, V.
    pub dc_bus_v: f32,
    /// Current-sense full scale, +/- A (the plant's current sensors use it too).
    pub current_full_scale_a: f32,
    /// Bus-sense full scale, V (default 1.5 x the bus; the plant's bus sensor uses it).
    #[serde(default)]
    pub bus_full_scale_v: Option<f32>,
    /// PWM and control frequency, Hz (default 5 000).
    #[serde(default)]
    pub pwm_frequency_hz: Option<f32>,
}

impl NameplateSpec {
    /// The library's nameplate (the informative `torque_nm` is not part of it).
    pub fn nameplate(&self) -> acim::nameplate::Nameplate {
        acim::nameplate::Nameplate {
            power_w: self.power_w,
            voltage_v: self.voltage_v,
            current_a: self.current_a,
            frequency_hz: self.frequency_hz,
            speed_rpm: self.speed_rpm,
            power_factor: self.power_factor,
            pole_pairs: self.pole_pairs,
        }
    }
}

impl BoardSpec {
    /// The library's board description (dead time and device drop: the inverter's).
    pub fn board(&self, inverter: &InverterSpec) -> acim::nameplate::Board {
        acim::nameplate::Board {
            dc_bus_v: self.dc_bus_v,
            current_full_scale_a: self.current_full_scale_a,
            bus_full_scale_v: self.bus_full_scale_v.unwrap_or(1.5 * self.dc_bus_v),
            pwm_frequency_hz: self.pwm_frequency_hz.unwrap_or(5000.0),
            dead_time_s: inverter.dead_time_s,
            device_drop_v: inverter.device_drop_v,
        }
    }
}

/// Main-flux saturation of the plant: L_m = L_m0 / (1 + (beta |psi_r|)^S)
/// (`acim_plant::Saturation`).
#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct SaturationSpec {
    /// beta, 1/Wb (L_m halves at 1/beta).
    pub beta_per_wb: f32,
    /// The integer exponent S.
    pub exponent: u8,
}

/// A time window over which steady-state metrics are computed.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Window {
    /// Window name (metrics key).
    pub name: String,
    /// Start, s.
    pub from_s: f32,
    /// End, s.
    pub to_s: f32,
}

/// A whole scenario.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct Scenario {
    /// Name (output file stem).
    pub name: String,
    /// One-line description.
    pub description: String,
    /// Simulated time, s.
    pub duration_s: f32,
    /// Noise seed.
    pub seed: u64,
    /// Write every n-th control step to the CSV (1 = all). Unset: every step up to
    /// 100 000 steps, beyond that the smallest step that keeps the CSV within 100 000 rows
    /// (`acim_sim::output::csv_decimation`).
    pub csv_decimation: Option<u32>,
    /// The real machine.
    pub plant: MachineSpec,
    /// The controller's model of the machine (may differ).
    pub controller: MachineSpec,
    /// Drive settings.
    pub drive: DriveSpec,
    /// Inverter settings.
    pub inverter: InverterSpec,
    /// Sensor settings.
    pub sensors: SensorSpec,
    /// DC link.
    pub dc_link: DcLinkSpec,
    /// Speed-target changes.
    pub speed_profile: Vec<SpeedPoint>,
    /// Load changes.
    pub load_profile: Vec<LoadPoint>,
    /// Injected faults.
    pub faults: FaultSpec,
    /// Changes of the plant's resistances over time (`[[plant_changes]]`).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub plant_changes: Vec<PlantChange>,
    /// Start command time and initial rotor speed.
    pub start: StartSpec,
    /// The motor's nameplate: when present (with `[board]`), the drive's ratings, limits,
    /// bandwidths, observer poles, period and per-unit bases follow from it and the
    /// controller's machine (`acim::nameplate::drive_config`), and `[drive]` only chooses
    /// `mode`, `arithmetic`, `observer`, `rs_estimation`, `rs_estimation_mode`,
    /// `rs_initial_ohm`, `orientation_gain`, `current_sensing`, `field_weakening`,
    /// `overvoltage_control`, `flux_optimisation`, `zero_speed_policy`,
    /// `zero_speed_dwell_s`, `regen_min_frequency_hz`, `max_speed_rpm`, `slow_period_s` and the
    /// `inverter_identification`, `offset_tracking`, `inverter_tracking`, `current_gain_calibration`,
    /// `rr_adaptation`, `sensor_check`, `speed_oscillation_check`, `far_side_gain`, `load_torque_feedforward`, `overload_duration_s`
    /// and `overload_time_s`; the plant's sensors take the board's full
    /// scales.
    pub nameplate: Option<NameplateSpec>,
    /// The power board (with `[nameplate]`).
    pub board: Option<BoardSpec>,
    /// The controller's machine from an `identified.toml` that `acim-sim commission`
    /// wrote (its `[inverse_gamma]`, `[mechanics]` and `[inverter]` replace
    /// `[controller]` and the dead time the drive compensates); a relative path is
    /// resolved against the folder of the scenario file that names it (against the
    /// working directory for a built-in scenario). Resolved when the scenario is loaded.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub controller_file: Option<String>,
    /// Main-flux saturation of the plant (absent: linear).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub saturation: Option<SaturationSpec>,
    /// Steady-state metric windows.
    pub windows: Vec<Window>,
    /// The verdict this scenario is expected to end with when it is not `kept`, and why
    /// (the summary line names a matching run as expected, e.g. a rotor that drifts at a
    /// held zero reference, where the stator frequency is zero and unobservable).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub expected: Option<Expected>,
    /// Deprecation notes from reading it (a `[drive]` key of the earlier flat layout,
    /// [`regroup_drive`]): kept with the validation's warnings.
    #[serde(skip)]
    pub notes: Vec<String>,
}

/// An expected verdict and its reason (see [`Scenario::expected`]).
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Expected {
    /// The verdict.
    pub verdict: crate::metrics::Verdict,
    /// Why, with a pointer to where it is measured.
    pub why: String,
}

impl Default for Scenario {
    fn default() -> Self {
        Self {
            name: "custom".into(),
            description: String::new(),
            duration_s: 5.0,
            seed: 1,
            csv_decimation: None,
            plant: MachineSpec::default(),
            controller: MachineSpec::default(),
            drive: DriveSpec::default(),
            inverter: InverterSpec::default(),
            sensors: SensorSpec::default(),
            dc_link: DcLinkSpec::default(),
            speed_profile: vec![],
            load_profile: vec![],
            faults: FaultSpec::default(),
            plant_changes: vec![],
            start: StartSpec::default(),
            nameplate: None,
            board: None,
            controller_file: None,
            saturation: None,
            windows: vec![],
            expected: None,
            notes: vec![],
        }
    }
}

/// Everything validated and converted to library types.
#[derive(Clone, Debug)]
pub struct Validated {
    /// The real machine.
    pub plant: MachineParams,
    /// The drive configuration.
    pub drive: acim::DriveConfig,
    /// Current channels.
    pub channels: CurrentChannels,
    /// The fixed-point drive's per-unit bases.
    pub bases: acim::fixed::PerUnitBases,
    /// The board, with `[nameplate]`.
    pub board: Option<acim::nameplate::Board>,
    /// What the user should know but is not an error (e.g. the plant's supply differs
    /// from the board's bus): printed before the run and kept in the summary.
    pub warnings: Vec<String>,
}

impl Scenario {
    /// Parses TOML text. A file that sets nothing (empty, or only comments) is an error:
    /// it would otherwise run the defaults silently.
    pub fn from_toml(text: &str) -> Result<Self, ScenarioError> {
        let table: toml::Table =
            toml::from_str(text).or_else(|e| err("(file)", &format!("{e}")))?;
        if table.is_empty() {
            return err(
                "(file)",
                "the scenario file sets no fields (it is empty or only comments); \
                 crates/acim-sim/scenarios/example.toml documents every field",
            );
        }
        if table.contains_key("nameplate") && !table.contains_key("plant") {
            return err(
                "plant",
                "is needed with [nameplate]: the simulator runs the motor that [plant] \
                 describes (rs_ohm, rr_ohm, ls_h, lr_h, lm_h, pole_pairs, inertia_kgm2, \
                 friction_nms); without it your nameplate would drive the paper's 750 W \
                 machine. Give the equivalent circuit from the datasheet or a test report \
                 (crates/acim-sim/scenarios/example.toml shows every field)",
            );
        }
        let mut v = toml::Value::Table(table);
        let notes = regroup_drive(&mut v)?;
        if !notes.is_empty() {
            // the earlier flat layout: read it with each key moved to its group on its own
            // line (errors quote the user's line); a layout that cannot be moved line by
            // line (a group's table given as well) is read from the regrouped value
            let mut s = match toml::from_str::<Self>(&regroup_drive_text(text)) {
                Ok(s) => s,
                Err(e) => {
                    Self::from_value(v, "(file)").or_else(|_| err("(file)", &format!("{e}")))?
                }
            };
            s.notes = notes;
            return Ok(s);
        }
        // parse the text itself: its errors quote the user's own file, with line numbers
        toml::from_str(text).or_else(|e| err("(file)", &format!("{e}")))
    }

    /// Deserialises a TOML value; errors carry no line numbers (the value may come from
    /// `--set` overrides, not from a file the user wrote).
    fn from_value(v: toml::Value, field: &str) -> Result<Self, ScenarioError> {
        v.try_into::<Self>().or_else(|e| {
            let msg = e.message().trim().to_string();
            err(field, &msg)
        })
    }

    /// Applies `key=value` overrides (dotted keys, TOML values; a bare word is a string).
    pub fn with_overrides(&self, sets: &[String]) -> Result<Self, ScenarioError> {
        if sets.is_empty() {
            return Ok(self.clone());
        }
        let mut v = toml::Value::try_from(self).or_else(|e| err("(scenario)", &format!("{e}")))?;
        let mut notes = self.notes.clone();
        for s in sets {
            // a flat `[drive]` key of the earlier layout names its grouped key (set in
            // place: the group's other keys keep their values)
            let grouped = s.split_once('=').and_then(|(k, val)| {
                let flat = k.trim().strip_prefix("drive.")?;
                let (_, group, key) = DRIVE_GROUP_KEYS.iter().find(|(f, ..)| *f == flat)?;
                notes.push(format!(
                    "--set {s}: drive.{flat} is deprecated: write it as drive.{group}.{key}"
                ));
                Some(format!("drive.{group}.{key}={val}"))
            });
            apply_override(&mut v, grouped.as_deref().unwrap_or(s))?;
            // check each override on its own, so an error names the `--set` that caused it
            Self::from_value(v.clone(), "--set").map_err(|e| ScenarioError {
                field: s
                    .split_once('=')
                    .map_or(s.as_str(), |(k, _)| k.trim())
                    .to_string(),
                allowed: format!("--set {s}: {}", e.allowed),
            })?;
        }
        let mut out = Self::from_value(v, "--set")?;
        out.notes = notes;
        Ok(out)
    }

    /// Checks every field and builds the library configuration.
    pub fn validate(&self) -> Result<Validated, ScenarioError> {
        check_range("duration_s", self.duration_s, 0.001, 600.0)?;
        check_name(&self.name)?;
        if self.csv_decimation == Some(0) {
            return err("csv_decimation", "must be an integer >= 1");
        }
        if self.board.is_some() && self.nameplate.is_none() {
            // its PWM frequency and full scales would be ignored while its bus fed the plant
            return err(
                "board",
                "is used with [nameplate] (the drive configured from the motor's ratings on \
                 this board); without one the drive follows [drive], the bus [dc_link] \
                 source_v and the sensing [sensors]",
            );
        }
        let plant = self.plant.params("plant")?;
        let ctl = self.controller.params("controller")?;
        let d = &self.drive;
        check_range(
            "drive.loops.control_period_s",
            d.loops.control_period_s,
            25e-6,
            2e-3,
        )?;
        check_range(
            "drive.loops.flux_current_a",
            d.loops.flux_current_a,
            0.05,
            100.0,
        )?;
        check_range(
            "drive.limits.current_limit_a",
            d.limits.current_limit_a,
            d.loops.flux_current_a * 1.01,
            200.0,
        )?;
        check_range(
            "drive.limits.overcurrent_trip_a",
            d.limits.overcurrent_trip_a,
            d.limits.current_limit_a,
            400.0,
        )?;
        check_range(
            "drive.limits.dc_bus_min_v",
            d.limits.dc_bus_min_v,
            1.0,
            1000.0,
        )?;
        check_range(
            "drive.limits.dc_bus_max_v",
            d.limits.dc_bus_max_v,
            d.limits.dc_bus_min_v + 1.0,
            2000.0,
        )?;
        check_range(
            "drive.loops.speed_ramp_rpm_s",
            d.loops.speed_ramp_rpm_s,
            1.0,
            1e5,
        )?;
        check_range(
            "drive.loops.current_bandwidth_rad_s",
            d.loops.current_bandwidth_rad_s,
            10.0,
            0.5 / d.loops.control_period_s,
        )?;
        check_range(
            "drive.loops.speed_bandwidth_rad_s",
            d.loops.speed_bandwidth_rad_s,
            0.1,
            d.loops.current_bandwidth_rad_s / 4.0,
        )?;
        for (i, p) in d.estimation.observer_poles_rad_s.iter().enumerate() {
            check_range(
                &format!("drive.estimation.observer_poles_rad_s[{i}]"),
                *p,
                1.0,
                0.99 / d.loops.control_period_s,
            )?;
        }
        let rs0 = d
            .estimation
            .rs_initial_ohm
            .unwrap_or(self.controller.rs_ohm);
        check_range("drive.estimation.rs_initial_ohm", rs0, 1e-3, 1e3)?;
        check_range(
            "drive.estimation.rs_convergence_time_s",
            d.estimation.rs_convergence_time_s,
            1e-3,
            100.0,
        )?;
        check_range(
            "drive.inverter.dead_time_comp_s",
            d.inverter.dead_time_comp_s,
            0.0,
            0.09 * d.loops.control_period_s,
        )?;
        check_range(
            "drive.inverter.device_drop_comp_v",
            d.inverter.device_drop_comp_v,
            0.0,
            20.0,
        )?;
        check_range(
            "drive.limits.stall_time_s",
            d.limits.stall_time_s,
            0.01,
            100.0,
        )?;
        check_range(
            "drive.estimation.orientation_gain",
            d.estimation.orientation_gain,
            0.0,
            50.0,
        )?;
        check_range(
            "drive.estimation.far_side_gain",
            d.estimation.far_side_gain,
            0.0,
            10.0,
        )?;
        check_range(
            "drive.zero_speed.dwell_s",
            d.zero_speed.dwell_s,
            1e-3,
            600.0,
        )?;
        check_range(
            "inverter.dead_time_s",
            self.inverter.dead_time_s,
            0.0,
            0.09 * d.loops.control_period_s,
        )?;
        check_range(
            "inverter.device_drop_v",
            self.inverter.device_drop_v,
            0.0,
            10.0,
        )?;
        if !(1..=200).contains(&self.inverter.substeps) {
            return err("inverter.substeps", "must be an integer in [1, 200]");
        }
        if let Some(level) = self.inverter.hardware_trip_a {
            if !(level.is_finite() && (0.01..=2000.0).contains(&level)) {
                return err(
                    "inverter.hardware_trip_a",
                    &format!(
                        "must be a level in A in [0.01, 2000], got {level} (leave it out for \
                         the drive's design level; `hardware_trip = false` turns the \
                         comparator off)"
                    ),
                );
            }
        }
        check_range(
            "inverter.hardware_trip_delay_s",
            self.inverter.hardware_trip_delay_s,
            0.0,
            d.loops.control_period_s,
        )?;
        let s = &self.sensors;
        if !(4..=24).contains(&s.adc_bits) {
            return err("sensors.adc_bits", "must be an integer in [4, 24]");
        }
        if !(4..=24).contains(&s.bus_adc_bits) {
            return err("sensors.bus_adc_bits", "must be an integer in [4, 24]");
        }
        check_range("sensors.full_scale_a", s.full_scale_a, 0.1, 1000.0)?;
        check_range("sensors.noise_a", s.noise_a, 0.0, 10.0)?;
        for i in 0..3 {
            check_range(
                &format!("sensors.gain_error[{i}]"),
                s.gain_error[i],
                -0.5,
                0.5,
            )?;
            check_range(
                &format!("sensors.offset_a[{i}]"),
                s.offset_a[i],
                -10.0,
                10.0,
            )?;
        }
        let channels = match s.channels {
            2 => CurrentChannels::Two,
            3 => CurrentChannels::Three,
            _ => return err("sensors.channels", "must be 2 or 3"),
        };
        check_range("dc_link.source_v", self.bus_v(), 1.0, 2000.0)?;
        let mut warnings = self.notes.clone();
        if let (Some(src), Some(b)) = (self.dc_link.source_v, self.board) {
            if (src - b.dc_bus_v).abs() > BUS_MISMATCH_FRACTION * b.dc_bus_v {
                warnings.push(format!(
                    "the plant's supply ([dc_link] source_v = {src} V) differs from the board's \
                     bus ([board] dc_bus_v = {} V) the drive is configured for; remove \
                     source_v to run the plant on the board's bus",
                    b.dc_bus_v
                ));
            }
        }
        check_range(
            "dc_link.capacitance_f",
            self.dc_link.capacitance_f,
            0.0,
            10.0,
        )?;
        check_range(
            "dc_link.source_resistance_ohm",
            self.dc_link.source_resistance_ohm,
            1e-3,
            1e3,
        )?;
        check_range(
            "dc_link.ripple_fraction",
            self.dc_link.ripple_fraction,
            0.0,
            0.5,
        )?;
        check_range("dc_link.ripple_hz", self.dc_link.ripple_hz, 0.1, 1000.0)?;
        for (i, p) in self.speed_profile.iter().enumerate() {
            check_range(
                &format!("speed_profile[{i}].t_s"),
                p.t_s,
                0.0,
                self.duration_s,
            )?;
            check_range(&format!("speed_profile[{i}].rpm"), p.rpm, -20000.0, 20000.0)?;
        }
        for (i, p) in self.load_profile.iter().enumerate() {
            check_range(
                &format!("load_profile[{i}].t_s"),
                p.t_s,
                0.0,
                self.duration_s,
            )?;
            check_range(
                &format!("load_profile[{i}].torque_nm"),
                p.torque_nm,
                -1000.0,
                1000.0,
            )?;
        }
        let mut free_from = 0.0f32;
        for (i, c) in self.plant_changes.iter().enumerate() {
            check_range(
                &format!("plant_changes[{i}].t_s"),
                c.t_s,
                free_from,
                self.duration_s,
            )?;
            check_range(&format!("plant_changes[{i}].ramp_s"), c.ramp_s, 0.0, 600.0)?;
            check_range(
                &format!("plant_changes[{i}].rs_factor"),
                c.rs_factor,
                0.2,
                5.0,
            )?;
            check_range(
                &format!("plant_changes[{i}].rr_factor"),
                c.rr_factor,
                0.2,
                5.0,
            )?;
            // in time order, each after the previous ramp has ended
            free_from = c.t_s + c.ramp_s;
        }
        if self.start.at_s != 0.0 {
            check_range("start.at_s", self.start.at_s, 0.0, self.duration_s)?;
        }
        check_range(
            "start.initial_speed_rpm",
            self.start.initial_speed_rpm,
            -10_000.0,
            10_000.0,
        )?;
        if let Some(sat) = self.saturation {
            check_range("saturation.beta_per_wb", sat.beta_per_wb, 1e-3, 100.0)?;
            if !(1..=20).contains(&sat.exponent) {
                return err("saturation.exponent", "must be an integer in 1 ..= 20");
            }
        }
        let f = &self.faults;
        for (name, t) in [
            ("faults.phase_short_at_s", f.phase_short_at_s),
            ("faults.bus_sag_at_s", f.bus_sag_at_s),
            ("faults.locked_rotor_at_s", f.locked_rotor_at_s),
            ("faults.nan_sample_at_s", f.nan_sample_at_s),
            ("faults.open_phase_at_s", f.open_phase_at_s),
            (
                "faults.current_sensor_stuck_at_s",
                f.current_sensor_stuck_at_s,
            ),
            (
                "faults.current_sensors_zero_at_s",
                f.current_sensors_zero_at_s,
            ),
            (
                "faults.current_sensor_offset_change_at_s",
                f.current_sensor_offset_change_at_s,
            ),
        ] {
            if let Some(t) = t {
                check_range(name, t, 0.0, self.duration_s)?;
            }
        }
        if f.bus_sag_at_s.is_some() {
            check_range("faults.bus_sag_to_v", f.bus_sag_to_v, 0.0, 2000.0)?;
        }
        if f.open_phase > 2 {
            return Err(ScenarioError {
                field: "faults.open_phase".into(),
                allowed: "0, 1 or 2 (phase a, b, c)".into(),
            });
        }
        if f.current_sensor_stuck_channel > 2 {
            return Err(ScenarioError {
                field: "faults.current_sensor_stuck_channel".into(),
                allowed: "0, 1 or 2 (phase a, b, c)".into(),
            });
        }
        if let Some(v) = f.current_sensor_stuck_value_a {
            check_range("faults.current_sensor_stuck_value_a", v, -1000.0, 1000.0)?;
        }
        check_range(
            "faults.current_sensor_offset_drift_a_per_s",
            f.current_sensor_offset_drift_a_per_s,
            -100.0,
            100.0,
        )?;
        for (i, o) in f.current_sensor_offset_change_a.iter().enumerate() {
            check_range(
                &format!("faults.current_sensor_offset_change_a[{i}]"),
                *o,
                -1000.0,
                1000.0,
            )?;
        }
        check_range(
            "faults.current_sensor_offset_change_ramp_s",
            f.current_sensor_offset_change_ramp_s,
            0.0,
            1.0e4,
        )?;
        for (i, w) in self.windows.iter().enumerate() {
            check_range(
                &format!("windows[{i}].from_s"),
                w.from_s,
                0.0,
                self.duration_s,
            )?;
            check_range(
                &format!("windows[{i}].to_s"),
                w.to_s,
                w.from_s,
                self.duration_s,
            )?;
        }

        let mut drive = acim::DriveConfig::paper_defaults();
        drive.machine = ctl;
        drive.loops.control_period = d.loops.control_period_s;
        drive.loops.slow_period = d.loops.slow_period_s;
        drive.loops.flux_current = d.loops.flux_current_a;
        drive.limits.current_limit = d.limits.current_limit_a;
        if let Some(i) = d.limits.continuous_current_a {
            check_range(
                "drive.limits.continuous_current_a",
                i,
                d.loops.flux_current_a * 1.01,
                200.0,
            )?;
            drive.limits.continuous_current = i;
        }
        if let Some(t) = d.limits.overload_duration_s {
            check_range("drive.limits.overload_duration_s", t, 0.1, 3600.0)?;
            drive.limits.overload_duration = t;
        }
        if let Some(t) = d.limits.overload_time_s {
            check_range("drive.limits.overload_time_s", t, 0.01, 60.0)?;
            drive.limits.overload_time = t;
        }
        drive.limits.overcurrent_trip = d.limits.overcurrent_trip_a;
        drive.limits.dc_bus_min = d.limits.dc_bus_min_v;
        drive.limits.dc_bus_max = d.limits.dc_bus_max_v;
        drive.loops.speed_ramp = d.loops.speed_ramp_rpm_s * acim::math::RPM_TO_RAD_S;
        drive.loops.current_bandwidth = d.loops.current_bandwidth_rad_s;
        drive.loops.speed_bandwidth = d.loops.speed_bandwidth_rad_s;
        drive.estimation.observer_poles = acim::observer::ObserverPoles {
            p1: d.estimation.observer_poles_rad_s[0],
            p2: d.estimation.observer_poles_rad_s[1],
            p3: d.estimation.observer_poles_rad_s[2],
        };
        drive.estimation.rs_estimation = d.estimation.rs_estimation;
        drive.estimation.rs_estimation_mode = d.estimation.rs_estimation_mode.mode();
        drive.estimation.rs_initial = rs0;
        drive.estimation.rs_convergence_time = d.estimation.rs_convergence_time_s;
        if let Some(t) = d.start.rs_identification_timeout_s {
            check_range("drive.start.rs_identification_timeout_s", t, 1e-3, 100.0)?;
            drive.start.rs_identification_timeout = t;
        }
        drive.inverter.dead_time = d.inverter.dead_time_comp_s;
        drive.inverter.device_drop = d.inverter.device_drop_comp_v;
        drive.limits.stall_time = d.limits.stall_time_s;
        drive.estimation.orientation_gain = d.estimation.orientation_gain;
        drive.estimation.far_side_gain = d.estimation.far_side_gain;
        if let Some(on) = d.loops.load_torque_feedforward {
            drive.loops.load_torque_feedforward = on;
        }
        if let Some(rpm) = d.limits.max_speed_rpm {
            drive.limits.max_speed = rpm * acim::math::RPM_TO_RAD_S;
        }
        drive.field_weakening.enabled = d.field_weakening.enabled;
        drive.field_weakening.overvoltage_control = d.field_weakening.overvoltage_control;
        drive.field_weakening.flux_optimisation = d.field_weakening.flux_optimisation;
        drive.zero_speed.policy = match d.zero_speed.policy {
            ZeroSpeed::Hold => acim::ZeroSpeedPolicy::Hold,
            ZeroSpeed::Stop => acim::ZeroSpeedPolicy::Stop,
        };
        drive.zero_speed.dwell = d.zero_speed.dwell_s;
        drive.loops.regen_min_frequency = d.loops.regen_min_frequency_hz * acim::math::TAU;
        drive.start.inverter_identification = d.start.inverter_identification;
        drive.start.rs_standstill_identification = d.start.rs_standstill_identification;
        drive.trackers.offset_tracking = d.trackers.offset_tracking;
        drive.trackers.inverter_tracking = d.trackers.inverter_tracking;
        drive.start.current_gain_calibration = d.start.current_gain_calibration;
        drive.trackers.rr_adaptation = d.trackers.rr_adaptation;
        drive.limits.sensor_check = d.limits.sensor_check;
        drive.limits.speed_oscillation_check = d.limits.speed_oscillation_check;
        drive.inverter.current_sensing = match channels {
            CurrentChannels::Two => acim::CurrentSensing::TwoPhase,
            CurrentChannels::Three => acim::CurrentSensing::ThreePhase,
        };
        // the drive's own checks name its fields; map them to scenario fields
        let mut bases = acim::fixed::PerUnitBases::PAPER;
        let mut board = None;
        if let Some(np) = self.nameplate {
            let Some(b) = self.board else {
                return err(
                    "board",
                    "is needed with [nameplate] (dc_bus_v, current_full_scale_a)",
                );
            };
            check_range("board.dc_bus_v", b.dc_bus_v, 1.0, 2000.0)?;
            if let Some(f) = b.pwm_frequency_hz {
                // the period's own bounds (20 us .. 10 ms), in the unit the user wrote
                check_range("board.pwm_frequency_hz", f, 100.0, 50_000.0)?;
            }
            let b = b.board(&self.inverter);
            let nameplate = np.nameplate();
            let mut cfg =
                acim::nameplate::drive_config(ctl, &nameplate, &b).map_err(|e| match e {
                    // the field once, in the error's own place
                    acim::nameplate::NameplateError::Invalid { field, rule } => ScenarioError {
                        field: field.into(),
                        allowed: rule.into(),
                    },
                    acim::nameplate::NameplateError::Config(c) => config_error(c, true),
                })?;
            cfg.estimation.rs_estimation = drive.estimation.rs_estimation;
            cfg.estimation.rs_estimation_mode = drive.estimation.rs_estimation_mode;
            if d.estimation.rs_initial_ohm.is_some() {
                cfg.estimation.rs_initial = drive.estimation.rs_initial;
            }
            cfg.estimation.orientation_gain = drive.estimation.orientation_gain;
            cfg.estimation.far_side_gain = drive.estimation.far_side_gain;
            if let Some(on) = d.loops.load_torque_feedforward {
                cfg.loops.load_torque_feedforward = on;
            }
            if d.limits.overload_duration_s.is_some() {
                cfg.limits.overload_duration = drive.limits.overload_duration;
            }
            if d.limits.overload_time_s.is_some() {
                cfg.limits.overload_time = drive.limits.overload_time;
            }
            cfg.inverter.current_sensing = drive.inverter.current_sensing;
            cfg.field_weakening = drive.field_weakening;
            cfg.zero_speed = drive.zero_speed;
            cfg.loops.regen_min_frequency = drive.loops.regen_min_frequency;
            // the switches (before, a `--set` of them was silently ignored here)
            cfg.start.inverter_identification = drive.start.inverter_identification;
            cfg.start.current_gain_calibration = drive.start.current_gain_calibration;
            cfg.trackers = drive.trackers;
            cfg.limits.sensor_check = drive.limits.sensor_check;
            cfg.limits.speed_oscillation_check = drive.limits.speed_oscillation_check;
            cfg.loops.slow_period = drive.loops.slow_period;
            if d.limits.max_speed_rpm.is_some() {
                cfg.limits.max_speed = drive.limits.max_speed;
            }
            bases = acim::nameplate::per_unit_bases(&cfg, &b);
            board = Some(b);
            drive = cfg;
        }
        drive.estimation.observer = match d.observer {
            Some(ObserverKind::Flux) => acim::ObserverChoice::Flux,
            Some(ObserverKind::Reduced | ObserverKind::FullOrder) => acim::ObserverChoice::Reduced,
            None if d.arithmetic == Arithmetic::Fixed => acim::ObserverChoice::Reduced,
            None => drive.estimation.observer,
        };
        if d.observer == Some(ObserverKind::Flux) && d.arithmetic == Arithmetic::Fixed {
            return err(
                "drive.observer",
                "\"flux\" runs in f32 only (drive.arithmetic = \"f32\")",
            );
        }
        acim::Drive::new(drive).map_err(|e| config_error(e, self.nameplate.is_some()))?;
        if d.observer == Some(ObserverKind::FullOrder) {
            if d.arithmetic == Arithmetic::Fixed {
                return err(
                    "drive.observer",
                    "\"full-order\" runs in f32 only (drive.arithmetic = \"f32\")",
                );
            }
            acim::full_order::FullOrder::new(&drive.machine, drive.loops.control_period).map_err(
                |e| ScenarioError {
                    field: "drive.observer".into(),
                    allowed: format!("a valid full-order design ({e:?})"),
                },
            )?;
        }
        if d.modulation == ModulationKind::Overmodulation && d.arithmetic == Arithmetic::Fixed {
            return err(
                "drive.modulation",
                "\"overmodulation\" runs in f32 only (drive.arithmetic = \"f32\")",
            );
        }
        if d.arithmetic == Arithmetic::Fixed {
            acim::fixed::FixedDrive::with_bases(drive, bases).map_err(|e| ScenarioError {
                field: "drive.arithmetic".into(),
                allowed: format!("{e}"),
            })?;
        }
        Ok(Validated {
            plant,
            drive,
            channels,
            bases,
            board,
            warnings,
        })
    }

    /// The plant's DC supply, V: `[dc_link] source_v`, else the board's `dc_bus_v`, else
    /// [`DEFAULT_BUS_V`].
    pub fn bus_v(&self) -> f32 {
        self.dc_link
            .source_v
            .or(self.board.map(|b| b.dc_bus_v))
            .unwrap_or(DEFAULT_BUS_V)
    }
}

/// The drive's own validation error as a scenario error, naming the scenario field the
/// user wrote where there is one (`with_board`: the period comes from the board's PWM).
fn config_error(e: acim::ConfigError, with_board: bool) -> ScenarioError {
    match e {
        acim::ConfigError::Invalid { field, rule } => ScenarioError {
            field: match field {
                "loops.control_period" if with_board => "board.pwm_frequency_hz".into(),
                other => scenario_key(other).unwrap_or_else(|| format!("drive ({other})")),
            },
            allowed: rule.into(),
        },
        other => ScenarioError {
            field: "drive".into(),
            allowed: format!("{other}"),
        },
    }
}

/// The scenario key of a drive configuration field (`loops.speed_bandwidth` ->
/// `drive.loops.speed_bandwidth_rad_s`: the same name in the same group, with the unit
/// the scenario writes), if the scenario sets it.
fn scenario_key(field: &str) -> Option<String> {
    let (group, name) = field.split_once('.')?;
    DRIVE_GROUP_KEYS
        .iter()
        .find(|(_, g, key)| {
            *g == group
                && (*key == name
                    || key
                        .strip_prefix(name)
                        .is_some_and(|unit| unit.starts_with('_')))
        })
        .map(|(_, g, key)| format!("drive.{g}.{key}"))
}

/// A machine file (`[nameplate]`, `[plant]`, `[inverse_gamma]`, `[board]`, as in the
/// project's acceptance set) reads as a scenario: its `[inverse_gamma]` table (the same
/// machine in another form) is dropped, the controller gets the plant's data (the plant
/// runs on the board's bus, as every scenario with a `[board]` does), and a board without a current-sense range gets 2.2 x the rated peak
/// current (the trip, 1.75 x, with margin). Any other text passes unchanged.
pub fn machine_file_as_scenario(text: &str) -> String {
    // a TOML number as written: `540` and `540.0` are the same bus
    fn number(v: &toml::Value) -> Option<f64> {
        v.as_float().or(v.as_integer().map(|i| i as f64))
    }
    let Ok(mut t) = text.parse::<toml::Table>() else {
        return text.to_string();
    };
    if t.remove("inverse_gamma").is_none() {
        return text.to_string();
    }
    if let Some(plant) = t.get("plant").cloned() {
        t.entry("controller").or_insert(plant);
    }
    let rated_peak = t
        .get("nameplate")
        .and_then(|n| n.get("current_a"))
        .and_then(number)
        .map(|i| i * std::f64::consts::SQRT_2);
    if let Some(b) = t.get_mut("board").and_then(|b| b.as_table_mut()) {
        if let (false, Some(i)) = (b.contains_key("current_full_scale_a"), rated_peak) {
            b.insert("current_full_scale_a".into(), toml::Value::Float(2.2 * i));
        }
    }
    if let Some(n) = t.get_mut("nameplate").and_then(|n| n.as_table_mut()) {
        n.remove("torque_nm");
    }
    toml::to_string(&t).unwrap_or_else(|_| text.to_string())
}

/// A table header line's name (`[board]` -> `board`, `[[windows]]` -> `windows`), or
/// `None` for any other line.
fn header_name(line: &str) -> Option<&str> {
    let t = line.trim();
    let (inner, rest) = if let Some(r) = t.strip_prefix("[[") {
        r.split_once("]]")?
    } else {
        t.strip_prefix('[')?.split_once(']')?
    };
    let rest = rest.trim_start();
    let name = inner.trim();
    let key_like = !name.is_empty()
        && name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || "_-. \"'".contains(c));
    (key_like && (rest.is_empty() || rest.starts_with('#'))).then_some(name)
}

/// The text [`machine_file_as_scenario`] makes of a machine file, written on the user's
/// own lines: `[inverse_gamma]` and `torque_nm` blanked out, the added board current range
/// on a blank line of `[board]` (or at the end), the controller appended at the end. Every
/// line the user wrote keeps its number, so a parse error quotes it where it is. `None`
/// where that is not possible, or the result is not the same table.
fn machine_file_on_user_lines(text: &str) -> Option<String> {
    let original: toml::Table = text.parse().ok()?;
    let converted: toml::Table = machine_file_as_scenario(text).parse().ok()?;
    if !original.contains_key("inverse_gamma") {
        return None;
    }
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    // the table each line belongs to
    let mut table = String::new();
    let mut scope = Vec::with_capacity(lines.len());
    for l in &lines {
        if let Some(name) = header_name(l) {
            table = name.replace(' ', "");
        }
        scope.push(table.clone());
    }
    for (l, t) in lines.iter_mut().zip(&scope) {
        let key = l.split('=').next().unwrap_or("").trim();
        if t == "inverse_gamma"
            || t.starts_with("inverse_gamma.")
            || (t == "nameplate" && key == "torque_nm")
        {
            l.clear();
        }
    }
    let added =
        |t: &toml::Table, k: &str| -> Option<toml::Value> { t.get("board")?.get(k).cloned() };
    let mut tail = String::new();
    if let (Some(fs), None) = (
        added(&converted, "current_full_scale_a"),
        added(&original, "current_full_scale_a"),
    ) {
        let line = format!("current_full_scale_a = {fs}");
        let last = scope.iter().rposition(|t| t == "board")?;
        let blank = (0..=last)
            .rev()
            .take_while(|&i| scope[i] == "board" && header_name(&lines[i]).is_none())
            .find(|&i| lines[i].trim().is_empty());
        match blank {
            Some(i) => lines[i] = line,
            // the last table: its scope runs to the end of the file
            None if scope.last().map(String::as_str) == Some("board") => {
                tail += &format!("{line}\n");
            }
            None => return None,
        }
    }
    if !original.contains_key("controller") {
        if let Some(plant) = converted.get("controller").and_then(|c| c.as_table()) {
            tail += &format!("[controller]\n{}", toml::to_string(plant).ok()?);
        }
    }
    let out = lines.join("\n") + "\n" + &tail;
    (out.parse::<toml::Table>().ok()? == converted).then_some(out)
}

impl Scenario {
    /// Reads a scenario or machine file ([`machine_file_as_scenario`]). Errors quote the
    /// user's own text with its line numbers, also where the machine file was converted.
    pub fn from_file_text(text: &str) -> Result<Self, ScenarioError> {
        let converted = machine_file_as_scenario(text);
        match Self::from_toml(&converted) {
            Ok(s) => Ok(s),
            Err(e) if converted == text => Err(e),
            Err(e) => match machine_file_on_user_lines(text).map(|t| Self::from_toml(&t)) {
                Some(Err(on_user_lines)) => Err(on_user_lines),
                _ => Err(e),
            },
        }
    }

    /// Applies an `identified.toml` (from `acim-sim commission`) as the controller's
    /// machine: the exact T-model of its inverse-Gamma data (Ls = Lr), its inertia and
    /// friction, and its dead time as the drive's compensation. Errors name the key.
    pub fn apply_identified(&mut self, text: &str) -> Result<(), ScenarioError> {
        let t: toml::Table = text
            .parse()
            .or_else(|e| err("controller_file", &format!("not TOML: {e}")))?;
        let get = |table: &str, key: &str| -> Result<f32, ScenarioError> {
            t.get(table)
                .and_then(|x| x.get(key))
                .and_then(|v| v.as_float().or(v.as_integer().map(|i| i as f64)))
                .map(|v| v as f32)
                .ok_or_else(|| ScenarioError {
                    field: format!("controller_file: [{table}] {key}"),
                    allowed: "a number".into(),
                })
        };
        let (rs, r_r) = (
            get("inverse_gamma", "rs_ohm")?,
            get("inverse_gamma", "rr_ohm")?,
        );
        let (l_s, l_m) = (
            get("inverse_gamma", "l_sigma_h")?,
            get("inverse_gamma", "l_m_h")?,
        );
        check_range("controller_file: [inverse_gamma] l_m_h", l_m, 1e-6, 100.0)?;
        check_range(
            "controller_file: [inverse_gamma] l_sigma_h",
            l_s,
            1e-7,
            100.0,
        )?;
        let l = l_m + l_s;
        self.controller.rs_ohm = rs;
        self.controller.rr_ohm = r_r * l / l_m;
        self.controller.ls_h = l;
        self.controller.lr_h = l;
        self.controller.lm_h = (l_m * l).sqrt();
        if let Ok(j) = get("mechanics", "inertia_kgm2") {
            if j.is_finite() {
                self.controller.inertia_kgm2 = j;
            }
        }
        if let Ok(b) = get("mechanics", "friction_nms") {
            self.controller.friction_nms = b;
        }
        if let Ok(td) = get("inverter", "dead_time_s") {
            self.drive.inverter.dead_time_comp_s = td;
        }
        Ok(())
    }
}
