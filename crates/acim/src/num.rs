//! The arithmetic the cascade is generic over: [`f32`] in SI units and
//! [`Q24`](crate::fixed::Q24) (saturating Q7.24 in per unit).
//!
//! Every block and the drive itself are written once, over [`Num`] and the domain formats
//! they need ([`Arithmetic`] is all of them); the two arithmetics differ only where these
//! traits say so. The methods exist because the two arithmetics
//! need different operations for the same equation (a gain with its own binary point, a
//! reciprocal by Newton iteration, a turn-fraction angle, a finer integrator for Rs),
//! and because each instantiation reproduces the hand-written code it replaced bit for
//! bit: where the f32 code multiplied `(g a) b` and the fixed-point code `g (a b)`,
//! [`Num::gain_mul`] keeps both. Everything here is `#[inline(always)]` and compiles to
//! the operations the two hand-written copies had (the cycle bench checks it).

use core::fmt::Debug;
use core::ops::{Add, Mul, Neg, Sub};

/// `defmt::Format` when the `defmt` feature is on (the firmware logs the generic
/// types), nothing otherwise.
#[cfg(feature = "defmt")]
pub trait MaybeFormat: defmt::Format {}
#[cfg(feature = "defmt")]
impl<T: defmt::Format> MaybeFormat for T {}
/// `defmt::Format` when the `defmt` feature is on (the firmware logs the generic
/// types), nothing otherwise.
#[cfg(not(feature = "defmt"))]
pub trait MaybeFormat {}
#[cfg(not(feature = "defmt"))]
impl<T> MaybeFormat for T {}

/// A number the control step computes with: plain `+ - *` (saturating in fixed point), a
/// constant-factor type and the few operations the arithmetics do differently. The
/// domain formats each arithmetic also defines are traits of their own: [`DivSqrt`],
/// [`FineIntegrator`], [`Units`], [`Angles`] and
/// [`ThreePhase`]; [`Arithmetic`] is all of them, what
/// the drive is written over.
pub trait Num:
    Copy
    + Debug
    + MaybeFormat
    + Default
    + PartialEq
    + PartialOrd
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Neg<Output = Self>
{
    /// A constant factor (a design coefficient): `f32`, or a fixed-point gain with its own
    /// binary point that also carries the per-unit base conversion.
    type Gain: Copy + Debug + PartialEq + MaybeFormat;

    /// 0.
    const ZERO: Self;
    /// 1 (1.0 in SI, 1.0 pu).
    const ONE: Self;
    /// 0.5 (the neutral duty).
    const HALF: Self;

    /// `g x`.
    fn gain(g: Self::Gain, x: Self) -> Self;
    /// `g a b`: `(g a) b` in f32, `g (a b)` in fixed point (one gain on a product).
    fn gain_mul(g: Self::Gain, a: Self, b: Self) -> Self;
    /// `(a + b) x`: distributed as `a x + b x` in f32 (the order its feed-forward always
    /// had), one product in fixed point.
    fn sum_times(a: Self, b: Self, x: Self) -> Self;
    /// |x| (saturating).
    fn abs(self) -> Self;
    /// x / 2 (exact in f32; an arithmetic shift in fixed point).
    fn half(self) -> Self;
    /// 2 x.
    fn twice(self) -> Self;
    /// `self` limited to [lo, hi] (lo <= hi); NaN maps into the range.
    fn clamp(self, lo: Self, hi: Self) -> Self;
    /// [`Num::clamp`] for a value usually at one of its limits (a saturated sign, a
    /// completed fade): the same result; in f32 the code is laid out for the limits
    /// ([`crate::math::clamp_at_limits`]).
    #[inline(always)]
    fn clamp_at_limits(self, lo: Self, hi: Self) -> Self {
        self.clamp(lo, hi)
    }
    /// `self` limited to [lo, hi] where only f32 can leave it (a NaN): the identity in
    /// fixed point, whose results are in range by construction.
    fn into_range(self, lo: Self, hi: Self) -> Self;
    /// Whether finite (always in fixed point).
    fn is_finite(self) -> bool;
    /// Whether NaN (never in fixed point): one self-comparison in f32.
    fn is_nan(self) -> bool;
    /// Whether every value of `xs` is finite (always in fixed point): x - x is 0 for a
    /// finite x and NaN for an infinite or NaN one, so the sum of the differences is 0
    /// exactly when all are finite. One subtraction and one addition per value and one
    /// comparison, where a test per value took a bit test and a branch each.
    #[inline(always)]
    #[allow(clippy::eq_op)] // x - x is the test
    fn all_finite<const K: usize>(xs: [Self; K]) -> bool {
        let mut sum = Self::ZERO;
        for x in xs {
            sum = sum + (x - x);
        }
        sum == Self::ZERO
    }
    /// `self` if finite, else `fallback` (the identity in fixed point).
    #[inline(always)]
    fn finite_or(self, fallback: Self) -> Self {
        if self.is_finite() {
            self
        } else {
            fallback
        }
    }
}

/// The operations f32 does with its divide and square-root unit and fixed point by
/// Newton iteration or integer division.
pub trait DivSqrt: Num {
    /// 1/x for x above the caller's guard (> 0): a division in f32, a Newton reciprocal in
    /// fixed point.
    fn recip(self) -> Self;
    /// `num / den` for 0 < num < den (the overmodulation scale).
    fn ratio(num: Self, den: Self) -> Self;
    /// `x / count` for a count >= 1 (a running mean's step; 0 for a count of 0).
    fn per_count(x: Self, count: u32) -> Self;
    /// sqrt(x) for x >= 0 (0 for x <= 0): the field-weakening limits of
    /// [`crate::Drive`].
    fn sqrt(self) -> Self;
}

/// The slow integrators' finer format: the Rs estimate, the offset tracker's and the gain
/// calibration's integrators, whose steps per period are below the signal's resolution.
pub trait FineIntegrator: Num {
    /// The integrator state (`f32`, or Q1.30 for six more bits than the signal).
    type Fine: Copy + Debug + PartialEq + MaybeFormat;
    /// How much finer the integrator format is than the signal's (1 in f32; 64, six
    /// more bits, in fixed point): a gain into it carries this factor.
    const FINE_SCALE: f32;
    /// The whole range of the integrator format (unbounded in f32).
    const FINE_RANGE: (Self::Fine, Self::Fine);
    /// The integrator state holding `x` (in this arithmetic's units), if representable
    /// (design time).
    fn fine_from_f32(x: f32) -> Option<Self::Fine>;
    /// The integrator state holding `x`.
    fn to_fine(x: Self) -> Self::Fine;
    /// The signal value of an integrator state (rounded).
    fn from_fine(x: Self::Fine) -> Self;
    /// One adaptation step (for Rs eq. (19) with the corrected sign): `acc + sign * g e`,
    /// clamped to [lo, hi]; returns the new state and whether it sits at a bound.
    fn fine_step(
        acc: Self::Fine,
        g: Self::Gain,
        e: Self,
        positive: bool,
        lo: Self::Fine,
        hi: Self::Fine,
    ) -> (Self::Fine, bool);
}

/// The units an arithmetic's signals are in: SI in f32, per unit of its bases in fixed
/// point.
pub trait Units: Num {
    /// The per-unit bases (`()` for SI f32).
    type Bases: Copy + Debug + PartialEq + MaybeFormat;
    /// The smallest value (in this arithmetic's units) a reciprocal may be taken of: 0
    /// in f32, 0.02 pu in fixed point (the Newton reciprocal's domain, 2^-6 pu).
    const RECIP_FLOOR: f32;
    /// The largest magnitude a running sum may reach before a once-per-window solve
    /// refuses it (f32: any finite value; fixed point: 100 pu, below saturation at 128).
    const SUM_LIMIT: f32;
    /// The bases a design value in SI is divided by to be in this arithmetic's units
    /// ([`PerUnitBases::SI`] for f32).
    fn unit_bases(bases: &Self::Bases) -> PerUnitBases;
    /// `x` (in this arithmetic's units) as a signal, if it fits the range configured
    /// values may have (2 pu in fixed point, 64 times below saturation; any value in
    /// f32). Design time.
    fn checked_from_f32(x: f32) -> Option<Self>;
    /// `x` as a gain, if representable (design time).
    fn gain_from_f32(x: f32) -> Option<Self::Gain>;
    /// The value as an f32 in this arithmetic's units (SI in f32, per unit in fixed
    /// point): for the rare per-event arithmetic that needs a range no signal format has
    /// (the rotor-resistance adaptation's least-squares solve, [`crate::rr_estimator`]).
    fn to_f32(self) -> f32;
    /// The signal holding `x` (in this arithmetic's units; rounded and saturated).
    fn from_f32(x: f32) -> Self;
}

/// An arithmetic's frame angle and what the voltage lead needs.
pub trait Angles: Num {
    /// The frame angle: radians in `f32`, a `u32` turn fraction in fixed point.
    type Angle: Copy + Debug + Default + PartialEq + MaybeFormat;
    /// What the voltage-lead rotation needs (see [`crate::frames::LeadRotation::rotate_ahead`]).
    type Lead: Copy + Debug + PartialEq + MaybeFormat;
    /// The angle advanced by `frequency` over one period (`per_step` is Ts, or its
    /// turn-count equivalent), wrapped to one turn.
    fn advance(angle: Self::Angle, frequency: Self, per_step: Self::Gain) -> Self::Angle;
    /// The angle in radians (telemetry).
    fn angle_to_rad(a: Self::Angle) -> f32;
    /// The per-step gain of [`Angles::advance`] for `rad_per_unit` radians per period
    /// per unit of frequency (f32: Ts itself), if representable (design time).
    fn angle_gain(rad_per_unit: f32) -> Option<Self::Gain>;
    /// The voltage lead of `delay` periods of `ts` (s) with the bases `b` (design time).
    fn lead(ts: f32, delay: f32, b: &PerUnitBases) -> Option<Self::Lead>;
    /// Whether a large known turn (the offset tracker's per slow period) is cheaper as a
    /// series of products ([`crate::offset_tracker::large_turn`]) than as the drive's
    /// sin/cos: in f32, where a product is one instruction; not in fixed point, where
    /// it is a 64-bit multiply and shift and the sin/cos a table.
    const TURN_BY_PRODUCTS: bool;
}

/// The three-phase constants of Clarke, its inverse and the modulator in an arithmetic.
pub trait ThreePhase: Num {
    /// 1/sqrt(3) (Clarke).
    const INV_SQRT3: Self;
    /// sqrt(3)/2 (inverse Clarke).
    const SQRT3_2: Self;
    /// 1/3 (three-phase Clarke).
    const ONE_THIRD: Self;
    /// sqrt(3) (the chord of the q-voltage limit).
    const SQRT3: Self;
    /// -(a + b)/2 without overflow (the SVPWM zero-sequence offset).
    fn neg_mean(a: Self, b: Self) -> Self;
}

/// Per-unit bases: the physical value of 1.0 pu of each quantity (SI). Fixed point runs
/// in per unit of them; [`PerUnitBases::SI`] (every base 1) is the f32 drive's. Each
/// block converts its SI design to an arithmetic with them (its `convert`). Resistance is
/// V_base / I_base, so R i products are volts in pu directly.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PerUnitBases {
    /// Current base, A (phase peak, amplitude-invariant dq).
    pub current: f32,
    /// Voltage base, V (DC bus and phase peak).
    pub voltage: f32,
    /// Mechanical speed base, rad/s.
    pub speed: f32,
    /// Electrical (frame) frequency base, rad/s.
    pub frequency: f32,
    /// Rotor-flux base (inverse-Gamma lambda_r), Wb.
    pub flux: f32,
    /// Torque base, N m.
    pub torque: f32,
}

impl PerUnitBases {
    /// SI: every base 1 (the f32 drive; dividing by it is exact).
    pub const SI: Self = Self {
        current: 1.0,
        voltage: 1.0,
        speed: 1.0,
        frequency: 1.0,
        flux: 1.0,
        torque: 1.0,
    };

    /// The bases for the paper's machine (Table 1) and drive: 10 A (the current sensors'
    /// full scale, trip at 8 A = 0.8 pu), 400 V (the highest bus, 1.0 pu), 2000 rpm
    /// mechanical (the over-speed trip, 1.0 pu), 2 pi 100 rad/s electrical (2000 rpm at
    /// p = 2 is 0.67 pu), 1 Wb (nominal flux 0.781 Wb, 1.2x nominal = 0.94 pu), 10 N m
    /// (twice rated; the largest plausible load estimate, 15 N m, is 1.5 pu).
    pub const PAPER: Self = Self {
        current: 10.0,
        voltage: 400.0,
        speed: 2000.0 * crate::math::RPM_TO_RAD_S,
        frequency: 2.0 * core::f32::consts::PI * 100.0,
        flux: 1.0,
        torque: 10.0,
    };

    /// Resistance base V_base / I_base, ohm.
    pub fn resistance(&self) -> f32 {
        self.voltage / self.current
    }
}

/// `x / base` (a design value in SI) as a signal of the arithmetic `N`, if it fits the
/// configured range ([`Units::checked_from_f32`]); else the setting `field` it depends on.
pub fn signal_in<N: Units>(x: f32, base: f32, field: &'static str) -> Result<N, &'static str> {
    N::checked_from_f32(x / base).ok_or(field)
}

/// `x` (a design gain with its bases already applied) as a gain of the arithmetic `N`, if
/// representable; else the setting `field` it depends on.
pub fn gain_in<N: Units>(x: f32, field: &'static str) -> Result<N::Gain, &'static str> {
    N::gain_from_f32(x).ok_or(field)
}

/// Everything the cascade computes with: the arithmetic and its domain formats (the
/// bound of [`crate::Drive`] and of the blocks that need more than [`Num`]).
pub trait Arithmetic: Num + DivSqrt + FineIntegrator + Units + Angles + ThreePhase {}

impl<T> Arithmetic for T where T: Num + DivSqrt + FineIntegrator + Units + Angles + ThreePhase {}

impl Num for f32 {
    type Gain = f32;

    const ZERO: Self = 0.0;
    const ONE: Self = 1.0;
    const HALF: Self = 0.5;

    #[inline(always)]
    fn gain(g: f32, x: f32) -> f32 {
        g * x
    }
    #[inline(always)]
    fn gain_mul(g: f32, a: f32, b: f32) -> f32 {
        g * a * b
    }
    #[inline(always)]
    fn sum_times(a: f32, b: f32, x: f32) -> f32 {
        a * x + b * x
    }
    #[inline(always)]
    fn abs(self) -> f32 {
        f32::abs(self)
    }
    #[inline(always)]
    fn half(self) -> f32 {
        0.5 * self
    }
    #[inline(always)]
    fn twice(self) -> f32 {
        2.0 * self
    }
    #[inline(always)]
    fn clamp(self, lo: f32, hi: f32) -> f32 {
        crate::math::clamp_in_range(self, lo, hi)
    }
    #[inline(always)]
    fn clamp_at_limits(self, lo: f32, hi: f32) -> f32 {
        crate::math::clamp_at_limits(self, lo, hi)
    }
    #[inline(always)]
    fn into_range(self, lo: f32, hi: f32) -> f32 {
        crate::math::clamp_in_range(self, lo, hi)
    }
    #[inline(always)]
    fn is_finite(self) -> bool {
        crate::math::is_finite(self)
    }
    #[inline(always)]
    fn is_nan(self) -> bool {
        f32::is_nan(self)
    }
}

impl DivSqrt for f32 {
    #[inline(always)]
    fn recip(self) -> f32 {
        1.0 / self
    }
    #[inline(always)]
    fn ratio(num: f32, den: f32) -> f32 {
        num / den
    }
    #[inline(always)]
    fn per_count(x: f32, count: u32) -> f32 {
        if count == 0 {
            0.0
        } else {
            x / count as f32
        }
    }
    #[inline(always)]
    fn sqrt(self) -> f32 {
        crate::math::sqrt(self)
    }
}

impl FineIntegrator for f32 {
    type Fine = f32;
    const FINE_SCALE: f32 = 1.0;
    const FINE_RANGE: (f32, f32) = (f32::MIN, f32::MAX);
    fn fine_from_f32(x: f32) -> Option<f32> {
        Some(x)
    }
    #[inline(always)]
    fn to_fine(x: f32) -> f32 {
        x
    }
    #[inline(always)]
    fn from_fine(x: f32) -> f32 {
        x
    }
    #[inline(always)]
    fn fine_step(acc: f32, g: f32, e: f32, positive: bool, lo: f32, hi: f32) -> (f32, bool) {
        let step = g * e;
        let signed = if positive { step } else { -step };
        let next = crate::math::clamp_in_range(acc + signed, lo, hi);
        (next, next <= lo || next >= hi)
    }
}

impl Units for f32 {
    type Bases = ();
    const RECIP_FLOOR: f32 = 0.0;
    const SUM_LIMIT: f32 = f32::MAX;
    fn unit_bases(_: &()) -> PerUnitBases {
        PerUnitBases::SI
    }
    fn checked_from_f32(x: f32) -> Option<f32> {
        Some(x)
    }
    fn gain_from_f32(x: f32) -> Option<f32> {
        Some(x)
    }
    #[inline(always)]
    fn to_f32(self) -> f32 {
        self
    }
    #[inline(always)]
    fn from_f32(x: f32) -> f32 {
        x
    }
}

impl Angles for f32 {
    const TURN_BY_PRODUCTS: bool = true;
    type Angle = f32;
    /// (Ts, delay in periods): the lead is w_s Ts delay.
    type Lead = (f32, f32);
    #[inline(always)]
    fn advance(angle: f32, frequency: f32, per_step: f32) -> f32 {
        crate::math::wrap_angle_step(angle + frequency * per_step)
    }
    #[inline(always)]
    fn angle_to_rad(a: f32) -> f32 {
        a
    }
    fn angle_gain(rad_per_unit: f32) -> Option<f32> {
        Some(rad_per_unit)
    }
    fn lead(ts: f32, delay: f32, _: &PerUnitBases) -> Option<(f32, f32)> {
        Some((ts, delay))
    }
}

impl ThreePhase for f32 {
    const INV_SQRT3: Self = 0.577_350_26;
    const SQRT3_2: Self = 0.866_025_4;
    const ONE_THIRD: Self = 1.0 / 3.0;
    const SQRT3: Self = 1.732_050_8;
    #[inline(always)]
    fn neg_mean(a: f32, b: f32) -> f32 {
        -0.5 * (a + b)
    }
}

#[cfg(test)]
mod tests {
    use super::Num;

    /// `all_finite` agrees with a test per value on every pair and triple of values from
    /// the edges of f32 (the largest, the smallest subnormal, both zeros, both infinities,
    /// NaN of either sign).
    #[test]
    fn all_finite_is_every_value_finite() {
        let values = [
            0.0f32,
            -0.0,
            1.0,
            -3.5e-3,
            f32::MAX,
            f32::MIN,
            f32::MIN_POSITIVE,
            f32::from_bits(1),
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::NAN,
            -f32::NAN,
        ];
        for &a in &values {
            for &b in &values {
                assert_eq!(
                    f32::all_finite([a, b]),
                    a.is_finite() && b.is_finite(),
                    "{a} {b}"
                );
                for &c in &values {
                    let each = a.is_finite() && b.is_finite() && c.is_finite();
                    assert_eq!(f32::all_finite([a, b, c]), each, "{a} {b} {c}");
                }
            }
        }
    }
}
