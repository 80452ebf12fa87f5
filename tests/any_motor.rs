//! Any motor: each acceptance machine
//! (`crates/acim-sim/machines/`) is commissioned from its nameplate and board alone
//! against its plant (realistic sensors and inverter), the drive is built from the
//! identified model only, and it runs the acceptance scenarios closed loop
//! (`acim_sim::machines`). Acceptance: no fault, steady speed-estimation error and speed
//! error at most 1 % of rated speed in every window.

use acim_sim::machines::{prepare, MACHINES};

fn accept(which: usize) {
    for m in MACHINES.iter() {
        let (_, scenarios, rated_rpm) = prepare(m).unwrap_or_else(|e| panic!("{e}"));
        let sc = &scenarios[which];
        let (_, r) = acim_sim::run_with_metrics(sc).unwrap();
        assert_eq!(
            r.fault, None,
            "{}: {:?} at {:?}",
            sc.name, r.fault, r.fault_time_s
        );
        for (w, wm) in &r.windows {
            let bound = 0.01 * rated_rpm;
            assert!(
                wm.speed_est_err_max_rpm <= bound && wm.speed_err_max_rpm <= bound,
                "{} {w}: estimate {} / speed {} rpm off (1 % of rated is {bound})",
                sc.name,
                wm.speed_est_err_max_rpm,
                wm.speed_err_max_rpm
            );
        }
    }
}

/// Start to 1/3 rated speed, a rated-load step (held), the load off, a reversal.
#[test]
fn start_rated_load_step_and_reversal() {
    // TI's bare rotor (J = 0.001 kg m^2, 3 300 rad/s^2 at rated torque) included: its
    // speed loop follows its mechanical start time (`acim::nameplate::RATED_STEP_DIP`)
    accept(0);
}

/// A trapezoid at 3 % of the rated speed.
#[test]
fn trapezoid_at_3_percent_of_rated_speed() {
    accept(1);
}

/// Regeneration: an overhauling load of 70 % rated torque at 1/3 rated speed.
#[test]
fn regeneration_at_70_percent_rated_torque() {
    accept(2);
}
