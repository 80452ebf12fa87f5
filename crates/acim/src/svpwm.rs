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
//! * Overmodulation (the [`Overmodulation`] modulator, selectable instead of [`Svpwm`]):
//!   from the inscribed circle through to six-step, by minimum-distance limiting (each
//!   phase's duty clamped to [0, 1] after the min-max offset: the nearest point of the
//!   hexagon, a vertex for a long vector) of a reference pre-distorted so that the
//!   fundamental equals the command ("fundamental gain compensation"; Hava, Sul, Kerkman
//!   and Lipo, "Dynamic overmodulation characteristics of triangle intersection PWM
//!   methods", IEEE Trans. Ind. Appl. 35(4), 1999, describe the clamped min-max
//!   modulator's gain curve). The current loops may then ask for up to the six-step
//!   fundamental 2 V_dc/pi, 10 % above the circle.
//! * Bus compensation: the measured V_dc divides the voltages, so the output voltage does
//!   not depend on bus ripple. V_dc is floored at `min_bus_voltage` (no division by a
//!   vanishing bus; the drive faults on under-voltage before that matters).
//! * Dead-time and device-drop compensation: during the dead time the pole voltage follows
//!   the current sign (diode conduction), which loses (t_d/T_pwm) V_dc against the current,
//!   and the conducting device drops V_drop, also against the current. Each duty is raised
//!   by (t_d/T_pwm + V_drop/V_dc) sat(i_x/i_band): a sign function made linear within
//!   +/- `current_band` so that it does not chatter around zero crossings.

use crate::frames::{inverse_clarke, AlphaBeta};
use crate::math::{clamp, sqrt};
use crate::num::DivSqrt;
use crate::num::Num;
use crate::num::PerUnitBases;
use crate::num::ThreePhase;
use crate::num::Units;

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
    /// 1/V_dc -> 1/v_max: 1/([`VOLTAGE_MARGIN`]/sqrt 3) (the current loops' voltage
    /// limit's reciprocal from the bus's).
    pub voltage_limit_per_inv_bus: N::Gain,
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
            voltage_limit_per_inv_bus: 1.0 / (VOLTAGE_MARGIN * INV_SQRT3),
        }
    }
}

/// The voltage-feedback trim holds the voltage command at this fraction of the current
/// loops' limit: 8 % headroom for the current loops' transients at high speed, where the
/// machine runs on the voltage limit.
pub const FW_TRIM_FRACTION: f32 = 0.92;

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
pub fn linear_limit<N: Num + DivSqrt + ThreePhase + DivSqrt + ThreePhase>(dc_bus: N) -> N {
    dc_bus * N::INV_SQRT3
}

/// Duties for the voltage vector `v` (V, stationary frame) at bus `dc_bus` (V), with the
/// phase currents `phase_currents` (A) for dead-time compensation. The bus is floored at
/// `min_bus_voltage` (one reciprocal here; the drive's step uses
/// [`modulate_with_inverse`] with the reciprocal it already has).
#[inline]
pub fn modulate<N: Num + DivSqrt + ThreePhase + DivSqrt + ThreePhase>(
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
    modulate_with_inverse(cfg, v, vdc, vdc.recip(), phase_currents, N::ZERO)
}

/// [`modulate`] with the bus already checked (> 0) and its reciprocal `inv_dc_bus` given,
/// and `dead_time_correction` (duty; 0 for none) added to the configured dead-time duty of
/// every leg (the inverter test's correction).
#[inline(always)]
pub fn modulate_with_inverse<N: Num + DivSqrt + ThreePhase + DivSqrt + ThreePhase>(
    cfg: &SvpwmConfig<N>,
    v: AlphaBeta<N>,
    dc_bus: N,
    inv_dc_bus: N,
    phase_currents: [N; 3],
    dead_time_correction: N,
) -> Modulation<N> {
    let signs = current_signs(cfg.inv_current_band, phase_currents);
    modulate_signed(cfg, v, dc_bus, inv_dc_bus, signs, dead_time_correction)
}

/// [`modulate_with_inverse`] with the compensation's current signs given
/// ([`current_signs`] of the predicted phase currents): the drive computes them once for
/// the modulator and the running inverter tracker.
#[inline(always)]
pub fn modulate_signed<N: Num + DivSqrt + ThreePhase + DivSqrt + ThreePhase>(
    cfg: &SvpwmConfig<N>,
    v: AlphaBeta<N>,
    dc_bus: N,
    inv_dc_bus: N,
    current_signs: [N; 3],
    dead_time_correction: N,
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
        // outside the hexagon: scale onto it, angle kept (rare: marked cold)
        core::hint::cold_path();
        let k = N::ratio(vdc, span);
        a = a * k;
        b = b * k;
        c = c * k;
        offset = offset * k;
        out.alpha = out.alpha * k;
        out.beta = out.beta * k;
        saturated = true;
    }
    let dt = (cfg.dead_time_duty + dead_time_correction) + cfg.device_drop * inv_vdc;
    let base = N::HALF + offset * inv_vdc;
    let s = current_signs;
    Modulation {
        duties: [
            phase_duty(base, a, inv_vdc, dt, s[0]),
            phase_duty(base, b, inv_vdc, dt, s[1]),
            phase_duty(base, c, inv_vdc, dt, s[2]),
        ],
        voltage: out,
        saturated,
    }
}

/// The compensation's current sign, linear within the band: `sat(i / i_band)` from the
/// phase current `i` (A) and `inv_band` = 1/i_band (the running inverter tracker's sign
/// vector uses the same, [`crate::inverter_tracker::sign_vector`]).
#[inline(always)]
pub fn current_sign<N: Num + DivSqrt + ThreePhase + DivSqrt + ThreePhase>(
    inv_band: N::Gain,
    i: N,
) -> N {
    // (saturated outside the band, where the current is most of the period)
    N::gain(inv_band, i).clamp_at_limits(-N::ONE, N::ONE)
}

/// The three phases' [`current_sign`]s of `phase_currents` (A).
#[inline(always)]
pub fn current_signs<N: Num + DivSqrt + ThreePhase + DivSqrt + ThreePhase>(
    inv_band: N::Gain,
    phase_currents: [N; 3],
) -> [N; 3] {
    // (indexed, not `map`: the array's map stays out of line, outside the interrupt's
    // CCM SRAM)
    let [a, b, c] = phase_currents;
    [
        current_sign(inv_band, a),
        current_sign(inv_band, b),
        current_sign(inv_band, c),
    ]
}

/// One phase: base duty plus the phase voltage over the bus plus the dead-time and
/// device-drop compensation times the linearised current sign `sign`, clamped to [0, 1].
#[inline(always)]
fn phase_duty<N: Num + DivSqrt + ThreePhase + DivSqrt + ThreePhase>(
    base: N,
    vx: N,
    inv_vdc: N,
    comp: N,
    sign: N,
) -> N {
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
    /// The voltage the field weakening sizes the flux for, V peak: its model uses 97 % of
    /// it and its trim holds the command at [`FW_TRIM_FRACTION`] of it, the rest being
    /// the current loops' reserve. [`Svpwm`]: `max` (8 % reserve). [`Overmodulation`]:
    /// [`OVERMODULATION_STEADY`] of the linear limit / [`FW_TRIM_FRACTION`], so the trim
    /// holds the command at 96 % of the linear limit and the range up to six-step
    /// (15 % more) is the reserve.
    pub steady: N,
    /// The limit the current loops fall back to once a modulator's reserve above it is
    /// used up (the drive's `transient_limit`), V peak: `max` for [`Svpwm`] (no
    /// reserve), the linear limit for [`Overmodulation`].
    pub sustained: N,
    /// 1 / `sustained`, 1/V.
    pub inv_sustained: N,
}

/// The seam for the PWM stage: turns an alpha-beta voltage into duties and supplies the
/// voltage limit of the current controllers, so the two cannot disagree. Chosen by type
/// parameter of [`crate::Drive`] (zero cost in the interrupt).
pub trait Modulator<N: Num + DivSqrt + ThreePhase + DivSqrt + ThreePhase = f32> {
    /// Whether the modulator goes beyond its sustained limit in normal operation (its
    /// output then differs from the command: the drive gives the estimators the limited
    /// vector and keeps a time-limited reserve, `VoltageLimit::sustained`). A constant, so
    /// that a modulator without (the default, [`Svpwm`]) costs the step nothing.
    const OVERMODULATES: bool = false;
    /// The largest voltage vector the current loops may command at bus `dc_bus` (V, > 0)
    /// with `inv_dc_bus` = 1/`dc_bus`.
    fn voltage_limit(&self, pwm: &SvpwmConfig<N>, dc_bus: N, inv_dc_bus: N) -> VoltageLimit<N>;
    /// Duties for `v` (V, stationary frame) at bus `dc_bus` (> 0, with its reciprocal),
    /// with `current_signs` the dead-time compensation's signs ([`current_signs`] of the
    /// phase currents predicted for the period), whose duty per leg is the configured
    /// one plus `dead_time_correction` (the inverter test's; 0 leaves the configured
    /// compensation bit for bit).
    fn modulate(
        &self,
        pwm: &SvpwmConfig<N>,
        v: AlphaBeta<N>,
        dc_bus: N,
        inv_dc_bus: N,
        current_signs: [N; 3],
        dead_time_correction: N,
    ) -> Modulation<N>;
}

/// Min-max (symmetrical) SVPWM with dead-time compensation: this module's [`modulate`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Svpwm;

impl Modulator<f32> for Svpwm {
    /// 98 % of the inscribed circle V_dc/sqrt(3) ([`VOLTAGE_MARGIN`]).
    #[inline(always)]
    fn voltage_limit(&self, _: &SvpwmConfig, dc_bus: f32, inv_dc_bus: f32) -> VoltageLimit {
        let max = linear_limit(dc_bus) * VOLTAGE_MARGIN;
        // (the coefficient is 1/(0.98/sqrt 3), folded at compile time here)
        let inv_max = inv_dc_bus * (1.0 / (VOLTAGE_MARGIN * INV_SQRT3));
        VoltageLimit {
            max,
            inv_max,
            steady: max,
            sustained: max,
            inv_sustained: inv_max,
        }
    }
    #[inline(always)]
    fn modulate(
        &self,
        pwm: &SvpwmConfig,
        v: AlphaBeta,
        dc_bus: f32,
        inv_dc_bus: f32,
        current_signs: [f32; 3],
        dead_time_correction: f32,
    ) -> Modulation {
        modulate_signed(
            pwm,
            v,
            dc_bus,
            inv_dc_bus,
            current_signs,
            dead_time_correction,
        )
    }
}

/// With [`Overmodulation`], the fraction of the linear limit V_dc/sqrt 3 the field
/// weakening holds the steady command at: 2 % below the sustained limit
/// ([`VOLTAGE_MARGIN`]), the ripple of the command's magnitude at steady 3000 rpm
/// (`fw-reversal-3000`: 10th to 99.9th percentile within -1.7 % / +1.7 % of its median),
/// so that steady operation does not draw on the overmodulation reserve.
pub const OVERMODULATION_STEADY: f32 = 0.96;

/// The six-step fundamental per volt of bus, 2/pi: the largest fundamental an inverter
/// makes (1.1027 times the inscribed circle's 1/sqrt 3).
pub const SIX_STEP: f32 = core::f32::consts::FRAC_2_PI;

/// The fundamental (per volt of bus) above which [`Overmodulation`] gives six-step: the
/// last 0.5 % below it needs an ever longer reference.
pub const OVERMODULATION_TOP: f32 = 0.995 * SIX_STEP;

/// The reference radius (per volt of bus) whose minimum-distance limiting gives the
/// fundamental `INV_SQRT3 + i (OVERMODULATION_TOP - INV_SQRT3) / 32`, i = 0..=32: computed
/// by bisection on the fundamental of the clamped min-max duties over a revolution (2 880
/// points); linear interpolation between the nodes keeps the fundamental within 0.03 %
/// of the command (checked by `overmodulation_gives_the_commanded_fundamental`).
const OVERMODULATION_RADIUS: [f32; 33] = [
    0.577_350, 0.579_308, 0.581_482, 0.583_838, 0.586_371, 0.589_088, 0.592_001, 0.595_126,
    0.598_486, 0.602_109, 0.606_033, 0.610_309, 0.615_004, 0.620_214, 0.626_079, 0.632_820,
    0.640_828, 0.650_915, 0.665_550, 0.686_704, 0.710_182, 0.736_396, 0.765_917, 0.799_500,
    0.838_141, 0.883_259, 0.936_859, 1.001_939, 1.083_282, 1.188_943, 1.333_984, 1.550_919,
    1.928_824,
];

/// A reference radius (per volt of bus) the limiting turns into six-step: every point of
/// the circle is then nearest to a vertex except within 0.3 degrees of the side centres.
const SIX_STEP_RADIUS: f32 = 100.0;

/// Nodes per unit of fundamental in [`OVERMODULATION_RADIUS`].
const OVERMODULATION_NODES_PER_UNIT: f32 = 32.0 / (OVERMODULATION_TOP - INV_SQRT3);

/// The reference radius for the fundamental `m` (per volt of bus, >= 1/sqrt 3).
#[inline(always)]
fn overmodulation_radius(m: f32) -> f32 {
    if m.is_nan() || m >= OVERMODULATION_TOP {
        return SIX_STEP_RADIUS;
    }
    let t = ((m - INV_SQRT3) * OVERMODULATION_NODES_PER_UNIT).max(0.0);
    // t < 32 here: i <= 31 (`get` keeps the step free of a panic path regardless)
    let i = t as usize;
    let (Some(&r0), Some(&r1)) = (
        OVERMODULATION_RADIUS.get(i),
        OVERMODULATION_RADIUS.get(i + 1),
    ) else {
        return SIX_STEP_RADIUS;
    };
    r0 + (r1 - r0) * (t - i as f32)
}

/// Minimum-distance overmodulation with fundamental gain compensation (f32): [`Svpwm`]
/// inside the inscribed circle, beyond it through to six-step (module documentation).
/// The current loops may ask for up to the six-step fundamental for a while (the drive's
/// reserve, [`crate::design::OVERMODULATION_RESERVE_TIME`], then the sustained linear
/// limit); the field weakening holds the steady command at 96 % of the linear limit
/// ([`VoltageLimit::steady`]), so the samples of steady operation carry no
/// overmodulation harmonics and a transient can use 15 % more voltage.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Overmodulation;

impl Modulator<f32> for Overmodulation {
    const OVERMODULATES: bool = true;
    /// The six-step fundamental 2 V_dc/pi; steady: the linear limit over
    /// [`FW_TRIM_FRACTION`].
    #[inline(always)]
    fn voltage_limit(&self, _: &SvpwmConfig, dc_bus: f32, inv_dc_bus: f32) -> VoltageLimit {
        VoltageLimit {
            max: dc_bus * SIX_STEP,
            inv_max: inv_dc_bus * (1.0 / SIX_STEP),
            steady: linear_limit(dc_bus) * (OVERMODULATION_STEADY / FW_TRIM_FRACTION),
            sustained: linear_limit(dc_bus) * VOLTAGE_MARGIN,
            inv_sustained: inv_dc_bus * (1.0 / (VOLTAGE_MARGIN * INV_SQRT3)),
        }
    }
    #[inline(always)]
    fn modulate(
        &self,
        pwm: &SvpwmConfig,
        v: AlphaBeta,
        dc_bus: f32,
        inv_dc_bus: f32,
        current_signs: [f32; 3],
        dead_time_correction: f32,
    ) -> Modulation {
        overmodulate_signed(
            pwm,
            v,
            dc_bus,
            inv_dc_bus,
            current_signs,
            dead_time_correction,
        )
    }
}

/// [`modulate_with_inverse`] inside the inscribed circle; beyond it the vector is
/// lengthened to the radius whose minimum-distance limiting has the command's
/// fundamental, each phase's duty is clamped to [0, 1], and the dead-time compensation
/// is added to the phases that switch in this period (a clamped phase has no dead time).
/// `voltage` is the vector of this period (the limited one); `saturated` says the
/// command was beyond the circle (overmodulating).
#[inline(always)]
pub fn overmodulate(
    cfg: &SvpwmConfig,
    v: AlphaBeta,
    dc_bus: f32,
    inv_dc_bus: f32,
    phase_currents: [f32; 3],
) -> Modulation {
    overmodulate_corrected(cfg, v, dc_bus, inv_dc_bus, phase_currents, 0.0)
}

/// [`overmodulate`] with `dead_time_correction` (duty) added to the configured dead-time
/// duty of every switching leg, as [`modulate_with_inverse`].
#[inline(always)]
pub fn overmodulate_corrected(
    cfg: &SvpwmConfig,
    v: AlphaBeta,
    dc_bus: f32,
    inv_dc_bus: f32,
    phase_currents: [f32; 3],
    dead_time_correction: f32,
) -> Modulation {
    let signs = current_signs(cfg.inv_current_band, phase_currents);
    overmodulate_signed(cfg, v, dc_bus, inv_dc_bus, signs, dead_time_correction)
}

/// [`overmodulate_corrected`] with the compensation's current signs given
/// ([`current_signs`] of the predicted phase currents).
#[inline(always)]
pub fn overmodulate_signed(
    cfg: &SvpwmConfig,
    v: AlphaBeta,
    dc_bus: f32,
    inv_dc_bus: f32,
    current_signs: [f32; 3],
    dead_time_correction: f32,
) -> Modulation {
    let m2 = (v.alpha * v.alpha + v.beta * v.beta) * (inv_dc_bus * inv_dc_bus);
    // (a NaN command takes the linear path, which keeps the duties in range)
    if m2.is_nan() || m2 <= INV_SQRT3 * INV_SQRT3 {
        return modulate_signed(
            cfg,
            v,
            dc_bus,
            inv_dc_bus,
            current_signs,
            dead_time_correction,
        );
    }
    // m >= 1/sqrt 3 (up to rounding): the ratio's divisor cannot vanish
    let m = sqrt(m2).max(INV_SQRT3);
    let k = overmodulation_radius(m) / m * inv_dc_bus;
    let [a, b, c] = inverse_clarke(v);
    let (a, b, c) = (a * k, b * k, c * k);
    let (hi_ab, lo_ab) = if a > b { (a, b) } else { (b, a) };
    let max = if c > hi_ab { c } else { hi_ab };
    let min = if c < lo_ab { c } else { lo_ab };
    let base = 0.5 - 0.5 * (max + min);
    let d = [
        clamp(base + a, 0.0, 1.0),
        clamp(base + b, 0.0, 1.0),
        clamp(base + c, 0.0, 1.0),
    ];
    // the vector these duties make (the common mode drops out)
    let voltage = AlphaBeta {
        alpha: (d[0] - 0.5 * (d[1] + d[2])) * (2.0 / 3.0) * dc_bus,
        beta: (d[1] - d[2]) * INV_SQRT3 * dc_bus,
    };
    let dt = (cfg.dead_time_duty + dead_time_correction) + cfg.device_drop * inv_dc_bus;
    let comp = |d: f32, sign: f32| {
        if d > 0.0 && d < 1.0 {
            clamp(d + dt * sign, 0.0, 1.0)
        } else {
            d
        }
    };
    let s = current_signs;
    Modulation {
        duties: [comp(d[0], s[0]), comp(d[1], s[1]), comp(d[2], s[2])],
        voltage,
        saturated: true,
    }
}

impl SvpwmConfig<f32> {
    /// This design in the arithmetic `N` with the bases `b` (duties are dimensionless;
    /// voltages of V_base, currents of I_base). `None` if a gain is not representable.
    pub fn convert<N: Num + Units>(&self, b: &PerUnitBases) -> Option<SvpwmConfig<N>> {
        Some(SvpwmConfig {
            dead_time_duty: N::from_f32(self.dead_time_duty),
            device_drop: N::from_f32(self.device_drop / b.voltage),
            inv_current_band: N::gain_from_f32(self.inv_current_band * b.current)?,
            min_bus_voltage: N::from_f32(self.min_bus_voltage / b.voltage),
            // dimensionless
            voltage_limit_per_inv_bus: N::gain_from_f32(self.voltage_limit_per_inv_bus)?,
        })
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

    /// The fundamental of the limited vectors over a revolution (720 steps) of a command
    /// of `m` volts per volt of bus: (magnitude per volt of bus, phase error in rad).
    fn fundamental(m: f32) -> (f32, f32) {
        let vdc = 325.0;
        let n = 720;
        let (mut re, mut im) = (0.0f32, 0.0f32);
        for k in 0..n {
            let th = core::f32::consts::TAU * (k as f32 + 0.5) / n as f32;
            let v = AlphaBeta {
                alpha: m * vdc * th.cos(),
                beta: m * vdc * th.sin(),
            };
            let o = overmodulate(&no_dt(), v, vdc, 1.0 / vdc, [0.0; 3]);
            let back = reconstruct(o.duties, vdc);
            assert!(
                (back.alpha - o.voltage.alpha).abs() < 1e-3
                    && (back.beta - o.voltage.beta).abs() < 1e-3
            );
            // back * e^{-j th}
            re += back.alpha * th.cos() + back.beta * th.sin();
            im += back.beta * th.cos() - back.alpha * th.sin();
        }
        let (re, im) = (re / (n as f32 * vdc), im / (n as f32 * vdc));
        ((re * re + im * im).sqrt(), im.atan2(re))
    }

    #[test]
    fn overmodulation_gives_the_commanded_fundamental() {
        // through the table (nodes and between them): within 0.05 %, no phase error
        for i in 0..=64 {
            let m = INV_SQRT3 + (OVERMODULATION_TOP - INV_SQRT3) * (i as f32 + 0.25) / 64.5;
            let (f, ph) = fundamental(m);
            assert!((f / m - 1.0).abs() < 5e-4, "m {m}: fundamental {f}");
            assert!(ph.abs() < 1e-3, "m {m}: phase {ph}");
        }
        // above the table, and beyond what an inverter makes: six-step
        for m in [0.634, SIX_STEP, 0.7, 5.0] {
            let (f, ph) = fundamental(m);
            assert!((f / SIX_STEP - 1.0).abs() < 1e-3, "m {m}: fundamental {f}");
            assert!(ph.abs() < 1e-3);
        }
        let six = overmodulate(
            &no_dt(),
            AlphaBeta {
                alpha: 1e4,
                beta: 10.0,
            },
            325.0,
            1.0 / 325.0,
            [0.0; 3],
        );
        assert_eq!(six.duties, [1.0, 0.0, 0.0], "a vertex: no switching");
    }

    #[test]
    fn overmodulation_leaves_clamped_phases_without_dead_time_compensation() {
        let cfg = SvpwmConfig::new(1.5e-6, 200e-6, 1.0, 0.1);
        // 0.6 V_dc towards a side's centre (30 degrees): phase a clamped high, c low
        let v = AlphaBeta {
            alpha: 195.0 * 0.866_025_4,
            beta: 195.0 * 0.5,
        };
        let i = [-3.0, 1.5, 1.5];
        let o = overmodulate(&cfg, v, 325.0, 1.0 / 325.0, i);
        assert!(o.saturated);
        // no compensation on the clamped phases, whatever their current
        assert_eq!((o.duties[0], o.duties[2]), (1.0, 0.0));
        let plain = overmodulate(&no_dt(), v, 325.0, 1.0 / 325.0, i);
        let dt = 1.5e-6 / 200e-6 + 1.0 / 325.0;
        assert!(plain.duties[1] > 0.0 && plain.duties[1] < 1.0);
        assert!((o.duties[1] - (plain.duties[1] + dt)).abs() < 1e-6);
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

        #[test]
        fn overmodulation_is_svpwm_inside_the_circle_and_in_range_everywhere(
            mag in 0.0f32..3.0, ang in -4.0f32..4.0, vdc in 50.0f32..800.0,
            ia in -10.0f32..10.0, ib in -10.0f32..10.0,
        ) {
            let lim = linear_limit(vdc);
            let v = AlphaBeta { alpha: mag * lim * ang.cos(), beta: mag * lim * ang.sin() };
            let i = [ia, ib, -ia - ib];
            let cfg = SvpwmConfig::new(1.5e-6, 200e-6, 1.0, 0.1);
            let o = overmodulate(&cfg, v, vdc, 1.0 / vdc, i);
            prop_assert!(o.duties.iter().all(|d| (0.0..=1.0).contains(d)));
            prop_assert!(o.voltage.alpha.is_finite() && o.voltage.beta.is_finite());
            if mag < 0.999 {
                prop_assert_eq!(o, modulate_with_inverse(&cfg, v, vdc, 1.0 / vdc, i, 0.0));
            } else if mag > 1.001 {
                prop_assert!(o.saturated);
            }
        }
    }

    #[test]
    fn overmodulation_keeps_bad_inputs_in_range() {
        for (a, b) in [
            (f32::NAN, 1.0),
            (f32::INFINITY, 0.0),
            (1e30, -1e30),
            (0.0, f32::NEG_INFINITY),
        ] {
            let o = overmodulate(
                &no_dt(),
                AlphaBeta { alpha: a, beta: b },
                325.0,
                1.0 / 325.0,
                [f32::NAN; 3],
            );
            assert!(
                o.duties.iter().all(|d| (0.0..=1.0).contains(d)),
                "{a} {b}: {:?}",
                o.duties
            );
        }
    }
}
