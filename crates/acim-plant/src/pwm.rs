//! The PWM timing model: what a centre-aligned timer with preloaded compare registers
//! applies to the motor, once per control period.
//!
//! The controller samples at the period boundary k and computes its command; the timer
//! loads it at the next update event, so it acts over the period *after* the present one
//! (k+1 .. k+2) while the present period (k .. k+1) runs the command written one step
//! earlier. Switching off is not delayed: clearing the main output enable (MOE on TIM1)
//! acts at once. This is the convention the drive compensates for (see `acim::drive`,
//! "Timing convention"), and the one model that the simulator, the tests, the cycle bench
//! and the firmware's self-test share.

use acim::PwmOutput;

/// One-period preload of the PWM command (see the module doc).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PwmPreload {
    /// The command loaded at the last update event: it acts over the coming period.
    preloaded: PwmOutput,
}

impl PwmPreload {
    /// Outputs off, nothing preloaded.
    pub const fn new() -> Self {
        Self {
            preloaded: PwmOutput::OFF,
        }
    }

    /// Takes the command computed at this sampling instant and returns the command the
    /// inverter applies over the present period: the previous command if `command` keeps
    /// the outputs on, all switches off at once if it does not. `command` is preloaded for
    /// the period after.
    pub fn advance(&mut self, command: PwmOutput) -> PwmOutput {
        let applied = if command.enabled {
            self.preloaded
        } else {
            PwmOutput::OFF
        };
        self.preloaded = command;
        applied
    }

    /// Drops the preloaded command (what clearing MOE does to the next period).
    pub fn switch_off(&mut self) {
        self.preloaded = PwmOutput::OFF;
    }

    /// The command that will act over the next period.
    pub fn preloaded(&self) -> PwmOutput {
        self.preloaded
    }
}

impl Default for PwmPreload {
    fn default() -> Self {
        Self::new()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn on(d: f32) -> PwmOutput {
        PwmOutput {
            duties: [d; 3],
            enabled: true,
        }
    }

    #[test]
    fn a_command_acts_one_period_later() {
        let mut p = PwmPreload::new();
        assert_eq!(p.advance(on(0.1)), PwmOutput::OFF);
        assert_eq!(p.advance(on(0.2)), on(0.1));
        assert_eq!(p.advance(on(0.3)), on(0.2));
        assert_eq!(p.preloaded(), on(0.3));
    }

    #[test]
    fn switching_off_acts_at_once_and_is_not_undone() {
        let mut p = PwmPreload::new();
        p.advance(on(0.1));
        p.advance(on(0.2));
        assert_eq!(p.advance(PwmOutput::OFF), PwmOutput::OFF);
        // the next enabled command starts from the off state, not from a stale duty
        assert_eq!(p.advance(on(0.4)), PwmOutput::OFF);
        assert_eq!(p.advance(on(0.5)), on(0.4));
        p.switch_off();
        assert_eq!(p.advance(on(0.6)), PwmOutput::OFF);
    }
}
