//! Rs tracked while running, the robustness matrix (a subset) and the
//! zero-speed policy, closed loop against the motor model. The whole matrix:
//! `cargo run --release -p acim-sim -- robustness` (docs/robustness-matrix.md).

use acim_sim::robustness::{run, Case, Variant};
use acim_sim::scenario::{RsMode, Scenario, ZeroSpeed};

fn case(variant: Variant, rpm: f32, regenerating: bool, load_nm: f32) -> Case {
    Case {
        rpm,
        regenerating,
        load_nm,
        variant,
    }
}

/// Item 1: a +30 % plant Rs ramp over 20 s and a +20 % step, 1.5 N m, at 500, 120 and
/// 60 rpm motoring and at 500 and 120 rpm regenerating: with the running mode the
/// estimate is within 3 % of the true Rs 2 s after the change ends and the steady
/// speed-estimation error is at most 2 rpm. (60 rpm regenerating at 1.5 N m sits at
/// f_s = 0.99 Hz, on the edge of the unobservable region: docs/robustness.md.)
#[test]
fn rs_tracked_while_running() {
    for variant in [Variant::PlantRsDrift30, Variant::PlantRsStep20] {
        for (rpm, regen) in [
            (500.0, false),
            (120.0, false),
            (60.0, false),
            (500.0, true),
            (120.0, true),
        ] {
            let c = case(variant, rpm, regen, 1.5);
            assert!(c.stator_frequency_hz().abs() >= 1.0);
            let o = run(&c, RsMode::Running).unwrap();
            assert!(!o.faulted && !o.lost, "{c:?}: {o:?}");
            assert!(o.rs_error_pct.abs() <= 3.0, "{c:?}: {o:?}");
            assert!(o.speed_est_error_rpm.abs() <= 2.0, "{c:?}: {o:?}");
            assert!(o.pass());
        }
    }
}

/// In the standstill mode the same drift leaves the estimate at its
/// standstill value and the speed estimate off by the Rs error times i_sq / (p lambda):
/// the required 18.5 rpm at 500 rpm.
#[test]
fn standstill_mode_misses_the_drift() {
    let c = case(Variant::PlantRsDrift30, 500.0, false, 1.5);
    let o = run(&c, RsMode::Standstill).unwrap();
    assert!(o.rs_error_pct < -20.0, "{o:?}");
    assert!(o.speed_est_error_rpm > 10.0, "{o:?}");
}

/// A subset of the matrix with the running mode: controller Rs -20 %, inverter dead time
/// 1.0 and 2.2 us with 1.5 us compensated, 20 mA offsets; 500 and 120 rpm, motoring and
/// regenerating, 1.5 N m, and 500 rpm at 4.5 N m.
#[test]
fn matrix_subset_holds() {
    for variant in [
        Variant::ControllerRsMinus20,
        Variant::DeadTime1_0,
        Variant::DeadTime2_2,
        Variant::Offset20mA,
    ] {
        for (rpm, regen, load) in [
            (500.0, false, 1.5),
            (500.0, true, 1.5),
            (120.0, false, 1.5),
            (120.0, true, 1.5),
            (500.0, true, 4.5),
        ] {
            let c = case(variant, rpm, regen, load);
            let o = run(&c, RsMode::Running).unwrap();
            assert!(o.pass(), "{c:?}: {o:?}");
        }
    }
}

fn zero_speed_scenario(policy: ZeroSpeed) -> Scenario {
    let mut s = acim_sim::builtins::all()
        .into_iter()
        .find(|s| s.name == "paper-fig6")
        .unwrap();
    // 500 rpm, reversal at 4 s, zero target at 6.5 s (the ramp reaches it at 7.5 s)
    s.speed_profile
        .push(acim_sim::scenario::SpeedPoint { t_s: 6.5, rpm: 0.0 });
    s.duration_s = 9.0;
    s.drive.zero_speed.policy = policy;
    s
}

/// Item 6: with `stop` the drive switches off 0.5 s after the reference reached a held
/// zero (no fault; `stop` is the default); the reversal before still passes through
/// zero. With `hold` it keeps running.
#[test]
fn zero_speed_policy() {
    let stop = acim_sim::sim::run(&zero_speed_scenario(ZeroSpeed::Stop)).unwrap();
    assert_eq!(stop.fault, None);
    assert_eq!(stop.final_state, acim::DriveState::Idle);
    assert!(stop.switches_off_at_end);
    // running through the reversal (4 .. 6 s) and until the dwell after 7.5 s
    let running_at = |t: f32| {
        stop.rows
            .iter()
            .find(|r| r.t_s >= t)
            .map(|r| r.pwm_enabled)
            .unwrap()
    };
    assert!(running_at(5.0) && running_at(7.9));
    assert!(!running_at(8.1));
    // the reversal reached -500 rpm
    assert!(stop.rows.iter().any(|r| r.speed_rpm < -490.0));
    let hold = acim_sim::sim::run(&zero_speed_scenario(ZeroSpeed::Hold)).unwrap();
    assert_eq!(hold.final_state, acim::DriveState::Running);
    assert_eq!(hold.fault, None);
}

/// Item 5: 120 rpm regenerating at 4.5 N m sits at f_s = 0.96 Hz. Without the
/// regeneration limit the drive loses the point: it trips (the active load then drives
/// the coasting rotor away), loses the speed, or (with the running Rs law's steadiness
/// gate, measured) drifts towards the line with the estimate 66 rpm off; with
/// `regen_min_frequency_hz = 1.5` it holds the reachable
/// speed instead, about 15 rpm above the target at f_s = 1.5 Hz, without a fault, and
/// estimates it within 2 rpm.
#[test]
fn regeneration_limit_keeps_off_the_unobservable_line() {
    use acim_sim::robustness::{run_scenario, Setup};
    let c = case(Variant::Nominal, 120.0, true, 4.5);
    assert!(c.stator_frequency_hz().abs() < 1.0);
    let off = run(&c, RsMode::Running).unwrap();
    assert!(
        off.faulted || off.lost || off.speed_est_error_rpm.abs() > 20.0,
        "{off:?}"
    );
    let sc = c.scenario_with(&Setup {
        mode: RsMode::Running,
        regen_min_frequency_hz: 1.5,
    });
    let on = run_scenario(&c, &sc).unwrap();
    assert!(!on.faulted && !on.lost, "{on:?}");
    assert!((on.stator_frequency_hz - 1.5).abs() < 0.1, "{on:?}");
    assert!(
        on.speed_error_rpm > 0.0 && on.speed_error_rpm < 20.0,
        "{on:?}"
    );
    assert!(on.speed_est_error_rpm.abs() < 2.0, "{on:?}");
}

/// Item 6, measured: `crates/acim-sim/scenarios/zero-hold.toml` holds a zero target for
/// 30 s with 5 mA offsets. With `stop` the drive is off and the rotor at rest; with
/// `hold` the rotor creeps (the unobservable zero frequency) while running.
#[test]
fn zero_hold_scenario() {
    let text = include_str!("../crates/acim-sim/scenarios/zero-hold.toml");
    let sc = Scenario::from_toml(text).unwrap();
    let max_after = |r: &acim_sim::sim::RunResult| {
        r.rows
            .iter()
            .filter(|x| x.t_s >= 4.6)
            .map(|x| x.speed_rpm.abs())
            .fold(0.0f32, f32::max)
    };
    let mut stop = sc.clone();
    stop.drive.zero_speed.policy = ZeroSpeed::Stop;
    let r = acim_sim::sim::run(&stop).unwrap();
    assert_eq!(r.final_state, acim::DriveState::Idle);
    // switched off 0.5 s after the reference reached zero (4.0 s), never on again; the
    // rotor coasts down from the creep it had then (3.1 rpm measured) and comes to rest
    assert!(r
        .rows
        .iter()
        .filter(|x| x.t_s >= 4.6)
        .all(|x| !x.pwm_enabled));
    assert!(max_after(&r) < 5.0, "{}", max_after(&r));
    let last = r.rows.last().unwrap().speed_rpm.abs();
    assert!(last < 0.1, "{last}");
    // the file leaves the policy at the default, `stop`
    assert_eq!(sc.drive.zero_speed.policy, ZeroSpeed::Stop);
    // `hold`: the creep documented in docs/robustness.md is a random walk of the noise
    // (under 5 to 16.5 rpm over noise seeds 1-6, with the inverter test at start as
    // without it): over
    // three seeds it is present, and never a runaway
    let mut creep = Vec::new();
    for seed in 1..=3 {
        let mut hold = sc.clone();
        hold.drive.zero_speed.policy = ZeroSpeed::Hold;
        hold.seed = seed;
        let r = acim_sim::sim::run(&hold).unwrap();
        assert_eq!(r.final_state, acim::DriveState::Running);
        assert_eq!(r.fault, None);
        let m = max_after(&r);
        assert!(m < 40.0, "seed {seed}: {m}");
        creep.push(m);
    }
    assert!(creep.iter().any(|&m| m > 5.0), "{creep:?}");
}

fn builtin(name: &str) -> Scenario {
    acim_sim::builtins::all()
        .into_iter()
        .find(|s| s.name == name)
        .unwrap()
}

/// Item 2: the inverter test at start (0.45 s of magnetizing, three d-axis current levels)
/// finds the dead time of inverters with 0.5-3 us within 10 % while the drive is
/// configured for 1.5 us, with the paper scenarios' 12-bit sensors (noise, gain errors,
/// offsets), in both arithmetics; the drive then runs fig 12's 60 rpm trapezoid with it.
/// On a flying start (the rotor turns) the test does not apply and is skipped.
#[test]
fn inverter_test_finds_the_dead_time_within_ten_percent() {
    use acim_sim::scenario::Arithmetic;
    for (dt_us, arithmetic) in [
        (0.5, Arithmetic::F32),
        (1.0, Arithmetic::F32),
        (2.2, Arithmetic::F32),
        (3.0, Arithmetic::F32),
        (1.0, Arithmetic::Fixed),
        (3.0, Arithmetic::Fixed),
    ] {
        let mut s = builtin("paper-fig12");
        s.duration_s = 1.5;
        s.speed_profile.retain(|p| p.t_s <= 1.5);
        s.load_profile.retain(|p| p.t_s <= 1.5);
        s.windows.clear();
        s.drive.start.inverter_identification = true;
        s.drive.arithmetic = arithmetic;
        s.inverter.dead_time_s = dt_us * 1e-6;
        let r = acim_sim::sim::run(&s).unwrap();
        assert_eq!(r.fault, None);
        let t = r.inverter_test.unwrap();
        assert_eq!(t.outcome, "Identified", "{dt_us} us {arithmetic:?}");
        assert!(
            (t.dead_time_us - dt_us).abs() <= 0.1 * dt_us,
            "{dt_us} us {arithmetic:?}: {t:?}"
        );
        // the test lasts 0.45 s: magnetizing (state 1) never ends before it
        let magnetized = r.rows.iter().find(|row| row.state == 2).unwrap().t_s;
        assert!(magnetized >= 0.45, "{magnetized}");
    }
    let mut s = builtin("flying-start-800");
    s.drive.start.inverter_identification = true;
    let r = acim_sim::sim::run(&s).unwrap();
    assert_eq!(r.inverter_test.unwrap().outcome, "Skipped");
    assert_eq!(r.fault, None);
}

/// Item 2, online: with the start test off (as on a flying start, which skips it) the
/// running tracker finds the inverter's error from its sixth harmonic across the current
/// (`acim::inverter_tracker`): the drive configured for 1.5 us, inverters of 0.5, 2.2 and
/// 3.0 us are compensated within 10 % of their dead time after 16 s of running (measured:
/// 0.2-0.7 %), in f32 and Q7.24 (without it the compensation would stay at 1.5 us,
/// 47-200 % off).
#[test]
fn inverter_error_is_tracked_while_running() {
    use acim_sim::robustness::Setup;
    let defaults = Setup {
        mode: RsMode::Running,
        regen_min_frequency_hz: 1.5,
    };
    for (dt_us, rpm, load, arithmetic) in [
        (0.5, 120.0, 1.5, "f32"),
        (3.0, 120.0, 1.5, "f32"),
        (2.2, 500.0, 4.5, "fixed"),
    ] {
        let c = case(Variant::DeadTime1_0NotIdentified, rpm, false, load);
        let mut sc = c
            .scenario_with(&defaults)
            .with_overrides(&[
                format!("drive.arithmetic=\"{arithmetic}\""),
                "duration_s=16".into(),
            ])
            .unwrap();
        sc.inverter.dead_time_s = dt_us * 1e-6;
        let r = acim_sim::sim::run(&sc).unwrap();
        assert_eq!(r.fault, None);
        let t = r.inverter_test.unwrap();
        assert!(t.tracked && t.outcome == "NotRun", "{t:?}");
        assert!(
            (t.dead_time_us - dt_us).abs() <= 0.1 * dt_us,
            "{dt_us} us {arithmetic}: {t:?}"
        );
    }
}

/// A scenario with a nameplate derives the drive from it; the switches still come
/// from `[drive]` (before, `--set drive.start.inverter_identification=false` and the other
/// three were silently ignored there).
#[test]
fn nameplate_scenarios_take_the_robustness_switches() {
    let mut s = builtin("fw-2k2-reversal-3000");
    s.duration_s = 1.2;
    s.speed_profile.retain(|p| p.t_s <= 1.2);
    s.windows.clear();
    let r = acim_sim::sim::run(&s).unwrap();
    assert!(r.config.start.inverter_identification && r.config.trackers.offset_tracking);
    assert_eq!(r.inverter_test.unwrap().outcome, "Identified");
    let s = s
        .with_overrides(&[
            "drive.start.inverter_identification=false".into(),
            "drive.trackers.offset_tracking=false".into(),
            "drive.trackers.inverter_tracking=false".into(),
            "drive.start.current_gain_calibration=false".into(),
            "drive.trackers.rr_adaptation=true".into(),
        ])
        .unwrap();
    let r = acim_sim::sim::run(&s).unwrap();
    let c = r.config;
    assert!(
        !c.start.inverter_identification
            && !c.trackers.offset_tracking
            && !c.start.current_gain_calibration
    );
    assert!(!c.trackers.inverter_tracking);
    assert!(c.trackers.rr_adaptation);
    assert!(r.inverter_test.is_none());
}

/// Item 2: the inverter test's fit also measures the stator resistance (its slope, which
/// the inverter's error does not move). With Rs estimation on, the standstill
/// identification goes on from it: fig 9's +50 % initial Rs error is within 2 % when the
/// test ends (0.59 s measured) and speed control starts about 0.17 s later (0.77 s),
/// where without the slope the identification, started only after the test, ran into its
/// timeout (1.5 s, counted from the start); without the test it takes 1.09 s.
#[test]
fn inverter_test_seeds_the_standstill_rs_identification() {
    use acim_sim::scenario::Arithmetic;
    for arithmetic in [Arithmetic::F32, Arithmetic::Fixed] {
        let mut s = builtin("paper-fig9");
        s.drive.start.inverter_identification = true;
        s.drive.arithmetic = arithmetic;
        s.duration_s = 2.0;
        s.speed_profile.retain(|p| p.t_s <= 2.0);
        s.load_profile.retain(|p| p.t_s <= 2.0);
        s.windows.clear();
        let r = acim_sim::sim::run(&s).unwrap();
        assert_eq!(r.fault, None);
        assert_eq!(r.inverter_test.as_ref().unwrap().outcome, "Identified");
        let running = r.rows.iter().find(|row| row.state == 2).unwrap();
        assert!(
            running.t_s < 0.85,
            "{arithmetic:?}: Running at {} s",
            running.t_s
        );
        let rs = running.stator_resistance_est_ohm;
        assert!((rs - 10.5).abs() <= 0.02 * 10.5, "{arithmetic:?}: {rs} ohm");
    }
}

/// Item 2: the matrix's dead-time rows with the drive configured for 1.5 us and the
/// inverter at 1.0 or 2.2 us hold with the start test (on by default) in the standstill Rs
/// mode, where the Rs identification reads an uncompensated inverter error as resistance;
/// with the test switched off, 4.5 N m at 500 rpm regenerating fails there
/// (docs/robustness-matrix.md).
#[test]
fn identified_dead_time_rows_hold() {
    for (variant, not_identified) in [
        (Variant::DeadTime1_0, Variant::DeadTime1_0NotIdentified),
        (Variant::DeadTime2_2, Variant::DeadTime2_2NotIdentified),
    ] {
        for (rpm, regen, load) in [(500.0, false, 4.5), (500.0, true, 4.5), (120.0, true, 1.5)] {
            let c = case(variant, rpm, regen, load);
            let o = run(&c, RsMode::Standstill).unwrap();
            assert!(o.pass(), "{c:?}: {o:?}");
        }
        let c = case(not_identified, 500.0, true, 4.5);
        let o = run(&c, RsMode::Standstill).unwrap();
        assert!(!o.pass(), "{c:?}: {o:?}");
    }
}

/// Item 1's fig 9 variant: Rs estimated only while turning (`rs_standstill_identification
/// = false`, running mode), from the paper's +50 % initial error. At no load the running
/// law has no information (it needs torque current) and holds; the 1.5 N m load at 4 s
/// brings it within 2 % in under 1 s, and the load window's speed estimate within 2 rpm.
/// (The start itself is fig 8c's: with +50 % Rs at a few Hz the estimate runs up to
/// 110 rpm ahead for 0.4 s; docs/robustness.md.)
#[test]
fn fig9_rs_converges_while_running_without_standstill_identification() {
    let mut s = builtin("paper-fig9");
    s.drive.estimation.rs_estimation_mode = RsMode::Running;
    s.drive.start.rs_standstill_identification = false;
    let r = acim_sim::sim::run(&s).unwrap();
    assert_eq!(r.fault, None);
    let m = acim_sim::metrics::compute(&r, 0.0);
    let from = m.rs.within_2pct_from_s.expect("Rs never within 2 %");
    assert!((4.0..=5.0).contains(&from), "within 2 % from {from} s");
    assert!((m.rs.final_ohm - 10.5).abs() <= 0.02 * 10.5);
    let w = &m.windows["load"];
    assert!(w.speed_est_err_max_rpm <= 2.0, "{w:?}");
}

/// Item 3: 20 mA offsets drifting in after the start's switches-off measurement, at
/// 60 rpm regenerating (0.5 N m, f_s = 1.67 Hz): with the running offset tracker the
/// speed estimate holds within 2 rpm (0.11 rpm with the 1 kHz slow task, 0.19 at the
/// control rate); without it the drift pulls the running Rs law and the estimate is off
/// by more (0.52 rpm; 1.16 at the control rate, 1.51 rpm before the inverter test at
/// start shipped on, 2.17 rpm before the sensors' gain mismatch was calibrated at start,
/// whose ripple added to it): at least 2.5 times the tracked error and beyond 0.5 rpm
/// (docs/robustness.md, item 3). (The slow task's Rs law, on the slow period's means,
/// took the drift's pull at -0.55 % against -0.81 %.)
#[test]
fn offset_drift_after_the_start_is_tracked() {
    let c = case(Variant::OffsetDrift20mA, 60.0, true, 0.5);
    assert!(c.stator_frequency_hz().abs() >= 1.0);
    offset_drift_tracked(&c, 2.0);
}

/// The drifting offsets' case `c` with the drive's defaults (running Rs law, 1.5 Hz
/// regeneration limit): it passes with the speed-estimation error within `bound` rpm
/// tracked, and untracked the error is beyond 0.5 rpm and 2.5 times the tracked one.
fn offset_drift_tracked(c: &Case, bound: f32) {
    let setup = acim_sim::robustness::Setup {
        mode: RsMode::Running,
        regen_min_frequency_hz: 1.5,
    };
    let mut s = c.scenario_with(&setup);
    let o = acim_sim::robustness::run_scenario(c, &s).unwrap();
    assert!(o.pass(), "{o:?}");
    assert!(o.speed_est_error_rpm.abs() <= bound, "{o:?}");
    s.drive.trackers.offset_tracking = false;
    let off = acim_sim::robustness::run_scenario(c, &s).unwrap();
    let (on, off_err) = (o.speed_est_error_rpm.abs(), off.speed_est_error_rpm.abs());
    assert!(off_err > 0.5 && off_err > 2.5 * on, "{o:?} vs {off:?}");
}

/// Item 3 at the regeneration limit's hold: 60 rpm regenerating 1.5 N m is below 1 Hz, so
/// the limit holds it at 1.5 Hz, the tracker's gate. The hold moves the speed reference
/// with the speed, which is not a ramp: the tracker adapts there. When it read the hold
/// as a ramp it never did, and 20 mA drifting in left 1.17 rpm of estimation error, as
/// with the tracker off (1.19); tracked, 0.18 rpm at the control rate. With the 1 kHz
/// slow task: 0.39 rpm tracked, 1.12 untracked.
#[test]
fn offset_drift_is_tracked_at_the_regeneration_limits_hold() {
    let c = case(Variant::OffsetDrift20mA, 60.0, true, 1.5);
    assert!(c.stator_frequency_hz().abs() < 1.0);
    offset_drift_tracked(&c, 0.5);
}

/// Item 3 on the far side (60 rpm, 4.5 N m regenerating, f_s = -1.05 Hz): below the
/// tracker's 1.5 Hz gate, but in the drive's far-side mode the offset adapts from 0.5 Hz
/// at a tenth of its rate (`crates/acim/src/offset_tracker.rs`, "On the far side"). The
/// 20 mA that drift in over 4-5 s are then held within the required 2 rpm at 17-19 s,
/// 12-14 s after the drift ended (measured -0.95 rpm; untracked -4.1 rpm there and -5.4
/// in the matrix's window at 7-9 s, where the tracked drive still reads -4.2 rpm).
#[test]
fn offset_drift_is_tracked_slowly_on_the_far_side() {
    let c = case(Variant::OffsetDrift20mA, 60.0, true, 4.5);
    assert!(c.stator_frequency_hz() < -1.0);
    let setup = acim_sim::robustness::Setup {
        mode: RsMode::Running,
        regen_min_frequency_hz: 1.5,
    };
    let mut s = c.scenario_with(&setup);
    const LATER: f32 = 10.0;
    s.duration_s += LATER;
    for w in &mut s.windows {
        w.from_s += LATER;
        w.to_s += LATER;
    }
    let o = acim_sim::robustness::run_scenario(&c, &s).unwrap();
    assert!(o.pass(), "{o:?}");
    assert!(o.speed_est_error_rpm.abs() <= 2.0, "{o:?}");
    s.drive.trackers.offset_tracking = false;
    let off = acim_sim::robustness::run_scenario(&c, &s).unwrap();
    assert!(off.speed_est_error_rpm.abs() > 3.0, "{off:?}");
}

/// Item 3's tracker below 1.5 Hz: there a DC current's answer through the sensorless
/// loop (a torque ripple at f_s, inside the speed loop's band) turns the tracker's
/// signature, and with a 1 Hz gate the estimate ran away with no offset drift at all:
/// 60 rpm at 1.0 N m regenerating (f_s = 1.33 Hz) was lost at 51 mA and 8.2 rpm of
/// estimation error, and on the far side (60 rpm, 4.5 N m regenerating, -1.05 Hz) the
/// plant's Rs drift made it walk to 43 mA, and the rotor ran away to an overload trip.
/// With the gate at 1.5 Hz both hold
/// (no regeneration limit, running Rs law; `crates/acim/src/offset_tracker.rs`).
#[test]
fn offset_tracker_holds_below_its_gate() {
    let setup = acim_sim::robustness::Setup {
        mode: RsMode::Running,
        regen_min_frequency_hz: 0.0,
    };
    for (variant, load) in [(Variant::Nominal, 1.0), (Variant::PlantRsDrift30, 4.5)] {
        let c = case(variant, 60.0, true, load);
        let f_s = c.stator_frequency_hz().abs();
        assert!((1.0..1.5).contains(&f_s), "{f_s}");
        let o = acim_sim::robustness::run_scenario(&c, &c.scenario_with(&setup)).unwrap();
        assert!(o.pass(), "{o:?}");
    }
}

/// Items 4-5, the far side: 60 rpm with 4.5 N m regenerating sits at f_s = -1.05 Hz,
/// across the line w_s = 0. The drive as it ships (running Rs law, 1.5 Hz regeneration
/// limit) reaches it: once the load estimate puts the target's point 1 Hz beyond the line
/// (and the inverter test identified the voltage error at this start) the far-side mode
/// releases the limit and adds the far-side term to the observer, and the point is held
/// within the matrix's 2 rpm, in f32 and Q7.24. Without the inverter test, or with the
/// far-side gain at 0 (the drive before), the limit holds the reachable speed at
/// f_s = 1.5 Hz instead. When the load falls to 0.5 N m (f_s = +1.66 Hz) the mode is
/// left and the near-side point is held.
#[test]
fn far_side_mode_holds_the_far_side_by_default() {
    use acim_sim::robustness::{run_scenario, Setup};
    let defaults = Setup {
        mode: RsMode::Running,
        regen_min_frequency_hz: 1.5,
    };
    for (variant, arithmetic) in [
        (Variant::Nominal, "f32"),
        (Variant::Nominal, "fixed"),
        (Variant::DeadTime2_2, "f32"),
    ] {
        let c = case(variant, 60.0, true, 4.5);
        let sc = c
            .scenario_with(&defaults)
            .with_overrides(&[format!("drive.arithmetic=\"{arithmetic}\"")])
            .unwrap();
        let o = run_scenario(&c, &sc).unwrap();
        assert!(o.pass(), "{arithmetic}: {o:?}");
        assert!((o.stator_frequency_hz + 1.05).abs() < 0.05, "{o:?}");
    }
    // kept off the line by the limit
    let held = |c: &Case, sc: &Scenario| {
        let o = run_scenario(c, sc).unwrap();
        assert!(!o.faulted && !o.lost, "{o:?}");
        assert!((o.stator_frequency_hz - 1.5).abs() < 0.1, "{o:?}");
    };
    let c = case(Variant::DeadTime1_0NotIdentified, 60.0, true, 4.5);
    let mut blind = c.scenario_with(&defaults);
    blind.drive.trackers.inverter_tracking = false;
    held(&c, &blind);
    let c = case(Variant::Nominal, 60.0, true, 4.5);
    let mut before = c.scenario_with(&defaults);
    before.drive.estimation.far_side_gain = 0.0;
    held(&c, &before);
    // back across the line to the near side
    let mut back = c.scenario_with(&defaults);
    let window = back.windows[0].from_s;
    back.load_profile.push(acim_sim::scenario::LoadPoint {
        t_s: window - 3.0,
        kind: acim_sim::scenario::LoadKind::Active,
        torque_nm: -0.5,
    });
    let o = run_scenario(&c, &back).unwrap();
    assert!(!o.faulted && !o.lost, "{o:?}");
    assert!((o.stator_frequency_hz - 1.66).abs() < 0.1, "{o:?}");
    assert!(
        o.speed_error_rpm.abs() < 2.0 && o.speed_est_error_rpm.abs() < 2.0,
        "{o:?}"
    );
}

/// without the start test the inverter's error is unknown, and
/// the limit holds the far-side target at f_s = 1.5 Hz; the inverter tracker adapts there
/// (the limit's hold is not a ramp), and once it has adapted for
/// `INVERTER_TRACKER_TRUST` (3 s) its correction stands in for the test's: the mode takes
/// the drive across, and 60 rpm regenerating at 4.5 N m is held within the matrix's
/// 2 rpm. Measured: across at 7.8 s (1.0 us) and 8.5 s (2.2 us); at 12-14 s speed error
/// -0.5 / -0.4 rpm, estimation error +0.6 / +0.3 rpm. The matrix's window (6-8 s) is
/// before the transit, so its two rows still read "not held".
#[test]
fn far_side_mode_follows_a_trusted_inverter_tracker() {
    use acim_sim::robustness::{run_scenario, Setup};
    let defaults = Setup {
        mode: RsMode::Running,
        regen_min_frequency_hz: 1.5,
    };
    for variant in [
        Variant::DeadTime1_0NotIdentified,
        Variant::DeadTime2_2NotIdentified,
    ] {
        let c = case(variant, 60.0, true, 4.5);
        let mut sc = c.scenario_with(&defaults);
        sc.duration_s = 14.0;
        sc.windows[0].from_s = 12.0;
        sc.windows[0].to_s = 14.0;
        let o = run_scenario(&c, &sc).unwrap();
        assert!(!o.faulted && !o.lost, "{o:?}");
        assert!((o.stator_frequency_hz + 1.05).abs() < 0.05, "{o:?}");
        assert!(
            o.speed_error_rpm.abs() < 2.0 && o.speed_est_error_rpm.abs() < 2.0,
            "{o:?}"
        );
    }
}

const RR_SCENARIO: &str = include_str!("../crates/acim-sim/scenarios/rr-adaptation.toml");

/// the rotor resistance adapted at speed steps (f32 and Q7.24), with
/// the controller's Rr 30 % low or high and its J 5 % off: R_R_hat within 5 % (the
/// windows scatter by about 3 % with the paper scenarios' sensor noise) and the steady
/// speed-estimation error within the matrix's 2 rpm; without the adaptation the slip
/// error stays in the speed estimate.
#[test]
fn rotor_resistance_adapts_at_speed_steps() {
    let base = Scenario::from_toml(RR_SCENARIO).unwrap();
    let cases: [&[&str]; 4] = [
        &[],
        &["controller.rr_ohm=10.92"],
        &["controller.inertia_kgm2=0.0105"],
        &["drive.arithmetic=\"fixed\""],
    ];
    for overrides in cases {
        let ov: Vec<String> = overrides.iter().map(|s| s.to_string()).collect();
        let sc = base.with_overrides(&ov).unwrap();
        let (r, m) = acim_sim::run_with_metrics(&sc).unwrap();
        assert!(m.control_kept && r.fault.is_none(), "{overrides:?}");
        let rr = r.rotor_resistance.clone().unwrap();
        assert!(rr.updates >= 3 && rr.rejected == 0, "{overrides:?}: {rr:?}");
        assert!(
            (rr.estimate_ohm - rr.true_ohm).abs() <= 0.05 * rr.true_ohm,
            "{overrides:?}: {rr:?}"
        );
        let before = m.windows.get("before").unwrap().speed_est_err_mean_rpm;
        let after = m.windows.get("adapted").unwrap().speed_est_err_mean_rpm;
        assert!(before.abs() > 5.0, "{overrides:?}: {before}");
        // the matrix's bound, max(2 rpm, 1 % of the reference)
        assert!(after.abs() <= 2.0, "{overrides:?}: {before} -> {after}");
        let off = sc
            .with_overrides(&["drive.trackers.rr_adaptation=false".into()])
            .unwrap();
        let (_, m_off) = acim_sim::run_with_metrics(&off).unwrap();
        let off_err = m_off.windows.get("adapted").unwrap().speed_est_err_mean_rpm;
        assert!(off_err.abs() > 5.0, "{overrides:?}: {off_err}");
    }
}

/// The current sensors' gain mismatch (the paper scenarios' +0.3 % / -0.3 %) identified
/// while magnetizing at rest, in both arithmetics: the ratio g_a / g_b within 0.15 % (the
/// idle offset measurement's noise, 0.45 mA on 1.5 A, scatters it by about 0.05 %), the
/// two arithmetics within 0.02 % of each other; and its effect on the far side of the
/// unobservable line (60 rpm, 4.5 N m regenerating, f_s = -1.05 Hz, no regeneration
/// limit), where the negative-sequence ripple the mismatch makes is in the observer's
/// band: held within 2 rpm with the calibration, beyond without it when the far-side
/// term is off too (docs/robustness.md, the far side; with the term, 0.87 rpm without
/// the calibration).
#[test]
fn current_gain_mismatch_is_calibrated_at_start() {
    let c = case(Variant::Nominal, 60.0, true, 4.5);
    assert!(c.stator_frequency_hz() <= -1.0);
    let setup = acim_sim::robustness::Setup {
        mode: RsMode::Running,
        regen_min_frequency_hz: 0.0,
    };
    let s = c.scenario_with(&setup);
    let g = s.sensors.gain_error;
    let ratio = (1.0 + g[0]) / (1.0 + g[1]);
    let mut ks = Vec::new();
    for arithmetic in ["f32", "fixed"] {
        let sc = s
            .with_overrides(&[format!("drive.arithmetic=\"{arithmetic}\"")])
            .unwrap();
        let r = acim_sim::sim::run(&sc).unwrap();
        let k = r.current_gain_correction;
        assert!(
            (k / ratio - 1.0).abs() < 1.5e-3,
            "{arithmetic}: k {k}, true {ratio}"
        );
        ks.push(k);
        let o = acim_sim::robustness::run_scenario(&c, &sc).unwrap();
        assert!(o.pass(), "{arithmetic}: {o:?}");
    }
    assert!((ks[0] / ks[1] - 1.0).abs() < 2e-4, "{ks:?}");
    let mut off = s.clone();
    off.drive.start.current_gain_calibration = false;
    off.drive.estimation.far_side_gain = 0.0;
    let o = acim_sim::robustness::run_scenario(&c, &off).unwrap();
    assert!(o.speed_est_error_rpm.abs() > 2.0, "{o:?}");
}
