//! Stability map of the orientation mode over the torque-speed plane, measured on the
//! project's own closed loop (drive + plant), before (paper's scheme, orientation gain 0)
//! and after (the orientation correction).
//!
//! Method: at each operating point (speed, active load torque) the loop is brought to a
//! steady state with the correction on (so that unstable points can be reached at all),
//! the gain under test is set, and the plant's rotor flux is rotated by a small angle: an
//! orientation-error step. The growth rate sigma (1/s) of the orientation error's
//! deviation from its equilibrium is fitted from its rms over two windows,
//! sigma = ln(rms2/rms1)/dt (positive: unstable). Ideal sensors and inverter, zero
//! friction, so the only torque is the load's.
//!
//! Theory beside it (module docs of `acim::drive`): with x = lambda_d - lambda_hat,
//! y = lambda_q the orientation mode is s^2 + s (1/tau_r + k |w_s|) + k |w_s|/tau_r +
//! w_s w_slip = 0; k = 0 is the paper's scheme, unstable when w_s w_slip < 0.

use crate::scenario::{LoadKind, LoadPoint, Scenario, ScenarioError, SpeedPoint};
use acim::math::RPM_TO_RAD_S;
use acim::{Drive, DriveInputs, DriveState};
use acim_plant::{LoadTorque, PwmPreload};
use serde::Serialize;

/// One measured operating point.
#[derive(Clone, Debug, Serialize)]
pub struct GrowthPoint {
    /// Speed, rpm.
    pub speed_rpm: f32,
    /// Active load torque, N m (positive opposes forward rotation).
    pub load_nm: f32,
    /// Orientation-correction gain.
    pub gain: f32,
    /// Measured growth rate of the orientation error, 1/s.
    pub growth_rate: f32,
    /// Largest real part of the second-order model's roots, 1/s.
    pub theory: f32,
    /// Whether the drive faulted or the error passed 30 degrees.
    pub lost: bool,
}

/// Largest real part of s^2 + a s + b.
fn max_real_root(a: f32, b: f32) -> f32 {
    let d = a * a - 4.0 * b;
    if d >= 0.0 {
        (-a + d.sqrt()) / 2.0
    } else {
        -a / 2.0
    }
}

/// Theory for the paper's machine at `speed_rpm`, `load_nm`, gain `k`.
pub fn theory(speed_rpm: f32, load_nm: f32, k: f32) -> f32 {
    let m = acim::MachineParams::paper_table1();
    let tau_r = m.rotor_time_constant();
    let lambda = m.rotor_flux_for(acim::params::DEFAULT_FLUX_CURRENT);
    let i_sq = load_nm / m.torque_constant(lambda);
    let w_slip = m.referred_rotor_resistance() * i_sq / lambda;
    let w_s = m.pole_pairs_f32() * speed_rpm * RPM_TO_RAD_S + w_slip;
    let a = 1.0 / tau_r + k * w_s.abs();
    let b = k * w_s.abs() / tau_r + w_s * w_slip;
    max_real_root(a, b)
}

fn rms(x: &[f32]) -> f32 {
    if x.is_empty() {
        return 0.0;
    }
    (x.iter().map(|v| v * v).sum::<f32>() / x.len() as f32).sqrt()
}

/// The rms of the deviation `dev` (one sample per step of `ts` s after the kick) between
/// `a` and `b` s, clipped to what was recorded.
fn window_rms(dev: &[f32], ts: f32, a: f32, b: f32) -> f32 {
    let (i, j) = ((a / ts) as usize, (b / ts) as usize);
    rms(&dev[i.min(dev.len())..j.min(dev.len())])
}

/// Measures the growth rate at one operating point with gain `k`.
pub fn measure(speed_rpm: f32, load_nm: f32, k: f32) -> Result<GrowthPoint, ScenarioError> {
    measure_with(speed_rpm, load_nm, k, &|_| {})
}

/// The paper machine and the drive's defaults with what the stability maps leave out:
/// zero friction, no inverter error (none in the plant, none compensated), and the Rs
/// estimate held at the controller's value (a map switches the estimator on itself). The
/// sensors are ideal, so the running offset tracker has nothing to
/// track: it is off, as in the linearisation, which does not model it (a perturbation's
/// transient would otherwise reach it as a DC voltage).
pub fn ideal_scenario(name: &str) -> Scenario {
    let mut sc = Scenario {
        name: name.into(),
        ..Scenario::default()
    };
    sc.drive.estimation.rs_estimation = false;
    sc.drive.trackers.offset_tracking = false;
    sc.drive.trackers.inverter_tracking = false;
    sc.plant.friction_nms = 0.0;
    sc.controller.friction_nms = 0.0;
    sc.inverter.dead_time_s = 0.0;
    sc.inverter.device_drop_v = 0.0;
    sc.drive.inverter.dead_time_comp_s = 0.0;
    sc.drive.inverter.device_drop_comp_v = 0.0;
    sc
}

/// The header of a map over [`ROBUST_LOADS_NM`] (columns) by speed (rows).
pub fn map_header(md: &mut String) {
    md.push_str("| speed (rpm) |");
    for l in ROBUST_LOADS_NM {
        md.push_str(&format!(" {l} N m |"));
    }
    md.push_str("\n|---|");
    for _ in ROBUST_LOADS_NM {
        md.push_str("---|");
    }
    md.push('\n');
}

/// [`measure`] with the scenario changed by `setup` before it is built (parameter errors,
/// inverter, Rs estimation mode).
pub fn measure_with(
    speed_rpm: f32,
    load_nm: f32,
    k: f32,
    setup: &dyn Fn(&mut Scenario),
) -> Result<GrowthPoint, ScenarioError> {
    let (dev, lost, ts) = kicked(speed_rpm, load_nm, k, setup, 2.0)?;
    let w = |a: f32, b: f32| window_rms(&dev, ts, a, b);
    let growth_rate = if lost || dev.len() < (0.5 / ts) as usize {
        // diverged: from the first window to the end of what was recorded
        let t_end = dev.len() as f32 * ts;
        let early = w(0.01, 0.06);
        let late = w((t_end - 0.05).max(0.06), t_end);
        if early > 0.0 && t_end > 0.1 {
            (late / early).ln() / (t_end - 0.05 - 0.035)
        } else {
            f32::INFINITY
        }
    } else {
        let (r1, r2) = (w(0.02, 0.12), w(0.38, 0.48));
        if r1 > 0.0 && r2 > 0.0 {
            (r2 / r1).ln() / 0.36
        } else {
            f32::NEG_INFINITY
        }
    };
    Ok(GrowthPoint {
        speed_rpm,
        load_nm,
        gain: k,
        growth_rate,
        theory: theory(speed_rpm, load_nm, k),
        lost,
    })
}

/// The growth rate of an unstable point while its orientation error is still small, 1/s:
/// a 0.1 degree kick, and the rms of the deviation 0.10-0.15 s and 0.20-0.25 s after it
/// (the faster modes the kick excites have mostly died out by then, and an error growing
/// at 11.5/s is still below 2 degrees at 0.25 s). [`measure`]'s 2 degree kick and fit to the end
/// of the record (up to 30 degrees, where a diverging point is stopped) include the
/// error's nonlinear growth: at the paper scheme's 250 rpm / -1.5 N m it gives +13.4/s
/// where this gives +11.5/s. For comparing with the linearisation (`crate::linear`).
/// `setup` changes the scenario before it is built, as in [`measure_with`].
pub fn linear_growth_rate(
    speed_rpm: f32,
    load_nm: f32,
    k: f32,
    setup: &dyn Fn(&mut Scenario),
) -> Result<f32, ScenarioError> {
    let (dev, lost, ts) = kicked(speed_rpm, load_nm, k, setup, 0.1)?;
    let w = |a: f32, b: f32| window_rms(&dev, ts, a, b);
    let (r1, r2) = (w(0.10, 0.15), w(0.20, 0.25));
    // a diverging point is stopped at 30 degrees, after the windows
    let recorded = dev.len() as f32 * ts >= 0.25;
    Ok(if (lost && !recorded) || r1 <= 0.0 || r2 <= 0.0 {
        f32::NAN
    } else {
        (r2 / r1).ln() / 0.1
    })
}

/// The orientation error's deviation (degrees) from 0.1 s before a kick of `kick_deg`
/// degrees to the plant's rotor flux, recorded from the kick on; whether the drive lost
/// the orientation (beyond 30 degrees, or a fault); the control period, s.
fn kicked(
    speed_rpm: f32,
    load_nm: f32,
    k: f32,
    setup: &dyn Fn(&mut Scenario),
    kick_deg: f32,
) -> Result<(Vec<f32>, bool, f32), ScenarioError> {
    let mut sc = ideal_scenario("stability");
    sc.duration_s = 10.0;
    sc.sensors.adc_bits = 16;
    sc.drive.loops.speed_ramp_rpm_s = 2000.0;
    // the map measures the estimators at the labelled operating point: without the
    // regeneration limit (on by default), which would move a regenerating point near
    // the unobservable line to a higher speed
    sc.drive.loops.regen_min_frequency_hz = 0.0;
    sc.speed_profile = vec![SpeedPoint {
        t_s: 0.0,
        rpm: speed_rpm,
    }];
    sc.load_profile = vec![LoadPoint {
        t_s: 0.0,
        kind: LoadKind::Active,
        torque_nm: load_nm,
    }];
    setup(&mut sc);
    let v = sc.validate()?;
    let mut plant = crate::sim::build_plant(&sc, &v);
    let mut drive = Drive::new(v.drive).map_err(|e| ScenarioError {
        field: "drive".into(),
        allowed: format!("{e}"),
    })?;
    let ts = sc.drive.loops.control_period_s;
    crate::sim::power_up(&mut plant, &mut drive, &crate::sim::build_dc_link(&sc), ts);
    let _ = drive.set_speed_target(speed_rpm * RPM_TO_RAD_S);
    let _ = drive.start();
    let mut pwm = PwmPreload::new();
    let settle_s = 2.0;
    let pre_s = 0.1;
    let obs_s = 0.6;
    let n = ((settle_s + pre_s + obs_s) / ts) as usize;
    let mut phi = Vec::with_capacity(n);
    let mut lost = false;
    let mut loaded = false;
    for step in 0..n {
        let t = step as f32 * ts;
        // the load comes on once the speed is reached (a free rotor would run away while
        // magnetizing)
        if !loaded && drive.state() == DriveState::Running && t > 0.3 + speed_rpm.abs() / 2000.0 {
            loaded = true;
        }
        if (t - settle_s).abs() < 0.5 * ts {
            let _ = drive.set_orientation_gain(k);
        }
        if (t - (settle_s + pre_s)).abs() < 0.5 * ts {
            // rotate the rotor flux by the kick: an orientation-error step
            let mut st = plant.machine().state();
            let (s, c) = (kick_deg.to_radians().sin(), kick_deg.to_radians().cos());
            let (a, b) = (st.psi_alpha, st.psi_beta);
            st.psi_alpha = c * a - s * b;
            st.psi_beta = s * a + c * b;
            plant.machine_mut().set_state(st);
        }
        let meas = plant.sample();
        let out = drive.step(&DriveInputs {
            phase_currents: meas.phase_currents,
            dc_bus: meas.dc_bus,
        });
        if drive.state() == DriveState::Fault {
            lost = true;
            break;
        }
        let lam = plant.machine().lambda_r();
        let err = crate::sim::wrap_deg(drive.telemetry().angle - lam.beta.atan2(lam.alpha));
        if t >= settle_s {
            phi.push(err);
            if t > settle_s + pre_s && err.abs() > 30.0 {
                lost = true;
                break;
            }
        }
        let applied = pwm.advance(out);
        let load = if loaded {
            LoadTorque::Active { torque: load_nm }
        } else {
            LoadTorque::None
        };
        plant.run_pwm_period(applied, load);
        // the plant's hardware comparator opened the switches: the drive is tripped
        // (HardwareBreak) as in the simulator's loop, and the case counts as lost
        if plant.comparator_trip().is_some() {
            drive.trip(acim::FaultReason::HardwareBreak);
            lost = true;
            break;
        }
    }
    // deviation from the equilibrium just before the step
    let pre = (pre_s / ts) as usize;
    let eq = if phi.len() > pre {
        phi[pre - (0.02 / ts) as usize..pre].iter().sum::<f32>() / (0.02 / ts)
    } else {
        0.0
    };
    let dev: Vec<f32> = phi.iter().skip(pre).map(|p| p - eq).collect();
    Ok((dev, lost, ts))
}

/// Speeds of the map, rpm.
pub const SPEEDS_RPM: [f32; 12] = [
    -750.0, -500.0, -250.0, -120.0, -60.0, -30.0, 30.0, 60.0, 120.0, 250.0, 500.0, 750.0,
];
/// Active load torques of the map, N m.
pub const LOADS_NM: [f32; 5] = [-3.0, -1.5, 0.0, 1.5, 3.0];

/// The whole map for gains `gains`.
pub fn map(gains: &[f32]) -> Result<Vec<GrowthPoint>, ScenarioError> {
    let mut out = Vec::new();
    for &k in gains {
        for &l in &LOADS_NM {
            for &s in &SPEEDS_RPM {
                out.push(measure(s, l, k)?);
            }
        }
    }
    Ok(out)
}

/// Speeds of the robust-stability map, rpm (forward; the map is symmetric under reversal).
pub const ROBUST_SPEEDS_RPM: [f32; 6] = [15.0, 30.0, 60.0, 120.0, 250.0, 500.0];
/// Active load torques of the robust-stability map, N m (positive: motoring, negative:
/// regenerating at forward speed).
pub const ROBUST_LOADS_NM: [f32; 7] = [-4.5, -3.0, -1.5, 0.0, 1.5, 3.0, 4.5];

/// A change applied to a scenario before it is built.
pub type ScenarioChange = Box<dyn Fn(&mut Scenario)>;

/// The parameter and inverter errors of the robust-stability map: a name and the change to the
/// scenario (the controller's model or the compensation differs from the plant).
pub fn robust_errors() -> Vec<(&'static str, ScenarioChange)> {
    fn with_inverter(s: &mut Scenario, comp: f32) {
        s.inverter.dead_time_s = 1.5e-6;
        s.inverter.device_drop_v = 1.0;
        s.drive.inverter.dead_time_comp_s = comp * 1.5e-6;
        s.drive.inverter.device_drop_comp_v = comp;
    }
    vec![
        ("nominal", Box::new(|_: &mut Scenario| {})),
        (
            "controller Rs +20 %",
            Box::new(|s: &mut Scenario| s.controller.rs_ohm *= 1.2),
        ),
        (
            "controller Rs -20 %",
            Box::new(|s: &mut Scenario| s.controller.rs_ohm *= 0.8),
        ),
        (
            "controller Rr +30 %",
            Box::new(|s: &mut Scenario| s.controller.rr_ohm *= 1.3),
        ),
        (
            "controller Rr -30 %",
            Box::new(|s: &mut Scenario| s.controller.rr_ohm *= 0.7),
        ),
        (
            "inverter error +30 % (compensated 70 %)",
            Box::new(|s: &mut Scenario| with_inverter(s, 0.7)),
        ),
        (
            "inverter error -30 % (compensated 130 %)",
            Box::new(|s: &mut Scenario| with_inverter(s, 1.3)),
        ),
    ]
}

/// The stator frequency of an operating point of the paper machine, Hz (ideal model,
/// zero friction as in [`measure`]).
pub fn stator_frequency_hz(speed_rpm: f32, load_nm: f32) -> f32 {
    let m = acim::MachineParams::paper_table1();
    let lambda = m.rotor_flux_for(acim::params::DEFAULT_FLUX_CURRENT);
    let i_sq = load_nm / m.torque_constant(lambda);
    let w_slip = m.referred_rotor_resistance() * i_sq / lambda;
    (m.pole_pairs_f32() * speed_rpm * RPM_TO_RAD_S + w_slip) / acim::math::TAU
}

/// the orientation gain against its stability bound up to the current
/// limit. In regeneration the orientation mode is stable for k > tau_r |w_slip|
/// (`docs/orientation-stability.md`); with lambda = L_M i_sd* and tau_r = L_M / R_R that is
/// k > |i_sq| / i_sd*, independent of speed. The drive's gain is scheduled with the load,
/// k max(1, c |i_sq|) (`OrientationDesign::load_factor_per_current`, c =
/// `ORIENTATION_GAIN_MARGIN` / (k i_sd*)); the table gives both gains' margin k / (tau_r
/// |w_slip|) from no load to the torque at the current limit (paper machine, defaults).
pub fn gain_margin_markdown() -> String {
    let cfg = acim::DriveConfig::paper_defaults();
    let m = cfg.machine;
    let k = cfg.estimation.orientation_gain;
    let c = acim::design::ORIENTATION_GAIN_MARGIN / (k * cfg.loops.flux_current);
    let lambda = m.rotor_flux_for(cfg.loops.flux_current);
    let kt = 1.5 * m.pole_pairs_f32() * lambda;
    let i_max = (cfg.limits.current_limit * cfg.limits.current_limit
        - cfg.loops.flux_current * cfg.loops.flux_current)
        .sqrt();
    let mut md = format!(
        "## Orientation gain against its stability bound\n\n\
         Regeneration is stable for k > tau_r |w_slip| = |i_sq| / i_sd* (at any speed). The \
         fixed gain k = {k} meets it up to {:.1} N m; the drive schedules the gain with the \
         load, k max(1, {:.3} |i_sq|), which keeps the margin k / (tau_r |w_slip|) at least \
         {} up to the current limit ({:.2} A of torque current, {:.2} N m).\n\n\
         | torque (N m) | i_sq (A) | tau_r \\|w_slip\\| | margin, fixed k = {k} | scheduled k | margin, scheduled |\n\
         |---|---|---|---|---|---|\n",
        k * cfg.loops.flux_current * kt,
        c,
        acim::design::ORIENTATION_GAIN_MARGIN,
        i_max,
        kt * i_max,
    );
    for t in [1.5, 3.0, 4.5, 6.0, 7.5, 9.0] {
        let i = t / kt;
        md.push_str(&margin_row(t, i, k, c, cfg.loops.flux_current));
    }
    md.push_str(&margin_row(kt * i_max, i_max, k, c, cfg.loops.flux_current));
    md.push('\n');
    md
}

fn margin_row(t: f32, i_sq: f32, k: f32, c: f32, i_sd: f32) -> String {
    let bound = i_sq / i_sd;
    let scheduled = k * (c * i_sq).max(1.0);
    format!(
        "| {t:.2} | {i_sq:.2} | {bound:.2} | {:.2} | {scheduled:.2} | {:.2} |\n",
        k / bound,
        scheduled / bound
    )
}

/// The robust-stability map as Markdown: for each error of [`robust_errors`] and each Rs mode
/// (estimator off, as in the paper's scheme with the correction, and the running mode),
/// the measured growth rate of a 2 degree orientation step at every point of
/// [`ROBUST_SPEEDS_RPM`] x [`ROBUST_LOADS_NM`] with the drive's orientation gain.
pub fn robust_map_markdown(progress: &mut dyn FnMut(&str)) -> Result<String, ScenarioError> {
    use crate::scenario::RsMode;
    let k = acim::DriveConfig::paper_defaults()
        .estimation
        .orientation_gain;
    let mut md = String::from(
        "<!-- generated by `cargo run --release -p acim-sim -- robust-stability`; do not edit -->\n\n\
         Measured growth rate (1/s, negative: decays) of the orientation error after a 2 degree \
         step of the plant's rotor flux, closed loop (`acim_sim::stability::measure_with`: ideal \
         sensors, zero friction, active load), with the drive's orientation gain. Rows: speed; \
         columns: load torque (positive motoring, negative regenerating); `lost`: fault or \
         error beyond 30 degrees. The first table gives the stator frequency of each point \
         (ideal model); cells with |f_s| < 1 Hz are marked `*`. These are measured growth rates \
         of one perturbation, not eigenvalues of the linearised loop.\n\n",
    );
    let header = map_header;
    md.push_str(&gain_margin_markdown());
    md.push_str("## Stator frequency (Hz)\n\n");
    header(&mut md);
    for s in ROBUST_SPEEDS_RPM {
        md.push_str(&format!("| {s} |"));
        for l in ROBUST_LOADS_NM {
            md.push_str(&format!(" {:.2} |", stator_frequency_hz(s, l)));
        }
        md.push('\n');
    }
    md.push('\n');
    let mut summary = String::from(
        "## Summary: points with |f_s| >= 1 Hz that grow or are lost\n\n| error | Rs estimation | unstable / lost with \\|f_s\\| >= 1 Hz | unstable / lost below 1 Hz |\n|---|---|---|---|\n",
    );
    let mut tables = String::new();
    for (name, err) in robust_errors() {
        for (mode_name, mode) in [("off", None), ("running", Some(RsMode::Running))] {
            let setup = |sc: &mut Scenario| {
                err(sc);
                if let Some(m) = mode {
                    sc.drive.estimation.rs_estimation = true;
                    sc.drive.estimation.rs_estimation_mode = m;
                }
            };
            tables.push_str(&format!("## {name}, Rs estimation {mode_name}\n\n"));
            header(&mut tables);
            let (mut bad_obs, mut bad_low) = (0, 0);
            for s in ROBUST_SPEEDS_RPM {
                tables.push_str(&format!("| {s} |"));
                for l in ROBUST_LOADS_NM {
                    let p = measure_with(s, l, k, &setup)?;
                    let low = stator_frequency_hz(s, l).abs() < 1.0;
                    let bad = p.lost || p.growth_rate > 0.0;
                    if bad && low {
                        bad_low += 1;
                    } else if bad {
                        bad_obs += 1;
                    }
                    let cell = if p.lost {
                        "lost".to_string()
                    } else {
                        format!("{:.1}", p.growth_rate)
                    };
                    tables.push_str(&format!(" {cell}{} |", if low { "*" } else { "" }));
                }
                tables.push('\n');
            }
            tables.push('\n');
            progress(&format!("{name}, Rs {mode_name}: {bad_obs} / {bad_low}"));
            summary.push_str(&format!(
                "| {name} | {mode_name} | {bad_obs} | {bad_low} |\n"
            ));
        }
    }
    md.push_str(&summary);
    md.push('\n');
    md.push_str(&tables);
    Ok(md)
}
