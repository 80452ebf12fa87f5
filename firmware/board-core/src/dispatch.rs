//! The board's command handling, shared by the firmware's main loop and the virtual
//! board: a parsed request in ([`crate::protocol::parse_line`]), its action, its reply
//! lines out. One text for every reply, so a host tool meets the same board on a UART and
//! on a TCP port.
//!
//! What differs between the two boards is a [`Platform`]: how a command reaches the
//! control loop (the firmware queues it for its interrupt and gets the answer later, the
//! virtual board applies it at once), how a drive is rebuilt from new settings, where
//! `save` writes, whether a motor model takes `load`, the `params` reply, and the
//! commissioning's hand-over. Replies go into a caller's [`Reply`] sink, a line at a
//! time; nothing here allocates.
//!
//! The commissioning's result is kept here ([`Outcome`]) and applied only on `commission
//! apply`: a start, vf, set or defaults that takes effect before it discards a pending
//! result (a start or vf goes on with the settings in use, and a set or defaults would be
//! undone by settings made from the ones before it); a new `commission` replaces it.
//! `save` (it stores the settings in use), `speed`, `stop`, `reset` and the queries keep
//! it.

use crate::board::PWM_FREQUENCY_HZ;
use crate::command::{Command, ParseError};
use crate::commission::{self, Commissioning, Decision, NameplateArgs, Outcome, Proposal};
use crate::control::{refusal_text, ControlCommand, STATE_COMMISSIONING};
use crate::protocol::{Request, RequestError, PROTOCOL_VERSION};
use crate::settings::{
    format_fixed, format_significant, format_value, SettingError, Settings, FIELDS,
};
use acim::commissioning::Stage;
use acim::CommandError;

/// Where the reply goes: text in pieces, each line closed by [`Reply::end`] (the sink
/// adds the line end, or frames the line).
pub trait Reply {
    /// Appends ASCII text (no line end) to the line being written.
    fn put(&mut self, text: &[u8]);
    /// Ends the line.
    fn end(&mut self);
    /// A whole line.
    fn line(&mut self, text: &[u8]) {
        self.put(text);
        self.end();
    }
}

/// How a command reached the control loop.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Sent {
    /// Applied at once, with this result: the reply follows now.
    Done(Result<(), CommandError>),
    /// Queued: the control loop's result comes later, through
    /// [`Dispatch::control_reply`].
    Queued,
    /// The queue is full: dropped.
    Busy,
}

/// Why new settings did not reach the drive.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Rebuild {
    /// The drive is not Idle (or left Idle meanwhile).
    NotIdle,
    /// The drive refused the configuration.
    Invalid(SettingError),
}

/// What a board does its own way.
pub trait Platform {
    /// The board's name in the `version` reply.
    const NAME: &'static str;
    /// `load` reaches a motor model (the self-test, the virtual board).
    const PLANT: bool;
    /// The fastest `rate` whose samples the link carries whole (periods); a faster one is
    /// accepted with [`RATE_ABOVE_UART`]. 0: the link carries every rate.
    const RATE_FLOOR: u16 = 0;

    /// Hands a command to the control loop.
    fn send(&mut self, cmd: ControlCommand) -> Sent;
    /// The state code of the last period ([`crate::control::ControlLoop::state_code`]).
    fn state_code(&self) -> u8;
    /// The fault code of the last period.
    fn fault_code(&self) -> u8;
    /// The `status` reply's state and fault codes (the firmware also logs more).
    fn status(&mut self) -> (u8, u8) {
        (self.state_code(), self.fault_code())
    }
    /// The bus of the last period, V.
    fn dc_bus(&self) -> f32;
    /// Control periods run since power-up (wraps).
    fn periods(&self) -> u32;
    /// Builds a drive from `next` and swaps it in, only while Idle.
    fn rebuild(&mut self, next: &Settings) -> Result<(), Rebuild>;
    /// Keeps `s` over a power cycle: what the `ok` line says after `ok `, or why not.
    fn save(&mut self, s: &Settings) -> Result<&'static str, &'static str>;
    /// The whole `params` reply, its last line `ok ...`.
    fn params<R: Reply>(&mut self, s: &Settings, out: &mut R);
    /// Telemetry frames on this link on or off.
    fn set_stream(&mut self, on: bool);
    /// Hands the sequence built for the next `Commission` command to the control loop.
    fn stage_commissioning(&mut self, c: Option<Commissioning>);
    /// The running commissioning's stage and its time in it, s.
    fn commissioning_progress(&self) -> Option<(Stage, f32)>;
    /// Takes a commissioning that has finished (done or failed) from the control loop.
    fn take_finished_commissioning(&mut self) -> Option<Commissioning>;
}

/// Telemetry samples per second a 115 200 baud UART carries: a `$T` frame and its `$X`
/// are about 128 bytes with the values of a running drive, 10 bits per byte on the line.
pub const UART_SAMPLES_PER_S: u32 = crate::board::UART_BAUD / 10 / 128;

/// The fastest `rate` whose samples all fit the UART (periods).
pub const UART_RATE_FLOOR: u16 = PWM_FREQUENCY_HZ.div_ceil(UART_SAMPLES_PER_S) as u16;

/// The reply to a `rate` faster than [`Platform::RATE_FLOOR`]: accepted, with what the
/// user will see.
pub const RATE_ABOVE_UART: &[u8] =
    b"ok (the UART carries about 90 samples/s, a rate of 56 periods: faster samples are dropped whole, seq shows the gaps)";
const _: () = assert!(
    UART_SAMPLES_PER_S == 90 && UART_RATE_FLOOR == 56,
    "RATE_ABOVE_UART states these numbers"
);

/// The reply to an accepted `commission <nameplate>`.
pub const COMMISSION_STARTED: &[u8] = b"ok commissioning started: about 20 s, the rotor turns in the last test (commission: progress; stop: abort)";

/// The `help` reply, before its `ok` line (each line fits a reply frame).
pub const HELP: [&[u8]; 3] = [
    b"commands: start | vf | stop | speed <rpm> | reset | params | status | stream on|off | load <N m> (self-test) | version | rate <periods>",
    b"settings: set <name> <value> | get [<name>] | save | defaults [low-voltage]",
    b"commissioning: commission <P W> <V> <A> <Hz> <rpm> | commission (progress, result) | commission apply (its settings; a start, vf, set or defaults before it discards them)",
];

/// The main loop's half of `commission`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct CommissionState {
    /// The nameplate of the sequence under way or last run.
    nameplate: Option<NameplateArgs>,
    /// A sequence is under way.
    running: bool,
    /// [`Platform::periods`] when it was accepted.
    started: u32,
    /// How the last one ended.
    outcome: Option<Outcome>,
}

/// The command handling: the settings in use and the commissioning's state.
#[derive(Clone, Debug, PartialEq)]
pub struct Dispatch {
    settings: Settings,
    com: CommissionState,
}

impl Dispatch {
    /// The handling of a board whose drive runs on `settings`.
    pub fn new(settings: Settings) -> Self {
        Self {
            settings,
            com: CommissionState::default(),
        }
    }

    /// The settings in use.
    pub fn settings(&self) -> &Settings {
        &self.settings
    }

    /// Records that the drive now runs on `s`, swapped in without a command (a replay of
    /// a logged run).
    pub fn replace_settings(&mut self, s: Settings) {
        self.settings = s;
    }

    /// How the last commissioning ended (`None`: none ended since power-up, or one runs).
    pub fn outcome(&self) -> Option<&Outcome> {
        self.com.outcome.as_ref()
    }

    /// Handles one parsed request (plain or framed: the sink frames the lines). An error
    /// changes nothing; a blank line gets no reply.
    #[inline(never)]
    pub fn handle<P: Platform, R: Reply>(
        &mut self,
        request: Result<Request, RequestError>,
        p: &mut P,
        out: &mut R,
    ) {
        let c = match request {
            Ok(Request::Command(c)) => c,
            Ok(Request::Version) => {
                out.put(b"ok protocol ");
                put_uint(out, PROTOCOL_VERSION as u32);
                out.put(b" board ");
                out.put(P::NAME.as_bytes());
                out.put(b" pwm ");
                put_uint(out, PWM_FREQUENCY_HZ);
                out.line(b" Hz");
                return;
            }
            // to the control loop's decimator; its "ok" comes back as for any command
            Ok(Request::Rate(n)) => return self.send(ControlCommand::Rate(n), p, out),
            Err(RequestError::Parse(ParseError::Empty)) => return,
            Err(e) => {
                out.put(b"err ");
                out.line(e.as_str().as_bytes());
                return;
            }
        };
        match c {
            Command::Start => self.send(ControlCommand::Start, p, out),
            Command::StartOpenLoop => self.send(ControlCommand::StartOpenLoop, p, out),
            Command::Stop => self.send(ControlCommand::Stop, p, out),
            Command::Speed(rpm) => self.send(ControlCommand::SpeedRpm(rpm), p, out),
            Command::ResetFault => self.send(ControlCommand::ResetFault, p, out),
            Command::Load(nm) if P::PLANT => self.send(ControlCommand::PlantLoad(nm), p, out),
            Command::Load(_) => out.line(b"err load applies to the self-test's motor model only"),
            Command::Stream(on) => {
                p.set_stream(on);
                out.line(b"ok");
            }
            Command::Commission(None) => self.report(p, out),
            Command::Commission(Some(args)) => {
                let bus = p.dc_bus();
                match commission::check(&args, bus, &self.settings) {
                    // built here (outside the control step), started by the control loop;
                    // a nameplate the library refuses reaches it with nothing staged,
                    // which it refuses (`err value out of range`)
                    Ok(_) => {
                        p.stage_commissioning(commission::build(&args, bus));
                        self.send(ControlCommand::Commission(args), p, out);
                    }
                    Err(e) => setting_refusal(out, &e),
                }
            }
            Command::CommissionApply => self.apply_commissioned(p, out),
            Command::Params => p.params(&self.settings, out),
            Command::Status => {
                let (state, fault) = p.status();
                out.put(b"ok state ");
                out.put(&[b'0' + state.min(9)]);
                out.put(b" fault ");
                out.line(&[b'0' + fault / 10 % 10, b'0' + fault % 10]);
            }
            Command::Set(i, v) => {
                let Some(field) = FIELDS.get(i) else {
                    return out.line(b"err unknown setting");
                };
                match self.settings.set(i, v) {
                    Ok(next) => {
                        if self.apply_settings(next, field.name.as_bytes(), p, out) {
                            out.put(b"ok ");
                            out.put(field.name.as_bytes());
                            out.line(b" applied (save to keep it)");
                        }
                    }
                    Err(e) => setting_refusal(out, &e),
                }
            }
            Command::Defaults(low_voltage) => {
                let profile = if low_voltage {
                    crate::board::BOARD.low_voltage
                } else {
                    crate::board::PROFILE
                };
                let next = Settings::from_config(&crate::board::drive_config_for(&profile));
                if self.apply_settings(next, b"defaults", p, out) {
                    out.line(b"ok defaults applied (save to keep it)");
                }
            }
            Command::Get(which) => {
                match which {
                    Some(i) => setting_line(out, &self.settings, i),
                    None => (0..FIELDS.len()).for_each(|i| setting_line(out, &self.settings, i)),
                }
                out.line(b"ok");
            }
            Command::Save => {
                if p.state_code() != 0 {
                    out.line(
                        b"err save: refused while the drive is not idle (stop or reset first)",
                    );
                } else {
                    match p.save(&self.settings) {
                        Ok(what) => {
                            out.put(b"ok ");
                            out.line(what.as_bytes());
                        }
                        Err(why) => {
                            out.put(b"err save failed: ");
                            out.line(why.as_bytes());
                        }
                    }
                }
            }
            Command::Help => {
                for l in HELP {
                    out.line(l);
                }
                out.line(b"ok");
            }
        }
    }

    /// The control loop's answer to a command (at once, or for a queued one when it comes
    /// back): `ok`, or the refusal. An accepted `commission` starts its bookkeeping; an
    /// accepted start or vf discards a pending result.
    #[inline(never)]
    pub fn control_reply<P: Platform, R: Reply>(
        &mut self,
        cmd: ControlCommand,
        result: Result<(), CommandError>,
        p: &mut P,
        out: &mut R,
    ) {
        if let Err(e) = result {
            let t = refusal_text(e);
            return out.line(t.strip_suffix(b"\r\n").unwrap_or(t));
        }
        match cmd {
            ControlCommand::Commission(args) => {
                self.com = CommissionState {
                    nameplate: Some(args),
                    running: true,
                    started: p.periods(),
                    outcome: None,
                };
                out.line(COMMISSION_STARTED);
            }
            ControlCommand::Rate(n) if n < P::RATE_FLOOR => out.line(RATE_ABOVE_UART),
            ControlCommand::Start | ControlCommand::StartOpenLoop => {
                self.discard();
                out.line(b"ok");
            }
            _ => out.line(b"ok"),
        }
    }

    /// Once per main-loop pass (firmware) or period (virtual board): the fits of a
    /// commissioning that has finished, or the end of one that was stopped or tripped.
    #[inline(never)]
    pub fn poll<P: Platform>(&mut self, p: &mut P) {
        if let Some(c) = p.take_finished_commissioning() {
            let running = core::mem::replace(&mut self.com.running, false);
            let periods = if running {
                p.periods().wrapping_sub(self.com.started)
            } else {
                0
            };
            let seconds = periods as f32 / PWM_FREQUENCY_HZ as f32;
            self.com.outcome = Some(commission::outcome(
                &c,
                self.com.nameplate.as_ref(),
                &self.settings,
                seconds,
            ));
        } else if self.com.running && p.state_code() != STATE_COMMISSIONING {
            // stopped, or abandoned by a trip
            self.com.running = false;
            self.com.outcome = Some(Outcome::Aborted(p.fault_code()));
        }
    }

    /// A pending result is dropped (a start, vf, set or defaults took effect).
    fn discard(&mut self) {
        if let Some(Outcome::Identified(pr)) = self.com.outcome.as_mut() {
            if pr.decision == Decision::Pending {
                pr.decision = Decision::Discarded;
            }
        }
    }

    fn send<P: Platform, R: Reply>(&mut self, cmd: ControlCommand, p: &mut P, out: &mut R) {
        match p.send(cmd) {
            Sent::Done(result) => self.control_reply(cmd, result, p, out),
            // the reply ("ok" / the refusal) comes back from the control loop
            Sent::Queued => {}
            Sent::Busy => out.line(b"err busy, command dropped"),
        }
    }

    /// Rebuilds the drive from `next` and swaps it in if Idle; on success the settings
    /// are `next` (and a pending commissioning result is dropped) and the caller replies,
    /// otherwise this replies the refusal naming `field`.
    #[inline(never)]
    fn apply_settings<P: Platform, R: Reply>(
        &mut self,
        next: Settings,
        field: &[u8],
        p: &mut P,
        out: &mut R,
    ) -> bool {
        let result = if p.state_code() != 0 {
            Err(Rebuild::NotIdle)
        } else {
            p.rebuild(&next)
        };
        match result {
            Ok(()) => {
                self.settings = next;
                self.discard();
                true
            }
            Err(Rebuild::NotIdle) => {
                out.put(b"err ");
                out.put(field);
                out.line(b": refused while the drive is not idle (stop or reset first)");
                false
            }
            Err(Rebuild::Invalid(e)) => {
                setting_refusal(out, &e);
                false
            }
        }
    }

    /// `commission apply`.
    #[inline(never)]
    fn apply_commissioned<P: Platform, R: Reply>(&mut self, p: &mut P, out: &mut R) {
        let pending = match self.com.outcome {
            Some(Outcome::Identified(pr)) if !self.com.running => match pr.decision {
                Decision::Pending => pr.settings,
                Decision::Applied => return out.line(b"err nothing to apply (already applied)"),
                Decision::Discarded => {
                    return out.line(
                        b"err nothing to apply (discarded by a start, vf, set or defaults after it)",
                    )
                }
            },
            _ if self.com.running => {
                return out.line(b"err nothing to apply (commissioning runs: commission shows it)")
            }
            _ => {
                return out.line(
                    b"err nothing to apply (no accepted commissioning result: commission shows the last)",
                )
            }
        };
        if self.apply_settings(pending, b"commission apply", p, out) {
            if let Some(Outcome::Identified(pr)) = self.com.outcome.as_mut() {
                pr.decision = Decision::Applied;
            }
            out.line(b"ok applied (get lists the settings; save to keep them)");
        }
    }

    /// The `commission` query's reply: progress, or how the last one ended.
    #[inline(never)]
    fn report<P: Platform, R: Reply>(&self, p: &mut P, out: &mut R) {
        let mut buf = [0u8; 24];
        if let Some((stage, t)) = p.commissioning_progress() {
            out.put(b"ok commissioning: ");
            out.put(commission::stage_name(stage).as_bytes());
            out.put(b", ");
            out.put(format_fixed(t, 1, &mut buf));
            out.line(b" s in this stage");
            return;
        }
        match &self.com.outcome {
            None => out.line(b"ok no commissioning yet (commission <P W> <V> <A> <Hz> <rpm>)"),
            Some(Outcome::Identified(pr)) => proposal(out, pr),
            Some(Outcome::Failed(e)) => {
                out.put(b"err commissioning failed: ");
                out.put(commission::error_text(*e).as_bytes());
                if let Some(d) = commission::error_detail(*e) {
                    out.put(b" (");
                    out.put(d.as_bytes());
                    out.put(b")");
                }
                out.line(b"; settings unchanged");
            }
            Some(Outcome::Refused(e)) => {
                out.put(b"err commissioning failed: the identified model is refused");
                setting_error(out, e);
                out.line(b"; settings unchanged");
            }
            Some(Outcome::Aborted(0)) => {
                out.line(b"ok commissioning aborted by stop; settings unchanged")
            }
            Some(Outcome::Aborted(f)) => {
                out.put(b"err commissioning abandoned: the drive tripped (fault ");
                out.put(crate::protocol::fault_name(*f).as_bytes());
                out.line(b"); settings unchanged");
            }
        }
    }
}

/// An accepted result: each identified value with the bound on its error, then where it
/// stands.
#[inline(never)]
fn proposal<R: Reply>(out: &mut R, pr: &Proposal) {
    let (id, c) = (&pr.identified, &pr.confidence);
    let mut buf = [0u8; 24];
    out.put(b"identified in ");
    out.put(format_fixed(pr.seconds, 1, &mut buf));
    out.line(b" s (inverse-Gamma model; +/-: the bound on each value's error)");
    identified(
        out,
        b"rs",
        id.stator_resistance,
        b"ohm",
        c.stator_resistance,
    );
    identified(out, b"r_r", id.rotor_resistance, b"ohm", c.rotor_resistance);
    identified(
        out,
        b"l_sigma",
        id.leakage_inductance * 1e3,
        b"mH",
        c.leakage_inductance,
    );
    identified(
        out,
        b"l_m",
        id.magnetizing_inductance * 1e3,
        b"mH",
        c.magnetizing_inductance,
    );
    identified(
        out,
        b"loops.flux_current",
        id.rated_flux_current,
        b"A",
        c.rated_flux_current,
    );
    match id.inertia {
        Some(j) => identified(out, b"machine.inertia", j, b"kg m^2", c.inertia),
        None => out.line(b"identified machine.inertia: not resolved (the setting is kept)"),
    }
    identified(
        out,
        b"machine.viscous_friction",
        id.viscous_friction,
        b"N m s/rad",
        c.viscous_friction,
    );
    identified(out, b"dead_time", id.dead_time * 1e6, b"us", c.dead_time);
    out.line(match pr.decision {
        Decision::Pending => {
            b"ok commissioned: send 'commission apply' to use these settings (or 'commission <P W> <V> <A> <Hz> <rpm>' to repeat)" as &[u8]
        }
        Decision::Applied => b"ok commissioned: applied (get lists the settings; save to keep them)",
        Decision::Discarded => {
            b"ok commissioned: not applied (a start, vf, set or defaults came first; settings unchanged)"
        }
    });
}

/// `identified <name> <value> <unit> +/-<bound> %`.
#[inline(never)]
fn identified<R: Reply>(out: &mut R, name: &[u8], v: f32, unit: &[u8], bound: f32) {
    let mut buf = [0u8; 24];
    out.put(b"identified ");
    out.put(name);
    out.put(b" ");
    out.put(format_significant(v, 4, &mut buf));
    out.put(b" ");
    out.put(unit);
    if bound.is_finite() {
        out.put(b" +/-");
        out.put(format_significant(100.0 * bound, 2, &mut buf));
        out.line(b" %");
    } else {
        out.line(b" (no bound)");
    }
}

/// A whole number.
fn put_uint<R: Reply>(out: &mut R, mut n: u32) {
    let mut digits = [0u8; 10];
    let mut k = digits.len();
    loop {
        k -= 1;
        digits[k] = b'0' + (n % 10) as u8;
        n /= 10;
        if n == 0 {
            break;
        }
    }
    out.put(&digits[k..]);
}

/// ` (field: rule)`, within a line.
pub fn setting_error<R: Reply>(out: &mut R, e: &SettingError) {
    out.put(b" (");
    out.put(e.field.as_bytes());
    out.put(b": ");
    out.put(e.rule.as_bytes());
    out.put(b")");
}

/// The line `err (field: rule)`.
fn setting_refusal<R: Reply>(out: &mut R, e: &SettingError) {
    out.put(b"err");
    setting_error(out, e);
    out.end();
}

/// The line `name = value unit` of setting `i` (nothing for an index beyond the fields).
#[inline(never)]
pub fn setting_line<R: Reply>(out: &mut R, s: &Settings, i: usize) {
    let Some(f) = FIELDS.get(i) else { return };
    let mut buf = [0u8; 24];
    out.put(f.name.as_bytes());
    out.put(b" = ");
    out.put(format_value(s.get(i), &mut buf));
    if !f.unit.is_empty() {
        out.put(b" ");
        out.put(f.unit.as_bytes());
    }
    out.end();
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::protocol::parse_line;
    use acim::commissioning::{CommissioningError, Concern, Confidence, Identified};
    use acim::DriveState;
    use heapless::{String, Vec};

    /// Reply lines, as text.
    #[derive(Default)]
    struct Lines {
        done: Vec<String<256>, 24>,
        cur: String<256>,
    }

    impl Reply for Lines {
        fn put(&mut self, text: &[u8]) {
            self.cur
                .push_str(core::str::from_utf8(text).unwrap())
                .unwrap();
        }
        fn end(&mut self) {
            let l = core::mem::take(&mut self.cur);
            self.done.push(l).unwrap();
        }
    }

    /// A board whose control loop is a state code: commands are queued (as the
    /// firmware's) or applied at once, and every accepted one is recorded.
    struct Fake {
        queued: bool,
        state: u8,
        fault: u8,
        sent: Vec<ControlCommand, 16>,
        rebuilt: Vec<Settings, 4>,
        saved: Option<Settings>,
        stream: bool,
        periods: u32,
        finished: Option<Commissioning>,
    }

    impl Fake {
        fn new(queued: bool) -> Self {
            Fake {
                queued,
                state: 0,
                fault: 0,
                sent: Vec::new(),
                rebuilt: Vec::new(),
                saved: None,
                stream: false,
                periods: 0,
                finished: None,
            }
        }
    }

    impl Platform for Fake {
        const NAME: &'static str = "fake";
        const PLANT: bool = false;
        const RATE_FLOOR: u16 = UART_RATE_FLOOR;

        fn send(&mut self, cmd: ControlCommand) -> Sent {
            if self.sent.push(cmd).is_err() {
                return Sent::Busy;
            }
            if self.queued {
                return Sent::Queued;
            }
            Sent::Done(match cmd {
                ControlCommand::Start if self.state == 0 => {
                    self.state = DriveState::Running.code();
                    Ok(())
                }
                ControlCommand::Start => Err(CommandError::WrongState(DriveState::Running)),
                ControlCommand::Stop => {
                    self.state = 0;
                    Ok(())
                }
                ControlCommand::Commission(_) => {
                    self.state = STATE_COMMISSIONING;
                    Ok(())
                }
                _ => Ok(()),
            })
        }
        fn state_code(&self) -> u8 {
            self.state
        }
        fn fault_code(&self) -> u8 {
            self.fault
        }
        fn dc_bus(&self) -> f32 {
            325.0
        }
        fn periods(&self) -> u32 {
            self.periods
        }
        fn rebuild(&mut self, next: &Settings) -> Result<(), Rebuild> {
            self.rebuilt.push(*next).unwrap();
            Ok(())
        }
        fn save(&mut self, s: &Settings) -> Result<&'static str, &'static str> {
            self.saved = Some(*s);
            Ok("saved")
        }
        fn params<R: Reply>(&mut self, _s: &Settings, out: &mut R) {
            out.line(b"ok params");
        }
        fn set_stream(&mut self, on: bool) {
            self.stream = on;
        }
        fn stage_commissioning(&mut self, _c: Option<Commissioning>) {}
        fn commissioning_progress(&self) -> Option<(Stage, f32)> {
            (self.state == STATE_COMMISSIONING).then_some((Stage::DcStep(1), 1.25))
        }
        fn take_finished_commissioning(&mut self) -> Option<Commissioning> {
            self.finished.take()
        }
    }

    fn say(d: &mut Dispatch, p: &mut Fake, line: &str) -> Vec<String<256>, 24> {
        let mut out = Lines::default();
        d.handle(parse_line(line.as_bytes()).request, p, &mut out);
        assert!(out.cur.is_empty(), "an unfinished line");
        out.done
    }

    fn one(d: &mut Dispatch, p: &mut Fake, line: &str) -> String<256> {
        let r = say(d, p, line);
        assert_eq!(r.len(), 1, "{line}: {r:?}");
        r[0].clone()
    }

    /// An accepted result, pending, with settings unlike the defaults.
    fn pending(d: &mut Dispatch) -> Settings {
        let lim = crate::settings::field_index(b"limits.current_limit").unwrap();
        let settings = d.settings().set(lim, 3.0).unwrap();
        d.com.outcome = Some(Outcome::Identified(Proposal {
            identified: Identified {
                stator_resistance: 10.497,
                rotor_resistance: 7.2134,
                leakage_inductance: 0.041271,
                magnetizing_inductance: 0.42193,
                magnetizing_inductance_small_signal: 0.43,
                rated_flux_current: 1.2034,
                inverter_error: 3.0,
                dead_time: 1.492e-6,
                dc_fit_residual: 0.001,
                inertia: Some(0.023449),
                viscous_friction: 0.0021,
            },
            confidence: Confidence {
                stator_resistance: 0.0081,
                rotor_resistance: 0.021,
                leakage_inductance: 0.015,
                magnetizing_inductance: 0.012,
                rated_flux_current: 0.011,
                inverter_error: 0.05,
                dead_time: 0.033,
                inertia: 0.042,
                viscous_friction: f32::INFINITY,
            },
            settings,
            seconds: 16.27,
            decision: Decision::Pending,
        }));
        settings
    }

    #[test]
    fn replies_of_the_plain_commands() {
        let mut d = Dispatch::new(Settings::defaults());
        let mut p = Fake::new(false);
        assert_eq!(
            one(&mut d, &mut p, "version"),
            "ok protocol 1 board fake pwm 5000 Hz"
        );
        assert_eq!(one(&mut d, &mut p, "status"), "ok state 0 fault 00");
        p.fault = 17;
        assert_eq!(one(&mut d, &mut p, "status"), "ok state 0 fault 17");
        p.fault = 0;
        assert_eq!(
            one(&mut d, &mut p, "bogus"),
            "err unknown command (try help)"
        );
        assert!(say(&mut d, &mut p, "").is_empty());
        assert_eq!(
            one(&mut d, &mut p, "load 1"),
            "err load applies to the self-test's motor model only"
        );
        assert_eq!(one(&mut d, &mut p, "stream on"), "ok");
        assert!(p.stream);
        assert_eq!(one(&mut d, &mut p, "rate 100"), "ok");
        assert_eq!(
            one(&mut d, &mut p, "rate 55"),
            core::str::from_utf8(RATE_ABOVE_UART).unwrap()
        );
        assert_eq!(
            say(&mut d, &mut p, "get limits.current_limit").as_slice(),
            ["limits.current_limit = 4.67 A", "ok"]
        );
        assert_eq!(say(&mut d, &mut p, "get").len(), FIELDS.len() + 1);
        assert_eq!(
            one(&mut d, &mut p, "set limits.current_limit 4"),
            "ok limits.current_limit applied (save to keep it)"
        );
        assert_eq!(d.settings().get(2), 4.0);
        assert!(one(&mut d, &mut p, "set limits.current_limit 99")
            .starts_with("err (limits.overcurrent_trip: "));
        assert_eq!(
            one(&mut d, &mut p, "defaults"),
            "ok defaults applied (save to keep it)"
        );
        assert_eq!(*d.settings(), Settings::defaults());
        assert_eq!(one(&mut d, &mut p, "save"), "ok saved");
        assert_eq!(p.saved, Some(Settings::defaults()));
        let help = say(&mut d, &mut p, "help");
        assert_eq!(help.len(), HELP.len() + 1);
        assert_eq!(help.last().unwrap().as_str(), "ok");
        for l in &help {
            // each line fits a reply frame
            assert!(l.len() + 10 <= crate::protocol::LINE_CAPACITY - 8, "{l}");
        }
        assert_eq!(one(&mut d, &mut p, "start"), "ok");
        assert_eq!(one(&mut d, &mut p, "start"), "err refused in this state");
        assert_eq!(
            one(&mut d, &mut p, "set limits.current_limit 4"),
            "err limits.current_limit: refused while the drive is not idle (stop or reset first)"
        );
        assert_eq!(
            one(&mut d, &mut p, "save"),
            "err save: refused while the drive is not idle (stop or reset first)"
        );
        assert_eq!(*d.settings(), Settings::defaults());
    }

    /// The firmware's way: the reply to a queued command comes with the control loop's
    /// answer; a full queue drops the command.
    #[test]
    fn queued_commands_are_answered_later() {
        let mut d = Dispatch::new(Settings::defaults());
        let mut p = Fake::new(true);
        assert!(say(&mut d, &mut p, "speed 500").is_empty());
        assert_eq!(p.sent.as_slice(), [ControlCommand::SpeedRpm(500.0)]);
        let mut out = Lines::default();
        d.control_reply(ControlCommand::SpeedRpm(500.0), Ok(()), &mut p, &mut out);
        d.control_reply(
            ControlCommand::Start,
            Err(CommandError::Demagnetizing),
            &mut p,
            &mut out,
        );
        assert_eq!(out.done[0].as_str(), "ok");
        assert!(out.done[1].starts_with("err the rotor flux has not decayed"));
        while p.sent.push(ControlCommand::Stop).is_ok() {}
        assert_eq!(one(&mut d, &mut p, "stop"), "err busy, command dropped");
    }

    #[test]
    fn a_commissioning_is_started_reported_and_aborted() {
        let mut d = Dispatch::new(Settings::defaults());
        let mut p = Fake::new(false);
        assert_eq!(
            one(&mut d, &mut p, "commission"),
            "ok no commissioning yet (commission <P W> <V> <A> <Hz> <rpm>)"
        );
        assert!(one(&mut d, &mut p, "commission 2000 230 3.3 50 1500")
            .starts_with("err (nameplate.power_w: "));
        assert_eq!(
            one(&mut d, &mut p, "commission apply"),
            "err nothing to apply (no accepted commissioning result: commission shows the last)"
        );
        assert_eq!(
            one(&mut d, &mut p, "commission 750 230 3.3 50 1500"),
            core::str::from_utf8(COMMISSION_STARTED).unwrap()
        );
        assert_eq!(
            one(&mut d, &mut p, "commission"),
            "ok commissioning: DC steps (Rs, inverter error), 1.3 s in this stage"
        );
        assert_eq!(
            one(&mut d, &mut p, "commission apply"),
            "err nothing to apply (commissioning runs: commission shows it)"
        );
        d.poll(&mut p);
        assert_eq!(d.outcome(), None, "still running");
        // a trip abandons it
        p.state = DriveState::Fault.code();
        p.fault = 16;
        d.poll(&mut p);
        assert_eq!(
            one(&mut d, &mut p, "commission"),
            "err commissioning abandoned: the drive tripped (fault HardwareBreak (break input)); settings unchanged"
        );
        p.state = 0;
        p.fault = 0;
        assert_eq!(
            one(&mut d, &mut p, "commission 750 230 3.3 50 1500").len(),
            COMMISSION_STARTED.len()
        );
        assert_eq!(one(&mut d, &mut p, "stop"), "ok");
        d.poll(&mut p);
        assert_eq!(
            one(&mut d, &mut p, "commission"),
            "ok commissioning aborted by stop; settings unchanged"
        );
        assert!(one(&mut d, &mut p, "commission apply").starts_with("err nothing to apply"));
        // a refused result names why, and there is nothing to apply
        d.com.outcome = Some(Outcome::Failed(CommissioningError::Implausible(
            Concern::CoupledLoad,
        )));
        assert_eq!(
            one(&mut d, &mut p, "commission"),
            "err commissioning failed: a load seems coupled (no-load torque over 10 % of rated) \
             (uncouple the load and run again (or check the power)); settings unchanged"
        );
        assert!(one(&mut d, &mut p, "commission apply").starts_with("err nothing to apply"));
        assert!(p.rebuilt.is_empty());
        assert_eq!(*d.settings(), Settings::defaults());
    }

    #[test]
    fn a_result_is_reported_with_its_bounds_and_applied_once() {
        let mut d = Dispatch::new(Settings::defaults());
        let mut p = Fake::new(false);
        let next = pending(&mut d);
        let r = say(&mut d, &mut p, "commission");
        assert_eq!(
            r.as_slice(),
            [
                "identified in 16.3 s (inverse-Gamma model; +/-: the bound on each value's error)",
                "identified rs 10.5 ohm +/-0.81 %",
                "identified r_r 7.213 ohm +/-2.1 %",
                "identified l_sigma 41.27 mH +/-1.5 %",
                "identified l_m 421.9 mH +/-1.2 %",
                "identified loops.flux_current 1.203 A +/-1.1 %",
                "identified machine.inertia 0.02345 kg m^2 +/-4.2 %",
                "identified machine.viscous_friction 0.0021 N m s/rad (no bound)",
                "identified dead_time 1.492 us +/-3.3 %",
                "ok commissioned: send 'commission apply' to use these settings \
                 (or 'commission <P W> <V> <A> <Hz> <rpm>' to repeat)",
            ]
        );
        for l in &r {
            assert!(l.len() + 10 <= crate::protocol::LINE_CAPACITY - 8, "{l}");
        }
        // nothing changed before the apply
        assert_eq!(*d.settings(), Settings::defaults());
        // refused while not idle, and still pending
        p.state = DriveState::Fault.code();
        assert_eq!(
            one(&mut d, &mut p, "commission apply"),
            "err commission apply: refused while the drive is not idle (stop or reset first)"
        );
        p.state = 0;
        assert_eq!(
            one(&mut d, &mut p, "commission apply"),
            "ok applied (get lists the settings; save to keep them)"
        );
        assert_eq!(*d.settings(), next);
        assert_eq!(p.rebuilt.as_slice(), [next]);
        assert_eq!(
            one(&mut d, &mut p, "commission apply"),
            "err nothing to apply (already applied)"
        );
        assert_eq!(
            say(&mut d, &mut p, "commission").last().unwrap().as_str(),
            "ok commissioned: applied (get lists the settings; save to keep them)"
        );
        // a start after it does not undo it
        assert_eq!(one(&mut d, &mut p, "start"), "ok");
        assert_eq!(*d.settings(), next);
    }

    /// What discards a pending result (it took effect), and what keeps it.
    #[test]
    fn start_vf_set_and_defaults_discard_a_pending_result() {
        let discarding = ["start", "vf", "set limits.current_limit 4", "defaults"];
        for cmd in discarding {
            let mut d = Dispatch::new(Settings::defaults());
            let mut p = Fake::new(false);
            pending(&mut d);
            // the queries, save, and the commands that change no settings keep it
            for keep in [
                "status",
                "get",
                "params",
                "commission",
                "help",
                "version",
                "save",
                "speed 300",
                "stop",
                "reset",
                "stream on",
                "rate 100",
            ] {
                say(&mut d, &mut p, keep);
            }
            assert!(
                matches!(d.outcome(), Some(Outcome::Identified(pr)) if pr.decision == Decision::Pending),
                "{cmd}"
            );
            assert!(one(&mut d, &mut p, cmd).starts_with("ok"), "{cmd}");
            assert_eq!(one(&mut d, &mut p, "stop"), "ok");
            assert_eq!(
                one(&mut d, &mut p, "commission apply"),
                "err nothing to apply (discarded by a start, vf, set or defaults after it)",
                "{cmd}"
            );
            assert_eq!(
                say(&mut d, &mut p, "commission").last().unwrap().as_str(),
                "ok commissioned: not applied (a start, vf, set or defaults came first; settings unchanged)"
            );
        }
        // a refused start (it changes nothing) keeps it
        let mut d = Dispatch::new(Settings::defaults());
        let mut p = Fake::new(true);
        pending(&mut d);
        assert!(say(&mut d, &mut p, "start").is_empty());
        let mut out = Lines::default();
        d.control_reply(
            ControlCommand::Start,
            Err(CommandError::WrongState(DriveState::Fault)),
            &mut p,
            &mut out,
        );
        assert_eq!(
            one(&mut d, &mut p, "commission apply").as_str(),
            "ok applied (get lists the settings; save to keep them)"
        );
        // a new commissioning replaces a pending result
        let mut d = Dispatch::new(Settings::defaults());
        let mut p = Fake::new(false);
        pending(&mut d);
        assert!(one(&mut d, &mut p, "commission 750 230 3.3 50 1500")
            .starts_with("ok commissioning started"));
        assert_eq!(d.outcome(), None);
    }
}
