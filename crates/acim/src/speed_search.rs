//! Flying start: the rotor speed measured from the voltage the current loops apply while
//! the drive magnetizes with the frame held, before any speed estimate is trusted.
//!
//! ## Principle
//!
//! Magnetizing holds the stator current constant, i_s = i_sd* along the held d axis. With
//! a constant current the machine equations (paper eq. 1-3; design notes section 2, in
//! the inverse-Gamma form the drive uses) reduce to
//!
//! ```text
//! e = v_s - Rs i_s = d lambda_r/dt                       (stator, di_s/dt = 0)
//! d lambda_r/dt = R_R i_s - (1/tau_r - j w) lambda_r     (rotor, w = p Omega)
//! ```
//!
//! so `de/dt = -(1/tau_r - j w) e`: the voltage the current loops need beyond the
//! resistive drop is a vector that decays with the rotor time constant and **rotates at
//! the rotor's electrical speed**. At rest it only decays; a turning rotor makes it turn.
//! Everything constant (the error of the Rs estimate times the DC current, the inverter's
//! voltage error at a DC current) adds a fixed offset `b`.
//!
//! ## Estimator
//!
//! The samples are averaged over blocks of `m` periods (a filter that keeps the mode a
//! mode: the block means obey the same law with `a = exp((-1/tau_r + j w) m Ts)`, and
//! the current-loop noise averages out), then `x[n+1] = a x[n] + b` is fitted by least
//! squares over the window:
//!
//! ```text
//! a = cov(x[n+1], x[n]) / var(x[n]),   cov(y, x) = mean(y conj x) - mean(y) conj mean(x)
//! ```
//!
//! The variance is real and positive, so `arg a = arg cov = w m Ts`: the speed follows
//! from the argument of one complex covariance, without dividing by the variance. `m` is
//! chosen so that the largest speed the drive allows turns the vector by at most pi/4
//! per block (`|Im cov| <= Re cov`, where a polynomial arc tangent is accurate to 1e-5
//! rad); a larger turn is a rotor beyond the speed limit (over-speed, measured, not
//! estimated). The window starts once the current loops have settled and lasts two rotor
//! time constants (the signal decays as `e^(-t/tau_r)`).
//!
//! The result decides the start: below `standstill_speed` the magnetizing goes on as from
//! rest (frame held, standstill Rs identification); above it the drive sets the speed
//! estimate to the measured speed, lets the frame turn with the rotor (zero slip at zero
//! torque current) and builds the flux again from zero in that frame, so the rotor sees a
//! DC current as at rest and the flux model (eq. 13) holds. Any flux left from the search
//! decays with tau_r while the new one builds (the magnetizing waits for the model flux to
//! settle, about 4 tau_r).
//!
//! Cost: a few multiply-adds per step, during the search window only.

use crate::frames::Dq;
use crate::num::DivSqrt;
use crate::num::Num;
use crate::num::PerUnitBases;
use crate::num::Units;

/// The search's constants, from the configuration ([`crate::DriveDesign`]).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SpeedSearchDesign<N: Num = f32> {
    /// Whether the search runs ([`StartSettings::flying_start`](crate::StartSettings::flying_start)).
    pub enabled: bool,
    /// Magnetizing steps before the first sample: five current-loop time constants.
    pub begin_step: u32,
    /// Samples per block, m.
    pub block_len: u32,
    /// Block pairs in the window (two rotor time constants).
    pub pairs: u32,
    /// Voltage (V) to normalised block-mean contribution: 1 / (m V_n), V_n = 2 R_R i_sd*
    /// (twice the largest expected signal, so products stay within 64 in fixed point).
    pub sample_gain: N::Gain,
    /// 1 / pairs: the means over the window.
    pub pair_weight: N::Gain,
    /// Smallest normalised covariance that carries a usable signal (below it the search
    /// is inconclusive and the start goes on as from rest).
    pub signal_floor: N,
    /// Mechanical speed per radian of block rotation, 1 / (p m Ts), rad/s.
    pub speed_per_rad: N::Gain,
    /// |speed| below which the rotor counts as at rest, rad/s mechanical.
    pub standstill_speed: N,
    /// The over-speed limit, rad/s mechanical.
    pub max_speed: N,
    /// atan(t) = t (c0 + c1 t^2 + c2 t^4 + c3 t^6 + c4 t^8) on |t| <= 1 (Abramowitz and
    /// Stegun 4.4.49, |error| <= 1e-5 rad).
    pub atan: [N; 5],
}

/// The polynomial arc tangent's coefficients (Abramowitz and Stegun 4.4.49).
pub const ATAN_COEFFS: [f32; 5] = [0.999_866, -0.330_299_5, 0.180_141, -0.085_133, 0.020_835_1];

/// The window lasts this many rotor time constants.
pub const WINDOW_TAU_R: f32 = 2.0;

/// The window starts after this many current-loop time constants (the current settled).
pub const SETTLE_CURRENT_LOOP_CONSTANTS: f32 = 5.0;

/// The signal floor as a fraction of the smallest covariance a clean search produces (at
/// rest, about 0.058 (R_R i_sd*)^2 over two rotor time constants: normalised by
/// V_n = 2 R_R i_sd*, 0.0145).
pub const SIGNAL_FLOOR: f32 = 1e-3;

/// What the search is designed from: the drive's period, machine and limits.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SpeedSearchSpec {
    /// Whether the search runs ([`StartSettings::flying_start`](crate::StartSettings::flying_start)).
    pub enabled: bool,
    /// The control period Ts, s.
    pub control_period: f32,
    /// The rotor time constant tau_r, s.
    pub rotor_time_constant: f32,
    /// R_R, ohm.
    pub referred_rotor_resistance: f32,
    /// The flux current i_sd*, A.
    pub i_sd_ref: f32,
    /// The current loops' bandwidth, rad/s.
    pub current_bandwidth: f32,
    /// Pole pairs p.
    pub pole_pairs: f32,
    /// The over-speed limit, rad/s mechanical.
    pub max_speed: f32,
    /// Below this the rotor counts as at rest, rad/s electrical.
    pub standstill_frequency: f32,
}

impl SpeedSearchDesign<f32> {
    /// The search for `spec`. `None` when the search is enabled and the largest speed
    /// turns the voltage by more than pi/4 in one period (no block length can resolve it).
    pub fn new(spec: &SpeedSearchSpec) -> Option<Self> {
        let &SpeedSearchSpec {
            enabled,
            control_period: ts,
            rotor_time_constant: tau_r,
            referred_rotor_resistance,
            i_sd_ref,
            current_bandwidth,
            pole_pairs,
            max_speed,
            standstill_frequency,
        } = spec;
        let quarter = 0.25 * core::f32::consts::PI;
        let per_period = pole_pairs * max_speed * ts;
        let resolvable = per_period <= quarter;
        if enabled && !resolvable {
            return None;
        }
        // (a disabled search keeps a well-formed design: one-period blocks)
        let m = if resolvable {
            (quarter / per_period) as u32
        } else {
            1
        };
        let m = m.clamp(1, 64);
        let block = m as f32 * ts;
        let pairs = ((WINDOW_TAU_R * tau_r / block) as u32).max(4);
        let v_n = 2.0 * referred_rotor_resistance * i_sd_ref;
        Some(Self {
            enabled,
            begin_step: (SETTLE_CURRENT_LOOP_CONSTANTS / (current_bandwidth * ts)) as u32,
            block_len: m,
            pairs,
            sample_gain: 1.0 / (m as f32 * v_n),
            pair_weight: 1.0 / pairs as f32,
            signal_floor: SIGNAL_FLOOR,
            speed_per_rad: 1.0 / (pole_pairs * block),
            standstill_speed: standstill_frequency / pole_pairs,
            max_speed,
            atan: ATAN_COEFFS,
        })
    }

    /// Steps from the start to the decision.
    pub fn decision_step(&self) -> u32 {
        self.begin_step + (self.pairs + 1) * self.block_len
    }
}

/// What the search found.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum SearchOutcome<N = f32> {
    /// Still measuring.
    Searching,
    /// The rotor is at rest (below the standstill threshold): start as from rest.
    Standstill,
    /// No usable signal (the covariance below its floor): start as from rest; the control
    /// monitor judges the current response.
    Inconclusive,
    /// The rotor turns at this speed, rad/s mechanical: catch it.
    Turning(N),
    /// The rotor turns faster than the over-speed limit: fault.
    OverSpeed,
}

/// The search's state: block accumulator and the window's running means.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SpeedSearch<N: Num = f32> {
    step: u32,
    in_block: u32,
    blocks: u32,
    acc: Dq<N>,
    prev: Dq<N>,
    mean_x: Dq<N>,
    mean_y: Dq<N>,
    /// mean(y conj x): d real part, q imaginary part.
    cross: Dq<N>,
    /// The outcome (`Searching` until the decision).
    pub outcome: SearchOutcome<N>,
    /// The measured speed at the decision (0 until then), rad/s mechanical.
    pub measured_speed: N,
}

impl<N: Num + DivSqrt> Default for SpeedSearch<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<N: Num + DivSqrt> SpeedSearch<N> {
    /// Before the start.
    pub fn new() -> Self {
        let z = Dq {
            d: N::ZERO,
            q: N::ZERO,
        };
        Self {
            step: 0,
            in_block: 0,
            blocks: 0,
            acc: z,
            prev: z,
            mean_x: z,
            mean_y: z,
            cross: z,
            outcome: SearchOutcome::Searching,
            measured_speed: N::ZERO,
        }
    }

    /// Whether the search has decided (or does not run).
    pub fn done(&self, d: &SpeedSearchDesign<N>) -> bool {
        !d.enabled || self.outcome != SearchOutcome::Searching
    }

    /// One magnetizing step: `v` the voltage applied over the past period and `i` the
    /// measured current, both in the held frame (V, A), `rs` the resistance estimate
    /// (ohm). Returns the outcome once, at the decision; `None` otherwise.
    #[inline(always)]
    pub fn update(
        &mut self,
        d: &SpeedSearchDesign<N>,
        v: Dq<N>,
        i: Dq<N>,
        rs: N,
    ) -> Option<SearchOutcome<N>> {
        if self.done(d) {
            return None;
        }
        self.step = self.step.saturating_add(1);
        if self.step <= d.begin_step {
            return None;
        }
        // e = v - Rs i = d lambda_r/dt, normalised and averaged over the block
        self.acc.d = self.acc.d + N::gain(d.sample_gain, v.d - rs * i.d);
        self.acc.q = self.acc.q + N::gain(d.sample_gain, v.q - rs * i.q);
        self.in_block += 1;
        if self.in_block < d.block_len {
            return None;
        }
        let y = self.acc;
        self.acc = Dq {
            d: N::ZERO,
            q: N::ZERO,
        };
        self.in_block = 0;
        if self.blocks > 0 {
            let (x, w) = (self.prev, d.pair_weight);
            self.mean_x.d = self.mean_x.d + N::gain(w, x.d);
            self.mean_x.q = self.mean_x.q + N::gain(w, x.q);
            self.mean_y.d = self.mean_y.d + N::gain(w, y.d);
            self.mean_y.q = self.mean_y.q + N::gain(w, y.q);
            self.cross.d = self.cross.d + N::gain(w, y.d * x.d + y.q * x.q);
            self.cross.q = self.cross.q + N::gain(w, y.q * x.d - y.d * x.q);
        }
        self.prev = y;
        self.blocks += 1;
        if self.blocks <= d.pairs {
            return None;
        }
        self.outcome = self.decide(d);
        Some(self.outcome)
    }

    /// The decision from the window's covariance (module docs).
    fn decide(&mut self, d: &SpeedSearchDesign<N>) -> SearchOutcome<N> {
        let (mx, my) = (self.mean_x, self.mean_y);
        let re = self.cross.d - (my.d * mx.d + my.q * mx.q);
        let im = self.cross.q - (my.q * mx.d - my.d * mx.q);
        if re.abs() <= d.signal_floor && im.abs() <= d.signal_floor {
            return SearchOutcome::Inconclusive;
        }
        // beyond pi/4 per block (or backwards): faster than the search resolves, which
        // the block length puts above the over-speed limit
        // (written so that a NaN, impossible behind the gate, would also land here)
        let within_quarter_turn = re > d.signal_floor && im.abs() <= re;
        if !within_quarter_turn {
            return SearchOutcome::OverSpeed;
        }
        // re > floor > 0: the reciprocal is guarded; |t| <= 1
        let t = im * re.recip();
        let t2 = t * t;
        let [c0, c1, c2, c3, c4] = d.atan;
        let angle = t * (c0 + t2 * (c1 + t2 * (c2 + t2 * (c3 + t2 * c4))));
        let speed = N::gain(d.speed_per_rad, angle);
        self.measured_speed = speed;
        if speed.abs() > d.max_speed {
            SearchOutcome::OverSpeed
        } else if speed.abs() < d.standstill_speed {
            SearchOutcome::Standstill
        } else {
            SearchOutcome::Turning(speed)
        }
    }
}

impl SpeedSearchDesign<f32> {
    /// This design in the arithmetic `N` with the bases `b`: voltages of V_base in,
    /// speeds of Omega_base out; the normalised covariance and the arc tangent's argument
    /// are dimensionless. Fails naming the setting the value depends on.
    pub fn convert<N: Num + Units>(
        &self,
        b: &PerUnitBases,
    ) -> Result<SpeedSearchDesign<N>, &'static str> {
        let g = crate::num::gain_in::<N>;
        Ok(SpeedSearchDesign {
            enabled: self.enabled,
            begin_step: self.begin_step,
            block_len: self.block_len,
            pairs: self.pairs,
            sample_gain: g(self.sample_gain * b.voltage, "loops.flux_current")?,
            pair_weight: g(self.pair_weight, "machine")?,
            signal_floor: N::from_f32(self.signal_floor),
            speed_per_rad: g(self.speed_per_rad / b.speed, "loops.control_period")?,
            standstill_speed: N::checked_from_f32(self.standstill_speed / b.speed)
                .ok_or("estimation.rs_max_frequency")?,
            max_speed: N::checked_from_f32(self.max_speed / b.speed).ok_or("limits.max_speed")?,
            atan: self.atan.map(N::from_f32),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The paper machine's numbers: tau_r = 0.56/8.4 s, R_R = (0.54/0.56)^2 8.4 ohm.
    fn design() -> SpeedSearchDesign {
        let tau_r = 0.56 / 8.4;
        let rr = (0.54f32 / 0.56).powi(2) * 8.4;
        SpeedSearchDesign::new(&SpeedSearchSpec {
            enabled: true,
            control_period: 200e-6,
            rotor_time_constant: tau_r,
            referred_rotor_resistance: rr,
            i_sd_ref: 1.5,
            current_bandwidth: 1000.0,
            pole_pairs: 2.0,
            max_speed: 2000.0 * crate::math::RPM_TO_RAD_S,
            standstill_frequency: 2.0 * core::f32::consts::PI * 1.5,
        })
        .unwrap()
    }

    /// Feeds the ideal voltage of a constant current into a rotor turning at `w`
    /// (electrical rad/s): e = R_R i e^((-1/tau_r + j w) t) plus an offset `b`.
    fn run(w: f32, b: (f32, f32), noise: f32) -> (SearchOutcome, f32) {
        let d = design();
        let mut s = SpeedSearch::new();
        let (tau_r, ts) = (0.56f32 / 8.4, 200e-6f32);
        let rr = (0.54f32 / 0.56).powi(2) * 8.4;
        let (rs, i) = (10.5f32, 1.5f32);
        let mut seed = 12345u32;
        for k in 0..20_000 {
            let t = k as f32 * ts;
            let mag = rr * i * (-t / tau_r).exp();
            let mut rnd = || {
                seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                (seed >> 8) as f32 / (1u32 << 24) as f32 - 0.5
            };
            let v = Dq {
                d: rs * i + mag * (w * t).cos() + b.0 + noise * rnd(),
                q: mag * (w * t).sin() + b.1 + noise * rnd(),
            };
            if let Some(o) = s.update(&d, v, Dq { d: i, q: 0.0 }, rs) {
                return (o, s.measured_speed);
            }
        }
        (s.outcome, s.measured_speed)
    }

    #[test]
    fn block_length_keeps_the_speed_limit_within_a_quarter_turn() {
        let d = design();
        let w_max = 2.0 * 2000.0 * crate::math::RPM_TO_RAD_S;
        let per_block = w_max * d.block_len as f32 * 200e-6;
        assert!(per_block <= 0.25 * core::f32::consts::PI, "{per_block}");
        assert!(per_block > 0.125 * core::f32::consts::PI, "{per_block}");
        assert!(d.pairs >= 40, "{}", d.pairs);
    }

    #[test]
    fn measures_the_rotor_speed_both_ways_with_offsets_and_noise() {
        for rpm in [
            -1000.0f32, -300.0, -60.0, 60.0, 150.0, 500.0, 1000.0, 1800.0,
        ] {
            let w = 2.0 * rpm * crate::math::RPM_TO_RAD_S;
            let (o, speed) = run(w, (3.0, -2.0), 2.0);
            let SearchOutcome::Turning(s) = o else {
                panic!("{rpm} rpm: {o:?}");
            };
            assert_eq!(s, speed);
            let err = (s * crate::math::RAD_S_TO_RPM - rpm).abs();
            // the noise (0.58 V rms per sample, the current loops' share of 10-25 mA of
            // sensor noise) leaves about 10 rpm of spread: well below the standstill
            // threshold (45 rpm)
            assert!(err < 0.01 * rpm.abs() + 15.0, "{rpm} rpm: {err} rpm off");
        }
    }

    #[test]
    fn at_rest_is_standstill_despite_offsets_and_noise() {
        let (o, speed) = run(0.0, (5.0, 3.0), 2.0);
        assert_eq!(o, SearchOutcome::Standstill, "{speed}");
        assert!(speed.abs() * crate::math::RAD_S_TO_RPM < 15.0, "{speed}");
    }

    #[test]
    fn beyond_the_speed_limit_is_over_speed() {
        let w = 2.0 * 2600.0 * crate::math::RPM_TO_RAD_S;
        assert_eq!(run(w, (0.0, 0.0), 0.0).0, SearchOutcome::OverSpeed);
    }

    #[test]
    fn no_signal_is_inconclusive() {
        let d = design();
        let mut s = SpeedSearch::new();
        let mut out = None;
        for _ in 0..20_000 {
            let v = Dq { d: 15.75, q: 0.0 };
            if let Some(o) = s.update(&d, v, Dq { d: 1.5, q: 0.0 }, 10.5) {
                out = Some(o);
                break;
            }
        }
        assert_eq!(out, Some(SearchOutcome::Inconclusive));
        assert!(s.done(&d));
    }

    #[test]
    fn a_period_too_long_for_the_speed_limit_is_refused() {
        let tau_r = 0.56 / 8.4;
        let max_speed = 2000.0 * crate::math::RPM_TO_RAD_S;
        // p max_speed Ts = 2 * 209 * 2e-3 = 0.84 > pi/4
        let d = SpeedSearchDesign::new(&SpeedSearchSpec {
            enabled: true,
            control_period: 2e-3,
            rotor_time_constant: tau_r,
            referred_rotor_resistance: 7.8,
            i_sd_ref: 1.5,
            current_bandwidth: 100.0,
            pole_pairs: 2.0,
            max_speed,
            standstill_frequency: 9.4,
        });
        assert!(d.is_none());
        let mut cfg = crate::DriveConfig::paper_defaults();
        cfg.loops.control_period = 2e-3;
        cfg.loops.current_bandwidth = 100.0;
        cfg.loops.speed_bandwidth = 5.0;
        let e = crate::DriveDesign::new(cfg).unwrap_err();
        assert!(
            matches!(
                e,
                crate::ConfigError::Invalid {
                    field: "start.flying_start",
                    ..
                }
            ),
            "{e:?}"
        );
        let mut off = cfg;
        off.start.flying_start = false;
        assert!(
            crate::DriveDesign::new(off).is_ok(),
            "{:?}",
            crate::DriveDesign::new(off)
        );
    }

    #[test]
    fn a_disabled_search_never_decides() {
        let mut d = design();
        d.enabled = false;
        let mut s = SpeedSearch::new();
        for _ in 0..1000 {
            assert!(s
                .update(&d, Dq { d: 1.0, q: 2.0 }, Dq { d: 1.5, q: 0.0 }, 10.5)
                .is_none());
        }
        assert!(s.done(&d));
    }
}
