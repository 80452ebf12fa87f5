//! The two settings pages in flash (RM0440 section 3.3.6-3.3.8): read a page's record,
//! and erase and program one page (unlock with the two KEYR keys, page erase
//! PER/BKER/PNB/STRT, double-word programming with PG, BSY wait, errors checked, lock, data
//! cache reset). Which page a save writes, the read-back and the boot's choice are
//! `acim_firmware_core::store` (host-tested with a power cut at every operation); this
//! module is its [`store::PageFlash`].
//!
//! Only the two reserved pages (`settings::SETTINGS_ADDR`: bank 2, pages 126 and 127 of
//! the 512 KiB STM32G474xE; memory.x keeps the program out of them, fwcheck.py checks that
//! they exist on that part and lie above the image) are ever erased, one per save, and only
//! with the factory bank mapping (FLASH_OPTR.BFB2 = 0: no bank swap). Writing needs the
//! factory dual-bank mode (FLASH_OPTR.DBANK = 1): then the erase runs in bank 2 while the
//! program (bank 1) and the control interrupt (CCM SRAM) keep running; in single-bank mode
//! the pages are 4 KiB and an erase would stall every flash fetch for up to 40 ms, so
//! `save` is refused.
//!
//! Called from the main loop only (never from an interrupt), while the drive is Idle.

use acim_firmware_core::settings::{
    RECORD_LEN, SETTINGS_ADDR, SETTINGS_PAGES, SETTINGS_PAGE_BYTES,
};
use acim_firmware_core::store::{self, Page, PageRead};
use core::sync::atomic::{AtomicU8, Ordering};
use stm32g4xx_hal::pac;

/// Flash ECC double errors found in the settings pages (by the NMI handler,
/// [`ecc_error_in_settings`]): bit 0 page A, bit 1 page B, until [`take_ecc_error`].
static ECC_IN_SETTINGS: AtomicU8 = AtomicU8::new(0);

/// FLASH_ECCR: ECCD (double error, rc_w1), BK_ECC, ADDR_ECC (offset in the bank).
const ECCR_ECCD: u32 = 1 << 31;
const ECCR_BK_ECC: u32 = 1 << 21;
const ECCR_ADDR_ECC: u32 = 0x7_FFFF;
/// Bank 2's start in dual-bank mode (256 KiB banks).
const BANK2: u32 = 0x0804_0000;

/// Called by the NMI handler: if the NMI is a flash ECC double error inside a settings
/// page (a double word torn by a power cut during `save`), clears ECCD, notes the page,
/// and returns true: the handler returns and the read carries on with whatever the word
/// holds; the page is then refused as torn, whatever its CRC says (review N2: the board
/// hung in the NMI handler at every boot, before the watchdog and the UART). Any other
/// NMI: false.
pub fn ecc_error_in_settings() -> bool {
    let f = flash();
    let eccr = f.eccr().read().bits();
    let addr = BANK2 + (eccr & ECCR_ADDR_ECC);
    let end = SETTINGS_ADDR + SETTINGS_PAGES * SETTINGS_PAGE_BYTES;
    if eccr & ECCR_ECCD == 0 || eccr & ECCR_BK_ECC == 0 || !(SETTINGS_ADDR..end).contains(&addr) {
        return false;
    }
    // SAFETY: ECCD is rc_w1; the other bits written as read (ECCCIE kept, ECCC not set)
    f.eccr().write(|w| unsafe { w.bits(eccr & !(1 << 30)) });
    let page = (addr - SETTINGS_ADDR) / SETTINGS_PAGE_BYTES;
    ECC_IN_SETTINGS.fetch_or(1 << page, Ordering::Relaxed);
    true
}

/// Whether an ECC double error in `page` was found since the last call for it.
fn take_ecc_error(page: Page) -> bool {
    let bit = 1u8 << page.index();
    ECC_IN_SETTINGS.fetch_and(!bit, Ordering::Relaxed) & bit != 0
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

/// The record area of a settings page as stored, and whether reading it met an ECC
/// double error (its NMI returns, [`ecc_error_in_settings`]).
#[inline(never)]
pub fn read_page(page: Page) -> PageRead {
    take_ecc_error(page);
    let mut record = [0u8; RECORD_LEN];
    for (i, chunk) in record.chunks_exact_mut(4).enumerate() {
        // SAFETY: an aligned word inside a reserved flash page (always readable; erased
        // flash reads 0xFF; a torn double word raises the NMI, which returns for it).
        let w = unsafe { core::ptr::read_volatile((page.addr() as *const u32).add(i)) };
        chunk.copy_from_slice(&w.to_le_bytes());
    }
    PageRead {
        record,
        ecc_error: take_ecc_error(page),
    }
}

/// The settings pages for `acim_firmware_core::store`: `poll` runs while the flash is busy
/// (the main loop's watchdog and interrupt watch).
pub struct Pages<'a> {
    /// Called in every BSY wait.
    pub poll: &'a mut dyn FnMut(),
}

impl store::PageFlash for Pages<'_> {
    type Error = FlashError;
    fn read(&mut self, page: Page) -> PageRead {
        read_page(page)
    }
    fn write(&mut self, page: Page, record: &[u8; RECORD_LEN]) -> Result<(), FlashError> {
        write_page(page, record, self.poll)
    }
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

/// Erases settings page `page` and programs `record` at its start (the other page is not
/// touched; `store::save` reads it back); `poll` runs while the flash is busy.
fn write_page(
    page: Page,
    record: &[u8; RECORD_LEN],
    poll: &mut dyn FnMut(),
) -> Result<(), FlashError> {
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
    let result = erase_and_program(f, page, record, poll);
    f.cr()
        .modify(|_, w| w.pg().clear_bit().per().clear_bit().lock().set_bit());
    // the flash data cache may hold the page's old words: reset it (DCEN off around DCRST)
    f.acr().modify(|_, w| w.dcen().clear_bit());
    f.acr().modify(|_, w| w.dcrst().set_bit());
    f.acr()
        .modify(|_, w| w.dcrst().clear_bit().dcen().set_bit());
    result
}

fn erase_and_program(
    f: &pac::flash::RegisterBlock,
    page: Page,
    record: &[u8; RECORD_LEN],
    poll: &mut dyn FnMut(),
) -> Result<(), FlashError> {
    // SAFETY: writing 1 clears a status flag (rc_w1); no other effect
    f.sr().write(|w| unsafe { w.bits(SR_ERRORS | SR_EOP) });
    // page erase: bank 2, page 126 or 127 (a reserved page), then start
    f.cr().modify(|_, w| {
        // SAFETY: PNB is a 7-bit page number; Page::number is 126 or 127, a reserved page
        unsafe { w.per().set_bit().bker().bank2().pnb().bits(page.number()) }
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
        let addr = (page.addr() as *mut u32).wrapping_add(2 * i);
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
