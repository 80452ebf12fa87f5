//! The speed loop configured from the nameplate (`acim::speed_loop`, the two-degree-of-
//! freedom design with the observer's load estimate fed forward) on motulator's 2.2 kW
//! machine, both the plant and the sensors ideal (no dead time, no offset, no noise), as
//! in the side-by-side benchmark (`benches/peer/`): load steps, rated motoring load down
//! to zero speed, a reversal against a load, and the short-time overload rating
//! (`acim::thermal`).

/// Rated torque of the machine, N m.
const RATED_NM: f32 = 14.6;

use acim_tests::peer::{excursion, profiles, run, scenario};

/// A rated-load step at 750 rpm: the rotor slows by at most 151 rpm and is back within
/// 1 % (7.5 rpm) in at most 0.18 s (motulator's sensorless drive on the same machine,
/// the same current limit: 151 rpm and 0.18 s); measured 145 rpm and 0.10 s.
#[test]
fn a_rated_load_step_is_caught_as_fast_as_the_peer() {
    let sc = scenario(
        "step-750",
        3.5,
        &profiles(&[(0.2, 750.0)], &[(2.5, RATED_NM, 0.0)]),
    );
    let (rows, m) = run(&sc);
    assert_eq!(m.fault, None);
    let (dip, back) = excursion(&rows, 2.5, 7.5);
    assert!(dip <= 151.0, "dip {dip} rpm");
    assert!(back <= 0.18, "back within 1 % after {back} s");
    // and at 10 % of base speed: no fault, back within 1 % of the rated speed. (At 2 %
    // and 5 %, 30 and 75 rpm, a rated step, not a ramp, throws the rotor backwards through
    // the stator frequency's zero, where the observer loses it and the rotor runs away
    // until `Overload` trips: measured with and without the feed-forward; the ramped
    // load of the test below is held.)
    let rpm = 150.0;
    {
        let sc = scenario(
            &format!("step-{rpm}"),
            4.0,
            &profiles(&[(0.2, rpm)], &[(2.5, RATED_NM, 0.0)]),
        );
        let (rows, m) = run(&sc);
        assert_eq!(m.fault, None, "{rpm} rpm");
        let (dip, back) = excursion(&rows, 2.5, 15.0);
        assert!(
            dip < 200.0 && back < 0.5,
            "{rpm} rpm: dip {dip}, back {back} s"
        );
    }
}

/// Rated motoring load ramped in over 1 s at 45, 30 and 15 rpm and at a held zero speed:
/// held (the project's earlier speed PI, half as stiff and without the feed-forward,
/// let the rotor run away backwards and tripped `Overload` at each).
#[test]
fn rated_motoring_load_is_held_down_to_zero_speed() {
    for rpm in [45.0f32, 30.0, 15.0, 0.0] {
        let mut sc = scenario(
            &format!("rated-{rpm}"),
            5.0,
            &profiles(&[(0.2, rpm)], &[(2.0, RATED_NM, 1.0)]),
        );
        sc = sc
            .with_overrides(&["drive.zero_speed.policy=\"hold\"".to_string()])
            .unwrap();
        let (rows, m) = run(&sc);
        assert_eq!(m.fault, None, "{rpm} rpm");
        let (worst, _) = excursion(&rows, 4.0, 0.0);
        assert!(worst < 2.0, "{rpm} rpm: {worst} rpm off in the last second");
    }
}

/// A reversal +750 -> -750 rpm against half the rated load (active), load from 2 s:
/// within 20 rpm of the ramp (motulator: 18 rpm; measured 19 rpm). Not every reversal
/// is: with the load from 3 s (docs/peer-benchmark.md) the regeneration limit's hold at
/// the zero crossing shifts the drive's ramp by 57 rpm, which it then keeps to -750 rpm.
#[test]
fn a_reversal_against_a_load_follows_the_ramp() {
    let sc = scenario(
        "reversal-750",
        8.0,
        &profiles(
            &[(0.2, 750.0), (4.0, -750.0)],
            &[(2.0, 0.5 * RATED_NM, 0.0)],
        ),
    );
    let (rows, m) = run(&sc);
    assert_eq!(m.fault, None);
    let (worst, _) = excursion(&rows, 3.0, 0.0);
    assert!(worst <= 20.0, "{worst} rpm");
}

/// The short-time rating: the nameplate's limit is 1.5 x the rated current. A load of
/// 1.45 x rated is held while the allowance lasts (1 s at the limit here instead of 60
/// s: at |i_s| = 1.21 x the rated current, 1 s (1.5^2 - 1) / (1.21^2 - 1) = 2.7 s), then
/// the limit folds back to the rated current, the rotor slows and the drive faults
/// `Overload` (measured: the fold-back at 4.5 s, the fault at 5.0 s); 0.9 x rated is
/// held throughout.
#[test]
fn an_overload_is_held_for_the_rating_then_faults() {
    let over = scenario(
        "overload-145",
        7.0,
        &profiles(&[(0.2, 750.0)], &[(2.0, 1.45 * RATED_NM, 0.0)]),
    )
    .with_overrides(&["drive.limits.overload_duration_s=1.0".to_string()])
    .unwrap();
    let (rows, m) = run(&over);
    assert_eq!(m.fault.as_deref(), Some("Overload"), "{m:#?}");
    let t = m.fault_time_s.unwrap();
    assert!(t > 4.2 && t < 5.5, "faulted at {t} s");
    let held = rows.iter().filter(|r| r.t_s > 2.7 && r.t_s < 4.2);
    assert!(held.clone().count() > 0);
    for r in held {
        assert!(
            (r.speed_rpm - 750.0).abs() < 10.0,
            "{} rpm at {} s",
            r.speed_rpm,
            r.t_s
        );
    }
    let rated = scenario(
        "load-90",
        5.0,
        &profiles(&[(0.2, 750.0)], &[(2.0, 0.9 * RATED_NM, 0.0)]),
    )
    .with_overrides(&["drive.limits.overload_duration_s=1.0".to_string()])
    .unwrap();
    let (_, m) = run(&rated);
    assert_eq!(m.fault, None);
}
