//! `acim-sim`: run the sensorless drive closed loop against the motor model.
//!
//! ```text
//! acim-sim                          run every paper scenario into out/ and print metrics
//! acim-sim list                     list the built-in scenarios
//! acim-sim run <name|file.toml> [--out DIR] [--set key=value]...
//! acim-sim figures [--out DIR]      regenerate docs/figures (PNGs + metrics.md)
//! ```

use acim_sim::builtins;
use acim_sim::metrics::Metrics;
use acim_sim::scenario::Scenario;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

const USAGE: &str = "usage:
  acim-sim                                  run all paper scenarios into out/, print metrics
  acim-sim list                             list built-in scenarios
  acim-sim run <name|file.toml> [--out DIR] [--set key=value]...
  acim-sim figures [--out DIR]              regenerate docs/figures/*.png and metrics.md
  acim-sim stability [DIR]                  orientation stability map (docs/stability)
  acim-sim observers [FILE] [--out DIR]     reduced- vs full-order observer, closed loop
                                            (table to FILE, default docs/observers.md)
  acim-sim faults [FILE] [--out DIR]        every fault-* scenario: reason, detection time,
                                            peaks (table to FILE, default docs/faults.md)";

fn load(spec: &str) -> Result<Scenario, String> {
    if let Some(s) = builtins::get(spec) {
        return Ok(s);
    }
    if spec.ends_with(".toml") || Path::new(spec).exists() {
        let text = std::fs::read_to_string(spec).map_err(|e| format!("{spec}: {e}"))?;
        return Scenario::from_toml(&text).map_err(|e| format!("{spec}: {e}"));
    }
    Err(format!(
        "no built-in scenario or file named `{spec}` (see `acim-sim list`)"
    ))
}

fn summary_header() -> String {
    format!(
        "{:<26} {:>9} {:>8} {:>8} {:>9} {:>9} {:>9}  {}",
        "scenario", "window", "est.err", "spd.err", "TL err", "orient", "Rs", "fault / note"
    )
}

/// How a run ended, in one phrase (console table and metrics.md).
fn outcome(m: &Metrics) -> String {
    match &m.fault {
        Some(f) => format!(
            "{f} at {:.3} s, switches {}",
            m.fault_time_s.unwrap_or(0.0),
            if m.switches_off_at_end { "off" } else { "ON" }
        ),
        None if m.control_kept => "control kept".to_string(),
        None => format!(
            "control lost (max err {:.0} rpm)",
            m.speed_err_max_running_rpm
        ),
    }
}

fn summary_lines(m: &Metrics) -> Vec<String> {
    let mut out = Vec::new();
    let note = outcome(m);
    if m.windows.is_empty() {
        out.push(format!("{:<26} {:>9}  {note}", m.name, "-"));
    }
    for (i, (name, w)) in m.windows.iter().enumerate() {
        out.push(format!(
            "{:<26} {:>9} {:>8.2} {:>8.2} {:>9.3} {:>8.2}° {:>9.3}  {}",
            if i == 0 { m.name.as_str() } else { "" },
            name,
            w.speed_est_err_max_rpm,
            w.speed_err_max_rpm,
            w.load_est_err_mean_nm,
            w.orientation_err_max_deg,
            w.rs_est_mean_ohm,
            if i == 0 { note.as_str() } else { "" },
        ));
    }
    if let Some(s) = m.speed_search.filter(|s| s.true_rpm.abs() > 1.0) {
        out.push(format!(
            "{:<26} flying start: speed search at {:.3} s measured {:.0} rpm (rotor {:.0} rpm)",
            "", s.t_s, s.measured_rpm, s.true_rpm
        ));
    }
    for s in &m.load_steps {
        out.push(format!(
            "{:<26} load {:+.2} N m at {:.1} s: estimate within 0.05 N m after {}, speed within 5 rpm after {} (dip {:.1} rpm)",
            "",
            s.load_nm,
            s.t_s,
            s.load_est_settle_s.map_or("never".into(), |x| format!("{x:.3} s")),
            s.speed_recovery_s.map_or("never".into(), |x| format!("{x:.3} s")),
            s.speed_dip_rpm
        ));
    }
    if m.rs.initial_ohm != m.rs.true_ohm || m.rs.final_ohm != m.rs.initial_ohm {
        out.push(format!(
            "{:<26} Rs {:.2} -> {:.3} ohm (true {:.2}); within 2 % from {} ({} after speed control started)",
            "",
            m.rs.initial_ohm,
            m.rs.final_ohm,
            m.rs.true_ohm,
            m.rs.within_2pct_from_s.map_or("never".into(), |x| format!("{x:.3} s")),
            m.rs.within_2pct_after_running_s.map_or("-".into(), |x| format!("{x:.3} s")),
        ));
    }
    out
}

fn run_many(names: &[String], out: &Path) -> Result<Vec<Metrics>, String> {
    let mut all = Vec::new();
    println!("{}", summary_header());
    for name in names {
        let sc = load(name)?;
        let m = acim_sim::run_and_write(&sc, out).map_err(|e| format!("{name}: {e}"))?;
        for l in summary_lines(&m) {
            println!("{l}");
        }
        all.push(m);
    }
    println!(
        "\nerrors in rpm are maxima of 10 ms averages over each steady window; TL err is the mean |estimate - real|; outputs in {}",
        out.display()
    );
    Ok(all)
}

fn write_metrics_md(path: &Path, all: &[Metrics]) -> std::io::Result<()> {
    let mut s = String::from(
        "<!-- generated by `cargo run --release -p acim-sim -- figures`; do not edit -->\n\n| scenario | window | speed est. error max (rpm) | speed error max (rpm) | load est. error mean (N m) | orientation error max (deg) | Rs mean (ohm) | outcome |\n|---|---|---|---|---|---|---|---|\n",
    );
    for m in all {
        let outcome = outcome(m);
        for (name, w) in &m.windows {
            s += &format!(
                "| {} | {} | {:.2} | {:.2} | {:.3} | {:.2} | {:.3} | {} |\n",
                m.name,
                name,
                w.speed_est_err_max_rpm,
                w.speed_err_max_rpm,
                w.load_est_err_mean_nm,
                w.orientation_err_max_deg,
                w.rs_est_mean_ohm,
                outcome
            );
        }
        if m.windows.is_empty() {
            s += &format!("| {} | - | | | | | | {} |\n", m.name, outcome);
        }
    }
    // open-loop rows have no estimate (NaN in the metrics)
    let mut s = s
        .replace("| NaN |", "| n/a |")
        .replace("| NaN |", "| n/a |");
    s += "\nLoad steps and Rs convergence:\n\n";
    for m in all {
        for st in &m.load_steps {
            s += &format!(
                "- {}: load {:+.2} N m at {:.1} s: estimate within 0.05 N m after {}; speed within 5 rpm after {} (largest deviation {:.1} rpm)\n",
                m.name,
                st.load_nm,
                st.t_s,
                st.load_est_settle_s.map_or("never".into(), |x| format!("{x:.3} s")),
                st.speed_recovery_s.map_or("never".into(), |x| format!("{x:.3} s")),
                st.speed_dip_rpm
            );
        }
        if m.rs.final_ohm != m.rs.initial_ohm {
            s += &format!(
                "- {}: Rs estimate {:.2} -> {:.3} ohm (true {:.2}), within 2 % from t = {} ({} after speed control started)\n",
                m.name,
                m.rs.initial_ohm,
                m.rs.final_ohm,
                m.rs.true_ohm,
                m.rs.within_2pct_from_s.map_or("never".into(), |x| format!("{x:.3} s")),
                m.rs.within_2pct_after_running_s.map_or("-".into(), |x| format!("{x:.3} s")),
            );
        }
    }
    std::fs::write(path, s)
}

fn real_main(args: Vec<String>) -> Result<(), String> {
    let mut it = args.into_iter();
    let cmd = it.next();
    let rest: Vec<String> = it.collect();
    let mut out = PathBuf::from("out");
    let mut sets = Vec::new();
    let mut positional = Vec::new();
    let mut i = 0;
    while i < rest.len() {
        match rest[i].as_str() {
            "--out" => {
                out = PathBuf::from(rest.get(i + 1).ok_or("--out needs a directory")?);
                i += 1;
            }
            "--set" => {
                sets.push(rest.get(i + 1).ok_or("--set needs key=value")?.clone());
                i += 1;
            }
            a if a.starts_with("--set=") => sets.push(a["--set=".len()..].to_string()),
            a if a.starts_with("--") => return Err(format!("unknown option {a}\n{USAGE}")),
            a => positional.push(a.to_string()),
        }
        i += 1;
    }
    match cmd.as_deref() {
        None => {
            run_many(&builtins::paper_names(), &out)?;
        }
        Some("list") => {
            for s in builtins::all() {
                println!("{:<28} {}", s.name, s.description);
            }
        }
        Some("run") => {
            let [spec] = positional.as_slice() else {
                return Err(format!("run takes one scenario name or file\n{USAGE}"));
            };
            let sc = load(spec)?
                .with_overrides(&sets)
                .map_err(|e| e.to_string())?;
            sc.validate().map_err(|e| e.to_string())?;
            let m = acim_sim::run_and_write(&sc, &out).map_err(|e| e.to_string())?;
            println!("{}", summary_header());
            for l in summary_lines(&m) {
                println!("{l}");
            }
            println!(
                "simulated {:.1} s in {:.3} s ({:.0}x real time); wrote {}/{}.{{csv,json,png}}",
                m.duration_s,
                m.wall_time_s,
                m.real_time_factor,
                out.display(),
                sc.name
            );
        }
        Some("figures") => {
            let fig = if positional.is_empty() {
                PathBuf::from("docs/figures")
            } else {
                PathBuf::from(&positional[0])
            };
            let names: Vec<String> = builtins::all().into_iter().map(|s| s.name).collect();
            let all = run_many(&names, &out)?;
            std::fs::create_dir_all(&fig).map_err(|e| e.to_string())?;
            for n in &names {
                std::fs::copy(out.join(format!("{n}.png")), fig.join(format!("{n}.png")))
                    .map_err(|e| e.to_string())?;
            }
            write_metrics_md(&fig.join("metrics.md"), &all).map_err(|e| e.to_string())?;
            println!("figures and metrics.md written to {}", fig.display());
        }
        Some("stability") => {
            let dir = if positional.is_empty() {
                PathBuf::from("docs/stability")
            } else {
                PathBuf::from(&positional[0])
            };
            let gains = [0.0, acim::DriveConfig::paper_defaults().orientation_gain];
            let t0 = std::time::Instant::now();
            let pts = acim_sim::stability::map(&gains).map_err(|e| e.to_string())?;
            acim_sim::output::write_stability(&dir, &pts, &gains).map_err(|e| e.to_string())?;
            println!(
                "{} operating points in {:.1} s; map and tables in {}",
                pts.len(),
                t0.elapsed().as_secs_f64(),
                dir.display()
            );
            let unstable = |k: f32| {
                pts.iter()
                    .filter(|p| p.gain == k && (p.lost || p.growth_rate > 0.0))
                    .count()
            };
            println!(
                "unstable or lost: {} of {} without the correction, {} of {} with it",
                unstable(gains[0]),
                pts.len() / 2,
                unstable(gains[1]),
                pts.len() / 2
            );
        }
        Some("observers") => {
            let file = positional
                .first()
                .map(PathBuf::from)
                .unwrap_or_else(|| PathBuf::from("docs/observers.md"));
            let rows = acim_sim::observers::compare(&out)?;
            let cycles =
                acim_sim::observers::bench_cycles(Path::new("benches/results/cycles.json"));
            let md = acim_sim::observers::markdown(&rows, cycles);
            write_table(&file, &md, &out)?;
        }
        Some("faults") => {
            let file = positional
                .first()
                .map(PathBuf::from)
                .unwrap_or_else(|| PathBuf::from("docs/faults.md"));
            let rows = acim_sim::faults::run_all(&out)?;
            let md = acim_sim::faults::markdown(&rows);
            write_table(&file, &md, &out)?;
        }
        Some("-h" | "--help" | "help") => println!("{USAGE}"),
        Some(other) => return Err(format!("unknown command `{other}`\n{USAGE}")),
    }
    Ok(())
}

fn main() -> ExitCode {
    match real_main(std::env::args().skip(1).collect()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("acim-sim: {e}");
            ExitCode::FAILURE
        }
    }
}

/// Prints a generated Markdown table and writes it to `file` (creating its directory).
fn write_table(file: &Path, md: &str, out: &Path) -> Result<(), String> {
    print!("{md}");
    if let Some(dir) = file.parent() {
        std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    }
    std::fs::write(file, md).map_err(|e| format!("{}: {e}", file.display()))?;
    println!(
        "\nwrote {} (run outputs in {})",
        file.display(),
        out.display()
    );
    Ok(())
}
