//! The reduced-order flux observer (`acim::flux_observer`, `drive.observer = "flux"`) in
//! the closed loop on motulator's 2.2 kW machine configured from its nameplate, ideal
//! plant and sensors, as in the side-by-side benchmark (`benches/peer/`): the cases where
//! the paper's observer needs its regeneration limit or loses the rotor (rated-load
//! steps at low speed, regenerating loads at 15-45 rpm with no limit at all), and the
//! controller's parameter errors of the benchmark.

use acim_sim::sim::Row;
use acim_tests::peer::{excursion, profiles, run, scenario};

/// Rated torque of the machine, N m.
const RATED_NM: f32 = 14.6;

/// The benchmark's case with the flux observer and `extra` TOML (e.g. a `[controller]`).
fn flux(name: &str, duration_s: f32, profiles: &str, extra: &str) -> Vec<Row> {
    let sc = scenario(name, duration_s, &format!("{profiles}{extra}"))
        .with_overrides(&["drive.observer=\"flux\"".to_string()])
        .unwrap();
    let (rows, m) = run(&sc);
    assert_eq!(m.fault, None, "{name}");
    rows
}

/// Largest |speed - target| over the last second, rpm.
fn last_second_error(rows: &[Row], target: f32) -> f32 {
    let end = rows.last().unwrap().t_s;
    rows.iter()
        .filter(|r| r.t_s >= end - 1.0)
        .map(|r| (r.speed_rpm - target).abs())
        .fold(0.0, f32::max)
}

/// The controller's model with L_M, R_R and Rs scaled (inverse-Gamma data of the machine
/// file, written as a T model with Lr = Lm).
fn controller(l_m: f32, r_r: f32, r_s: f32) -> String {
    let (l_m, l_s) = (0.224 * l_m, 0.021);
    format!(
        "[controller]\nrs_ohm = {}\nrr_ohm = {}\nls_h = {}\nlr_h = {l_m}\nlm_h = {l_m}\n\
         pole_pairs = 2\ninertia_kgm2 = 0.015\nfriction_nms = 0.0\n",
        3.7 * r_s,
        2.1 * r_r,
        l_m + l_s
    )
}

/// A rated-load step at 750, 75 and 30 rpm: at 750 rpm the dip at most 151 rpm and back
/// within 1 % in 0.18 s (the peer's figures; measured 83 rpm and 0.05 s); at 75 and 30
/// rpm, where the step throws the paper's observer through w_s = 0 and the rotor runs
/// away, held with a dip under 151 rpm (measured 82 and 82), back within 15 rpm in at
/// most 0.5 s (0.18 and 0.34 s).
#[test]
fn rated_load_steps_are_caught_down_to_30_rpm() {
    for (rpm, back_s) in [(750.0f32, 0.18f32), (75.0, 0.5), (30.0, 0.5)] {
        let rows = flux(
            &format!("step-{rpm}"),
            4.0,
            &profiles(&[(0.2, rpm)], &[(2.5, RATED_NM, 0.0)]),
            "",
        );
        let band = if rpm >= 750.0 { 7.5 } else { 15.0 };
        let (dip, back) = excursion(&rows, 2.5, band);
        assert!(
            dip <= 151.0 && back <= back_s,
            "{rpm} rpm: dip {dip}, back {back} s"
        );
        assert!(last_second_error(&rows, rpm) < 2.0, "{rpm} rpm");
    }
}

/// Regenerating (overhauling) load of 25, 50 and 100 % of rated, ramped in over 4 s at
/// 15 rpm and 45 rpm: the rotor held within 30 rpm of the target over the last second,
/// with no regeneration limit (the flux observer has none) (measured 7, 5, 0.2 rpm off at
/// 15 rpm; 10, 3, 12 at 45 rpm: the running Rs law's small errors near w_s = 0).
#[test]
fn regenerating_loads_are_held_at_low_speed_without_a_limit() {
    for rpm in [15.0f32, 45.0] {
        for frac in [0.25f32, 0.5, 1.0] {
            let rows = flux(
                &format!("regen-{frac}-{rpm}"),
                8.0,
                &profiles(&[(1.2, rpm)], &[(2.0, -frac * RATED_NM, 4.0)]),
                "",
            );
            let err = last_second_error(&rows, rpm);
            assert!(err <= 30.0, "{rpm} rpm, {frac} of rated: {err} rpm off");
            assert!(
                rows.iter().all(|r| !r.speed_target_limited),
                "{rpm} rpm {frac}: limited"
            );
        }
    }
}

/// A reversal +750 -> -750 rpm against half the rated load: within 20 rpm of the ramp
/// (the peer: 18 rpm; measured 3 rpm).
#[test]
fn a_reversal_against_a_load_follows_the_ramp() {
    let rows = flux(
        "reversal",
        6.0,
        &profiles(
            &[(0.2, 750.0), (3.0, -750.0)],
            &[(2.0, 0.5 * RATED_NM, 0.0)],
        ),
        "",
    );
    let (worst, _) = excursion(&rows, 3.0, 0.0);
    assert!(worst <= 20.0, "{worst} rpm");
}

/// The controller's L_M 15 % low and high at 750 rpm, Rs 20 % low and high at 75 rpm,
/// rated load motoring and regenerating: held within 30 rpm (the running Rs law adapts
/// only at low stator frequency, so an inductance error at speed does not pull it to its
/// bound: with the paper's observer the L_M cases trip `EstimatorOutOfRange`). Measured
/// 15-25 rpm off for L_M (the speed error an L_M error leaves in any model-based
/// estimator), under 1 rpm for Rs.
#[test]
fn parameter_errors_are_held() {
    let cases = [
        (750.0f32, controller(0.85, 1.0, 1.0)),
        (750.0, controller(1.15, 1.0, 1.0)),
        (75.0, controller(1.0, 1.0, 0.8)),
        (75.0, controller(1.0, 1.0, 1.2)),
    ];
    for (rpm, ctl) in cases {
        for sign in [1.0f32, -1.0] {
            let rows = flux(
                "err",
                6.0,
                &profiles(&[(1.2, rpm)], &[(3.0, sign * RATED_NM, 1.0)]),
                &ctl,
            );
            let err = last_second_error(&rows, rpm);
            assert!(err <= 31.0, "{rpm} rpm, load {sign}, {ctl}: {err} rpm off");
        }
    }
}

/// A machine file (with `extra`, e.g. a `[controller]`), a speed target and an active
/// load from 3 s, the flux observer; returns the rows (no fault allowed).
fn machine_case(file: &str, extra: &str, rpm: f32, load_nm: f32) -> Vec<Row> {
    let text = format!(
        "name = \"m\"\nduration_s = 8.0\n{file}\n{extra}[[speed_profile]]\nt_s = 0.2\nrpm = {rpm}\n\
         [[load_profile]]\nt_s = 3.0\nkind = \"active\"\ntorque_nm = {load_nm}\n"
    );
    let sc = acim_sim::scenario::Scenario::from_file_text(&text)
        .unwrap()
        .with_overrides(&["drive.observer=\"flux\"".to_string()])
        .unwrap();
    let (rows, m) = run(&sc);
    assert_eq!(m.fault, None, "{extra} {rpm} rpm, {load_nm} N m");
    rows
}

/// The paper machine's controller model with L_M scaled by `k` (its file's inverse-Gamma
/// data, written as a T model with Lr = Lm).
fn paper_controller(k: f32) -> String {
    let l_m = 0.520714 * k;
    format!(
        "[controller]\nrs_ohm = 10.5\nrr_ohm = 7.810714\nls_h = {}\nlr_h = {l_m}\nlm_h = {l_m}\n\
         pole_pairs = 2\ninertia_kgm2 = 0.01\nfriction_nms = 0.002\n",
        l_m + 0.039286
    )
}

/// Inductance errors with the default sensors and inverter (offsets, noise, dead time):
/// the paper's machine at 1200 rpm with 2 N m motoring and regenerating and the
/// controller's L_M 10 % and 15 % low and high (with the paper's observer each trips
/// `CurrentRegulation`, `LossOfControl` or `EstimatorOutOfRange`, its Rs estimate
/// pulled to 5.25 or 14.4 ohm); the saturated 2.2 kW machine run with its file's
/// unsaturated data at a third of rated and at rated load (with the paper's observer
/// the third of rated trips `EstimatorOutOfRange`, Rs_hat at its clamp). Held within
/// 30 rpm, the running Rs estimate within 10 % of the true resistance (measured: within
/// 7 rpm and +5 % on the paper machine, 12 rpm and -2 % on the saturated one).
#[test]
fn inductance_errors_neither_lose_the_rotor_nor_pull_rs() {
    let paper = include_str!("../crates/acim-sim/machines/paper-750w.toml");
    for k in [0.85f32, 0.9, 1.1, 1.15] {
        for load in [2.0f32, -2.0] {
            let rows = machine_case(paper, &paper_controller(k), 1200.0, load);
            let err = last_second_error(&rows, 1200.0);
            let rs = rows.last().unwrap().stator_resistance_est_ohm;
            assert!(err <= 30.0, "paper, L_M x {k}, {load} N m: {err} rpm off");
            assert!(
                (rs / 10.5 - 1.0).abs() <= 0.1,
                "paper, L_M x {k}, {load} N m: Rs_hat {rs}"
            );
        }
    }
    let saturated = include_str!("../crates/acim-sim/machines/motulator-2k2-saturated.toml");
    for load in [RATED_NM / 3.0, -RATED_NM / 3.0, RATED_NM, -RATED_NM] {
        let rows = machine_case(saturated, "", 750.0, load);
        let err = last_second_error(&rows, 750.0);
        let rs = rows.last().unwrap().stator_resistance_est_ohm;
        assert!(err <= 30.0, "saturated, {load} N m: {err} rpm off");
        assert!(
            (rs / 3.7 - 1.0).abs() <= 0.1,
            "saturated, {load} N m: Rs_hat {rs}"
        );
    }
}

/// Field weakening to twice the base speed, the flux observer on the built-in scenarios
/// of the paper's machine (325 V, 3000 rpm) and of the 2.2 kW machine (540 V, 3000 rpm):
/// control kept, no fault, the speed estimate within 4 rpm of the rotor in every window
/// at the control rate (measured 0.6-2.5 rpm at speed, 3.5 rpm held at zero after
/// `fw-braking-3000`; the paper's observer 4.5-17 at speed) and 6 rpm with the 1 kHz
/// slow task, whose hand-over delays the speed loop by about a slow period: on the
/// 2.2 kW machine at 3000 rpm a 12 Hz wobble of the speed loop, 5.1 rpm (1.9 at the
/// control rate; 3.7 with the reference stepped at the tick instead of ramped over the
/// slow period, which made a locked rotor read as a current-sensor fault). Before the
/// adaptation's
/// schedule at high stator frequency (`flux_observer::SENSITIVITY_LIMIT`) and the frame
/// lock (`flux_observer::FRAME_LOCK_FROM`) the 2.2 kW machine held a +-40 rpm limit
/// cycle from 2300 rpm, and on the paper's machine `fw-reversal-3000` and
/// `fw-load-step-2500` tripped `CurrentRegulation`, `fw-sag-3000` and `fw-braking-3000`
/// `LossOfControl`; with the schedule alone the 2.2 kW reversal lost the rotor at 6.3 s
/// (the rotor-flux model's frame lags the speed estimate's error through 1/tau_r).
#[test]
fn field_weakening_to_twice_base_speed() {
    for name in [
        "fw-reversal-3000",
        "fw-load-step-2500",
        "fw-ramp-3000",
        "fw-sag-3000",
        "fw-braking-3000",
        "fw-ripple-2500",
        "fw-unreachable-3200",
        "fw-2k2-reversal-3000",
        "fw-2k2-braking-3000",
    ] {
        for (slow, bound) in [("0.0", 4.0), ("0.001", 6.0)] {
            let slow = format!("drive.loops.slow_period_s={slow}");
            let m = acim_tests::run(name, &["drive.observer=\"flux\"", &slow]);
            assert!(m.fault.is_none() && m.control_kept, "{name}: {:?}", m.fault);
            for (w, r) in &m.windows {
                assert!(r.speed_est_err_max_rpm <= bound, "{name} {slow} {w}: {r:?}");
            }
        }
    }
}
