//! ADC counts to SI units (the one place where raw numbers become amperes and volts),
//! start-up offset calibration, and duty to timer compare counts.
//!
//! Everything called from the control interrupt ([`Converter::convert`],
//! [`duty_to_compare`]) is branch-light f32 code that cannot panic.

use crate::board::{PowerStage, OFFSET_TOLERANCE_COUNTS};
use acim::DriveInputs;

/// One period's raw injected conversions (12-bit right-aligned counts).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct RawSample {
    /// Phase U, V, W current amplifier outputs (W unused with two shunts).
    pub currents: [u16; 3],
    /// DC-bus divider output.
    pub dc_bus: u16,
}

/// A converted sample.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Converted {
    /// Phase currents (A) and DC bus (V) for [`acim::Drive::step`].
    pub inputs: DriveInputs,
    /// A current channel sat at an ADC rail: the true current may be beyond the
    /// measurable range, so the caller trips the drive (over-current).
    pub saturated: bool,
}

/// Count-to-unit conversion with calibrated offsets.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Converter {
    amps_per_count: f32,
    volts_per_count: f32,
    offsets: [f32; 3],
    max_count: u16,
    channels: usize,
}

impl Converter {
    /// Nominal conversion for `stage` (offsets at the nominal amplifier bias).
    pub fn new(stage: &PowerStage) -> Self {
        let b = stage.bias_counts();
        Self {
            amps_per_count: stage.amps_per_count(),
            volts_per_count: stage.volts_per_count(),
            offsets: [b; 3],
            max_count: (stage.adc_counts.saturating_sub(1)).min(u16::MAX as u32) as u16,
            channels: if stage.shunts >= 3 { 3 } else { 2 },
        }
    }

    /// The same conversion with calibrated zero-current offsets (counts).
    pub fn with_offsets(mut self, offsets: [f32; 3]) -> Self {
        self.offsets = offsets;
        self
    }

    /// Zero-current offsets in use, counts.
    pub fn offsets(&self) -> [f32; 3] {
        self.offsets
    }

    /// Raw counts to amperes and volts. Never panics; an unused third channel reads 0 A.
    // always inlined: the control interrupt is its caller (out of line, the call and the
    // result's copy through memory cost more than its arithmetic)
    #[inline(always)]
    pub fn convert(&self, raw: &RawSample) -> Converted {
        let k = self.amps_per_count;
        let [ra, rb, rc] = raw.currents;
        let a = (ra as f32 - self.offsets[0]) * k;
        let b = (rb as f32 - self.offsets[1]) * k;
        let three = self.channels == 3;
        let c = if three {
            (rc as f32 - self.offsets[2]) * k
        } else {
            0.0
        };
        // x == 0 or x >= max_count in one unsigned comparison (0 wraps to the top);
        // bitwise, not short-circuit: no branches
        let span = self.max_count.saturating_sub(1);
        let rail = |x: u16| x.wrapping_sub(1) >= span;
        let saturated = rail(ra) | rail(rb) | (three & rail(rc));
        Converted {
            inputs: DriveInputs {
                phase_currents: [a, b, c],
                dc_bus: raw.dc_bus as f32 * self.volts_per_count,
            },
            saturated,
        }
    }

    /// Inverse of the current conversion for channel `ch` (0..3): the count a current of
    /// `amps` produces, rounded and clamped to the ADC range (used by the self-test's
    /// simulated ADC and by tests).
    pub fn amps_to_counts(&self, ch: usize, amps: f32) -> u16 {
        let off = match self.offsets.get(ch) {
            Some(o) => *o,
            None => return 0,
        };
        self.clamp_count(off + amps / self.amps_per_count)
    }

    /// Inverse of the bus conversion: the count a bus voltage of `volts` produces.
    pub fn volts_to_counts(&self, volts: f32) -> u16 {
        self.clamp_count(volts / self.volts_per_count)
    }

    fn clamp_count(&self, x: f32) -> u16 {
        // `as` saturates and maps NaN to 0; round half up
        let c = (x + 0.5) as i32;
        c.max(0).min(self.max_count as i32) as u16
    }
}

/// Why the offset calibration was rejected.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum OffsetError {
    /// A channel's mean is further than [`OFFSET_TOLERANCE_COUNTS`] from the nominal bias
    /// (amplifier unpowered, wrong wiring, or current flowing while it should not).
    OutOfTolerance {
        /// Channel index (0 = U).
        channel: u8,
        /// Measured mean, counts.
        mean: u16,
    },
    /// No samples were taken.
    NoSamples,
}

/// Averages the current channels while the switches are off.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct OffsetCalibrator {
    sums: [u32; 3],
    count: u32,
}

impl OffsetCalibrator {
    /// An empty accumulator.
    pub const fn new() -> Self {
        Self {
            sums: [0; 3],
            count: 0,
        }
    }

    /// Adds one sample (saturating: cannot overflow or panic).
    pub fn push(&mut self, raw: &RawSample) {
        for (s, r) in self.sums.iter_mut().zip(raw.currents) {
            *s = s.saturating_add(r as u32);
        }
        self.count = self.count.saturating_add(1);
    }

    /// Samples accumulated so far.
    pub fn count(&self) -> u32 {
        self.count
    }

    /// The mean offsets (counts), checked against the stage's nominal bias on its used
    /// channels; unused channels get the nominal bias.
    pub fn finish(&self, stage: &PowerStage) -> Result<[f32; 3], OffsetError> {
        if self.count == 0 {
            return Err(OffsetError::NoSamples);
        }
        let nominal = stage.bias_counts();
        let used = if stage.shunts >= 3 { 3 } else { 2 };
        let mut out = [nominal; 3];
        for (i, (o, s)) in out.iter_mut().zip(self.sums).enumerate().take(used) {
            let mean = s as f32 / self.count as f32;
            if (mean - nominal).abs() > OFFSET_TOLERANCE_COUNTS {
                return Err(OffsetError::OutOfTolerance {
                    channel: i as u8,
                    mean: (mean + 0.5) as u16,
                });
            }
            *o = mean;
        }
        Ok(out)
    }
}

/// High-side duty in [0, 1] to the TIM1 compare value for centre-aligned PWM mode 1
/// (high side on while CNT < CCR): CCR = duty * ARR rounded, duty clamped to
/// [0, `max_duty`] (the low side must stay on long enough to sample the shunt),
/// NaN -> 50 %.
#[inline]
pub fn duty_to_compare(duty: f32, arr: u16, max_duty: f32) -> u16 {
    // clamped on the count, not on the duty: the conversion to an unsigned integer
    // saturates (a negative or -inf duty gives 0; one instruction on the FPU), and the
    // count is monotonic in the duty, so min(count, count at max_duty) is the count of
    // the clamped duty. Comparisons and `min` on integers: no f32 clamp (it asserts
    // min <= max: a panic path) and no fmaxf/fminf calls. With the board's constants
    // the largest count folds at compile time (and is never above ARR, whatever
    // `max_duty`: the cast below cannot wrap).
    let scale = arr as f32;
    let largest = ((max_duty * scale + 0.5) as u32).min(arr as u32);
    let x = duty * scale + 0.5;
    #[allow(clippy::eq_op)] // the NaN test
    let count = if x == x {
        (x as u32).min(largest)
    } else {
        (arr as u32).div_ceil(2)
    };
    // count <= largest <= arr: fits u16
    count as u16
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::board::{MAX_DUTY, POWER_STAGE, PWM_ARR};

    fn conv() -> Converter {
        Converter::new(&POWER_STAGE)
    }

    #[test]
    fn zero_current_at_bias() {
        let c = conv();
        let out = c.convert(&RawSample {
            currents: [2048, 2048, 2048],
            dc_bus: 0,
        });
        assert_eq!(out.inputs.phase_currents, [0.0, 0.0, 0.0]);
        assert!(!out.saturated);
    }

    #[test]
    fn gain_and_sign() {
        let c = conv();
        // 100 counts below bias: +100 * 3.3/4096/0.165 = +0.4883 A (low-side shunt, sign -1)
        let out = c.convert(&RawSample {
            currents: [1948, 2148, 2048],
            dc_bus: 2750,
        });
        let [a, b, cc] = out.inputs.phase_currents;
        assert!((a - 0.488_281).abs() < 1e-4, "{a}");
        assert!((b + 0.488_281).abs() < 1e-4, "{b}");
        assert_eq!(cc, 0.0);
        // 2750 counts = 2.2156 V at the ADC -> * 146.59 = 324.8 V
        assert!(
            (out.inputs.dc_bus - 324.77).abs() < 0.05,
            "{}",
            out.inputs.dc_bus
        );
    }

    #[test]
    fn calibrated_offsets_are_subtracted() {
        let c = conv().with_offsets([2000.0, 2100.0, 2048.0]);
        let out = c.convert(&RawSample {
            currents: [2000, 2100, 2048],
            dc_bus: 0,
        });
        assert_eq!(out.inputs.phase_currents, [0.0, 0.0, 0.0]);
    }

    #[test]
    fn rails_flag_saturation() {
        let c = conv();
        for raw in [[0, 2048, 2048], [2048, 4095, 2048], [2048, 2048, 0]] {
            let out = c.convert(&RawSample {
                currents: raw,
                dc_bus: 100,
            });
            assert!(out.saturated, "{raw:?}");
        }
    }

    #[test]
    fn round_trip_counts() {
        let c = conv().with_offsets([2040.0, 2050.0, 2047.0]);
        for amps in [-9.0f32, -1.0, 0.0, 0.3, 4.67, 9.5] {
            for ch in 0..3 {
                let n = c.amps_to_counts(ch, amps);
                let mut raw = RawSample {
                    currents: [2048; 3],
                    dc_bus: 0,
                };
                raw.currents[ch] = n;
                let back = c.convert(&raw).inputs.phase_currents[ch];
                assert!((back - amps).abs() <= 0.5 * c.amps_per_count.abs() + 1e-5);
            }
        }
        let v = c.volts_to_counts(325.0);
        let back = c
            .convert(&RawSample {
                currents: [2048; 3],
                dc_bus: v,
            })
            .inputs
            .dc_bus;
        assert!((back - 325.0).abs() < 0.1);
        // beyond the range: clamped, never wraps
        assert_eq!(c.amps_to_counts(0, 1e9), 0);
        assert_eq!(c.amps_to_counts(0, -1e9), 4095);
        assert_eq!(c.amps_to_counts(0, f32::NAN), 0);
        assert_eq!(c.amps_to_counts(7, 1.0), 0);
        assert_eq!(c.volts_to_counts(1e6), 4095);
    }

    #[test]
    fn offset_calibration() {
        let mut cal = OffsetCalibrator::new();
        assert_eq!(cal.finish(&POWER_STAGE), Err(OffsetError::NoSamples));
        for i in 0..1024u32 {
            cal.push(&RawSample {
                currents: [2030 + (i % 3) as u16, 2060, 2048],
                dc_bus: 0,
            });
        }
        let off = cal.finish(&POWER_STAGE).unwrap();
        assert!((off[0] - 2031.0).abs() < 0.01);
        assert_eq!(off[1], 2060.0);

        let mut bad = OffsetCalibrator::new();
        bad.push(&RawSample {
            currents: [2048, 2048, 3000],
            dc_bus: 0,
        });
        assert_eq!(
            bad.finish(&POWER_STAGE),
            Err(OffsetError::OutOfTolerance {
                channel: 2,
                mean: 3000
            })
        );
    }

    #[test]
    fn duty_compare() {
        assert_eq!(duty_to_compare(0.5, PWM_ARR, MAX_DUTY), 8500);
        assert_eq!(duty_to_compare(0.0, PWM_ARR, MAX_DUTY), 0);
        assert_eq!(duty_to_compare(-3.0, PWM_ARR, MAX_DUTY), 0);
        assert_eq!(duty_to_compare(f32::NAN, PWM_ARR, MAX_DUTY), 8500);
        let max = duty_to_compare(1.0, PWM_ARR, MAX_DUTY);
        assert_eq!(max, duty_to_compare(f32::INFINITY, PWM_ARR, MAX_DUTY));
        // MAX_DUTY 0.972 of ARR 17 000 (board::LOW_SIDE_HALF_WINDOW_NS)
        assert_eq!(max, (MAX_DUTY * PWM_ARR as f32 + 0.5) as u16);
        assert!((16_400..16_600).contains(&max), "{max}");
        assert_eq!(duty_to_compare(-f32::INFINITY, PWM_ARR, MAX_DUTY), 0);
    }

    /// The count clamped equals the clamped duty's count, rounded: every duty of a fine
    /// grid over [-0.1, 1.1], each duty next to the largest, at three periods; a
    /// largest duty above 1 (not a board's) still gives at most ARR.
    #[test]
    fn clamping_the_count_is_clamping_the_duty() {
        let clamped_duty = |duty: f32, arr: u16, max_duty: f32| -> u16 {
            let d = if duty > max_duty {
                max_duty
            } else {
                duty.max(0.0)
            };
            (d * arr as f32 + 0.5) as u16
        };
        for arr in [PWM_ARR, 4250, 999] {
            let check = |duty: f32| {
                assert_eq!(
                    duty_to_compare(duty, arr, MAX_DUTY),
                    clamped_duty(duty, arr, MAX_DUTY),
                    "{arr} {duty}"
                );
            };
            (-1000..=11_000).for_each(|k| check(k as f32 * 1e-4));
            let below = MAX_DUTY.to_bits() - 8;
            (below..below + 16).for_each(|bits| check(f32::from_bits(bits)));
            assert_eq!(duty_to_compare(3.0, arr, 4.0), arr, "{arr}");
        }
    }

    /// A count at either rail (0, or the top count and above) is saturated; every count
    /// between is not; the third channel counts only with three shunts.
    #[test]
    fn rails_are_the_ends_of_the_range() {
        let c = conv();
        let top = c.max_count;
        for (x, rail) in [
            (0, true),
            (1, false),
            (2048, false),
            (top - 1, false),
            (top, true),
            (u16::MAX, true),
        ] {
            let raw = RawSample {
                currents: [x, 2048, 2048],
                dc_bus: 1000,
            };
            assert_eq!(c.convert(&raw).saturated, rail, "{x}");
            let raw = RawSample {
                currents: [2048, x, 2048],
                dc_bus: 1000,
            };
            assert_eq!(c.convert(&raw).saturated, rail, "{x}");
            let raw = RawSample {
                currents: [2048, 2048, x],
                dc_bus: 1000,
            };
            assert_eq!(c.convert(&raw).saturated, rail && c.channels == 3, "{x}");
        }
    }
}
