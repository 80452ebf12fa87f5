//! sin/cos for the drive from the G4 CORDIC peripheral (q1.31 in and out, 24 iterations,
//! zero-overhead mode: write the argument, read the results; the bus stalls until they
//! are ready, about 10 clock cycles). Residual error about 2^-19 (~2e-6).
use acim::frames::{SinCos, SinCosValue};
use acim::math::wrap_angle;
use core::f32::consts::PI;
use stm32g4xx_hal::cordic::{
    op::SinCos as SinCosOp, prec::P24, types::I1F31, types::Q31, Cordic, Ext as _,
};
use stm32g4xx_hal::pac::CORDIC;
use stm32g4xx_hal::rcc::Rcc;

/// CORDIC-backed [`SinCos`].
pub struct CordicSinCos {
    cordic: Cordic<Q31, Q31, P24, SinCosOp>,
}

const Q31_PER_RAD: f32 = 2_147_483_648.0 / PI;
const RAD_PER_Q31: f32 = 1.0 / 2_147_483_648.0;

impl CordicSinCos {
    /// Enables and configures the CORDIC for sin/cos.
    pub fn new(cordic: CORDIC, rcc: &mut Rcc) -> Self {
        Self {
            cordic: cordic.constrain(rcc).freeze(),
        }
    }
}

impl SinCos for CordicSinCos {
    #[inline(always)]
    fn sin_cos(&mut self, theta: f32) -> SinCosValue {
        // the library passes angles in [-pi, pi); anything else is wrapped first
        let t = if theta.abs() <= PI {
            theta
        } else {
            wrap_angle(theta)
        };
        // theta/pi in q1.31; `as` saturates (+pi -> i32::MAX) and maps NaN to 0
        let arg = (t * Q31_PER_RAD) as i32;
        self.cordic.start(I1F31::from_bits(arg));
        let (s, c) = self.cordic.result();
        SinCosValue {
            sin: s.to_bits() as f32 * RAD_PER_Q31,
            cos: c.to_bits() as f32 * RAD_PER_Q31,
        }
    }
}
