//! The machine's short-time overload rating: an I^2 t model that lets the torque current
//! use the overload limit (e.g. 150 % of the rated current) for a stated time and then
//! folds the limit back to the continuous (rated) current until the machine has cooled.
//!
//! Heat, in units of the allowance (1.0 = the overload time spent at the overload
//! limit), integrates the squared current above the continuous one:
//!
//! ```text
//! heat[k+1] = clamp(heat[k] + g (|i_s|^2 - I_c^2), 0, 1),   g = Ts / ((I_max^2 - I_c^2) t_ol)
//! ```
//!
//! It reaches 1 after t_ol at I_max (longer below it; never at or below I_c). At 1 the
//! torque-current limits are scaled by `continuous_ratio` = sqrt(I_c^2 - i_sd^2) /
//! sqrt(I_max^2 - i_sd^2) at the rated flux current, which keeps |i_s| within I_c at the
//! rated flux and below it with a weakened flux (i_sd^2 + r^2 (I_max^2 - i_sd^2) <= I_c^2
//! for i_sd below the rated one). The fold-back is released when the heat has fallen to
//! [`RELEASE_HEAT`]: at the continuous current it never falls, so a machine that is
//! loaded at its rating stays at it (as the IEC 60034-1 duty allows), and the drive's
//! overload fault ([`crate::supervisor`]) judges whether the load can still be held.
//!
//! A model of the motor's thermal rating, not of the inverter's: it is not a protection
//! of the switches, which the over-current trip and the break input are.

use crate::num::DivSqrt;
use crate::num::Num;
use crate::num::Units;

/// Heat at which the fold-back is released (half the allowance).
pub const RELEASE_HEAT: f32 = 0.5;

/// The model's coefficients (configuration, apart from state).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ThermalConfig<N: Num = f32> {
    /// g = Ts / ((I_max^2 - I_c^2) t_ol): squared current (A^2) -> heat per step; zero
    /// when the overload limit is the continuous current (no fold-back).
    pub heat_gain: N::Gain,
    /// I_c^2, the continuous current squared (A^2).
    pub continuous_squared: N,
    /// The torque-current limits' factor while folded back (<= 1).
    pub continuous_ratio: N,
    /// [`RELEASE_HEAT`].
    pub release: N,
    /// Whether there is a fold-back at all (the step skips the model otherwise).
    pub enabled: bool,
}

impl ThermalConfig<f32> {
    /// The model for a current limit `current_limit` (A peak) allowed for
    /// `overload_time` (s), a continuous current `continuous_current` (A peak), the rated
    /// flux current `flux_current` (A) and period `ts` (s). A continuous current of 0 or
    /// at or above the limit (or a zero overload time) disables the fold-back.
    pub fn new(
        current_limit: f32,
        continuous_current: f32,
        overload_time: f32,
        flux_current: f32,
        ts: f32,
    ) -> Self {
        let (max2, c2, d2) = (
            current_limit * current_limit,
            continuous_current * continuous_current,
            flux_current * flux_current,
        );
        if !(continuous_current > 0.0 && continuous_current < current_limit)
            || overload_time <= 0.0
            || c2 <= d2
        {
            return Self {
                heat_gain: 0.0,
                continuous_squared: 0.0,
                continuous_ratio: 1.0,
                release: RELEASE_HEAT,
                enabled: false,
            };
        }
        Self {
            heat_gain: ts / ((max2 - c2) * overload_time),
            continuous_squared: c2,
            continuous_ratio: crate::math::sqrt((c2 - d2) / (max2 - d2)),
            release: RELEASE_HEAT,
            enabled: true,
        }
    }
}

/// The model's state: heat and whether the limit is folded back.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ThermalModel<N = f32> {
    heat: N,
    folded: bool,
}

impl<N: Num + DivSqrt> ThermalModel<N> {
    /// A cold machine.
    pub fn new() -> Self {
        Self {
            heat: N::ZERO,
            folded: false,
        }
    }

    /// One period with the measured current `i_dq` (A): returns the factor for the
    /// torque-current limits (1, or `continuous_ratio` while folded back).
    #[inline(always)]
    pub fn update(&mut self, cfg: &ThermalConfig<N>, i_d: N, i_q: N) -> N {
        let i2 = i_d * i_d + i_q * i_q;
        let heat = self.heat + N::gain(cfg.heat_gain, i2 - cfg.continuous_squared);
        // (a NaN current leaves the heat where it was: the sense stage trips on it)
        self.heat = heat.clamp(N::ZERO, N::ONE);
        if self.heat >= N::ONE {
            self.folded = true;
        } else if self.heat <= cfg.release {
            self.folded = false;
        }
        if self.folded {
            cfg.continuous_ratio
        } else {
            N::ONE
        }
    }

    /// Heat, fraction of the allowance (0 cold, 1 folded back).
    pub fn heat(&self) -> N {
        self.heat
    }

    /// Whether the current limit is folded back to the continuous current.
    pub fn folded(&self) -> bool {
        self.folded
    }
}

impl ThermalConfig<f32> {
    /// This design in the arithmetic `N` with the current base `current` (A); fails
    /// naming the setting the value depends on.
    pub fn convert<N: Num + Units>(&self, current: f32) -> Result<ThermalConfig<N>, &'static str> {
        let pu =
            |x: f32, base: f32, field: &'static str| N::checked_from_f32(x / base).ok_or(field);
        Ok(ThermalConfig {
            heat_gain: N::gain_from_f32(self.heat_gain * current * current)
                .ok_or("limits.overload_duration")?,
            continuous_squared: pu(
                self.continuous_squared,
                current * current,
                "limits.continuous_current",
            )?,
            continuous_ratio: pu(self.continuous_ratio, 1.0, "limits.continuous_current")?,
            release: pu(self.release, 1.0, "limits.overload_duration")?,
            enabled: self.enabled,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const TS: f32 = 200e-6;

    fn steps_to_fold(cfg: &ThermalConfig, i: f32) -> Option<u32> {
        let mut m = ThermalModel::new();
        (1..2_000_000).find(|_| m.update(cfg, 0.0, i) < 1.0)
    }

    /// 150 % for 60 s: the limit folds back after 60 s at the limit, later below it,
    /// never at the continuous current; it is released after cooling.
    #[test]
    fn folds_back_after_the_overload_time_and_releases_when_cool() {
        let cfg = ThermalConfig::new(1.5, 1.0, 60.0, 0.5, TS);
        // (within 0.2 %: the f32 heat near 1 has a granularity of 6e-8 against steps of
        // 3.7e-6, so each step rounds by up to 0.8 %, mostly cancelling)
        let at_limit = steps_to_fold(&cfg, 1.5).unwrap() as f32 * TS;
        assert!((at_limit - 60.0).abs() < 0.12, "{at_limit}");
        let at_125 = steps_to_fold(&cfg, 1.25).unwrap() as f32 * TS;
        // (1.5^2 - 1) / (1.25^2 - 1) = 2.22 times longer
        // (smaller steps, coarser relative rounding: within 1 %)
        assert!(
            (at_125 / (60.0 * 1.25 / 0.5625) - 1.0).abs() < 0.01,
            "{at_125}"
        );
        assert_eq!(
            steps_to_fold(&ThermalConfig::new(1.5, 1.0, 1.0, 0.5, TS), 1.0),
            None
        );
        // folded: |i_s| at the rated flux current within the continuous current
        let r = cfg.continuous_ratio;
        let iq = r * (1.5f32 * 1.5 - 0.25).sqrt();
        assert!((0.25 + iq * iq).sqrt() <= 1.0 + 1e-5);
        // held at the continuous current it stays folded; at zero current it cools
        let mut m = ThermalModel::new();
        while m.update(&cfg, 0.0, 1.5) == 1.0 {}
        for _ in 0..1_000_000 {
            assert_eq!(m.update(&cfg, 0.0, 1.0), r);
        }
        let mut k = 0u32;
        while m.update(&cfg, 0.0, 0.0) < 1.0 {
            k += 1;
        }
        // from 1 to 0.5 at zero current: 0.5 (I_max^2 - I_c^2) t_ol / I_c^2 = 37.5 s
        assert!(
            (k as f32 * TS / 37.5 - 1.0).abs() < 0.01,
            "{}",
            k as f32 * TS
        );
    }

    #[test]
    fn no_fold_back_without_an_overload_rating() {
        for continuous in [0.0, 4.67, 5.0] {
            let cfg = ThermalConfig::new(4.67, continuous, 60.0, 1.5, TS);
            assert_eq!(cfg.heat_gain, 0.0);
            let mut m = ThermalModel::new();
            for _ in 0..100_000 {
                assert_eq!(m.update(&cfg, 1.5, 10.0), 1.0);
            }
        }
    }
}
