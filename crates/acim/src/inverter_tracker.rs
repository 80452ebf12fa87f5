//! The inverter's voltage error tracked while running (online part):
//! its sixth harmonic, which the stator resistance does not make.
//!
//! Each leg's error voltage opposes its current: the machine sees the command less
//! E sigma_x, sigma_x the sign of phase x's current (linearised within the compensation's
//! current band, the modulator's own `sat(i_x / i_band)`), E the error per leg the
//! compensation leaves (the configured dead time, device drop and the start test's
//! correction against the inverter's). Clarke of (sigma_a, sigma_b, sigma_c) is a vector
//! on the hexagon's vertices (magnitude 4/3) that steps every 60 degrees of the current's
//! angle: along the current, its mean is the fundamental (4/pi) E, which no steady
//! measurement can tell from a resistance error dRs |i| (docs/robustness.md, "Online");
//! across the current, its component is `(4/3) sin(delta)` with delta the vertex's angle from
//! the current, uniform in +/-30 degrees: a sawtooth at six times the stator frequency with
//! zero mean, mean square (16/9)(1/2 - 3 sqrt(3) / (4 pi)) = 0.154, which a resistance
//! (its voltage is along the current) cannot make at all.
//!
//! The current loops, of bandwidth w_c, answer a disturbance at 6 w_s by putting it into
//! their command, w_c / (j 6 w_s + w_c) of it. So the command's component across the
//! current reference, `y = v x i_ref` (the cross product, frame-invariant), carries
//! `E (sigma x i_ref)` with a phase lag below 45 degrees while 6 |w_s| <= w_c, plus the
//! slow part (the back-EMF across the current), which a low-pass `b` over
//! [`INVERTER_TRACKER_DC_TIME`] removes. The law is a null-seeking correlation:
//!
//! `d/dt correction = x (y - b) / (tau 0.154 V_dc (|i_ref|^2 + floor))`, `x = sigma x i_ref`,
//!
//! which at convergence has compensated the error (no sixth harmonic left in the
//! command): the loop's gain and phase at 6 w_s set the rate, not the fixed point
//! (measured: a 1.7-2.2 s time constant for tau = 1 s). The floor (1 % of i_sd*^2) keeps
//! the divisor from vanishing.
//!
//! Gates, each from a failure (docs/robustness.md, "Online: the sixth harmonic"): the
//! running Rs law adapting this step (the resistance estimate carries the error the
//! correction takes away; without the law, a tracker at no load left Rs_hat 7 % low and the
//! next load step lost the orientation), the speed reference not ramping (the low-pass
//! lags a ramp's back-EMF; the regeneration limit's hold, which moves the reference with
//! the speed at a torque that is a slow function of it, is not a ramp), |w_s| at least
//! [`INVERTER_TRACKER_MIN_FREQUENCY_HZ`] and 6 |w_s| at most the current bandwidth, the modulation linear, and
//! [`INVERTER_TRACKER_HOLDOFF`] of open gate before it adapts (a load step's recovery moved
//! the correction by 0.2 us in 0.1 s without it). The correction is bounded as the start
//! test's (+/- 0.05 duty).
//!
//! After [`INVERTER_TRACKER_TRUST`] of adaptation (summed since power-up) the drive takes
//! the correction as known, as after a start test that identified the error: the far-side
//! mode's condition. A correction at its bound is not taken as known (the bound cut the
//! error short). Without the start test, a drive held by the regeneration limit at
//! 60 rpm regenerating 4.5 N m learns the error there and crosses the line 5.3-6.2 s
//! after the load (docs/robustness.md, "A trusted tracker stands in for the start test").

use crate::frames::{clarke_three, park, Dq, SinCosValue};
use crate::num::DivSqrt;
use crate::num::Num;
use crate::num::PerUnitBases;
use crate::num::ThreePhase;
use crate::num::Units;

/// Below this stator frequency the tracker holds, Hz.
pub const INVERTER_TRACKER_MIN_FREQUENCY_HZ: f32 = 1.0;
/// The low-pass that takes the slow part out of the command's cross component, s.
pub const INVERTER_TRACKER_DC_TIME: f32 = 0.1;
/// The correction's time constant for a loop that passes the whole disturbance, s.
pub const INVERTER_TRACKER_TIME: f32 = 1.0;
/// The gate holds this long before the tracker adapts (the DC filter settles and a
/// transient's remains pass), s.
pub const INVERTER_TRACKER_HOLDOFF: f32 = 0.5;
/// The tracker has adapted this long (summed over the run since power-up, like the
/// correction it adapts) before the drive trusts its correction as it trusts the start
/// test's ([`InverterTracker::trusted`]): about 1.5 of its measured 1.7-2.2 s time
/// constants, s.
pub const INVERTER_TRACKER_TRUST: f32 = 3.0;
/// Mean square of the sign vector's component across the current (see the module).
pub const CROSS_MEAN_SQUARE: f32 = 0.154;

/// The tracker's design ([`TrackerSettings::inverter_tracking`](crate::TrackerSettings::inverter_tracking)).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct InverterTrackerConfig<N: Num = f32> {
    /// Whether it runs.
    pub enabled: bool,
    /// The DC low-pass, per step.
    pub dc_filter: N::Gain,
    /// Ts / (tau 0.154) per step, applied to x (y - b) / (V_dc (|i_ref|^2 + floor)).
    pub rate: N::Gain,
    /// The floor added to |i_ref|^2 in the normalisation (0.01 i_sd*^2; the divisor
    /// cannot vanish), A^2.
    pub current_floor: N,
    /// The gate's lower |w_s|, rad/s.
    pub min_frequency: N,
    /// The gate's upper |w_s|, rad/s (6 |w_s| <= current bandwidth).
    pub max_frequency: N,
    /// The correction's bound, duty.
    pub limit: N,
    /// Steps of open gate before adapting.
    pub holdoff_steps: u32,
    /// Steps of adaptation before the correction is trusted.
    pub trust_steps: u32,
}

impl InverterTrackerConfig<f32> {
    /// The design for period `ts` (s), the flux current `flux_current` (A) and the current
    /// loops' bandwidth `current_bandwidth` (rad/s).
    pub fn new(enabled: bool, ts: f32, flux_current: f32, current_bandwidth: f32) -> Self {
        Self {
            enabled,
            dc_filter: (ts / INVERTER_TRACKER_DC_TIME).min(1.0),
            rate: ts / (INVERTER_TRACKER_TIME * CROSS_MEAN_SQUARE),
            current_floor: (0.01 * flux_current * flux_current).max(1e-6),
            min_frequency: 2.0 * core::f32::consts::PI * INVERTER_TRACKER_MIN_FREQUENCY_HZ,
            max_frequency: current_bandwidth / 6.0,
            limit: crate::inverter_test::INVERTER_TEST_MAX_DUTY,
            holdoff_steps: (INVERTER_TRACKER_HOLDOFF / ts) as u32,
            trust_steps: (INVERTER_TRACKER_TRUST / ts) as u32,
        }
    }
}

/// The sign vector sigma in the dq frame at `rot`: Clarke of the three phases'
/// `sat(i_x / i_band)`, the linearised signs the modulator compensates with
/// (`signs`, [`crate::svpwm::current_signs`] of the predicted phase currents).
#[inline(always)]
pub fn sign_vector<N: Num + DivSqrt + ThreePhase + DivSqrt + ThreePhase>(
    signs: [N; 3],
    rot: SinCosValue<N>,
) -> Dq<N> {
    park(clarke_three(signs[0], signs[1], signs[2]), rot)
}

/// The tracker's state.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct InverterTracker<N: Num = f32> {
    /// The low-passed cross component of the command, V A.
    dc: N,
    /// Steps since the gate opened (saturating).
    open_steps: u32,
    /// Steps it adapted since power-up (saturating; the correction is kept across
    /// starts, and so is this).
    adapted_steps: u32,
    /// Whether the last step adapted.
    pub active: bool,
}

/// What the tracker reads each step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct InverterTrackerInputs<N: Num = f32> {
    /// The voltage command, rotor-flux frame, V.
    pub v: Dq<N>,
    /// The current reference, same frame, A.
    pub i_ref: Dq<N>,
    /// The sign vector in that frame ([`sign_vector`]).
    pub sigma: Dq<N>,
    /// 1/V_dc, 1/V.
    pub inv_dc_bus: N,
    /// The stator frequency w_s, rad/s electrical.
    pub stator_frequency: N,
    /// The drive's conditions hold (running, linear, not ramping).
    pub gate: bool,
}

impl<N: Num + DivSqrt + ThreePhase + DivSqrt + ThreePhase> InverterTracker<N> {
    /// Whether it has adapted for [`INVERTER_TRACKER_TRUST`] and its `correction` (duty)
    /// is inside the bound: the drive then takes the correction as known, as after a
    /// start test that identified the error (the far-side mode's condition,
    /// [`EstimationSettings::far_side_gain`](crate::EstimationSettings::far_side_gain)). A correction at the bound is an error the
    /// bound cut short (an inverter beyond the range, or a tracker misled), not a known one.
    #[inline(always)]
    pub fn trusted(&self, cfg: &InverterTrackerConfig<N>, correction: N) -> bool {
        cfg.enabled && self.adapted_steps >= cfg.trust_steps && correction.abs() < cfg.limit
    }

    /// One step on the inputs `x`. Returns the new correction from `correction` (duty).
    #[inline(always)]
    pub fn update(
        &mut self,
        cfg: &InverterTrackerConfig<N>,
        x: &InverterTrackerInputs<N>,
        correction: N,
    ) -> N {
        let &InverterTrackerInputs {
            v,
            i_ref,
            sigma,
            inv_dc_bus,
            stator_frequency,
            gate,
        } = x;
        let y = v.q * i_ref.d - v.d * i_ref.q;
        let ws = stator_frequency.abs();
        let on = cfg.enabled && gate && ws >= cfg.min_frequency && ws <= cfg.max_frequency;
        if !on {
            // (gated off: the cheap periods, marked cold so that the adapting ones fall
            // through)
            core::hint::cold_path();
            self.dc = y;
            self.open_steps = 0;
            self.active = false;
            return correction;
        }
        self.dc = self.dc + N::gain(cfg.dc_filter, y - self.dc);
        self.open_steps = self.open_steps.saturating_add(1);
        self.active = self.open_steps > cfg.holdoff_steps;
        if !self.active {
            core::hint::cold_path();
            return correction;
        }
        self.adapted_steps = self.adapted_steps.saturating_add(1);
        let x = sigma.q * i_ref.d - sigma.d * i_ref.q;
        let i2 = i_ref.d * i_ref.d + i_ref.q * i_ref.q + cfg.current_floor;
        let step = N::gain(cfg.rate, N::ratio(x * (y - self.dc) * inv_dc_bus, i2));
        (correction + step).clamp(-cfg.limit, cfg.limit)
    }
}

impl InverterTrackerConfig<f32> {
    /// This design in the arithmetic `N` with the bases `b`: its rate needs no scaling
    /// (the per-unit bases of `x (y - b) / (V_dc |i_ref|^2)` cancel: the step is a duty
    /// either way); its current floor is in current units squared. `None` if a gain is
    /// not representable.
    pub fn convert<N: Num + Units>(&self, b: &PerUnitBases) -> Option<InverterTrackerConfig<N>> {
        Some(InverterTrackerConfig {
            enabled: self.enabled,
            dc_filter: N::gain_from_f32(self.dc_filter)?,
            rate: N::gain_from_f32(self.rate)?,
            current_floor: N::from_f32(self.current_floor / (b.current * b.current)),
            min_frequency: N::from_f32(self.min_frequency / b.frequency),
            max_frequency: N::from_f32(self.max_frequency / b.frequency),
            limit: N::from_f32(self.limit),
            holdoff_steps: self.holdoff_steps,
            trust_steps: self.trust_steps,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frames::{inverse_clarke, inverse_park};
    use crate::svpwm::current_signs;

    const TS: f32 = 2e-4;
    const VDC: f32 = 325.0;
    const BAND: f32 = 0.05;

    /// A current loop that puts the uncompensated error into its command: the command is
    /// the back-EMF `dc` (dq, constant) plus `E - c V_dc` times the sign vector, with the
    /// current reference `i_ref` turning at `f_s` Hz. Returns the correction after `secs`.
    fn run(e_true: f32, f_s: f32, i_ref: Dq, dc: Dq, secs: f32, gate: bool) -> f32 {
        let cfg = InverterTrackerConfig::new(true, TS, 1.4, 1000.0);
        let mut t = InverterTracker::default();
        let mut c = 0.0f32;
        let w = core::f32::consts::TAU * f_s;
        for k in 0..(secs / TS) as usize {
            let th = w * k as f32 * TS;
            let rot = SinCosValue {
                sin: th.sin(),
                cos: th.cos(),
            };
            let sigma = sign_vector(
                current_signs(1.0 / BAND, inverse_clarke(inverse_park(i_ref, rot))),
                rot,
            );
            let e = e_true - c * VDC;
            let v = Dq {
                d: dc.d + e * sigma.d,
                q: dc.q + e * sigma.q,
            };
            c = t.update(
                &cfg,
                &InverterTrackerInputs {
                    v,
                    i_ref,
                    sigma,
                    inv_dc_bus: 1.0 / VDC,
                    stator_frequency: w,
                    gate,
                },
                c,
            );
        }
        c
    }

    #[test]
    fn converges_to_the_error_the_compensation_leaves() {
        let i = Dq { d: 1.4, q: 2.0 };
        let emf = Dq { d: -3.0, q: 60.0 };
        // 0.8 V over-compensated and 1.1 V under-compensated, at 2 and 15 Hz
        for (e, f) in [(-0.8, 2.0), (1.1, 15.0), (1.1, -5.0)] {
            let c = run(e, f, i, emf, 12.0, true);
            assert!(
                (c * VDC - e).abs() < 0.02 * e.abs(),
                "{e} V at {f} Hz: {}",
                c * VDC
            );
        }
        // nothing to correct: it stays
        assert!(run(0.0, 5.0, i, emf, 5.0, true).abs() * VDC < 1e-3);
    }

    #[test]
    fn holds_outside_its_gate() {
        let i = Dq { d: 1.4, q: 1.0 };
        let emf = Dq { d: 0.0, q: 30.0 };
        // closed gate, below 1 Hz, above w_c / 6 (1000 rad/s: 26.5 Hz)
        assert_eq!(run(1.0, 5.0, i, emf, 3.0, false), 0.0);
        assert_eq!(run(1.0, 0.8, i, emf, 3.0, true), 0.0);
        assert_eq!(run(1.0, 30.0, i, emf, 3.0, true), 0.0);
        // and waits out its holdoff
        assert_eq!(
            run(1.0, 5.0, i, emf, INVERTER_TRACKER_HOLDOFF - 0.01, true),
            0.0
        );
    }

    #[test]
    fn trusted_after_its_adaptation_time_summed_over_open_gates() {
        let cfg = InverterTrackerConfig::new(true, TS, 1.4, 1000.0);
        let mut t = InverterTracker::default();
        let (v, i) = (Dq { d: 10.0, q: 40.0 }, Dq { d: 1.4, q: 1.0 });
        let sigma = Dq { d: 0.5, q: 0.5 };
        let w = core::f32::consts::TAU * 5.0;
        let steps = |t: &mut InverterTracker, secs: f32, gate: bool| {
            for _ in 0..(secs / TS) as usize {
                t.update(
                    &cfg,
                    &InverterTrackerInputs {
                        v,
                        i_ref: i,
                        sigma,
                        inv_dc_bus: 1.0 / VDC,
                        stator_frequency: w,
                        gate,
                    },
                    0.0,
                );
            }
        };
        // two open spells of 2 s: each adapts 1.5 s after its holdoff
        steps(&mut t, 2.0, true);
        steps(&mut t, 1.0, false);
        assert!(!t.trusted(&cfg, 0.0));
        steps(&mut t, 2.0 - 0.01, true);
        assert!(!t.trusted(&cfg, 0.0));
        steps(&mut t, 0.02, true);
        assert!(t.trusted(&cfg, 0.0));
        // a closed gate does not take the trust back (the correction is kept)
        steps(&mut t, 1.0, false);
        assert!(t.trusted(&cfg, 0.0));
        // a correction at its bound is not trusted, one just inside it is
        assert!(!t.trusted(&cfg, cfg.limit));
        assert!(!t.trusted(&cfg, -cfg.limit));
        assert!(t.trusted(&cfg, 0.99 * cfg.limit));
        // and a tracker switched off is never trusted
        let off = InverterTrackerConfig::new(false, TS, 1.4, 1000.0);
        assert!(!t.trusted(&off, 0.0));
    }

    #[test]
    fn a_resistance_error_does_not_move_it() {
        // a resistance error's voltage is along the current: dR i_ref, no cross part
        let cfg = InverterTrackerConfig::new(true, TS, 1.4, 1000.0);
        let mut t = InverterTracker::default();
        let mut c = 0.0f32;
        let i = Dq { d: 1.4, q: 2.0 };
        let w = core::f32::consts::TAU * 3.0;
        for k in 0..(5.0 / TS) as usize {
            let th = w * k as f32 * TS;
            let rot = SinCosValue {
                sin: th.sin(),
                cos: th.cos(),
            };
            let sigma = sign_vector(
                current_signs(1.0 / BAND, inverse_clarke(inverse_park(i, rot))),
                rot,
            );
            // a resistance error that changes with time (a thermal ramp) along the current
            let dr = 2.0 * k as f32 * TS / 5.0;
            let v = Dq {
                d: 10.0 + dr * i.d,
                q: 40.0 + dr * i.q,
            };
            c = t.update(
                &cfg,
                &InverterTrackerInputs {
                    v,
                    i_ref: i,
                    sigma,
                    inv_dc_bus: 1.0 / VDC,
                    stator_frequency: w,
                    gate: true,
                },
                c,
            );
        }
        // what is left is the DC filter's lag behind the ramp times the sawtooth's mean
        // over a part period: about 2 mV, a thousandth of a 1 us error's 1.6 V
        assert!(c.abs() * VDC < 0.01, "{}", c * VDC);
    }
}
