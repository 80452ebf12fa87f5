//! Small f32 helpers that `core` lacks on `no_std` targets (no `sqrt`, no `floor`).
//!
//! Everything here is branch-light, allocation-free, panic-free and f32-only, so it can run
//! in the control step on a Cortex-M4F without pulling in f64 or `libm`.

use core::f32::consts::PI;

/// 2 pi.
pub const TAU: f32 = 2.0 * PI;

/// True when `x` is neither NaN nor infinite (bit test, no float compare tricks).
#[inline(always)]
pub fn is_finite(x: f32) -> bool {
    (x.to_bits() & 0x7f80_0000) != 0x7f80_0000
}

/// 1/sqrt(x) for x > 0 by an exponent-halving seed and three Newton steps
/// (relative error below 2e-7 over the normal range). Returns 0 for x <= 0 or NaN, and
/// 0 for +inf. No division.
#[inline]
pub fn rsqrt(x: f32) -> f32 {
    if x.is_nan() || x <= 0.0 || !is_finite(x) {
        return 0.0;
    }
    let mut y = f32::from_bits(0x5f37_5a86_u32.wrapping_sub(x.to_bits() >> 1));
    let hx = 0.5 * x;
    y *= 1.5 - hx * y * y;
    y *= 1.5 - hx * y * y;
    y *= 1.5 - hx * y * y;
    y
}

/// sqrt(x) for x >= 0 (returns 0 for x <= 0 or NaN), relative error below 2e-7.
#[inline]
pub fn sqrt(x: f32) -> f32 {
    let r = rsqrt(x);
    if r > 0.0 {
        x * r
    } else {
        0.0
    }
}

/// Wraps an angle that is at most one turn outside [-pi, pi) (the usual case: an angle
/// advanced by a small increment) with one comparison each way; anything else (large,
/// NaN) goes through [`wrap_angle`].
#[inline(always)]
pub fn wrap_angle_step(x: f32) -> f32 {
    // an x in [-pi, pi) needs no range check after the two compares: only NaN (every
    // comparison false) gets past them unwrapped, and one self-comparison finds it (the
    // same results as checking the range of every outcome, one compare fewer on the
    // common path)
    // (the wrapping arms are marked cold: an angle advanced by a period's increment
    // wraps once per turn, and the in-range case falls through)
    let a = if x >= PI {
        core::hint::cold_path();
        x - TAU
    } else if x < -PI {
        core::hint::cold_path();
        x + TAU
    } else if !x.is_nan() {
        return x;
    } else {
        core::hint::cold_path();
        return wrap_angle(x);
    };
    if (-PI..PI).contains(&a) {
        a
    } else {
        wrap_angle(x)
    }
}

/// Wraps an angle (rad) into [-pi, pi). Exact for |x| < 3 pi (one correction); larger
/// inputs are reduced by an integer number of turns first. NaN maps to 0.
#[inline]
pub fn wrap_angle(x: f32) -> f32 {
    if !is_finite(x) {
        return 0.0;
    }
    let mut a = x;
    if !(-3.0 * PI..3.0 * PI).contains(&a) {
        // Work in turns: the fractional part of a/TAU is exact in f32. Beyond 2^23 turns
        // there is no fractional part left to keep. `as i32` saturates, never panics.
        let turns = a * (1.0 / TAU);
        a = if turns.abs() < 8_388_608.0 {
            (turns - (turns as i32) as f32) * TAU
        } else {
            0.0
        };
    }
    if a >= PI {
        a -= TAU;
    } else if a < -PI {
        a += TAU;
    }
    if a >= PI {
        a -= TAU;
    } else if a < -PI {
        a += TAU;
    }
    a
}

/// Clamps to [lo, hi] (requires lo <= hi); a NaN input returns 0 clamped into range.
/// Comparisons only: `f32::clamp` asserts `lo <= hi` and would link a panic path (and
/// core's float formatting) into the control step. The control step uses
/// [`clamp_in_range`] or [`clamp_at_limits`], the same function laid out for its usual
/// case.
#[inline(always)]
pub fn clamp(x: f32, lo: f32, hi: f32) -> f32 {
    if x > hi {
        hi
    } else if x >= lo {
        x
    } else {
        clamp_below(x, lo, hi)
    }
}

/// [`clamp`] for a value usually in range (a regulator's integral, a correction within
/// its bound): the same result, with the limits' arms marked cold, so that a value in
/// range falls through.
#[inline(always)]
pub fn clamp_in_range(x: f32, lo: f32, hi: f32) -> f32 {
    if x > hi {
        core::hint::cold_path();
        hi
    } else if x >= lo {
        x
    } else {
        core::hint::cold_path();
        clamp_below(x, lo, hi)
    }
}

/// [`clamp`] for a value usually at one of its limits (a saturated sign, a fade that is
/// complete): the same result, with the in-range arm marked cold instead.
#[inline(always)]
pub fn clamp_at_limits(x: f32, lo: f32, hi: f32) -> f32 {
    if x > hi {
        hi
    } else if x < lo {
        lo
    } else if x >= lo {
        core::hint::cold_path();
        x
    } else {
        core::hint::cold_path();
        clamp_below(x, lo, hi)
    }
}

/// [`clamp`]'s arms for an `x` not above `hi` and not at or above `lo`: below `lo`, or
/// NaN (0 clamped into range).
#[inline(always)]
fn clamp_below(x: f32, lo: f32, hi: f32) -> f32 {
    if x < lo {
        lo
    } else if 0.0 > hi {
        // NaN
        hi
    } else if 0.0 < lo {
        lo
    } else {
        0.0
    }
}

/// Radians per second to revolutions per minute.
pub const RAD_S_TO_RPM: f32 = 60.0 / TAU;
/// Revolutions per minute to radians per second.
pub const RPM_TO_RAD_S: f32 = TAU / 60.0;

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn sqrt_is_exact_enough() {
        for &x in &[1e-12f32, 1e-6, 0.01, 0.5, 1.0, 2.0, 3.0, 1e3, 1e9, 3.3e38] {
            let r = sqrt(x);
            let e = (r as f64 - (x as f64).sqrt()).abs() / (x as f64).sqrt();
            assert!(e < 3e-7, "sqrt({x}) = {r}, rel err {e}");
        }
        assert_eq!(sqrt(0.0), 0.0);
        assert_eq!(sqrt(-1.0), 0.0);
        assert_eq!(sqrt(f32::NAN), 0.0);
    }

    #[test]
    fn wrap_handles_edges() {
        assert_eq!(wrap_angle(PI), -PI);
        assert_eq!(wrap_angle(-PI), -PI);
        assert_eq!(wrap_angle(f32::NAN), 0.0);
        assert!((wrap_angle(7.0) - (7.0 - TAU)).abs() < 1e-6);
        assert!(wrap_angle(1e9).abs() <= PI);
        assert_eq!(clamp(f32::NAN, -1.0, 1.0), 0.0);
        assert_eq!(clamp(f32::NAN, 0.5, 1.0), 0.5);
    }

    /// The three layouts of the clamp are one function: bit for bit on the edges (both
    /// limits, both zeros, infinities, NaN) of three ranges, one of them below zero.
    #[test]
    fn clamp_layouts_are_clamp() {
        let xs = [
            f32::NEG_INFINITY,
            -2.0,
            -1.0,
            -0.5,
            -0.0,
            0.0,
            f32::MIN_POSITIVE,
            0.5,
            1.0,
            2.0,
            f32::INFINITY,
            f32::NAN,
            -f32::NAN,
        ];
        for (lo, hi) in [(-1.0f32, 1.0f32), (0.0, 1.0), (-3.0, -2.0)] {
            for x in xs {
                assert_eq!(
                    clamp_at_limits(x, lo, hi).to_bits(),
                    clamp(x, lo, hi).to_bits(),
                    "{x} in [{lo}, {hi}]"
                );
                assert_eq!(
                    clamp_in_range(x, lo, hi).to_bits(),
                    clamp(x, lo, hi).to_bits(),
                    "{x} in [{lo}, {hi}]"
                );
            }
        }
    }

    proptest! {
        #[test]
        fn wrap_stays_in_range_and_preserves_angle(x in -1e4f32..1e4) {
            let w = wrap_angle(x);
            prop_assert!((-PI..PI).contains(&w));
            let d = (x as f64 - w as f64) / core::f64::consts::TAU;
            prop_assert!((d - d.round()).abs() < 1e-3 * (1.0 + x.abs() as f64 / 1e3));
        }

        #[test]
        fn clamp_layouts_match_clamp(x in -1e3f32..1e3, lo in -10f32..0.0, w in 0f32..20.0) {
            let hi = lo + w;
            prop_assert_eq!(clamp_at_limits(x, lo, hi).to_bits(), clamp(x, lo, hi).to_bits());
            prop_assert_eq!(clamp_in_range(x, lo, hi).to_bits(), clamp(x, lo, hi).to_bits());
        }

        #[test]
        fn wrap_step_matches_wrap(x in -20f32..20.0) {
            prop_assert_eq!(wrap_angle_step(x), wrap_angle(x));
        }

        #[test]
        fn sqrt_matches_std(x in 1e-20f32..1e30) {
            let e = (sqrt(x) as f64 - (x as f64).sqrt()).abs() / (x as f64).sqrt();
            prop_assert!(e < 3e-7);
        }
    }
}
