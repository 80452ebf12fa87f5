//! The control interrupt's period sequence, written once over a [`PowerStageIo`] trait so
//! that its ordering rules are tested on the host against a model of the registers
//! (`firmware/src/hw.rs` implements the trait for TIM1 and ADC1/2).
//!
//! Rules this sequence keeps (issue 11, firmware review D1 and D3):
//! - the ADC completion flags of *both* converters are read before they are acknowledged
//!   (acknowledging first made the second flag read as "not done" and tripped every
//!   interrupt);
//! - the periodic path never sets the main output enable (MOE): it is armed once, by a
//!   start command, and only if no break flag is set. If MOE is found clear while the drive
//!   believes it is switching, the hardware break fired during or after the last check:
//!   the drive trips instead of re-arming;
//! - break flags are cleared only by an accepted fault reset.

use crate::control::{CommandReply, ControlCommand, ControlLoop, FirmwareFault};
use crate::convert::RawSample;
use acim::frames::SinCos;
use acim::PwmOutput;

/// What the period sequence needs from the power stage's registers.
pub trait PowerStageIo {
    /// End-of-sequence flags of the two converters (ADC1, ADC2), not yet acknowledged.
    fn conversions_done(&self) -> (bool, bool);
    /// The converted samples.
    fn read(&self) -> RawSample;
    /// Acknowledges both converters' end-of-sequence flags.
    fn acknowledge(&mut self);
    /// A new conversion completed since [`PowerStageIo::acknowledge`] (deadline missed).
    fn sequence_pending(&self) -> bool;
    /// Any break flag set (BIF, B2IF or SBIF): the hardware has cleared MOE.
    fn break_flag(&self) -> bool;
    /// Clears the break flags.
    fn clear_break_flags(&mut self);
    /// Whether the main output is enabled (MOE).
    fn outputs_enabled(&self) -> bool;
    /// Sets MOE (arming after a start command).
    fn enable_outputs(&mut self);
    /// Writes the compare values (preloaded: act from the next period).
    fn write_duties(&mut self, duties: [f32; 3]);
    /// Clears MOE at once and returns the compare values to 50 %.
    fn switch_off(&mut self);
}

/// Applies one command from the main loop, with the hardware side of it: an accepted
/// start arms the outputs (if no break is pending, else the drive trips), an accepted
/// reset clears the break flags (a refused one leaves them).
pub fn apply_command<S: SinCos, P: PowerStageIo>(
    ctl: &mut ControlLoop<S>,
    io: &mut P,
    cmd: ControlCommand,
) -> CommandReply {
    let reply = ctl.apply(cmd);
    if reply.result.is_ok() {
        match cmd {
            ControlCommand::ResetFault => io.clear_break_flags(),
            ControlCommand::Start
            | ControlCommand::StartOpenLoop
            | ControlCommand::Commission(_) => {
                if io.break_flag() {
                    ctl.trip(FirmwareFault::HardwareBreak);
                    io.switch_off();
                } else {
                    io.enable_outputs();
                }
            }
            ControlCommand::Stop
            | ControlCommand::SpeedRpm(_)
            | ControlCommand::PlantLoad(_)
            | ControlCommand::Rate(_) => {}
        }
    }
    reply
}

/// One control period: samples, checks, the step, the PWM write, the deadline check.
/// Returns the command written.
#[inline(always)]
pub fn control_period<S: SinCos, P: PowerStageIo>(
    ctl: &mut ControlLoop<S>,
    io: &mut P,
) -> PwmOutput {
    // read both completion flags and the samples before acknowledging
    let (adc1_done, adc2_done) = io.conversions_done();
    let raw = io.read();
    io.acknowledge();
    let switching = ctl.switching();
    let out = if io.break_flag() || (switching && !io.outputs_enabled()) {
        ctl.trip(FirmwareFault::HardwareBreak)
    } else if !(adc1_done && adc2_done) {
        ctl.trip(FirmwareFault::AdcSequence)
    } else {
        ctl.step(&raw)
    };
    write(io, &out);
    if io.sequence_pending() {
        let off = ctl.trip(FirmwareFault::DeadlineMissed);
        write(io, &off);
        return off;
    }
    out
}

#[inline(always)]
fn write<P: PowerStageIo>(io: &mut P, out: &PwmOutput) {
    if out.enabled {
        // never sets MOE: a break that cleared it since the check above stays effective
        io.write_duties(out.duties);
    } else {
        io.switch_off();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::board::POWER_STAGE;
    use crate::control::ControlLoop;
    use crate::convert::Converter;
    use acim::DriveState;

    /// A register model of TIM1 and ADC1/2 as the reference manual describes them:
    /// acknowledging clears both end flags, a break clears MOE and sets BIF, MOE can be
    /// set only while no break flag is set.
    #[derive(Default)]
    struct Regs {
        jeos: [bool; 2],
        sample: RawSample,
        bif: bool,
        moe: bool,
        ccr_writes: u32,
        moe_sets: u32,
        pending: bool,
        /// a break fires during the next `write_duties`
        break_during_write: bool,
    }

    impl PowerStageIo for Regs {
        fn conversions_done(&self) -> (bool, bool) {
            (self.jeos[0], self.jeos[1])
        }
        fn read(&self) -> RawSample {
            self.sample
        }
        fn acknowledge(&mut self) {
            self.jeos = [false, false];
        }
        fn sequence_pending(&self) -> bool {
            self.pending
        }
        fn break_flag(&self) -> bool {
            self.bif
        }
        fn clear_break_flags(&mut self) {
            self.bif = false;
        }
        fn outputs_enabled(&self) -> bool {
            self.moe
        }
        fn enable_outputs(&mut self) {
            if !self.bif {
                self.moe = true;
                self.moe_sets += 1;
            }
        }
        fn write_duties(&mut self, _d: [f32; 3]) {
            if self.break_during_write {
                self.bif = true;
                self.moe = false;
                self.break_during_write = false;
            }
            self.ccr_writes += 1;
        }
        fn switch_off(&mut self) {
            self.moe = false;
        }
    }

    fn setup() -> (ControlLoop<acim::frames::FastSinCos>, Regs) {
        let conv = Converter::new(&POWER_STAGE);
        let ctl = ControlLoop::new(crate::control::tests::powered(), conv, 500);
        let bias = POWER_STAGE.bias_counts() as u16;
        let bus = (325.0 / POWER_STAGE.volts_per_count()) as u16;
        let regs = Regs {
            sample: RawSample {
                currents: [bias; 3],
                dc_bus: bus,
            },
            ..Regs::default()
        };
        (ctl, regs)
    }

    fn conversion(r: &mut Regs) {
        r.jeos = [true, true];
    }

    /// D1: both converters finished (the normal case) must not be a sequence fault; the
    /// old order (acknowledge, then read ADC2's flag) tripped fault 19 on every interrupt.
    #[test]
    fn completed_conversions_run_the_step() {
        let (mut ctl, mut r) = setup();
        assert!(apply_command(&mut ctl, &mut r, ControlCommand::Start)
            .result
            .is_ok());
        // (a few periods: the bias-only samples of this register model carry no current,
        // which the drive's current-response check rightly faults on after some ms)
        for _ in 0..10 {
            conversion(&mut r);
            let out = control_period(&mut ctl, &mut r);
            assert!(out.enabled, "fault {}", ctl.fault_code());
        }
        assert_eq!(ctl.state(), DriveState::Magnetizing);
        // a missing ADC2 sequence is still a fault
        r.jeos = [true, false];
        assert!(!control_period(&mut ctl, &mut r).enabled);
        assert_eq!(ctl.fault_code(), 19);
    }

    /// D3: MOE is set once, by the start command; a break during the step's PWM write
    /// leaves it clear, the next period trips, and only an accepted reset clears BIF.
    #[test]
    fn a_break_during_the_step_is_not_undone() {
        let (mut ctl, mut r) = setup();
        apply_command(&mut ctl, &mut r, ControlCommand::Start);
        assert!(r.moe);
        for _ in 0..10 {
            conversion(&mut r);
            control_period(&mut ctl, &mut r);
        }
        assert_eq!(r.moe_sets, 1, "the periodic path never sets MOE");
        r.break_during_write = true;
        conversion(&mut r);
        control_period(&mut ctl, &mut r);
        assert!(!r.moe, "the break cleared MOE and nothing re-armed it");
        conversion(&mut r);
        let out = control_period(&mut ctl, &mut r);
        assert!(!out.enabled && !r.moe);
        assert_eq!(ctl.fault_code(), 16);
        // a start while faulted is refused and does not touch MOE or the flags
        assert!(apply_command(&mut ctl, &mut r, ControlCommand::Start)
            .result
            .is_err());
        assert!(r.bif && !r.moe);
        // stop is accepted (faulted drives stay faulted) and does not clear the flag
        let _ = apply_command(&mut ctl, &mut r, ControlCommand::Stop);
        assert!(r.bif);
        // an accepted reset clears BIF; a new start arms again
        assert!(apply_command(&mut ctl, &mut r, ControlCommand::ResetFault)
            .result
            .is_ok());
        assert!(!r.bif);
        // a start before the rotor flux has decayed (5 tau_r) is refused, MOE stays clear
        assert!(apply_command(&mut ctl, &mut r, ControlCommand::Start)
            .result
            .is_err());
        assert!(!r.moe);
        let cfg = ctl.drive().config();
        let wait = (5.0 * cfg.machine.rotor_time_constant() / cfg.control_period) as u32;
        for _ in 0..wait {
            conversion(&mut r);
            control_period(&mut ctl, &mut r);
        }
        assert!(apply_command(&mut ctl, &mut r, ControlCommand::Start)
            .result
            .is_ok());
        assert!(r.moe);
    }

    /// A refused reset (drive not faulted) leaves the break flags alone.
    #[test]
    fn a_refused_reset_keeps_the_break_flags() {
        let (mut ctl, mut r) = setup();
        r.bif = true;
        assert!(apply_command(&mut ctl, &mut r, ControlCommand::ResetFault)
            .result
            .is_err());
        assert!(r.bif);
        // and a start with a pending break trips instead of arming
        assert!(apply_command(&mut ctl, &mut r, ControlCommand::Start)
            .result
            .is_ok());
        assert!(!r.moe);
        assert_eq!(ctl.state(), DriveState::Fault);
    }

    /// A missed deadline switches off in the same period.
    #[test]
    fn a_missed_deadline_switches_off() {
        let (mut ctl, mut r) = setup();
        apply_command(&mut ctl, &mut r, ControlCommand::Start);
        conversion(&mut r);
        r.pending = true;
        let out = control_period(&mut ctl, &mut r);
        assert!(!out.enabled && !r.moe);
        assert_eq!(ctl.fault_code(), 17);
    }
}
