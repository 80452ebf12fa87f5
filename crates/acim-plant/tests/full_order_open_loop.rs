//! The full-order (Kubota) baseline observer against the motor model, open loop: fed by
//! a rotating voltage, it converges to the true speed from a wrong initial estimate.
//! (Its closed-loop comparison with the reduced-order observer is
//! `acim-sim observers` and `tests/observer_comparison.rs`.)

use acim::full_order::{FullOrderConfig, FullOrderDesign, FullOrderObserver};
use acim::math::RPM_TO_RAD_S;
use acim::MachineParams;
use acim_plant::{InductionMachine, LoadTorque};

const TS: f32 = 200e-6;

fn cfg(m: &MachineParams) -> FullOrderConfig {
    FullOrderConfig::new(m, FullOrderDesign::paper_defaults(m), TS).unwrap()
}

/// Runs the motor model (RK4, 4 sub-steps per period) fed by a rotating voltage at the
/// synchronous frequency of `rpm`, with the observer starting from `initial_rpm` and
/// zero flux. Returns (true rpm, estimated rpm, worst |error| in rpm over the last
/// `check` seconds).
fn run(rpm: f32, initial_rpm: f32, seconds: f32, check: f32) -> (f32, f32, f32) {
    let m = MachineParams::paper_table1();
    let c = cfg(&m);
    let mut machine = InductionMachine::new(m);
    let speed = rpm * RPM_TO_RAD_S;
    machine.set_speed(speed);
    // zero-slip voltage for 1.5 A magnetising current: |v| = 1.5 |Rs + j w Ls|
    let ws = speed * m.pole_pairs_f32();
    let (r, x) = (m.stator_resistance(), ws * m.stator_inductance());
    let vmag = 1.5 * acim::math::sqrt(r * r + x * x);
    let mut obs = FullOrderObserver::with_speed(&c, initial_rpm * RPM_TO_RAD_S);
    let n = (seconds / TS) as usize;
    let n_check = (check / TS) as usize;
    let mut theta = 0.0f32;
    let mut worst = 0.0f32;
    let mut est = 0.0;
    for k in 0..n {
        let (s, co) = (theta as f64).sin_cos();
        let (va, vb) = (vmag * co as f32, vmag * s as f32);
        let i = machine.current_alpha_beta();
        est = obs.update(&c, va, vb, i.alpha, i.beta) / RPM_TO_RAD_S;
        if k >= n - n_check {
            worst = worst.max((est - machine.speed() / RPM_TO_RAD_S).abs());
        }
        for _ in 0..4 {
            machine.step(va, vb, LoadTorque::None, TS / 4.0);
        }
        theta = acim::math::wrap_angle(theta + ws * TS);
    }
    (machine.speed() / RPM_TO_RAD_S, est, worst)
}

#[test]
fn converges_to_500_rpm_from_standstill_estimate() {
    let (truth, est, worst) = run(500.0, 0.0, 0.8, 0.3);
    assert!((truth - 500.0).abs() < 20.0, "plant at {truth} rpm");
    assert!(
        worst < 3.0,
        "estimate {est} rpm vs {truth} rpm, worst {worst}"
    );
}

#[test]
fn converges_to_60_rpm_from_a_wrong_estimate() {
    let (truth, est, worst) = run(60.0, 300.0, 0.8, 0.3);
    assert!((truth - 60.0).abs() < 10.0, "plant at {truth} rpm");
    assert!(
        worst < 1.0,
        "estimate {est} rpm vs {truth} rpm, worst {worst}"
    );
}
