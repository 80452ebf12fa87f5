//! the overhauling-load sweep: an active load that drives the machine (0 to 12 N m,
//! the paper machine's torque capability is about 10.3 N m at the 4.67 A current limit)
//! applied at 2.5 s while the drive holds 500, 120 or 60 rpm. Each case must be held (at
//! its target, or at the reachable speed the low-frequency regeneration limit allows,
//! reported as limited) or end in a clean fault (switched off, never switching beyond the
//! current trip or 110 % of the speed limit for more than 5 ms). `acim-sim overhauling`
//! writes the table to `docs/overhauling.md`; `tests/fault_scenarios.rs` asserts it.

use crate::builtins;
use crate::metrics::Metrics;
use crate::scenario::{LoadKind, LoadPoint, Scenario, SpeedPoint, Window};
use std::fmt::Write as _;

/// Speeds held, rpm.
pub const SPEEDS_RPM: [f32; 3] = [500.0, 120.0, 60.0];
/// Overhauling load torques, N m (the load drives the rotor forwards).
pub const LOADS_NM: [f32; 13] = [
    0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0, 10.0, 11.0, 12.0,
];
/// When the load steps in, s.
pub const LOAD_AT_S: f32 = 2.5;
/// Run length, s; the judged window is the last [`WINDOW_S`].
pub const DURATION_S: f32 = 6.0;
/// Length of the judged window at the end, s.
pub const WINDOW_S: f32 = 1.5;
/// Longest time switching beyond the trip or 110 % of the speed limit a clean outcome
/// allows, s (5 ms).
pub const BEYOND_LIMIT_S: f32 = 0.005;

/// How one case ended.
#[derive(Clone, Debug, PartialEq)]
pub enum Outcome {
    /// No fault; the window's mean speed within max(4 rpm, 2 %) of the target.
    Held,
    /// No fault; the speed held steady (within 100 rpm of the drive's held reference)
    /// above the target, the target reported as limited: the regeneration limit keeps the
    /// stator frequency away from zero and the load pushes the speed up to where the
    /// braking torque it allows balances the load.
    Limited {
        /// Window mean speed, rpm.
        speed_rpm: f32,
    },
    /// The drive faulted and switched off.
    Fault {
        /// The reason the drive gave.
        reason: String,
        /// From the load step to the switch-off, s.
        after_s: f32,
    },
    /// None of these: the speed neither held nor faulted (the failure this sweep looks
    /// for).
    NotHeld {
        /// Largest |speed - reference| of the window's 10 ms means, rpm.
        speed_err_rpm: f32,
    },
}

/// One case of the sweep.
#[derive(Clone, Debug)]
pub struct Cell {
    /// Target speed, rpm.
    pub rpm: f32,
    /// Overhauling load, N m.
    pub load_nm: f32,
    /// Stator frequency of the operating point at the target, Hz (paper machine, rated
    /// flux): w_s = p Omega + R_R i_sq / lambda with T_e = -T_L + B Omega.
    pub stator_frequency_hz: f32,
    /// How it ended.
    pub outcome: Outcome,
    /// The run's metrics.
    pub metrics: Metrics,
}

impl Cell {
    /// Held, limited and reported, or a clean fault; and never switching beyond the
    /// limits for more than [`BEYOND_LIMIT_S`].
    pub fn clean(&self) -> bool {
        !matches!(self.outcome, Outcome::NotHeld { .. })
            && self.metrics.switching_beyond_limits_s <= BEYOND_LIMIT_S
    }
}

/// The scenario of one case: the built-in overhauling scenario (paper machine, default
/// drive, the scenarios' realistic sensors) with this speed and load.
pub fn scenario(rpm: f32, load_nm: f32) -> Scenario {
    let mut s = builtins::get("fault-overhauling-500-8nm").expect("built-in scenario");
    s.name = format!("overhauling-{rpm:.0}-{load_nm:.0}nm");
    s.description = format!("overhauling load {load_nm} N m at {rpm} rpm");
    s.duration_s = DURATION_S;
    s.speed_profile = vec![SpeedPoint { t_s: 0.5, rpm }];
    s.load_profile = vec![LoadPoint {
        t_s: LOAD_AT_S,
        kind: LoadKind::Active,
        torque_nm: -load_nm,
    }];
    s.windows = vec![Window {
        name: "end".into(),
        from_s: DURATION_S - WINDOW_S,
        to_s: DURATION_S,
    }];
    s
}

/// Stator frequency of the steady operating point at `rpm` against `load_nm` of
/// overhauling load, Hz (the robustness matrix's computation: paper machine, rated flux).
pub fn stator_frequency_hz(rpm: f32, load_nm: f32) -> f32 {
    crate::robustness::Case {
        rpm,
        regenerating: true,
        load_nm,
        variant: crate::robustness::Variant::Nominal,
    }
    .stator_frequency_hz()
}

/// Judges one run.
pub fn judge(rpm: f32, m: &Metrics) -> Outcome {
    if let (Some(reason), Some(t)) = (&m.fault, m.fault_time_s) {
        return Outcome::Fault {
            reason: reason.clone(),
            after_s: t - LOAD_AT_S,
        };
    }
    let w = &m.windows["end"];
    if w.speed_err_max_rpm > 100.0 {
        return Outcome::NotHeld {
            speed_err_rpm: w.speed_err_max_rpm,
        };
    }
    if (w.speed_mean_rpm - rpm).abs() <= (0.02 * rpm).max(4.0) {
        Outcome::Held
    } else if m.speed_target_limited_s > 0.0 {
        Outcome::Limited {
            speed_rpm: w.speed_mean_rpm,
        }
    } else {
        Outcome::NotHeld {
            speed_err_rpm: w.speed_err_max_rpm,
        }
    }
}

/// Runs every case with `sets` applied, each through `run`.
pub fn sweep_with(
    sets: &[String],
    run: &mut dyn FnMut(&Scenario) -> Result<Metrics, String>,
) -> Result<Vec<Cell>, String> {
    let mut cells = Vec::new();
    for rpm in SPEEDS_RPM {
        for load_nm in LOADS_NM {
            let sc = scenario(rpm, load_nm)
                .with_overrides(sets)
                .map_err(|e| e.to_string())?;
            let metrics = run(&sc)?;
            cells.push(Cell {
                rpm,
                load_nm,
                stator_frequency_hz: stator_frequency_hz(rpm, load_nm),
                outcome: judge(rpm, &metrics),
                metrics,
            });
        }
    }
    Ok(cells)
}

/// [`sweep_with`] without overrides, each case run in memory.
pub fn sweep() -> Result<Vec<Cell>, String> {
    sweep_with(&[], &mut |sc| {
        crate::run_with_metrics(sc)
            .map(|r| r.1)
            .map_err(|e| format!("{}: {e}", sc.name))
    })
}

/// The outcome of the run of `sc` (a [`scenario`] of this sweep) in a few words.
pub fn judge_text(sc: &Scenario, m: &Metrics) -> String {
    let rpm = sc.speed_profile.first().map_or(0.0, |p| p.rpm);
    outcome_text(&judge(rpm, m))
}

/// The outcome in a few words.
pub fn outcome_text(o: &Outcome) -> String {
    match o {
        Outcome::Held => "held".into(),
        Outcome::Limited { speed_rpm } => {
            format!("held at {speed_rpm:.0} rpm, reported limited")
        }
        Outcome::Fault { reason, after_s } => {
            format!("{reason} after {:.0} ms", after_s * 1e3)
        }
        Outcome::NotHeld { speed_err_rpm } => {
            format!("NOT HELD (speed {speed_err_rpm:.0} rpm off its reference)")
        }
    }
}

/// The table as Markdown.
pub fn markdown(cells: &[Cell]) -> String {
    let mut s = String::from(
        "<!-- generated by `cargo run --release -p acim-sim -- overhauling`; do not edit -->\n\n\
         Overhauling (active) load stepped in at 2.5 s while the drive holds the speed, paper \
         machine, default drive (regeneration limit 1.5 Hz, far-side mode), the scenarios' \
         sensors; judged over the last 1.5 s of a 6 s run. Held: mean speed within max(4 rpm, \
         2 %) of the target (beyond the line w_s = 0, f_s <= -1 Hz, the far-side mode releases \
         the regeneration limit and the drive crosses to its target). Held and reported \
         limited: the regeneration limit keeps the stator frequency at least 1.5 Hz on the \
         rotor's side of zero, so a load beyond the braking torque it allows raises the speed \
         to where the two balance; the target is reported as limited \
         (`speed_target_limited`). Fault: switched off (the overhauling load then drives the \
         coasting machine on). f_s: the stator frequency of the operating point at the \
         target (computed, rated flux). Peaks are true values while switching; beyond: time \
         switched with the current beyond the 8 A trip or the speed beyond 110 % of the \
         2000 rpm limit (at most 5 ms).\n\n\
         | speed (rpm) | load (N m) | f_s at the target (Hz) | outcome | peak speed while switching (rpm) | peak current while switching (A) | beyond (ms) |\n\
         |---|---|---|---|---|---|---|\n",
    );
    for c in cells {
        let _ = writeln!(
            s,
            "| {:.0} | {:.0} | {:.2} | {} | {:.0} | {:.2} | {:.1} |",
            c.rpm,
            c.load_nm,
            c.stator_frequency_hz,
            outcome_text(&c.outcome),
            c.metrics.peak_speed_switching_rpm,
            c.metrics.peak_current_a,
            c.metrics.switching_beyond_limits_s * 1e3,
        );
    }
    let clean = cells.iter().filter(|c| c.clean()).count();
    let _ = writeln!(
        s,
        "\n{clean} of {} cases held or ended in a clean fault.",
        cells.len()
    );
    s
}
