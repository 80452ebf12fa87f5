//! Space-vector modulation (min-max zero-sequence injection) with DC-bus and dead-time
//! compensation in Q7.24: the algorithm of [`crate::svpwm`], its configuration converted
//! from [`SvpwmConfig`].
//!
//! d_x = 1/2 + (v_x + v_0)/V_dc + (t_d/T + V_drop/V_dc) sat(i_x/i_band), clamped to
//! [0, 1]; beyond the hexagon (span > V_dc) every phase is scaled by V_dc/span (the one
//! runtime reciprocal, only then). Voltages in Q7.24 of V_base, currents of I_base,
//! duties Q7.24 (1.0 = always on); 1/V_dc is passed in (Q7.24 per voltage pu), shared
//! with the drive's voltage limit.

use super::q::{clamp, mul, reciprocal, to_q24, Gain, HALF, ONE};
use super::trig::{inverse_clarke, FixedAlphaBeta};
use super::PerUnitBases;
use crate::svpwm::SvpwmConfig;

/// Modulator configuration in per unit.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FixedSvpwmConfig {
    /// t_d/T_pwm, Q7.24 duty.
    pub dead_time_duty: i32,
    /// Device drop, Q7.24 voltage pu.
    pub device_drop: i32,
    /// I_base/i_band: current pu -> linearised sign (Q7.24, limited to +/-1).
    pub inv_current_band: Gain,
}

impl FixedSvpwmConfig {
    /// Converts `cfg` with `bases`; `None` if a coefficient is not representable.
    pub fn from_f32(cfg: &SvpwmConfig, bases: &PerUnitBases) -> Option<Self> {
        Some(Self {
            dead_time_duty: to_q24(cfg.dead_time_duty),
            device_drop: to_q24(cfg.device_drop / bases.voltage),
            inv_current_band: Gain::from_f32(cfg.inv_current_band * bases.current)?,
        })
    }
}

/// Output of the modulator.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FixedModulation {
    /// High-side duties a, b, c, Q7.24 in [0, 1.0].
    pub duties: [i32; 3],
    /// The voltage actually produced (after any overmodulation limit), voltage pu.
    pub voltage: FixedAlphaBeta,
    /// True when the command was scaled onto the hexagon.
    pub saturated: bool,
}

/// Duties for `v` (voltage pu) at bus `dc_bus` (voltage pu, checked by the caller to be at
/// least 2^-6 pu) with `inv_dc_bus` = 1/`dc_bus` and the phase currents predicted for
/// the period (current pu) for the dead-time compensation.
#[inline(always)]
pub fn modulate(
    cfg: &FixedSvpwmConfig,
    v: FixedAlphaBeta,
    dc_bus: i32,
    inv_dc_bus: i32,
    phase_currents: [i32; 3],
) -> FixedModulation {
    let [mut a, mut b, mut c] = inverse_clarke(v);
    let (hi_ab, lo_ab) = if a > b { (a, b) } else { (b, a) };
    let max = if c > hi_ab { c } else { hi_ab };
    let min = if c < lo_ab { c } else { lo_ab };
    let span = max.saturating_sub(min);
    let mut out = v;
    let mut saturated = false;
    // -(max + min)/2 without overflow: each halved first
    let mut offset = 0i32.saturating_sub((max >> 1).saturating_add(min >> 1));
    if span > dc_bus {
        let k = mul(dc_bus, reciprocal(span)); // < 1.0
        a = mul(a, k);
        b = mul(b, k);
        c = mul(c, k);
        offset = mul(offset, k);
        out.alpha = mul(out.alpha, k);
        out.beta = mul(out.beta, k);
        saturated = true;
    }
    let comp = cfg
        .dead_time_duty
        .saturating_add(mul(cfg.device_drop, inv_dc_bus));
    let base = HALF.saturating_add(mul(offset, inv_dc_bus));
    let [ia, ib, ic] = phase_currents;
    FixedModulation {
        duties: [
            phase_duty(cfg, base, a, inv_dc_bus, comp, ia),
            phase_duty(cfg, base, b, inv_dc_bus, comp, ib),
            phase_duty(cfg, base, c, inv_dc_bus, comp, ic),
        ],
        voltage: out,
        saturated,
    }
}

/// One phase: base + v_x/V_dc + comp sat(i_x/i_band), clamped to [0, 1.0].
#[inline(always)]
fn phase_duty(cfg: &FixedSvpwmConfig, base: i32, vx: i32, inv_vdc: i32, comp: i32, i: i32) -> i32 {
    let sign = clamp(cfg.inv_current_band.apply(i), -ONE, ONE);
    clamp(
        base.saturating_add(mul(vx, inv_vdc))
            .saturating_add(mul(comp, sign)),
        0,
        ONE,
    )
}
