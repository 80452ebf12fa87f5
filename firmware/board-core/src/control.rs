//! The per-period control loop that the firmware's interrupt runs: raw ADC counts in,
//! PWM command out, plus fault bookkeeping and decimated telemetry.
//!
//! Hardware-independent and generic over the sin/cos provider, so the same code runs with
//! the CORDIC on the target, with [`acim::frames::FastSinCos`] in host tests, and against
//! the motor model in the self-test ([`crate::sim`]).

use crate::commission::{Commissioning, NameplateArgs};
use crate::convert::{Converter, RawSample};
use crate::telemetry::TelemetrySample;
use crate::timing::{CycleStats, CycleSummary, Decimator};
use acim::frames::SinCos;
use acim::math::{RAD_S_TO_RPM, RPM_TO_RAD_S};
use acim::{CommandError, Drive, DriveInputs, DriveState, FaultReason, PwmOutput, TelemetryRate};

/// Faults detected by the firmware rather than by the drive library.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum FirmwareFault {
    /// The timer's break input fired (gate driver or over-current comparator): the
    /// hardware already cleared the main output.
    HardwareBreak,
    /// A new conversion completed before the previous step finished.
    DeadlineMissed,
    /// A current channel sat at an ADC rail.
    AdcSaturated,
    /// The injected sequence was incomplete when the interrupt ran.
    AdcSequence,
}

impl FirmwareFault {
    /// The [`FaultReason`] passed to [`Drive::trip`] (the exact firmware cause is also
    /// kept here and published as the fault code).
    pub fn drive_reason(self) -> FaultReason {
        match self {
            FirmwareFault::HardwareBreak => FaultReason::HardwareBreak,
            FirmwareFault::AdcSaturated => FaultReason::OverCurrent,
            FirmwareFault::DeadlineMissed => FaultReason::DeadlineMissed,
            FirmwareFault::AdcSequence => FaultReason::NonFiniteInput,
        }
    }
}

/// Fault code published in telemetry: 0 none, 1..15 and 20 the drive's [`FaultReason`],
/// 16..19 a [`FirmwareFault`].
pub struct FaultCode;

impl FaultCode {
    /// The code of a fault state.
    pub fn of(drive: Option<FaultReason>, firmware: Option<FirmwareFault>) -> u8 {
        if let Some(f) = firmware {
            return match f {
                FirmwareFault::HardwareBreak => 16,
                FirmwareFault::DeadlineMissed => 17,
                FirmwareFault::AdcSaturated => 18,
                FirmwareFault::AdcSequence => 19,
            };
        }
        match drive {
            None => 0,
            Some(FaultReason::OverCurrent) => 1,
            Some(FaultReason::DcBusOverVoltage) => 2,
            Some(FaultReason::DcBusUnderVoltage) => 3,
            Some(FaultReason::OverSpeed) => 4,
            Some(FaultReason::NonFiniteInput) => 5,
            Some(FaultReason::EstimatorOutOfRange) => 6,
            Some(FaultReason::Stall) => 7,
            Some(FaultReason::HardwareBreak) => 8,
            Some(FaultReason::DeadlineMissed) => 9,
            Some(FaultReason::CurrentRegulation) => 10,
            Some(FaultReason::LossOfControl) => 11,
            Some(FaultReason::CurrentSensor) => 12,
            Some(FaultReason::MagnetizingTimeout) => 13,
            Some(FaultReason::NoCurrentResponse) => 14,
            Some(FaultReason::Overload) => 15,
            Some(FaultReason::SpeedOscillation) => 20,
        }
    }
}

/// Commands the main loop sends to the interrupt (through a lock-free queue: the
/// interrupt owns the drive, the main loop never touches it).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ControlCommand {
    /// Idle -> magnetizing -> running.
    Start,
    /// Idle -> open-loop V/f.
    StartOpenLoop,
    /// Switches off.
    Stop,
    /// Speed target, rpm.
    SpeedRpm(f32),
    /// Fault -> idle (also clears a firmware fault).
    ResetFault,
    /// Self-test: the motor model's load torque, N m (the drive itself is unaffected).
    PlantLoad(f32),
    /// Idle -> self-commissioning with this nameplate (checked by the main loop with
    /// [`crate::commission::check`] first, and built by it: [`ControlLoop::stage_commissioning`]
    /// before the command); `Stop` aborts it.
    Commission(NameplateArgs),
    /// Telemetry every this many periods from the next period on (the protocol's `rate`,
    /// 2 ..= 50 000 checked by its parser; any state).
    Rate(u16),
}

/// The telemetry state code while commissioning runs (the drive's own codes are 0..=4).
pub const STATE_COMMISSIONING: u8 = 5;

/// The interrupt's reply to a [`ControlCommand`].
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct CommandReply {
    /// The command.
    pub command: ControlCommand,
    /// Its outcome.
    pub result: Result<(), CommandError>,
}

/// The UART reply line to a refused command (ASCII, `\r\n`-terminated).
pub fn refusal_text(e: CommandError) -> &'static [u8] {
    match e {
        CommandError::Demagnetizing => {
            b"err the rotor flux has not decayed: retry 5 rotor time constants after the switch-off\r\n"
        }
        CommandError::SensorOffset => {
            b"err current-sensor offset beyond its limit: fault CurrentSensor\r\n"
        }
        CommandError::NotFinite => b"err value not finite\r\n",
        CommandError::OutOfRange => b"err value out of range\r\n",
        CommandError::WrongState(_) => b"err refused in this state\r\n",
    }
}

/// Drive + conversion + statistics, owned by the control interrupt.
// `repr(C)`, the interrupt's small state first: the drive is 4.7 kB, and placed after it
// (the compiler's order) the conversion's and the statistics' fields lay beyond the reach
// of a load's offset (1020 B for `vldr`), so each took an address computation of its own
#[repr(C)]
pub struct ControlLoop<S: SinCos> {
    conv: Converter,
    inputs: DriveInputs,
    stats: CycleStats,
    decim: Decimator,
    fw_fault: Option<FirmwareFault>,
    seq: u32,
    /// Periods closed by [`ControlLoop::finish_period`] since power-up (wraps).
    period: u32,
    last_summary: CycleSummary,
    drive: Drive<S>,
    commissioning: Option<Commissioning>,
    /// The sequence the main loop built for the next `Commission` command.
    staged: Option<Commissioning>,
}

impl<S: SinCos> ControlLoop<S> {
    /// A loop around an idle drive; telemetry every `decimation` periods.
    pub fn new(drive: Drive<S>, conv: Converter, decimation: u16) -> Self {
        let mut c = Self {
            drive,
            conv,
            stats: CycleStats::new(),
            last_summary: CycleSummary::default(),
            decim: Decimator::new(decimation),
            seq: 0,
            period: 0,
            fw_fault: None,
            inputs: DriveInputs::default(),
            commissioning: None,
            staged: None,
        };
        c.match_telemetry_rate();
        c
    }

    /// The drive records its telemetry as often as this loop samples it: at the slow
    /// ticks only ([`TelemetryRate::SlowTick`]: the other periods skip the record) when
    /// the samples are at least a slow period apart, so that each sample is at most one
    /// slow period old; every period when they come faster.
    fn match_telemetry_rate(&mut self) {
        let divider = self.drive.coeffs().cascade.slow_divider;
        let rate = if u32::from(self.decim.every()) >= divider {
            TelemetryRate::SlowTick
        } else {
            TelemetryRate::EveryPeriod
        };
        self.drive.set_telemetry_rate(rate);
    }

    /// One control step on this period's raw sample, the slow task's work included
    /// ([`acim::Drive::step`]): [`ControlLoop::step_fast`], then
    /// [`ControlLoop::run_slow`].
    #[inline]
    pub fn step(&mut self, raw: &RawSample) -> PwmOutput {
        let out = self.step_fast(raw);
        self.run_slow();
        out
    }

    /// The fast part of one control step ([`acim::Drive::step_fast`]): with a slow task,
    /// a slow tick leaves its work for [`ControlLoop::run_slow`]. A saturated current
    /// channel trips the drive; every fault returns [`PwmOutput::OFF`] in this same step.
    // always inlined: the control interrupt is its one caller on the board, and an
    // out-of-line copy (LLVM's choice once the interrupt grew by a check) cost 4 KB of
    // CCM SRAM
    #[inline(always)]
    pub fn step_fast(&mut self, raw: &RawSample) -> PwmOutput {
        let c = self.conv.convert(raw);
        self.inputs = c.inputs;
        if c.saturated {
            return self.trip(FirmwareFault::AdcSaturated);
        }
        // self-commissioning drives the switches instead of the (idle) drive; it switches
        // off by itself when done or failed, and the main loop takes its result
        if let Some(com) = self.commissioning.as_mut() {
            return com.step(&c.inputs);
        }
        self.drive.step_fast(&c.inputs)
    }

    /// Whether a slow tick's work waits for [`ControlLoop::run_slow`].
    #[inline]
    pub fn slow_pending(&self) -> bool {
        self.drive.slow_pending()
    }

    /// The slow task's work of the last slow tick ([`acim::Drive::run_slow`]); nothing if
    /// none waits. A fault it finds switches the outputs off at the next period.
    #[inline(never)]
    pub fn run_slow(&mut self) {
        self.drive.run_slow();
    }

    /// Forces a fault; the first cause is kept. A running commissioning is abandoned.
    #[inline]
    pub fn trip(&mut self, fault: FirmwareFault) -> PwmOutput {
        self.commissioning = None;
        if self.drive.fault().is_none() {
            self.fw_fault = Some(fault);
        }
        self.drive.trip(fault.drive_reason())
    }

    /// Applies a command from the main loop.
    pub fn apply(&mut self, cmd: ControlCommand) -> CommandReply {
        let busy = self.commissioning.is_some();
        let result = match cmd {
            ControlCommand::Start
            | ControlCommand::StartOpenLoop
            | ControlCommand::Commission(_)
                if busy =>
            {
                Err(CommandError::WrongState(self.drive.state()))
            }
            ControlCommand::Start => self.drive.start(),
            ControlCommand::StartOpenLoop => self.drive.start_open_loop(),
            ControlCommand::Commission(_) => self.start_commissioning(),
            ControlCommand::Stop => {
                self.commissioning = None;
                self.drive.stop();
                Ok(())
            }
            ControlCommand::SpeedRpm(rpm) => self.drive.set_speed_target(rpm * RPM_TO_RAD_S),
            // applied by the self-test's interrupt to its motor model
            ControlCommand::PlantLoad(_) => Ok(()),
            ControlCommand::Rate(every) => {
                self.set_decimation(every);
                Ok(())
            }
            ControlCommand::ResetFault => {
                let r = self.drive.reset_fault();
                if r.is_ok() {
                    self.fw_fault = None;
                }
                r
            }
        };
        CommandReply {
            command: cmd,
            result,
        }
    }

    /// Hands over the sequence the main loop built ([`crate::commission::build`]) for the
    /// next `Commission` command, replacing one not started (`None`: the library refused
    /// the nameplate, and the command is refused): building it in the interrupt put the
    /// nameplate's design into CCM SRAM, which the control step needs.
    pub fn stage_commissioning(&mut self, c: Option<Commissioning>) {
        self.staged = c;
    }

    fn start_commissioning(&mut self) -> Result<(), CommandError> {
        let state = self.drive.state();
        // a start waiting for the offset measurement has the motor claimed already
        if state != DriveState::Idle || self.drive.start_pending() {
            return Err(CommandError::WrongState(state));
        }
        // none staged: the main loop refused the nameplate or the board
        let c = self.staged.take().ok_or(CommandError::OutOfRange)?;
        self.commissioning = Some(c);
        Ok(())
    }

    /// The running (or finished, not yet taken) commissioning.
    pub fn commissioning(&self) -> Option<&Commissioning> {
        self.commissioning.as_ref()
    }

    /// Takes a commissioning that has finished (done or failed; the switches are already
    /// off) for its fits in the main loop; `None` while it runs or when there is none.
    pub fn take_finished_commissioning(&mut self) -> Option<Commissioning> {
        use acim::commissioning::Stage;
        match self.commissioning.as_ref().map(|c| c.stage()) {
            Some(Stage::Done | Stage::Failed(_)) => self.commissioning.take(),
            _ => None,
        }
    }

    /// Whether [`ControlLoop::replace_drive`] would accept a drive now: the running one
    /// Idle, not commissioning and no start waiting for the offset measurement (a start
    /// waiting is not dropped under the user); else the state that refuses it. The
    /// firmware checks this with interrupts masked, then moves the drive in with them
    /// enabled while the control interrupt leaves the drive alone.
    pub fn can_replace_drive(&self) -> Result<(), DriveState> {
        let state = self.drive.state();
        if state != DriveState::Idle || self.commissioning.is_some() || self.drive.start_pending() {
            return Err(state);
        }
        Ok(())
    }

    /// Swaps in a drive rebuilt from new settings ([`crate::settings`]), only while Idle
    /// with no start waiting and not commissioning: otherwise the state that refused it (the machine model of a
    /// running drive never changes under it). The new drive starts Idle, with fresh
    /// estimator state.
    pub fn replace_drive(&mut self, drive: Drive<S>) -> Result<(), DriveState> {
        self.can_replace_drive()?;
        self.drive = drive;
        self.fw_fault = None;
        self.match_telemetry_rate();
        Ok(())
    }

    /// Closes the period: records the step's cycle count and, every `decimation` periods,
    /// returns a telemetry sample. `plant_speed_rpm` is the self-test model's speed (0 on
    /// hardware).
    #[inline]
    pub fn finish_period(&mut self, cycles: u32, plant_speed_rpm: f32) -> Option<TelemetrySample> {
        let period = self.period;
        self.period = period.wrapping_add(1);
        self.stats.record(cycles);
        if !self.decim.tick() {
            return None;
        }
        let cyc = self.stats.take();
        self.last_summary = cyc;
        let t = self.drive.telemetry();
        self.seq = self.seq.wrapping_add(1);
        Some(TelemetrySample {
            seq: self.seq,
            state: self.state_code(),
            fault: self.fault_code(),
            speed_ref_rpm: t.speed_reference * RAD_S_TO_RPM,
            speed_est_rpm: t.speed_estimate * RAD_S_TO_RPM,
            i_d: t.current.d,
            i_q: t.current.q,
            torque: t.torque_estimate,
            load_torque: t.load_torque_estimate,
            rs: t.stator_resistance_estimate,
            flux: t.rotor_flux,
            dc_bus: self.inputs.dc_bus,
            cycles_min: cyc.min,
            cycles_mean: cyc.mean,
            cycles_max: cyc.max,
            plant_speed_rpm,
            period,
            i_d_ref: t.current_reference.d,
            i_q_ref: t.current_reference.q,
        })
    }

    /// Telemetry every `every` periods from now on (the protocol's `rate`; 0 is taken as
    /// 1). The window of cycle statistics restarts with it.
    pub fn set_decimation(&mut self, every: u16) {
        self.decim = Decimator::new(every);
        self.stats = CycleStats::new();
        self.match_telemetry_rate();
    }

    /// Whether the switches should be on: the drive magnetizing, running or in V/f, or
    /// a commissioning still running (the interrupt trips if MOE is found cleared).
    #[inline]
    pub fn switching(&self) -> bool {
        use acim::commissioning::Stage;
        matches!(
            self.drive.state(),
            DriveState::Magnetizing | DriveState::Running | DriveState::OpenLoop
        ) || self
            .commissioning
            .as_ref()
            .is_some_and(|c| !matches!(c.stage(), Stage::Done | Stage::Failed(_)))
    }

    /// The published state code: the drive's ([`DriveState::code`]), Magnetizing while a
    /// start waits for the offset measurement ([`Drive::start_pending`]), or
    /// [`STATE_COMMISSIONING`].
    pub fn state_code(&self) -> u8 {
        if self.commissioning.is_some() {
            STATE_COMMISSIONING
        } else if self.drive.start_pending() {
            // a start waiting for the offset measurement (switches off, at most 0.1 s) is
            // reported as the start it is: nothing that needs an idle drive (set, save,
            // defaults, commissioning) may run under it
            DriveState::Magnetizing.code()
        } else {
            self.drive.state().code()
        }
    }

    /// The published fault code.
    pub fn fault_code(&self) -> u8 {
        FaultCode::of(self.drive.fault(), self.fw_fault)
    }

    /// The firmware-detected fault, if it was the first cause.
    pub fn firmware_fault(&self) -> Option<FirmwareFault> {
        self.fw_fault
    }

    /// The drive.
    pub fn drive(&self) -> &Drive<S> {
        &self.drive
    }

    /// State of the drive.
    pub fn state(&self) -> DriveState {
        self.drive.state()
    }

    /// Inputs of the last step (A, V).
    pub fn inputs(&self) -> &DriveInputs {
        &self.inputs
    }

    /// Cycle statistics of the last closed window.
    pub fn last_cycles(&self) -> CycleSummary {
        self.last_summary
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::board::{drive_config, POWER_STAGE};

    /// A drive powered long enough, switches off and no current, for its offset
    /// measurement to have settled: a start switches at the next step (at power-up a
    /// start waits up to 0.1 s for the measurement, `Drive::start_pending`).
    pub(crate) fn powered() -> Drive<acim::frames::FastSinCos> {
        let mut d = Drive::new(drive_config()).unwrap();
        for _ in 0..d.coeffs().limits.offset_settle_steps {
            d.step(&acim::DriveInputs {
                phase_currents: [0.0; 3],
                dc_bus: 325.0,
            });
        }
        d
    }

    fn looped() -> ControlLoop<acim::frames::FastSinCos> {
        ControlLoop::new(powered(), Converter::new(&POWER_STAGE), 10)
    }

    fn raw_at_bus(c: &Converter, v: f32) -> RawSample {
        RawSample {
            currents: [2048; 3],
            dc_bus: c.volts_to_counts(v),
        }
    }

    #[test]
    fn saturation_trips_in_the_same_step() {
        let mut l = looped();
        let conv = Converter::new(&POWER_STAGE);
        assert!(l.apply(ControlCommand::Start).result.is_ok());
        let out = l.step(&raw_at_bus(&conv, 325.0));
        assert!(out.enabled);
        let mut raw = raw_at_bus(&conv, 325.0);
        raw.currents[1] = 4095;
        let out = l.step(&raw);
        assert!(!out.enabled);
        assert_eq!(l.state(), DriveState::Fault);
        assert_eq!(l.firmware_fault(), Some(FirmwareFault::AdcSaturated));
        assert_eq!(l.fault_code(), 18);
        // start refused while faulted, reset clears both faults
        assert!(l.apply(ControlCommand::Start).result.is_err());
        assert!(l.apply(ControlCommand::ResetFault).result.is_ok());
        assert_eq!(l.fault_code(), 0);
        assert_eq!(l.state(), DriveState::Idle);
    }

    #[test]
    fn first_cause_is_kept() {
        let mut l = looped();
        let conv = Converter::new(&POWER_STAGE);
        l.apply(ControlCommand::Start);
        // bus over-voltage: the drive's own fault
        let out = l.step(&raw_at_bus(&conv, 450.0));
        assert!(!out.enabled);
        assert_eq!(l.fault_code(), 2);
        let out = l.trip(FirmwareFault::DeadlineMissed);
        assert!(!out.enabled);
        assert_eq!(
            l.fault_code(),
            2,
            "later firmware trip does not hide the first cause"
        );
        let mut l = looped();
        l.trip(FirmwareFault::HardwareBreak);
        assert_eq!(l.fault_code(), 16);
        assert_eq!(l.drive().fault(), Some(FaultReason::HardwareBreak));
    }

    #[test]
    fn telemetry_is_decimated_with_cycle_stats() {
        let mut l = looped();
        let conv = Converter::new(&POWER_STAGE);
        let mut samples = 0;
        for k in 0..100u32 {
            l.step(&raw_at_bus(&conv, 325.0));
            if let Some(s) = l.finish_period(1000 + k % 10, 0.0) {
                samples += 1;
                assert_eq!(s.cycles_min, 1000);
                assert_eq!(s.cycles_max, 1009);
                assert_eq!(s.cycles_mean, 1004);
                assert_eq!(s.state, 0);
                assert!((s.dc_bus - 325.0).abs() < 0.2);
            }
        }
        assert_eq!(samples, 10);
    }

    /// The drive records its telemetry at the slow ticks only while the samples are a slow
    /// period or more apart (the test loop's 10 periods against a slow divider of 5), every
    /// period when `rate` asks for samples closer than that, and a rebuilt drive moved in
    /// gets the loop's choice.
    #[test]
    fn the_telemetry_is_recorded_as_often_as_it_is_sampled() {
        let mut l = looped();
        let divider = l.drive().coeffs().cascade.slow_divider;
        assert_eq!(divider, 5);
        assert_eq!(l.drive().telemetry_rate(), TelemetryRate::SlowTick);
        assert!(l.apply(ControlCommand::Rate(4)).result.is_ok());
        assert_eq!(l.drive().telemetry_rate(), TelemetryRate::EveryPeriod);
        assert!(l.apply(ControlCommand::Rate(5)).result.is_ok());
        assert_eq!(l.drive().telemetry_rate(), TelemetryRate::SlowTick);
        assert!(l.apply(ControlCommand::Rate(1)).result.is_ok());
        let fresh = looped().drive;
        assert_eq!(fresh.telemetry_rate(), TelemetryRate::SlowTick);
        assert!(l.replace_drive(fresh).is_ok());
        assert_eq!(l.drive().telemetry_rate(), TelemetryRate::EveryPeriod);
    }

    /// `rate` takes effect from the next period in any state; the sample carries the
    /// period it closes (for `$X`) and the current references.
    #[test]
    fn rate_changes_the_decimation_and_samples_carry_their_period() {
        let mut l = looped();
        let conv = Converter::new(&POWER_STAGE);
        let mut periods: heapless::Vec<u32, 32> = heapless::Vec::new();
        let mut i_d_ref_max = 0.0f32;
        for k in 0..100u32 {
            if k == 30 {
                assert!(l.apply(ControlCommand::Start).result.is_ok());
                assert!(l.apply(ControlCommand::Rate(4)).result.is_ok());
                assert_eq!(
                    l.state(),
                    DriveState::Magnetizing,
                    "a rate leaves the state alone"
                );
            }
            l.step(&raw_at_bus(&conv, 325.0));
            if let Some(s) = l.finish_period(1000, 0.0) {
                assert_eq!(s.period, k);
                let r = l.drive().telemetry().current_reference;
                assert_eq!((s.i_d_ref, s.i_q_ref), (r.d, r.q));
                i_d_ref_max = i_d_ref_max.max(s.i_d_ref);
                periods.push(s.period).unwrap();
            }
        }
        // every 10 periods before, every 4 from period 30 (the window restarts there)
        let want: heapless::Vec<u32, 32> = [9, 19, 29]
            .into_iter()
            .chain((33..100).step_by(4))
            .collect();
        assert_eq!(periods, want);
        assert!(
            i_d_ref_max > 0.0,
            "the magnetizing current reference is published"
        );
    }

    /// New settings reach the drive only while it is Idle (`set` is refused while
    /// running, magnetizing, in V/f or faulted).
    #[test]
    fn settings_are_refused_while_running() {
        use crate::settings::{field_index, Settings};
        let conv = Converter::new(&POWER_STAGE);
        let i = field_index(b"limits.current_limit").unwrap();
        let s = Settings::defaults().set(i, 4.0).unwrap();
        let rebuilt = || Drive::new(s.drive_config().unwrap()).unwrap();
        let mut l = looped();
        assert!(l.apply(ControlCommand::Start).result.is_ok());
        l.step(&raw_at_bus(&conv, 325.0));
        assert_eq!(l.replace_drive(rebuilt()), Err(DriveState::Magnetizing));
        assert_eq!(
            l.drive().config().limits.current_limit,
            Settings::defaults().get(i)
        );
        l.trip(FirmwareFault::HardwareBreak);
        assert_eq!(l.replace_drive(rebuilt()), Err(DriveState::Fault));
        assert!(l.apply(ControlCommand::ResetFault).result.is_ok());
        assert_eq!(l.replace_drive(rebuilt()), Ok(()));
        assert_eq!(l.drive().config().limits.current_limit, 4.0);
        assert_eq!(l.state(), DriveState::Idle);
    }

    /// A restart right after a stop is refused with its own reason and changes nothing;
    /// after 5 tau_r it is accepted.
    #[test]
    fn a_restart_waits_for_the_flux_to_decay() {
        let conv = Converter::new(&POWER_STAGE);
        let mut l = looped();
        assert!(l.apply(ControlCommand::Start).result.is_ok());
        l.step(&raw_at_bus(&conv, 325.0));
        assert!(l.apply(ControlCommand::Stop).result.is_ok());
        let r = l.apply(ControlCommand::Start).result;
        assert_eq!(r, Err(CommandError::Demagnetizing));
        assert!(refusal_text(CommandError::Demagnetizing).starts_with(b"err the rotor flux"));
        assert_eq!(l.state(), DriveState::Idle);
        let m = l.drive().config().machine;
        let wait = (5.0 * m.rotor_time_constant() / l.drive().config().loops.control_period) as u32;
        for _ in 0..wait {
            l.step(&raw_at_bus(&conv, 325.0));
        }
        assert!(l.apply(ControlCommand::Start).result.is_ok());
    }

    /// Commissioning takes the switches from the idle drive, refuses a start and a
    /// settings swap while it runs, and ends on stop or on any trip with the switches off.
    #[test]
    fn commissioning_owns_the_switches_until_stopped_or_tripped() {
        let conv = Converter::new(&POWER_STAGE);
        let paper = [750.0, 230.0, 3.3, 50.0, 1500.0];
        let mut l = looped();
        l.step(&raw_at_bus(&conv, 325.0));
        l.stage_commissioning(crate::commission::build(&paper, 325.0));
        assert!(l.apply(ControlCommand::Commission(paper)).result.is_ok());
        assert!(l.switching());
        assert_eq!(l.state_code(), STATE_COMMISSIONING);
        assert!(l.apply(ControlCommand::Start).result.is_err());
        l.stage_commissioning(crate::commission::build(&paper, 325.0));
        assert!(l.apply(ControlCommand::Commission(paper)).result.is_err());
        let fresh = Drive::new(drive_config()).unwrap();
        assert!(l.replace_drive(fresh).is_err());
        assert!(l.take_finished_commissioning().is_none(), "still running");
        // offsets first (switches off), then the DC steps switch
        let mut on = false;
        for _ in 0..2000 {
            on |= l.step(&raw_at_bus(&conv, 325.0)).enabled;
        }
        // no current follows the zero-current raw samples: motor not connected
        assert!(on);
        let c = l.take_finished_commissioning().expect("failed: finished");
        assert_eq!(
            c.stage(),
            acim::commissioning::Stage::Failed(
                acim::commissioning::CommissioningError::MotorNotConnected
            )
        );
        assert!(!l.switching());
        assert_eq!(l.state_code(), 0);
        // stop aborts
        l.stage_commissioning(crate::commission::build(&paper, 325.0));
        assert!(l.apply(ControlCommand::Commission(paper)).result.is_ok());
        assert!(l.apply(ControlCommand::Stop).result.is_ok());
        assert!(l.commissioning().is_none() && !l.switching());
        // a trip abandons it, the fault is the drive's
        l.stage_commissioning(crate::commission::build(&paper, 325.0));
        assert!(l.apply(ControlCommand::Commission(paper)).result.is_ok());
        l.step(&raw_at_bus(&conv, 325.0));
        let mut raw = raw_at_bus(&conv, 325.0);
        raw.currents[0] = 0;
        assert!(!l.step(&raw).enabled);
        assert!(l.commissioning().is_none());
        assert_eq!(l.state(), DriveState::Fault);
        assert_eq!(l.state_code(), 4);
        l.stage_commissioning(crate::commission::build(&paper, 325.0));
        assert!(l.apply(ControlCommand::Commission(paper)).result.is_err());
        // nothing staged (the main loop could not build it): refused, nothing switches
        let mut l = looped();
        l.step(&raw_at_bus(&conv, 325.0));
        assert_eq!(
            l.apply(ControlCommand::Commission(paper)).result,
            Err(CommandError::OutOfRange)
        );
        assert!(!l.switching());
    }

    #[test]
    fn speed_command_in_rpm() {
        let mut l = looped();
        assert!(l.apply(ControlCommand::SpeedRpm(500.0)).result.is_ok());
        assert!(l.apply(ControlCommand::SpeedRpm(f32::NAN)).result.is_err());
        assert!(l.apply(ControlCommand::Stop).result.is_ok());
    }
}
