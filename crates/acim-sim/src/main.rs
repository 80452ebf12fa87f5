//! `acim-sim`: run the sensorless drive closed loop against the motor model.
//!
//! ```text
//! acim-sim [OPTIONS]                       run every paper scenario into out/ and print metrics
//! acim-sim list                            list the built-in scenarios
//! acim-sim run <name|file.toml> [OPTIONS]  one scenario
//! acim-sim figures [DIR] [OPTIONS]         regenerate docs/figures (PNGs + metrics.md)
//! acim-sim stability [DIR]                 orientation stability map (docs/stability)
//! acim-sim observers [FILE] [OPTIONS]      reduced- vs full-order observer table
//! acim-sim faults [FILE] [OPTIONS]         fault table
//! acim-sim overhauling [FILE] [OPTIONS]    overhauling-load sweep
//! acim-sim load-steps [FILE]               rated load applied and removed, every machine
//! acim-sim low-speed [FILE]                low speed under rated load, every machine
//! acim-sim robustness [FILE]               the robustness matrix
//! acim-sim robust-stability [FILE]         growth rates with parameter errors
//! acim-sim linear-stability [FILE]         eigenvalues of the linearised closed loop
//! ```

use acim_sim::builtins;
use acim_sim::metrics::{Metrics, Verdict};
use acim_sim::output::{self, FileError};
use acim_sim::scenario::Scenario;
use acim_sim::WriteOptions;
use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

const USAGE: &str = "usage:
  acim-sim [OPTIONS]                        run all paper scenarios into out/, print metrics
  acim-sim list                             list built-in scenarios (takes no options)
  acim-sim serve [--tcp ADDR] [--speed X|max] [--rate N]
                                            the virtual board: the firmware's control loop live
                                            on a TCP port (docs/protocol.md; see serve --help)
  acim-sim run <name|file.toml> [OPTIONS]   run one scenario: <out>/<name>.{csv,json,png}
  acim-sim figures [DIR] [OPTIONS]          every built-in scenario; PNGs and metrics.md to DIR
                                            (default docs/figures; with --set: <out>/figures)
  acim-sim stability [DIR]                  orientation stability map (default docs/stability;
                                            --out DIR is the same; --set is not supported)
  acim-sim observers [FILE] [OPTIONS]       reduced- vs full-order observer, closed loop (table
                                            to FILE, default docs/observers.md; with --set:
                                            <out>/observers.md)
  acim-sim load-steps [FILE] [OPTIONS]      rated load applied and removed at 10, 50 and 100 %
                                            of rated speed on every machine of the set,
                                            commissioned first (table to FILE, default
                                            docs/load-steps.md; --set is not supported)
  acim-sim low-speed [FILE] [OPTIONS]       rated motoring load at 0-3 % of synchronous speed,
                                            overhauling load at 1 %, parameter errors at 5
                                            and 50 %, on every machine of the load-step set,
                                            commissioned first (table to FILE, default
                                            docs/low-speed.md; --set is not supported)
  acim-sim capability [FILE]                steady torque held per speed vs the envelope of the
                                            machine equations (table to FILE, default
                                            docs/capability.md, plot next to it; --set is
                                            not supported)
  acim-sim faults [FILE] [OPTIONS]          every fault-* scenario: reason, detection time,
                                            peaks (table to FILE, default docs/faults.md; with
                                            --set: <out>/faults.md)
  acim-sim overhauling [FILE] [OPTIONS]     overhauling loads 0-12 N m at 500, 120 and 60 rpm:
                                            held, limited or a clean fault (table to FILE,
                                            default docs/overhauling.md; with --set:
                                            <out>/overhauling.md; no run outputs)
  acim-sim any-motor [FILE] [OPTIONS]       every acceptance machine commissioned, then
                                            driven with the identified model (table to FILE,
                                            default docs/any-motor.md; figures beside it)
  acim-sim robust-stability [FILE]          orientation growth rates over the torque-speed plane
                                            with parameter and inverter errors (table to FILE,
                                            default docs/robust-stability.md)
  acim-sim linear-stability [FILE]          eigenvalues of the linearised closed loop over the
                                            same plane and errors (table to FILE, default
                                            docs/linear-stability.md)
  acim-sim robustness [FILE] [OPTIONS]      the robustness matrix, Rs estimation in the
                                            standstill and running modes (table to FILE,
                                            default docs/robustness-matrix.md; with --set:
                                            <out>/robustness-matrix.md)
  acim-sim commission <scenario|machine.toml> [--nameplate FILE] [OPTIONS]
                                            self-commissioning against the plant: the
                                            inverse-Gamma model, J, B and the dead time to
                                            <out>/identified.toml, with the true values
options:
  --out DIR        directory for the run outputs (CSV, JSON, PNG), default out
  --set key=value  override a scenario field (dotted TOML key), repeatable; applies to every
                   scenario the command runs
  --gzip           write the CSV gzip-compressed, <name>.csv.gz (about 4x smaller; for long runs)
  --quiet, -q      no progress bar (it is shown only when stderr is a terminal anyway)
  --nameplate FILE (commission) the [nameplate] and [board] tables of FILE";

/// Command-line options shared by the subcommands.
#[derive(Debug, Default)]
struct Opts {
    out: Option<PathBuf>,
    sets: Vec<String>,
    gzip: bool,
    quiet: bool,
    nameplate: Option<PathBuf>,
    positional: Vec<String>,
}

impl Opts {
    fn parse(rest: &[String]) -> Result<Opts, String> {
        let mut o = Opts::default();
        let mut i = 0;
        while i < rest.len() {
            match rest[i].as_str() {
                "--out" => {
                    let dir = rest.get(i + 1).ok_or("--out needs a directory")?;
                    if dir.is_empty() {
                        return Err("--out needs a directory, got an empty string".into());
                    }
                    o.out = Some(PathBuf::from(dir));
                    i += 1;
                }
                a if a.starts_with("--out=") => {
                    let dir = &a["--out=".len()..];
                    if dir.is_empty() {
                        return Err("--out needs a directory, got an empty string".into());
                    }
                    o.out = Some(PathBuf::from(dir));
                }
                "--set" => {
                    o.sets
                        .push(rest.get(i + 1).ok_or("--set needs key=value")?.clone());
                    i += 1;
                }
                a if a.starts_with("--set=") => o.sets.push(a["--set=".len()..].to_string()),
                "--gzip" => o.gzip = true,
                "--nameplate" => {
                    let f = rest.get(i + 1).ok_or("--nameplate needs a TOML file")?;
                    o.nameplate = Some(PathBuf::from(f));
                    i += 1;
                }
                "--quiet" | "-q" => o.quiet = true,
                a if a.starts_with('-') && a.len() > 1 => {
                    return Err(format!("unknown option {a}\n{USAGE}"))
                }
                a => o.positional.push(a.to_string()),
            }
            i += 1;
        }
        Ok(o)
    }

    fn out(&self) -> PathBuf {
        self.out.clone().unwrap_or_else(|| PathBuf::from("out"))
    }

    fn write(&self) -> WriteOptions {
        WriteOptions {
            gzip_csv: self.gzip,
        }
    }

    /// Rejects what a subcommand does not take, with the reason.
    fn reject(&self, cmd: &str, set: Option<&str>, gzip: Option<&str>) -> Result<(), String> {
        if let (Some(why), false) = (set, self.sets.is_empty()) {
            return Err(format!("`{cmd}` does not take --set: {why}"));
        }
        if let (Some(why), true) = (gzip, self.gzip) {
            return Err(format!("`{cmd}` does not take --gzip: {why}"));
        }
        Ok(())
    }

    fn at_most_positional(&self, cmd: &str, n: usize, what: &str) -> Result<(), String> {
        if self.positional.len() > n {
            return Err(format!(
                "`{cmd}` takes {what}, got {:?}\n{USAGE}",
                self.positional
            ));
        }
        Ok(())
    }
}

/// A progress reporter for one run: an indicatif bar on stderr when it is a terminal and
/// not `--quiet`, nothing otherwise.
struct Progress {
    bar: Option<indicatif::ProgressBar>,
}

impl Progress {
    fn new(quiet: bool, sc: &Scenario) -> Progress {
        if quiet || !std::io::stderr().is_terminal() {
            return Progress { bar: None };
        }
        let steps = (sc.duration_s / sc.drive.loops.control_period_s)
            .round()
            .max(1.0) as u64;
        let bar = indicatif::ProgressBar::new(steps);
        // short enough for an 80-column terminal (a wrapped bar redraws badly)
        let style = indicatif::ProgressStyle::with_template(
            "{prefix} [{bar:24}] {percent:>3}% of {msg}, eta {eta}",
        )
        .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar())
        .progress_chars("=> ");
        bar.set_style(style);
        bar.set_prefix(sc.name.clone());
        bar.set_message(format!("{:.0} s simulated", sc.duration_s));
        Progress { bar: Some(bar) }
    }

    fn update(&self, done: usize, total: usize) {
        if let Some(b) = &self.bar {
            b.set_length(total as u64);
            b.set_position(done as u64);
        }
    }

    fn finish(&self) {
        if let Some(b) = &self.bar {
            b.finish_and_clear();
        }
    }
}

fn load(spec: &str) -> Result<Scenario, String> {
    let mut sc = load_plain(spec)?;
    if let Some(f) = sc.controller_file.clone() {
        // relative to the scenario file that names it, as a user reads the file
        let base = if builtins::get(spec).is_some() {
            None
        } else {
            Path::new(spec).parent()
        };
        let path = acim_sim::output::resolve_beside(base, Path::new(&f));
        let text = acim_sim::output::read_text_file(&path, acim_sim::output::MAX_INPUT_BYTES)
            .map_err(|e| {
                format!(
                    "{spec}: scenario field `controller_file`: {}: {e}",
                    path.display()
                )
            })?;
        sc.apply_identified(&text)
            .map_err(|e| format!("{spec}: {e}"))?;
    }
    Ok(sc)
}

fn load_plain(spec: &str) -> Result<Scenario, String> {
    if let Some(s) = builtins::get(spec) {
        return Ok(s);
    }
    if spec.ends_with(".toml") || Path::new(spec).exists() {
        let text =
            acim_sim::output::read_text_file(Path::new(spec), acim_sim::output::MAX_INPUT_BYTES)
                .map_err(|e| format!("{spec}: {e}"))?;
        let mut sc = Scenario::from_file_text(&text).map_err(|e| format!("{spec}: {e}"))?;
        // a file that names no scenario (a machine file) is called after itself, so
        // that its outputs and plot titles say which machine they are
        let named = text
            .parse::<toml::Table>()
            .is_ok_and(|t| t.contains_key("name"));
        if let (false, Some(stem)) = (named, Path::new(spec).file_stem()) {
            sc.name = stem.to_string_lossy().into_owned();
        }
        return Ok(sc);
    }
    Err(format!(
        "no built-in scenario or file named `{spec}` (see `acim-sim list`)"
    ))
}

/// Loads `spec` and applies the `--set` overrides, then validates.
fn load_with(spec: &str, sets: &[String]) -> Result<Scenario, String> {
    let sc = load(spec)?
        .with_overrides(sets)
        .map_err(|e| format!("{spec}: {e}"))?;
    sc.validate().map_err(|e| format!("{spec}: {e}"))?;
    Ok(sc)
}

/// Runs one scenario with a progress bar and writes its files.
fn run_one(sc: &Scenario, out: &Path, o: &Opts) -> Result<Metrics, String> {
    let p = Progress::new(o.quiet, sc);
    let r = acim_sim::run_and_write_with(sc, out, o.write(), &mut |d, n| p.update(d, n));
    p.finish();
    r.map_err(|e| format!("{}: {e}", sc.name))
}

fn summary_header() -> String {
    format!(
        "{:<26} {:>9} {:>8} {:>8} {:>9} {:>9} {:>9}  {}\n{:<26} {:>9} {:>8} {:>8} {:>9} {:>9} {:>9}",
        "scenario",
        "window",
        "est.err",
        "spd.err",
        "TL err",
        "orient",
        "Rs",
        "verdict / note",
        "",
        "",
        "(rpm)",
        "(rpm)",
        "(N m)",
        "(deg)",
        "(ohm)"
    )
}

/// A load step's line: the thresholds it was judged with and whether the largest speed
/// deviation was a dip (slower than the reference) or an overshoot (faster).
fn load_step_text(m: &Metrics, s: &acim_sim::metrics::LoadStepMetrics) -> String {
    let th = &m.thresholds;
    format!(
        "load {:+.2} N m at {:.1} s: estimate within {:.2} N m after {}, speed within {} rpm after {} ({} {:.1} rpm)",
        s.load_nm,
        s.t_s,
        th.load_estimate_nm,
        s.load_est_settle_s.map_or("never".into(), |x| format!("{x:.3} s")),
        acim_sim::metrics::rpm_text(th.recovery_rpm),
        s.speed_recovery_s.map_or("never".into(), |x| format!("{x:.3} s")),
        if s.overshoot { "overshoot" } else { "dip" },
        s.speed_dip_rpm
    )
}

/// The verdict notes a target held below what was asked (by the voltage, the current or
/// the regeneration limit) when it was held this long in all, s.
const TARGET_LIMITED_NOTE_S: f32 = 0.5;

/// How a run ended, in one phrase (console table and metrics.md); the criteria are
/// [`acim_sim::metrics::Verdict`]'s.
fn outcome(m: &Metrics) -> String {
    let verdict = match (m.verdict, &m.fault) {
        (Verdict::Faulted, Some(f)) => format!(
            "{f} at {:.3} s, switches {}",
            m.fault_time_s.unwrap_or(0.0),
            if m.switches_off_at_end { "off" } else { "ON" }
        ),
        (Verdict::Lost, _) => {
            let lost = m
                .excursions
                .iter()
                .find(|x| {
                    x.recovered_after_s
                        .is_none_or(|d| d > acim_sim::metrics::LOST_RECOVERY_S)
                })
                .copied()
                .unwrap_or_default();
            format!(
                "control lost (max err {:.0} rpm; beyond {} rpm from {:.2} s{})",
                m.speed_err_max_running_rpm,
                acim_sim::metrics::rpm_text(m.thresholds.lost_rpm),
                lost.from_s,
                lost.recovered_after_s
                    .map_or(", never recovered".into(), |d| format!(" for {d:.2} s"))
            )
        }
        (Verdict::LimitCycle, _) => {
            let o = m.oscillation.unwrap_or_default();
            format!(
                "limit cycle: true speed {:.0}-{:.0} rpm around a steady reference for {:.0} s from {:.2} s (swing {:.0} rpm, bound {})",
                o.speed_min_rpm,
                o.speed_max_rpm,
                o.duration_s,
                o.from_s,
                o.peak_to_peak_rpm,
                acim_sim::metrics::rpm_text(m.thresholds.oscillation_rpm)
            )
        }
        (Verdict::Drifting, _) => format!(
            "drifting: rotor at up to {:.1} rpm with the reference held at 0 from {:.2} s",
            m.zero_hold.as_ref().map_or(0.0, |z| z.speed_max_rpm),
            m.zero_hold.as_ref().map_or(0.0, |z| z.from_s),
        ),
        _ => "control kept".to_string(),
    };
    // what the verdict alone would hide: a recovered transient, a clamped target
    let mut notes = Vec::new();
    if m.verdict != Verdict::Lost && m.verdict != Verdict::Faulted {
        for x in &m.excursions {
            if let Some(d) = x.recovered_after_s {
                notes.push(format!(
                    "transient {:.0} rpm off at {:.2} s, back within {} rpm after {:.2} s",
                    x.peak_rpm,
                    x.from_s,
                    acim_sim::metrics::rpm_text(m.thresholds.lost_rpm),
                    d
                ));
            }
        }
    }
    if let Some(h) = m.hardware_trip {
        notes.push(format!(
            "hardware over-current trip: {:.1} A (level {:.1} A) switched off at {:.4} s",
            h.current_a, h.level_a, h.off_s
        ));
    }
    // a short hold (an acceleration at the current limit) is in the CSV and the JSON only
    if m.target_clamps.is_empty() && m.speed_target_limited_s >= TARGET_LIMITED_NOTE_S {
        notes.push(format!(
            "the reference held short of the target for {:.2} s in all (a voltage, current or regeneration limit)",
            m.speed_target_limited_s
        ));
    }
    for c in &m.target_clamps {
        notes.push(format!(
            "target {:.0} rpm at {:.2} s limited to {:.0} rpm (90 % of drive.limits.max_speed_rpm)",
            c.target_rpm, c.t_s, c.limited_to_rpm
        ));
    }
    if notes.is_empty() {
        verdict
    } else {
        format!("{verdict}; {}", notes.join("; "))
    }
}

/// A note on the CSV's decimation when it was chosen automatically and thins the file.
fn decimation_note(sc: &Scenario, opts: WriteOptions, always: bool) -> Option<String> {
    let (n, auto) = output::csv_decimation(sc);
    let file = opts.csv_name(&sc.name);
    let gz_hint = if sc.duration_s > 60.0 && !opts.gzip_csv {
        "; --gzip compresses it"
    } else {
        ""
    };
    match (n, auto) {
        (1, _) if !always => None,
        (1, _) => Some(format!("{file}: every control step{gz_hint}")),
        (n, true) => Some(format!(
            "{file}: one row per {n} control steps, chosen for a {:.0} s run (at most {} rows; set csv_decimation to change){gz_hint}",
            sc.duration_s,
            output::CSV_ROWS_DEFAULT_MAX
        )),
        (n, false) if always => Some(format!(
            "{file}: one row per {n} control steps (csv_decimation){gz_hint}"
        )),
        _ => None,
    }
}

/// A table cell: `x` with `decimals`, or `n/a` where there is no value (open loop has no
/// estimate).
fn cell(x: f32, decimals: usize) -> String {
    if x.is_nan() {
        "n/a".into()
    } else {
        format!("{x:.decimals$}")
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
            "{:<26} {:>9} {:>8} {:>8} {:>9} {:>8}° {:>9}  {}",
            if i == 0 { m.name.as_str() } else { "" },
            name,
            cell(w.speed_est_err_max_rpm, 2),
            cell(w.speed_err_max_rpm, 2),
            cell(w.load_est_err_mean_nm, 3),
            cell(w.orientation_err_max_deg, 2),
            cell(w.rs_est_mean_ohm, 3),
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
        out.push(format!("{:<26} {}", "", load_step_text(m, s)));
    }
    if m.rs.estimator_on {
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
    if let Some(t) = &m.inverter_test {
        out.push(format!(
            "{:<26} inverter test at start: {}{}; dead time compensated at the end {:.3} us (configured {:.3}, true {:.3}: {:+.1} %)",
            "",
            t.outcome,
            if t.tracked { ", tracked while running" } else { "" },
            t.dead_time_us,
            t.configured_dead_time_us,
            t.true_dead_time_us,
            100.0 * (t.dead_time_us - t.true_dead_time_us) / t.true_dead_time_us.max(1e-3),
        ));
    }
    if let Some(r) = &m.rotor_resistance {
        out.push(format!(
            "{:<26} rotor resistance R_R: estimate {:.3} ohm (configured {:.3}, true {:.3}: {:+.1} %); {} windows used, {} rejected; last fit: J model error {:+.2} %, residual {:.3} rpm rms",
            "",
            r.estimate_ohm,
            r.configured_ohm,
            r.true_ohm,
            100.0 * (r.estimate_ohm - r.true_ohm) / r.true_ohm.max(1e-3),
            r.updates,
            r.rejected,
            r.last_model_error_pct,
            r.last_fit_rms_rpm,
        ));
    }
    out
}

fn run_many(scenarios: &[Scenario], o: &Opts) -> Result<Vec<Metrics>, String> {
    let out = o.out();
    let mut all = Vec::new();
    println!("{}", summary_header());
    for sc in scenarios {
        let m = run_one(sc, &out, o)?;
        for l in summary_lines(&m) {
            println!("{l}");
        }
        if let Some(n) = decimation_note(sc, o.write(), false) {
            println!("{:<26} {n}", "");
        }
        all.push(m);
    }
    println!("\n{}", verdict_summary(&all));
    println!(
        "errors in rpm are maxima of 10 ms averages over each steady window (in time order); TL err is the mean |estimate - real|; outputs in {}",
        out.display()
    );
    println!("{}", acim_sim::metrics::verdict_criteria());
    if !o.sets.is_empty() {
        println!(
            "overrides applied to every scenario: --set {}",
            o.sets.join(" --set ")
        );
    }
    Ok(all)
}

/// One line over a set of runs: how many of each verdict, the expected ones named as such
/// (a scenario's `expected_verdict`, e.g. the paper's zero-speed holds, which drift).
fn verdict_summary(all: &[Metrics]) -> String {
    let mut parts = Vec::new();
    for v in [
        Verdict::Kept,
        Verdict::Drifting,
        Verdict::Lost,
        Verdict::LimitCycle,
        Verdict::Faulted,
    ] {
        let runs: Vec<&Metrics> = all.iter().filter(|m| m.verdict == v).collect();
        if runs.is_empty() {
            continue;
        }
        let mut p = format!("{} {}", runs.len(), v.as_str());
        // the expected ones, grouped by their reason
        let mut whys: Vec<(&str, Vec<&str>)> = Vec::new();
        for m in &runs {
            if let Some(e) = m
                .expected
                .as_ref()
                .filter(|e| v != Verdict::Kept && e.verdict == v)
            {
                match whys.iter_mut().find(|(w, _)| *w == e.why) {
                    Some((_, names)) => names.push(&m.name),
                    None => whys.push((&e.why, vec![&m.name])),
                }
            }
        }
        for (why, names) in whys {
            p += &format!(" ({} expected: {why})", names.join(", "));
        }
        parts.push(p);
    }
    let unexpected = all
        .iter()
        .filter(|m| {
            m.verdict != Verdict::Kept && m.expected.as_ref().map(|e| e.verdict) != Some(m.verdict)
        })
        .count();
    format!(
        "{} scenario{}: {}{}",
        all.len(),
        if all.len() == 1 { "" } else { "s" },
        parts.join(", "),
        if unexpected == 0 {
            String::new()
        } else {
            format!("; {unexpected} not as expected")
        }
    )
}

/// The named scenarios with the `--set` overrides applied.
fn scenarios(names: &[String], sets: &[String]) -> Result<Vec<Scenario>, String> {
    names.iter().map(|n| load_with(n, sets)).collect()
}

fn write_metrics_md(path: &Path, all: &[Metrics], sets: &[String]) -> Result<(), FileError> {
    let cmd = std::iter::once("figures".to_string())
        .chain(sets.iter().map(|s| format!("--set {s}")))
        .collect::<Vec<_>>()
        .join(" ");
    let mut s = format!(
        "<!-- generated by `cargo run --release -p acim-sim -- {cmd}`; do not edit -->\n\n| scenario | window | speed est. error max (rpm) | speed error max (rpm) | load est. error mean (N m) | orientation error max (deg) | Rs mean (ohm) | outcome |\n|---|---|---|---|---|---|---|---|\n",
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
            s += &format!("- {}: {}\n", m.name, load_step_text(m, st));
        }
        if m.rs.estimator_on {
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
    s += &format!("\n{}.\n", verdict_summary(all));
    s += &format!("\n{}.\n", acim_sim::metrics::verdict_criteria());
    output::write_file(path, s.as_bytes())
}

fn real_main(args: Vec<String>) -> Result<(), String> {
    // `acim-sim [OPTIONS]` is the main job; otherwise the first word is the command
    let (cmd, rest) = match args.split_first() {
        Some((c, r)) if !c.starts_with('-') || c == "-h" || c == "--help" => (Some(c.as_str()), r),
        _ => (None, &args[..]),
    };
    if cmd == Some("serve") {
        return serve(rest);
    }
    let o = Opts::parse(rest)?;
    match cmd {
        None => {
            o.at_most_positional("acim-sim", 0, "no arguments besides options")?;
            run_many(&scenarios(&builtins::paper_names(), &o.sets)?, &o)?;
        }
        Some("list") => {
            if !rest.is_empty() {
                return Err(format!(
                    "`list` takes no options or arguments, got {rest:?}"
                ));
            }
            for s in builtins::all() {
                println!("{:<28} {}", s.name, s.description);
            }
        }
        Some("run") => {
            let [spec] = o.positional.as_slice() else {
                return Err(format!("run takes one scenario name or file\n{USAGE}"));
            };
            let sc = load_with(spec, &o.sets)?;
            let out = o.out();
            let m = run_one(&sc, &out, &o)?;
            println!("{}", summary_header());
            for l in summary_lines(&m) {
                println!("{l}");
            }
            println!("\n{}", verdict_summary(std::slice::from_ref(&m)));
            println!("{}", acim_sim::metrics::verdict_criteria());
            if let Some(n) = decimation_note(&sc, o.write(), true) {
                println!("{n}");
            }
            println!(
                "simulated {:.1} s in {:.3} s ({:.0}x real time); wrote {} and {}.{{json,png}} in {}",
                m.duration_s,
                m.wall_time_s,
                m.real_time_factor,
                o.write().csv_name(&sc.name),
                sc.name,
                out.display(),
            );
        }
        Some("figures") => {
            o.at_most_positional("figures", 1, "at most one figure directory")?;
            let fig = match (o.positional.first(), o.sets.is_empty()) {
                (Some(d), _) => PathBuf::from(d),
                (None, true) => PathBuf::from("docs/figures"),
                // overridden runs must not overwrite the committed figures
                (None, false) => o.out().join("figures"),
            };
            let names: Vec<String> = builtins::all().into_iter().map(|s| s.name).collect();
            let all = run_many(&scenarios(&names, &o.sets)?, &o)?;
            let out = o.out();
            output::create_dir(&fig).map_err(|e| e.to_string())?;
            for n in &names {
                let from = out.join(format!("{n}.png"));
                let png = std::fs::read(&from).map_err(|e| FileError::new(&from, e).to_string())?;
                output::write_file(&fig.join(format!("{n}.png")), &png)
                    .map_err(|e| e.to_string())?;
            }
            write_metrics_md(&fig.join("metrics.md"), &all, &o.sets).map_err(|e| e.to_string())?;
            println!("figures and metrics.md written to {}", fig.display());
        }
        Some("stability") => {
            o.at_most_positional("stability", 1, "at most one output directory")?;
            o.reject(
                "stability",
                Some("it measures fixed operating points of the paper's machine with ideal sensors and inverter (crates/acim-sim/src/stability.rs)"),
                Some("it writes no CSV"),
            )?;
            let dir = match (o.positional.first(), &o.out) {
                (Some(p), Some(d)) if Path::new(p) != d => {
                    return Err(format!(
                        "`stability` got two output directories, {p} and --out {}",
                        d.display()
                    ))
                }
                (Some(p), _) => PathBuf::from(p),
                (None, Some(d)) => d.clone(),
                (None, None) => PathBuf::from("docs/stability"),
            };
            let gains = [
                0.0,
                acim::DriveConfig::paper_defaults()
                    .estimation
                    .orientation_gain,
            ];
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
            o.at_most_positional("observers", 1, "at most one table file")?;
            let file = table_file(&o, "observers.md");
            let out = o.out();
            let rows = acim_sim::observers::compare_with(&o.sets, &mut |sc| run_one(sc, &out, &o))?;
            let cycles =
                acim_sim::observers::bench_cycles(Path::new("benches/results/cycles.json"));
            let md = acim_sim::observers::markdown(&rows, cycles);
            write_table(&file, &with_overrides_note(md, &o.sets), &out)?;
        }
        Some("faults") => {
            o.at_most_positional("faults", 1, "at most one table file")?;
            let file = table_file(&o, "faults.md");
            let out = o.out();
            let rows = acim_sim::faults::run_all_with(&o.sets, &mut |sc| run_one(sc, &out, &o))?;
            // the same scenarios at one rate, with no slow task (unless the overrides choose
            // the slow period)
            let one_rate = if o
                .sets
                .iter()
                .any(|s| s.starts_with("drive.loops.slow_period_s"))
            {
                Vec::new()
            } else {
                let mut sets = o.sets.clone();
                sets.push(acim_sim::faults::one_rate_override());
                acim_sim::faults::run_all_with(&sets, &mut |sc| {
                    acim_sim::run_with_metrics(sc)
                        .map(|r| r.1)
                        .map_err(|e| format!("{}: {e}", sc.name))
                })?
            };
            let mut md = acim_sim::faults::markdown(&rows, &one_rate);
            // the current-sensor matrix on every acceptance machine (its own machines and
            // settings: the --set overrides apply to the fault-* scenarios only)
            let sensor = acim_sim::faults::run_sensor_cases(&mut |sc| run_one(sc, &out, &o))?;
            md.push_str(&acim_sim::faults::sensor_markdown(&sensor));
            write_table(&file, &with_overrides_note(md, &o.sets), &out)?;
        }
        Some("overhauling") => {
            o.at_most_positional("overhauling", 1, "at most one table file")?;
            let file = table_file(&o, "overhauling.md");
            let quiet = o.quiet;
            let cells = acim_sim::overhauling::sweep_with(&o.sets, &mut |sc| {
                let (_, m) =
                    acim_sim::run_with_metrics(sc).map_err(|e| format!("{}: {e}", sc.name))?;
                if !quiet {
                    eprintln!("{}: {}", sc.name, acim_sim::overhauling::judge_text(sc, &m));
                }
                Ok(m)
            })?;
            let md = acim_sim::overhauling::markdown(&cells);
            write_table(&file, &with_overrides_note(md, &o.sets), &o.out())?;
            let bad = cells.iter().filter(|c| !c.clean()).count();
            if bad > 0 {
                return Err(format!("{bad} case(s) neither held nor faulted cleanly"));
            }
        }
        Some("commission") => {
            let [spec] = o.positional.as_slice() else {
                return Err(format!(
                    "commission takes one scenario or machine file\n{USAGE}"
                ));
            };
            let mut sc = load(spec)?;
            if let Some(f) = &o.nameplate {
                let text = acim_sim::output::read_text_file(f, acim_sim::output::MAX_INPUT_BYTES)
                    .map_err(|e| format!("{}: {e}", f.display()))?;
                let t: toml::Table = acim_sim::scenario::machine_file_as_scenario(&text)
                    .parse()
                    .map_err(|e| format!("{}: {e}", f.display()))?;
                let part = |k: &str| {
                    t.get(k)
                        .cloned()
                        .ok_or(format!("{}: no [{k}]", f.display()))
                };
                sc.nameplate = Some(
                    part("nameplate")?
                        .try_into()
                        .map_err(|e| format!("{}: [nameplate]: {e}", f.display()))?,
                );
                sc.board = Some(
                    part("board")?
                        .try_into()
                        .map_err(|e| format!("{}: [board]: {e}", f.display()))?,
                );
                // the motor to simulate: the file's own [plant], or the scenario's when the
                // scenario is a file that describes one; never the paper's machine by default
                match t.get("plant") {
                    Some(p) => {
                        sc.plant = p
                            .clone()
                            .try_into()
                            .map_err(|e| format!("{}: [plant]: {e}", f.display()))?;
                        sc.controller = sc.plant;
                    }
                    None if builtins::get(spec).is_some() => {
                        return Err(format!(
                            "{}: no [plant]: commissioning simulates a motor, and `{spec}` \
                             is a built-in scenario of the paper's 750 W machine, not yours; \
                             add your motor's equivalent circuit as [plant] to {} \
                             (docs/guide/your-motor.md)",
                            f.display(),
                            f.display()
                        ));
                    }
                    None => {}
                }
            }
            let sc = sc
                .with_overrides(&o.sets)
                .map_err(|e| format!("{spec}: {e}"))?;
            // the scenario's load_profile, if any, stays coupled (a load left on)
            let run = acim_sim::commission::run(&sc)?;
            let r = &run.report;
            let out = o.out();
            std::fs::create_dir_all(&out).map_err(|e| format!("{}: {e}", out.display()))?;
            // a refused result goes to refused.toml: a controller_file never reads it
            let file = out.join(if r.refusal.is_none() {
                "identified.toml"
            } else {
                "refused.toml"
            });
            let text = r.toml();
            print!("{text}");
            std::fs::write(&file, &text).map_err(|e| format!("{}: {e}", file.display()))?;
            println!("wrote {}", file.display());
            for f in acim_sim::commission::write_figures(&run, &out)? {
                println!("wrote {}", f.display());
            }
            print!("{}", r.summary());
            if let Some(why) = &r.refusal {
                return Err(format!("{why}; identified.toml not written"));
            }
        }
        Some("any-motor") => {
            o.at_most_positional("any-motor", 1, "at most one table file")?;
            o.reject(
                "any-motor",
                Some("it runs the machine files as they are"),
                None,
            )?;
            let file = table_file(&o, "any-motor.md");
            let out = o.out();
            let figs = file
                .parent()
                .map_or_else(|| PathBuf::from("any-motor"), |d| d.join("any-motor"));
            let md = any_motor(&out, &figs, &o)?;
            write_table(&file, &md, &out)?;
        }
        Some("load-steps") => {
            o.at_most_positional("load-steps", 1, "at most one table file")?;
            o.reject(
                "load-steps",
                Some("it runs the machine files as they are"),
                Some("it writes no CSV"),
            )?;
            let file = table_file(&o, "load-steps.md");
            let quiet = o.quiet;
            let mut run = |sc: &Scenario| {
                let (r, m) =
                    acim_sim::run_with_metrics(sc).map_err(|e| format!("{}: {e}", sc.name))?;
                Ok((r.rows, m))
            };
            // the default drive (the nameplate's: the flux observer) and the paper's observer
            let (mut default, mut paper) = (Vec::new(), Vec::new());
            for m in &acim_sim::load_steps::MACHINES {
                let p = acim_sim::load_steps::prepare(m)?;
                for (observer, sets, cases) in [
                    ("default", vec![], &mut default),
                    (
                        "paper's",
                        vec!["drive.observer=\"reduced\"".to_string()],
                        &mut paper,
                    ),
                ] {
                    let c = acim_sim::load_steps::cases(&p, &sets, &mut run)?;
                    if !quiet {
                        for c in &c {
                            eprintln!(
                                "{} ({observer} observer) {:.0} rpm {:+.1} N m: {}",
                                m.name,
                                c.rpm,
                                c.load_nm,
                                c.failure().unwrap_or_else(|| "pass".into())
                            );
                        }
                    }
                    cases.extend(c);
                }
            }
            let md = acim_sim::load_steps::markdown(&default, &paper);
            write_table(&file, &md, &o.out())?;
            let bad = default.iter().filter(|c| c.failure().is_some()).count();
            if bad > 0 {
                return Err(format!(
                    "{bad} case(s) of the default drive outside their bounds"
                ));
            }
        }
        Some("low-speed") => {
            o.at_most_positional("low-speed", 1, "at most one table file")?;
            o.reject(
                "low-speed",
                Some("it runs the machine files as they are"),
                Some("it writes no CSV"),
            )?;
            let file = table_file(&o, "low-speed.md");
            let quiet = o.quiet;
            let mut run = |sc: &Scenario| {
                let (r, m) =
                    acim_sim::run_with_metrics(sc).map_err(|e| format!("{}: {e}", sc.name))?;
                Ok((r.rows, m))
            };
            let mut all = Vec::new();
            for m in &acim_sim::load_steps::MACHINES {
                let p = acim_sim::load_steps::prepare(m)?;
                let c = acim_sim::low_speed::cases(&p, &mut run)?;
                if !quiet {
                    for c in &c {
                        eprintln!(
                            "{} {} {:.1} rpm {:+.2} N m: {} {}",
                            m.name,
                            c.error.label(),
                            c.rpm,
                            c.load_nm,
                            c.cell(),
                            c.failure().unwrap_or_else(|| "pass".into())
                        );
                    }
                }
                all.extend(c);
            }
            let md = acim_sim::low_speed::markdown(&all);
            write_table(&file, &md, &o.out())?;
            let bad = all
                .iter()
                .filter(|c| c.asserted && c.failure().is_some())
                .count();
            if bad > 0 {
                return Err(format!("{bad} asserted low-speed case(s) fail"));
            }
        }
        Some("capability") => {
            o.at_most_positional("capability", 1, "at most one table file")?;
            o.reject(
                "capability",
                Some("its operating points are defined in crates/acim-sim/src/capability.rs"),
                Some("it writes no CSV"),
            )?;
            let file = table_file(&o, "capability.md");
            let points = acim_sim::capability::measure_with(&mut |sc| {
                acim_sim::run_with_metrics(sc)
                    .map(|r| r.1)
                    .map_err(|e| format!("{}: {e}", sc.name))
            })?;
            for p in &points {
                println!(
                    "{:6.0} rpm: envelope {:6.2} N m; held {:6.2} N m ({:3.0} %) linear, {:6.2} N m ({:3.0} %) overmodulation",
                    p.rpm,
                    p.envelope_nm,
                    p.held_nm,
                    100.0 * p.held_nm / p.envelope_nm.max(1e-6),
                    p.held_overmodulation_nm,
                    100.0 * p.held_overmodulation_nm / p.envelope_nm.max(1e-6)
                );
            }
            let md = acim_sim::capability::markdown(&points);
            print!("{md}");
            if let Some(dir) = file.parent().filter(|d| !d.as_os_str().is_empty()) {
                output::create_dir(dir).map_err(|e| e.to_string())?;
            }
            let png = file.with_extension("png");
            acim_sim::capability::plot(&points, &png)
                .map_err(|e| format!("{}: {e}", png.display()))?;
            output::write_file(&file, md.as_bytes()).map_err(|e| e.to_string())?;
            println!("\nwrote {} and {}", file.display(), png.display());
        }
        Some("linear-stability") => {
            o.at_most_positional("linear-stability", 1, "at most one table file")?;
            o.reject(
                "linear-stability",
                Some("its points and errors are defined in crates/acim-sim/src/stability.rs"),
                Some("it writes no CSV"),
            )?;
            let file = table_file(&o, "linear-stability.md");
            let (md, unstable) = acim_sim::linear::map_markdown().map_err(|e| e.to_string())?;
            write_table(&file, &md, &o.out())?;
            if !o.quiet {
                println!("{unstable} unstable points with |f_s| >= 1 Hz (all errors)");
            }
        }
        Some("robust-stability") => {
            o.at_most_positional("robust-stability", 1, "at most one table file")?;
            o.reject(
                "robust-stability",
                Some("its points and errors are defined in crates/acim-sim/src/stability.rs"),
                Some("it writes no CSV"),
            )?;
            let file = table_file(&o, "robust-stability.md");
            let quiet = o.quiet;
            let md = acim_sim::stability::robust_map_markdown(&mut |l| {
                if !quiet {
                    eprintln!("{l}");
                }
            })
            .map_err(|e| e.to_string())?;
            write_table(&file, &md, &o.out())?;
        }
        Some("robustness") => {
            o.at_most_positional("robustness", 1, "at most one table file")?;
            o.reject("robustness", None, Some("it writes no CSV"))?;
            let file = table_file(&o, "robustness-matrix.md");
            let quiet = o.quiet;
            let md = acim_sim::robustness::report(&o.sets, &mut |l| {
                if !quiet {
                    eprintln!("{l}");
                }
            })
            .map_err(|e| e.to_string())?;
            write_table(&file, &with_overrides_note(md, &o.sets), &o.out())?;
        }
        Some("-h" | "--help" | "help") => println!("{USAGE}"),
        Some(other) => return Err(format!("unknown command `{other}`\n{USAGE}")),
    }
    Ok(())
}

/// `acim-sim any-motor`: every acceptance machine commissioned, then its scenarios with
/// the identified model; PNGs to `figs`, the Markdown table returned.
fn any_motor(out: &Path, figs: &Path, o: &Opts) -> Result<String, String> {
    use acim_sim::machines::{prepare, MACHINES};
    std::fs::create_dir_all(figs).map_err(|e| format!("{}: {e}", figs.display()))?;
    let mut md = String::from(
        "<!-- generated by `cargo run --release -p acim-sim -- any-motor`; do not edit -->\n\n\
         Each machine commissioned from its nameplate against its plant, then driven with the \
         identified model only. Steady speed-estimation error / speed error, maxima of 10 ms \
         averages in rpm; the acceptance bound is 1 % of rated speed.\n\n\
         | machine | rated-load step | reversal at 1/3 rated | 3 % trapezoid | 70 % rated regeneration | 1 % of rated (rpm) |\n|---|---|---|---|---|---|\n",
    );
    let mut identified = String::from(
        "\nCommissioning against the plant (`acim-sim commission`), identified against true, \
         errors in % (acceptance in the header):\n\n\
         | machine | Rs (2) | R_R (5) | L_sigma (5) | L_M at rated flux (5) | J (10) | dead time (10) | time (s) |\n|---|---|---|---|---|---|---|---|\n",
    );
    let mut reports = String::from(
        "\n## Commissioning reports\n\n\
         Each quantity as identified, the identification's own bound on its error (its fit \
         repeated on each half of its window, its inputs moved by their bounds: what a user \
         without the true values judges by), the plant's true value and the error. The figure \
         is the whole sequence (`acim-sim commission` writes it and four more beside \
         `identified.toml`). The bound does not cover the current sensors' calibration, which \
         commissioning cannot see: their gain error scales every impedance alike (these runs \
         have +-0.3 % on the two measured channels: Rs -0.32 %, marked outside its bound), and \
         with their offsets it moves the no-load hold's small torque, which friction B rests \
         on (errors of 9-42 % against bounds of 7-36 %: B enters the speed loop's friction \
         feed-forward and the observers' mechanical models, where the load estimate takes up \
         what it misses). \
         `tests/commissioning.rs` runs the same machines with noise alone: every error within \
         its bound.\n",
    );
    for m in MACHINES.iter() {
        let (run, scenarios, rated_rpm) = prepare(m)?;
        let report = &run.report;
        let dir = out.join(format!("{}-commission", m.name));
        std::fs::create_dir_all(&dir).map_err(|e| format!("{}: {e}", dir.display()))?;
        acim_sim::commission::write_figures(&run, &dir)?;
        let fig = format!("{}-commissioning.png", m.name);
        std::fs::copy(dir.join("commission-overview.png"), figs.join(&fig))
            .map_err(|e| format!("{}: {e}", figs.join(&fig).display()))?;
        reports += &format!(
            "\n### {}\n\n{}\n![commissioning of {}](any-motor/{fig})\n",
            m.name,
            report.markdown_table(),
            m.name
        );
        let e = |p: &acim_sim::commission::Pair| format!("{:+.2}", p.error_pct);
        identified += &format!(
            "| {} | {} | {} | {} | {} | {} | {} | {:.1} |\n",
            m.name,
            e(&report.rs_ohm),
            e(&report.rr_ohm),
            e(&report.l_sigma_h),
            e(&report.l_m_h),
            report
                .inertia_kgm2
                .as_ref()
                .map_or("not resolved".into(), e),
            e(&report.dead_time_s),
            report.total_s
        );
        let mut cells = Vec::new();
        for (k, sc) in scenarios.iter().enumerate() {
            let met = run_one(sc, out, o)?;
            let png = format!("{}.png", sc.name);
            std::fs::copy(out.join(&png), figs.join(&png))
                .map_err(|e| format!("{}: {e}", figs.join(&png).display()))?;
            let pick = |w: &str| {
                met.windows.iter().find(|(n, _)| n.as_str() == w).map_or(
                    "-".to_string(),
                    |(_, x)| {
                        format!(
                            "{:.2} / {:.2}",
                            x.speed_est_err_max_rpm, x.speed_err_max_rpm
                        )
                    },
                )
            };
            let cell = match (&met.fault, k) {
                (Some(f), _) => format!("{f} (not met)"),
                (None, 0) => format!("{}; {}", pick("rated-load"), pick("reversed")),
                (None, 1) => pick("reverse"),
                (None, _) => pick("regenerating"),
            };
            cells.push(cell);
        }
        let (load, rev) = cells[0]
            .split_once("; ")
            .map_or((cells[0].clone(), cells[0].clone()), |(a, b)| {
                (a.into(), b.into())
            });
        md += &format!(
            "| {} | {load} | {rev} | {} | {} | {:.2} |\n",
            m.name,
            cells[1],
            cells[2],
            0.01 * rated_rpm
        );
    }
    Ok(md + &identified + &reports)
}

/// The table file of `observers`/`faults`: the positional FILE, else `docs/<name>`, or
/// `<out>/<name>` when `--set` changed the scenarios (the committed table stays as is).
fn table_file(o: &Opts, name: &str) -> PathBuf {
    match (o.positional.first(), o.sets.is_empty()) {
        (Some(f), _) => PathBuf::from(f),
        (None, true) => Path::new("docs").join(name),
        (None, false) => o.out().join(name),
    }
}

fn with_overrides_note(mut md: String, sets: &[String]) -> String {
    if !sets.is_empty() {
        md += &format!(
            "\nOverrides applied to every run: `--set {}`.\n",
            sets.join(" --set ")
        );
    }
    md
}

/// `acim-sim serve [--tcp ADDR] [--speed FACTOR|max] [--rate PERIODS]`: the virtual
/// board until the process is stopped.
fn serve(args: &[String]) -> Result<(), String> {
    let mut addr = "127.0.0.1:7878".to_string();
    let mut opts = acim_vboard::server::Options::default();
    let mut it = args.iter();
    while let Some(a) = it.next() {
        let mut value = |what: &str| {
            it.next()
                .cloned()
                .ok_or_else(|| format!("serve: {a} needs {what}"))
        };
        match a.as_str() {
            "--tcp" => addr = value("an address, e.g. 127.0.0.1:7878")?,
            "--speed" => opts.pace = acim_vboard::server::Pace::parse(&value("a factor or max")?)?,
            "--rate" => {
                let v = value("a number of control periods")?;
                let n = v
                    .parse::<u16>()
                    .ok()
                    .filter(|n| {
                        (acim_vboard::protocol_limits::MIN_RATE_PERIODS
                            ..=acim_vboard::protocol_limits::MAX_RATE_PERIODS)
                            .contains(n)
                    })
                    .ok_or_else(|| {
                        format!(
                            "serve: --rate takes {}..={} control periods, got {v:?}",
                            acim_vboard::protocol_limits::MIN_RATE_PERIODS,
                            acim_vboard::protocol_limits::MAX_RATE_PERIODS
                        )
                    })?;
                opts.rate = Some(n);
            }
            "-h" | "--help" => {
                println!("{SERVE_USAGE}");
                return Ok(());
            }
            other => return Err(format!("serve: unknown option {other:?}\n{SERVE_USAGE}")),
        }
    }
    let listener = std::net::TcpListener::bind(&addr)
        .map_err(|e| format!("serve: cannot listen on {addr}: {e}"))?;
    let server = acim_vboard::server::start(listener, opts)
        .map_err(|e| format!("serve: cannot start: {e}"))?;
    let pace = match opts.pace {
        acim_vboard::server::Pace::Max => "as fast as it runs".to_string(),
        acim_vboard::server::Pace::Factor(1.0) => "real time".to_string(),
        acim_vboard::server::Pace::Factor(f) => format!("{f}x real time"),
    };
    println!(
        "virtual board on tcp {} ({pace}); watch it: cargo run --release -p acim-monitor -- --tcp {}",
        server.local_addr(),
        server.local_addr()
    );
    server.wait();
    Ok(())
}

const SERVE_USAGE: &str = "usage: acim-sim serve [--tcp ADDR] [--speed FACTOR|max] [--rate PERIODS]
  the virtual board: the firmware's control loop (ControlLoop + SimulatedStage) speaking
  the firmware's protocol (docs/protocol.md) on a local TCP port
  --tcp ADDR        listen address (default 127.0.0.1:7878; port 0 picks a free one)
  --speed FACTOR    simulated seconds per second (default 1, real time), or max
  --rate PERIODS    telemetry every PERIODS control periods at start (default 500: 10 Hz)";

/// The arguments as text: one that is not valid Unicode is a usage error naming it.
fn args_text(args: impl Iterator<Item = std::ffi::OsString>) -> Result<Vec<String>, String> {
    args.enumerate()
        .map(|(i, a)| {
            a.into_string().map_err(|a| {
                format!(
                    "argument {} ({}) is not valid Unicode: file and directory names must be \
                     UTF-8 text",
                    i + 1,
                    a.to_string_lossy()
                )
            })
        })
        .collect()
}

fn main() -> ExitCode {
    let args = match args_text(std::env::args_os().skip(1)) {
        Ok(a) => a,
        Err(e) => {
            eprintln!("acim-sim: {e}\n{USAGE}");
            return ExitCode::from(2);
        }
    };
    match real_main(args) {
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
    if let Some(dir) = file.parent().filter(|d| !d.as_os_str().is_empty()) {
        output::create_dir(dir).map_err(|e| e.to_string())?;
    }
    output::write_file(file, md.as_bytes()).map_err(|e| e.to_string())?;
    println!(
        "\nwrote {} (run outputs in {})",
        file.display(),
        out.display()
    );
    Ok(())
}
