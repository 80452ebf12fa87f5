//! Host simulator for the `acim` drive: scenarios, the closed loop against the `acim-plant`
//! motor model, metrics, CSV/JSON output and paper-style plots.

pub mod builtins;
pub mod faults;
pub mod metrics;
pub mod observers;
pub mod output;
pub mod plot;
pub mod scenario;
pub mod sim;
pub mod stability;

use std::path::Path;

/// Runs a scenario and computes its metrics (wall time included).
pub fn run_with_metrics(
    sc: &scenario::Scenario,
) -> Result<(sim::RunResult, metrics::Metrics), scenario::ScenarioError> {
    let t0 = std::time::Instant::now();
    let r = sim::run(sc)?;
    let wall = t0.elapsed().as_secs_f64();
    let m = metrics::compute(&r, wall);
    Ok((r, m))
}

/// Runs a scenario and writes `<out>/<name>.csv`, `.json` and `.png`.
pub fn run_and_write(
    sc: &scenario::Scenario,
    out: &Path,
) -> Result<metrics::Metrics, Box<dyn std::error::Error>> {
    let (r, m) = run_with_metrics(sc)?;
    std::fs::create_dir_all(out)?;
    output::write_csv(&out.join(format!("{}.csv", sc.name)), &r)?;
    output::write_json(&out.join(format!("{}.json", sc.name)), &m)?;
    output::write_png(&out.join(format!("{}.png", sc.name)), &r)?;
    Ok(m)
}
