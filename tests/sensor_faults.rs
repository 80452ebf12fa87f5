//! Current-sensor faults at any speed on every acceptance machine: every channel reading
//! 0 A, or one channel stuck at its last reading, with two and three shunts, at 60, 500,
//! 1500 rpm and in field weakening (`acim_sim::faults::sensor_cases`, the rows of the
//! second table of `docs/faults.md`).
//!
//! The drive's software over-current trip cannot see a current its sensors do not report.
//! Two protections find these faults: the drive's sensor check (`acim::sensor_check`: a
//! channel standing still where the stator equation says the applied voltage moved it)
//! and the plant's hardware comparator (the simulator's default, at the drive's trip
//! level), which opens the switches. Acceptance: the true phase current above the drive's
//! trip level for at most one PWM period while switching (measured at every integration
//! sub-step, not only at the samples), every case ends with the switches off, the drive
//! trips after the fault, not before, and with one of these two reasons, the sensor
//! check within its bound ([`max_detection_periods`]); or, every channel dead, within the
//! same bound, with the control monitor's reasons whose documented scope includes dead
//! sensing (`NoCurrentResponse`, `CurrentRegulation`; a stuck channel also
//! `CurrentRegulation`).
//!
//! Measured (`cargo run --release -p acim-sim -- faults`, the table in `docs/faults.md`;
//! `cargo test -p acim-tests --test sensor_faults -- --nocapture` prints every case),
//! the machines configured from their nameplates (the flux observer, the default 1 kHz
//! slow task): at most 1.5 us above the trip in every case (the comparator's delay); the
//! sensor check first in 77 of the 108 reached cases (dead channels after at most 16
//! periods, a stuck one after at most 91 at 500 rpm and above, 273 at 60 rpm), the
//! comparator first in 25, the control monitor in 6: every channel dead on the 37 kW and
//! 7.5 kW machines at 60 rpm (`NoCurrentResponse` after 13-16 periods) and on the 37 kW
//! machine at 500 rpm with two shunts (`CurrentRegulation`, 16 periods), and channel b
//! stuck on the 2.2 kW machine at 500 rpm with two shunts (`CurrentRegulation` after 87
//! periods, before the sensor check's judgement in the slow task). Without the comparator
//! (the second test) 25 cases stay above the trip for more than a period while switching
//! (longest: the 0.18 kW machine at 1500 rpm with channel b stuck, two shunts, 3.81 A for
//! 4.76 ms); without the sensor check as well, 62 (longest: the 0.18 kW machine at
//! 1500 rpm, every channel dead, three shunts, 4.00 A for 7.23 ms).

use acim_sim::faults::{run_sensor_cases, SensorCase};
use acim_sim::metrics::Metrics;

/// The points the drive does not reach without any sensor fault, so no fault is injected
/// there (the run is still checked against the criterion). The 37 kW machine with its
/// file's model trips `CurrentRegulation` at about 1570 rpm while accelerating at its
/// current limit towards its field-weakening point (the voltage saturates before the
/// flux is weakened): a drive limitation of its own, listed in `docs/faults.md`.
/// The bound, in PWM periods after the injection, for a case. Every channel dead: two
/// of the sensor check's 8-period windows at any speed (the current loops wind up
/// against the missing current at once). One channel stuck at its last reading: it
/// reads the true current until the phase current leaves that reading, which it has
/// done by at least the check's threshold within half an electrical period at the
/// point (the phase current sweeps from one peak to the other), then two windows.
/// Measured: dead channels within 16 periods; stuck ones within 142 at 500 rpm and above
/// (the 37 kW machine, whose stuck reading first drives a torque-current transient the
/// check holds its decision through) and 655 at 60 rpm, against 166 and 1266 for that
/// machine (with the paper's observer: 99 and 612). With a slow task, which judges the
/// windows, one slow period more.
fn max_detection_periods(c: &SensorCase) -> f32 {
    let loops = &c.scenario.drive.loops;
    let windows = 2.0 * 8.0 + loops.slow_period_s / loops.control_period_s;
    if c.fault.contains("stuck") {
        let rpm: f32 = c
            .point
            .trim_end_matches(" rpm")
            .rsplit(' ')
            .next()
            .and_then(|x| x.parse().ok())
            .expect("the point's speed");
        let electrical_hz = rpm / 60.0 * c.scenario.plant.pole_pairs as f32;
        0.5 / electrical_hz / loops.control_period_s + windows
    } else {
        windows + 1.0
    }
}

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
        7 * 4 * 4,
        "every machine, point, fault and sensing"
    );
    let mut failures = Vec::new();
    let mut software = Vec::new();
    let mut hardware = 0;
    let mut monitor = 0;
    let mut worst = std::collections::BTreeMap::new();
    for (c, m) in &rows {
        let ts = c.scenario.drive.loops.control_period_s;
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
                // found by one of the current-path protections: the sensor check
                // (software) or the comparator (hardware), whichever comes first; every
                // channel dead, also the control monitor's checks on the measured
                // current against the voltage (NoCurrentResponse: "current sensing dead
                // or motor disconnected") or against its reference (CurrentRegulation),
                // within the sensor check's bound; a stuck channel, also the regulation
                // check, when the current it drives off its reference is judged before
                // the sensor check's windows (both judged in the slow task)
                let periods = (m.fault_time_s.unwrap_or(at) - at) / ts;
                let stuck = c.fault.contains("stuck");
                match m.fault.as_deref() {
                    Some(reason @ ("NoCurrentResponse" | "CurrentRegulation"))
                        if !stuck || reason == "CurrentRegulation" =>
                    {
                        monitor += 1;
                        if periods > max_detection_periods(c) {
                            failures.push(format!("found after {periods:.0} periods: {line}"));
                        }
                    }
                    Some("CurrentSensor") => {
                        software.push(periods);
                        worst
                            .entry((c.fault, c.point.starts_with("60 ")))
                            .and_modify(|w: &mut f32| *w = w.max(periods))
                            .or_insert(periods);
                        if periods > max_detection_periods(c) {
                            failures.push(format!("found after {periods:.0} periods: {line}"));
                        }
                    }
                    Some("HardwareBreak") => hardware += 1,
                    _ => failures.push(format!("not a current-path protection: {line}")),
                }
            }
            (None, None) => failures.push(format!("no injection: {line}")),
        }
        if m.fault.is_some() && !m.switches_off_at_end {
            failures.push(format!("switching after the trip: {line}"));
        }
    }
    software.sort_by(f32::total_cmp);
    println!(
        "sensor check first in {} cases (periods after the injection: median {:.0}, max {:.0}), \
         the comparator first in {hardware}, the control monitor in \
         {monitor}",
        software.len(),
        software.get(software.len() / 2).copied().unwrap_or(0.0),
        software.last().copied().unwrap_or(0.0),
    );
    for ((fault, low), w) in &worst {
        let at = if *low { "60 rpm" } else { "500 rpm and above" };
        println!("  {fault} at {at}: found after at most {w:.0} periods");
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// The same cases without the plant's comparator (the drive's software checks alone),
/// with and without the sensor check: the finding reproduced, and what the check gains.
/// The true current stays above the trip for more than a period while switching in some
/// cases (each case and the worst are printed; the figures are in the module
/// documentation): the check takes up to two windows, the loops can reach the trip
/// sooner. It must leave fewer such cases than the other checks alone.
#[test]
fn without_the_comparator_the_true_current_stays_above_the_trip() {
    let beyond_with = software_alone(true);
    let beyond_without = software_alone(false);
    assert!(
        !beyond_without.is_empty(),
        "the software alone kept every case"
    );
    assert!(
        beyond_with.len() < beyond_without.len() / 2,
        "the sensor check: {} cases beyond a period, {} without it",
        beyond_with.len(),
        beyond_without.len()
    );
}

/// The reached cases without the comparator whose true current stays above the trip for
/// more than a period while switching.
fn software_alone(sensor_check: bool) -> Vec<String> {
    let mut beyond = Vec::new();
    let mut worst = (0.0f32, 0.0f32, String::new());
    for c in acim_sim::faults::sensor_cases().unwrap() {
        if c.not_reached.is_some() {
            continue;
        }
        let mut sc = c.scenario.clone();
        sc.inverter.hardware_trip = false;
        sc.drive.limits.sensor_check = sensor_check;
        let (_, m) = acim_sim::run_with_metrics(&sc).unwrap();
        assert!(m.hardware_trip.is_none());
        let ts = sc.drive.loops.control_period_s;
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
            "{} (sensor check {sensor_check}): {} peak {:.2} A, above the trip {:.2} ms",
            sc.name,
            m.fault.as_deref().unwrap_or("none"),
            m.peak_true_current_switching_a,
            m.above_trip_switching_longest_s * 1e3
        );
    }
    println!(
        "sensor check {sensor_check}: {} cases beyond one period; worst {}: {:.2} A for {:.2} ms",
        beyond.len(),
        worst.2,
        worst.0,
        worst.1 * 1e3
    );
    beyond
}
