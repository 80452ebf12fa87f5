//! Current and DC-bus voltage sensors: gain error, offset, Gaussian-like noise from a seeded
//! PRNG, ADC quantisation and saturation at the ADC rails.
//!
//! Signal chain per channel: `x_meas = (1 + gain_error) x + offset + noise_std * n`,
//! with `n` approximately standard normal, then the ADC: saturation to its range and
//! quantisation to integer counts (round to nearest), converted back to A or V.
//!
//! Timing: the plant integrates a whole PWM period, then the simulator calls
//! [`super::Plant::sample`]; the sample instant is therefore the period boundary, which in
//! the centre-aligned pattern of [`super::inverter`] is the centre of the zero vector
//! (carrier trough), where the ripple of a centre-aligned PWM current crosses its
//! period average.

use acim::math::is_finite;

/// xorshift64* pseudo-random generator (Vigna 2016): tiny, no_std, reproducible.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Rng {
    state: u64,
}

impl Rng {
    /// A generator from `seed`; seed 0 (a fixed point of xorshift) is replaced by a
    /// constant.
    pub fn new(seed: u64) -> Self {
        let s = seed ^ 0x9E37_79B9_7F4A_7C15;
        Self {
            state: if s == 0 { 0x2545_F491_4F6C_DD1D } else { s },
        }
    }

    /// Next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        let mut x = self.state;
        x ^= x >> 12;
        x ^= x << 25;
        x ^= x >> 27;
        self.state = x;
        x.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }

    /// Uniform in [0, 1) with 24-bit resolution.
    pub fn uniform(&mut self) -> f32 {
        ((self.next_u64() >> 40) as u32) as f32 * (1.0 / 16_777_216.0)
    }

    /// Approximately standard normal: sum of 12 uniforms minus 6 (Irwin-Hall), mean 0,
    /// standard deviation exactly 1, tails truncated at +/-6.
    pub fn normal(&mut self) -> f32 {
        let mut s = 0.0f32;
        for _ in 0..12 {
            s += self.uniform();
        }
        s - 6.0
    }
}

/// An ADC channel's transfer: resolution and range.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Adc {
    /// Resolution in bits (1..=24); 0 means no quantisation and no saturation (ideal).
    pub bits: u8,
    /// Full scale: the range is [-full_scale, full_scale) when `bipolar`, else
    /// [0, full_scale).
    pub full_scale: f32,
    /// Symmetric (current) or unipolar (bus voltage) range.
    pub bipolar: bool,
}

fn round_to_i32(y: f32) -> i32 {
    let t = y + 0.5;
    let k = t as i32; // saturating, NaN -> 0
    if (k as f32) > t {
        // saturating: far below i32::MIN the cast gives MIN, and MIN - 1 would overflow
        k.saturating_sub(1)
    } else {
        k
    }
}

impl Adc {
    /// Quantisation step (LSB), in the measured unit; 0 for an ideal ADC.
    pub fn lsb(&self) -> f32 {
        if self.bits == 0 {
            return 0.0;
        }
        let counts = (1u32 << (if self.bits > 24 { 24 } else { self.bits })) as f32;
        let span = if self.bipolar {
            2.0 * self.full_scale
        } else {
            self.full_scale
        };
        span / counts
    }

    /// Converts `x` to counts (saturating at the rails) and back.
    pub fn quantize(&self, x: f32) -> f32 {
        let lsb = self.lsb();
        if lsb <= 0.0 || !is_finite(lsb) {
            return x;
        }
        // lsb > 0 implies 1 <= bits; bits above 24 act as 24 (see `lsb`)
        let bits = if self.bits > 24 { 24 } else { self.bits };
        let half = 1i32 << (bits.saturating_sub(1));
        let (lo, hi) = if self.bipolar {
            (-half, half - 1)
        } else {
            (0, 2 * half - 1)
        };
        let k = round_to_i32(x / lsb);
        let k = if k > hi {
            hi
        } else if k < lo {
            lo
        } else {
            k
        };
        k as f32 * lsb
    }
}

/// Number of measured current channels.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum CurrentChannels {
    /// Phases a and b measured; the drive computes i_c = -(i_a + i_b). The third entry of
    /// [`Measurements::phase_currents`] is then 0 (not measured).
    #[default]
    Two,
    /// All three phases measured.
    Three,
}

/// Measurements taken at the sample instant.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Measurements {
    /// Phase currents (i_a, i_b, i_c), A; i_c is 0 (not measured) with
    /// [`CurrentChannels::Two`].
    pub phase_currents: [f32; 3],
    /// DC-bus voltage, V.
    pub dc_bus: f32,
    /// Which current channels are valid.
    pub channels: CurrentChannels,
}

/// Current-sensor configuration.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct CurrentSensorConfig {
    /// ADC (bipolar, full scale in A; default 12 bits, +/-10 A).
    pub adc: Adc,
    /// Two or three channels.
    pub channels: CurrentChannels,
    /// Relative gain error per channel (0.01 = reads 1 % high).
    pub gain_error: [f32; 3],
    /// Offset per channel, A.
    pub offset: [f32; 3],
    /// Noise standard deviation, A (before quantisation).
    pub noise_std: f32,
}

/// Default current full scale, A.
pub const DEFAULT_CURRENT_FULL_SCALE: f32 = 10.0;

impl Default for CurrentSensorConfig {
    fn default() -> Self {
        Self {
            adc: Adc {
                bits: 12,
                full_scale: DEFAULT_CURRENT_FULL_SCALE,
                bipolar: true,
            },
            channels: CurrentChannels::Two,
            gain_error: [0.0; 3],
            offset: [0.0; 3],
            noise_std: 0.0,
        }
    }
}

/// Phase-current sensors with their ADC.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CurrentSensors {
    cfg: CurrentSensorConfig,
    rng: Rng,
}

fn finite_or(x: f32, d: f32) -> f32 {
    if is_finite(x) {
        x
    } else {
        d
    }
}

impl CurrentSensors {
    /// Sensors with configuration `cfg` and noise seed `seed`.
    pub fn new(cfg: CurrentSensorConfig, seed: u64) -> Self {
        Self {
            cfg,
            rng: Rng::new(seed),
        }
    }

    /// Ideal sensors: three channels, no quantisation, saturation, gain, offset or noise.
    pub fn ideal() -> Self {
        Self::new(
            CurrentSensorConfig {
                adc: Adc {
                    bits: 0,
                    full_scale: DEFAULT_CURRENT_FULL_SCALE,
                    bipolar: true,
                },
                channels: CurrentChannels::Three,
                ..CurrentSensorConfig::default()
            },
            1,
        )
    }

    /// The paper's bench: two channels, 8-bit ADC, +/-10 A.
    pub fn paper_bench(seed: u64) -> Self {
        let mut cfg = CurrentSensorConfig::default();
        cfg.adc.bits = 8;
        Self::new(cfg, seed)
    }

    /// STM32G4-like: 12-bit ADC, +/-10 A, `channels` channels.
    pub fn g474(channels: CurrentChannels, seed: u64) -> Self {
        Self::new(
            CurrentSensorConfig {
                channels,
                ..CurrentSensorConfig::default()
            },
            seed,
        )
    }

    /// The configuration.
    pub fn config(&self) -> &CurrentSensorConfig {
        &self.cfg
    }

    /// Measures true phase currents `i` (A). Draws noise only when `noise_std > 0`, one
    /// draw per measured channel, so a given seed gives a reproducible sequence.
    pub fn measure(&mut self, i: [f32; 3]) -> [f32; 3] {
        let n_ch = match self.cfg.channels {
            CurrentChannels::Two => 2,
            CurrentChannels::Three => 3,
        };
        let mut out = [0.0f32; 3];
        for (k, (o, ((&x, &g), &off))) in out
            .iter_mut()
            .zip(
                i.iter()
                    .zip(self.cfg.gain_error.iter())
                    .zip(self.cfg.offset.iter()),
            )
            .enumerate()
        {
            if k >= n_ch {
                break;
            }
            let noise = if self.cfg.noise_std > 0.0 {
                self.cfg.noise_std * self.rng.normal()
            } else {
                0.0
            };
            let y = (1.0 + finite_or(g, 0.0)) * finite_or(x, 0.0) + finite_or(off, 0.0) + noise;
            *o = self.cfg.adc.quantize(y);
        }
        out
    }
}

/// DC-bus voltage sensor configuration.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct BusSensorConfig {
    /// ADC (unipolar, full scale in V; default 12 bits, 0..500 V).
    pub adc: Adc,
    /// Relative gain error.
    pub gain_error: f32,
    /// Offset, V.
    pub offset: f32,
    /// Noise standard deviation, V.
    pub noise_std: f32,
}

/// Default DC-bus sensor full scale, V.
pub const DEFAULT_BUS_FULL_SCALE: f32 = 500.0;

impl Default for BusSensorConfig {
    fn default() -> Self {
        Self {
            adc: Adc {
                bits: 12,
                full_scale: DEFAULT_BUS_FULL_SCALE,
                bipolar: false,
            },
            gain_error: 0.0,
            offset: 0.0,
            noise_std: 0.0,
        }
    }
}

/// DC-bus voltage sensor.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BusVoltageSensor {
    cfg: BusSensorConfig,
    rng: Rng,
}

impl BusVoltageSensor {
    /// Sensor with configuration `cfg` and noise seed `seed`.
    pub fn new(cfg: BusSensorConfig, seed: u64) -> Self {
        Self {
            cfg,
            rng: Rng::new(seed),
        }
    }

    /// Ideal sensor (no quantisation, gain, offset or noise).
    pub fn ideal() -> Self {
        let mut cfg = BusSensorConfig::default();
        cfg.adc.bits = 0;
        Self::new(cfg, 2)
    }

    /// The configuration.
    pub fn config(&self) -> &BusSensorConfig {
        &self.cfg
    }

    /// Measures the true bus voltage `v` (V).
    pub fn measure(&mut self, v: f32) -> f32 {
        let noise = if self.cfg.noise_std > 0.0 {
            self.cfg.noise_std * self.rng.normal()
        } else {
            0.0
        };
        let y = (1.0 + finite_or(self.cfg.gain_error, 0.0)) * finite_or(v, 0.0)
            + finite_or(self.cfg.offset, 0.0)
            + noise;
        self.cfg.adc.quantize(y)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Far beyond the range (and beyond i32 in LSBs) the quantiser saturates to its end
    /// codes instead of overflowing (it overflowed beyond about 1e7 A).
    #[test]
    fn quantiser_saturates_at_any_input() {
        let adc = CurrentSensorConfig::default().adc;
        let top = adc.quantize(1e3);
        let bottom = adc.quantize(-1e3);
        for x in [1e7f32, 1e12, f32::MAX, f32::INFINITY] {
            assert_eq!(adc.quantize(x), top);
            assert_eq!(adc.quantize(-x), bottom);
        }
        assert!(adc.quantize(f32::NAN).is_finite());
        assert!(bottom < 0.0 && top > 0.0);
    }
}
