//! The board without its link: the firmware's control loop on the motor model, and the
//! firmware's command handling with its reply texts (firmware/src/main.rs), plus protocol
//! version 1 ([`acim_firmware_core::protocol`]).

use acim::frames::FastSinCos;
use acim::{Drive, DriveState};
use acim_firmware_core::board::{self, POWER_STAGE, PWM_FREQUENCY_HZ, TELEMETRY_DECIMATION};
use acim_firmware_core::command::{Command, ParseError};
use acim_firmware_core::commission::{self, Commissioning, NameplateArgs};
use acim_firmware_core::control::{refusal_text, ControlCommand, ControlLoop};
use acim_firmware_core::convert::Converter;
use acim_firmware_core::protocol::{self, Extension, Request, RequestError};
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
    /// A drive rebuilt from new settings.
    Settings(Settings),
    /// Commissioning finished and its settings replaced the drive's (`None`: it failed
    /// and nothing changed). [`replay`] re-derives it from the commission command.
    Commissioned(Option<Settings>),
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
/// Only what took effect is logged (and how a commissioning ended): a command the drive
/// refused, a setting the validation refused and every line answered with `err` leave no
/// entry (they change nothing, so [`replay`] needs none).
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
    ctl: ControlLoop<FastSinCos>,
    stage: SimulatedStage,
    settings: Settings,
    saved: Settings,
    period: u64,
    timed: bool,
    log: EventLog,
    /// The nameplate of the commissioning under way or last run.
    nameplate: Option<NameplateArgs>,
    /// The reply lines of the last finished commissioning.
    commissioned: Option<Vec<String>>,
    /// The period the commissioning under way started at.
    commission_started: Option<u64>,
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
            ctl: ControlLoop::new(drive, conv, TELEMETRY_DECIMATION),
            stage: SimulatedStage::new(conv),
            settings,
            saved: settings,
            period: 0,
            timed,
            log: EventLog::default(),
            nameplate: None,
            commissioned: None,
            commission_started: None,
        };
        board.power_up();
        board
    }

    /// The board's power-up before it answers: the drive's switches-off offset
    /// measurement (0.1 s, which every start waits for) on the idle stage's samples, as
    /// the firmware's interrupt runs it while the main loop boots. Not counted as
    /// periods, no telemetry.
    fn power_up(&mut self) {
        for _ in 0..self.ctl.drive().coeffs().limits.offset_settle_steps {
            let raw = self.stage.sample();
            let out = self.ctl.step(&raw);
            self.stage.run_period(out);
        }
    }

    /// Periods run so far.
    pub fn period(&self) -> u64 {
        self.period
    }

    /// The last [`LOG_CAPACITY`] events that took effect, in order (a server moves them
    /// out with [`Board::take_log_into`]).
    pub fn log(&self) -> &EventLog {
        &self.log
    }

    /// Moves the events logged since the last call into `dst`, so that each is kept in
    /// one place (the server's log, which other threads read).
    pub fn take_log_into(&mut self, dst: &mut EventLog) {
        self.log.move_into(dst);
    }

    /// The drive's state.
    pub fn state(&self) -> DriveState {
        self.ctl.state()
    }

    /// The settings in use.
    pub fn settings(&self) -> &Settings {
        &self.settings
    }

    /// The motor model's true speed, rpm.
    pub fn plant_speed_rpm(&self) -> f32 {
        self.stage.speed_rpm()
    }

    /// Sends a command to the control loop before the next period (as the firmware's
    /// interrupt takes it from its queue); `load` also reaches the motor model. Logged
    /// only if the control loop accepts it (a refused command changes nothing).
    pub fn apply(&mut self, cmd: ControlCommand) -> Result<(), acim::CommandError> {
        if let ControlCommand::PlantLoad(nm) = cmd {
            self.stage.set_brake_nm(nm);
        }
        // as the firmware's main loop: the sequence is built outside the control step, with
        // the bus of the last period, and staged for the command that starts it
        if let ControlCommand::Commission(args) = cmd {
            self.ctl
                .stage_commissioning(commission::build(&args, self.ctl.inputs().dc_bus));
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

    /// Telemetry every `every` periods from the next period on.
    pub fn set_rate(&mut self, every: u16) {
        self.log.push(Logged {
            period: self.period,
            event: Event::Rate(every),
        });
        // as the firmware's interrupt applies it
        let _ = self.ctl.apply(ControlCommand::Rate(every));
    }

    /// Runs one control period (sample, step, PWM into the model) and returns the
    /// telemetry sample if this period closes a decimation window.
    pub fn step(&mut self) -> Option<Sample> {
        let raw = self.stage.sample();
        let t0 = self.timed.then(Instant::now);
        let out = self.ctl.step(&raw);
        let cycles = t0.map_or(0, |t| {
            (t.elapsed().as_nanos() as f64 * board::SYSCLK_HZ as f64 * 1e-9) as u32
        });
        self.stage.run_period(out);
        if let Some(c) = self.ctl.take_finished_commissioning() {
            self.finish_commissioning(&c);
        } else if self.commission_started.is_some() && self.ctl.commissioning().is_none() {
            // abandoned: a stop, or a trip (the drive's fault says which)
            self.commission_started = None;
            self.commissioned = Some(vec![if self.ctl.state() == DriveState::Fault {
                format!(
                    "err commissioning abandoned: the drive tripped (fault {}); settings unchanged",
                    protocol::fault_name(self.ctl.fault_code())
                )
            } else {
                "ok commissioning aborted by stop; settings unchanged".into()
            }]);
        }
        self.period += 1;
        // the loop counts the periods too (`t.period`, u32): the same as `self.period`
        // before this one, wrapped
        let t = self.ctl.finish_period(cycles, self.stage.speed_rpm())?;
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
        let texts = match p.request {
            Err(RequestError::Parse(ParseError::Empty)) => Vec::new(),
            Err(e) => vec![format!("err {}", e.as_str())],
            Ok(r) => self.handle(r, stream),
        };
        texts
            .into_iter()
            .map(|t| {
                if p.framed {
                    protocol::reply_frame(t.as_bytes()).to_vec()
                } else {
                    format!("{t}\r\n").into_bytes()
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

    /// The main loop's half of commissioning: the fits, the settings, the new drive.
    fn finish_commissioning(&mut self, c: &Commissioning) {
        let t = self.commission_started.take().map_or(0.0, |k| {
            (self.period + 1 - k) as f32 / PWM_FREQUENCY_HZ as f32
        });
        let fail = |why: &str| {
            vec![format!(
                "err commissioning failed: {why}; settings unchanged"
            )]
        };
        let rated = self
            .nameplate
            .and_then(|a| commission::nameplate(&a).rated().ok());
        let (lines, applied) = match (c.identify(), rated) {
            (Err(e), _) => {
                let why = commission::error_text(e);
                match commission::error_detail(e) {
                    Some(d) => (fail(&format!("{why} ({d})")), None),
                    None => (fail(why), None),
                }
            }
            (Ok(_), None) => (fail("no nameplate"), None),
            (Ok(id), Some(rated)) => {
                match commission::settings_from(&id, &rated, &self.settings).and_then(|next| {
                    Drive::new(next.drive_config()?)
                        .map(|d| (next, d))
                        .map_err(settings::SettingError::from)
                }) {
                    Err(e) => (
                        fail(&format!(
                            "the identified model is refused ({}: {})",
                            e.field, e.rule
                        )),
                        None,
                    ),
                    Ok((next, drive)) => match self.ctl.replace_drive(drive) {
                        Err(_) => (fail("the drive left Idle"), None),
                        Ok(()) => {
                            self.settings = next;
                            let j = id.inertia.map_or("not resolved (kept)".to_string(), |j| {
                                format!("{j:.5} kg m^2")
                            });
                            (
                                vec![
                                    format!(
                                        "identified in {t:.1} s: Rs {:.3} ohm, R_R {:.3} ohm, L_sigma {:.2} mH, L_M {:.1} mH (inverse-Gamma)",
                                        id.stator_resistance,
                                        id.rotor_resistance,
                                        id.leakage_inductance * 1e3,
                                        id.magnetizing_inductance * 1e3
                                    ),
                                    format!(
                                        "rated flux current {:.3} A, dead time {:.2} us, J {j}, friction {:.5} N m s/rad",
                                        id.rated_flux_current,
                                        id.dead_time * 1e6,
                                        id.viscous_friction
                                    ),
                                    "ok commissioned: settings applied (get lists them; save to keep them)".into(),
                                ],
                                Some(next),
                            )
                        }
                    },
                }
            }
        };
        self.log.push(Logged {
            period: self.period,
            event: Event::Commissioned(applied),
        });
        self.commissioned = Some(lines);
    }

    fn commission(&mut self, args: Option<NameplateArgs>) -> Vec<String> {
        let Some(args) = args else {
            if let Some(c) = self.ctl.commissioning() {
                return vec![format!(
                    "ok commissioning: {}, {:.1} s in this stage",
                    commission::stage_name(c.stage()),
                    c.stage_time()
                )];
            }
            return self.commissioned.clone().unwrap_or_else(|| {
                vec!["ok no commissioning yet (commission <P W> <V> <A> <Hz> <rpm>)".into()]
            });
        };
        if let Err(e) = commission::check(&args, self.ctl.inputs().dc_bus, &self.settings) {
            return vec![format!("err ({}: {})", e.field, e.rule)];
        }
        match self.apply(ControlCommand::Commission(args)) {
            Ok(()) => {
                self.nameplate = Some(args);
                self.commissioned = None;
                self.commission_started = Some(self.period);
                vec!["ok commissioning started: about 20 s, the rotor turns in the last test (commission: progress; stop: abort)".into()]
            }
            Err(e) => vec![String::from_utf8_lossy(refusal_text(e))
                .trim_end()
                .to_string()],
        }
    }

    fn control(&mut self, cmd: ControlCommand) -> String {
        match self.apply(cmd) {
            Ok(()) => "ok".into(),
            Err(e) => String::from_utf8_lossy(refusal_text(e))
                .trim_end()
                .to_string(),
        }
    }

    fn setting_line(&self, i: usize) -> String {
        let f = &FIELDS[i];
        let mut buf = [0u8; 24];
        let v = String::from_utf8_lossy(settings::format_value(self.settings.get(i), &mut buf))
            .to_string();
        if f.unit.is_empty() {
            format!("{} = {v}", f.name)
        } else {
            format!("{} = {v} {}", f.name, f.unit)
        }
    }

    fn apply_settings(&mut self, next: Settings, field: &str) -> String {
        let refused =
            format!("err {field}: refused while the drive is not idle (stop or reset first)");
        if self.ctl.state() != DriveState::Idle {
            return refused;
        }
        let drive = match next.drive_config() {
            Ok(cfg) => Drive::new(cfg).map_err(settings::SettingError::from),
            Err(e) => Err(e),
        };
        match drive {
            Err(e) => format!("err ({}: {})", e.field, e.rule),
            Ok(drive) => match self.ctl.replace_drive(drive) {
                Ok(()) => {
                    self.settings = next;
                    self.log.push(Logged {
                        period: self.period,
                        event: Event::Settings(next),
                    });
                    format!("ok {field} applied (save to keep it)")
                }
                Err(_) => refused,
            },
        }
    }

    fn handle(&mut self, r: Request, stream: &mut bool) -> Vec<String> {
        let c = match r {
            Request::Version => {
                return vec![format!(
                    "ok protocol {} board {BOARD_NAME} pwm {PWM_FREQUENCY_HZ} Hz",
                    protocol::PROTOCOL_VERSION
                )]
            }
            Request::Rate(n) => {
                self.set_rate(n);
                return vec!["ok".into()];
            }
            Request::Command(c) => c,
        };
        let one = |s: String| vec![s];
        match c {
            Command::Start => one(self.control(ControlCommand::Start)),
            Command::StartOpenLoop => one(self.control(ControlCommand::StartOpenLoop)),
            Command::Stop => one(self.control(ControlCommand::Stop)),
            Command::Speed(rpm) => one(self.control(ControlCommand::SpeedRpm(rpm))),
            Command::ResetFault => one(self.control(ControlCommand::ResetFault)),
            Command::Load(nm) => one(self.control(ControlCommand::PlantLoad(nm))),
            Command::Commission(args) => self.commission(args),
            Command::Stream(on) => {
                *stream = on;
                one("ok".into())
            }
            Command::Params => {
                let mut v: Vec<String> = (0..FIELDS.len()).map(|i| self.setting_line(i)).collect();
                v.insert(
                    0,
                    format!(
                        "params: Ts {} s, telemetry every {} periods, board {}",
                        1.0 / PWM_FREQUENCY_HZ as f32,
                        TELEMETRY_DECIMATION,
                        POWER_STAGE.name
                    ),
                );
                v.push("ok parameters listed (the firmware logs them on RTT)".into());
                v
            }
            Command::Status => one(format!(
                "ok state {} fault {:02}",
                self.ctl.state_code().min(9),
                self.ctl.fault_code() % 100
            )),
            Command::Set(i, v) => match (FIELDS.get(i), self.settings.set(i, v)) {
                (None, _) => one("err unknown setting".into()),
                (Some(f), Ok(next)) => one(self.apply_settings(next, f.name)),
                (Some(_), Err(e)) => one(format!("err ({}: {})", e.field, e.rule)),
            },
            Command::Defaults(low_voltage) => {
                let p = if low_voltage {
                    board::LOW_VOLTAGE
                } else {
                    board::PROFILE
                };
                let next = Settings::from_config(&board::drive_config_for(&p));
                one(self.apply_settings(next, "defaults"))
            }
            Command::Get(which) => {
                let mut v: Vec<String> = match which {
                    Some(i) if i < FIELDS.len() => vec![self.setting_line(i)],
                    Some(_) => Vec::new(),
                    None => (0..FIELDS.len()).map(|i| self.setting_line(i)).collect(),
                };
                v.push("ok".into());
                v
            }
            Command::Save => {
                if self.ctl.state() != DriveState::Idle {
                    one("err save: refused while the drive is not idle (stop or reset first)".into())
                } else {
                    self.saved = self.settings;
                    one("ok saved (virtual board: kept in memory until it exits)".into())
                }
            }
            // protocol 1: every reply ends with an `ok` or `err` line (the firmware's help
            // line has none)
            Command::Help => vec![
                "commands: start | vf | stop | speed <rpm> | reset | params | status | stream on|off | load <N m> (self-test) | set <name> <value> | get [<name>] | save | defaults [low-voltage] | commission [<P W> <V> <A> <Hz> <rpm>] | version | rate <periods>"
                    .into(),
                "ok".into(),
            ],
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
                    let accepted = b.apply(c).is_ok();
                    if let (ControlCommand::Commission(args), true) = (c, accepted) {
                        b.nameplate = Some(args);
                        b.commission_started = Some(b.period);
                    }
                }
                // re-derived by the replayed board itself
                Event::Commissioned(_) => {}
                Event::Rate(n) => b.set_rate(n),
                Event::Settings(s) => {
                    if let Ok(Ok(d)) = s.drive_config().map(Drive::new) {
                        if b.ctl.replace_drive(d).is_ok() {
                            b.settings = s;
                        }
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
            say(&mut b, "get current_limit"),
            "current_limit = 4.67 A\r\nok\r\n"
        );
        assert!(say(&mut b, "set current_limit -1").starts_with("err (current_limit: "));
        assert_eq!(say(&mut b, "start"), "ok\r\n");
        assert_eq!(
            say(&mut b, "set current_limit 4"),
            "err current_limit: refused while the drive is not idle (stop or reset first)\r\n"
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
        assert!(say(&mut b, "set current_limit 99").starts_with("err (overcurrent_trip: "));
        assert!(b.log().is_empty(), "{:?}", b.log());
        assert_eq!(say(&mut b, "start"), "ok\r\n");
        run(&mut b, 100);
        assert_eq!(say(&mut b, "start"), "err refused in this state\r\n");
        assert!(say(&mut b, "commission 750 230 3.3 50 1500").starts_with("err "));
        assert!(say(&mut b, "set current_limit 4").starts_with("err current_limit: refused"));
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
