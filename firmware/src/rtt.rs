//! The defmt global logger over RTT, holding no critical section while it encodes a frame.
//!
//! defmt-rtt masks every interrupt for the whole frame (about 940 instructions for
//! `status`'s frame, 2400 for a telemetry sample's), which delays the control interrupt.
//! Here nothing is masked: the interrupts never log (`control_isr` has no defmt call), so
//! the main loop owns the channel. A handler that logs while the main loop's frame is
//! open (the panic handler, a fault handler) finds the logger taken and drops its own frame
//! instead of corrupting the open one. The emulator measures the main loop's masked
//! sections (`fil/test_fil.py`, `MaskedSections`).
//!
//! The control block has SEGGER's layout (`_SEGGER_RTT`, one up channel named "defmt",
//! non-blocking: what does not fit is dropped); the probe (probe-rs) finds it by its
//! symbol. Where a write goes is computed by `acim_firmware_core::rtt::plan_write`
//! (host-tested); this module holds the two byte copies into the shared buffer.

use acim_firmware_core::rtt::plan_write;
use core::cell::UnsafeCell;
use core::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

/// The channel's buffer, bytes.
const BUF_SIZE: usize = 1024;
/// The channel's mode bits: non-blocking, trimming what does not fit.
const MODE_NON_BLOCKING_TRIM: usize = 1;

/// An RTT up channel descriptor (SEGGER's layout, read by the probe).
#[repr(C)]
struct Channel {
    name: *const u8,
    buffer: *mut u8,
    size: usize,
    /// Advanced by the target.
    write: AtomicUsize,
    /// Advanced by the probe.
    read: AtomicUsize,
    flags: AtomicUsize,
}

/// The RTT control block (SEGGER's layout).
#[repr(C)]
struct Header {
    id: [u8; 16],
    max_up_channels: usize,
    max_down_channels: usize,
    up_channel: Channel,
}

// SAFETY: the raw pointers name statics that live for the program; the buffer is written
// only by the logger's owner (module docs) and read by the probe.
unsafe impl Sync for Header {}

/// The buffer the probe reads.
struct Buffer(UnsafeCell<[u8; BUF_SIZE]>);
// SAFETY: written only by the logger's owner (module docs).
unsafe impl Sync for Buffer {}

static BUFFER: Buffer = Buffer(UnsafeCell::new([0; BUF_SIZE]));

/// The channel's name (read-only data; the probe reads it once, by the pointer in the block).
static NAME: [u8; 6] = *b"defmt\0";

#[no_mangle]
static _SEGGER_RTT: Header = Header {
    id: *b"SEGGER RTT\0\0\0\0\0\0",
    max_up_channels: 1,
    max_down_channels: 0,
    up_channel: Channel {
        name: NAME.as_ptr(),
        buffer: BUFFER.0.get() as *mut u8,
        size: BUF_SIZE,
        write: AtomicUsize::new(0),
        read: AtomicUsize::new(0),
        flags: AtomicUsize::new(MODE_NON_BLOCKING_TRIM),
    },
};

impl Channel {
    /// Writes what fits of `bytes` and drops the rest (never waits for the probe).
    fn write_trimmed(&self, bytes: &[u8]) {
        let read = self.read.load(Ordering::Acquire);
        let write = self.write.load(Ordering::Relaxed);
        let p = plan_write(self.size, read, write, bytes.len());
        if p.first + p.second == 0 {
            // full, or offsets outside the ring (a corrupted block): nothing is written and
            // no pointer is formed from them
            return;
        }
        // SAFETY: with something to write, `plan_write` has checked `write < size` and keeps
        // both copies inside the `size`-byte buffer and before the probe's read offset;
        // `first + second <= bytes.len()`; the logger's owner is the only writer (module
        // docs).
        unsafe {
            core::ptr::copy_nonoverlapping(bytes.as_ptr(), self.buffer.add(write), p.first);
            core::ptr::copy_nonoverlapping(bytes.as_ptr().add(p.first), self.buffer, p.second);
        }
        // the bytes before the offset that publishes them
        self.write.store(p.next, Ordering::Release);
    }
}

/// The frame's owner holds it; a logger found taken drops the new frame.
static TAKEN: AtomicBool = AtomicBool::new(false);
/// The frame being dropped (a handler's, while the main loop's frame is open).
static DROPPING: AtomicBool = AtomicBool::new(false);

/// The defmt encoder's state (used only by the frame's owner).
struct EncoderCell(UnsafeCell<defmt::Encoder>);
// SAFETY: accessed only between a successful `acquire` and its `release` (`TAKEN`).
unsafe impl Sync for EncoderCell {}
static ENCODER: EncoderCell = EncoderCell(UnsafeCell::new(defmt::Encoder::new()));

fn emit(bytes: &[u8]) {
    _SEGGER_RTT.up_channel.write_trimmed(bytes);
}

#[defmt::global_logger]
struct Logger;

// SAFETY: defmt calls `acquire`, then `write`s, then `release` from one context; a context
// that preempts an open frame (a handler) takes the `DROPPING` path and touches neither the
// encoder nor the channel, so the open frame stays whole.
unsafe impl defmt::Logger for Logger {
    fn acquire() {
        if TAKEN.swap(true, Ordering::Acquire) {
            DROPPING.store(true, Ordering::Relaxed);
            return;
        }
        // SAFETY: this context owns the encoder until `release` (`TAKEN`)
        unsafe { (*ENCODER.0.get()).start_frame(emit) }
    }

    unsafe fn flush() {}

    unsafe fn release() {
        if DROPPING.swap(false, Ordering::Relaxed) {
            return;
        }
        // SAFETY: as in `acquire`
        unsafe { (*ENCODER.0.get()).end_frame(emit) }
        TAKEN.store(false, Ordering::Release);
    }

    unsafe fn write(bytes: &[u8]) {
        if DROPPING.load(Ordering::Relaxed) {
            return;
        }
        // SAFETY: as in `acquire`
        unsafe { (*ENCODER.0.get()).write(bytes, emit) }
    }
}
