//! The linearised closed loop: the eigenvalues of the drive's
//! sensorless speed control around an operating point, with the controller's model and the
//! inverter compensation different from the machine.
//!
//! ## The model
//!
//! Continuous time, the real machine in the inverse-Gamma form (design notes, section 2)
//! written in the controller's frame (the angle of the flux model, eq. 13, turning at w_s),
//! with the currents regulated (i_sd at its reference; i_sq follows the speed PI's output,
//! or the regeneration limit's bound where it binds, with the current loops' first-order
//! response). Up to twelve states:
//!
//! | state | meaning | equation |
//! |---|---|---|
//! | lambda_d, lambda_q | the real rotor flux in the controller's frame | d lambda/dt = R_R i - lambda/tau_r - j (w_s - p Omega) lambda |
//! | Omega | the rotor speed | J dOmega/dt = 1.5 p (lambda_d i_sq - lambda_q i_sd) - B Omega - T_L |
//! | lambda_hat | the flux model (eq. 13) | dlambda_hat/dt = (L_M^ i_sd - lambda_hat)/tau_r^ |
//! | i_d_hat | the eq. (20) current model of the Rs estimator | sigma Ls^ di/dt = v_sd* - Rs^ i_d_hat + sigma Ls^ w_s i_sq |
//! | i_q_hat, Omega_hat, T_hat | the reduced-order observer (eq. 12) | as `acim::observer`, its gains from the drive's design |
//! | I | the speed PI's integral | dI/dt = K_i (Omega* - Omega_hat) |
//! | Rs_hat, i_q_hat | the running Rs law and its q-axis current model, where the drive runs it and it adapts | `acim::rs_estimator`, "While running" |
//! | i_sq | the regulated torque current | di_sq/dt = w_c (i_sq* - i_sq), w_c the current loops' bandwidth |
//!
//! The frame turns at w_s = p Omega_hat + R_R^ i_sq / lambda_hat + dw (eq. 8 with the
//! orientation correction dw of `acim::orientation`, its fade and load scheduling), and the
//! voltage the controller sees is the machine's, v = Rs i + L_sigma di/dt + j w_s L_sigma
//! i + d lambda/dt + j w_s lambda (di/dt: the torque current's first-order response; i_sd
//! is held), plus the inverter error the compensation leaves: a leg error dV gives the
//! fundamental (4/pi) dV along the current. With the drive's Rs estimator off (or in the
//! standstill mode, whose law is gated off above 1.5 Hz) the Rs estimate is held at the
//! controller's value; in the running mode (the default) Rs_hat and the law's q-axis
//! model are states where the law's gate is open at the operating point (|w_s| >= 1 Hz,
//! |i_sq| >= 0.2 i_sd*; the steadiness gate is open at any equilibrium) and held where it
//! is shut. Where the regeneration limit binds (a braking point whose torque current is
//! beyond (p |Omega_hat| - w_min) lambda_ref / R_R_hat), the torque-current reference is
//! that bound at the estimated speed and the speed PI's integral is held: the drive holds
//! the reachable speed, which is where the equilibrium is found. (The sampled loop does
//! the same: there the PI sits at the bound and the torque-current reference follows the
//! bound at the estimated speed step by step, a speed feedback of gain p lambda_ref /
//! R_R_hat.) In the drive's far-side mode (`DriveConfig.estimation.far_side_gain`
//! on, the running Rs law, no inverter error left, and a load that puts the target's point
//! at least `far_side_enter` beyond the line w_s = 0) the limit does not bind and, where
//! w_s turns against Omega_hat, the observer's speed and load updates take
//! e - c max(1, a |i_sq|) w e_d instead of e (w the orientation correction's fade). Every
//! coefficient of the controller's side comes from `acim::Drive::coeffs` (the per-step
//! coefficients over Ts), so the model is the drive's, not a copy of its design rules.
//!
//! The equilibrium is found by Newton's method on f(x) = 0 from the ideal operating point
//! (it exists and is found for unstable points too); the Jacobian by central differences;
//! its eigenvalues by nalgebra's Schur decomposition.
//!
//! What it leaves out, so what the measured growth rates (`crate::stability`) still check:
//! the sampling, the 1.5-period voltage delay and the discretisation (at most 0.04 Ts p of
//! the observer's poles), the current loops' cross-coupling and voltage limit, saturation
//! of any limit but the regeneration limit, the PWM ripple, the sensors, and the inverter
//! error's harmonics and its shape near a current's zero crossing.

use crate::scenario::{Scenario, ScenarioError};
use nalgebra::{DMatrix, DVector};

/// Number of states, in the order of the table above (the running law's two are left out
/// of the linearisation where the law does not adapt, the integral where the
/// regeneration limit binds).
pub const STATES: usize = 12;
/// Index of the speed PI's integral.
const INTEGRAL: usize = 8;
/// Index of the Rs estimate.
const RS_HAT: usize = 9;
/// Index of the running law's q-axis current model.
const IQ_MODEL: usize = 10;
/// Index of the regulated torque current.
const IQ: usize = 11;

/// One operating point's linearisation.
#[derive(Clone, Debug)]
pub struct Linearisation {
    /// The equilibrium state (see the module documentation for the order).
    pub state: [f64; STATES],
    /// The stator frequency there, rad/s electrical.
    pub stator_frequency: f64,
    /// Eigenvalues (re, im), 1/s, sorted by decreasing real part.
    pub eigenvalues: Vec<(f64, f64)>,
    /// The regeneration limit holds the torque current there: the equilibrium is at the
    /// reachable speed `state[2]`, not at the reference.
    pub limited: bool,
    /// The running Rs law adapts there (its two states are in the linearisation).
    pub rs_adapting: bool,
}

impl Linearisation {
    /// The largest real part, 1/s (> 0: unstable).
    pub fn max_real(&self) -> f64 {
        self.eigenvalues.first().map_or(f64::NAN, |&(re, _)| re)
    }
}

/// The running Rs law's coefficients (`acim::rs_estimator`, "While running").
#[derive(Clone, Copy, Debug)]
struct RunningLaw {
    /// alpha_r, ohm per V per s.
    alpha: f64,
    /// The gate: |w_s| at least this, rad/s.
    min_frequency: f64,
    /// The gate: |i_sq| at least this, A.
    min_torque_current: f64,
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
    /// The current loops' bandwidth, rad/s: the torque current follows its reference
    /// as a first-order lag (the PI design's closed loop with the decoupling).
    current_bandwidth: f64,
    /// The running Rs law, when the scenario's drive runs it.
    running: Option<RunningLaw>,
    /// The regeneration limit's w_min, rad/s (0: off).
    regen_min_frequency: f64,
    /// lambda_ref / R_R_hat, A per rad/s.
    regen_current_per_frequency: f64,
    /// The leg error the compensation leaves, V (its fundamental is 4/pi of it).
    inverter_error: f64,
    // the operating point
    speed_ref: f64,
    load: f64,
    /// The regeneration limit binds at this point (decided from the ideal operating
    /// point): the torque current is the limit's, the speed PI's integral is held.
    limited: bool,
    /// The far-side gain c of the observer's speed and load updates.
    far_side_gain: f64,
    /// Its load scheduling c(i_sq) = c max(1, a |i_sq|), 1/A.
    far_side_load_factor: f64,
    /// The drive's far-side mode at this point (the term on, the regeneration limit off).
    far_side: bool,
}

impl Model {
    /// The model of `sc` (its machine, controller model, drive settings and inverter) at
    /// speed `speed_rpm` with the active load `load_nm` (N m, positive opposing positive
    /// rotation). With the scenario's Rs estimator on in the running mode the running
    /// law's dynamics are in the model; with its regeneration limit on, a point beyond
    /// the limit is linearised where the drive holds it (the reachable speed).
    pub fn new(sc: &Scenario, speed_rpm: f32, load_nm: f32) -> Result<Self, ScenarioError> {
        let v = sc.validate()?;
        let drive = acim::Drive::new(v.drive).map_err(|e| ScenarioError {
            field: "drive".into(),
            allowed: format!("a valid drive configuration ({e:?})"),
        })?;
        let c = drive.coeffs();
        let ts = f64::from(v.drive.loops.control_period);
        let m = v.plant;
        let inv = &sc.inverter;
        let bus = f64::from(sc.bus_v());
        // the leg error: dead time over the period times the bus, plus the device drop;
        // less what the drive compensates
        let leg = |dead: f32, drop: f32| f64::from(dead) / ts * bus + f64::from(drop);
        let inverter_error = leg(inv.dead_time_s, inv.device_drop_v)
            - leg(v.drive.inverter.dead_time, v.drive.inverter.device_drop);
        let o = &c.observer;
        let run = &c.rs_running;
        let running = (c.rs.adapt && run.enabled).then(|| RunningLaw {
            alpha: f64::from(run.alpha_ts) / ts,
            min_frequency: f64::from(run.min_frequency),
            min_torque_current: f64::from(run.min_torque_current),
        });
        let mut model = Self {
            rs: f64::from(m.stator_resistance()),
            rr: f64::from(m.referred_rotor_resistance()),
            lm: f64::from(m.magnetizing_inductance()),
            ls: f64::from(m.transient_inductance()),
            j: f64::from(m.inertia()),
            b: f64::from(m.viscous_friction()),
            p: f64::from(m.pole_pairs_f32()),
            i_sd: f64::from(c.cascade.i_sd_ref),
            rs_hat: f64::from(v.drive.estimation.rs_initial),
            rr_hat: f64::from(c.model.referred_rotor_resistance),
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
            kp: f64::from(c.speed_loop.pi.kp),
            // the speed loop runs once per slow period
            ki: f64::from(c.speed_loop.pi.ki_ts) / f64::from(drive.design().slow_ts),
            k_per_flux: f64::from(c.orientation.gain_per_flux),
            load_factor: f64::from(c.orientation.load_factor_per_current),
            fade_start: f64::from(c.orientation.fade_start),
            inv_fade_width: f64::from(c.orientation.inv_fade_width),
            correction_limit: f64::from(c.orientation.limit),
            current_bandwidth: f64::from(v.drive.loops.current_bandwidth),
            running,
            regen_min_frequency: f64::from(c.speed_loop.regen_min_frequency),
            regen_current_per_frequency: f64::from(c.speed_loop.regen_current_per_frequency),
            inverter_error,
            speed_ref: f64::from(speed_rpm) * f64::from(acim::math::RPM_TO_RAD_S),
            load: f64::from(load_nm),
            limited: false,
            far_side_gain: f64::from(c.orientation.far_side_gain),
            far_side_load_factor: f64::from(c.orientation.far_side_load_factor),
            far_side: false,
        };
        // the limit binds where the braking torque current the point needs is beyond it
        // (`acim::drive`'s regen_limit, holding a target of the rotor's sign), unless the
        // far-side transit releases it: the braking torque the point needs (the load,
        // which the observer's estimate equals at the equilibrium) puts its stator
        // frequency `far_side_enter` beyond the line (the drive's test). The drive
        // transits only after its inverter test at start identified the voltage error,
        // which leaves none: a row with an inverter error stands for a drive whose test
        // did not run or was rejected, which keeps the limit
        let braking = -model.speed_ref.signum() * model.load;
        let enter = f64::from(c.speed_loop.far_side_enter);
        model.far_side = enter > 0.0
            && model.inverter_error == 0.0
            && braking
                >= f64::from(c.speed_loop.far_side_torque_per_frequency)
                    * (model.p * model.speed_ref.abs() + enter);
        if model.regen_min_frequency > 0.0 {
            let i_need = model.ideal_torque_current(model.speed_ref);
            let bound = model.regen_bound(model.speed_ref);
            model.limited = !model.far_side && model.speed_ref.signum() * i_need < -bound;
        }
        Ok(model)
    }

    /// The torque current that carries the load at speed `w` (the flux at its reference).
    fn ideal_torque_current(&self, w: f64) -> f64 {
        (self.load + self.b * w) / (1.5 * self.p * self.lm_hat * self.i_sd)
    }

    /// The regeneration limit's bound on the braking torque current at estimated speed
    /// `wh`, A (>= 0).
    fn regen_bound(&self, wh: f64) -> f64 {
        self.regen_current_per_frequency * (self.p * wh.abs() - self.regen_min_frequency).max(0.0)
    }

    /// The Rs estimate of state `x`.
    fn rs_estimate(&self, x: &[f64; STATES]) -> f64 {
        if self.running.is_some() {
            x[RS_HAT]
        } else {
            self.rs_hat
        }
    }

    /// The torque-current reference of state `x`: the speed PI's, or where the
    /// regeneration limit binds the limit's, at the estimated speed.
    fn torque_reference(&self, x: &[f64; STATES]) -> f64 {
        let wh = x[6];
        if self.limited {
            -wh.signum() * self.regen_bound(wh)
        } else {
            self.kp * (self.speed_ref - wh) + x[INTEGRAL]
        }
    }

    /// The stator frequency and the (regulated) torque current of state `x`.
    fn frame(&self, x: &[f64; STATES]) -> (f64, f64) {
        let (lh, id_hat, wh, i_sq) = (x[3], x[4], x[6], x[IQ]);
        let inv_flux = 1.0 / lh.max(self.min_flux);
        let slip = self.slip_gain * i_sq * inv_flux;
        let r_d = self.rs_estimate(x) * (id_hat - self.i_sd);
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
        let [ld, lq, w, lh, id_hat, iq_hat, wh, th, _, _, iq_model, _] = *x;
        let (ws, i_sq) = self.frame(x);
        let rs_hat = self.rs_estimate(x);
        let i_sd = self.i_sd;
        let slip_true = ws - self.p * w;
        let dld = self.rr * i_sd - self.rr / self.lm * ld + slip_true * lq;
        let dlq = self.rr * i_sq - self.rr / self.lm * lq - slip_true * ld;
        // the voltage the current loops apply: the machine's plus the inverter's error
        let mag = (i_sd * i_sd + i_sq * i_sq).sqrt().max(1e-9);
        let u = 4.0 / core::f64::consts::PI * self.inverter_error / mag;
        let v_d = self.rs * i_sd - ws * self.ls * i_sq + dld - ws * lq + u * i_sd;
        // the torque current follows its reference with the current loops' first-order
        // response, and the machine's voltage carries the transient inductance's part of
        // that change, L_sigma di_sq/dt (i_sd is held at its reference: no d-axis part)
        let dq = self.current_bandwidth * (self.torque_reference(x) - i_sq);
        let v_q = self.rs * i_sq + self.ls * dq + ws * self.ls * i_sd + dlq + ws * ld + u * i_sq;
        let dw = (1.5 * self.p * (ld * i_sq - lq * i_sd) - self.b * w - self.load) / self.j;
        let dlh = self.blend * (self.lm_hat * i_sd - lh);
        let did = self.rs_model * (v_d - rs_hat * id_hat) + ws * i_sq;
        let inv_flux = 1.0 / lh.max(self.min_flux);
        let e = iq_hat - i_sq;
        let rseq = rs_hat + self.rr_hat;
        let diq = self.obs_a * e + self.obs_inv_l * (v_q - rseq * i_sq)
            - self.obs_p_inv_l * lh * wh
            - ws * i_sd;
        // the far side (w_s against Omega_hat): the speed and load updates see
        // e - c w e_d, w the orientation correction's fade (`acim::drive`)
        let e = if self.far_side && ws * wh < 0.0 {
            let fade = (self.inv_fade_width * (ws.abs() - self.fade_start)).clamp(0.0, 1.0);
            let sched = (self.far_side_load_factor * i_sq.abs()).max(1.0);
            e - self.far_side_gain * sched * fade * (id_hat - i_sd)
        } else {
            e
        };
        let dwh = self.obs_torque * lh * i_sq - self.obs_inv_j * th - self.obs_friction * wh
            + self.obs_g2 * e * inv_flux;
        let dth = self.obs_g3 * e * inv_flux;
        let di = self.ki * (self.speed_ref - wh);
        // the running law: d Rs_hat/dt = alpha_r sign(i_sd) Rs_hat (i_sq e_d + i_sd e_q) /
        // i_sq, and its q-axis current model (`acim::rs_estimator::update_running`)
        let (drs, diq_model) = match self.running {
            Some(law) => {
                let (e_d, e_q) = (id_hat - i_sd, iq_model - i_sq);
                let drs = law.alpha * i_sd.signum() * rs_hat * (i_sq * e_d + i_sd * e_q)
                    / if i_sq.abs() > 1e-9 { i_sq } else { 1e-9 };
                let dq = self.rs_model * (v_q - rs_hat * iq_model - ws * lh) - ws * i_sd;
                (drs, dq)
            }
            None => (0.0, 0.0),
        };
        [
            dld, dlq, dw, dlh, did, diq, dwh, dth, di, drs, diq_model, dq,
        ]
    }

    /// The states that move at this point: the integral is held where the regeneration
    /// limit binds, the running law's two where it does not adapt (or does not run).
    fn active(&self, rs_adapting: bool) -> Vec<usize> {
        (0..STATES)
            .filter(|&k| match k {
                INTEGRAL => !self.limited,
                RS_HAT | IQ_MODEL => rs_adapting,
                _ => true,
            })
            .collect()
    }

    /// The Jacobian of [`Model::derivative`] over the states `active` at `x` (central
    /// differences).
    fn jacobian_of(&self, x: &[f64; STATES], active: &[usize]) -> DMatrix<f64> {
        let n = active.len();
        let mut jm = DMatrix::zeros(n, n);
        for (c, &k) in active.iter().enumerate() {
            let h = 1e-6 * x[k].abs().max(1e-3);
            let (mut a, mut b) = (*x, *x);
            a[k] += h;
            b[k] -= h;
            let (fa, fb) = (self.derivative(&a), self.derivative(&b));
            for (r, &row) in active.iter().enumerate() {
                jm[(r, c)] = (fa[row] - fb[row]) / (2.0 * h);
            }
        }
        jm
    }

    /// The Jacobian of [`Model::derivative`] at `x` over every state (central
    /// differences).
    pub fn jacobian(&self, x: &[f64; STATES]) -> DMatrix<f64> {
        let all: Vec<usize> = (0..STATES).collect();
        self.jacobian_of(x, &all)
    }

    /// The ideal operating point: the flux at its reference, the speeds at the reference
    /// (where the regeneration limit binds: at the speed where the limit's torque current
    /// carries the load), the torque current that carries the load.
    fn guess(&self) -> [f64; STATES] {
        let lambda = self.lm_hat * self.i_sd;
        let speed = if self.limited {
            // 1.5 p lambda (-g (p w - w_min)) = load (+ B w), w > 0
            let kt = 1.5 * self.p * lambda;
            let g = self.regen_current_per_frequency;
            (kt * g * self.regen_min_frequency - self.load) / (kt * g * self.p + self.b)
                * self.speed_ref.signum()
        } else {
            self.speed_ref
        };
        let i_sq = self.ideal_torque_current(speed);
        let load_hat =
            (self.obs_torque * lambda * i_sq - self.obs_friction * speed) / self.obs_inv_j;
        // the integral: the PI's output at zero error (held where the limit binds)
        let integral = if self.limited { 0.0 } else { i_sq };
        let rs_hat = self.rs_hat;
        [
            lambda, 0.0, speed, lambda, self.i_sd, i_sq, speed, load_hat, integral, rs_hat, i_sq,
            i_sq,
        ]
    }

    /// Whether the running law adapts at state `x` (its gate: |w_s| and |i_sq|).
    fn rs_adapting(&self, x: &[f64; STATES]) -> bool {
        self.running.is_some_and(|law| {
            let (ws, i_sq) = self.frame(x);
            ws.abs() >= law.min_frequency && i_sq.abs() >= law.min_torque_current
        })
    }

    /// Newton's method on the `active` states from `x`; `damped`: each step halved until
    /// the residual falls. `None` when it does not converge.
    fn newton(
        &self,
        mut x: [f64; STATES],
        active: &[usize],
        damped: bool,
    ) -> Option<[f64; STATES]> {
        let residual = |x: &[f64; STATES]| -> (Vec<f64>, f64) {
            let f = self.derivative(x);
            let fa: Vec<f64> = active.iter().map(|&k| f[k]).collect();
            let norm = fa.iter().map(|v| v * v).sum::<f64>().sqrt();
            (fa, norm)
        };
        let (mut fa, mut norm) = residual(&x);
        for _ in 0..100 {
            if !norm.is_finite() {
                return None;
            }
            if norm < 1e-9 {
                return Some(x);
            }
            let jm = self.jacobian_of(&x, active);
            let step = jm.lu().solve(&DVector::from_row_slice(&fa))?;
            let mut scale = 1.0;
            loop {
                let mut next = x;
                for (&k, s) in active.iter().zip(step.iter()) {
                    next[k] -= scale * s;
                }
                let (f_next, n_next) = residual(&next);
                if !damped || n_next < norm || scale < 1e-6 {
                    x = next;
                    fa = f_next;
                    norm = n_next;
                    break;
                }
                scale *= 0.5;
            }
        }
        None
    }

    /// The equilibrium near the ideal operating point and the eigenvalues there; `None`
    /// when Newton's method does not converge from it, with full or with damped steps (no
    /// equilibrium near it).
    pub fn linearise(&self) -> Option<Linearisation> {
        let guess = self.guess();
        let rs_adapting = self.rs_adapting(&guess);
        let active = self.active(rs_adapting);
        // Newton's method from the ideal point; where the full steps do not converge,
        // once more with steps halved until the residual falls
        let x = self
            .newton(guess, &active, false)
            .or_else(|| self.newton(guess, &active, true))?;
        let mut eigenvalues: Vec<(f64, f64)> = self
            .jacobian_of(&x, &active)
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
            limited: self.limited,
            rs_adapting,
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

/// The base of the first map: [`crate::stability::ideal_scenario`] (the measured map's
/// conventions) with the Rs estimate held at the controller's value and without the
/// regeneration limit: every labelled point is linearised where it is labelled.
pub fn base_scenario() -> Scenario {
    let mut sc = crate::stability::ideal_scenario("linear");
    sc.drive.loops.regen_min_frequency_hz = 0.0;
    sc
}

/// The base of the second map, the drive as it ships: [`crate::stability::ideal_scenario`]
/// with the drive's defaults for what it left out, Rs tracked while running (the
/// estimator on, the running mode) and the regeneration limit (1.5 Hz).
pub fn default_drive_scenario() -> Scenario {
    let mut sc = crate::stability::ideal_scenario("linear-default");
    let defaults = Scenario::default();
    sc.drive.estimation.rs_estimation = defaults.drive.estimation.rs_estimation;
    sc.drive.estimation.rs_estimation_mode = defaults.drive.estimation.rs_estimation_mode;
    sc.drive.loops.regen_min_frequency_hz = defaults.drive.loops.regen_min_frequency_hz;
    sc
}

/// One cell's text, whether it is unstable (`None`: no equilibrium) and its stator
/// frequency, Hz.
fn cell(l: &Option<Linearisation>) -> (String, Option<bool>, f64) {
    match l {
        None => ("no equilibrium".into(), None, f64::NAN),
        Some(l) => {
            let (re, im) = l.eigenvalues[0];
            let mut text = if im.abs() > 1e-6 {
                format!("{re:.2} ±{:.1}j", im.abs())
            } else {
                format!("{re:.2}")
            };
            if l.limited {
                let rpm = l.state[2] * f64::from(acim::math::RAD_S_TO_RPM);
                text = format!("held at {rpm:.0} rpm: {text}");
            }
            (
                text,
                Some(re > 0.0),
                l.stator_frequency / core::f64::consts::TAU,
            )
        }
    }
}

/// Counts of one map.
#[derive(Clone, Copy, Debug, Default)]
struct Counts {
    unstable_observable: usize,
    unstable_low: usize,
    no_equilibrium: usize,
    limited: usize,
}

/// One map per error of [`crate::stability::robust_errors`] on `base`, as Markdown
/// tables, and a summary row per error.
fn maps(base: fn() -> Scenario, section: &str) -> Result<(String, String, usize), ScenarioError> {
    use crate::stability::{robust_errors, ROBUST_LOADS_NM, ROBUST_SPEEDS_RPM};
    let header = crate::stability::map_header;
    let mut summary = String::new();
    let mut tables = String::new();
    let mut unstable_observable = 0;
    for (name, err) in robust_errors() {
        let mut sc = base();
        err(&mut sc);
        tables.push_str(&format!("### {section}: {name}\n\n"));
        header(&mut tables);
        let mut n = Counts::default();
        let mut worst = f64::NEG_INFINITY;
        for s in ROBUST_SPEEDS_RPM {
            tables.push_str(&format!("| {s} |"));
            for l in ROBUST_LOADS_NM {
                let lin = linearise(&sc, s, l)?;
                let (text, unstable, fs) = cell(&lin);
                let low = fs.abs() < 1.0;
                match unstable {
                    None => n.no_equilibrium += 1,
                    Some(true) if low => n.unstable_low += 1,
                    Some(true) => n.unstable_observable += 1,
                    Some(false) => {}
                }
                if lin.as_ref().is_some_and(|l| l.limited) {
                    n.limited += 1;
                }
                if let (Some(l), false) = (&lin, low) {
                    worst = worst.max(l.max_real());
                }
                tables.push_str(&format!(" {text}{} |", if low { "*" } else { "" }));
            }
            tables.push('\n');
        }
        tables.push('\n');
        unstable_observable += n.unstable_observable;
        summary.push_str(&format!(
            "| {name} | {} | {} | {} | {} | {worst:.2} |\n",
            n.unstable_observable, n.unstable_low, n.no_equilibrium, n.limited
        ));
    }
    Ok((summary, tables, unstable_observable))
}

/// The eigenvalue maps of as Markdown: for each error of
/// [`crate::stability::robust_errors`], the largest real part of the linearised closed
/// loop's eigenvalues over [`crate::stability::ROBUST_SPEEDS_RPM`] x
/// [`crate::stability::ROBUST_LOADS_NM`], first with the Rs estimate held and no
/// regeneration limit (every labelled point), then for the drive as it ships (Rs tracked
/// while running, the regeneration limit), with a summary. Also returns the number of
/// unstable points with |f_s| >= 1 Hz of the drive as it ships.
pub fn map_markdown() -> Result<(String, usize), ScenarioError> {
    let mut md = String::from(
        "<!-- generated by `cargo run --release -p acim-sim -- linear-stability`; do not edit -->\n\n\
         Eigenvalues of the linearised closed loop (`acim_sim::linear`: the machine in the \
         controller's frame with regulated currents, the flux model, the eq. (20) current \
         model, the reduced-order observer and the speed PI, with the running Rs law and \
         the regeneration limit where the drive has them, every controller coefficient \
         from the drive's design; docs/robustness.md derives it). Each cell: the eigenvalue \
         with the largest real part, 1/s (`±...j`: a complex pair, its imaginary part in \
         rad/s); positive is unstable. Rows: speed; columns: active load torque (positive \
         motoring, negative regenerating). `*`: the point's stator frequency (at the \
         equilibrium, with the error) is below 1 Hz. `held at N rpm`: the regeneration \
         limit binds there and the drive holds the reachable speed N (reported), where the \
         cell's eigenvalue is. Paper machine, drive defaults (orientation gain 2, \
         load-scheduled), zero friction, no inverter error unless the row says so.\n\n\
         Two maps: **the drive as it ships** (the Rs estimator on in the running mode: \
         its estimate and q-axis model are states where the law adapts, |f_s| >= 1 Hz and \
         |i_sq| >= 0.2 i_sd*, and held at the controller's value elsewhere; the 1.5 Hz \
         regeneration limit; the far-side mode where the load puts the target's point at \
         least 1 Hz beyond the line w_s = 0: the observer's far-side term on and the limit \
         released, except in the inverter-error rows, which stand for a drive whose \
         inverter test did not run and which keeps the limit), and **the labelled points** \
         (the Rs estimate held at the controller's value, no regeneration limit, no \
         far-side mode, which needs the running Rs law: every point linearised where it \
         is labelled, as the measured map of robust-stability.md does).\n\n",
    );
    let head = "| error | unstable with \\|f_s\\| >= 1 Hz | unstable below 1 Hz | no equilibrium | held by the regeneration limit | least damped with \\|f_s\\| >= 1 Hz (1/s) |\n|---|---|---|---|---|---|\n";
    let (s_ship, t_ship, unstable) = maps(default_drive_scenario, "As it ships")?;
    let (s_fixed, t_fixed, _) = maps(base_scenario, "Labelled points, Rs held")?;
    md.push_str("## Summary: the drive as it ships\n\n");
    md.push_str(head);
    md.push_str(&s_ship);
    md.push_str("\n## Summary: the labelled points, Rs held, no regeneration limit\n\n");
    md.push_str(head);
    md.push_str(&s_fixed);
    md.push_str("\n## The drive as it ships\n\n");
    md.push_str(&t_ship);
    md.push_str("## The labelled points, Rs held, no regeneration limit\n\n");
    md.push_str(&t_fixed);
    Ok((md, unstable))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn point(k: f32, rpm: f32, load: f32) -> Linearisation {
        let mut s = base_scenario();
        s.drive.estimation.orientation_gain = k;
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
        // and the closed loop, sampled, with the plant model, grows at that rate while the
        // error is small: +11.5/s against the model's +10.5/s. (`measure`'s map figure,
        // +13.4/s, fits up to a 30 degree error, where the growth is faster.)
        let g = f64::from(crate::stability::linear_growth_rate(250.0, -1.5, 0.0, &|_| {}).unwrap());
        assert!(
            (g - re).abs() < 0.1 * g,
            "measured {g}/s, linearised {re}/s"
        );
    }

    /// The regeneration limit's held points with the controller's R_R 30 % low (15 rpm /
    /// -1.5 N m, 30 / -3, 60 / -4.5, held at the reachable speed): the sampled loop holds
    /// 60 rpm / -4.5 N m steadily (the bound at the estimated speed, no oscillation), and
    /// so does the model now that the observer sees the voltage the current loops apply to change the torque current,
    /// L_sigma di_sq/dt included. Without that term the model found a 44 Hz pair growing
    /// at +35/s there: the observer's current model saw the lagged current change with
    /// no voltage driving it, and read the difference as speed.
    #[test]
    fn the_held_points_with_rr_low_are_stable() {
        let mut sc = default_drive_scenario();
        sc.controller.rr_ohm *= 0.7;
        for (rpm, load) in [(15.0, -1.5), (30.0, -3.0), (60.0, -4.5)] {
            let l = linearise(&sc, rpm, load).unwrap().unwrap();
            assert!(l.limited, "{rpm} rpm {load} N m");
            assert!(
                l.max_real() < 0.0,
                "{rpm} rpm {load} N m: {:?}",
                l.eigenvalues
            );
        }
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
        let k = acim::DriveConfig::paper_defaults()
            .estimation
            .orientation_gain;
        for (rpm, load) in [(120.0, -4.5), (250.0, -3.0), (500.0, -4.5)] {
            let lin = point(k, rpm, load).max_real();
            let measured = f64::from(crate::stability::measure(rpm, load, k).unwrap().growth_rate);
            assert!(
                (lin > 0.0) == (measured > 0.0) && (lin - measured).abs() < 1.5,
                "{rpm} rpm {load} N m: linearised {lin}/s, measured {measured}/s"
            );
        }
    }

    /// With Rs tracked while running (the drive as it ships) the estimate is a state: at a
    /// regenerating point where the held -20 % Rs error is unstable (250 rpm, -3 N m),
    /// the equilibrium has the estimate at the machine's Rs and the point is stable.
    #[test]
    fn the_running_law_removes_the_rs_error() {
        let mut held = base_scenario();
        held.controller.rs_ohm = 0.8 * held.plant.rs_ohm;
        assert!(linearise(&held, 250.0, -3.0).unwrap().unwrap().max_real() > 0.0);
        let mut ships = default_drive_scenario();
        ships.controller.rs_ohm = 0.8 * ships.plant.rs_ohm;
        let l = linearise(&ships, 250.0, -3.0).unwrap().unwrap();
        assert!(l.rs_adapting && !l.limited);
        let rs = l.state[RS_HAT];
        assert!((rs - 10.5).abs() < 0.01 * 10.5, "{rs}");
        assert!(l.max_real() < -1.0, "{:?}", l.eigenvalues);
        // at zero torque the law has no information: the estimate stays held
        let l = linearise(&ships, 250.0, 0.0).unwrap().unwrap();
        assert!(!l.rs_adapting);
    }

    /// Where the regeneration limit binds (120 rpm at -4.5 N m would sit at f_s = 0.96
    /// Hz, inside the far-side transit's 1 Hz) the drive holds the reachable speed, where
    /// the stator frequency is the limit's 1.5 Hz; the overhauling sweep holds 126 rpm at
    /// 4 N m and 147 rpm at 5 N m there (docs/overhauling.md), and the point is stable.
    #[test]
    fn the_regeneration_limit_holds_the_reachable_speed() {
        let l = linearise(&default_drive_scenario(), 120.0, -4.5)
            .unwrap()
            .unwrap();
        assert!(l.limited);
        let fs = l.stator_frequency / core::f64::consts::TAU;
        assert!((fs - 1.5).abs() < 0.05, "{fs}");
        let rpm = l.state[2] * f64::from(acim::math::RAD_S_TO_RPM);
        assert!((126.0..147.0).contains(&rpm), "{rpm}");
        assert!(l.max_real() < 0.0, "{:?}", l.eigenvalues);
        // without the limit the same point is linearised where it is labelled
        let l = linearise(&base_scenario(), 60.0, -4.5).unwrap().unwrap();
        assert!(!l.limited && (l.state[2] - 2.0 * core::f64::consts::PI).abs() < 0.1);
    }

    /// The far-side transit: 60 rpm at -4.5 N m is 1.05 Hz beyond the
    /// line, so the drive as it ships releases the limit and holds the point, stable with
    /// the far-side gain. Without the gain (0: no transit either) the limit holds it at the
    /// reachable speed, and without the limit it is unstable; with the gain but Rs held (no
    /// running law) the drive keeps the limit.
    #[test]
    fn the_far_side_transit_holds_the_point() {
        let ships = default_drive_scenario();
        let l = linearise(&ships, 60.0, -4.5).unwrap().unwrap();
        assert!(!l.limited);
        let fs = l.stator_frequency / core::f64::consts::TAU;
        assert!((fs + 1.05).abs() < 0.05, "{fs}");
        assert!((l.state[2] - 2.0 * core::f64::consts::PI).abs() < 0.1);
        assert!(l.max_real() < -1.0, "{:?}", l.eigenvalues);
        let mut off = default_drive_scenario();
        off.drive.estimation.far_side_gain = 0.0;
        assert!(linearise(&off, 60.0, -4.5).unwrap().unwrap().limited);
        // the far-side term is what holds it: without it (and without the limit) the
        // point is unstable
        let mut zero = default_drive_scenario();
        zero.drive.estimation.far_side_gain = 0.0;
        zero.drive.loops.regen_min_frequency_hz = 0.0;
        let l = linearise(&zero, 60.0, -4.5).unwrap().unwrap();
        assert!(l.max_real() > 0.0, "{:?}", l.eigenvalues);
        // Rs held: no transit
        let mut held = default_drive_scenario();
        held.drive.estimation.rs_estimation = false;
        assert!(linearise(&held, 60.0, -4.5).unwrap().unwrap().limited);
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
