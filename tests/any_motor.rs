//! Any motor: each acceptance machine
//! (`crates/acim-sim/machines/`) is commissioned from its nameplate and board alone
//! against its plant (realistic sensors and inverter), the drive is built from the
//! identified model only, and it runs the acceptance scenarios closed loop
//! (`acim_sim::machines`). Acceptance: no fault, steady speed-estimation error and speed
//! error at most 1 % of rated speed in every window.

use acim_sim::machines::{prepare, MACHINES};

fn accept(which: usize) {
    for m in MACHINES.iter() {
        let (_, scenarios, rated_rpm) = prepare(m).unwrap_or_else(|e| panic!("{e}"));
        let sc = &scenarios[which];
        let (_, r) = acim_sim::run_with_metrics(sc).unwrap();
        assert_eq!(
            r.fault, None,
            "{}: {:?} at {:?}",
            sc.name, r.fault, r.fault_time_s
        );
        for (w, wm) in &r.windows {
            let bound = 0.01 * rated_rpm;
            assert!(
                wm.speed_est_err_max_rpm <= bound && wm.speed_err_max_rpm <= bound,
                "{} {w}: estimate {} / speed {} rpm off (1 % of rated is {bound})",
                sc.name,
                wm.speed_est_err_max_rpm,
                wm.speed_err_max_rpm
            );
        }
    }
}

/// Start to 1/3 rated speed, a rated-load step (held), the load off, a reversal.
#[test]
fn start_rated_load_step_and_reversal() {
    // TI's bare rotor (J = 0.001 kg m^2, 3 300 rad/s^2 at rated torque) included: its
    // speed loop follows its mechanical start time (`acim::nameplate::RATED_STEP_DIP`)
    accept(0);
}

/// A trapezoid at 3 % of the rated speed.
#[test]
fn trapezoid_at_3_percent_of_rated_speed() {
    accept(1);
}

/// Regeneration: an overhauling load of 70 % rated torque at 1/3 rated speed.
#[test]
fn regeneration_at_70_percent_rated_torque() {
    accept(2);
}

/// Rated load applied and removed, motoring and regenerating, at 10, 50 and 100 % of
/// rated speed on every machine of the load-step set (`acim_sim::load_steps::MACHINES`:
/// the acceptance machines and a 4 kW class motor), each with a catalogue inertia for
/// its rating (`acim::commissioning::catalogue_inertia`), commissioned from its
/// nameplate and driven with the identified model (the default drive: the flux
/// observer). No fault; the dip (applied) and the overshoot (removed) within the speed
/// loop's designed response, T_rated / (2 alpha J); below rated speed the speed and its
/// estimate back within 1 % of rated speed in 4 / alpha (`docs/load-steps.md`).
/// Measured: dips 3.3-13.0 % of rated speed (57-179 rpm against bounds of 122-213; the
/// 0.18 kW machine's loop is capped by the observer's rate limit), back in 0.03-0.06 s
/// against 0.06-0.16, the estimate 16-68 rpm off and back within 0.04 s (0.43 s once, at
/// rated speed). (The paper's observer: outside the bounds in every case, and five faults:
/// `SpeedOscillation`, `Overload`, `CurrentSensor` twice, `EstimatorOutOfRange`.)
#[test]
fn rated_load_applied_and_removed_on_every_machine() {
    use acim_sim::load_steps::{cases, prepare, MACHINES};
    let mut run = |sc: &acim_sim::scenario::Scenario| {
        let (r, m) = acim_sim::run_with_metrics(sc).map_err(|e| format!("{}: {e}", sc.name))?;
        Ok((r.rows, m))
    };
    let mut failures = Vec::new();
    for m in &MACHINES {
        let p = prepare(m).unwrap_or_else(|e| panic!("{e}"));
        for c in cases(&p, &[], &mut run).unwrap() {
            if let Some(why) = c.failure() {
                failures.push(format!(
                    "{} at {:.0} rpm, {:+.1} N m: {why}",
                    c.machine, c.rpm, c.load_nm
                ));
            }
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// Low speed under rated load on every machine of the load-step set, commissioned from
/// its nameplate and driven with the identified model (the default drive: the flux
/// observer; `acim_sim::low_speed`, `docs/low-speed.md`): rated motoring load at 3, 2, 1
/// and 0 % of the synchronous speed n_s held within 0.33 % of n_s; 25, 50 and 100 %
/// rated overhauling load at 1 % of n_s held within 2 % of n_s with the regeneration limit
/// not acting; the controller's L_M -/+15 %, R_R -/+30 % (plus the slip's error it
/// implies) and Rs -/+20 % at rated load, motoring at 5 and 50 % of n_s and regenerating
/// at 50 %, held within 2 % of n_s or ended by a clean fault (or refused at
/// configuration). The regenerating parameter errors at 5 % of n_s, which the page shows
/// and does not assert on every machine, are asserted on the machines of the project's
/// shared acceptance set (`acim_sim::low_speed::SHARED_ACCEPTANCE`: the paper's, the TI benchmark's and
/// motulator's 2.2 kW machine). Measured: 218 of 218; the page's other regenerating
/// parameter errors 28 of 30 (the 0.18 kW machine with R_R -30 % and Rs -20 %:
/// `acim::rs_estimator`, "Down to zero stator frequency").
#[test]
fn low_speed_under_rated_load_on_every_machine() {
    use acim_sim::load_steps::{prepare, MACHINES};
    use acim_sim::low_speed::cases;
    let mut run = |sc: &acim_sim::scenario::Scenario| {
        let (r, m) = acim_sim::run_with_metrics(sc).map_err(|e| format!("{}: {e}", sc.name))?;
        Ok((r.rows, m))
    };
    let mut failures = Vec::new();
    let mut asserted = 0;
    for m in &MACHINES {
        let p = prepare(m).unwrap_or_else(|e| panic!("{e}"));
        for c in cases(&p, &mut run).unwrap() {
            if !c.asserted {
                continue;
            }
            asserted += 1;
            if let Some(why) = c.failure() {
                failures.push(format!(
                    "{} {} at {:.1} rpm, {:+.2} N m: {why}",
                    c.machine,
                    c.error.label(),
                    c.rpm,
                    c.load_nm
                ));
            }
        }
    }
    assert_eq!(asserted, 218);
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// An inductance error while regenerating rated load near zero stator frequency (5 % of
/// the synchronous speed: 0.16 Hz on motulator's 2.2 kW machine). The standstill Rs
/// carries the inverter test's error, whose flux-rate correction uses the controller's
/// rotor model (3.63 against 3.70 ohm there with L_M 15 % high), and the flux observer
/// needs Rs to about a per cent at this point: while the running Rs law stopped at 1 Hz
/// the rotor ran 73 rpm (2.2 kW), 40 rpm (7.5 kW) and 39 rpm (37 kW, whose Rs/L_M of
/// 0.36 Hz also closed the law's band) ahead of the target. The law adapts down to zero
/// stator frequency with the flux observer and a torque current at least the flux
/// current (`acim::rs_estimator`, "Down to zero stator frequency"): mean errors -0.4,
/// +12.2 and +23.9 rpm with L_M +15 %; +1.1 (2.2 kW) and -16.5 rpm (37 kW) with -15 %
/// (the 7.5 kW machine's nameplate refuses that model at configuration, a clean fault),
/// within the page's 2 % of n_s (30 and 36 rpm) at every sample of the last second.
#[test]
fn inductance_errors_regenerating_near_zero_stator_frequency_are_held() {
    use acim_sim::load_steps::{prepare, MACHINES};
    use acim_sim::low_speed::{
        last_second, scenario, synchronous_rpm, ParameterError, ERROR_SPEEDS, HOLD_TOLERANCE,
    };
    for name in ["motulator-2k2", "simscape-7k5", "krause-50hp"] {
        let m = MACHINES.iter().find(|m| m.name == name).unwrap();
        let p = prepare(m).unwrap_or_else(|e| panic!("{e}"));
        let ns = synchronous_rpm(&p.identified).unwrap();
        let rpm = ERROR_SPEEDS[0] * ns;
        for k in [0.85, 1.15] {
            let mut base = p.identified.clone();
            base.controller = ParameterError::MagnetizingInductance(k).apply(&base.controller);
            let sc = scenario(&base, rpm, -p.rated_nm, 1.0, 1.0);
            if sc.validate().is_err() {
                continue;
            }
            let (r, metrics) = acim_sim::run_with_metrics(&sc).unwrap();
            assert_eq!(metrics.fault, None, "{name} L_M x{k}");
            // the largest deviation over the last second, as the page judges it
            let (mean, deviation, _, limited) = last_second(&r.rows, sc.duration_s, rpm);
            assert!(!limited, "{name} L_M x{k}");
            assert!(
                deviation <= HOLD_TOLERANCE * ns,
                "{name} L_M x{k}: {deviation} rpm off (mean {mean} against {rpm})"
            );
        }
    }
}

/// The flux observer at a start with Rs wrong: the 0.18 kW machine (its flux current is
/// below the inverter test's minimum, so no test presets Rs), the controller's Rs 20 %
/// high, rated load at half the synchronous speed. The standstill identification finds Rs
/// (48.85 against 48.90 ohm) before the handover, but while it converged the observer's
/// voltage model, left to itself with the frame held, was drained by the resistance error
/// and turned away from the frame: at the handover its adapted speed ran off at its rate
/// bound and the drive tripped `LossOfControl` 10 ms later. With the estimate held on the
/// drive's flux model while the frame is held (`acim::flux_observer`), it holds: measured
/// 0.7 rpm off.
#[test]
fn a_start_with_rs_wrong_hands_over_to_the_flux_observer_cleanly() {
    use acim_sim::load_steps::{prepare, MACHINES};
    use acim_sim::low_speed::{scenario, synchronous_rpm, ParameterError};
    let m = MACHINES.iter().find(|m| m.name == "emwb-180w").unwrap();
    let p = prepare(m).unwrap_or_else(|e| panic!("{e}"));
    let mut base = p.identified.clone();
    base.controller = ParameterError::StatorResistance(1.2).apply(&base.controller);
    let ns = synchronous_rpm(&base).unwrap();
    for sign in [1.0f32, -1.0] {
        let sc = scenario(&base, 0.5 * ns, sign * p.rated_nm, 1.0, 1.0);
        let (r, metrics) = acim_sim::run_with_metrics(&sc).unwrap();
        assert_eq!(metrics.fault, None, "{}", sc.name);
        let (_, deviation, _, _) =
            acim_sim::low_speed::last_second(&r.rows, sc.duration_s, 0.5 * ns);
        assert!(deviation < 0.02 * ns, "{}: {deviation} rpm", sc.name);
    }
}
