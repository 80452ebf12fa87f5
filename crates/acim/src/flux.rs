//! Rotor-flux model (eq. 13) and the indirect vector-control law (eq. 8): the current
//! model that gives the flux amplitude, the slip frequency and the angle of the dq frame.
//!
//! Eq. (13): d lambda_r/dt = -lambda_r/tau_r + (L_M/tau_r) i_sd, discretised exactly for a
//! constant i_sd over one period: lambda\[k+1\] = lambda\[k\] + g (L_M i_sd - lambda\[k\]),
//! g = 1 - e^(-Ts/tau_r) (written so that the steady state is exactly L_M i_sd in f32).
//! Eq. (8): w_s = p Omega + (L_M/tau_r) i_sq / lambda_r, theta_s\[k+1\] = theta_s\[k\] + w_s Ts.
//! The division by lambda_r is guarded: the flux used in the denominator is never below
//! `min_flux` (a configured fraction of the nominal flux), so start-up from zero flux cannot
//! produce an infinite slip.

use crate::num::Angles;
use crate::num::DivSqrt;
use crate::num::Num;
use crate::num::PerUnitBases;
use crate::num::Units;
use crate::params::MachineParams;

/// Precomputed coefficients of the flux model and slip law (designed in f32 SI; in fixed
/// point the gains also carry the per-unit base conversions).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FluxModelConfig<N: Num = f32> {
    /// g = 1 - e^(-Ts/tau_r), dimensionless.
    pub blend: N::Gain,
    /// L_M = Lm^2/Lr, H (Wb/A).
    pub magnetizing_inductance: N::Gain,
    /// Slip gain L_M/tau_r = (Lm/Lr)^2 Rr, ohm (rad/s per A/Wb).
    pub slip_gain: N::Gain,
    /// Smallest flux used as a divisor in the slip law, Wb.
    pub min_flux: N,
    /// Control period, s (the angle advance per rad/s; turn counts per frequency pu in
    /// fixed point).
    pub ts: N::Gain,
}

impl FluxModelConfig<f32> {
    /// Coefficients for machine `m` (the controller's copy) at period `ts` (s);
    /// `nominal_flux` (Wb) sets the divisor guard at 10 % of it.
    pub fn new(m: &MachineParams, ts: f32, nominal_flux: f32) -> Self {
        let x = ts / m.rotor_time_constant();
        Self {
            // 1 - e^(-x) from its own series: 1.0 - exp(-x) would lose digits to cancellation
            blend: one_minus_exp_neg_small(x),
            magnetizing_inductance: m.magnetizing_inductance(),
            slip_gain: m.magnetizing_inductance() / m.rotor_time_constant(),
            min_flux: (0.1 * nominal_flux).max(1e-3),
            ts,
        }
    }
}

/// 1 - e^(-x) for 0 <= x <= ~1 without cancellation (series x - x^2/2 + ...);
/// configuration time only.
pub(crate) fn one_minus_exp_neg_small(x: f32) -> f32 {
    let mut term = -1.0f32;
    let mut sum = 0.0f32;
    let mut k = 1.0f32;
    while k < 12.0 {
        term *= -x / k;
        sum += term;
        k += 1.0;
    }
    sum
}

/// State of the flux model and frame angle.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FluxModel<N: Num + Angles = f32> {
    /// Estimated rotor flux amplitude lambda_r (Wb, referred to the stator).
    pub rotor_flux: N,
    /// 1 / max(lambda_r, min_flux), 1/Wb, refreshed every step (also used by the observer).
    pub inv_rotor_flux: N,
    /// Slip frequency w_s - p Omega, rad/s electrical.
    pub slip_frequency: N,
    /// Stator frequency w_s (of the rotor-flux frame), rad/s electrical.
    pub stator_frequency: N,
    /// dq-frame angle theta_s, rad electrical wrapped to [-pi, pi) (a turn fraction in
    /// fixed point).
    pub angle: N::Angle,
}

impl<N: Num + DivSqrt + Angles + DivSqrt + Angles> FluxModel<N> {
    /// Zero flux, angle 0.
    pub fn new() -> Self {
        Self::default()
    }

    /// One step: slip (eq. 8) from the present flux and the measured i_sq, stator
    /// frequency from `rotor_speed_elec` (rad/s: the estimated electrical rotor speed
    /// p Omega_hat, plus any frame-frequency correction the caller adds), angle advance,
    /// then the flux update (eq. 13) with the measured i_sd.
    /// When `hold_angle` is set (magnetising), the frame does not rotate.
    #[inline(always)]
    pub fn update(
        &mut self,
        cfg: &FluxModelConfig<N>,
        i_sd: N,
        i_sq: N,
        rotor_speed_elec: N,
        hold_angle: bool,
    ) {
        let divisor = if self.rotor_flux > cfg.min_flux {
            self.rotor_flux
        } else {
            cfg.min_flux
        };
        self.inv_rotor_flux = divisor.recip();
        self.slip_frequency = N::gain_mul(cfg.slip_gain, i_sq, self.inv_rotor_flux);
        self.stator_frequency = if hold_angle {
            N::ZERO
        } else {
            rotor_speed_elec + self.slip_frequency
        };
        self.angle = N::advance(self.angle, self.stator_frequency, cfg.ts);
        let target = N::gain(cfg.magnetizing_inductance, i_sd);
        let next = self.rotor_flux + N::gain(cfg.blend, target - self.rotor_flux);
        // a non-finite current would poison the state: keep the last flux instead
        self.rotor_flux = next.finite_or(self.rotor_flux);
    }
}

impl FluxModelConfig<f32> {
    /// This design in the arithmetic `N` with the bases `b`; `None` if a gain is not
    /// representable.
    pub fn convert<N: Num + Units + Angles>(&self, b: &PerUnitBases) -> Option<FluxModelConfig<N>> {
        Some(FluxModelConfig {
            blend: N::gain_from_f32(self.blend)?,
            magnetizing_inductance: N::gain_from_f32(
                self.magnetizing_inductance * b.current / b.flux,
            )?,
            slip_gain: N::gain_from_f32(self.slip_gain * b.current / (b.flux * b.frequency))?,
            min_flux: N::from_f32(self.min_flux / b.flux),
            ts: N::angle_gain(b.frequency * self.ts)?,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_minus_exp_matches_std() {
        for &x in &[0.0f32, 1e-4, 3e-3, 0.1, 0.5, 1.0] {
            let e1 = one_minus_exp_neg_small(x) as f64 - (1.0 - (-(x as f64)).exp());
            assert!(e1.abs() <= 1e-6 * (x as f64), "{x}: {e1}");
        }
    }

    #[test]
    fn flux_rises_with_rotor_time_constant() {
        let m = MachineParams::paper_table1();
        let ts = 200e-6;
        let cfg = FluxModelConfig::new(&m, ts, m.rotor_flux_for(1.5));
        let mut f = FluxModel::new();
        let tau = m.rotor_time_constant();
        let n = (tau / ts).round() as usize;
        for _ in 0..n {
            f.update(&cfg, 1.5, 0.0, 0.0, true);
        }
        let target = m.rotor_flux_for(1.5);
        let expect = target * (1.0 - (-(n as f32) * ts / tau).exp());
        assert!(
            (f.rotor_flux - expect).abs() < 1e-4 * target,
            "{} vs {}",
            f.rotor_flux,
            expect
        );
        assert_eq!(f.angle, 0.0);
        for _ in 0..20 * n {
            f.update(&cfg, 1.5, 0.0, 0.0, true);
        }
        // f32 limit: the update stalls once g*(target - flux) < ulp(flux)/2, i.e. within
        // ulp(0.78)/(2 g) = 6e-8/(2*0.003) = 1e-5 Wb of the target.
        assert!(
            (f.rotor_flux - target).abs() < 2e-5,
            "{} vs {}",
            f.rotor_flux,
            target
        );
    }

    #[test]
    fn slip_law_matches_eq8_and_is_guarded_at_zero_flux() {
        let m = MachineParams::paper_table1();
        let cfg = FluxModelConfig::new(&m, 200e-6, m.rotor_flux_for(1.5));
        let mut f = FluxModel::new();
        // zero flux: the slip is bounded by the guard
        f.update(&cfg, 0.0, 3.0, 0.0, false);
        assert!(f.slip_frequency.is_finite());
        assert!((f.slip_frequency - cfg.slip_gain * 3.0 / cfg.min_flux).abs() < 1e-2);
        // settled flux: w_slip = (L_M/tau_r) i_sq / lambda_r = R_R i_sq / lambda_r
        f.rotor_flux = m.rotor_flux_for(1.5);
        f.update(&cfg, 1.5, 2.0, 100.0, false);
        let expect = m.referred_rotor_resistance() * 2.0 / m.rotor_flux_for(1.5);
        assert!((f.slip_frequency - expect).abs() < 1e-3 * expect);
        assert!((f.stator_frequency - (100.0 + expect)).abs() < 1e-3);
        // the angle advances by w_s Ts and stays wrapped
        let mut g = f;
        for _ in 0..100_000 {
            g.update(&cfg, 1.5, 2.0, 300.0, false);
            assert!((-core::f32::consts::PI..core::f32::consts::PI).contains(&g.angle));
        }
        // a NaN current keeps the flux finite
        g.update(&cfg, f32::NAN, f32::NAN, 0.0, false);
        assert!(g.rotor_flux.is_finite() && g.angle.is_finite());
    }
}
