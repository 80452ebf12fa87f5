//! The board without its link: the firmware's control loop on the motor model, and the
//! firmware's own command handling ([`acim_firmware_core::dispatch`], shared with
//! firmware/src/main.rs) with protocol version 1 ([`acim_firmware_core::protocol`]).

use acim::commissioning::Stage;
use acim::frames::FastSinCos;
use acim::{Drive, DriveState};
use acim_firmware_core::board::{self, POWER_STAGE, PWM_FREQUENCY_HZ, TELEMETRY_DECIMATION};
use acim_firmware_core::command::ParseError;
use acim_firmware_core::commission::{self, Commissioning};
use acim_firmware_core::control::{ControlCommand, ControlLoop};
use acim_firmware_core::convert::Converter;
use acim_firmware_core::dispatch::{self, Dispatch, Platform, Rebuild, Reply, Sent};
use acim_firmware_core::protocol::{self, Extension};
use acim_firmware_core::settings::{self, Settings, FIELDS};
use acim_firmware_core::sim::SimulatedStage;
use acim_firmware_core::telemetry::{self, TelemetrySample};
use std::collections::VecDeque;
use std::time::Instant;

/// The name in the hello frame and the `version` reply.
pub const BOARD_NAME: &str = "acim-vboard (firmware ControlLoop + SimulatedStage)";

/// The first line a connection receives after the hello frame (the firmware's boot line
/// names the firmware instead).
pub const READY_LINE: &str = "acim-vboard ready (help for commands)";

/// Something that changed the drive or its telemetry, at the period it took effect.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Event {
    /// A command to the control loop (the firmware's interrupt queue).
    Control(ControlCommand),
    /// A new telemetry decimation.
    Rate(u16),
    /// A drive rebuilt from new settings (`set`, `defaults`, `commission apply`).
    Settings(Settings),
}

/// An [`Event`] and the period it was applied before.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Logged {
    /// Index of the first period that ran with it.
    pub period: u64,
    /// What happened.
    pub event: Event,
}

/// Entries an [`EventLog`] keeps: the last 1024 events (a [`Logged`] is 72 bytes on a
/// 64-bit host: 72 KiB). A session's commands are typed or scripted, tens to hundreds of
/// them, so a whole session normally fits and [`replay`] can reproduce it; past the bound
/// the oldest entries go (see [`EventLog::is_complete`]).
pub const LOG_CAPACITY: usize = 1024;

/// The board's event log: a ring of the last [`LOG_CAPACITY`] (or a chosen number of)
/// [`Logged`] events, oldest first, and the count of every event ever logged.
///
/// Only what took effect is logged: a command the drive refused, a setting the validation
/// refused and every line answered with `err` leave no entry (they change nothing, so
/// [`replay`] needs none). A commissioning's end is not an entry: [`replay`] re-derives
/// it from the commission command, and its settings are a [`Event::Settings`] entry when
/// `commission apply` uses them.
#[derive(Clone, Debug, PartialEq)]
pub struct EventLog {
    entries: VecDeque<Logged>,
    capacity: usize,
    total: u64,
}

impl Default for EventLog {
    fn default() -> Self {
        Self::with_capacity(LOG_CAPACITY)
    }
}

impl EventLog {
    /// An empty log keeping the last `capacity` entries (at least one).
    pub fn with_capacity(capacity: usize) -> Self {
        Self {
            entries: VecDeque::new(),
            capacity: capacity.max(1),
            total: 0,
        }
    }

    /// Appends `l`, dropping the oldest entry when the log is full.
    pub fn push(&mut self, l: Logged) {
        if self.entries.len() == self.capacity {
            self.entries.pop_front();
        }
        self.entries.push_back(l);
        self.total += 1;
    }

    /// Entries kept (at most [`EventLog::capacity`]).
    pub fn len(&self) -> usize {
        self.entries.len()
    }

    /// No entry kept.
    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    /// The most entries it keeps.
    pub fn capacity(&self) -> usize {
        self.capacity
    }

    /// Events logged since it was made, kept or not.
    pub fn total(&self) -> u64 {
        self.total
    }

    /// Nothing has been dropped: the entries go back to the first event, so [`replay`]
    /// of them reproduces the run from power-up.
    pub fn is_complete(&self) -> bool {
        self.total == self.entries.len() as u64
    }

    /// The kept entries, oldest first.
    pub fn iter(&self) -> impl Iterator<Item = &Logged> + '_ {
        self.entries.iter()
    }

    /// The kept entries, oldest first, as a vector (for [`replay`]).
    pub fn to_vec(&self) -> Vec<Logged> {
        self.entries.iter().copied().collect()
    }

    /// Moves every kept entry to the end of `dst` (as [`EventLog::push`]es), leaving this
    /// log empty (its [`EventLog::total`] unchanged).
    pub fn move_into(&mut self, dst: &mut EventLog) {
        for l in self.entries.drain(..) {
            dst.push(l);
        }
    }
}

/// One decimated telemetry sample as the link sends it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sample {
    /// The `$T` frame's content.
    pub t: TelemetrySample,
    /// The `$X` frame's content.
    pub x: Extension,
}

impl Sample {
    /// `$T` then `$X`, each with its CRC and line end.
    pub fn encode(&self) -> Vec<u8> {
        let mut v = telemetry::encode(&self.t).to_vec();
        v.extend_from_slice(&protocol::encode_extension(&self.x));
        v
    }
}

/// The virtual board: the self-test firmware's interrupt body and main-loop command
/// handling, with no I/O.
pub struct Board {
    hw: Hw,
    dispatch: Dispatch,
}

/// What the firmware's interrupt and its flash are on this board: the control loop, the
/// motor model, the "flash" and the event log.
struct Hw {
    ctl: ControlLoop<FastSinCos>,
    stage: SimulatedStage,
    saved: Settings,
    period: u64,
    timed: bool,
    log: EventLog,
}

impl Hw {
    /// Applies `cmd` to the control loop (a commissioning must be staged first); `load`
    /// also reaches the motor model. Logged only if accepted.
    fn apply(&mut self, cmd: ControlCommand) -> Result<(), acim::CommandError> {
        if let ControlCommand::PlantLoad(nm) = cmd {
            self.stage.set_brake_nm(nm);
        }
        let result = self.ctl.apply(cmd).result;
        if result.is_ok() {
            self.log.push(Logged {
                period: self.period,
                event: Event::Control(cmd),
            });
        }
        result
    }

    fn set_rate(&mut self, every: u16) {
        self.log.push(Logged {
            period: self.period,
            event: Event::Rate(every),
        });
        // as the firmware's interrupt applies it
        let _ = self.ctl.apply(ControlCommand::Rate(every));
    }

    /// A drive for `next`, swapped in only while Idle.
    fn rebuild(&mut self, next: &Settings) -> Result<(), Rebuild> {
        let drive = next
            .drive_config()
            .and_then(|cfg| Drive::new(cfg).map_err(settings::SettingError::from))
            .map_err(Rebuild::Invalid)?;
        self.ctl.replace_drive(drive).map_err(|_| Rebuild::NotIdle)
    }
}

/// The board as the shared command handling sees it: the hardware half and this
/// connection's telemetry switch.
struct Link<'a> {
    hw: &'a mut Hw,
    stream: &'a mut bool,
}

impl Platform for Link<'_> {
    const NAME: &'static str = BOARD_NAME;
    const PLANT: bool = true;

    fn send(&mut self, cmd: ControlCommand) -> Sent {
        // applied before the next period, as the firmware's interrupt takes it from its
        // queue
        Sent::Done(match cmd {
            ControlCommand::Rate(n) => {
                self.hw.set_rate(n);
                Ok(())
            }
            _ => self.hw.apply(cmd),
        })
    }
    fn state_code(&self) -> u8 {
        self.hw.ctl.state_code()
    }
    fn fault_code(&self) -> u8 {
        self.hw.ctl.fault_code()
    }
    fn dc_bus(&self) -> f32 {
        self.hw.ctl.inputs().dc_bus
    }
    fn periods(&self) -> u32 {
        self.hw.period as u32
    }
    fn rebuild(&mut self, next: &Settings) -> Result<(), Rebuild> {
        self.hw.rebuild(next)?;
        self.hw.log.push(Logged {
            period: self.hw.period,
            event: Event::Settings(*next),
        });
        Ok(())
    }
    fn save(&mut self, s: &Settings) -> Result<&'static str, &'static str> {
        self.hw.saved = *s;
        Ok("saved (virtual board: kept in memory until it exits)")
    }
    fn params<R: Reply>(&mut self, s: &Settings, out: &mut R) {
        out.line(
            format!(
                "params: Ts {} s, telemetry every {} periods, board {}",
                1.0 / PWM_FREQUENCY_HZ as f32,
                TELEMETRY_DECIMATION,
                POWER_STAGE.name
            )
            .as_bytes(),
        );
        for i in 0..FIELDS.len() {
            dispatch::setting_line(out, s, i);
        }
        out.line(b"ok parameters listed (the firmware logs them on RTT)");
    }
    fn set_stream(&mut self, on: bool) {
        *self.stream = on;
    }
    fn stage_commissioning(&mut self, c: Option<Commissioning>) {
        self.hw.ctl.stage_commissioning(c);
    }
    fn commissioning_progress(&self) -> Option<(Stage, f32)> {
        let c = self.hw.ctl.commissioning()?;
        Some((c.stage(), c.stage_time()))
    }
    fn take_finished_commissioning(&mut self) -> Option<Commissioning> {
        self.hw.ctl.take_finished_commissioning()
    }
}

/// Reply lines without their line ends.
#[derive(Default)]
struct Lines {
    done: Vec<Vec<u8>>,
    cur: Vec<u8>,
}

impl Reply for Lines {
    fn put(&mut self, text: &[u8]) {
        self.cur.extend_from_slice(text);
    }
    fn end(&mut self) {
        self.done.push(std::mem::take(&mut self.cur));
    }
}

impl Default for Board {
    fn default() -> Self {
        Self::new(true)
    }
}

impl Board {
    /// A board with the firmware's default settings, idle, telemetry every
    /// [`TELEMETRY_DECIMATION`] periods. `timed`: the interrupt-time fields carry the
    /// host's step time (in 170 MHz cycles); otherwise 0 (reproducible runs).
    pub fn new(timed: bool) -> Self {
        let settings = Settings::defaults();
        // the defaults are valid by construction (the firmware's own boot path)
        let cfg = settings
            .drive_config()
            .unwrap_or_else(|_| board::drive_config());
        let conv = Converter::new(&POWER_STAGE);
        let drive = match Drive::new(cfg) {
            Ok(d) => d,
            Err(e) => panic!("the firmware's default drive configuration is refused: {e:?}"),
        };
        let mut board = Self {
            hw: Hw {
                ctl: ControlLoop::new(drive, conv, TELEMETRY_DECIMATION),
                stage: SimulatedStage::new(conv),
                saved: settings,
                period: 0,
                timed,
                log: EventLog::default(),
            },
            dispatch: Dispatch::new(settings),
        };
        board.power_up();
        board
    }

    /// The board's power-up before it answers: the drive's switches-off offset
    /// measurement (0.1 s, which every start waits for) on the idle stage's samples, as
    /// the firmware's interrupt runs it while the main loop boots. Not counted as
    /// periods, no telemetry.
    fn power_up(&mut self) {
        let hw = &mut self.hw;
        for _ in 0..hw.ctl.drive().coeffs().limits.offset_settle_steps {
            let raw = hw.stage.sample();
            let out = hw.ctl.step(&raw);
            hw.stage.run_period(out);
        }
    }

    /// Periods run so far.
    pub fn period(&self) -> u64 {
        self.hw.period
    }

    /// The last [`LOG_CAPACITY`] events that took effect, in order (a server moves them
    /// out with [`Board::take_log_into`]).
    pub fn log(&self) -> &EventLog {
        &self.hw.log
    }

    /// Moves the events logged since the last call into `dst`, so that each is kept in
    /// one place (the server's log, which other threads read).
    pub fn take_log_into(&mut self, dst: &mut EventLog) {
        self.hw.log.move_into(dst);
    }

    /// The drive's state.
    pub fn state(&self) -> DriveState {
        self.hw.ctl.state()
    }

    /// The settings in use.
    pub fn settings(&self) -> &Settings {
        self.dispatch.settings()
    }

    /// The motor model's true speed, rpm.
    pub fn plant_speed_rpm(&self) -> f32 {
        self.hw.stage.speed_rpm()
    }

    /// Sends a command to the control loop before the next period (as the firmware's
    /// interrupt takes it from its queue), as if it had come over the link with its reply
    /// dropped; `load` also reaches the motor model. Logged only if the control loop
    /// accepts it (a refused command changes nothing).
    pub fn apply(&mut self, cmd: ControlCommand) -> Result<(), acim::CommandError> {
        // as the firmware's main loop: the sequence is built outside the control step, with
        // the bus of the last period, and staged for the command that starts it
        if let ControlCommand::Commission(args) = cmd {
            let bus = self.hw.ctl.inputs().dc_bus;
            self.hw
                .ctl
                .stage_commissioning(commission::build(&args, bus));
        }
        let result = self.hw.apply(cmd);
        let mut stream = false;
        let mut link = Link {
            hw: &mut self.hw,
            stream: &mut stream,
        };
        self.dispatch
            .control_reply(cmd, result, &mut link, &mut Lines::default());
        result
    }

    /// Telemetry every `every` periods from the next period on.
    pub fn set_rate(&mut self, every: u16) {
        self.hw.set_rate(every);
    }

    /// Runs one control period (sample, step, PWM into the model) and returns the
    /// telemetry sample if this period closes a decimation window.
    pub fn step(&mut self) -> Option<Sample> {
        let hw = &mut self.hw;
        let raw = hw.stage.sample();
        let t0 = hw.timed.then(Instant::now);
        let out = hw.ctl.step(&raw);
        let cycles = t0.map_or(0, |t| {
            (t.elapsed().as_nanos() as f64 * board::SYSCLK_HZ as f64 * 1e-9) as u32
        });
        hw.stage.run_period(out);
        // the main loop's half: a finished commissioning's fits, or its abort
        let mut stream = false;
        self.dispatch.poll(&mut Link {
            hw: &mut self.hw,
            stream: &mut stream,
        });
        let hw = &mut self.hw;
        hw.period += 1;
        // the loop counts the periods too (`t.period`, u32): the same as `self.period`
        // before this one, wrapped
        let t = hw.ctl.finish_period(cycles, hw.stage.speed_rpm())?;
        Some(Sample {
            t,
            x: Extension::of(&t),
        })
    }

    /// Handles one received line (plain or `$C` framed, without its terminator) and
    /// returns the reply lines, each with its line end, framed if the request was.
    /// `stream` is this connection's telemetry switch. Nothing changes on an error.
    pub fn handle_line(&mut self, line: &[u8], stream: &mut bool) -> Vec<Vec<u8>> {
        let p = protocol::parse_line(line);
        let mut out = Lines::default();
        let mut link = Link {
            hw: &mut self.hw,
            stream,
        };
        self.dispatch.handle(p.request, &mut link, &mut out);
        out.done
            .into_iter()
            .map(|t| {
                if p.framed {
                    protocol::reply_frame(&t).to_vec()
                } else {
                    let mut t = t;
                    t.extend_from_slice(b"\r\n");
                    t
                }
            })
            .collect()
    }

    /// The reply to a line too long to keep (`framed`: it started with `$`).
    pub fn too_long(framed: bool) -> Vec<u8> {
        let t = format!("err {}", ParseError::TooLong.as_str());
        if framed {
            protocol::reply_frame(t.as_bytes()).to_vec()
        } else {
            format!("{t}\r\n").into_bytes()
        }
    }
}

/// Runs `periods` periods from power-up with the events of `log` applied at their
/// periods, untimed: the reference trace a recording of the same run must reproduce.
/// `log` must go back to power-up ([`EventLog::is_complete`]) for that.
pub fn replay(log: &[Logged], periods: u64) -> Vec<Sample> {
    let mut b = Board::new(false);
    let mut out = Vec::new();
    let mut next = log.iter().peekable();
    while b.period() < periods {
        while let Some(l) = next.next_if(|l| l.period <= b.period()) {
            match l.event {
                Event::Control(c) => {
                    let _ = b.apply(c);
                }
                Event::Rate(n) => b.set_rate(n),
                Event::Settings(s) => {
                    if b.hw.rebuild(&s).is_ok() {
                        b.dispatch.replace_settings(s);
                    }
                }
            }
        }
        if let Some(s) = b.step() {
            out.push(s);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn say(b: &mut Board, line: &str) -> String {
        let mut stream = false;
        let r = b.handle_line(line.as_bytes(), &mut stream);
        String::from_utf8(r.concat()).unwrap()
    }

    #[test]
    fn replies_follow_the_firmware() {
        let mut b = Board::new(false);
        assert_eq!(say(&mut b, "bogus"), "err unknown command (try help)\r\n");
        assert_eq!(say(&mut b, "speed 1801"), "err out of range\r\n");
        assert_eq!(say(&mut b, "status"), "ok state 0 fault 00\r\n");
        assert_eq!(say(&mut b, "speed 500"), "ok\r\n");
        assert_eq!(
            say(&mut b, "get limits.current_limit"),
            "limits.current_limit = 4.67 A\r\nok\r\n"
        );
        assert!(
            say(&mut b, "set limits.current_limit -1").starts_with("err (limits.current_limit: ")
        );
        assert_eq!(say(&mut b, "start"), "ok\r\n");
        assert_eq!(
            say(&mut b, "set limits.current_limit 4"),
            "err limits.current_limit: refused while the drive is not idle (stop or reset first)\r\n"
        );
        assert!(say(&mut b, "version").starts_with("ok protocol 1 board acim-vboard"));
        let f = say(&mut b, "$C,rate 1*0000");
        assert!(f.starts_with("$E,err bad frame: checksum*"), "{f}");
        let c = protocol::command_frame("rate 1");
        let f = say(&mut b, std::str::from_utf8(&c).unwrap().trim_end());
        assert!(f.starts_with("$E,err out of range*"), "{f}");
        let c = protocol::command_frame("status");
        let f = say(&mut b, std::str::from_utf8(&c).unwrap().trim_end());
        assert!(f.starts_with("$R,ok state 1 fault 00*"), "{f}");
        // the firmware's texts (acim_firmware_core::dispatch), a line each
        let help: String = dispatch::HELP
            .iter()
            .map(|l| format!("{}\r\n", std::str::from_utf8(l).unwrap()))
            .collect();
        assert_eq!(say(&mut b, "help"), format!("{help}ok\r\n"));
        assert_eq!(
            say(&mut b, "commission apply"),
            "err nothing to apply (no accepted commissioning result: commission shows the last)\r\n"
        );
        assert_eq!(
            say(&mut b, "save"),
            "err save: refused while the drive is not idle (stop or reset first)\r\n"
        );
        assert_eq!(
            say(&mut b, "defaults"),
            "err defaults: refused while the drive is not idle (stop or reset first)\r\n"
        );
        assert_eq!(say(&mut b, "stop"), "ok\r\n");
        assert_eq!(
            say(&mut b, "save"),
            "ok saved (virtual board: kept in memory until it exits)\r\n"
        );
        // a framed reply of several lines: one frame a line, the last an `ok`
        let c = protocol::command_frame("get limits.current_limit");
        let f = say(&mut b, std::str::from_utf8(&c).unwrap().trim_end());
        let lines: Vec<&str> = f.lines().collect();
        assert_eq!(lines.len(), 2, "{f}");
        assert_eq!(
            protocol::unframe(lines[0].as_bytes()).unwrap(),
            (b'R', &b"limits.current_limit = 4.67 A"[..])
        );
        assert_eq!(
            protocol::unframe(lines[1].as_bytes()).unwrap(),
            (b'R', &b"ok"[..])
        );
    }

    #[test]
    fn replay_reproduces_a_run() {
        let mut b = Board::new(false);
        let mut live = Vec::new();
        for k in 0..20_000u32 {
            match k {
                100 => assert!(b.apply(ControlCommand::Start).is_ok()),
                200 => assert!(b.apply(ControlCommand::SpeedRpm(300.0)).is_ok()),
                300 => b.set_rate(50),
                _ => {}
            }
            live.extend(b.step());
        }
        assert!(
            (b.plant_speed_rpm() - 300.0).abs() < 20.0,
            "{}",
            b.plant_speed_rpm()
        );
        assert_eq!(replay(&b.log().to_vec(), 20_000), live);
    }

    fn at(period: u64) -> Logged {
        Logged {
            period,
            event: Event::Rate(2),
        }
    }

    #[test]
    fn the_log_keeps_the_last_entries() {
        let mut log = EventLog::with_capacity(3);
        assert!(log.is_empty() && log.is_complete());
        for p in 0..3 {
            log.push(at(p));
        }
        assert_eq!(log.len(), 3);
        assert!(log.is_complete());
        for p in 3..10 {
            log.push(at(p));
        }
        assert_eq!(log.len(), 3);
        assert_eq!(log.total(), 10);
        assert!(!log.is_complete());
        assert_eq!(log.to_vec(), [at(7), at(8), at(9)]);

        // moved, not copied: the source is left empty, the destination keeps its bound
        let mut dst = EventLog::with_capacity(4);
        dst.push(at(0));
        dst.push(at(1));
        log.move_into(&mut dst);
        assert!(log.is_empty());
        assert_eq!(log.total(), 10);
        assert_eq!(dst.to_vec(), [at(1), at(7), at(8), at(9)]);
        assert_eq!(dst.total(), 5);

        // the board's own log is bounded at LOG_CAPACITY
        let mut b = Board::new(false);
        for _ in 0..LOG_CAPACITY + 10 {
            assert_eq!(say(&mut b, "rate 2"), "ok\r\n");
        }
        assert_eq!(b.log().len(), LOG_CAPACITY);
        assert_eq!(b.log().total(), (LOG_CAPACITY + 10) as u64);
    }

    #[test]
    fn refused_commands_are_not_logged() {
        let mut b = Board::new(false);
        let mut live = Vec::new();
        let mut run = |b: &mut Board, n: u32| {
            for _ in 0..n {
                live.extend(b.step());
            }
        };
        // refused by the drive: no fault to reset, no start while running, a commission
        // while running; refused by the parser or the validation: never reach the drive
        assert_eq!(say(&mut b, "reset"), "err refused in this state\r\n");
        assert_eq!(say(&mut b, "speed 1801"), "err out of range\r\n");
        assert!(say(&mut b, "set limits.current_limit 99")
            .starts_with("err (limits.overcurrent_trip: "));
        assert!(b.log().is_empty(), "{:?}", b.log());
        assert_eq!(say(&mut b, "start"), "ok\r\n");
        run(&mut b, 100);
        assert_eq!(say(&mut b, "start"), "err refused in this state\r\n");
        assert!(say(&mut b, "commission 750 230 3.3 50 1500").starts_with("err "));
        assert!(say(&mut b, "set limits.current_limit 4")
            .starts_with("err limits.current_limit: refused"));
        assert_eq!(say(&mut b, "speed 300"), "ok\r\n");
        run(&mut b, 2000);
        // a refused command through the board's own interface
        assert!(b.apply(ControlCommand::ResetFault).is_err());
        run(&mut b, 100);
        let events: Vec<Event> = b.log().iter().map(|l| l.event).collect();
        assert_eq!(
            events,
            [
                Event::Control(ControlCommand::Start),
                Event::Control(ControlCommand::SpeedRpm(300.0))
            ]
        );
        // and the run is reproduced without them
        assert_eq!(replay(&b.log().to_vec(), b.period()), live);
    }
}
