//! The hardware over-current trip: the level at which a comparator on the true phase
//! currents (the current-sense amplifier outputs, not the ADC samples) opens all six
//! switches by itself, without the control step.
//!
//! The software trip ([`crate::DriveConfig::overcurrent_trip`], checked on the samples
//! every period) cannot see a current its sensors do not report: a dead or stuck current
//! channel lets the true current run away between samples the drive believes. A
//! comparator on each current-sense amplifier output, wired into the timer's break input,
//! switches the bridge off within its propagation delay and filter (a few microseconds)
//! whatever the software believes (ST AN5306 "Operational amplifier (OPAMP) usage in
//! STM32G4 Series" and AN4277 "Using STM32 device PWM shut-down features for motor
//! control and digital power conversion": comparator + DAC threshold into TIM1's break
//! input, MOE cleared in hardware).
//!
//! Its level sits a margin [`HARDWARE_TRIP_MARGIN`] above the software trip, so that with
//! working sensors the software trip acts first (and reports its own reason) and the
//! comparator only fires when the samples do not show the current.

use crate::design::DriveConfig;

/// The hardware trip level over the software trip level (a ratio, 1.1 = 10 % above).
///
/// The margin covers what separates the two measurements with healthy sensors: the
/// current channels' gain tolerance (a few percent: shunt 1 %, amplifier gain 1-2 %), the
/// comparator's input offset and the DAC's error (a few millivolts against the amplifier's
/// 1-2 V span at the trip) and the current ripple between two samples, which the samples
/// taken at the PWM centre do not see. Above it, a current the samples miss is cut within
/// the comparator's delay.
pub const HARDWARE_TRIP_MARGIN: f32 = 1.1;

/// The comparator's delay from the current crossing its level to the gates off, s:
/// comparator propagation (tens of ns on the STM32G4's comparators), the break input's
/// digital filter and blanking (the default used here allows about 1 us for the filter,
/// to ride through the switching spikes), and the gate drivers' turn-off (about 0.5 us).
pub const HARDWARE_TRIP_DELAY: f32 = 1.5e-6;

/// The hardware trip level of a drive configuration, A (phase peak):
/// [`HARDWARE_TRIP_MARGIN`] times its software trip
/// ([`DriveConfig::overcurrent_trip`]).
pub fn hardware_trip_level(cfg: &DriveConfig) -> f32 {
    HARDWARE_TRIP_MARGIN * cfg.overcurrent_trip
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Above the software trip, so working sensors trip in software first.
    #[test]
    fn the_hardware_level_is_above_the_software_trip() {
        let cfg = DriveConfig::paper_defaults();
        let hw = hardware_trip_level(&cfg);
        assert!(hw > cfg.overcurrent_trip);
        assert!((hw - 8.8).abs() < 1e-4, "{hw}");
    }
}
