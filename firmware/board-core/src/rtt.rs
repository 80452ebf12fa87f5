//! The arithmetic of the firmware's RTT up channel (SEGGER's Real-Time Transfer: a ring
//! buffer in target RAM that the debug probe reads while the core runs), which carries the
//! defmt log. The target writes and advances `write`; the probe reads and advances `read`;
//! one byte stays free so that `read == write` means empty. Non-blocking: what does not fit
//! is dropped (trimmed), so a log never waits for the probe.
//!
//! The firmware's global logger (`firmware/src/rtt.rs`) holds no critical section while it
//! encodes a frame: the interrupts never log, so the main loop owns the channel, and a
//! fault handler that logs while a frame is open drops its own frame. Here is the part that
//! needs no `unsafe`: where the next bytes go.

/// Where a write of `len` bytes goes in a ring of `size` bytes with the probe's offset
/// `read` and the target's `write`: `first` bytes at `write`, then `second` bytes at 0,
/// and the new write offset `next`. `first + second` is what fits (the rest is dropped);
/// offsets outside the ring (a corrupted control block) write nothing.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RingWrite {
    /// Bytes written at `write`, up to the end of the ring.
    pub first: usize,
    /// Bytes written from the ring's start.
    pub second: usize,
    /// The write offset after the write.
    pub next: usize,
}

/// The plan of a non-blocking write ([`RingWrite`]).
pub fn plan_write(size: usize, read: usize, write: usize, len: usize) -> RingWrite {
    if size < 2 || read >= size || write >= size {
        return RingWrite {
            first: 0,
            second: 0,
            next: write,
        };
    }
    // free bytes, one kept empty
    let free = if read > write {
        read - write - 1
    } else {
        size - write + read - 1
    };
    let n = len.min(free);
    let first = n.min(size - write);
    let second = n - first;
    let next = if second > 0 {
        second
    } else if write + first == size {
        0
    } else {
        write + first
    };
    RingWrite {
        first,
        second,
        next,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fills_up_to_one_free_byte_and_wraps() {
        // empty ring of 8: 7 fit
        assert_eq!(
            plan_write(8, 0, 0, 10),
            RingWrite {
                first: 7,
                second: 0,
                next: 7
            }
        );
        // write near the end, read ahead of the start: wraps
        assert_eq!(
            plan_write(8, 3, 6, 4),
            RingWrite {
                first: 2,
                second: 2,
                next: 2
            }
        );
        // exactly to the end: the offset wraps to 0
        assert_eq!(
            plan_write(8, 2, 6, 2),
            RingWrite {
                first: 2,
                second: 0,
                next: 0
            }
        );
        // full (write just behind read): nothing
        assert_eq!(
            plan_write(8, 4, 3, 5),
            RingWrite {
                first: 0,
                second: 0,
                next: 3
            }
        );
        // read ahead: up to one byte before it
        assert_eq!(
            plan_write(8, 6, 2, 9),
            RingWrite {
                first: 3,
                second: 0,
                next: 5
            }
        );
        // corrupted offsets write nothing
        assert_eq!(
            plan_write(8, 9, 0, 1).first + plan_write(8, 9, 0, 1).second,
            0
        );
        assert_eq!(plan_write(8, 0, 8, 1).first, 0);
    }

    #[test]
    fn never_overruns_the_reader_over_any_sequence() {
        // a simulated ring: the reader takes some bytes, the writer writes some; the bytes
        // read are exactly the bytes written, in order, less what was dropped when full
        let size = 16;
        let mut ring = [0u8; 16];
        let (mut read, mut write) = (0usize, 0usize);
        let mut sent = 0u8;
        let mut expect = 0u8;
        for k in 0..2000usize {
            let len = (k * 7) % 11;
            let p = plan_write(size, read, write, len);
            assert!(p.first + p.second <= len);
            for b in ring.iter_mut().skip(write).take(p.first) {
                *b = sent;
                sent = sent.wrapping_add(1);
            }
            for b in ring.iter_mut().take(p.second) {
                *b = sent;
                sent = sent.wrapping_add(1);
            }
            write = p.next;
            assert!(write < size);
            // the reader takes up to (k % 13) bytes
            let mut take = k % 13;
            while take > 0 && read != write {
                assert_eq!(ring[read], expect);
                expect = expect.wrapping_add(1);
                read = (read + 1) % size;
                take -= 1;
            }
        }
    }
}
