//! The linearised closed loop (issue 13, item 4): the eigenvalues of the drive's
//! sensorless speed control around an operating point, with the controller's model and the
//! inverter compensation different from the machine.
//!
//! ## The model
//!
//! Continuous time, the real machine in the inverse-Gamma form (design notes, section 2)
//! written in the controller's frame (the angle of the flux model, eq. 13, turning at w_s),
//! with the currents regulated (the current loops, 1000 rad/s, are taken as ideal: i_sd is
//! its reference, i_sq the speed PI's output). Nine states:
//!
//! | state | meaning | equation |
//! |---|---|---|
//! | lambda_d, lambda_q | the real rotor flux in the controller's frame | d lambda/dt = R_R i - lambda/tau_r - j (w_s - p Omega) lambda |
//! | Omega | the rotor speed | J dOmega/dt = 1.5 p (lambda_d i_sq - lambda_q i_sd) - B Omega - T_L |
//! | lambda_hat | the flux model (eq. 13) | dlambda_hat/dt = (L_M^ i_sd - lambda_hat)/tau_r^ |
//! | i_d_hat | the eq. (20) current model of the Rs estimator | sigma Ls^ di/dt = v_sd* - Rs^ i_d_hat + sigma Ls^ w_s i_sq |
//! | i_q_hat, Omega_hat, T_hat | the reduced-order observer (eq. 12) | as `acim::observer`, its gains from the drive's design |
//! | I | the speed PI's integral | dI/dt = K_i (Omega* - Omega_hat) |
//!
//! The frame turns at w_s = p Omega_hat + R_R^ i_sq / lambda_hat + dw (eq. 8 with the
//! orientation correction dw of `acim::orientation`, its fade and load scheduling), and the
//! voltage the controller sees is the machine's, v = Rs i + j w_s L_sigma i + d lambda/dt +
//! j w_s lambda, plus the inverter error the compensation leaves: a leg error dV gives the
//! fundamental (4/pi) dV along the current. The Rs estimate is held at the controller's
//! value (the standstill mode's law is gated off above 1.5 Hz; the map is of the fixed
//! errors). Every coefficient of the controller's side comes from `acim::Drive::coeffs`
//! (the per-step coefficients over Ts), so the model is the drive's, not a copy of its
//! design rules.
//!
//! The equilibrium is found by Newton's method on f(x) = 0 from the ideal operating point
//! (it exists and is found for unstable points too); the Jacobian by central differences;
//! its eigenvalues by nalgebra's Schur decomposition.
//!
//! What it leaves out, so what the measured growth rates (`crate::stability`) still check:
//! the sampling, the 1.5-period voltage delay and the discretisation (at most 0.04 Ts p of
//! the observer's poles), the current loops, saturation of any limit, the PWM ripple, the
//! sensors, and the inverter error's harmonics and its shape near a current's zero
//! crossing.

use crate::scenario::{Scenario, ScenarioError};
use nalgebra::{DMatrix, DVector};

/// Number of states.
pub const STATES: usize = 9;

/// One operating point's linearisation.
#[derive(Clone, Debug)]
pub struct Linearisation {
    /// The equilibrium state (see the module documentation for the order).
    pub state: [f64; STATES],
    /// The stator frequency there, rad/s electrical.
    pub stator_frequency: f64,
    /// Eigenvalues (re, im), 1/s, sorted by decreasing real part.
    pub eigenvalues: Vec<(f64, f64)>,
}

impl Linearisation {
    /// The largest real part, 1/s (> 0: unstable).
    pub fn max_real(&self) -> f64 {
        self.eigenvalues.first().map_or(f64::NAN, |&(re, _)| re)
    }
}

/// The model of a scenario's machine, controller and inverter at one operating point.
#[derive(Clone, Debug)]
pub struct Model {
    // the machine
    rs: f64,
    rr: f64,
    lm: f64,
    ls: f64,
    j: f64,
    b: f64,
    p: f64,
    // the controller, per second (coefficients over Ts)
    i_sd: f64,
    rs_hat: f64,
    rr_hat: f64,
    blend: f64,
    lm_hat: f64,
    slip_gain: f64,
    min_flux: f64,
    rs_model: f64,
    obs_a: f64,
    obs_inv_l: f64,
    obs_p_inv_l: f64,
    obs_torque: f64,
    obs_inv_j: f64,
    obs_friction: f64,
    obs_g2: f64,
    obs_g3: f64,
    kp: f64,
    ki: f64,
    k_per_flux: f64,
    load_factor: f64,
    fade_start: f64,
    inv_fade_width: f64,
    correction_limit: f64,
    /// The leg error the compensation leaves, V (its fundamental is 4/pi of it).
    inverter_error: f64,
    // the operating point
    speed_ref: f64,
    load: f64,
}

impl Model {
    /// The model of `sc` (its machine, controller model, drive settings and inverter) at
    /// speed `speed_rpm` with the active load `load_nm` (N m, positive opposing positive
    /// rotation).
    pub fn new(sc: &Scenario, speed_rpm: f32, load_nm: f32) -> Result<Self, ScenarioError> {
        let v = sc.validate()?;
        let drive = acim::Drive::new(v.drive).map_err(|e| ScenarioError {
            field: "drive".into(),
            allowed: format!("a valid drive configuration ({e:?})"),
        })?;
        let c = drive.coeffs();
        let ts = f64::from(v.drive.control_period);
        let m = v.plant;
        let inv = &sc.inverter;
        let bus = f64::from(sc.dc_link.source_v);
        // the leg error: dead time over the period times the bus, plus the device drop;
        // less what the drive compensates
        let leg = |dead: f32, drop: f32| f64::from(dead) / ts * bus + f64::from(drop);
        let inverter_error =
            leg(inv.dead_time_s, inv.device_drop_v) - leg(v.drive.dead_time, v.drive.device_drop);
        let o = &c.observer;
        Ok(Self {
            rs: f64::from(m.stator_resistance()),
            rr: f64::from(m.referred_rotor_resistance()),
            lm: f64::from(m.magnetizing_inductance()),
            ls: f64::from(m.transient_inductance()),
            j: f64::from(m.inertia()),
            b: f64::from(m.viscous_friction()),
            p: f64::from(m.pole_pairs_f32()),
            i_sd: f64::from(c.i_sd_ref),
            rs_hat: f64::from(v.drive.rs_initial),
            rr_hat: f64::from(c.referred_rotor_resistance),
            blend: f64::from(c.flux.blend) / ts,
            lm_hat: f64::from(c.flux.magnetizing_inductance),
            slip_gain: f64::from(c.flux.slip_gain),
            min_flux: f64::from(c.flux.min_flux),
            rs_model: f64::from(c.rs.ts_over_transient_inductance) / ts,
            obs_a: f64::from(o.ts_a) / ts,
            obs_inv_l: f64::from(o.ts_inv_l) / ts,
            obs_p_inv_l: f64::from(o.ts_p_inv_l) / ts,
            obs_torque: f64::from(o.ts_torque_per_inertia) / ts,
            obs_inv_j: f64::from(o.ts_inv_inertia) / ts,
            obs_friction: f64::from(o.ts_friction_rate) / ts,
            obs_g2: f64::from(o.ts_g2) / ts,
            obs_g3: f64::from(o.ts_g3) / ts,
            kp: f64::from(c.pi_speed.kp),
            ki: f64::from(c.pi_speed.ki_ts) / ts,
            k_per_flux: f64::from(c.orientation.gain_per_flux),
            load_factor: f64::from(c.orientation.load_factor_per_current),
            fade_start: f64::from(c.orientation.fade_start),
            inv_fade_width: f64::from(c.orientation.inv_fade_width),
            correction_limit: f64::from(c.orientation.limit),
            inverter_error,
            speed_ref: f64::from(speed_rpm) * f64::from(acim::math::RPM_TO_RAD_S),
            load: f64::from(load_nm),
        })
    }

    /// The stator frequency and the torque current of state `x`.
    fn frame(&self, x: &[f64; STATES]) -> (f64, f64) {
        let [_, _, _, lh, id_hat, _, wh, _, integral] = *x;
        let i_sq = self.kp * (self.speed_ref - wh) + integral;
        let inv_flux = 1.0 / lh.max(self.min_flux);
        let slip = self.slip_gain * i_sq * inv_flux;
        let r_d = self.rs_hat * (id_hat - self.i_sd);
        let load_scale = (self.load_factor * i_sq.abs()).max(1.0);
        // the correction's fade and sign follow w_s itself (the drive uses last step's):
        // a few fixed-point passes (the correction is small against w_s)
        let mut ws = self.p * wh + slip;
        for _ in 0..8 {
            let fade = (self.inv_fade_width * (ws.abs() - self.fade_start)).clamp(0.0, 1.0);
            let signed = if ws >= 0.0 { -r_d } else { r_d };
            let dw = (self.k_per_flux * fade * signed * load_scale)
                .clamp(-self.correction_limit, self.correction_limit);
            ws = self.p * wh + slip + dw;
        }
        (ws, i_sq)
    }

    /// dx/dt.
    pub fn derivative(&self, x: &[f64; STATES]) -> [f64; STATES] {
        let [ld, lq, w, lh, id_hat, iq_hat, wh, th, _] = *x;
        let (ws, i_sq) = self.frame(x);
        let i_sd = self.i_sd;
        let slip_true = ws - self.p * w;
        let dld = self.rr * i_sd - self.rr / self.lm * ld + slip_true * lq;
        let dlq = self.rr * i_sq - self.rr / self.lm * lq - slip_true * ld;
        // the voltage the current loops apply: the machine's plus the inverter's error
        let mag = (i_sd * i_sd + i_sq * i_sq).sqrt().max(1e-9);
        let u = 4.0 / core::f64::consts::PI * self.inverter_error / mag;
        let v_d = self.rs * i_sd - ws * self.ls * i_sq + dld - ws * lq + u * i_sd;
        let v_q = self.rs * i_sq + ws * self.ls * i_sd + dlq + ws * ld + u * i_sq;
        let dw = (1.5 * self.p * (ld * i_sq - lq * i_sd) - self.b * w - self.load) / self.j;
        let dlh = self.blend * (self.lm_hat * i_sd - lh);
        let did = self.rs_model * (v_d - self.rs_hat * id_hat) + ws * i_sq;
        let inv_flux = 1.0 / lh.max(self.min_flux);
        let e = iq_hat - i_sq;
        let rseq = self.rs_hat + self.rr_hat;
        let diq = self.obs_a * e + self.obs_inv_l * (v_q - rseq * i_sq)
            - self.obs_p_inv_l * lh * wh
            - ws * i_sd;
        let dwh = self.obs_torque * lh * i_sq - self.obs_inv_j * th - self.obs_friction * wh
            + self.obs_g2 * e * inv_flux;
        let dth = self.obs_g3 * e * inv_flux;
        let di = self.ki * (self.speed_ref - wh);
        [dld, dlq, dw, dlh, did, diq, dwh, dth, di]
    }

    /// The Jacobian of [`Model::derivative`] at `x` (central differences).
    pub fn jacobian(&self, x: &[f64; STATES]) -> DMatrix<f64> {
        let mut jm = DMatrix::zeros(STATES, STATES);
        for k in 0..STATES {
            let h = 1e-6 * x[k].abs().max(1e-3);
            let (mut a, mut b) = (*x, *x);
            a[k] += h;
            b[k] -= h;
            let (fa, fb) = (self.derivative(&a), self.derivative(&b));
            for r in 0..STATES {
                jm[(r, k)] = (fa[r] - fb[r]) / (2.0 * h);
            }
        }
        jm
    }

    /// The ideal operating point: the flux at its reference, the speeds at the reference,
    /// the torque current that carries the load.
    fn guess(&self) -> [f64; STATES] {
        let lambda = self.lm_hat * self.i_sd;
        let i_sq = (self.load + self.b * self.speed_ref) / (1.5 * self.p * lambda);
        let load_hat =
            (self.obs_torque * lambda * i_sq - self.obs_friction * self.speed_ref) / self.obs_inv_j;
        [
            lambda,
            0.0,
            self.speed_ref,
            lambda,
            self.i_sd,
            i_sq,
            self.speed_ref,
            load_hat,
            i_sq,
        ]
    }

    /// The equilibrium near the ideal operating point and the eigenvalues there; `None`
    /// when Newton's method does not converge (no equilibrium near it).
    pub fn linearise(&self) -> Option<Linearisation> {
        let mut x = self.guess();
        let mut converged = false;
        for _ in 0..60 {
            let f = self.derivative(&x);
            let norm: f64 = f.iter().map(|v| v * v).sum::<f64>().sqrt();
            if !norm.is_finite() {
                return None;
            }
            if norm < 1e-9 {
                converged = true;
                break;
            }
            let jm = self.jacobian(&x);
            let step = jm.lu().solve(&DVector::from_row_slice(&f))?;
            for (xi, s) in x.iter_mut().zip(step.iter()) {
                *xi -= s;
            }
        }
        if !converged {
            return None;
        }
        let mut eigenvalues: Vec<(f64, f64)> = self
            .jacobian(&x)
            .complex_eigenvalues()
            .iter()
            .map(|z| (z.re, z.im))
            .collect();
        eigenvalues.sort_by(|a, b| b.0.total_cmp(&a.0).then(b.1.total_cmp(&a.1)));
        let (ws, _) = self.frame(&x);
        Some(Linearisation {
            state: x,
            stator_frequency: ws,
            eigenvalues,
        })
    }
}

/// The linearisation of `sc` at `speed_rpm` with the active load `load_nm`.
pub fn linearise(
    sc: &Scenario,
    speed_rpm: f32,
    load_nm: f32,
) -> Result<Option<Linearisation>, ScenarioError> {
    Ok(Model::new(sc, speed_rpm, load_nm)?.linearise())
}

/// The base of the map: [`crate::stability::ideal_scenario`] (the measured map's
/// conventions) with the Rs estimate held at the controller's value.
pub fn base_scenario() -> Scenario {
    let mut sc = crate::stability::ideal_scenario("linear");
    sc.drive.rs_estimation = false;
    sc
}

fn cell(l: &Option<Linearisation>) -> (String, Option<bool>, f64) {
    match l {
        None => ("no equilibrium".into(), None, f64::NAN),
        Some(l) => {
            let (re, im) = l.eigenvalues[0];
            let text = if im.abs() > 1e-6 {
                format!("{re:.2} ±{:.1}j", im.abs())
            } else {
                format!("{re:.2}")
            };
            (
                text,
                Some(re > 0.0),
                l.stator_frequency / core::f64::consts::TAU,
            )
        }
    }
}

/// The eigenvalue map of issue 13 item 4 as Markdown: for each error of
/// [`crate::stability::robust_errors`], the largest real part of the linearised closed
/// loop's eigenvalues over [`crate::stability::ROBUST_SPEEDS_RPM`] x
/// [`crate::stability::ROBUST_LOADS_NM`], with a summary. Also returns the number of
/// unstable points with |f_s| >= 1 Hz.
pub fn map_markdown() -> Result<(String, usize), ScenarioError> {
    use crate::stability::{robust_errors, ROBUST_LOADS_NM, ROBUST_SPEEDS_RPM};
    let mut md = String::from(
        "<!-- generated by `cargo run --release -p acim-sim -- linear-stability`; do not edit -->\n\n\
         Eigenvalues of the linearised closed loop (`acim_sim::linear`: the machine in the \
         controller's frame with regulated currents, the flux model, the eq. (20) current \
         model, the reduced-order observer and the speed PI, every controller coefficient \
         from the drive's design; docs/robustness.md derives it). Each cell: the eigenvalue \
         with the largest real part, 1/s (`±...j`: a complex pair, its imaginary part in \
         rad/s); positive is unstable. Rows: speed; columns: active load torque (positive \
         motoring, negative regenerating). `*`: the point's stator frequency (at the \
         equilibrium, with the error) is below 1 Hz. Paper machine, drive defaults \
         (orientation gain 2, load-scheduled), zero friction, the Rs estimate held at the \
         controller's value.\n\n",
    );
    let header = crate::stability::map_header;
    let mut summary = String::from(
        "## Summary\n\n| error | unstable with \\|f_s\\| >= 1 Hz | unstable below 1 Hz | no equilibrium | least damped with \\|f_s\\| >= 1 Hz (1/s) |\n|---|---|---|---|---|\n",
    );
    let mut tables = String::new();
    let mut unstable_observable = 0;
    for (name, err) in robust_errors() {
        let mut sc = base_scenario();
        err(&mut sc);
        tables.push_str(&format!("## {name}\n\n"));
        header(&mut tables);
        let (mut bad_obs, mut bad_low, mut none) = (0, 0, 0);
        let mut worst = f64::NEG_INFINITY;
        for s in ROBUST_SPEEDS_RPM {
            tables.push_str(&format!("| {s} |"));
            for l in ROBUST_LOADS_NM {
                let lin = linearise(&sc, s, l)?;
                let (text, unstable, fs) = cell(&lin);
                let low = fs.abs() < 1.0;
                match unstable {
                    None => none += 1,
                    Some(true) if low => bad_low += 1,
                    Some(true) => bad_obs += 1,
                    Some(false) => {}
                }
                if let (Some(l), false) = (&lin, low) {
                    worst = worst.max(l.max_real());
                }
                tables.push_str(&format!(" {text}{} |", if low { "*" } else { "" }));
            }
            tables.push('\n');
        }
        tables.push('\n');
        unstable_observable += bad_obs;
        summary.push_str(&format!(
            "| {name} | {bad_obs} | {bad_low} | {none} | {worst:.2} |\n"
        ));
    }
    md.push_str(&summary);
    md.push('\n');
    md.push_str(&tables);
    Ok((md, unstable_observable))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn point(k: f32, rpm: f32, load: f32) -> Linearisation {
        let mut s = base_scenario();
        s.drive.orientation_gain = k;
        linearise(&s, rpm, load).unwrap().unwrap()
    }

    /// The paper's scheme (k = 0) regenerating at 250 rpm and -1.5 N m: the orientation
    /// mode's root of docs/orientation-stability.md, (-1/tau_r + sqrt(1/tau_r^2 - 4 w_s
    /// w_slip))/2 = +11/s, is the full model's only unstable eigenvalue (real).
    #[test]
    fn the_paper_scheme_regenerating_has_the_orientation_root() {
        let l = point(0.0, 250.0, -1.5);
        let (re, im) = l.eigenvalues[0];
        assert!((re - 11.0).abs() < 1.0 && im == 0.0, "{:?}", l.eigenvalues);
        assert!(l.eigenvalues[1].0 < 0.0);
        let theory = crate::stability::theory(250.0, -1.5, 0.0);
        assert!((re - f64::from(theory)).abs() < 1.0, "{re} vs {theory}");
        // and the closed loop, sampled, with the plant model, grows at that rate
        let measured = crate::stability::measure(250.0, -1.5, 0.0).unwrap();
        let g = f64::from(measured.growth_rate);
        assert!(
            (g - re).abs() < 0.25 * re,
            "measured {g}/s, linearised {re}/s"
        );
    }

    /// With the correction the same point is stable, and motoring stays stable.
    #[test]
    fn the_correction_stabilises_regeneration() {
        assert!(point(2.0, 250.0, -1.5).max_real() < -5.0);
        assert!(point(2.0, 250.0, 1.5).max_real() < -5.0);
        assert!(point(0.0, 250.0, 1.5).max_real() < -5.0);
    }

    /// With the drive's defaults the linearisation and the measured growth rate (sampled
    /// loop, plant model, `stability::measure`, without the regeneration limit) agree in
    /// sign and within 1.5/s at points either side of the stability boundary in
    /// regeneration: 120 rpm at -4.5 N m (f_s just below 1 Hz, unstable) and 250 / 500 rpm
    /// (stable).
    #[test]
    fn agrees_with_the_measured_growth_rates() {
        let k = acim::DriveConfig::paper_defaults().orientation_gain;
        for (rpm, load) in [(120.0, -4.5), (250.0, -3.0), (500.0, -4.5)] {
            let lin = point(k, rpm, load).max_real();
            let measured = f64::from(crate::stability::measure(rpm, load, k).unwrap().growth_rate);
            assert!(
                (lin > 0.0) == (measured > 0.0) && (lin - measured).abs() < 1.5,
                "{rpm} rpm {load} N m: linearised {lin}/s, measured {measured}/s"
            );
        }
    }

    /// The equilibrium is the operating point: the true speed at the reference, the
    /// observer's load estimate at the load.
    #[test]
    fn the_equilibrium_is_the_operating_point() {
        let l = point(2.0, 500.0, 3.0);
        let rpm = l.state[2] * f64::from(acim::math::RAD_S_TO_RPM);
        assert!((rpm - 500.0).abs() < 0.5, "{rpm}");
        assert!((l.state[7] - 3.0).abs() < 0.05, "{:?}", l.state);
    }
}
