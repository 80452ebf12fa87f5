//! Fault cases: each ends with the switches off and the right reason reported.

use acim_sim::builtins;

fn check(name: &str, reason: &str, after_s: f32, within_s: f32) {
    let sc = builtins::get(name).unwrap();
    let (r, m) = acim_sim::run_with_metrics(&sc).unwrap();
    assert_eq!(m.fault.as_deref(), Some(reason), "{name}: {m:#?}");
    let t = m.fault_time_s.unwrap();
    assert!(
        t >= after_s && t <= after_s + within_s,
        "{name}: fault at {t} s, expected in [{after_s}, {}]",
        after_s + within_s
    );
    assert!(m.switches_off_at_end);
    // switches off from the fault step on, every step
    assert!(r
        .rows
        .iter()
        .filter(|row| row.t_s >= t)
        .all(|row| !row.pwm_enabled && row.state == 4));
}

#[test]
fn phase_short_trips_on_over_current() {
    check("fault-short", "OverCurrent", 3.0, 0.01);
}

#[test]
fn bus_sag_trips_on_under_voltage() {
    check("fault-bus-sag", "DcBusUnderVoltage", 3.0, 1.0);
}

#[test]
fn braking_without_chopper_trips_on_over_voltage() {
    check("fault-overvoltage-braking", "DcBusOverVoltage", 2.5, 1.0);
}

#[test]
fn locked_rotor_trips_on_stall() {
    check("fault-locked-rotor", "Stall", 3.0, 1.2);
}

#[test]
fn nan_sample_trips_at_once() {
    check("fault-nan-sample", "NonFiniteInput", 3.0, 0.0002);
}
