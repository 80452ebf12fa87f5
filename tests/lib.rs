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

/// Every steady window of `m` keeps control with |speed_est - speed| <= `est_max` rpm
/// and, if given, |speed - ref| <= `speed_max` rpm (maxima of 10 ms moving averages).
pub fn check_windows(m: &Metrics, est_max: f32, speed_max: Option<f32>) {
    assert!(m.control_kept, "{}: control lost: {m:#?}", m.name);
    assert!(!m.windows.is_empty());
    for (name, w) in &m.windows {
        assert!(
            w.speed_est_err_max_rpm <= est_max,
            "{} {name}: |speed_est - speed| = {} rpm > {est_max}",
            m.name,
            w.speed_est_err_max_rpm
        );
        if let Some(s) = speed_max {
            assert!(
                w.speed_err_max_rpm <= s,
                "{} {name}: |speed - ref| = {} rpm > {s}",
                m.name,
                w.speed_err_max_rpm
            );
        }
    }
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

/// motulator's 2.2 kW machine as in the side-by-side benchmark (`benches/peer/`): the
/// machine file with an ideal inverter and ideal sensors, configured from its nameplate.
pub mod peer {
    use acim_sim::scenario::Scenario;
    use acim_sim::sim::Row;

    /// The machine file with an ideal inverter and ideal sensors, and the given profiles.
    pub fn scenario(name: &str, duration_s: f32, profiles: &str) -> Scenario {
        let machine = include_str!("../crates/acim-sim/machines/motulator-2k2.toml");
        let text = format!(
            "name = \"{name}\"\nduration_s = {duration_s}\n{machine}\ncurrent_full_scale_a = 20.0\n\
             [inverter]\ndead_time_s = 0.0\ndevice_drop_v = 0.0\n\
             [sensors]\nnoise_a = 0.0\ngain_error = [0.0, 0.0, 0.0]\noffset_a = [0.0, 0.0, 0.0]\n\
             full_scale_a = 20.0\nadc_bits = 16\n{profiles}"
        );
        Scenario::from_file_text(&text).unwrap_or_else(|e| panic!("{name}: {e}"))
    }

    /// Runs `sc`: every control step's row and the metrics.
    pub fn run(sc: &Scenario) -> (Vec<Row>, acim_sim::metrics::Metrics) {
        let (r, m) = acim_sim::run_with_metrics(sc).unwrap();
        (r.rows, m)
    }

    /// Speed target steps (t, rpm) and active load steps (t, N m; a ramp is ten steps).
    pub fn profiles(speeds: &[(f32, f32)], loads: &[(f32, f32, f32)]) -> String {
        let mut s = String::new();
        for (t, rpm) in speeds {
            s += &format!("[[speed_profile]]\nt_s = {t}\nrpm = {rpm}\n");
        }
        for &(t, nm, ramp_s) in loads {
            let n = if ramp_s > 0.0 { 10 } else { 1 };
            for k in 0..n {
                let tk = t + ramp_s * k as f32 / n as f32;
                let nk = nm * (k + 1) as f32 / n as f32;
                s +=
                    &format!("[[load_profile]]\nt_s = {tk}\nkind = \"active\"\ntorque_nm = {nk}\n");
            }
        }
        s
    }

    /// Largest |reference - speed| from `t0`, and the time after `t0` of the last sample
    /// more than `band` rpm off.
    pub fn excursion(rows: &[Row], t0: f32, band: f32) -> (f32, f32) {
        let after = rows.iter().filter(|r| r.t_s >= t0);
        let peak = after
            .clone()
            .map(|r| (r.speed_ref_rpm - r.speed_rpm).abs())
            .fold(0.0, f32::max);
        let last = after
            .filter(|r| (r.speed_ref_rpm - r.speed_rpm).abs() > band)
            .map(|r| r.t_s)
            .fold(t0, f32::max);
        (peak, last - t0)
    }
}
