//! Flying start: the start command comes while the rotor turns; the
//! speed search measures the rotor speed from the voltage the current loops apply while
//! magnetizing and the drive catches it, instead of braking it with DC or faulting.

use acim_sim::builtins;
use acim_sim::scenario::{Arithmetic, Scenario, SpeedPoint, StartSpec, Window};

/// Runs `sc` and checks: no fault, the search measured the rotor within `tol` (fraction)
/// of the speeds it turned at during the search, speed control started within 0.6 s of the start command, never
/// switching beyond the trip or 110 % speed, and the speed error in the last window.
fn check(sc: &Scenario, tol: f32, window_err_rpm: f32) {
    let name = &sc.name;
    let (r, m) = acim_sim::run_with_metrics(sc).unwrap();
    assert_eq!(m.fault, None, "{name}: {m:#?}");
    let s = m.speed_search.expect("the search ran");
    // the search measures the mean speed over its window, while DC braking slows the
    // rotor: within `tol` of the range the rotor swept from the start to the decision
    let (lo, hi) = r
        .rows
        .iter()
        .filter(|row| row.t_s >= sc.start.at_s && row.t_s <= s.t_s)
        .fold((f32::MAX, f32::MIN), |(lo, hi), row| {
            (lo.min(row.speed_rpm), hi.max(row.speed_rpm))
        });
    let slack = tol * hi.abs().max(lo.abs());
    assert!(
        s.measured_rpm >= lo - slack && s.measured_rpm <= hi + slack,
        "{name}: measured {} rpm, rotor {lo} .. {hi} rpm",
        s.measured_rpm
    );
    let running = r.rows.iter().find(|row| row.state == 2).unwrap().t_s;
    assert!(
        running - sc.start.at_s <= 0.6,
        "{name}: speed control from {running} s"
    );
    assert_eq!(m.switching_beyond_limits_s, 0.0, "{name}");
    assert!(
        m.peak_current_a < 4.67 * 1.1,
        "{name}: {} A",
        m.peak_current_a
    );
    for (w, wm) in &m.windows {
        assert!(
            wm.speed_err_max_rpm <= window_err_rpm,
            "{name} {w}: {} rpm",
            wm.speed_err_max_rpm
        );
    }
}

#[test]
fn builtin_flying_starts_catch_the_rotor() {
    check(&builtins::get("flying-start-800").unwrap(), 0.06, 5.0);
    check(&builtins::get("flying-start-reverse").unwrap(), 0.06, 5.0);
}

/// The acceptance sweep: +/-1000 rpm, 10x inertia (the rotor keeps its speed through
/// the search), both arithmetics, a speed target different from the caught speed.
#[test]
fn catches_any_speed_within_1000_rpm_in_both_arithmetics() {
    sweep(false);
}

/// The same sweep with the inverter test at start on: the search runs
/// first, at the flux current it is designed for, and the test does not begin on a turning
/// rotor. (Before, the test's first level, 0.4 of the flux current, was already applied
/// during the search: at -500 rpm in Q7.24 the search measured -390 rpm of -493 and the
/// drive stalled.)
#[test]
fn catches_any_speed_with_the_inverter_test_on() {
    sweep(true);
}

fn sweep(inverter_identification: bool) {
    for arithmetic in [Arithmetic::F32, Arithmetic::Fixed] {
        for rpm in [-1000.0f32, -500.0, -150.0, 150.0, 500.0, 1000.0] {
            let mut sc = builtins::get("flying-start-800").unwrap();
            sc.drive.start.inverter_identification = inverter_identification;
            sc.name = format!("fly-{rpm}-{arithmetic:?}");
            sc.duration_s = 3.0;
            sc.plant.inertia_kgm2 = 0.1;
            sc.controller.inertia_kgm2 = 0.1;
            sc.drive.arithmetic = arithmetic;
            sc.start = StartSpec {
                at_s: 0.5,
                initial_speed_rpm: rpm,
            };
            let target = 0.7 * rpm;
            sc.speed_profile = vec![SpeedPoint {
                t_s: 0.0,
                rpm: target,
            }];
            sc.windows = vec![Window {
                name: "end".into(),
                from_s: 2.5,
                to_s: 3.0,
            }];
            check(&sc, 0.06, 5.0);
        }
    }
}

/// At rest the search says so: the standstill sequence runs unchanged (the paper
/// scenarios' outputs are byte-identical with the search on).
#[test]
fn at_rest_the_search_reports_standstill() {
    for name in ["paper-fig6", "paper-fig9", "paper-fig12"] {
        let sc = builtins::get(name).unwrap();
        let (_, m) = acim_sim::run_with_metrics(&sc).unwrap();
        let s = m.speed_search.expect("the search ran");
        assert!(s.measured_rpm.abs() < 45.0, "{name}: {s:?}");
        assert!(s.true_rpm.abs() < 1.0, "{name}: {s:?}");
    }
}
