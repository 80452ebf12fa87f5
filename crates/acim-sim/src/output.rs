//! Writing a run: `<name>.csv` (one row per control step, or every `csv_decimation`-th;
//! `<name>.csv.gz` when compressed), `<name>.json` (metrics) and `<name>.png`
//! (paper-style panels).
//!
//! Every file is written atomically: into a temporary file beside it, then renamed over
//! it, so a failure (a full disk, a plotting error) leaves no partial file behind. Every
//! error names the file it concerns ([`FileError`]).

use crate::metrics::Metrics;
use crate::plot::{render_panels_marked, Color, LineStyle, Marks, Panel, Series, SPAN_COLOR};
use crate::scenario::ControlMode;
use crate::sim::{RunResult, CSV_HEADER};
use std::io::Write;
use std::path::{Path, PathBuf};

/// An I/O (or encoding) error, with the path it concerns.
#[derive(Debug)]
pub struct FileError {
    /// The file or directory.
    pub path: PathBuf,
    /// What went wrong.
    pub message: String,
}

impl FileError {
    /// An error about `path`.
    pub fn new(path: &Path, e: impl std::fmt::Display) -> Self {
        FileError {
            path: path.to_path_buf(),
            message: e.to_string(),
        }
    }
}

impl std::fmt::Display for FileError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}: {}", self.path.display(), self.message)
    }
}

impl std::error::Error for FileError {}

/// Creates `dir` and its parents, naming it on failure.
pub fn create_dir(dir: &Path) -> Result<(), FileError> {
    std::fs::create_dir_all(dir).map_err(|e| FileError::new(dir, e))
}

/// The temporary file `path` is first written to: hidden, beside it (same file system,
/// so the rename is atomic), with the same extension (the PNG encoder goes by it).
fn temp_path(path: &Path) -> PathBuf {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let ext = path
        .extension()
        .map(|e| format!(".{}", e.to_string_lossy()))
        .unwrap_or_default();
    path.with_file_name(format!(".{name}.{}.partial{ext}", std::process::id()))
}

/// Produces `path` atomically: `make` writes the temporary file it is given; on success
/// the file is synced and renamed to `path`, on failure it is removed. Errors name `path`.
pub fn with_temp_file(
    path: &Path,
    make: impl FnOnce(&Path) -> Result<(), Box<dyn std::error::Error>>,
) -> Result<(), FileError> {
    let tmp = temp_path(path);
    let result = make(&tmp)
        .and_then(|()| {
            std::fs::File::open(&tmp)?.sync_all()?;
            Ok(())
        })
        .and_then(|()| Ok(std::fs::rename(&tmp, path)?));
    if let Err(e) = result {
        let _ = std::fs::remove_file(&tmp);
        return Err(FileError::new(path, e));
    }
    Ok(())
}

/// Writes `path` atomically through a buffered writer.
pub fn write_atomic(
    path: &Path,
    write: impl FnOnce(&mut dyn Write) -> std::io::Result<()>,
) -> Result<(), FileError> {
    with_temp_file(path, |tmp| {
        let mut f = std::io::BufWriter::new(std::fs::File::create(tmp)?);
        write(&mut f)?;
        f.flush()?;
        Ok(())
    })
}

/// Writes `bytes` to `path` atomically.
pub fn write_file(path: &Path, bytes: &[u8]) -> Result<(), FileError> {
    write_atomic(path, |w| w.write_all(bytes))
}

/// The largest input file (scenario, machine, nameplate or identified model) the
/// simulator reads, bytes: a scenario is a few kB, and a path to a device such as
/// `/dev/zero` must end in an error, not in reading until memory runs out.
pub const MAX_INPUT_BYTES: u64 = 1 << 20;

/// `path` as the user wrote it, relative to `base` (the folder of the file that names it)
/// when it is relative and a base is given.
pub fn resolve_beside(base: Option<&Path>, path: &Path) -> PathBuf {
    match base {
        Some(b) if path.is_relative() => b.join(path),
        _ => path.to_path_buf(),
    }
}

/// Reads a UTF-8 text file of at most `max` bytes; a folder, a device or a larger file is
/// an error that says which.
pub fn read_text_file(path: &Path, max: u64) -> Result<String, String> {
    use std::io::Read;
    let meta = std::fs::metadata(path).map_err(|e| e.to_string())?;
    if meta.is_dir() {
        return Err("is a folder, not a file".into());
    }
    if !meta.is_file() {
        return Err("is not a regular file (a device or a pipe?)".into());
    }
    let mut bytes = Vec::new();
    std::fs::File::open(path)
        .and_then(|f| f.take(max + 1).read_to_end(&mut bytes))
        .map_err(|e| e.to_string())?;
    if bytes.len() as u64 > max {
        return Err(format!(
            "is larger than {max} bytes: not a scenario or machine file"
        ));
    }
    String::from_utf8(bytes).map_err(|_| "is not UTF-8 text".into())
}

/// Rows longer than this many control steps get a CSV decimation by default.
pub const CSV_ROWS_DEFAULT_MAX: usize = 100_000;

/// The CSV decimation of a run: the scenario's `csv_decimation` if set, otherwise 1 up to
/// [`CSV_ROWS_DEFAULT_MAX`] control steps and the smallest step that keeps the file
/// within that many rows beyond (a 600 s run at 5 kHz: every 30th step). Returns the
/// decimation and whether it was chosen automatically.
pub fn csv_decimation(sc: &crate::scenario::Scenario) -> (u32, bool) {
    match sc.csv_decimation {
        Some(n) => (n.max(1), false),
        None => {
            let steps = (sc.duration_s / sc.drive.loops.control_period_s)
                .round()
                .max(1.0) as usize;
            (steps.div_ceil(CSV_ROWS_DEFAULT_MAX).max(1) as u32, true)
        }
    }
}

/// Writes the CSV file (gzip-compressed when `gzip`; the path should then end in `.gz`).
pub fn write_csv_to(path: &Path, r: &RunResult, gzip: bool) -> Result<(), FileError> {
    let step = csv_decimation(&r.scenario).0 as usize;
    let body = |f: &mut dyn Write| -> std::io::Result<()> {
        writeln!(f, "{CSV_HEADER}")?;
        for row in r.rows.iter().step_by(step) {
            writeln!(f, "{}", row.csv())?;
        }
        Ok(())
    };
    if gzip {
        write_atomic(path, |w| {
            let mut gz = flate2::write::GzEncoder::new(w, flate2::Compression::default());
            body(&mut gz)?;
            gz.finish()?;
            Ok(())
        })
    } else {
        write_atomic(path, body)
    }
}

/// Writes the CSV file, uncompressed.
pub fn write_csv(path: &Path, r: &RunResult) -> Result<(), FileError> {
    write_csv_to(path, r, false)
}

/// Writes the metrics JSON file.
pub fn write_json(path: &Path, m: &Metrics) -> Result<(), FileError> {
    let text = serde_json::to_string_pretty(m).map_err(|e| FileError::new(path, e))?;
    write_file(path, (text + "\n").as_bytes())
}

/// Renders the paper-style figure: speed (the target as given, the ramped reference, real,
/// estimated), speed-estimation error, dq currents, load torque (real and estimated), and
/// Rs estimate when the estimator is on or the controller's Rs differs from the plant's.
/// Every panel shades the metric windows and marks the drive's state changes (a fault in
/// red). Open-loop V/f runs have no estimator: their figure shows no estimate, no
/// estimation error and no Rs.
pub fn write_png(path: &Path, r: &RunResult) -> Result<(), FileError> {
    with_temp_file(path, |tmp| draw_png(tmp, r))
}

fn draw_png(path: &Path, r: &RunResult) -> Result<(), Box<dyn std::error::Error>> {
    let open_loop = r.scenario.drive.mode == ControlMode::Vf;
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
    let rs_true: Vec<f32> = rows
        .iter()
        .map(|x| {
            r.scenario.plant.rs_ohm
                * crate::scenario::plant_factors(&r.scenario.plant_changes, x.t_s).0
        })
        .collect();
    let target = ctl(|r| r.speed_target_rpm);
    // legend entries for the marks drawn behind every panel (no samples of their own)
    let none = vec![f32::NAN; t.len()];
    let faulted = rows.iter().any(|x| x.state == 4);
    let mut speed = vec![
        Series {
            label: "target",
            values: &target,
            style: LineStyle::Dashed(Color::Black),
        },
        Series {
            label: "reference (ramped)",
            values: &sref,
            style: LineStyle::Dashed(Color::Gray),
        },
        Series {
            label: "real",
            values: &s,
            style: LineStyle::Solid(Color::Blue),
        },
    ];
    let mut load = vec![Series {
        label: "real",
        values: &tl,
        style: LineStyle::Solid(Color::Blue),
    }];
    if !open_loop {
        speed.push(Series {
            label: "estimated",
            values: &se,
            style: LineStyle::Dashed(Color::Red),
        });
        load.push(Series {
            label: "estimated",
            values: &tle,
            style: LineStyle::Dashed(Color::Red),
        });
    }
    speed.push(Series {
        label: "metric windows",
        values: &none,
        style: LineStyle::Solid(SPAN_COLOR),
    });
    speed.push(Series {
        label: "state change",
        values: &none,
        style: LineStyle::Solid(Color::Purple),
    });
    if faulted {
        speed.push(Series {
            label: "fault",
            values: &none,
            style: LineStyle::Solid(Color::Red),
        });
    }
    let mut panels = vec![Panel {
        title: "Speed",
        y_label: "rpm",
        series: speed,
    }];
    if !open_loop {
        panels.push(Panel {
            title: "Speed estimation error (estimated - real)",
            y_label: "rpm",
            series: vec![Series {
                label: "error",
                values: &err,
                style: LineStyle::Solid(Color::Black),
            }],
        });
    }
    panels.push(Panel {
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
    });
    panels.push(Panel {
        title: "Load torque",
        y_label: "N m",
        series: load,
    });
    let sc = &r.scenario;
    if !open_loop
        && (sc.drive.estimation.rs_estimation
            || (sc.controller.rs_ohm - sc.plant.rs_ohm).abs() > 1e-6)
    {
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
    let mut marks = Marks {
        spans: sc
            .windows
            .iter()
            .map(|w| (f64::from(w.from_s), f64::from(w.to_s)))
            .collect(),
        lines: Vec::new(),
    };
    for w in rows.windows(2) {
        if w[1].state != w[0].state {
            let c = if w[1].state == 4 {
                Color::Red
            } else {
                Color::Purple
            };
            marks.lines.push((f64::from(w[1].t_s), c));
        }
    }
    render_panels_marked(path, &title, &t, &panels, 1200, height, &marks)?;
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
    create_dir(dir)?;
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
    let png = dir.join("stability-map.png");
    with_temp_file(&png, |tmp| {
        Ok(crate::plot::render_panels_over(
        tmp,
        "Orientation mode over the torque-speed plane: measured (dark) and second-order theory (light)",
        "Speed (rpm); active load torque T_L > 0 opposes forward rotation (regeneration where speed and T_L have opposite signs)",
        &x,
        &panels,
        1600,
        1100,
    )?)
    })?;
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
    write_file(&dir.join("growth-rates.md"), md.as_bytes())?;
    write_file(
        &dir.join("growth-rates.json"),
        (serde_json::to_string_pretty(points)? + "\n").as_bytes(),
    )?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scratch(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("acim-sim-output-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    fn entries(d: &Path) -> Vec<String> {
        let mut v: Vec<String> = std::fs::read_dir(d)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        v.sort();
        v
    }

    #[test]
    fn a_failed_write_leaves_no_file_and_names_the_path() {
        let d = scratch("fail");
        let path = d.join("run.csv");
        // an earlier, complete file stays as it was
        write_file(&path, b"old\n").unwrap();
        let e = write_atomic(&path, |w| {
            w.write_all(b"half a row")?;
            Err(std::io::Error::other("disk full"))
        })
        .unwrap_err();
        assert_eq!(e.path, path);
        assert!(e.to_string().contains("run.csv: disk full"), "{e}");
        assert_eq!(std::fs::read(&path).unwrap(), b"old\n");
        assert_eq!(entries(&d), ["run.csv"]);
        // a new file that fails is not created at all
        let fresh = d.join("fresh.json");
        assert!(write_atomic(&fresh, |_| Err(std::io::Error::other("no"))).is_err());
        assert_eq!(entries(&d), ["run.csv"]);
        let _ = std::fs::remove_dir_all(&d);
    }

    #[test]
    fn io_errors_name_the_path() {
        let d = scratch("missing");
        let e = write_file(&d.join("no-such-dir/x.json"), b"{}").unwrap_err();
        assert!(e.to_string().contains("no-such-dir/x.json"), "{e}");
        let e = create_dir(Path::new("/proc/acim-sim-cannot")).unwrap_err();
        assert!(e.to_string().starts_with("/proc/acim-sim-cannot: "), "{e}");
        let _ = std::fs::remove_dir_all(&d);
    }

    #[test]
    fn default_decimation_follows_the_duration() {
        let mut sc = crate::scenario::Scenario {
            duration_s: 10.0, // 50 000 steps
            ..Default::default()
        };
        assert_eq!(csv_decimation(&sc), (1, true));
        sc.duration_s = 20.0; // 100 000 steps
        assert_eq!(csv_decimation(&sc), (1, true));
        sc.duration_s = 600.0; // 3 000 000 steps
        assert_eq!(csv_decimation(&sc), (30, true));
        sc.csv_decimation = Some(7);
        assert_eq!(csv_decimation(&sc), (7, false));
    }
}
