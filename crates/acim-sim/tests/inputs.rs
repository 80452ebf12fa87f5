//! Inputs a user can get wrong, found by an adversarial review: a machine file's parse
//! error quotes the user's own line, an empty `--out=` and a non-Unicode argument are
//! usage errors, PWM frequencies and periods out of range name their field, and every file
//! the command line reads goes through the bounded reader.

use std::ffi::OsStr;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn sim<S: AsRef<OsStr>>(args: &[S], dir: &Path) -> Output {
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
    let d = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(format!("inputs-{name}"));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn fails_with(o: &Output, needle: &str) -> String {
    let err = text(&o.stderr);
    assert!(!o.status.success(), "should fail: {err}");
    assert!(err.contains(needle), "stderr lacks `{needle}`: {err}");
    err
}

/// A machine file goes through `machine_file_as_scenario`, which re-serialises it; its
/// errors must still quote the user's own line, with the user's line number.
#[test]
fn machine_file_errors_quote_the_users_own_line() {
    let d = scratch("machine-line");
    for m in acim_sim::machines::MACHINES {
        // the [plant] table's inertia line, replaced by a wrong type with a comment
        let lines: Vec<&str> = m.text.lines().collect();
        let plant = lines.iter().position(|l| l.trim() == "[plant]").unwrap();
        let n = plant
            + lines[plant..]
                .iter()
                .position(|l| l.starts_with("inertia_kgm2"))
                .unwrap();
        let bad = "inertia_kgm2 = \"heavy\"    # my flywheel";
        let mut edited: Vec<&str> = lines.clone();
        edited[n] = bad;
        let file = d.join(format!("{}.toml", m.name));
        std::fs::write(&file, edited.join("\n") + "\n").unwrap();
        let o = sim(&["run", file.to_str().unwrap(), "--out", "res"], &d);
        let err = fails_with(&o, bad);
        assert!(
            err.contains(&format!("line {}", n + 1)),
            "{}: not at line {}: {err}",
            m.name,
            n + 1
        );
        // and the library function reports the same
        let e = acim_sim::scenario::Scenario::from_file_text(&(edited.join("\n") + "\n"))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains(bad) && e.contains(&format!("line {}", n + 1)),
            "{e}"
        );
        // the files themselves still read as before
        let direct = acim_sim::scenario::Scenario::from_toml(
            &acim_sim::scenario::machine_file_as_scenario(m.text),
        )
        .unwrap();
        assert_eq!(
            acim_sim::scenario::Scenario::from_file_text(m.text).unwrap(),
            direct
        );
    }
    // a plain scenario file's error, as before, on its own line
    std::fs::write(
        d.join("plain.toml"),
        "name = \"plain\"\n\n[drive]\nflux_current_a = \"lots\" # mine\n",
    )
    .unwrap();
    let o = sim(&["run", "plain.toml"], &d);
    let err = fails_with(&o, "flux_current_a = \"lots\" # mine");
    assert!(err.contains("line 4"), "{err}");
    assert!(!d.join("res").exists());
}

/// `--out=` with nothing after it would write into the working directory.
#[test]
fn an_empty_out_is_a_usage_error() {
    let d = scratch("empty-out");
    for args in [
        &["run", "vf-open-loop", "--out="][..],
        &["run", "vf-open-loop", "--out", ""][..],
    ] {
        fails_with(&sim(args, &d), "--out needs a directory");
    }
    let left: Vec<_> = std::fs::read_dir(&d).unwrap().collect();
    assert!(left.is_empty(), "{left:?}");
}

/// An argument that is not valid Unicode (a file name in another encoding) is a usage
/// error, exit code 2, not a panic (101).
#[cfg(unix)]
#[test]
fn a_non_unicode_argument_is_a_usage_error() {
    use std::os::unix::ffi::OsStrExt;
    let d = scratch("non-unicode");
    let bad = OsStr::from_bytes(b"sc\xe9nario.toml");
    for args in [
        vec![OsStr::new("run"), bad],
        vec![
            OsStr::new("run"),
            OsStr::new("paper-fig7"),
            OsStr::new("--out"),
            bad,
        ],
        vec![bad],
    ] {
        let o = sim(&args, &d);
        let err = fails_with(&o, "is not valid Unicode");
        assert_eq!(o.status.code(), Some(2), "{err}");
        assert!(!err.contains("panicked"), "{err}");
    }
}

/// A PWM frequency or control period out of range names the field the user wrote, on
/// every path: a scenario's period, a machine file's board, and their overrides.
#[test]
fn pwm_frequency_and_period_errors_name_the_field() {
    let d = scratch("pwm");
    let machine = d.join("paper.toml");
    std::fs::write(&machine, acim_sim::machines::MACHINES[0].text).unwrap();
    let m = machine.to_str().unwrap();
    for (args, field) in [
        (
            vec![
                "run",
                "paper-fig7",
                "--set",
                "drive.loops.control_period_s=1",
            ],
            "drive.loops.control_period_s",
        ),
        (
            vec![
                "run",
                "paper-fig7",
                "--set",
                "drive.loops.control_period_s=1e-6",
            ],
            "drive.loops.control_period_s",
        ),
        (
            vec!["run", m, "--set", "board.pwm_frequency_hz=1"],
            "board.pwm_frequency_hz",
        ),
        (
            vec!["run", m, "--set", "board.pwm_frequency_hz=1e6"],
            "board.pwm_frequency_hz",
        ),
        (
            vec!["commission", m, "--set", "board.pwm_frequency_hz=1"],
            "board.pwm_frequency_hz",
        ),
    ] {
        let o = sim(&args, &d);
        let err = fails_with(&o, field);
        assert!(!err.contains("panicked"), "{args:?}: {err}");
    }
    let mut with_board = acim_sim::machines::MACHINES[0].text.to_string();
    with_board += "pwm_frequency_hz = 1\n";
    std::fs::write(d.join("pwm1.toml"), with_board).unwrap();
    fails_with(&sim(&["run", "pwm1.toml"], &d), "board.pwm_frequency_hz");
}

/// Every file the command line reads is read with the bounded reader: a folder, a device
/// and a missing file are clear errors naming the path.
#[cfg(unix)]
#[test]
fn every_file_read_is_bounded_and_named() {
    let d = scratch("files");
    std::fs::create_dir_all(d.join("folder.toml")).unwrap();
    let machine = d.join("paper.toml");
    std::fs::write(&machine, acim_sim::machines::MACHINES[0].text).unwrap();
    let m = machine.to_str().unwrap();
    for (args, needle) in [
        (vec!["run", "folder.toml"], "folder.toml: is a folder"),
        (vec!["run", "/dev/zero"], "/dev/zero: is not a regular file"),
        (vec!["run", "missing.toml"], "missing.toml"),
        (
            vec!["commission", m, "--nameplate", "/dev/zero"],
            "/dev/zero: is not a regular file",
        ),
        (
            vec!["commission", m, "--nameplate", "folder.toml"],
            "is a folder",
        ),
    ] {
        fails_with(&sim(&args, &d), needle);
    }
}
