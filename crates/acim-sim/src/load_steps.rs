//! Rated load applied and removed across the machines: each machine of the set with a
//! catalogue inertia for its rating (`acim::commissioning::catalogue_inertia`, the line
//! commissioning judges an identified J against), commissioned from its
//! nameplate against its plant, then driven with the identified model at 10, 50 and 100 %
//! of its rated speed while its rated torque is applied as an active load (opposing the
//! rotation: motoring; driving it: regenerating) at [`APPLIED_AT_S`] and removed at
//! [`REMOVED_AT_S`]. Each event is judged against the speed loop's designed response
//! ([`Bounds`]). `acim-sim load-steps` writes the table to `docs/load-steps.md`;
//! `tests/any_motor.rs` asserts it.

use crate::commission::commission;
use crate::machines::{self, MachineFile};
use crate::metrics::Metrics;
use crate::scenario::{LoadKind, LoadPoint, Scenario, SpeedPoint};
use crate::sim::Row;
use std::fmt::Write as _;

/// Runs one scenario: its rows and metrics.
pub type RunFn<'a> = dyn FnMut(&Scenario) -> Result<(Vec<Row>, Metrics), String> + 'a;

/// The machines of the load-step set: the acceptance machines and a 4 kW motor of a
/// class a user tried.
pub const MACHINES: [MachineFile; 8] = [
    machines::MACHINES[6],
    machines::MACHINES[0],
    machines::MACHINES[1],
    machines::MACHINES[2],
    machines::MACHINES[3],
    MachineFile {
        name: "class-4kw",
        text: include_str!("../machines/class-4kw.toml"),
    },
    machines::MACHINES[5],
    machines::MACHINES[4],
];

/// Fractions of the rated speed the load steps run at.
pub const SPEED_FRACTIONS: [f32; 3] = [0.1, 0.5, 1.0];
/// When the rated load is applied, s.
pub const APPLIED_AT_S: f32 = 3.0;
/// When it is removed, s.
pub const REMOVED_AT_S: f32 = 5.0;
/// Run length, s.
pub const DURATION_S: f32 = 7.0;
/// The band "back" means: 1 % of the rated speed.
pub const BAND: f32 = 0.01;

/// The bounds one case is judged against, from the speed loop's design.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Bounds {
    /// Largest dip (or overshoot), rpm: the rated torque met by the speed PI's
    /// proportional torque 2 alpha J dOmega alone, T_rated / (2 alpha J) (the load
    /// estimate's feed-forward only makes it less). With the nameplate design this is
    /// `acim::nameplate::RATED_STEP_DIP` of the rated speed unless the loop is capped.
    /// With a slow task, plus the speed the rated torque gives the rotor in one slow
    /// period, T_rated t_slow / J: the speed loop reads the estimate at its tick and its
    /// new torque is reached over the next slow period, so it meets the step up to one
    /// slow period late.
    pub dip_rpm: f32,
    /// Back within [`BAND`] of the rated speed (the speed, and the estimate on the
    /// rotor), s: four time constants of the speed loop, 4 / alpha.
    pub back_s: f32,
}

/// One event (the load applied or removed).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Event {
    /// Largest |reference - speed| after the event, rpm.
    pub dip_rpm: f32,
    /// From the event to the last sample more than [`BAND`] of rated speed off the
    /// reference, s.
    pub back_s: f32,
    /// Largest |estimate - speed| after the event, rpm.
    pub est_err_rpm: f32,
    /// From the event to the last sample with the estimate more than [`BAND`] of
    /// rated speed off the rotor, s.
    pub est_back_s: f32,
}

/// One case: a machine, a speed, a direction of the load.
#[derive(Clone, Debug)]
pub struct Case {
    /// Machine name.
    pub machine: String,
    /// Fraction of the rated speed.
    pub fraction: f32,
    /// Speed, rpm.
    pub rpm: f32,
    /// The load torque while applied, N m (negative: regenerating).
    pub load_nm: f32,
    /// The bounds.
    pub bounds: Bounds,
    /// The drive's fault, if any.
    pub fault: Option<String>,
    /// The load applied and removed (meaningless after a fault).
    pub events: [Event; 2],
}

impl Case {
    /// Why the case fails its bounds, if it does. At rated speed the recovery time is
    /// reported, not bounded: the rated load there takes the voltage's whole reserve and
    /// the speed loop recovers at the rate the remaining torque allows.
    pub fn failure(&self) -> Option<String> {
        if let Some(f) = &self.fault {
            return Some(format!("fault {f}"));
        }
        for (e, what) in self.events.iter().zip(["applied", "removed"]) {
            if e.dip_rpm > self.bounds.dip_rpm {
                return Some(format!(
                    "{what}: dip {:.1} rpm > {:.1}",
                    e.dip_rpm, self.bounds.dip_rpm
                ));
            }
            if self.fraction < 1.0 && e.back_s.max(e.est_back_s) > self.bounds.back_s {
                return Some(format!(
                    "{what}: back after {:.2} s (estimate {:.2} s) > {:.2}",
                    e.back_s, e.est_back_s, self.bounds.back_s
                ));
            }
        }
        None
    }
}

/// The machine with its catalogue inertia in the plant and realistic sensors
/// ([`machines::base`]).
pub fn base(m: &MachineFile) -> Result<Scenario, String> {
    let mut sc = machines::base(m)?;
    let (_, rated_nm) = machines::rated(&sc)?;
    sc.plant.inertia_kgm2 = acim::commissioning::catalogue_inertia(rated_nm);
    Ok(sc)
}

/// The case's scenario on the identified model `run`.
pub fn scenario(run: &Scenario, rpm: f32, load_nm: f32) -> Scenario {
    let mut s = run.clone();
    s.name = format!("{}-load-steps-{rpm:.0}-{load_nm:.1}", run.name);
    s.description = "rated load applied and removed".into();
    s.duration_s = DURATION_S;
    s.speed_profile = vec![SpeedPoint { t_s: 0.2, rpm }];
    s.load_profile = vec![
        LoadPoint {
            t_s: APPLIED_AT_S,
            kind: LoadKind::Active,
            torque_nm: load_nm,
        },
        LoadPoint {
            t_s: REMOVED_AT_S,
            kind: LoadKind::Active,
            torque_nm: 0.0,
        },
    ];
    s.windows = Vec::new();
    s
}

/// The bounds of `sc` (the identified model's drive on the plant) for the rated torque.
pub fn bounds(sc: &Scenario, rated_nm: f32) -> Result<Bounds, String> {
    let v = sc.validate().map_err(|e| format!("{}: {e}", sc.name))?;
    let alpha = v.drive.loops.speed_bandwidth;
    let slow_period = v.drive.loops.slow_period;
    Ok(Bounds {
        dip_rpm: rated_nm * (1.0 / (2.0 * alpha) + slow_period) / v.plant.inertia()
            * acim::math::RAD_S_TO_RPM,
        back_s: 4.0 / alpha,
    })
}

/// The event at `t0` in `rows` (samples before `t0 + 2 s`).
pub fn event(rows: &[Row], t0: f32, band_rpm: f32) -> Event {
    let after: Vec<&Row> = rows
        .iter()
        .filter(|r| r.t_s >= t0 && r.t_s < t0 + 2.0)
        .collect();
    let peak = |f: &dyn Fn(&Row) -> f32| after.iter().map(|r| f(r).abs()).fold(0.0, f32::max);
    let last = |f: &dyn Fn(&Row) -> f32| {
        after
            .iter()
            .filter(|r| f(r).abs() > band_rpm)
            .map(|r| r.t_s)
            .fold(t0, f32::max)
            - t0
    };
    let off = |r: &Row| r.speed_ref_rpm - r.speed_rpm;
    let est = |r: &Row| r.speed_est_rpm - r.speed_rpm;
    Event {
        dip_rpm: peak(&off),
        back_s: last(&off),
        est_err_rpm: peak(&est),
        est_back_s: last(&est),
    }
}

/// A machine of the set commissioned (with its catalogue inertia): the identified model
/// as a scenario, and its rating.
#[derive(Clone, Debug)]
pub struct Prepared {
    /// Machine name.
    pub name: &'static str,
    /// The machine driven with the identified model.
    pub identified: Scenario,
    /// Rated speed, rpm.
    pub rated_rpm: f32,
    /// Rated torque, N m.
    pub rated_nm: f32,
}

/// Commissions `m` with its catalogue inertia.
pub fn prepare(m: &MachineFile) -> Result<Prepared, String> {
    let sc = base(m)?;
    let report = commission(&sc)?;
    let (rated_rpm, rated_nm) = machines::rated(&sc)?;
    Ok(Prepared {
        name: m.name,
        identified: machines::identified(&sc, &report),
        rated_rpm,
        rated_nm,
    })
}

/// Runs the six cases of `p` with the `--set`-style overrides `sets` (e.g. the
/// observer); `run` runs one scenario.
pub fn cases(p: &Prepared, sets: &[String], run: &mut RunFn) -> Result<Vec<Case>, String> {
    let identified = p
        .identified
        .with_overrides(sets)
        .map_err(|e| format!("{}: {e}", p.name))?;
    let bounds = bounds(&identified, p.rated_nm)?;
    let mut cases = Vec::new();
    for fraction in SPEED_FRACTIONS {
        for sign in [1.0f32, -1.0] {
            let rpm = fraction * p.rated_rpm;
            let load_nm = sign * p.rated_nm;
            let (rows, metrics) = run(&scenario(&identified, rpm, load_nm))?;
            let band = BAND * p.rated_rpm;
            cases.push(Case {
                machine: p.name.to_string(),
                fraction,
                rpm,
                load_nm,
                bounds,
                fault: metrics.fault.clone(),
                events: [
                    event(&rows, APPLIED_AT_S, band),
                    event(&rows, REMOVED_AT_S, band),
                ],
            });
        }
    }
    Ok(cases)
}

/// The table: one row per case, the default drive (the nameplate's configuration: the
/// flux observer) and the paper's observer side by side.
pub fn markdown(default: &[Case], paper: &[Case]) -> String {
    let mut md = String::from(
        "<!-- generated by `cargo run --release -p acim-sim -- load-steps`; do not edit -->\n\n",
    );
    let _ = writeln!(
        md,
        "# Rated load applied and removed\n\n\
         Each machine with the rotor inertia of a catalogue 4-pole motor of its rated torque \
         (J = 0.0035 kg m^2 (P / 1 kW)^1.3 with P = T_rated x 157 rad/s: \
         `acim::commissioning::catalogue_inertia`, the line commissioning judges J against), \
         commissioned from its nameplate against its plant (`acim-sim commission`), then \
         driven with the identified model, realistic sensors (0.1 % noise, 0.3 % gain and \
         0.05 % offset errors) and the default inverter, at 5 kHz with the speed loop in \
         a 1 kHz slow task. The machine's rated torque is applied as an active load at \
         {APPLIED_AT_S} s (motoring: opposing the rotation; regenerating: driving it) and removed at {REMOVED_AT_S} s. The drive as \
         configured from the nameplate (the flux observer, the default), and again with the \
         paper's observer (`--set drive.observer=reduced`), which is not judged.\n\n\
         Bounds from the nameplate's speed-loop design (bandwidth alpha, the plant's J): \
         dip (applied) or overshoot (removed) at most T_rated / (2 alpha J), the rated \
         torque met by the speed PI's proportional torque alone, 10 % of rated speed unless \
         the loop is capped, plus T_rated t_slow / J for the slow task's period t_slow (the \
         speed loop meets the step up to one slow period late); below rated speed, the \
         speed and its estimate back within 1 % of rated speed in 4 / alpha. At rated speed the recovery time is reported, not \
         bounded (the load takes the voltage's reserve). Each cell: dip (rpm) / back (s) / \
         largest estimation error (rpm) / estimate back (s) after the event; `-` where the \
         drive switched off.\n"
    );
    let mut names: Vec<&str> = default.iter().map(|c| c.machine.as_str()).collect();
    names.dedup();
    for name in names {
        let rows: Vec<(&Case, Option<&Case>)> = default
            .iter()
            .filter(|c| c.machine == name)
            .map(|c| {
                let p = paper
                    .iter()
                    .find(|p| p.machine == c.machine && p.rpm == c.rpm && p.load_nm == c.load_nm);
                (c, p)
            })
            .collect();
        let b = rows[0].0.bounds;
        let _ = writeln!(
            md,
            "\n## {name}\n\nBounds: dip {:.0} rpm, back in {:.2} s.\n\n\
             | speed (rpm) | load (N m) | observer | applied | removed | verdict |\n\
             |---|---|---|---|---|---|",
            b.dip_rpm, b.back_s
        );
        for (c, p) in rows {
            for (obs, case) in [("default (flux)", Some(c)), ("paper's", p)] {
                let Some(case) = case else { continue };
                let cell = |e: &Event| {
                    if case.fault.is_some() {
                        "-".to_string()
                    } else {
                        format!(
                            "{:.0} / {:.2} / {:.0} / {:.2}",
                            e.dip_rpm, e.back_s, e.est_err_rpm, e.est_back_s
                        )
                    }
                };
                let verdict = match case.failure() {
                    None => "pass".to_string(),
                    Some(why) if obs == "paper's" => format!("outside: {why}"),
                    Some(why) => format!("**fails**: {why}"),
                };
                let _ = writeln!(
                    md,
                    "| {:.0} | {} | {obs} | {} | {} | {verdict} |",
                    case.rpm,
                    // three significant digits: a 0.18 kW machine's 1.25 N m, not 1.2
                    if case.load_nm.abs() < 10.0 {
                        format!("{:+.2}", case.load_nm)
                    } else {
                        format!("{:+.1}", case.load_nm)
                    },
                    cell(&case.events[0]),
                    cell(&case.events[1])
                );
            }
        }
    }
    md
}
