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
//! `cargo test -p acim-tests --test lockstep -- --nocapture`; after the handover, below):
//! speed estimate 0.20-0.42 rpm, true speed 0.09-0.18 rpm, i_sq* 2.6-4.8 mA, rotor flux
//! 36 uWb in the scenarios with the default sensors; in fig 12 (realistic sensors: ADC
//! steps of 4.9 mA and a switching inverter, estimate jitter of +/-3.6 rpm raw) the two
//! runs' jitter differs sample by sample: speed estimate 0.87 rpm, true speed 0.16 rpm,
//! i_sq* 10 mA. The bounds (0.75 rpm, 0.5 rpm, 5 mA; fig 12: 4 rpm, 1 rpm, 50 mA) were
//! set at about twice the default-sensor figures and 1.3-1.6 times fig 12's as they were
//! measured compared step for step.
//!
//! Transitions. A transition decided by a threshold crossed within rounding (the flux's,
//! the standstill Rs identification's settle gate) may come a few steps apart: in fig 9
//! the two runs reach `Running` 5 steps apart, in regen-120 one. What follows moves with
//! it (a speed ramp moves the reference by its rate times the gap), and an i_sq* switch at a
//! threshold (the regeneration limit at the speed estimate's zero crossing) may come a
//! step apart too: each quantity is compared with the other run's nearest value within
//! the largest transition gap either side (at least one step). The observers then start
//! on different noisy samples, and their start transients differ: over the handover
//! (the first 20 ms of `Running`) fig 9's speed estimates by 0.72 rpm and its i_sq* by
//! 10 mA, regen-120's by 1.07 rpm and 12 mA. The handover has its own bounds, 1.5 rpm and
//! 20 mA; after it, the scenarios' bounds apply (as measured: fig 9 0.42 rpm and 4.8 mA,
//! regen-120 0.30 rpm and 3.5 mA).

use acim_sim::sim::{Row, RunResult};

/// `name` with the suffix `+ff`: the builtin with the two-degree-of-freedom speed loop
/// (`acim::speed_loop`, the load estimate fed forward).
fn run(name: &str, arithmetic: &str) -> RunResult {
    let (builtin, ff) = match name.strip_suffix("+ff") {
        Some(b) => (b, true),
        None => (name, false),
    };
    let mut sets = vec![format!("drive.arithmetic={arithmetic}")];
    if ff {
        sets.push("drive.loops.load_torque_feedforward=true".into());
    }
    let sc = acim_sim::builtins::get(builtin)
        .unwrap()
        .with_overrides(&sets)
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
    /// Steps after the first `Running` step where the speed estimates and the i_sq*
    /// differ most (after the handover).
    speed_est_at: usize,
    i_sq_ref_at: usize,
    /// The same differences over the handover ([`HANDOVER_STEPS`] after the first
    /// `Running` step).
    handover_speed_est_rpm: f32,
    handover_i_sq_ref_a: f32,
}

/// The handover from magnetizing to running: 20 ms. Where the two runs' transitions come
/// a few steps apart (a threshold crossed within rounding: the flux, or the standstill Rs
/// identification's settle gate), their observers start on different noisy samples and
/// their start transients differ for about 5 ms; those steps have their own bounds.
const HANDOVER_STEPS: usize = 100;

fn lockstep(name: &str) -> Worst {
    let (a, b) = (run(name, "f32"), run(name, "fixed"));
    assert_eq!(a.fault, b.fault, "{name}: faults differ");
    let (ta, tb) = (transitions(&a.rows), transitions(&b.rows));
    assert_eq!(
        ta.iter().map(|t| t.1).collect::<Vec<_>>(),
        tb.iter().map(|t| t.1).collect::<Vec<_>>(),
        "{name}: state sequences differ: {ta:?} vs {tb:?}"
    );
    // the largest transition gap (at least a step): the two runs' events that follow a
    // transition (the speed ramp after magnetizing) are that many steps apart
    let mut gap = 1;
    for (x, y) in ta.iter().zip(&tb) {
        gap = gap.max(x.0.abs_diff(y.0));
        // measured: fig 9 5 steps, regen-120 6 (the Rs settle gate after the inverter
        // test at start, whose corrections agree to 0.001 us in the two arithmetics)
        assert!(
            x.0.abs_diff(y.0) <= 10,
            "{name}: transition to state {} at step {} (f32) vs {} (fixed)",
            x.1,
            x.0,
            y.0
        );
    }
    let mut w = Worst::default();
    let running_from = a.rows.iter().position(|r| r.state == 2).unwrap_or(0);
    for (k, (x, y)) in a.rows.iter().zip(&b.rows).enumerate() {
        // both running (the other run's values near this step are compared)
        if x.state != 2 || y.state != 2 {
            continue;
        }
        // a transition that came `gap` steps apart shifts what follows it by as much, and
        // i_sq* switches where a
        // threshold is crossed (the regeneration limit at a zero crossing of the speed
        // estimate), which may come a step apart like a transition: each quantity is
        // compared with the other run's nearest value within the gap either side (at
        // least one step)
        let near = &b.rows[k.saturating_sub(gap)..(k + gap + 1).min(b.rows.len())];
        let nearest = |f: fn(&Row) -> f32| {
            near.iter()
                .map(|z| (f(x) - f(z)).abs())
                .fold(f32::INFINITY, f32::min)
        };
        let since = k - running_from;
        let (d_est, d_i_sq) = (nearest(|r| r.speed_est_rpm), nearest(|r| r.i_sq_ref_a));
        if since < HANDOVER_STEPS {
            w.handover_speed_est_rpm = w.handover_speed_est_rpm.max(d_est);
            w.handover_i_sq_ref_a = w.handover_i_sq_ref_a.max(d_i_sq);
        } else {
            if d_est > w.speed_est_rpm {
                (w.speed_est_rpm, w.speed_est_at) = (d_est, since);
            }
            if d_i_sq > w.i_sq_ref_a {
                (w.i_sq_ref_a, w.i_sq_ref_at) = (d_i_sq, since);
            }
        }
        w.speed_rpm = w.speed_rpm.max(nearest(|r| r.speed_rpm));
        w.flux_wb = w.flux_wb.max(nearest(|r| r.rotor_flux_est));
    }
    w
}

#[test]
fn the_two_arithmetics_run_in_lockstep() {
    // (scenario, speed estimate rpm, true speed rpm, i_sq* A)
    for (name, est, speed, i_sq) in [
        ("paper-fig6", 0.75, 0.5, 0.005),
        ("paper-fig7", 0.75, 0.5, 0.005),
        // the feed-forward passes the observer's load estimate straight into i_sq*
        // (1 / k_t = 0.43 A per N m): the estimates' 0.02-0.03 N m between the
        // arithmetics reach it undamped, and the slow task holds the tick's sample for its
        // period (14.0 mA measured with the 1 kHz slow task, 8.7 at the control rate)
        ("paper-fig7+ff", 0.75, 0.5, 0.016),
        // the magnetizing -> running transitions come 5 steps (fig 9) and a step (regen-120)
        // apart: the handovers differ (module docs; the offsets each run subtracts agree:
        // `acim::fixed` test `idle_offsets_are_compensated_alike_in_both_arithmetics`)
        ("paper-fig9", 0.75, 0.5, 0.005),
        // regenerating at 120 rpm (f_s near 1.5 Hz) the slow task's tick samples of the
        // two estimates, held for a slow period, move the two runs further apart (0.99 rpm,
        // 0.52 rpm and 10.9 mA measured with the 1 kHz slow task; within the other
        // scenarios' bounds at the control rate)
        ("regen-120", 1.25, 0.75, 0.012),
        ("paper-fig12", 4.0, 1.0, 0.05),
    ] {
        let w = lockstep(name);
        println!("{name}: worst per-step difference while running: {w:?}");
        assert!(w.speed_est_rpm < est, "{name}: {w:?}");
        assert!(w.speed_rpm < speed, "{name}: {w:?}");
        assert!(w.i_sq_ref_a < i_sq, "{name}: {w:?}");
        assert!(w.flux_wb < 1e-4, "{name}: {w:?}");
        assert!(w.handover_speed_est_rpm < 1.5, "{name}: {w:?}");
        assert!(w.handover_i_sq_ref_a < 0.02, "{name}: {w:?}");
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
