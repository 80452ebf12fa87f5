//! The inverter's hardware over-current comparator: a comparator on each true phase
//! current (the current-sense amplifier output, before any ADC) that clears the gate
//! enable (TIM1's main output enable, MOE) through the timer's break input, so all six
//! switches open and the currents decay through the diodes into the bus.
//!
//! # Timing and how the plant resolves it
//!
//! The comparator fires when any |i_x| exceeds its level; the switches open
//! [`ComparatorConfig::delay`] later (comparator propagation, the break input's filter and
//! blanking, the gate drivers' turn-off: [`acim::hardware_trip::HARDWARE_TRIP_DELAY`],
//! 1.5 us, by default). The plant checks the phase currents at the end of every
//! integration sub-step (at most `T_pwm / substeps` long: 40 us with the simulator's 5
//! sub-steps at 5 kHz, shorter in the switching-level model). When a sub-step ends above
//! the level, the crossing instant is placed by linear interpolation of max |i_x| over the
//! sub-step, the sub-step is integrated again from its start up to the crossing plus the
//! delay, and the rest of the period runs with all gates off. A switch-off that falls
//! after the sub-step's end (a crossing in its last `delay`) is reached by one more short
//! step with the same terminal source (in the switching-level model a switching edge
//! inside those `delay` seconds is then missed), and one that falls after the period's
//! end is taken at the period's end (the latch keeps the gates off from there): either
//! way the switch-off lands at the crossing plus the delay to within the interpolation's
//! error (second order in the sub-step), or at most `delay` early at a period's end.
//!
//! # Latching
//!
//! Once fired, the comparator keeps the gates off (the break clears MOE; software must set
//! it again) until [`super::Plant::reset_comparator`], which the owner calls when the drive
//! resets its fault. It is only evaluated while the gates are on: with them off there is
//! nothing to open.

/// Level and delay of the comparator.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ComparatorConfig {
    /// Trip level on |i_x|, any phase, A (e.g.
    /// [`acim::hardware_trip::hardware_trip_level`] of the drive's configuration).
    pub level: f32,
    /// From the crossing to the gates off, s.
    pub delay: f32,
}

impl ComparatorConfig {
    /// A comparator at `level` A with the default delay
    /// ([`acim::hardware_trip::HARDWARE_TRIP_DELAY`]).
    pub fn at(level: f32) -> Self {
        Self {
            level,
            delay: acim::hardware_trip::HARDWARE_TRIP_DELAY,
        }
    }
}

/// When and at what current the comparator fired.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ComparatorTrip {
    /// The plant period it fired in (the value of [`super::Plant::periods`] before that
    /// period ran).
    pub period: u64,
    /// Crossing of the level, s from that period's start.
    pub crossing_s: f32,
    /// Gates off, s from that period's start.
    pub off_s: f32,
    /// The largest |i_x| when the gates went off, A.
    pub current_a: f32,
}

/// The comparator's state: its configuration (`None`: not fitted) and its latch.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub(crate) struct Comparator {
    pub(crate) cfg: Option<ComparatorConfig>,
    pub(crate) trip: Option<ComparatorTrip>,
}

/// Largest |i_x|, A.
pub(crate) fn max_abs(i: [f32; 3]) -> f32 {
    i.iter()
        .fold(0.0f32, |m, x| if x.abs() > m { x.abs() } else { m })
}

/// Fraction (0..=1) of a sub-step at which a quantity going linearly from `a` to `b`
/// crosses `level` upwards (0 when it starts at or above it).
pub(crate) fn crossing_fraction(a: f32, b: f32, level: f32) -> f32 {
    if a >= level || b <= a {
        0.0
    } else {
        let f = (level - a) / (b - a);
        if f > 1.0 {
            1.0
        } else if f > 0.0 {
            f
        } else {
            0.0
        }
    }
}

/// Time (s) of a sub-step of length `h` during which a quantity going linearly from `a` to
/// `b` is above `level`.
pub(crate) fn time_above(a: f32, b: f32, level: f32, h: f32) -> f32 {
    match (a > level, b > level) {
        (true, true) => h,
        (false, false) => 0.0,
        // b > level >= a: b > a, the denominator is positive
        (false, true) => h * (b - level) / (b - a),
        // a > level >= b
        (true, false) => h * (a - level) / (a - b),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crossing_and_time_above_interpolate_linearly() {
        assert_eq!(crossing_fraction(0.0, 10.0, 5.0), 0.5);
        assert_eq!(crossing_fraction(6.0, 10.0, 5.0), 0.0);
        assert_eq!(crossing_fraction(4.0, 4.0, 5.0), 0.0);
        assert!((time_above(0.0, 10.0, 5.0, 2.0) - 1.0).abs() < 1e-6);
        assert!((time_above(10.0, 0.0, 2.5, 2.0) - 1.5).abs() < 1e-6);
        assert_eq!(time_above(6.0, 7.0, 5.0, 2.0), 2.0);
        assert_eq!(time_above(1.0, 2.0, 5.0, 2.0), 0.0);
        assert_eq!(max_abs([1.0, -3.0, 2.0]), 3.0);
    }
}
