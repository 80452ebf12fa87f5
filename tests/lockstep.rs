//! Drive-level lockstep of the two arithmetics (architecture issue): the paper's scenarios
//! run closed loop twice against identical plants (same machine, inverter, sensors and
//! noise seed), once with the f32 drive and once with the fixed-point drive (the same
//! cascade instantiated with Q7.24). Compared step by step: the same sequence of states
//! at the same steps (a transition may move by a few steps where a threshold is crossed
//! within rounding), the same fault, and the trajectories within stated bounds.
//!
//! Bounds. The blocks agree within 1e-5 to 1e-4 pu (`acim::fixed` tests); in the closed
//! loop each drive's differences feed back through the plant, which keeps them bounded.
//! The worst per-step differences while running, as measured (printed by
//! `cargo test -p acim-tests --test lockstep -- --nocapture`): speed estimate 0.23-0.39 rpm,
//! true speed 0.10-0.23 rpm, i_sq* 3.5 mA, rotor flux 40 uWb in the scenarios with the
//! default sensors; in fig 12 (realistic sensors: ADC steps of 4.9 mA and a switching
//! inverter, estimate jitter of +/-3.6 rpm raw) the two runs' jitter differs sample by
//! sample: speed estimate 2.56 rpm, true speed 0.79 rpm, i_sq* 32 mA. The bounds are
//! about twice the default-sensor figures and 1.3-1.6 times fig 12's. Since every start waits for the switches-off offset measurement
//! (the simulator powers the drive 0.1 s before t = 0), regen-120's two runs reach
//! `Running` a step apart and their speed estimates' handover transients differ by
//! 0.90 rpm and their i_sq* by 10 mA: its bounds are 1.5 rpm and 20 mA. A switch of i_sq* at a threshold (the regeneration
//! limit at the speed estimate's zero crossing) is compared with the other run's value
//! one step either side, as a transition may move.

use acim_sim::sim::{Row, RunResult};

fn run(name: &str, arithmetic: &str) -> RunResult {
    let sc = acim_sim::builtins::get(name)
        .unwrap()
        .with_overrides(&[format!("drive.arithmetic={arithmetic}")])
        .unwrap();
    acim_sim::sim::run(&sc).unwrap()
}

/// The steps where the state changes, with the new state.
fn transitions(rows: &[Row]) -> Vec<(usize, u8)> {
    let mut out = vec![(0, rows[0].state)];
    for (k, w) in rows.windows(2).enumerate() {
        if w[1].state != w[0].state {
            out.push((k + 1, w[1].state));
        }
    }
    out
}

#[derive(Default, Debug)]
struct Worst {
    speed_est_rpm: f32,
    speed_rpm: f32,
    i_sq_ref_a: f32,
    flux_wb: f32,
}

fn lockstep(name: &str) -> Worst {
    let (a, b) = (run(name, "f32"), run(name, "fixed"));
    assert_eq!(a.fault, b.fault, "{name}: faults differ");
    let (ta, tb) = (transitions(&a.rows), transitions(&b.rows));
    assert_eq!(
        ta.iter().map(|t| t.1).collect::<Vec<_>>(),
        tb.iter().map(|t| t.1).collect::<Vec<_>>(),
        "{name}: state sequences differ: {ta:?} vs {tb:?}"
    );
    for (x, y) in ta.iter().zip(&tb) {
        assert!(
            x.0.abs_diff(y.0) <= 5,
            "{name}: transition to state {} at step {} (f32) vs {} (fixed)",
            x.1,
            x.0,
            y.0
        );
    }
    let mut w = Worst::default();
    for (k, (x, y)) in a.rows.iter().zip(&b.rows).enumerate() {
        if x.state != 2 || y.state != 2 {
            continue;
        }
        w.speed_est_rpm = w
            .speed_est_rpm
            .max((x.speed_est_rpm - y.speed_est_rpm).abs());
        w.speed_rpm = w.speed_rpm.max((x.speed_rpm - y.speed_rpm).abs());
        // i_sq* switches where a threshold is crossed (the regeneration limit at a zero
        // crossing of the speed estimate): like a state transition, that may come a step
        // apart, so the other run's value one step either side counts too
        let near = b.rows[k.saturating_sub(1)..(k + 2).min(b.rows.len())]
            .iter()
            .map(|z| (x.i_sq_ref_a - z.i_sq_ref_a).abs())
            .fold(f32::INFINITY, f32::min);
        w.i_sq_ref_a = w.i_sq_ref_a.max(near);
        w.flux_wb = w.flux_wb.max((x.rotor_flux_est - y.rotor_flux_est).abs());
    }
    w
}

#[test]
fn the_two_arithmetics_run_in_lockstep() {
    // (scenario, speed estimate rpm, true speed rpm, i_sq* A)
    for (name, est, speed, i_sq) in [
        ("paper-fig6", 0.75, 0.5, 0.005),
        ("paper-fig7", 0.75, 0.5, 0.005),
        ("paper-fig9", 0.75, 0.5, 0.005),
        // the two runs' magnetizing -> running transitions come a step apart here, so the
        // observers start on different noisy samples: their handover transients differ by
        // up to 0.90 rpm and 10 mA of i_sq* for about 5 ms (the offsets each subtracts agree:
        // `acim::fixed` test `idle_offsets_are_compensated_alike_in_both_arithmetics`)
        ("regen-120", 1.5, 0.5, 0.02),
        ("paper-fig12", 4.0, 1.0, 0.05),
    ] {
        let w = lockstep(name);
        println!("{name}: worst per-step difference while running: {w:?}");
        assert!(w.speed_est_rpm < est, "{name}: {w:?}");
        assert!(w.speed_rpm < speed, "{name}: {w:?}");
        assert!(w.i_sq_ref_a < i_sq, "{name}: {w:?}");
        assert!(w.flux_wb < 1e-4, "{name}: {w:?}");
    }
}

#[test]
fn the_two_arithmetics_fault_alike() {
    for name in ["fault-short", "fault-locked-rotor", "fault-nan-sample"] {
        let (a, b) = (run(name, "f32"), run(name, "fixed"));
        assert_eq!(a.fault, b.fault, "{name}");
        let (ta, tb) = (a.fault_time_s.unwrap(), b.fault_time_s.unwrap());
        assert!((ta - tb).abs() <= 0.005, "{name}: {ta} s vs {tb} s");
    }
}

/// The fixed-point drive has the open-loop V/f mode too (the cascade is the same code):
/// the V/f commissioning scenario runs alike in both arithmetics.
#[test]
fn open_loop_vf_runs_alike() {
    let (a, b) = (run("vf-open-loop", "f32"), run("vf-open-loop", "fixed"));
    assert_eq!((a.fault, b.fault), (None, None));
    let worst = a
        .rows
        .iter()
        .zip(&b.rows)
        .map(|(x, y)| (x.speed_rpm - y.speed_rpm).abs())
        .fold(0.0f32, f32::max);
    assert!(worst < 1.0, "true speed differs by {worst} rpm");
    assert!(a.rows.last().unwrap().speed_rpm > 600.0);
}
