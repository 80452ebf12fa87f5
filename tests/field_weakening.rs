//! The whole speed range: field weakening on the paper machine at 325 V up to
//! 3000 rpm (2x its nameplate speed, about 2.9x the no-load base speed at rated flux),
//! the reachable speed held and reported, braking without a brake resistor on a 470 uF
//! link with the over-voltage control. Scenarios in `acim_sim::builtins` (`fw-*`).
//!
//! Measured (f32, `cargo run --release -p acim-sim -- run <name>`): see the numbers in
//! each test. The required 0.5 % steady speed error at 3000 rpm is met since the sense
//! stage removes the current ripple a boundary sample carries (`DriveCoeffs::
//! sample_ripple`): before, the true speed ran 1.2 % above the estimate there (the flux
//! model read i_sd 2 % high at 0.22 Wb).

use acim_sim::metrics::Metrics;
use acim_tests::run;

fn kept(m: &Metrics) {
    assert!(m.control_kept, "{}: control lost: {m:#?}", m.name);
    assert!(m.fault.is_none(), "{}: fault {:?}", m.name, m.fault);
}

/// No-load reversal +3000 -> -3000 rpm: both directions reach the target (window means
/// 3036.5 and -3036.9 rpm measured), control kept, no fault.
#[test]
fn reversal_at_twice_nameplate_speed() {
    let m = run("fw-reversal-3000", &[]);
    kept(&m);
    let f = &m.windows["forward"];
    let r = &m.windows["reverse"];
    assert!(f.speed_mean_rpm > 2985.0, "{f:?}");
    assert!(r.speed_mean_rpm < -2985.0, "{r:?}");
    // the flux is weakened to below a third of its rated 0.78 Wb
    assert!(f.rotor_flux_true_min < 0.26, "{f:?}");
}

/// Ramp to 3000 rpm against a 1 N m passive load plus 2e-3 N m s/rad friction (1.63 N m
/// at 3000 rpm, above the 1.42 N m the machine equations allow there with the linear
/// modulation limit): the drive holds the speed it can reach (2336 rpm measured), keeps
/// control and does not trip.
#[test]
fn ramp_with_load_holds_the_reachable_speed() {
    let m = run("fw-ramp-3000", &[]);
    kept(&m);
    let w = &m.windows["steady"];
    assert!(
        w.speed_mean_rpm > 2200.0 && w.speed_mean_rpm < 3000.0,
        "{w:?}"
    );
    // held: the reference stays with the speed instead of running away to 3000 rpm
    assert!(w.speed_err_max_rpm < 60.0, "{w:?}");
}

/// A target of 3200 rpm with 1.2 N m: held at the reachable speed (2146 rpm measured),
/// reported (telemetry `speed_target_limited`), control kept.
#[test]
fn unreachable_target_is_held() {
    let m = run("fw-unreachable-3200", &[]);
    kept(&m);
    let w = &m.windows["held"];
    assert!(
        w.speed_mean_rpm > 1900.0 && w.speed_mean_rpm < 3000.0,
        "{w:?}"
    );
    assert!(w.speed_err_max_rpm < 60.0, "{w:?}");
}

/// 0.8 N m load step at 2500 rpm (with friction about 90 % of the torque the drive holds
/// there): held at 2500 rpm, control kept.
#[test]
fn load_step_at_2500_rpm() {
    let m = run("fw-load-step-2500", &[]);
    kept(&m);
    for (name, w) in &m.windows {
        assert!((w.speed_mean_rpm - 2500.0).abs() < 40.0, "{name}: {w:?}");
    }
}

/// Braking from 3000 rpm at up to 2000 rpm/s on 470 uF without a brake resistor: the
/// over-voltage control keeps the bus below the 400 V trip (peak 389.9 V measured) and
/// the drive does not trip. The regenerated power is limited to the losses, so the speed
/// falls at about 500 rpm/s with the reference held at it; the rotor stops at about
/// 13.3 s (window `stopped`: |speed| below 5 rpm). The ramp up at 2000 rpm/s is held at
/// the torque the weakened flux allows: control kept (|speed - ref| below 100 rpm in
/// 10 ms means) and the speed overshoots 3000 rpm by 18 rpm (78 rpm, and a 138 rpm lag
/// on the way up, while the speed PI's gain was not scaled with the flux).
#[test]
fn braking_from_3000_rpm_stays_below_the_overvoltage_trip() {
    let sc = acim_sim::builtins::get("fw-braking-3000").unwrap();
    let (r, m) = acim_sim::run_with_metrics(&sc).unwrap();
    kept(&m);
    let peak = r.rows.iter().map(|x| x.dc_bus_v).fold(0.0f32, f32::max);
    assert!(peak < sc.drive.limits.dc_bus_max_v, "bus peak {peak} V");
    let top = r.rows.iter().map(|x| x.speed_rpm).fold(0.0f32, f32::max);
    assert!(top < 3030.0, "overshoot to {top} rpm");
    let stopped = &m.windows["stopped"];
    assert!(stopped.speed_mean_rpm.abs() < 5.0, "{stopped:?}");
}

/// The same braking without the over-voltage control trips on over-voltage: the control
/// is what keeps the bus down.
#[test]
fn braking_without_overvoltage_control_trips() {
    let m = run(
        "fw-braking-3000",
        &["drive.field_weakening.overvoltage_control=false"],
    );
    assert_eq!(m.fault.as_deref(), Some("DcBusOverVoltage"), "{m:#?}");
}

/// Fixed point (Q7.24) keeps control through the reversal as f32 does.
#[test]
fn fixed_point_reversal() {
    let m = run("fw-reversal-3000", &["drive.arithmetic=\"fixed\""]);
    kept(&m);
    assert!(m.windows["forward"].speed_mean_rpm > 2985.0);
}

/// The acceptance: steady speed error at most 0.5 % of the reference at
/// 3000 rpm (15 rpm), on the paper machine and the 2.2 kW machine, and at 2500 rpm
/// through the load step (12.5 rpm). Measured: 4.35 / 5.55 rpm (paper machine, forward /
/// reverse), 5.08 / 3.73 rpm (2.2 kW), 4.72 / 4.21 rpm (2500 rpm, before / after the
/// step); 37.6 / 37.8 rpm on the paper machine before the ripple correction, 3.71 / 4.52
/// before the speed PI's gain followed the flux (a higher gain on the estimate's noise).
#[test]
fn steady_speed_error_within_half_a_percent() {
    for name in ["fw-reversal-3000", "fw-2k2-reversal-3000"] {
        let m = run(name, &[]);
        for w in m.windows.values() {
            assert!(w.speed_err_max_rpm <= 15.0, "{name}: {w:?}");
        }
    }
    let m = run("fw-load-step-2500", &[]);
    for w in m.windows.values() {
        assert!(w.speed_err_max_rpm <= 12.5, "{w:?}");
    }
}

/// The 2.2 kW machine (`../shared/machines/motulator-2k2.toml`) from its nameplate on
/// 540 V: reversal +3000 -> -3000 rpm, 2x its base speed (window means 3044.5 and
/// -3043.6 rpm measured, flux down to 0.40 Wb), control kept.
#[test]
fn machine_2k2_reversal_at_twice_base_speed() {
    let m = run("fw-2k2-reversal-3000", &[]);
    kept(&m);
    assert!(m.windows["forward"].speed_mean_rpm > 2985.0, "{m:#?}");
    assert!(m.windows["reverse"].speed_mean_rpm < -2985.0, "{m:#?}");
}

/// The 2.2 kW machine braking from 3000 rpm to 0 on 470 uF with the over-voltage
/// control: bus peak below the drive's over-voltage trip (657.7 V measured), stopped.
#[test]
fn machine_2k2_braking_stays_below_the_overvoltage_trip() {
    let sc = acim_sim::builtins::get("fw-2k2-braking-3000").unwrap();
    let (r, m) = acim_sim::run_with_metrics(&sc).unwrap();
    kept(&m);
    let peak = r.rows.iter().map(|x| x.dc_bus_v).fold(0.0f32, f32::max);
    assert!(
        peak < r.config.limits.dc_bus_max,
        "bus peak {peak} V vs {}",
        r.config.limits.dc_bus_max
    );
    assert!(r.rows.last().unwrap().speed_rpm.abs() < 20.0);
}

/// A rippling bus (+/-10 % at 100 Hz, a rectifier on a small capacitor) at 2500 rpm with a
/// 0.5 N m load: the voltage limit follows the measured bus every period; control kept, no
/// fault, steady speed error within 0.5 % (measured 4.02 rpm).
#[test]
fn a_rippling_bus_moves_the_limits_with_it() {
    let m = run("fw-ripple-2500", &[]);
    kept(&m);
    let w = &m.windows["steady"];
    assert!(w.speed_err_max_rpm <= 12.5, "{w:?}");
}

/// The bus sags from 325 to 260 V at 9 s with a 3000 rpm target and a 1 N m load: the
/// reachable speed falls with it (measured 2334 -> 1735 rpm), the reference is held there
/// and the target reported as limited the whole time it is (8.9 s of the run), no fault.
#[test]
fn a_bus_sag_lowers_the_reachable_speed_held_and_reported() {
    let m = run("fw-sag-3000", &[]);
    kept(&m);
    let (a, b) = (&m.windows["325 V"], &m.windows["260 V"]);
    assert!(a.speed_mean_rpm > 2200.0, "{a:?}");
    assert!(b.speed_mean_rpm < a.speed_mean_rpm - 400.0, "{b:?}");
    assert!(b.speed_mean_rpm > 1500.0, "{b:?}");
    assert!(
        m.speed_target_limited_s > 8.0,
        "{}",
        m.speed_target_limited_s
    );
}

/// Runs the paper machine at 500 rpm with a passive `light` N m load from 1 s and a step
/// to `rated` N m at 6 s, flux optimisation on or off; returns the copper losses
/// (stator + rotor, W, the plant's energy account) over 4-6 s and the time from the step
/// until the speed is back within 5 rpm of the reference (s).
fn light_load(optimise: bool, light: f32, rated: f32) -> (f32, f32, f32) {
    use acim::math::{RAD_S_TO_RPM, RPM_TO_RAD_S};
    use acim::{Drive, DriveConfig, DriveInputs, DriveState};
    use acim_plant::{LoadTorque, Plant, PwmPreload};
    let mut cfg = DriveConfig::paper_defaults();
    cfg.field_weakening.flux_optimisation = optimise;
    let ts = cfg.loops.control_period;
    let mut drive = Drive::new(cfg).unwrap();
    let mut plant = Plant::paper_default(3);
    let mut pwm = PwmPreload::new();
    drive.start().unwrap();
    drive.set_speed_target(500.0 * RPM_TO_RAD_S).unwrap();
    let (mut e4, mut e6, mut recovered, mut flux_light) = (0.0f32, 0.0f32, None, 0.0f32);
    let copper =
        |p: &Plant| p.machine().energy().stator_copper() + p.machine().energy().rotor_copper();
    for k in 0..(10.0 / ts) as usize {
        let t = k as f32 * ts;
        let m = plant.sample();
        let out = drive.step(&DriveInputs {
            phase_currents: m.phase_currents,
            dc_bus: m.dc_bus,
        });
        let torque = if t >= 6.0 {
            rated
        } else if t >= 1.0 {
            light
        } else {
            0.0
        };
        plant.run_pwm_period(pwm.advance(out), LoadTorque::Passive { torque });
        if k == (4.0 / ts) as usize {
            e4 = copper(&plant);
        }
        if k == (6.0 / ts) as usize {
            e6 = copper(&plant);
            flux_light = drive.telemetry().rotor_flux;
        }
        let err = (plant.speed() * RAD_S_TO_RPM - 500.0).abs();
        if t > 6.05 && recovered.is_none() && err < 5.0 {
            recovered = Some(t - 6.0);
        }
        if t > 6.05 && err >= 5.0 {
            recovered = None;
        }
    }
    assert_eq!(drive.state(), DriveState::Running);
    (
        (e6 - e4) / 2.0,
        recovered.expect("back within 5 rpm"),
        flux_light,
    )
}

/// Light-load flux optimisation: at 20 % of the paper machine's rated
/// torque (0.95 of 4.77 N m) at 500 rpm the copper losses (the plant's energy account,
/// stator and rotor, 4-6 s) fall from 41.0 to 28.1 W (-31 %; the steady-state optimum of
/// the equations predicts -36 % for the load alone, friction adds torque), the flux from
/// 0.78 to 0.49 Wb; a step to rated torque is back within 5 rpm of the reference after
/// 0.36 s (0.47 s at rated flux; the flux rebuilds with tau_r = 67 ms meanwhile).
#[test]
fn light_load_flux_optimisation_saves_copper_and_recovers() {
    let (p_rated, t_rated, f_rated) = light_load(false, 0.95, 4.77);
    let (p_opt, t_opt, f_opt) = light_load(true, 0.95, 4.77);
    eprintln!("rated flux: {p_rated:.1} W, recovery {t_rated:.3} s, flux {f_rated:.3} Wb");
    eprintln!("optimised:  {p_opt:.1} W, recovery {t_opt:.3} s, flux {f_opt:.3} Wb");
    assert!(p_opt < 0.75 * p_rated, "{p_opt} W against {p_rated} W");
    assert!(f_opt < 0.7 * f_rated);
    assert!(t_opt < 0.6, "recovery {t_opt} s");
}

const OVERMODULATION: &[&str] = &["drive.modulation=\"overmodulation\""];

/// Overmodulation (item 1, `drive.modulation = "overmodulation"`): the acceptance again,
/// with the steady command at 96 % of the linear limit and the range up to six-step as
/// the current loops' reserve. Measured (steady speed error, rpm; linear SVPWM in
/// brackets): reversal 5.12 / 6.26 (4.35 / 5.55), 2500 rpm load step 4.22 / 5.26
/// (4.72 / 4.21), 2.2 kW reversal 4.22 / 4.18 (5.08 / 3.73), rippling bus at 2500 rpm 7.00
/// (4.02); the reachable speed under `fw-ramp-3000`'s load 2529 rpm (2337).
#[test]
fn overmodulation_keeps_the_acceptance_and_reaches_further() {
    for name in ["fw-reversal-3000", "fw-2k2-reversal-3000"] {
        let m = run(name, OVERMODULATION);
        kept(&m);
        for w in m.windows.values() {
            assert!(w.speed_err_max_rpm <= 15.0, "{name}: {w:?}");
        }
    }
    for name in ["fw-load-step-2500", "fw-ripple-2500"] {
        let m = run(name, OVERMODULATION);
        kept(&m);
        for w in m.windows.values() {
            assert!(w.speed_err_max_rpm <= 12.5, "{name}: {w:?}");
        }
    }
    let linear = run("fw-ramp-3000", &[]);
    let m = run("fw-ramp-3000", OVERMODULATION);
    kept(&m);
    let (reach, reach_linear) = (
        m.windows["steady"].speed_mean_rpm,
        linear.windows["steady"].speed_mean_rpm,
    );
    assert!(
        reach > reach_linear + 150.0,
        "{reach} vs {reach_linear} rpm"
    );
    // a target beyond reach and a sagging bus: held and reported, no fault, control kept
    for name in ["fw-unreachable-3200", "fw-sag-3000"] {
        let m = run(name, OVERMODULATION);
        kept(&m);
        assert!(m.speed_target_limited_s > 1.0, "{name}: {m:#?}");
    }
    // braking on the capacitive link stays below the trip, control kept, stopped
    let m = run("fw-braking-3000", OVERMODULATION);
    kept(&m);
    assert!(m.windows["stopped"].speed_mean_rpm.abs() < 5.0);
}

/// The capability acceptance: with overmodulation the steady torque held is
/// within 5 % of the envelope of the machine equations (0.98 V_dc/sqrt 3, the current
/// limit; `acim-sim capability` measures all twelve speeds, 95-100 %); linear SVPWM holds
/// 85 %, its 8 % voltage headroom (torque goes with V^2).
#[test]
fn overmodulation_holds_the_torque_envelope_within_5_percent() {
    let points = acim_sim::capability::measure_at(
        &mut |sc| {
            acim_sim::run_with_metrics(sc)
                .map(|r| r.1)
                .map_err(|e| e.to_string())
        },
        &[1000.0, 3000.0],
    )
    .unwrap();
    for p in points {
        let om = p.held_overmodulation_nm / p.envelope_nm;
        let lin = p.held_nm / p.envelope_nm;
        assert!((0.95..=1.05).contains(&om), "{p:?}");
        assert!((0.80..0.90).contains(&lin), "{p:?}");
    }
}

/// Overmodulation is an f32 modulator: a fixed-point scenario asking for it is refused
/// with the field named.
#[test]
fn overmodulation_in_fixed_point_is_refused() {
    let sc = acim_sim::builtins::get("fw-reversal-3000")
        .unwrap()
        .with_overrides(&[
            "drive.modulation=\"overmodulation\"".to_string(),
            "drive.arithmetic=\"fixed\"".to_string(),
        ])
        .unwrap();
    let e = sc.validate().expect_err("refused");
    assert_eq!(e.field, "drive.modulation");
}
