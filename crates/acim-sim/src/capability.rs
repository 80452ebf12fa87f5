//! `acim-sim capability`: the steady torque the drive holds at each speed up
//! to 3000 rpm, against the theoretical envelope of the machine equations with the same
//! current and voltage limits.
//!
//! Measured: for each speed the paper machine (325 V, `fw-ramp-3000`'s settings) runs up
//! to the speed unloaded, then a passive load is applied; the load is bisected (8 steps)
//! for the largest one under which the drive keeps control without a fault and the
//! speed stays within 1 % of the target over the last second. The torque held is that
//! load plus the plant's viscous friction at the speed.
//!
//! Both modulators are measured: linear SVPWM (the default), whose field weakening holds
//! the command at 92 % of the current loops' limit for their transients, and
//! overmodulation (`drive.modulation = "overmodulation"`), which holds it at the linear
//! limit and gives the current loops the range up to six-step instead.
//!
//! Envelope: the steady-state T-model in the rotor-flux frame (eq. 9a/9b with
//! lambda_r = (L_M^2/L_R) i_sd and the slip law eq. 8), |i| <= I_max (the drive's current
//! limit) and |v| <= 0.98 V_dc/sqrt 3 (the current loops' voltage limit), torque
//! 1.5 p (L_M^2/L_R) i_sd i_sq maximised over i_sd.

use crate::builtins;
use crate::metrics::Metrics;
use crate::scenario::{
    LoadKind, LoadPoint, MachineSpec, ModulationKind, Scenario, SpeedPoint, Window,
};
use std::fmt::Write as _;

/// One speed of the capability curve.
#[derive(Clone, Copy, Debug)]
pub struct Point {
    /// Speed, rpm.
    pub rpm: f32,
    /// Electromagnetic torque held (load + friction), linear SVPWM, N m.
    pub held_nm: f32,
    /// The same with overmodulation, N m.
    pub held_overmodulation_nm: f32,
    /// The envelope of the machine equations, N m.
    pub envelope_nm: f32,
    /// The same envelope at the voltage the field weakening holds the command at,
    /// [`acim::design::FW_TRIM_FRACTION`] x the current loops' limit, N m.
    pub envelope_trim_nm: f32,
    /// The envelope at the six-step fundamental 2 V_dc/pi (no PWM), N m: what the
    /// inverter could give in steady six-step operation.
    pub envelope_six_step_nm: f32,
}

/// The speeds measured, rpm.
pub const SPEEDS_RPM: [f32; 12] = [
    250.0, 500.0, 750.0, 1000.0, 1250.0, 1500.0, 1750.0, 2000.0, 2250.0, 2500.0, 2750.0, 3000.0,
];

/// Largest steady torque (N m) of machine `m` at `rpm` with current limit `i_max` (A peak)
/// and voltage limit `v_max` (V peak), by search over i_sd and bisection on i_sq.
pub fn envelope_nm(m: &MachineSpec, i_max: f32, i_d_max: f32, v_max: f32, rpm: f32) -> f32 {
    let (rs, rr, ls, lr, lm) = (
        m.rs_ohm as f64,
        m.rr_ohm as f64,
        m.ls_h as f64,
        m.lr_h as f64,
        m.lm_h as f64,
    );
    let p = m.pole_pairs as f64;
    let sigma_ls = ls - lm * lm / lr;
    let rr_ref = (lm / lr) * (lm / lr) * rr;
    let l_flux = lm * lm / lr;
    let w_mech = rpm as f64 * std::f64::consts::PI / 30.0;
    let (i_max, v_max) = (i_max as f64, v_max as f64);
    let fits = |i_d: f64, i_q: f64| {
        let lambda = l_flux * i_d;
        let ws = p * w_mech + rr_ref * i_q / lambda;
        let vd = rs * i_d - ws * sigma_ls * i_q;
        let vq = rs * i_q + ws * ls * i_d;
        vd * vd + vq * vq <= v_max * v_max
    };
    let mut best = 0.0f64;
    for k in 1..=400 {
        let i_d = i_d_max.min(i_max as f32) as f64 * k as f64 / 400.0;
        if !fits(i_d, 0.0) {
            continue;
        }
        let (mut lo, mut hi) = (0.0, (i_max * i_max - i_d * i_d).max(0.0).sqrt());
        if fits(i_d, hi) {
            lo = hi;
        } else {
            for _ in 0..40 {
                let mid = 0.5 * (lo + hi);
                if fits(i_d, mid) {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
        }
        best = best.max(1.5 * p * l_flux * i_d * lo);
    }
    best as f32
}

/// The scenario holding `rpm` with a passive `load_nm` applied once at speed.
fn scenario(rpm: f32, load_nm: f32, modulation: ModulationKind) -> Scenario {
    let mut s = builtins::get("fw-ramp-3000").expect("fw-ramp-3000 is a built-in");
    s.drive.modulation = modulation;
    let t_load = 0.5 + rpm / s.drive.loops.speed_ramp_rpm_s + 1.0;
    s.name = format!("capability-{rpm:.0}");
    s.speed_profile = vec![SpeedPoint { t_s: 0.5, rpm }];
    // the load rises in ten steps over 2 s (a sudden passive step at low speed stops
    // the rotor before the speed loop answers: a transient, not the steady capability)
    s.load_profile = (1..=10)
        .map(|k| LoadPoint {
            t_s: t_load + 0.2 * (k - 1) as f32,
            kind: LoadKind::Passive,
            torque_nm: load_nm * k as f32 / 10.0,
        })
        .collect();
    s.duration_s = t_load + 4.0;
    s.windows = vec![Window {
        name: "held".into(),
        from_s: t_load + 3.0,
        to_s: t_load + 4.0,
    }];
    s.csv_decimation = Some(100);
    s
}

fn holds(m: &Metrics, rpm: f32) -> bool {
    m.control_kept
        && m.fault.is_none()
        && m.windows
            .get("held")
            .is_some_and(|w| (w.speed_mean_rpm - rpm).abs() <= 0.02 * rpm)
}

/// Measures every speed of [`SPEEDS_RPM`] (each run through `run`).
pub fn measure_with(
    run: &mut dyn FnMut(&Scenario) -> Result<Metrics, String>,
) -> Result<Vec<Point>, String> {
    measure_at(run, &SPEEDS_RPM)
}

/// Measures the speeds `speeds_rpm` (each run through `run`).
pub fn measure_at(
    run: &mut dyn FnMut(&Scenario) -> Result<Metrics, String>,
    speeds_rpm: &[f32],
) -> Result<Vec<Point>, String> {
    let mut points = Vec::new();
    for &rpm in speeds_rpm {
        let sc = scenario(rpm, 0.0, ModulationKind::Linear);
        let i_max = sc.drive.limits.current_limit_a;
        let v_max = 0.98 * sc.bus_v() / 3f32.sqrt();
        let envelope = envelope_nm(&sc.plant, i_max, sc.drive.loops.flux_current_a, v_max, rpm);
        let envelope_trim = envelope_nm(
            &sc.plant,
            i_max,
            sc.drive.loops.flux_current_a,
            acim::design::FW_TRIM_FRACTION * v_max,
            rpm,
        );
        let envelope_six_step = envelope_nm(
            &sc.plant,
            i_max,
            sc.drive.loops.flux_current_a,
            acim::svpwm::SIX_STEP * sc.bus_v(),
            rpm,
        );
        let friction = sc.plant.friction_nms * rpm * std::f32::consts::PI / 30.0;
        let mut held = [0.0f32; 2];
        for (h, modulation) in held
            .iter_mut()
            .zip([ModulationKind::Linear, ModulationKind::Overmodulation])
        {
            // the bisection's upper end: above what the modulator's voltage can give
            let top = match modulation {
                ModulationKind::Linear => envelope,
                ModulationKind::Overmodulation => envelope_six_step,
            };
            let (mut lo, mut hi) = (0.0f32, (1.2 * top - friction).max(0.1));
            for _ in 0..8 {
                let mid = 0.5 * (lo + hi);
                if holds(&run(&scenario(rpm, mid, modulation))?, rpm) {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            *h = lo + friction;
        }
        points.push(Point {
            rpm,
            held_nm: held[0],
            held_overmodulation_nm: held[1],
            envelope_nm: envelope,
            envelope_trim_nm: envelope_trim,
            envelope_six_step_nm: envelope_six_step,
        });
    }
    Ok(points)
}

/// The table as Markdown.
pub fn markdown(points: &[Point]) -> String {
    let mut s = String::from(
        "<!-- generated by `cargo run --release -p acim-sim -- capability`; do not edit -->\n\n\
         Steady torque the drive holds (paper machine, 325 V, field weakening; load bisected \
         8 times, speed within 2 % over the last second) against the envelope of the \
         machine equations with the same current limit (4.67 A), flux current \
         at most its rated 1.5 A and voltage limit (0.98 V_dc/sqrt 3, the linear range the \
         drive runs in steady state). Linear SVPWM: the field weakening holds the command at \
         92 % of that voltage (its headroom for the current loops). Overmodulation \
         (`drive.modulation = \"overmodulation\"`): the command is held at the linear limit \
         and the current loops' headroom is the range up to six-step. Last column: the \
         envelope at the six-step fundamental 2 V_dc/pi, which steady six-step operation \
         (not done: no current control left) would approach. Plot: `capability.png`.\n\n\
         | speed (rpm) | envelope (N m) | linear SVPWM: held (N m) | held / envelope | overmodulation: held (N m) | held / envelope | envelope at 92 % voltage (N m) | envelope at six-step (N m) |\n|---|---|---|---|---|---|---|---|\n",
    );
    for p in points {
        let pct = |x: f32| 100.0 * x / p.envelope_nm.max(1e-6);
        let _ = writeln!(
            s,
            "| {:.0} | {:.2} | {:.2} | {:.0} % | {:.2} | {:.0} % | {:.2} | {:.2} |",
            p.rpm,
            p.envelope_nm,
            p.held_nm,
            pct(p.held_nm),
            p.held_overmodulation_nm,
            pct(p.held_overmodulation_nm),
            p.envelope_trim_nm,
            p.envelope_six_step_nm,
        );
    }
    s
}

/// The curve as a PNG at `path`.
pub fn plot(points: &[Point], path: &std::path::Path) -> Result<(), crate::plot::PlotError> {
    use crate::plot::{Color, LineStyle, Panel, Series};
    let x: Vec<f32> = points.iter().map(|p| p.rpm).collect();
    let held: Vec<f32> = points.iter().map(|p| p.held_nm).collect();
    let held_om: Vec<f32> = points.iter().map(|p| p.held_overmodulation_nm).collect();
    let env_six: Vec<f32> = points.iter().map(|p| p.envelope_six_step_nm).collect();
    let env: Vec<f32> = points.iter().map(|p| p.envelope_nm).collect();
    let env_trim: Vec<f32> = points.iter().map(|p| p.envelope_trim_nm).collect();
    crate::plot::render_panels_over(
        path,
        "Torque capability: paper machine, 325 V, field weakening",
        "Speed (rpm)",
        &x,
        &[Panel {
            title: "Steady torque",
            y_label: "N m",
            series: vec![
                Series {
                    label: "envelope (machine equations)",
                    values: &env,
                    style: LineStyle::Solid(Color::Gray),
                },
                Series {
                    label: "envelope at 92 % voltage",
                    values: &env_trim,
                    style: LineStyle::Solid(Color::Orange),
                },
                Series {
                    label: "envelope at six-step",
                    values: &env_six,
                    style: LineStyle::Solid(Color::Green),
                },
                Series {
                    label: "held, linear SVPWM",
                    values: &held,
                    style: LineStyle::Solid(Color::Blue),
                },
                Series {
                    label: "held, overmodulation",
                    values: &held_om,
                    style: LineStyle::Solid(Color::Red),
                },
            ],
        }],
        1600,
        600,
    )
}
