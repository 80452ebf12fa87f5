//! Protocol version 1 of the command and telemetry link (docs/protocol.md is the
//! reference; this module is its code, shared by the virtual board and the host tools).
//!
//! Every line is ASCII and ends with `\r\n` (a lone `\r` or `\n` also ends a line). Two
//! forms of request exist side by side:
//!
//! - a **plain** command line, e.g. `speed 500` ([`crate::command`]), answered with plain
//!   lines (`ok ...`, `err ...`): what a person types in a serial terminal;
//! - a **framed** command, `$C,<command line>*HHHH`, answered with framed lines,
//!   `$R,<text>*HHHH` (a reply line; the last one starts with `ok`) or `$E,<text>*HHHH`
//!   (the error: the command changed nothing): what a host tool sends, so that a
//!   corrupted byte in either direction is detected instead of acted on.
//!
//! `HHHH` is the CRC-16/CCITT-FALSE ([`crc16`]) of every byte between `$` and `*`, as in
//! the telemetry frame ([`crate::telemetry`]). A framed line whose CRC does not match is
//! answered `$E,bad frame: checksum*HHHH` and is not executed.
//!
//! Protocol version 1 adds, to the firmware's command set, `version` (the reply names the
//! protocol version and the board) and `rate <periods>` (telemetry every that many control
//! periods); a source announces itself with the hello frame `$V,<version>,<pwm Hz>,<board
//! name>*HHHH` when a host connects.

use crate::command::{parse as parse_command, parse_decimal, Command, ParseError};
use crate::telemetry::crc16;
use heapless::Vec;

/// This protocol's version, in the hello frame and the `version` reply.
pub const PROTOCOL_VERSION: u16 = 1;

/// Bytes a framed command adds to its command line (`$C,` and `*HHHH`).
pub const FRAME_OVERHEAD: usize = 8;

/// Longest framed line accepted, bytes (without the terminator).
pub const MAX_FRAMED_LINE: usize = crate::command::MAX_LINE + FRAME_OVERHEAD;

/// Fewest control periods between two telemetry samples (`rate`): 2.5 kHz at 5 kHz.
pub const MIN_RATE_PERIODS: u16 = 2;

/// Most control periods between two telemetry samples (`rate`): 10 s at 5 kHz.
pub const MAX_RATE_PERIODS: u16 = 50_000;

/// The upper-case hex digits of the CRC.
const HEX: &[u8; 16] = b"0123456789ABCDEF";

/// A framed line's capacity, bytes.
pub const LINE_CAPACITY: usize = 256;

/// An encoded line.
pub type Line = Vec<u8, LINE_CAPACITY>;

/// `$<kind>,<payload>*HHHH\r\n`. A payload longer than the line's capacity is cut at
/// `LINE_CAPACITY - 10` bytes (the CRC covers what is sent).
pub fn frame(kind: u8, payload: &[u8]) -> Line {
    let mut out = Line::new();
    let _ = out.push(b'$');
    let _ = out.push(kind);
    let _ = out.push(b',');
    let room = LINE_CAPACITY - 10;
    let _ = out.extend_from_slice(&payload[..payload.len().min(room)]);
    let cs = crc16(&out[1..]);
    let _ = out.push(b'*');
    for shift in [12, 8, 4, 0] {
        let _ = out.push(HEX[((cs >> shift) & 15) as usize]);
    }
    let _ = out.extend_from_slice(b"\r\n");
    out
}

/// Why a framed line was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FrameError {
    /// No `$`, kind letter, `,`, `*` or four hex digits where they belong.
    Syntax,
    /// The CRC does not match the bytes received.
    Checksum,
    /// Not a command frame (`$C`).
    NotACommand,
}

impl FrameError {
    /// Short text for the error reply.
    pub fn as_str(self) -> &'static str {
        match self {
            FrameError::Syntax => "bad frame: expected $C,<command>*HHHH",
            FrameError::Checksum => "bad frame: checksum",
            FrameError::NotACommand => "bad frame: hosts send $C frames only",
        }
    }
}

fn hex_val(b: u8) -> Option<u16> {
    HEX.iter().position(|&h| h == b).map(|p| p as u16)
}

/// Splits a framed line (with or without its line end) into its kind letter and payload,
/// after checking the CRC. `$T` telemetry frames have no `,` after the kind in version 0
/// either, so every kind is followed by `,`.
pub fn unframe(line: &[u8]) -> Result<(u8, &[u8]), FrameError> {
    let line = line.strip_suffix(b"\r\n").unwrap_or(line);
    let body = line.strip_prefix(b"$").ok_or(FrameError::Syntax)?;
    let star = body
        .iter()
        .rposition(|&b| b == b'*')
        .ok_or(FrameError::Syntax)?;
    let (content, cs) = (&body[..star], &body[star + 1..]);
    if cs.len() != 4 || content.len() < 2 || content[1] != b',' {
        return Err(FrameError::Syntax);
    }
    let mut want: u16 = 0;
    for &c in cs {
        want = want << 4 | hex_val(c).ok_or(FrameError::Syntax)?;
    }
    if crc16(content) != want {
        return Err(FrameError::Checksum);
    }
    Ok((content[0], &content[2..]))
}

/// A request of protocol version 1.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Request {
    /// One of the firmware's commands ([`crate::command`]).
    Command(Command),
    /// `version`: reply with the protocol version and the board.
    Version,
    /// `rate <periods>`: telemetry every that many control periods.
    Rate(u16),
}

/// Why a request was refused (nothing was executed).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RequestError {
    /// The frame around it.
    Frame(FrameError),
    /// The command line inside it.
    Parse(ParseError),
}

impl RequestError {
    /// Short text for the error reply.
    pub fn as_str(self) -> &'static str {
        match self {
            RequestError::Frame(e) => e.as_str(),
            RequestError::Parse(e) => e.as_str(),
        }
    }
}

/// A parsed line: whether it came framed (the reply must be framed too) and what it asks.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Parsed {
    /// The line was a `$C` frame.
    pub framed: bool,
    /// The request, or why it was refused.
    pub request: Result<Request, RequestError>,
}

/// Parses one plain command line, with the version-1 words `version` and `rate`.
pub fn parse_plain(line: &[u8]) -> Result<Request, ParseError> {
    if line.len() > crate::command::MAX_LINE {
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
    match words.next() {
        Some(b"version") => match words.next() {
            None => Ok(Request::Version),
            Some(_) => Err(ParseError::UnexpectedArgument),
        },
        Some(b"rate") => {
            let a = words.next().ok_or(ParseError::MissingArgument)?;
            if words.next().is_some() {
                return Err(ParseError::UnexpectedArgument);
            }
            let v = parse_decimal(a).ok_or(ParseError::BadNumber)?;
            if !(MIN_RATE_PERIODS as f32..=MAX_RATE_PERIODS as f32).contains(&v) {
                return Err(ParseError::OutOfRange);
            }
            if v != (v as u32) as f32 {
                return Err(ParseError::BadNumber);
            }
            Ok(Request::Rate(v as u16))
        }
        _ => parse_command(line).map(Request::Command),
    }
}

/// Parses one line, plain or framed (without its terminator).
pub fn parse_line(line: &[u8]) -> Parsed {
    if line.first() != Some(&b'$') {
        return Parsed {
            framed: false,
            request: parse_plain(line).map_err(RequestError::Parse),
        };
    }
    let request = if line.len() > MAX_FRAMED_LINE {
        Err(RequestError::Parse(ParseError::TooLong))
    } else {
        match unframe(line) {
            Err(e) => Err(RequestError::Frame(e)),
            Ok((b'C', inner)) => parse_plain(inner).map_err(RequestError::Parse),
            Ok(_) => Err(RequestError::Frame(FrameError::NotACommand)),
        }
    };
    Parsed {
        framed: true,
        request,
    }
}

/// Collects received bytes into lines (terminated by `\r` or `\n`) and parses each,
/// plain or framed, in a fixed buffer: the firmware's receive path. An oversized line is
/// discarded up to its terminator and reported once as [`ParseError::TooLong`] (framed if
/// it started with `$`).
#[derive(Clone, Debug, Default)]
pub struct RequestAssembler {
    buf: Vec<u8, MAX_FRAMED_LINE>,
    overflow: bool,
    dollar: bool,
}

impl RequestAssembler {
    /// An empty assembler.
    pub const fn new() -> Self {
        Self {
            buf: Vec::new(),
            overflow: false,
            dollar: false,
        }
    }

    /// Feeds one byte; returns the parsed line when it completes a non-empty one.
    pub fn push(&mut self, byte: u8) -> Option<Parsed> {
        if byte == b'\r' || byte == b'\n' {
            let overflow = core::mem::replace(&mut self.overflow, false);
            let dollar = core::mem::replace(&mut self.dollar, false);
            let result = if overflow {
                Some(Parsed {
                    framed: dollar,
                    request: Err(RequestError::Parse(ParseError::TooLong)),
                })
            } else {
                match parse_line(&self.buf) {
                    Parsed {
                        request: Err(RequestError::Parse(ParseError::Empty)),
                        ..
                    } => None,
                    p => Some(p),
                }
            };
            self.buf.clear();
            return result;
        }
        if self.buf.is_empty() && !self.overflow {
            self.dollar = byte == b'$';
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
        self.dollar = false;
    }
}

/// The frame a host sends for `command` (e.g. `$C,speed 500*HHHH\r\n`).
pub fn command_frame(command: &str) -> Line {
    frame(b'C', command.as_bytes())
}

/// The reply line to a framed request: `$E` for a line starting with `err`, `$R` else.
/// `text` is one reply line without its line end.
pub fn reply_frame(text: &[u8]) -> Line {
    let kind = if text.starts_with(b"err") { b'E' } else { b'R' };
    frame(kind, text)
}

/// The four upper-case hex digits of a CRC.
pub const fn crc_hex(crc: u16) -> [u8; 4] {
    [
        HEX[(crc >> 12) as usize & 15],
        HEX[(crc >> 8) as usize & 15],
        HEX[(crc >> 4) as usize & 15],
        HEX[crc as usize & 15],
    ]
}

/// The firmware's hello frame, built at compile time (the same bytes as
/// [`hello_frame`]`(5000, "acim-firmware")`).
pub const FIRMWARE_HELLO: [u8; 30] = {
    const BODY: &[u8; 22] = b"V,1,5000,acim-firmware";
    let h = crc_hex(crc16(BODY));
    let mut out = [0u8; 30];
    out[0] = b'$';
    let mut i = 0;
    while i < BODY.len() {
        out[1 + i] = BODY[i];
        i += 1;
    }
    out[23] = b'*';
    out[24] = h[0];
    out[25] = h[1];
    out[26] = h[2];
    out[27] = h[3];
    out[28] = b'\r';
    out[29] = b'\n';
    out
};

/// The hello frame: `$V,<version>,<pwm Hz>,<board>*HHHH\r\n`.
pub fn hello_frame(pwm_hz: u32, board: &str) -> Line {
    let mut p: Vec<u8, 96> = Vec::new();
    push_u32(&mut p, PROTOCOL_VERSION as u32);
    let _ = p.push(b',');
    push_u32(&mut p, pwm_hz);
    let _ = p.push(b',');
    let _ = p.extend_from_slice(&board.as_bytes()[..board.len().min(64)]);
    frame(b'V', &p)
}

fn push_u32<const N: usize>(out: &mut Vec<u8, N>, mut n: u32) {
    let mut d = [0u8; 10];
    let mut len = 0;
    loop {
        d[len] = b'0' + (n % 10) as u8;
        len += 1;
        n /= 10;
        if n == 0 {
            break;
        }
    }
    for &b in d[..len].iter().rev() {
        let _ = out.push(b);
    }
}

/// The version-1 telemetry extension, sent right after each `$T` frame:
/// `$X,seq,period,i_d_ref,i_q_ref*HHHH` (the `$T` frame's `seq`; the control period
/// counter at the sample, which gives the time axis whatever the rate; the d/q current
/// references in mA). The `$T` frame itself is unchanged from version 0.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Extension {
    /// The `seq` of the `$T` frame it extends.
    pub seq: u32,
    /// Control periods since power-up (wraps).
    pub period: u32,
    /// d-axis current reference, A.
    pub i_d_ref: f32,
    /// q-axis current reference, A.
    pub i_q_ref: f32,
}

impl Extension {
    /// The extension of a sample (its `seq`, `period` and current references).
    pub fn of(s: &crate::telemetry::TelemetrySample) -> Self {
        Self {
            seq: s.seq,
            period: s.period,
            i_d_ref: s.i_d_ref,
            i_q_ref: s.i_q_ref,
        }
    }
}

fn milli(x: f32) -> i32 {
    let v = x * 1e3;
    // `as` saturates (NaN -> 0)
    (if v >= 0.0 { v + 0.5 } else { v - 0.5 }) as i32
}

fn push_i32<const N: usize>(out: &mut Vec<u8, N>, v: i32) {
    if v < 0 {
        let _ = out.push(b'-');
    }
    push_u32(out, v.unsigned_abs());
}

/// Encodes the extension frame.
pub fn encode_extension(e: &Extension) -> Line {
    let mut p: Vec<u8, 64> = Vec::new();
    push_u32(&mut p, e.seq);
    let _ = p.push(b',');
    push_u32(&mut p, e.period);
    let _ = p.push(b',');
    push_i32(&mut p, milli(e.i_d_ref));
    let _ = p.push(b',');
    push_i32(&mut p, milli(e.i_q_ref));
    frame(b'X', &p)
}

/// Decodes an extension frame (with or without its line end).
pub fn decode_extension(line: &[u8]) -> Result<Extension, crate::telemetry::FrameError> {
    use crate::telemetry::FrameError as F;
    let (kind, payload) = unframe(line).map_err(|e| match e {
        FrameError::Checksum => F::Checksum,
        _ => F::Syntax,
    })?;
    if kind != b'X' {
        return Err(F::Syntax);
    }
    let mut v = [0i64; 4];
    let mut parts = payload.split(|&b| b == b',');
    for slot in v.iter_mut() {
        let f = parts.next().ok_or(F::Field)?;
        let (neg, d) = match f.split_first() {
            Some((b'-', r)) => (true, r),
            _ => (false, f),
        };
        if d.is_empty() || d.len() > 10 || !d.iter().all(u8::is_ascii_digit) {
            return Err(F::Field);
        }
        let n = d.iter().fold(0i64, |a, &c| a * 10 + (c - b'0') as i64);
        *slot = if neg { -n } else { n };
    }
    if parts.next().is_some() {
        return Err(F::Field);
    }
    let u = |x: i64| u32::try_from(x).map_err(|_| F::Field);
    let i = |x: i64| {
        i32::try_from(x)
            .map(|x| x as f32 / 1e3)
            .map_err(|_| F::Field)
    };
    Ok(Extension {
        seq: u(v[0])?,
        period: u(v[1])?,
        i_d_ref: i(v[2])?,
        i_q_ref: i(v[3])?,
    })
}

/// The drive state's name for a telemetry state code.
pub fn state_name(code: u8) -> &'static str {
    match code {
        0 => "Idle",
        1 => "Magnetizing",
        2 => "Running",
        3 => "OpenLoop",
        4 => "Fault",
        5 => "Commissioning",
        _ => "?",
    }
}

/// The fault's name for a telemetry fault code ([`crate::control::FaultCode`]).
pub fn fault_name(code: u8) -> &'static str {
    match code {
        0 => "none",
        1 => "OverCurrent",
        2 => "DcBusOverVoltage",
        3 => "DcBusUnderVoltage",
        4 => "OverSpeed",
        5 => "NonFiniteInput",
        6 => "EstimatorOutOfRange",
        7 => "Stall",
        8 => "HardwareBreak",
        9 => "DeadlineMissed",
        10 => "CurrentRegulation",
        11 => "LossOfControl",
        12 => "CurrentSensor",
        13 => "MagnetizingTimeout",
        14 => "NoCurrentResponse",
        15 => "Overload",
        16 => "HardwareBreak (break input)",
        17 => "DeadlineMissed (interrupt)",
        18 => "AdcSaturated",
        19 => "AdcSequence",
        20 => "SpeedOscillation",
        _ => "?",
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::control::FaultCode;
    use acim::FaultReason;

    #[test]
    fn framed_command_round_trip() {
        let f = command_frame("speed 500");
        assert!(f.starts_with(b"$C,speed 500*"));
        assert!(f.ends_with(b"\r\n"));
        let p = parse_line(&f[..f.len() - 2]);
        assert!(p.framed);
        assert_eq!(
            p.request,
            Ok(Request::Command(Command::Speed(500.0))),
            "{:?}",
            core::str::from_utf8(&f)
        );
    }

    #[test]
    fn every_single_byte_error_in_a_frame_is_refused() {
        let f = command_frame("speed 1500");
        let line = &f[..f.len() - 2];
        for i in 1..line.len() {
            for flip in [0x01u8, 0x02, 0x10, 0x20] {
                let mut g: Line = Line::new();
                g.extend_from_slice(line).unwrap();
                g[i] ^= flip;
                let p = parse_line(&g);
                assert!(p.framed);
                assert_ne!(
                    p.request,
                    Ok(Request::Command(Command::Speed(1500.0))),
                    "byte {i} ^ {flip:#x} accepted"
                );
            }
        }
        assert_eq!(
            parse_line(b"$C,start*0000").request,
            Err(RequestError::Frame(FrameError::Checksum))
        );
        assert_eq!(
            parse_line(b"$C,start").request,
            Err(RequestError::Frame(FrameError::Syntax))
        );
        let t = frame(b'T', b"1,2");
        assert_eq!(
            parse_line(&t[..t.len() - 2]).request,
            Err(RequestError::Frame(FrameError::NotACommand))
        );
    }

    #[test]
    fn the_assembler_parses_plain_and_framed_lines() {
        let mut a = RequestAssembler::new();
        let mut got = heapless::Vec::<Parsed, 8>::new();
        let f = command_frame("speed -1.5");
        for &b in b"start\r\n\r\n".iter().chain(f.iter()).chain(b"bogus\n") {
            if let Some(p) = a.push(b) {
                got.push(p).unwrap();
            }
        }
        assert_eq!(got.len(), 3);
        assert_eq!(got[0].request, Ok(Request::Command(Command::Start)));
        assert!(!got[0].framed);
        assert_eq!(got[1].request, Ok(Request::Command(Command::Speed(-1.5))));
        assert!(got[1].framed);
        assert_eq!(
            got[2].request,
            Err(RequestError::Parse(ParseError::UnknownCommand))
        );
        // oversized: one error, framed if it started with `$`, then the next line parses
        for &b in [b'$'; 100].iter() {
            assert_eq!(a.push(b), None);
        }
        let p = a.push(b'\n').unwrap();
        assert!(p.framed);
        assert_eq!(p.request, Err(RequestError::Parse(ParseError::TooLong)));
        for &b in b"stop" {
            a.push(b);
        }
        assert_eq!(
            a.push(b'\r').map(|p| p.request),
            Some(Ok(Request::Command(Command::Stop)))
        );
        // every setting line fits framed
        let long = command_frame("set machine.stator_inductance -123456.123");
        assert!(long.len() - 2 <= MAX_FRAMED_LINE);
    }

    #[test]
    fn version_and_rate() {
        assert_eq!(parse_plain(b"version"), Ok(Request::Version));
        assert_eq!(parse_plain(b"rate 50"), Ok(Request::Rate(50)));
        assert_eq!(parse_plain(b"rate 1"), Err(ParseError::OutOfRange));
        assert_eq!(parse_plain(b"rate 50001"), Err(ParseError::OutOfRange));
        assert_eq!(parse_plain(b"rate 5.5"), Err(ParseError::BadNumber));
        assert_eq!(parse_plain(b"rate -5"), Err(ParseError::OutOfRange));
        assert_eq!(parse_plain(b"rate"), Err(ParseError::MissingArgument));
        assert_eq!(
            parse_plain(b"rate 5 5"),
            Err(ParseError::UnexpectedArgument)
        );
        assert_eq!(
            parse_plain(b"version 2"),
            Err(ParseError::UnexpectedArgument)
        );
        assert_eq!(parse_plain(b"bogus"), Err(ParseError::UnknownCommand));
        assert_eq!(parse_plain(b"stop"), Ok(Request::Command(Command::Stop)));
    }

    #[test]
    fn the_firmware_hello_is_the_hello_frame() {
        assert_eq!(
            FIRMWARE_HELLO.as_slice(),
            hello_frame(5000, "acim-firmware").as_slice()
        );
        assert_eq!(crc_hex(0x29B1), *b"29B1");
    }

    #[test]
    fn replies_and_hello() {
        let e = reply_frame(b"err out of range");
        assert_eq!(unframe(&e), Ok((b'E', b"err out of range".as_slice())));
        let r = reply_frame(b"ok");
        assert_eq!(unframe(&r), Ok((b'R', b"ok".as_slice())));
        let h = hello_frame(5000, "acim-vboard");
        assert_eq!(unframe(&h), Ok((b'V', b"1,5000,acim-vboard".as_slice())));
        // a payload too long for a line is cut, and still framed correctly
        let long = [b'a'; 400];
        let f = frame(b'R', &long);
        assert!(f.len() <= LINE_CAPACITY);
        assert!(unframe(&f).is_ok());
    }

    #[test]
    fn extension_round_trip() {
        let e = Extension {
            seq: 7,
            period: 4_000_000_000,
            i_d_ref: 1.234,
            i_q_ref: -0.5,
        };
        let f = encode_extension(&e);
        assert!(f.starts_with(b"$X,7,4000000000,1234,-500*"));
        assert_eq!(decode_extension(&f), Ok(e));
        let mut bad = f.clone();
        bad[4] ^= 1;
        assert!(decode_extension(&bad).is_err());
        assert!(decode_extension(&frame(b'X', b"1,2,3")).is_err());
        assert!(decode_extension(&frame(b'X', b"1,2,3,4,5")).is_err());
        assert!(decode_extension(&frame(b'T', b"1,2,3,4")).is_err());
    }

    #[test]
    fn names_cover_every_code() {
        assert_eq!(state_name(acim::DriveState::Running.code()), "Running");
        assert_eq!(
            fault_name(FaultCode::of(Some(FaultReason::Overload), None)),
            "Overload"
        );
        for c in 0..20 {
            assert_ne!(fault_name(c), "?");
        }
    }
}
