//! Scenario files: the commented example parses and runs, bad files name the field and
//! the allowed range, overrides work, and the CSV has the required columns first.

use acim_sim::scenario::Scenario;

const EXAMPLE: &str = include_str!("../crates/acim-sim/scenarios/example.toml");

#[test]
fn example_file_parses_validates_and_runs() {
    let sc = Scenario::from_toml(EXAMPLE).unwrap();
    assert_eq!(sc.name, "example");
    sc.validate().unwrap();
    let (r, m) = acim_sim::run_with_metrics(&sc).unwrap();
    assert_eq!(r.rows.len(), 30_000);
    assert!(m.control_kept);
    // a profile event beyond the duration is a field error, not a silent no-op
    let e = sc
        .with_overrides(&["duration_s=1.0".into()])
        .unwrap()
        .validate()
        .unwrap_err();
    assert_eq!(e.field, "load_profile[0].t_s");
}

#[test]
fn bad_values_name_the_field_and_range() {
    let sc = Scenario::from_toml(EXAMPLE).unwrap();
    let e = sc
        .with_overrides(&["plant.rs_ohm=-1".into()])
        .unwrap()
        .validate()
        .unwrap_err();
    assert_eq!(e.field, "plant.rs_ohm");
    assert!(e.allowed.contains("[0.001, 1000]"), "{e}");
    let e = sc
        .with_overrides(&["sensors.channels=4".into()])
        .unwrap()
        .validate()
        .unwrap_err();
    assert_eq!(e.field, "sensors.channels");
    let e = sc
        .with_overrides(&["drive.estimation.observer_poles_rad_s=[100.0, 6000.0, 200.0]".into()])
        .unwrap()
        .validate()
        .unwrap_err();
    assert_eq!(e.field, "drive.estimation.observer_poles_rad_s[1]");
    let e = sc
        .with_overrides(&["controller.lm_h=0.6".into()])
        .unwrap()
        .validate()
        .unwrap_err();
    assert_eq!(e.field, "controller.lm_h");
    // unknown fields and type errors are rejected by the parser, naming the key
    let e = Scenario::from_toml("duration = 3.0").unwrap_err();
    assert!(e.allowed.contains("duration"), "{e}");
    let e = Scenario::from_toml("[sensors]\nadc_bits = \"twelve\"").unwrap_err();
    assert!(e.allowed.contains("adc_bits"), "{e}");
}

#[test]
fn csv_has_the_required_columns_first() {
    let required = "t_s,speed_ref_rpm,speed_rpm,speed_est_rpm,load_torque_nm,load_torque_est_nm,torque_nm,i_sd_a,i_sq_a,i_sd_ref_a,i_sq_ref_a,rotor_flux_est,stator_resistance_est_ohm,v_sd_v,v_sq_v,state";
    assert!(acim_sim::sim::CSV_HEADER.starts_with(required));
    let n = acim_sim::sim::CSV_HEADER.split(',').count();
    let row = acim_sim::sim::Row::default().csv();
    assert_eq!(row.split(',').count(), n);
}

#[test]
fn every_builtin_validates() {
    let all = acim_sim::builtins::all();
    assert!(all.len() >= 17);
    for sc in all {
        sc.validate().unwrap_or_else(|e| panic!("{}: {e}", sc.name));
    }
}

/// `[[plant_changes]]`: factors ramp linearly from the values in effect, bad entries name
/// their field, and the closed loop sees the change (a +50 % Rs step without the
/// estimator moves the speed estimate, as Fig. 8 shows).
#[test]
fn plant_changes_ramp_validate_and_act() {
    use acim_sim::scenario::{plant_factors, PlantChange};
    let ch = [
        PlantChange {
            t_s: 1.0,
            ramp_s: 2.0,
            rs_factor: 1.3,
            rr_factor: 1.0,
        },
        PlantChange {
            t_s: 4.0,
            ramp_s: 0.0,
            rs_factor: 1.0,
            rr_factor: 1.5,
        },
    ];
    assert_eq!(plant_factors(&ch, 0.5), (1.0, 1.0));
    let (rs, rr) = plant_factors(&ch, 2.0);
    assert!((rs - 1.15).abs() < 1e-6 && rr == 1.0, "{rs} {rr}");
    assert_eq!(plant_factors(&ch, 3.5), (1.3, 1.0));
    assert_eq!(plant_factors(&ch, 4.0), (1.0, 1.5));

    let text = format!("{EXAMPLE}\n[[plant_changes]]\nt_s = 4.0\nramp_s = 0.0\nrs_factor = 1.5\n");
    let sc = Scenario::from_toml(&text).unwrap();
    sc.validate().unwrap();
    // field errors: factor out of range, overlapping ramps, unknown key
    let bad = |extra: &str| {
        Scenario::from_toml(&format!("{EXAMPLE}\n{extra}"))
            .and_then(|s| s.validate().map(|_| ()))
            .unwrap_err()
    };
    let e = bad("[[plant_changes]]\nt_s = 1.0\nrs_factor = 0.0\n");
    assert_eq!(e.field, "plant_changes[0].rs_factor");
    assert!(e.allowed.contains("[0.2, 5]"), "{e}");
    let e = bad("[[plant_changes]]\nt_s = 1.0\nramp_s = 2.0\nrs_factor = 1.2\n[[plant_changes]]\nt_s = 2.0\nrr_factor = 1.2\n");
    assert_eq!(e.field, "plant_changes[1].t_s");
    let e = bad("[[plant_changes]]\nt_s = 1.0\nramp_s = -1.0\n");
    assert_eq!(e.field, "plant_changes[0].ramp_s");
    let e = bad("[[plant_changes]]\nt_s = 1.0\nrs = 1.2\n");
    assert!(e.allowed.contains("rs"), "{e}");

    // the loop sees it: same scenario with and without the step at 4 s (load on from
    // 3 s), speed-estimation error in the load window
    let err_in_load = |sc: &Scenario| {
        let r = acim_sim::sim::run(sc).unwrap();
        let w: Vec<_> = r
            .rows
            .iter()
            .filter(|x| x.t_s >= 5.0 && x.t_s < 6.0)
            .collect();
        w.iter().map(|x| x.speed_est_rpm - x.speed_rpm).sum::<f32>() / w.len() as f32
    };
    let base = err_in_load(&Scenario::from_toml(EXAMPLE).unwrap());
    let hot = err_in_load(&sc);
    assert!(
        (hot - base).abs() > 3.0,
        "a +50 % plant Rs step moved the speed-estimation error only from {base} to {hot} rpm"
    );
}

/// The hardware over-current comparator: on by default at the drive's trip level, its
/// level and delay validated with the field named, and off when asked (the drive's own
/// checks then find a dead current sensing).
#[test]
fn the_hardware_comparator_is_configurable() {
    let sc = Scenario::from_toml(EXAMPLE).unwrap();
    assert!(sc.inverter.hardware_trip && sc.inverter.hardware_trip_a.is_none());
    for bad in ["-1.0", "0.0", "1e9", "nan"] {
        let e = sc
            .with_overrides(&[format!("inverter.hardware_trip_a={bad}")])
            .and_then(|s| s.validate().map(|_| ()))
            .unwrap_err();
        assert_eq!(e.field, "inverter.hardware_trip_a", "{bad}: {e}");
        assert!(e.allowed.contains("hardware_trip = false"), "{e}");
    }
    let e = sc
        .with_overrides(&["inverter.hardware_trip_delay_s=1.0".into()])
        .unwrap()
        .validate()
        .unwrap_err();
    assert_eq!(e.field, "inverter.hardware_trip_delay_s");
    // dead current sensing with the drive's sensor check off (it finds the dead channels
    // first): the comparator fires at the trip level, and the run says so
    let mut dead = acim_sim::builtins::get("fault-sensors-zero").unwrap();
    dead.drive.limits.sensor_check = false;
    let (r, m) = acim_sim::run_with_metrics(&dead).unwrap();
    let h = m.hardware_trip.expect("the comparator fired");
    assert_eq!(h.level_a, r.config.limits.overcurrent_trip);
    assert!(h.off_s > 3.0 && h.off_s - h.crossing_s < 2e-6, "{h:?}");
    assert_eq!(m.fault.as_deref(), Some("HardwareBreak"));
    assert!(r.rows.last().unwrap().csv().ends_with(",1"));
    // a level of its own
    let (_, m) = acim_sim::run_with_metrics(
        &dead
            .with_overrides(&["inverter.hardware_trip_a=7.0".into()])
            .unwrap(),
    )
    .unwrap();
    assert_eq!(m.hardware_trip.unwrap().level_a, 7.0);
    // switched off: the drive's software checks alone
    let (r, m) = acim_sim::run_with_metrics(
        &dead
            .with_overrides(&["inverter.hardware_trip=false".into()])
            .unwrap(),
    )
    .unwrap();
    assert!(m.hardware_trip.is_none());
    assert_eq!(m.fault.as_deref(), Some("NoCurrentResponse"));
    assert!(r.rows.iter().all(|x| !x.hardware_trip));
}

#[test]
fn drive_keys_live_in_the_configs_groups_and_flat_keys_are_read_with_a_note() {
    // the grouped layout: no note
    let grouped = Scenario::from_toml(
        "[drive.estimation]\nrs_estimation = false\n[drive.field_weakening]\nenabled = false\n\
         [drive.zero_speed]\npolicy = \"hold\"\n",
    )
    .unwrap();
    assert!(grouped.notes.is_empty(), "{:?}", grouped.notes);
    let v = grouped.validate().unwrap();
    assert!(!v.drive.estimation.rs_estimation);
    assert!(!v.drive.field_weakening.enabled);
    assert_eq!(v.drive.zero_speed.policy, acim::ZeroSpeedPolicy::Hold);
    // the earlier flat layout: the same scenario, one deprecation note per key, shown
    // with the validation's warnings
    let flat = Scenario::from_toml(
        "[drive]\nrs_estimation = false\nfield_weakening = false\nzero_speed_policy = \"hold\"\n",
    )
    .unwrap();
    assert_eq!(flat.drive, grouped.drive);
    assert_eq!(flat.notes.len(), 3, "{:?}", flat.notes);
    assert!(
        flat.notes[0].contains("drive.estimation.rs_estimation"),
        "{:?}",
        flat.notes
    );
    assert_eq!(flat.validate().unwrap().warnings.len(), 3);
    // a flat --set is moved the same way and says so
    let sc = Scenario::from_toml(EXAMPLE).unwrap();
    let set = sc
        .with_overrides(&["drive.current_limit_a=4.0".into()])
        .unwrap();
    assert_eq!(set.drive.limits.current_limit_a, 4.0);
    assert!(
        set.notes[0].starts_with("--set drive.current_limit_a=4.0: "),
        "{:?}",
        set.notes
    );
    // `field_weakening` is a flat switch and a group: the flat --set sets the switch and
    // keeps the group's other keys
    let on = sc
        .with_overrides(&["drive.field_weakening.overvoltage_control=true".into()])
        .unwrap();
    let off = on
        .with_overrides(&["drive.field_weakening=false".into()])
        .unwrap();
    assert!(!off.drive.field_weakening.enabled);
    assert!(off.drive.field_weakening.overvoltage_control);
    assert_eq!(off.notes.len(), 1, "{:?}", off.notes);
    // both ways at once could disagree: refused
    let e = Scenario::from_toml(
        "[drive]\nrs_estimation = false\n[drive.estimation]\nrs_estimation = true\n",
    )
    .unwrap_err();
    assert_eq!(e.field, "drive.rs_estimation");
    // an unknown key in a group names itself
    let e = Scenario::from_toml("[drive.loops]\ncurrent_limit_a = 4.0\n").unwrap_err();
    assert!(e.allowed.contains("current_limit_a"), "{e}");
    // the drive's own rules name the scenario key (limits.overcurrent_trip, at most three
    // times the current limit -> drive.limits.overcurrent_trip_a)
    let e = sc
        .with_overrides(&["drive.limits.overcurrent_trip_a=20.0".into()])
        .unwrap()
        .validate()
        .unwrap_err();
    assert_eq!(e.field, "drive.limits.overcurrent_trip_a", "{e}");
}
