//! Host simulator for the `acim` drive: scenarios, the closed loop against the `acim-plant`
//! motor model, metrics, CSV/JSON output and paper-style plots.

pub mod builtins;
pub mod capability;
pub mod commission;
pub mod faults;
pub mod linear;
pub mod load_steps;
pub mod low_speed;
pub mod machines;
pub mod metrics;
pub mod observers;
pub mod output;
pub mod overhauling;
pub mod plot;
pub mod robustness;
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

/// How a run's files are written.
#[derive(Clone, Copy, Debug, Default)]
pub struct WriteOptions {
    /// Compress the CSV with gzip (`<name>.csv.gz` instead of `<name>.csv`).
    pub gzip_csv: bool,
}

impl WriteOptions {
    /// The CSV file name of scenario `name`.
    pub fn csv_name(&self, name: &str) -> String {
        if self.gzip_csv {
            format!("{name}.csv.gz")
        } else {
            format!("{name}.csv")
        }
    }
}

/// Runs a scenario and writes `<out>/<name>.csv`, `.json` and `.png`.
pub fn run_and_write(
    sc: &scenario::Scenario,
    out: &Path,
) -> Result<metrics::Metrics, Box<dyn std::error::Error>> {
    run_and_write_with(sc, out, WriteOptions::default(), &mut |_, _| {})
}

/// [`run_and_write`] with options and a progress callback (`done`, `total` control steps).
/// The scenario is validated (its name included: it becomes the file names) before
/// anything is written; each file is written atomically.
pub fn run_and_write_with(
    sc: &scenario::Scenario,
    out: &Path,
    opts: WriteOptions,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<metrics::Metrics, Box<dyn std::error::Error>> {
    sc.validate()?;
    let t0 = std::time::Instant::now();
    let r = sim::run_with_progress(sc, progress)?;
    let m = metrics::compute(&r, t0.elapsed().as_secs_f64());
    output::create_dir(out)?;
    output::write_csv_to(&out.join(opts.csv_name(&sc.name)), &r, opts.gzip_csv)?;
    output::write_json(&out.join(format!("{}.json", sc.name)), &m)?;
    output::write_png(&out.join(format!("{}.png", sc.name)), &r)?;
    Ok(m)
}
