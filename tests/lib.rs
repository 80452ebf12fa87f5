//! Helpers shared by the closed-loop acceptance tests (`paper_scenarios.rs`,
//! `orientation_scenarios.rs`, `fixed_point.rs`, ...).

use acim_sim::builtins;
use acim_sim::metrics::Metrics;

/// Runs the built-in scenario `name` with `--set`-style overrides and returns its metrics.
pub fn run(name: &str, sets: &[&str]) -> Metrics {
    let sc = builtins::get(name).expect("built-in scenario");
    let sets: Vec<String> = sets.iter().map(|s| s.to_string()).collect();
    let sc = sc.with_overrides(&sets).expect("overrides");
    acim_sim::run_with_metrics(&sc).expect("valid scenario").1
}

/// The load-step acceptance of Fig. 7: after the 1.5 N m step, the load estimate is
/// within 0.05 N m of the real load within 0.5 s and the speed back within 5 rpm of the
/// reference within 0.5 s.
pub fn assert_load_step_tracked(m: &Metrics) {
    let step = &m.load_steps[0];
    assert!((step.load_nm - 1.5).abs() < 1e-6, "{step:?}");
    let settle = step.load_est_settle_s.expect("load estimate never settled");
    assert!(
        settle <= 0.5,
        "load estimate within 0.05 N m after {settle} s"
    );
    let rec = step.speed_recovery_s.expect("speed never recovered");
    assert!(rec <= 0.5, "speed back within 5 rpm after {rec} s");
}
