//! The current loop: d/q PIs with the decoupling feed-forward of eq. (9a, 9b), the voltage
//! vector limited with d-axis priority, and the overmodulation reserve that lets the
//! loops borrow a modulator's range above its sustained limit for a while.

use crate::config::DriveConfig;
use crate::frames::Dq;
use crate::num::DivSqrt;
use crate::num::Num;
use crate::num::PerUnitBases;
use crate::num::ThreePhase;
use crate::num::Units;
use crate::pi::{PiConfig, PiController};
use crate::svpwm::VoltageLimit;

/// How long the current loops may use a modulator's range above its sustained limit in
/// one stretch, s (the [`crate::svpwm::Overmodulation`] reserve): long enough for a current
/// transient and half a speed-loop transient (the current loops settle in about 3 ms, the
/// speed loop in about 0.1 s), short enough that a drive held at its voltage limit (a
/// target beyond the reachable speed) runs in the linear range, where its current samples
/// carry no overmodulation harmonics.
pub const OVERMODULATION_RESERVE_TIME: f32 = 0.05;

/// The current loop's design.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CurrentLoopConfig<N: Num = f32> {
    /// d-axis current PI (eq. 9a plant; pole cancellation).
    pub pi_d: PiConfig<N>,
    /// q-axis current PI (eq. 9b plant).
    pub pi_q: PiConfig<N>,
    /// Steps the loops may spend beyond the sustained voltage limit in a row before it
    /// applies ([`OVERMODULATION_RESERVE_TIME`]; only a modulator whose
    /// [`VoltageLimit::sustained`] is below its `max` has such a reserve).
    pub overmodulation_reserve_steps: u32,
}

impl CurrentLoopConfig {
    /// The design for `cfg`, with the PIs at the bandwidth `current_bandwidth` against
    /// the voltage `v_static` the static decoupling leaves them (V).
    pub fn new(cfg: &DriveConfig, v_static: f32) -> Self {
        let ts = cfg.loops.control_period;
        let pi = PiConfig::current_loop(&cfg.machine, cfg.loops.current_bandwidth, ts, v_static);
        Self {
            pi_d: pi,
            pi_q: pi,
            overmodulation_reserve_steps: ((OVERMODULATION_RESERVE_TIME / ts) as u32).max(1),
        }
    }
}

/// The machine-model constants and this step's signals the current loop reads (SI in
/// f32, per unit in fixed point).
#[derive(Clone, Copy, Debug)]
pub struct CurrentLoopInputs<N: Num> {
    /// R_R, ohm.
    pub referred_rotor_resistance: N,
    /// 1/tau_r: flux -> voltage (lambda_r / tau_r).
    pub inv_rotor_time_constant: N::Gain,
    /// sigma Ls: (frequency x current) -> voltage.
    pub transient_inductance: N::Gain,
    /// p: (speed x flux) -> voltage (the back-EMF p Omega lambda_r).
    pub back_emf: N::Gain,
    /// Rs_hat, ohm.
    pub stator_resistance: N,
    /// Stator frequency w_s, rad/s electrical.
    pub stator_frequency: N,
    /// Model rotor flux lambda_r, Wb.
    pub rotor_flux: N,
    /// Omega_hat, rad/s mechanical.
    pub speed: N,
    /// i_dq*, A.
    pub reference: Dq<N>,
    /// Measured i_dq, A.
    pub current: Dq<N>,
    /// The voltage limit this step ([`CurrentLoop::limit`]).
    pub limit: VoltageLimit<N>,
}

/// The current loop's state: the two PIs and the overmodulation reserve.
#[derive(Clone, Copy, Debug)]
pub struct CurrentLoop<N> {
    d: PiController<N>,
    q: PiController<N>,
    /// Steps left of the overmodulation reserve (`overmodulation_reserve_steps` when
    /// full).
    reserve: u32,
}

impl<N: Num + DivSqrt + ThreePhase + DivSqrt + ThreePhase> Default for CurrentLoop<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<N: Num + DivSqrt + ThreePhase + DivSqrt + ThreePhase> CurrentLoop<N> {
    /// Integrals zero, no reserve.
    pub fn new() -> Self {
        Self {
            d: PiController::new(),
            q: PiController::new(),
            reserve: 0,
        }
    }

    /// The d-axis PI (its integral and saturation: supervision).
    #[inline(always)]
    pub fn d(&self) -> &PiController<N> {
        &self.d
    }

    /// The q-axis PI (its integral is the voltage the model misses; its saturation: the
    /// torque is short of voltage).
    #[inline(always)]
    pub fn q(&self) -> &PiController<N> {
        &self.q
    }

    /// The voltage limit this step. A modulator with a range above its sustained limit
    /// (`overmodulates`, [`crate::svpwm::Overmodulation`]) lends it as a reserve: each step
    /// whose command (`last_voltage`, the last one) was beyond the sustained limit uses a
    /// step of it, each step at or below returns one, and with none left the sustained
    /// limit applies ([`OVERMODULATION_RESERVE_TIME`]). A modulator without one
    /// ([`crate::Svpwm`]: `sustained == max`) passes unchanged.
    #[inline(always)]
    pub fn limit(
        &mut self,
        cfg: &CurrentLoopConfig<N>,
        limit: VoltageLimit<N>,
        last_voltage: Dq<N>,
        overmodulates: bool,
    ) -> VoltageLimit<N> {
        if !overmodulates || limit.sustained >= limit.max {
            return limit;
        }
        let v = last_voltage;
        let s = limit.sustained;
        let r = &mut self.reserve;
        if v.d * v.d + v.q * v.q > s * s {
            *r = r.saturating_sub(1);
        } else if *r < cfg.overmodulation_reserve_steps {
            *r += 1;
        }
        if *r == 0 {
            VoltageLimit {
                max: s,
                inv_max: limit.inv_sustained,
                ..limit
            }
        } else {
            limit
        }
    }

    /// One step: d/q PIs with decoupling feed-forward (eq. 9a, 9b), the voltage vector
    /// limited to `x.limit` with d-axis priority. Returns v_dq*, V.
    #[inline(always)]
    pub fn update(&mut self, cfg: &CurrentLoopConfig<N>, x: &CurrentLoopInputs<N>) -> Dq<N> {
        let (rs, ws, lambda) = (x.stator_resistance, x.stator_frequency, x.rotor_flux);
        let (i_sd_ref, i_sq_ref) = (x.reference.d, x.reference.q);
        // eq. (9a): v_sd = Rseq i_sd - lambda_r/tau_r - sigma Ls w_s i_sq
        let ff_d = N::sum_times(rs, x.referred_rotor_resistance, i_sd_ref)
            - N::gain(x.inv_rotor_time_constant, lambda)
            - N::gain_mul(x.transient_inductance, ws, i_sq_ref);
        // eq. (9b): v_sq = Rseq i_sq + sigma Ls w_s i_sd + p Omega lambda_r
        let ff_q = (rs + x.referred_rotor_resistance) * i_sq_ref
            + N::gain_mul(x.transient_inductance, ws, i_sd_ref)
            + N::gain_mul(x.back_emf, x.speed, lambda);
        let v_max = x.limit.max;
        let v_d = self
            .d
            .update_with_limits(&cfg.pi_d, i_sd_ref - x.current.d, ff_d, -v_max, v_max);
        // q limit on the circle |v| <= v_max with d priority, sqrt(v_max^2 - v_d^2), without
        // a square root: the Taylor bound v_max - v_d^2/(2 v_max) while |v_d| <= v_max/2
        // (at most 1 % above the circle there), the chord sqrt(3) (v_max - |v_d|) beyond
        // (inside the circle, zero when v_d is at its limit)
        let ad = v_d.abs();
        let v_q_max = if ad <= v_max.half() {
            v_max - (v_d * v_d).half() * x.limit.inv_max
        } else {
            core::hint::cold_path();
            N::SQRT3 * (v_max - ad)
        };
        let v_q =
            self.q
                .update_with_limits(&cfg.pi_q, i_sq_ref - x.current.q, ff_q, -v_q_max, v_q_max);
        Dq { d: v_d, q: v_q }
    }
}

impl CurrentLoopConfig<f32> {
    /// This design in the arithmetic `N` with the bases `b` (current error in, voltage
    /// out); `None` if a gain is not representable.
    pub fn convert<N: Num + Units>(&self, b: &PerUnitBases) -> Option<CurrentLoopConfig<N>> {
        Some(CurrentLoopConfig {
            pi_d: self.pi_d.convert(b.current, b.voltage)?,
            pi_q: self.pi_q.convert(b.current, b.voltage)?,
            overmodulation_reserve_steps: self.overmodulation_reserve_steps,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::design::{DriveConfig, DriveDesign};

    fn design() -> DriveDesign {
        DriveDesign::new(DriveConfig::paper_defaults()).unwrap()
    }

    fn limit(max: f32, sustained: f32) -> VoltageLimit {
        VoltageLimit {
            max,
            inv_max: 1.0 / max,
            steady: max,
            sustained,
            inv_sustained: 1.0 / sustained,
        }
    }

    fn inputs(
        d: &DriveDesign,
        reference: Dq,
        current: Dq,
        lim: VoltageLimit,
    ) -> CurrentLoopInputs<f32> {
        CurrentLoopInputs {
            referred_rotor_resistance: d.model.referred_rotor_resistance,
            inv_rotor_time_constant: d.model.inv_rotor_time_constant,
            transient_inductance: d.model.transient_inductance,
            back_emf: d.pole_pairs,
            stator_resistance: d.config.machine.stator_resistance(),
            stator_frequency: 150.0,
            rotor_flux: d.flux_reference,
            speed: 70.0,
            reference,
            current,
            limit: lim,
        }
    }

    #[test]
    fn without_a_reserve_the_limit_passes_unchanged() {
        let d = design();
        let mut c = CurrentLoop::<f32>::new();
        let l = limit(180.0, 180.0);
        let big = Dq { d: 0.0, q: 500.0 };
        assert_eq!(c.limit(&d.current_loop, l, big, true), l);
        assert_eq!(
            c.limit(&d.current_loop, limit(200.0, 180.0), big, false),
            limit(200.0, 180.0)
        );
    }

    #[test]
    fn the_overmodulation_reserve_drains_and_refills() {
        let d = design();
        let n = d.current_loop.overmodulation_reserve_steps;
        let mut c = CurrentLoop::<f32>::new();
        let l = limit(200.0, 180.0);
        let small = Dq { d: 0.0, q: 100.0 };
        let big = Dq { d: 0.0, q: 190.0 };
        for _ in 0..n {
            assert_eq!(c.limit(&d.current_loop, l, small, true).max, 200.0);
        }
        // full: n steps beyond the sustained limit, then the sustained limit applies
        for _ in 0..n - 1 {
            assert_eq!(c.limit(&d.current_loop, l, big, true).max, 200.0);
        }
        let held = c.limit(&d.current_loop, l, big, true);
        assert_eq!((held.max, held.inv_max), (180.0, 1.0 / 180.0));
        // one step at or below returns one step of it
        assert_eq!(c.limit(&d.current_loop, l, small, true).max, 200.0);
    }

    #[test]
    fn with_no_current_error_the_command_is_the_feedforward_of_eq_9() {
        let d = design();
        let mut c = CurrentLoop::<f32>::new();
        let i = Dq { d: 1.5, q: 2.0 };
        let x = inputs(&d, i, i, limit(300.0, 300.0));
        let v = c.update(&d.current_loop, &x);
        let rs = x.stator_resistance;
        let rr = x.referred_rotor_resistance;
        let ff_d = (rs + rr) * i.d
            - x.inv_rotor_time_constant * x.rotor_flux
            - x.transient_inductance * x.stator_frequency * i.q;
        let ff_q = (rs + rr) * i.q
            + x.transient_inductance * x.stator_frequency * i.d
            + x.back_emf * x.speed * x.rotor_flux;
        assert!(
            (v.d - ff_d).abs() < 1e-3 * ff_d.abs().max(1.0),
            "{v:?} {ff_d}"
        );
        assert!(
            (v.q - ff_q).abs() < 1e-3 * ff_q.abs().max(1.0),
            "{v:?} {ff_q}"
        );
    }

    #[test]
    fn a_large_error_stays_inside_the_circle_with_d_priority() {
        let d = design();
        let mut c = CurrentLoop::<f32>::new();
        let x = inputs(
            &d,
            Dq { d: 50.0, q: 50.0 },
            Dq { d: 0.0, q: 0.0 },
            limit(100.0, 100.0),
        );
        for _ in 0..20 {
            let v = c.update(&d.current_loop, &x);
            assert!((v.d * v.d + v.q * v.q).sqrt() <= 100.0 * 1.01, "{v:?}");
            assert!(v.d > 0.0 && v.d <= 100.0);
        }
        assert!(c.d().saturated());
    }
}
