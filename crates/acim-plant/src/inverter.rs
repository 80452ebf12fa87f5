//! Two-level three-phase voltage-source inverter: averaged and switching-level models.
//!
//! # Conventions
//!
//! Phase current `i_x` (x = a, b, c) is positive out of the inverter into the machine. The
//! pole voltage `v_x0` is measured from the negative DC rail. The machine's star point is
//! isolated, so the phase-to-neutral voltages are the pole voltages minus their common
//! mode, `v_xn = v_x0 - (v_a0 + v_b0 + v_c0)/3`, and the amplitude-invariant Clarke
//! transform `v_alpha = (2 v_a - v_b - v_c)/3`, `v_beta = (v_b - v_c)/sqrt3` ignores the
//! common mode anyway.
//!
//! # Switch-state model shared by both modes
//!
//! Over a PWM period each leg connects its terminal to the positive rail for a fraction of
//! the time that depends on the sign of the current during the dead times:
//! `h+` when the current is positive (it flows through the upper switch or the lower
//! diode, so the terminal follows the *upper* gate, whose turn-on is delayed by the dead
//! time) and `h-` when it is negative (it follows the *lower* gate). With the duty `d`
//! (clamped to [0, 1], NaN read as 0.5) and `delta = t_dead / T_pwm`:
//!
//! ```text
//! 0 < d < 1:  h+ = max(d - delta, 0)      h- = min(d + delta, 1)
//! d = 0:      h+ = h- = 0   (no pulse, no dead time: lower switch always on)
//! d = 1:      h+ = h- = 1
//! disabled:   h+ = 0, h- = 1   (all gates off: the current picks the diode of the rail
//!                               opposite its sign)
//! ```
//!
//! The current sign is smoothed, `s = clamp(i / I_band, -1, 1)`, and the pole voltage is
//!
//! ```text
//! v_x0 = Vdc [ (1 + s)/2 h+  +  (1 - s)/2 h- ]  -  s V_drop
//! ```
//!
//! which for a mid-range duty is `d Vdc - s (t_dead/T_pwm) Vdc - s V_drop`: the dead-time
//! error and the device drop (one forward drop for switch and diode alike) both oppose the
//! current. The DC-link current is `i_dc = sum_x i_x [ (1 + s)/2 h+ + (1 - s)/2 h- ]`, so
//! `Vdc i_dc - sum_x v_xn i_x = V_drop sum_x s_x i_x >= 0` is the conduction loss.
//!
//! The band `I_band` ([`InverterConfig::current_band`], default 50 mA) avoids the chatter
//! a hard sign would cause when a current crosses zero.
//!
//! # Gates off (`enabled == false`)
//!
//! With every switch off each terminal is clamped by a diode to the rail opposite its
//! current's sign (`h+ = 0, h- = 1` above). Inside the smooth band this clamp behaves like
//! a resistor `R = (Vdc/2 + V_drop)/band` per phase, which for a 50 mA band would be far
//! too stiff for an explicit integrator, so the disabled band is widened to
//! `max(I_band, (Vdc/2 + V_drop) * freewheel_slope)` where the plant sets
//! `freewheel_slope = 2 h / (sigma Ls)` from its integration step `h` (R h/(sigma Ls) =
//! 1/2: monotone, non-oscillating decay; about 0.17 A at 325 V and h = 20 us).
//! [`super::Plant::run_period`] then decides before every sub-step:
//!
//! - all three phase currents inside that band **and** the machine's open-circuit
//!   line-to-line back-EMF spread (max - min of the phase EMFs) at most
//!   `Vdc + 2 V_drop`: every diode blocks, the stator is open,
//!   [`super::InductionMachine::step_open_circuit`] sets i_s = 0 exactly (its tiny stored
//!   energy, below 1 mJ, is booked as returned through the terminals) and the rotor flux
//!   decays with tau_r;
//! - otherwise the diode clamp drives the currents: the machine returns its magnetic
//!   energy to the bus (a 1 A current reaches the band within about 0.1 ms), or rectifies
//!   its back-EMF into the bus while that exceeds it (generator braking, e.g. after a bus
//!   sag at high speed).
//!
//! So the currents reach exactly zero within a PWM period or two and never oscillate.
//!
//! # Switching-level model
//!
//! Centre-aligned PWM: the carrier period starts and ends at the carrier trough (all
//! upper switches off for d < 1, the PWM "centre" of the zero vector where the currents are
//! sampled), and the upper switch reference of phase x is high on
//! `[(1-d)T/2, (1+d)T/2]`. The dead time is applied symmetrically about that centre:
//! `h+` interval `[(1-d)T/2 + td/2, (1+d)T/2 - td/2]`, `h-` interval
//! `[(1-d)T/2 - td/2, (1+d)T/2 + td/2]` clipped to the period. (A real TIM1 delays each
//! rising edge by the whole dead time, which also shifts the pulse centre by td/2; that
//! shift is neglected, it does not change the volt-seconds per period.) The union of all
//! edges splits the period into at most 13 intervals (7 without dead time) with constant
//! switch states; [`SwitchingPattern`] lists them and the plant integrates the machine
//! over each one. With this choice the period average of the switched pole voltage equals
//! the averaged model exactly for a fixed current sign.

use acim::frames::{clarke_three, AlphaBeta};
use acim::math::{clamp, is_finite};

/// Default dead time, s.
pub const DEFAULT_DEAD_TIME: f32 = 1.5e-6;
/// Default PWM (and control) period, s: 5 kHz as in the paper.
pub const DEFAULT_PWM_PERIOD: f32 = 200e-6;
/// Default forward drop of a conducting switch or diode, V.
pub const DEFAULT_DEVICE_DROP: f32 = 1.0;
/// Default half-width of the smooth current sign, A.
pub const DEFAULT_CURRENT_BAND: f32 = 0.05;

/// Inverter non-idealities. All may be zero (ideal inverter).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct InverterConfig {
    /// Dead time t_dead, s (default 1.5 us).
    pub dead_time: f32,
    /// PWM carrier period T_pwm, s (default 200 us); also the plant's control period.
    pub pwm_period: f32,
    /// Forward drop of a conducting switch or diode, V (default 1 V).
    pub device_drop: f32,
    /// Half-width of the linear zone of the smooth current sign, A (default 50 mA;
    /// 0 gives a hard sign).
    pub current_band: f32,
}

impl Default for InverterConfig {
    fn default() -> Self {
        Self {
            dead_time: DEFAULT_DEAD_TIME,
            pwm_period: DEFAULT_PWM_PERIOD,
            device_drop: DEFAULT_DEVICE_DROP,
            current_band: DEFAULT_CURRENT_BAND,
        }
    }
}

impl InverterConfig {
    /// No dead time, no device drop, default period.
    pub fn ideal() -> Self {
        Self {
            dead_time: 0.0,
            device_drop: 0.0,
            ..Self::default()
        }
    }
}

/// Fractions of the period (0..=1) during which a leg's terminal is tied to the positive
/// rail, for a positive (`pos`) and a negative (`neg`) phase current.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct LegState {
    /// Fraction for a positive current, h+.
    pub pos: f32,
    /// Fraction for a negative current, h-.
    pub neg: f32,
}

/// Output of the inverter for given leg states and currents.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct InverterOutput {
    /// Pole voltages v_x0 (from the negative rail), V.
    pub pole: [f32; 3],
    /// Phase-to-neutral voltages v_xn (pole minus common mode), V.
    pub phase: [f32; 3],
    /// Amplitude-invariant Clarke of the phase voltages, (v_alpha, v_beta), V.
    pub alpha_beta: AlphaBeta,
    /// DC-link current drawn from the positive rail, A.
    pub dc_current: f32,
}

/// Two-level inverter with a settable DC-bus voltage.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Inverter {
    cfg: InverterConfig,
    dc_bus: f32,
    freewheel_slope: f32,
}

impl Default for Inverter {
    fn default() -> Self {
        Self::new(InverterConfig::default(), acim::params::DEFAULT_DC_BUS)
    }
}

/// Duty sanitising: NaN reads as 0.5, the rest is clamped to [0, 1].
pub fn sanitize_duty(d: f32) -> f32 {
    if d.is_nan() {
        0.5
    } else {
        clamp(d, 0.0, 1.0)
    }
}

/// Smooth sign: i/band clamped to [-1, 1]; a hard sign (0 at 0) for band <= 0.
pub fn smooth_sign(i: f32, band: f32) -> f32 {
    if band > 0.0 {
        clamp(i / band, -1.0, 1.0)
    } else if i > 0.0 {
        1.0
    } else if i < 0.0 {
        -1.0
    } else {
        0.0
    }
}

fn non_negative(x: f32) -> f32 {
    if is_finite(x) && x > 0.0 {
        x
    } else {
        0.0
    }
}

impl Inverter {
    /// An inverter with configuration `cfg` and DC bus `dc_bus` (V). Negative or
    /// non-finite settings are taken as 0, a non-positive PWM period as the default.
    pub fn new(cfg: InverterConfig, dc_bus: f32) -> Self {
        let period = if is_finite(cfg.pwm_period) && cfg.pwm_period > 0.0 {
            cfg.pwm_period
        } else {
            DEFAULT_PWM_PERIOD
        };
        let cfg = InverterConfig {
            dead_time: clamp(non_negative(cfg.dead_time), 0.0, period),
            pwm_period: period,
            device_drop: non_negative(cfg.device_drop),
            current_band: non_negative(cfg.current_band),
        };
        Self {
            cfg,
            dc_bus: non_negative(dc_bus),
            // 2 * 20 us / sigma Ls of the Table 1 machine; the plant overrides it.
            freewheel_slope: 2.0 * 20e-6 / 0.039_29,
        }
    }

    /// Ideal inverter (no dead time, no drop) on bus `dc_bus` (V).
    pub fn ideal(dc_bus: f32) -> Self {
        Self::new(InverterConfig::ideal(), dc_bus)
    }

    /// The (sanitised) configuration.
    pub fn config(&self) -> &InverterConfig {
        &self.cfg
    }

    /// PWM period, s.
    pub fn pwm_period(&self) -> f32 {
        self.cfg.pwm_period
    }

    /// Sets the DC-bus voltage (V, e.g. to simulate a sag); negative or NaN gives 0.
    pub fn set_dc_bus(&mut self, v: f32) {
        self.dc_bus = non_negative(v);
    }

    /// DC-bus voltage, V.
    pub fn dc_bus(&self) -> f32 {
        self.dc_bus
    }

    /// Sets the slope (A/V) that widens the diode-clamp band when disabled, see the
    /// module documentation (the plant sets it to `2 h / (sigma Ls)`).
    pub fn set_freewheel_slope(&mut self, slope: f32) {
        self.freewheel_slope = non_negative(slope);
    }

    /// Band of the smooth sign used when the inverter is disabled, A.
    pub fn freewheel_band(&self) -> f32 {
        let b = (0.5 * self.dc_bus + self.cfg.device_drop) * self.freewheel_slope;
        if b > self.cfg.current_band {
            b
        } else {
            self.cfg.current_band
        }
    }

    /// Averaged leg state for a duty (see the module documentation).
    pub fn averaged_leg(&self, duty: f32) -> LegState {
        let d = sanitize_duty(duty);
        let delta = self.cfg.dead_time / self.cfg.pwm_period;
        if d >= 1.0 {
            LegState { pos: 1.0, neg: 1.0 }
        } else if d <= 0.0 {
            LegState { pos: 0.0, neg: 0.0 }
        } else {
            LegState {
                pos: clamp(d - delta, 0.0, 1.0),
                neg: clamp(d + delta, 0.0, 1.0),
            }
        }
    }

    /// Leg states of the three phases for an averaged period; `enabled == false` gives the
    /// all-off (diode) state.
    pub fn averaged_legs(&self, duties: [f32; 3], enabled: bool) -> [LegState; 3] {
        if enabled {
            let [a, b, c] = duties;
            [
                self.averaged_leg(a),
                self.averaged_leg(b),
                self.averaged_leg(c),
            ]
        } else {
            [LegState { pos: 0.0, neg: 1.0 }; 3]
        }
    }

    /// Inverter output for leg states `legs`, phase currents `currents` (A) and smooth-sign
    /// band `band` (A).
    pub fn output(&self, legs: [LegState; 3], currents: [f32; 3], band: f32) -> InverterOutput {
        let mut pole = [0.0f32; 3];
        let mut idc = 0.0f32;
        for ((v, leg), &i) in pole.iter_mut().zip(legs.iter()).zip(currents.iter()) {
            let s = smooth_sign(i, band);
            let up = 0.5 * (1.0 + s) * leg.pos + 0.5 * (1.0 - s) * leg.neg;
            *v = self.dc_bus * up - s * self.cfg.device_drop;
            idc += up * i;
        }
        let [a, b, c] = pole;
        let cm = (a + b + c) * (1.0 / 3.0);
        let phase = [a - cm, b - cm, c - cm];
        InverterOutput {
            pole,
            phase,
            alpha_beta: clarke_three(phase[0], phase[1], phase[2]),
            dc_current: idc,
        }
    }

    /// Averaged-model output for `duties`, `enabled` and phase currents (A). Uses the
    /// configured current band when enabled and the freewheel band when disabled.
    pub fn averaged_output(
        &self,
        duties: [f32; 3],
        enabled: bool,
        currents: [f32; 3],
    ) -> InverterOutput {
        let band = if enabled {
            self.cfg.current_band
        } else {
            self.freewheel_band()
        };
        self.output(self.averaged_legs(duties, enabled), currents, band)
    }

    /// Switching pattern of one centre-aligned PWM period for `duties`.
    pub fn switching_pattern(&self, duties: [f32; 3]) -> SwitchingPattern {
        let t = self.cfg.pwm_period;
        let td = self.cfg.dead_time;
        let mut windows = [[Window::EMPTY; 2]; 3];
        let mut edges = [0.0f32; MAX_EDGES];
        let mut n = 0usize;
        let push = |x: f32, edges: &mut [f32; MAX_EDGES], n: &mut usize| {
            if let Some(e) = edges.get_mut(*n) {
                *e = clamp(x, 0.0, t);
                *n += 1;
            }
        };
        push(0.0, &mut edges, &mut n);
        push(t, &mut edges, &mut n);
        for (w, &duty) in windows.iter_mut().zip(duties.iter()) {
            let d = sanitize_duty(duty);
            let (pos, neg) = if d >= 1.0 {
                (Window { t0: 0.0, t1: t }, Window { t0: 0.0, t1: t })
            } else if d <= 0.0 {
                (Window::EMPTY, Window::EMPTY)
            } else {
                let a = 0.5 * (1.0 - d) * t;
                let b = 0.5 * (1.0 + d) * t;
                let pos = if b - a > td {
                    Window {
                        t0: a + 0.5 * td,
                        t1: b - 0.5 * td,
                    }
                } else {
                    Window::EMPTY
                };
                let neg = Window {
                    t0: clamp(a - 0.5 * td, 0.0, t),
                    t1: clamp(b + 0.5 * td, 0.0, t),
                };
                (pos, neg)
            };
            *w = [pos, neg];
            for win in [pos, neg] {
                if win.t1 > win.t0 {
                    push(win.t0, &mut edges, &mut n);
                    push(win.t1, &mut edges, &mut n);
                }
            }
        }
        SwitchingPattern {
            windows,
            edges: sort_edges(&edges, n),
            n_edges: n,
        }
    }
}

const MAX_EDGES: usize = 14;

/// Selection sort of the first `n` edges (at most 14, all finite): panic-free and without
/// the ordering-violation panic path of `core`'s slice sorts.
fn sort_edges(edges: &[f32; MAX_EDGES], n: usize) -> [f32; MAX_EDGES] {
    let mut out = [0.0f32; MAX_EDGES];
    let mut taken = [false; MAX_EDGES];
    for o in out.iter_mut().take(n) {
        let mut best: Option<usize> = None;
        let mut best_v = f32::INFINITY;
        for (k, (&e, &tk)) in edges.iter().zip(taken.iter()).enumerate().take(n) {
            if !tk && (best.is_none() || e < best_v) {
                best = Some(k);
                best_v = e;
            }
        }
        if let Some(tk) = best.and_then(|k| taken.get_mut(k)) {
            *tk = true;
            *o = best_v;
        }
    }
    out
}

/// A time window [t0, t1) inside the period, s.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Window {
    t0: f32,
    t1: f32,
}

impl Window {
    const EMPTY: Window = Window { t0: 0.0, t1: 0.0 };
    fn contains(&self, t: f32) -> bool {
        t >= self.t0 && t < self.t1
    }
}

/// One interval of a [`SwitchingPattern`] with constant switch states.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SwitchInterval {
    /// Start, s from the period start.
    pub t0: f32,
    /// End, s.
    pub t1: f32,
    /// Leg states (each fraction 0 or 1) during the interval.
    pub legs: [LegState; 3],
}

/// The switch states of one centre-aligned PWM period, split at every switching edge.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SwitchingPattern {
    windows: [[Window; 2]; 3],
    edges: [f32; MAX_EDGES],
    n_edges: usize,
}

impl SwitchingPattern {
    /// Leg states at time `t` (s from the period start).
    pub fn legs_at(&self, t: f32) -> [LegState; 3] {
        let mut legs = [LegState::default(); 3];
        for (l, [pos, neg]) in legs.iter_mut().zip(self.windows.iter()) {
            l.pos = if pos.contains(t) { 1.0 } else { 0.0 };
            l.neg = if neg.contains(t) { 1.0 } else { 0.0 };
        }
        legs
    }

    /// The intervals of non-zero length, in time order (at most 13).
    pub fn intervals(&self) -> impl Iterator<Item = SwitchInterval> + '_ {
        let used = self.edges.get(..self.n_edges).unwrap_or(&[]);
        used.windows(2).filter_map(move |w| match *w {
            [t0, t1] if t1 > t0 => Some(SwitchInterval {
                t0,
                t1,
                legs: self.legs_at(0.5 * (t0 + t1)),
            }),
            _ => None,
        })
    }
}
