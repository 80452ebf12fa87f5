//! Settings changeable over the serial link and kept in flash: the board's bus window,
//! trips, current and speed limits and flux current, and the controller's machine
//! parameters (`set <name> <value>`, `save`; firmware/README.md).
//!
//! Validation is the library's own: a candidate set becomes a [`DriveConfig`] through
//! [`MachineParams::new`] and [`DriveDesign::new`], plus this board's measurement limits
//! (a trip and a bus maximum the ADC can still see). Errors name the field and the rule.
//!
//! The flash record ([`RECORD_LEN`] bytes at the start of each of the two reserved pages,
//! little endian; [`crate::store`] writes them alternately):
//!
//! | offset | content |
//! |---|---|
//! | 0 | magic `b"ACIM"` |
//! | 4 | format version ([`SETTINGS_VERSION`], u16) |
//! | 6 | number of values ([`FIELD_COUNT`], u16) |
//! | 8 | sequence number (u32; one more at every save, wrapping: [`crate::store`]) |
//! | 12 | the values in [`FIELDS`] order, f32 each |
//! | 12 + 4 n | CRC-32 (IEEE 802.3, reflected, as zlib's `crc32`) of all bytes before it |
//! | ... | zero padding to a whole number of 64-bit flash double words |
//!
//! A blank page (erased flash reads 0xFF) holds nothing. Any other record that fails the
//! magic, version, length, CRC or validation is refused as a whole with a [`LoadError`];
//! [`crate::store`] then uses the other page's record, or the defaults, and says so.

use crate::board::{self, POWER_STAGE};
use acim::math::{sqrt, RAD_S_TO_RPM, RPM_TO_RAD_S};
use acim::{
    ConfigError, DriveConfig, DriveDesign, DriveObserver, MachineData, MachineParams,
    ObserverChoice, ParamError,
};

/// Start of the two flash pages reserved for the settings (A, then B): the last 4 KiB of
/// the STM32G474RE's 512 KiB (bank 2, pages 126 and 127, in the factory dual-bank mode).
/// memory.x ends the program's FLASH region here.
pub const SETTINGS_ADDR: u32 = 0x0807_F000;
/// Size of one reserved page, bytes.
pub const SETTINGS_PAGE_BYTES: u32 = 2048;
/// Number of reserved pages (A and B, written alternately).
pub const SETTINGS_PAGES: u32 = 2;
/// Page number of the first reserved page (A) within its bank (dual-bank mode); B is the
/// next one.
pub const SETTINGS_PAGE_NUMBER: u8 = 126;
/// Version of the record layout; a record of another version is refused.
pub const SETTINGS_VERSION: u16 = 4;
/// The format before the observer's choice: its 15 values are read, the paper's observer.
const VERSION_WITHOUT_OBSERVER: u16 = 3;
/// The format before the slow period: its 14 values are read, the slow task off.
const VERSION_WITHOUT_SLOW_PERIOD: u16 = 2;
/// First bytes of a record.
pub const MAGIC: [u8; 4] = *b"ACIM";
/// Number of settable values.
pub const FIELD_COUNT: usize = 16;
/// Length of the record, bytes (a multiple of 8: whole flash double words).
pub const RECORD_LEN: usize = (VALUES + 4 * FIELD_COUNT + 4).div_ceil(8) * 8;
/// Offset of the sequence number in a record.
const SEQ: usize = 8;
/// Offset of the first value in a record.
const VALUES: usize = 12;
/// Offset of the CRC in a record.
pub(crate) const CRC: usize = VALUES + 4 * FIELD_COUNT;

/// One settable value: its name on the serial link (its path in [`DriveConfig`]'s groups,
/// the machine's fields under `machine.`) and its unit.
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
    f("limits.dc_bus_min", "V"),
    f("limits.dc_bus_max", "V"),
    f("limits.current_limit", "A"),
    f("limits.overcurrent_trip", "A"),
    f("loops.flux_current", "A"),
    f("limits.max_speed", "rpm"),
    f("machine.stator_resistance", "ohm"),
    f("machine.rotor_resistance", "ohm"),
    f("machine.stator_inductance", "H"),
    f("machine.rotor_inductance", "H"),
    f("machine.mutual_inductance", "H"),
    f("machine.pole_pairs", ""),
    f("machine.inertia", "kg m^2"),
    f("machine.viscous_friction", "N m s/rad"),
    f("loops.slow_period", "ms"),
    f("estimation.observer", ""),
];

// indices in FIELDS
const DC_BUS_MIN: usize = 0;
const DC_BUS_MAX: usize = 1;
const CURRENT_LIMIT: usize = 2;
const OVERCURRENT_TRIP: usize = 3;
const FLUX_CURRENT: usize = 4;
const MAX_SPEED: usize = 5;
const STATOR_RESISTANCE: usize = 6;
const ROTOR_RESISTANCE: usize = 7;
const STATOR_INDUCTANCE: usize = 8;
const ROTOR_INDUCTANCE: usize = 9;
const MUTUAL_INDUCTANCE: usize = 10;
const POLE_PAIRS: usize = 11;
const INERTIA: usize = 12;
const VISCOUS_FRICTION: usize = 13;
const SLOW_PERIOD: usize = 14;
pub(crate) const OBSERVER: usize = 15;

/// `estimation.observer`'s value for `choice`: 0 the paper's reduced-order observer, 1
/// the flux observer.
pub(crate) fn observer_value(choice: ObserverChoice) -> f32 {
    match choice {
        ObserverChoice::Reduced => 0.0,
        ObserverChoice::Flux => 1.0,
    }
}

/// The index in [`FIELDS`] of a name: its path in [`DriveConfig`]'s groups
/// (`limits.current_limit`), or the name without its group (`current_limit`, the earlier
/// flat name, still accepted; the replies name the field by its path).
pub fn field_index(name: &[u8]) -> Option<usize> {
    FIELDS.iter().position(|f| {
        let path = f.name.as_bytes();
        path == name || path.rsplit(|&b| b == b'.').next() == Some(name)
    })
}

/// The [`FIELDS`] name of a library field: its path as given (`limits.current_limit`), or
/// the path of a machine field the library names alone (`stator_resistance` ->
/// `machine.stator_resistance`).
fn field_path(field: &'static str) -> &'static str {
    FIELDS
        .iter()
        .find(|f| f.name.strip_prefix("machine.") == Some(field))
        .map_or(field, |f| f.name)
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
                field: "estimation.observer_poles",
                rule: "no stable observer for this machine (check the machine parameters)",
            },
        }
    }
}

impl From<ParamError> for SettingError {
    fn from(e: ParamError) -> Self {
        match e {
            ParamError::NotPositive(field) => SettingError {
                field: field_path(field),
                rule: "must be finite and > 0",
            },
            ParamError::Negative(field) => SettingError {
                field: field_path(field),
                rule: "must be finite and >= 0",
            },
            ParamError::NoLeakage => SettingError {
                field: "machine.mutual_inductance",
                rule: "too large: need mutual_inductance^2 < stator_inductance * rotor_inductance",
            },
            ParamError::PolePairs => SettingError {
                field: "machine.pole_pairs",
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
                c.limits.dc_bus_min,
                c.limits.dc_bus_max,
                c.limits.current_limit,
                c.limits.overcurrent_trip,
                c.loops.flux_current,
                c.limits.max_speed * RAD_S_TO_RPM,
                m.stator_resistance(),
                m.rotor_resistance(),
                m.stator_inductance(),
                m.rotor_inductance(),
                m.mutual_inductance(),
                m.pole_pairs() as f32,
                m.inertia(),
                m.viscous_friction(),
                c.loops.slow_period * 1000.0,
                observer_value(c.estimation.observer),
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

    /// A copy with field `i` set to `value`, validated as a whole. A refused relation
    /// between fields of this board's bounds names field `i` when it is one of them.
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
        next.checked_config(Some(i))?;
        Ok(next)
    }

    /// The drive configuration: this board's defaults with these values, checked by
    /// [`MachineParams::new`], [`DriveDesign::new`], the board's measurement limits and
    /// the physical bounds of every field ([`MIN_TIME_CONSTANT_S`] and the constants after
    /// it). The initial stator-resistance estimate follows `machine.stator_resistance`.
    pub fn drive_config(&self) -> Result<DriveConfig, SettingError> {
        self.checked_config(None)
    }

    /// [`Settings::drive_config`]; a relation that fails names `changed` (the field a
    /// `set` changed) when it is one of the related fields, else its first field.
    fn checked_config(&self, changed: Option<usize>) -> Result<DriveConfig, SettingError> {
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
        cfg.estimation.rs_initial = machine.stator_resistance();
        cfg.limits.dc_bus_min = v[0];
        cfg.limits.dc_bus_max = v[1];
        cfg.limits.current_limit = v[2];
        cfg.limits.overcurrent_trip = v[3];
        cfg.loops.flux_current = v[4];
        cfg.limits.max_speed = v[5] * RPM_TO_RAD_S;
        cfg.loops.slow_period = v[SLOW_PERIOD] / 1000.0;
        cfg.estimation.observer = match v[OBSERVER] {
            0.0 => ObserverChoice::Reduced,
            1.0 => ObserverChoice::Flux,
            _ => {
                return Err(SettingError {
                    field: "estimation.observer",
                    rule: "0 (the paper's reduced-order observer) or 1 (the flux observer)",
                })
            }
        };
        // bounds the library would report under a field `set` does not know (`machine`,
        // `regen_min_frequency`, `flying_start`), or does not have
        machine_bounds(&cfg, changed)?;
        speed_bounds(&cfg, changed)?;
        DriveDesign::new(cfg)?;
        DriveObserver::new(&cfg)?;
        // all finite and positive from here: DriveDesign::new has refused anything else
        if cfg.limits.overcurrent_trip > TRIP_FULL_SCALE_FRACTION * POWER_STAGE.current_full_scale()
        {
            return Err(SettingError {
                field: "limits.overcurrent_trip",
                rule: "at most 90 % of the current-sense full scale (board::POWER_STAGE)",
            });
        }
        if cfg.limits.dc_bus_max > BUS_FULL_SCALE_FRACTION * POWER_STAGE.bus_full_scale() {
            return Err(SettingError {
                field: "limits.dc_bus_max",
                rule: "at most 95 % of the bus-sense full scale (board::POWER_STAGE)",
            });
        }
        protection_bounds(&cfg, changed)?;
        mechanical_bounds(&cfg, changed)?;
        Ok(cfg)
    }

    /// The flash record, with sequence number `seq`.
    pub fn encode(&self, seq: u32) -> [u8; RECORD_LEN] {
        let mut r = [0u8; RECORD_LEN];
        r[0..4].copy_from_slice(&MAGIC);
        r[4..6].copy_from_slice(&SETTINGS_VERSION.to_le_bytes());
        r[6..8].copy_from_slice(&(FIELD_COUNT as u16).to_le_bytes());
        r[SEQ..SEQ + 4].copy_from_slice(&seq.to_le_bytes());
        for (i, v) in self.values.iter().enumerate() {
            r[VALUES + 4 * i..VALUES + 4 + 4 * i].copy_from_slice(&v.to_le_bytes());
        }
        let crc = crc32(&r[..CRC]);
        r[CRC..CRC + 4].copy_from_slice(&crc.to_le_bytes());
        r
    }

    /// Reads a record (at least [`RECORD_LEN`] bytes of the page); never panics.
    pub fn decode(page: &[u8]) -> Result<Settings, LoadError> {
        Self::decode_record(page).map(|(s, _)| s)
    }

    /// Reads a record and its sequence number; never panics.
    pub fn decode_record(page: &[u8]) -> Result<(Settings, u32), LoadError> {
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
        // a record of an earlier format holds the first values (a board keeps its settings
        // across the update: the slow task off, the paper's observer)
        let count = match version {
            SETTINGS_VERSION => FIELD_COUNT,
            VERSION_WITHOUT_OBSERVER => OBSERVER,
            VERSION_WITHOUT_SLOW_PERIOD => SLOW_PERIOD,
            _ => return Err(LoadError::Version(version)),
        };
        if u16_at(6) as usize != count {
            return Err(LoadError::Length);
        }
        let crc_at = VALUES + 4 * count;
        if crc32(&r[..crc_at]) != u32_at(crc_at) {
            return Err(LoadError::Crc);
        }
        let mut s = Settings {
            values: [0.0; FIELD_COUNT],
        };
        for (i, v) in s.values.iter_mut().take(count).enumerate() {
            *v = f32::from_bits(u32_at(VALUES + 4 * i));
        }
        s.drive_config().map_err(LoadError::Invalid)?;
        Ok((s, u32_at(SEQ)))
    }
}

/// Largest trip as a fraction of the current-sense full scale (saturation trips anyway).
pub const TRIP_FULL_SCALE_FRACTION: f32 = 0.9;
/// Largest bus maximum as a fraction of the bus-sense full scale.
pub const BUS_FULL_SCALE_FRACTION: f32 = 0.95;

// The physical bounds of the settings, beyond the library's own rules (which stay in
// force: `DriveDesign::new` checks the same configuration). Each keeps `set` from
// accepting a value that switches a protection off, makes it fire where the drive
// operates, or leaves the state machine waiting for ever. Per field:
//
// - dc_bus_min: at least MIN_DC_BUS_V and MIN_BUS_WINDOW of dc_bus_max (below dc_bus_max:
//   the library).
// - dc_bus_max: at most 95 % of the bus-sense full scale; above dc_bus_min and at most
//   dc_bus_min / MIN_BUS_WINDOW.
// - current_limit: above flux_current (library); the trip between MIN_TRIP_OVER_LIMIT and
//   3 times it; the bus must drive it through the stator resistance at standstill.
// - overcurrent_trip: MIN_TRIP_OVER_LIMIT .. 3 x current_limit, at most 90 % of the
//   current-sense full scale.
// - flux_current: below current_limit (library), at least MIN_FLUX_OVER_TRIP of the trip.
// - max_speed: at least twice the regeneration limit's speed, at most
//   MAX_SPEED_OVER_COMMAND times the largest speed command, within the flying start's
//   quarter turn per period, at most 3 x the base speed (library).
// - stator_resistance: stator time constant Ls/Rs within the TIME_CONSTANT range; Rs times
//   current_limit within the linear voltage at dc_bus_max.
// - rotor_resistance, rotor_inductance: rotor time constant Lr/Rr within the
//   TIME_CONSTANT range.
// - stator_inductance: the stator time constant, the transient time constant
//   sigma Ls / (Rs + R_R) of at least MIN_TRANSIENT_TIME_CONSTANT_PERIODS periods.
// - mutual_inductance: Lm^2 < Ls Lr (library), Lm at least MIN_MAGNETIZING_FRACTION of
//   Ls and of Lr, and the transient time constant.
// - pole_pairs: whole, 1..=32 (library), and the speed bounds above.
// - inertia: the full-torque run-up to max_speed at least one observer time constant,
//   the speed ramp within the torque at the current limit.
// - viscous_friction: >= 0 (library), B/J at most the observer's slowest pole.

/// Shortest rotor (Lr/Rr) and stator (Ls/Rs) time constant, s: 5 control periods at
/// 5 kHz (the library's `MIN_ROTOR_TIME_CONSTANT_PERIODS`); a motor's are tens of
/// milliseconds to seconds.
pub const MIN_TIME_CONSTANT_S: f32 = 1e-3;
/// Longest rotor and stator time constant, s (`acim::design::MAX_ROTOR_TIME_CONSTANT`):
/// magnetizing gives up after 10 rotor time constants, and the current loops' integral
/// (time constant Ls/Rs) must act within it.
pub const MAX_TIME_CONSTANT_S: f32 = acim::design::MAX_ROTOR_TIME_CONSTANT;
/// The transient time constant sigma Ls / (Rs + R_R) spans at least this many control
/// periods: the current loops and the observer's Euler step assume the electrical pole
/// slower than the sampling (the paper's machine: 10.7 periods at 5 kHz).
pub const MIN_TRANSIENT_TIME_CONSTANT_PERIODS: f32 = 5.0;
/// The mutual inductance is at least this fraction of the stator and rotor inductances:
/// an induction motor's magnetizing path dominates its leakage (0.93-0.98 in the
/// acceptance machines); below it the rotor flux the drive orients on is mostly leakage.
pub const MIN_MAGNETIZING_FRACTION: f32 = 0.5;
/// Lowest under-voltage trip, V: half the low-voltage bring-up profile's
/// ([`board::LOW_VOLTAGE`]), the lowest bus this power stage is run from. Below it the
/// trip no longer stops switching on a collapsed supply.
pub const MIN_DC_BUS_V: f32 = 0.5 * board::LOW_VOLTAGE.dc_bus_min;
/// The under-voltage trip is at least this fraction of the over-voltage trip: a window
/// wider than 4:1 cannot tell a collapsed bus from the supply it brackets (mains: at
/// least 100 V under a 400 V maximum; the bring-up profile: 16.5 V under 66 V).
pub const MIN_BUS_WINDOW: f32 = 0.25;
/// The over-current trip is at least this multiple of `limits.current_limit`: the regulated
/// current's PWM ripple and the current loops' overshoot must not reach it (both
/// profiles: 1.6-1.7).
pub const MIN_TRIP_OVER_LIMIT: f32 = 1.2;
/// `loops.flux_current` is at least this fraction of the trip: five times the current-sensor
/// offset the drive tolerates (`acim::design::OFFSET_FRACTION`, 2 % of the trip), so an
/// accepted offset cannot be a sizeable part of the magnetizing current.
pub const MIN_FLUX_OVER_TRIP: f32 = 5.0 * acim::design::OFFSET_FRACTION;
/// The over-speed trip is at most this multiple of the largest speed command
/// ([`board::MAX_SPEED_COMMAND_RPM`]): targets are clamped to 90 % of it anyway, and a
/// trip far above every commanded speed lets a runaway go unchecked.
pub const MAX_SPEED_OVER_COMMAND: f32 = 2.0;

/// A relation between fields: `Ok` when `ok`, else an error naming `changed` if it is one
/// of `fields`, else `fields[0]`.
fn relation(
    ok: bool,
    fields: &[usize],
    changed: Option<usize>,
    rule: &'static str,
) -> Result<(), SettingError> {
    if ok {
        return Ok(());
    }
    let i = changed.filter(|c| fields.contains(c)).unwrap_or(fields[0]);
    Err(SettingError {
        field: FIELDS[i].name,
        rule,
    })
}

/// The machine model's time constants and inductance ratios (`MachineParams::new` has
/// checked every value finite and positive).
fn machine_bounds(cfg: &DriveConfig, changed: Option<usize>) -> Result<(), SettingError> {
    let m = &cfg.machine;
    let range = MIN_TIME_CONSTANT_S..=MAX_TIME_CONSTANT_S;
    relation(
        range.contains(&m.rotor_time_constant()),
        &[ROTOR_RESISTANCE, ROTOR_INDUCTANCE],
        changed,
        "rotor time constant rotor_inductance / rotor_resistance must be within \
         1 ms ..= 10 s (magnetizing and its timeout take 3 and 10 of them)",
    )?;
    relation(
        range.contains(&(m.stator_inductance() / m.stator_resistance())),
        &[STATOR_RESISTANCE, STATOR_INDUCTANCE],
        changed,
        "stator time constant stator_inductance / stator_resistance must be within \
         1 ms ..= 10 s",
    )?;
    let lm = m.mutual_inductance();
    relation(
        lm >= MIN_MAGNETIZING_FRACTION * m.stator_inductance()
            && lm >= MIN_MAGNETIZING_FRACTION * m.rotor_inductance(),
        &[MUTUAL_INDUCTANCE, STATOR_INDUCTANCE, ROTOR_INDUCTANCE],
        changed,
        "must be at least half of stator_inductance and of rotor_inductance (the \
         magnetizing path dominates the leakage)",
    )?;
    relation(
        m.transient_time_constant()
            >= MIN_TRANSIENT_TIME_CONSTANT_PERIODS * cfg.loops.control_period,
        &[
            STATOR_INDUCTANCE,
            MUTUAL_INDUCTANCE,
            ROTOR_INDUCTANCE,
            STATOR_RESISTANCE,
            ROTOR_RESISTANCE,
        ],
        changed,
        "transient time constant sigma Ls / (Rs + R_R) must span at least 5 control \
         periods (1 ms)",
    )
}

/// The over-speed trip's range, where it is finite and positive (the library names it
/// otherwise).
fn speed_bounds(cfg: &DriveConfig, changed: Option<usize>) -> Result<(), SettingError> {
    let w = cfg.limits.max_speed;
    if !(acim::math::is_finite(w) && w > 0.0) {
        return Ok(());
    }
    let p = cfg.machine.pole_pairs_f32();
    relation(
        p * w >= 2.0 * cfg.loops.regen_min_frequency,
        &[MAX_SPEED, POLE_PAIRS],
        changed,
        "must be at least 180 rpm / pole_pairs: twice the speed of the regeneration \
         limit's 1.5 Hz (below it the trip sits in the speed estimate's noise at rest)",
    )?;
    relation(
        w * RAD_S_TO_RPM <= MAX_SPEED_OVER_COMMAND * board::MAX_SPEED_COMMAND_RPM,
        &[MAX_SPEED],
        changed,
        "must be at most 3600 rpm: twice the largest speed command (a trip far above every \
         commanded speed lets a runaway go unchecked)",
    )?;
    relation(
        p * w * cfg.loops.control_period <= 0.25 * core::f32::consts::PI,
        &[MAX_SPEED, POLE_PAIRS],
        changed,
        "pole_pairs x max_speed must be at most 37 500 rpm: a quarter electrical turn per \
         control period (the flying start's speed search)",
    )
}

/// Trips against the operating limits and the bus against the machine (all values finite
/// and positive: `DriveDesign::new` accepted them).
fn protection_bounds(cfg: &DriveConfig, changed: Option<usize>) -> Result<(), SettingError> {
    relation(
        cfg.limits.dc_bus_min >= MIN_DC_BUS_V,
        &[DC_BUS_MIN],
        changed,
        "must be at least 10 V: half the low-voltage bring-up profile's (below it the \
         under-voltage trip no longer stops switching on a collapsed supply)",
    )?;
    relation(
        cfg.limits.dc_bus_min >= MIN_BUS_WINDOW * cfg.limits.dc_bus_max,
        &[DC_BUS_MIN, DC_BUS_MAX],
        changed,
        "dc_bus_min must be at least a quarter of dc_bus_max (a wider window cannot tell \
         a collapsed bus from the supply)",
    )?;
    relation(
        cfg.limits.overcurrent_trip >= MIN_TRIP_OVER_LIMIT * cfg.limits.current_limit,
        &[OVERCURRENT_TRIP, CURRENT_LIMIT],
        changed,
        "overcurrent_trip must be at least 1.2 x current_limit (the regulated current's \
         ripple and overshoot must not reach it)",
    )?;
    relation(
        cfg.loops.flux_current >= MIN_FLUX_OVER_TRIP * cfg.limits.overcurrent_trip,
        &[FLUX_CURRENT, OVERCURRENT_TRIP],
        changed,
        "flux_current must be at least 10 % of overcurrent_trip (five times the \
         current-sensor offset the drive tolerates)",
    )?;
    relation(
        cfg.machine.stator_resistance() * cfg.limits.current_limit
            <= acim::svpwm::linear_limit(cfg.limits.dc_bus_max),
        &[STATOR_RESISTANCE, CURRENT_LIMIT, DC_BUS_MAX],
        changed,
        "stator_resistance x current_limit must be within the linear voltage at \
         dc_bus_max, dc_bus_max / sqrt 3 (the bus must drive the current limit at \
         standstill; the current-response and model checks scale with it)",
    )
}

/// The inertia and friction against the speed loop and the observer.
fn mechanical_bounds(cfg: &DriveConfig, changed: Option<usize>) -> Result<(), SettingError> {
    let m = &cfg.machine;
    let i_q = sqrt(
        cfg.limits.current_limit * cfg.limits.current_limit
            - cfg.loops.flux_current * cfg.loops.flux_current,
    );
    let torque = m.torque_constant(m.rotor_flux_for(cfg.loops.flux_current)) * i_q;
    let j = m.inertia();
    let slowest_pole = cfg
        .estimation
        .observer_poles
        .p1
        .min(cfg.estimation.observer_poles.p2)
        .min(cfg.estimation.observer_poles.p3);
    relation(
        j * cfg.limits.max_speed * slowest_pole >= torque,
        &[INERTIA, MAX_SPEED, CURRENT_LIMIT, FLUX_CURRENT],
        changed,
        "inertia too small: the run-up to max_speed at the current limit's torque must \
         take at least the observer's slowest time constant (1/120 s); faster, the rotor \
         is past the over-speed trip before the speed estimate follows",
    )?;
    relation(
        j * cfg.loops.speed_ramp <= torque,
        &[INERTIA, CURRENT_LIMIT, FLUX_CURRENT],
        changed,
        "inertia too large: the speed ramp (500 rpm/s) must need less than the torque at \
         current_limit (every ramp would end in an overload fault)",
    )?;
    relation(
        m.viscous_friction() <= slowest_pole * j,
        &[VISCOUS_FRICTION, INERTIA],
        changed,
        "viscous_friction / inertia must be at most the observer's slowest pole, 120 /s \
         (its mechanical model's Euler step and gains assume a slower friction rate)",
    )
}

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
    // f32 keeps about 7 significant digits: as many fraction digits as the integer part
    // leaves of them (so the scaled value stays below 1e7 and fits a u32)
    let mut digits = 6usize;
    let mut lim = 10.0f32;
    while digits > 0 && v.abs() >= lim {
        digits -= 1;
        lim *= 10.0;
    }
    format_digits(v, digits, true, buf)
}

/// Formats a value with exactly `decimals` fraction digits (at most 6), rounded
/// (`16.0`, `0.25`); values of 1e7 or more, and non-finite ones, print as `?`.
pub fn format_fixed(v: f32, decimals: usize, buf: &mut [u8; 24]) -> &[u8] {
    format_digits(v, decimals.min(6), false, buf)
}

/// Formats a value rounded to `significant` digits (at most 6 fraction digits), trailing
/// zeros dropped: 4 digits give `10.5`, `421.9`, `0.02345`, `1.492`; 2 give `0.81`,
/// `2.1`, `15`. Values of 1e7 or more, and non-finite ones, print as `?`.
pub fn format_significant(v: f32, significant: u32, buf: &mut [u8; 24]) -> &[u8] {
    // the decimal exponent of |v| (0 for values below 1e-6: they print as 0)
    let a = v.abs();
    let mut exp: i32 = 0;
    if a >= 1.0 {
        let mut lim = 10.0f32;
        while a >= lim && exp < 7 {
            exp += 1;
            lim *= 10.0;
        }
    } else if a > 0.0 {
        let mut lim = 1.0f32;
        while a < lim && exp > -7 {
            exp -= 1;
            lim *= 0.1;
        }
    }
    let decimals = (significant as i32 - 1 - exp).clamp(0, 6) as usize;
    format_digits(v, decimals, true, buf)
}

/// `v` rounded to `digits` fraction digits (at most 6), trailing zeros dropped if
/// `strip`; `?` for values of 1e7 or more and non-finite ones.
fn format_digits(v: f32, mut digits: usize, strip: bool, buf: &mut [u8; 24]) -> &[u8] {
    const POW10: [u32; 7] = [1, 10, 100, 1_000, 10_000, 100_000, 1_000_000];
    let a = v.abs();
    if !a.is_finite() || a >= 1e7 {
        buf[0] = b'?';
        return &buf[..1];
    }
    // at most 1e7 * 10^digits fits a u32 only while the product stays below 4.29e9
    while digits > 0 && a * POW10[digits] as f32 >= 4.0e9 {
        digits -= 1;
    }
    let scale = POW10[digits];
    let scaled = (a * scale as f32 + 0.5) as u32;
    let (mut int, mut frac) = (scaled / scale, scaled % scale);
    let mut tmp = [0u8; 24];
    let mut n = 0;
    while strip && digits > 0 && frac % 10 == 0 {
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

    /// A record of an earlier format `version`: magic, version, the first `count` values
    /// of `s`, sequence number 9, the CRC after the values.
    fn old_record(version: u16, count: usize, s: &Settings) -> [u8; RECORD_LEN] {
        let mut rec = [0u8; RECORD_LEN];
        rec[0..4].copy_from_slice(&MAGIC);
        rec[4..6].copy_from_slice(&version.to_le_bytes());
        rec[6..8].copy_from_slice(&(count as u16).to_le_bytes());
        rec[SEQ..SEQ + 4].copy_from_slice(&9u32.to_le_bytes());
        for i in 0..count {
            let at = VALUES + 4 * i;
            rec[at..at + 4].copy_from_slice(&s.get(i).to_le_bytes());
        }
        let crc_at = VALUES + 4 * count;
        let crc = crc32(&rec[..crc_at]);
        rec[crc_at..crc_at + 4].copy_from_slice(&crc.to_le_bytes());
        rec
    }

    #[test]
    fn names_are_the_configs_paths_and_the_flat_names_still_resolve() {
        for (i, f) in FIELDS.iter().enumerate() {
            let (group, name) = f.name.split_once('.').unwrap();
            assert!(
                ["machine", "limits", "loops", "estimation"].contains(&group),
                "{}",
                f.name
            );
            assert_eq!(field_index(f.name.as_bytes()), Some(i));
            assert_eq!(field_index(name.as_bytes()), Some(i), "{name}");
        }
        assert_eq!(field_index(b"loops.current_limit"), None);
        assert_eq!(field_index(b"limits."), None);
        assert_eq!(field_index(b""), None);
        // the library's machine errors name the setting's path
        let e = Settings::defaults()
            .set(idx("machine.stator_resistance"), -1.0)
            .unwrap_err();
        assert_eq!(e.field, "machine.stator_resistance");
    }

    #[test]
    fn defaults_are_this_builds_drive() {
        let s = Settings::defaults();
        let cfg = s.drive_config().unwrap();
        assert_eq!(cfg, board::drive_config());
        assert!(Drive::new(cfg).is_ok());
        assert_eq!(RECORD_LEN % 8, 0);
        assert_eq!(RECORD_LEN, 80);
    }

    #[test]
    fn round_trip_through_the_record() {
        let s = Settings::defaults()
            .set(idx("limits.current_limit"), 4.0)
            .unwrap()
            .set(idx("machine.stator_resistance"), 11.25)
            .unwrap();
        let rec = s.encode(0xFFFF_FFFE);
        assert_eq!(&rec[..4], b"ACIM");
        assert_eq!(Settings::decode_record(&rec), Ok((s, 0xFFFF_FFFE)));
        let back = Settings::decode(&rec).unwrap();
        assert_eq!(back, s);
        assert_eq!(back.get(idx("limits.current_limit")), 4.0);
        let cfg = back.drive_config().unwrap();
        assert_eq!(cfg.estimation.rs_initial, 11.25);
        // a whole page (record then erased flash) reads the same
        let mut page = [0xFFu8; SETTINGS_PAGE_BYTES as usize];
        page[..RECORD_LEN].copy_from_slice(&rec);
        assert_eq!(Settings::decode(&page), Ok(s));
    }

    #[test]
    fn every_corrupted_byte_is_refused() {
        let rec = Settings::defaults().encode(41);
        let used = CRC + 4;
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

    /// The slow task is a setting in milliseconds: 1 ms by default, 0 (off) or 0.5-2 ms,
    /// the library's rule, named; a record of the format before it keeps its values with
    /// the slow task off (the one rate those values were saved with).
    #[test]
    fn the_slow_period_is_a_setting_and_old_records_load_without_it() {
        let d = Settings::defaults();
        assert_eq!(d.get(idx("loops.slow_period")), 1.0);
        assert_eq!(d.drive_config().unwrap().loops.slow_period, 1e-3);
        let s = d.set(idx("loops.slow_period"), 2.0).unwrap();
        assert_eq!(s.drive_config().unwrap().loops.slow_period, 2e-3);
        let one_rate = d.set(idx("loops.slow_period"), 0.0).unwrap();
        assert_eq!(one_rate.drive_config().unwrap().loops.slow_period, 0.0);
        assert_eq!(Settings::decode(&s.encode(3)).unwrap(), s);
        for bad in [0.2, 3.0, -1.0, f32::NAN] {
            assert_eq!(
                d.set(idx("loops.slow_period"), bad).unwrap_err().field,
                "loops.slow_period",
                "{bad}"
            );
        }
        // the version-2 record: magic, version, 14 values, CRC after them
        let old = d.set(idx("limits.current_limit"), 4.0).unwrap();
        let loaded = old.set(idx("loops.slow_period"), 0.0).unwrap();
        assert_eq!(
            Settings::decode_record(&old_record(2, 14, &old)),
            Ok((loaded, 9))
        );
    }

    /// The observer is a setting: 0 the paper's (the default), 1 the flux observer, any
    /// other value refused with the field named; a record of the format before it loads
    /// with the paper's observer.
    #[test]
    fn the_observer_is_a_setting_and_old_records_load_with_the_papers() {
        let d = Settings::defaults();
        assert_eq!(d.get(idx("estimation.observer")), 0.0);
        let s = d.set(idx("estimation.observer"), 1.0).unwrap();
        assert_eq!(
            s.drive_config().unwrap().estimation.observer,
            ObserverChoice::Flux
        );
        assert_eq!(Settings::decode(&s.encode(3)).unwrap(), s);
        for bad in [0.5, 2.0, -1.0, f32::NAN] {
            assert_eq!(
                d.set(idx("estimation.observer"), bad).unwrap_err().field,
                "estimation.observer",
                "{bad}"
            );
        }
        // the version-3 record: magic, version, 15 values, CRC after them
        let old = d.set(idx("limits.current_limit"), 4.0).unwrap();
        assert_eq!(
            Settings::decode_record(&old_record(3, 15, &old)),
            Ok((old, 9))
        );
    }

    #[test]
    fn blank_short_wrong_version() {
        assert_eq!(Settings::decode(&[0xFF; 80]), Err(LoadError::Blank));
        assert_eq!(Settings::decode(&[0xFF; 8]), Err(LoadError::Short));
        assert_eq!(Settings::decode(&[0u8; 80]), Err(LoadError::BadMagic));
        // another version, with a CRC that matches it: still refused (version 1, the
        // single-page record without a sequence number, included; versions 2 and 3 are
        // read)
        for other in [1u16, 5] {
            let mut rec = Settings::defaults().encode(7);
            rec[4..6].copy_from_slice(&other.to_le_bytes());
            let crc = crc32(&rec[..CRC]);
            rec[CRC..CRC + 4].copy_from_slice(&crc.to_le_bytes());
            assert_eq!(Settings::decode(&rec), Err(LoadError::Version(other)));
        }
    }

    #[test]
    fn an_intact_record_with_a_refused_value_is_refused() {
        // a record written by a build with other limits: CRC good, value out of range
        let mut s = Settings::defaults();
        s.values[idx("loops.flux_current")] = 50.0;
        let e = Settings::decode(&s.encode(1)).unwrap_err();
        assert_eq!(
            e,
            LoadError::Invalid(SettingError {
                field: "loops.flux_current",
                rule: "must be below current_limit"
            })
        );
    }

    #[test]
    fn out_of_range_values_name_the_field() {
        let s = Settings::defaults();
        let cases: &[(&str, f32, &str)] = &[
            ("limits.current_limit", -1.0, "limits.current_limit"),
            ("limits.current_limit", f32::NAN, "limits.current_limit"),
            ("loops.flux_current", 6.0, "loops.flux_current"),
            ("limits.dc_bus_min", 500.0, "limits.dc_bus_max"),
            ("limits.dc_bus_max", 470.0, "limits.dc_bus_max"),
            ("limits.overcurrent_trip", 9.5, "limits.overcurrent_trip"),
            ("limits.overcurrent_trip", 3.0, "limits.overcurrent_trip"),
            ("limits.max_speed", 0.0, "limits.max_speed"),
            (
                "machine.stator_resistance",
                0.0,
                "machine.stator_resistance",
            ),
            (
                "machine.mutual_inductance",
                10.0,
                "machine.mutual_inductance",
            ),
            ("machine.pole_pairs", 2.5, "machine.pole_pairs"),
            ("machine.pole_pairs", 0.0, "machine.pole_pairs"),
            ("machine.pole_pairs", 33.0, "machine.pole_pairs"),
            ("machine.viscous_friction", -0.1, "machine.viscous_friction"),
            ("machine.inertia", f32::INFINITY, "machine.inertia"),
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
            s.set(idx("limits.current_limit"), 2.5).unwrap_err().field,
            "limits.overcurrent_trip"
        );
        let low = s
            .set(idx("limits.overcurrent_trip"), 7.0)
            .and_then(|s| s.set(idx("limits.current_limit"), 2.5))
            .and_then(|s| s.set(idx("limits.overcurrent_trip"), 4.0))
            .unwrap();
        // the bus window moves in steps that keep it within 4:1 (or `defaults
        // low-voltage`), the speed limit first (it must stay within 3 x base speed)
        let low = low
            .set(idx("limits.max_speed"), 300.0)
            .and_then(|s| s.set(idx("limits.dc_bus_min"), 100.0))
            .and_then(|s| s.set(idx("limits.dc_bus_max"), 120.0))
            .and_then(|s| s.set(idx("limits.dc_bus_min"), 30.0))
            .and_then(|s| s.set(idx("limits.dc_bus_max"), 66.0))
            .and_then(|s| s.set(idx("limits.dc_bus_min"), 20.0))
            .unwrap();
        let lv = Settings::from_config(&board::drive_config_for(&board::LOW_VOLTAGE));
        assert!(lv.drive_config().is_ok());
        for (i, f) in FIELDS.iter().enumerate() {
            let (a, b) = (low.get(i), lv.get(i));
            assert!((a - b).abs() <= 1e-5 * b.abs(), "{}: {a} vs {b}", f.name);
        }
        // both profiles' defaults are valid on this board, whichever the build
        let mains = Settings::from_config(&board::drive_config_for(&board::MAINS));
        assert!(mains.drive_config().is_ok());
    }

    /// The values an adversarial review found accepted: a rotor resistance that left the
    /// drive magnetizing for days, an under-voltage trip that could never fire, an inertia
    /// that tripped on over-speed at rest. Each is refused, naming the field; the bound
    /// values themselves are accepted.
    #[test]
    fn values_that_disable_a_protection_are_refused() {
        let s = Settings::defaults();
        let tiny = parse_value(b"0.0000001").unwrap();
        for name in [
            "machine.rotor_resistance",
            "limits.dc_bus_min",
            "machine.inertia",
        ] {
            let e = s.set(idx(name), tiny).unwrap_err();
            assert_eq!(e.field, name, "{e:?}");
        }
        // rotor time constant: 0.56 H / 10 s and 0.56 H / 1 ms
        assert!(s.set(idx("machine.rotor_resistance"), 0.057).is_ok());
        assert_eq!(
            s.set(idx("machine.rotor_resistance"), 0.05)
                .unwrap_err()
                .field,
            "machine.rotor_resistance"
        );
        assert!(s.set(idx("machine.rotor_resistance"), 560.0).is_err());
        // a relation names the field that was set
        assert_eq!(
            s.set(idx("machine.rotor_inductance"), 100.0)
                .unwrap_err()
                .field,
            "machine.rotor_inductance"
        );
        // the under-voltage trip: at least a quarter of dc_bus_max (400 V here)
        assert!(s.set(idx("limits.dc_bus_min"), 100.0).is_ok());
        assert_eq!(
            s.set(idx("limits.dc_bus_min"), 99.0).unwrap_err().field,
            "limits.dc_bus_min"
        );
        let narrow = s.set(idx("limits.dc_bus_min"), 100.0).unwrap();
        assert_eq!(
            narrow
                .set(idx("limits.dc_bus_max"), 401.0)
                .unwrap_err()
                .field,
            "limits.dc_bus_max"
        );
        // the inertia: the paper machine at 2000 rpm and 4.67 A runs up in
        // J x 209 rad/s / 10.4 N m; at least 1/120 s, and the 500 rpm/s ramp within it
        assert!(s.set(idx("machine.inertia"), 0.001).is_ok());
        assert_eq!(
            s.set(idx("machine.inertia"), 0.0003).unwrap_err().field,
            "machine.inertia"
        );
        assert!(s.set(idx("machine.inertia"), 0.15).is_ok());
        assert_eq!(
            s.set(idx("machine.inertia"), 0.25).unwrap_err().field,
            "machine.inertia"
        );
    }

    /// Every field has bounds beyond finite and positive; a refusal names the field set.
    #[test]
    fn every_field_is_bounded() {
        let s = Settings::defaults();
        let cases: &[(&str, f32)] = &[
            ("limits.dc_bus_min", 5.0),
            ("limits.dc_bus_max", 460.0),
            ("limits.current_limit", 6.8),
            ("limits.overcurrent_trip", 5.0),
            ("loops.flux_current", 0.7),
            ("limits.max_speed", 80.0),
            ("limits.max_speed", 3700.0),
            ("machine.stator_resistance", 0.05),
            ("machine.stator_resistance", 60.0),
            ("machine.rotor_resistance", 0.01),
            ("machine.stator_inductance", 200.0),
            ("machine.stator_inductance", 1.5),
            ("machine.rotor_inductance", 1.2),
            ("machine.mutual_inductance", 0.2),
            ("machine.mutual_inductance", 0.5599),
            ("machine.pole_pairs", 20.0),
            ("machine.inertia", 0.0001),
            ("machine.viscous_friction", 2.0),
        ];
        for &(name, v) in cases {
            let e = s.set(idx(name), v).unwrap_err();
            assert_eq!(e.field, name, "{name} = {v}: {e:?}");
        }
        // and values inside them are taken
        for (name, v) in [
            ("limits.dc_bus_min", 150.0),
            ("limits.dc_bus_max", 450.0),
            ("limits.current_limit", 6.0),
            ("limits.overcurrent_trip", 6.0),
            ("loops.flux_current", 0.9),
            ("limits.max_speed", 100.0),
            ("limits.max_speed", 3000.0),
            ("machine.stator_resistance", 20.0),
            ("machine.rotor_resistance", 2.0),
            ("machine.mutual_inductance", 0.5),
            ("machine.pole_pairs", 4.0),
            ("machine.inertia", 0.05),
            ("machine.viscous_friction", 0.1),
        ] {
            assert!(s.set(idx(name), v).is_ok(), "{name} = {v}");
        }
    }

    mod accepted_values {
        use super::*;
        use acim::DriveDesign;
        use proptest::prelude::*;

        /// Any value: from far below to far above every field's scale, either sign, zero
        /// and the non-finite ones.
        fn value() -> impl Strategy<Value = f32> {
            prop_oneof![
                (-8.0f32..7.0, any::<bool>())
                    .prop_map(|(e, neg)| if neg { -1.0 } else { 1.0 } * 10f32.powf(e)),
                Just(0.0),
                Just(f32::NAN),
                Just(f32::INFINITY),
            ]
        }

        fn change() -> impl Strategy<Value = (usize, f32, bool, f32)> {
            (
                0..FIELD_COUNT,
                value(),
                any::<bool>(),
                (-1.5f32..1.5).prop_map(|e| 10f32.powf(e)),
            )
        }

        /// The drive a configuration builds: magnetizing ends (settled or faulted) within
        /// a bounded time, a restart waits a bounded time, every trip stays where it can
        /// fire and above where the drive operates, and the observer stays stable.
        fn assert_protected(cfg: &DriveConfig) {
            let d = DriveDesign::new(*cfg).expect("accepted settings build a drive");
            let l = &d.limits;
            let ts = cfg.loops.control_period;
            let magnetizing_s = l.magnetizing_timeout_steps as f32 * ts;
            // Rs identification 1.5 s + inverter test 0.45 s + 10 tau_r + the search's
            // 2 tau_r, tau_r <= 10 s
            assert!(
                magnetizing_s > 0.0 && magnetizing_s <= 125.0,
                "{magnetizing_s} s"
            );
            assert!(l.demagnetize_steps as f32 * ts <= 50.0);
            // under-voltage trip: a real bus level, within 4:1 of the over-voltage trip
            assert!(l.dc_bus_min >= MIN_DC_BUS_V && l.dc_bus_min >= 0.25 * l.dc_bus_max);
            assert!(l.dc_bus_max <= BUS_FULL_SCALE_FRACTION * POWER_STAGE.bus_full_scale());
            // over-current trip: measurable, above the regulated current
            let fs = POWER_STAGE.current_full_scale();
            assert!(l.overcurrent_trip <= TRIP_FULL_SCALE_FRACTION * fs);
            assert!(l.overcurrent_trip >= MIN_TRIP_OVER_LIMIT * cfg.limits.current_limit);
            assert!(l.offset_limit <= 0.2 * cfg.loops.flux_current * 1.0001);
            // over-speed trip: above the speed targets, below a runaway, and not reached
            // from rest at full torque within the observer's slowest time constant
            let rpm = l.max_speed * RAD_S_TO_RPM;
            assert!(rpm <= 3600.0 && d.cascade.speed_target_limit < l.max_speed);
            let m = &cfg.machine;
            let torque = m.torque_constant(d.flux_reference) * d.i_sq_limit;
            assert!(torque / m.inertia() <= l.max_speed * 120.0 * 1.0001);
            // every judged time is a positive number of steps
            for steps in [
                l.stall_steps,
                l.overload_steps,
                l.implausible_steps,
                l.blind_steps,
            ] {
                assert!(steps > 0 && steps < u32::MAX / 2);
            }
            // the observer's discrete error dynamics are stable at the rated flux, and its
            // friction step is a decay
            let rseq = m.equivalent_resistance();
            assert!(d.observer.discrete_stable(d.flux_reference, rseq));
            assert!(d.observer.coeffs.ts_friction_rate < 1.0);
        }

        proptest! {
            #![proptest_config(ProptestConfig::with_cases(2000))]
            #[test]
            fn any_accepted_set_keeps_the_drive_protected(
                changes in proptest::collection::vec(change(), 1..8)
            ) {
                let mut s = Settings::defaults();
                for (i, v, scaled, k) in changes {
                    // half the values near the field's present one, the rest anywhere
                    let v = if scaled { s.get(i) * k } else { v };
                    if let Ok(next) = s.set(i, v) {
                        s = next;
                        assert_protected(&s.drive_config().unwrap());
                    }
                }
            }
        }
    }

    /// The linker never places code or data in the settings pages, and both are the last
    /// two 2 KiB pages of bank 2 of the 512 KiB part (the factory dual-bank mode).
    #[test]
    fn memory_x_leaves_the_settings_pages_out() {
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
            SETTINGS_ADDR + SETTINGS_PAGES * SETTINGS_PAGE_BYTES,
            0x0800_0000 + 512 * 1024
        );
        assert_eq!(
            SETTINGS_ADDR,
            0x0804_0000 + SETTINGS_PAGE_NUMBER as u32 * SETTINGS_PAGE_BYTES
        );
        // bank 2 has 128 pages of 2 KiB (PNB is 7 bits): both page numbers exist
        assert!(SETTINGS_PAGE_NUMBER as u32 + SETTINGS_PAGES <= 128);
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

    #[test]
    fn fixed_and_significant_formats() {
        let mut buf = [0u8; 24];
        for (v, d, text) in [
            (16.0f32, 1, "16.0"),
            (16.04, 1, "16.0"),
            (16.05, 1, "16.1"),
            (0.25, 2, "0.25"),
            (-0.25, 1, "-0.3"),
            (-0.04, 1, "0.0"),
            (2.0, 0, "2"),
            (1234.5, 2, "1234.50"),
            (f32::INFINITY, 1, "?"),
        ] {
            assert_eq!(
                core::str::from_utf8(format_fixed(v, d, &mut buf)).unwrap(),
                text,
                "{v} {d}"
            );
        }
        for (v, sig, text) in [
            (10.497f32, 4, "10.5"),
            (421.93, 4, "421.9"),
            (0.023449, 4, "0.02345"),
            (1.49234, 4, "1.492"),
            (7.2134, 4, "7.213"),
            (0.81234, 2, "0.81"),
            (2.0512, 2, "2.1"),
            (15.3, 2, "15"),
            (150.2, 2, "150"),
            (-0.0021, 3, "-0.0021"),
            (0.0, 4, "0"),
            (1e-9, 4, "0"),
            (9.9996, 4, "10"),
            (f32::NAN, 4, "?"),
        ] {
            assert_eq!(
                core::str::from_utf8(format_significant(v, sig, &mut buf)).unwrap(),
                text,
                "{v} {sig}"
            );
        }
    }
}
