//! The link to a board: a serial port or a TCP port (the virtual board), on its own
//! thread, reconnecting with a backoff after a cable pull.
//!
//! The thread decodes every line into an [`Event`] and sends the commands it is given:
//! `$C` framed (with a CRC) once the board has said hello with protocol version 1 or
//! later, plain lines otherwise (the firmware before version 1). After each (re)connection
//! it repeats the connection's own settings the user gave (`stream`, `rate`), so the
//! telemetry resumes by itself.

use acim_firmware_core::protocol::{self, Extension};
use acim_firmware_core::telemetry::{self, TelemetrySample};
use std::io::{self, Read, Write};
use std::net::TcpStream;
use std::sync::mpsc::{self, Receiver, Sender, TryRecvError};
use std::thread;
use std::time::{Duration, Instant};

/// Where the board is.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Source {
    /// A TCP address, e.g. the virtual board's `127.0.0.1:7878`.
    Tcp(String),
    /// A serial port and its baud rate (the firmware's UART runs at 115 200 baud).
    Serial(String, u32),
}

impl std::fmt::Display for Source {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Source::Tcp(a) => write!(f, "tcp {a}"),
            Source::Serial(p, b) => write!(f, "serial {p} @ {b}"),
        }
    }
}

/// What the link reports.
#[derive(Clone, Debug, PartialEq)]
pub enum Event {
    /// Connected (again).
    Connected,
    /// The connection failed or was lost; the link retries after `retry_in`.
    Disconnected {
        /// Why.
        reason: String,
        /// The backoff before the next attempt.
        retry_in: Duration,
    },
    /// The hello frame: protocol version, PWM frequency, board name.
    Hello {
        /// Protocol version.
        version: u16,
        /// Control periods per second.
        pwm_hz: u32,
        /// The board's name.
        board: String,
    },
    /// A `$T` frame.
    Telemetry(TelemetrySample),
    /// A `$X` frame.
    Extension(Extension),
    /// A reply line; `error`: it refused the command (nothing changed).
    Reply {
        /// The text.
        text: String,
        /// An `err` reply.
        error: bool,
    },
    /// A line that failed its CRC or syntax (dropped, counted).
    BadFrame(String),
    /// A command was sent.
    Sent(String),
}

/// The monitor's side of a running link.
pub struct Link {
    commands: Sender<String>,
    events: Receiver<Event>,
}

impl Link {
    /// Starts the link thread for `source`.
    pub fn spawn(source: Source) -> Link {
        let (ctx, crx) = mpsc::channel();
        let (etx, erx) = mpsc::channel();
        let _ = thread::Builder::new()
            .name("monitor-link".into())
            .spawn(move || run(source, crx, etx));
        Link {
            commands: ctx,
            events: erx,
        }
    }

    /// Queues one command line for the board.
    pub fn send(&self, command: &str) {
        let _ = self.commands.send(command.to_string());
    }

    /// The next event, if any.
    pub fn try_event(&self) -> Option<Event> {
        self.events.try_recv().ok()
    }

    /// The next event, waiting at most `timeout`.
    pub fn event_timeout(&self, timeout: Duration) -> Option<Event> {
        self.events.recv_timeout(timeout).ok()
    }
}

trait Port: Read + Write + Send {}
impl<T: Read + Write + Send> Port for T {}

fn open(source: &Source) -> io::Result<Box<dyn Port>> {
    match source {
        Source::Tcp(addr) => {
            let s = TcpStream::connect(addr)?;
            s.set_nodelay(true)?;
            s.set_read_timeout(Some(Duration::from_millis(20)))?;
            Ok(Box::new(s))
        }
        Source::Serial(path, baud) => {
            let p = serialport::new(path, *baud)
                .timeout(Duration::from_millis(20))
                .open()
                .map_err(io::Error::other)?;
            Ok(Box::new(p))
        }
    }
}

/// Decodes one received line.
pub fn decode_line(line: &[u8]) -> Event {
    let text = || String::from_utf8_lossy(line).to_string();
    if line.first() != Some(&b'$') {
        let t = text();
        let error = t.starts_with("err") || t.starts_with("warn");
        return Event::Reply { text: t, error };
    }
    if line.starts_with(b"$T,") {
        return match telemetry::decode(line) {
            Ok(s) => Event::Telemetry(s),
            Err(e) => Event::BadFrame(format!("{e:?}: {}", text())),
        };
    }
    match protocol::unframe(line) {
        Err(e) => Event::BadFrame(format!("{}: {}", e.as_str(), text())),
        Ok((b'X', _)) => match protocol::decode_extension(line) {
            Ok(x) => Event::Extension(x),
            Err(e) => Event::BadFrame(format!("{e:?}: {}", text())),
        },
        Ok((b'R', p)) => Event::Reply {
            text: String::from_utf8_lossy(p).to_string(),
            error: false,
        },
        Ok((b'E', p)) => Event::Reply {
            text: String::from_utf8_lossy(p).to_string(),
            error: true,
        },
        Ok((b'V', p)) => {
            let p = String::from_utf8_lossy(p);
            let mut w = p.splitn(3, ',');
            let version = w.next().and_then(|v| v.parse().ok());
            let pwm = w.next().and_then(|v| v.parse().ok());
            match (version, pwm) {
                (Some(version), Some(pwm_hz)) => Event::Hello {
                    version,
                    pwm_hz,
                    board: w.next().unwrap_or("").to_string(),
                },
                _ => Event::BadFrame(format!("bad hello: {}", text())),
            }
        }
        Ok((k, _)) => Event::BadFrame(format!("unknown frame kind {}: {}", k as char, text())),
    }
}

fn run(source: Source, commands: Receiver<String>, events: Sender<Event>) {
    // the connection's own settings, repeated after every reconnection
    let mut session: Vec<String> = Vec::new();
    let mut backoff = Duration::from_millis(100);
    loop {
        let mut port = match open(&source) {
            Ok(p) => p,
            Err(e) => {
                if events
                    .send(Event::Disconnected {
                        reason: format!("{source}: {e}"),
                        retry_in: backoff,
                    })
                    .is_err()
                {
                    return;
                }
                if !wait_disconnected(&commands, &events, backoff, &mut session) {
                    return;
                }
                backoff = (backoff * 2).min(Duration::from_secs(2));
                continue;
            }
        };
        backoff = Duration::from_millis(100);
        if events.send(Event::Connected).is_err() {
            return;
        }
        let reason = serve(&mut *port, &commands, &events, &mut session);
        match reason {
            None => return,
            Some(reason) => {
                if events
                    .send(Event::Disconnected {
                        reason,
                        retry_in: backoff,
                    })
                    .is_err()
                {
                    return;
                }
                thread::sleep(backoff);
            }
        }
    }
}

/// Waits `d` while disconnected; commands typed meanwhile are refused with an error reply
/// (the board did not get them), except the connection's settings, which are sent on
/// reconnection. Returns false when the monitor has gone.
fn wait_disconnected(
    commands: &Receiver<String>,
    events: &Sender<Event>,
    d: Duration,
    session: &mut Vec<String>,
) -> bool {
    let end = Instant::now() + d;
    loop {
        let left = end.saturating_duration_since(Instant::now());
        if left.is_zero() {
            return true;
        }
        match commands.recv_timeout(left) {
            Ok(c) => {
                let kept = remember(session, &c);
                let text = if kept {
                    format!("not connected: `{c}` will be sent on reconnection")
                } else {
                    format!("err not connected: `{c}` was not sent")
                };
                let error = !kept;
                if events.send(Event::Reply { text, error }).is_err() {
                    return false;
                }
            }
            Err(mpsc::RecvTimeoutError::Timeout) => return true,
            Err(mpsc::RecvTimeoutError::Disconnected) => return false,
        }
    }
}

/// Keeps `c` if it is one of the connection's settings; true if kept.
fn remember(session: &mut Vec<String>, c: &str) -> bool {
    let word = c.split_whitespace().next().unwrap_or("");
    let kept = word == "stream" || word == "rate";
    if kept {
        session.retain(|s| s.split_whitespace().next() != Some(word));
        session.push(c.trim().to_string());
    }
    kept
}

/// Talks to one connection until it fails (`Some(reason)`) or the monitor has gone
/// (`None`).
fn serve(
    port: &mut dyn Port,
    commands: &Receiver<String>,
    events: &Sender<Event>,
    session: &mut Vec<String>,
) -> Option<String> {
    let mut framed = false;
    let mut pending: Vec<String> = Vec::new();
    let mut line: Vec<u8> = Vec::new();
    let mut buf = [0u8; 4096];
    let connected = Instant::now();
    let mut known = false; // the protocol version is known
    let mut probe: Option<Instant> = None;
    let mut resumed = false;
    loop {
        // the board says hello when a host connects; a board that was already running
        // when the cable went in (a UART has no connection) is asked `version`; a board
        // without either speaks protocol 0 and gets plain lines
        if !known && probe.is_none() && connected.elapsed() > Duration::from_millis(300) {
            if let Err(e) = port.write_all(b"version\r\n").and_then(|()| port.flush()) {
                return Some(format!("write: {e}"));
            }
            probe = Some(Instant::now());
        }
        let probing = !known && probe.is_some_and(|p| p.elapsed() < Duration::from_secs(1));
        if !resumed && (known || (probe.is_some() && !probing)) {
            resumed = true;
            pending.splice(0..0, session.iter().cloned());
        }
        loop {
            match commands.try_recv() {
                Ok(c) => {
                    remember(session, &c);
                    pending.push(c);
                }
                Err(TryRecvError::Empty) => break,
                Err(TryRecvError::Disconnected) => return None,
            }
        }
        if resumed {
            for c in pending.drain(..) {
                let bytes = if framed {
                    protocol::command_frame(c.trim()).to_vec()
                } else {
                    format!("{}\r\n", c.trim()).into_bytes()
                };
                if let Err(e) = port.write_all(&bytes).and_then(|()| port.flush()) {
                    return Some(format!("write: {e}"));
                }
                if events.send(Event::Sent(c)).is_err() {
                    return None;
                }
            }
        }
        let n = match port.read(&mut buf) {
            Ok(0) => return Some("connection closed by the board".into()),
            Ok(n) => n,
            Err(e)
                if matches!(
                    e.kind(),
                    io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut
                ) =>
            {
                0
            }
            Err(e) if e.kind() == io::ErrorKind::Interrupted => 0,
            Err(e) => return Some(format!("read: {e}")),
        };
        for &b in &buf[..n] {
            if b == b'\r' || b == b'\n' {
                if !line.is_empty() {
                    let mut ev = decode_line(&line);
                    line.clear();
                    if let (true, Event::Reply { text, error }) = (probing && !known, &ev) {
                        match version_reply(text) {
                            Some(h) => ev = h,
                            // the answer of a board without `version`: not the user's
                            None if *error => {
                                known = true;
                                continue;
                            }
                            None => {}
                        }
                    }
                    if let Event::Hello { version, .. } = ev {
                        known = true;
                        framed = version >= 1;
                    }
                    // the board restarted behind a live cable (its hello or boot line
                    // again): its telemetry is off, so the connection's settings go again
                    let boot = match &ev {
                        Event::Hello { .. } => true,
                        Event::Reply { text, .. } => text.ends_with(" ready (help for commands)"),
                        _ => false,
                    };
                    if boot && resumed {
                        pending.extend(session.iter().cloned());
                    }
                    if events.send(ev).is_err() {
                        return None;
                    }
                }
            } else if line.len() < 1024 {
                line.push(b);
            }
        }
    }
}

/// The hello in a `version` reply: `ok protocol <v> board <name> pwm <Hz> Hz`.
fn version_reply(text: &str) -> Option<Event> {
    let rest = text.strip_prefix("ok protocol ")?;
    let (v, rest) = rest.split_once(' ')?;
    let rest = rest.strip_prefix("board ")?;
    let (board, pwm) = rest.rsplit_once(" pwm ")?;
    Some(Event::Hello {
        version: v.parse().ok()?,
        pwm_hz: pwm.strip_suffix(" Hz")?.parse().ok()?,
        board: board.to_string(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lines_decode() {
        let t = telemetry::encode(&TelemetrySample {
            seq: 3,
            ..Default::default()
        });
        assert!(matches!(decode_line(&t[..t.len() - 2]), Event::Telemetry(s) if s.seq == 3));
        let mut bad = t.clone();
        bad[4] ^= 1;
        assert!(matches!(
            decode_line(&bad[..bad.len() - 2]),
            Event::BadFrame(_)
        ));
        assert_eq!(
            decode_line(b"err out of range"),
            Event::Reply {
                text: "err out of range".into(),
                error: true
            }
        );
        let e = protocol::reply_frame(b"err out of range");
        assert_eq!(
            decode_line(&e[..e.len() - 2]),
            Event::Reply {
                text: "err out of range".into(),
                error: true
            }
        );
        let h = protocol::hello_frame(5000, "b");
        assert_eq!(
            decode_line(&h[..h.len() - 2]),
            Event::Hello {
                version: 1,
                pwm_hz: 5000,
                board: "b".into()
            }
        );
    }

    #[test]
    fn version_replies_are_hellos() {
        assert_eq!(
            version_reply("ok protocol 1 board acim-firmware power stage pwm 5000 Hz"),
            Some(Event::Hello {
                version: 1,
                pwm_hz: 5000,
                board: "acim-firmware power stage".into()
            })
        );
        assert_eq!(version_reply("err unknown command (try help)"), None);
        assert_eq!(version_reply("ok protocol x board b pwm 5000 Hz"), None);
    }

    #[test]
    fn the_session_keeps_the_last_stream_and_rate() {
        let mut s = Vec::new();
        for c in [
            "stream on",
            "start",
            "rate 50",
            "rate 100",
            "stream off",
            "stream on",
        ] {
            remember(&mut s, c);
        }
        assert!(!remember(&mut s, "start"));
        assert_eq!(s, ["rate 100", "stream on"]);
    }
}
