//! Current-sensor faults at any speed on every acceptance machine: every channel reading
//! 0 A, or one channel stuck at its last reading, with two and three shunts, at 60, 500,
//! 1500 rpm and in field weakening (`acim_sim::faults::sensor_cases`, the rows of the
//! second table of `docs/faults.md`).
//!
//! The drive's software over-current trip cannot see a current its sensors do not report;
//! the plant's hardware comparator (the simulator's default, at the drive's trip level)
//! opens the switches. Acceptance: the true phase current above the drive's trip level for
//! at most one PWM period while switching (measured at every integration sub-step, not
//! only at the samples), every case ends with the switches off, and the drive trips after
//! the fault, not before.
//!
//! Measured (`cargo run --release -p acim-sim -- faults`, the table in `docs/faults.md`;
//! `cargo test -p acim-tests --test sensor_faults -- --nocapture` prints every case): at
//! most 1.5 us above the trip in every case (the comparator's delay). Without the
//! comparator (the second test) 46 of the 76 reached cases stay above the trip for more
//! than a period while switching: the 2.2 kW machine at 1500 rpm with every channel at
//! 0 A 34.5 A for 3.98 ms against its 12.4 A trip, TI's motor at 60 rpm with channel b
//! stuck (two shunts) 9.2 A for 6.88 ms against 7.4 A, the saturated 2.2 kW machine in
//! field weakening (1800 rpm) 31.8 A for 3.93 ms.

use acim_sim::faults::{run_sensor_cases, SensorCase};
use acim_sim::metrics::Metrics;

/// The points the drive does not reach without any sensor fault, so no fault is injected
/// there (the run is still checked against the criterion). The 37 kW machine with its
/// file's model trips `CurrentRegulation` at about 1570 rpm while accelerating at its
/// current limit towards its field-weakening point (the voltage saturates before the
/// flux is weakened): a drive limitation of its own, listed in `docs/faults.md`.
const NOT_REACHED: &[(&str, &str)] = &[("krause-50hp", "field weakening 2160 rpm")];

fn run_all() -> Vec<(SensorCase, Metrics)> {
    run_sensor_cases(&mut |sc| {
        acim_sim::run_with_metrics(sc)
            .map(|(_, m)| m)
            .map_err(|e| format!("{}: {e}", sc.name))
    })
    .unwrap()
}

#[test]
fn the_true_current_exceeds_the_trip_for_at_most_one_period_while_switching() {
    let rows = run_all();
    assert_eq!(
        rows.len(),
        5 * 4 * 4,
        "every machine, point, fault and sensing"
    );
    let mut failures = Vec::new();
    for (c, m) in &rows {
        let ts = c.scenario.drive.control_period_s;
        let name = &c.scenario.name;
        let line = format!(
            "{name}: {} after {:?} s (injected {:?}), peak {:.2} A, above the trip {:.1} us",
            m.fault.as_deref().unwrap_or("none"),
            m.fault_time_s,
            c.injected_at_s,
            m.peak_true_current_switching_a,
            m.above_trip_switching_longest_s * 1e6
        );
        println!("{line}");
        // the criterion holds in every run, the point reached or not
        if m.above_trip_switching_longest_s > ts {
            failures.push(format!("beyond one period: {line}"));
        }
        match (&c.not_reached, c.injected_at_s) {
            (Some(why), _) => {
                println!("  point not reached: {why}");
                if !NOT_REACHED.contains(&(c.machine, c.point.as_str())) {
                    failures.push(format!("point not reached ({why}): {line}"));
                }
            }
            (None, Some(at)) => {
                if m.fault_time_s.is_none_or(|t| t < at) {
                    failures.push(format!("no trip, or a trip before the fault: {line}"));
                }
            }
            (None, None) => failures.push(format!("no injection: {line}")),
        }
        if m.fault.is_some() && !m.switches_off_at_end {
            failures.push(format!("switching after the trip: {line}"));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// The same cases without the plant's comparator (the drive's software checks alone):
/// the finding reproduced. The true current stays above the trip for more than a period
/// while switching in many cases (each case and the worst are printed; the figures are in
/// the module documentation).
#[test]
fn without_the_comparator_the_true_current_stays_above_the_trip() {
    let mut beyond = Vec::new();
    let mut worst = (0.0f32, 0.0f32, String::new());
    for c in acim_sim::faults::sensor_cases().unwrap() {
        if c.not_reached.is_some() {
            continue;
        }
        let mut sc = c.scenario.clone();
        sc.inverter.hardware_trip = false;
        let (_, m) = acim_sim::run_with_metrics(&sc).unwrap();
        assert!(m.hardware_trip.is_none());
        let ts = sc.drive.control_period_s;
        if m.above_trip_switching_longest_s > ts {
            beyond.push(sc.name.clone());
        }
        if m.above_trip_switching_longest_s > worst.1 {
            worst = (
                m.peak_true_current_switching_a,
                m.above_trip_switching_longest_s,
                sc.name.clone(),
            );
        }
        println!(
            "{}: {} peak {:.2} A, above the trip {:.2} ms",
            sc.name,
            m.fault.as_deref().unwrap_or("none"),
            m.peak_true_current_switching_a,
            m.above_trip_switching_longest_s * 1e3
        );
    }
    println!(
        "{} cases beyond one period; worst {}: {:.2} A for {:.2} ms",
        beyond.len(),
        worst.2,
        worst.0,
        worst.1 * 1e3
    );
    assert!(!beyond.is_empty(), "the software alone kept every case");
}
