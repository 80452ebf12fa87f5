//! # Fixed-point control path (per unit, Q7.24 in `i32`)
//!
//! The control step for cores without an FPU (Cortex-M0+/M3; the paper's ADMC201
//! coprocessor was fixed point too) is not a second copy: every block (PI, flux model and
//! slip law, reduced-order observer, Rs estimator, SVPWM, the frame transforms) and the
//! drive's cascade itself are written once over [`crate::num::Num`] and instantiated
//! here with [`Q24`]. This module holds only what the arithmetic itself needs: the Q7.24
//! type and its saturating operations, gains and reciprocal ([`q`]), the turn-fraction
//! angle and table sin/cos ([`trig`]), the arithmetic's conversions of design values
//! ([`crate::num::Units`]; each block converts its own design with them) and the
//! fixed-point specifics of the drive (the modulator's voltage
//! limit, Q15 duties, the SI boundary: [`drive`]). The designs stay single-sourced in
//! f32. The step uses no float, no division beyond one hardware `UDIV` per reciprocal, no
//! allocation and no panicking operation.
//!
//! ## Number format: why hand-written Q7.24
//!
//! Signals are `i32` holding `value_pu * 2^24` (Q7.24: range [-128, 128) pu, resolution
//! 6.0e-8 pu). Products go through `i64` (one `SMULL` on Cortex-M3/M4), are rounded to
//! nearest and saturated ([`q::mul`]); sums use `saturating_add`/`saturating_sub`. Constant
//! factors are [`q::Gain`]s: an `i32` mantissa normalised to 30 bits with its own shift,
//! so small coefficients (Ts B/J = 4e-5) keep the same relative precision (~2e-9) as large
//! ones. Q7.24 rather than Q1.15 or Q1.31: the integrators (flux, observer, Rs, PI
//! integrals) add increments of 1e-5 to 1e-4 of their value per step, which Q1.15 would
//! round away, and Q1.31 would leave no headroom for intermediate sums and transients;
//! 24 fraction bits match the f32 mantissa near 1 pu, and 7 integer bits give 64x headroom
//! over the 2 pu the configuration may use. Hand-written rather than the `fixed` crate:
//! the operations needed are few (multiply, gain, reciprocal, table), each one's rounding
//! and saturation is explicit and reviewable here, and the core crate stays free of
//! dependencies (`fixed` would also not give per-constant binary points).
//!
//! ## Per-unit bases ([`PerUnitBases::PAPER`]) and headroom
//!
//! | quantity | base | largest value in the operating range | pu | headroom to 128 pu |
//! |---|---|---|---|---|
//! | current (phase peak, dq) | 10 A (sensor full scale) | 8 A trip; ADC clip 10 A | 0.8 / 1.0 | 128x |
//! | voltage (bus, phase peak) | 400 V | 400 V bus max; |v_dq| <= 231 V | 1.0 / 0.58 | 128x |
//! | resistance | 40 ohm (V/I) | Rs clamp 26.3 + R_R 7.8 ohm | 0.85 | 150x |
//! | mechanical speed | 2000 rpm (209.4 rad/s) | over-speed trip 2000 rpm | 1.0 | 128x |
//! | stator frequency (elec.) | 2 pi 100 rad/s | p 2000 rpm + slip at 10 % flux (467 rad/s) | 1.41 | 90x |
//! | rotor flux | 1 Wb | 1.2 x 0.781 Wb | 0.94 | 136x |
//! | torque | 10 N m | 1.5 p lambda I_max = 10.9; load estimate limit 15 N m | 1.1 / 1.5 | 85x |
//! | 1/lambda_r (slip law, observer) | 1/Wb | 1/(0.1 x 0.781) | 12.8 | 10x |
//! | duty | 1 | [0, 1] | 1 | 128x |
//!
//! [`FixedDrive::with_bases`] checks every configured limit, trip and reference against 2 pu
//! and rejects a configuration that does not fit. Products of two signals are formed only
//! for pairs whose product stays below 20 pu (e.g. i_sq x 1/lambda <= 1.2 x 12.8). Beyond
//! that, every operation saturates: a fault (a shorted phase, a bad sample) cannot wrap a
//! control quantity around to the opposite sign.
//!
//! ## Angle: the one intended wrap-around
//!
//! The frame angle is a `u32` turn fraction (2^32 = 2 pi rad electrical, 1.5e-9 rad per
//! count); the frequency times Ts is added with `wrapping_add`, which is exactly the
//! modulo-one-turn an angle needs ([`trig`]).
//!
//! ## Accuracy against f32
//!
//! Stated in [`tests`](self) (equivalence property tests over the operating envelope) and
//! in `tests/fixed_point.rs` (the closed-loop paper scenarios with
//! `drive.arithmetic = "fixed"` in the simulator).

pub mod drive;
pub mod q;
pub mod trig;

#[cfg(test)]
mod tests;

pub use drive::{FixedDrive, FixedInputs, FixedPwm, FixedTelemetry};
pub use q::{Gain, PerUnitBases, Q24};
pub use trig::TableSinCos;

/// Why a fixed-point drive configuration was rejected: the same error as the f32 drive's
/// (a value that does not fit the per-unit bases names its field).
pub type FixedConfigError = crate::design::ConfigError;
