//! Reference-frame transforms (paper Fig. 3: the stationary 0-alpha-beta frame and the
//! rotating 0dq frame at angle theta_s) and the sin/cos provider.
//!
//! Scaling is amplitude-invariant: a balanced set of phase currents of peak value I gives
//! |i_alpha_beta| = |i_dq| = I. Hence Te = 1.5 p lambda_r i_sq (design notes section 2).
//! The q axis leads the d axis by 90 degrees; Park rotates by -theta.

use crate::num::{Angles, Num, ThreePhase};

/// A vector in the stationary alpha-beta frame (A or V, peak-value scaling; pu in fixed
/// point).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct AlphaBeta<N = f32> {
    /// alpha component (aligned with phase a).
    pub alpha: N,
    /// beta component (90 degrees ahead of alpha).
    pub beta: N,
}

/// A vector in the rotating dq frame (A or V, peak-value scaling; pu in fixed point).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Dq<N = f32> {
    /// d (flux) axis component.
    pub d: N,
    /// q (torque) axis component.
    pub q: N,
}

/// sin and cos of one angle, computed together.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SinCosValue<N = f32> {
    /// sin(theta).
    pub sin: N,
    /// cos(theta).
    pub cos: N,
}

/// A source of sin/cos for the arithmetic `N`. The f32 library uses [`FastSinCos`]; the
/// firmware plugs in the STM32G4 CORDIC through this trait; fixed point uses the table of
/// [`crate::fixed::trig`]. Implementations take any angle (the library passes angles
/// already wrapped to one turn) and must not panic; for a non-finite input they return
/// some finite value of unit magnitude.
pub trait SinCos<N: Angles = f32> {
    /// sin and cos of `theta` (rad in f32, a turn fraction in fixed point).
    fn sin_cos(&mut self, theta: N::Angle) -> SinCosValue<N>;
}

/// Software sin/cos in f32: quadrant reduction (Cody-Waite, two-part pi/2) and
/// Taylor polynomials of degree 9 (sin) and 8 (cos) on [-pi/4, pi/4].
///
/// Accuracy (tested against f64 over [-pi, pi] and over +/-100 rad): absolute error
/// below 2.5e-7 (about 2 ulp near 1), and sin^2 + cos^2 = 1 within 1e-6. About 20 FPU
/// operations, no division, no table, no f64.
#[derive(Clone, Copy, Debug, Default)]
pub struct FastSinCos;

// pi/2 split so that k * PIO2_HI is exact for |k| < 2^10.
const PIO2_HI: f32 = 1.570_312_5;
// pi/2 - PIO2_HI = 4.838267948966e-4, written out: computing it from the f32 FRAC_PI_2
// would carry that constant's 4.4e-8 rounding error into every reduced angle.
const PIO2_LO: f32 = 4.838_268e-4;
const FRAC_2_PI: f32 = core::f32::consts::FRAC_2_PI;

impl FastSinCos {
    /// sin and cos of `theta` (rad). Exact quadrant reduction for |theta| < 1000 rad;
    /// beyond that the angle is first wrapped (precision of the input dominates).
    #[inline(always)]
    pub fn eval(theta: f32) -> SinCosValue {
        let x = if theta.abs() < 1000.0 {
            theta
        } else {
            crate::math::wrap_angle(theta)
        };
        // nearest quadrant index; `as i32` saturates (NaN -> 0), never panics.
        let kf = x * FRAC_2_PI;
        let k = (kf + 0.5f32.copysign(kf)) as i32;
        let r = (x - k as f32 * PIO2_HI) - k as f32 * PIO2_LO;
        let r2 = r * r;
        let s = r
            * (1.0
                + r2 * (-1.0 / 6.0
                    + r2 * (1.0 / 120.0 + r2 * (-1.0 / 5040.0 + r2 * (1.0 / 362_880.0)))));
        let c = 1.0 + r2 * (-0.5 + r2 * (1.0 / 24.0 + r2 * (-1.0 / 720.0 + r2 * (1.0 / 40320.0))));
        // always finite: x is finite with |x| < 1000 or wrapped into [-pi, pi) (a NaN or
        // an infinity wraps to 0), so |r| <= pi/4 and the polynomials are bounded. The
        // finiteness check the result used to get could never fail (test
        // `non_finite_and_extreme_inputs_give_finite_values`).
        match k & 3 {
            0 => SinCosValue { sin: s, cos: c },
            1 => SinCosValue { sin: c, cos: -s },
            2 => SinCosValue { sin: -s, cos: -c },
            _ => SinCosValue { sin: -c, cos: s },
        }
    }
}

impl SinCos for FastSinCos {
    #[inline(always)]
    fn sin_cos(&mut self, theta: f32) -> SinCosValue {
        Self::eval(theta)
    }
}

/// Clarke transform from two measured phase currents, assuming i_a + i_b + i_c = 0:
/// i_alpha = i_a, i_beta = (i_a + 2 i_b)/sqrt(3).
#[inline(always)]
pub fn clarke_two<N: ThreePhase>(i_a: N, i_b: N) -> AlphaBeta<N> {
    AlphaBeta {
        alpha: i_a,
        beta: (i_a + i_b.twice()) * N::INV_SQRT3,
    }
}

/// Clarke transform of three phase quantities (zero sequence rejected):
/// alpha = (2a - b - c)/3, beta = (b - c)/sqrt(3).
#[inline(always)]
pub fn clarke_three<N: ThreePhase>(a: N, b: N, c: N) -> AlphaBeta<N> {
    AlphaBeta {
        alpha: (a.twice() - b - c) * N::ONE_THIRD,
        beta: (b - c) * N::INV_SQRT3,
    }
}

/// Inverse amplitude-invariant Clarke (no zero sequence): phase values a, b, c.
#[inline(always)]
pub fn inverse_clarke<N: ThreePhase>(v: AlphaBeta<N>) -> [N; 3] {
    let half_alpha = v.alpha.half();
    let k = N::SQRT3_2 * v.beta;
    [v.alpha, k - half_alpha, -half_alpha - k]
}

/// Park transform: stationary to the dq frame at angle theta (given by its sin/cos):
/// d = alpha cos + beta sin, q = beta cos - alpha sin.
#[inline(always)]
pub fn park<N: Num>(v: AlphaBeta<N>, sc: SinCosValue<N>) -> Dq<N> {
    Dq {
        d: v.alpha * sc.cos + v.beta * sc.sin,
        q: v.beta * sc.cos - v.alpha * sc.sin,
    }
}

/// Inverse Park transform: dq frame at angle theta back to stationary.
#[inline(always)]
pub fn inverse_park<N: Num>(v: Dq<N>, sc: SinCosValue<N>) -> AlphaBeta<N> {
    AlphaBeta {
        alpha: v.d * sc.cos - v.q * sc.sin,
        beta: v.d * sc.sin + v.q * sc.cos,
    }
}

/// sin/cos of (theta + delta) from sin/cos of theta and a small delta (|delta| < 0.3 rad)
/// by the angle-sum formula with 3rd/4th-order series for delta (error < 2e-5 at 0.3 rad,
/// < 1e-7 at the 0.1 rad of 1500 rpm and 1.5 periods). The f32 voltage lead.
/// Always inlined: LLVM kept it out of line in the step (a call, a frame and four
/// register moves, about 15 cycles of its 50).
#[inline(always)]
pub fn small_rotation(sc: SinCosValue, delta: f32) -> SinCosValue {
    let d = crate::math::clamp_in_range(delta, -0.3, 0.3);
    let d2 = d * d;
    let sd = d * (1.0 - d2 * (1.0 / 6.0));
    let cd = 1.0 - d2 * (0.5 - d2 * (1.0 / 24.0));
    SinCosValue {
        sin: sc.sin * cd + sc.cos * sd,
        cos: sc.cos * cd - sc.sin * sd,
    }
}

/// An arithmetic's sin/cos at the angle the voltage acts at: the frame angle advanced by
/// the computation and PWM delay (the modulation stage's lead).
pub trait LeadRotation: Angles {
    /// `theta` (with `sc` its sin/cos) advanced by the lead of `frequency` (rad/s
    /// electrical) over `lead` (the delay).
    fn rotate_ahead<S: SinCos<Self>>(
        sincos: &mut S,
        sc: SinCosValue<Self>,
        theta: Self::Angle,
        frequency: Self,
        lead: Self::Lead,
    ) -> SinCosValue<Self>;
}

impl LeadRotation for f32 {
    /// The small rotation by w_s Ts delay (its series, no second sin/cos).
    #[inline(always)]
    fn rotate_ahead<S: SinCos<f32>>(
        _sincos: &mut S,
        sc: SinCosValue<f32>,
        _theta: f32,
        frequency: f32,
        lead: (f32, f32),
    ) -> SinCosValue<f32> {
        small_rotation(sc, frequency * lead.0 * lead.1)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use core::f32::consts::{FRAC_PI_2, PI, TAU as TAU_F};
    use proptest::prelude::*;

    #[test]
    fn fast_sincos_accuracy_over_a_turn_and_beyond() {
        let mut worst = 0.0f64;
        let n = 200_000;
        for i in 0..=n {
            let x = -100.0 + 200.0 * i as f64 / n as f64;
            let v = FastSinCos::eval(x as f32);
            let xf = x as f32 as f64; // compare against the angle actually passed
            worst = worst
                .max((v.sin as f64 - xf.sin()).abs())
                .max((v.cos as f64 - xf.cos()).abs());
        }
        assert!(worst < 2.5e-7, "worst abs error {worst}");
        for &x in &[
            0.0f32, PI, -PI, FRAC_PI_2, -FRAC_PI_2, 1e-30, 999.9, 1e6, -1e30,
        ] {
            let v = FastSinCos::eval(x);
            assert!((v.sin * v.sin + v.cos * v.cos - 1.0).abs() < 1e-6, "{x}");
        }
        let v = FastSinCos::eval(f32::NAN);
        assert_eq!((v.sin, v.cos), (0.0, 1.0));
        let v = FastSinCos::eval(f32::INFINITY);
        assert_eq!((v.sin, v.cos), (0.0, 1.0));
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(100_000))]
        /// Every f32 bit pattern (NaN payloads, infinities, subnormals, the extremes)
        /// gives a finite sin/cos: the reason `eval` needs no finiteness check of its own.
        #[test]
        fn non_finite_and_extreme_inputs_give_finite_values(bits in any::<u32>()) {
            let v = FastSinCos::eval(f32::from_bits(bits));
            prop_assert!(v.sin.is_finite() && v.cos.is_finite(), "{:e}", f32::from_bits(bits));
            prop_assert!(v.sin.abs() <= 1.0 + 1e-6 && v.cos.abs() <= 1.0 + 1e-6);
        }
    }

    #[test]
    fn non_finite_and_extreme_inputs_exhaustive_edges() {
        for x in [
            f32::NAN,
            -f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::MAX,
            f32::MIN,
            f32::MIN_POSITIVE,
            -f32::MIN_POSITIVE,
            1e-45,
            -0.0,
            999.999_94,
            -999.999_94,
            1000.0,
            -1000.0,
            8_388_608.0 * TAU_F,
            -8_388_608.0 * TAU_F,
        ] {
            let v = FastSinCos::eval(x);
            assert!(v.sin.is_finite() && v.cos.is_finite(), "{x:e}");
        }
        // every float in [-1000, 1000] reachable by a coarse walk over the bit patterns
        let mut b = 0u32;
        while b < u32::MAX - 4093 {
            let x = f32::from_bits(b);
            let v = FastSinCos::eval(x);
            assert!(v.sin.is_finite() && v.cos.is_finite(), "{x:e}");
            b += 4093;
        }
    }

    #[test]
    fn clarke_of_balanced_set_has_peak_magnitude() {
        let amp = 3.0f32;
        for k in 0..12 {
            let th = k as f32 * PI / 6.0;
            let a = amp * th.cos();
            let b = amp * (th - 2.0 * PI / 3.0).cos();
            let c = amp * (th + 2.0 * PI / 3.0).cos();
            let v2 = clarke_two(a, b);
            let v3 = clarke_three(a, b, c);
            assert!((v2.alpha - amp * th.cos()).abs() < 1e-5);
            assert!((v2.beta - amp * th.sin()).abs() < 1e-5);
            assert!((v3.alpha - v2.alpha).abs() < 1e-5 && (v3.beta - v2.beta).abs() < 1e-5);
            // Park at the same angle gives a pure d-axis vector.
            let dq = park(v2, FastSinCos::eval(th));
            assert!((dq.d - amp).abs() < 1e-5 && dq.q.abs() < 1e-5);
        }
        // three-current variant rejects a zero-sequence offset
        let v = clarke_three(1.0 + 0.3, -0.5 + 0.3, -0.5 + 0.3);
        assert!((v.alpha - 1.0).abs() < 1e-6 && v.beta.abs() < 1e-6);
    }

    proptest! {
        #[test]
        fn park_round_trip(alpha in -100f32..100.0, beta in -100f32..100.0, th in -10f32..10.0) {
            let sc = FastSinCos::eval(th);
            let v = AlphaBeta { alpha, beta };
            let back = inverse_park(park(v, sc), sc);
            prop_assert!((back.alpha - alpha).abs() < 1e-4 && (back.beta - beta).abs() < 1e-4);
            let dq = park(v, sc);
            let m0 = alpha * alpha + beta * beta;
            let m1 = dq.d * dq.d + dq.q * dq.q;
            prop_assert!((m0 - m1).abs() <= 1e-5 * (1.0 + m0));
        }

        #[test]
        fn clarke_round_trip(alpha in -100f32..100.0, beta in -100f32..100.0) {
            let [a, b, c] = inverse_clarke(AlphaBeta { alpha, beta });
            prop_assert!((a + b + c).abs() < 1e-4);
            let v2 = clarke_two(a, b);
            let v3 = clarke_three(a, b, c);
            prop_assert!((v2.alpha - alpha).abs() < 1e-4 && (v2.beta - beta).abs() < 1e-4);
            prop_assert!((v3.alpha - alpha).abs() < 1e-4 && (v3.beta - beta).abs() < 1e-4);
        }

        #[test]
        fn sincos_unit_magnitude(th in -1e4f32..1e4) {
            let v = FastSinCos::eval(th);
            prop_assert!((v.sin * v.sin + v.cos * v.cos - 1.0).abs() < 1e-6);
        }
    }
}
