//! Copies the `.ccmram` load image (control-step code and initialised data, see
//! `ccmram.x`) from flash to CCM SRAM. Must run first in `main`, before anything calls
//! into CCM and before any interrupt is enabled.

extern "C" {
    static mut __sccmram: u32;
    static mut __eccmram: u32;
    static __siccmram: u32;
}

/// Copies flash -> CCM SRAM, word by word.
#[inline(never)]
pub fn init() {
    // SAFETY: the three symbols are defined by ccmram.x: [__sccmram, __eccmram) is the
    // section's 8-byte aligned run address range in CCM SRAM (32 KiB, enabled at reset)
    // and __siccmram its 4-byte aligned load address in flash, holding as many bytes. No
    // Rust reference to CCM exists yet (this runs first in main, single-threaded, with
    // interrupts not yet enabled), so the raw volatile writes alias nothing. Volatile
    // word copies (not `copy_nonoverlapping`, which could call a memcpy that ccmram.x
    // might one day place in CCM itself).
    unsafe {
        let mut dst = core::ptr::addr_of_mut!(__sccmram);
        let end = core::ptr::addr_of_mut!(__eccmram);
        let mut src = core::ptr::addr_of!(__siccmram);
        while dst < end {
            dst.write_volatile(src.read_volatile());
            dst = dst.add(1);
            src = src.add(1);
        }
    }
    // the copied words are instructions: make sure they are visible before executing them
    cortex_m::asm::dsb();
    cortex_m::asm::isb();
}
