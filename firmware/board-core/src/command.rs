//! The bounded command parser: one ASCII line per command, at most [`MAX_LINE`] bytes.
//!
//! ```text
//! start            Idle -> magnetizing -> sensorless speed control
//! vf               Idle -> open-loop V/f (commissioning)
//! stop             switches off, the machine coasts
//! speed <rpm>      speed target, |rpm| <= MAX_SPEED_COMMAND_RPM, e.g. "speed -500" or "speed 120.5"
//! reset            fault -> idle
//! params           print the drive configuration and board values
//! status           print the state, fault and timing
//! stream on|off    text telemetry frames on the UART as well as RTT
//! load <N m>       self-test only: the motor model's load torque (a brake), |N m| <= 20
//! set <name> <v>   change a setting (crate::settings::FIELDS), Idle only, e.g. "set limits.current_limit 2.5"
//! get [<name>]     print one setting, or all of them
//! save             write the settings to the reserved flash page (Idle only)
//! defaults [low-voltage]  this build's default settings (or the 24-60 V bring-up profile), Idle only, not saved
//! commission <P W> <V> <A> <Hz> <rpm>  self-commissioning from the nameplate (rated power, line
//!                  voltage rms, line current rms, frequency, speed), Idle only; the rotor turns
//! commission       its progress, or its result (the identified values with their confidence)
//! commission apply use the last commissioning's result: its settings replace the drive's
//!                  (Idle only; a start, vf, set or defaults after the result discards it)
//! help             list the commands
//! ```
//!
//! Words are separated by spaces or tabs, case-sensitive lower case. A malformed line
//! (unknown word, missing, extra or bad argument, non-ASCII byte, longer than
//! [`MAX_LINE`]) yields a [`ParseError`] and no command: nothing changes.

use crate::board::MAX_SPEED_COMMAND_RPM;
use crate::settings::{field_index, parse_value};

/// Largest load torque the self-test's `load` command accepts, N m.
pub const MAX_LOAD_COMMAND_NM: f32 = 20.0;
use heapless::Vec;

/// Longest accepted line, bytes (without the terminator).
pub const MAX_LINE: usize = 48;

/// A parsed command.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Command {
    /// Start sensorless speed control.
    Start,
    /// Start open-loop V/f.
    StartOpenLoop,
    /// Switches off.
    Stop,
    /// Speed target, rpm (mechanical).
    Speed(f32),
    /// Leave the fault state.
    ResetFault,
    /// Print the parameters.
    Params,
    /// Print the status.
    Status,
    /// Text telemetry on the UART on/off.
    Stream(bool),
    /// Self-test: the motor model's (passive) load torque, N m.
    Load(f32),
    /// Change setting `.0` (index into [`crate::settings::FIELDS`]) to `.1`.
    Set(usize, f32),
    /// Print one setting (`Some` index) or all.
    Get(Option<usize>),
    /// Write the settings to flash.
    Save,
    /// Load the default settings (`true`: the low-voltage bring-up profile).
    Defaults(bool),
    /// Start self-commissioning with this nameplate (`Some`), or report its progress or
    /// result (`None`); see [`crate::commission`].
    Commission(Option<crate::commission::NameplateArgs>),
    /// `commission apply`: the last commissioning's identified settings replace the
    /// drive's ([`crate::dispatch`]).
    CommissionApply,
    /// List the commands.
    Help,
}

/// Why a line was rejected.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ParseError {
    /// Blank line.
    Empty,
    /// Longer than [`MAX_LINE`] bytes.
    TooLong,
    /// A byte outside printable ASCII.
    NotAscii,
    /// Unknown command word.
    UnknownCommand,
    /// The command needs an argument.
    MissingArgument,
    /// More words than the command takes.
    UnexpectedArgument,
    /// The argument is not a decimal number (at most 5 integer and 3 fraction digits).
    BadNumber,
    /// The number is outside the accepted range.
    OutOfRange,
    /// Expected `on` or `off`.
    BadSwitch,
    /// Not a setting name (see `get`).
    UnknownSetting,
    /// Expected `low-voltage` or nothing.
    BadProfile,
}

impl ParseError {
    /// Short text for the error reply.
    pub fn as_str(self) -> &'static str {
        match self {
            ParseError::Empty => "empty line",
            ParseError::TooLong => "line too long",
            ParseError::NotAscii => "non-ASCII byte",
            ParseError::UnknownCommand => "unknown command (try help)",
            ParseError::MissingArgument => "missing argument",
            ParseError::UnexpectedArgument => "unexpected argument",
            ParseError::BadNumber => "bad number",
            ParseError::OutOfRange => "out of range",
            ParseError::BadSwitch => "expected on or off",
            ParseError::UnknownSetting => "unknown setting (get lists them)",
            ParseError::BadProfile => "expected defaults or defaults low-voltage",
        }
    }
}

/// Parses one line (without its terminator).
pub fn parse(line: &[u8]) -> Result<Command, ParseError> {
    if line.len() > MAX_LINE {
        return Err(ParseError::TooLong);
    }
    if line
        .iter()
        .any(|&b| !(b == b'\t' || (0x20..0x7f).contains(&b)))
    {
        return Err(ParseError::NotAscii);
    }
    let mut words = line
        .split(|&b| b == b' ' || b == b'\t')
        .filter(|w| !w.is_empty());
    let cmd = words.next().ok_or(ParseError::Empty)?;
    if cmd == b"commission" {
        return commission(words);
    }
    let arg = words.next();
    let arg2 = words.next();
    if words.next().is_some() || (arg2.is_some() && cmd != b"set") {
        return Err(ParseError::UnexpectedArgument);
    }
    let no_arg = |c: Command| match arg {
        None => Ok(c),
        Some(_) => Err(ParseError::UnexpectedArgument),
    };
    let setting = |a: &[u8]| field_index(a).ok_or(ParseError::UnknownSetting);
    match cmd {
        b"start" => no_arg(Command::Start),
        b"vf" => no_arg(Command::StartOpenLoop),
        b"stop" => no_arg(Command::Stop),
        b"reset" => no_arg(Command::ResetFault),
        b"params" => no_arg(Command::Params),
        b"status" => no_arg(Command::Status),
        b"help" => no_arg(Command::Help),
        b"save" => no_arg(Command::Save),
        b"set" => {
            let i = setting(arg.ok_or(ParseError::MissingArgument)?)?;
            let v = parse_value(arg2.ok_or(ParseError::MissingArgument)?)
                .ok_or(ParseError::BadNumber)?;
            Ok(Command::Set(i, v))
        }
        b"get" => match arg {
            None => Ok(Command::Get(None)),
            Some(a) => Ok(Command::Get(Some(setting(a)?))),
        },
        b"defaults" => match arg {
            None => Ok(Command::Defaults(false)),
            Some(b"low-voltage") => Ok(Command::Defaults(true)),
            Some(_) => Err(ParseError::BadProfile),
        },
        b"speed" => {
            let a = arg.ok_or(ParseError::MissingArgument)?;
            let rpm = parse_decimal(a).ok_or(ParseError::BadNumber)?;
            if rpm.abs() > MAX_SPEED_COMMAND_RPM {
                return Err(ParseError::OutOfRange);
            }
            Ok(Command::Speed(rpm))
        }
        b"load" => {
            let a = arg.ok_or(ParseError::MissingArgument)?;
            let nm = parse_decimal(a).ok_or(ParseError::BadNumber)?;
            if nm.abs() > MAX_LOAD_COMMAND_NM {
                return Err(ParseError::OutOfRange);
            }
            Ok(Command::Load(nm))
        }
        b"stream" => match arg.ok_or(ParseError::MissingArgument)? {
            b"on" => Ok(Command::Stream(true)),
            b"off" => Ok(Command::Stream(false)),
            _ => Err(ParseError::BadSwitch),
        },
        _ => Err(ParseError::UnknownCommand),
    }
}

/// `commission` and its five positive nameplate numbers, or none, or `apply`.
fn commission<'a>(mut words: impl Iterator<Item = &'a [u8]>) -> Result<Command, ParseError> {
    let Some(first) = words.next() else {
        return Ok(Command::Commission(None));
    };
    if first == b"apply" {
        return match words.next() {
            None => Ok(Command::CommissionApply),
            Some(_) => Err(ParseError::UnexpectedArgument),
        };
    }
    let mut args = [0.0f32; 5];
    let mut word = Some(first);
    for a in args.iter_mut() {
        let w = word.ok_or(ParseError::MissingArgument)?;
        *a = parse_decimal(w).ok_or(ParseError::BadNumber)?;
        if *a <= 0.0 {
            return Err(ParseError::OutOfRange);
        }
        word = words.next();
    }
    if word.is_some() {
        return Err(ParseError::UnexpectedArgument);
    }
    Ok(Command::Commission(Some(args)))
}

/// A bounded decimal: optional sign, 1 to 5 integer digits, optionally `.` and 1 to 3
/// fraction digits. No exponent, no `inf`/`nan`.
pub fn parse_decimal(s: &[u8]) -> Option<f32> {
    let (neg, rest) = match s.split_first() {
        Some((b'-', r)) => (true, r),
        Some((b'+', r)) => (false, r),
        Some(_) => (false, s),
        None => return None,
    };
    let (int, frac) = match rest.iter().position(|&b| b == b'.') {
        Some(p) => (&rest[..p], Some(&rest[p + 1..])),
        None => (rest, None),
    };
    if int.is_empty() || int.len() > 5 {
        return None;
    }
    let mut whole: u32 = 0;
    for &d in int {
        if !d.is_ascii_digit() {
            return None;
        }
        whole = whole * 10 + (d - b'0') as u32;
    }
    let mut milli: u32 = 0;
    if let Some(f) = frac {
        if f.is_empty() || f.len() > 3 {
            return None;
        }
        let mut scale = 100;
        for &d in f {
            if !d.is_ascii_digit() {
                return None;
            }
            milli += (d - b'0') as u32 * scale;
            scale /= 10;
        }
    }
    // integer part and thousandths separately: whole numbers stay exact
    let v = whole as f32 + milli as f32 / 1000.0;
    Some(if neg { -v } else { v })
}

/// Collects bytes into lines (terminated by `\r` or `\n`) in a fixed buffer. An oversized
/// line is discarded up to its terminator and reported once as [`ParseError::TooLong`].
#[derive(Clone, Debug, Default)]
pub struct LineAssembler {
    buf: Vec<u8, MAX_LINE>,
    overflow: bool,
}

impl LineAssembler {
    /// An empty assembler.
    pub const fn new() -> Self {
        Self {
            buf: Vec::new(),
            overflow: false,
        }
    }

    /// Feeds one byte; returns the parse result when it completes a non-empty line
    /// (blank lines, e.g. the `\n` of a `\r\n` pair, return `None`).
    pub fn push(&mut self, byte: u8) -> Option<Result<Command, ParseError>> {
        if byte == b'\r' || byte == b'\n' {
            let overflow = core::mem::replace(&mut self.overflow, false);
            let result = if overflow {
                Some(Err(ParseError::TooLong))
            } else {
                match parse(&self.buf) {
                    Err(ParseError::Empty) => None,
                    r => Some(r),
                }
            };
            self.buf.clear();
            return result;
        }
        if !self.overflow && self.buf.push(byte).is_err() {
            self.overflow = true;
            self.buf.clear();
        }
        None
    }

    /// Drops a partial line (e.g. after a UART overrun).
    pub fn reset(&mut self) {
        self.buf.clear();
        self.overflow = false;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn feed(a: &mut LineAssembler, s: &[u8]) -> heapless::Vec<Result<Command, ParseError>, 8> {
        let mut out = heapless::Vec::new();
        for &b in s {
            if let Some(r) = a.push(b) {
                out.push(r).unwrap();
            }
        }
        out
    }

    #[test]
    fn load_command_is_bounded() {
        assert_eq!(parse(b"load 1.5"), Ok(Command::Load(1.5)));
        assert_eq!(parse(b"load -2"), Ok(Command::Load(-2.0)));
        assert_eq!(parse(b"load 20.001"), Err(ParseError::OutOfRange));
        assert_eq!(parse(b"load"), Err(ParseError::MissingArgument));
        assert_eq!(parse(b"load x"), Err(ParseError::BadNumber));
    }

    #[test]
    fn valid_commands() {
        assert_eq!(parse(b"start"), Ok(Command::Start));
        assert_eq!(parse(b"  stop  "), Ok(Command::Stop));
        assert_eq!(parse(b"vf"), Ok(Command::StartOpenLoop));
        assert_eq!(parse(b"reset"), Ok(Command::ResetFault));
        assert_eq!(parse(b"params"), Ok(Command::Params));
        assert_eq!(parse(b"status"), Ok(Command::Status));
        assert_eq!(parse(b"help"), Ok(Command::Help));
        assert_eq!(parse(b"speed 500"), Ok(Command::Speed(500.0)));
        assert_eq!(parse(b"speed\t-120.5"), Ok(Command::Speed(-120.5)));
        assert_eq!(parse(b"speed +0.125"), Ok(Command::Speed(0.125)));
        assert_eq!(parse(b"speed 1800"), Ok(Command::Speed(1800.0)));
        assert_eq!(parse(b"stream on"), Ok(Command::Stream(true)));
        assert_eq!(parse(b"stream off"), Ok(Command::Stream(false)));
    }

    #[test]
    fn settings_commands() {
        use crate::settings::FIELDS;
        let lim = FIELDS
            .iter()
            .position(|f| f.name == "limits.current_limit")
            .unwrap();
        assert_eq!(
            parse(b"set limits.current_limit 2.5"),
            Ok(Command::Set(lim, 2.5))
        );
        assert_eq!(
            parse(b"set machine.stator_inductance 0.4476"),
            Ok(Command::Set(8, 0.4476))
        );
        assert_eq!(parse(b"get"), Ok(Command::Get(None)));
        assert_eq!(
            parse(b"get limits.current_limit"),
            Ok(Command::Get(Some(lim)))
        );
        assert_eq!(parse(b"save"), Ok(Command::Save));
        assert_eq!(parse(b"defaults"), Ok(Command::Defaults(false)));
        assert_eq!(parse(b"defaults low-voltage"), Ok(Command::Defaults(true)));
        use ParseError::*;
        let cases: &[(&[u8], ParseError)] = &[
            (b"set", MissingArgument),
            (b"set limits.current_limit", MissingArgument),
            (b"set currentlimit 2", UnknownSetting),
            (b"set limits.current_limit x", BadNumber),
            (b"set limits.current_limit 1e3", BadNumber),
            (b"set limits.current_limit 2 3", UnexpectedArgument),
            (b"get bogus", UnknownSetting),
            (b"save now", UnexpectedArgument),
            (b"defaults mains", BadProfile),
            (b"speed 1 2", UnexpectedArgument),
        ];
        for (line, err) in cases {
            assert_eq!(parse(line), Err(*err), "{:?}", core::str::from_utf8(line));
        }
        // every setting name fits a line with a long value
        for f in FIELDS {
            let mut line: heapless::Vec<u8, 64> = heapless::Vec::new();
            line.extend_from_slice(b"set ").unwrap();
            line.extend_from_slice(f.name.as_bytes()).unwrap();
            line.extend_from_slice(b" -123456.123").unwrap();
            assert!(line.len() <= MAX_LINE, "{}", f.name);
            assert!(matches!(parse(&line), Ok(Command::Set(..))), "{}", f.name);
        }
    }

    #[test]
    fn malformed_commands() {
        use ParseError::*;
        let cases: &[(&[u8], ParseError)] = &[
            (b"", Empty),
            (b"   ", Empty),
            (b"go", UnknownCommand),
            (b"START", UnknownCommand),
            (b"start now", UnexpectedArgument),
            (b"speed", MissingArgument),
            (b"speed 1 2", UnexpectedArgument),
            (b"speed fast", BadNumber),
            (b"speed 1e3", BadNumber),
            (b"speed nan", BadNumber),
            (b"speed inf", BadNumber),
            (b"speed -", BadNumber),
            (b"speed .5", BadNumber),
            (b"speed 5.", BadNumber),
            (b"speed 1.2345", BadNumber),
            (b"speed 123456", BadNumber),
            (b"speed 1.2.3", BadNumber),
            (b"speed --5", BadNumber),
            (b"speed 1801", OutOfRange),
            (b"speed -99999.999", OutOfRange),
            (b"stream", MissingArgument),
            (b"stream maybe", BadSwitch),
            (b"sta\xffrt", NotAscii),
            (b"stop\x00", NotAscii),
        ];
        for (line, err) in cases {
            assert_eq!(parse(line), Err(*err), "{:?}", core::str::from_utf8(line));
        }
    }

    #[test]
    fn oversized_line_rejected() {
        let long = [b'a'; MAX_LINE + 1];
        assert_eq!(parse(&long), Err(ParseError::TooLong));
        let mut a = LineAssembler::new();
        let mut input = [b'x'; 100];
        input[99] = b'\n';
        let r = feed(&mut a, &input);
        assert_eq!(r.as_slice(), &[Err(ParseError::TooLong)]);
        // the assembler recovers: the next line parses normally
        assert_eq!(feed(&mut a, b"start\r\n").as_slice(), &[Ok(Command::Start)]);
        // a line of exactly MAX_LINE bytes is accepted by the assembler
        let mut exact = [b' '; MAX_LINE + 1];
        exact[..4].copy_from_slice(b"stop");
        exact[MAX_LINE] = b'\n';
        assert_eq!(feed(&mut a, &exact).as_slice(), &[Ok(Command::Stop)]);
    }

    #[test]
    fn assembler_lines() {
        let mut a = LineAssembler::new();
        let r = feed(&mut a, b"speed 300\r\n\r\nbogus\nstop\n");
        assert_eq!(
            r.as_slice(),
            &[
                Ok(Command::Speed(300.0)),
                Err(ParseError::UnknownCommand),
                Ok(Command::Stop)
            ]
        );
        feed(&mut a, b"spe");
        a.reset();
        assert_eq!(
            feed(&mut a, b"ed 1\n").as_slice(),
            &[Err(ParseError::UnknownCommand)]
        );
    }

    #[test]
    fn commission_takes_five_positive_numbers_or_none() {
        assert_eq!(parse(b"commission"), Ok(Command::Commission(None)));
        assert_eq!(
            parse(b"commission 750 230 3.3 50 1500"),
            Ok(Command::Commission(Some([750.0, 230.0, 3.3, 50.0, 1500.0])))
        );
        assert_eq!(
            parse(b"commission 750 230 3.3 50"),
            Err(ParseError::MissingArgument)
        );
        assert_eq!(
            parse(b"commission 750 230 3.3 50 1500 2"),
            Err(ParseError::UnexpectedArgument)
        );
        assert_eq!(
            parse(b"commission 750 230 -3.3 50 1500"),
            Err(ParseError::OutOfRange)
        );
        assert_eq!(
            parse(b"commission 750 230 x 50 1500"),
            Err(ParseError::BadNumber)
        );
        assert_eq!(
            parse(b"commission 750 230 3.3 0 1500"),
            Err(ParseError::OutOfRange)
        );
    }

    #[test]
    fn commission_apply_takes_nothing_more() {
        assert_eq!(parse(b"commission apply"), Ok(Command::CommissionApply));
        assert_eq!(parse(b" commission\tapply  "), Ok(Command::CommissionApply));
        assert_eq!(
            parse(b"commission apply now"),
            Err(ParseError::UnexpectedArgument)
        );
        assert_eq!(
            parse(b"commission apply 750"),
            Err(ParseError::UnexpectedArgument)
        );
        // only the whole word, in lower case, and only first
        assert_eq!(parse(b"commission Apply"), Err(ParseError::BadNumber));
        assert_eq!(parse(b"commission applied"), Err(ParseError::BadNumber));
        assert_eq!(parse(b"commission 750 apply"), Err(ParseError::BadNumber));
        assert_eq!(parse(b"apply"), Err(ParseError::UnknownCommand));
        // framed and plain alike (the protocol's parser routes it here)
        assert_eq!(
            crate::protocol::parse_plain(b"commission apply"),
            Ok(crate::protocol::Request::Command(Command::CommissionApply))
        );
    }

    #[test]
    fn arbitrary_bytes_never_panic() {
        // a cheap deterministic fuzz over all byte values and lengths
        let mut a = LineAssembler::new();
        let mut x: u32 = 1;
        for _ in 0..20_000 {
            x ^= x << 13;
            x ^= x >> 17;
            x ^= x << 5;
            let _ = a.push((x >> 24) as u8);
        }
        for n in 0..=MAX_LINE + 2 {
            let mut line = [0u8; MAX_LINE + 2];
            for (i, b) in line.iter_mut().enumerate().take(n) {
                *b = b"speed -1.5 9"[i % 12];
            }
            let _ = parse(&line[..n]);
        }
    }
}
