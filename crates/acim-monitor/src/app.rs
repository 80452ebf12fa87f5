//! The monitor's state: the samples in view, the board's replies, the parameters, the
//! command line and the recording. Independent of the terminal, so the headless mode
//! and the tests drive it the same way a person does.

use crate::link::Event;
use crate::record::Recorder;
use acim_firmware_core::protocol::{self, Extension};
use acim_firmware_core::telemetry::TelemetrySample;
use std::collections::VecDeque;
use std::path::PathBuf;
use std::time::Duration;

/// The firmware's telemetry decimation, used for the time axis when a board sends no
/// period counter (protocol 0).
const V0_DECIMATION: f64 = 500.0;

/// One telemetry sample, merged from its `$T` and (protocol 1) `$X` frames.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Row {
    /// Board time, s (control periods / PWM frequency).
    pub time_s: f64,
    /// The `$T` content.
    pub t: TelemetrySample,
    /// The `$X` content, if the board sends it.
    pub x: Option<Extension>,
}

/// The link's state as shown.
#[derive(Clone, Debug, PartialEq)]
pub enum LinkState {
    /// Not yet connected.
    Connecting,
    /// Connected.
    Connected,
    /// Lost; retrying.
    Retrying(String),
}

/// A line in the message pane.
#[derive(Clone, Debug, PartialEq)]
pub struct Message {
    /// The text.
    pub text: String,
    /// Shown as an error.
    pub error: bool,
    /// Sent by the monitor (echo of a command).
    pub sent: bool,
}

/// Everything the screen shows.
pub struct App {
    /// Where the board is (for the status line).
    pub source: String,
    /// Link state.
    pub link: LinkState,
    /// Protocol version from the hello (None: no hello, protocol 0).
    pub version: Option<u16>,
    /// Board name from the hello.
    pub board: String,
    /// Control periods per second.
    pub pwm_hz: f64,
    /// Samples in view (the last [`App::window_s`] seconds).
    pub rows: VecDeque<Row>,
    /// Seconds of board time in view.
    pub window_s: f64,
    /// Replies and events, newest last.
    pub messages: VecDeque<Message>,
    /// The last `get`/`params` values, `name = value unit`.
    pub params: Vec<(String, String)>,
    /// The command line being typed.
    pub input: String,
    /// Earlier commands (Up/Down).
    pub history: Vec<String>,
    /// Position in the history while browsing it.
    pub history_pos: Option<usize>,
    /// Frames received.
    pub frames: u64,
    /// Frames dropped for a bad CRC or syntax.
    pub bad_frames: u64,
    /// Reconnections after a loss.
    pub reconnects: u64,
    /// Samples missing from the sequence (lost frames, time disconnected).
    pub missed: u64,
    /// Plots frozen (data is still recorded).
    pub paused: bool,
    /// The CSV recording, if any.
    pub recorder: Option<Recorder>,
    /// Quit requested.
    pub quit: bool,
    pending: Option<TelemetrySample>,
    last_seq: Option<u32>,
    was_connected: bool,
}

impl App {
    /// An empty monitor for `source`.
    pub fn new(source: String) -> App {
        App {
            source,
            link: LinkState::Connecting,
            version: None,
            board: String::new(),
            pwm_hz: 5000.0,
            rows: VecDeque::new(),
            window_s: 10.0,
            messages: VecDeque::new(),
            params: Vec::new(),
            input: String::new(),
            history: Vec::new(),
            history_pos: None,
            frames: 0,
            bad_frames: 0,
            reconnects: 0,
            missed: 0,
            paused: false,
            recorder: None,
            quit: false,
            pending: None,
            last_seq: None,
            was_connected: false,
        }
    }

    /// The newest sample.
    pub fn last(&self) -> Option<&Row> {
        self.rows.back()
    }

    /// Adds a line to the message pane.
    pub fn message(&mut self, text: impl Into<String>, error: bool) {
        self.messages.push_back(Message {
            text: text.into(),
            error,
            sent: false,
        });
        while self.messages.len() > 200 {
            self.messages.pop_front();
        }
    }

    /// Takes one event from the link.
    pub fn on_event(&mut self, ev: Event) {
        match ev {
            Event::Connected => {
                if self.was_connected {
                    self.reconnects += 1;
                }
                self.was_connected = true;
                self.link = LinkState::Connected;
                self.message(format!("connected to {}", self.source), false);
            }
            Event::Disconnected { reason, retry_in } => {
                self.flush_pending();
                if self.link != LinkState::Retrying(reason.clone()) {
                    self.message(
                        format!(
                            "link lost: {reason}; retrying every {} ms",
                            retry_in.as_millis()
                        ),
                        true,
                    );
                }
                self.link = LinkState::Retrying(reason);
            }
            Event::Hello {
                version,
                pwm_hz,
                board,
            } => {
                self.version = Some(version);
                if pwm_hz > 0 {
                    self.pwm_hz = pwm_hz as f64;
                }
                self.message(format!("{board}: protocol {version}, {pwm_hz} Hz"), false);
                self.board = board;
            }
            Event::Telemetry(t) => {
                self.frames += 1;
                self.flush_pending();
                if self.version.unwrap_or(0) >= 1 {
                    self.pending = Some(t);
                } else {
                    self.push(t, None);
                }
            }
            Event::Extension(x) => {
                self.frames += 1;
                match self.pending.take() {
                    Some(t) if t.seq == x.seq => self.push(t, Some(x)),
                    Some(t) => {
                        self.push(t, None);
                    }
                    None => {}
                }
            }
            Event::Reply { text, error } => {
                if let Some((name, value)) = text.split_once(" = ") {
                    let name = name.trim().to_string();
                    match self.params.iter_mut().find(|(n, _)| *n == name) {
                        Some(p) => p.1 = value.to_string(),
                        None => self.params.push((name, value.to_string())),
                    }
                }
                self.message(text, error);
            }
            Event::BadFrame(text) => {
                self.bad_frames += 1;
                self.message(format!("bad frame dropped: {text}"), true);
            }
            Event::Sent(c) => {
                self.messages.push_back(Message {
                    text: format!("> {c}"),
                    error: false,
                    sent: true,
                });
            }
        }
    }

    /// Takes in a `$T` still waiting for its `$X` (call before closing a recording).
    pub fn flush_pending(&mut self) {
        if let Some(t) = self.pending.take() {
            self.push(t, None);
        }
    }

    fn push(&mut self, t: TelemetrySample, x: Option<Extension>) {
        if let Some(last) = self.last_seq {
            let gap = t.seq.wrapping_sub(last);
            if gap > 1 && gap < u32::MAX / 2 {
                self.missed += (gap - 1) as u64;
            }
        }
        self.last_seq = Some(t.seq);
        let time_s = match x {
            Some(x) => x.period as f64 / self.pwm_hz,
            None => t.seq as f64 * V0_DECIMATION / self.pwm_hz,
        };
        let row = Row { time_s, t, x };
        if let Some(r) = self.recorder.as_mut() {
            if let Err(e) = r.write(&row) {
                let text = format!("recording stopped: {e}");
                self.recorder = None;
                self.message(text, true);
            }
        }
        if self.paused {
            return;
        }
        // a board restarted (time went back): start the view afresh
        if self.rows.back().is_some_and(|b| b.time_s > time_s) {
            self.rows.clear();
        }
        self.rows.push_back(row);
        while self
            .rows
            .front()
            .is_some_and(|f| f.time_s < time_s - self.window_s)
        {
            self.rows.pop_front();
        }
    }

    /// What the Enter key does with the command line: a `:` command acts on the
    /// monitor, anything else goes to the board (returned).
    pub fn submit(&mut self) -> Option<String> {
        let line = std::mem::take(&mut self.input);
        let line = line.trim().to_string();
        self.history_pos = None;
        if line.is_empty() {
            return None;
        }
        if self.history.last() != Some(&line) {
            self.history.push(line.clone());
        }
        self.command(&line)
    }

    /// Runs one command line (as [`App::submit`]).
    pub fn command(&mut self, line: &str) -> Option<String> {
        let Some(local) = line.strip_prefix(':') else {
            return Some(line.to_string());
        };
        let mut w = local.split_whitespace();
        match (w.next(), w.next()) {
            (Some("q" | "quit"), None) => self.quit = true,
            (Some("pause"), None) => {
                self.paused = !self.paused;
                let s = if self.paused {
                    "plots paused (still recording)"
                } else {
                    "plots live"
                };
                self.message(s, false);
            }
            (Some("window"), Some(s)) => match s.parse::<f64>() {
                Ok(v) if v.is_finite() && (0.1..=3600.0).contains(&v) => {
                    self.window_s = v;
                    self.message(format!("plots show the last {v} s"), false);
                }
                _ => self.message(format!("err :window takes 0.1..3600 s, got {s:?}"), true),
            },
            (Some("record"), Some(path)) => match Recorder::create(PathBuf::from(path)) {
                Ok(r) => {
                    self.message(format!("recording to {path}"), false);
                    self.recorder = Some(r);
                }
                Err(e) => self.message(format!("err cannot record to {path}: {e}"), true),
            },
            (Some("record"), None) | (Some("stop-record"), None) => match self.recorder.take() {
                Some(r) => {
                    let rows = r.rows();
                    match r.finish() {
                        Ok(p) => self.message(
                            format!("recording closed: {rows} rows in {}", p.display()),
                            false,
                        ),
                        Err(e) => self.message(format!("err recording: {e}"), true),
                    }
                }
                None => self.message("err not recording (:record FILE starts)", true),
            },
            (Some("help"), None) => {
                for l in HELP {
                    self.message(*l, false);
                }
            }
            _ => self.message(
                format!("err unknown monitor command {line:?} (:help)"),
                true,
            ),
        }
        None
    }

    /// Flushes the recording (call now and then, and before exit).
    pub fn flush(&mut self) {
        if let Some(r) = self.recorder.as_mut() {
            if let Err(e) = r.flush() {
                self.message(format!("recording: {e}"), true);
            }
        }
    }

    /// The drive state and fault, as names.
    pub fn state_text(&self) -> (String, String) {
        match self.last() {
            Some(r) => (
                protocol::state_name(r.t.state).to_string(),
                protocol::fault_name(r.t.fault).to_string(),
            ),
            None => ("-".into(), "-".into()),
        }
    }

    /// Time since nothing else happened, for the idle poll.
    pub const POLL: Duration = Duration::from_millis(25);
}

/// The help text (`:help`, F1).
pub const HELP: &[&str] = &[
    "keys: type a command and Enter; Up/Down history; Esc sends stop; Ctrl-C quits",
    "board: start | vf | stop | speed <rpm> | load <N m> | reset | status | get [<name>] | set <name> <value> | defaults | save | rate <periods> | version | help",
    "monitor: :record FILE | :record (close) | :pause | :window <s> | :quit | :help",
];
