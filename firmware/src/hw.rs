//! The one module with direct register access: what stm32g4xx-hal 0.1.0 does not offer.
//!
//! - The board profile's gate enables (GPIO BSRR/MODER; only boards that have them) and
//!   TIM1 output polarity (`acim_firmware_core::board::BOARD`).
//! - TIM1: safe off-state (MOE, OSSI/OSSR, idle levels), TRGO2 = OC4REF as the ADC
//!   trigger at the sampling instant, one update event per period (RCR), compare writes,
//!   main-output control and the break flag.
//! - ADC1/ADC2: power-up, calibration and injected conversions triggered by TIM1 TRGO2.
//! - The hardware over-current path: COMPx with DAC3/DAC4 thresholds on the current-sense
//!   amplifier outputs into TIM1's break 2 (the board profile's `hardware_trip`).
//! - NVIC priority/unmask of the control interrupt.
//! - TIM6 flags for the self-test's period interrupt.
//! - The main loop's period count (TIM1's update flag), the UART's receive flush and the
//!   last-words line of a fatal error, flash prefetch.
//!
//! Soundness, common to every `unsafe` below: the peripherals are used by exactly one
//! context at a time. `main` configures them before the control interrupt is unmasked;
//! afterwards only the control interrupt touches TIM1/ADC/TIM6 registers, except
//! [`emergency_off`], which the panic and HardFault handlers call with interrupts
//! disabled (or from a fault that cannot be preempted by the control interrupt). The
//! HAL's TIM1/TIM6 objects do not touch these registers after their set-up. Register
//! pointers come from the PAC and are valid for the whole program.

use acim_firmware_core::board::BOARD;
use acim_firmware_core::convert::{duty_to_compare, RawSample};
use acim_firmware_core::profile::Signal;
use acim_firmware_core::stage::PowerStageIo;
use stm32g4xx_hal::pac;

/// The board's gate-enable pins as (GPIO base address, pin mask), if it has them (the
/// X-NUCLEO-IHM16M1's EN1..3): all on one port (checked below).
const ENABLE: Option<(u32, u32)> = match BOARD.gates.enable() {
    Some([a, b, c]) => {
        assert!(
            a.port as u8 == b.port as u8 && b.port as u8 == c.port as u8,
            "the enable pins must share a port"
        );
        Some((a.gpio_base(), (1 << a.n) | (1 << b.n) | (1 << c.n)))
    }
    None => None,
};

/// Drives the board's gate-enable pins (none on boards without them): on only together
/// with MOE, so that a phase input at its idle level (low: the low side on, for an
/// input/enable driver) never reaches a switch while the outputs are meant off.
#[inline(always)]
fn gate_enable(on: bool) {
    if let Some((base, mask)) = ENABLE {
        // SAFETY: BSRR is a write-only set/reset register: one store sets (low half) or
        // resets (high half) exactly these pins, atomically, from any context; no other
        // code drives them (main configures them once, before TIM1).
        unsafe {
            let bsrr = (base + 0x18) as *mut u32;
            core::ptr::write_volatile(bsrr, if on { mask } else { mask << 16 });
        }
    }
}

/// The gate-enable pins as push-pull outputs, driven low (disabled) first, before TIM1 is
/// set up (boards without enables: nothing).
pub fn gate_enable_init() {
    if let Some((base, mask)) = ENABLE {
        gate_enable(false);
        // SAFETY: start-up, single-threaded: a read-modify-write of this port's MODER
        // (0b01, general-purpose output, for the enable pins only); the HAL never takes
        // these pins. OTYPER stays push-pull (reset value).
        unsafe {
            let moder = base as *mut u32;
            let mut v = core::ptr::read_volatile(moder);
            for n in 0..16 {
                if mask & (1 << n) != 0 {
                    v = (v & !(0b11 << (2 * n))) | (0b01 << (2 * n));
                }
            }
            core::ptr::write_volatile(moder, v);
        }
    }
}

/// The board's output polarity (CCxP/CCxNP in TIM1_CCER; the L6390's active-low LIN),
/// after the HAL enabled the channels. Nothing to write for active-high inputs.
pub fn tim1_polarity() {
    let bits = BOARD.gates.ccer_polarity();
    if bits != 0 {
        // SAFETY: a read-modify-write adding polarity bits only, at start-up with MOE
        // clear (the outputs at their idle levels)
        tim1()
            .ccer()
            .modify(|r, w| unsafe { w.bits(r.bits() | bits) });
    }
}

#[inline(always)]
fn tim1() -> &'static pac::tim1::RegisterBlock {
    // SAFETY: valid, 'static MMIO block (module doc for exclusivity).
    unsafe { &*pac::TIM1::ptr() }
}

#[inline(always)]
fn adc1() -> &'static pac::adc1::RegisterBlock {
    // SAFETY: valid, 'static MMIO block (module doc for exclusivity).
    unsafe { &*pac::ADC1::ptr() }
}

#[inline(always)]
fn adc2() -> &'static pac::adc1::RegisterBlock {
    // SAFETY: valid, 'static MMIO block (ADC2 has ADC1's layout).
    unsafe { &*pac::ADC2::ptr() }
}

/// Disables TIM1's main output: all switches off (each output at its off level; a board's
/// gate enables dropped first) after the dead time, from any context. Used by the panic,
/// fault and NMI handlers and the main loop's interrupt watch.
#[inline(always)]
pub fn emergency_off() {
    // SAFETY: a read-modify-write of BDTR clearing MOE only; called with interrupts
    // disabled or from HardFault, so nothing interleaves. Clearing MOE is always safe
    // (and harmless if TIM1 was never enabled: the register then reads as 0).
    let t = unsafe { &*pac::TIM1::ptr() };
    gate_enable(false);
    t.bdtr().modify(|_, w| w.moe().clear_bit());
}

/// Right after the HAL's `finalize` (which sets MOE): main output off, off-state
/// selection so that a disabled output drives the idle level (switch off) instead of
/// floating, idle levels at each output's off level (the board profile's: low for
/// active-high inputs, high for active-low ones).
pub fn tim1_safe_state() {
    let t = tim1();
    // SAFETY (bits): BKF is a 4-bit filter code (board::BREAK_FILTER, checked < 16)
    t.bdtr().modify(|_, w| unsafe {
        w.moe()
            .clear_bit()
            .ossi()
            .set_bit()
            .ossr()
            .set_bit()
            .bkf()
            .bits(acim_firmware_core::board::BREAK_FILTER)
    });
    // OIS1..OIS3N are CR2 bits 8..13
    let idle = BOARD.gates.idle_bits();
    // SAFETY: only the six idle-state bits change
    t.cr2()
        .modify(|r, w| unsafe { w.bits((r.bits() & !0x3F00) | idle) });
}

/// Sampling trigger and period structure, then (re)starts the counter:
/// - CH4 in PWM mode 2 with CCR4 = `trigger`: OC4REF rises when the up-counting counter
///   reaches CCR4, just before the peak (mid low-side-on);
/// - TRGO2 = OC4REF (MMS2 = 0b0111) -> ADC injected trigger;
/// - RCR = 1, written before the counter starts: one update event per period, at the
///   overflow (peak), so compare values written by the step load at the next peak and act
///   over one whole period (the drive's 1.5-period delay model);
/// - compare values at 50 %, outputs still off (MOE = 0).
pub fn tim1_start(arr: u16, trigger: u16) {
    let t = tim1();
    t.cr1().modify(|_, w| w.cen().clear_bit());
    // SAFETY (bits): OC4M = 0b0111 is PWM mode 2, a valid encoding of the 4-bit field
    // (bit 3 = 0 selects the classic modes).
    t.ccmr2_output()
        .modify(|_, w| unsafe { w.oc4m().bits(0b0111).oc4pe().set_bit() });
    t.ccr4().write(|w| unsafe { w.ccr().bits(trigger as u32) }); // SAFETY: any 16-bit value
    let half = (arr / 2) as u32;
    // SAFETY: compare values are any 16-bit count
    t.ccr1().write(|w| unsafe { w.ccr().bits(half) });
    t.ccr2().write(|w| unsafe { w.ccr().bits(half) });
    t.ccr3().write(|w| unsafe { w.ccr().bits(half) });
    // SAFETY: MMS2 = 0b0111 (OC4REF as TRGO2) is a valid 4-bit encoding.
    t.cr2().modify(|_, w| unsafe { w.mms2().bits(0b0111) });
    // SAFETY: REP is a plain 16-bit count.
    t.rcr().write(|w| unsafe { w.rep().bits(1) });
    t.cnt().write(|w| unsafe { w.cnt().bits(0) }); // SAFETY: any count
    t.egr().write(|w| w.ug().set_bit());
    // clear every status flag (UG sets UIF; a stale break flag must not trip at start)
    // SAFETY: writing 0 to rc_w0 flags only clears them.
    t.sr().write(|w| unsafe { w.bits(0) });
    t.cr1().modify(|_, w| w.cen().set_bit());
}

/// TIM1_SR: break (BIF), break 2 (B2IF) and system break (SBIF) flags.
const BREAK_FLAGS: u32 = (1 << 7) | (1 << 8) | (1 << 13);

/// The break input, break 2 or the system break (lockup, ECC, SRAM parity, PVD: see
/// [`link_system_break`]) fired since the flags were last cleared; the hardware has
/// already cleared MOE (AOE = 0 keeps it cleared).
#[inline(always)]
pub fn break_flag() -> bool {
    tim1().sr().read().bits() & BREAK_FLAGS != 0
}

/// Clears the break flags (on an accepted fault reset only; if the break line is still
/// active the flag sets again at once and the drive trips again).
pub fn clear_break_flags() {
    // SAFETY: rc_w0 flags: writing 1 leaves a flag unchanged, 0 clears it.
    tim1().sr().write(|w| unsafe { w.bits(!BREAK_FLAGS) });
}

/// A PWM period passed since the last call: TIM1's update flag (one update per period,
/// RCR = 1), read and cleared. Main loop only: the control interrupt never reads UIF, and
/// its only SR write ([`clear_break_flags`]) writes 1 to UIF, which leaves it unchanged.
pub fn take_period_flag() -> bool {
    let t = tim1();
    if t.sr().read().uif().bit_is_clear() {
        return false;
    }
    // SAFETY: rc_w0 flags: writing 0 clears UIF, the 1s leave every other flag as it is
    // (a break flag set meanwhile is not lost)
    t.sr().write(|w| unsafe { w.bits(!1) });
    true
}

/// Discards the USART2 receive FIFO (RQR.RXFRQ): after an overrun its bytes are the start
/// of a line whose rest was lost.
pub fn uart_flush_rx() {
    // SAFETY: RQR is a write-only request register; RXFRQ only empties the RX FIFO. The
    // main loop owns USART2 (the HAL's Rx does not cache anything).
    let u = unsafe { &*pac::USART2::ptr() };
    u.rqr().write(|w| w.rxfrq().set_bit());
}

/// The last words of a fatal error on the UART (review N8: boot failures and panics were
/// on RTT only): `fatal <what><detail>; switches off\r\n`, written directly to USART2 with
/// a bounded wait per byte. Does nothing before the UART is enabled.
#[inline(never)]
pub fn uart_fatal(what: &[u8], detail: &[u8]) {
    // SAFETY: called with the outputs already off, on the way to a halt or a watchdog
    // reset; the main loop's UART objects are not used again. Reads of CR1/ISR, writes of
    // TDR only.
    let u = unsafe { &*pac::USART2::ptr() };
    if u.cr1().read().ue().bit_is_clear() {
        return;
    }
    for part in [
        b"\r\nfatal ".as_slice(),
        what,
        detail,
        b"; switches off\r\n",
    ] {
        for &b in part {
            // TXFNF (bit 7 in FIFO mode); about 87 us per byte at 115 200 baud
            let mut n = 0u32;
            while u.isr().read().bits() & (1 << 7) == 0 && n < 100_000 {
                n += 1;
            }
            // SAFETY: any byte may be written to TDR
            u.tdr().write(|w| unsafe { w.bits(b as u32) });
        }
    }
}

/// Flash prefetch on (FLASH_ACR.PRFTEN; review D12), after the HAL has set the wait
/// states; the instruction and data caches stay on.
pub fn flash_prefetch_on() {
    // SAFETY: a read-modify-write of PRFTEN only, at start-up (single-threaded)
    let f = unsafe { &*pac::FLASH::ptr() };
    f.acr().modify(|_, w| w.prften().set_bit());
}

/// TIM1 and ADC1/2 as the control interrupt's power stage (the sequence itself, with its
/// ordering rules, is `acim_firmware_core::stage`, host-tested).
pub struct Tim1Adc {
    /// TIM1 auto-reload value.
    pub arr: u16,
    /// Largest high-side duty.
    pub max_duty: f32,
}

impl PowerStageIo for Tim1Adc {
    #[inline(always)]
    fn conversions_done(&self) -> (bool, bool) {
        (
            adc1().isr().read().jeos().bit_is_set(),
            adc2().isr().read().jeos().bit_is_set(),
        )
    }
    #[inline(always)]
    fn read(&self) -> RawSample {
        adc_read()
    }
    #[inline(always)]
    fn acknowledge(&mut self) {
        adc_ack();
    }
    #[inline(always)]
    fn sequence_pending(&self) -> bool {
        adc_sequence_pending()
    }
    #[inline(always)]
    fn break_flag(&self) -> bool {
        break_flag()
    }
    fn clear_break_flags(&mut self) {
        clear_break_flags();
    }
    #[inline(always)]
    fn outputs_enabled(&self) -> bool {
        outputs_enabled()
    }
    fn enable_outputs(&mut self) {
        // re-check the flags right before the write: MOE cannot be set while a level
        // break is active, and a latched pulse must not be armed over
        if !break_flag() {
            tim1().bdtr().modify(|_, w| w.moe().set_bit());
            gate_enable(true);
        }
    }
    /// Compare values (preloaded: act from the next period). Never touches MOE.
    #[inline(always)]
    fn write_duties(&mut self, duties: [f32; 3]) {
        let t = tim1();
        let [a, b, c] = duties;
        let (arr, m) = (self.arr, self.max_duty);
        // SAFETY: compare values are any 16-bit count (duty_to_compare returns <= arr)
        t.ccr1()
            .write(|w| unsafe { w.ccr().bits(duty_to_compare(a, arr, m) as u32) });
        t.ccr2()
            .write(|w| unsafe { w.ccr().bits(duty_to_compare(b, arr, m) as u32) });
        t.ccr3()
            .write(|w| unsafe { w.ccr().bits(duty_to_compare(c, arr, m) as u32) });
    }
    /// MOE cleared at once (switches off within this period, after the dead time) and
    /// compare values back to 50 %.
    #[inline(always)]
    fn switch_off(&mut self) {
        let t = tim1();
        gate_enable(false);
        t.bdtr().modify(|_, w| w.moe().clear_bit());
        let half = (self.arr / 2) as u32;
        // SAFETY: any 16-bit count
        t.ccr1().write(|w| unsafe { w.ccr().bits(half) });
        t.ccr2().write(|w| unsafe { w.ccr().bits(half) });
        t.ccr3().write(|w| unsafe { w.ccr().bits(half) });
    }

    /// Pends the slow task's interrupt ([`SLOW_TASK_IRQ`]): NVIC_ISPR, a write the NVIC
    /// takes atomically.
    #[inline(always)]
    fn pend_slow_task(&mut self) {
        cortex_m::peripheral::NVIC::pend(SLOW_TASK_IRQ);
    }
}

/// The slow task's interrupt: FMAC's vector, pended by software only (the filter
/// accelerator is not used and its interrupt is never enabled in the peripheral).
pub const SLOW_TASK_IRQ: pac::Interrupt = pac::Interrupt::FMAC;

/// The slow task's NVIC priority: below the control interrupt's (0), above the main loop.
pub const SLOW_TASK_PRIORITY: u8 = 0x80;

/// Sets the slow task's interrupt priority below the control interrupt's and unmasks it.
pub fn nvic_enable_slow_task(nvic: &mut cortex_m::peripheral::NVIC) {
    // SAFETY: as for `nvic_enable_top`: no priority-based critical section exists; the
    // slow interrupt shares the drive with the control interrupt through
    // `stage::SlowTaskGate`, which does not depend on priorities beyond the control
    // interrupt's preempting this one.
    unsafe { nvic.set_priority(SLOW_TASK_IRQ, SLOW_TASK_PRIORITY) };
    // SAFETY: everything its handler uses is initialised before (see main).
    unsafe { cortex_m::peripheral::NVIC::unmask(SLOW_TASK_IRQ) };
}

/// The clock registers read back after the HAL's set-up (checked by
/// `acim_firmware_core::clock::check`).
pub fn clock_registers() -> acim_firmware_core::clock::ClockRegisters {
    // SAFETY: read-only accesses of RCC, FLASH and PWR configuration registers, at
    // start-up (single-threaded); the HAL owns them but no longer writes them.
    let (rcc, flash, pwr) = unsafe { (&*pac::RCC::ptr(), &*pac::FLASH::ptr(), &*pac::PWR::ptr()) };
    acim_firmware_core::clock::ClockRegisters {
        rcc_cfgr: rcc.cfgr().read().bits(),
        rcc_pllcfgr: rcc.pllcfgr().read().bits(),
        flash_acr: flash.acr().read().bits(),
        pwr_cr1: pwr.cr1().read().bits(),
        pwr_cr5: pwr.cr5().read().bits(),
    }
}

/// The stack guard (review D16): MPU region 0 made a 32-byte no-access region on the
/// statics' end (`board::stack_guard_region`), the MPU enabled with the default map
/// elsewhere, and the MemManage fault enabled so that an overflow runs its handler
/// (outputs off) rather than escalating. Written once at start-up, before any interrupt
/// is unmasked.
pub fn stack_guard(mpu: &mut cortex_m::peripheral::MPU, scb: &mut cortex_m::peripheral::SCB) {
    extern "C" {
        // cortex-m-rt's link.x: the end of .bss/.uninit, where the (unused) heap would
        // start; above it only the main stack, growing down from the top of SRAM
        static __sheap: u32;
    }
    // only the symbol's address is taken, never its value
    let end = core::ptr::addr_of!(__sheap) as u32;
    let (rbar, rasr) = acim_firmware_core::board::stack_guard_region(end);
    // SAFETY: MPU programming at start-up with interrupts masked; region 0 is the only
    // region used, the default map stays in force elsewhere (PRIVDEFENA), and the
    // barriers make the new map effective before the next access.
    unsafe {
        mpu.rnr.write(0);
        mpu.rbar.write(rbar);
        mpu.rasr.write(rasr);
        mpu.ctrl.write(acim_firmware_core::board::MPU_CTRL_GUARD);
    }
    scb.enable(cortex_m::peripheral::scb::Exception::MemoryManagement);
    cortex_m::asm::dsb();
    cortex_m::asm::isb();
}

/// Debug halts stop TIM1 (outputs to their off-state) and the watchdog, so a breakpoint
/// during bring-up leaves the bridge off instead of switching at a frozen duty (review
/// D6). Written once at start-up.
pub fn freeze_on_debug_halt() {
    // SAFETY: DBGMCU is only written here, at start-up (single-threaded).
    let dbg = unsafe { &*pac::DBGMCU::ptr() };
    dbg.apb2_fz().modify(|_, w| w.dbg_tim1_stop().set_bit());
    dbg.apb1l_fz().modify(|_, w| w.dbg_iwdg_stop().set_bit());
}

/// Routes core lockup (CLL), SRAM parity (SPL), PVD (PVDL) and flash ECC (ECCL) events
/// to TIM1's system break in hardware, so they switch the bridge off even when no
/// handler can run (review D7). SYSCFG's clock is enabled first. The lock bits are
/// write-once until reset.
pub fn link_system_break() {
    // SAFETY: init only, single-threaded: RCC read-modify-write of SYSCFGEN only.
    let rcc = unsafe { &*pac::RCC::ptr() };
    rcc.apb2enr().modify(|_, w| w.syscfgen().set_bit());
    // the enable takes effect before the next access
    let _ = rcc.apb2enr().read();
    // SAFETY: SYSCFG is only written here, at start-up; the lock bits only add break
    // sources.
    let syscfg = unsafe { &*pac::SYSCFG::ptr() };
    syscfg.cfgr2().modify(|_, w| {
        w.cll()
            .set_bit()
            .spl()
            .set_bit()
            .pvdl()
            .set_bit()
            .eccl()
            .set_bit()
    });
}

/// DAC3 and DAC4 (AHB2): the internal-only DACs of the G474 (RM0440, chapter "Digital-to-analog
/// converter (DAC)"; the addresses as in the `stm32g4` PAC's `DAC3`/`DAC4`).
const DAC3: u32 = 0x5000_1000;
const DAC4: u32 = 0x5000_1400;

/// The DAC register block of DAC 3 or 4.
fn dac(n: u8) -> &'static pac::dac1::RegisterBlock {
    let base = if n == 3 { DAC3 } else { DAC4 };
    // SAFETY: DAC3 and DAC4 share DAC1's register layout (the PAC's `DAC3`/`DAC4` are
    // `dac1::RegisterBlock` at these addresses); valid for the whole program.
    unsafe { &*(base as *const pac::dac1::RegisterBlock) }
}

/// Sets the hardware over-current comparators' threshold for a trip of `level_a` A (the
/// drive's trip, `acim::hardware_trip::hardware_trip_level`): the DAC code of the
/// amplifier output at that current (`comparator_threshold`, from the board's
/// measurement chain). A level the chain cannot represent leaves the previous code (the
/// settings' bounds keep the trip inside the sense range). Nothing on a board without a
/// hardware trip. Main context only: the control interrupt never touches the DACs.
pub fn set_hardware_trip(level_a: f32) {
    let Some(h) = BOARD.hardware_trip else { return };
    let Ok(t) = acim_firmware_core::profile::comparator_threshold(&BOARD.stage, level_a) else {
        return;
    };
    for (n, ch) in h.dac_channels().into_iter().flatten() {
        // SAFETY (bits): a 12-bit code (comparator_threshold keeps it below 4095)
        let d = dac(n);
        if ch == 1 {
            d.dhr12r1()
                .write(|w| unsafe { w.bits(t.dac_counts as u32) });
        } else {
            d.dhr12r2()
                .write(|w| unsafe { w.bits(t.dac_counts as u32) });
        }
    }
}

/// Configures the board's hardware over-current path (none without one), with MOE clear
/// and before the outputs are ever enabled:
/// 1. RCC_AHB2ENR.DAC3EN/DAC4EN (RM0440, RCC chapter) for the DACs the comparators use;
///    the comparators are clocked with SYSCFG (APB2ENR.SYSCFGEN, set by
///    [`link_system_break`], which runs first);
/// 2. each DAC channel: DAC_MCR.HFSEL = 0b10 (AHB clock above 160 MHz) and MODEx = 0b011
///    (normal mode, on-chip peripherals only, buffer off: DAC3/DAC4 have no pin), then the
///    code ([`set_hardware_trip`]), then DAC_CR.ENx and a bounded wait for
///    DAC_SR.DACxRDY (RM0440, DAC chapter: DAC_MCR, DAC_CR, DAC_SR);
/// 3. each comparator: COMPx_CSR with INPSEL on its amplifier pin (already analog),
///    INMSEL = 0b100 (its DAC3/DAC4 channel), POL for an amplifier that falls with the
///    motor current, 10 mV hysteresis, no blanking, EN (RM0440, chapter "Comparator
///    (COMP)", COMPx_CSR; field layout as in the `stm32g4` PAC);
/// 4. TIM1_AF2: BK2CMPxE for each comparator, BK2INE off (no break-2 pin), BK2CMPxP = 0
///    (RM0440 section 29, advanced-control timers, TIMx_AF2);
/// 5. TIM1_BDTR: BK2F (the profile's filter), BK2P = 1 (a comparator output is active
///    high), BK2E = 1 (RM0440 section 29, TIMx_BDTR). From here a comparator crossing clears MOE
///    in hardware and sets SR.B2IF, which [`break_flag`] reports to the drive as
///    `HardwareBreak`.
///
/// Returns false if a DAC did not report ready (the caller halts with the outputs off).
pub fn hardware_trip_init(level_a: f32) -> bool {
    let Some(h) = BOARD.hardware_trip else {
        return true;
    };
    // SAFETY: init only, single-threaded: RCC read-modify-write of the DAC enables only.
    let rcc = unsafe { &*pac::RCC::ptr() };
    let uses = |n: u8| h.dac_channels().into_iter().flatten().any(|(d, _)| d == n);
    rcc.ahb2enr()
        .modify(|_, w| w.dac3en().bit(uses(3)).dac4en().bit(uses(4)));
    // the enable takes effect before the next access
    let _ = rcc.ahb2enr().read();
    let channels = h.dac_channels();
    for (n, ch) in channels.into_iter().flatten() {
        let d = dac(n);
        // SAFETY (bits): HFSEL = 0b10 and MODEx = 0b011 are valid encodings of their
        // fields (HFSEL bits 15:14; MODE1 bits 2:0, MODE2 bits 18:16), written while the
        // channel is disabled, as MODEx requires.
        d.mcr().modify(|r, w| unsafe {
            let mode = if ch == 1 { 0b011 } else { 0b011 << 16 };
            let keep = if ch == 1 { !0b111 } else { !(0b111 << 16) };
            w.bits((r.bits() & keep & !(0b11 << 14)) | (0b10 << 14) | mode)
        });
    }
    set_hardware_trip(level_a);
    for (n, ch) in channels.into_iter().flatten() {
        let d = dac(n);
        // SAFETY (bits): EN1 is bit 0, EN2 bit 16
        d.cr()
            .modify(|r, w| unsafe { w.bits(r.bits() | if ch == 1 { 1 } else { 1 << 16 }) });
        // DACxRDY: bit 11 (channel 1), bit 27 (channel 2); a few microseconds after EN
        let rdy = if ch == 1 { 1 << 11 } else { 1 << 27 };
        if !wait(|| d.sr().read().bits() & rdy != 0) {
            return false;
        }
    }
    let threshold = acim_firmware_core::profile::comparator_threshold(&BOARD.stage, level_a);
    let inverted = threshold.map_or(BOARD.stage.current_sign < 0.0, |t| t.inverted);
    // SAFETY: COMP shares its APB2 clock with SYSCFG (enabled); init only.
    let comp = unsafe { &*pac::COMP::ptr() };
    let mut af2 = 0u32;
    for c in h.comparators {
        let k = c.comp as usize;
        // SAFETY (bits): INMSEL = 0b100 and HYST = 0b001 are valid 3-bit encodings;
        // the comparator index is 1..=7 (the profile's check).
        comp.ccsr(k - 1).write(|w| unsafe {
            w.inpsel()
                .bit(c.io2)
                .inmsel()
                .bits(acim_firmware_core::profile::COMP_INMSEL_DAC34 as u8)
                .pol()
                .bit(inverted)
                .hyst()
                .bits(0b001)
                .en()
                .set_bit()
        });
        af2 |= 1 << k; // BK2CMPxE: bits 1..7
    }
    let t = tim1();
    // SAFETY (bits): only BK2CMPxE set; BK2INE (bit 0), BK2INP and BK2CMPxP clear.
    t.af2().write(|w| unsafe { w.bits(af2) });
    // SAFETY (bits): BK2F is a 4-bit code (the profile's check keeps it below 16)
    t.bdtr()
        .modify(|_, w| unsafe { w.bk2f().bits(h.filter).bk2p().set_bit().bk2e().set_bit() });
    // a B2IF latched by the comparators' enable transient must not trip the idle drive
    // (with MOE clear there was no current to cut); a level still active (an amplifier
    // without supply reads below the threshold) sets it again at once, and the drive then
    // reports `HardwareBreak`, as for BKIN.
    // SAFETY: rc_w0 flags: writing 1 leaves a flag unchanged, 0 clears it: every flag of
    // TIM1_SR (bits 0-13, 16-17, 20-23; the reserved bits stay 0) written 1 but B2IF (bit 8).
    t.sr().write(|w| unsafe { w.bits(0x00F3_3FFF & !(1 << 8)) });
    true
}

/// Whether the main output is on.
pub fn outputs_enabled() -> bool {
    tim1().bdtr().read().moe().bit_is_set()
}

/// Injected channel sequences (channel numbers of ADC1 and ADC2, two ranks each).
pub struct InjectedChannels {
    /// ADC1 rank 1, rank 2.
    pub adc1: [u8; 2],
    /// ADC2 rank 1, rank 2.
    pub adc2: [u8; 2],
    /// The bus divider's channel and ADC (1 or 2): the longer sampling time.
    pub slow: (u8, u8),
}

impl InjectedChannels {
    /// The board profile's plan.
    pub const fn of_board() -> Self {
        let a = BOARD.adc;
        Self {
            adc1: [a.adc1[0].channel, a.adc1[1].channel],
            adc2: [a.adc2[0].channel, a.adc2[1].channel],
            slow: a.bus(),
        }
    }
}

/// Powers up, calibrates and enables ADC1 and ADC2 (independent mode, synchronous clock
/// HCLK/4 = 42.5 MHz, 12 bits), and arms their injected sequences on TIM1 TRGO2 (rising
/// edge). `delay_us` is a busy-wait. Returns false if a step timed out.
pub fn adc_init(ch: &InjectedChannels, mut delay_us: impl FnMut(u32)) -> bool {
    // SAFETY: RCC is shared with the HAL's `Rcc`, but only during single-threaded init;
    // these are read-modify-writes of ADC12's own enable and clock-select bits.
    let rcc = unsafe { &*pac::RCC::ptr() };
    rcc.ahb2enr().modify(|_, w| w.adc12en().set_bit());
    // SAFETY: ADC12SEL = 0b10 (system clock) is a valid encoding (only used for async mode)
    rcc.ccipr()
        .modify(|_, w| unsafe { w.adc12sel().bits(0b10) });
    // SAFETY: ADC1/2 common registers, init only. CKMODE = 0b11: HCLK/4 (<= 60 MHz);
    // DUAL = 0: independent (both ADCs take the same TIM1 TRGO2 edge).
    let common = unsafe { &*pac::ADC12_COMMON::ptr() };
    common
        .ccr()
        .modify(|_, w| unsafe { w.ckmode().bits(0b11).dual().bits(0) });

    let mut ok = true;
    for (number, adc, chans) in [(1, adc1(), ch.adc1), (2, adc2(), ch.adc2)] {
        adc.cr().modify(|_, w| w.deeppwd().clear_bit());
        adc.cr().modify(|_, w| w.advregen().set_bit());
        delay_us(30); // t_ADCVREG_STUP = 20 us
        adc.cr().modify(|_, w| w.adcaldif().clear_bit());
        adc.cr().modify(|_, w| w.adcal().set_bit());
        ok &= wait(|| adc.cr().read().adcal().bit_is_clear());
        delay_us(2);
        adc.isr().write(|w| w.adrdy().clear()); // clear (rc_w1)
        adc.cr().modify(|_, w| w.aden().set_bit());
        ok &= wait(|| adc.isr().read().adrdy().bit_is_set());
        // 12-bit right-aligned; injected queue disabled (JSQR acts directly)
        // SAFETY: RES = 0 is 12 bits
        adc.cfgr()
            .modify(|_, w| unsafe { w.res().bits(0).jqdis().set_bit() });
        // sampling times: 24.5 cycles (0.58 us) on the current channels, longer on the
        // bus divider's channel (ch.slow: its source impedance, review D11)
        for c in chans {
            let smp = if (c, number) == ch.slow {
                acim_firmware_core::board::BUS_SMP
            } else {
                0b011
            };
            if c <= 9 {
                // SAFETY: SMPx is a 3-bit code (board constants < 8), c in 0..=9
                adc.smpr1().modify(|_, w| unsafe { w.smp(c).bits(smp) });
            } else {
                // SAFETY: as above, c in 10..=18
                adc.smpr2()
                    .modify(|_, w| unsafe { w.smp(c - 10).bits(smp) });
            }
        }
        // SAFETY: JL = 1 (two conversions), channel numbers < 19, JEXTSEL/JEXTEN from the
        // PAC's enumerations.
        adc.jsqr().write(|w| unsafe {
            w.jl()
                .bits(1)
                .jextsel()
                .tim1_trgo2()
                .jexten()
                .rising_edge()
                .jsq1()
                .bits(chans[0])
                .jsq2()
                .bits(chans[1])
        });
        adc.isr().write(|w| w.jeos().clear().jeoc().clear()); // clear
        adc.cr().modify(|_, w| w.jadstart().set_bit());
    }
    ok
}

fn wait(mut cond: impl FnMut() -> bool) -> bool {
    for _ in 0..1_000_000 {
        if cond() {
            return true;
        }
    }
    false
}

/// Polls for a completed injected sequence on both ADCs (start-up calibration, before the
/// interrupt is enabled); clears the flags and returns the sample.
pub fn adc_poll(timeout_loops: u32) -> Option<RawSample> {
    for _ in 0..timeout_loops {
        if adc1().isr().read().jeos().bit_is_set() && adc2().isr().read().jeos().bit_is_set() {
            let s = adc_read();
            adc_ack();
            return Some(s);
        }
    }
    None
}

/// Enables the end-of-injected-sequence interrupt of ADC1 (the control interrupt).
pub fn adc_enable_interrupt() {
    adc_ack();
    adc1().ier().modify(|_, w| w.jeosie().set_bit());
}

/// Clears both ADCs' injected end flags (first thing in the interrupt).
#[inline(always)]
pub fn adc_ack() {
    adc1().isr().write(|w| w.jeos().clear().jeoc().clear());
    adc2().isr().write(|w| w.jeos().clear().jeoc().clear());
}

/// A new injected sequence completed since [`adc_ack`]: the step missed its deadline.
#[inline(always)]
pub fn adc_sequence_pending() -> bool {
    adc1().isr().read().jeos().bit_is_set()
}

/// The injected results, read as ADC1 rank 1, ADC2 rank 1, ADC2 rank 2, ADC1 rank 2 and
/// sorted by the board's ADC plan (the generic stage: U, V, W, DC bus in that order).
#[inline(always)]
pub fn adc_read() -> RawSample {
    const U: usize = BOARD.adc.slot(Signal::CurrentU);
    const V: usize = BOARD.adc.slot(Signal::CurrentV);
    const W: usize = BOARD.adc.slot(Signal::CurrentW);
    const BUS: usize = BOARD.adc.slot(Signal::Bus);
    let a1 = adc1();
    let a2 = adc2();
    let r = [
        a1.jdr1().read().jdata().bits(),
        a2.jdr1().read().jdata().bits(),
        a2.jdr2().read().jdata().bits(),
        a1.jdr2().read().jdata().bits(),
    ];
    RawSample {
        currents: [r[U], r[V], r[W]],
        dc_bus: r[BUS],
    }
}

/// Top priority (0) for the control interrupt, then unmask it.
pub fn nvic_enable_top(irq: pac::Interrupt, nvic: &mut cortex_m::peripheral::NVIC) {
    // SAFETY: priority changes can break priority-based critical sections; this firmware
    // uses none (the interrupt and main share data only through lock-free queues).
    unsafe { nvic.set_priority(irq, 0) };
    // SAFETY: unmasking is sound because every datum the handler uses is initialised
    // before this call (see main).
    unsafe { cortex_m::peripheral::NVIC::unmask(irq) };
}

/// Self-test: TIM6's update flag (the period interrupt's source).
#[cfg(feature = "selftest")]
#[inline(always)]
pub fn tim6_update_pending() -> bool {
    // SAFETY: read-only access to TIM6's status register.
    let t = unsafe { &*pac::TIM6::ptr() };
    t.sr().read().uif().bit_is_set()
}

/// Self-test: clears TIM6's update flag.
#[cfg(feature = "selftest")]
#[inline(always)]
pub fn tim6_ack() {
    // SAFETY: writing 0 to the rc_w0 UIF flag clears it; TIM6 is used by the self-test's
    // period interrupt only.
    let t = unsafe { &*pac::TIM6::ptr() };
    t.sr().write(|w| w.uif().clear_bit());
}
