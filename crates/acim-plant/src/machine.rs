//! Induction machine: electrical model (paper eq. 1, rewritten in the stationary frame),
//! mechanics (eq. 2) and torque (eq. 3), integrated with classic fourth-order Runge-Kutta.
//!
//! # State and equations
//!
//! States (all f32, SI): stator current `i_s = i_alpha + j i_beta` (A, peak phase values,
//! amplitude-invariant Clarke), rotor flux linkage `psi_r = psi_alpha + j psi_beta`
//! (Wb, stator-referred, the state of the paper's eq. (1): its `lambda_r` there tends to
//! `Lm i_sd`, i.e. it is `psi_r`), mechanical speed `Omega` (rad/s) and mechanical angle
//! (rad, wrapped into [-pi, pi)). The inverse-Gamma flux of the rest of the crate
//! (design notes, section 2) is `lambda_r = (Lm/Lr) psi_r`, see
//! [`InductionMachine::lambda_r`].
//!
//! Eq. (1) written in the stationary alpha-beta frame (omega_s = 0), with
//! `w = p Omega` (electrical rad/s), `sigma Ls` the transient inductance,
//! `Rseq = Rs + (Lm/Lr)^2 Rr` and `tau_r = Lr/Rr`:
//!
//! ```text
//! sigma Ls di_s/dt  = v_s - Rseq i_s + (Lm/Lr) (1/tau_r - j w) psi_r          (1a, 1b)
//! dpsi_r/dt         = -psi_r/tau_r + (Lm/tau_r) i_s + j w psi_r               (1c, 1d)
//! J dOmega/dt       = Te - B Omega - T_L(Omega)                               (2)
//! Te                = 1.5 p (Lm/Lr) (psi_alpha i_beta - psi_beta i_alpha)     (3)
//! ```
//!
//! The 1.5 in (3) is the amplitude-invariant scaling (the paper's (3) has none). Eq. (2)
//! is the paper's with the viscous friction B of [`MachineParams`] written out.
//!
//! # Energy
//!
//! With amplitude-invariant quantities every power carries the factor 1.5:
//! input `1.5 (v_alpha i_alpha + v_beta i_beta)`, stator copper `1.5 Rs |i_s|^2`, rotor
//! copper `1.5 Rr |i_r|^2` with `i_r = (psi_r - Lm i_s)/Lr`, stored magnetic energy
//! `W_m = 0.75 (sigma Ls |i_s|^2 + |psi_r|^2 / Lr)` and kinetic energy `0.5 J Omega^2`.
//! The balance `P_in = P_cu_s + P_cu_r + dW_m/dt + Te Omega` holds exactly for (1)-(3);
//! the machine integrates each power with the same RK4 weights as the states and keeps the
//! sums in an [`EnergyAccount`].

use crate::load::LoadTorque;
use acim::frames::{inverse_clarke, AlphaBeta};
use acim::math::{is_finite, wrap_angle};
use acim::params::MachineParams;

/// Default number of RK4 sub-steps per control period.
pub const DEFAULT_SUBSTEPS: u32 = 10;

/// Full state of the machine model (see the module documentation for the units).
#[derive(Clone, Copy, Debug, PartialEq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct MachineState {
    /// Stator current, alpha axis, A (peak phase value).
    pub i_alpha: f32,
    /// Stator current, beta axis, A.
    pub i_beta: f32,
    /// Rotor flux linkage psi_r, alpha axis, Wb (stator-referred).
    pub psi_alpha: f32,
    /// Rotor flux linkage psi_r, beta axis, Wb.
    pub psi_beta: f32,
    /// Mechanical speed Omega, rad/s.
    pub speed: f32,
    /// Mechanical angle, rad, in [-pi, pi).
    pub angle: f32,
}

/// Compensated (Kahan) f32 accumulator, so that long runs keep the energy sums to about
/// f32 resolution instead of losing one rounding per step.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
struct KahanSum {
    sum: f32,
    c: f32,
}

impl KahanSum {
    fn add(&mut self, x: f32) {
        let y = x - self.c;
        let t = self.sum + y;
        self.c = (t - self.sum) - y;
        self.sum = t;
    }
}

/// Energies (J) integrated since the last [`InductionMachine::reset_energy`].
///
/// Balance: `input = stator_copper + rotor_copper + friction + load
/// + (magnetic energy now - at reset) + (kinetic energy now - at reset)`, see
/// [`InductionMachine::energy_residual`].
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct EnergyAccount {
    input: KahanSum,
    stator_copper: KahanSum,
    rotor_copper: KahanSum,
    friction: KahanSum,
    load: KahanSum,
    magnetic_at_reset: f32,
    kinetic_at_reset: f32,
}

impl EnergyAccount {
    /// Electrical energy delivered at the machine terminals, integral of
    /// 1.5 (v_alpha i_alpha + v_beta i_beta) dt, J.
    pub fn input(&self) -> f32 {
        self.input.sum
    }
    /// Stator copper losses, integral of 1.5 Rs |i_s|^2 dt, J.
    pub fn stator_copper(&self) -> f32 {
        self.stator_copper.sum
    }
    /// Rotor copper losses, integral of 1.5 Rr |i_r|^2 dt, J.
    pub fn rotor_copper(&self) -> f32 {
        self.rotor_copper.sum
    }
    /// Viscous friction losses, integral of B Omega^2 dt, J.
    pub fn friction(&self) -> f32 {
        self.friction.sum
    }
    /// Energy delivered to the load, integral of T_L Omega dt, J (negative when an active
    /// load drives the machine).
    pub fn load(&self) -> f32 {
        self.load.sum
    }
    /// Stored magnetic energy at the last reset, J.
    pub fn magnetic_at_reset(&self) -> f32 {
        self.magnetic_at_reset
    }
    /// Kinetic energy at the last reset, J.
    pub fn kinetic_at_reset(&self) -> f32 {
        self.kinetic_at_reset
    }
}

/// Voltage applied during one RK4 stage, returned by the voltage source of
/// [`InductionMachine::step_with`].
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub(crate) struct StageSource {
    pub v_alpha: f32,
    pub v_beta: f32,
    /// Power drawn from the DC link, W (0 when there is no inverter).
    pub p_dc: f32,
}

/// RK4-weighted integrals of the source over one step (volt-seconds and DC energy).
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub(crate) struct StepSourceIntegral {
    pub v_alpha_dt: f32,
    pub v_beta_dt: f32,
    pub e_dc: f32,
    pub e_in: f32,
}

impl StepSourceIntegral {
    /// Adds another step's integrals.
    pub(crate) fn add(&mut self, s: StepSourceIntegral) {
        self.v_alpha_dt += s.v_alpha_dt;
        self.v_beta_dt += s.v_beta_dt;
        self.e_dc += s.e_dc;
        self.e_in += s.e_in;
    }
}

/// Coefficients of eq. (1)-(3) precomputed from the parameters (no division per stage).
#[derive(Clone, Copy, Debug, PartialEq)]
struct Coeffs {
    inv_sigma_ls: f32,
    rseq: f32,
    kr: f32,
    inv_tau_r: f32,
    lm_over_tau_r: f32,
    p: f32,
    inv_j: f32,
    b: f32,
    rs: f32,
    rr: f32,
    lm: f32,
    inv_lr: f32,
    kt: f32,
}

impl Coeffs {
    fn new(m: &MachineParams) -> Self {
        let lr = m.rotor_inductance();
        let lm = m.mutual_inductance();
        let inv_tau_r = m.rotor_resistance() / lr;
        let kr = lm / lr;
        Self {
            inv_sigma_ls: 1.0 / m.transient_inductance(),
            rseq: m.equivalent_resistance(),
            kr,
            inv_tau_r,
            lm_over_tau_r: lm * inv_tau_r,
            p: m.pole_pairs_f32(),
            inv_j: 1.0 / m.inertia(),
            b: m.viscous_friction(),
            rs: m.stator_resistance(),
            rr: m.rotor_resistance(),
            lm,
            inv_lr: 1.0 / lr,
            kt: 1.5 * m.pole_pairs_f32() * kr,
        }
    }
}

/// Main-flux saturation of the plant (off by default): the magnetizing inductance falls
/// with the rotor flux linkage as `L_m(|psi_r|) = L_m0 / (1 + (beta |psi_r|)^S)` (the
/// power law of motulator's saturation model, here on the T-model's L_m with the
/// leakages constant). The model is quasi-static: every RK4 stage uses the coefficients of
/// eq. (1)-(3) at its own flux, which gives the right saturation curve in steady state
/// (psi_r = L_m(psi_r) i_sd) and neglects the d L_m/dt terms in transients; the energy
/// account (built for constant inductances) does not balance with it on.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Saturation {
    /// beta, 1/Wb: the flux where the inductance has halved is 1/beta.
    pub beta: f32,
    /// The exponent S (an integer: no `powf` in `no_std`).
    pub exponent: u8,
}

impl Saturation {
    /// L_m / L_m0 at rotor flux linkage `psi` (Wb).
    pub fn factor(&self, psi: f32) -> f32 {
        let x = self.beta * psi;
        let mut xs = 1.0f32;
        for _ in 0..self.exponent {
            xs *= x;
        }
        1.0 / (1.0 + xs)
    }
}

/// Number of integrated states: i_alpha, i_beta, psi_alpha, psi_beta, Omega, angle.
const NX: usize = 6;
/// Number of integrated powers: input, stator Cu, rotor Cu, friction, load, v_alpha,
/// v_beta, DC power.
const NA: usize = 8;

/// Induction-machine plant model: its own [`MachineParams`] (independent of any
/// controller's copy) plus the state of eq. (1)-(3).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct InductionMachine {
    params: MachineParams,
    c: Coeffs,
    x: MachineState,
    /// Kahan compensation of the integrated states: the f32 state increments of one step
    /// are often below half an ulp of the state (e.g. the speed at steady state), and
    /// without compensation the speed would freeze at a torque imbalance of a few mN m.
    comp: [f32; NX],
    locked: bool,
    energy: EnergyAccount,
    #[cfg(feature = "saturation")]
    saturation: Option<Saturation>,
}

fn finite_or_zero(x: f32) -> f32 {
    if is_finite(x) {
        x
    } else {
        0.0
    }
}

impl InductionMachine {
    /// A machine at rest, demagnetised, with the given parameters.
    pub fn new(params: MachineParams) -> Self {
        Self {
            params,
            c: Coeffs::new(&params),
            x: MachineState::default(),
            comp: [0.0; NX],
            locked: false,
            energy: EnergyAccount::default(),
            #[cfg(feature = "saturation")]
            saturation: None,
        }
    }

    /// The plant's parameters.
    pub fn params(&self) -> &MachineParams {
        &self.params
    }

    /// Changes the parameters (e.g. a rotor-resistance rise) keeping the state.
    pub fn set_params(&mut self, params: MachineParams) {
        self.params = params;
        self.c = Coeffs::new(&params);
    }

    /// Switches main-flux saturation on (`Some`) or off (feature `saturation`).
    #[cfg(feature = "saturation")]
    pub fn set_saturation(&mut self, saturation: Option<Saturation>) {
        self.saturation = saturation;
    }

    /// The parameters at flux linkage `psi` (Wb) under saturation (the unsaturated ones
    /// without it, or if the saturated set is not valid).
    #[cfg(feature = "saturation")]
    fn params_at(&self, psi: f32) -> MachineParams {
        let Some(sat) = self.saturation else {
            return self.params;
        };
        let d = self.params.data();
        let lm = d.mutual_inductance * sat.factor(psi);
        let ls = d.stator_inductance - d.mutual_inductance + lm;
        let lr = d.rotor_inductance - d.mutual_inductance + lm;
        MachineParams::new(acim::params::MachineData {
            stator_inductance: ls,
            rotor_inductance: lr,
            mutual_inductance: lm,
            ..d
        })
        .unwrap_or(self.params)
    }

    /// The parameters in effect now: at the present rotor flux under saturation.
    pub fn effective_params(&self) -> MachineParams {
        #[cfg(feature = "saturation")]
        {
            let (pa, pb) = (self.x.psi_alpha, self.x.psi_beta);
            self.params_at(acim::math::sqrt(pa * pa + pb * pb))
        }
        #[cfg(not(feature = "saturation"))]
        self.params
    }

    /// The coefficients in effect now (at the present flux under saturation).
    fn coeffs_now(&self) -> Coeffs {
        #[cfg(feature = "saturation")]
        if self.saturation.is_some() {
            return Coeffs::new(&self.effective_params());
        }
        self.c
    }

    /// The full state.
    pub fn state(&self) -> MachineState {
        self.x
    }

    /// Sets the full state (non-finite fields become 0; the angle is wrapped; a locked
    /// rotor keeps speed 0). Resets the energy account so that it stays consistent.
    pub fn set_state(&mut self, s: MachineState) {
        self.x = MachineState {
            i_alpha: finite_or_zero(s.i_alpha),
            i_beta: finite_or_zero(s.i_beta),
            psi_alpha: finite_or_zero(s.psi_alpha),
            psi_beta: finite_or_zero(s.psi_beta),
            speed: if self.locked {
                0.0
            } else {
                finite_or_zero(s.speed)
            },
            angle: wrap_angle(s.angle),
        };
        self.comp = [0.0; NX];
        self.reset_energy();
    }

    /// Sets the mechanical speed Omega (rad/s), keeping the electrical state.
    pub fn set_speed(&mut self, speed: f32) {
        let mut s = self.x;
        s.speed = speed;
        self.set_state(s);
    }

    /// Sets the rotor flux linkage psi_r (Wb, alpha and beta), keeping the rest.
    pub fn set_rotor_flux(&mut self, psi_alpha: f32, psi_beta: f32) {
        let mut s = self.x;
        s.psi_alpha = psi_alpha;
        s.psi_beta = psi_beta;
        self.set_state(s);
    }

    /// Locks (true) or releases (false) the rotor. Locked: speed forced to 0 and held there
    /// whatever the torque (locked-rotor fault case or a standstill test).
    pub fn set_locked(&mut self, locked: bool) {
        self.locked = locked;
        if locked {
            self.x.speed = 0.0;
            self.comp = [0.0; NX];
            self.reset_energy();
        }
    }

    /// True when the rotor is locked.
    pub fn is_locked(&self) -> bool {
        self.locked
    }

    /// Stator current (i_alpha, i_beta), A.
    pub fn current_alpha_beta(&self) -> AlphaBeta {
        AlphaBeta {
            alpha: self.x.i_alpha,
            beta: self.x.i_beta,
        }
    }

    /// Phase currents (i_a, i_b, i_c), A (inverse amplitude-invariant Clarke; they sum to 0
    /// because the star point is isolated).
    pub fn phase_currents(&self) -> [f32; 3] {
        inverse_clarke(self.current_alpha_beta())
    }

    /// Rotor flux linkage psi_r (alpha, beta), Wb (the model state).
    pub fn psi_r(&self) -> AlphaBeta {
        AlphaBeta {
            alpha: self.x.psi_alpha,
            beta: self.x.psi_beta,
        }
    }

    /// Inverse-Gamma rotor flux lambda_r = (Lm/Lr) psi_r (alpha, beta), Wb: the
    /// `lambda_r` of the paper's eq. (8), (13) and of the controller.
    pub fn lambda_r(&self) -> AlphaBeta {
        AlphaBeta {
            alpha: self.coeffs_now().kr * self.x.psi_alpha,
            beta: self.coeffs_now().kr * self.x.psi_beta,
        }
    }

    /// Mechanical speed Omega, rad/s.
    pub fn speed(&self) -> f32 {
        self.x.speed
    }

    /// Electrical rotor speed p Omega, rad/s.
    pub fn speed_elec(&self) -> f32 {
        self.c.p * self.x.speed
    }

    /// Mechanical angle, rad, in [-pi, pi).
    pub fn angle(&self) -> f32 {
        self.x.angle
    }

    /// Electrical rotor angle p * angle, rad, wrapped into [-pi, pi).
    pub fn angle_elec(&self) -> f32 {
        wrap_angle(self.c.p * self.x.angle)
    }

    /// Electromagnetic torque Te (eq. 3 with the amplitude-invariant 1.5), N m.
    pub fn torque(&self) -> f32 {
        self.coeffs_now().kt * (self.x.psi_alpha * self.x.i_beta - self.x.psi_beta * self.x.i_alpha)
    }

    /// Rotor current i_r = (psi_r - Lm i_s)/Lr (alpha, beta), A.
    pub fn rotor_current(&self) -> AlphaBeta {
        AlphaBeta {
            alpha: (self.x.psi_alpha - self.coeffs_now().lm * self.x.i_alpha)
                * self.coeffs_now().inv_lr,
            beta: (self.x.psi_beta - self.coeffs_now().lm * self.x.i_beta)
                * self.coeffs_now().inv_lr,
        }
    }

    /// Stored magnetic energy W_m = 0.75 (sigma Ls |i_s|^2 + |psi_r|^2/Lr), J.
    pub fn magnetic_energy(&self) -> f32 {
        let i2 = self.x.i_alpha * self.x.i_alpha + self.x.i_beta * self.x.i_beta;
        let p2 = self.x.psi_alpha * self.x.psi_alpha + self.x.psi_beta * self.x.psi_beta;
        0.75 * (i2 / self.c.inv_sigma_ls + p2 * self.c.inv_lr)
    }

    /// Kinetic energy 0.5 J Omega^2, J.
    pub fn kinetic_energy(&self) -> f32 {
        0.5 * self.params.inertia() * self.x.speed * self.x.speed
    }

    /// Energies integrated since the last reset.
    pub fn energy(&self) -> &EnergyAccount {
        &self.energy
    }

    /// Zeroes the energy integrals and records the present stored energies.
    pub fn reset_energy(&mut self) {
        self.energy = EnergyAccount {
            magnetic_at_reset: self.magnetic_energy(),
            kinetic_at_reset: self.kinetic_energy(),
            ..EnergyAccount::default()
        };
    }

    /// Energy balance residual since the last reset, J: input minus (copper losses +
    /// friction + load + change of magnetic and kinetic energy). Zero up to integration
    /// and rounding error. With a locked rotor no mechanical energy flows (Omega = 0).
    pub fn energy_residual(&self) -> f32 {
        let e = &self.energy;
        e.input()
            - (e.stator_copper()
                + e.rotor_copper()
                + e.friction()
                + e.load()
                + (self.magnetic_energy() - e.magnetic_at_reset)
                + (self.kinetic_energy() - e.kinetic_at_reset))
    }

    /// State derivative (eq. 1-3) and the powers, for stage state `x`. The source is a
    /// trait object: one copy of this code for every inverter model (the firmware's
    /// self-test carries the plant within its 128 KiB flash budget).
    fn deriv(
        &self,
        x: &[f32; NX],
        load: LoadTorque,
        src: &dyn Fn(f32, f32) -> StageSource,
        open: bool,
    ) -> ([f32; NX], [f32; NA]) {
        #[cfg(feature = "saturation")]
        let saturated;
        #[cfg(feature = "saturation")]
        let c = match self.saturation {
            None => &self.c,
            Some(_) => {
                let psi = acim::math::sqrt(x[2] * x[2] + x[3] * x[3]);
                saturated = Coeffs::new(&self.params_at(psi));
                &saturated
            }
        };
        #[cfg(not(feature = "saturation"))]
        let c = &self.c;
        let [ia, ib, pa, pb, w, _th] = *x;
        let s = src(ia, ib);
        let (va, vb) = (finite_or_zero(s.v_alpha), finite_or_zero(s.v_beta));
        let we = c.p * w;
        let (dia, dib) = if open {
            // stator open: i_s stays 0, the terminals take the back-EMF (no power flows)
            (0.0, 0.0)
        } else {
            (
                c.inv_sigma_ls * (va - c.rseq * ia + c.kr * (c.inv_tau_r * pa + we * pb)),
                c.inv_sigma_ls * (vb - c.rseq * ib + c.kr * (c.inv_tau_r * pb - we * pa)),
            )
        };
        let dpa = -c.inv_tau_r * pa + c.lm_over_tau_r * ia - we * pb;
        let dpb = -c.inv_tau_r * pb + c.lm_over_tau_r * ib + we * pa;
        let te = c.kt * (pa * ib - pb * ia);
        let tl = load.torque(w);
        let (dw, dth) = if self.locked {
            (0.0, 0.0)
        } else {
            (c.inv_j * (te - c.b * w - tl), w)
        };
        let ira = (pa - c.lm * ia) * c.inv_lr;
        let irb = (pb - c.lm * ib) * c.inv_lr;
        let (p_fric, p_load) = if self.locked {
            (0.0, 0.0)
        } else {
            (c.b * w * w, tl * w)
        };
        (
            [dia, dib, dpa, dpb, dw, dth],
            [
                1.5 * (va * ia + vb * ib),
                1.5 * c.rs * (ia * ia + ib * ib),
                1.5 * c.rr * (ira * ira + irb * irb),
                p_fric,
                p_load,
                va,
                vb,
                finite_or_zero(s.p_dc),
            ],
        )
    }

    /// One RK4 step of length `dt` (s) with a voltage source evaluated at every stage from
    /// the stage's stator current (i_alpha, i_beta). Returns the step's source integrals.
    /// Non-positive or non-finite `dt` does nothing.
    pub(crate) fn step_with<F>(&mut self, dt: f32, load: LoadTorque, src: &F) -> StepSourceIntegral
    where
        F: Fn(f32, f32) -> StageSource,
    {
        self.rk4(dt, load, src, false)
    }

    fn rk4(
        &mut self,
        dt: f32,
        load: LoadTorque,
        src: &dyn Fn(f32, f32) -> StageSource,
        open: bool,
    ) -> StepSourceIntegral {
        if dt <= 0.0 || !is_finite(dt) {
            return StepSourceIntegral::default();
        }
        let x0 = [
            self.x.i_alpha,
            self.x.i_beta,
            self.x.psi_alpha,
            self.x.psi_beta,
            self.x.speed,
            self.x.angle,
        ];
        let h2 = 0.5 * dt;
        let (k1, a1) = self.deriv(&x0, load, src, open);
        let x1 = axpy(&x0, h2, &k1);
        let (k2, a2) = self.deriv(&x1, load, src, open);
        let x2 = axpy(&x0, h2, &k2);
        let (k3, a3) = self.deriv(&x2, load, src, open);
        let x3 = axpy(&x0, dt, &k3);
        let (k4, a4) = self.deriv(&x3, load, src, open);
        let h6 = dt * (1.0 / 6.0);
        let mut xn = x0;
        for ((xi, ci), (((d1, d2), d3), d4)) in xn
            .iter_mut()
            .zip(self.comp.iter_mut())
            .zip(k1.iter().zip(k2.iter()).zip(k3.iter()).zip(k4.iter()))
        {
            // Kahan-compensated update x += h/6 (k1 + 2 k2 + 2 k3 + k4)
            let y = h6 * (d1 + 2.0 * d2 + 2.0 * d3 + d4) - *ci;
            let t = *xi + y;
            *ci = (t - *xi) - y;
            *xi = t;
        }
        let mut a = [0.0f32; NA];
        for (ai, (((p1, p2), p3), p4)) in a
            .iter_mut()
            .zip(a1.iter().zip(a2.iter()).zip(a3.iter()).zip(a4.iter()))
        {
            *ai = h6 * (p1 + 2.0 * p2 + 2.0 * p3 + p4);
        }
        let [ia, ib, pa, pb, w, th] = xn;
        if self.locked {
            let [_, _, _, _, c_speed, _] = &mut self.comp;
            *c_speed = 0.0;
        }
        self.x = MachineState {
            i_alpha: ia,
            i_beta: ib,
            psi_alpha: pa,
            psi_beta: pb,
            speed: if self.locked { 0.0 } else { w },
            angle: wrap_angle(th),
        };
        let [e_in, e_cs, e_cr, e_f, e_l, vadt, vbdt, e_dc] = a;
        self.energy.input.add(e_in);
        self.energy.stator_copper.add(e_cs);
        self.energy.rotor_copper.add(e_cr);
        self.energy.friction.add(e_f);
        self.energy.load.add(e_l);
        StepSourceIntegral {
            v_alpha_dt: vadt,
            v_beta_dt: vbdt,
            e_dc,
            e_in,
        }
    }

    /// Stator voltage (v_alpha, v_beta) that the open-circuit machine shows at its
    /// terminals (back-EMF), V: with i_s = 0 and di_s/dt = 0, eq. (1a, 1b) give
    /// `v_s = -(Lm/Lr)(1/tau_r - j p Omega) psi_r`. Used by the inverter model to decide
    /// whether the freewheeling diodes conduct when the gates are off.
    pub fn open_circuit_voltage(&self) -> AlphaBeta {
        let c = &self.c;
        let we = c.p * self.x.speed;
        AlphaBeta {
            alpha: -c.kr * (c.inv_tau_r * self.x.psi_alpha + we * self.x.psi_beta),
            beta: -c.kr * (c.inv_tau_r * self.x.psi_beta - we * self.x.psi_alpha),
        }
    }

    /// One RK4 step of `dt` seconds with the stator open (disconnected, or all inverter
    /// switches off with every diode blocked): i_s = 0, the rotor flux decays with tau_r
    /// and rotates with the rotor, Te = 0. A non-zero stator current is first set to 0;
    /// its small stored energy 0.75 sigma Ls |i_s|^2 is booked as returned through the
    /// terminals (negative input energy), so the energy account stays balanced.
    pub fn step_open_circuit(&mut self, load: LoadTorque, dt: f32) {
        if dt <= 0.0 || !is_finite(dt) {
            return;
        }
        if self.x.i_alpha != 0.0 || self.x.i_beta != 0.0 {
            let i2 = self.x.i_alpha * self.x.i_alpha + self.x.i_beta * self.x.i_beta;
            self.energy.input.add(-0.75 * i2 / self.c.inv_sigma_ls);
            self.x.i_alpha = 0.0;
            self.x.i_beta = 0.0;
            let [c_ia, c_ib, _, _, _, _] = &mut self.comp;
            *c_ia = 0.0;
            *c_ib = 0.0;
        }
        self.rk4(dt, load, &|_, _| StageSource::default(), true);
    }

    /// One RK4 step of `dt` seconds with the stator voltage (v_alpha, v_beta) (V, peak
    /// phase values) held constant over the step and load torque `load`. Non-finite
    /// voltages are taken as 0; non-positive or non-finite `dt` does nothing.
    ///
    /// Accuracy: the fastest eigenvalues of the Table 1 machine are about
    /// Rseq/(sigma Ls) = 466 1/s and the electrical speed (314 rad/s at 50 Hz), so a
    /// 20 us step gives |lambda dt| < 0.01, far inside RK4's stability region and with a
    /// local error of order (lambda dt)^5.
    pub fn step(&mut self, v_alpha: f32, v_beta: f32, load: LoadTorque, dt: f32) {
        let s = StageSource {
            v_alpha,
            v_beta,
            p_dc: 0.0,
        };
        self.step_with(dt, load, &|_, _| s);
    }

    /// Runs one control period of `period` seconds as `substeps` equal RK4 steps with a
    /// constant voltage (a zero-order hold, what an ideal averaged inverter applies).
    /// Default use: `period` = 200 us and [`DEFAULT_SUBSTEPS`] = 10, i.e. 20 us steps.
    /// `substeps == 0` does nothing.
    pub fn step_period(
        &mut self,
        v_alpha: f32,
        v_beta: f32,
        load: LoadTorque,
        period: f32,
        substeps: u32,
    ) {
        if substeps == 0 {
            return;
        }
        let dt = period / substeps as f32;
        for _ in 0..substeps {
            self.step(v_alpha, v_beta, load, dt);
        }
    }
}

fn axpy(x: &[f32; NX], h: f32, k: &[f32; NX]) -> [f32; NX] {
    let mut y = *x;
    for (yi, ki) in y.iter_mut().zip(k.iter()) {
        *yi += h * ki;
    }
    y
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Saturation: a DC voltage on a locked rotor settles where the rotor flux linkage
    /// is L_m(psi) i_s (the magnetizing curve's fixed point), below the linear L_m0 i_s.
    #[test]
    #[cfg(feature = "saturation")]
    fn saturation_settles_on_the_magnetizing_curve() {
        let params = MachineParams::paper_table1();
        let mut m = InductionMachine::new(params);
        m.set_locked(true);
        let sat = Saturation {
            beta: 1.2,
            exponent: 7,
        };
        m.set_saturation(Some(sat));
        let v = 1.5 * params.stator_resistance();
        for _ in 0..200_000 {
            m.step(v, 0.0, LoadTorque::None, 20e-6);
        }
        let i = m.current_alpha_beta().alpha;
        let psi = m.psi_r().alpha;
        assert!((i - 1.5).abs() < 1e-3, "{i}");
        let lm = params.mutual_inductance() * sat.factor(psi);
        assert!((psi - lm * i).abs() < 1e-3 * psi, "{psi} vs {}", lm * i);
        assert!(
            psi < 0.9 * params.mutual_inductance() * i,
            "{psi}: not saturated"
        );
        assert!(m.effective_params().mutual_inductance() < params.mutual_inductance());
    }

    #[test]
    fn dc_excitation_settles_to_flux_without_torque() {
        let mut m = InductionMachine::new(MachineParams::paper_table1());
        m.set_locked(true);
        // 1 A DC in alpha needs v = Rs i at steady state.
        for _ in 0..50_000 {
            m.step(10.5, 0.0, LoadTorque::None, 20e-6);
        }
        assert!((m.current_alpha_beta().alpha - 1.0).abs() < 1e-3);
        assert!((m.psi_r().alpha - 0.54).abs() < 1e-3);
        assert!(m.torque().abs() < 1e-5);
        assert!((m.lambda_r().alpha - 0.54 * 0.54 / 0.56).abs() < 1e-3);
        assert_eq!(m.speed(), 0.0);
    }

    #[test]
    fn bad_dt_is_ignored() {
        let mut m = InductionMachine::new(MachineParams::paper_table1());
        m.step(100.0, 0.0, LoadTorque::None, f32::NAN);
        m.step(100.0, 0.0, LoadTorque::None, -1.0);
        m.step_period(100.0, 0.0, LoadTorque::None, 200e-6, 0);
        assert_eq!(m.state(), MachineState::default());
        m.step(f32::NAN, 0.0, LoadTorque::None, 1e-5);
        assert_eq!(m.state(), MachineState::default());
    }
}
