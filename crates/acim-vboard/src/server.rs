//! The board on a local TCP port: one simulation thread paced to real time (or a multiple
//! of it, or as fast as it runs), and a reader and a writer thread per connection.
//!
//! Each connection is one "cable": it receives the hello frame and the ready line, sends
//! commands, and gets telemetry once it says `stream on`. Closing it (or
//! [`ServerHandle::disconnect_all`], a cable pull) leaves the drive running, as a board
//! does.

use crate::board::{Board, Logged, READY_LINE};
use acim_firmware_core::board::PWM_FREQUENCY_HZ;
use acim_firmware_core::protocol::{self, MAX_FRAMED_LINE};
use std::collections::BTreeMap;
use std::io::{self, Read, Write};
use std::net::{Shutdown, SocketAddr, TcpListener, TcpStream};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{self, Receiver, Sender, SyncSender, TrySendError};
use std::sync::{Arc, Mutex};
use std::thread::{self, JoinHandle};
use std::time::{Duration, Instant};

/// How fast simulated time runs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Pace {
    /// This many simulated seconds per wall-clock second (1 = real time). A connection
    /// that does not keep up loses telemetry frames, never replies.
    Factor(f64),
    /// As fast as the host runs it; telemetry is never dropped (a slow reader slows the
    /// simulation down).
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

enum Incoming {
    Connected(u64, SyncSender<Vec<u8>>, TcpStream),
    Line(u64, Vec<u8>),
    TooLong(u64, bool),
    Closed(u64),
}

struct Client {
    tx: SyncSender<Vec<u8>>,
    sock: TcpStream,
    stream: bool,
}

struct Shared {
    stop: AtomicBool,
    period: AtomicU64,
    dropped: AtomicU64,
    log: Mutex<Vec<Logged>>,
    socks: Mutex<Vec<TcpStream>>,
}

/// A running server.
pub struct ServerHandle {
    addr: SocketAddr,
    shared: Arc<Shared>,
    threads: Vec<JoinHandle<()>>,
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

    /// Every command, rate and settings change so far, at its period.
    pub fn log(&self) -> Vec<Logged> {
        self.shared
            .log
            .lock()
            .map(|l| l.clone())
            .unwrap_or_default()
    }

    /// Closes every connection (a cable pull); the drive keeps running.
    pub fn disconnect_all(&self) {
        if let Ok(mut s) = self.shared.socks.lock() {
            for c in s.drain(..) {
                let _ = c.shutdown(Shutdown::Both);
            }
        }
    }

    /// Stops the simulation and every thread.
    pub fn shutdown(mut self) {
        self.shared.stop.store(true, Ordering::Relaxed);
        self.disconnect_all();
        for t in self.threads.drain(..) {
            let _ = t.join();
        }
    }

    /// Blocks until the server stops (it runs until the process ends).
    pub fn wait(mut self) {
        for t in self.threads.drain(..) {
            let _ = t.join();
        }
    }
}

/// Starts serving on `listener`.
pub fn start(listener: TcpListener, opts: Options) -> io::Result<ServerHandle> {
    let addr = listener.local_addr()?;
    listener.set_nonblocking(true)?;
    let shared = Arc::new(Shared {
        stop: AtomicBool::new(false),
        period: AtomicU64::new(0),
        dropped: AtomicU64::new(0),
        log: Mutex::new(Vec::new()),
        socks: Mutex::new(Vec::new()),
    });
    let (in_tx, in_rx) = mpsc::channel::<Incoming>();
    let sim = {
        let shared = shared.clone();
        thread::Builder::new()
            .name("vboard-sim".into())
            .spawn(move || simulate(opts, in_rx, &shared))?
    };
    let acceptor = {
        let shared = shared.clone();
        thread::Builder::new()
            .name("vboard-accept".into())
            .spawn(move || accept(listener, in_tx, &shared, opts.pace))?
    };
    Ok(ServerHandle {
        addr,
        shared,
        threads: vec![sim, acceptor],
    })
}

fn accept(listener: TcpListener, in_tx: Sender<Incoming>, shared: &Shared, pace: Pace) {
    let mut next_id = 0u64;
    while !shared.stop.load(Ordering::Relaxed) {
        match listener.accept() {
            Ok((sock, _)) => {
                next_id += 1;
                if let Err(e) = connect(next_id, sock, &in_tx, shared, pace) {
                    eprintln!("acim-vboard: connection refused: {e}");
                }
            }
            Err(e) if e.kind() == io::ErrorKind::WouldBlock => {
                thread::sleep(Duration::from_millis(5))
            }
            Err(e) => {
                eprintln!("acim-vboard: accept: {e}");
                thread::sleep(Duration::from_millis(50));
            }
        }
    }
}

fn connect(
    id: u64,
    sock: TcpStream,
    in_tx: &Sender<Incoming>,
    shared: &Shared,
    pace: Pace,
) -> io::Result<()> {
    sock.set_nonblocking(false)?;
    sock.set_nodelay(true)?;
    // at a factor: room for bursts before frames are dropped; as fast as it runs: a short
    // queue, so a reader's view stays close to the board's present
    let depth = match pace {
        Pace::Factor(_) => 4096,
        Pace::Max => 16,
    };
    let (tx, rx) = mpsc::sync_channel::<Vec<u8>>(depth);
    let mut hello = protocol::hello_frame(PWM_FREQUENCY_HZ, crate::board::BOARD_NAME).to_vec();
    hello.extend_from_slice(format!("{READY_LINE}\r\n").as_bytes());
    let _ = tx.send(hello);
    if let Ok(mut s) = shared.socks.lock() {
        s.push(sock.try_clone()?);
    }
    let mut w = sock.try_clone()?;
    thread::Builder::new()
        .name(format!("vboard-tx{id}"))
        .spawn(move || {
            while let Ok(buf) = rx.recv() {
                if w.write_all(&buf).is_err() {
                    let _ = w.shutdown(Shutdown::Both);
                    break;
                }
            }
        })?;
    let _ = in_tx.send(Incoming::Connected(id, tx, sock.try_clone()?));
    let in_tx = in_tx.clone();
    let mut r = sock;
    thread::Builder::new()
        .name(format!("vboard-rx{id}"))
        .spawn(move || {
            let mut line: Vec<u8> = Vec::new();
            let mut overflow = false;
            let mut buf = [0u8; 512];
            loop {
                let n = match r.read(&mut buf) {
                    Ok(0) | Err(_) => break,
                    Ok(n) => n,
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
                                return;
                            }
                        }
                    } else if line.len() < MAX_FRAMED_LINE + 1 {
                        line.push(b);
                    } else {
                        overflow = true;
                    }
                }
            }
            let _ = in_tx.send(Incoming::Closed(id));
        })?;
    Ok(())
}

fn simulate(opts: Options, in_rx: Receiver<Incoming>, shared: &Shared) {
    let mut board = Board::new(true);
    if let Some(n) = opts.rate {
        board.set_rate(n);
    }
    let mut clients: BTreeMap<u64, Client> = BTreeMap::new();
    let pwm = PWM_FREQUENCY_HZ as f64;
    let mut t0 = Instant::now();
    let mut p0 = 0u64;
    let mut logged = 0;
    while !shared.stop.load(Ordering::Relaxed) {
        while let Ok(m) = in_rx.try_recv() {
            match m {
                Incoming::Connected(id, tx, sock) => {
                    clients.insert(
                        id,
                        Client {
                            tx,
                            sock,
                            stream: false,
                        },
                    );
                }
                Incoming::Closed(id) => {
                    if let Some(c) = clients.remove(&id) {
                        let _ = c.sock.shutdown(Shutdown::Both);
                    }
                }
                Incoming::TooLong(id, framed) => {
                    if let Some(c) = clients.get(&id) {
                        let _ = c.tx.send(Board::too_long(framed));
                    }
                }
                Incoming::Line(id, line) => {
                    if let Some(c) = clients.get_mut(&id) {
                        let reply = board.handle_line(&line, &mut c.stream).concat();
                        if !reply.is_empty() {
                            let _ = c.tx.send(reply);
                        }
                    }
                }
            }
        }
        if board.log().len() != logged {
            if let Ok(mut l) = shared.log.lock() {
                l.extend_from_slice(&board.log()[logged..]);
            }
            logged = board.log().len();
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
        for _ in 0..n {
            if let Some(s) = board.step() {
                let bytes = s.encode();
                clients.retain(|_, c| {
                    if !c.stream {
                        return true;
                    }
                    match opts.pace {
                        Pace::Max => c.tx.send(bytes.clone()).is_ok(),
                        Pace::Factor(_) => match c.tx.try_send(bytes.clone()) {
                            Ok(()) => true,
                            Err(TrySendError::Full(_)) => {
                                shared.dropped.fetch_add(1, Ordering::Relaxed);
                                true
                            }
                            Err(TrySendError::Disconnected(_)) => false,
                        },
                    }
                });
            }
        }
        shared.period.store(board.period(), Ordering::Relaxed);
    }
}
