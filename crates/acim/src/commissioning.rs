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
//!    rated volts per hertz, hold, Fourier sums in the voltage's frame, then a ramp down
//!    at the same rate to 24 %: at no load the slip is nearly zero and Z = Rs + j w
//!    (L_sigma + L_M): L_M at rated flux (saturation found, not assumed), and with it the
//!    rated flux current, the no-load current at rated voltage and frequency
//!    `V / |Rs + j w_r (L_sigma + L_M)|` (the test's own current is not it: its voltage,
//!    V/f plus an in-phase Rs boost, over-fluxes a high-Rs machine).
//!
//! 5. **Inertia and friction**, from the same test: over the V/f ramps the rotor follows
//!    the frequency less its slip (`R_R T / (1.5 p^2 psi_R^2)` with the identified model
//!    and the test's flux), and the air-gap torque from the power balance
//!    (`p (1.5 v i_d - 1.5 Rs |i|^2 - inverter loss) / w`) accelerates it: J is the
//!    difference of its impulses up and down over the same speed band, friction removed,
//!    over the difference of the speed changes, B the hold's torque over its speed. Up
//!    and down share the copper and inverter losses at each speed (the current's
//!    magnitude is the same), so an error in Rs or the inverter error, which on a small
//!    high-Rs machine dwarfs the inertial torque (the 0.18 kW machine's no-load copper
//!    loss is half its rated output), cancels from J; with the acceleration alone that
//!    machine's J was within +-84 %, now +-3 %.
//!
//! 6. **Confidence and plausibility** ([`Commissioning::assess`]): each quantity comes
//!    with a bound on its relative error, and the whole result is checked against the
//!    nameplate; a result that fails is refused ([`CommissioningError::Implausible`]),
//!    with what to check ([`Concern`]). See "How sure" below.
//!
//! The fits run in [`Commissioning::identify`], outside the interrupt, once the step
//! reports [`Stage::Done`]. [`mechanics_from_slopes`] gives J and B from two
//! accelerations at a known torque instead (a test under speed control).
//!
//! ## How sure: the confidence of each quantity
//!
//! Every window is summed in two halves (each DC step's measuring time, the periods of
//! each impedance test, the no-load hold) and the V/f ramp's band in a lower and an upper
//! speed half. The fits are repeated (a) on each half, (b) with each input they take from
//! an earlier fit moved by that input's own bound (Rs into the impedances, the no-load
//! test and the power balance; L_sigma into the no-load test; the inverter error, with
//! its loss model's [`INVERTER_LOSS_MODEL_UNCERTAINTY`], into the no-load test and the
//! power balance), and (c) with the voltage's timing model (it acts 1.5 periods after
//! it is computed) off by half a period either way. A quantity's bound
//! ([`Confidence`]) is the sum of the half-window spread (1.5 times the difference of
//! the two halves: three standard deviations of their mean) and of the largest change
//! each moved input makes; Rs and the inverter error add three standard errors of the
//! least-squares line through the DC steps. A bound is a worst-case sum, not a standard
//! deviation: the acceptance machines' true errors lie inside it (tests/commissioning.rs).
//!
//! ## Plausibility against the nameplate ([`Concern`])
//!
//! - **A coupled load**: the air-gap torque the no-load hold needs at constant speed is
//!   friction and windage only: at most about 3 % of the rated torque for a 4-pole motor
//!   of 0.5-50 kW (friction and windage losses of 0.5-3 % of the rated output at rated
//!   speed, e.g. the loss segregation of the no-load test in IEC 60034-2-1, and less at
//!   80 % speed). Above [`COUPLED_LOAD_TORQUE`] (10 %) a load is coupled. A load that
//!   is not the same on the ramps up and down (it changed between them, or it is not a
//!   rigid rotor) splits the inertias of the two speed halves apart
//!   ([`INERTIA_SPREAD_MAX`]); a load that depends on the speed alone cancels from J up
//!   and down, and the hold's torque shows it.
//! - **Inertia against the rating**: catalogue rotors of 4-pole IEC motors grow roughly as
//!   the 1.3th power of the rated power ([`catalogue_inertia`]); the frame follows the
//!   torque, so a machine of other pole count is compared at the power a 4-pole 50 Hz
//!   machine of its torque has. More than [`INERTIA_RANGE`] (a factor of ten) either way
//!   of that line: a load or flywheel is coupled, or the nameplate is wrong.
//! - **The no-load (magnetizing) current against the rated current**: typically 25-60 %
//!   of rated, more for small machines; outside [`FLUX_CURRENT_RANGE`] (15-85 %) the
//!   nameplate current or voltage is wrong (e.g. star typed for delta), or the test did
//!   not reach rated flux. With a printed power factor it must also stay below
//!   [`FLUX_OVER_REACTIVE_MAX`] times the rated reactive current I sin(phi), which
//!   carries it. This is the same check as L_M in per unit: at rated volts per hertz
//!   i_m = V / (w L_M).
//! - **Each confidence against its acceptance limit** ([`MAX_UNCERTAINTY`]): a fit that
//!   cannot tell its own result within it is refused.

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
/// V/f ramp time to the no-load frequency, s (the ramp down after the hold runs at the
/// same rate).
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

/// Largest air-gap torque the no-load hold may need, fraction of the rated torque (module
/// docs: friction and windage take at most about 3 %): above it a load is coupled.
pub const COUPLED_LOAD_TORQUE: f32 = 0.10;
/// Largest difference of the inertias of the ramps' lower and upper speed halves (each
/// from the ramp up and down), relative to J: both see the same rotor; a load that is not
/// the same on both ramps splits them.
pub const INERTIA_SPREAD_MAX: f32 = 0.25;
/// Plausible inertia, times the catalogue line [`catalogue_inertia`] (low, high).
pub const INERTIA_RANGE: (f32, f32) = (0.1, 10.0);
/// Plausible rated flux (no-load) current, fraction of the rated current (low, high).
pub const FLUX_CURRENT_RANGE: (f32, f32) = (0.15, 0.85);
/// Largest rated flux current over the rated reactive current I sin(phi) (a printed
/// power factor only).
pub const FLUX_OVER_REACTIVE_MAX: f32 = 1.2;
/// Relative uncertainty of the inverter's loss model, (6/pi) V_e |i| (the fundamental of
/// a square-wave error of V_e per leg): it ignores the current ripple about each zero
/// crossing, where a leg's error is below V_e. The power balance (J, B) and the no-load
/// fit (its R_inv) are redone with V_e moved by this fraction on top of its own bound.
pub const INVERTER_LOSS_MODEL_UNCERTAINTY: f32 = 0.05;
/// Relative uncertainty of J's model, added to its bound: the power balance leaves out
/// the magnetic energy the machine stores and gives back along the ramps (the V/f boost
/// moves the flux with the frequency), which the difference of the ramps up and down
/// keeps; measured up to 0.7 % (the paper's machine with an ideal inverter and no
/// friction).
pub const INERTIA_MODEL_UNCERTAINTY: f32 = 0.01;
/// Resolution of the current converters assumed by the no-load fit's bound, bits (the
/// G474's 12-bit ADC): one step of the full scale over the no-load current is added to
/// the bounds of L_M and the flux current (an offset left after the offset measurement).
pub const CURRENT_ADC_BITS: u32 = 12;
/// Largest accepted relative uncertainty bound: Rs, R_R, L_sigma, L_M, J (a light rotor's
/// J rests on a small acceleration torque: half of it).
pub const MAX_UNCERTAINTY: [f32; 5] = [0.05, 0.2, 0.25, 0.1, 0.5];
/// The catalogue line of [`catalogue_inertia`]: inertia at 1 kW, kg m^2, and exponent.
pub const CATALOGUE_INERTIA_1KW: f32 = 0.0035;
/// See [`CATALOGUE_INERTIA_1KW`].
pub const CATALOGUE_INERTIA_EXPONENT: f32 = 1.3;

/// The rotor inertia of a catalogue 4-pole IEC induction motor of the rated torque
/// `torque` (N m), kg m^2: J = 0.0035 kg m^2 (P / 1 kW)^1.3 with P = torque x 157.08 rad/s
/// (the power a 4-pole 50 Hz motor of that torque is rated for: frame size follows the
/// torque). The line is an approximate reading of the rotor inertias that 4-pole IE3
/// catalogue ranges list (roughly 0.0025 kg m^2 at 0.75 kW, 0.01 at 2.2 kW, 0.06 at
/// 11 kW, 0.35 at 37 kW, 1.5 at 110 kW), not yet checked against a catalogue table: the
/// plausible range [`INERTIA_RANGE`] is a factor of ten either way, so an error of the
/// line by two refuses no real machine (the acceptance set spans 0.25x to 5x the line).
pub fn catalogue_inertia(torque: f32) -> f32 {
    let p_kw = torque * (0.5 * 2.0 * core::f32::consts::PI * 50.0) / 1000.0;
    if !(p_kw > 0.0) {
        return 0.0;
    }
    CATALOGUE_INERTIA_1KW * exp(CATALOGUE_INERTIA_EXPONENT * ln(p_kw))
}

/// Natural logarithm of `x` > 0 (0 otherwise): exponent and an atanh series of the
/// mantissa, relative error below 1e-6 (outside the control step).
fn ln(x: f32) -> f32 {
    if !(x > 0.0) || !is_finite(x) {
        return 0.0;
    }
    let bits = x.to_bits();
    let e = ((bits >> 23) & 0xff) as i32 - 127;
    let m = f32::from_bits((bits & 0x007f_ffff) | 0x3f80_0000);
    let t = (m - 1.0) / (m + 1.0);
    let t2 = t * t;
    let series = t * (1.0 + t2 * (1.0 / 3.0 + t2 * (0.2 + t2 * (1.0 / 7.0 + t2 / 9.0))));
    e as f32 * core::f32::consts::LN_2 + 2.0 * series
}

/// e^y for |y| < 80 (saturates outside), relative error below 1e-6.
fn exp(y: f32) -> f32 {
    let y = y.clamp(-80.0, 80.0);
    let k = (y / core::f32::consts::LN_2 + if y >= 0.0 { 0.5 } else { -0.5 }) as i32;
    let r = y - k as f32 * core::f32::consts::LN_2;
    let mut term = 1.0f32;
    let mut sum = 1.0f32;
    for n in 1..10 {
        term *= r / n as f32;
        sum += term;
    }
    sum * f32::from_bits(((k + 127) as u32) << 23)
}

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
    /// The result is out of line with the nameplate, the test saw a coupled load, or a fit
    /// cannot tell its own result well enough: refused ([`Concern`] says what to check).
    Implausible(Concern),
}

/// Why a result is refused: what was seen and what to check (module docs, "Plausibility").
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Concern {
    /// The no-load hold needed more than [`COUPLED_LOAD_TORQUE`] of the rated torque.
    CoupledLoad,
    /// The ramp's two speed halves give inertias more than [`INERTIA_SPREAD_MAX`] apart.
    InertiaInconsistent,
    /// J above [`INERTIA_RANGE`] times the catalogue line for the rating.
    InertiaHigh,
    /// J below [`INERTIA_RANGE`] times the catalogue line for the rating.
    InertiaLow,
    /// The rated flux current above [`FLUX_CURRENT_RANGE`] of the rated current, or
    /// above [`FLUX_OVER_REACTIVE_MAX`] times the rated reactive current.
    FluxCurrentHigh,
    /// The rated flux current below [`FLUX_CURRENT_RANGE`] of the rated current.
    FluxCurrentLow,
    /// A quantity's uncertainty bound above [`MAX_UNCERTAINTY`] (the quantity named).
    Uncertain(&'static str),
}

impl Concern {
    /// What was seen, for a user (one short clause, no numbers).
    pub fn reason(self) -> &'static str {
        match self {
            Concern::CoupledLoad => "a load seems coupled (no-load torque over 10 % of rated)",
            Concern::InertiaInconsistent => {
                "a load seems coupled (J differs at low and high speed)"
            }
            Concern::InertiaHigh => "J is over 10 times a motor of this rating's",
            Concern::InertiaLow => "J is under a tenth of a motor of this rating's",
            Concern::FluxCurrentHigh => "the no-load current is over 85 % of rated",
            Concern::FluxCurrentLow => "the no-load current is under 15 % of rated",
            Concern::Uncertain(_) => "a fit is too uncertain to use",
        }
    }

    /// What to check before running again.
    pub fn advice(self) -> &'static str {
        match self {
            Concern::CoupledLoad => "uncouple the load and run again (or check the power)",
            Concern::InertiaInconsistent => "uncouple the load and run again",
            Concern::InertiaHigh => "uncouple the load; check the nameplate power",
            Concern::InertiaLow => "check the nameplate power and speed",
            Concern::FluxCurrentHigh | Concern::FluxCurrentLow => {
                "check the nameplate voltage and current (star or delta?)"
            }
            Concern::Uncertain(_) => "keep the rotor free and the supply steady, run again",
        }
    }

    /// The quantity the check is about.
    pub fn field(self) -> &'static str {
        match self {
            Concern::CoupledLoad => "viscous_friction",
            Concern::InertiaInconsistent | Concern::InertiaHigh | Concern::InertiaLow => "inertia",
            Concern::FluxCurrentHigh | Concern::FluxCurrentLow => "rated_flux_current",
            Concern::Uncertain(f) => f,
        }
    }
}

/// One plausibility check: the measured figure and its accepted range (the same unit:
/// a ratio, see [`Concern`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Check {
    /// What a failure means.
    pub concern: Concern,
    /// The measured figure.
    pub value: f32,
    /// Accepted range, inclusive (low, high).
    pub range: (f32, f32),
}

impl Check {
    /// Inside its range.
    pub fn passed(&self) -> bool {
        self.value >= self.range.0 && self.value <= self.range.1
    }
}

/// Bounds on the relative error of each identified quantity (fractions: 0.01 is 1 %);
/// module docs, "How sure". Infinite where the quantity was not resolved.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Confidence {
    /// Rs.
    pub stator_resistance: f32,
    /// R_R.
    pub rotor_resistance: f32,
    /// L_sigma.
    pub leakage_inductance: f32,
    /// L_M at rated flux.
    pub magnetizing_inductance: f32,
    /// The rated flux current.
    pub rated_flux_current: f32,
    /// The inverter voltage error.
    pub inverter_error: f32,
    /// The dead time (its error alone; the board's assumed device drop is not known to it).
    pub dead_time: f32,
    /// J.
    pub inertia: f32,
    /// B.
    pub viscous_friction: f32,
}

/// Number of plausibility checks in [`Assessment::checks`].
pub const CHECK_COUNT: usize = 12;

/// The identified model, how sure each quantity is, and the checks against the nameplate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Assessment {
    /// The model.
    pub identified: Identified,
    /// Relative error bounds.
    pub confidence: Confidence,
    /// Every check, in order: coupled load (hold torque / rated torque), inertia spread
    /// (|J_low - J_high| / J), inertia / catalogue line (high, then low), flux current /
    /// rated current (high, then low), flux current / rated reactive current (an open
    /// range without a printed power factor), and the uncertainty bounds of Rs, R_R,
    /// L_sigma, L_M and J. The inertia checks are open (always passed) when J is not
    /// resolved.
    pub checks: [Check; CHECK_COUNT],
    /// J of the ramps' lower and upper speed halves (each up and down), kg m^2 (0 when
    /// unresolved): the spread check's.
    pub inertia_halves: (f32, f32),
    /// The air-gap torque the no-load hold needed, N m.
    pub hold_torque: f32,
}

impl Assessment {
    /// The first failed check, if any (the order of [`Assessment::checks`]).
    pub fn refusal(&self) -> Option<Check> {
        self.checks.iter().copied().find(|c| !c.passed())
    }
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
    /// Rated flux current: the no-load current at rated voltage and frequency, A peak,
    /// `V_ph / |Rs + j w_r (L_sigma + L_M)|` with the identified model and L_M at the
    /// no-load test's flux (the nameplate's definition, [`crate::nameplate`]).
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

impl Fourier {
    fn plus(&self, o: &Fourier) -> Fourier {
        Fourier {
            v: AlphaBeta {
                alpha: self.v.alpha + o.v.alpha,
                beta: self.v.beta + o.v.beta,
            },
            i: AlphaBeta {
                alpha: self.i.alpha + o.i.alpha,
                beta: self.i.beta + o.i.beta,
            },
        }
    }
}

/// The air-gap torque of the power balance in parts, so that the fits can redo it with
/// another Rs or inverter error: T = input - Rs copper - V_e inverter (module docs, 5).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct TorqueParts {
    /// p 1.5 v i_d / w, N m.
    input: f32,
    /// p 1.5 |i|^2 / w, N m per ohm.
    copper: f32,
    /// p (6 / pi) |i| / w, N m per volt.
    inverter: f32,
}

impl TorqueParts {
    fn torque(&self, rs: f32, v_e: f32) -> f32 {
        self.input - rs * self.copper - v_e * self.inverter
    }
    fn add(&mut self, o: &TorqueParts, k: f32) {
        self.input += k * o.input;
        self.copper += k * o.copper;
        self.inverter += k * o.inverter;
    }
}

#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct RampSums {
    impulse: TorqueParts,
    /// The voltage's frequency's change over the half, rad/s mechanical.
    speed_change: f32,
    /// The voltage's frequency's integral, rad mechanical.
    angle: f32,
    /// The air-gap torque's change over the half (with the sequence's Rs and inverter
    /// error), N m: the slip's change, which the rotor's speed change lacks.
    torque_change: f32,
}

#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct HoldSums {
    torque: TorqueParts,
    speed: f32,
    n: u32,
}

/// The fixed part: what the nameplate and the board give (set by
/// [`Commissioning::new`]).
#[derive(Clone, Debug)]
struct Setup {
    /// The nameplate's rated point.
    rated: RatedPoint,
    /// The nameplate's power factor, if printed.
    power_factor: Option<f32>,
    /// The board.
    board: Board,
    /// The control period, s.
    ts: f32,
    /// The over-current trip level, A peak.
    trip: f32,
    /// The modulator.
    pwm: SvpwmConfig,
    /// The current channels measured.
    sensing: CurrentSensing,
}

/// The current loops of the standstill tests (alpha and beta, stationary frame).
#[derive(Clone, Debug)]
struct CurrentLoops {
    /// Their gains, for an unknown machine.
    pi: PiConfig,
    /// The alpha current's loop.
    alpha: PiController,
    /// The beta current's loop.
    beta: PiController,
}

/// The DC steps (Rs and the inverter error): their sums and the line's fit.
#[derive(Clone, Debug)]
struct DcSteps {
    /// Per DC level and half of its measuring time: mean current and voltage.
    levels: [[(f32, f32); 2]; 4],
    /// The bus voltage summed over the measuring times, V (the mean bus, with `bus_n`).
    bus_sum: f32,
    /// The bus samples in `bus_sum`.
    bus_n: u32,
    /// The present DC step's sums per half (current, A; voltage, V).
    acc: [(f32, f32); 2],
    /// Their sample counts.
    acc_n: [u32; 2],
    /// The line's Rs, ohm (after the last DC step).
    rs_fit: f32,
    /// The inverter error V_e from the line's intercept, V (after the last DC step).
    inverter_fit: f32,
}

/// Impedance tests' Fourier sums, per half of the window.
#[derive(Clone, Debug)]
struct ImpedanceSums {
    /// At the low frequency.
    low: [Fourier; 2],
    /// At the rated frequency.
    high: [Fourier; 2],
}

/// The V/f stabiliser of the no-load test ([`VF_STABILISER_GAIN`]).
#[derive(Clone, Debug)]
struct Stabiliser {
    /// Its gain, rad/s electrical per N m.
    gain: f32,
    /// Its low-pass factor, Ts / [`VF_STABILISER_TIME`].
    alpha: f32,
    /// The low-passed air-gap torque, N m.
    torque: f32,
    /// The frequency offset, rad/s electrical.
    offset: f32,
}

/// The no-load test (V/f ramp and hold): its sums, its frequency and its stabiliser.
#[derive(Clone, Debug)]
struct NoLoadTest {
    /// No-load hold: per half, the mean voltage (alpha: its magnitude) and current in the
    /// voltage's frame.
    sums: [Fourier; 2],
    /// Ramp, per speed half (below and above 60 % of the end frequency): the air-gap
    /// torque's impulse in parts (N m s), the half's speed change (rad/s mechanical), the
    /// integral of the speed over it (rad).
    ramp: [RampSums; 2],
    /// The same over the ramp down after the hold (its speed changes negative).
    ramp_down: [RampSums; 2],
    /// Hold, per half: the mean air-gap torque in parts (N m) and the mean speed (rad/s).
    hold: [HoldSums; 2],
    /// The last step's air-gap torque estimate, N m (the no-load test; 0 before it).
    torque: f32,
    /// The V/f stator frequency (without the stabiliser's offset), rad/s electrical.
    frequency: f32,
    /// The stabiliser.
    stab: Stabiliser,
    /// The last step's voltage frequency with the stabiliser's offset, rad/s electrical,
    /// and air-gap torque, N m: the ramp's sums take their changes.
    last: (f32, f32),
}

/// The sequence's state.
#[derive(Clone, Debug)]
pub struct Commissioning {
    /// The fixed part.
    setup: Setup,
    /// The current loops.
    loops: CurrentLoops,
    /// The stage the sequence is in.
    stage: Stage,
    /// Steps spent in the present stage.
    steps: u32,
    /// The current channels' offsets, A (the first stage's means).
    offsets: [f32; 3],
    /// The DC steps.
    dc: DcSteps,
    /// The impedance tests.
    impedance: ImpedanceSums,
    /// The no-load test.
    no_load: NoLoadTest,
    /// The test sinusoid's (or the V/f voltage's) angle, rad.
    angle: f32,
    /// The voltage commanded by the last step (alpha, beta), V.
    last_v: AlphaBeta,
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
            setup: Setup {
                rated,
                power_factor: nameplate.power_factor,
                board: *board,
                ts,
                trip: crate::nameplate::TRIP_OVER_LIMIT * rated.current,
                pwm: SvpwmConfig::new(0.0, ts, 0.0, 0.05),
                sensing: CurrentSensing::TwoPhase,
            },
            loops: CurrentLoops {
                pi,
                alpha: PiController::new(),
                beta: PiController::new(),
            },
            stage: Stage::Offsets,
            steps: 0,
            offsets: [0.0; 3],
            dc: DcSteps {
                levels: [[(0.0, 0.0); 2]; 4],
                bus_sum: 0.0,
                bus_n: 0,
                acc: [(0.0, 0.0); 2],
                acc_n: [0; 2],
                rs_fit: 0.0,
                inverter_fit: 0.0,
            },
            impedance: ImpedanceSums {
                low: [Fourier::default(); 2],
                high: [Fourier::default(); 2],
            },
            no_load: NoLoadTest {
                sums: [Fourier::default(); 2],
                ramp: [RampSums::default(); 2],
                ramp_down: [RampSums::default(); 2],
                hold: [HoldSums::default(); 2],
                torque: 0.0,
                frequency: 0.0,
                stab: Stabiliser {
                    gain: stab_gain,
                    alpha: ts / VF_STABILISER_TIME,
                    torque: 0.0,
                    offset: 0.0,
                },
                last: (0.0, 0.0),
            },
            angle: 0.0,
            last_v: AlphaBeta::default(),
        })
    }

    /// The no-load test's sums (diagnostics), with the Rs and inverter error of the DC
    /// steps: ramp impulse (N m s), ramp speed change (rad/s), ramp angle (rad), hold
    /// torque (N m), hold speed (rad/s).
    pub fn mechanics_sums(&self) -> [f32; 5] {
        let (rs, ve) = (self.dc.rs_fit, self.dc.inverter_fit);
        let [a, b] = &self.no_load.ramp;
        let [h0, h1] = &self.no_load.hold;
        [
            a.impulse.torque(rs, ve) + b.impulse.torque(rs, ve),
            a.speed_change + b.speed_change,
            a.angle + b.angle,
            0.5 * (h0.torque.torque(rs, ve) + h1.torque.torque(rs, ve)),
            0.5 * (h0.speed + h1.speed),
        ]
    }

    /// The voltage commanded by the last step (alpha, beta), V: it acts over the next
    /// period. Zero with the switches off.
    pub fn voltage(&self) -> AlphaBeta {
        if matches!(self.stage, Stage::Offsets | Stage::Done | Stage::Failed(_)) {
            AlphaBeta::default()
        } else {
            self.last_v
        }
    }

    /// The no-load test's air-gap torque estimate of the last step (power balance with the
    /// DC steps' Rs and inverter error), N m; 0 outside the test.
    pub fn air_gap_torque(&self) -> f32 {
        self.no_load.torque
    }

    /// The V/f test's stator frequency (without the stabiliser's offset), rad/s electrical.
    pub fn frequency(&self) -> f32 {
        self.no_load.frequency
    }

    /// The DC steps (after [`Stage::DcStep`] 3): mean alpha current (A) and voltage (V)
    /// per level, for a plot of the line fit.
    pub fn dc_points(&self) -> [(f32, f32); 4] {
        // the step calls this from the interrupt: a plain array map (a zipped iterator's
        // generic `next` would be instantiated out of line, in flash)
        self.dc
            .levels
            .map(|d| (0.5 * (d[0].0 + d[1].0), 0.5 * (d[0].1 + d[1].1)))
    }

    /// The line through the DC steps: Rs (ohm) and the intercept (V): v = Rs i + c.
    pub fn dc_line(&self) -> (f32, f32) {
        let (rs, c, _) = line_fit(&self.dc_points());
        (rs, c)
    }

    /// The stage the sequence is in.
    pub fn stage(&self) -> Stage {
        self.stage
    }

    /// Time spent so far in the present stage, s.
    pub fn stage_time(&self) -> f32 {
        self.steps as f32 * self.setup.ts
    }

    fn fail(&mut self, e: CommissioningError) -> PwmOutput {
        self.stage = Stage::Failed(e);
        PwmOutput::OFF
    }

    fn next(&mut self, s: Stage) {
        self.stage = s;
        self.steps = 0;
        self.dc.acc = [(0.0, 0.0); 2];
        self.dc.acc_n = [0; 2];
    }

    fn steps_of(&self, t: f32) -> u32 {
        (t / self.setup.ts) as u32
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
        if a.abs() > self.setup.trip || b.abs() > self.setup.trip || (a + b).abs() > self.setup.trip
        {
            return self.fail(CommissioningError::OverCurrent);
        }
        let bus = inp.dc_bus;
        if !(bus > 0.6 * self.setup.board.dc_bus_v && bus < 1.25 * self.setup.board.dc_bus_v) {
            return self.fail(CommissioningError::DcBus);
        }
        self.steps = self.steps.saturating_add(1);
        let [oa, ob, oc] = self.offsets;
        let i = match self.setup.sensing {
            CurrentSensing::TwoPhase => clarke_two(a - oa, b - ob),
            CurrentSensing::ThreePhase => clarke_three(a - oa, b - ob, c - oc),
        };
        let i_r = self.setup.rated.current;
        let v = match self.stage {
            Stage::Offsets => {
                let n = self.steps as f32;
                for (o, x) in self.offsets.iter_mut().zip([a, b, c]) {
                    *o += (x - *o) / n;
                }
                if self.steps >= self.steps_of(0.2) {
                    let limit = 0.02 * self.setup.trip;
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
                    // the voltage applied over the past period: last step's command; in
                    // two halves of the measuring time
                    let h = usize::from(
                        self.steps > measure_from + self.steps_of(0.5 * DC_MEASURE_TIME),
                    );
                    if let (Some(a), Some(n)) = (self.dc.acc.get_mut(h), self.dc.acc_n.get_mut(h)) {
                        a.0 += i.alpha;
                        a.1 += self.last_v.alpha;
                        *n += 1;
                    }
                    self.dc.bus_sum += bus;
                    self.dc.bus_n += 1;
                }
                if self.steps >= self.steps_of(DC_STEP_TIME) {
                    if let Some(d) = self.dc.levels.get_mut(k as usize) {
                        // indexed: the interrupt runs this, and a zipped iterator's generic
                        // `next` would be instantiated out of line, in flash
                        let (acc, acc_n) = (self.dc.acc, self.dc.acc_n);
                        let mean = |h: usize| {
                            let n = acc_n[h].max(1) as f32;
                            (acc[h].0 / n, acc[h].1 / n)
                        };
                        *d = [mean(0), mean(1)];
                    }
                    if (k as usize) + 1 < DC_LEVELS.len() {
                        self.next(Stage::DcStep(k + 1));
                    } else {
                        let (rs, c, _) = line_fit(&self.dc_points());
                        self.dc.rs_fit = rs;
                        self.dc.inverter_fit = 0.75 * c;
                        self.next(Stage::ImpedanceLow);
                        self.angle = 0.0;
                    }
                }
                v
            }
            Stage::ImpedanceLow => {
                let w = LOW_FREQUENCY * self.setup.rated.frequency;
                let sc = FastSinCos.sin_cos(self.angle);
                let i_ref = (AC_BIAS + AC_AMPLITUDE * sc.cos) * i_r;
                let v = self.regulate(i_ref, i, bus);
                let period = core::f32::consts::TAU / w;
                // one period to settle, then four
                let settle = self.steps_of(period);
                if self.steps > settle {
                    let h = usize::from(self.steps > settle + self.steps_of(2.0 * period));
                    if let Some(f) = self.impedance.low.get_mut(h) {
                        accumulate(f, self.last_v.alpha, i.alpha, self.angle, w, self.setup.ts);
                    }
                }
                self.angle = wrap_angle_step(self.angle + w * self.setup.ts);
                if self.steps >= settle + self.steps_of(4.0 * period) {
                    self.next(Stage::ImpedanceHigh);
                    self.angle = 0.0;
                }
                v
            }
            Stage::ImpedanceHigh => {
                let w = self.setup.rated.frequency;
                let sc = FastSinCos.sin_cos(self.angle);
                let mut v = self.regulate(AC_BIAS * i_r, i, bus);
                // the loops hold the bias; the injected voltage rides over them
                let z_guess = 2.0 * self.dc.rs_fit
                    + w * 0.1 * self.setup.rated.phase_voltage
                        / (w * 0.4 * self.setup.rated.current);
                v.alpha += AC_INJECTION * i_r * z_guess * sc.cos;
                let period = core::f32::consts::TAU / w;
                let settle = self.steps_of(0.1);
                if self.steps > settle {
                    let h = usize::from(self.steps > settle + self.steps_of(5.0 * period));
                    if let Some(f) = self.impedance.high.get_mut(h) {
                        accumulate(f, self.last_v.alpha, i.alpha, self.angle, w, self.setup.ts);
                    }
                }
                self.angle = wrap_angle_step(self.angle + w * self.setup.ts);
                if self.steps >= settle + self.steps_of(10.0 * period) {
                    self.next(Stage::NoLoad);
                    self.angle = 0.0;
                    self.no_load.frequency = 0.0;
                }
                v
            }
            Stage::NoLoad => {
                let w_end = NO_LOAD_FREQUENCY * self.setup.rated.frequency;
                let ramp = self.steps_of(NO_LOAD_RAMP_TIME);
                let settle = ramp + self.steps_of(NO_LOAD_SETTLE_TIME);
                let hold_end = settle + self.steps_of(NO_LOAD_MEASURE_TIME);
                // down at the ramp's rate to the lower end of its band
                let down_end = hold_end + ramp - ramp * 3 / 10;
                self.no_load.frequency = if self.steps < ramp {
                    w_end * self.steps as f32 / ramp as f32
                } else if self.steps < hold_end {
                    w_end
                } else {
                    w_end * (1.0 - (self.steps - hold_end) as f32 / ramp as f32)
                };
                // rated volts per hertz plus the drop of the no-load current in Rs
                let mag = self.setup.rated.phase_voltage / self.setup.rated.frequency
                    * self.no_load.frequency
                    + self.dc.rs_fit * 0.4 * i_r;
                let sc = FastSinCos.sin_cos(self.angle);
                let v = AlphaBeta {
                    alpha: mag * sc.cos,
                    beta: mag * sc.sin,
                };
                // air-gap torque from the power balance in the voltage's frame (the rotor
                // follows the V/f ramp at a small slip): T = p (P_in - P_Cu - P_inv) / w,
                // P_in = 1.5 v i_d (amplitude-invariant), P_Cu = 1.5 Rs |i|^2, the
                // inverter's loss (6/pi) V_e |i| (each leg's error opposes its sinusoid)
                let (s_, c_) = (sc.sin, sc.cos);
                let i_d = i.alpha * c_ + i.beta * s_;
                let i_q = -i.alpha * s_ + i.beta * c_;
                let i_mag = sqrt(i_d * i_d + i_q * i_q);
                let p = self.setup.rated.pole_pairs as f32;
                let w = self.no_load.frequency;
                if w > 0.0 {
                    // the voltage commanded at this angle acts 1.5 periods later, so in
                    // the current's frame it lags by phi = 1.5 w Ts:
                    // P_in = 1.5 Re(v e^(-j phi) conj(i)) = 1.5 v (i_d cos phi - i_q sin phi)
                    let phi = FastSinCos.sin_cos(1.5 * w * self.setup.ts);
                    let p_in = 1.5 * mag * (i_d * phi.cos - i_q * phi.sin);
                    let parts = TorqueParts {
                        input: p * p_in / w,
                        copper: p * 1.5 * i_mag * i_mag / w,
                        inverter: p * 6.0 / core::f32::consts::PI * i_mag / w,
                    };
                    let torque = parts.torque(self.dc.rs_fit, self.dc.inverter_fit);
                    self.no_load.torque = torque;
                    // V/f stabiliser (VF_STABILISER_GAIN): the frequency the voltage turns
                    // at yields to the torque's swing about its low-pass
                    self.no_load.stab.torque +=
                        (torque - self.no_load.stab.torque) * self.no_load.stab.alpha;
                    self.no_load.stab.offset =
                        -self.no_load.stab.gain * (torque - self.no_load.stab.torque);
                    // the rotor turns at the voltage's frequency (the ramp's and the
                    // stabiliser's offset) less the slip its torque needs: the sums keep
                    // the frequency and the torque apart, the slip per torque is the
                    // identified model's (`mechanics`)
                    let f = w + self.no_load.stab.offset;
                    let in_band = w > 0.3 * w_end && w < 0.9 * w_end;
                    let sums = if self.steps < ramp {
                        Some(&mut self.no_load.ramp)
                    } else if self.steps >= hold_end {
                        Some(&mut self.no_load.ramp_down)
                    } else {
                        None
                    };
                    if let (true, Some(sums)) = (in_band, sums) {
                        if let Some(r) = sums.get_mut(usize::from(w >= 0.6 * w_end)) {
                            r.impulse.add(&parts, self.setup.ts);
                            r.speed_change += (f - self.no_load.last.0) / p;
                            r.angle += f / p * self.setup.ts;
                            r.torque_change += torque - self.no_load.last.1;
                        }
                    }
                    self.no_load.last = (f, torque);
                    if self.steps > settle && self.steps < hold_end {
                        let half = self.steps_of(0.5 * NO_LOAD_MEASURE_TIME);
                        if let Some(h) = self
                            .no_load
                            .hold
                            .get_mut(usize::from(self.steps > settle + half))
                        {
                            h.torque.add(&parts, 1.0);
                            h.speed += w / p;
                        }
                    }
                }
                if self.steps > settle && self.steps < hold_end {
                    // in the voltage's frame: last step's voltage was (mag_prev, 0) at its
                    // own angle; the current rotated back by this step's angle
                    let (s, c) = (sc.sin, sc.cos);
                    let i_d = i.alpha * c + i.beta * s;
                    let i_q = -i.alpha * s + i.beta * c;
                    let half = self.steps_of(0.5 * NO_LOAD_MEASURE_TIME);
                    let h = usize::from(self.steps > settle + half);
                    if let (Some(f), Some(hs)) =
                        (self.no_load.sums.get_mut(h), self.no_load.hold.get_mut(h))
                    {
                        f.i.alpha += i_d;
                        f.i.beta += i_q;
                        f.v.alpha += mag;
                        hs.n += 1;
                    }
                }
                if self.steps == hold_end {
                    for k in 0..2 {
                        let (f, h) = (&mut self.no_load.sums[k], &mut self.no_load.hold[k]);
                        let n = h.n.max(1) as f32;
                        f.i.alpha /= n;
                        f.i.beta /= n;
                        f.v.alpha /= n;
                        h.torque = TorqueParts {
                            input: h.torque.input / n,
                            copper: h.torque.copper / n,
                            inverter: h.torque.inverter / n,
                        };
                        h.speed /= n;
                    }
                }
                if self.steps >= down_end {
                    self.no_load.torque = 0.0;
                    self.next(Stage::Done);
                    return PwmOutput::OFF;
                }
                self.angle = wrap_angle_step(
                    self.angle
                        + (self.no_load.frequency + self.no_load.stab.offset) * self.setup.ts,
                );
                v
            }
            Stage::Done | Stage::Failed(_) => return PwmOutput::OFF,
        };
        self.last_v = v;
        let m = modulate(&self.setup.pwm, v, bus, inverse_clarke(i));
        PwmOutput {
            duties: m.duties,
            enabled: true,
        }
    }

    /// The alpha current to `i_ref`, beta to zero.
    fn regulate(&mut self, i_ref: f32, i: AlphaBeta, bus: f32) -> AlphaBeta {
        let lim = 0.95 * linear_limit(bus);
        AlphaBeta {
            alpha: self.loops.alpha.update_with_limits(
                &self.loops.pi,
                i_ref - i.alpha,
                0.0,
                -lim,
                lim,
            ),
            beta: self
                .loops
                .beta
                .update_with_limits(&self.loops.pi, -i.beta, 0.0, -lim, lim),
        }
    }

    /// The identified model, once [`Stage::Done`] (outside the interrupt: bisections):
    /// [`Commissioning::assess`], a failed plausibility check refusing the result
    /// ([`CommissioningError::Implausible`]).
    pub fn identify(&self) -> Result<Identified, CommissioningError> {
        let a = self.assess()?;
        match a.refusal() {
            Some(c) => Err(CommissioningError::Implausible(c.concern)),
            None => Ok(a.identified),
        }
    }

    /// The identified model with the bound of each quantity's error and every
    /// plausibility check (module docs, "How sure" and "Plausibility"), whether the checks
    /// pass or not (a report shows a refused result too). An error: the sequence failed,
    /// or a fit has no result at all.
    pub fn assess(&self) -> Result<Assessment, CommissioningError> {
        if let Stage::Failed(e) = self.stage {
            return Err(e);
        }
        let r = &self.setup.rated;
        let z_nom = r.phase_voltage / r.current;
        // 1. Rs and the inverter error: the line, its standard errors, its two halves
        let pts = self.dc_points();
        let (rs, c, residual) = line_fit(&pts);
        if !(residual < 0.05) {
            return Err(CommissioningError::PoorFit("stator_resistance"));
        }
        if !(rs > 1e-4 * z_nom && rs < z_nom) {
            return Err(CommissioningError::ResultOutOfRange("stator_resistance"));
        }
        let half_line = |h: usize| {
            let mut p = [(0.0, 0.0); 4];
            for (o, d) in p.iter_mut().zip(&self.dc.levels) {
                *o = if h == 0 { d[0] } else { d[1] };
            }
            line_fit(&p)
        };
        let ((rs_a, c_a, _), (rs_b, c_b, _)) = (half_line(0), half_line(1));
        let (se_rs, se_c) = line_errors(&pts, rs, c);
        let u_rs = 3.0 * se_rs + spread(rs_a, rs_b);
        let u_c = 3.0 * se_c + spread(c_a, c_b);
        let v_e = 0.75 * c;
        let u_ve = 0.75 * u_c;
        let bus = if self.dc.bus_n > 0 {
            self.dc.bus_sum / self.dc.bus_n as f32
        } else {
            self.setup.board.dc_bus_v
        };
        let dead_time = ((v_e - self.setup.board.device_drop_v) / bus * self.setup.ts).max(0.0);
        let u_dead = u_ve / bus * self.setup.ts;

        // 2. the standstill impedances: both halves, Rs moved, the timing moved
        let [l0, l1] = &self.impedance.low;
        let [h0, h1] = &self.impedance.high;
        let (low, high) = (l0.plus(l1), h0.plus(h1));
        let e0 = self.electrical(rs, &low, &high, 0.0)?;
        let mut u_e = halves(
            self.electrical(rs, l0, h0, 0.0).ok(),
            self.electrical(rs, l1, h1, 0.0).ok(),
        );
        add(
            &mut u_e,
            worst(&e0, [-u_rs, u_rs], |d| {
                self.electrical(rs + d, &low, &high, 0.0).ok()
            }),
        );
        add(
            &mut u_e,
            worst(&e0, [-0.5, 0.5], |d| {
                self.electrical(rs, &low, &high, d).ok()
            }),
        );
        let [r_r, l_sigma, l_m_ss] = e0;
        let u_ls = u_e[1];

        // 3. the no-load test: both halves, Rs, the inverter error, L_sigma and the timing
        let [n0, n1] = &self.no_load.sums;
        let mut nl = n0.plus(n1);
        nl.v.alpha *= 0.5;
        nl.i.alpha *= 0.5;
        nl.i.beta *= 0.5;
        let m0 = self.no_load_fit(&nl, rs, v_e, l_sigma, 0.0)?;
        let mut u_m = halves(
            self.no_load_fit(n0, rs, v_e, l_sigma, 0.0).ok(),
            self.no_load_fit(n1, rs, v_e, l_sigma, 0.0).ok(),
        );
        let u_ve_model = u_ve + INVERTER_LOSS_MODEL_UNCERTAINTY * v_e.abs();
        for (delta, f) in [(u_rs, 0usize), (u_ve_model, 1), (u_ls, 2), (0.5, 3)] {
            add(
                &mut u_m,
                worst(&m0, [-delta, delta], |d| {
                    let p = |k: usize| if k == f { d } else { 0.0 };
                    self.no_load_fit(&nl, rs + p(0), v_e + p(1), l_sigma + p(2), p(3))
                        .ok()
                }),
            );
        }
        let [l_m, i_flux] = m0;
        // one converter step over the no-load current (CURRENT_ADC_BITS)
        let lsb = 2.0 * self.setup.board.current_full_scale_a / (1u32 << CURRENT_ADC_BITS) as f32;
        let i_nl = sqrt(nl.i.alpha * nl.i.alpha + nl.i.beta * nl.i.beta);
        if i_nl > 0.0 {
            u_m[0] += l_m * lsb / i_nl;
            u_m[1] += i_flux * lsb / i_nl;
        }

        // 4. inertia and friction: the ramp's halves, the hold's halves, Rs, V_e and the
        // slip moved; the rotor's slip per torque R_R / (1.5 p^2 psi_R^2) at the test's
        // flux (psi_R > 0: the branch's reactance was positive)
        let p = r.pole_pairs as f32;
        let psi = self.no_load_branch(&nl, rs, v_e, l_sigma, 0.0)?.1;
        let slip = r_r / (1.5 * p * p * psi * psi);
        // its bound: R_R's, and twice the flux's (as L_M's)
        let u_slip = (u_e[0] / r_r + 2.0 * u_m[0] / l_m) * slip;
        let mech = self.mechanics(rs, v_e, slip);
        let [hh0, hh1] = &self.no_load.hold;
        let b_half = |h: &HoldSums| {
            if h.speed > 0.0 {
                h.torque.torque(rs, v_e) / h.speed
            } else {
                0.0
            }
        };
        let mut u_b = spread(b_half(hh0), b_half(hh1));
        let mut u_j = match mech.inertia {
            Some(_) => {
                let [ra, rb] = &self.no_load.ramp;
                let [da, db] = &self.no_load.ramp_down;
                // J = (I_up - I_down - B (A_up - A_down)) / (dw_up - dw_down): the
                // halves' disagreement, and the friction's spread on the angles' difference
                let dw = ra.speed_change + rb.speed_change - da.speed_change - db.speed_change;
                let da_angle = ra.angle + rb.angle - da.angle - db.angle;
                0.5 * (mech.inertia_halves.0 - mech.inertia_halves.1).abs()
                    + if dw > 0.0 {
                        u_b * da_angle.abs() / dw
                    } else {
                        f32::INFINITY
                    }
            }
            None => f32::INFINITY,
        };
        for (drs, dve, dslip) in [
            (-u_rs, 0.0, 0.0),
            (u_rs, 0.0, 0.0),
            (0.0, -u_ve_model, 0.0),
            (0.0, u_ve_model, 0.0),
            (0.0, 0.0, -u_slip),
            (0.0, 0.0, u_slip),
        ] {
            let m = self.mechanics(rs + drs, v_e + dve, slip + dslip);
            u_b += 0.5 * (m.friction - mech.friction).abs();
            if let (Some(a), Some(b)) = (m.inertia, mech.inertia) {
                u_j += 0.5 * (a - b).abs();
            }
        }

        if !(r_r > 0.0 && r_r < z_nom && l_m_ss > l_sigma && l_m_ss < 100.0 * z_nom / r.frequency) {
            return Err(CommissioningError::ResultOutOfRange("rotor_resistance"));
        }
        if !(l_m > 0.0 && i_flux < r.current) {
            return Err(CommissioningError::ResultOutOfRange(
                "magnetizing_inductance",
            ));
        }
        let rel = |u: f32, x: f32| {
            if x.abs() > 0.0 && is_finite(u) {
                u / x.abs()
            } else {
                f32::INFINITY
            }
        };
        let confidence = Confidence {
            stator_resistance: rel(u_rs, rs),
            rotor_resistance: rel(u_e[0], r_r),
            leakage_inductance: rel(u_e[1], l_sigma),
            magnetizing_inductance: rel(u_m[0], l_m),
            rated_flux_current: rel(u_m[1], i_flux),
            inverter_error: rel(u_ve, v_e),
            dead_time: rel(u_dead, dead_time),
            inertia: mech
                .inertia
                .map_or(f32::INFINITY, |j| rel(u_j, j) + INERTIA_MODEL_UNCERTAINTY),
            viscous_friction: rel(u_b, mech.friction),
        };
        let identified = Identified {
            inertia: mech.inertia,
            viscous_friction: mech.friction,
            stator_resistance: rs,
            rotor_resistance: r_r,
            leakage_inductance: l_sigma,
            magnetizing_inductance: l_m,
            magnetizing_inductance_small_signal: l_m_ss,
            rated_flux_current: i_flux,
            inverter_error: v_e,
            dead_time,
            dc_fit_residual: residual,
        };

        // 5. plausibility
        const OPEN: (f32, f32) = (f32::NEG_INFINITY, f32::INFINITY);
        let check = |concern, value, range| Check {
            concern,
            value,
            range,
        };
        let (j_spread, j_ratio) = match mech.inertia {
            Some(j) => (
                (mech.inertia_halves.0 - mech.inertia_halves.1).abs() / j,
                j / catalogue_inertia(r.torque),
            ),
            None => (0.0, 1.0),
        };
        let resolved = mech.inertia.is_some();
        let flux = i_flux / r.current;
        let reactive = match self.setup.power_factor {
            Some(pf) if pf < 1.0 => i_flux / (r.current * sqrt(1.0 - pf * pf)),
            _ => 0.0,
        };
        let limit = |x: f32| (0.0, x);
        let checks = [
            check(
                Concern::CoupledLoad,
                mech.hold_torque / r.torque,
                (f32::NEG_INFINITY, COUPLED_LOAD_TORQUE),
            ),
            check(
                Concern::InertiaInconsistent,
                j_spread,
                if resolved {
                    limit(INERTIA_SPREAD_MAX)
                } else {
                    OPEN
                },
            ),
            check(
                Concern::InertiaHigh,
                j_ratio,
                if resolved {
                    (0.0, INERTIA_RANGE.1)
                } else {
                    OPEN
                },
            ),
            check(
                Concern::InertiaLow,
                j_ratio,
                if resolved {
                    (INERTIA_RANGE.0, f32::INFINITY)
                } else {
                    OPEN
                },
            ),
            check(Concern::FluxCurrentHigh, flux, (0.0, FLUX_CURRENT_RANGE.1)),
            check(
                Concern::FluxCurrentLow,
                flux,
                (FLUX_CURRENT_RANGE.0, f32::INFINITY),
            ),
            check(
                Concern::FluxCurrentHigh,
                reactive,
                if self.setup.power_factor.is_some() {
                    (0.0, FLUX_OVER_REACTIVE_MAX)
                } else {
                    OPEN
                },
            ),
            check(
                Concern::Uncertain("stator_resistance"),
                confidence.stator_resistance,
                limit(MAX_UNCERTAINTY[0]),
            ),
            check(
                Concern::Uncertain("rotor_resistance"),
                confidence.rotor_resistance,
                limit(MAX_UNCERTAINTY[1]),
            ),
            check(
                Concern::Uncertain("leakage_inductance"),
                confidence.leakage_inductance,
                limit(MAX_UNCERTAINTY[2]),
            ),
            check(
                Concern::Uncertain("magnetizing_inductance"),
                confidence.magnetizing_inductance,
                limit(MAX_UNCERTAINTY[3]),
            ),
            check(
                Concern::Uncertain("inertia"),
                if resolved { confidence.inertia } else { 0.0 },
                limit(MAX_UNCERTAINTY[4]),
            ),
        ];
        Ok(Assessment {
            identified,
            confidence,
            checks,
            inertia_halves: mech.inertia_halves,
            hold_torque: mech.hold_torque,
        })
    }

    /// R_R, L_sigma and the small-signal L_M from the two impedance tests' sums, with Rs
    /// `rs` (ohm) and the voltage acting `delay` periods later than modelled.
    fn electrical(
        &self,
        rs: f32,
        low: &Fourier,
        high: &Fourier,
        delay: f32,
    ) -> Result<[f32; 3], CommissioningError> {
        let r = &self.setup.rated;
        let w_l = LOW_FREQUENCY * r.frequency;
        let w_h = r.frequency;
        let zl = impedance(low, rs, w_l * delay * self.setup.ts);
        let zh = impedance(high, rs, w_h * delay * self.setup.ts);
        let (Some(zl), Some(zh)) = (zl, zh) else {
            return Err(CommissioningError::ResultOutOfRange("impedance"));
        };
        // A fixed point: at the low frequency the rotor branch's admittance
        // Y = 1 / (Z' - j w L_sigma) = 1/R_R - j / (w L_M) gives R_R and L_M for a given
        // L_sigma (which is a tenth of that impedance there); at the rated frequency the
        // rotor branch is nearly R_R alone and the reactance is w L_sigma plus the branch's
        // small X_r = w L_M R_R^2 / (R_R^2 + (w L_M)^2), so L_sigma = (Im Z'_h - X_r) / w.
        // Each pass changes L_sigma by the few per cent X_r is of Im Z'_h: it converges in
        // a few passes, and errors of R_R and L_M reach L_sigma only through X_r. (Equating
        // the real parts of Y at both frequencies instead, the earlier method, is
        // ill-conditioned: both tend to 1/R_R near the root, and a 0.1 % error in either
        // moved L_sigma by several per cent or left no root.)
        let mut l_sigma = zh.1 / w_h;
        let (mut r_r, mut l_m_ss) = (0.0f32, 0.0f32);
        for _ in 0..30 {
            let (x, y) = (zl.0, zl.1 - w_l * l_sigma);
            let d = x * x + y * y;
            if !(x > 0.0 && y > 0.0 && d > 0.0) {
                return Err(CommissioningError::ResultOutOfRange("leakage_inductance"));
            }
            // Y = (x - j y) / d
            r_r = d / x;
            l_m_ss = d / (w_l * y);
            let xm = w_h * l_m_ss;
            let x_r = xm * r_r * r_r / (r_r * r_r + xm * xm);
            l_sigma = (zh.1 - x_r) / w_h;
            if !(l_sigma > 0.0) {
                return Err(CommissioningError::ResultOutOfRange("leakage_inductance"));
            }
        }
        Ok([r_r, l_sigma, l_m_ss])
    }

    /// L_M at rated flux (H) and the rated flux current (A peak) from the no-load hold's
    /// mean voltage and current `nl` (the voltage's frame), with Rs, the inverter error
    /// and L_sigma, the voltage acting `delay` periods later than modelled. The rotor
    /// branch's admittance Y = 1 / (Z - Rs - R_inv - j w L_sigma) = s / R_R - j / (w L_M)
    /// (R_inv = (4/pi) V_e / |I|, the inverter error's fundamental, in phase with the
    /// current): its imaginary part gives L_M whatever the slip, so friction or a load
    /// does not bias it; the rated flux current is the no-load current at rated voltage
    /// and frequency with that L_M, V / |Rs + j w_r (L_sigma + L_M)|.
    fn no_load_fit(
        &self,
        nl: &Fourier,
        rs: f32,
        v_e: f32,
        l_sigma: f32,
        delay: f32,
    ) -> Result<[f32; 2], CommissioningError> {
        let (l_m, _) = self.no_load_branch(nl, rs, v_e, l_sigma, delay)?;
        // the no-load current at rated voltage and frequency with this model (not the
        // test's own magnetizing current: the test's voltage, V/f plus an in-phase Rs
        // boost, over-fluxes a machine whose no-load current is nearly in quadrature
        // with a large Rs drop, 5 % on the 0.18 kW machine); |.| >= w_r L_M > 0
        let r = &self.setup.rated;
        let x_r = r.frequency * (l_sigma + l_m);
        let i_flux = r.phase_voltage / sqrt(rs * rs + x_r * x_r);
        Ok([l_m, i_flux])
    }

    /// The no-load test's magnetizing branch: L_M (H) and the rotor flux it carries
    /// during the test, psi_R = |E| / w (Wb).
    fn no_load_branch(
        &self,
        nl: &Fourier,
        rs: f32,
        v_e: f32,
        l_sigma: f32,
        delay: f32,
    ) -> Result<(f32, f32), CommissioningError> {
        let w_n = NO_LOAD_FREQUENCY * self.setup.rated.frequency;
        // the voltage commanded at an angle acts 1.5 periods later: V e^(-j 1.5 w Ts)
        let lead = FastSinCos.sin_cos(w_n * (1.5 + delay) * self.setup.ts);
        let (vd, vq) = (nl.v.alpha * lead.cos, -nl.v.alpha * lead.sin);
        let (id, iq) = (nl.i.alpha, nl.i.beta);
        let i2 = id * id + iq * iq;
        if !(i2 > 0.0) {
            return Err(CommissioningError::ResultOutOfRange("rated_flux_current"));
        }
        let i_mag = sqrt(i2);
        // Z = V conj(I) / |I|^2, less the series elements
        let r_inv = 4.0 / core::f32::consts::PI * v_e / i_mag;
        let x = (vd * id + vq * iq) / i2 - rs - r_inv;
        let y = (vq * id - vd * iq) / i2 - w_n * l_sigma;
        if !(y > 0.0) {
            return Err(CommissioningError::ResultOutOfRange(
                "magnetizing_inductance",
            ));
        }
        let z2 = x * x + y * y;
        Ok((z2 / (w_n * y), sqrt(z2) * i_mag / w_n))
    }

    /// J and B from the no-load test's sums with Rs `rs`, inverter error `v_e` and the
    /// rotor's slip per air-gap torque `slip` (rad/s mechanical per N m,
    /// `R_R / (1.5 p^2 psi_R^2)`): the rotor turns at the voltage's frequency less the
    /// slip, in the hold and over the ramps.
    fn mechanics(&self, rs: f32, v_e: f32, slip: f32) -> Mechanics {
        let [h0, h1] = &self.no_load.hold;
        let hold_torque = 0.5 * (h0.torque.torque(rs, v_e) + h1.torque.torque(rs, v_e));
        let speed = 0.5 * (h0.speed + h1.speed) - slip * hold_torque;
        // a half's rotor: its speed change and angle less the slip's
        let rotor = |r: &RampSums| {
            (
                r.speed_change - slip * r.torque_change,
                r.angle - slip * r.impulse.torque(rs, v_e),
            )
        };
        let friction = if speed > 0.0 {
            (hold_torque / speed).max(0.0)
        } else {
            0.0
        };
        // J from a speed half up and down: J dw = impulse - B angle on each, and the
        // difference cancels what both runs share (module docs, "Inertia and friction")
        let up_down = |u: &RampSums, d: &RampSums| {
            let ((wu, au), (wd, ad)) = (rotor(u), rotor(d));
            let impulse =
                u.impulse.torque(rs, v_e) - d.impulse.torque(rs, v_e) - friction * (au - ad);
            (impulse, wu - wd)
        };
        let [a, b] = &self.no_load.ramp;
        let [da, db] = &self.no_load.ramp_down;
        let (ia, wa) = up_down(a, da);
        let (ib, wb) = up_down(b, db);
        // each half up (speed_change > 0) and down (< 0) for a resolved half
        let resolved = |u: &RampSums, d: &RampSums| u.speed_change > 0.0 && d.speed_change < 0.0;
        let j_of = |i: f32, w: f32, ok: bool| if ok { i / w } else { 0.0 };
        let inertia = if resolved(a, da) && resolved(b, db) {
            let j = (ia + ib) / (wa + wb);
            (j > 0.0).then_some(j)
        } else {
            None
        };
        Mechanics {
            inertia,
            inertia_halves: (j_of(ia, wa, resolved(a, da)), j_of(ib, wb, resolved(b, db))),
            friction,
            hold_torque,
        }
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

/// Z - Rs from Fourier sums (real, imaginary), the voltage delayed by `phi` (rad) more
/// than its timing model says; `None` without current.
fn impedance(f: &Fourier, rs: f32, phi: f32) -> Option<(f32, f32)> {
    let ph = FastSinCos.sin_cos(phi);
    // V e^(-j phi)
    let vr = f.v.alpha * ph.cos + f.v.beta * ph.sin;
    let vi = f.v.beta * ph.cos - f.v.alpha * ph.sin;
    let (ir, ii) = (f.i.alpha, f.i.beta);
    let d = ir * ir + ii * ii;
    if !(d > 0.0) {
        return None;
    }
    Some(((vr * ir + vi * ii) / d - rs, (vi * ir - vr * ii) / d))
}

/// J, B and the hold's torque from the no-load test.
#[derive(Clone, Copy, Debug)]
struct Mechanics {
    inertia: Option<f32>,
    /// J of each speed half, up and down.
    inertia_halves: (f32, f32),
    friction: f32,
    hold_torque: f32,
}

/// Least-squares line v = Rs i + c through the DC steps; (Rs, c, relative residual: the
/// largest deviation over its Rs i).
fn line_fit(points: &[(f32, f32); 4]) -> (f32, f32, f32) {
    let n = points.len() as f32;
    let (mut si, mut sv, mut sii, mut siv) = (0.0, 0.0, 0.0, 0.0);
    for &(i, v) in points {
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
    for &(i, v) in points {
        worst = worst.max((v - rs * i - c).abs() / (rs * i).abs().max(1e-6));
    }
    (rs, c, worst)
}

/// Standard errors of the slope and the intercept of the line (`rs`, `c`) through
/// `points` (ordinary least squares, n - 2 degrees of freedom).
fn line_errors(points: &[(f32, f32); 4], rs: f32, c: f32) -> (f32, f32) {
    let n = points.len() as f32;
    let mean_i = points.iter().map(|p| p.0).sum::<f32>() / n;
    let mut sxx = 0.0;
    let mut ssr = 0.0;
    let mut sii = 0.0;
    for &(i, v) in points {
        sxx += (i - mean_i) * (i - mean_i);
        let e = v - rs * i - c;
        ssr += e * e;
        sii += i * i;
    }
    if !(sxx > 0.0) {
        return (f32::INFINITY, f32::INFINITY);
    }
    let s2 = ssr / (n - 2.0);
    (sqrt(s2 / sxx), sqrt(s2 * sii / (n * sxx)))
}

/// The half-window part of a bound: 1.5 |a - b|, three standard deviations of the mean of
/// two estimates whose difference is `a - b`.
fn spread(a: f32, b: f32) -> f32 {
    1.5 * (a - b).abs()
}

/// [`spread`] of each component of two fits' results; infinite where a half had none.
fn halves<const N: usize>(a: Option<[f32; N]>, b: Option<[f32; N]>) -> [f32; N] {
    let mut out = [f32::INFINITY; N];
    if let (Some(a), Some(b)) = (a, b) {
        for ((o, x), y) in out.iter_mut().zip(a).zip(b) {
            *o = spread(x, y);
        }
    }
    out
}

/// The largest change of each component of `base` when the fit `f` is redone with each
/// of `deltas`; infinite where it has no result.
fn worst<const N: usize>(
    base: &[f32; N],
    deltas: [f32; 2],
    f: impl Fn(f32) -> Option<[f32; N]>,
) -> [f32; N] {
    let mut out = [0.0f32; N];
    for d in deltas {
        match f(d) {
            Some(x) => {
                for ((o, x), b) in out.iter_mut().zip(x).zip(base) {
                    *o = o.max((x - b).abs());
                }
            }
            None => out = [f32::INFINITY; N],
        }
    }
    out
}

fn add<const N: usize>(acc: &mut [f32; N], x: [f32; N]) {
    for (a, x) in acc.iter_mut().zip(x) {
        *a += x;
    }
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn logarithm_and_exponential_are_accurate() {
        for x in [1e-3f32, 0.3, 1.0, 2.0, 7.5, 1234.0] {
            let l = ln(x);
            assert!((exp(l) - x).abs() <= 2e-6 * x, "{x}");
        }
        assert!((ln(10.0) - core::f32::consts::LN_10).abs() < 2e-6);
        assert!((exp(1.0) - core::f32::consts::E).abs() < 2e-6);
    }

    /// The catalogue line: about 0.0024 kg m^2 for a 0.75 kW 4-pole motor, and a 2-pole
    /// motor of twice the power (the same torque) gets the same.
    #[test]
    fn catalogue_inertia_follows_the_torque() {
        let j = catalogue_inertia(750.0 / 157.08);
        assert!((j - 0.0035 * 0.75f32.powf(1.3)).abs() < 1e-6, "{j}");
        assert!((catalogue_inertia(37_000.0 / 157.08) - 0.0035 * 37f32.powf(1.3)).abs() < 1e-3);
        assert_eq!(catalogue_inertia(0.0), 0.0);
    }

    #[test]
    fn every_concern_says_what_to_check_within_a_reply_line() {
        for c in [
            Concern::CoupledLoad,
            Concern::InertiaInconsistent,
            Concern::InertiaHigh,
            Concern::InertiaLow,
            Concern::FluxCurrentHigh,
            Concern::FluxCurrentLow,
            Concern::Uncertain("magnetizing_inductance"),
        ] {
            assert!(c.reason().len() + c.advice().len() < 120, "{c:?}");
            assert!(!c.field().is_empty());
        }
        let k = Check {
            concern: Concern::CoupledLoad,
            value: 0.3,
            range: (f32::NEG_INFINITY, COUPLED_LOAD_TORQUE),
        };
        assert!(!k.passed());
    }
}
