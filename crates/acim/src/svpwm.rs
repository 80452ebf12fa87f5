//! Space-vector modulation with DC-bus compensation, a defined overmodulation limit and
//! dead-time compensation (the PWM block of paper Fig. 1 and 5).
//!
//! Implemented as min-max (symmetrical) zero-sequence injection, which gives the same
//! centre-aligned duties as classical sector-based SVPWM:
//!
//! ```text
//! v_x  = inverse Clarke of (v_alpha, v_beta)       phase-to-neutral, x = a, b, c
//! v_0  = -(max v_x + min v_x)/2                    zero-sequence offset
//! d_x  = 1/2 + (v_x + v_0)/V_dc                    duty of the high-side switch
//! ```
//!
//! * Linear range: |v_alpha_beta| <= V_dc/sqrt(3) (the hexagon's inscribed circle); in the
//!   whole hexagon max v_x - min v_x <= V_dc and the duties reproduce the command exactly.
//! * Overmodulation/limit: outside the hexagon the vector is scaled down onto it (angle
//!   kept, magnitude reduced: "minimum phase error" limiting) and `saturated` is reported
//!   (telemetry). The current controllers do not rely on it: they limit their own output
//!   to the circle the modulator supplies ([`Modulator::voltage_limit`]), inside the
//!   hexagon, so their integrators never wind up against the modulator.
//! * Bus compensation: the measured V_dc divides the voltages, so the output voltage does
//!   not depend on bus ripple. V_dc is floored at `min_bus_voltage` (no division by a
//!   vanishing bus; the drive faults on under-voltage before that matters).
//! * Dead-time and device-drop compensation: during the dead time the pole voltage follows
//!   the current sign (diode conduction), which loses (t_d/T_pwm) V_dc against the current,
//!   and the conducting device drops V_drop, also against the current. Each duty is raised
//!   by (t_d/T_pwm + V_drop/V_dc) sat(i_x/i_band): a sign function made linear within
//!   +/- `current_band` so that it does not chatter around zero crossings.

use crate::design::DriveCoeffs;
use crate::frames::{inverse_clarke, AlphaBeta};
use crate::math::clamp;
use crate::num::Num;

/// 1/sqrt(3): the linear limit per volt of bus.
pub const INV_SQRT3: f32 = 0.577_350_26;

/// Modulator configuration.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SvpwmConfig<N: Num = f32> {
    /// Dead time over PWM period, t_d/T_pwm (dimensionless duty).
    pub dead_time_duty: N,
    /// Device (IGBT/diode) on-state drop, V.
    pub device_drop: N,
    /// 1/current_band, 1/A: slope of the linearised sign used for dead-time compensation.
    pub inv_current_band: N::Gain,
    /// Smallest bus voltage used as divisor, V.
    pub min_bus_voltage: N,
}

impl SvpwmConfig<f32> {
    /// Dead time `dead_time` (s) at PWM period `pwm_period` (s) and device drop
    /// `device_drop` (V); compensation linear within +/- `current_band` (A, > 0).
    pub fn new(dead_time: f32, pwm_period: f32, device_drop: f32, current_band: f32) -> Self {
        Self {
            dead_time_duty: clamp(dead_time / pwm_period, 0.0, 0.1),
            device_drop: clamp(device_drop, 0.0, 20.0),
            inv_current_band: 1.0 / current_band.max(1e-3),
            min_bus_voltage: 1.0,
        }
    }
}

/// Output of the modulator.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Modulation<N = f32> {
    /// High-side duties a, b, c in [0, 1].
    pub duties: [N; 3],
    /// The voltage actually produced (the command, scaled onto the hexagon if it was
    /// outside), V.
    pub voltage: AlphaBeta<N>,
    /// Whether the command was outside the hexagon.
    pub saturated: bool,
}

/// Largest voltage vector magnitude in the linear range at bus `dc_bus`: V_dc/sqrt(3).
#[inline]
pub fn linear_limit<N: Num>(dc_bus: N) -> N {
    dc_bus * N::INV_SQRT3
}

/// Duties for the voltage vector `v` (V, stationary frame) at bus `dc_bus` (V), with the
/// phase currents `phase_currents` (A) for dead-time compensation. The bus is floored at
/// `min_bus_voltage` (one reciprocal here; the drive's step uses
/// [`modulate_with_inverse`] with the reciprocal it already has).
#[inline]
pub fn modulate<N: Num>(
    cfg: &SvpwmConfig<N>,
    v: AlphaBeta<N>,
    dc_bus: N,
    phase_currents: [N; 3],
) -> Modulation<N> {
    let vdc = if dc_bus > cfg.min_bus_voltage {
        dc_bus
    } else {
        cfg.min_bus_voltage
    };
    modulate_with_inverse(cfg, v, vdc, vdc.recip(), phase_currents)
}

/// [`modulate`] with the bus already checked (> 0) and its reciprocal `inv_dc_bus` given.
#[inline(always)]
pub fn modulate_with_inverse<N: Num>(
    cfg: &SvpwmConfig<N>,
    v: AlphaBeta<N>,
    dc_bus: N,
    inv_dc_bus: N,
    phase_currents: [N; 3],
) -> Modulation<N> {
    let vdc = dc_bus;
    let inv_vdc = inv_dc_bus;
    let [mut a, mut b, mut c] = inverse_clarke(v);
    let (hi_ab, lo_ab) = if a > b { (a, b) } else { (b, a) };
    let max = if c > hi_ab { c } else { hi_ab };
    let min = if c < lo_ab { c } else { lo_ab };
    let span = max - min;
    let mut out = v;
    let mut saturated = false;
    let mut offset = N::neg_mean(max, min);
    if span > vdc {
        // outside the hexagon: scale onto it, angle kept
        let k = N::ratio(vdc, span);
        a = a * k;
        b = b * k;
        c = c * k;
        offset = offset * k;
        out.alpha = out.alpha * k;
        out.beta = out.beta * k;
        saturated = true;
    }
    let dt = cfg.dead_time_duty + cfg.device_drop * inv_vdc;
    let s = cfg.inv_current_band;
    let base = N::HALF + offset * inv_vdc;
    Modulation {
        duties: [
            phase_duty(base, a, inv_vdc, dt, s, phase_currents[0]),
            phase_duty(base, b, inv_vdc, dt, s, phase_currents[1]),
            phase_duty(base, c, inv_vdc, dt, s, phase_currents[2]),
        ],
        voltage: out,
        saturated,
    }
}

/// One phase: base duty plus the phase voltage over the bus plus the dead-time and
/// device-drop compensation times the linearised current sign, clamped to [0, 1].
#[inline(always)]
fn phase_duty<N: Num>(base: N, vx: N, inv_vdc: N, comp: N, inv_band: N::Gain, i: N) -> N {
    let sign = N::gain(inv_band, i).clamp(-N::ONE, N::ONE);
    (base + vx * inv_vdc + comp * sign).clamp(N::ZERO, N::ONE)
}

/// Fraction of the linear limit V_dc/sqrt(3) the current controllers may use: 2 %
/// margin inside the hexagon's inscribed circle for the dead-time compensation.
pub const VOLTAGE_MARGIN: f32 = 0.98;

/// The voltage the current controllers may ask for this step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VoltageLimit<N = f32> {
    /// Largest |v_dq|, V peak.
    pub max: N,
    /// 1 / `max`, 1/V.
    pub inv_max: N,
}

/// The seam for the PWM stage: turns an alpha-beta voltage into duties and supplies the
/// voltage limit of the current controllers, so the two cannot disagree. Chosen by type
/// parameter of [`crate::Drive`] (zero cost in the interrupt).
pub trait Modulator<N: Num = f32> {
    /// The largest voltage vector the current loops may command at bus `dc_bus` (V, > 0)
    /// with `inv_dc_bus` = 1/`dc_bus`.
    fn voltage_limit(&self, coeffs: &DriveCoeffs<N>, dc_bus: N, inv_dc_bus: N) -> VoltageLimit<N>;
    /// Duties for `v` (V, stationary frame) at bus `dc_bus` (> 0, with its reciprocal),
    /// with `phase_currents` (A) predicted for the dead-time compensation.
    fn modulate(
        &self,
        coeffs: &DriveCoeffs<N>,
        v: AlphaBeta<N>,
        dc_bus: N,
        inv_dc_bus: N,
        phase_currents: [N; 3],
    ) -> Modulation<N>;
}

/// Min-max (symmetrical) SVPWM with dead-time compensation: this module's [`modulate`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Svpwm;

impl Modulator<f32> for Svpwm {
    /// 98 % of the inscribed circle V_dc/sqrt(3) ([`VOLTAGE_MARGIN`]).
    #[inline(always)]
    fn voltage_limit(&self, _: &DriveCoeffs<f32>, dc_bus: f32, inv_dc_bus: f32) -> VoltageLimit {
        VoltageLimit {
            max: linear_limit(dc_bus) * VOLTAGE_MARGIN,
            // (the coefficient is 1/(0.98/sqrt 3), folded at compile time here)
            inv_max: inv_dc_bus * (1.0 / (VOLTAGE_MARGIN * INV_SQRT3)),
        }
    }
    #[inline(always)]
    fn modulate(
        &self,
        coeffs: &DriveCoeffs<f32>,
        v: AlphaBeta,
        dc_bus: f32,
        inv_dc_bus: f32,
        phase_currents: [f32; 3],
    ) -> Modulation {
        modulate_with_inverse(&coeffs.pwm, v, dc_bus, inv_dc_bus, phase_currents)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frames::clarke_three;
    use proptest::prelude::*;

    fn no_dt() -> SvpwmConfig {
        SvpwmConfig::new(0.0, 200e-6, 0.0, 0.1)
    }

    fn reconstruct(d: [f32; 3], vdc: f32) -> AlphaBeta {
        clarke_three(d[0] * vdc, d[1] * vdc, d[2] * vdc)
    }

    #[test]
    fn zero_command_gives_half_duty() {
        let m = modulate(&no_dt(), AlphaBeta::default(), 325.0, [0.0; 3]);
        assert_eq!(m.duties, [0.5; 3]);
        assert!(!m.saturated);
    }

    #[test]
    fn dead_time_compensation_follows_current_sign() {
        let cfg = SvpwmConfig::new(1.5e-6, 200e-6, 0.0, 0.1);
        let m = modulate(&cfg, AlphaBeta::default(), 325.0, [2.0, -2.0, 0.05]);
        assert!((m.duties[0] - (0.5 + 0.0075)).abs() < 1e-6);
        assert!((m.duties[1] - (0.5 - 0.0075)).abs() < 1e-6);
        assert!((m.duties[2] - (0.5 + 0.00375)).abs() < 1e-6);
        // a 1.3 V device drop on a 325 V bus adds 0.004 duty against the current
        let cfg = SvpwmConfig::new(1.5e-6, 200e-6, 1.3, 0.1);
        let m = modulate(&cfg, AlphaBeta::default(), 325.0, [2.0, -2.0, 0.0]);
        assert!((m.duties[0] - (0.5 + 0.0115)).abs() < 1e-6);
        assert!((m.duties[1] - (0.5 - 0.0115)).abs() < 1e-6);
        assert!((m.duties[2] - 0.5).abs() < 1e-6);
    }

    #[test]
    fn bad_bus_and_nan_stay_in_range() {
        for vdc in [0.0f32, -5.0, f32::NAN, 1e-9] {
            let m = modulate(
                &no_dt(),
                AlphaBeta {
                    alpha: 100.0,
                    beta: 0.0,
                },
                vdc,
                [0.0; 3],
            );
            assert!(m.duties.iter().all(|d| (0.0..=1.0).contains(d)));
        }
        let m = modulate(
            &no_dt(),
            AlphaBeta {
                alpha: f32::NAN,
                beta: 1.0,
            },
            325.0,
            [f32::NAN; 3],
        );
        assert!(m.duties.iter().all(|d| (0.0..=1.0).contains(d)));
    }

    proptest! {
        #[test]
        fn duties_in_range_and_linear_range_reproduced(
            mag in 0.0f32..1.2, ang in -4.0f32..4.0, vdc in 50.0f32..800.0,
            ia in -10.0f32..10.0, ib in -10.0f32..10.0,
        ) {
            let lim = linear_limit(vdc);
            let v = AlphaBeta { alpha: mag * lim * ang.cos(), beta: mag * lim * ang.sin() };
            let m = modulate(&no_dt(), v, vdc, [ia, ib, -ia - ib]);
            prop_assert!(m.duties.iter().all(|d| (0.0..=1.0).contains(d)));
            let back = reconstruct(m.duties, vdc);
            if mag <= 1.0 {
                prop_assert!(!m.saturated);
                prop_assert!((back.alpha - v.alpha).abs() < 1e-4 * vdc);
                prop_assert!((back.beta - v.beta).abs() < 1e-4 * vdc);
            } else {
                // on the hexagon: angle kept, magnitude never above the command
                prop_assert!((back.alpha - m.voltage.alpha).abs() < 1e-4 * vdc);
                prop_assert!((back.beta - m.voltage.beta).abs() < 1e-4 * vdc);
                let cross = back.alpha * v.beta - back.beta * v.alpha;
                prop_assert!(cross.abs() < 1e-3 * vdc * vdc);
                let mb = back.alpha * back.alpha + back.beta * back.beta;
                let mv = v.alpha * v.alpha + v.beta * v.beta;
                prop_assert!(mb <= mv * (1.0 + 1e-5));
            }
        }
    }
}
