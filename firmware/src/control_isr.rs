//! The control interrupt: one step per PWM period, at top priority, code and state in CCM
//! SRAM (see ccmram.x).
//!
//! Hardware: ADC1's end-of-injected-sequence interrupt (`ADC1_2`), triggered through
//! TIM1 TRGO2 at the sampling instant. Self-test: TIM6's 5 kHz update interrupt, with the
//! motor model in place of ADC and PWM (TIM1 is never configured, outputs stay off).
//!
//! Per period: acknowledge, apply at most one queued command, read the samples, break /
//! sequence checks, `ControlLoop::step_fast`, write the PWM (switches off in this same
//! period on any fault), deadline check, cycle statistics and decimated telemetry.
//!
//! With a slow task (the `loops.slow_period` setting), a slow tick's work (speed loop,
//! field weakening, slow supervision) runs in a second interrupt of lower priority
//! (`FMAC`'s vector, `hw::SLOW_TASK_IRQ`), pended by the period and run from flash once
//! the control interrupt returns; the two share the drive through
//! `acim_firmware_core::stage::SlowTaskGate` (the slow task must end within the period;
//! if not, the next control period switches the outputs off, the one after trips
//! `DeadlineMissed`). The self-test runs the slow work inline (`ControlLoop::step`).
//!
//! Data shared with `main` only through lock-free SPSC queues and atomics: the
//! interrupts own the drive.

use crate::board_cfg::Sc;
#[cfg(feature = "selftest")]
use acim_firmware_core::control::FirmwareFault;
use acim_firmware_core::control::{CommandReply, ControlCommand, ControlLoop};
use acim_firmware_core::telemetry::TelemetrySample;
use acim_firmware_core::timing::elapsed;
use core::mem::MaybeUninit;
use core::sync::atomic::{AtomicBool, AtomicU32, AtomicU8, Ordering};
use cortex_m::peripheral::DWT;
use heapless::spsc::{Consumer, Producer};
use stm32g4xx_hal::pac::interrupt;

#[cfg(not(feature = "selftest"))]
use crate::hw;
#[cfg(not(feature = "selftest"))]
use acim_firmware_core::board::{MAX_DUTY, PWM_ARR};
#[cfg(not(feature = "selftest"))]
use acim_firmware_core::control::FirmwareFault;
#[cfg(not(feature = "selftest"))]
use acim_firmware_core::stage::{
    apply_command, control_period, slow_period, ControlEntry, PowerStageIo, SlowTaskGate,
};

/// The drive's hand-over between the control interrupt and the slow task's.
#[cfg(not(feature = "selftest"))]
static SLOW_GATE: SlowTaskGate = SlowTaskGate::new();

/// Telemetry queue length (holds N-1 samples: 1.5 s at 10 Hz).
pub const TEL_Q: usize = 16;
/// Command and reply queue length.
pub const CMD_Q: usize = 4;

/// Everything the interrupt owns.
// `repr(C)`, the drive's loop last: its 4.7 kB put the queues' and the outputs' fields
// beyond a load's offset reach (each access took an address computation of its own)
#[repr(C)]
pub struct IsrState {
    /// Telemetry out.
    pub tel: Producer<'static, TelemetrySample, TEL_Q>,
    /// Commands in.
    pub cmd: Consumer<'static, ControlCommand, CMD_Q>,
    /// Replies out.
    pub reply: Producer<'static, CommandReply, CMD_Q>,
    /// Self-test: the simulated power stage.
    #[cfg(feature = "selftest")]
    pub sim: acim_firmware_core::sim::SimulatedStage,
    /// The start latch and whether the last period switched on (MOE set only on a
    /// deliberate off-to-on transition: `acim_firmware_core::stage`).
    #[cfg(not(feature = "selftest"))]
    pub outputs: acim_firmware_core::stage::Outputs,
    /// Drive, conversion and statistics.
    pub ctl: ControlLoop<Sc>,
}

// In SRAM1, not CCM: the interrupt's code runs from CCM SRAM over the I-bus while its
// data goes over the S-bus (both zero wait states), so fetches and loads do not contend,
// and CCM's 32 KiB stay for the code (the state outgrew the room beside it when the
// commissioning's accumulators doubled for its confidence bounds).
#[link_section = ".uninit.isr_state"]
static mut STATE: MaybeUninit<IsrState> = MaybeUninit::uninit();
static READY: AtomicBool = AtomicBool::new(false);

/// Periods run (the watchdog is fed only while this advances).
pub static HEARTBEAT: AtomicU32 = AtomicU32::new(0);
/// Drive state code of the last period (for the LED and `status`).
pub static STATE_CODE: AtomicU8 = AtomicU8::new(0);
/// A commissioning has finished and waits for the main loop
/// ([`take_finished_commissioning`]): the main loop masks interrupts only then.
pub static COMMISSION_FINISHED: AtomicBool = AtomicBool::new(false);
/// The bus of the last period, V (f32 bits), for the main loop's checks.
pub static DC_BUS_BITS: AtomicU32 = AtomicU32::new(0);
/// Fault code of the last period.
pub static FAULT_CODE: AtomicU8 = AtomicU8::new(0);
/// Telemetry samples dropped because the queue was full.
pub static TEL_DROPPED: AtomicU32 = AtomicU32::new(0);

/// Hands the state to the interrupt. Called once by `main` before the interrupt is
/// unmasked.
pub fn install(state: IsrState) {
    // SAFETY: called once, before the control interrupt is unmasked (READY is false and
    // the handler returns early until it is set), so no reference to STATE exists.
    unsafe { (*core::ptr::addr_of_mut!(STATE)).write(state) };
    READY.store(true, Ordering::Release);
}

/// Set while the main loop moves a rebuilt drive in: the interrupts then leave the state
/// alone (no reference to it) and keep the outputs off.
static SWAPPING: AtomicBool = AtomicBool::new(false);

/// Swaps in a drive rebuilt from new settings if the running one is Idle; otherwise the
/// state that refused it. The check and the claim ([`SWAPPING`]) run with interrupts
/// masked (a few loads: the control interrupt cannot start the drive between them); the
/// move of the whole drive (about 4.4 KB, 2800 instructions: it had held the interrupts
/// off for about 16 us) runs with them enabled, while the control interrupt, seeing the
/// claim, keeps the outputs off and returns (a period or two of the idle drive's offset
/// measurement skipped; the rebuilt drive measures its own).
pub fn replace_drive_if_idle(drive: acim::Drive<Sc>) -> Result<(), acim::DriveState> {
    cortex_m::interrupt::free(|_| match state() {
        Some(st) => st.ctl.can_replace_drive().map(|()| {
            SWAPPING.store(true, Ordering::SeqCst);
        }),
        None => Err(acim::DriveState::Fault),
    })?;
    // SWAPPING is set: no interrupt takes a reference to the state until it is cleared
    // (each checks it before `state()`), and none was running when it was set (the
    // claim ran with interrupts masked, and both interrupts preempt this loop and
    // finish before it resumes)
    let result = match state() {
        Some(st) => st.ctl.replace_drive(drive),
        None => Err(acim::DriveState::Fault),
    };
    SWAPPING.store(false, Ordering::Release);
    result
}

/// Hands the commissioning the main loop built (`commission::build`, from flash; `None`
/// if the library refused the nameplate) to the interrupt for the `Commission` command
/// that follows; interrupts are masked for the move (about 400 bytes), as for
/// [`take_finished_commissioning`].
pub fn stage_commissioning(c: Option<acim::commissioning::Commissioning>) {
    cortex_m::interrupt::free(|_| {
        if let Some(st) = state() {
            st.ctl.stage_commissioning(c);
        }
    });
}

/// Takes a finished commissioning (done or failed: the interrupt already switched off)
/// for its fits in the main loop. Interrupts are masked for the move (about 400 bytes).
pub fn take_finished_commissioning() -> Option<acim::commissioning::Commissioning> {
    if !COMMISSION_FINISHED.load(Ordering::Acquire) {
        return None;
    }
    let c = cortex_m::interrupt::free(|_| state()?.ctl.take_finished_commissioning());
    COMMISSION_FINISHED.store(false, Ordering::Release);
    c
}

/// The running commissioning's stage and its time in it, s (interrupts masked to read
/// them).
pub fn commissioning_progress() -> Option<(acim::commissioning::Stage, f32)> {
    cortex_m::interrupt::free(|_| {
        let c = state()?.ctl.commissioning()?;
        Some((c.stage(), c.stage_time()))
    })
}

#[inline(always)]
fn state() -> Option<&'static mut IsrState> {
    if !READY.load(Ordering::Acquire) {
        return None;
    }
    // SAFETY: STATE was initialised by `install` (READY is set after the write). After
    // `install` only the control interrupt takes this reference (it does not preempt
    // itself), the slow task's interrupt between `SLOW_GATE.enter` and `exit` (the control
    // interrupt, which preempts it, takes none then: `SlowTaskGate::control_entry`; the
    // slow interrupt never preempts the control one), `replace_drive_if_idle` (its check
    // with all interrupts masked, its move while SWAPPING keeps both interrupts out), and the
    // three commissioning accessors with all interrupts masked: the &mut is unique
    // for the duration of one invocation.
    Some(unsafe { (*core::ptr::addr_of_mut!(STATE)).assume_init_mut() })
}

/// Words of [`FIL_PROBE`].
#[cfg(feature = "selftest")]
pub const PROBE_WORDS: usize = 10;

/// Self-test: this period's step, for the firmware-in-the-loop harness that compares it
/// bit for bit with the host (`firmware/fil/test_fil.py`, class `BitExact`; the
/// `hostloop` example of acim-firmware-core prints the same words): period index, command
/// applied (0 none, 1 start, 2 speed, 3 load, 4 stop, 5 vf, 6 reset, 7 commission,
/// 8 rate), its argument (f32 bits), the three duties (f32 bits), outputs enabled, speed
/// estimate (rad/s, f32 bits), rotor flux estimate (Wb, f32 bits), model speed (rpm, f32
/// bits).
/// Plain RAM the interrupt overwrites each period (ten stores); nothing reads it.
#[cfg(feature = "selftest")]
#[no_mangle]
pub static FIL_PROBE: [AtomicU32; PROBE_WORDS] = [const { AtomicU32::new(0) }; PROBE_WORDS];

#[cfg(feature = "selftest")]
#[inline(always)]
fn probe(st: &IsrState, cmd: Option<ControlCommand>, out: &acim::PwmOutput) {
    let (code, arg) = match cmd {
        None => (0, 0.0),
        Some(ControlCommand::Start) => (1, 0.0),
        Some(ControlCommand::SpeedRpm(rpm)) => (2, rpm),
        Some(ControlCommand::PlantLoad(nm)) => (3, nm),
        Some(ControlCommand::Stop) => (4, 0.0),
        Some(ControlCommand::StartOpenLoop) => (5, 0.0),
        Some(ControlCommand::ResetFault) => (6, 0.0),
        Some(ControlCommand::Commission(_)) => (7, 0.0),
        Some(ControlCommand::Rate(n)) => (8, n as f32),
    };
    let t = st.ctl.drive().telemetry();
    let words = [
        HEARTBEAT.load(Ordering::Relaxed),
        code,
        f32::to_bits(arg),
        out.duties[0].to_bits(),
        out.duties[1].to_bits(),
        out.duties[2].to_bits(),
        out.enabled as u32,
        t.speed_estimate.to_bits(),
        t.rotor_flux.to_bits(),
        st.sim.speed_rpm().to_bits(),
    ];
    for (p, w) in FIL_PROBE.iter().zip(words) {
        p.store(w, Ordering::Relaxed);
    }
}

#[cfg(feature = "selftest")]
#[inline(always)]
fn commands(st: &mut IsrState) -> Option<ControlCommand> {
    let cmd = st.cmd.dequeue()?;
    if let ControlCommand::PlantLoad(nm) = cmd {
        st.sim.set_brake_nm(nm);
    }
    let r = st.ctl.apply(cmd);
    let _ = st.reply.enqueue(r);
    Some(cmd)
}

#[inline(never)]
fn publish(st: &mut IsrState, cycles: u32, plant_speed_rpm: f32) {
    if let Some(s) = st.ctl.finish_period(cycles, plant_speed_rpm) {
        if st.tel.enqueue(s).is_err() {
            TEL_DROPPED.fetch_add(1, Ordering::Relaxed);
        }
    }
    let code = st.ctl.state_code();
    if code == acim_firmware_core::control::STATE_COMMISSIONING {
        // switched off while still holding it: done or failed, the fits are the main loop's
        COMMISSION_FINISHED.store(!st.ctl.switching(), Ordering::Release);
    }
    STATE_CODE.store(code, Ordering::Relaxed);
    DC_BUS_BITS.store(st.ctl.inputs().dc_bus.to_bits(), Ordering::Relaxed);
    FAULT_CODE.store(st.ctl.fault_code(), Ordering::Relaxed);
    HEARTBEAT.fetch_add(1, Ordering::Release);
}

#[cfg(not(feature = "selftest"))]
#[interrupt]
fn ADC1_2() {
    let t0 = DWT::cycle_count();
    let mut io = hw::Tim1Adc {
        arr: PWM_ARR,
        max_duty: MAX_DUTY,
    };
    let entry = SLOW_GATE.control_entry();
    if entry == ControlEntry::SlowTaskBusy {
        // the slow task overran into this period and holds the drive: outputs off now,
        // the drive untouched; the next period trips it
        io.switch_off();
        io_ack(&mut io);
        return;
    }
    if SWAPPING.load(Ordering::Acquire) {
        // the main loop is moving a rebuilt drive in (the running one was Idle, outputs
        // off): keep them off, leave the state alone
        io.switch_off();
        io_ack(&mut io);
        return;
    }
    let Some(st) = state() else {
        // not installed yet: only acknowledge
        io_ack(&mut io);
        return;
    };
    if entry == ControlEntry::SlowTaskOverran {
        st.ctl.trip(FirmwareFault::DeadlineMissed);
    }
    // at most one command per period; a start arms the outputs, an accepted reset
    // clears breaks
    if let Some(cmd) = st.cmd.dequeue() {
        let r = apply_command(&mut st.ctl, &mut io, &mut st.outputs, cmd);
        let _ = st.reply.enqueue(r);
    }
    // flags read before acknowledging, break checks, step, PWM write (MOE set only on an
    // armed off-to-on transition with no break flag), deadline check:
    // acim_firmware_core::stage::control_period
    control_period(&mut st.ctl, &mut io, &mut st.outputs);
    let t1 = DWT::cycle_count();
    publish(st, elapsed(t0, t1), 0.0);
}

/// The slow task's interrupt: a slow tick's work, pended by the control interrupt, at a
/// lower priority; its code runs from flash (ccmram.x).
#[cfg(not(feature = "selftest"))]
#[interrupt]
fn FMAC() {
    SLOW_GATE.enter();
    if !SWAPPING.load(Ordering::Acquire) {
        if let Some(st) = state() {
            slow_period(&mut st.ctl);
        }
    }
    SLOW_GATE.exit();
}

#[cfg(not(feature = "selftest"))]
#[inline(always)]
fn io_ack(io: &mut hw::Tim1Adc) {
    use acim_firmware_core::stage::PowerStageIo;
    io.acknowledge();
}

#[cfg(feature = "selftest")]
#[interrupt]
fn TIM6_DACUNDER() {
    let t0 = DWT::cycle_count();
    crate::hw::tim6_ack();
    if SWAPPING.load(Ordering::Acquire) {
        // a rebuilt drive is being moved in (replace_drive_if_idle): the simulated stage
        // is idle with the outputs off; leave the state alone
        return;
    }
    let Some(st) = state() else { return };
    let cmd = commands(st);
    let raw = st.sim.sample();
    let out = st.ctl.step(&raw);
    let t1 = DWT::cycle_count();
    // the model is the power stage: it runs outside the measured step
    st.sim.run_period(out);
    probe(st, cmd, &out);
    if crate::hw::tim6_update_pending() {
        st.ctl.trip(FirmwareFault::DeadlineMissed);
        st.sim.switch_off();
    }
    let speed = st.sim.speed_rpm();
    publish(st, elapsed(t0, t1), speed);
}
