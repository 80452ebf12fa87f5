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
        .with_overrides(&["drive.observer_poles_rad_s=[100.0, 6000.0, 200.0]".into()])
        .unwrap()
        .validate()
        .unwrap_err();
    assert_eq!(e.field, "drive.observer_poles_rad_s[1]");
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
