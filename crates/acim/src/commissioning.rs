//! Self-commissioning: the inverse-Gamma model (Rs, R_R, L_sigma, L_M), the rated flux
//! current and the inverter's voltage error of an unknown motor, identified by the drive
//! itself from its nameplate and board, before any speed control (f32, allocation-free,
//! one [`Commissioning::step`] per control period like [`crate::Drive::step`]).
//!
//! Terminal measurements cannot separate Ls from Lr; the inverse-Gamma model (design
//! notes section 2) is what they identify and what the drive uses.
//!
//! ## The sequence (each test with its timeout, plausibility bounds and error)
//!
//! 1. **Offsets**, switches off: each current channel's mean.
//! 2. **Rs and the inverter voltage error**: DC currents along the alpha axis at four
//!    levels (25-70 % of the rated peak), each held until the rotor flux has settled
//!    (1.2 s); the mean voltage the current loops need is `Rs i + (4/3) V_e` (phase a
//!    carries +i, b and c -i/2: each leg's dead-time and device-drop error V_e opposes
//!    its current, and the amplitude-invariant Clarke transform of (+V_e, -V_e, -V_e) is
//!    4/3 V_e on alpha). A straight-line fit gives Rs (slope) and V_e (intercept); the
//!    dead time is (V_e - V_drop) T_pwm / V_dc with the board's device drop.
//! 3. **Impedance at standstill**, alpha axis only (a pulsating field: no torque, the
//!    rotor stays): on a DC bias of 30 % rated current (so no phase current crosses zero
//!    and the inverter error stays constant), a sinusoid at 4 % of the rated frequency
//!    (current reference, tracked by the loops) and one at the rated frequency (voltage
//!    injected over the loops); Fourier sums of the applied voltage (its timing: it acts
//!    1.5 periods after its sample) and the measured current give Z(jw). With
//!    Z'(jw) = Z - Rs = j w L_sigma + (j w L_M R_R) / (R_R + j w L_M), the admittance
//!    Y = 1 / (Z' - j w L_sigma) = 1/R_R - j / (w L_M) has the same real part at both
//!    frequencies only for the true L_sigma: found by bisection, then R_R and L_M.
//! 4. **No-load test** (the rotor turns): V/f ramp to 80 % of the rated frequency at the
//!    rated volts per hertz, hold, Fourier sums in the voltage's frame: at no load the
//!    slip is nearly zero and Z = Rs + j w (L_sigma + L_M): L_M at rated flux (saturation
//!    found, not assumed) and the rated flux current (the no-load current).
//!
//! 5. **Inertia and friction**, from the same test: over the V/f ramp the rotor follows
//!    the frequency at a small slip, and the air-gap torque from the power balance
//!    (`p (1.5 v i_d - 1.5 Rs |i|^2 - inverter loss) / w`) accelerates it: J is its
//!    impulse over the ramp's speed change (friction removed), B the hold's torque over
//!    its speed.
//!
//! The fits run in [`Commissioning::identify`], outside the interrupt, once the step
//! reports [`Stage::Done`]. [`mechanics_from_slopes`] gives J and B from two
//! accelerations at a known torque instead (a test under speed control).

// `!(x > 0.0)` is meant: it also rejects a NaN, which `x <= 0.0` would let through
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use crate::design::CurrentSensing;
use crate::drive::{DriveInputs, PwmOutput};
use crate::frames::{clarke_three, clarke_two, inverse_clarke, AlphaBeta, FastSinCos, SinCos};
use crate::math::{is_finite, sqrt, wrap_angle, wrap_angle_step};
use crate::nameplate::{Board, Nameplate, NameplateError, RatedPoint};
use crate::pi::{PiConfig, PiController};
use crate::svpwm::{linear_limit, modulate, SvpwmConfig};

/// DC-step currents as fractions of the rated peak current.
pub const DC_LEVELS: [f32; 4] = [0.25, 0.4, 0.55, 0.7];
/// Time each DC step is held, s (the rotor flux settles with tau_r, up to 0.25 s).
pub const DC_STEP_TIME: f32 = 1.2;
/// The last part of each DC step that is averaged, s.
pub const DC_MEASURE_TIME: f32 = 0.3;
/// DC bias of the impedance tests, fraction of the rated peak current: low enough that a
/// saturating machine stays on the linear part of its magnetizing curve (the rated-flux
/// L_M comes from the no-load test).
pub const AC_BIAS: f32 = 0.3;
/// AC amplitude of the impedance tests, fraction of the rated peak current.
pub const AC_AMPLITUDE: f32 = 0.15;
/// The injected voltage at the rated frequency, in rated current times the guessed
/// impedance (about 0.08-0.25 of the rated current flows: no phase current crosses zero on
/// the bias).
pub const AC_INJECTION: f32 = 0.08;
/// The low test frequency as a fraction of the rated frequency (near the rotor corner).
pub const LOW_FREQUENCY: f32 = 0.04;
/// The no-load test frequency as a fraction of the rated frequency (voltage headroom).
pub const NO_LOAD_FREQUENCY: f32 = 0.8;
/// V/f ramp time to the no-load frequency, s.
pub const NO_LOAD_RAMP_TIME: f32 = 5.0;
/// No-load hold before measuring, s, and the measuring time, s.
pub const NO_LOAD_SETTLE_TIME: f32 = 2.0;
/// See [`NO_LOAD_SETTLE_TIME`].
pub const NO_LOAD_MEASURE_TIME: f32 = 1.0;

/// The V/f stabiliser of the no-load test: the stator frequency yields to the swing of the
/// air-gap torque by this many times the machine's own slip per torque at the rated point,
/// p (Omega_sync - Omega_rated) / T_rated (so a torque swing moves the frequency by about
/// the slip it would make). Open-loop V/f at light load is known to hunt on machines of
/// small inertia (e.g. Ueda, Sonoda, Takata, "Experimental results and their simplified
/// analysis on instability problems in PWM inverter induction motor drives", IEEE Trans.
/// Ind. Appl. 25(1), 1989): TI's bare rotor (J = 0.001 kg m^2) swung +/-9 % at 2.5 Hz with
/// a growing amplitude, which took L_M 4 % low and left J unresolved. Measured on it: 0
/// (none) grows, 1 holds the speed within 0.05 %, 3 hunts again.
pub const VF_STABILISER_GAIN: f32 = 1.0;
/// The stabiliser acts on the air-gap torque minus its low-pass over this time, s: a
/// corner (2.5 rad/s) well below the hunting (16 rad/s), so the ramp's steady
/// acceleration torque and the hold's friction pass unchanged.
pub const VF_STABILISER_TIME: f32 = 0.4;

/// The stage the sequence is in.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stage {
    /// Switches off, measuring the current-sensor offsets.
    Offsets,
    /// DC step `k` (Rs and inverter error).
    DcStep(u8),
    /// Impedance at the low frequency.
    ImpedanceLow,
    /// Impedance at the rated frequency.
    ImpedanceHigh,
    /// V/f no-load test (the rotor turns).
    NoLoad,
    /// Finished: call [`Commissioning::identify`].
    Done,
    /// Stopped by an error (switches off).
    Failed(CommissioningError),
}

/// Why commissioning stopped.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CommissioningError {
    /// A current or bus sample was not finite.
    NonFiniteInput,
    /// A phase current beyond the trip.
    OverCurrent,
    /// The bus left its window.
    DcBus,
    /// The current did not follow its reference with the voltage at its limit: motor not
    /// connected or a phase open.
    MotorNotConnected,
    /// A current-sensor offset beyond 2 % of the trip.
    SensorOffset,
    /// A fit gave a value outside its plausible range (the field is named).
    ResultOutOfRange(&'static str),
    /// The DC steps do not lie on a straight line (residual above 5 %): the rotor moved
    /// or the inverter error depends on the current.
    PoorFit(&'static str),
}

/// The inverse-Gamma model and the inverter error the sequence found.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Identified {
    /// Stator resistance, ohm.
    pub stator_resistance: f32,
    /// Rotor resistance R_R (inverse-Gamma), ohm.
    pub rotor_resistance: f32,
    /// Leakage inductance L_sigma, H.
    pub leakage_inductance: f32,
    /// Magnetizing inductance at rated flux (no-load test), H.
    pub magnetizing_inductance: f32,
    /// Magnetizing inductance at standstill and small flux (impedance test), H.
    pub magnetizing_inductance_small_signal: f32,
    /// Rated flux current: the no-load current at rated volts per hertz, A peak.
    pub rated_flux_current: f32,
    /// Inverter voltage error per leg (dead time and device drop), V.
    pub inverter_error: f32,
    /// Dead time, s (from the error, with the board's device drop).
    pub dead_time: f32,
    /// Residual of the DC-step line fit, relative.
    pub dc_fit_residual: f32,
    /// Inertia, kg m^2 (the air-gap torque's impulse over the V/f ramp against the speed
    /// change, friction removed); `None` when that comes out non-positive (the error of
    /// the power balance, mostly the inverter-loss model, above the ramp's acceleration
    /// torque: a very light rotor).
    pub inertia: Option<f32>,
    /// Viscous friction, N m s/rad (the air-gap torque at the no-load hold over its speed).
    pub viscous_friction: f32,
}

/// Fourier sums of voltage and current at one frequency.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct Fourier {
    v: AlphaBeta,
    i: AlphaBeta,
}

/// The sequence's state.
#[derive(Clone, Debug)]
pub struct Commissioning {
    rated: RatedPoint,
    board: Board,
    ts: f32,
    trip: f32,
    pi: PiConfig,
    pwm: SvpwmConfig,
    sensing: CurrentSensing,
    stage: Stage,
    steps: u32,
    alpha: PiController,
    beta: PiController,
    offsets: [f32; 3],
    /// Per DC level: mean current and voltage; and the mean bus.
    dc: [(f32, f32); 4],
    bus_sum: f32,
    bus_n: u32,
    acc: (f32, f32),
    low: Fourier,
    high: Fourier,
    no_load: Fourier,
    rs_fit: f32,
    inverter_fit: f32,
    /// Ramp: integral of the air-gap torque over the band (N m s), the band's speed
    /// change (rad/s mechanical), the integral of the speed over it (rad); hold: the mean
    /// air-gap torque (N m) and speed (rad/s).
    ramp_impulse: f32,
    ramp_speed_change: f32,
    ramp_angle: f32,
    hold_torque: f32,
    hold_speed: f32,
    angle: f32,
    frequency: f32,
    last_v: AlphaBeta,
    /// The stabiliser: its gain (rad/s electrical per N m), low-pass factor Ts / time,
    /// low-passed air-gap torque (N m) and frequency offset (rad/s electrical).
    stab_gain: f32,
    stab_alpha: f32,
    stab_torque: f32,
    stab_offset: f32,
}

impl Commissioning {
    /// The sequence for a motor with `nameplate` on `board`.
    pub fn new(nameplate: &Nameplate, board: &Board) -> Result<Self, NameplateError> {
        let rated = nameplate.rated()?;
        let ts = 1.0 / board.pwm_frequency_hz;
        // current loops for an unknown machine: the leakage guessed at a tenth of the
        // no-load reactance of a machine whose magnetizing current is 40 % of rated; a
        // bandwidth of 0.05 / Ts leaves a factor of 3 either way of margin
        let l_guess = 0.1 * rated.phase_voltage / (rated.frequency * 0.4 * rated.current);
        let w_c = 0.05 / ts;
        let kp = l_guess * w_c;
        let pi = PiConfig::new(kp, 0.5 * kp * w_c, ts, linear_limit(board.dc_bus_v));
        // rated torque > 0 and synchronous speed > rated speed (`Nameplate::rated`)
        let stab_gain =
            VF_STABILISER_GAIN * rated.pole_pairs as f32 * (rated.synchronous_speed - rated.speed)
                / rated.torque;
        Ok(Self {
            rated,
            board: *board,
            ts,
            trip: crate::nameplate::TRIP_OVER_LIMIT * rated.current,
            pi,
            pwm: SvpwmConfig::new(0.0, ts, 0.0, 0.05),
            sensing: CurrentSensing::TwoPhase,
            stage: Stage::Offsets,
            steps: 0,
            alpha: PiController::new(),
            beta: PiController::new(),
            offsets: [0.0; 3],
            dc: [(0.0, 0.0); 4],
            bus_sum: 0.0,
            bus_n: 0,
            acc: (0.0, 0.0),
            low: Fourier::default(),
            high: Fourier::default(),
            no_load: Fourier::default(),
            rs_fit: 0.0,
            inverter_fit: 0.0,
            ramp_impulse: 0.0,
            ramp_speed_change: 0.0,
            ramp_angle: 0.0,
            hold_torque: 0.0,
            hold_speed: 0.0,
            angle: 0.0,
            frequency: 0.0,
            last_v: AlphaBeta::default(),
            stab_gain,
            stab_alpha: ts / VF_STABILISER_TIME,
            stab_torque: 0.0,
            stab_offset: 0.0,
        })
    }

    /// The no-load test's sums (diagnostics): ramp impulse (N m s), ramp speed change
    /// (rad/s), ramp angle (rad), hold torque (N m), hold speed (rad/s).
    pub fn mechanics_sums(&self) -> [f32; 5] {
        [
            self.ramp_impulse,
            self.ramp_speed_change,
            self.ramp_angle,
            self.hold_torque,
            self.hold_speed,
        ]
    }

    /// The stage the sequence is in.
    pub fn stage(&self) -> Stage {
        self.stage
    }

    /// Time spent so far in the present stage, s.
    pub fn stage_time(&self) -> f32 {
        self.steps as f32 * self.ts
    }

    fn fail(&mut self, e: CommissioningError) -> PwmOutput {
        self.stage = Stage::Failed(e);
        PwmOutput::OFF
    }

    fn next(&mut self, s: Stage) {
        self.stage = s;
        self.steps = 0;
        self.acc = (0.0, 0.0);
    }

    fn steps_of(&self, t: f32) -> u32 {
        (t / self.ts) as u32
    }

    /// One control period: samples in, PWM out (switches off once done or failed).
    pub fn step(&mut self, inp: &DriveInputs) -> PwmOutput {
        if matches!(self.stage, Stage::Done | Stage::Failed(_)) {
            return PwmOutput::OFF;
        }
        let [a, b, c] = inp.phase_currents;
        if !(is_finite(a) && is_finite(b) && is_finite(c) && is_finite(inp.dc_bus)) {
            return self.fail(CommissioningError::NonFiniteInput);
        }
        if a.abs() > self.trip || b.abs() > self.trip || (a + b).abs() > self.trip {
            return self.fail(CommissioningError::OverCurrent);
        }
        let bus = inp.dc_bus;
        if !(bus > 0.6 * self.board.dc_bus_v && bus < 1.25 * self.board.dc_bus_v) {
            return self.fail(CommissioningError::DcBus);
        }
        self.steps = self.steps.saturating_add(1);
        let [oa, ob, oc] = self.offsets;
        let i = match self.sensing {
            CurrentSensing::TwoPhase => clarke_two(a - oa, b - ob),
            CurrentSensing::ThreePhase => clarke_three(a - oa, b - ob, c - oc),
        };
        let i_r = self.rated.current;
        let v = match self.stage {
            Stage::Offsets => {
                let n = self.steps as f32;
                for (o, x) in self.offsets.iter_mut().zip([a, b, c]) {
                    *o += (x - *o) / n;
                }
                if self.steps >= self.steps_of(0.2) {
                    let limit = 0.02 * self.trip;
                    if self.offsets.iter().any(|o| o.abs() > limit) {
                        return self.fail(CommissioningError::SensorOffset);
                    }
                    self.next(Stage::DcStep(0));
                }
                return PwmOutput::OFF;
            }
            Stage::DcStep(k) => {
                // k < DC_LEVELS.len() by construction; `get` keeps a panic path out of the
                // interrupt (an impossible k ends the steps)
                let level = DC_LEVELS.get(k as usize).copied().unwrap_or(0.0);
                let i_ref = level * i_r;
                let v = self.regulate(i_ref, i, bus);
                // the current must follow: 50 ms after the step, at least half of it
                if self.steps == self.steps_of(0.05) && i.alpha < 0.5 * i_ref {
                    return self.fail(CommissioningError::MotorNotConnected);
                }
                let measure_from = self.steps_of(DC_STEP_TIME - DC_MEASURE_TIME);
                if self.steps > measure_from {
                    // the voltage applied over the past period: last step's command
                    self.acc.0 += i.alpha;
                    self.acc.1 += self.last_v.alpha;
                    self.bus_sum += bus;
                    self.bus_n += 1;
                }
                if self.steps >= self.steps_of(DC_STEP_TIME) {
                    let n = (self.steps - measure_from) as f32;
                    if let Some(d) = self.dc.get_mut(k as usize) {
                        *d = (self.acc.0 / n, self.acc.1 / n);
                    }
                    if (k as usize) + 1 < DC_LEVELS.len() {
                        self.next(Stage::DcStep(k + 1));
                    } else {
                        let (rs, c, _) = self.line_fit();
                        self.rs_fit = rs;
                        self.inverter_fit = 0.75 * c;
                        self.next(Stage::ImpedanceLow);
                        self.angle = 0.0;
                    }
                }
                v
            }
            Stage::ImpedanceLow => {
                let w = LOW_FREQUENCY * self.rated.frequency;
                let sc = FastSinCos.sin_cos(self.angle);
                let i_ref = (AC_BIAS + AC_AMPLITUDE * sc.cos) * i_r;
                let v = self.regulate(i_ref, i, bus);
                let period = core::f32::consts::TAU / w;
                // one period to settle, then four
                let settle = self.steps_of(period);
                if self.steps > settle {
                    accumulate(
                        &mut self.low,
                        self.last_v.alpha,
                        i.alpha,
                        self.angle,
                        w,
                        self.ts,
                    );
                }
                self.angle = wrap_angle_step(self.angle + w * self.ts);
                if self.steps >= settle + self.steps_of(4.0 * period) {
                    self.next(Stage::ImpedanceHigh);
                    self.angle = 0.0;
                }
                v
            }
            Stage::ImpedanceHigh => {
                let w = self.rated.frequency;
                let sc = FastSinCos.sin_cos(self.angle);
                let mut v = self.regulate(AC_BIAS * i_r, i, bus);
                // the loops hold the bias; the injected voltage rides over them
                let z_guess = 2.0 * self.rs_fit
                    + w * 0.1 * self.rated.phase_voltage / (w * 0.4 * self.rated.current);
                v.alpha += AC_INJECTION * i_r * z_guess * sc.cos;
                let period = core::f32::consts::TAU / w;
                let settle = self.steps_of(0.1);
                if self.steps > settle {
                    accumulate(
                        &mut self.high,
                        self.last_v.alpha,
                        i.alpha,
                        self.angle,
                        w,
                        self.ts,
                    );
                }
                self.angle = wrap_angle_step(self.angle + w * self.ts);
                if self.steps >= settle + self.steps_of(10.0 * period) {
                    self.next(Stage::NoLoad);
                    self.angle = 0.0;
                    self.frequency = 0.0;
                }
                v
            }
            Stage::NoLoad => {
                let w_end = NO_LOAD_FREQUENCY * self.rated.frequency;
                let ramp = self.steps_of(NO_LOAD_RAMP_TIME);
                self.frequency = if self.steps < ramp {
                    w_end * self.steps as f32 / ramp as f32
                } else {
                    w_end
                };
                // rated volts per hertz plus the drop of the no-load current in Rs
                let mag = self.rated.phase_voltage / self.rated.frequency * self.frequency
                    + self.rs_fit * 0.4 * i_r;
                let sc = FastSinCos.sin_cos(self.angle);
                let v = AlphaBeta {
                    alpha: mag * sc.cos,
                    beta: mag * sc.sin,
                };
                let settle = ramp + self.steps_of(NO_LOAD_SETTLE_TIME);
                // air-gap torque from the power balance in the voltage's frame (the rotor
                // follows the V/f ramp at a small slip): T = p (P_in - P_Cu - P_inv) / w,
                // P_in = 1.5 v i_d (amplitude-invariant), P_Cu = 1.5 Rs |i|^2, the
                // inverter's loss (6/pi) V_e |i| (each leg's error opposes its sinusoid)
                let (s_, c_) = (sc.sin, sc.cos);
                let i_d = i.alpha * c_ + i.beta * s_;
                let i_q = -i.alpha * s_ + i.beta * c_;
                let i_mag = sqrt(i_d * i_d + i_q * i_q);
                let p = self.rated.pole_pairs as f32;
                let w = self.frequency;
                if w > 0.0 {
                    // the voltage commanded at this angle acts 1.5 periods later, so in
                    // the current's frame it lags by phi = 1.5 w Ts:
                    // P_in = 1.5 Re(v e^(-j phi) conj(i)) = 1.5 v (i_d cos phi - i_q sin phi)
                    let phi = FastSinCos.sin_cos(1.5 * w * self.ts);
                    let p_in = 1.5 * mag * (i_d * phi.cos - i_q * phi.sin);
                    let p_gap = p_in
                        - 1.5 * self.rs_fit * i_mag * i_mag
                        - 6.0 / core::f32::consts::PI * self.inverter_fit * i_mag;
                    let torque = p * p_gap / w;
                    // V/f stabiliser (VF_STABILISER_GAIN): the frequency the voltage turns
                    // at yields to the torque's swing about its low-pass
                    self.stab_torque += (torque - self.stab_torque) * self.stab_alpha;
                    self.stab_offset = -self.stab_gain * (torque - self.stab_torque);
                    let in_band = w > 0.3 * w_end && w < 0.9 * w_end && self.steps < ramp;
                    if in_band {
                        self.ramp_impulse += torque * self.ts;
                        self.ramp_speed_change += w_end / ramp as f32 / p;
                        self.ramp_angle += w / p * self.ts;
                    }
                    if self.steps > settle {
                        self.hold_torque += torque;
                        self.hold_speed += w / p;
                    }
                }
                if self.steps > settle {
                    // in the voltage's frame: last step's voltage was (mag_prev, 0) at its
                    // own angle; the current rotated back by this step's angle
                    let (s, c) = (sc.sin, sc.cos);
                    let i_d = i.alpha * c + i.beta * s;
                    let i_q = -i.alpha * s + i.beta * c;
                    let f = &mut self.no_load;
                    f.i.alpha += i_d;
                    f.i.beta += i_q;
                    f.v.alpha += mag;
                }
                if self.steps >= settle + self.steps_of(NO_LOAD_MEASURE_TIME) {
                    let n = (self.steps - settle) as f32;
                    self.no_load.i.alpha /= n;
                    self.no_load.i.beta /= n;
                    self.no_load.v.alpha /= n;
                    self.hold_torque /= n;
                    self.hold_speed /= n;
                    self.next(Stage::Done);
                    return PwmOutput::OFF;
                }
                self.angle =
                    wrap_angle_step(self.angle + (self.frequency + self.stab_offset) * self.ts);
                v
            }
            Stage::Done | Stage::Failed(_) => return PwmOutput::OFF,
        };
        self.last_v = v;
        let m = modulate(&self.pwm, v, bus, inverse_clarke(i));
        PwmOutput {
            duties: m.duties,
            enabled: true,
        }
    }

    /// The alpha current to `i_ref`, beta to zero.
    fn regulate(&mut self, i_ref: f32, i: AlphaBeta, bus: f32) -> AlphaBeta {
        let lim = 0.95 * linear_limit(bus);
        AlphaBeta {
            alpha: self
                .alpha
                .update_with_limits(&self.pi, i_ref - i.alpha, 0.0, -lim, lim),
            beta: self
                .beta
                .update_with_limits(&self.pi, -i.beta, 0.0, -lim, lim),
        }
    }

    /// Least-squares line v = Rs i + c through the DC steps; (Rs, c, relative residual).
    fn line_fit(&self) -> (f32, f32, f32) {
        let n = self.dc.len() as f32;
        let (mut si, mut sv, mut sii, mut siv) = (0.0, 0.0, 0.0, 0.0);
        for &(i, v) in &self.dc {
            si += i;
            sv += v;
            sii += i * i;
            siv += i * v;
        }
        let den = n * sii - si * si;
        if !(den > 0.0) {
            return (0.0, 0.0, f32::INFINITY);
        }
        let rs = (n * siv - si * sv) / den;
        let c = (sv - rs * si) / n;
        let mut worst = 0.0f32;
        for &(i, v) in &self.dc {
            worst = worst.max((v - rs * i - c).abs() / (rs * i).abs().max(1e-6));
        }
        (rs, c, worst)
    }

    /// The identified model, once [`Stage::Done`] (outside the interrupt: a bisection).
    pub fn identify(&self) -> Result<Identified, CommissioningError> {
        if let Stage::Failed(e) = self.stage {
            return Err(e);
        }
        let (rs, c, residual) = self.line_fit();
        if !(residual < 0.05) {
            return Err(CommissioningError::PoorFit("stator_resistance"));
        }
        let r = &self.rated;
        let z_nom = r.phase_voltage / r.current;
        if !(rs > 1e-4 * z_nom && rs < z_nom) {
            return Err(CommissioningError::ResultOutOfRange("stator_resistance"));
        }
        let v_e = 0.75 * c;
        let bus = if self.bus_n > 0 {
            self.bus_sum / self.bus_n as f32
        } else {
            self.board.dc_bus_v
        };
        let dead_time = ((v_e - self.board.device_drop_v) / bus * self.ts).max(0.0);
        // impedances, the resistance removed
        let w_l = LOW_FREQUENCY * r.frequency;
        let w_h = r.frequency;
        let zl = impedance(&self.low, rs);
        let zh = impedance(&self.high, rs);
        let (Some(zl), Some(zh)) = (zl, zh) else {
            return Err(CommissioningError::ResultOutOfRange("impedance"));
        };
        // Re Y(w) = Re 1/(Z' - j w L_sigma): equal at both frequencies for the true L_sigma
        let re_y = |z: (f32, f32), w: f32, ls: f32| {
            let (x, y) = (z.0, z.1 - w * ls);
            x / (x * x + y * y)
        };
        let f = |ls: f32| re_y(zl, w_l, ls) - re_y(zh, w_h, ls);
        let (mut lo, mut hi) = (0.0f32, zh.1 / w_h);
        if !(hi > 0.0) || f(lo) * f(hi * 0.999) > 0.0 {
            return Err(CommissioningError::ResultOutOfRange("leakage_inductance"));
        }
        for _ in 0..60 {
            let mid = 0.5 * (lo + hi);
            if f(lo) * f(mid) <= 0.0 {
                hi = mid;
            } else {
                lo = mid;
            }
        }
        let l_sigma = 0.5 * (lo + hi);
        let y = |z: (f32, f32), w: f32| {
            let (x, yy) = (z.0, z.1 - w * l_sigma);
            let d = x * x + yy * yy;
            (x / d, -yy / d)
        };
        let (gl, bl) = y(zl, w_l);
        let (gh, bh) = y(zh, w_h);
        let r_r = 2.0 / (gl + gh);
        // Im Y = -1/(w L_M): the low frequency resolves L_M (at the high one it is small)
        let l_m_ss = 1.0 / (w_l * -bl);
        let _ = bh;
        if !(r_r > 0.0 && r_r < z_nom && l_m_ss > l_sigma && l_m_ss < 100.0 * z_nom / w_h) {
            return Err(CommissioningError::ResultOutOfRange("rotor_resistance"));
        }
        // no-load: Z = V / I in the frame of the current's samples, where the voltage
        // commanded at the same angle acts 1.5 periods later: V e^(-j 1.5 w Ts)
        let nl = &self.no_load;
        let w_n = NO_LOAD_FREQUENCY * r.frequency;
        let lead = w_n * 1.5 * self.ts;
        let lead = FastSinCos.sin_cos(lead);
        let (vd, vq) = (nl.v.alpha * lead.cos, -nl.v.alpha * lead.sin);
        let (id, iq) = (nl.i.alpha, nl.i.beta);
        let i2 = id * id + iq * iq;
        if !(i2 > 0.0) {
            return Err(CommissioningError::ResultOutOfRange("rated_flux_current"));
        }
        // Z = V conj(I) / |I|^2: the reactance
        let x = (vq * id - vd * iq) / i2;
        let l_m = x / w_n - l_sigma;
        let i_flux = sqrt(i2);
        if !(l_m > 0.0 && i_flux < r.current) {
            return Err(CommissioningError::ResultOutOfRange(
                "magnetizing_inductance",
            ));
        }
        let b = if self.hold_speed > 0.0 {
            (self.hold_torque / self.hold_speed).max(0.0)
        } else {
            0.0
        };
        let j = if self.ramp_speed_change > 0.0 {
            let j = (self.ramp_impulse - b * self.ramp_angle) / self.ramp_speed_change;
            (j > 0.0).then_some(j)
        } else {
            None
        };
        Ok(Identified {
            inertia: j,
            viscous_friction: b,
            stator_resistance: rs,
            rotor_resistance: r_r,
            leakage_inductance: l_sigma,
            magnetizing_inductance: l_m,
            magnetizing_inductance_small_signal: l_m_ss,
            rated_flux_current: i_flux,
            inverter_error: v_e,
            dead_time,
            dc_fit_residual: residual,
        })
    }
}

/// Adds a sample pair to the Fourier sums at `w`: the current sampled now, at `angle`, and
/// the last step's command, which acts over the period that starts now (preloaded
/// compare registers), centred half a period later: at `angle + w Ts / 2`.
fn accumulate(f: &mut Fourier, v_prev: f32, i: f32, angle: f32, w: f32, ts: f32) {
    let now = FastSinCos.sin_cos(angle);
    let (si, ci) = (now.sin, now.cos);
    let then = FastSinCos.sin_cos(wrap_angle(angle + 0.5 * w * ts));
    let (sv, cv) = (then.sin, then.cos);
    f.i.alpha += i * ci;
    f.i.beta -= i * si;
    f.v.alpha += v_prev * cv;
    f.v.beta -= v_prev * sv;
}

/// Z - Rs from Fourier sums (real, imaginary), `None` without current.
fn impedance(f: &Fourier, rs: f32) -> Option<(f32, f32)> {
    let (vr, vi, ir, ii) = (f.v.alpha, f.v.beta, f.i.alpha, f.i.beta);
    let d = ir * ir + ii * ii;
    if !(d > 0.0) {
        return None;
    }
    Some(((vr * ir + vi * ii) / d - rs, (vi * ir - vr * ii) / d))
}

/// Inertia J (kg m^2) and viscous friction B (N m s/rad) from two accelerations at the
/// same mean speed `speed` (rad/s) with the torque `torque` (N m) and `-torque`:
/// J (a_up - a_down) = 2 T, J (a_up + a_down) = -2 B speed. `None` when the
/// accelerations do not bracket.
pub fn mechanics_from_slopes(
    torque: f32,
    a_up: f32,
    a_down: f32,
    speed: f32,
) -> Option<(f32, f32)> {
    let d = a_up - a_down;
    if !(d > 0.0 && torque > 0.0) {
        return None;
    }
    let j = 2.0 * torque / d;
    let b = if speed.abs() > 0.0 {
        -(j * (a_up + a_down)) / (2.0 * speed)
    } else {
        0.0
    };
    Some((j, b.max(0.0)))
}
