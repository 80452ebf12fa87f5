//! The fixed-point drive (`acim::fixed::FixedDrive`, selected with
//! `drive.arithmetic = "fixed"`) closed loop against the motor model: the paper's
//! scenarios at 500, 120 and 60 rpm, the load step and the Rs estimation meet the same
//! acceptance bounds as the f32 drive (`paper_scenarios.rs`) plus a margin, and stay
//! close to the f32 run of the same scenario (same plant, same noise seed).
//!
//! Margin: +0.5 rpm on every speed bound, and at most 0.5 rpm between the two
//! arithmetics' window errors. Measured, the fixed-point run differs from the f32 run by
//! at most 0.08 rpm in these windows (0.24 rpm in regen-60's regenerating window, not
//! bounded here): the per-block differences (module `acim::fixed` tests, 1e-5 to 1e-4
//! pu) are far below the 10 mA sensor noise, which sets the window errors of both. The
//! margin leaves room for the noise realisation to shift by a few samples, not for a
//! systematic degradation (that would show in the f32 comparison first).

use acim_sim::builtins;
use acim_sim::metrics::Metrics;

const MARGIN_RPM: f32 = 0.5;

fn run(name: &str, arithmetic: &str) -> Metrics {
    acim_tests::run(name, &[&format!("drive.arithmetic={arithmetic}")])
}

/// Runs `name` in both arithmetics; checks the fixed-point run against the f32
/// acceptance bounds + margin and against the f32 run itself; returns the fixed run.
fn check(name: &str, est_max: f32, speed_max: Option<f32>) -> Metrics {
    let fx = run(name, "fixed");
    let fl = run(name, "f32");
    assert!(fx.control_kept, "{name}: fixed point lost control: {fx:#?}");
    assert_eq!(fx.windows.len(), fl.windows.len());
    for (w, x) in &fx.windows {
        let f = &fl.windows[w];
        eprintln!(
            "{name} {w}: est err {:.2} (f32 {:.2}) rpm, speed err {:.2} (f32 {:.2}) rpm, orientation {:.2} (f32 {:.2}) deg",
            x.speed_est_err_max_rpm,
            f.speed_est_err_max_rpm,
            x.speed_err_max_rpm,
            f.speed_err_max_rpm,
            x.orientation_err_max_deg,
            f.orientation_err_max_deg
        );
        assert!(
            x.speed_est_err_max_rpm <= est_max + MARGIN_RPM,
            "{name} {w}: |speed_est - speed| = {} rpm > {est_max} + {MARGIN_RPM}",
            x.speed_est_err_max_rpm
        );
        if let Some(s) = speed_max {
            assert!(
                x.speed_err_max_rpm <= s + MARGIN_RPM,
                "{name} {w}: |speed - ref| = {} rpm > {s} + {MARGIN_RPM}",
                x.speed_err_max_rpm
            );
        }
        assert!(
            (x.speed_est_err_max_rpm - f.speed_est_err_max_rpm).abs() <= MARGIN_RPM
                && (x.speed_err_max_rpm - f.speed_err_max_rpm).abs() <= MARGIN_RPM,
            "{name} {w}: fixed {x:?} vs f32 {f:?}"
        );
    }
    fx
}

#[test]
fn fixed_fig7_load_step_at_500_rpm() {
    let m = check("paper-fig7", 2.0, Some(2.0));
    acim_tests::assert_load_step_tracked(&m);
}

#[test]
fn fixed_fig9_rs_estimator_converges() {
    let m = check("paper-fig9", 2.0, None);
    let t = m.rs.within_2pct_from_s.expect("Rs never within 2 %");
    assert!(t <= 1.0, "Rs within 2 % of 10.5 ohm only from {t} s");
    assert!(
        (m.rs.final_ohm - 10.5).abs() <= 0.02 * 10.5,
        "{}",
        m.rs.final_ohm
    );
}

#[test]
fn fixed_fig10_trapezoid_500_rpm() {
    check("paper-fig10", 2.0, Some(2.0));
}

#[test]
fn fixed_fig11_trapezoid_120_rpm() {
    check("paper-fig11", 4.0, None);
}

#[test]
fn fixed_fig12_trapezoid_60_rpm() {
    check("paper-fig12", 4.0, None);
}

#[test]
fn fixed_fig12_at_60_rpm_with_load() {
    check("paper-fig12-load", 4.0, None);
}

/// Faults switch the fixed-point drive off with the same reason at the same time as the
/// f32 drive (a NaN sample is caught at the simulator boundary), within 2 ms and, for the
/// checks the slow task judges, a slow period more (a crossing between the arithmetics'
/// signals can fall on the next tick: the phase short 2.6 ms apart).
#[test]
fn fixed_faults_switch_off_like_f32() {
    for name in [
        "fault-short",
        "fault-nan-sample",
        "fault-locked-rotor",
        "fault-bus-sag",
    ] {
        let sc = builtins::get(name).unwrap();
        let fx = sc
            .with_overrides(&["drive.arithmetic=fixed".into()])
            .unwrap();
        let a = acim_sim::sim::run(&fx).unwrap();
        let b = acim_sim::sim::run(&sc).unwrap();
        assert!(a.switches_off_at_end, "{name}");
        assert_eq!(a.fault, b.fault, "{name}");
        let (ta, tb) = (a.fault_time_s.unwrap(), b.fault_time_s.unwrap());
        let bound = 0.002 + sc.drive.loops.slow_period_s;
        assert!((ta - tb).abs() <= bound, "{name}: {ta} vs {tb}");
    }
}

#[test]
fn arithmetic_field_is_validated() {
    let sc = builtins::get("vf-ramp")
        .or_else(|| {
            builtins::all()
                .into_iter()
                .find(|s| s.drive.mode == acim_sim::scenario::ControlMode::Vf)
        })
        .expect("a V/f scenario");
    // the fixed-point drive is the same cascade and has V/f too (tests/lockstep.rs runs it)
    sc.with_overrides(&["drive.arithmetic=fixed".into()])
        .unwrap()
        .validate()
        .expect("V/f in fixed point");
    let e = builtins::get("paper-fig7")
        .unwrap()
        .with_overrides(&["drive.arithmetic=double".into()])
        .unwrap_err();
    assert!(e.allowed.contains("arithmetic"), "{e}");
}
