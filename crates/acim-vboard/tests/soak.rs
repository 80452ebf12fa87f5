//! Soak: the virtual board under many short connections and one client that asks for the
//! fastest telemetry, keeps sending commands and never reads its socket, while another
//! client watches its own telemetry.
//!
//! What must hold (Linux: descriptors and memory are read from /proc/self):
//! - the watcher's telemetry never stops for longer than [`MAX_GAP`] (the stuck client
//!   must not hold the simulation thread);
//! - the stuck client is disconnected within [`STUCK_DISCONNECT_WITHIN`];
//! - every one of [`CYCLES`] connections is answered, and once they are closed the open
//!   descriptor count is back within [`FD_SLACK`] of its start, with the server still
//!   running;
//! - the resident memory grows by less than [`RSS_GROWTH_KIB`];
//! - the event log holds at most [`LOG_CAPACITY`] entries although every cycle logs one.
//!
//! It runs alone in its own test binary, so no other test's sockets are counted.
#![cfg(target_os = "linux")]

use acim_vboard::board::LOG_CAPACITY;
use acim_vboard::server::{self, Options, Pace, ServerHandle, STALL_TIMEOUT};
use std::io::{BufRead, BufReader, ErrorKind, Read, Write};
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::thread;
use std::time::{Duration, Instant};

/// Connect/disconnect cycles.
const CYCLES: usize = 3000;
/// The longest wall-clock time between two `$T` frames the watcher may see. The board
/// sends 12 500 samples/s here (rate 2 at 5x real time).
const MAX_GAP: Duration = Duration::from_secs(1);
/// From the stuck client's first command to its disconnection: filling the loopback
/// socket buffers (a few MB at about 2.5 MB/s of telemetry and replies: about 3 s here),
/// then the server's reply bound (`server::REPLY_QUEUE_BYTES`: under 0.1 s more) or at
/// most its stall bound ([`STALL_TIMEOUT`], 2 s), with room for a loaded machine.
const STUCK_DISCONNECT_WITHIN: Duration = STALL_TIMEOUT.saturating_add(Duration::from_secs(10));
/// Open descriptors allowed above the count before the cycles.
const FD_SLACK: usize = 3;
/// Resident-memory growth allowed over the whole soak, KiB.
const RSS_GROWTH_KIB: u64 = 32 * 1024;
/// How long a cycle waits for the hello or a reply.
const REPLY_TIMEOUT: Duration = Duration::from_secs(5);

fn open_fds() -> usize {
    std::fs::read_dir("/proc/self/fd")
        .expect("/proc/self/fd")
        .count()
}

fn rss_kib() -> u64 {
    let s = std::fs::read_to_string("/proc/self/status").expect("/proc/self/status");
    s.lines()
        .find_map(|l| l.strip_prefix("VmRSS:"))
        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
        .expect("VmRSS")
}

/// Polls `f` until it holds or `within` has passed; its last value.
fn eventually(within: Duration, mut f: impl FnMut() -> bool) -> bool {
    let t0 = Instant::now();
    loop {
        if f() {
            return true;
        }
        if t0.elapsed() > within {
            return false;
        }
        thread::sleep(Duration::from_millis(10));
    }
}

/// Reads telemetry until `done`; the longest wall-clock gap between two `$T` frames (and
/// from the last one to `done`) and the number of frames.
fn watch(addr: SocketAddr, done: Arc<AtomicBool>) -> (Duration, u64) {
    let s = TcpStream::connect(addr).unwrap();
    s.set_read_timeout(Some(Duration::from_millis(50))).unwrap();
    (&s).write_all(b"stream on\r\n").unwrap();
    let mut r = BufReader::new(s);
    let mut line = Vec::new();
    let mut last: Option<Instant> = None;
    let (mut gap, mut frames) = (Duration::ZERO, 0u64);
    while !done.load(Ordering::Relaxed) {
        match r.read_until(b'\n', &mut line) {
            Ok(0) => panic!("the watcher was disconnected"),
            // a timeout may leave part of a line: keep it for the next read
            Ok(_) if line.last() == Some(&b'\n') => {
                if line.starts_with(b"$T,") {
                    let now = Instant::now();
                    if let Some(t) = last {
                        gap = gap.max(now - t);
                    }
                    last = Some(now);
                    frames += 1;
                }
                line.clear();
            }
            Ok(_) => {}
            Err(e) if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut) => {}
            Err(e) => panic!("the watcher's read failed: {e}"),
        }
    }
    if let Some(t) = last {
        gap = gap.max(t.elapsed());
    }
    (gap, frames)
}

/// The stuck client's commands, sent every millisecond without reading a byte, until a
/// send fails (the server closed the connection) or `done`. When the sends failed.
fn flood(s: TcpStream, done: Arc<AtomicBool>) -> Option<Instant> {
    s.set_write_timeout(Some(Duration::from_millis(500)))
        .unwrap();
    let mut w = &s;
    w.write_all(b"stream on\r\nrate 2\r\n").unwrap();
    while !done.load(Ordering::Relaxed) {
        match w.write_all(b"params\r\nstatus\r\n") {
            Ok(()) => {}
            // the server is not reading its input (backpressure): try again
            Err(e) if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut) => {}
            Err(_) => return Some(Instant::now()),
        }
        thread::sleep(Duration::from_millis(1));
    }
    None
}

/// One short connection: the hello and ready line, `rate 2` (one logged event), its reply
/// if `wait_reply`, then close.
fn cycle(addr: SocketAddr, wait_reply: bool) -> Result<(), String> {
    let s =
        TcpStream::connect_timeout(&addr, REPLY_TIMEOUT).map_err(|e| format!("connect: {e}"))?;
    s.set_read_timeout(Some(REPLY_TIMEOUT)).unwrap();
    let mut r = BufReader::new(&s);
    let mut l = String::new();
    for want in ["$V,1,", "acim-vboard ready"] {
        l.clear();
        r.read_line(&mut l).map_err(|e| format!("no hello: {e}"))?;
        if !l.starts_with(want) {
            return Err(format!("expected {want:?}, got {l:?}"));
        }
    }
    (&s).write_all(b"rate 2\r\n")
        .map_err(|e| format!("send: {e}"))?;
    if wait_reply {
        l.clear();
        r.read_line(&mut l)
            .map_err(|e| format!("no reply to rate 2: {e}"))?;
        if l != "ok\r\n" {
            return Err(format!("reply to rate 2: {l:?}"));
        }
    }
    Ok(())
}

#[test]
fn thousands_of_connections_and_a_client_that_never_reads() {
    let fd_start = open_fds();
    let srv: ServerHandle = server::start(
        TcpListener::bind("127.0.0.1:0").unwrap(),
        Options {
            pace: Pace::Factor(5.0),
            rate: None,
        },
    )
    .unwrap();
    let addr = srv.local_addr();
    let mut problems: Vec<String> = Vec::new();

    let done = Arc::new(AtomicBool::new(false));
    let watcher = {
        let done = done.clone();
        thread::spawn(move || watch(addr, done))
    };
    // the watcher's connection is up (its two descriptors and the server's one)
    thread::sleep(Duration::from_millis(200));
    let fd_base = open_fds();
    let rss_base = rss_kib();

    let stuck = TcpStream::connect(addr).unwrap();
    let stuck_started = Instant::now();
    let flooder = {
        let (s, done) = (stuck.try_clone().unwrap(), done.clone());
        thread::spawn(move || flood(s, done))
    };

    // the cycles; once a reply is missing, the rest only connect and close (each missing
    // reply would cost the whole timeout)
    let t0 = Instant::now();
    let mut wait_reply = true;
    let mut failed_cycles = 0;
    for k in 0..CYCLES {
        if let Err(e) = cycle(addr, wait_reply) {
            if failed_cycles == 0 {
                problems.push(format!("cycle {k}: {e}"));
            }
            failed_cycles += 1;
            wait_reply = false;
        }
    }
    let cycles_took = t0.elapsed();
    if failed_cycles > 0 {
        problems.push(format!("{failed_cycles} of {CYCLES} cycles failed"));
    }

    // the stuck client is disconnected within its bound
    let deadline = STUCK_DISCONNECT_WITHIN.saturating_sub(stuck_started.elapsed());
    if !eventually(deadline, || flooder.is_finished()) {
        problems.push(format!(
            "the client that never reads was not disconnected within {STUCK_DISCONNECT_WITHIN:?}"
        ));
    }
    done.store(true, Ordering::Relaxed);
    let stuck_cut = flooder.join().unwrap();
    let (gap, frames) = watcher.join().unwrap();
    if gap > MAX_GAP {
        problems.push(format!(
            "the watcher's telemetry stopped for {gap:?} (bound {MAX_GAP:?})"
        ));
    }
    if frames < 1000 {
        problems.push(format!("the watcher got only {frames} frames"));
    }
    // the stuck client reads what reached it: the server closed its end
    if stuck_cut.is_some() {
        stuck
            .set_read_timeout(Some(Duration::from_secs(2)))
            .unwrap();
        let mut buf = vec![0u8; 1 << 16];
        loop {
            match (&stuck).read(&mut buf) {
                Ok(0) => break,
                Ok(_) => {}
                Err(e) if e.kind() == ErrorKind::ConnectionReset => break,
                Err(e) => {
                    problems.push(format!("the stuck client's socket was not closed: {e}"));
                    break;
                }
            }
        }
    }
    drop(stuck);

    // descriptors: back to the count before the cycles, the server still running
    let mut fds = open_fds();
    if !eventually(Duration::from_secs(5), || {
        fds = open_fds();
        fds <= fd_base + FD_SLACK
    }) {
        problems.push(format!(
            "{fds} descriptors open after {CYCLES} closed connections, {fd_base} before"
        ));
    }
    let rss = rss_kib();
    if rss > rss_base + RSS_GROWTH_KIB {
        problems.push(format!(
            "resident memory grew from {rss_base} KiB to {rss} KiB"
        ));
    }
    let log = srv.log();
    if srv.logged() < CYCLES as u64 {
        problems.push(format!(
            "{} events logged, {CYCLES} expected (one per cycle)",
            srv.logged()
        ));
    }
    if log.len() > LOG_CAPACITY {
        problems.push(format!(
            "the event log holds {} entries (bound {LOG_CAPACITY})",
            log.len()
        ));
    }
    eprintln!(
        "soak: {CYCLES} cycles in {cycles_took:?}; watcher {frames} frames, longest gap {gap:?}; \
         stuck client cut after {:?}; {} frames dropped; fds {fd_start} -> {fd_base} -> {fds}; \
         VmRSS {rss_base} -> {rss} KiB; log {} entries",
        stuck_cut.map(|t| t - stuck_started),
        srv.dropped(),
        log.len()
    );
    assert!(problems.is_empty(), "{}", problems.join("\n"));

    srv.shutdown();
    let mut fds = open_fds();
    assert!(
        eventually(Duration::from_secs(5), || {
            fds = open_fds();
            fds <= fd_start + FD_SLACK
        }),
        "{fds} descriptors open after shutdown, {fd_start} before the server"
    );
}
