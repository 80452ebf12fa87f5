//! Metrics of a run: steady-state errors per window, load-step tracking, Rs convergence,
//! faults. Speeds in rpm, torques in N m.
//!
//! Steady-state speed errors are taken on 10 ms moving averages (50 control steps): a
//! speed measurement on a bench (the paper's 1024-line encoder) averages over a similar
//! time, and this removes the 5 kHz sensor-noise jitter of the estimate without hiding any
//! error slower than 100 Hz. The raw (unfiltered) maxima are reported too.

use crate::sim::{Row, RunResult};
use serde::ser::SerializeMap;
use serde::{Serialize, Serializer};

/// Moving-average length for steady-state speed errors, control steps (10 ms at 5 kHz).
pub const SMOOTHING_STEPS: usize = 50;

/// Version of the metrics JSON (`<name>.json`): raised whenever a field is renamed,
/// removed or changes meaning (adding a field does not raise it).
///
/// 1: the first versioned layout (verdict, time-ordered windows, saturation and
/// modulation index, `rs.estimator_on`).
pub const SCHEMA_VERSION: u32 = 1;

/// A speed-loop error (10 ms average of |speed - reference|) above this while running
/// is an excursion, rpm, at the reference rating ([`REFERENCE_RATED_SPEED_RPM`]); one
/// that lasts longer than [`LOST_RECOVERY_S`] (or never ends) means control was lost.
/// Scaled to the machine by [`Thresholds`].
pub const LOST_ERROR_RPM: f32 = 100.0;

/// An excursion beyond the lost bound that ends within this time is a transient the drive
/// recovered from (a load step, a reversal), reported with its depth and duration, not a
/// loss of control, s.
pub const LOST_RECOVERY_S: f32 = 1.0;

/// With the reference held at zero, a true speed (10 ms average) above this means the
/// rotor is drifting, rpm, at the reference rating (scaled by [`Thresholds`]).
pub const DRIFT_SPEED_RPM: f32 = 5.0;

/// A load change's speed recovery: |speed - ref| (10 ms average) back within this, rpm, at
/// the reference rating (scaled by [`Thresholds`]).
pub const RECOVERY_SPEED_RPM: f32 = 5.0;

/// A load change's torque estimate: |estimate - load| (10 ms average) within this, N m,
/// at the reference rating (scaled by [`Thresholds`]).
pub const LOAD_ESTIMATE_NM: f32 = 0.05;

/// A limit cycle: with the reference steady, the true speed's swing around it (peak to
/// peak of its 10 ms average, over each [`OSCILLATION_BLOCK_S`]) above this, rpm at the
/// reference rating (scaled by [`Thresholds`]; 2 % of rated speed).
pub const OSCILLATION_RPM: f32 = 30.0;

/// The swing is judged over blocks of this length, s (a cycle of 1 Hz or faster shows its
/// whole swing in one block).
pub const OSCILLATION_BLOCK_S: f32 = 1.0;

/// ... in at least this many consecutive blocks (a transient settles within one).
pub const OSCILLATION_BLOCKS: usize = 3;

/// The reference must have been constant, and the load unchanged, this long before a
/// block counts as steady, s.
pub const STEADY_AFTER_S: f32 = 1.0;

/// The rating every absolute threshold above is stated for: the paper's 750 W machine
/// (Table 1: 1500 rpm, 5 N m), rpm.
pub const REFERENCE_RATED_SPEED_RPM: f32 = 1500.0;
/// See [`REFERENCE_RATED_SPEED_RPM`], N m.
pub const REFERENCE_RATED_TORQUE_NM: f32 = 5.0;

/// The verdict's and the load steps' thresholds for one machine: the constants above
/// scaled by its rated speed and torque (from `[nameplate]`; a scenario without one is
/// judged at the reference rating, the paper's machine).
#[derive(Clone, Copy, Debug, Default, Serialize, PartialEq)]
pub struct Thresholds {
    /// Rated speed the thresholds scale with, rpm.
    pub rated_speed_rpm: f32,
    /// Rated torque the thresholds scale with, N m.
    pub rated_torque_nm: f32,
    /// Whether the rating is the scenario's nameplate (false: the reference rating).
    pub from_nameplate: bool,
    /// [`LOST_ERROR_RPM`] scaled, rpm.
    pub lost_rpm: f32,
    /// [`DRIFT_SPEED_RPM`] scaled, rpm.
    pub drift_rpm: f32,
    /// [`RECOVERY_SPEED_RPM`] scaled, rpm.
    pub recovery_rpm: f32,
    /// [`LOAD_ESTIMATE_NM`] scaled, N m.
    pub load_estimate_nm: f32,
    /// [`OSCILLATION_RPM`] scaled, rpm.
    pub oscillation_rpm: f32,
}

impl Thresholds {
    /// The thresholds for a machine rated `speed_rpm` and `torque_nm`.
    pub fn for_rating(speed_rpm: f32, torque_nm: f32, from_nameplate: bool) -> Self {
        let ks = speed_rpm / REFERENCE_RATED_SPEED_RPM;
        let kt = torque_nm / REFERENCE_RATED_TORQUE_NM;
        Self {
            rated_speed_rpm: speed_rpm,
            rated_torque_nm: torque_nm,
            from_nameplate,
            lost_rpm: LOST_ERROR_RPM * ks,
            drift_rpm: DRIFT_SPEED_RPM * ks,
            recovery_rpm: RECOVERY_SPEED_RPM * ks,
            load_estimate_nm: LOAD_ESTIMATE_NM * kt,
            oscillation_rpm: OSCILLATION_RPM * ks,
        }
    }

    /// The scenario's thresholds: its nameplate's rating, else the reference rating.
    pub fn for_scenario(sc: &crate::scenario::Scenario) -> Self {
        let rated = sc.nameplate.and_then(|np| np.nameplate().rated().ok());
        match rated {
            Some(r) => Self::for_rating(r.speed * acim::math::RAD_S_TO_RPM, r.torque, true),
            None => Self::for_rating(REFERENCE_RATED_SPEED_RPM, REFERENCE_RATED_TORQUE_NM, false),
        }
    }
}

/// A speed value for a sentence: whole rpm when it is one, else one decimal.
pub fn rpm_text(x: f32) -> String {
    if (x - x.round()).abs() < 1e-3 {
        format!("{x:.0}")
    } else {
        format!("{x:.1}")
    }
}

/// A sustained oscillation of the true speed around a steady reference (see
/// [`Verdict::LimitCycle`]).
#[derive(Clone, Copy, Debug, Default, Serialize, PartialEq)]
pub struct Oscillation {
    /// Start of the first block of the longest run of oscillating blocks, s.
    pub from_s: f32,
    /// How long it lasted (whole blocks), s.
    pub duration_s: f32,
    /// Largest peak-to-peak swing of speed - ref (10 ms average) in one block, rpm.
    pub peak_to_peak_rpm: f32,
    /// Lowest and highest true speed (10 ms average) over those blocks, rpm.
    pub speed_min_rpm: f32,
    /// See `speed_min_rpm`, rpm.
    pub speed_max_rpm: f32,
}

/// A stretch of running time with |speed - ref| (10 ms average) beyond the lost bound.
#[derive(Clone, Copy, Debug, Default, Serialize, PartialEq)]
pub struct Excursion {
    /// When it began, s.
    pub from_s: f32,
    /// Its largest |speed - ref| (10 ms average), rpm.
    pub peak_rpm: f32,
    /// How long until the error was back within the bound, s (`None`: it never was).
    pub recovered_after_s: Option<f32>,
}

/// The reference counts as held at zero this long after it reached zero (the speed loop
/// has settled), s.
pub const DRIFT_SETTLE_S: f32 = 0.5;

/// How a run ended, judged by stated criteria (most severe first):
///
/// - `faulted`: the drive tripped (a fault reason is reported);
/// - `lost`: while running, the 10 ms average of |speed - reference| exceeded
///   [`LOST_ERROR_RPM`];
/// - `limit cycle`: not lost, but around a steady reference the true speed swings beyond
///   [`OSCILLATION_RPM`] (scaled) block after block ([`Oscillation`]);
/// - `drifting`: control was not lost, but with the ramped reference held at zero for
///   [`DRIFT_SETTLE_S`] or longer the rotor's true speed (10 ms average) exceeded
///   [`DRIFT_SPEED_RPM`]: at zero stator frequency the estimator does not see the rotor;
/// - `kept`: none of the above.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Verdict {
    /// No fault, speed error bounded, no creep at a held zero reference.
    #[default]
    Kept,
    /// The rotor creeps with the reference held at zero.
    Drifting,
    /// The speed error left the bound while running.
    Lost,
    /// With the reference steady, the true speed swings around it beyond a bound, block
    /// after block: a limit cycle or a forced oscillation the average hides.
    #[serde(rename = "limit-cycle")]
    LimitCycle,
    /// The drive tripped.
    Faulted,
}

impl Verdict {
    /// The verdict as one lowercase word.
    pub fn as_str(self) -> &'static str {
        match self {
            Verdict::Kept => "kept",
            Verdict::Drifting => "drifting",
            Verdict::Lost => "lost",
            Verdict::LimitCycle => "limit cycle",
            Verdict::Faulted => "faulted",
        }
    }
}

/// One-paragraph statement of the verdict criteria (printed under the console table).
pub fn verdict_criteria() -> String {
    format!(
        "verdicts (thresholds per rated speed: {LOST_ERROR_RPM:.0} and {DRIFT_SPEED_RPM:.0} rpm per {REFERENCE_RATED_SPEED_RPM:.0} rpm, the paper machine's values; \
         a scenario without a [nameplate] is judged at that rating): faulted = the drive tripped; \
         lost = |speed - ref| (10 ms average) above {:.2} % of rated speed while running, for longer than {LOST_RECOVERY_S} s or to the end (a shorter excursion is reported with its depth and recovery time); \
         limit cycle = not lost, but with the reference and the load steady for {STEADY_AFTER_S} s the true speed (10 ms average) swung more than {:.0} % of rated speed peak to peak in each of {OSCILLATION_BLOCKS} consecutive {OSCILLATION_BLOCK_S} s blocks; \
         drifting = none of these, but with the reference held at 0 for {DRIFT_SETTLE_S} s or more the true speed (10 ms average) exceeded {:.2} % of rated speed; \
         kept = none of these",
        100.0 * LOST_ERROR_RPM / REFERENCE_RATED_SPEED_RPM,
        100.0 * OSCILLATION_RPM / REFERENCE_RATED_SPEED_RPM,
        100.0 * DRIFT_SPEED_RPM / REFERENCE_RATED_SPEED_RPM,
    )
}

/// Per-window metrics in the scenario's time order (start, then end), looked up by name.
/// Serialised as a JSON object whose keys keep that order.
#[derive(Clone, Debug, Default)]
pub struct Windows(Vec<(String, WindowMetrics)>);

impl Windows {
    /// Windows in time order.
    pub fn iter(&self) -> impl Iterator<Item = (&String, &WindowMetrics)> {
        self.0.iter().map(|(k, v)| (k, v))
    }
    /// The metrics of each window, in time order.
    pub fn values(&self) -> impl Iterator<Item = &WindowMetrics> {
        self.0.iter().map(|(_, v)| v)
    }
    /// Window names, in time order.
    pub fn keys(&self) -> impl Iterator<Item = &String> {
        self.0.iter().map(|(k, _)| k)
    }
    /// The window called `name`.
    pub fn get(&self, name: &str) -> Option<&WindowMetrics> {
        self.0.iter().find(|(k, _)| k == name).map(|(_, v)| v)
    }
    /// Number of windows.
    pub fn len(&self) -> usize {
        self.0.len()
    }
    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.0.is_empty()
    }
    /// Adds a window (a repeated name replaces the earlier one) and keeps time order.
    fn insert(&mut self, name: String, m: WindowMetrics) {
        self.0.retain(|(k, _)| *k != name);
        self.0.push((name, m));
        self.0.sort_by(|a, b| {
            a.1.from_s
                .total_cmp(&b.1.from_s)
                .then(a.1.to_s.total_cmp(&b.1.to_s))
        });
    }
}

impl<Q: AsRef<str> + ?Sized> std::ops::Index<&Q> for Windows {
    type Output = WindowMetrics;
    /// The window called `name`; panics if there is none (like a map's index).
    fn index(&self, name: &Q) -> &WindowMetrics {
        let name = name.as_ref();
        self.get(name)
            .unwrap_or_else(|| panic!("no metric window named `{name}`"))
    }
}

impl<'a> IntoIterator for &'a Windows {
    type Item = (&'a String, &'a WindowMetrics);
    type IntoIter = std::iter::Map<
        std::slice::Iter<'a, (String, WindowMetrics)>,
        fn(&'a (String, WindowMetrics)) -> (&'a String, &'a WindowMetrics),
    >;
    fn into_iter(self) -> Self::IntoIter {
        self.0.iter().map(|(k, v)| (k, v))
    }
}

impl Serialize for Windows {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let mut m = s.serialize_map(Some(self.0.len()))?;
        for (k, v) in &self.0 {
            m.serialize_entry(k, v)?;
        }
        m.end()
    }
}

/// Steady-state metrics over one window.
#[derive(Clone, Debug, Default, Serialize)]
pub struct WindowMetrics {
    /// Window start, s.
    pub from_s: f32,
    /// Window end, s.
    pub to_s: f32,
    /// Max |speed_est - speed| of the 10 ms averages, rpm.
    pub speed_est_err_max_rpm: f32,
    /// Mean speed_est - speed, rpm (signed).
    pub speed_est_err_mean_rpm: f32,
    /// Max |speed_est - speed| unfiltered, rpm.
    pub speed_est_err_raw_max_rpm: f32,
    /// Max |speed - speed_ref| of the 10 ms averages, rpm.
    pub speed_err_max_rpm: f32,
    /// Mean speed - speed_ref, rpm (signed).
    pub speed_err_mean_rpm: f32,
    /// Mean |load_est - load|, N m.
    pub load_est_err_mean_nm: f32,
    /// Max |orientation error|, degrees electrical.
    pub orientation_err_max_deg: f32,
    /// Mean Rs estimate, ohm.
    pub rs_est_mean_ohm: f32,
    /// Mean true speed, rpm.
    pub speed_mean_rpm: f32,
    /// Smallest true rotor flux amplitude (inverse-Gamma), Wb.
    pub rotor_flux_true_min: f32,
}

/// Tracking after one load change.
#[derive(Clone, Debug, Default, Serialize)]
pub struct LoadStepMetrics {
    /// When the load changed, s.
    pub t_s: f32,
    /// New load torque, N m.
    pub load_nm: f32,
    /// Time until |load_est - load| (10 ms average) is within
    /// [`Thresholds::load_estimate_nm`] for good (until the next load or speed-target
    /// change), s.
    pub load_est_settle_s: Option<f32>,
    /// Time until |speed - ref| (10 ms average) is within [`Thresholds::recovery_rpm`]
    /// for good, s.
    pub speed_recovery_s: Option<f32>,
    /// Largest |speed - ref| after the change (10 ms average), rpm.
    pub speed_dip_rpm: f32,
    /// Whether that largest deviation took the rotor faster than the reference (a load
    /// removed: an overshoot) rather than slower (a dip).
    pub overshoot: bool,
}

/// Rs estimator convergence.
#[derive(Clone, Debug, Default, Serialize)]
pub struct RsMetrics {
    /// Whether the Rs estimator ran (`drive.estimation.rs_estimation`); the other fields only mean
    /// something when it did.
    pub estimator_on: bool,
    /// True stator resistance, ohm.
    pub true_ohm: f32,
    /// Initial estimate, ohm.
    pub initial_ohm: f32,
    /// Final estimate, ohm.
    pub final_ohm: f32,
    /// First time from which the estimate stays within 2 % of the true value, s.
    pub within_2pct_from_s: Option<f32>,
    /// The same, counted from the start of speed control (end of magnetizing), s.
    pub within_2pct_after_running_s: Option<f32>,
}

/// Rotor creep with the reference held at zero (see [`Verdict::Drifting`]).
#[derive(Clone, Debug, Default, Serialize)]
pub struct ZeroHoldMetrics {
    /// When the ramped reference first reached zero (and stayed there while running), s.
    pub from_s: f32,
    /// How long it was held at zero while running, s.
    pub held_s: f32,
    /// Largest |true speed| (10 ms average) from [`DRIFT_SETTLE_S`] after `from_s`, rpm.
    pub speed_max_rpm: f32,
}

/// All metrics of a run.
#[derive(Clone, Debug, Default, Serialize)]
pub struct Metrics {
    /// Layout version of this JSON ([`SCHEMA_VERSION`]).
    pub schema_version: u32,
    /// Scenario name.
    pub name: String,
    /// Scenario description.
    pub description: String,
    /// Simulated time, s.
    pub duration_s: f32,
    /// Fault reason, if the drive faulted.
    pub fault: Option<String>,
    /// Fault time, s.
    pub fault_time_s: Option<f32>,
    /// Whether the switches were off at the end.
    pub switches_off_at_end: bool,
    /// Final drive state.
    pub final_state: String,
    /// Whether the drive stayed in control: no fault, and |speed - ref| (10 ms average)
    /// stayed below [`LOST_ERROR_RPM`] whenever running (a drifting run counts as kept
    /// here; [`Metrics::verdict`] tells them apart).
    pub control_kept: bool,
    /// The verdict: kept, drifting, lost or faulted ([`Verdict`] states the criteria).
    pub verdict: Verdict,
    /// The verdict the scenario expects when not kept, and why (`[expected]`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub expected: Option<crate::scenario::Expected>,
    /// The thresholds the verdict and the load steps were judged with.
    pub thresholds: Thresholds,
    /// Running stretches with the speed error beyond the lost bound, in time order (a
    /// recovered one is a transient, reported; [`LOST_RECOVERY_S`]).
    pub excursions: Vec<Excursion>,
    /// Speed targets the drive clamped to its speed limit.
    pub target_clamps: Vec<crate::sim::TargetClamp>,
    /// The longest sustained oscillation around a steady reference, if any.
    pub oscillation: Option<Oscillation>,
    /// Rotor creep at a held zero reference, when the reference was held at zero long
    /// enough to judge it.
    pub zero_hold: Option<ZeroHoldMetrics>,
    /// Time running (closed or open loop) with the modulator limiting the voltage, s.
    pub voltage_saturated_s: f32,
    /// Largest modulation index |v_dq| / (V_dc / sqrt 3) while switching (1 = the linear
    /// limit of space-vector modulation).
    pub modulation_index_max: f32,
    /// Time running with the speed target beyond the reachable speed (the reference held
    /// at what the drive reaches, reported by its telemetry), s.
    pub speed_target_limited_s: f32,
    /// Largest |true phase current| while switching, A.
    pub peak_current_a: f32,
    /// Largest |true speed|, rpm.
    pub peak_speed_rpm: f32,
    /// Largest |true speed| while switching, rpm.
    pub peak_speed_switching_rpm: f32,
    /// Time spent switching with the true speed beyond 110 % of `max_speed` or a true
    /// phase current beyond the trip, s.
    pub switching_beyond_limits_s: f32,
    /// Largest |true phase current| with the gates on, checked at every integration
    /// sub-step (not only at the samples), A.
    pub peak_true_current_switching_a: f32,
    /// Total time with the gates on and the true phase current above the drive's trip
    /// level (sub-step resolution, interpolated), s.
    pub above_trip_switching_s: f32,
    /// The longest such episode (consecutive periods with time above the trip), s.
    pub above_trip_switching_longest_s: f32,
    /// The plant's hardware over-current comparator opened the gates (absent: it did not,
    /// or none was fitted).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub hardware_trip: Option<crate::sim::HardwareTripRecord>,
    /// Largest |speed - ref| while running (10 ms average), rpm.
    pub speed_err_max_running_rpm: f32,
    /// The flying start's speed search at its decision.
    pub speed_search: Option<crate::sim::SearchRecord>,
    /// Per-window steady-state metrics, in time order.
    pub windows: Windows,
    /// Load changes.
    pub load_steps: Vec<LoadStepMetrics>,
    /// Rs estimator convergence.
    pub rs: RsMetrics,
    /// The inverter test at start (only when the drive runs it).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub inverter_test: Option<crate::sim::InverterTestRecord>,
    /// The rotor-resistance adaptation at the end (only when the drive runs it).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub rotor_resistance: Option<crate::sim::RotorResistanceRecord>,
    /// Wall-clock time of the simulation, s.
    pub wall_time_s: f64,
    /// Simulated seconds per wall-clock second.
    pub real_time_factor: f64,
}

fn moving_average(x: &[f32], n: usize) -> Vec<f32> {
    let mut out = Vec::with_capacity(x.len());
    let mut sum = 0.0f64;
    for i in 0..x.len() {
        sum += x[i] as f64;
        if i >= n {
            sum -= x[i - n] as f64;
        }
        let len = (i + 1).min(n);
        out.push((sum / len as f64) as f32);
    }
    out
}

/// The longest run of at least [`OSCILLATION_BLOCKS`] consecutive steady blocks whose
/// swing of speed - ref (10 ms average) exceeds the bound. A block is steady when the
/// drive runs throughout, the reference has not moved for [`STEADY_AFTER_S`] and the load
/// has not changed for as long.
fn oscillation(r: &RunResult, spd_avg: &[f32], th: &Thresholds) -> Option<Oscillation> {
    let rows = &r.rows;
    let ts = r.config.loops.control_period;
    let block = ((OSCILLATION_BLOCK_S / ts).round() as usize).max(1);
    let settle = ((STEADY_AFTER_S / ts).round() as usize).max(1);
    // steps since the last reference move, load change or leaving the running state
    let mut quiet = 0usize;
    let mut run: Vec<(usize, f32, f32, f32)> = Vec::new(); // (start, p-p, min, max)
    let mut best: Option<Oscillation> = None;
    let mut k = 0;
    let close = |run: &mut Vec<(usize, f32, f32, f32)>, best: &mut Option<Oscillation>| {
        if run.len() >= OSCILLATION_BLOCKS {
            let o = Oscillation {
                from_s: rows[run[0].0].t_s,
                duration_s: run.len() as f32 * block as f32 * ts,
                peak_to_peak_rpm: run.iter().fold(0.0f32, |m, b| m.max(b.1)),
                speed_min_rpm: run.iter().fold(f32::INFINITY, |m, b| m.min(b.2)),
                speed_max_rpm: run.iter().fold(f32::NEG_INFINITY, |m, b| m.max(b.3)),
            };
            if best.is_none_or(|b| o.duration_s > b.duration_s) {
                *best = Some(o);
            }
        }
        run.clear();
    };
    while k < rows.len() {
        let steady = |j: usize| {
            rows[j].state == 2
                && (j == 0
                    || (rows[j].speed_ref_rpm == rows[j - 1].speed_ref_rpm
                        && rows[j].load_torque_nm == rows[j - 1].load_torque_nm))
        };
        if !steady(k) {
            quiet = 0;
            close(&mut run, &mut best);
            k += 1;
            continue;
        }
        quiet += 1;
        if quiet < settle || k + block > rows.len() {
            k += 1;
            continue;
        }
        // one block from k, if it stays steady throughout
        if let Some(bad) = (k..k + block).find(|&j| !steady(j)) {
            quiet = 0;
            close(&mut run, &mut best);
            k = bad + 1;
            continue;
        }
        let (lo, hi) = spd_avg[k..k + block]
            .iter()
            .fold((f32::INFINITY, f32::NEG_INFINITY), |(l, h), &e| {
                (l.min(e), h.max(e))
            });
        let (slo, shi) = rows[k..k + block]
            .iter()
            .fold((f32::INFINITY, f32::NEG_INFINITY), |(l, h), x| {
                (l.min(x.speed_rpm), h.max(x.speed_rpm))
            });
        if hi - lo > th.oscillation_rpm {
            run.push((k, hi - lo, slo, shi));
        } else {
            close(&mut run, &mut best);
        }
        quiet += block;
        k += block;
    }
    close(&mut run, &mut best);
    best
}

fn idx(rows: &[Row], t: f32) -> usize {
    rows.partition_point(|r| r.t_s < t)
}

/// Computes the metrics of a run.
pub fn compute(r: &RunResult, wall_time_s: f64) -> Metrics {
    let rows = &r.rows;
    let sc = &r.scenario;
    let est_err: Vec<f32> = rows.iter().map(|r| r.speed_est_rpm - r.speed_rpm).collect();
    let spd_err: Vec<f32> = rows.iter().map(|r| r.speed_rpm - r.speed_ref_rpm).collect();
    let est_avg = moving_average(&est_err, SMOOTHING_STEPS);
    let load_err: Vec<f32> = rows
        .iter()
        .map(|r| r.load_torque_est_nm - r.load_torque_nm)
        .collect();
    let load_avg = moving_average(&load_err, SMOOTHING_STEPS);
    let spd_avg = moving_average(&spd_err, SMOOTHING_STEPS);
    let th = Thresholds::for_scenario(sc);

    let mut windows = Windows::default();
    for w in &sc.windows {
        let (a, b) = (idx(rows, w.from_s), idx(rows, w.to_s));
        if b <= a {
            continue;
        }
        let n = (b - a) as f32;
        let rs = &rows[a..b];
        let m = WindowMetrics {
            from_s: w.from_s,
            to_s: w.to_s,
            speed_est_err_max_rpm: est_avg[a..b].iter().fold(0.0, |m, x| m.max(x.abs())),
            speed_est_err_mean_rpm: est_err[a..b].iter().sum::<f32>() / n,
            speed_est_err_raw_max_rpm: est_err[a..b].iter().fold(0.0, |m, x| m.max(x.abs())),
            speed_err_max_rpm: spd_avg[a..b].iter().fold(0.0, |m, x| m.max(x.abs())),
            speed_err_mean_rpm: spd_err[a..b].iter().sum::<f32>() / n,
            load_est_err_mean_nm: rs
                .iter()
                .map(|r| (r.load_torque_est_nm - r.load_torque_nm).abs())
                .sum::<f32>()
                / n,
            orientation_err_max_deg: rs
                .iter()
                .fold(0.0, |m, r| m.max(r.orientation_error_deg.abs())),
            rs_est_mean_ohm: rs.iter().map(|r| r.stator_resistance_est_ohm).sum::<f32>() / n,
            speed_mean_rpm: rs.iter().map(|r| r.speed_rpm).sum::<f32>() / n,
            rotor_flux_true_min: rs
                .iter()
                .fold(f32::INFINITY, |m, r| m.min(r.rotor_flux_true)),
        };
        let mut m = m;
        if sc.drive.mode == crate::scenario::ControlMode::Vf {
            // open loop: there is no speed estimate to compare
            m.speed_est_err_max_rpm = f32::NAN;
            m.speed_est_err_mean_rpm = f32::NAN;
            m.speed_est_err_raw_max_rpm = f32::NAN;
            m.load_est_err_mean_nm = f32::NAN;
        }
        windows.insert(w.name.clone(), m);
    }

    // load steps: each change until the next one (or the end)
    let mut changes: Vec<(f32, f32)> = Vec::new();
    let mut sorted = sc.load_profile.clone();
    sorted.sort_by(|a, b| a.t_s.total_cmp(&b.t_s));
    for p in &sorted {
        changes.push((p.t_s, p.load().torque(1.0)));
    }
    let mut load_steps = Vec::new();
    if sc.drive.mode == crate::scenario::ControlMode::Vf {
        // open loop: no load estimate to track
        changes.clear();
    }
    for (t, _) in changes.iter() {
        // evaluate until the next load change or speed-target change (a reversal is not a
        // load-tracking failure), or the end
        let end = changes
            .iter()
            .map(|c| c.0)
            .chain(sc.speed_profile.iter().map(|p| p.t_s))
            .filter(|&x| x > *t)
            .fold(sc.duration_s, f32::min);
        let (a, b) = (idx(rows, *t), idx(rows, end));
        if b <= a + 1 {
            continue;
        }
        let mut last_bad_load = None;
        let mut last_bad_speed = None;
        let mut dip = 0.0f32;
        let mut overshoot = false;
        for k in a..b {
            if load_avg[k].abs() > th.load_estimate_nm {
                last_bad_load = Some(k);
            }
            if spd_avg[k].abs() > th.recovery_rpm {
                last_bad_speed = Some(k);
            }
            if spd_avg[k].abs() > dip {
                dip = spd_avg[k].abs();
                // faster than the reference in its own direction (at a zero reference:
                // in the direction the load pushes it, counted as a dip)
                overshoot = spd_avg[k] * rows[k].speed_ref_rpm > 0.0;
            }
        }
        let settle = |bad: Option<usize>| match bad {
            None => Some(0.0),
            Some(k) if k + 1 < b => Some(rows[k + 1].t_s - t),
            Some(_) => None,
        };
        load_steps.push(LoadStepMetrics {
            t_s: *t,
            load_nm: rows[a].load_torque_nm,
            load_est_settle_s: settle(last_bad_load),
            speed_recovery_s: settle(last_bad_speed),
            speed_dip_rpm: dip,
            overshoot,
        });
    }

    // Rs convergence
    let true_rs = sc.plant.rs_ohm;
    let mut last_out = None;
    for (k, r) in rows.iter().enumerate() {
        if (r.stator_resistance_est_ohm - true_rs).abs() > 0.02 * true_rs {
            last_out = Some(k);
        }
    }
    let within = match last_out {
        None => Some(0.0),
        Some(k) if k + 1 < rows.len() => Some(rows[k + 1].t_s),
        Some(_) => None,
    };
    let running_from = rows.iter().find(|r| r.state == 2).map(|r| r.t_s);
    let rs = RsMetrics {
        estimator_on: sc.drive.estimation.rs_estimation,
        true_ohm: true_rs,
        initial_ohm: rows
            .first()
            .map(|r| r.stator_resistance_est_ohm)
            .unwrap_or(0.0),
        final_ohm: rows
            .last()
            .map(|r| r.stator_resistance_est_ohm)
            .unwrap_or(0.0),
        within_2pct_from_s: within,
        within_2pct_after_running_s: match (within, running_from) {
            (Some(w), Some(r)) => Some((w - r).max(0.0)),
            _ => None,
        },
    };

    // judged on averages over running steps only (before running the reference is 0
    // while the rotor may turn: a flying start)
    let mut max_running = 0.0f32;
    let mut running_steps = 0usize;
    let mut excursions: Vec<Excursion> = Vec::new();
    let mut open: Option<usize> = None; // index into excursions of the one under way
    for (k, r) in rows.iter().enumerate() {
        if r.state == 2 || r.state == 3 {
            running_steps += 1;
            if running_steps >= SMOOTHING_STEPS {
                let e = spd_avg[k].abs();
                max_running = max_running.max(e);
                match (open, e > th.lost_rpm) {
                    (None, true) => {
                        excursions.push(Excursion {
                            from_s: r.t_s,
                            peak_rpm: e,
                            recovered_after_s: None,
                        });
                        open = Some(excursions.len() - 1);
                    }
                    (Some(i), true) => excursions[i].peak_rpm = excursions[i].peak_rpm.max(e),
                    (Some(i), false) => {
                        excursions[i].recovered_after_s = Some(r.t_s - excursions[i].from_s);
                        open = None;
                    }
                    (None, false) => {}
                }
            }
        } else {
            running_steps = 0;
            // leaving the running states ends the stretch without a recovery (a stop or a
            // trip)
            open = None;
        }
    }
    // creep at a held zero reference: the last stretch (while running) over which the
    // ramped reference is zero, judged from DRIFT_SETTLE_S after it reached zero
    let mut zero_hold = None;
    let mut k = 0;
    while k < rows.len() {
        let held = |r: &Row| r.state == 2 && r.speed_ref_rpm.abs() < 1e-3;
        if !held(&rows[k]) {
            k += 1;
            continue;
        }
        let start = k;
        while k < rows.len() && held(&rows[k]) {
            k += 1;
        }
        let from = rows[start].t_s;
        let held_s = rows[k - 1].t_s - from + r.config.loops.control_period;
        if held_s > DRIFT_SETTLE_S {
            let a = idx(rows, from + DRIFT_SETTLE_S);
            let speed_avg = moving_average(
                &rows[start..k]
                    .iter()
                    .map(|r| r.speed_rpm)
                    .collect::<Vec<_>>(),
                SMOOTHING_STEPS,
            );
            let worst = speed_avg[a - start..]
                .iter()
                .fold(0.0f32, |m, x| m.max(x.abs()));
            let z = zero_hold.get_or_insert(ZeroHoldMetrics {
                from_s: from,
                held_s,
                speed_max_rpm: worst,
            });
            if worst > z.speed_max_rpm {
                *z = ZeroHoldMetrics {
                    from_s: from,
                    held_s,
                    speed_max_rpm: worst,
                };
            }
        }
    }
    let control_kept = r.fault.is_none() && max_running < th.lost_rpm;
    let lost = excursions
        .iter()
        .any(|x| x.recovered_after_s.is_none_or(|d| d > LOST_RECOVERY_S));
    let oscillation = oscillation(r, &spd_avg, &th);
    let verdict = if r.fault.is_some() {
        Verdict::Faulted
    } else if lost {
        Verdict::Lost
    } else if oscillation.is_some() {
        Verdict::LimitCycle
    } else if zero_hold
        .as_ref()
        .is_some_and(|z| z.speed_max_rpm > th.drift_rpm)
    {
        Verdict::Drifting
    } else {
        Verdict::Kept
    };
    let active = || rows.iter().filter(|r| r.state == 2 || r.state == 3);
    let voltage_saturated_s =
        active().filter(|r| r.voltage_saturated).count() as f32 * r.config.loops.control_period;
    let speed_target_limited_s =
        active().filter(|r| r.speed_target_limited).count() as f32 * r.config.loops.control_period;
    let modulation_index_max = rows
        .iter()
        .filter(|r| r.pwm_enabled)
        .fold(0.0f32, |m, r| m.max(r.modulation_index));

    let max_speed_rpm = r.config.limits.max_speed * acim::math::RAD_S_TO_RPM;
    let trip = r.config.limits.overcurrent_trip;
    let ts = r.config.loops.control_period;
    let switching = || rows.iter().filter(|r| r.pwm_enabled);
    let peak_current_a = switching().fold(0.0f32, |m, r| m.max(r.i_phase_peak_a));
    let peak_speed_rpm = rows.iter().fold(0.0f32, |m, r| m.max(r.speed_rpm.abs()));
    let peak_speed_switching_rpm = switching().fold(0.0f32, |m, r| m.max(r.speed_rpm.abs()));
    let switching_beyond_limits_s = switching()
        .filter(|r| r.speed_rpm.abs() > 1.1 * max_speed_rpm || r.i_phase_peak_a > trip)
        .count() as f32
        * ts;
    let peak_true_current_switching_a = rows
        .iter()
        .fold(0.0f32, |m, r| m.max(r.i_phase_peak_switching_a));
    let above_trip_switching_s: f32 = rows.iter().map(|r| r.above_trip_switching_s).sum();
    let mut above_trip_switching_longest_s = 0.0f32;
    let mut episode = 0.0f32;
    for r in rows {
        if r.above_trip_switching_s > 0.0 {
            episode += r.above_trip_switching_s;
            above_trip_switching_longest_s = above_trip_switching_longest_s.max(episode);
        } else {
            episode = 0.0;
        }
    }
    Metrics {
        schema_version: SCHEMA_VERSION,
        name: sc.name.clone(),
        description: sc.description.clone(),
        duration_s: sc.duration_s,
        fault: r.fault.map(|f| format!("{f:?}")),
        fault_time_s: r.fault_time_s,
        switches_off_at_end: r.switches_off_at_end,
        final_state: format!("{:?}", r.final_state),
        control_kept,
        verdict,
        expected: sc.expected.clone(),
        thresholds: th,
        excursions,
        target_clamps: r.target_clamps.clone(),
        oscillation,
        zero_hold,
        voltage_saturated_s,
        modulation_index_max,
        speed_target_limited_s,
        speed_err_max_running_rpm: max_running,
        speed_search: r.search,
        inverter_test: r.inverter_test.clone(),
        rotor_resistance: r.rotor_resistance.clone(),
        peak_current_a,
        peak_speed_rpm,
        peak_speed_switching_rpm,
        switching_beyond_limits_s,
        peak_true_current_switching_a,
        above_trip_switching_s,
        above_trip_switching_longest_s,
        hardware_trip: r.hardware_trip,
        windows,
        load_steps,
        rs,
        wall_time_s,
        real_time_factor: if wall_time_s > 0.0 {
            sc.duration_s as f64 / wall_time_s
        } else {
            0.0
        },
    }
}
