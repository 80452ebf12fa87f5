//! Q7.24 signal arithmetic, construction-time gains with their own binary point, the
//! per-unit bases and a division-free-in-spirit reciprocal (one hardware 32-bit division
//! for the seed, one Newton step).
//!
//! Every signal is an `i32` holding `value_pu * 2^24` (Q7.24: sign, 7 integer bits, 24
//! fraction bits; range [-128, 128) pu, resolution 6.0e-8 pu). Every operation saturates
//! to that range: products go through `i64` and are rounded to nearest, then clamped;
//! sums use `saturating_add`/`saturating_sub`. Nothing in a control quantity wraps; only
//! the frame angle (a turn fraction, [`super::trig`]) wraps, by design.

/// Fraction bits of the signal format (Q7.24).
pub const FRAC_BITS: u32 = 24;
/// 1.0 pu in Q7.24.
pub const ONE: i32 = 1 << FRAC_BITS;
/// 0.5 pu in Q7.24.
pub const HALF: i32 = 1 << (FRAC_BITS - 1);

/// Clamps an `i64` into the `i32` range (saturation, never wrap-around).
#[inline(always)]
pub fn saturate(v: i64) -> i32 {
    if v > i32::MAX as i64 {
        i32::MAX
    } else if v < i32::MIN as i64 {
        i32::MIN
    } else {
        v as i32
    }
}

/// The `i32` saturation of the 64-bit value `hi:lo` (`hi` its upper word, `lo` its lower
/// word as a signed bit pattern): `lo` when `hi` is its sign extension, else the bound of
/// the value's sign, which the caller passes as `sign` (negative or not; the caller knows
/// it from its operands' signs without looking at the 64-bit value, which keeps the
/// compiler from rebuilding the two 64-bit comparisons of [`saturate`]). The same function
/// of the 64-bit value as [`saturate`].
#[inline(always)]
fn saturate_words(hi: i32, lo: i32, sign: i32) -> i32 {
    if hi != lo >> 31 {
        (sign >> 31) ^ i32::MAX
    } else {
        lo
    }
}

/// Product of two Q7.24 values in Q7.24, rounded to nearest (ties up) and saturated:
/// `saturate((a b + 2^23) >> 24)`. The `i64` product of two `i32` cannot overflow
/// (|a b| <= 2^62), nor the rounded sum. Computed on the two words of the product: the
/// result is bits 24..56 of the rounded product, saturated from its two words (bit-identical to the 64-bit form, `tests::mul_matches_the_64_bit_form`).
#[inline(always)]
pub fn mul(a: i32, b: i32) -> i32 {
    // wrapping_* on operations that cannot overflow: no overflow-check panic path in any
    // build profile (the i64 product is below 2^62, the rounded sum below 2^63)
    let p = (a as i64)
        .wrapping_mul(b as i64)
        .wrapping_add(1i64 << (FRAC_BITS - 1));
    let hi = (p >> 32) as i32;
    let lo = p as u32;
    let r = ((lo >> FRAC_BITS) | ((hi as u32) << (32 - FRAC_BITS))) as i32;
    // when it does not fit, |a b| >= 2^54: the product is nonzero and its sign is that of
    // a ^ b
    saturate_words(hi >> FRAC_BITS, r, a ^ b)
}

/// `x` limited to [lo, hi] by comparisons (requires lo <= hi; `Ord::clamp` asserts that and
/// would link a panic path).
#[inline(always)]
pub fn clamp(x: i32, lo: i32, hi: i32) -> i32 {
    if x > hi {
        hi
    } else if x < lo {
        lo
    } else {
        x
    }
}

/// f32 to Q7.24, rounded and saturated (configuration and the simulator boundary only;
/// NaN maps to 0).
pub fn to_q24(x: f32) -> i32 {
    let s = x * ONE as f32;
    // `as` from f32 saturates and maps NaN to 0
    (s + if s >= 0.0 { 0.5 } else { -0.5 }) as i32
}

/// Q7.24 to f32 (telemetry and the simulator boundary only).
pub fn from_q24(x: i32) -> f32 {
    x as f32 * (1.0 / ONE as f32)
}

/// A constant factor with its own binary point: `value = mantissa / 2^shift`, the
/// mantissa normalised to 29-30 significant bits at construction, so a gain of 4e-5 keeps
/// the same relative precision (about 2e-9, better than the f32 it comes from) as a gain
/// of 200. [`Gain::apply`] multiplies a Q7.24 signal by it: `saturate((x mantissa +
/// 2^(shift-1)) >> shift)`, the exact product rounded to nearest and saturated.
///
/// The step never shifts a 64-bit value by a variable amount: construction splits the
/// gain into the words [`Gain::apply`] needs (see there), so one apply is two multiplies
/// into 64 bits and a few single-word operations on every core (Cortex-M3 included).
///
/// Gains are built from the f32 designs at construction time (the designs stay
/// single-sourced in `observer`, `pi`, `flux`, `rs_estimator`, `svpwm`); the step never
/// sees an f32.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Gain {
    mantissa: i32,
    shift: u32,
    /// Multiplier of the 64-bit word sum (the fraction part): `(mantissa mod 2^shift)
    /// 2^(32-shift)` for shift <= 32, `mantissa` above.
    frac: i32,
    /// Multiplier of the integer part: `round(mantissa / 2^shift)` for shift <= 32, 0
    /// above (the result then cannot saturate).
    int: i32,
    /// Rounding constant added below the fraction product, low and high words: 2^31 for
    /// shift <= 32, `2^(shift-1)` above.
    round_lo: u32,
    /// High word of the rounding constant.
    round_hi: i32,
    /// Final right shift: 0 for shift <= 32, `shift - 32` above.
    post: u32,
}

impl Gain {
    /// The zero gain.
    pub const ZERO: Self = Self {
        mantissa: 0,
        shift: 0,
        frac: 0,
        int: 0,
        round_lo: 0,
        round_hi: 0,
        post: 0,
    };

    /// The gain `mantissa / 2^shift` (shift <= 62) with its apply words.
    const fn from_parts(mantissa: i32, shift: u32) -> Self {
        if shift <= 32 {
            // int = floor((m + 2^(shift-1)) / 2^shift), frac = m - int 2^shift in
            // [-2^(shift-1), 2^(shift-1)): frac 2^(32-shift) in [-2^31, 2^31)
            let m = mantissa as i64;
            let (int, rem) = if shift == 0 {
                (m, 0)
            } else {
                let i = (m + (1i64 << (shift - 1))) >> shift;
                (i, m - (i << shift))
            };
            Self {
                mantissa,
                shift,
                frac: (rem << (32 - shift)) as i32,
                int: int as i32,
                round_lo: 1 << 31,
                round_hi: 0,
                post: 0,
            }
        } else {
            let round = 1i64 << (shift - 1);
            Self {
                mantissa,
                shift,
                frac: mantissa,
                int: 0,
                round_lo: round as u32,
                round_hi: (round >> 32) as i32,
                post: shift - 32,
            }
        }
    }

    /// The gain nearest to `x`, or `None` when `x` is not finite or |x| >= 2^30
    /// (configuration time only).
    pub fn from_f32(x: f32) -> Option<Self> {
        if !crate::math::is_finite(x) || x.abs() >= 1_073_741_824.0 {
            return None;
        }
        if x == 0.0 {
            return Some(Self::ZERO);
        }
        // largest shift with |x| 2^shift < 2^30 (exact: scaling by 2 is exact in f32)
        let mut scaled = x;
        let mut shift = 0u32;
        while shift < 62 && (scaled * 2.0).abs() < 1_073_741_824.0 {
            scaled *= 2.0;
            shift += 1;
        }
        let mantissa = (scaled + if scaled >= 0.0 { 0.5 } else { -0.5 }) as i32;
        Some(Self::from_parts(mantissa, shift))
    }

    /// The value as f32 (tests and diagnostics).
    pub fn to_f32(self) -> f32 {
        let mut v = self.mantissa as f32;
        let mut s = 0;
        while s < self.shift {
            v *= 0.5;
            s += 1;
        }
        v
    }

    /// `x * value`, rounded to nearest and saturated: `saturate((x mantissa +
    /// 2^(shift-1)) >> shift)` (0 for the rounding term at shift 0), bit for bit
    /// (`tests::apply_matches_the_64_bit_form` over every shift and random inputs).
    ///
    /// How, with `m = int 2^shift + frac'` split at construction:
    /// - shift <= 32: `x m / 2^shift = x int + x frac' / 2^shift`, and the rounded
    ///   second term is the upper word of `x frac + 2^31` (`frac = frac' 2^(32-shift)`,
    ///   a 32-bit factor); the sum `x int + that` is exact in 64 bits and saturated to
    ///   `i32` from its two words;
    /// - shift > 32 (gains below 1/4): `int = 0`, the upper word of `x m + 2^(shift-1)`
    ///   shifted right by `shift - 32` is the result, which cannot saturate (|x m| <
    ///   2^61).
    ///
    /// Two multiply-accumulates (`SMLAL`), no variable 64-bit shift, no 64-bit compare.
    #[inline(always)]
    pub fn apply(self, x: i32) -> i32 {
        // the i64 arithmetic below cannot overflow (|x frac| < 2^62 plus a constant
        // below 2^61; |x int| <= 2^61 plus a word); the wrapping forms only keep
        // overflow-check panic paths out of every build profile
        let round = ((self.round_hi as i64) << 32) | self.round_lo as i64;
        let f = (x as i64)
            .wrapping_mul(self.frac as i64)
            .wrapping_add(round);
        let t = (f >> 32) as i32;
        if self.int == 0 {
            // gains below 1/2: no integer part, no saturation (post is 0 at shift 32)
            return t >> self.post;
        }
        let p = (x as i64)
            .wrapping_mul(self.int as i64)
            .wrapping_add(t as i64);
        // here shift <= 31, post = 0 and |t| <= 2^30: the sum leaves i32 only when
        // |x int| > 2^30, so x int is nonzero and has the sign of x ^ int
        saturate_words((p >> 32) as i32, p as i32, x ^ self.int)
    }
}

/// Square root of a Q7.24 value, in Q7.24 (0 for x <= 0): exact to the floor of the
/// last bit (integer square root of x 2^24). Used by the field-weakening limits.
#[inline]
pub fn sqrt_q24(x: i32) -> i32 {
    if x <= 0 {
        return 0;
    }
    // sqrt(x / 2^24) * 2^24 = isqrt(x * 2^24): digit-by-digit integer square root of a
    // value below 2^55, 28 fixed iterations (no division, no panic path)
    let n = (x as u64) << FRAC_BITS;
    let mut rem = n;
    let mut root = 0u64;
    let mut bit = 1u64 << 54;
    while bit != 0 {
        let trial = root.wrapping_add(bit);
        if rem >= trial {
            rem = rem.wrapping_sub(trial);
            root = (root >> 1).wrapping_add(bit);
        } else {
            root >>= 1;
        }
        bit >>= 2;
    }
    root as i32
}

/// Reciprocal of a positive Q7.24 value, in Q7.24: `2^48 / x`, for x in [2^-6, 128) pu
/// (inputs below 2^-6 pu, zero or negative are taken as 2^-6 pu, so the result is at most
/// 64 pu). Relative error below 1e-8 plus the final rounding (tests check 2 LSB).
///
/// Method: normalise x to X in [0.5, 1) with a count of leading zeros; seed 1/X with one
/// 32-bit hardware division (UDIV on Cortex-M3/M4, 2-12 cycles) of 2^32-1 by the top 16
/// bits of X (relative error < 2^-15); one Newton step y (2 - X y) squares that error.
/// Used where f32 divides too: 1/lambda_r in the slip law (eq. 8) and the observer, 1/V_dc
/// in the modulator and the voltage limit, and the overmodulation scale.
#[inline]
pub fn reciprocal(x: i32) -> i32 {
    const MIN_INPUT: i32 = 1 << (FRAC_BITS - 6);
    let x = if x > MIN_INPUT { x } else { MIN_INPUT } as u32;
    // x in [2^18, 2^31): n in [1, 13]
    let n = x.leading_zeros();
    // shifts and products below are in range by the bounds noted; the wrapping forms only
    // keep overflow-check panic paths out of every build profile
    let xn = x.wrapping_shl(n.wrapping_sub(1)); // [2^30, 2^31): X = xn / 2^31
    let d = (xn >> 15) | 1; // [2^15, 2^16), nonzero (the `| 1` changes it by < 2^-15)
    let q0 = u32::MAX / d; // 1/X in Q16, in [2^16, 2^17)
    let y0 = (q0 as u64) << 14; // 1/X in Q30 (< 2^31)
    let xy = (xn as u64).wrapping_mul(y0) >> 31; // X y0 in Q30
    let t = (2u64 << 30).saturating_sub(xy); // 2 - X y0 in Q30
    let y1 = y0.wrapping_mul(t) >> 30; // 1/X in Q30, about (2^30, 2^31]
                                       // 1/x_pu = Y 2^(n-8) -> Q24 raw = y1 / 2^(14-n), 14 - n in [1, 13]
    let s = 14u32.wrapping_sub(n);
    let r = y1
        .wrapping_add(1u64.wrapping_shl(s.wrapping_sub(1)))
        .wrapping_shr(s);
    saturate(r as i64)
}

pub use crate::num::PerUnitBases;

/// Frame angle: fraction of one electrical turn, 2^32 counts per turn (wraps by design).
pub type Angle = u32;

/// Counts per radian: 2^32 / (2 pi).
pub const COUNTS_PER_RAD: f32 = 4_294_967_296.0 / (2.0 * core::f32::consts::PI);

/// An angle from radians (configuration and the simulator boundary only).
pub fn angle_from_rad(rad: f32) -> Angle {
    let turns = rad * (1.0 / (2.0 * core::f32::consts::PI));
    let frac = turns - (turns as i64) as f32; // (-1, 1); `as` saturates, NaN -> 0
    (frac * 4_294_967_296.0) as i64 as u32
}

/// An angle in radians, in [-pi, pi) (telemetry and the simulator boundary only).
pub fn angle_to_rad(a: Angle) -> f32 {
    (a as i32) as f32 * (1.0 / COUNTS_PER_RAD)
}

/// A Q7.24 signal (`value_pu * 2^24` in an `i32`) with saturating arithmetic: `+`, `-`
/// and unary `-` saturate, `*` is [`mul`] (rounded, saturated). The cascade's fixed-point
/// [`Num`](crate::num::Num).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, PartialOrd)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(transparent)]
pub struct Q24(pub i32);

impl Q24 {
    /// The value nearest to `x` pu (configuration and the SI boundary only).
    pub fn from_pu(x: f32) -> Self {
        Q24(to_q24(x))
    }
    /// The value in pu (telemetry and the SI boundary only).
    pub fn to_pu(self) -> f32 {
        from_q24(self.0)
    }
}

impl core::ops::Add for Q24 {
    type Output = Q24;
    #[inline(always)]
    fn add(self, rhs: Q24) -> Q24 {
        Q24(self.0.saturating_add(rhs.0))
    }
}

impl core::ops::Sub for Q24 {
    type Output = Q24;
    #[inline(always)]
    fn sub(self, rhs: Q24) -> Q24 {
        Q24(self.0.saturating_sub(rhs.0))
    }
}

impl core::ops::Neg for Q24 {
    type Output = Q24;
    #[inline(always)]
    fn neg(self) -> Q24 {
        Q24(0i32.saturating_sub(self.0))
    }
}

impl core::ops::Mul for Q24 {
    type Output = Q24;
    #[inline(always)]
    fn mul(self, rhs: Q24) -> Q24 {
        Q24(mul(self.0, rhs.0))
    }
}

/// Extra fraction bits of the Rs integrator (Q1.30 in an `i32`).
const RS_EXTRA_BITS: u32 = 6;

impl crate::num::Num for Q24 {
    type Gain = Gain;

    const ZERO: Self = Q24(0);
    const ONE: Self = Q24(ONE);
    const HALF: Self = Q24(HALF);

    #[inline(always)]
    fn gain(g: Gain, x: Q24) -> Q24 {
        Q24(g.apply(x.0))
    }
    #[inline(always)]
    fn gain_mul(g: Gain, a: Q24, b: Q24) -> Q24 {
        Q24(g.apply(mul(a.0, b.0)))
    }
    #[inline(always)]
    fn sum_times(a: Q24, b: Q24, x: Q24) -> Q24 {
        (a + b) * x
    }
    #[inline(always)]
    fn abs(self) -> Q24 {
        Q24(self.0.saturating_abs())
    }
    #[inline(always)]
    fn half(self) -> Q24 {
        Q24(self.0 >> 1)
    }
    #[inline(always)]
    fn twice(self) -> Q24 {
        Q24(self.0.saturating_add(self.0))
    }
    #[inline(always)]
    fn clamp(self, lo: Q24, hi: Q24) -> Q24 {
        Q24(clamp(self.0, lo.0, hi.0))
    }
    #[inline(always)]
    fn into_range(self, _lo: Q24, _hi: Q24) -> Q24 {
        self
    }
    #[inline(always)]
    fn is_finite(self) -> bool {
        true
    }
    #[inline(always)]
    fn all_finite<const K: usize>(_: [Self; K]) -> bool {
        true
    }
    #[inline(always)]
    fn is_nan(self) -> bool {
        false
    }
}

impl crate::num::DivSqrt for Q24 {
    #[inline(always)]
    fn recip(self) -> Q24 {
        Q24(reciprocal(self.0))
    }
    #[inline(always)]
    fn ratio(num: Q24, den: Q24) -> Q24 {
        Q24(mul(num.0, reciprocal(den.0)))
    }
    #[inline(always)]
    fn per_count(x: Q24, count: u32) -> Q24 {
        // an integer division rounded to nearest (a running mean's steps would otherwise
        // all lean towards zero); a count beyond i32 leaves 0
        match i32::try_from(count) {
            Ok(n) if n > 0 => {
                let half = n / 2;
                let r = if x.0 >= 0 {
                    x.0.saturating_add(half)
                } else {
                    x.0.saturating_sub(half)
                };
                Q24(r / n)
            }
            _ => Q24(0),
        }
    }
    #[inline(always)]
    fn sqrt(self) -> Q24 {
        Q24(sqrt_q24(self.0))
    }
}

impl crate::num::FineIntegrator for Q24 {
    /// Q1.30: six bits finer than the signal, so that alpha Ts e (1e-6 pu per step at a
    /// settled residual) still moves it.
    type Fine = i32;
    const FINE_SCALE: f32 = (1u32 << RS_EXTRA_BITS) as f32;
    /// The signal's +/-2 pu in Q1.30: `to_fine` of -2^25 and 2^25 - 1.
    const FINE_RANGE: (i32, i32) = (i32::MIN, i32::MAX - 63);
    /// Below 2 pu (a margin under Q1.30's limit).
    fn fine_from_f32(x: f32) -> Option<i32> {
        if crate::math::is_finite(x) && x.abs() < 1.99 {
            Some(to_q24(x * Self::FINE_SCALE))
        } else {
            None
        }
    }
    #[inline(always)]
    fn to_fine(x: Q24) -> i32 {
        let r0 = clamp(x.0, -(1 << 25), (1 << 25) - 1);
        r0 << RS_EXTRA_BITS
    }
    #[inline(always)]
    fn from_fine(x: i32) -> Q24 {
        // rounded (|x| < 2^31 - 2^5: no overflow)
        Q24(x.saturating_add(1 << (RS_EXTRA_BITS - 1)) >> RS_EXTRA_BITS)
    }
    #[inline(always)]
    fn fine_step(acc: i32, g: Gain, e: Q24, positive: bool, lo: i32, hi: i32) -> (i32, bool) {
        let step = g.apply(e.0);
        let signed = if positive {
            step
        } else {
            0i32.saturating_sub(step)
        };
        let next = clamp(acc.saturating_add(signed), lo, hi);
        (next, next <= lo || next >= hi)
    }
}

impl crate::num::Units for Q24 {
    type Bases = PerUnitBases;
    const RECIP_FLOOR: f32 = 0.02;
    /// Q7.24 saturates at 128 pu.
    const SUM_LIMIT: f32 = 100.0;
    fn unit_bases(bases: &PerUnitBases) -> PerUnitBases {
        *bases
    }
    /// Within 2 pu (64x below saturation, the module docs' headroom).
    fn checked_from_f32(x: f32) -> Option<Q24> {
        if crate::math::is_finite(x) && x.abs() <= 2.0 {
            Some(Q24(to_q24(x)))
        } else {
            None
        }
    }
    fn gain_from_f32(x: f32) -> Option<Gain> {
        Gain::from_f32(x)
    }
    fn to_f32(self) -> f32 {
        from_q24(self.0)
    }
    fn from_f32(x: f32) -> Q24 {
        Q24(to_q24(x))
    }
}

impl crate::num::Angles for Q24 {
    const TURN_BY_PRODUCTS: bool = false;
    type Angle = Angle;
    /// Angle counts of the voltage lead per frequency pu.
    type Lead = Gain;
    /// Angle counts per step per frequency pu.
    fn angle_gain(rad_per_unit: f32) -> Option<Gain> {
        Gain::from_f32(rad_per_unit * COUNTS_PER_RAD / (1u32 << FRAC_BITS) as f32)
    }
    fn lead(ts: f32, delay: f32, b: &PerUnitBases) -> Option<Gain> {
        Self::angle_gain(b.frequency * ts * delay)
    }
    #[inline(always)]
    fn advance(angle: u32, frequency: Q24, per_step: Gain) -> u32 {
        // a signed increment added modulo one turn: the intended wrap of an angle
        angle.wrapping_add(per_step.apply(frequency.0) as u32)
    }
    fn angle_to_rad(a: u32) -> f32 {
        angle_to_rad(a)
    }
}

impl crate::num::ThreePhase for Q24 {
    const INV_SQRT3: Self = Q24(9_686_330);
    const SQRT3_2: Self = Q24(14_529_495);
    const ONE_THIRD: Self = Q24(5_592_405);
    const SQRT3: Self = Q24(29_058_991);
    #[inline(always)]
    fn neg_mean(a: Q24, b: Q24) -> Q24 {
        // each halved first: no overflow
        Q24(0i32.saturating_sub((a.0 >> 1).saturating_add(b.0 >> 1)))
    }
}

impl crate::frames::LeadRotation for Q24 {
    #[inline(always)]
    fn rotate_ahead<S: crate::frames::SinCos<Q24>>(
        sincos: &mut S,
        _sc: crate::frames::SinCosValue<Q24>,
        theta: u32,
        frequency: Q24,
        lead: Gain,
    ) -> crate::frames::SinCosValue<Q24> {
        // the exact rotation from the table (no series needed)
        sincos.sin_cos(theta.wrapping_add(lead.apply(frequency.0) as u32))
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use proptest::prelude::*;

    /// The 64-bit form [`mul`] had before the word-wise rewrite, verbatim: the
    /// reference the rewrite must reproduce bit for bit.
    fn mul_64(a: i32, b: i32) -> i32 {
        saturate(
            (a as i64)
                .wrapping_mul(b as i64)
                .wrapping_add(1i64 << (FRAC_BITS - 1))
                >> FRAC_BITS,
        )
    }

    /// The 64-bit form [`Gain::apply`] had before the rewrite (variable 64-bit shift,
    /// 64-bit saturation), verbatim.
    fn apply_64(g: Gain, x: i32) -> i32 {
        let p = (x as i64).wrapping_mul(g.mantissa as i64);
        let round = 1i64.wrapping_shl(g.shift) >> 1;
        saturate(p.wrapping_add(round).wrapping_shr(g.shift))
    }

    /// Inputs where rounding and saturation change: the extremes, zero, +-1, the
    /// powers of two and their neighbours.
    fn edge_inputs() -> std::vec::Vec<i32> {
        let mut v = std::vec![0, 1, -1, i32::MAX, i32::MIN, i32::MAX - 1, i32::MIN + 1];
        for k in 0..31 {
            let p = 1i32 << k;
            v.extend_from_slice(&[p, p - 1, p + 1, -p, -p + 1, -p - 1]);
        }
        v
    }

    /// Every mantissa/shift pair the constructor can produce is covered: shift 0..=62,
    /// mantissas at the normalisation bounds (2^29, 2^30 - 1 and negative) and random
    /// ones (including the small mantissas at the shift-62 cap).
    fn any_gain() -> impl Strategy<Value = Gain> {
        (
            prop_oneof![
                3 => (1i32 << 29)..(1i32 << 30),
                3 => -(1i32 << 30) + 1..=-(1i32 << 29),
                1 => Just((1i32 << 30) - 1),
                1 => Just(-(1i32 << 30) + 1),
                1 => Just(1i32 << 29),
                1 => -(1i32 << 29)..(1i32 << 29),
            ],
            0u32..=62,
        )
            .prop_map(|(m, s)| Gain::from_parts(m, s))
    }

    fn any_signal() -> impl Strategy<Value = i32> {
        prop_oneof![
            4 => any::<i32>(),
            4 => -(1i32 << 26)..(1i32 << 26),
            1 => -1024i32..1024,
            1 => prop_oneof![Just(i32::MAX), Just(i32::MIN), Just(0)],
        ]
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(200_000))]
        /// The word-wise [`Gain::apply`] is the 64-bit form, bit for bit.
        #[test]
        fn apply_matches_the_64_bit_form(g in any_gain(), x in any_signal()) {
            prop_assert_eq!(g.apply(x), apply_64(g, x), "{:?} x = {}", g, x);
        }

        /// The word-wise [`mul`] is the 64-bit form, bit for bit.
        #[test]
        fn mul_matches_the_64_bit_form(a in any_signal(), b in any_signal()) {
            prop_assert_eq!(mul(a, b), mul_64(a, b), "{} {}", a, b);
        }
    }

    /// Exhaustive over the edges: every shift, mantissas at the bounds, every edge input
    /// (where saturation and the rounding tie change), for both forms.
    #[test]
    fn apply_and_mul_match_on_the_edges() {
        let xs = edge_inputs();
        for s in 0..=62u32 {
            for m in [
                1 << 29,
                (1 << 30) - 1,
                -(1 << 29),
                -(1 << 30) + 1,
                1,
                -1,
                0x2AAA_AAAB,
                -0x3555_5555,
            ] {
                let g = Gain::from_parts(m, s);
                for &x in &xs {
                    assert_eq!(g.apply(x), apply_64(g, x), "m {m} s {s} x {x}");
                }
            }
        }
        for &a in &xs {
            for &b in &xs {
                assert_eq!(mul(a, b), mul_64(a, b), "{a} {b}");
            }
        }
    }

    /// The gains of the paper design (every shift class it uses) over a dense sweep of
    /// the signal range.
    #[test]
    fn apply_matches_for_the_design_gains() {
        let d =
            crate::design::DriveDesign::new(crate::design::DriveConfig::paper_defaults()).unwrap();
        let c = crate::design::DriveCoeffs::<Q24>::new(&d, &PerUnitBases::PAPER).unwrap();
        let gains = [
            c.current_loop.pi_d.kp,
            c.current_loop.pi_d.ki_ts,
            c.speed_loop.pi.kp,
            c.speed_loop.pi.ki_ts,
            c.speed_loop.acceleration_feedforward,
            c.speed_loop.friction_feedforward,
            c.speed_loop.load_feedforward,
            c.flux.blend,
            c.flux.magnetizing_inductance,
            c.flux.slip_gain,
            c.flux.ts,
            c.observer.ts_a,
            c.observer.ts_inv_l,
            c.observer.ts_p_inv_l,
            c.observer.ts,
            c.observer.ts_torque_per_inertia,
            c.observer.ts_inv_inertia,
            c.observer.ts_friction_rate,
            c.observer.ts_g2,
            c.observer.ts_g3,
            c.rs.ts,
            c.rs.ts_over_transient_inductance,
            c.rs.alpha_ts,
            c.pwm.inv_current_band,
            c.model.transient_inductance,
            c.model.inv_rotor_time_constant,
            c.model.pole_pairs,
            c.model.back_emf,
            c.model.torque_factor,
            c.speed_loop.speed_per_volt,
            c.cascade.lead,
            c.pwm.voltage_limit_per_inv_bus,
        ];
        let mut shifts = [false; 63];
        for g in gains {
            shifts[g.shift as usize] = true;
            let mut x = i32::MIN;
            loop {
                assert_eq!(g.apply(x), apply_64(g, x), "{g:?} x {x}");
                assert_eq!(g.apply(x ^ 0x5A5A), apply_64(g, x ^ 0x5A5A), "{g:?} x {x}");
                match x.checked_add(65_537) {
                    Some(n) => x = n,
                    None => break,
                }
            }
        }
        // both construction classes are exercised by the design
        assert!(shifts[..=32].iter().any(|&b| b) && shifts[33..].iter().any(|&b| b));
    }

    #[test]
    fn reciprocal_is_accurate_over_its_range() {
        let mut x = 1i32 << 18;
        let mut worst = 0.0f64;
        while x < i32::MAX / 2 {
            for k in 0..64 {
                let v = x + k * (x >> 6);
                let exact = (1u64 << 48) as f64 / v as f64;
                let err = (reciprocal(v) as f64 - exact).abs();
                worst = worst.max(err);
                assert!(err <= 2.0, "x = {v}: {} vs {exact}", reciprocal(v));
            }
            x *= 2;
        }
        assert!(worst <= 2.0);
        assert_eq!(reciprocal(0), reciprocal(1 << 18));
        assert_eq!(reciprocal(-5), reciprocal(1 << 18));
        assert_eq!(reciprocal(ONE), ONE);
    }

    #[test]
    fn gains_keep_relative_precision_and_saturate() {
        for &g in &[4e-5f32, 0.003, 1.0, -0.7, 5.12, 200.0, -754.0] {
            let k = Gain::from_f32(g).unwrap();
            assert!(((k.to_f32() - g) / g).abs() < 1e-7, "{g}");
            let y = k.apply(ONE / 1000);
            let exact = g as f64 * (ONE / 1000) as f64;
            assert!((y as f64 - exact).abs() <= 1.0 + exact.abs() * 1e-7, "{g}");
        }
        assert_eq!(Gain::from_f32(0.0), Some(Gain::ZERO));
        assert_eq!(Gain::from_f32(f32::NAN), None);
        assert_eq!(Gain::from_f32(2e9), None);
        let big = Gain::from_f32(1000.0).unwrap();
        assert_eq!(big.apply(i32::MAX), i32::MAX);
        assert_eq!(big.apply(i32::MIN), i32::MIN);
        assert_eq!(mul(i32::MAX, i32::MAX), i32::MAX);
        assert_eq!(mul(i32::MIN, i32::MAX), i32::MIN);
        assert_eq!(mul(ONE, -ONE), -ONE);
        assert_eq!(to_q24(f32::NAN), 0);
        assert_eq!(to_q24(1e9), i32::MAX);
    }
}
