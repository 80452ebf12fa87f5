//! `acim-sim commission`: the drive's self-commissioning ([`acim::commissioning`]) run
//! against the plant of a scenario (its inverter and sensor imperfections included, and
//! its `load_profile`, if any, coupled to the shaft: a load left on), and the result as
//! `identified.toml` with the confidence of each quantity, the true values and the
//! errors, and a figure of each test ([`write_figures`]).
//!
//! A result that fails a plausibility check ([`acim::commissioning::Concern`]: a coupled
//! load, an inertia or a no-load current out of line with the nameplate, a fit too
//! uncertain) is refused: [`commission`] returns the reason and what to check, and the
//! command writes `refused.toml` and the figures instead of `identified.toml`.

use crate::scenario::Scenario;
use crate::sim::build_plant;
use acim::commissioning::{Assessment, Check, Commissioning, Concern, Confidence, Stage};
use acim::DriveInputs;
use acim_plant::{LoadTorque, PwmPreload};
use serde::Serialize;
use std::path::{Path, PathBuf};

/// Longest commissioning, simulated s (the bound is 60 s).
pub const TIMEOUT_S: f32 = 60.0;

/// Identified against true values, with the identification's own bound on its error.
#[derive(Serialize, Clone, Copy, Debug, PartialEq)]
pub struct Pair {
    /// Identified.
    pub identified: f32,
    /// The plant's.
    pub true_value: f32,
    /// (identified - true) / true, %.
    pub error_pct: f32,
    /// The identification's bound on |error|, % ([`acim::commissioning::Confidence`]);
    /// infinite when it has none.
    pub confidence_pct: f32,
}

fn pair(identified: f32, true_value: f32, confidence: f32) -> Pair {
    Pair {
        identified,
        true_value,
        error_pct: 100.0 * (identified - true_value) / true_value,
        confidence_pct: 100.0 * confidence,
    }
}

impl Pair {
    /// The true error lies inside the confidence.
    pub fn bounded(&self) -> bool {
        self.error_pct.abs() <= self.confidence_pct
    }
}

/// One plausibility check as the report shows it.
#[derive(Serialize, Clone, Debug, PartialEq)]
pub struct CheckLine {
    /// The quantity.
    pub field: String,
    /// What a failure means.
    pub reason: String,
    /// Measured figure.
    pub value: f32,
    /// Accepted range.
    pub low: f32,
    /// See `low`.
    pub high: f32,
    /// Inside the range.
    pub passed: bool,
}

fn check_line(c: &Check) -> CheckLine {
    CheckLine {
        field: c.concern.field().into(),
        reason: c.concern.reason().into(),
        value: c.value,
        low: c.range.0,
        high: c.range.1,
        passed: c.passed(),
    }
}

/// The text a user sees for a refusal: reason, the measured figure, the range, advice.
pub fn refusal_text(c: &Check) -> String {
    let figure = match c.concern {
        Concern::CoupledLoad => format!(
            "{:.0} % of the rated torque at constant speed",
            100.0 * c.value
        ),
        Concern::InertiaInconsistent => format!("{:.0} % apart", 100.0 * c.value),
        Concern::InertiaHigh | Concern::InertiaLow => {
            format!("{:.2} times the catalogue line", c.value)
        }
        Concern::FluxCurrentHigh | Concern::FluxCurrentLow => {
            format!("{:.0} % measured", 100.0 * c.value)
        }
        Concern::Uncertain(f) => format!("{f} +-{:.1} %", 100.0 * c.value),
    };
    format!(
        "commissioning refused: {} ({figure}); {}",
        c.concern.reason(),
        c.concern.advice()
    )
}

/// What commissioning found.
#[derive(Serialize, Clone, Debug, PartialEq)]
pub struct Report {
    /// Scenario name.
    pub name: String,
    /// Rs, ohm.
    pub rs_ohm: Pair,
    /// R_R, ohm.
    pub rr_ohm: Pair,
    /// L_sigma, H.
    pub l_sigma_h: Pair,
    /// L_M at rated flux, H.
    pub l_m_h: Pair,
    /// Rated flux current (no-load current), A peak; the true value is the plant's
    /// no-load current at the same voltage and frequency.
    pub rated_flux_current_a: f32,
    /// Its confidence, %.
    pub rated_flux_current_confidence_pct: f32,
    /// J, kg m^2 (`None`: not resolved, see [`acim::commissioning::Identified::inertia`]).
    pub inertia_kgm2: Option<Pair>,
    /// B, N m s/rad (identified; the true viscous friction for comparison).
    pub friction_nms: Pair,
    /// Dead time, s.
    pub dead_time_s: Pair,
    /// Inverter voltage error per leg, V.
    pub inverter_error_v: f32,
    /// Device drop assumed (the board's), V.
    pub device_drop_v: f32,
    /// Electrical sequence time, simulated s.
    pub electrical_s: f32,
    /// Whole commissioning time, simulated s.
    pub total_s: f32,
    /// Every plausibility check.
    pub checks: Vec<CheckLine>,
    /// The refusal a user sees (`None`: accepted).
    pub refusal: Option<String>,
}

impl Report {
    /// `identified.toml`: `[inverse_gamma]`, `[mechanics]`, `[inverter]` (the keys a
    /// scenario's `controller_file` reads), `[confidence]` (each quantity's bound on its
    /// relative error, %), `[plausibility]` (each check's figure and range), and, per
    /// quantity, the true value and the error in `[check]`.
    pub fn toml(&self) -> String {
        let p = |k: &str, x: &Pair| {
            format!(
                "{k} = {{ identified = {}, true = {}, error_pct = {:.3}, confidence_pct = {} }}\n",
                x.identified,
                x.true_value,
                x.error_pct,
                pct(x.confidence_pct)
            )
        };
        let mut s = format!(
            "# written by `acim-sim commission` for `{}`{}\n\n[inverse_gamma]\nrs_ohm = {}\nrr_ohm = {}\nl_sigma_h = {}\nl_m_h = {}\nrated_flux_current_a = {}\n\n[mechanics]\ninertia_kgm2 = {}\nfriction_nms = {}\n\n[inverter]\ndead_time_s = {}\ndevice_drop_v = {}\n\n",
            self.name,
            self.refusal
                .as_ref()
                .map_or(String::new(), |r| format!("\n# REFUSED, not for use: {r}")),
            self.rs_ohm.identified,
            self.rr_ohm.identified,
            self.l_sigma_h.identified,
            self.l_m_h.identified,
            self.rated_flux_current_a,
            self.inertia_kgm2
                .map_or("nan # not resolved".to_string(), |j| j.identified.to_string()),
            self.friction_nms.identified,
            self.dead_time_s.identified,
            self.device_drop_v,
        );
        s += "# each quantity's bound on its relative error, % (acim::commissioning::Confidence)\n[confidence]\n";
        for (k, v) in [
            ("rs_ohm", self.rs_ohm.confidence_pct),
            ("rr_ohm", self.rr_ohm.confidence_pct),
            ("l_sigma_h", self.l_sigma_h.confidence_pct),
            ("l_m_h", self.l_m_h.confidence_pct),
            (
                "rated_flux_current_a",
                self.rated_flux_current_confidence_pct,
            ),
            (
                "inertia_kgm2",
                self.inertia_kgm2
                    .map_or(f32::INFINITY, |j| j.confidence_pct),
            ),
            ("friction_nms", self.friction_nms.confidence_pct),
            ("dead_time_s", self.dead_time_s.confidence_pct),
        ] {
            s += &format!("{k} = {}\n", pct(v));
        }
        s += &format!(
            "\n# the checks against the nameplate (acim::commissioning::Concern)\n[plausibility]\naccepted = {}\n",
            self.refusal.is_none()
        );
        if let Some(r) = &self.refusal {
            s += &format!("refusal = {r:?}\n");
        }
        // a check with no bound on either side does not apply here (e.g. the power factor's
        // when the nameplate prints none): not listed
        let applied = self
            .checks
            .iter()
            .filter(|c| c.low.is_finite() || c.high.is_finite());
        for (k, c) in applied.enumerate() {
            s += &format!(
                "check_{k} = {{ field = \"{}\", value = {}, low = {}, high = {}, passed = {}, fails_as = {:?} }}\n",
                c.field,
                toml_f32(c.value),
                toml_f32(c.low),
                toml_f32(c.high),
                c.passed,
                c.reason
            );
        }
        s += "\n[check]\n";
        s += &p("rs_ohm", &self.rs_ohm);
        s += &p("rr_ohm", &self.rr_ohm);
        s += &p("l_sigma_h", &self.l_sigma_h);
        s += &p("l_m_h", &self.l_m_h);
        if let Some(j) = &self.inertia_kgm2 {
            s += &p("inertia_kgm2", j);
        }
        s += &p("friction_nms", &self.friction_nms);
        s += &p("dead_time_s", &self.dead_time_s);
        s += &format!(
            "commissioning_s = {:.2}\nelectrical_s = {:.2}\n",
            self.total_s, self.electrical_s
        );
        s
    }

    /// Each quantity with its name, display unit and scale (each in a unit that shows
    /// its digits: a dead time of 1.5e-6 s printed with six decimals read as 0.000001
    /// against a true 0.000002).
    fn quantities(&self) -> Vec<(&'static str, &'static str, f32, &Pair)> {
        let mut q = vec![
            ("Rs", "ohm", 1.0, &self.rs_ohm),
            ("R_R", "ohm", 1.0, &self.rr_ohm),
            ("L_sigma", "mH", 1e3, &self.l_sigma_h),
            ("L_M", "mH", 1e3, &self.l_m_h),
        ];
        if let Some(j) = &self.inertia_kgm2 {
            q.push(("J", "g m^2", 1e3, j));
        }
        q.push(("B", "mN m s", 1e3, &self.friction_nms));
        q.push(("dead time", "us", 1e6, &self.dead_time_s));
        q
    }

    /// One line per quantity: identified, confidence, true, error.
    pub fn summary(&self) -> String {
        let mut s = String::new();
        for (k, unit, scale, x) in self.quantities() {
            s += &format!(
                "{k:<10} {:>11.4} {unit:<6} +-{:>6} %   true {:>11.4}  error {:>+7.2} %{}\n",
                x.identified * scale,
                pct(x.confidence_pct),
                x.true_value * scale,
                x.error_pct,
                if x.bounded() { "" } else { "  (outside)" }
            );
        }
        s
    }

    /// The same as a Markdown table, with the rated flux current (no true value: the
    /// plant's no-load current is not computed) and the sequence's time.
    pub fn markdown_table(&self) -> String {
        let mut s = String::from(
            "| quantity | identified | bound (+-%) | true | error (%) |\n|---|---|---|---|---|\n",
        );
        for (k, unit, scale, x) in self.quantities() {
            s += &format!(
                "| {k} ({unit}) | {:.4} | {} | {:.4} | {:+.2}{} |\n",
                x.identified * scale,
                pct(x.confidence_pct),
                x.true_value * scale,
                x.error_pct,
                if x.bounded() { "" } else { " (outside)" }
            );
        }
        s += &format!(
            "| rated flux current (A peak) | {:.4} | {} | | |\n\nIdentified in {:.1} s.\n",
            self.rated_flux_current_a,
            pct(self.rated_flux_current_confidence_pct),
            self.total_s
        );
        s
    }
}

fn pct(x: f32) -> String {
    if x.is_finite() {
        format!("{x:.2}")
    } else {
        "inf".into()
    }
}

fn toml_f32(x: f32) -> String {
    if x.is_finite() {
        format!("{x}")
    } else if x > 0.0 {
        "inf".into()
    } else {
        "-inf".into()
    }
}

/// One control period of the sequence, for the figures.
#[derive(Clone, Copy, Debug, Default)]
pub struct Sample {
    /// Time, s.
    pub t: f32,
    /// Stage: 0 offsets, 1 DC steps, 2 low-frequency impedance, 3 rated-frequency
    /// impedance, 4 no-load test.
    pub stage: u8,
    /// Measured phase currents a, b, A.
    pub i_ab: [f32; 2],
    /// Measured alpha/beta current, A.
    pub i_alpha_beta: [f32; 2],
    /// Commanded alpha/beta voltage (acts over the next period), V.
    pub v_alpha_beta: [f32; 2],
    /// The plant's mechanical speed, rpm.
    pub speed_rpm: f32,
    /// The V/f test's synchronous speed, rpm.
    pub sync_rpm: f32,
    /// The air-gap torque estimate, N m.
    pub torque_nm: f32,
}

/// A commissioning run: the report, the library's assessment and the trace.
#[derive(Clone, Debug)]
pub struct Run {
    /// The report.
    pub report: Report,
    /// The library's result.
    pub assessment: Assessment,
    /// The DC steps (A, V) and the line (Rs, intercept).
    pub dc: ([(f32, f32); 4], (f32, f32)),
    /// Every control period.
    pub trace: Vec<Sample>,
    /// Rated electrical frequency, rad/s; pole pairs.
    pub rated_frequency: f32,
    /// See `rated_frequency`.
    pub pole_pairs: u8,
    /// Control period, s.
    pub ts: f32,
}

/// Runs commissioning on `sc`'s plant, which needs `[nameplate]` and `[board]`: the
/// report if the result is accepted, the refusal ([`refusal_text`]) if not.
pub fn commission(sc: &Scenario) -> Result<Report, String> {
    let r = run(sc)?;
    match r.report.refusal {
        Some(e) => Err(e),
        None => Ok(r.report),
    }
}

/// The scenario's load at `t` s after the start.
fn load_at(sc: &Scenario, t: f32) -> LoadTorque {
    sc.load_profile
        .iter()
        .rfind(|p| p.t_s <= t)
        .map_or(LoadTorque::None, |p| p.load())
}

/// Runs commissioning on `sc`'s plant and keeps everything (a refused result too).
pub fn run(sc: &Scenario) -> Result<Run, String> {
    let v = sc.validate().map_err(|e| e.to_string())?;
    let (Some(np), Some(board)) = (sc.nameplate, v.board) else {
        return Err("commissioning needs [nameplate] and [board] (or --nameplate FILE)".into());
    };
    let nameplate = np.nameplate();
    let rated = nameplate.rated().map_err(|e| e.to_string())?;
    let mut plant = build_plant(sc, &v);
    let ts = 1.0 / board.pwm_frequency_hz;
    let mut pwm = PwmPreload::new();
    let mut com = Commissioning::new(&nameplate, &board).map_err(|e| e.to_string())?;
    let mut t = 0.0f32;
    let mut trace = Vec::new();
    let p = rated.pole_pairs as f32;
    let to_rpm = 60.0 / std::f32::consts::TAU;
    // the plant's magnetizing inductance at the no-load test's flux (saturation)
    let mut at_rated_flux = v.plant;
    while !matches!(com.stage(), Stage::Done | Stage::Failed(_)) {
        if t > TIMEOUT_S {
            return Err(format!("commissioning: no result within {TIMEOUT_S} s"));
        }
        let m = plant.sample();
        let out = com.step(&DriveInputs {
            phase_currents: m.phase_currents,
            dc_bus: m.dc_bus,
        });
        let stage = match com.stage() {
            Stage::Offsets => 0,
            Stage::DcStep(_) => 1,
            Stage::ImpedanceLow => 2,
            Stage::ImpedanceHigh => 3,
            _ => 4,
        };
        // the no-load hold (its frequency at the test's end value; the ramp down after it
        // leaves the test's flux)
        let w_hold = acim::commissioning::NO_LOAD_FREQUENCY * rated.frequency;
        if com.stage() == Stage::NoLoad && com.frequency() >= 0.999 * w_hold {
            at_rated_flux = plant.machine().effective_params();
        }
        let [a, b, _] = m.phase_currents;
        let vab = com.voltage();
        trace.push(Sample {
            t,
            stage,
            i_ab: [a, b],
            i_alpha_beta: [a, (a + 2.0 * b) / 3f32.sqrt()],
            v_alpha_beta: [vab.alpha, vab.beta],
            speed_rpm: plant.speed() * to_rpm,
            sync_rpm: com.frequency() / p * to_rpm,
            torque_nm: com.air_gap_torque(),
        });
        plant.set_dc_bus(sc.bus_v());
        plant.run_pwm_period(pwm.advance(out), load_at(sc, t));
        // the plant's hardware comparator (the simulator's default) opened the switches:
        // the result would be built on currents that never flowed
        if let Some(trip) = plant.comparator_trip() {
            return Err(format!(
                "commissioning: the hardware over-current comparator opened the switches at \
                 {:.4} s ({:.1} A, level {:.1} A)",
                t + trip.off_s,
                trip.current_a,
                plant.comparator().map_or(0.0, |c| c.level)
            ));
        }
        t += ts;
    }
    let electrical_s = t;
    if std::env::var_os("ACIM_COMMISSION_DEBUG").is_some() {
        eprintln!("{:?} {:?}", com.stage(), com.mechanics_sums());
    }
    let a = com.assess().map_err(|e| format!("commissioning: {e:?}"))?;
    if std::env::var_os("ACIM_COMMISSION_DEBUG").is_some() {
        eprintln!("{a:#?}");
    }
    let id = a.identified;
    let c: Confidence = a.confidence;
    let p = v.plant;
    let report = Report {
        name: sc.name.clone(),
        rs_ohm: pair(
            id.stator_resistance,
            p.stator_resistance(),
            c.stator_resistance,
        ),
        rr_ohm: pair(
            id.rotor_resistance,
            p.referred_rotor_resistance(),
            c.rotor_resistance,
        ),
        l_sigma_h: pair(
            id.leakage_inductance,
            p.transient_inductance(),
            c.leakage_inductance,
        ),
        l_m_h: pair(
            id.magnetizing_inductance,
            at_rated_flux.magnetizing_inductance(),
            c.magnetizing_inductance,
        ),
        rated_flux_current_a: id.rated_flux_current,
        rated_flux_current_confidence_pct: 100.0 * c.rated_flux_current,
        inertia_kgm2: id.inertia.map(|j| pair(j, p.inertia(), c.inertia)),
        friction_nms: pair(
            id.viscous_friction,
            p.viscous_friction().max(1e-9),
            c.viscous_friction,
        ),
        dead_time_s: pair(id.dead_time, sc.inverter.dead_time_s, c.dead_time),
        inverter_error_v: id.inverter_error,
        device_drop_v: board.device_drop_v,
        electrical_s,
        total_s: t,
        checks: a.checks.iter().map(check_line).collect(),
        refusal: a.refusal().map(|c| refusal_text(&c)),
    };
    Ok(Run {
        report,
        assessment: a,
        dc: (com.dc_points(), com.dc_line()),
        trace,
        rated_frequency: rated.frequency,
        pole_pairs: rated.pole_pairs,
        ts,
    })
}

/// The figures of a run in `dir`: `commission-overview.png` (the whole sequence),
/// `commission-dc.png` (the DC steps and their line), `commission-impedance-low.png` and
/// `commission-impedance-rated.png` (each standstill test's current against the fitted
/// model's) and `commission-no-load.png`
/// (the V/f test: currents, voltage, speed against the speed the identified J and B give
/// from the air-gap torque). Returns the paths written.
pub fn write_figures(run: &Run, dir: &Path) -> Result<Vec<PathBuf>, String> {
    use crate::plot::{render_panels, render_panels_over, Color, LineStyle, Panel, Series};
    let e = |p: &Path, x: crate::plot::PlotError| format!("{}: {x:?}", p.display());
    let mut written = Vec::new();
    let tr = &run.trace;
    let col = |f: &dyn Fn(&Sample) -> f32, s: &[Sample]| -> Vec<f32> { s.iter().map(f).collect() };
    let title = |what: &str| {
        format!(
            "Commissioning of {}: {what}{}",
            run.report.name,
            if run.report.refusal.is_some() {
                " (REFUSED)"
            } else {
                ""
            }
        )
    };

    // 1. overview
    let t = col(&|s| s.t, tr);
    let ia = col(&|s| s.i_ab[0], tr);
    let ib = col(&|s| s.i_ab[1], tr);
    let va = col(&|s| s.v_alpha_beta[0], tr);
    let vb = col(&|s| s.v_alpha_beta[1], tr);
    let n = col(&|s| s.speed_rpm, tr);
    let ns = col(&|s| s.sync_rpm, tr);
    let top = ns.iter().copied().fold(0.0f32, f32::max);
    // the power balance's torque (p P / w) is noise below 10 % of the end frequency
    let tq = col(
        &|s| {
            if s.stage == 4 && s.sync_rpm >= 0.1 * top {
                s.torque_nm
            } else {
                f32::NAN
            }
        },
        tr,
    );
    let path = dir.join("commission-overview.png");
    render_panels(
        &path,
        &title("the whole sequence (offsets, DC steps, impedances, no-load V/f)"),
        &t,
        &[
            Panel {
                title: "Measured phase currents",
                y_label: "A",
                series: vec![
                    Series {
                        label: "i_a",
                        values: &ia,
                        style: LineStyle::Solid(Color::Blue),
                    },
                    Series {
                        label: "i_b",
                        values: &ib,
                        style: LineStyle::Solid(Color::Orange),
                    },
                ],
            },
            Panel {
                title: "Commanded voltage",
                y_label: "V",
                series: vec![
                    Series {
                        label: "v_alpha",
                        values: &va,
                        style: LineStyle::Solid(Color::Blue),
                    },
                    Series {
                        label: "v_beta",
                        values: &vb,
                        style: LineStyle::Solid(Color::Orange),
                    },
                ],
            },
            Panel {
                title: "Speed",
                y_label: "rpm",
                series: vec![
                    Series {
                        label: "rotor (plant)",
                        values: &n,
                        style: LineStyle::Solid(Color::Blue),
                    },
                    Series {
                        label: "V/f synchronous",
                        values: &ns,
                        style: LineStyle::Dashed(Color::Gray),
                    },
                ],
            },
            Panel {
                title: "Air-gap torque (power balance, no-load test)",
                y_label: "N m",
                series: vec![Series {
                    label: "estimate",
                    values: &tq,
                    style: LineStyle::Solid(Color::Green),
                }],
            },
        ],
        1400,
        1200,
    )
    .map_err(|x| e(&path, x))?;
    written.push(path);

    // 2. the DC steps
    let (pts, (rs, c)) = run.dc;
    let x: Vec<f32> = pts.iter().map(|p| p.0).collect();
    let vm: Vec<f32> = pts.iter().map(|p| p.1).collect();
    let vf: Vec<f32> = pts.iter().map(|p| rs * p.0 + c).collect();
    let res: Vec<f32> = pts.iter().map(|p| p.1 - rs * p.0 - c).collect();
    let path = dir.join("commission-dc.png");
    let fit_label = format!(
        "fit: Rs {:.4} ohm +-{} %, intercept {:.3} V",
        rs,
        pct(run.report.rs_ohm.confidence_pct),
        c
    );
    render_panels_over(
        &path,
        &title("DC steps, mean alpha voltage against current"),
        "alpha current (A)",
        &x,
        &[
            Panel {
                title: "Voltage the current loops needed",
                y_label: "V",
                series: vec![
                    Series {
                        label: "measured (4 steps)",
                        values: &vm,
                        style: LineStyle::Solid(Color::Blue),
                    },
                    Series {
                        label: &fit_label,
                        values: &vf,
                        style: LineStyle::Dashed(Color::Red),
                    },
                ],
            },
            Panel {
                title: "Residual of the line",
                y_label: "V",
                series: vec![Series {
                    label: "measured - fit",
                    values: &res,
                    style: LineStyle::Solid(Color::Gray),
                }],
            },
        ],
        1200,
        700,
    )
    .map_err(|x| e(&path, x))?;
    written.push(path);

    // 3. the impedance tests: the measured alpha current against the model's response to
    // the applied voltage's fundamental
    let id = &run.assessment.identified;
    let seg: Vec<Sample> = tr
        .iter()
        .filter(|s| s.stage == 2 || s.stage == 3)
        .copied()
        .collect();
    let mut fit = vec![f32::NAN; seg.len()];
    for (stage, w) in [
        (
            2u8,
            acim::commissioning::LOW_FREQUENCY * run.rated_frequency,
        ),
        (3u8, run.rated_frequency),
    ] {
        let idx: Vec<usize> = (0..seg.len()).filter(|&k| seg[k].stage == stage).collect();
        if idx.is_empty() {
            continue;
        }
        // the last whole periods of the window: the voltage's fundamental (it acts 1.5
        // periods after its sample) and the current's mean
        let period = std::f32::consts::TAU / w;
        let t_end = seg[*idx.last().unwrap_or(&0)].t;
        let whole = ((t_end - seg[idx[0]].t) / period).floor().max(1.0);
        let t0 = t_end - whole * period;
        let (mut vr, mut vi, mut i_mean, mut nn) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
        for &k in &idx {
            let s = &seg[k];
            if s.t < t0 {
                continue;
            }
            let th = (w * (s.t + 1.5 * run.ts)) as f64;
            vr += s.v_alpha_beta[0] as f64 * th.cos();
            vi -= s.v_alpha_beta[0] as f64 * th.sin();
            i_mean += s.i_alpha_beta[0] as f64;
            nn += 1.0;
        }
        if nn == 0.0 {
            continue;
        }
        let (vr, vi, i_mean) = (2.0 * vr / nn, 2.0 * vi / nn, i_mean / nn);
        // Z = Rs + j w L_sigma + (j w L_M R_R) / (R_R + j w L_M), L_M small-signal
        let (wl, rr) = (
            (w * id.magnetizing_inductance_small_signal) as f64,
            id.rotor_resistance as f64,
        );
        let d = rr * rr + wl * wl;
        let zr = id.stator_resistance as f64 + wl * wl * rr / d;
        let zi = (w * id.leakage_inductance) as f64 + wl * rr * rr / d;
        let z2 = zr * zr + zi * zi;
        let (ir, ii) = ((vr * zr + vi * zi) / z2, (vi * zr - vr * zi) / z2);
        for &k in &idx {
            let th = (w * seg[k].t) as f64;
            fit[k] = (i_mean + ir * th.cos() - ii * th.sin()) as f32;
        }
    }
    let fit_label = format!(
        "model: R_R {:.4} ohm +-{} %, L_sigma {:.3} mH +-{} %",
        id.rotor_resistance,
        pct(run.report.rr_ohm.confidence_pct),
        id.leakage_inductance * 1e3,
        pct(run.report.l_sigma_h.confidence_pct)
    );
    for (stage, file, what) in [
        (
            2u8,
            "commission-impedance-low.png",
            "standstill impedance at 4 % of the rated frequency",
        ),
        (
            3u8,
            "commission-impedance-rated.png",
            "standstill impedance at the rated frequency",
        ),
    ] {
        let pick = |f: &dyn Fn(&Sample) -> f32| -> Vec<f32> {
            seg.iter().filter(|s| s.stage == stage).map(f).collect()
        };
        let ts = pick(&|s| s.t);
        let im = pick(&|s| s.i_alpha_beta[0]);
        let vs = pick(&|s| s.v_alpha_beta[0]);
        let fit_k: Vec<f32> = seg
            .iter()
            .zip(&fit)
            .filter(|(s, _)| s.stage == stage)
            .map(|(_, f)| *f)
            .collect();
        if ts.is_empty() {
            continue;
        }
        let path = dir.join(file);
        render_panels(
            &path,
            &title(what),
            &ts,
            &[
                Panel {
                    title: "Alpha current (the model's: its response to the voltage's fundamental)",
                    y_label: "A",
                    series: vec![
                        Series {
                            label: "measured",
                            values: &im,
                            style: LineStyle::Solid(Color::Blue),
                        },
                        Series {
                            label: &fit_label,
                            values: &fit_k,
                            style: LineStyle::Dashed(Color::Red),
                        },
                    ],
                },
                Panel {
                    title: "Alpha voltage commanded",
                    y_label: "V",
                    series: vec![Series {
                        label: "v_alpha",
                        values: &vs,
                        style: LineStyle::Solid(Color::Orange),
                    }],
                },
            ],
            1400,
            800,
        )
        .map_err(|x| e(&path, x))?;
        written.push(path);
    }

    // 4. the no-load test: the speed the identified J and B give from the air-gap torque
    let seg: Vec<Sample> = tr.iter().filter(|s| s.stage == 4).copied().collect();
    if !seg.is_empty() {
        let to_rad = std::f32::consts::TAU / 60.0;
        let (j, b) = (id.inertia.unwrap_or(f32::NAN), id.viscous_friction);
        // from where the ramp's band starts (30 % of the end frequency, as the fit), from
        // the rotor's speed there
        let end_rpm = seg.iter().map(|s| s.sync_rpm).fold(0.0f32, f32::max);
        let mut w = f32::NAN;
        let mut model = Vec::with_capacity(seg.len());
        for s in &seg {
            if w.is_nan() && s.sync_rpm >= 0.3 * end_rpm {
                w = s.speed_rpm * to_rad;
            }
            model.push(w / to_rad);
            if !w.is_nan() {
                w += (s.torque_nm - b * w) / j * run.ts;
            }
        }
        let t: Vec<f32> = seg.iter().map(|s| s.t).collect();
        let imag: Vec<f32> = seg
            .iter()
            .map(|s| s.i_alpha_beta[0].hypot(s.i_alpha_beta[1]))
            .collect();
        let vmag: Vec<f32> = seg
            .iter()
            .map(|s| s.v_alpha_beta[0].hypot(s.v_alpha_beta[1]))
            .collect();
        let n: Vec<f32> = seg.iter().map(|s| s.speed_rpm).collect();
        let ns: Vec<f32> = seg.iter().map(|s| s.sync_rpm).collect();
        // below 10 % of the end frequency the power balance's torque (p P / w) is noise
        let tq: Vec<f32> = seg
            .iter()
            .map(|s| {
                if s.sync_rpm >= 0.1 * end_rpm {
                    s.torque_nm
                } else {
                    f32::NAN
                }
            })
            .collect();
        let ia: Vec<f32> = seg.iter().map(|s| s.i_ab[0]).collect();
        let j_label = format!(
            "from the torque with J {} +-{} %, B {:.5} N m s/rad",
            id.inertia
                .map_or("not resolved".to_string(), |j| format!("{j:.5} kg m^2")),
            pct(run
                .report
                .inertia_kgm2
                .map_or(f32::INFINITY, |j| j.confidence_pct)),
            b
        );
        let path = dir.join("commission-no-load.png");
        render_panels(
            &path,
            &title("no-load V/f test (L_M, the flux current, J and friction)"),
            &t,
            &[
                Panel {
                    title: "Current",
                    y_label: "A",
                    series: vec![
                        Series {
                            label: "i_a",
                            values: &ia,
                            style: LineStyle::Solid(Color::Gray),
                        },
                        Series {
                            label: "|i| (peak)",
                            values: &imag,
                            style: LineStyle::Solid(Color::Blue),
                        },
                    ],
                },
                Panel {
                    title: "Voltage amplitude",
                    y_label: "V",
                    series: vec![Series {
                        label: "|v| commanded",
                        values: &vmag,
                        style: LineStyle::Solid(Color::Orange),
                    }],
                },
                Panel {
                    title: "Speed",
                    y_label: "rpm",
                    series: vec![
                        Series {
                            label: "rotor (plant)",
                            values: &n,
                            style: LineStyle::Solid(Color::Blue),
                        },
                        Series {
                            label: &j_label,
                            values: &model,
                            style: LineStyle::Dashed(Color::Red),
                        },
                        Series {
                            label: "V/f synchronous",
                            values: &ns,
                            style: LineStyle::Dashed(Color::Gray),
                        },
                    ],
                },
                Panel {
                    title: "Air-gap torque (power balance)",
                    y_label: "N m",
                    series: vec![Series {
                        label: "estimate",
                        values: &tq,
                        style: LineStyle::Solid(Color::Green),
                    }],
                },
            ],
            1400,
            1200,
        )
        .map_err(|x| e(&path, x))?;
        written.push(path);
    }
    Ok(written)
}
