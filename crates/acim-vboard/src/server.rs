//! The board on a local TCP port: one simulation thread paced to real time (or a multiple
//! of it, or as fast as it runs), an acceptor thread, and a reader and a writer thread per
//! connection.
//!
//! Each connection is one "cable": it receives the hello frame and the ready line, sends
//! commands, and gets telemetry once it says `stream on`. Closing it (or
//! [`ServerHandle::disconnect_all`], a cable pull) leaves the drive running, as a board
//! does.
//!
//! # Output and its bounds
//!
//! The simulation thread never waits for a connection: it puts each reply and telemetry
//! sample in the connection's output queue (a mutex held only to push or pop, never
//! across I/O) and the connection's writer thread sends them, replies first.
//!
//! - **Telemetry** at a [`Pace::Factor`]: a sample that finds [`FRAME_QUEUE_BYTES`] of
//!   samples still queued for a connection is dropped for that connection (whole: a `$T`
//!   and its `$X`), counted in [`ServerHandle::dropped`]. At [`Pace::Max`] no sample is
//!   dropped: the board does not run the next sample's periods until every streaming
//!   connection has less than [`LOSSLESS_FRAME_QUEUE_BYTES`] queued (it keeps answering
//!   commands meanwhile).
//! - **Replies** are never dropped. A connection with more than [`REPLY_QUEUE_BYTES`] of
//!   replies unsent is disconnected.
//! - A connection whose socket does not take a batch of output (at most
//!   [`WRITE_BATCH_BYTES`]) within [`STALL_TIMEOUT`] is disconnected: a host reading less
//!   than 2 KiB/s, or nothing (at [`Pace::Max`] that is also about the longest a stalled
//!   reader holds the board).
//!
//! When a connection ends (the host closes it, a bound above, a cable pull), its socket
//! is shut down, both its threads end and are joined, and the last handle to it closes its
//! descriptor. A host that closes only its sending half still gets the replies already
//! queued.

use crate::board::{Board, EventLog, Logged, READY_LINE};
use acim_firmware_core::board::PWM_FREQUENCY_HZ;
use acim_firmware_core::protocol::{self, MAX_FRAMED_LINE};
use std::collections::{BTreeMap, VecDeque};
use std::io::{self, Read, Write};
use std::net::{IpAddr, Ipv4Addr, Ipv6Addr, Shutdown, SocketAddr, TcpListener, TcpStream};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{self, Receiver, SyncSender, TryRecvError};
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::thread::{self, JoinHandle};
use std::time::{Duration, Instant};

/// Unsent reply bytes past which a connection is disconnected. The longest reply
/// (`params`, `get`) is under 1 KiB and a host normally waits for each reply, so only a
/// host that sends command after command without reading (beyond what the kernel's socket
/// buffers hold) gets here; replies cannot be dropped instead.
pub const REPLY_QUEUE_BYTES: usize = 64 * 1024;

/// Telemetry bytes queued for one connection at a [`Pace::Factor`] beyond which new
/// samples are dropped for it: about 1 000 samples of about 125 bytes, 0.4 s at the
/// fastest rate (2 periods) in real time, 100 s at the default 10 Hz; room for the
/// bursts of a board catching up (at most 500 periods per round). The queue holds at most
/// this plus one sample.
pub const FRAME_QUEUE_BYTES: usize = 128 * 1024;

/// Telemetry bytes queued for one connection at [`Pace::Max`] beyond which the board waits
/// for it: about 64 samples, so what a reader sees stays close to the board's present.
pub const LOSSLESS_FRAME_QUEUE_BYTES: usize = 8 * 1024;

/// How long one batch of output ([`WRITE_BATCH_BYTES`]) may take to go into the socket
/// before the connection is closed. A local reader that takes less than that in this
/// time is stopped or gone.
pub const STALL_TIMEOUT: Duration = Duration::from_secs(2);

/// The most bytes a writer thread takes from its queue for one write, bytes (whole
/// entries; a larger single entry, which no reply or sample is, goes alone).
pub const WRITE_BATCH_BYTES: usize = 4 * 1024;

/// Messages (lines, connections, ends) waiting for the simulation thread, from all
/// connections together; a reader that finds the queue full waits, which holds back its
/// host through TCP's flow control.
const INCOMING_DEPTH: usize = 1024;

/// The most messages the simulation thread handles between two rounds of periods, so a
/// host flooding commands cannot starve the telemetry of the others.
const MESSAGES_PER_ROUND: usize = 256;

/// How fast simulated time runs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Pace {
    /// This many simulated seconds per wall-clock second (1 = real time). A connection
    /// that does not keep up loses telemetry frames, never replies.
    Factor(f64),
    /// As fast as the host runs it; telemetry is never dropped (a slow reader slows the
    /// simulation down; one that takes no batch of output within [`STALL_TIMEOUT`] is
    /// disconnected).
    Max,
}

impl Pace {
    /// Parses `--speed`: a positive factor or `max`.
    pub fn parse(s: &str) -> Result<Pace, String> {
        if s == "max" {
            return Ok(Pace::Max);
        }
        match s.parse::<f64>() {
            Ok(f) if f.is_finite() && f > 0.0 && f <= 1000.0 => Ok(Pace::Factor(f)),
            _ => Err(format!(
                "--speed takes a factor in (0, 1000] or `max`, got {s:?}"
            )),
        }
    }
}

/// Server options.
#[derive(Clone, Copy, Debug)]
pub struct Options {
    /// Simulated time against wall-clock time.
    pub pace: Pace,
    /// Telemetry decimation at power-up (the firmware's is 500 periods, 10 Hz).
    pub rate: Option<u16>,
}

impl Default for Options {
    fn default() -> Self {
        Self {
            pace: Pace::Factor(1.0),
            rate: None,
        }
    }
}

/// The bounds of one connection's output.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Limits {
    /// Unsent reply bytes past which the connection is closed.
    reply_bytes: usize,
    /// Queued telemetry bytes from which samples are dropped (at a factor) or the board
    /// waits (at max).
    frame_bytes: usize,
    /// The longest a batch of output may take to go into the socket.
    stall: Duration,
}

impl Limits {
    fn for_pace(pace: Pace) -> Self {
        Self {
            reply_bytes: REPLY_QUEUE_BYTES,
            frame_bytes: match pace {
                Pace::Factor(_) => FRAME_QUEUE_BYTES,
                Pace::Max => LOSSLESS_FRAME_QUEUE_BYTES,
            },
            stall: STALL_TIMEOUT,
        }
    }
}

/// What became of a telemetry sample offered to a connection.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Offered {
    Queued,
    /// Its queue was full: this connection does not get it.
    Dropped,
    /// The connection is closed.
    Closed,
}

/// Where a connection's output stands.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Flow {
    Open,
    /// The host closed its sending half: send what is queued, then end.
    Finishing,
    /// Ended: nothing more is sent, the queue is discarded.
    Closed,
}

/// One connection's output waiting for its writer thread: the queue policy, without I/O.
#[derive(Debug)]
struct Outbox {
    replies: VecDeque<Vec<u8>>,
    reply_bytes: usize,
    frames: VecDeque<Vec<u8>>,
    frame_bytes: usize,
    limits: Limits,
    flow: Flow,
}

impl Outbox {
    fn new(limits: Limits) -> Self {
        Self {
            replies: VecDeque::new(),
            reply_bytes: 0,
            frames: VecDeque::new(),
            frame_bytes: 0,
            limits,
            flow: Flow::Open,
        }
    }

    fn is_empty(&self) -> bool {
        self.replies.is_empty() && self.frames.is_empty()
    }

    /// Queues a reply. `false`: it would put more than the reply bound unsent, so the
    /// outbox is closed instead (its queue discarded); also `false` once closed.
    fn push_reply(&mut self, bytes: Vec<u8>) -> bool {
        if self.flow == Flow::Closed {
            return false;
        }
        if self.reply_bytes + bytes.len() > self.limits.reply_bytes {
            self.close();
            return false;
        }
        self.reply_bytes += bytes.len();
        self.replies.push_back(bytes);
        true
    }

    /// Room for another telemetry sample (a closed outbox takes and discards any).
    fn has_frame_room(&self) -> bool {
        self.flow == Flow::Closed || self.frame_bytes < self.limits.frame_bytes
    }

    /// Queues a telemetry sample if there is room, else drops it.
    fn offer_frame(&mut self, bytes: Vec<u8>) -> Offered {
        if self.flow == Flow::Closed {
            Offered::Closed
        } else if self.frame_bytes < self.limits.frame_bytes {
            self.frame_bytes += bytes.len();
            self.frames.push_back(bytes);
            Offered::Queued
        } else {
            Offered::Dropped
        }
    }

    /// Whole entries, replies first, until the batch holds `max` bytes or more (a larger
    /// single entry goes alone); empty when nothing is queued or the outbox is closed.
    fn take_batch(&mut self, max: usize) -> Vec<u8> {
        let mut batch = Vec::new();
        if self.flow == Flow::Closed {
            return batch;
        }
        while batch.len() < max {
            if let Some(r) = self.replies.pop_front() {
                self.reply_bytes -= r.len();
                batch.extend_from_slice(&r);
            } else if let Some(f) = self.frames.pop_front() {
                self.frame_bytes -= f.len();
                batch.extend_from_slice(&f);
            } else {
                break;
            }
        }
        batch
    }

    /// Send what is queued, then end.
    fn finish(&mut self) {
        if self.flow == Flow::Open {
            self.flow = Flow::Finishing;
        }
    }

    /// End now, discarding the queue.
    fn close(&mut self) {
        self.flow = Flow::Closed;
        self.replies = VecDeque::new();
        self.frames = VecDeque::new();
        self.reply_bytes = 0;
        self.frame_bytes = 0;
    }

    /// Nothing more will be sent.
    fn is_done(&self) -> bool {
        match self.flow {
            Flow::Open => false,
            Flow::Finishing => self.is_empty(),
            Flow::Closed => true,
        }
    }
}

/// One connection, shared by its reader and writer threads, the simulation thread and the
/// server's list of connections; its descriptor closes when the last of them drops it.
struct Link {
    sock: TcpStream,
    out: Mutex<Outbox>,
    /// Wakes the writer: output queued on an empty outbox, or its end.
    wake: Condvar,
}

impl Link {
    fn new(sock: TcpStream, limits: Limits) -> io::Result<Self> {
        sock.set_nonblocking(false)?;
        sock.set_nodelay(true)?;
        Ok(Self {
            sock,
            out: Mutex::new(Outbox::new(limits)),
            wake: Condvar::new(),
        })
    }

    fn lock(&self) -> MutexGuard<'_, Outbox> {
        self.out.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Queues a reply; `false`: the connection is closed (now, past the reply bound, or
    /// before).
    fn reply(&self, bytes: Vec<u8>) -> bool {
        let mut o = self.lock();
        let was_empty = o.is_empty();
        if o.push_reply(bytes) {
            if was_empty {
                self.wake.notify_one();
            }
            true
        } else {
            drop(o);
            self.close();
            false
        }
    }

    fn offer_frame(&self, bytes: Vec<u8>) -> Offered {
        let mut o = self.lock();
        let was_empty = o.is_empty();
        let r = o.offer_frame(bytes);
        if r == Offered::Queued && was_empty {
            self.wake.notify_one();
        }
        r
    }

    fn has_frame_room(&self) -> bool {
        self.lock().has_frame_room()
    }

    /// The host closed its sending half: the writer sends what is queued, then ends.
    fn finish(&self) {
        self.lock().finish();
        self.wake.notify_all();
    }

    /// Ends the connection now: the queue is discarded, the socket shut down (which ends
    /// a blocked read or write of either thread).
    fn close(&self) {
        self.lock().close();
        self.wake.notify_all();
        let _ = self.sock.shutdown(Shutdown::Both);
    }

    fn is_closed(&self) -> bool {
        self.lock().flow == Flow::Closed
    }
}

/// The writer thread's body: sends queued output until the outbox is done, or closes the
/// connection when a write fails (the host went, or did not take a batch within the stall
/// bound).
fn write_out(link: &Link) {
    let stall = link.lock().limits.stall;
    loop {
        let batch = {
            let mut o = link.lock();
            loop {
                let b = o.take_batch(WRITE_BATCH_BYTES);
                if !b.is_empty() {
                    break b;
                }
                if o.is_done() {
                    return;
                }
                o = link.wake.wait(o).unwrap_or_else(|e| e.into_inner());
            }
        };
        if send(&link.sock, &batch, stall).is_err() {
            link.close();
            return;
        }
    }
}

/// Writes all of `bytes` within `within` (the partial writes of a slow reader do not
/// extend it, as a plain write timeout would).
fn send(sock: &TcpStream, bytes: &[u8], within: Duration) -> io::Result<()> {
    let t0 = Instant::now();
    let mut rest = bytes;
    while !rest.is_empty() {
        let left = within.saturating_sub(t0.elapsed());
        if left.is_zero() {
            return Err(io::ErrorKind::TimedOut.into());
        }
        sock.set_write_timeout(Some(left))?;
        match (&*sock).write(rest) {
            Ok(0) => return Err(io::ErrorKind::WriteZero.into()),
            Ok(n) => rest = &rest[n..],
            Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(())
}

enum Incoming {
    Connected(u64, Arc<Link>),
    Line(u64, Vec<u8>),
    TooLong(u64, bool),
    /// The connection's input ended; `true`: cleanly, the host closed its sending half
    /// (send what is queued first).
    Closed(u64, bool),
}

struct Client {
    link: Arc<Link>,
    stream: bool,
}

struct Shared {
    stop: AtomicBool,
    period: AtomicU64,
    dropped: AtomicU64,
    /// The board's events, moved here from the board as they happen (kept once).
    log: Mutex<EventLog>,
    /// The open connections, for a cable pull and shutdown; each removes itself.
    links: Mutex<BTreeMap<u64, Arc<Link>>>,
}

impl Shared {
    fn links(&self) -> MutexGuard<'_, BTreeMap<u64, Arc<Link>>> {
        self.links.lock().unwrap_or_else(|e| e.into_inner())
    }

    fn log(&self) -> MutexGuard<'_, EventLog> {
        self.log.lock().unwrap_or_else(|e| e.into_inner())
    }
}

/// A running server.
pub struct ServerHandle {
    addr: SocketAddr,
    shared: Arc<Shared>,
    sim: Option<JoinHandle<()>>,
    acceptor: Option<JoinHandle<()>>,
}

impl ServerHandle {
    /// The address it listens on.
    pub fn local_addr(&self) -> SocketAddr {
        self.addr
    }

    /// Periods simulated so far.
    pub fn period(&self) -> u64 {
        self.shared.period.load(Ordering::Relaxed)
    }

    /// Telemetry frames dropped for connections that did not keep up.
    pub fn dropped(&self) -> u64 {
        self.shared.dropped.load(Ordering::Relaxed)
    }

    /// The last [`LOG_CAPACITY`](crate::board::LOG_CAPACITY) commands, rate and settings
    /// changes that took effect, at their periods, oldest first (refused commands are not
    /// logged). It goes back to power-up while [`ServerHandle::logged`] equals its
    /// length.
    pub fn log(&self) -> Vec<Logged> {
        self.shared.log().to_vec()
    }

    /// Events logged since power-up, kept in [`ServerHandle::log`] or not.
    pub fn logged(&self) -> u64 {
        self.shared.log().total()
    }

    /// Connections accepted and not yet ended.
    pub fn connections(&self) -> usize {
        self.shared.links().len()
    }

    /// Closes every connection (a cable pull); the drive keeps running.
    pub fn disconnect_all(&self) {
        for l in self.shared.links().values() {
            l.close();
        }
    }

    /// Stops the simulation and every thread, closes every connection and the listener.
    pub fn shutdown(mut self) {
        self.shared.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.sim.take() {
            let _ = t.join();
        }
        // the acceptor waits in accept(): a connection of our own wakes it
        let wake = SocketAddr::new(
            match self.addr.ip() {
                IpAddr::V4(a) if a.is_unspecified() => IpAddr::V4(Ipv4Addr::LOCALHOST),
                IpAddr::V6(a) if a.is_unspecified() => IpAddr::V6(Ipv6Addr::LOCALHOST),
                a => a,
            },
            self.addr.port(),
        );
        match TcpStream::connect_timeout(&wake, Duration::from_secs(1)) {
            Ok(_) => {
                if let Some(t) = self.acceptor.take() {
                    let _ = t.join();
                }
            }
            // it ends at the next connection; the connections close now
            Err(e) => {
                eprintln!(
                    "acim-vboard: cannot wake the acceptor ({e}); it ends at the next connection"
                );
                self.disconnect_all();
            }
        }
    }

    /// Blocks until the server stops (it runs until the process ends).
    pub fn wait(mut self) {
        for t in [self.sim.take(), self.acceptor.take()]
            .into_iter()
            .flatten()
        {
            let _ = t.join();
        }
    }
}

/// Starts serving on `listener`.
pub fn start(listener: TcpListener, opts: Options) -> io::Result<ServerHandle> {
    let addr = listener.local_addr()?;
    listener.set_nonblocking(false)?;
    let shared = Arc::new(Shared {
        stop: AtomicBool::new(false),
        period: AtomicU64::new(0),
        dropped: AtomicU64::new(0),
        log: Mutex::new(EventLog::default()),
        links: Mutex::new(BTreeMap::new()),
    });
    let (in_tx, in_rx) = mpsc::sync_channel::<Incoming>(INCOMING_DEPTH);
    let sim = {
        let shared = shared.clone();
        thread::Builder::new()
            .name("vboard-sim".into())
            .spawn(move || simulate(opts, in_rx, &shared))?
    };
    let acceptor = {
        let shared = shared.clone();
        let limits = Limits::for_pace(opts.pace);
        thread::Builder::new()
            .name("vboard-accept".into())
            .spawn(move || accept(listener, in_tx, &shared, limits))?
    };
    Ok(ServerHandle {
        addr,
        shared,
        sim: Some(sim),
        acceptor: Some(acceptor),
    })
}

/// The acceptor thread: opens each connection and joins the threads of those that ended
/// (at each accept, and all of them at shutdown).
fn accept(
    listener: TcpListener,
    in_tx: SyncSender<Incoming>,
    shared: &Arc<Shared>,
    limits: Limits,
) {
    let mut next_id = 0u64;
    let mut conns: Vec<JoinHandle<()>> = Vec::new();
    loop {
        let accepted = listener.accept();
        if shared.stop.load(Ordering::Relaxed) {
            break;
        }
        let (ended, live): (Vec<_>, Vec<_>) = conns.into_iter().partition(|t| t.is_finished());
        conns = live;
        for t in ended {
            let _ = t.join();
        }
        match accepted {
            Ok((sock, _)) => {
                next_id += 1;
                match open(next_id, sock, &in_tx, shared, limits) {
                    Ok(t) => conns.push(t),
                    Err(e) => eprintln!("acim-vboard: connection refused: {e}"),
                }
            }
            // e.g. out of descriptors: the pending connections wait in the backlog
            Err(e) => {
                eprintln!("acim-vboard: accept: {e}");
                thread::sleep(Duration::from_millis(10));
            }
        }
    }
    drop(listener);
    for l in shared.links().values() {
        l.close();
    }
    for t in conns {
        let _ = t.join();
    }
}

/// Sets up a connection: its hello, its place in the list and the simulation, its thread.
fn open(
    id: u64,
    sock: TcpStream,
    in_tx: &SyncSender<Incoming>,
    shared: &Arc<Shared>,
    limits: Limits,
) -> io::Result<JoinHandle<()>> {
    let link = Arc::new(Link::new(sock, limits)?);
    let mut hello = protocol::hello_frame(PWM_FREQUENCY_HZ, crate::board::BOARD_NAME).to_vec();
    hello.extend_from_slice(format!("{READY_LINE}\r\n").as_bytes());
    link.reply(hello);
    if in_tx.send(Incoming::Connected(id, link.clone())).is_err() {
        link.close();
        return Err(io::Error::other("the simulation has stopped"));
    }
    shared.links().insert(id, link.clone());
    let spawned = {
        let (link, in_tx, shared) = (link.clone(), in_tx.clone(), shared.clone());
        thread::Builder::new()
            .name(format!("vboard-rx{id}"))
            .spawn(move || serve(id, &link, &in_tx, &shared))
    };
    if spawned.is_err() {
        link.close();
        shared.links().remove(&id);
        let _ = in_tx.send(Incoming::Closed(id, false));
    }
    spawned
}

/// A connection's thread: starts its writer, reads its lines for the simulation until the
/// input ends, then ends the connection and joins the writer.
fn serve(id: u64, link: &Arc<Link>, in_tx: &SyncSender<Incoming>, shared: &Shared) {
    let writer = {
        let link = link.clone();
        thread::Builder::new()
            .name(format!("vboard-tx{id}"))
            .spawn(move || write_out(&link))
    };
    let clean_end = match &writer {
        Ok(_) => read_lines(id, link, in_tx),
        Err(e) => {
            eprintln!("acim-vboard: connection {id}: no writer thread: {e}");
            false
        }
    };
    if !clean_end {
        link.close();
    }
    // the simulation drops the connection (after the writer has sent what is queued, on a
    // clean end); if it has stopped, nobody else will end it
    if in_tx.send(Incoming::Closed(id, clean_end)).is_err() {
        link.close();
    }
    if let Ok(w) = writer {
        let _ = w.join();
    }
    link.close();
    shared.links().remove(&id);
}

/// Reads lines for the simulation until the input ends: `true` at the host's clean end of
/// its sending half, `false` on an error, a closed connection or a stopped simulation.
fn read_lines(id: u64, link: &Link, in_tx: &SyncSender<Incoming>) -> bool {
    let mut line: Vec<u8> = Vec::new();
    let mut overflow = false;
    let mut buf = [0u8; 512];
    loop {
        let n = match (&link.sock).read(&mut buf) {
            Ok(0) => return !link.is_closed(),
            Ok(n) => n,
            Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
            Err(_) => return false,
        };
        for &b in &buf[..n] {
            if b == b'\r' || b == b'\n' {
                let msg = if overflow {
                    Some(Incoming::TooLong(id, line.first() == Some(&b'$')))
                } else if !line.is_empty() {
                    Some(Incoming::Line(id, std::mem::take(&mut line)))
                } else {
                    None
                };
                line.clear();
                overflow = false;
                if let Some(m) = msg {
                    if in_tx.send(m).is_err() {
                        return false;
                    }
                }
            } else if line.len() < MAX_FRAMED_LINE + 1 {
                line.push(b);
            } else {
                overflow = true;
            }
        }
    }
}

/// The simulation thread: the board, its commands and replies, its telemetry to the
/// streaming connections. It never waits on a connection.
fn simulate(opts: Options, in_rx: Receiver<Incoming>, shared: &Shared) {
    let mut board = Board::new(true);
    if let Some(n) = opts.rate {
        board.set_rate(n);
    }
    let mut clients: BTreeMap<u64, Client> = BTreeMap::new();
    let pwm = PWM_FREQUENCY_HZ as f64;
    let mut t0 = Instant::now();
    let mut p0 = 0u64;
    while !shared.stop.load(Ordering::Relaxed) {
        for _ in 0..MESSAGES_PER_ROUND {
            match in_rx.try_recv() {
                Ok(m) => handle(&mut board, &mut clients, m),
                Err(TryRecvError::Empty | TryRecvError::Disconnected) => break,
            }
        }
        if !board.log().is_empty() {
            board.take_log_into(&mut shared.log());
        }
        let n = match opts.pace {
            Pace::Max => 50,
            Pace::Factor(f) => {
                let due = p0 + (t0.elapsed().as_secs_f64() * pwm * f) as u64;
                let behind = due.saturating_sub(board.period());
                if behind as f64 > 0.5 * pwm * f {
                    // the host cannot keep this pace: carry on from here, no catch-up burst
                    t0 = Instant::now();
                    p0 = board.period();
                }
                behind.min(500)
            }
        };
        if n == 0 {
            thread::sleep(Duration::from_micros(500));
            continue;
        }
        let waiting = run(&mut board, &mut clients, n, opts.pace, shared);
        shared.period.store(board.period(), Ordering::Relaxed);
        if waiting {
            // at max: a streaming connection's queue is full; its writer drains it, or
            // the stall bound ends it
            thread::sleep(Duration::from_micros(100));
        }
    }
    for c in clients.values() {
        c.link.close();
    }
}

/// One message for the simulation thread.
fn handle(board: &mut Board, clients: &mut BTreeMap<u64, Client>, m: Incoming) {
    let (id, reply) = match m {
        Incoming::Connected(id, link) => {
            clients.insert(
                id,
                Client {
                    link,
                    stream: false,
                },
            );
            return;
        }
        Incoming::Closed(id, clean) => {
            if let Some(c) = clients.remove(&id) {
                if clean {
                    c.link.finish();
                } else {
                    c.link.close();
                }
            }
            return;
        }
        Incoming::TooLong(id, framed) => (id, Board::too_long(framed)),
        Incoming::Line(id, line) => match clients.get_mut(&id) {
            Some(c) => (id, board.handle_line(&line, &mut c.stream).concat()),
            None => return,
        },
    };
    if reply.is_empty() {
        return;
    }
    // past the reply bound the connection is closed: it takes no more
    if let Some(c) = clients.get(&id) {
        if !c.link.reply(reply) {
            clients.remove(&id);
        }
    }
}

/// Runs up to `n` periods and offers each telemetry sample to the streaming connections.
/// At [`Pace::Max`] it stops before a sample that a full queue could not take; `true`
/// then.
fn run(
    board: &mut Board,
    clients: &mut BTreeMap<u64, Client>,
    mut n: u64,
    pace: Pace,
    shared: &Shared,
) -> bool {
    let lossless = pace == Pace::Max;
    while n > 0 {
        if lossless
            && !clients
                .values()
                .all(|c| !c.stream || c.link.has_frame_room())
        {
            return true;
        }
        let mut sample = None;
        while n > 0 && sample.is_none() {
            n -= 1;
            sample = board.step();
        }
        let Some(s) = sample else { break };
        let bytes = s.encode();
        clients.retain(|_, c| {
            if !c.stream {
                return true;
            }
            match c.link.offer_frame(bytes.clone()) {
                Offered::Queued => true,
                Offered::Dropped => {
                    shared.dropped.fetch_add(1, Ordering::Relaxed);
                    true
                }
                Offered::Closed => false,
            }
        });
    }
    false
}

#[cfg(test)]
mod tests {
    use super::*;

    fn limits(reply_bytes: usize, frame_bytes: usize) -> Limits {
        Limits {
            reply_bytes,
            frame_bytes,
            stall: Duration::from_millis(100),
        }
    }

    #[test]
    fn frames_are_dropped_replies_are_kept() {
        let mut o = Outbox::new(limits(1000, 50));
        // frames queue while under the bound (the last may pass it by one frame)
        assert_eq!(o.offer_frame(vec![b'a'; 20]), Offered::Queued);
        assert_eq!(o.offer_frame(vec![b'b'; 20]), Offered::Queued);
        assert_eq!(o.offer_frame(vec![b'c'; 20]), Offered::Queued);
        assert!(!o.has_frame_room());
        assert_eq!(o.offer_frame(vec![b'd'; 20]), Offered::Dropped);
        // replies still queue, and go first
        assert!(o.push_reply(b"ok\r\n".to_vec()));
        assert!(o.push_reply(b"ok 2\r\n".to_vec()));
        let all = o.take_batch(usize::MAX);
        assert_eq!(
            all,
            [
                &b"ok\r\nok 2\r\n"[..],
                &[b'a'; 20],
                &[b'b'; 20],
                &[b'c'; 20]
            ]
            .concat()
        );
        assert!(o.is_empty() && o.has_frame_room());
        assert_eq!(o.offer_frame(vec![b'e'; 20]), Offered::Queued);
    }

    #[test]
    fn batches_are_whole_entries() {
        let mut o = Outbox::new(limits(1000, 1000));
        for k in 0..5u8 {
            assert_eq!(o.offer_frame(vec![k; 30]), Offered::Queued);
        }
        assert!(o.push_reply(vec![9; 100]));
        // a larger single entry goes alone; then whole entries up to the batch size
        assert_eq!(o.take_batch(50), vec![9; 100]);
        assert_eq!(o.take_batch(50), [vec![0; 30], vec![1; 30]].concat());
        assert_eq!(
            o.take_batch(1000),
            [vec![2; 30], vec![3; 30], vec![4; 30]].concat()
        );
        assert!(o.take_batch(1000).is_empty());
    }

    #[test]
    fn replies_past_the_bound_close_the_connection() {
        let mut o = Outbox::new(limits(100, 1000));
        assert!(o.push_reply(vec![b'r'; 60]));
        assert!(o.push_reply(vec![b'r'; 40]));
        assert_eq!(o.offer_frame(vec![b'f'; 20]), Offered::Queued);
        // 101 bytes would be unsent: closed, everything discarded, nothing more taken
        assert!(!o.push_reply(vec![b'r'; 1]));
        assert!(o.is_done());
        assert!(o.take_batch(1000).is_empty());
        assert!(!o.push_reply(b"ok\r\n".to_vec()));
        assert_eq!(o.offer_frame(vec![b'f'; 20]), Offered::Closed);
        // a closed connection never holds the board back
        assert!(o.has_frame_room());
    }

    #[test]
    fn a_finishing_connection_sends_what_is_queued() {
        let mut o = Outbox::new(limits(100, 100));
        assert!(o.push_reply(b"ok\r\n".to_vec()));
        o.finish();
        assert!(!o.is_done());
        assert_eq!(o.take_batch(1000), b"ok\r\n");
        assert!(o.is_done());
    }

    /// Polls `f` for up to 5 s.
    fn eventually(f: impl Fn() -> bool) -> bool {
        let t0 = Instant::now();
        while !f() {
            if t0.elapsed() > Duration::from_secs(5) {
                return false;
            }
            thread::sleep(Duration::from_millis(10));
        }
        true
    }

    /// A pair of connected sockets: (the server's end, the host's end).
    fn socket_pair() -> (TcpStream, TcpStream) {
        let l = TcpListener::bind("127.0.0.1:0").unwrap();
        let host = TcpStream::connect(l.local_addr().unwrap()).unwrap();
        let (server, _) = l.accept().unwrap();
        (server, host)
    }

    #[test]
    fn a_reader_that_takes_nothing_is_disconnected_after_the_stall_bound() {
        let (server, host) = socket_pair();
        let link = Arc::new(Link::new(server, limits(64 * 1024, 64 * 1024)).unwrap());
        let writer = {
            let link = link.clone();
            thread::spawn(move || write_out(&link))
        };
        // until the host's socket buffers are full and a batch has waited for the stall
        // bound (100 ms here)
        let t0 = Instant::now();
        let mut offered = 0u64;
        while !link.is_closed() {
            assert!(
                t0.elapsed() < Duration::from_secs(20),
                "not disconnected after {offered} samples"
            );
            if link.offer_frame(vec![b'x'; 1024]) == Offered::Dropped {
                thread::sleep(Duration::from_millis(1));
            }
            offered += 1;
        }
        writer.join().unwrap();
        // the host reads what reached it, then the end
        host.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
        let mut buf = vec![0u8; 1 << 16];
        loop {
            match (&host).read(&mut buf) {
                Ok(0) => break,
                Ok(_) => {}
                Err(e) if e.kind() == io::ErrorKind::ConnectionReset => break,
                Err(e) => panic!("not closed: {e}"),
            }
        }
    }

    #[test]
    fn a_reader_that_keeps_up_is_not_disconnected() {
        let (server, host) = socket_pair();
        let link = Arc::new(Link::new(server, limits(64 * 1024, 64 * 1024)).unwrap());
        let writer = {
            let link = link.clone();
            thread::spawn(move || write_out(&link))
        };
        let reader = thread::spawn(move || {
            let mut n = 0usize;
            let mut buf = vec![0u8; 1 << 16];
            while let Ok(k @ 1..) = (&host).read(&mut buf) {
                n += k;
            }
            n
        });
        // 0.5 s of samples and replies, several stall bounds
        let t0 = Instant::now();
        let mut replies = 0;
        while t0.elapsed() < Duration::from_millis(500) {
            assert_ne!(link.offer_frame(vec![b'x'; 125]), Offered::Closed);
            assert!(link.reply(b"ok\r\n".to_vec()));
            replies += 1;
            thread::sleep(Duration::from_micros(200));
        }
        link.finish();
        writer.join().unwrap();
        link.close();
        assert!(reader.join().unwrap() >= replies * 4);
    }

    /// At max pace a streaming host that takes nothing holds the board for at most the
    /// stall bound (plus the time to fill its socket buffers); another host's commands are
    /// answered meanwhile.
    #[test]
    fn at_max_pace_a_stalled_reader_holds_the_board_only_for_a_bound() {
        let srv = start(
            TcpListener::bind("127.0.0.1:0").unwrap(),
            Options {
                pace: Pace::Max,
                rate: Some(2),
            },
        )
        .unwrap();
        let stuck = TcpStream::connect(srv.local_addr()).unwrap();
        (&stuck).write_all(b"stream on\r\n").unwrap();
        let other = TcpStream::connect(srv.local_addr()).unwrap();
        other
            .set_read_timeout(Some(Duration::from_secs(1)))
            .unwrap();
        let mut r = io::BufReader::new(&other);
        let mut line = String::new();
        let ask = |r: &mut io::BufReader<&TcpStream>, line: &mut String| {
            (&other).write_all(b"status\r\n").unwrap();
            loop {
                line.clear();
                io::BufRead::read_line(r, line).expect("a reply within 1 s");
                if line.starts_with("ok state") {
                    return;
                }
            }
        };
        // the board stalls (no period for 200 ms) once the stuck host's socket buffers are
        // full, until the stuck host is cut; replies to the other host all along
        let t0 = Instant::now();
        let (mut last, mut last_change) = (srv.period(), Instant::now());
        let mut stalled_since: Option<Instant> = None;
        let held = loop {
            assert!(
                t0.elapsed() < STALL_TIMEOUT + Duration::from_secs(10),
                "stalled since {stalled_since:?}, {} connections",
                srv.connections()
            );
            ask(&mut r, &mut line);
            let p = srv.period();
            if p != last {
                if let Some(s) = stalled_since {
                    break s.elapsed();
                }
                (last, last_change) = (p, Instant::now());
            } else if stalled_since.is_none() && last_change.elapsed() > Duration::from_millis(200)
            {
                stalled_since = Some(last_change);
            }
            thread::sleep(Duration::from_millis(20));
        };
        // the stall bound, and room for the disconnection
        assert!(
            held < STALL_TIMEOUT + Duration::from_secs(1),
            "held {held:?}"
        );
        assert!(
            eventually(|| srv.connections() == 1),
            "{} connections",
            srv.connections()
        );
        srv.shutdown();
    }
}
