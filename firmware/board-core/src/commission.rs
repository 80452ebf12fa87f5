//! The `commission` command: the library's self-commissioning
//! ([`acim::commissioning::Commissioning`]) run by the control loop on a nameplate the
//! user types, and its result written into the settings.
//!
//! The sequence and its checks are the library's: current-sensor offsets,
//! DC steps for Rs and the inverter's voltage error, two standstill impedance tests for
//! R_R, L_sigma and L_M, and a V/f no-load test (**the rotor turns**, up to 80 % of the
//! rated frequency) for L_M at rated flux, the rated flux current, J and friction. It runs
//! in the control interrupt, one step per period ([`crate::control::ControlLoop`]); the
//! fits ([`Commissioning::identify`], a bisection) run in the main loop once it is done.
//!
//! What commissioning writes ([`settings_from`]): the machine model (Rs, Rr, Ls, Lr, Lm
//! from the inverse-Gamma model, pole pairs from the nameplate, J and friction), the flux
//! current (the no-load current at rated volts per hertz), and the limits **only where
//! the nameplate is tighter**: current limit at most the rated peak current, trip at most
//! [`acim::nameplate::TRIP_OVER_LIMIT`] times it, speed limit at most
//! [`acim::nameplate::SPEED_LIMIT_OVER_RATED`] times the synchronous speed. The bus window
//! stays the user's. It selects the flux observer (`estimation.observer` 1,
//! [`acim::flux_observer`]), as the library's nameplate configuration does
//! ([`acim::nameplate`]): its gain is designed stable while regenerating near zero stator
//! frequency, where the paper's observer needs the regeneration limit, and it is the
//! observer the nameplate path is measured with (`docs/low-speed.md`,
//! `docs/peer-benchmark.md`). `set estimation.observer 0` goes back to the paper's.
//!
//! A finished sequence becomes an [`Outcome`] ([`outcome`]): the identified values with
//! the library's bound on each one's error ([`acim::commissioning::Confidence`]) and the
//! settings they make, checked against the nameplate and validated as a whole. Those
//! settings wait for `commission apply` ([`crate::dispatch`]); nothing changes before it,
//! and nothing is saved until `save`. A result that fails a check is never applied.

use crate::board::{CONTROL_PERIOD_S, DEAD_TIME_NS, POWER_STAGE};
use crate::settings::{observer_value, SettingError, Settings, FIELD_COUNT, OBSERVER};
use acim::commissioning::{CommissioningError, Confidence, Identified, Stage};
use acim::math::RAD_S_TO_RPM;
use acim::nameplate::{
    Board, Nameplate, NameplateError, RatedPoint, SPEED_LIMIT_OVER_RATED, TRIP_OVER_LIMIT,
};
use acim::{InverseGamma, MachineParams};

pub use acim::commissioning::Commissioning;

/// The numbers of `commission <P W> <V rms> <I rms> <f Hz> <rpm>`, in that order: rated
/// output power (W), line-to-line voltage (V rms), line current (A rms), frequency (Hz)
/// and speed (rpm), as printed on the nameplate (pole pairs follow from speed and
/// frequency).
pub type NameplateArgs = [f32; 5];

/// The power stage's device on-state drop assumed by the dead-time estimate, V.
pub const DEVICE_DROP_V: f32 = 1.0;

/// Fraction of the current-sense full scale commissioning's own trip may use (as the
/// settings' trip, [`crate::settings::TRIP_FULL_SCALE_FRACTION`]).
pub const TRIP_FULL_SCALE_FRACTION: f32 = crate::settings::TRIP_FULL_SCALE_FRACTION;

/// The nameplate of the command's numbers.
pub fn nameplate(args: &NameplateArgs) -> Nameplate {
    Nameplate {
        power_w: args[0],
        voltage_v: args[1],
        current_a: args[2],
        frequency_hz: args[3],
        speed_rpm: Some(args[4]),
        power_factor: None,
        pole_pairs: None,
    }
}

/// This board as commissioning sees it, with the bus it measured (V) as the nominal bus
/// (commissioning trips when the bus leaves 0.6-1.25 of it).
pub fn board(dc_bus: f32) -> Board {
    Board {
        dc_bus_v: dc_bus,
        current_full_scale_a: POWER_STAGE.current_full_scale(),
        bus_full_scale_v: POWER_STAGE.bus_full_scale(),
        pwm_frequency_hz: 1.0 / CONTROL_PERIOD_S,
        dead_time_s: DEAD_TIME_NS as f32 * 1e-9,
        device_drop_v: DEVICE_DROP_V,
    }
}

/// Builds the sequence for `args` on this board with the bus `dc_bus` (V), in the main
/// loop: the interrupt only starts it ([`crate::control::ControlLoop::stage_commissioning`],
/// then [`crate::control::ControlCommand::Commission`]), so the construction (a nameplate's
/// rated point and the sequence's design) runs from flash, not in the control interrupt's
/// CCM SRAM. `None`: the library refused the nameplate or the board.
pub fn build(args: &NameplateArgs, dc_bus: f32) -> Option<Commissioning> {
    Commissioning::new(&nameplate(args), &board(dc_bus)).ok()
}

fn nameplate_error(e: NameplateError) -> SettingError {
    match e {
        NameplateError::Invalid { field, rule } => SettingError { field, rule },
        NameplateError::Config(c) => c.into(),
    }
}

/// Checks a `commission` request before it reaches the interrupt: a consistent nameplate,
/// the measured bus (V) inside the settings' window, and commissioning's trip (1.75 times
/// the rated peak current) inside the current sense. Returns the rated point.
pub fn check(
    args: &NameplateArgs,
    dc_bus: f32,
    settings: &Settings,
) -> Result<RatedPoint, SettingError> {
    let rated = nameplate(args).rated().map_err(nameplate_error)?;
    let (lo, hi) = (settings.get(0), settings.get(1));
    if !(dc_bus >= lo && dc_bus <= hi) {
        return Err(SettingError {
            field: "dc_bus",
            rule: "the measured bus must be inside dc_bus_min..dc_bus_max to commission",
        });
    }
    // rated.current is finite and positive (rated() checked it)
    if TRIP_OVER_LIMIT * rated.current > TRIP_FULL_SCALE_FRACTION * POWER_STAGE.current_full_scale()
    {
        return Err(SettingError {
            field: "nameplate.current_a",
            rule: "1.75 times its peak must stay inside 90 % of the current-sense full scale",
        });
    }
    Ok(rated)
}

/// The settings after commissioning: `current` with the identified machine, the rated
/// flux current, the nameplate's tighter limits and the flux observer (module docs),
/// validated as a whole.
/// An unresolved inertia keeps the present value.
pub fn settings_from(
    id: &Identified,
    rated: &RatedPoint,
    current: &Settings,
) -> Result<Settings, SettingError> {
    let m = MachineParams::from_inverse_gamma(InverseGamma {
        stator_resistance: id.stator_resistance,
        rotor_resistance: id.rotor_resistance,
        leakage_inductance: id.leakage_inductance,
        magnetizing_inductance: id.magnetizing_inductance,
        pole_pairs: rated.pole_pairs,
        inertia: id.inertia.unwrap_or(current.get(12)),
        viscous_friction: id.viscous_friction.max(0.0),
    })?;
    let mut v = [0.0f32; FIELD_COUNT];
    for (i, x) in v.iter_mut().enumerate() {
        *x = current.get(i);
    }
    v[2] = v[2].min(rated.current);
    v[3] = v[3].min(TRIP_OVER_LIMIT * rated.current);
    v[4] = id.rated_flux_current;
    v[5] = v[5].min(SPEED_LIMIT_OVER_RATED * rated.synchronous_speed * RAD_S_TO_RPM);
    v[6] = m.stator_resistance();
    v[7] = m.rotor_resistance();
    v[8] = m.stator_inductance();
    v[9] = m.rotor_inductance();
    v[10] = m.mutual_inductance();
    v[11] = m.pole_pairs() as f32;
    v[12] = m.inertia();
    v[13] = m.viscous_friction();
    // the flux observer, as the library's nameplate configuration chooses it (module docs)
    v[OBSERVER] = observer_value(acim::ObserverChoice::Flux);
    Settings::from_values(v)
}

/// Where an accepted result stands.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Decision {
    /// Waiting for `commission apply`.
    Pending,
    /// Its settings replaced the drive's.
    Applied,
    /// Dropped: a start, vf, set or defaults came before `commission apply`.
    Discarded,
}

/// An accepted result: what was identified, how sure, and the settings `commission
/// apply` writes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Proposal {
    /// The identified model.
    pub identified: Identified,
    /// The bound on each quantity's relative error.
    pub confidence: Confidence,
    /// The settings made from it and the settings in use when it finished
    /// ([`settings_from`]), validated as a whole.
    pub settings: Settings,
    /// How long the sequence ran, s.
    pub seconds: f32,
    /// Applied, waiting, or dropped.
    pub decision: Decision,
}

/// How the last commissioning ended.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Outcome {
    /// Identified, every check passed, the settings valid: see [`Proposal::decision`].
    Identified(Proposal),
    /// The sequence failed, or a check refused the result
    /// ([`CommissioningError::Implausible`]).
    Failed(CommissioningError),
    /// The settings made from the result were refused by their validation.
    Refused(SettingError),
    /// Stopped (fault code 0) or abandoned by a trip (its fault code).
    Aborted(u8),
}

/// The outcome of the finished sequence `c` run on `args` (the fits, a bisection: in the
/// main loop, not in the interrupt), with `current` the settings in use and `seconds` its
/// duration. Only a result that passes every check of [`Commissioning::assess`] and whose
/// settings pass their validation is an [`Outcome::Identified`], and that is pending.
#[inline(never)]
pub fn outcome(
    c: &Commissioning,
    args: Option<&NameplateArgs>,
    current: &Settings,
    seconds: f32,
) -> Outcome {
    let a = match c.assess() {
        Ok(a) => a,
        Err(e) => return Outcome::Failed(e),
    };
    if let Some(refused) = a.refusal() {
        return Outcome::Failed(CommissioningError::Implausible(refused.concern));
    }
    let Some(rated) = args.and_then(|a| nameplate(a).rated().ok()) else {
        return Outcome::Refused(SettingError {
            field: "nameplate",
            rule: "missing",
        });
    };
    match settings_from(&a.identified, &rated, current) {
        Err(e) => Outcome::Refused(e),
        Ok(settings) => Outcome::Identified(Proposal {
            identified: a.identified,
            confidence: a.confidence,
            settings,
            seconds,
            decision: Decision::Pending,
        }),
    }
}

/// The stage's name in the `commission` progress reply.
pub fn stage_name(s: Stage) -> &'static str {
    match s {
        Stage::Offsets => "sensor offsets (switches off)",
        Stage::DcStep(_) => "DC steps (Rs, inverter error)",
        Stage::ImpedanceLow => "standstill impedance, low frequency",
        Stage::ImpedanceHigh => "standstill impedance, rated frequency",
        Stage::NoLoad => "no-load V/f test (the rotor turns)",
        Stage::Done => "done, fitting",
        Stage::Failed(_) => "failed",
    }
}

/// The reason in the `commission` failure reply.
pub fn error_text(e: CommissioningError) -> &'static str {
    match e {
        CommissioningError::NonFiniteInput => "a current or bus sample was not finite",
        CommissioningError::OverCurrent => "over-current (beyond 1.75 times the rated peak)",
        CommissioningError::DcBus => "the bus left 0.6-1.25 of its value at the start",
        CommissioningError::MotorNotConnected => {
            "the current did not follow: motor not connected or a phase open"
        }
        CommissioningError::SensorOffset => "a current-sensor offset beyond 2 % of the trip",
        CommissioningError::ResultOutOfRange(f) => f,
        CommissioningError::PoorFit(f) => f,
        CommissioningError::Implausible(c) => c.reason(),
    }
}

/// A second line for the two errors that name a field: what went wrong with it.
pub fn error_detail(e: CommissioningError) -> Option<&'static str> {
    match e {
        CommissioningError::ResultOutOfRange(_) => Some("result outside its plausible range"),
        CommissioningError::PoorFit(_) => {
            Some("the DC steps are not on a line: the rotor moved or the inverter error varies")
        }
        CommissioningError::Implausible(c) => Some(c.advice()),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The paper's machine (shared/machines/paper-750w.toml).
    const PAPER: NameplateArgs = [750.0, 230.0, 3.3, 50.0, 1500.0];

    #[test]
    fn a_request_is_checked_before_the_interrupt_sees_it() {
        let s = Settings::defaults();
        let r = check(&PAPER, 325.0, &s).unwrap();
        assert_eq!(r.pole_pairs, 2);
        // P >= sqrt(3) V I
        let e = check(&[2000.0, 230.0, 3.3, 50.0, 1500.0], 325.0, &s).unwrap_err();
        assert_eq!(e.field, "nameplate.power_w");
        // speed above synchronous for every pole count is caught as a pole/speed rule
        let e = check(&[750.0, 230.0, 3.3, 50.0, 3100.0], 325.0, &s).unwrap_err();
        assert_eq!(e.field, "nameplate.speed_rpm");
        // the bus outside the window (not powered)
        let e = check(&PAPER, 5.0, &s).unwrap_err();
        assert_eq!(e.field, "dc_bus");
        // a motor whose trip the 10 A sense cannot carry
        let e = check(&[2200.0, 400.0, 4.9, 50.0, 1430.0], 325.0, &s).unwrap_err();
        assert_eq!(e.field, "nameplate.current_a");
    }

    #[test]
    fn the_result_replaces_the_machine_and_only_tightens_limits() {
        let s = Settings::defaults();
        let rated = check(&PAPER, 325.0, &s).unwrap();
        // the paper's inverse-Gamma model, as the machine file gives it
        let id = Identified {
            stator_resistance: 10.5,
            rotor_resistance: 7.810714,
            leakage_inductance: 0.039286,
            magnetizing_inductance: 0.520714,
            magnetizing_inductance_small_signal: 0.520714,
            rated_flux_current: 1.2,
            inverter_error: 3.0,
            dead_time: 1.4e-6,
            dc_fit_residual: 0.001,
            inertia: None,
            viscous_friction: 0.002,
        };
        let n = settings_from(&id, &rated, &s).unwrap();
        assert_eq!(n.get(6), 10.5);
        assert_eq!(n.get(4), 1.2);
        assert_eq!(
            n.get(12),
            s.get(12),
            "an unresolved inertia keeps the setting"
        );
        assert!(n.get(2) <= s.get(2) && n.get(3) <= s.get(3) && n.get(5) <= s.get(5));
        assert_eq!((n.get(0), n.get(1)), (s.get(0), s.get(1)));
        // the nameplate's observer: the flux observer, from the defaults' paper observer
        assert_eq!(
            (s.get(OBSERVER), n.get(OBSERVER)),
            (
                observer_value(acim::ObserverChoice::Reduced),
                observer_value(acim::ObserverChoice::Flux)
            )
        );
        // the T-model carries the same inverse-Gamma model
        let m = MachineParams::new(acim::MachineData {
            stator_resistance: n.get(6),
            rotor_resistance: n.get(7),
            stator_inductance: n.get(8),
            rotor_inductance: n.get(9),
            mutual_inductance: n.get(10),
            pole_pairs: 2,
            inertia: n.get(12),
            viscous_friction: n.get(13),
        })
        .unwrap();
        assert!((m.referred_rotor_resistance() - 7.810714).abs() < 1e-3);
        assert!((m.transient_inductance() - 0.039286).abs() < 1e-5);
        // a model the drive refuses names the field
        let bad = Identified {
            rated_flux_current: 50.0,
            ..id
        };
        assert!(settings_from(&bad, &rated, &s).is_err());
    }
}
