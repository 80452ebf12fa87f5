//! The robustness matrix of speeds x motoring/regenerating x loads x parameter
//! and inverter errors, with the paper scenarios' sensor noise and gain errors, measured
//! closed loop. `acim-sim robustness` writes it to `docs/robustness.md`.
//!
//! Each case: start, ramp to the speed at 0.5 s, an active load (constant sign: it opposes
//! the rotation when motoring and drives it when regenerating) from 2.5 s, then the case's
//! error. The steady window is the last 2 s. The steady speed-estimation error is the mean
//! of (estimated - true speed) over the window; the stator frequency is its mean there.
//! A case with |f_s| >= 1 Hz passes when that error is at most max(2 rpm, 1 % of the
//! reference), the speed is held (its mean within max(4 rpm, 2 %) of the target), the
//! drive did not fault and the speed stayed within 100 rpm of its reference (10 ms means, from 1 s after the load step); below 1 Hz (the unobservable line) it passes without a fault and without
//! losing the speed.

use crate::scenario::{LoadKind, LoadPoint, PlantChange, RsMode, Scenario, SpeedPoint, Window};
use crate::sim;

/// The error a case adds to the nominal drive.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Variant {
    /// Nothing.
    Nominal,
    /// The controller's Rs 20 % above the machine's.
    ControllerRsPlus20,
    /// The controller's Rs 20 % below the machine's.
    ControllerRsMinus20,
    /// The machine's Rs rises 30 % over 20 s while running.
    PlantRsDrift30,
    /// The machine's Rs steps up 20 % while running.
    PlantRsStep20,
    /// The inverter's dead time is 1.0 us; the drive is configured for 1.5 us (and, as it
    /// ships, identifies the error at start: `drive.start.inverter_identification`
    /// item 2).
    DeadTime1_0,
    /// The inverter's dead time is 2.2 us; the drive is configured for 1.5 us.
    DeadTime2_2,
    /// 20 mA offsets on phases a and b from t = 0, before the drive could measure them:
    /// uncompensated through the standstill Rs identification and the run (what a failed
    /// or skipped switches-off measurement leaves).
    Offset20mA,
    /// 20 mA offsets on phases a and b drifting in after the start's measurement, over
    /// 1 s from the change time while the motor turns (an amplifier's drift).
    OffsetDrift20mA,
    /// The inverter's dead time is 1.0 us, the drive is configured for 1.5 us and its start
    /// test is switched off (`drive.start.inverter_identification = false`): the configured
    /// compensation alone, what the test buys.
    DeadTime1_0NotIdentified,
    /// The inverter's dead time is 2.2 us, configured 1.5 us, the start test off.
    DeadTime2_2NotIdentified,
}

impl Variant {
    /// Every variant of the acceptance matrix, in table order.
    pub const MATRIX: [Variant; 10] = [
        Variant::Nominal,
        Variant::ControllerRsPlus20,
        Variant::ControllerRsMinus20,
        Variant::PlantRsDrift30,
        Variant::DeadTime1_0,
        Variant::DeadTime2_2,
        Variant::DeadTime1_0NotIdentified,
        Variant::DeadTime2_2NotIdentified,
        Variant::Offset20mA,
        Variant::OffsetDrift20mA,
    ];

    /// Short name for the table.
    pub fn name(self) -> &'static str {
        match self {
            Variant::Nominal => "nominal",
            Variant::ControllerRsPlus20 => "ctl Rs +20 %",
            Variant::ControllerRsMinus20 => "ctl Rs -20 %",
            Variant::PlantRsDrift30 => "plant Rs +30 % / 20 s",
            Variant::PlantRsStep20 => "plant Rs +20 % step",
            Variant::DeadTime1_0 => "dead time 1.0 us",
            Variant::DeadTime2_2 => "dead time 2.2 us",
            Variant::Offset20mA => "offsets 20 mA from power-up",
            Variant::OffsetDrift20mA => "offsets 20 mA, drifting in",
            Variant::DeadTime1_0NotIdentified => "dead time 1.0 us, not identified",
            Variant::DeadTime2_2NotIdentified => "dead time 2.2 us, not identified",
        }
    }
}

/// How the drive is set up for a case (the rest is the paper defaults).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Setup {
    /// Rs estimation mode.
    pub mode: RsMode,
    /// `drive.loops.regen_min_frequency_hz` (0: off).
    pub regen_min_frequency_hz: f32,
}

/// The setups the report compares: earlier (the standstill Rs mode, no regeneration
/// limit), Rs while running, Rs while running with the 1.5 Hz regeneration limit (the
/// drive's defaults), and the standstill Rs mode with the limit (the defaults the
/// overhauling-load sweep set, before Rs tracking became the default).
pub const SETUPS: [(Setup, &str); 4] = [
    (
        Setup {
            mode: RsMode::Standstill,
            regen_min_frequency_hz: 0.0,
        },
        "Rs mode standstill (identification before the ramp, then eq. 19 below 1.5 Hz), no regeneration limit (regen_min_frequency_hz = 0: the defaults before the limit)",
    ),
    (
        Setup {
            mode: RsMode::Running,
            regen_min_frequency_hz: 0.0,
        },
        "Rs mode running (the q/d residual combination while turning), no regeneration limit",
    ),
    (
        Setup {
            mode: RsMode::Running,
            regen_min_frequency_hz: 1.5,
        },
        "Rs mode running, regeneration limit 1.5 Hz (the drive's defaults)",
    ),
    (
        Setup {
            mode: RsMode::Standstill,
            regen_min_frequency_hz: 1.5,
        },
        "Rs mode standstill, regeneration limit 1.5 Hz (the defaults before Rs tracking while running)",
    ),
];

/// One case of the matrix.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Case {
    /// Speed reference, rpm (> 0).
    pub rpm: f32,
    /// The load drives the machine (regeneration) instead of opposing it.
    pub regenerating: bool,
    /// Load torque magnitude, N m.
    pub load_nm: f32,
    /// The error.
    pub variant: Variant,
}

/// The load is applied at this time, s.
const LOAD_AT: f32 = 2.5;
/// The plant change starts at this time, s.
const CHANGE_AT: f32 = 4.0;
/// Length of the steady window at the end, s.
const WINDOW: f32 = 2.0;
/// The offset drift's ramp, s ([`Variant::OffsetDrift20mA`]).
const OFFSET_DRIFT_RAMP: f32 = 1.0;

impl Case {
    /// The stator frequency of the case's steady operating point, Hz: w_s = p Omega +
    /// R_R i_sq / lambda with the electromagnetic torque T_e = +/-T_L + B Omega =
    /// 1.5 p lambda i_sq and lambda = L_M i_sd* (paper machine, nominal drive).
    pub fn stator_frequency_hz(&self) -> f32 {
        let m = acim::MachineParams::paper_table1();
        let d = acim::DriveConfig::paper_defaults();
        let lambda = m.rotor_flux_for(d.loops.flux_current);
        let p = m.pole_pairs_f32();
        let omega = self.rpm * acim::math::RPM_TO_RAD_S;
        let load = if self.regenerating {
            -self.load_nm
        } else {
            self.load_nm
        };
        let te = load + m.viscous_friction() * omega;
        let i_sq = te / (1.5 * p * lambda);
        (p * omega + m.referred_rotor_resistance() * i_sq / lambda) / acim::math::TAU
    }

    /// The scenario of this case, with the Rs estimator on in `mode`.
    pub fn scenario(&self, mode: RsMode) -> Scenario {
        self.scenario_with(&Setup {
            mode,
            regen_min_frequency_hz: 0.0,
        })
    }

    /// The scenario of this case with the drive set up as `setup`.
    pub fn scenario_with(&self, setup: &Setup) -> Scenario {
        let mode = setup.mode;
        let mut s = Scenario {
            name: "robustness".into(),
            description: String::new(),
            ..Scenario::default()
        };
        // the paper scenarios' sensors (noise, gain errors, 5 mA offsets)
        s.sensors.noise_a = 0.01;
        s.sensors.gain_error = [0.003, -0.003, 0.0];
        s.sensors.offset_a = [0.005, -0.005, 0.0];
        s.drive.estimation.rs_estimation = true;
        s.drive.estimation.rs_estimation_mode = mode;
        s.drive.loops.regen_min_frequency_hz = setup.regen_min_frequency_hz;
        s.speed_profile = vec![SpeedPoint {
            t_s: 0.5,
            rpm: self.rpm,
        }];
        let torque = if self.regenerating {
            -self.load_nm
        } else {
            self.load_nm
        };
        s.load_profile = vec![LoadPoint {
            t_s: LOAD_AT,
            kind: LoadKind::Active,
            torque_nm: torque,
        }];
        // the change ends at `end`; the window starts 2 s later ("2 s after
        // the change ends")
        let mut end = CHANGE_AT;
        match self.variant {
            Variant::Nominal => {}
            Variant::ControllerRsPlus20 => s.controller.rs_ohm = 1.2 * s.plant.rs_ohm,
            Variant::ControllerRsMinus20 => s.controller.rs_ohm = 0.8 * s.plant.rs_ohm,
            Variant::PlantRsDrift30 => {
                s.plant_changes = vec![PlantChange {
                    t_s: CHANGE_AT,
                    ramp_s: 20.0,
                    rs_factor: 1.3,
                    rr_factor: 1.0,
                }];
                end = CHANGE_AT + 20.0;
            }
            Variant::PlantRsStep20 => {
                s.plant_changes = vec![PlantChange {
                    t_s: CHANGE_AT,
                    ramp_s: 0.0,
                    rs_factor: 1.2,
                    rr_factor: 1.0,
                }];
            }
            Variant::DeadTime1_0 => s.inverter.dead_time_s = 1.0e-6,
            Variant::DeadTime2_2 => s.inverter.dead_time_s = 2.2e-6,
            Variant::DeadTime1_0NotIdentified => {
                s.inverter.dead_time_s = 1.0e-6;
                s.drive.start.inverter_identification = false;
            }
            Variant::DeadTime2_2NotIdentified => {
                s.inverter.dead_time_s = 2.2e-6;
                s.drive.start.inverter_identification = false;
            }
            // present from power-up: every start waits for the switches-off measurement
            // (the simulator powers the drive 0.1 s before t = 0, `sim::POWER_UP_S`), so
            // they are measured and subtracted, up to the sensors' noise
            Variant::Offset20mA => s.sensors.offset_a = [0.020, -0.020, 0.0],
            // on top of the paper sensors' 5 mA (measured before the start), 20 mA more
            // drift in while the motor turns, after the measurement
            Variant::OffsetDrift20mA => {
                s.faults.current_sensor_offset_change_a = [0.020, -0.020, 0.0];
                s.faults.current_sensor_offset_change_at_s = Some(CHANGE_AT);
                s.faults.current_sensor_offset_change_ramp_s = OFFSET_DRIFT_RAMP;
                end = CHANGE_AT + OFFSET_DRIFT_RAMP;
            }
        }
        let from = end + 2.0;
        s.duration_s = from + WINDOW;
        s.windows = vec![Window {
            name: "steady".into(),
            from_s: from,
            to_s: from + WINDOW,
        }];
        s
    }
}

/// What a case measured.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Outcome {
    /// The case.
    pub case: Case,
    /// Mean (estimated - true speed) over the steady window, rpm.
    pub speed_est_error_rpm: f32,
    /// Mean (true speed - the case's speed target) over the steady window, rpm.
    pub speed_error_rpm: f32,
    /// Mean stator frequency the drive measured over the window, Hz.
    pub stator_frequency_hz: f32,
    /// (Rs_hat - Rs_true) / Rs_true at the window's start, %.
    pub rs_error_pct: f32,
    /// The drive faulted.
    pub faulted: bool,
    /// |speed - reference| exceeded 100 rpm (10 ms mean) from 1 s after the load step.
    pub lost: bool,
}

impl Outcome {
    /// The observable region: |f_s| >= 1 Hz at the case's operating point
    /// ([`Case::stator_frequency_hz`]; the measured mean moves when the drive drifts).
    pub fn observable(&self) -> bool {
        self.case.stator_frequency_hz().abs() >= 1.0
    }

    /// The speed is held: |speed error| at most max(4 rpm, 2 % of the target).
    pub fn held(&self) -> bool {
        self.speed_error_rpm.abs() <= (0.02 * self.case.rpm).max(4.0)
    }

    /// The pass criterion (module docs).
    pub fn pass(&self) -> bool {
        let ok = !self.faulted && !self.lost;
        if self.observable() {
            ok && self.held() && self.speed_est_error_rpm.abs() <= (0.01 * self.case.rpm).max(2.0)
        } else {
            ok
        }
    }
}

/// Runs one case.
pub fn run(case: &Case, mode: RsMode) -> Result<Outcome, crate::scenario::ScenarioError> {
    run_scenario(case, &case.scenario(mode))
}

/// Runs `sc`, a case's scenario (possibly modified), and measures it as `case`.
pub fn run_scenario(case: &Case, sc: &Scenario) -> Result<Outcome, crate::scenario::ScenarioError> {
    let r = sim::run(sc)?;
    let w = &sc.windows[0];
    let rows: Vec<_> = r
        .rows
        .iter()
        .filter(|x| x.t_s >= w.from_s && x.t_s < w.to_s)
        .collect();
    let n = rows.len().max(1) as f32;
    let mean = |f: &dyn Fn(&sim::Row) -> f32| rows.iter().map(|x| f(x)).sum::<f32>() / n;
    let rs_true = sc.plant.rs_ohm * crate::scenario::plant_factors(&sc.plant_changes, w.from_s).0;
    let rs_hat = rows
        .first()
        .map_or(f32::NAN, |x| x.stator_resistance_est_ohm);
    // lost: a 10 ms mean of |speed - reference| above 100 rpm after the load step
    let per = (0.01 / r.config.loops.control_period).round().max(1.0) as usize;
    let after_load: Vec<f32> = r
        .rows
        .iter()
        .filter(|x| x.t_s >= LOAD_AT + 1.0)
        .map(|x| x.speed_rpm - x.speed_ref_rpm)
        .collect();
    let lost = after_load
        .chunks(per)
        .any(|c| (c.iter().sum::<f32>() / c.len() as f32).abs() > 100.0);
    Ok(Outcome {
        case: *case,
        speed_est_error_rpm: mean(&|x| x.speed_est_rpm - x.speed_rpm),
        speed_error_rpm: mean(&|x| x.speed_rpm) - case.rpm,
        stator_frequency_hz: mean(&|x| x.stator_frequency_hz),
        rs_error_pct: 100.0 * (rs_hat - rs_true) / rs_true,
        faulted: r.fault.is_some(),
        lost,
    })
}

/// Every case of the acceptance matrix: 500, 120, 60 rpm x motoring/regenerating x 1.5 and
/// 4.5 N m x [`Variant::MATRIX`].
pub fn matrix() -> Vec<Case> {
    let mut v = Vec::new();
    for variant in Variant::MATRIX {
        for rpm in [500.0, 120.0, 60.0] {
            for regenerating in [false, true] {
                for load_nm in [1.5, 4.5] {
                    v.push(Case {
                        rpm,
                        regenerating,
                        load_nm,
                        variant,
                    });
                }
            }
        }
    }
    v
}

/// The matrix as a markdown table, one row per case.
pub fn table(outcomes: &[Outcome]) -> String {
    let mut s = String::from(
        "| error | speed (rpm) | quadrant | load (N m) | f_s (Hz) | f_s measured (Hz) | speed est. error (rpm) | speed error (rpm) | Rs_hat error (%) | result |\n|---|---|---|---|---|---|---|---|---|---|\n",
    );
    for o in outcomes {
        let c = &o.case;
        let result = match (o.faulted, o.lost, o.observable(), o.pass()) {
            (true, _, _, _) => "FAIL (fault)",
            (_, true, _, _) => "FAIL (lost)",
            (_, _, true, true) => "pass",
            (_, _, true, false) if !o.held() => "FAIL (not held)",
            (_, _, true, false) => "FAIL (error)",
            (_, _, false, _) => "below 1 Hz: no fault, not lost",
        };
        s.push_str(&format!(
            "| {} | {} | {} | {} | {:.2} | {:.2} | {:.2} | {:.2} | {:.1} | {} |\n",
            c.variant.name(),
            c.rpm,
            if c.regenerating { "regen" } else { "motor" },
            c.load_nm,
            c.stator_frequency_hz(),
            o.stator_frequency_hz,
            o.speed_est_error_rpm,
            o.speed_error_rpm,
            o.rs_error_pct,
            result
        ));
    }
    s
}

/// The Rs-tracking cases of a +30 % plant Rs ramp over 20 s and a +20 %
/// step, at 500, 120 and 60 rpm, motoring and regenerating, 1.5 N m.
pub fn tracking_cases() -> Vec<Case> {
    let mut v = Vec::new();
    for variant in [Variant::PlantRsDrift30, Variant::PlantRsStep20] {
        for rpm in [500.0, 120.0, 60.0] {
            for regenerating in [false, true] {
                v.push(Case {
                    rpm,
                    regenerating,
                    load_nm: 1.5,
                    variant,
                });
            }
        }
    }
    v
}

/// `acim-sim robustness`: the Rs-tracking cases and the whole matrix, with the Rs
/// estimator in the standstill mode (earlier) and the running mode (the default),
/// as Markdown. `sets` are `--set` overrides applied to every case's scenario (e.g. another
/// control rate and a slow task); `progress` is called with each case's one-line summary.
pub fn report(
    sets: &[String],
    progress: &mut dyn FnMut(&str),
) -> Result<String, crate::scenario::ScenarioError> {
    let mut md = String::from(
        "<!-- generated by `cargo run --release -p acim-sim -- robustness`; do not edit -->\n\n\
         Closed loop, the paper machine, 12-bit sensors with 10 mA noise, gain errors +/-0.3 % \
         and 5 mA offsets (the paper scenarios' Figs. 10-12), the drive configured for a \
         dead time of 1.5 us and a 1 V drop and identifying the inverter's error beyond it at \
         every start (the drive's default) unless the case says otherwise, Rs estimator on. The drive is powered 0.1 s \
         before t = 0 with the switches off and measures the current offsets; start at 0, ramp to the \
         speed at 0.5 s, active load from 2.5 s (opposing the rotation: motor; driving it: \
         regen), the case's change from 4 s; steady window: the last 2 s, starting 2 s after \
         the change ends. f_s: the stator frequency of the operating point (computed) and as \
         the drive measured it. Speed est. error: mean of estimated - true speed over the \
         window; speed error: mean of true speed - the speed target. Pass with |f_s| >= 1 Hz: no \
         fault, not lost (|speed - reference| within 100 rpm, 10 ms means, from 1 s after \
         the load step), speed held (|speed error| <= max(4 rpm, 2 %)) and |speed est. \
         error| <= max(2 rpm, 1 % of the reference). Below \
         1 Hz: no fault and not lost (the speed error is reported, not bounded).\n\n",
    );
    md += "## Rs tracking while running (item 1)\n\n";
    for (setup, label) in &SETUPS[..2] {
        md += &format!("### {label}\n\n");
        let mut outs = Vec::new();
        for c in tracking_cases() {
            let o = run_scenario(&c, &c.scenario_with(setup).with_overrides(sets)?)?;
            progress(&format!(
                "{setup:?} {:?} {} rpm regen={} -> pass={}",
                c.variant,
                c.rpm,
                c.regenerating,
                o.pass()
            ));
            outs.push(o);
        }
        md += &table(&outs);
        md += "\n";
    }
    md += "## The matrix\n\n";
    for (setup, label) in &SETUPS {
        let mut outs = Vec::new();
        for c in matrix() {
            let o = run_scenario(&c, &c.scenario_with(setup).with_overrides(sets)?)?;
            progress(&format!(
                "{setup:?} {:?} {} rpm regen={} {} N m -> pass={}",
                c.variant,
                c.rpm,
                c.regenerating,
                c.load_nm,
                o.pass()
            ));
            outs.push(o);
        }
        let observable: Vec<_> = outs.iter().filter(|o| o.observable()).collect();
        let passed = observable.iter().filter(|o| o.pass()).count();
        let low: Vec<_> = outs.iter().filter(|o| !o.observable()).collect();
        let low_ok = low.iter().filter(|o| o.pass()).count();
        md += &format!(
            "### {label}\n\n{passed} of {} cases with |f_s| >= 1 Hz pass; \
             {low_ok} of {} cases below 1 Hz end without a fault and without losing the speed.\n\n",
            observable.len(),
            low.len()
        );
        md += &table(&outs);
        md += "\n";
    }
    Ok(md)
}
