//! The two-rate schedule (`DriveConfig.loops.slow_period`): the speed loop, field
//! weakening and the slow supervision once per slow period, the current loop, the
//! estimators and the fast protections every control period. The paper's scenarios keep
//! their acceptance bounds with a 1 kHz slow task at 5 kHz, and at 10, 20 and 40 kHz (Fig.
//! 12 with the drive's default current-gain calibration: the paper's uncalibrated sensors
//! miss its 60 rpm bound there whatever the schedule); every fault
//! scenario keeps its reason (a switch short: one of the estimate-independent detectors
//! that find it, as at one rate), found no later than one slow period after the
//! single-rate drive finds it. The slow task runs after each tick's output
//! (`Drive::step_fast`, then `Drive::run_slow`), as in the firmware's slow interrupt.

use acim_sim::builtins;

use acim_tests::{assert_load_step_tracked, check_windows, run};

/// A 1 kHz slow task.
const SLOW: &str = "drive.loops.slow_period_s=0.001";
/// The slow period, s.
const SLOW_PERIOD_S: f32 = acim::design::TYPICAL_SLOW_PERIOD;

/// The bounds of `paper_scenarios.rs`, with the speed loop at 1 kHz.
#[test]
fn paper_scenarios_keep_their_bounds_with_a_1_khz_slow_task() {
    for name in ["paper-fig6", "paper-fig7", "paper-fig10"] {
        check_windows(&run(name, &[SLOW]), 2.0, Some(2.0));
    }
    assert_load_step_tracked(&run("paper-fig7", &[SLOW]));
    for name in ["paper-fig11", "paper-fig12", "paper-fig12-load"] {
        check_windows(&run(name, &[SLOW]), 4.0, None);
    }
    let m = run("paper-fig9", &[SLOW]);
    let t = m.rs.within_2pct_from_s.expect("Rs never within 2 %");
    assert!(t <= 1.0, "Rs within 2 % only from {t} s");
    check_windows(&m, 2.0, None);
}

/// The fast rates the G474 runs (10, 20 and 40 kHz PWM and sampling; docs/guide/porting.md,
/// "Rates") under the 1 kHz slow task: the slow tick is one period in ten, twenty and
/// forty, and the paper's scenarios keep the bounds of `paper_scenarios.rs`, but one.
///
/// Fig. 12 (60 rpm, no load) misses its 4 rpm estimation bound at 10 kHz and above with a
/// single rate as well (4.5, 5.3 and 9.7 rpm at 10, 20 and 40 kHz): the dead time's
/// voltage error grows with the PWM rate (`V_dc T_d f`: 2.4 V at 5 kHz, 19.5 V at 40 kHz,
/// against about 20 V of stator voltage at 60 rpm) and what its compensation leaves
/// grows with it; with no dead time in the plant and none compensated the same run holds
/// 1.9 rpm at 40 kHz. There the slow task must not add to it: within 0.5 rpm of the
/// single-rate drive at the same rate. What the compensation leaves comes from the
/// figure's sensors: the shunts' gains differ by 0.6 % and the paper's setup runs without
/// the start-up gain calibration, so the true currents cross zero away from where the
/// reference (on which the compensation switches) predicts; with the calibration on (the
/// drive's default) the figure is within its 4 rpm at every rate (1.7, 1.1 and 1.3 rpm).
#[test]
fn paper_scenarios_at_10_20_and_40_khz_with_a_1_khz_slow_task() {
    for period in ["100e-6", "50e-6", "25e-6"] {
        let rate = format!("drive.loops.control_period_s={period}");
        let o = [rate.as_str(), SLOW];
        for name in ["paper-fig6", "paper-fig7", "paper-fig10"] {
            check_windows(&run(name, &o), 2.0, Some(2.0));
        }
        assert_load_step_tracked(&run("paper-fig7", &o));
        for name in ["paper-fig11", "paper-fig12-load"] {
            check_windows(&run(name, &o), 4.0, None);
        }
        let m = run("paper-fig9", &o);
        let t = m.rs.within_2pct_from_s.expect("Rs never within 2 %");
        assert!(t <= 1.0, "{period}: Rs within 2 % only from {t} s");
        check_windows(&m, 2.0, None);
        let calibrated = [
            rate.as_str(),
            SLOW,
            "drive.start.current_gain_calibration=true",
        ];
        check_windows(&run("paper-fig12", &calibrated), 4.0, None);
        let two = run("paper-fig12", &o);
        let single = run("paper-fig12", &[rate.as_str()]);
        assert!(two.control_kept && single.control_kept, "{period}");
        for (name, w) in &two.windows {
            let s = &single.windows[name];
            assert!(
                w.speed_est_err_max_rpm <= s.speed_est_err_max_rpm + 0.5,
                "{period} paper-fig12 {name}: {} rpm with the slow task, {} without",
                w.speed_est_err_max_rpm,
                s.speed_est_err_max_rpm
            );
        }
    }
}

/// Every `fault-*` scenario with the `--set` overrides `sets`.
fn fault_runs(
    sets: &[String],
) -> Vec<(
    acim_sim::scenario::Scenario,
    Option<f32>,
    acim_sim::metrics::Metrics,
)> {
    acim_sim::faults::run_all_with(sets, &mut |sc| {
        acim_sim::run_with_metrics(sc)
            .map(|r| r.1)
            .map_err(|e| e.to_string())
    })
    .unwrap()
}

/// A switch that fails short is found by whichever estimate-independent detector crosses
/// first, which depends on the instant (`phase_short_trips_at_any_instant_of_the_period`
/// in tests/fault_scenarios.rs).
const SHORT: [&str; 4] = [
    "OverCurrent",
    "HardwareBreak",
    "LossOfControl",
    "CurrentRegulation",
];

/// Every `fault-*` scenario: the same reason with the slow task as without it, found at
/// most one slow period later (the protections of the fast path find it in the same
/// period; the slow ones judge once per slow period, with their times unchanged).
#[test]
fn fault_scenarios_keep_their_reason_and_time_with_a_1_khz_slow_task() {
    let single = fault_runs(&[]);
    let two = fault_runs(&[SLOW.to_string()]);
    assert_eq!(single.len(), two.len());
    assert!(single.len() >= 15, "{} fault scenarios", single.len());
    // a switch that fails short: SHORT (the slow task's one-period shift of the references
    // can move the first crossing from one detector to another)
    for ((sc, _, a), (_, _, b)) in single.iter().zip(&two) {
        let name = &sc.name;
        if name == "fault-short" {
            let found = b.fault.as_deref().unwrap_or_default();
            assert!(SHORT.contains(&found), "{name}: {found}");
        } else {
            assert_eq!(a.fault, b.fault, "{name}");
        }
        assert_eq!(a.switches_off_at_end, b.switches_off_at_end, "{name}");
        if let (Some(ta), Some(tb)) = (a.fault_time_s, b.fault_time_s) {
            assert!(
                tb <= ta + SLOW_PERIOD_S,
                "{name}: found at {tb} s with the slow task, {ta} s without"
            );
        }
    }
}

/// Every `fault-*` scenario at 10, 20 and 40 kHz under the 1 kHz slow task: the reason it
/// has at 5 kHz (a switch short: one of the detectors that find it, as above), and a
/// detection time within the 5 kHz one plus a slow period, or, where the time depends on
/// the instant the fault meets the current's phase, within the scenario's own bound
/// (`tests/fault_scenarios.rs`): a channel stuck near its peak reads near the true
/// current until the phase leaves the peak, which the electrical frequency sets (the
/// sensor check's bound for a stuck channel at 500 rpm, 24 ms; measured 3.2-12.8 ms
/// over the rates), and an open phase or a short is found when the current it disturbs
/// crosses a check (20 ms). The locked rotor was named `CurrentSensor` at 40 kHz before
/// the sensor check asked a standing channel for a second witness after the model broke
/// (`acim::sensor_check`, "The decision").
#[test]
fn fault_scenarios_keep_their_reason_at_10_20_and_40_khz() {
    let base = fault_runs(&[]);
    // the bounds of the faults whose detection time depends on the fault's instant, s
    let own_bound = |name: &str| match name {
        "fault-sensor-stuck" => Some(0.024),
        "fault-sensor-stuck-3shunt" | "fault-open-phase" | "fault-short" => Some(0.02),
        _ => None,
    };
    for period in ["100e-6", "50e-6", "25e-6"] {
        let rows = fault_runs(&[
            format!("drive.loops.control_period_s={period}"),
            SLOW.to_string(),
        ]);
        assert_eq!(base.len(), rows.len());
        for ((sc, at, a), (_, _, b)) in base.iter().zip(&rows) {
            let name = &sc.name;
            if name == "fault-short" {
                let found = b.fault.as_deref().unwrap_or_default();
                assert!(SHORT.contains(&found), "{period} {name}: {found}");
            } else {
                assert_eq!(a.fault, b.fault, "{period} {name}");
            }
            assert_eq!(
                a.switches_off_at_end, b.switches_off_at_end,
                "{period} {name}"
            );
            if let (Some(at), Some(ta), Some(tb)) = (at, a.fault_time_s, b.fault_time_s) {
                let bound = own_bound(name).unwrap_or(ta - at + SLOW_PERIOD_S + 1e-4);
                assert!(
                    tb - at <= bound,
                    "{period} {name}: found after {} ms (at 5 kHz {} ms, bound {} ms)",
                    (tb - at) * 1e3,
                    (ta - at) * 1e3,
                    bound * 1e3
                );
            }
        }
    }
}

/// The built-in scenarios accept the slow period as a scenario key and the drive refuses
/// a slow period outside 0.5-2 ms (0: no slow task) with the field named.
#[test]
fn the_slow_period_is_a_checked_scenario_key() {
    let sc = builtins::get("paper-fig6").unwrap();
    for bad in ["0.0002", "0.003", "-0.001"] {
        let sc = sc
            .with_overrides(&[format!("drive.loops.slow_period_s={bad}")])
            .unwrap();
        let err = acim_sim::run_with_metrics(&sc).unwrap_err().to_string();
        assert!(err.contains("slow_period"), "{bad}: {err}");
    }
}

/// Telemetry recorded at the slow ticks only (`TelemetryRate::SlowTick`, the firmware's
/// choice when it samples the telemetry less often than once per slow period) changes
/// nothing the drive computes: two drives fed the same samples through a start and a
/// loaded ramp give the same duties in every period, bit for bit, and the slow-tick
/// drive's telemetry is the other's at each tick's period (after that period's slow task)
/// and held between ticks.
#[test]
fn telemetry_at_the_slow_ticks_changes_no_output() {
    use acim::math::RPM_TO_RAD_S;
    use acim::{Drive, DriveConfig, DriveInputs, DriveState, TelemetryRate};
    use acim_plant::{LoadTorque, Plant, PwmPreload};
    let cfg = DriveConfig::paper_defaults();
    let ts = cfg.loops.control_period;
    let mut every = Drive::new(cfg).unwrap();
    let mut ticks = Drive::new(cfg).unwrap();
    ticks.set_telemetry_rate(TelemetryRate::SlowTick);
    assert_eq!(ticks.telemetry_rate(), TelemetryRate::SlowTick);
    assert_eq!(every.telemetry_rate(), TelemetryRate::EveryPeriod);
    let mut plant = Plant::paper_default(3);
    let mut pwm = PwmPreload::new();
    for d in [&mut every, &mut ticks] {
        d.start().unwrap();
        d.set_speed_target(300.0 * RPM_TO_RAD_S).unwrap();
    }
    let (mut held, mut recorded) = (0usize, 0usize);
    for k in 0..(1.5 / ts) as usize {
        let t = k as f32 * ts;
        let m = plant.sample();
        let inp = DriveInputs {
            phase_currents: m.phase_currents,
            dc_bus: m.dc_bus,
        };
        let tick = ticks.slow_tick_due();
        let before = *ticks.telemetry();
        let a = every.step(&inp);
        let b = ticks.step(&inp);
        assert_eq!(a, b, "period {k}");
        let running = ticks.state() == DriveState::Running;
        if tick {
            assert_eq!(every.telemetry(), ticks.telemetry(), "tick at period {k}");
            recorded += running as usize;
        } else if running {
            assert_eq!(&before, ticks.telemetry(), "between ticks at period {k}");
            held += 1;
        }
        let torque = if t >= 1.0 { 3.0 } else { 0.0 };
        plant.run_pwm_period(pwm.advance(a), LoadTorque::Passive { torque });
    }
    assert_eq!(every.state(), DriveState::Running);
    // running for about half a second at 5 kHz with a 1 kHz slow task: four periods held
    // after each tick's, give or take the partial slow periods at the handover and the end
    assert!(recorded >= 500, "{recorded} ticks running");
    assert!(
        held.abs_diff(4 * recorded) <= 8,
        "{recorded} ticks, {held} held"
    );
}
