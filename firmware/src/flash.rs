//! The settings page in flash (RM0440 section 3.3.6-3.3.8): read the record, and erase and
//! program it (unlock with the two KEYR keys, page erase PER/BKER/PNB/STRT, double-word
//! programming with PG, BSY wait, errors checked, lock, data cache reset, read back).
//!
//! Only the reserved page `settings::SETTINGS_ADDR` (bank 2, page 127 of the 512 KiB
//! STM32G474xE; memory.x keeps the program out of it, fwcheck.py checks that it exists
//! on that part and lies above the image) is ever erased, and only with the factory bank
//! mapping (FLASH_OPTR.BFB2 = 0: no bank swap). Writing needs the factory dual-bank mode
//! (FLASH_OPTR.DBANK = 1): then the erase runs in bank 2 while the program (bank 1) and the
//! control interrupt (CCM SRAM) keep running; in single-bank mode the pages are 4 KiB and
//! an erase would stall every flash fetch for up to 40 ms, so `save` is refused.
//!
//! Called from the main loop only (never from an interrupt), while the drive is Idle.

use acim_firmware_core::settings::{
    RECORD_LEN, SETTINGS_ADDR, SETTINGS_PAGE_BYTES, SETTINGS_PAGE_NUMBER,
};
use core::sync::atomic::{AtomicBool, Ordering};
use stm32g4xx_hal::pac;

/// A flash ECC double error was found in the settings page (by the NMI handler,
/// [`ecc_error_in_settings`]) since the last [`take_ecc_error`].
static ECC_IN_SETTINGS: AtomicBool = AtomicBool::new(false);

/// FLASH_ECCR: ECCD (double error, rc_w1), BK_ECC, ADDR_ECC (offset in the bank).
const ECCR_ECCD: u32 = 1 << 31;
const ECCR_BK_ECC: u32 = 1 << 21;
const ECCR_ADDR_ECC: u32 = 0x7_FFFF;
/// Bank 2's start in dual-bank mode (256 KiB banks).
const BANK2: u32 = 0x0804_0000;

/// Called by the NMI handler: if the NMI is a flash ECC double error inside the settings
/// page (a double word torn by a power cut during `save`), clears ECCD, notes it, and
/// returns true: the handler returns and the read carries on with whatever the word
/// holds, which the record's CRC then refuses (review N2: the board hung in the NMI
/// handler at every boot, before the watchdog and the UART). Any other NMI: false.
pub fn ecc_error_in_settings() -> bool {
    let f = flash();
    let eccr = f.eccr().read().bits();
    let addr = BANK2 + (eccr & ECCR_ADDR_ECC);
    if eccr & ECCR_ECCD == 0
        || eccr & ECCR_BK_ECC == 0
        || !(SETTINGS_ADDR..SETTINGS_ADDR + SETTINGS_PAGE_BYTES).contains(&addr)
    {
        return false;
    }
    // SAFETY: ECCD is rc_w1; the other bits written as read (ECCCIE kept, ECCC not set)
    f.eccr().write(|w| unsafe { w.bits(eccr & !(1 << 30)) });
    ECC_IN_SETTINGS.store(true, Ordering::Relaxed);
    true
}

/// Whether an ECC double error in the settings page was found since the last call.
pub fn take_ecc_error() -> bool {
    ECC_IN_SETTINGS.swap(false, Ordering::Relaxed)
}

/// Why a save failed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FlashError {
    /// FLASH_OPTR.DBANK = 0 (single-bank mode, 4 KiB pages): not supported.
    SingleBank,
    /// FLASH_OPTR.BFB2 = 1: the banks may be swapped (boot from bank 2), and BKER selects
    /// the physical bank, so the erase could hit the running program: refused.
    BankSwap,
    /// The unlock sequence did not clear LOCK.
    Locked,
    /// BSY did not clear in time.
    Timeout,
    /// The erase set an error flag (FLASH_SR value).
    Erase(u32),
    /// Programming set an error flag (FLASH_SR value).
    Program(u32),
    /// The page does not read back as written.
    Verify,
}

impl FlashError {
    /// Short text for the reply.
    pub fn as_str(self) -> &'static str {
        match self {
            FlashError::SingleBank => "flash in single-bank mode (OPTR.DBANK = 0)",
            FlashError::BankSwap => "bank swap option set (OPTR.BFB2 = 1)",
            FlashError::Locked => "flash did not unlock",
            FlashError::Timeout => "flash busy timeout",
            FlashError::Erase(_) => "page erase error",
            FlashError::Program(_) => "programming error",
            FlashError::Verify => "read-back differs",
        }
    }
}

const KEY1: u32 = 0x4567_0123;
const KEY2: u32 = 0xCDEF_89AB;
/// FLASH_SR error flags: OPERR, PROGERR, WRPERR, PGAERR, SIZERR, PGSERR, MISERR, FASTERR,
/// RDERR, OPTVERR.
const SR_ERRORS: u32 = 0xC3FA;
const SR_EOP: u32 = 1;
/// BSY polls before giving up: well beyond the 40 ms maximum page erase at 170 MHz, and
/// below nothing that matters (the watchdog resets a stuck main loop anyway).
const BUSY_POLLS: u32 = 20_000_000;

fn flash() -> &'static pac::flash::RegisterBlock {
    // SAFETY: after the clock set-up (the HAL's only FLASH access, ACR latency) the
    // main loop is the only user of FLASH; the control interrupt never touches it.
    unsafe { &*pac::FLASH::ptr() }
}

/// The record area of the settings page, as stored.
#[inline(never)]
pub fn read_record() -> [u8; RECORD_LEN] {
    let mut r = [0u8; RECORD_LEN];
    for (i, chunk) in r.chunks_exact_mut(4).enumerate() {
        // SAFETY: an aligned word inside the reserved flash page (always readable;
        // erased flash reads 0xFF).
        let w = unsafe { core::ptr::read_volatile((SETTINGS_ADDR as *const u32).add(i)) };
        chunk.copy_from_slice(&w.to_le_bytes());
    }
    r
}

/// Waits for BSY to clear, calling `poll` (the main loop's watchdog and interrupt watch)
/// meanwhile: an erase takes up to 40 ms.
#[inline(never)]
fn wait_idle(f: &pac::flash::RegisterBlock, poll: &mut dyn FnMut()) -> Result<u32, FlashError> {
    for _ in 0..BUSY_POLLS {
        let sr = f.sr().read().bits();
        if sr & (1 << 16) == 0 {
            return Ok(sr);
        }
        poll();
    }
    Err(FlashError::Timeout)
}

/// Erases the settings page and programs `record` at its start, then reads it back;
/// `poll` runs while the flash is busy.
pub fn write_record(record: &[u8; RECORD_LEN], poll: &mut dyn FnMut()) -> Result<(), FlashError> {
    let f = flash();
    let optr = f.optr().read();
    if !optr.dbank().bit_is_set() {
        return Err(FlashError::SingleBank);
    }
    // BKER addresses the physical bank: with BFB2 set, bank 2 may be the one mapped at
    // 0x0800_0000 (the program), so the settings page of bank 2 is not ours to erase
    if optr.bfb2().bit_is_set() {
        return Err(FlashError::BankSwap);
    }
    wait_idle(f, poll)?;
    if f.cr().read().lock().bit_is_set() {
        // SAFETY (both writes): the documented unlock keys; a wrong sequence would only
        // lock FLASH_CR until the next reset.
        f.keyr().write(|w| unsafe { w.keyr().bits(KEY1) });
        f.keyr().write(|w| unsafe { w.keyr().bits(KEY2) });
    }
    if f.cr().read().lock().bit_is_set() {
        return Err(FlashError::Locked);
    }
    let result = erase_and_program(f, record, poll);
    f.cr()
        .modify(|_, w| w.pg().clear_bit().per().clear_bit().lock().set_bit());
    // the flash data cache may hold the page's old words: reset it (DCEN off around DCRST)
    f.acr().modify(|_, w| w.dcen().clear_bit());
    f.acr().modify(|_, w| w.dcrst().set_bit());
    f.acr()
        .modify(|_, w| w.dcrst().clear_bit().dcen().set_bit());
    result?;
    if read_record() != *record {
        return Err(FlashError::Verify);
    }
    Ok(())
}

fn erase_and_program(
    f: &pac::flash::RegisterBlock,
    record: &[u8; RECORD_LEN],
    poll: &mut dyn FnMut(),
) -> Result<(), FlashError> {
    // SAFETY: writing 1 clears a status flag (rc_w1); no other effect
    f.sr().write(|w| unsafe { w.bits(SR_ERRORS | SR_EOP) });
    // page erase: bank 2, page 127 (the reserved page), then start
    f.cr().modify(|_, w| {
        // SAFETY: PNB is a 7-bit page number; 127 is the reserved page
        unsafe {
            w.per()
                .set_bit()
                .bker()
                .bank2()
                .pnb()
                .bits(SETTINGS_PAGE_NUMBER)
        }
    });
    f.cr().modify(|_, w| w.strt().set_bit());
    let sr = wait_idle(f, poll)?;
    f.cr().modify(|_, w| w.per().clear_bit());
    if sr & SR_ERRORS != 0 {
        return Err(FlashError::Erase(sr));
    }
    // double-word programming: first word at an 8-byte aligned address, then the second
    f.cr().modify(|_, w| w.pg().set_bit());
    for (i, dw) in record.chunks_exact(8).enumerate() {
        let lo = u32::from_le_bytes([dw[0], dw[1], dw[2], dw[3]]);
        let hi = u32::from_le_bytes([dw[4], dw[5], dw[6], dw[7]]);
        let addr = (SETTINGS_ADDR as *mut u32).wrapping_add(2 * i);
        // SAFETY: an 8-byte aligned double word inside the erased, unlocked reserved
        // page, with PG set: the documented programming sequence (RM0440 3.3.7).
        unsafe {
            core::ptr::write_volatile(addr, lo);
            core::ptr::write_volatile(addr.add(1), hi);
        }
        let sr = wait_idle(f, poll)?;
        if sr & SR_ERRORS != 0 {
            return Err(FlashError::Program(sr));
        }
    }
    Ok(())
}
