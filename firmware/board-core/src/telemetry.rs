//! The decimated telemetry sample and its text framing.
//!
//! The control interrupt fills a [`TelemetrySample`] every
//! [`crate::board::TELEMETRY_DECIMATION`] periods and pushes it into a lock-free SPSC
//! queue; the main loop logs it with `defmt` over RTT and, when streaming is on, writes it
//! to the UART as one text frame:
//!
//! ```text
//! $T,seq,state,fault,speed_ref,speed_est,i_d,i_q,torque,load,rs,flux,dc_bus,cyc_min,cyc_mean,cyc_max,plant_speed*HHHH\r\n
//! ```
//!
//! Fields are decimal integers in fixed units (speeds 0.1 rpm, currents mA, torques mN m,
//! resistance mohm, flux mWb, bus 0.1 V, cycles of the 170 MHz core clock); `HHHH` is the
//! CRC-16/CCITT-FALSE (polynomial 0x1021, initial value 0xFFFF) of every byte between `$`
//! and `*`, in upper-case hex. A CRC-16 detects every single and double byte error and
//! every transposition of two different bytes, which the former XOR byte did not
//! (68 % of transpositions passed it). [`decode`] is the inverse, for host tools and tests.

/// One decimated sample.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct TelemetrySample {
    /// Sample counter (wraps).
    pub seq: u32,
    /// Drive state code (0 idle, 1 magnetizing, 2 running, 3 open loop, 4 fault).
    pub state: u8,
    /// Fault code, see [`crate::control::FaultCode`] (0 = none).
    pub fault: u8,
    /// Ramped speed reference, rpm.
    pub speed_ref_rpm: f32,
    /// Estimated speed, rpm.
    pub speed_est_rpm: f32,
    /// Measured d-axis current, A.
    pub i_d: f32,
    /// Measured q-axis current, A.
    pub i_q: f32,
    /// Estimated electromagnetic torque, N m.
    pub torque: f32,
    /// Estimated load torque, N m.
    pub load_torque: f32,
    /// Stator-resistance estimate, ohm.
    pub rs: f32,
    /// Model rotor flux, Wb.
    pub flux: f32,
    /// DC-bus voltage, V.
    pub dc_bus: f32,
    /// Fewest core cycles of the control step over the last window.
    pub cycles_min: u32,
    /// Mean core cycles of the control step over the last window.
    pub cycles_mean: u32,
    /// Most core cycles of the control step over the last window.
    pub cycles_max: u32,
    /// Self-test only: the motor model's true speed, rpm (0 on hardware).
    pub plant_speed_rpm: f32,
    /// Control periods since power-up at the sample (wraps). Not in the `$T` frame: the
    /// protocol's `$X` extension carries it ([`crate::protocol::Extension::of`]).
    pub period: u32,
    /// d-axis current reference, A (`$X` only).
    pub i_d_ref: f32,
    /// q-axis current reference, A (`$X` only).
    pub i_q_ref: f32,
}

/// Capacity of an encoded frame, bytes (the longest possible frame is shorter).
pub const FRAME_CAPACITY: usize = 224;

const FIELDS: usize = 16;

/// A frame buffer.
pub type Frame = heapless::Vec<u8, FRAME_CAPACITY>;

fn scaled(x: f32, scale: f32) -> i64 {
    // `as` saturates (NaN -> 0): a non-finite value cannot break the frame
    let v = x * scale;
    (if v >= 0.0 { v + 0.5 } else { v - 0.5 }) as i32 as i64
}

fn fields(s: &TelemetrySample) -> [i64; FIELDS] {
    [
        s.seq as i64,
        s.state as i64,
        s.fault as i64,
        scaled(s.speed_ref_rpm, 10.0),
        scaled(s.speed_est_rpm, 10.0),
        scaled(s.i_d, 1e3),
        scaled(s.i_q, 1e3),
        scaled(s.torque, 1e3),
        scaled(s.load_torque, 1e3),
        scaled(s.rs, 1e3),
        scaled(s.flux, 1e3),
        scaled(s.dc_bus, 10.0),
        s.cycles_min as i64,
        s.cycles_mean as i64,
        s.cycles_max as i64,
        scaled(s.plant_speed_rpm, 10.0),
    ]
}

fn push_int(out: &mut Frame, v: i64) {
    // every field fits i32 or u32: 32-bit arithmetic only (no u64 division routine)
    let neg = v < 0;
    let mut n = v.unsigned_abs().min(u32::MAX as u64) as u32;
    let mut digits = [0u8; 10];
    let mut len = 0;
    loop {
        digits[len] = b'0' + (n % 10) as u8;
        len += 1;
        n /= 10;
        if n == 0 || len == digits.len() {
            break;
        }
    }
    if neg {
        let _ = out.push(b'-');
    }
    for d in digits[..len].iter().rev() {
        let _ = out.push(*d);
    }
}

const HEX: &[u8; 16] = b"0123456789ABCDEF";

/// CRC-16/CCITT-FALSE of `data` (bitwise: 2 of these per 10 Hz frame cost nothing; a
/// `const fn`, so fixed frames such as the protocol's hello are checked at compile time).
pub const fn crc16(data: &[u8]) -> u16 {
    let mut crc: u16 = 0xFFFF;
    let mut i = 0;
    while i < data.len() {
        crc ^= (data[i] as u16) << 8;
        let mut bit = 0;
        while bit < 8 {
            crc = if crc & 0x8000 != 0 {
                (crc << 1) ^ 0x1021
            } else {
                crc << 1
            };
            bit += 1;
        }
        i += 1;
    }
    crc
}

/// Encodes `s` as one text frame (always fits [`FRAME_CAPACITY`]).
pub fn encode(s: &TelemetrySample) -> Frame {
    let mut out = Frame::new();
    let _ = out.extend_from_slice(b"$T");
    for v in fields(s) {
        let _ = out.push(b',');
        push_int(&mut out, v);
    }
    let cs = crc16(&out[1..]);
    let _ = out.push(b'*');
    for shift in [12, 8, 4, 0] {
        let _ = out.push(HEX[((cs >> shift) & 15) as usize]);
    }
    let _ = out.extend_from_slice(b"\r\n");
    out
}

/// Why a frame could not be decoded.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FrameError {
    /// Missing `$T`, `*HHHH` or the line end.
    Syntax,
    /// The checksum does not match.
    Checksum,
    /// Wrong number of fields or a field is not an integer in range.
    Field,
}

fn hex_val(b: u8) -> Option<u8> {
    HEX.iter().position(|&h| h == b).map(|p| p as u8)
}

fn parse_int(f: &[u8]) -> Option<i64> {
    let (neg, d) = match f.split_first()? {
        (b'-', r) => (true, r),
        _ => (false, f),
    };
    if d.is_empty() || d.len() > 18 {
        return None;
    }
    let mut v: i64 = 0;
    for &c in d {
        if !c.is_ascii_digit() {
            return None;
        }
        v = v * 10 + (c - b'0') as i64;
    }
    Some(if neg { -v } else { v })
}

/// Decodes one frame (with or without its `\r\n`); values come back in the frame's
/// resolution.
pub fn decode(frame: &[u8]) -> Result<TelemetrySample, FrameError> {
    let frame = frame.strip_suffix(b"\r\n").unwrap_or(frame);
    let body = frame.strip_prefix(b"$").ok_or(FrameError::Syntax)?;
    let star = body
        .iter()
        .rposition(|&b| b == b'*')
        .ok_or(FrameError::Syntax)?;
    let (payload, cs) = (&body[..star], &body[star + 1..]);
    if cs.len() != 4 {
        return Err(FrameError::Syntax);
    }
    let mut want: u16 = 0;
    for &c in cs {
        want = want << 4 | hex_val(c).ok_or(FrameError::Syntax)? as u16;
    }
    if crc16(payload) != want {
        return Err(FrameError::Checksum);
    }
    let mut parts = payload.split(|&b| b == b',');
    if parts.next() != Some(b"T".as_slice()) {
        return Err(FrameError::Syntax);
    }
    let mut v = [0i64; FIELDS];
    for slot in v.iter_mut() {
        *slot = parts.next().and_then(parse_int).ok_or(FrameError::Field)?;
    }
    if parts.next().is_some() {
        return Err(FrameError::Field);
    }
    let u32_of = |x: i64| u32::try_from(x).map_err(|_| FrameError::Field);
    let u8_of = |x: i64| u8::try_from(x).map_err(|_| FrameError::Field);
    Ok(TelemetrySample {
        seq: u32_of(v[0])?,
        state: u8_of(v[1])?,
        fault: u8_of(v[2])?,
        speed_ref_rpm: v[3] as f32 / 10.0,
        speed_est_rpm: v[4] as f32 / 10.0,
        i_d: v[5] as f32 / 1e3,
        i_q: v[6] as f32 / 1e3,
        torque: v[7] as f32 / 1e3,
        load_torque: v[8] as f32 / 1e3,
        rs: v[9] as f32 / 1e3,
        flux: v[10] as f32 / 1e3,
        dc_bus: v[11] as f32 / 10.0,
        cycles_min: u32_of(v[12])?,
        cycles_mean: u32_of(v[13])?,
        cycles_max: u32_of(v[14])?,
        plant_speed_rpm: v[15] as f32 / 10.0,
        // the `$X` frame's fields (`crate::protocol::decode_extension`)
        period: 0,
        i_d_ref: 0.0,
        i_q_ref: 0.0,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> TelemetrySample {
        TelemetrySample {
            seq: 4_000_000_123,
            state: 2,
            fault: 0,
            speed_ref_rpm: 500.0,
            speed_est_rpm: -498.76,
            i_d: 1.5,
            i_q: -0.234,
            torque: 1.234,
            load_torque: -0.05,
            rs: 10.5,
            flux: 0.781,
            dc_bus: 324.87,
            cycles_min: 2100,
            cycles_mean: 2234,
            cycles_max: 2890,
            plant_speed_rpm: 499.0,
            ..Default::default()
        }
    }

    #[test]
    fn known_frame() {
        let f = encode(&TelemetrySample::default());
        let s = core::str::from_utf8(&f).unwrap();
        let payload = "T,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0";
        let cs = crc16(payload.as_bytes());
        let mut expect: heapless::String<64> = heapless::String::new();
        core::fmt::write(&mut expect, format_args!("${payload}*{cs:04X}\r\n")).unwrap();
        assert_eq!(s, expect.as_str());
    }

    /// The standard check value of CRC-16/CCITT-FALSE.
    #[test]
    fn crc_check_value() {
        assert_eq!(crc16(b"123456789"), 0x29B1);
    }

    /// Every transposition of two different adjacent payload bytes and every single-byte
    /// change is rejected (the former XOR byte passed every transposition).
    #[test]
    fn transpositions_and_byte_errors_are_detected() {
        let f = encode(&sample());
        let star = f.iter().rposition(|&b| b == b'*').unwrap();
        for i in 1..star - 1 {
            if f[i] == f[i + 1] {
                continue;
            }
            let mut g = f.clone();
            g.swap(i, i + 1);
            assert!(decode(&g).is_err(), "transposition at {i} accepted");
        }
        for i in 1..star {
            for flip in [0x01u8, 0x10, 0x0F] {
                let mut g = f.clone();
                g[i] ^= flip;
                assert!(decode(&g).is_err(), "byte {i} ^ {flip:#x} accepted");
            }
        }
    }

    #[test]
    fn round_trip() {
        let s = sample();
        let f = encode(&s);
        assert!(f.ends_with(b"\r\n"));
        let d = decode(&f).unwrap();
        assert_eq!(d.seq, s.seq);
        assert_eq!(d.state, 2);
        assert_eq!(d.cycles_mean, 2234);
        assert!((d.speed_est_rpm + 498.8).abs() < 1e-3);
        assert!((d.i_q + 0.234).abs() < 1e-6);
        assert!((d.dc_bus - 324.9).abs() < 1e-3);
        assert!((d.rs - 10.5).abs() < 1e-6);
    }

    #[test]
    fn worst_case_fits() {
        let s = TelemetrySample {
            seq: u32::MAX,
            state: u8::MAX,
            fault: u8::MAX,
            speed_ref_rpm: -f32::MAX,
            speed_est_rpm: f32::NEG_INFINITY,
            i_d: f32::NAN,
            i_q: -1e30,
            torque: -1e30,
            load_torque: -1e30,
            rs: -1e30,
            flux: -1e30,
            dc_bus: -1e30,
            cycles_min: u32::MAX,
            cycles_mean: u32::MAX,
            cycles_max: u32::MAX,
            plant_speed_rpm: -1e30,
            ..Default::default()
        };
        let f = encode(&s);
        assert!(f.len() < FRAME_CAPACITY);
        assert!(f.ends_with(b"\r\n"));
        let d = decode(&f).unwrap();
        assert_eq!(d.i_d, 0.0, "NaN encodes as 0");
        assert_eq!(d.cycles_max, u32::MAX);
    }

    #[test]
    fn corrupted_frames_rejected() {
        let f = encode(&sample());
        // flip one payload byte: checksum error
        let mut bad = f.clone();
        bad[5] ^= 0x01;
        assert_eq!(decode(&bad), Err(FrameError::Checksum));
        assert_eq!(decode(b"T,1*00"), Err(FrameError::Syntax));
        assert_eq!(decode(b"$T,1"), Err(FrameError::Syntax));
        assert_eq!(decode(b"$T,1*0G"), Err(FrameError::Syntax));
        // right checksum, too few fields
        let payload = b"T,1,2";
        let cs = crc16(payload);
        let mut short: heapless::Vec<u8, 32> = heapless::Vec::new();
        short.extend_from_slice(b"$T,1,2*").unwrap();
        for shift in [12, 8, 4, 0] {
            short.push(HEX[((cs >> shift) & 15) as usize]).unwrap();
        }
        assert_eq!(decode(&short), Err(FrameError::Field));
        // truncated frame
        assert!(decode(&f[..f.len() / 2]).is_err());
    }
}
