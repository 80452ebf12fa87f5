//! The hardware over-current trip: the level at which a comparator on the true phase
//! currents (the current-sense amplifier outputs, not the ADC samples) opens all six
//! switches by itself, without the control step.
//!
//! The software trip ([`LimitSettings::overcurrent_trip`](crate::LimitSettings::overcurrent_trip), checked on the samples
//! every period) cannot see a current its sensors do not report: a dead or stuck current
//! channel lets the true current run away between samples the drive believes. A
//! comparator on each current-sense amplifier output, wired into the timer's break input,
//! switches the bridge off within its propagation delay and filter (a few microseconds)
//! whatever the software believes (ST AN4232 "Getting started with analog comparators for
//! STM32F3 Series and STM32G4 Series devices", its over-current case, and AN4277 "Using
//! STM32 device PWM shut-down features for motor control and digital power conversion":
//! comparator + DAC threshold into the timer's break input, MOE cleared in hardware).
//!
//! Its level is the software trip's own ([`HARDWARE_TRIP_RATIO`] = 1): the two watch the
//! same limit, the software on the samples once per period (and reports which check
//! fired), the comparator continuously on the amplifier outputs. A level above the
//! software trip would leave a band of current the samples may never report: a stuck
//! channel can hold the true current inside it for as long as the drive runs, so the
//! phase current would stay above the drive's trip while switching (measured with a level
//! 1.1 times the trip: the simulator's dead-sensing built-in, every channel at 0 A at
//! 500 rpm, stayed above the 8 A trip for 0.63 ms while switching, three periods).

use crate::config::DriveConfig;

/// The hardware trip level over the software trip level (a ratio; 1: the same level).
///
/// Not above 1, for the reason in the module documentation. What separates the two
/// measurements with healthy sensors (the channels' gain tolerance, a few percent; the
/// comparator's offset and the DAC's error, a few millivolts against the amplifier's 1-2 V
/// span at the trip; the current ripple between samples, which the samples at the PWM
/// centre do not see) then decides which of the two fires first at a real over-current:
/// the switches open either way.
pub const HARDWARE_TRIP_RATIO: f32 = 1.0;

/// The comparator's delay from the current crossing its level to the gates off, s:
/// comparator propagation (tens of ns on the STM32G4's comparators), the break input's
/// digital filter and blanking (the default used here allows about 1 us for the filter,
/// to ride through the switching spikes), and the gate drivers' turn-off (about 0.5 us).
pub const HARDWARE_TRIP_DELAY: f32 = 1.5e-6;

/// The hardware trip level of a drive configuration, A (phase peak):
/// [`HARDWARE_TRIP_RATIO`] times its software trip
/// ([`LimitSettings::overcurrent_trip`](crate::LimitSettings::overcurrent_trip)).
pub fn hardware_trip_level(cfg: &DriveConfig) -> f32 {
    HARDWARE_TRIP_RATIO * cfg.limits.overcurrent_trip
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Not above the software trip (no band the samples could hide), and from the
    /// configuration: the paper defaults' 8 A.
    #[test]
    fn the_hardware_level_is_the_software_trip() {
        let cfg = DriveConfig::paper_defaults();
        let hw = hardware_trip_level(&cfg);
        assert!(hw <= cfg.limits.overcurrent_trip);
        assert!((hw - 8.0).abs() < 1e-4, "{hw}");
    }
}
