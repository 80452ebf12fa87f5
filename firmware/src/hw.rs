//! The one module with direct register access: what stm32g4xx-hal 0.1.0 does not offer.
//!
//! - TIM1: safe off-state (MOE, OSSI/OSSR, idle levels), TRGO2 = OC4REF as the ADC
//!   trigger at the sampling instant, one update event per period (RCR), compare writes,
//!   main-output control and the break flag.
//! - ADC1/ADC2: power-up, calibration and injected conversions triggered by TIM1 TRGO2.
//! - NVIC priority/unmask of the control interrupt.
//! - TIM6 flags for the self-test's period interrupt.
//!
//! Soundness, common to every `unsafe` below: the peripherals are used by exactly one
//! context at a time. `main` configures them before the control interrupt is unmasked;
//! afterwards only the control interrupt touches TIM1/ADC/TIM6 registers, except
//! [`emergency_off`], which the panic and HardFault handlers call with interrupts
//! disabled (or from a fault that cannot be preempted by the control interrupt). The
//! HAL's TIM1/TIM6 objects do not touch these registers after their set-up. Register
//! pointers come from the PAC and are valid for the whole program.

use acim::PwmOutput;
use acim_firmware_core::convert::{duty_to_compare, RawSample};
use stm32g4xx_hal::pac;

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

/// Disables TIM1's main output: all six switches off (idle levels, low) after the dead
/// time, from any context. Used by the panic and HardFault handlers.
#[inline(always)]
pub fn emergency_off() {
    // SAFETY: a read-modify-write of BDTR clearing MOE only; called with interrupts
    // disabled or from HardFault, so nothing interleaves. Clearing MOE is always safe
    // (and harmless if TIM1 was never enabled: the register then reads as 0).
    let t = unsafe { &*pac::TIM1::ptr() };
    t.bdtr().modify(|_, w| w.moe().clear_bit());
}

/// Right after the HAL's `finalize` (which sets MOE): main output off, off-state
/// selection so that a disabled output drives the idle level (switch off) instead of
/// floating, idle levels low for all six outputs.
pub fn tim1_safe_state() {
    let t = tim1();
    t.bdtr()
        .modify(|_, w| w.moe().clear_bit().ossi().set_bit().ossr().set_bit());
    t.cr2().modify(|_, w| {
        w.ois1()
            .clear_bit()
            .ois1n()
            .clear_bit()
            .ois2()
            .clear_bit()
            .ois2n()
            .clear_bit()
            .ois3()
            .clear_bit()
            .ois3n()
            .clear_bit()
    });
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

/// Writes one step's command. Enabled: compare values (preloaded: act from the next
/// period) and MOE set. Disabled: MOE cleared at once (switches off within this period,
/// after the dead time) and compare values back to 50 %.
#[inline(always)]
pub fn pwm_write(out: &PwmOutput, arr: u16, max_duty: f32) {
    let t = tim1();
    if out.enabled {
        let [a, b, c] = out.duties;
        // SAFETY: compare values are any 16-bit count (duty_to_compare returns <= arr)
        t.ccr1()
            .write(|w| unsafe { w.ccr().bits(duty_to_compare(a, arr, max_duty) as u32) });
        t.ccr2()
            .write(|w| unsafe { w.ccr().bits(duty_to_compare(b, arr, max_duty) as u32) });
        t.ccr3()
            .write(|w| unsafe { w.ccr().bits(duty_to_compare(c, arr, max_duty) as u32) });
        if t.bdtr().read().moe().bit_is_clear() {
            t.bdtr().modify(|_, w| w.moe().set_bit());
        }
    } else {
        t.bdtr().modify(|_, w| w.moe().clear_bit());
        let half = (arr / 2) as u32;
        // SAFETY: any 16-bit count
        t.ccr1().write(|w| unsafe { w.ccr().bits(half) });
        t.ccr2().write(|w| unsafe { w.ccr().bits(half) });
        t.ccr3().write(|w| unsafe { w.ccr().bits(half) });
    }
}

/// The break input fired since the flag was last cleared (the hardware has already
/// cleared MOE; AOE = 0 keeps it cleared).
#[inline(always)]
pub fn break_flag() -> bool {
    let sr = tim1().sr().read();
    sr.bif().bit_is_set() || sr.b2if().bit_is_set()
}

/// Clears the break flags (on a fault reset; if the break line is still active the flag
/// sets again at once and the drive trips again).
pub fn clear_break_flag() {
    // SAFETY: rc_w0 flags: writing 1 leaves a flag unchanged, 0 clears it.
    tim1()
        .sr()
        .write(|w| unsafe { w.bits(!((1 << 7) | (1 << 8))) });
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
    for (adc, chans) in [(adc1(), ch.adc1), (adc2(), ch.adc2)] {
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
        // 24.5-cycle sampling on the used channels (code 0b011): 0.58 us
        for c in chans {
            if c <= 9 {
                // SAFETY: SMPx = 0b011 is a valid 3-bit code, c in 0..=9
                adc.smpr1().modify(|_, w| unsafe { w.smp(c).bits(0b011) });
            } else {
                // SAFETY: as above, c in 10..=18
                adc.smpr2()
                    .modify(|_, w| unsafe { w.smp(c - 10).bits(0b011) });
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

/// True once ADC2 has finished its sequence too (same trigger, clock and length as ADC1,
/// so it is normally done when ADC1 is).
#[inline(always)]
pub fn adc2_done() -> bool {
    adc2().isr().read().jeos().bit_is_set()
}

/// A new injected sequence completed since [`adc_ack`]: the step missed its deadline.
#[inline(always)]
pub fn adc_sequence_pending() -> bool {
    adc1().isr().read().jeos().bit_is_set()
}

/// The injected results: ADC1 = (U current, DC bus), ADC2 = (V current, W current).
#[inline(always)]
pub fn adc_read() -> RawSample {
    let a1 = adc1();
    let a2 = adc2();
    RawSample {
        currents: [
            a1.jdr1().read().jdata().bits(),
            a2.jdr1().read().jdata().bits(),
            a2.jdr2().read().jdata().bits(),
        ],
        dc_bus: a1.jdr2().read().jdata().bits(),
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
