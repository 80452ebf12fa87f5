//! The `acim-sim` command line as a user meets it: every subcommand honours `--out` and
//! `--set` or rejects them with a reason; bad names, empty files and unwritable places
//! are clear errors naming the field or path; files appear whole or not at all; no
//! progress bar when stderr is not a terminal.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn sim(args: &[&str], dir: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_acim-sim"))
        .args(args)
        .current_dir(dir)
        .output()
        .expect("acim-sim runs")
}

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

/// A fresh, empty directory under the target dir for one test.
fn scratch(name: &str) -> PathBuf {
    let d = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(format!("cli-{name}"));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn files(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .map(|r| {
            r.map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
                .collect()
        })
        .unwrap_or_default();
    v.sort();
    v
}

fn fails_with(o: &Output, needle: &str) {
    let err = text(&o.stderr);
    assert!(!o.status.success(), "should fail: {err}");
    assert!(err.contains(needle), "stderr lacks `{needle}`: {err}");
}

#[test]
fn subcommands_reject_options_they_cannot_honour() {
    let d = scratch("reject");
    fails_with(&sim(&["list", "--out", "x"], &d), "`list` takes no options");
    fails_with(
        &sim(&["list", "--set", "seed=2"], &d),
        "`list` takes no options",
    );
    fails_with(
        &sim(&["stability", "--set", "sensors.adc_bits=8"], &d),
        "`stability` does not take --set",
    );
    fails_with(
        &sim(&["robustness", "--gzip"], &d),
        "`robustness` does not take --gzip",
    );
    for cmd in ["capability", "robust-stability", "any-motor"] {
        fails_with(
            &sim(&[cmd, "--set", "drive.estimation.orientation_gain=3"], &d),
            "does not take --set",
        );
    }
    fails_with(
        &sim(&["stability", "a", "--out", "b"], &d),
        "two output directories",
    );
    fails_with(
        &sim(&["run", "paper-fig7", "--bogus"], &d),
        "unknown option --bogus",
    );
    fails_with(
        &sim(&["figures", "a", "b"], &d),
        "at most one figure directory",
    );
    fails_with(&sim(&["observers", "a", "b"], &d), "at most one table file");
    fails_with(&sim(&["faults", "a", "b"], &d), "at most one table file");
    fails_with(&sim(&["stray"], &d), "unknown command `stray`");
    // nothing was written by any of these
    assert!(files(&d).is_empty(), "{:?}", files(&d));
}

#[test]
fn run_honours_out_and_set_and_reports_what_ran() {
    let d = scratch("run");
    let o = sim(
        &[
            "run",
            "paper-fig8-rs",
            "--out",
            "res",
            "--set",
            "name=rs-short",
        ],
        &d,
    );
    assert!(o.status.success(), "{}", text(&o.stderr));
    // no progress bar when stderr is not a terminal
    assert!(o.stderr.is_empty(), "{}", text(&o.stderr));
    assert_eq!(
        files(&d.join("res")),
        ["rs-short.csv", "rs-short.json", "rs-short.png"]
    );
    let out = text(&o.stdout);
    // the Rs estimator is off in fig 8: no Rs convergence line
    assert!(!out.contains("Rs 15.75 ->"), "{out}");
    assert!(
        out.contains("is judged at that rating): faulted ="),
        "{out}"
    );
    let raw = std::fs::read_to_string(d.join("res/rs-short.json")).unwrap();
    let json: serde_json::Value = serde_json::from_str(&raw).unwrap();
    assert_eq!(json["schema_version"], 1);
    assert_eq!(json["name"], "rs-short");
    assert_eq!(json["rs"]["estimator_on"], false);
    // windows keep the scenario's time order, not alphabetical order
    // (in the file's text: serde_json's Value sorts keys)
    let at = |k: &str| raw.find(&format!("\"{k}\": {{")).unwrap();
    assert!(
        at("no-load") < at("load") && at("load") < at("unloaded"),
        "{raw}"
    );

    // with the estimator on, the line appears
    let o = sim(&["run", "paper-fig9", "--out", "res"], &d);
    assert!(
        text(&o.stdout).contains("Rs 15.75 ->"),
        "{}",
        text(&o.stdout)
    );
}

#[test]
fn bad_names_files_and_overrides_are_clear_errors() {
    let d = scratch("bad");
    std::fs::write(
        d.join("escape.toml"),
        "name = \"../../escape\"\nduration_s = 0.1\n",
    )
    .unwrap();
    let o = sim(&["run", "escape.toml", "--out", "res"], &d);
    fails_with(&o, "scenario field `name`");
    std::fs::write(d.join("empty.toml"), "# nothing but a comment\n").unwrap();
    fails_with(
        &sim(&["run", "empty.toml", "--out", "res"], &d),
        "sets no fields",
    );
    for name in ["", ".hidden", "a/b", "..", "a\\\\b"] {
        let o = sim(
            &[
                "run",
                "paper-fig7",
                "--out",
                "res",
                "--set",
                &format!("name=\"{name}\""),
            ],
            &d,
        );
        fails_with(&o, "scenario field `name`");
    }
    // an override error names the override, without line numbers of an internal file
    let o = sim(
        &["run", "paper-fig7", "--set", "sensors.adc_bits=twelve"],
        &d,
    );
    fails_with(&o, "scenario field `sensors.adc_bits`");
    assert!(!text(&o.stderr).contains("line"), "{}", text(&o.stderr));
    fails_with(
        &sim(&["run", "paper-fig7", "--set", "sensor.adc_bits=8"], &d),
        "unknown field `sensor`",
    );
    fails_with(&sim(&["run", "missing.toml"], &d), "missing.toml:");
    // --out naming a file: the error names the path
    std::fs::write(d.join("plain-file"), "x").unwrap();
    let o = sim(&["run", "vf-open-loop", "--out", "plain-file"], &d);
    fails_with(&o, "plain-file");
    assert!(!d.join("res").exists());
    assert!(!d.parent().unwrap().join("escape.csv").exists());
}

#[test]
fn long_runs_are_decimated_by_default_and_gzip_is_optional() {
    let d = scratch("long");
    let o = sim(
        &[
            "run",
            "paper-fig7",
            "--out",
            "res",
            "--gzip",
            "--set",
            "duration_s=45",
        ],
        &d,
    );
    assert!(o.status.success(), "{}", text(&o.stderr));
    let out = text(&o.stdout);
    assert!(
        out.contains("paper-fig7.csv.gz: one row per 3 control steps, chosen for a 45 s run"),
        "{out}"
    );
    let gz = std::fs::File::open(d.join("res/paper-fig7.csv.gz")).unwrap();
    let mut csv = String::new();
    std::io::Read::read_to_string(&mut flate2::read::GzDecoder::new(gz), &mut csv).unwrap();
    let mut lines = csv.lines();
    let header = lines.next().unwrap();
    assert_eq!(header, acim_sim::sim::CSV_HEADER);
    assert!(header.ends_with(
        "voltage_saturated,modulation_index,state_name,fault_reason,speed_target_limited,speed_target_rpm,i_phase_peak_switching_a,hardware_trip"
    ));
    assert_eq!(lines.count(), 75_000); // 225 000 steps, every 3rd
    assert_eq!(files(&d.join("res")).len(), 3);
}

#[test]
fn observers_and_faults_honour_set_without_touching_the_committed_tables() {
    let d = scratch("tables");
    let o = sim(
        &[
            "faults",
            "--out",
            "res",
            "--set",
            "sensors.adc_bits=10",
            "--quiet",
        ],
        &d,
    );
    assert!(o.status.success(), "{}", text(&o.stderr));
    let md = std::fs::read_to_string(d.join("res/faults.md")).unwrap();
    assert!(md.contains("`--set sensors.adc_bits=10`"), "{md}");
    assert!(files(&d.join("res")).contains(&"fault-short.csv".to_string()));
    assert!(!d.join("docs").exists());
}
