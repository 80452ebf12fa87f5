//! The monitor's state: the samples in view, the board's replies (and how far they are
//! scrolled back), the parameters, the command line and the recording, and whether the
//! values shown are fresh ([`App::held`]). Independent of the terminal, so the headless
//! mode and the tests drive it the same way a person does.

use crate::link::Event;
use crate::record::Recorder;
use acim_firmware_core::control::STATE_COMMISSIONING;
use acim_firmware_core::protocol::{self, Extension};
use acim_firmware_core::telemetry::TelemetrySample;
use std::cell::Cell;
use std::collections::VecDeque;
use std::path::PathBuf;
use std::time::{Duration, Instant};

/// The firmware's telemetry decimation, used for the time axis when a board sends no
/// period counter (protocol 0).
const V0_DECIMATION: f64 = 500.0;

/// How the virtual board's name (hello frame, `version` reply) begins: its interrupt-time
/// fields carry the host's step time, not MCU cycles.
pub const VIRTUAL_BOARD_PREFIX: &str = "acim-vboard";

/// The telemetry's drive state codes the monitor acts on (docs/protocol.md, `state`).
const STATE_IDLE: u8 = 0;
const STATE_FAULT: u8 = 4;

/// Connected but no telemetry frame for this long (wall-clock) at least, or for four of
/// the last observed intervals between frames if longer: the values are held.
pub const STALE_AFTER: Duration = Duration::from_secs(2);

/// Replies and events kept for the message pane (older ones are dropped).
pub const MESSAGES_KEPT: usize = 200;

/// Why the values on the screen are not fresh ([`App::held`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Held {
    /// The link is lost: every value is the last one received.
    LinkDown,
    /// Connected, but no telemetry for a while ([`STALE_AFTER`]; `stream off`, or the
    /// board stalled): every value is the last one received.
    NoTelemetry,
    /// The plots are paused (`:pause`): every plotted value is frozen; the status line's
    /// state and fault stay live, and the recording goes on.
    Paused,
    /// Self-commissioning runs (state 5): the drive is idle and its estimates hold.
    Commissioning,
    /// The drive tripped: its estimates hold.
    Fault,
    /// The drive is switched off (idle): its estimates hold.
    DriveOff,
}

impl Held {
    /// The marker the screen shows, e.g. `held: commissioning`.
    pub fn reason(self) -> &'static str {
        match self {
            Held::LinkDown => "held: link down",
            Held::NoTelemetry => "held: no telemetry",
            Held::Paused => "held: paused",
            Held::Commissioning => "held: commissioning",
            Held::Fault => "held: fault",
            Held::DriveOff => "held: drive off",
        }
    }

    /// True if every value is held; false if only the drive's own estimates and
    /// measurements are (the bus voltage, the motor model's speed and the interrupt time
    /// stay live).
    pub fn everything(self) -> bool {
        matches!(self, Held::LinkDown | Held::NoTelemetry | Held::Paused)
    }
}

/// When telemetry was last seen arriving (wall-clock, from [`App::tick`]).
#[derive(Clone, Copy, Debug)]
struct Fresh {
    at: Instant,
    gap: Option<Duration>,
}

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
    /// How far the replies pane is scrolled back, in wrapped lines from the newest
    /// (0: it follows the newest). See [`App::scroll_replies`].
    pub reply_scroll: usize,
    /// The replies pane's text area at the last draw, (columns, rows), set by
    /// [`crate::ui::render`]: what a page and a wrapped line are.
    pub reply_view: Cell<(u16, u16)>,
    pending: Option<TelemetrySample>,
    last_seq: Option<u32>,
    was_connected: bool,
    /// The newest sample, also while the plots are paused.
    latest: Option<Row>,
    fresh: Option<Fresh>,
    frames_at_tick: u64,
    stale: bool,
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
            reply_scroll: 0,
            reply_view: Cell::new((78, 6)),
            pending: None,
            last_seq: None,
            was_connected: false,
            latest: None,
            fresh: None,
            frames_at_tick: 0,
            stale: false,
        }
    }

    /// The newest sample in view (the plots' last; frozen while paused).
    pub fn last(&self) -> Option<&Row> {
        self.rows.back()
    }

    /// The newest sample received, also while the plots are paused.
    pub fn latest(&self) -> Option<&Row> {
        self.latest.as_ref()
    }

    /// Whether the board is the virtual board (its hello names it): its interrupt-time
    /// fields are the host's step time expressed in 170 MHz cycles, not the MCU's.
    pub fn is_virtual_board(&self) -> bool {
        self.board.starts_with(VIRTUAL_BOARD_PREFIX)
    }

    /// Why the values shown are not fresh, if they are not: the link is down, no
    /// telemetry arrives, the plots are paused, or the drive is commissioning, tripped or
    /// off (its estimates then hold their last values). The first that applies, in that
    /// order. None before the first sample.
    pub fn held(&self) -> Option<Held> {
        let r = self.latest.as_ref()?;
        if matches!(self.link, LinkState::Retrying(_)) {
            return Some(Held::LinkDown);
        }
        if self.stale {
            return Some(Held::NoTelemetry);
        }
        if self.paused {
            return Some(Held::Paused);
        }
        match r.t.state {
            STATE_COMMISSIONING => Some(Held::Commissioning),
            STATE_FAULT => Some(Held::Fault),
            STATE_IDLE => Some(Held::DriveOff),
            _ => None,
        }
    }

    /// The telemetry's age check, called now and then with the wall-clock time: connected
    /// and no frame for [`STALE_AFTER`] (or four times the last interval between frames,
    /// if longer), the values are held ([`Held::NoTelemetry`]).
    pub fn tick(&mut self, now: Instant) {
        if self.link != LinkState::Connected {
            // an outage is not a gap between frames; the link state says it
            self.fresh = None;
            self.stale = false;
            return;
        }
        let arrived = self.frames != self.frames_at_tick;
        self.frames_at_tick = self.frames;
        let f = match self.fresh {
            None => Fresh { at: now, gap: None },
            Some(f) if arrived => Fresh {
                at: now,
                gap: Some(now.saturating_duration_since(f.at)),
            },
            Some(f) => f,
        };
        self.fresh = Some(f);
        let limit = f.gap.map_or(STALE_AFTER, |g| (g * 4).max(STALE_AFTER));
        self.stale = self.latest.is_some() && now.saturating_duration_since(f.at) > limit;
    }

    /// Adds a line to the message pane.
    pub fn message(&mut self, text: impl Into<String>, error: bool) {
        self.push_message(Message {
            text: text.into(),
            error,
            sent: false,
        });
    }

    fn push_message(&mut self, m: Message) {
        // scrolled back, the view stays on what is being read
        if self.reply_scroll > 0 {
            self.reply_scroll += crate::ui::wrap(&m.text, self.reply_view.get().0).len();
        }
        self.messages.push_back(m);
        while self.messages.len() > MESSAGES_KEPT {
            self.messages.pop_front();
        }
        self.reply_scroll = self.reply_scroll.min(self.reply_scroll_max());
    }

    /// The replies pane's wrapped lines at its last drawn width.
    fn reply_lines(&self) -> usize {
        let w = self.reply_view.get().0;
        self.messages
            .iter()
            .map(|m| crate::ui::wrap(&m.text, w).len())
            .sum()
    }

    fn reply_scroll_max(&self) -> usize {
        self.reply_lines()
            .saturating_sub(self.reply_view.get().1 as usize)
    }

    /// Scrolls the replies pane `lines` wrapped lines back (older; negative: forward),
    /// within what there is.
    pub fn scroll_replies(&mut self, lines: isize) {
        let s = self.reply_scroll.saturating_add_signed(lines);
        self.reply_scroll = s.min(self.reply_scroll_max());
    }

    /// A page of the replies pane (its rows less one, so a line stays in view), lines.
    pub fn reply_page(&self) -> isize {
        (self.reply_view.get().1 as isize - 1).max(1)
    }

    /// Scrolls the replies pane to the oldest line kept.
    pub fn replies_oldest(&mut self) {
        self.reply_scroll = self.reply_scroll_max();
    }

    /// The replies pane follows the newest line again.
    pub fn replies_newest(&mut self) {
        self.reply_scroll = 0;
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
                self.push_message(Message {
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
        self.latest = Some(row);
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

    /// The drive state and fault of the newest sample (also while paused), as names.
    pub fn state_text(&self) -> (String, String) {
        match self.latest() {
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
    "replies: PgUp/PgDn scroll a page; Home the oldest, End the newest (and follow)",
    "board: start | vf | stop | speed <rpm> | load <N m> | reset | status | get [<name>] | set <name> <value> | defaults | save | rate <periods> | version | help",
    "commissioning: commission <P W> <V> <A> <Hz> <rpm> | commission (progress, result) | commission apply (its settings; a start, vf, set or defaults first discards them)",
    "monitor: :record FILE | :record (close) | :pause | :window <s> | :quit | :help",
];
