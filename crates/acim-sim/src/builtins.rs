//! Built-in scenarios: the paper's Figs. 6-12, open-loop V/f, regeneration (the subject of
//! a later issue: run and reported here), fault cases and flying starts.
//!
//! Common settings of the paper cases (design notes section 4 and the project's defaults):
//! Table 1 machine, J = 0.01 kg m^2, viscous friction 2e-3 N m s/rad, 325 V stiff bus,
//! 1.5 us dead time and 1 V device drop (compensated by the drive with its nominal values),
//! 12-bit current sensors with 10 mA rms noise, the paper's load as a passive brake.
//! Figs. 10-12 (the paper's experiments) add sensor gain and offset errors.

use crate::scenario::{
    ControlMode, LoadKind, LoadPoint, Scenario, SpeedPoint, StartSpec, Window, ZeroSpeed,
};

fn sp(t_s: f32, rpm: f32) -> SpeedPoint {
    SpeedPoint { t_s, rpm }
}

fn load(t_s: f32, kind: LoadKind, torque_nm: f32) -> LoadPoint {
    LoadPoint {
        t_s,
        kind,
        torque_nm,
    }
}

fn win(name: &str, from_s: f32, to_s: f32) -> Window {
    Window {
        name: name.into(),
        from_s,
        to_s,
    }
}

/// The common base of the paper cases.
fn base(name: &str, description: &str, duration_s: f32) -> Scenario {
    let mut s = Scenario {
        name: name.into(),
        description: description.into(),
        duration_s,
        ..Scenario::default()
    };
    s.sensors.noise_a = 0.01;
    s
}

/// A figure the paper ran without its Rs estimator (figs. 6-8, and the experiments of
/// figs. 10-12, for which it reports none): the drive's default, Rs tracked while running,
/// is switched off so that the published results are the paper's setup.
fn paper_without_rs_estimator(name: &str, description: &str, duration_s: f32) -> Scenario {
    let mut s = base(name, description, duration_s);
    s.drive.estimation.rs_estimation = false;
    s.drive.trackers.offset_tracking = false;
    s.drive.start.current_gain_calibration = false;
    s.drive.start.inverter_identification = false;
    s.drive.trackers.inverter_tracking = false;
    s
}

/// Sensor imperfections of the paper's experiments (Figs. 10-12).
fn realistic_sensors(s: &mut Scenario) {
    s.sensors.gain_error = [0.003, -0.003, 0.0];
    s.sensors.offset_a = [0.005, -0.005, 0.0];
}

/// Trapezoid with reversal at `rpm`: up at 0.5 s, reverse at 4 s, back to zero at 8 s.
fn trapezoid(name: &str, description: &str, rpm: f32) -> Scenario {
    let mut s = paper_without_rs_estimator(name, description, 10.0);
    realistic_sensors(&mut s);
    s.speed_profile = vec![sp(0.5, rpm), sp(4.0, -rpm), sp(8.0, 0.0)];
    // the paper's trapezoids hold zero speed for their last 2 s with the flux on: `hold`,
    // not the drive's default `stop` (which would switch off 0.5 s after reaching zero)
    s.drive.zero_speed.policy = ZeroSpeed::Hold;
    // steady windows start 1 s after the ramp ends (500 rpm/s)
    let ramp = 2.0 * rpm.abs() / s.drive.loops.speed_ramp_rpm_s;
    s.windows = vec![
        win(
            "forward",
            0.5 + rpm.abs() / s.drive.loops.speed_ramp_rpm_s + 1.0,
            4.0,
        ),
        win("reverse", (4.0 + ramp + 1.0).min(7.9), 8.0),
    ];
    s
}

/// The fig. 7 profile: 500 rpm, 1.5 N m brake from 4 s to 8 s, Rs estimator off (fig. 9
/// switches it on).
fn load_step(name: &str, description: &str) -> Scenario {
    let mut s = paper_without_rs_estimator(name, description, 10.0);
    s.speed_profile = vec![sp(0.5, 500.0)];
    s.load_profile = vec![
        load(4.0, LoadKind::Passive, 1.5),
        load(8.0, LoadKind::None, 0.0),
    ];
    // steady state: from 1 s after each step (the speed loop's slow PI tail)
    s.windows = vec![
        win("no-load", 2.5, 4.0),
        win("load", 5.0, 8.0),
        win("unloaded", 9.0, 10.0),
    ];
    s
}

/// Reversal against an active (constant-sign) load: regeneration while braking and in
/// the reverse direction.
fn regen(name: &str, rpm: f32) -> Scenario {
    let mut s = base(
        name,
        "reversal against an active 1.5 N m load (regenerating phase)",
        8.0,
    );
    s.speed_profile = vec![sp(0.5, rpm), sp(4.0, -rpm)];
    s.load_profile = vec![load(2.0, LoadKind::Active, 1.5)];
    let up = rpm.abs() / s.drive.loops.speed_ramp_rpm_s;
    s.windows = vec![
        win("motoring", (0.5 + up + 1.0).max(2.5), 4.0),
        win("regenerating", 4.0 + 2.0 * up + 1.0, 8.0),
    ];
    s
}

/// A fault case at 500 rpm: the fault strikes at 3 s.
fn fault(name: &str, description: &str) -> Scenario {
    let mut s = base(name, description, 5.0);
    s.speed_profile = vec![sp(0.5, 500.0)];
    // steady from 2.5 s: speed control starts at 0.77 s (the speed search, the inverter
    // test and the Rs identification), the ramp ends at 1.77 s and settles by 2.3 s
    s.windows = vec![win("before-fault", 2.5, 3.0)];
    s
}

/// Every built-in scenario, in listing order.
pub fn all() -> Vec<Scenario> {
    let mut v = Vec::new();

    let mut s = paper_without_rs_estimator(
        "paper-fig6",
        "Fig. 6: start-up, 500 rpm, speed reversal, no load",
        8.0,
    );
    s.speed_profile = vec![sp(0.5, 500.0), sp(4.0, -500.0)];
    s.windows = vec![win("forward", 2.5, 4.0), win("reverse", 7.0, 8.0)];
    v.push(s);

    v.push(load_step(
        "paper-fig7",
        "Fig. 7: 500 rpm, 1.5 N m load from 4 s to 8 s",
    ));

    let mut s = load_step(
        "paper-fig8-rr",
        "Fig. 8a-b: +50 % Rr in the controller, Rs estimator off",
    );
    s.controller.rr_ohm = 1.5 * s.plant.rr_ohm;
    v.push(s);

    let mut s = load_step(
        "paper-fig8-rs",
        "Fig. 8c-d: +50 % Rs in the controller, Rs estimator off",
    );
    s.controller.rs_ohm = 1.5 * s.plant.rs_ohm;
    v.push(s);

    let mut s = load_step(
        "paper-fig9",
        "Fig. 9: Rs estimator on, initial Rs_hat 15.75 ohm (+50 %)",
    );
    s.controller.rs_ohm = 1.5 * s.plant.rs_ohm;
    s.drive.estimation.rs_estimation = true;
    // speed control starts about 0.6 s later (standstill Rs identification), so the
    // ramp's settling tail reaches 2.5 s: the steady window starts at 3 s
    s.windows[0].from_s = 3.0;
    v.push(s);

    let mut s = trapezoid(
        "paper-fig10",
        "Fig. 10: trapezoid to 500 rpm with reversal, realistic sensors and inverter",
        500.0,
    );
    s.expected = Some(zero_speed_drift());
    v.push(s);
    v.push(trapezoid(
        "paper-fig11",
        "Fig. 11: trapezoid to 120 rpm with reversal, realistic sensors and inverter",
        120.0,
    ));
    let mut s = trapezoid(
        "paper-fig12",
        "Fig. 12: trapezoid to 60 rpm with reversal, realistic sensors and inverter",
        60.0,
    );
    s.expected = Some(zero_speed_drift());
    v.push(s);
    let mut s = trapezoid(
        "paper-fig12-load",
        "Fig. 12 with a 1.5 N m powder-brake load from 2 s: 60 rpm with reversal under load",
        60.0,
    );
    s.load_profile = vec![load(2.0, LoadKind::Passive, 1.5)];
    s.windows[0].from_s = s.windows[0].from_s.max(3.0);
    v.push(s);

    let mut s = base(
        "vf-open-loop",
        "open-loop V/f commissioning: ramp to 750 rpm, 1.5 N m brake at 3 s",
        5.0,
    );
    s.drive.mode = ControlMode::Vf;
    s.speed_profile = vec![sp(0.0, 750.0)];
    s.load_profile = vec![load(3.0, LoadKind::Passive, 1.5)];
    s.windows = vec![win("no-load", 2.0, 3.0), win("load", 4.0, 5.0)];
    v.push(s);

    v.push(regen("regen-500", 500.0));
    v.push(regen("regen-120", 120.0));
    v.push(regen("regen-60", 60.0));

    // zero torque: no load, no friction, 60 s (the orientation mode of the paper's scheme
    // is neutral there)
    for rpm in [500.0f32, 60.0] {
        let mut s = base(
            &format!("zero-torque-{rpm:.0}"),
            "no load and zero friction for 60 s: orientation must stay bounded",
            62.0,
        );
        s.plant.friction_nms = 0.0;
        s.controller.friction_nms = 0.0;
        s.csv_decimation = Some(10);
        s.speed_profile = vec![sp(0.5, rpm)];
        // from 2.5 s: the ramp's settling after the start's 0.77 s of magnetizing
        s.windows = vec![win("steady", 2.5, 62.0)];
        v.push(s);
    }

    let mut s = fault(
        "fault-short",
        "phase-a low-side switch fails short at 3 s: over-current trip",
    );
    s.faults.phase_short_at_s = Some(3.0);
    v.push(s);

    let mut s = fault(
        "fault-bus-sag",
        "mains sag: the bus source drops to 150 V at 3 s (470 uF link): under-voltage trip",
    );
    s.dc_link.capacitance_f = 470e-6;
    s.faults.bus_sag_at_s = Some(3.0);
    s.faults.bus_sag_to_v = 150.0;
    v.push(s);

    let mut s = base(
        "fault-overvoltage-braking",
        "fast braking from 1000 rpm on a 220 uF link without a chopper: over-voltage trip",
        4.0,
    );
    s.dc_link.capacitance_f = 220e-6;
    s.drive.loops.speed_ramp_rpm_s = 4000.0;
    s.speed_profile = vec![sp(0.5, 1000.0), sp(2.5, 0.0)];
    // from 2.0 s: speed control starts at 0.77 s, the ramp settles by about 1.5 s
    s.windows = vec![win("before-fault", 2.0, 2.5)];
    v.push(s);

    let mut s = fault(
        "fault-locked-rotor",
        "the rotor locks at 3 s: stall (locked-rotor) trip",
    );
    s.faults.locked_rotor_at_s = Some(3.0);
    v.push(s);

    let mut s = fault(
        "fault-nan-sample",
        "one NaN phase-current sample at 3 s: non-finite-input trip",
    );
    s.faults.nan_sample_at_s = Some(3.0);
    v.push(s);

    // faults the drive must detect without trusting its estimates
    let mut s = fault(
        "fault-open-phase",
        "motor phase b opens at 3 s (500 rpm, 1 N m): current-regulation trip",
    );
    s.load_profile = vec![load(2.0, LoadKind::Passive, 1.0)];
    s.faults.open_phase_at_s = Some(3.0);
    s.faults.open_phase = 1;
    v.push(s);

    let mut s = fault(
        "fault-sensor-stuck",
        "current channel a sticks at its last value at 3 s (two shunts, 500 rpm)",
    );
    s.faults.current_sensor_stuck_at_s = Some(3.0);
    v.push(s);

    let mut s = fault(
        "fault-sensor-stuck-3shunt",
        "current channel a sticks at its last value at 3 s (three shunts, 500 rpm)",
    );
    s.sensors.channels = 3;
    s.faults.current_sensor_stuck_at_s = Some(3.0);
    v.push(s);

    let mut s = fault(
        "fault-sensors-zero",
        "every current channel reads 0 A from 3 s (sense cable off, 500 rpm)",
    );
    s.faults.current_sensors_zero_at_s = Some(3.0);
    v.push(s);

    let mut s = fault(
        "fault-sensors-zero-at-start",
        "every current channel reads 0 A from power-up: magnetizing must not hang",
    );
    s.faults.current_sensors_zero_at_s = Some(0.0);
    s.windows = vec![];
    v.push(s);

    let mut s = fault(
        "fault-offset-drift",
        "channel a's offset drifts by 0.5 A/s from power-up (500 rpm)",
    );
    s.duration_s = 10.0;
    s.faults.current_sensor_offset_drift_a_per_s = 0.5;
    v.push(s);

    let mut s = fault(
        "fault-offset-drift-running",
        "channel a's offset drifts by 0.3 A over 10 s from 2 s while running at 500 rpm \
         (the limit is 0.16 A): found by the running offset tracker",
    );
    s.duration_s = 12.0;
    s.faults.current_sensor_offset_change_a = [0.3, 0.0, 0.0];
    s.faults.current_sensor_offset_change_at_s = Some(2.0);
    s.faults.current_sensor_offset_change_ramp_s = 10.0;
    v.push(s);

    for (rpm, nm) in [
        (500.0f32, 5.0f32),
        (500.0, 8.0),
        (500.0, 12.0),
        (120.0, 8.0),
    ] {
        let mut s = base(
            &format!("fault-overhauling-{rpm:.0}-{nm:.0}nm"),
            if rpm < 200.0 {
                "overhauling load at 120 rpm that would pin the stator frequency near zero: \
                 crossed by the far-side mode, held at the target"
            } else if nm <= 10.0 {
                "overhauling load at 500 rpm within the torque capability: held"
            } else {
                "overhauling load at 500 rpm beyond the torque capability: overload"
            },
            5.0,
        );
        s.speed_profile = vec![sp(0.5, rpm)];
        s.load_profile = vec![load(2.5, LoadKind::Active, -nm)];
        // from 2.25 s: the ramp's settling after the start's 0.77 s of magnetizing
        s.windows = vec![win("before-load", 2.25, 2.5)];
        v.push(s);
    }

    // flying starts: the start command comes while the rotor coasts (realistic sensors)
    let mut s = base(
        "flying-start-800",
        "start while the rotor coasts at 800 rpm: the speed search catches it (J = 0.01)",
        3.0,
    );
    realistic_sensors(&mut s);
    s.start = StartSpec {
        at_s: 0.5,
        initial_speed_rpm: 800.0,
    };
    s.speed_profile = vec![sp(0.0, 800.0)];
    s.windows = vec![win("caught", 2.0, 3.0)];
    v.push(s);

    let mut s = base(
        "flying-start-reverse",
        "start while a 10x inertia coasts at -1000 rpm, then reverse to +500 rpm",
        5.0,
    );
    realistic_sensors(&mut s);
    s.plant.inertia_kgm2 = 0.1;
    s.controller.inertia_kgm2 = 0.1;
    s.start = StartSpec {
        at_s: 0.5,
        initial_speed_rpm: -1000.0,
    };
    s.speed_profile = vec![sp(0.0, 500.0)];
    s.windows = vec![win("reversed", 4.5, 5.0)];
    v.push(s);

    // the whole speed range: field weakening up to 2x the nameplate speed
    let mut s = fw_base(
        "fw-ramp-3000",
        "field weakening: ramp 0 -> 3000 rpm with a 1 N m passive load",
        12.0,
    );
    s.speed_profile = vec![sp(0.5, 3000.0)];
    s.load_profile = vec![load(0.0, LoadKind::Passive, 1.0)];
    s.windows = vec![win("steady", 10.0, 12.0)];
    v.push(s);

    let mut s = fw_base(
        "fw-reversal-3000",
        "field weakening: reversal +3000 -> -3000 rpm, no load",
        24.0,
    );
    s.speed_profile = vec![sp(0.5, 3000.0), sp(9.0, -3000.0)];
    s.windows = vec![win("forward", 7.5, 9.0), win("reverse", 22.0, 24.0)];
    v.push(s);

    let mut s = fw_base(
        "fw-load-step-2500",
        "field weakening: 2500 rpm, passive load step to 0.8 N m at 8 s (with friction about 90 % of the torque held there)",
        14.0,
    );
    s.speed_profile = vec![sp(0.5, 2500.0)];
    s.load_profile = vec![load(8.0, LoadKind::Passive, 0.8)];
    s.windows = vec![win("no-load", 6.5, 8.0), win("load", 11.0, 14.0)];
    v.push(s);

    let mut s = fw_base(
        "fw-ripple-2500",
        "field weakening at 2500 rpm, 0.5 N m, bus ripple +/-10 % at 100 Hz",
        10.0,
    );
    s.speed_profile = vec![sp(0.5, 2500.0)];
    s.load_profile = vec![load(0.0, LoadKind::Passive, 0.5)];
    s.dc_link.ripple_fraction = 0.1;
    s.windows = vec![win("steady", 8.0, 10.0)];
    v.push(s);

    let mut s = fw_base(
        "fw-sag-3000",
        "3000 rpm target, 1 N m; bus sags 325 -> 260 V at 9 s: reachable speed held, reported",
        14.0,
    );
    s.speed_profile = vec![sp(0.5, 3000.0)];
    s.load_profile = vec![load(0.0, LoadKind::Passive, 1.0)];
    s.faults.bus_sag_at_s = Some(9.0);
    s.faults.bus_sag_to_v = 260.0;
    s.windows = vec![win("325 V", 7.5, 9.0), win("260 V", 12.0, 14.0)];
    v.push(s);

    let mut s = fw_base(
        "fw-unreachable-3200",
        "target 3200 rpm with a 1.2 N m load: held at the reachable speed and reported",
        12.0,
    );
    s.speed_profile = vec![sp(0.5, 3200.0)];
    s.load_profile = vec![load(0.0, LoadKind::Passive, 1.2)];
    s.windows = vec![win("held", 10.0, 12.0)];
    v.push(s);

    let mut s = fw_base(
        "fw-braking-3000",
        "braking 3000 -> 0 rpm at 2000 rpm/s on a 470 uF link, no chopper: over-voltage control",
        15.0,
    );
    s.dc_link.capacitance_f = 470e-6;
    s.drive.field_weakening.overvoltage_control = true;
    s.speed_profile = vec![sp(0.5, 3000.0), sp(8.0, 0.0)];
    // up and down at 2000 rpm/s where the torque allows: up, the reference is held at
    // the torque limit in field weakening; down, the over-voltage control limits the
    // braking torque to the losses and the reference is held with the speed (stopped
    // at about 13.3 s)
    s.drive.loops.speed_ramp_rpm_s = 2000.0;
    // the "stopped" window measures the drive holding zero with the flux on after the
    // braking: `hold`, not the default `stop` (which switches off 0.5 s after zero)
    s.drive.zero_speed.policy = ZeroSpeed::Hold;
    s.windows = vec![win("top", 6.5, 8.0), win("stopped", 14.0, 15.0)];
    v.push(s);

    // the 2.2 kW machine of ../shared/machines/motulator-2k2.toml from its nameplate on
    // its 540 V board, up to 2x its 1500 rpm base speed
    let mut s = fw_2k2(
        "fw-2k2-reversal-3000",
        "2.2 kW machine, 540 V: reversal +3000 -> -3000 rpm (2x base speed), no load",
        24.0,
    );
    s.speed_profile = vec![sp(0.5, 3000.0), sp(8.0, -3000.0)];
    // the ramp reaches 3000 rpm at 6.95 s (speed control from 0.98 s): forward from 7.5 s
    s.windows = vec![win("forward", 7.5, 8.0), win("reverse", 22.0, 24.0)];
    v.push(s);

    let mut s = fw_2k2(
        "fw-2k2-braking-3000",
        "2.2 kW machine, 540 V: braking 3000 -> 0 rpm on a 470 uF link, over-voltage control",
        16.0,
    );
    s.dc_link.capacitance_f = 470e-6;
    s.drive.field_weakening.overvoltage_control = true;
    s.speed_profile = vec![sp(0.5, 3000.0), sp(8.0, 0.0)];
    // held at zero after the braking as published (the default `stop` would switch off)
    s.drive.zero_speed.policy = ZeroSpeed::Hold;
    s.windows = vec![win("top", 7.5, 8.0)];
    v.push(s);

    // the injected faults the supervision must trip on (docs/faults.md); the other fault-*
    // scenarios are held, and say so by their verdict
    for sc in v
        .iter_mut()
        .filter(|s| EXPECTED_TRIPS.contains(&s.name.as_str()))
    {
        sc.expected = Some(crate::scenario::Expected {
            verdict: crate::metrics::Verdict::Faulted,
            why: "the injected faults, each tripped with its reason, see docs/faults.md".into(),
        });
    }
    v
}

/// The 2.2 kW machine (motulator's example, `../shared/machines/motulator-2k2.toml`, the
/// exact T-model of its inverse-Gamma data) from its nameplate on a 540 V board, with
/// the over-speed trip at 3600 rpm (the nameplate's 500 rpm/s ramp).
fn fw_2k2(name: &str, description: &str, duration_s: f32) -> Scenario {
    use crate::scenario::{BoardSpec, MachineSpec, NameplateSpec};
    let mut s = fw_base(name, description, duration_s);
    let plant = MachineSpec {
        rs_ohm: 3.7,
        rr_ohm: 2.296_875,
        ls_h: 0.245,
        lr_h: 0.245,
        lm_h: 0.234_265,
        pole_pairs: 2,
        inertia_kgm2: 0.015,
        friction_nms: 0.002,
    };
    s.plant = plant;
    s.controller = plant;
    s.nameplate = Some(NameplateSpec {
        power_w: 2200.0,
        voltage_v: 400.0,
        current_a: 5.0,
        frequency_hz: 50.0,
        speed_rpm: None,
        power_factor: None,
        pole_pairs: Some(2),
        torque_nm: Some(14.6),
    });
    s.board = Some(BoardSpec {
        dc_bus_v: 540.0,
        current_full_scale_a: 20.0,
        bus_full_scale_v: None,
        pwm_frequency_hz: None,
    });
    s.sensors.noise_a = 0.02;
    s
}

/// The fault scenarios whose injected fault must end in a trip (docs/faults.md lists the
/// reason each gives).
const EXPECTED_TRIPS: &[&str] = &[
    "fault-bus-sag",
    "fault-locked-rotor",
    "fault-nan-sample",
    "fault-offset-drift",
    "fault-offset-drift-running",
    "fault-open-phase",
    "fault-overhauling-500-12nm",
    "fault-overvoltage-braking",
    "fault-sensor-stuck",
    "fault-sensor-stuck-3shunt",
    "fault-sensors-zero",
    "fault-sensors-zero-at-start",
    "fault-short",
];

/// Why a trapezoid through zero drifts at its zero hold: with the reference held at 0 the
/// stator frequency is zero, where no current-based estimator sees the rotor (the
/// paper's own limit; docs/robustness.md, "Zero speed").
fn zero_speed_drift() -> crate::scenario::Expected {
    crate::scenario::Expected {
        verdict: crate::metrics::Verdict::Drifting,
        why: "at a held zero reference the stator frequency is 0 and the rotor unobservable, \
              see docs/robustness.md"
            .into(),
    }
}

/// The common base of the field-weakening cases: the paper machine on 325 V
/// with the over-speed trip at 3600 rpm (targets up to 3240 rpm).
fn fw_base(name: &str, description: &str, duration_s: f32) -> Scenario {
    let mut s = base(name, description, duration_s);
    s.drive.limits.max_speed_rpm = Some(3600.0);
    s.csv_decimation = Some(10);
    s
}

/// The built-in scenario called `name`.
pub fn get(name: &str) -> Option<Scenario> {
    all().into_iter().find(|s| s.name == name)
}

/// Names of the paper-figure scenarios (the main job).
pub fn paper_names() -> Vec<String> {
    all()
        .into_iter()
        .map(|s| s.name)
        .filter(|n| n.starts_with("paper-"))
        .collect()
}
