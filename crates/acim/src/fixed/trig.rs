//! Frame angle as a turn fraction, table sin/cos, and Clarke/Park in Q7.24 (paper Fig. 3;
//! the same amplitude-invariant transforms as [`crate::frames`]).
//!
//! ## Angle
//!
//! [`Angle`] is a `u32` fraction of one electrical turn: 2^32 counts = 2 pi rad, one count
//! = 1.46e-9 rad. Adding a signed increment with `wrapping_add` is exactly the wrap to one
//! turn that an angle needs: here wrap-around is the intended arithmetic, not an overflow
//! (the only wrapping quantity of the fixed-point path).
//!
//! ## sin/cos
//!
//! A quarter-wave table of sin at 257 points (0 .. pi/2, step pi/512), Q7.24, computed at
//! compile time by an integer Taylor series in Q62 (no float at all), with linear
//! interpolation on the next 16 bits of the angle. Error bound h^2/8 = 4.7e-6 for the
//! step h = pi/512 (measured: below 5e-6 against f64 over a full turn, test
//! `sin_cos_accuracy`); sin^2 + cos^2 = 1 within 1e-5. Quadrant symmetry gives the other
//! three quarters; cos(theta) = sin(theta + pi/2). About 20 instructions per value, no
//! multiply beyond the interpolation, 1 KiB of flash.

pub use super::q::{angle_from_rad, angle_to_rad, Angle, COUNTS_PER_RAD};
use super::q::{FRAC_BITS, Q24};
use crate::frames::{SinCos, SinCosValue};

/// pi/2 in Q62 (round(pi/2 2^62)).
const HALF_PI_Q62: i128 = 7_244_019_458_077_122_842;
/// Segments of the quarter-wave table.
const SEGMENTS: i128 = 256;

/// sin(k pi/512) in Q7.24, rounded, by the Taylor series in Q62 (compile time).
const fn table_entry(k: i128) -> i32 {
    let x = k * HALF_PI_Q62 / SEGMENTS;
    let x2 = (x * x) >> 62;
    let mut term = x;
    let mut sum = x;
    let mut n = 1;
    while n < 14 {
        // term_n = -term_{n-1} x^2 / ((2n)(2n+1))
        term = -((term * x2) >> 62) / ((2 * n) * (2 * n + 1));
        sum += term;
        n += 1;
    }
    ((sum + (1i128 << (61 - FRAC_BITS))) >> (62 - FRAC_BITS)) as i32
}

const fn build_table() -> [i32; 257] {
    let mut t = [0i32; 257];
    let mut k = 0;
    while k < 257 {
        t[k] = table_entry(k as i128);
        k += 1;
    }
    t
}

/// sin over the first quarter turn, 257 points, Q7.24.
static QUARTER_SINE: [i32; 257] = build_table();

/// sin of a turn-fraction angle, Q7.24 (see the module docs for the accuracy).
#[inline]
pub fn sin(a: Angle) -> i32 {
    let quadrant = a >> 30;
    let p = a & 0x3FFF_FFFF;
    // quadrants 1 and 3 run the quarter wave backwards; p in [0, 2^30]
    let p = if quadrant & 1 == 1 {
        (1u32 << 30).wrapping_sub(p)
    } else {
        p
    };
    let index = (p >> 22) as usize; // 0..=256
    let frac = ((p >> 6) & 0xFFFF) as i64; // 16 bits between two table points
    let y0 = QUARTER_SINE.get(index).copied().unwrap_or(0);
    // index 256 only with frac = 0: the missing neighbour is never weighted
    let y1 = QUARTER_SINE
        .get(index.wrapping_add(1))
        .copied()
        .unwrap_or(y0);
    // |y1 - y0| < 2^18 and frac < 2^16: the products and sums are far inside i64
    let slope = (y1 as i64).wrapping_sub(y0 as i64);
    let y = (y0 as i64).wrapping_add(slope.wrapping_mul(frac).wrapping_add(1 << 15) >> 16);
    let y = y as i32; // within [0, 2^24]: the table's range
    if quadrant & 2 != 0 {
        y.wrapping_neg() // |y| <= 2^24: exact
    } else {
        y
    }
}

/// sin and cos of `a` (Q7.24) from the table.
#[inline(always)]
pub fn sin_cos(a: Angle) -> SinCosValue<Q24> {
    SinCosValue {
        sin: Q24(sin(a)),
        cos: Q24(sin(a.wrapping_add(1 << 30))),
    }
}

/// The table sin/cos as the cascade's [`SinCos`] for Q7.24.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct TableSinCos;

impl SinCos<Q24> for TableSinCos {
    #[inline(always)]
    fn sin_cos(&mut self, theta: Angle) -> SinCosValue<Q24> {
        sin_cos(theta)
    }
}
