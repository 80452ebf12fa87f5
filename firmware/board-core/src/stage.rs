//! The control interrupt's period sequence, written once over a [`PowerStageIo`] trait so
//! that its ordering rules are tested on the host against a model of the registers
//! (`firmware/src/hw.rs` implements the trait for TIM1 and ADC1/2).
//!
//! Rules this sequence keeps (firmware reviews D1, D3 and N1):
//! - the ADC completion flags of *both* converters are read before they are acknowledged
//!   (acknowledging first made the second flag read as "not done" and tripped every
//!   interrupt);
//! - the main output enable (MOE) is set only on a deliberate off-to-on transition: the
//!   period's output turns on after a period with the outputs off, while the [`Outputs`]
//!   latch is armed (by an accepted start, V/f start or commissioning; disarmed by a stop,
//!   a fault, a break, the end of a commissioning), and only if no break flag is set
//!   (re-read just before the write). A start that switches off and on again inside it
//!   (the commissioning's offset stage, a start waiting for the offset measurement)
//!   switches on again; a break never re-arms: it trips;
//! - if MOE is found clear after a period that switched on, the hardware break fired
//!   during or after the last check: the drive trips (fault 16) instead of re-arming;
//! - break flags are cleared only by an accepted fault reset.
//!
//! With a slow task ([`acim::LoopSettings::slow_period`]) the period runs the drive's
//! fast part only ([`ControlLoop::step_fast`]); a slow tick's work waits, and the period
//! requests the slow task's interrupt ([`PowerStageIo::pend_slow_task`]), of lower
//! priority, which runs it ([`slow_period`]) once the control interrupt has written the
//! PWM and returned. The two share the drive through a [`SlowTaskGate`]: the slow task
//! must finish before the next control period; if it has not, that period switches the
//! outputs off without touching the drive, and the one after trips it
//! ([`FirmwareFault::DeadlineMissed`]).

use crate::control::{CommandReply, ControlCommand, ControlLoop, FirmwareFault};
use crate::convert::RawSample;
use acim::frames::SinCos;
use acim::PwmOutput;
use core::sync::atomic::{compiler_fence, AtomicBool, Ordering};

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
    /// Sets MOE unless a break flag is set (read again right before the write): the
    /// off-to-on transition of an armed start.
    fn enable_outputs(&mut self);
    /// Writes the compare values (preloaded: act from the next period).
    fn write_duties(&mut self, duties: [f32; 3]);
    /// Clears MOE at once and returns the compare values to 50 %.
    fn switch_off(&mut self);
    /// Requests the slow task's interrupt (lower priority than the control interrupt):
    /// it runs [`slow_period`] once the control interrupt returns.
    fn pend_slow_task(&mut self);
}

/// The hand-over of the drive between the control interrupt and the slow task's
/// lower-priority interrupt (lock-free: the control interrupt preempts the slow one,
/// never the reverse). The slow interrupt holds the drive between [`SlowTaskGate::enter`]
/// and [`SlowTaskGate::exit`]; the control interrupt asks [`SlowTaskGate::control_entry`]
/// before it touches the drive.
#[derive(Debug, Default)]
pub struct SlowTaskGate {
    running: AtomicBool,
    overran: AtomicBool,
}

/// What the control interrupt may do this period ([`SlowTaskGate::control_entry`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ControlEntry {
    /// The drive is free: run the period.
    Run,
    /// The slow task overran into this period and still holds the drive: switch the
    /// outputs off and return without touching it.
    SlowTaskBusy,
    /// The slow task overran into the last period (it has finished since): trip the
    /// drive ([`FirmwareFault::DeadlineMissed`]), then run the period (it switches off).
    SlowTaskOverran,
}

impl SlowTaskGate {
    /// A free gate.
    pub const fn new() -> Self {
        Self {
            running: AtomicBool::new(false),
            overran: AtomicBool::new(false),
        }
    }

    // One core, two interrupt levels: the flags need atomicity against preemption and
    // the compiler's ordering around the drive's accesses (the fences), not the
    // hardware's barriers.

    /// The slow interrupt takes the drive.
    #[inline(always)]
    pub fn enter(&self) {
        self.running.store(true, Ordering::Relaxed);
        compiler_fence(Ordering::SeqCst);
    }

    /// The slow interrupt gives the drive back.
    #[inline(always)]
    pub fn exit(&self) {
        compiler_fence(Ordering::SeqCst);
        self.running.store(false, Ordering::Relaxed);
    }

    /// The control interrupt's question at its entry (it preempted the slow interrupt
    /// if that one holds the drive; nothing preempts it, so its read and write of the
    /// overrun flag cannot be split).
    #[inline(always)]
    pub fn control_entry(&self) -> ControlEntry {
        let entry = if self.running.load(Ordering::Relaxed) {
            self.overran.store(true, Ordering::Relaxed);
            ControlEntry::SlowTaskBusy
        } else if self.overran.load(Ordering::Relaxed) {
            self.overran.store(false, Ordering::Relaxed);
            ControlEntry::SlowTaskOverran
        } else {
            ControlEntry::Run
        };
        compiler_fence(Ordering::SeqCst);
        entry
    }
}

/// The slow task's interrupt: the work of the last slow tick
/// ([`ControlLoop::run_slow`]). Call it between [`SlowTaskGate::enter`] and
/// [`SlowTaskGate::exit`].
#[inline(never)]
pub fn slow_period<S: SinCos>(ctl: &mut ControlLoop<S>) {
    ctl.run_slow();
}

/// The interrupt's memory of the outputs between periods.
#[derive(Clone, Copy, Debug, Default)]
pub struct Outputs {
    /// An accepted start (or V/f start, or commissioning) permits switching on; cleared
    /// once the loop neither switches nor waits for a start (stop, fault, break, the end
    /// of a commissioning).
    armed: bool,
    /// The last period switched on (MOE set and expected to stay set).
    on: bool,
}

impl Outputs {
    /// Whether a start, V/f start or commissioning is armed.
    pub fn armed(&self) -> bool {
        self.armed
    }
}

/// Applies one command from the main loop, with the hardware side of it: an accepted
/// start arms the [`Outputs`] latch (if no break is pending, else the drive trips; MOE
/// itself is set by the period that switches on), an accepted reset clears the break
/// flags (a refused one leaves them).
///
/// Out of line: a command arrives in few periods, and inlined into the control interrupt
/// it lengthened every period's code path (register pressure) and CCM SRAM.
#[inline(never)]
pub fn apply_command<S: SinCos, P: PowerStageIo>(
    ctl: &mut ControlLoop<S>,
    io: &mut P,
    outputs: &mut Outputs,
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
                    *outputs = Outputs::default();
                } else {
                    outputs.armed = true;
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
    outputs: &mut Outputs,
) -> PwmOutput {
    // read both completion flags and the samples before acknowledging
    let (adc1_done, adc2_done) = io.conversions_done();
    let raw = io.read();
    io.acknowledge();
    let out = if io.break_flag() || (outputs.on && !io.outputs_enabled()) {
        ctl.trip(FirmwareFault::HardwareBreak)
    } else if !(adc1_done && adc2_done) {
        ctl.trip(FirmwareFault::AdcSequence)
    } else {
        ctl.step_fast(&raw)
    };
    let mut out = write(ctl, io, outputs, out);
    if io.sequence_pending() {
        out = ctl.trip(FirmwareFault::DeadlineMissed);
        io.switch_off();
        outputs.on = false;
    }
    // a slow tick's work: in the slow task's interrupt, after this one
    if ctl.slow_pending() {
        io.pend_slow_task();
    }
    // disarmed once nothing switches and no start waits (stop, fault, commissioning done)
    outputs.armed &= ctl.switching() || ctl.drive().start_pending();
    out
}

/// Writes the period's output; returns what was written (a trip's switch-off if MOE may
/// not be set).
#[inline(always)]
fn write<S: SinCos, P: PowerStageIo>(
    ctl: &mut ControlLoop<S>,
    io: &mut P,
    outputs: &mut Outputs,
    out: PwmOutput,
) -> PwmOutput {
    if !out.enabled {
        io.switch_off();
        outputs.on = false;
        return out;
    }
    io.write_duties(out.duties);
    if !outputs.on {
        // off -> on, the only place the period sets MOE: armed, and no break flag (the
        // flag is read again just before the write by `enable_outputs`)
        if !outputs.armed || io.break_flag() {
            let off = ctl.trip(FirmwareFault::HardwareBreak);
            io.switch_off();
            *outputs = Outputs::default();
            return off;
        }
        io.enable_outputs();
        outputs.on = true;
    }
    // else: never touches MOE; a break that cleared it since the check stays effective
    out
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
        /// slow-task requests since the last look
        slow_requests: u32,
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
        fn pend_slow_task(&mut self) {
            self.slow_requests += 1;
        }
    }

    fn setup() -> (ControlLoop<acim::frames::FastSinCos>, Regs, Outputs) {
        setup_with(crate::control::tests::powered())
    }

    fn setup_with(
        drive: acim::Drive<acim::frames::FastSinCos>,
    ) -> (ControlLoop<acim::frames::FastSinCos>, Regs, Outputs) {
        let conv = Converter::new(&POWER_STAGE);
        let ctl = ControlLoop::new(drive, conv, 500);
        let bias = POWER_STAGE.bias_counts() as u16;
        let bus = (325.0 / POWER_STAGE.volts_per_count()) as u16;
        let regs = Regs {
            sample: RawSample {
                currents: [bias; 3],
                dc_bus: bus,
            },
            ..Regs::default()
        };
        (ctl, regs, Outputs::default())
    }

    fn conversion(r: &mut Regs) {
        r.jeos = [true, true];
    }

    /// D1: both converters finished (the normal case) must not be a sequence fault; the
    /// old order (acknowledge, then read ADC2's flag) tripped fault 19 on every interrupt.
    #[test]
    fn completed_conversions_run_the_step() {
        let (mut ctl, mut r, mut o) = setup();
        assert!(
            apply_command(&mut ctl, &mut r, &mut o, ControlCommand::Start)
                .result
                .is_ok()
        );
        // (a few periods: the bias-only samples of this register model carry no current,
        // which the drive's sensor check rightly reports as dead channels after its
        // first 8-period window)
        for _ in 0..4 {
            conversion(&mut r);
            let out = control_period(&mut ctl, &mut r, &mut o);
            assert!(out.enabled, "fault {}", ctl.fault_code());
        }
        assert_eq!(ctl.state(), DriveState::Magnetizing);
        // a missing ADC2 sequence is still a fault
        r.jeos = [true, false];
        assert!(!control_period(&mut ctl, &mut r, &mut o).enabled);
        assert_eq!(ctl.fault_code(), 19);
    }

    /// D3: MOE is set once, by the period that switches on after the start; a break
    /// during the step's PWM write leaves it clear, the next period trips, and only an
    /// accepted reset clears BIF.
    #[test]
    fn a_break_during_the_step_is_not_undone() {
        let (mut ctl, mut r, mut o) = setup();
        apply_command(&mut ctl, &mut r, &mut o, ControlCommand::Start);
        assert!(!r.moe, "the command arms; the period switches on");
        // (fewer periods than the sensor check's window: the samples carry no current)
        for _ in 0..4 {
            conversion(&mut r);
            control_period(&mut ctl, &mut r, &mut o);
            assert!(r.moe);
        }
        assert_eq!(r.moe_sets, 1, "MOE is set only on the off-to-on transition");
        r.break_during_write = true;
        conversion(&mut r);
        control_period(&mut ctl, &mut r, &mut o);
        assert!(!r.moe, "the break cleared MOE and nothing re-armed it");
        conversion(&mut r);
        let out = control_period(&mut ctl, &mut r, &mut o);
        assert!(!out.enabled && !r.moe);
        assert_eq!(ctl.fault_code(), 16);
        // a start while faulted is refused and does not touch MOE or the flags
        assert!(
            apply_command(&mut ctl, &mut r, &mut o, ControlCommand::Start)
                .result
                .is_err()
        );
        assert!(r.bif && !r.moe);
        // stop is accepted (faulted drives stay faulted) and does not clear the flag
        let _ = apply_command(&mut ctl, &mut r, &mut o, ControlCommand::Stop);
        assert!(r.bif);
        // an accepted reset clears BIF; a new start arms again
        assert!(
            apply_command(&mut ctl, &mut r, &mut o, ControlCommand::ResetFault)
                .result
                .is_ok()
        );
        assert!(!r.bif);
        // a start before the rotor flux has decayed (5 tau_r) is refused, MOE stays clear
        assert!(
            apply_command(&mut ctl, &mut r, &mut o, ControlCommand::Start)
                .result
                .is_err()
        );
        assert!(!r.moe);
        let cfg = ctl.drive().config();
        let wait = (5.0 * cfg.machine.rotor_time_constant() / cfg.loops.control_period) as u32;
        for _ in 0..wait {
            conversion(&mut r);
            control_period(&mut ctl, &mut r, &mut o);
        }
        assert!(
            apply_command(&mut ctl, &mut r, &mut o, ControlCommand::Start)
                .result
                .is_ok()
        );
        conversion(&mut r);
        control_period(&mut ctl, &mut r, &mut o);
        assert!(r.moe);
        assert_eq!(r.moe_sets, 2);
    }

    /// A refused reset (drive not faulted) leaves the break flags alone.
    #[test]
    fn a_refused_reset_keeps_the_break_flags() {
        let (mut ctl, mut r, mut o) = setup();
        r.bif = true;
        assert!(
            apply_command(&mut ctl, &mut r, &mut o, ControlCommand::ResetFault)
                .result
                .is_err()
        );
        assert!(r.bif);
        // and a start with a pending break trips instead of arming
        assert!(
            apply_command(&mut ctl, &mut r, &mut o, ControlCommand::Start)
                .result
                .is_ok()
        );
        assert!(!r.moe);
        assert_eq!(ctl.state(), DriveState::Fault);
    }

    /// A missed deadline switches off in the same period.
    #[test]
    fn a_missed_deadline_switches_off() {
        let (mut ctl, mut r, mut o) = setup();
        apply_command(&mut ctl, &mut r, &mut o, ControlCommand::Start);
        conversion(&mut r);
        r.pending = true;
        let out = control_period(&mut ctl, &mut r, &mut o);
        assert!(!out.enabled && !r.moe);
        assert_eq!(ctl.fault_code(), 17);
    }

    /// The register model around the self-test's motor model: each period converts the
    /// model's currents, and the model runs on what the registers hold (MOE and the
    /// compare values written).
    struct Bench {
        ctl: ControlLoop<acim::frames::FastSinCos>,
        r: Regs,
        o: Outputs,
        sim: crate::sim::SimulatedStage,
        duties: [f32; 3],
        slow_runs: u32,
    }

    impl Bench {
        fn new(drive: acim::Drive<acim::frames::FastSinCos>) -> Self {
            let (ctl, r, o) = setup_with(drive);
            let sim = crate::sim::SimulatedStage::new(Converter::new(&POWER_STAGE));
            Self {
                ctl,
                r,
                o,
                sim,
                duties: [0.5; 3],
                slow_runs: 0,
            }
        }
        fn command(&mut self, cmd: ControlCommand) -> bool {
            apply_command(&mut self.ctl, &mut self.r, &mut self.o, cmd)
                .result
                .is_ok()
        }
        fn periods(&mut self, n: u32) {
            for _ in 0..n {
                self.r.sample = self.sim.sample();
                conversion(&mut self.r);
                let out = control_period(&mut self.ctl, &mut self.r, &mut self.o);
                if out.enabled {
                    self.duties = out.duties;
                }
                // the slow task's interrupt, after the control interrupt returned
                if self.r.slow_requests > 0 {
                    self.r.slow_requests = 0;
                    self.slow_runs += 1;
                    slow_period(&mut self.ctl);
                }
                self.sim.run_period(PwmOutput {
                    duties: self.duties,
                    enabled: self.r.moe,
                });
            }
        }
    }

    /// A drive as `set`/`defaults`/commissioning leave it: freshly built, its offsets not
    /// measured yet (a start waits 0.1 s with the outputs off).
    fn unsettled() -> acim::Drive<acim::frames::FastSinCos> {
        acim::Drive::new(crate::board::drive_config()).unwrap()
    }

    /// N1: a start that waits for the offset measurement (outputs off) switches on after
    /// its wait; before, MOE was set by the command, cleared by the first off period and
    /// never set again: fault 16 at the end of the wait.
    #[test]
    fn a_start_that_waits_switches_on_after_the_wait() {
        let mut b = Bench::new(unsettled());
        assert!(b.command(ControlCommand::SpeedRpm(300.0)));
        assert!(b.command(ControlCommand::Start));
        assert!(b.ctl.drive().start_pending());
        b.periods(10);
        assert!(!b.r.moe, "outputs off while the start waits");
        b.periods(590);
        assert_eq!(b.ctl.fault_code(), 0);
        assert!(b.r.moe, "switched on after the wait");
        assert_eq!(b.r.moe_sets, 1);
        assert!(matches!(
            b.ctl.state(),
            DriveState::Magnetizing | DriveState::Running
        ));
        // stop: off and disarmed
        assert!(b.command(ControlCommand::Stop));
        b.periods(1);
        assert!(!b.r.moe && !b.o.armed());
    }

    /// N1: a commissioning (its first 0.2 s stage measures the offsets with the outputs
    /// off) switches on for its tests; before, fault 16 0.2 ms after it began.
    #[test]
    fn a_commissioning_switches_on_after_its_offset_stage() {
        let mut b = Bench::new(crate::control::tests::powered());
        let args = [750.0, 230.0, 3.3, 50.0, 1500.0];
        b.ctl
            .stage_commissioning(crate::commission::build(&args, 325.0));
        assert!(b.command(ControlCommand::Commission(args)));
        b.periods(500);
        assert_eq!(b.ctl.fault_code(), 0);
        b.periods(1000);
        assert_eq!(b.ctl.fault_code(), 0, "tripped after the offset stage");
        assert_eq!(b.ctl.state_code(), crate::control::STATE_COMMISSIONING);
        assert!(b.r.moe, "the commissioning's tests switch on");
        // a stop aborts it: off, disarmed
        assert!(b.command(ControlCommand::Stop));
        b.periods(1);
        assert!(!b.r.moe && !b.o.armed());
    }

    /// N1: a break while a start waits (outputs off) is never switched on over: the
    /// transition trips instead, MOE stays clear.
    #[test]
    fn a_break_during_the_wait_trips_at_the_transition() {
        let mut b = Bench::new(unsettled());
        assert!(b.command(ControlCommand::Start));
        b.periods(100);
        b.r.bif = true;
        b.periods(500);
        assert!(!b.r.moe);
        assert_eq!(b.r.moe_sets, 0);
        assert_eq!(b.ctl.fault_code(), 16);
        assert!(!b.o.armed());
    }

    /// Without a start, nothing switches on: the latch is clear.
    #[test]
    fn an_idle_loop_is_not_armed() {
        let mut b = Bench::new(crate::control::tests::powered());
        b.periods(10);
        assert!(!b.o.armed() && !b.r.moe);
        // a refused start (the drive is faulted) does not arm
        b.ctl.trip(FirmwareFault::AdcSequence);
        assert!(!b.command(ControlCommand::Start));
        assert!(!b.o.armed());
    }

    /// With a 1 ms slow task at 5 kHz, every fifth running period requests the slow
    /// task's interrupt, which runs the speed loop: the drive starts and follows a speed
    /// target as with one rate. Without a slow task nothing is requested.
    #[test]
    fn a_slow_tick_requests_the_slow_task_which_runs_the_speed_loop() {
        for slow_period in [0.0, 1e-3] {
            let mut cfg = crate::board::drive_config();
            cfg.loops.slow_period = slow_period;
            let mut d = acim::Drive::new(cfg).unwrap();
            // the offsets measured, as `powered` does
            for _ in 0..3000 {
                d.step(&acim::DriveInputs {
                    phase_currents: [0.0; 3],
                    dc_bus: 325.0,
                });
            }
            let mut b = Bench::new(d);
            assert!(b.command(ControlCommand::SpeedRpm(300.0)));
            assert!(b.command(ControlCommand::Start));
            b.periods(25_000);
            assert_eq!(b.ctl.fault_code(), 0, "slow period {slow_period}");
            assert_eq!(b.ctl.drive().state(), acim::DriveState::Running);
            let speed = b.ctl.drive().telemetry().speed_estimate * acim::math::RAD_S_TO_RPM;
            assert!((speed - 300.0).abs() < 15.0, "{slow_period}: {speed} rpm");
            if slow_period == 0.0 {
                assert_eq!(b.slow_runs, 0);
            } else {
                // one request per slow tick while switching (magnetizing and running):
                // a fifth of the periods, less the start's wait with the switches off
                let ticks = 25_000 / 5;
                assert!(
                    b.slow_runs > ticks * 9 / 10 && b.slow_runs <= ticks + 1,
                    "{}",
                    b.slow_runs
                );
            }
        }
    }

    /// The gate: while the slow interrupt holds the drive the control interrupt may not
    /// touch it; the period after, it trips the drive; then it runs again.
    #[test]
    fn a_slow_task_that_overruns_its_period_is_a_missed_deadline() {
        let g = SlowTaskGate::new();
        assert_eq!(g.control_entry(), ControlEntry::Run);
        g.enter();
        g.exit();
        assert_eq!(g.control_entry(), ControlEntry::Run);
        g.enter();
        assert_eq!(g.control_entry(), ControlEntry::SlowTaskBusy);
        assert_eq!(g.control_entry(), ControlEntry::SlowTaskBusy);
        g.exit();
        assert_eq!(g.control_entry(), ControlEntry::SlowTaskOverran);
        assert_eq!(g.control_entry(), ControlEntry::Run);
    }
}
