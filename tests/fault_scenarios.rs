//! Fault cases: each ends with the switches off and the right reason reported.

use acim_sim::builtins;

fn check(name: &str, reason: &str, after_s: f32, within_s: f32) {
    check_scenario(&builtins::get(name).unwrap(), reason, after_s, within_s);
}

fn check_scenario(sc: &acim_sim::scenario::Scenario, reason: &str, after_s: f32, within_s: f32) {
    check_one_of(sc, &[reason], after_s, within_s);
}

/// The run faults with one of `reasons` within `within_s` of `after_s` and stays off.
fn check_one_of(
    sc: &acim_sim::scenario::Scenario,
    reasons: &[&str],
    after_s: f32,
    within_s: f32,
) -> acim_sim::metrics::Metrics {
    let name = &sc.name;
    let (r, m) = acim_sim::run_with_metrics(sc).unwrap();
    assert!(
        reasons.contains(&m.fault.as_deref().unwrap_or("none")),
        "{name}: {m:#?}"
    );
    let t = m.fault_time_s.unwrap();
    assert!(
        t >= after_s && t <= after_s + within_s,
        "{name}: fault at {t} s, expected in [{after_s}, {}]",
        after_s + within_s
    );
    assert!(m.switches_off_at_end);
    // switches off from the fault step on, every step; a fault the slow task finds (after
    // the period's output was computed, `acim::Drive::run_slow`) from the next period
    let after = r.rows.iter().skip_while(|row| row.t_s < t);
    let slow_task = sc.drive.loops.slow_period_s > 0.0;
    let mut rows = after.clone().skip(usize::from(slow_task));
    assert!(rows.all(|row| !row.pwm_enabled && row.state == 4), "{name}");
    assert!(after.clone().all(|row| row.state == 4), "{name}");
    m
}

/// A phase-a low-side switch failing short at 500 rpm. Which estimate-independent
/// detector fires first depends on where in the electrical period the short comes: the
/// over-current trip when the current it drives adds to the phase's, the model residual
/// (`LossOfControl`) or the current regulation otherwise (with the builtin's instant,
/// 3.0 s: `CurrentRegulation` after 11 ms since the inverter test at start ships on;
/// `OverCurrent` after 5 ms before it, when the rotor reached that instant at another
/// angle). Swept over one electrical period (60 ms at 500 rpm) in 5 ms steps: every
/// instant trips within 20 ms (measured: 5-15 ms; the open phase's bound) and never
/// switches beyond the trip current for more than the required 5 ms. Where the short's
/// current crosses the trip between two samples, the plant's hardware comparator (at the
/// trip level) opens the switches first and the drive reports `HardwareBreak`: the
/// over-current kind of instant.
#[test]
fn phase_short_trips_at_any_instant_of_the_period() {
    let mut names = Vec::new();
    for k in 0..12 {
        let at = 3.0 + 0.005 * k as f32;
        let mut sc = builtins::get("fault-short").unwrap();
        sc.faults.phase_short_at_s = Some(at);
        sc.name = format!("fault-short-{at:.3}");
        let m = check_one_of(
            &sc,
            &[
                "OverCurrent",
                "HardwareBreak",
                "LossOfControl",
                "CurrentRegulation",
            ],
            at,
            0.02,
        );
        assert!(m.switching_beyond_limits_s <= 0.005, "{}: {m:#?}", sc.name);
        names.push(m.fault.unwrap_or_default());
    }
    // both kinds of instant occur over the period
    assert!(
        names
            .iter()
            .any(|n| n == "OverCurrent" || n == "HardwareBreak"),
        "{names:?}"
    );
    assert!(names.iter().any(|n| n == "LossOfControl"), "{names:?}");
}

#[test]
fn bus_sag_trips_on_under_voltage() {
    check("fault-bus-sag", "DcBusUnderVoltage", 3.0, 1.0);
}

#[test]
fn braking_without_chopper_trips_on_over_voltage() {
    check("fault-overvoltage-braking", "DcBusOverVoltage", 2.5, 1.0);
}

#[test]
fn locked_rotor_trips_on_stall() {
    check("fault-locked-rotor", "Stall", 3.0, 1.2);
}

#[test]
fn nan_sample_trips_at_once() {
    check("fault-nan-sample", "NonFiniteInput", 3.0, 0.0002);
}

// Faults judged without trusting the estimates. Bounds: the detection time
// measured with `cargo run --release -p acim-sim -- run <name>` plus margin, and the
// the safety bound: never switching with a true phase current beyond the trip
// or the true speed beyond 110 % of max_speed for more than 5 ms.

fn check_safe(name: &str) {
    let sc = builtins::get(name).unwrap();
    let (_, m) = acim_sim::run_with_metrics(&sc).unwrap();
    assert!(
        m.switching_beyond_limits_s <= 0.005,
        "{name}: switched {} s beyond the current trip or 110 % speed",
        m.switching_beyond_limits_s
    );
}

#[test]
fn open_phase_trips_within_20_ms() {
    check("fault-open-phase", "LossOfControl", 3.0, 0.02);
    check_safe("fault-open-phase");
}

/// The built-in without the plant's hardware comparator: what the drive's own checks find.
fn software_only(name: &str) -> acim_sim::scenario::Scenario {
    let mut sc = builtins::get(name).unwrap();
    sc.inverter.hardware_trip = false;
    sc
}

#[test]
fn stuck_channel_with_two_shunts_trips_within_30_ms() {
    // the sensor check finds the still channel within two of its 1.6 ms windows, judged
    // by the slow task up to one slow period later, with or without the hardware
    // comparator
    let bound = 0.0032 + acim::design::TYPICAL_SLOW_PERIOD;
    check_scenario(
        &software_only("fault-sensor-stuck"),
        "CurrentSensor",
        3.0,
        bound,
    );
    check("fault-sensor-stuck", "CurrentSensor", 3.0, bound);
    check_safe("fault-sensor-stuck");
    // without it the drive's other checks alone (the true current reaches 7.8 A)
    let mut sc = software_only("fault-sensor-stuck");
    sc.drive.limits.sensor_check = false;
    check_scenario(&sc, "LossOfControl", 3.0, 0.03);
    // and with the comparator the true current crosses the trip level first
    let mut sc = builtins::get("fault-sensor-stuck").unwrap();
    sc.drive.limits.sensor_check = false;
    check_scenario(&sc, "HardwareBreak", 3.0, 0.03);
}

#[test]
fn stuck_channel_with_three_shunts_trips_on_the_current_sum() {
    check("fault-sensor-stuck-3shunt", "CurrentSensor", 3.0, 0.02);
    check_safe("fault-sensor-stuck-3shunt");
}

#[test]
fn dead_current_sensing_trips_within_10_ms() {
    // the sensor check: every channel still within two of its 1.6 ms windows
    check_scenario(
        &software_only("fault-sensors-zero"),
        "CurrentSensor",
        3.0,
        0.0032,
    );
    check("fault-sensors-zero", "CurrentSensor", 3.0, 0.0032);
    check_safe("fault-sensors-zero");
    // without it, the control monitor alone
    let mut sc = software_only("fault-sensors-zero");
    sc.drive.limits.sensor_check = false;
    check_scenario(&sc, "NoCurrentResponse", 3.0, 0.01);
    // and with the hardware comparator the true current reaches the trip level first
    let mut sc = builtins::get("fault-sensors-zero").unwrap();
    sc.drive.limits.sensor_check = false;
    check_scenario(&sc, "HardwareBreak", 3.0, 0.01);
}

#[test]
fn dead_current_sensing_at_power_up_does_not_hang_in_magnetizing() {
    check("fault-sensors-zero-at-start", "CurrentSensor", 0.0, 0.0032);
    check_safe("fault-sensors-zero-at-start");
    let mut sc = builtins::get("fault-sensors-zero-at-start").unwrap();
    sc.drive.limits.sensor_check = false;
    check_scenario(&sc, "NoCurrentResponse", 0.0, 0.01);
}

#[test]
fn drifting_offset_ends_in_a_fault_not_a_runaway() {
    // the drift starts with the run (no idle offset to check at the start). The default
    // drive identifies Rs at standstill first: the current loop holds the measured d-axis
    // current, so the true one falls by the offset, and the drifting offset reads as a
    // falling resistance until the estimate reaches its lower bound (0.5 Rs) while
    // magnetizing (1.54 s; 1.49 s without the inverter test at start, which reads part
    // of the drift as inverter error and as resistance, from which the identification
    // starts after it)
    check("fault-offset-drift", "EstimatorOutOfRange", 1.0, 0.6);
    check_safe("fault-offset-drift");
    // without the Rs estimator the running check finds the DC component once the stator
    // frequency makes the current AC (about 1.05 s into the ramp) and within its 2 s
    // mean's rise to the limit: the check does not depend on the Rs estimate
    let mut sc = builtins::get("fault-offset-drift").unwrap();
    sc.drive.estimation.rs_estimation = false;
    check_scenario(&sc, "CurrentSensor", 1.0, 1.2);
}

/// Item 3 of an offset drifting beyond the limit while running (0.3 A over
/// 10 s from 2 s; the limit, 0.16 A, is crossed at 7.33 s) is followed by the running
/// offset tracker (about 0.8 s behind at 0.03 A/s, its 1 s time constant) until its
/// estimate reaches the limit: `CurrentSensor`. Without the tracker the 2 s mean of the
/// measured alpha-beta current does not see it: the current loops regulate the measured
/// current, so its DC part stays near zero while the true current carries the offset
/// (docs/robustness.md, item 3).
#[test]
fn an_offset_drifting_beyond_the_limit_while_running_is_found() {
    check("fault-offset-drift-running", "CurrentSensor", 7.33, 1.5);
    check_safe("fault-offset-drift-running");
    // without the tracker the offset's torque ripple swings the speed estimate around
    // the reference: the limit-cycle check faults it (measured 11.8 s, 4.4 s after the
    // offset crossed the limit)
    let mut sc = builtins::get("fault-offset-drift-running").unwrap();
    sc.drive.trackers.offset_tracking = false;
    check_scenario(&sc, "SpeedOscillation", 7.0, 5.0);
    // with neither, only the running offset check on the measured current's 2 s mean
    // is left, which the current loops keep near zero: at the control rate nothing finds
    // it; with the 1 kHz slow task that check finds it at 11.8 s, 4.5 s after the
    // crossing (never another reason)
    sc.drive.limits.speed_oscillation_check = false;
    let (_, m) = acim_sim::run_with_metrics(&sc).unwrap();
    assert!(
        m.fault.is_none()
            || (m.fault.as_deref() == Some("CurrentSensor") && m.fault_time_s > Some(7.33)),
        "{m:#?}"
    );
    sc.drive.loops.slow_period_s = 0.0;
    let (_, m) = acim_sim::run_with_metrics(&sc).unwrap();
    assert_eq!(m.fault, None, "{m:#?}");
}

/// Overhauling loads within the torque capability (about 10 N m at the current limit)
/// are held at 500 rpm with the orientation gain derived from the current limit.
#[test]
fn overhauling_loads_within_capability_are_held_at_500_rpm() {
    for name in ["fault-overhauling-500-5nm", "fault-overhauling-500-8nm"] {
        let sc = builtins::get(name).unwrap();
        let (r, m) = acim_sim::run_with_metrics(&sc).unwrap();
        assert_eq!(m.fault, None, "{name}");
        let end = r.rows.iter().filter(|row| row.t_s > 4.5);
        let worst = end.fold(0.0f32, |w, row| {
            w.max((row.speed_rpm - row.speed_ref_rpm).abs())
        });
        assert!(worst < 5.0, "{name}: speed error {worst} rpm at the end");
    }
}

/// Beyond the torque capability (12 N m against about 10 N m at the current limit) the
/// drive faults cleanly within 0.3 s (5 speed-loop time constants plus the ramp-in),
/// before the machine leaves the speed range.
#[test]
fn overhauling_load_beyond_capability_faults_as_overload() {
    check("fault-overhauling-500-12nm", "Overload", 2.5, 0.3);
    check_safe("fault-overhauling-500-12nm");
}

/// At 120 rpm an 8 N m overhauling load puts the regenerating stator frequency at -1.42
/// Hz, across the line w_s = 0 where no fundamental-model estimator sees the rotor (the
/// estimate settles at the slip, DC stator currents fitting any rotor speed, while the
/// rotor runs away). The load step throws the rotor to 359 rpm; by default the drive
/// brakes it back through the line to the far side (the far-side mode) and holds it
/// near 120 rpm (how well: below). Without the far-side mode the regeneration
/// limit (1.5 Hz) keeps the operating point off the line: the load raises the speed to
/// where the braking torque it allows balances the load (209 rpm measured), held and
/// reported. With the limit off as well, torque at its limit with |w_s| in the blind band
/// for one rotor time constant is an Overload (`Supervisor::blind`), before the machine
/// leaves the speed range (it used to run 21 ms above 110 % of the speed limit).
///
/// The far-side hold with the paper's observer is marginal (asserted: no fault, the
/// machine within its speed range, the target not limited; the recovery is not asserted,
/// the swing below decides it). Back within 5 rpm of the target after the step (measured over the scenario's 5 s): 2.05 s with the running
/// offset tracker off, at the control rate or with the 1 kHz slow task; with the tracker
/// on (the default), 2.47 s with the slow task and not at all at the control rate, where
/// a swing at the stator frequency grows (0.64 s before the tracker's floor gate got its
/// least band). Run for 12 s with the tracker on, the swing ends in `SpeedOscillation`
/// at 9.0 s with the slow task and in `Overload` at 7.5 s at the control rate (clean
/// faults, the machine within its speed range); with it off the hold stays within 3 rpm.
/// The tracker's adaptation excites it (at -1.4 Hz its model frequency wobbles across the
/// 1.5 Hz gate; even a frozen 1.6 mA estimate left a 101-137 rpm limit cycle). The flux
/// observer (the nameplate's default) holds the case within 5 rpm with the tracker on.
#[test]
fn overhauling_load_that_would_blind_the_estimator_is_held_or_faults_as_overload() {
    let sc = builtins::get("fault-overhauling-120-8nm").unwrap();
    let (_, m) = acim_sim::run_with_metrics(&sc).unwrap();
    assert_eq!(m.fault, None);
    assert!(m.peak_speed_rpm < 400.0, "{}", m.peak_speed_rpm);
    assert_eq!(m.speed_target_limited_s, 0.0);
    let no_far_side = sc
        .with_overrides(&["drive.estimation.far_side_gain=0.0".to_string()])
        .unwrap();
    let (_, m) = acim_sim::run_with_metrics(&no_far_side).unwrap();
    assert_eq!(m.fault, None);
    assert!(m.speed_target_limited_s > 1.0, "{m:#?}");
    assert!(m.peak_speed_rpm < 400.0, "{}", m.peak_speed_rpm);
    let off = no_far_side
        .with_overrides(&["drive.loops.regen_min_frequency_hz=0.0".to_string()])
        .unwrap();
    let (_, m) = acim_sim::run_with_metrics(&off).unwrap();
    assert_eq!(m.fault.as_deref(), Some("Overload"), "{m:#?}");
    let t = m.fault_time_s.unwrap();
    assert!((2.5..=3.5).contains(&t), "fault at {t} s");
    assert!(m.switching_beyond_limits_s <= 0.005);
}

/// the overhauling-load sweep (`acim_sim::overhauling`, `acim-sim overhauling`,
/// docs/overhauling.md): 0..12 N m at 500, 120 and 60 rpm. Every case is held at its
/// target, held at the reachable speed and reported (the regeneration limit keeps the
/// stator frequency 1.5 Hz on the rotor's side of zero), or faults cleanly; none switches
/// beyond the trip or 110 % of the speed limit for more than 5 ms. At 500 rpm, where the
/// whole range is observable, the capability (about 10.3 N m at the current limit) is
/// held up to 10 N m and 11 and 12 N m are an Overload. Without the regeneration limit
/// (the default before) 6-8 N m at 60 rpm oscillated between 0 and 300 rpm with no fault
/// and 7 N m at 120 rpm ran away to 4 500 rpm while switching (0.4 s beyond 110 %).
#[test]
fn overhauling_sweep_is_held_or_faults_cleanly() {
    use acim_sim::overhauling::{sweep, Outcome};
    let cells = sweep().unwrap();
    for c in &cells {
        assert!(
            c.clean(),
            "{} rpm, {} N m: {:?}, {} s beyond the limits",
            c.rpm,
            c.load_nm,
            c.outcome,
            c.metrics.switching_beyond_limits_s
        );
        assert!(
            c.metrics.peak_current_a < 8.0,
            "{} rpm, {} N m",
            c.rpm,
            c.load_nm
        );
        if c.rpm == 500.0 {
            let held = c.load_nm <= 10.0;
            match &c.outcome {
                Outcome::Held => assert!(held, "{} N m held beyond the capability", c.load_nm),
                Outcome::Fault { reason, .. } => {
                    assert!(!held, "{} N m: {reason}", c.load_nm);
                    assert_eq!(reason, "Overload");
                }
                o => panic!("500 rpm, {} N m: {o:?}", c.load_nm),
            }
        }
        // a limited speed is reported, not silent: above the target, below the limit
        if let Outcome::Limited { speed_rpm } = c.outcome {
            assert!(speed_rpm > c.rpm && speed_rpm < 2000.0, "{speed_rpm}");
        }
    }
}

/// After a fault the speed target is cleared: reset and start do not ramp back to the old
/// target without a new command.
#[test]
fn a_fault_clears_the_speed_target() {
    use acim::{Controller, DriveConfig, DriveInputs, DriveState};
    let mut d = acim::Drive::new(DriveConfig::paper_defaults()).unwrap();
    d.set_speed_target(50.0).unwrap();
    d.start().unwrap();
    d.step(&DriveInputs {
        phase_currents: [f32::NAN, 0.0, 0.0],
        dc_bus: 325.0,
    });
    assert_eq!(d.state(), DriveState::Fault);
    Controller::reset_fault(&mut d).unwrap();
    assert_eq!(Controller::telemetry(&d).speed_reference, 0.0);
    // the restart waits 5 tau_r for the rotor flux to decay (acim::design::DEMAGNETIZE_TAU_R)
    for _ in 0..2000 {
        d.step(&DriveInputs {
            phase_currents: [0.0; 3],
            dc_bus: 325.0,
        });
    }
    d.start().unwrap();
    for _ in 0..10 {
        d.step(&DriveInputs {
            phase_currents: [0.0; 3],
            dc_bus: 325.0,
        });
    }
    assert_eq!(Controller::telemetry(&d).speed_reference, 0.0);
}

/// A current offset drifting into one channel after the start's measurement (0.1-0.16 A,
/// up to the offset tracker's range; 1 s ramp from 4 s), at 60, 120, 250 and 500 rpm,
/// motoring and regenerating (the paper machine, 1-2 N m active load): every case is held
/// (no limit cycle, not lost) or faults with a reason after the drift began
/// (`SpeedOscillation` when the estimate swings around the reference, `CurrentSensor`
/// when the tracker reaches its bound, `LossOfControl`): 14 of 32 held, 18 faulted. None may end in a silent limit cycle, as 0.1-0.2 A did before the limit-cycle
/// check (true speed 45-141 rpm for a 120 rpm target, 20 s, `control kept`).
#[test]
fn drifting_offsets_are_held_or_faulted_never_a_silent_limit_cycle() {
    use acim_sim::metrics::Verdict;
    let mut outcomes = Vec::new();
    for rpm in [60.0f32, 120.0, 250.0, 500.0] {
        for load in [-2.0f32, -1.0, 1.0, 2.0] {
            for offset in [0.1f32, 0.16] {
                let text = format!(
                    "name = \"offset-{rpm}-{load}-{offset}\"\nduration_s = 14.0\ncsv_decimation = 10\n\
                     [sensors]\nnoise_a = 0.01\n\
                     [[speed_profile]]\nt_s = 0.5\nrpm = {rpm}\n\
                     [[load_profile]]\nt_s = 2.5\nkind = \"active\"\ntorque_nm = {load}\n\
                     [faults]\ncurrent_sensor_offset_change_a = [{offset}, 0.0, 0.0]\n\
                     current_sensor_offset_change_at_s = 4.0\n\
                     current_sensor_offset_change_ramp_s = 1.0\n"
                );
                let sc = acim_sim::scenario::Scenario::from_toml(&text).unwrap();
                let (_, m) = acim_sim::run_with_metrics(&sc).unwrap();
                let line = format!(
                    "{rpm} rpm, {load} N m, {offset} A: {:?} {:?}",
                    m.verdict, m.fault
                );
                println!("{line}");
                match (m.verdict, m.fault.as_deref()) {
                    (Verdict::Kept, None) => {}
                    // a fault with its reason (measured: SpeedOscillation in 13 cases,
                    // CurrentSensor in 4, LossOfControl in 1), after the drift began
                    (Verdict::Faulted, Some(_)) if m.fault_time_s.unwrap() > 4.0 => {}
                    _ => outcomes.push(line),
                }
            }
        }
    }
    assert!(outcomes.is_empty(), "{}", outcomes.join("\n"));
}
