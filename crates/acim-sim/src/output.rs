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

/// Writes the stability map: growth rate of the orientation error against speed, one line
/// per load torque, measured (solid) and second-order theory (dashed), one panel per gain;
/// and a markdown table of the measured rates.
pub fn write_stability(
    dir: &Path,
    points: &[crate::stability::GrowthPoint],
    gains: &[f32],
) -> Result<(), Box<dyn std::error::Error>> {
    use crate::stability::{LOADS_NM, SPEEDS_RPM};
    std::fs::create_dir_all(dir)?;
    let x: Vec<f32> = SPEEDS_RPM.to_vec();
    let colors = [
        Color::Red,
        Color::Orange,
        Color::Gray,
        Color::Green,
        Color::Blue,
    ];
    // theory in a lighter tint of the same colour (dashes break up on a 12-point axis)
    let light = [
        Color::Rgb(240, 150, 150),
        Color::Rgb(255, 200, 140),
        Color::Rgb(200, 200, 200),
        Color::Rgb(150, 215, 150),
        Color::Rgb(145, 190, 230),
    ];
    let mut labels = Vec::new();
    for l in LOADS_NM {
        labels.push(format!("T_L {l:+.1} N m"));
        labels.push(format!("theory {l:+.1}"));
    }
    let mut data: Vec<Vec<Vec<f32>>> = Vec::new();
    for &k in gains {
        let mut per_gain = Vec::new();
        for &l in &LOADS_NM {
            let pick = |f: fn(&crate::stability::GrowthPoint) -> f32| {
                SPEEDS_RPM
                    .iter()
                    .map(|&s| {
                        points
                            .iter()
                            .find(|p| p.gain == k && p.load_nm == l && p.speed_rpm == s)
                            .map(f)
                            .unwrap_or(f32::NAN)
                            .clamp(-60.0, 60.0)
                    })
                    .collect::<Vec<f32>>()
            };
            per_gain.push(pick(|p| p.growth_rate));
            per_gain.push(pick(|p| p.theory));
        }
        data.push(per_gain);
    }
    let titles: Vec<String> = gains
        .iter()
        .map(|k| {
            if *k == 0.0 {
                "Paper's scheme (gain 0): growth rate, 1/s (lost: drawn at 60)".to_string()
            } else {
                format!("With the orientation correction (gain {k}): growth rate, 1/s")
            }
        })
        .collect();
    let mut panels = Vec::new();
    for (gi, per_gain) in data.iter().enumerate() {
        let mut series = Vec::new();
        for (li, _) in LOADS_NM.iter().enumerate() {
            series.push(Series {
                label: &labels[2 * li],
                values: &per_gain[2 * li],
                style: LineStyle::Solid(colors[li]),
            });
            series.push(Series {
                label: &labels[2 * li + 1],
                values: &per_gain[2 * li + 1],
                style: LineStyle::Solid(light[li]),
            });
        }
        panels.push(Panel {
            title: &titles[gi],
            y_label: "1/s (> 0 unstable)",
            series,
        });
    }
    crate::plot::render_panels_over(
        &dir.join("stability-map.png"),
        "Orientation mode over the torque-speed plane: measured (dark) and second-order theory (light)",
        "Speed (rpm); active load torque T_L > 0 opposes forward rotation (regeneration where speed and T_L have opposite signs)",
        &x,
        &panels,
        1600,
        1100,
    )?;
    let mut md = String::from(
        "<!-- generated by `cargo run --release -p acim-sim -- stability`; do not edit -->\n\nMeasured growth rate of the orientation error, 1/s (positive: unstable; `lost`: control lost before the fit window ended; theory in parentheses).\n\n",
    );
    for &k in gains {
        md += &format!("\n### orientation gain {k}\n\n| T_L (N m) |");
        for s in SPEEDS_RPM {
            md += &format!(" {s:+.0} rpm |");
        }
        md += "\n|---|";
        for _ in SPEEDS_RPM {
            md += "---|";
        }
        md += "\n";
        for l in LOADS_NM {
            md += &format!("| {l:+.1} |");
            for s in SPEEDS_RPM {
                let p = points
                    .iter()
                    .find(|p| p.gain == k && p.load_nm == l && p.speed_rpm == s);
                md += &match p {
                    Some(p) if p.lost => format!(" lost ({:.1}) |", p.theory),
                    Some(p) => format!(" {:.1} ({:.1}) |", p.growth_rate, p.theory),
                    None => " - |".into(),
                };
            }
            md += "\n";
        }
    }
    std::fs::write(dir.join("growth-rates.md"), md)?;
    std::fs::write(
        dir.join("growth-rates.json"),
        serde_json::to_string_pretty(points)? + "\n",
    )?;
    Ok(())
}
