//! Settings changeable over the serial link and kept in flash: the board's bus window,
//! trips, current and speed limits and flux current, and the controller's machine
//! parameters (`set <name> <value>`, `save`; firmware/README.md).
//!
//! Validation is the library's own: a candidate set becomes a [`DriveConfig`] through
//! [`MachineParams::new`] and [`DriveDesign::new`], plus this board's measurement limits
//! (a trip and a bus maximum the ADC can still see). Errors name the field and the rule.
//!
//! The flash record ([`RECORD_LEN`] bytes at the start of the reserved page
//! [`SETTINGS_ADDR`], little endian):
//!
//! | offset | content |
//! |---|---|
//! | 0 | magic `b"ACIM"` |
//! | 4 | format version ([`SETTINGS_VERSION`], u16) |
//! | 6 | number of values ([`FIELD_COUNT`], u16) |
//! | 8 | the values in [`FIELDS`] order, f32 each |
//! | 8 + 4 n | CRC-32 (IEEE 802.3, reflected, as zlib's `crc32`) of all bytes before it |
//! | ... | zero padding to a whole number of 64-bit flash double words |
//!
//! A blank page (erased flash reads 0xFF) means "nothing saved": the defaults, silently.
//! Any other record that fails the magic, version, length, CRC or validation is refused
//! as a whole with a [`LoadError`]; the firmware then runs the defaults and reports it.

use crate::board::{self, POWER_STAGE};
use acim::math::{RAD_S_TO_RPM, RPM_TO_RAD_S};
use acim::{ConfigError, DriveConfig, DriveDesign, MachineData, MachineParams, ParamError};

/// Start of the flash page reserved for the settings: the last 2 KiB page of the
/// STM32G474RE's 512 KiB (bank 2, page 127, in the factory dual-bank mode). memory.x
/// ends the program's FLASH region here.
pub const SETTINGS_ADDR: u32 = 0x0807_F800;
/// Size of the reserved page, bytes.
pub const SETTINGS_PAGE_BYTES: u32 = 2048;
/// Page number of the reserved page within its bank (dual-bank mode).
pub const SETTINGS_PAGE_NUMBER: u8 = 127;
/// Version of the record layout; a record of another version is refused.
pub const SETTINGS_VERSION: u16 = 1;
/// First bytes of a record.
pub const MAGIC: [u8; 4] = *b"ACIM";
/// Number of settable values.
pub const FIELD_COUNT: usize = 14;
/// Length of the record, bytes (a multiple of 8: whole flash double words).
pub const RECORD_LEN: usize = (8 + 4 * FIELD_COUNT + 4).div_ceil(8) * 8;

/// One settable value: its name on the serial link (the field name of [`DriveConfig`] or
/// [`MachineData`]) and its unit.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Field {
    /// Name in commands and errors.
    pub name: &'static str,
    /// Unit.
    pub unit: &'static str,
}

const fn f(name: &'static str, unit: &'static str) -> Field {
    Field { name, unit }
}

/// The settable values, in record order.
pub const FIELDS: [Field; FIELD_COUNT] = [
    f("dc_bus_min", "V"),
    f("dc_bus_max", "V"),
    f("current_limit", "A"),
    f("overcurrent_trip", "A"),
    f("flux_current", "A"),
    f("max_speed", "rpm"),
    f("stator_resistance", "ohm"),
    f("rotor_resistance", "ohm"),
    f("stator_inductance", "H"),
    f("rotor_inductance", "H"),
    f("mutual_inductance", "H"),
    f("pole_pairs", ""),
    f("inertia", "kg m^2"),
    f("viscous_friction", "N m s/rad"),
];

const POLE_PAIRS: usize = 11;

/// The index in [`FIELDS`] of a name.
pub fn field_index(name: &[u8]) -> Option<usize> {
    FIELDS.iter().position(|f| f.name.as_bytes() == name)
}

/// Why a value or a set of values was refused: the field and the rule it broke.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SettingError {
    /// The offending field (a [`FIELDS`] name, or the [`DriveConfig`] field the library
    /// named).
    pub field: &'static str,
    /// The rule.
    pub rule: &'static str,
}

impl From<ConfigError> for SettingError {
    fn from(e: ConfigError) -> Self {
        match e {
            ConfigError::Invalid { field, rule } => SettingError { field, rule },
            ConfigError::Observer(_) => SettingError {
                field: "observer_poles",
                rule: "no stable observer for this machine (check the machine parameters)",
            },
        }
    }
}

impl From<ParamError> for SettingError {
    fn from(e: ParamError) -> Self {
        match e {
            ParamError::NotPositive(field) => SettingError {
                field,
                rule: "must be finite and > 0",
            },
            ParamError::Negative(field) => SettingError {
                field,
                rule: "must be finite and >= 0",
            },
            ParamError::NoLeakage => SettingError {
                field: "mutual_inductance",
                rule: "too large: need mutual_inductance^2 < stator_inductance * rotor_inductance",
            },
            ParamError::PolePairs => SettingError {
                field: "pole_pairs",
                rule: "must be a whole number in 1..=32",
            },
        }
    }
}

/// Why a stored record was not used.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum LoadError {
    /// The page is erased: nothing was saved (not a warning).
    Blank,
    /// Shorter than a record.
    Short,
    /// The first bytes are not [`MAGIC`].
    BadMagic,
    /// Another layout version (the stored one).
    Version(u16),
    /// Another number of values.
    Length,
    /// The CRC does not match: a corrupted or half-written page.
    Crc,
    /// Intact, but refused by today's validation.
    Invalid(SettingError),
}

impl LoadError {
    /// Short text for the boot warning.
    pub fn as_str(&self) -> &'static str {
        match self {
            LoadError::Blank => "nothing saved",
            LoadError::Short => "record too short",
            LoadError::BadMagic => "no settings record (bad magic)",
            LoadError::Version(_) => "record of another format version",
            LoadError::Length => "record with another number of values",
            LoadError::Crc => "CRC mismatch (corrupted record)",
            LoadError::Invalid(_) => "stored value refused",
        }
    }
}

/// A validated set of values ([`Settings::set`] and [`Settings::decode`] keep every
/// instance valid).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Settings {
    values: [f32; FIELD_COUNT],
}

impl Settings {
    /// This build's defaults ([`board::drive_config`]).
    pub fn defaults() -> Self {
        Self::from_config(&board::drive_config())
    }

    /// The values of a configuration.
    pub fn from_config(c: &DriveConfig) -> Self {
        let m = &c.machine;
        Self {
            values: [
                c.dc_bus_min,
                c.dc_bus_max,
                c.current_limit,
                c.overcurrent_trip,
                c.flux_current,
                c.max_speed * RAD_S_TO_RPM,
                m.stator_resistance(),
                m.rotor_resistance(),
                m.stator_inductance(),
                m.rotor_inductance(),
                m.mutual_inductance(),
                m.pole_pairs() as f32,
                m.inertia(),
                m.viscous_friction(),
            ],
        }
    }

    /// Values in [`FIELDS`] order, validated as a whole (commissioning's result,
    /// [`crate::commission::settings_from`]).
    pub(crate) fn from_values(values: [f32; FIELD_COUNT]) -> Result<Settings, SettingError> {
        let s = Settings { values };
        s.drive_config()?;
        Ok(s)
    }

    /// The value of field `i` (0 for an index beyond [`FIELD_COUNT`]).
    pub fn get(&self, i: usize) -> f32 {
        self.values.get(i).copied().unwrap_or(0.0)
    }

    /// A copy with field `i` set to `value`, validated as a whole.
    pub fn set(&self, i: usize, value: f32) -> Result<Settings, SettingError> {
        let mut next = *self;
        match next.values.get_mut(i) {
            Some(v) => *v = value,
            None => {
                return Err(SettingError {
                    field: "setting",
                    rule: "unknown setting",
                })
            }
        }
        next.drive_config()?;
        Ok(next)
    }

    /// The drive configuration: this board's defaults with these values, checked by
    /// [`MachineParams::new`], [`DriveDesign::new`] and the board's measurement limits.
    /// The initial stator-resistance estimate follows `stator_resistance`.
    pub fn drive_config(&self) -> Result<DriveConfig, SettingError> {
        let v = &self.values;
        let p = v[POLE_PAIRS];
        if !((1.0..=32.0).contains(&p) && p == (p as u32) as f32) {
            return Err(ParamError::PolePairs.into());
        }
        let machine = MachineParams::new(MachineData {
            stator_resistance: v[6],
            rotor_resistance: v[7],
            stator_inductance: v[8],
            rotor_inductance: v[9],
            mutual_inductance: v[10],
            pole_pairs: p as u8,
            inertia: v[12],
            viscous_friction: v[13],
        })?;
        let mut cfg = board::drive_config();
        cfg.machine = machine;
        cfg.rs_initial = machine.stator_resistance();
        cfg.dc_bus_min = v[0];
        cfg.dc_bus_max = v[1];
        cfg.current_limit = v[2];
        cfg.overcurrent_trip = v[3];
        cfg.flux_current = v[4];
        cfg.max_speed = v[5] * RPM_TO_RAD_S;
        DriveDesign::new(cfg)?;
        // both finite: DriveDesign::new has refused anything else
        if cfg.overcurrent_trip > TRIP_FULL_SCALE_FRACTION * POWER_STAGE.current_full_scale() {
            return Err(SettingError {
                field: "overcurrent_trip",
                rule: "at most 90 % of the current-sense full scale (board::POWER_STAGE)",
            });
        }
        if cfg.dc_bus_max > BUS_FULL_SCALE_FRACTION * POWER_STAGE.bus_full_scale() {
            return Err(SettingError {
                field: "dc_bus_max",
                rule: "at most 95 % of the bus-sense full scale (board::POWER_STAGE)",
            });
        }
        Ok(cfg)
    }

    /// The flash record.
    pub fn encode(&self) -> [u8; RECORD_LEN] {
        let mut r = [0u8; RECORD_LEN];
        r[0..4].copy_from_slice(&MAGIC);
        r[4..6].copy_from_slice(&SETTINGS_VERSION.to_le_bytes());
        r[6..8].copy_from_slice(&(FIELD_COUNT as u16).to_le_bytes());
        for (i, v) in self.values.iter().enumerate() {
            r[8 + 4 * i..12 + 4 * i].copy_from_slice(&v.to_le_bytes());
        }
        let end = 8 + 4 * FIELD_COUNT;
        let crc = crc32(&r[..end]);
        r[end..end + 4].copy_from_slice(&crc.to_le_bytes());
        r
    }

    /// Reads a record (at least [`RECORD_LEN`] bytes of the page); never panics.
    pub fn decode(page: &[u8]) -> Result<Settings, LoadError> {
        let r = page.get(..RECORD_LEN).ok_or(LoadError::Short)?;
        if r.iter().all(|&b| b == 0xFF) {
            return Err(LoadError::Blank);
        }
        if r[0..4] != MAGIC {
            return Err(LoadError::BadMagic);
        }
        let u16_at = |o: usize| u16::from_le_bytes([r[o], r[o + 1]]);
        let u32_at = |o: usize| u32::from_le_bytes([r[o], r[o + 1], r[o + 2], r[o + 3]]);
        let version = u16_at(4);
        if version != SETTINGS_VERSION {
            return Err(LoadError::Version(version));
        }
        if u16_at(6) as usize != FIELD_COUNT {
            return Err(LoadError::Length);
        }
        let end = 8 + 4 * FIELD_COUNT;
        if crc32(&r[..end]) != u32_at(end) {
            return Err(LoadError::Crc);
        }
        let mut s = Settings {
            values: [0.0; FIELD_COUNT],
        };
        for (i, v) in s.values.iter_mut().enumerate() {
            *v = f32::from_bits(u32_at(8 + 4 * i));
        }
        s.drive_config().map_err(LoadError::Invalid)?;
        Ok(s)
    }
}

/// Largest trip as a fraction of the current-sense full scale (saturation trips anyway).
pub const TRIP_FULL_SCALE_FRACTION: f32 = 0.9;
/// Largest bus maximum as a fraction of the bus-sense full scale.
pub const BUS_FULL_SCALE_FRACTION: f32 = 0.95;

/// CRC-32 (IEEE 802.3 polynomial, reflected, initial and final XOR 0xFFFF_FFFF: zlib's
/// `crc32`), bitwise: small, and run only at boot and on `save`.
pub fn crc32(data: &[u8]) -> u32 {
    let mut crc = 0xFFFF_FFFFu32;
    for &b in data {
        crc ^= b as u32;
        for _ in 0..8 {
            let mask = (crc & 1).wrapping_neg();
            crc = (crc >> 1) ^ (0xEDB8_8320 & mask);
        }
    }
    !crc
}

/// Parses a setting value: optional sign, 1 to 6 integer digits, optionally `.` and 1 to
/// 7 fraction digits (inductances and inertias need them), at most 9 digits in all. No
/// exponent, no inf/nan.
pub fn parse_value(s: &[u8]) -> Option<f32> {
    const POW10: [f32; 8] = [1.0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7];
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
    if int.is_empty() || int.len() > 6 {
        return None;
    }
    let frac = frac.unwrap_or(&[]);
    if frac.len() > 7 || (frac.is_empty() && rest.contains(&b'.')) {
        return None;
    }
    // at most 9 digits in all: the mantissa fits a u32 (and f32 keeps 7 of them anyway)
    if int.len() + frac.len() > 9 {
        return None;
    }
    let mut mant: u32 = 0;
    for &d in int.iter().chain(frac) {
        if !d.is_ascii_digit() {
            return None;
        }
        mant = mant * 10 + (d - b'0') as u32;
    }
    let v = mant as f32 / POW10[frac.len()];
    Some(if neg { -v } else { v })
}

/// Formats a value to about 7 significant digits (at most 6 fraction digits), trailing
/// zeros dropped (`4.67`, `0.0049`, `-12`); values of 1e7 or more, and non-finite ones,
/// print as `?`. Returns the used part of `buf`.
#[inline(never)]
pub fn format_value(v: f32, buf: &mut [u8; 24]) -> &[u8] {
    const POW10: [u32; 7] = [1, 10, 100, 1_000, 10_000, 100_000, 1_000_000];
    let a = v.abs();
    if !a.is_finite() || a >= 1e7 {
        buf[0] = b'?';
        return &buf[..1];
    }
    // f32 keeps about 7 significant digits: as many fraction digits as the integer part
    // leaves of them (so the scaled value stays below 1e7 and fits a u32)
    let mut digits = 6usize;
    let mut lim = 10.0f32;
    while digits > 0 && a >= lim {
        digits -= 1;
        lim *= 10.0;
    }
    let scale = POW10[digits];
    let scaled = (a * scale as f32 + 0.5) as u32;
    let (mut int, mut frac) = (scaled / scale, scaled % scale);
    let mut tmp = [0u8; 24];
    let mut n = 0;
    while digits > 0 && frac % 10 == 0 {
        frac /= 10;
        digits -= 1;
    }
    for _ in 0..digits {
        tmp[n] = b'0' + (frac % 10) as u8;
        frac /= 10;
        n += 1;
    }
    if digits > 0 {
        tmp[n] = b'.';
        n += 1;
    }
    loop {
        tmp[n] = b'0' + (int % 10) as u8;
        int /= 10;
        n += 1;
        if int == 0 {
            break;
        }
    }
    if v < 0.0 && scaled != 0 {
        tmp[n] = b'-';
        n += 1;
    }
    for i in 0..n {
        buf[i] = tmp[n - 1 - i];
    }
    &buf[..n]
}

#[cfg(test)]
mod tests {
    use super::*;
    use acim::Drive;

    fn idx(name: &str) -> usize {
        field_index(name.as_bytes()).unwrap()
    }

    #[test]
    fn defaults_are_this_builds_drive() {
        let s = Settings::defaults();
        let cfg = s.drive_config().unwrap();
        assert_eq!(cfg, board::drive_config());
        assert!(Drive::new(cfg).is_ok());
        assert_eq!(RECORD_LEN % 8, 0);
        assert_eq!(RECORD_LEN, 72);
    }

    #[test]
    fn round_trip_through_the_record() {
        let s = Settings::defaults()
            .set(idx("current_limit"), 4.0)
            .unwrap()
            .set(idx("stator_resistance"), 11.25)
            .unwrap();
        let rec = s.encode();
        assert_eq!(&rec[..4], b"ACIM");
        let back = Settings::decode(&rec).unwrap();
        assert_eq!(back, s);
        assert_eq!(back.get(idx("current_limit")), 4.0);
        let cfg = back.drive_config().unwrap();
        assert_eq!(cfg.rs_initial, 11.25);
        // a whole page (record then erased flash) reads the same
        let mut page = [0xFFu8; SETTINGS_PAGE_BYTES as usize];
        page[..RECORD_LEN].copy_from_slice(&rec);
        assert_eq!(Settings::decode(&page), Ok(s));
    }

    #[test]
    fn every_corrupted_byte_is_refused() {
        let rec = Settings::defaults().encode();
        let used = 8 + 4 * FIELD_COUNT + 4;
        for i in 0..used {
            for flip in [0x01u8, 0x80, 0xFF] {
                let mut bad = rec;
                bad[i] ^= flip;
                let e = Settings::decode(&bad).unwrap_err();
                assert!(
                    matches!(
                        e,
                        LoadError::Crc
                            | LoadError::BadMagic
                            | LoadError::Version(_)
                            | LoadError::Length
                    ),
                    "byte {i} ^ {flip:#x}: {e:?}"
                );
            }
        }
    }

    #[test]
    fn blank_short_wrong_version() {
        assert_eq!(Settings::decode(&[0xFF; 80]), Err(LoadError::Blank));
        assert_eq!(Settings::decode(&[0xFF; 8]), Err(LoadError::Short));
        assert_eq!(Settings::decode(&[0u8; 80]), Err(LoadError::BadMagic));
        // another version, with a CRC that matches it: still refused
        let mut rec = Settings::defaults().encode();
        rec[4..6].copy_from_slice(&2u16.to_le_bytes());
        let end = 8 + 4 * FIELD_COUNT;
        let crc = crc32(&rec[..end]);
        rec[end..end + 4].copy_from_slice(&crc.to_le_bytes());
        assert_eq!(Settings::decode(&rec), Err(LoadError::Version(2)));
    }

    #[test]
    fn an_intact_record_with_a_refused_value_is_refused() {
        // a record written by a build with other limits: CRC good, value out of range
        let mut s = Settings::defaults();
        s.values[idx("flux_current")] = 50.0;
        let e = Settings::decode(&s.encode()).unwrap_err();
        assert_eq!(
            e,
            LoadError::Invalid(SettingError {
                field: "flux_current",
                rule: "must be below current_limit"
            })
        );
    }

    #[test]
    fn out_of_range_values_name_the_field() {
        let s = Settings::defaults();
        let cases: &[(&str, f32, &str)] = &[
            ("current_limit", -1.0, "current_limit"),
            ("current_limit", f32::NAN, "current_limit"),
            ("flux_current", 6.0, "flux_current"),
            ("dc_bus_min", 500.0, "dc_bus_max"),
            ("dc_bus_max", 470.0, "dc_bus_max"),
            ("overcurrent_trip", 9.5, "overcurrent_trip"),
            ("overcurrent_trip", 3.0, "overcurrent_trip"),
            ("max_speed", 0.0, "max_speed"),
            ("stator_resistance", 0.0, "stator_resistance"),
            ("mutual_inductance", 10.0, "mutual_inductance"),
            ("pole_pairs", 2.5, "pole_pairs"),
            ("pole_pairs", 0.0, "pole_pairs"),
            ("pole_pairs", 33.0, "pole_pairs"),
            ("viscous_friction", -0.1, "viscous_friction"),
            ("inertia", f32::INFINITY, "inertia"),
        ];
        for &(name, v, field) in cases {
            let e = s.set(idx(name), v).unwrap_err();
            assert_eq!(e.field, field, "{name} = {v}: {e:?}");
            assert!(!e.rule.is_empty());
        }
        assert!(s.set(FIELD_COUNT, 1.0).is_err());
        // the refused value left nothing changed
        assert_eq!(s, Settings::defaults());
        // each value is checked against the others: lowering the limit and the trip
        // needs an order that stays valid (trip <= 3 x limit, trip >= limit)
        assert_eq!(
            s.set(idx("current_limit"), 2.5).unwrap_err().field,
            "overcurrent_trip"
        );
        let low = s
            .set(idx("dc_bus_min"), 20.0)
            .and_then(|s| s.set(idx("overcurrent_trip"), 7.0))
            .and_then(|s| s.set(idx("current_limit"), 2.5))
            .and_then(|s| s.set(idx("overcurrent_trip"), 4.0))
            .unwrap();
        let lv = Settings::from_config(&board::drive_config_for(&board::LOW_VOLTAGE));
        assert!(lv.drive_config().is_ok());
        assert_eq!(low.get(idx("current_limit")), lv.get(idx("current_limit")));
    }

    /// The linker never places code or data in the settings page.
    #[test]
    fn memory_x_leaves_the_settings_page_out() {
        let mx = include_str!("../../../memory.x");
        let line = mx
            .lines()
            .find(|l| l.trim_start().starts_with("FLASH"))
            .unwrap();
        assert!(line.contains("ORIGIN = 0x08000000"), "{line}");
        let kib: u32 = line
            .split("LENGTH =")
            .nth(1)
            .unwrap()
            .trim()
            .trim_end_matches('K')
            .parse()
            .unwrap();
        assert_eq!(0x0800_0000 + kib * 1024, SETTINGS_ADDR, "{line}");
        assert_eq!(
            SETTINGS_ADDR + SETTINGS_PAGE_BYTES,
            0x0800_0000 + 512 * 1024
        );
        assert_eq!(
            SETTINGS_ADDR,
            0x0804_0000 + SETTINGS_PAGE_NUMBER as u32 * SETTINGS_PAGE_BYTES
        );
    }

    #[test]
    fn crc_is_zlibs() {
        assert_eq!(crc32(b"123456789"), 0xCBF4_3926);
        assert_eq!(crc32(b""), 0);
    }

    #[test]
    fn values_parse_and_print_back() {
        for (text, v) in [
            ("4.67", 4.67f32),
            ("0.0049", 0.0049),
            ("-12", -12.0),
            ("200", 200.0),
            ("0.4476", 0.4476),
            ("+1.5", 1.5),
        ] {
            assert_eq!(parse_value(text.as_bytes()), Some(v), "{text}");
        }
        for bad in [
            "",
            "-",
            "1.",
            ".5",
            "1e3",
            "nan",
            "inf",
            "1234567",
            "1.12345678",
            "1..2",
        ] {
            assert_eq!(parse_value(bad.as_bytes()), None, "{bad}");
        }
        let mut buf = [0u8; 24];
        for (v, text) in [
            (4.67f32, "4.67"),
            (0.0049, "0.0049"),
            (-12.0, "-12"),
            (0.0, "0"),
            (15.75, "15.75"),
            (f32::NAN, "?"),
            (1e8, "?"),
        ] {
            assert_eq!(format_value(v, &mut buf), text.as_bytes(), "{v}");
        }
        // every default prints to a value that parses back to itself
        let s = Settings::defaults();
        for (i, field) in FIELDS.iter().enumerate() {
            let v = s.get(i);
            let text = format_value(v, &mut buf);
            let back = parse_value(text).unwrap();
            assert!(
                (back - v).abs() <= 1e-6 * v.abs().max(1.0),
                "{}",
                field.name
            );
        }
    }
}
