//! Writing a run: `<name>.csv` (one row per control step, or every `csv_decimation`-th),
//! `<name>.json` (metrics) and `<name>.png` (paper-style panels).

use crate::metrics::Metrics;
use crate::plot::{render_panels, Color, LineStyle, Panel, Series};
use crate::sim::{RunResult, CSV_HEADER};
use std::io::Write;
use std::path::Path;

/// Writes the CSV file.
pub fn write_csv(path: &Path, r: &RunResult) -> std::io::Result<()> {
    let mut f = std::io::BufWriter::new(std::fs::File::create(path)?);
    writeln!(f, "{CSV_HEADER}")?;
    let step = r.scenario.csv_decimation.max(1) as usize;
    for row in r.rows.iter().step_by(step) {
        writeln!(f, "{}", row.csv())?;
    }
    f.flush()
}

/// Writes the metrics JSON file.
pub fn write_json(path: &Path, m: &Metrics) -> std::io::Result<()> {
    let text = serde_json::to_string_pretty(m).map_err(std::io::Error::other)?;
    std::fs::write(path, text + "\n")
}

/// Renders the paper-style figure: speed (reference, real, estimated), speed-estimation
/// error, dq currents, load torque (real and estimated), and Rs estimate when the
/// estimator is on or the controller's Rs differs from the plant's.
pub fn write_png(path: &Path, r: &RunResult) -> Result<(), Box<dyn std::error::Error>> {
    let rows = &r.rows;
    let col = |f: fn(&crate::sim::Row) -> f32| rows.iter().map(f).collect::<Vec<f32>>();
    // the controller's quantities exist only while it runs: after a fault (switches off)
    // they are not drawn (NaN breaks the line) instead of showing the last values
    let ctl = |f: fn(&crate::sim::Row) -> f32| {
        rows.iter()
            .map(|r| if r.state == 4 { f32::NAN } else { f(r) })
            .collect::<Vec<f32>>()
    };
    let t = col(|r| r.t_s);
    let sref = ctl(|r| r.speed_ref_rpm);
    let s = col(|r| r.speed_rpm);
    let se = ctl(|r| r.speed_est_rpm);
    let err = ctl(|r| r.speed_est_rpm - r.speed_rpm);
    let isd = ctl(|r| r.i_sd_a);
    let isq = ctl(|r| r.i_sq_a);
    let tl = col(|r| r.load_torque_nm);
    let tle = ctl(|r| r.load_torque_est_nm);
    let rs = ctl(|r| r.stator_resistance_est_ohm);
    let rs_true = vec![r.scenario.plant.rs_ohm; rows.len()];
    let mut panels = vec![
        Panel {
            title: "Speed",
            y_label: "rpm",
            series: vec![
                Series {
                    label: "reference",
                    values: &sref,
                    style: LineStyle::Dashed(Color::Gray),
                },
                Series {
                    label: "real",
                    values: &s,
                    style: LineStyle::Solid(Color::Blue),
                },
                Series {
                    label: "estimated",
                    values: &se,
                    style: LineStyle::Dashed(Color::Red),
                },
            ],
        },
        Panel {
            title: "Speed estimation error (estimated - real)",
            y_label: "rpm",
            series: vec![Series {
                label: "error",
                values: &err,
                style: LineStyle::Solid(Color::Black),
            }],
        },
        Panel {
            title: "Stator current in the controller's frame",
            y_label: "A",
            series: vec![
                Series {
                    label: "i_sd",
                    values: &isd,
                    style: LineStyle::Solid(Color::Green),
                },
                Series {
                    label: "i_sq",
                    values: &isq,
                    style: LineStyle::Solid(Color::Orange),
                },
            ],
        },
        Panel {
            title: "Load torque",
            y_label: "N m",
            series: vec![
                Series {
                    label: "real",
                    values: &tl,
                    style: LineStyle::Solid(Color::Blue),
                },
                Series {
                    label: "estimated",
                    values: &tle,
                    style: LineStyle::Dashed(Color::Red),
                },
            ],
        },
    ];
    let sc = &r.scenario;
    if sc.drive.rs_estimation || (sc.controller.rs_ohm - sc.plant.rs_ohm).abs() > 1e-6 {
        panels.push(Panel {
            title: "Stator resistance",
            y_label: "ohm",
            series: vec![
                Series {
                    label: "real",
                    values: &rs_true,
                    style: LineStyle::Dashed(Color::Gray),
                },
                Series {
                    label: "estimated",
                    values: &rs,
                    style: LineStyle::Solid(Color::Purple),
                },
            ],
        });
    }
    let title = format!("{}: {}", sc.name, sc.description);
    let height = 220 * panels.len() as u32 + 80;
    render_panels(path, &title, &t, &panels, 1200, height)?;
    Ok(())
}
