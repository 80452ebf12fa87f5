//! `commission` as a user runs it on the virtual board: the nameplate typed on the
//! command line, progress while it runs, the identified values with their bounds, the
//! settings unchanged until `commission apply`, then a sensorless start on those settings
//! alone. The motor model is the paper's machine
//! (shared/machines/paper-750w.toml: 750 W, 230 V, 3.3 A, 50 Hz, 1500 rpm), behind the
//! firmware's ADC conversion and the model's default inverter (1.5 us dead time).

use acim::{DriveState, MachineParams};
use acim_firmware_core::settings::{field_index, format_value};
use acim_vboard::board::Board;

fn say(b: &mut Board, line: &str) -> Vec<String> {
    let mut stream = false;
    b.handle_line(line.as_bytes(), &mut stream)
        .into_iter()
        .map(|l| String::from_utf8(l).unwrap().trim_end().to_string())
        .collect()
}

fn setting(b: &Board, name: &str) -> f32 {
    b.settings().get(field_index(name.as_bytes()).unwrap())
}

fn run(b: &mut Board, seconds: f32) {
    for _ in 0..(seconds * 5000.0) as u32 {
        b.step();
    }
}

#[test]
fn commissioning_identifies_the_motor_and_the_drive_runs_on_the_result() {
    let mut b = Board::new(false);
    run(&mut b, 0.01);
    // refused requests change nothing
    let before = *b.settings();
    let r = say(&mut b, "commission 2000 230 3.3 50 1500");
    assert!(r[0].starts_with("err (nameplate.power_w: "), "{r:?}");
    let r = say(&mut b, "commission 750 230 3.3 50");
    assert_eq!(r, ["err missing argument"]);
    assert_eq!(
        say(&mut b, "commission"),
        ["ok no commissioning yet (commission <P W> <V> <A> <Hz> <rpm>)"]
    );
    assert_eq!(*b.settings(), before);
    assert_eq!(b.state(), DriveState::Idle);

    let r = say(&mut b, "commission 750 230 3.3 50 1500");
    assert!(r[0].starts_with("ok commissioning started"), "{r:?}");
    assert_eq!(say(&mut b, "status"), ["ok state 5 fault 00"]);
    assert_eq!(say(&mut b, "start"), ["err refused in this state"]);
    assert!(say(&mut b, "set limits.current_limit 4")[0]
        .starts_with("err limits.current_limit: refused"));
    run(&mut b, 2.0);
    let p = say(&mut b, "commission");
    assert!(p[0].starts_with("ok commissioning: DC steps"), "{p:?}");
    // the whole sequence within the required 60 s
    let mut t = 2.0;
    while say(&mut b, "status")[0] == "ok state 5 fault 00" {
        assert!(t < 60.0, "commissioning should end within 60 s");
        run(&mut b, 0.5);
        t += 0.5;
    }
    let r = say(&mut b, "commission");
    println!("commissioned in about {t:.1} s:\n{}", r.join("\n"));
    assert_eq!(
        r.last().unwrap(),
        "ok commissioned: send 'commission apply' to use these settings \
         (or 'commission <P W> <V> <A> <Hz> <rpm>' to repeat)"
    );
    assert!(r[0].starts_with("identified in "), "{r:?}");
    // each identified value with its bound, the bound covering the true error
    let value = |name: &str| -> (f32, f32) {
        let l = r
            .iter()
            .find(|l| l.starts_with(&format!("identified {name} ")))
            .unwrap_or_else(|| panic!("no {name} in {r:?}"));
        let w: Vec<&str> = l.split(' ').collect();
        let bound = l.split("+/-").nth(1).unwrap().trim_end_matches(" %");
        (w[2].parse().unwrap(), bound.parse().unwrap())
    };
    let (rs, rs_pct) = value("rs");
    assert!((rs - 10.5).abs() / 10.5 < 0.02, "{rs}");
    assert!(rs_pct > 0.0 && rs_pct < 10.0, "{rs_pct}");
    assert!(
        100.0 * (rs - 10.5).abs() / 10.5 <= rs_pct + 0.05,
        "{rs} +/-{rs_pct} %"
    );
    for name in ["r_r", "l_sigma", "l_m", "loops.flux_current", "dead_time"] {
        let (v, pct) = value(name);
        assert!(v > 0.0 && pct > 0.0, "{name} {v} +/-{pct}");
    }
    // nothing applied yet: the settings are the ones before, and the drive idle
    assert_eq!(*b.settings(), before);
    assert_eq!(say(&mut b, "status"), ["ok state 0 fault 00"]);
    // the queries and save keep the result (save stores the settings in use)
    assert!(say(&mut b, "get").len() > 10);
    assert!(say(&mut b, "save")[0].starts_with("ok saved"));
    assert_eq!(say(&mut b, "commission"), r);
    let log = b.log().len();
    assert_eq!(
        say(&mut b, "commission apply"),
        ["ok applied (get lists the settings; save to keep them)"]
    );
    assert_ne!(*b.settings(), before);
    assert_eq!(
        say(&mut b, "commission apply"),
        ["err nothing to apply (already applied)"]
    );
    assert_eq!(
        say(&mut b, "commission").last().unwrap(),
        "ok commissioned: applied (get lists the settings; save to keep them)"
    );
    // the applied settings are an entry of the log (a replay reproduces them)
    assert_eq!(b.log().len(), log + 1);
    assert_eq!(
        b.log().iter().last().unwrap().event,
        acim_vboard::board::Event::Settings(*b.settings())
    );

    // against the paper machine's inverse-Gamma model (the bounds)
    let truth = MachineParams::paper_table1();
    let m = MachineParams::new(acim::MachineData {
        stator_resistance: setting(&b, "machine.stator_resistance"),
        rotor_resistance: setting(&b, "machine.rotor_resistance"),
        stator_inductance: setting(&b, "machine.stator_inductance"),
        rotor_inductance: setting(&b, "machine.rotor_inductance"),
        mutual_inductance: setting(&b, "machine.mutual_inductance"),
        pole_pairs: setting(&b, "machine.pole_pairs") as u8,
        inertia: setting(&b, "machine.inertia"),
        viscous_friction: setting(&b, "machine.viscous_friction"),
    })
    .unwrap();
    let err = |x: f32, t: f32| (x - t).abs() / t;
    let rs = err(m.stator_resistance(), truth.stator_resistance());
    let rr = err(
        m.referred_rotor_resistance(),
        truth.referred_rotor_resistance(),
    );
    let ls = err(m.transient_inductance(), truth.transient_inductance());
    let lm = err(
        m.mutual_inductance() * m.mutual_inductance() / m.rotor_inductance(),
        truth.mutual_inductance() * truth.mutual_inductance() / truth.rotor_inductance(),
    );
    let j = err(m.inertia(), truth.inertia());
    println!("errors: Rs {rs:.4}, R_R {rr:.4}, L_sigma {ls:.4}, L_M {lm:.4}, J {j:.4}");
    assert!(rs < 0.02 && rr < 0.05 && ls < 0.05 && lm < 0.05 && j < 0.10);
    assert_eq!(setting(&b, "machine.pole_pairs"), 2.0);
    let mut buf = [0u8; 24];
    let flux = String::from_utf8_lossy(format_value(setting(&b, "loops.flux_current"), &mut buf))
        .to_string();
    println!("loops.flux_current {flux} A");

    // the drive on the commissioned settings alone: wait for the flux to decay and the
    // rotor to coast down from the no-load test, then start, 500 rpm, the paper's load
    run(&mut b, 3.0);
    assert_eq!(say(&mut b, "start"), ["ok"]);
    assert_eq!(say(&mut b, "speed 500"), ["ok"]);
    run(&mut b, 3.0);
    assert_eq!(say(&mut b, "load 4"), ["ok"]);
    run(&mut b, 2.0);
    assert_eq!(say(&mut b, "status"), ["ok state 2 fault 00"]);
    let n = b.plant_speed_rpm();
    assert!((n - 500.0).abs() < 10.0, "plant speed {n} rpm");
}

#[test]
fn stop_aborts_commissioning_and_nothing_changes() {
    let mut b = Board::new(false);
    run(&mut b, 0.01);
    let before = *b.settings();
    assert!(
        say(&mut b, "commission 750 230 3.3 50 1500")[0].starts_with("ok commissioning started")
    );
    run(&mut b, 1.0);
    assert_eq!(say(&mut b, "stop"), ["ok"]);
    assert_eq!(say(&mut b, "status"), ["ok state 0 fault 00"]);
    run(&mut b, 0.1);
    assert_eq!(*b.settings(), before);
    assert_eq!(
        say(&mut b, "commission"),
        ["ok commissioning aborted by stop; settings unchanged"]
    );
    assert!(say(&mut b, "commission apply")[0].starts_with("err nothing to apply"));
    assert_eq!(*b.settings(), before);
}

/// A start before `commission apply` goes on with the settings in use: the result is
/// discarded, and `commission apply` has nothing to apply afterwards.
#[test]
fn a_start_before_the_apply_discards_the_result() {
    let mut b = Board::new(false);
    run(&mut b, 0.01);
    let before = *b.settings();
    assert!(
        say(&mut b, "commission 750 230 3.3 50 1500")[0].starts_with("ok commissioning started")
    );
    let mut t = 0.0;
    while say(&mut b, "status")[0] == "ok state 5 fault 00" {
        assert!(t < 60.0);
        run(&mut b, 0.5);
        t += 0.5;
    }
    assert!(say(&mut b, "commission")
        .last()
        .unwrap()
        .starts_with("ok commissioned: send 'commission apply'"));
    // the rotor coasts down from the no-load test and the flux decays, then a start
    run(&mut b, 3.0);
    assert_eq!(say(&mut b, "start"), ["ok"]);
    assert_eq!(say(&mut b, "stop"), ["ok"]);
    assert_eq!(
        say(&mut b, "commission apply"),
        ["err nothing to apply (discarded by a start, vf, set or defaults after it)"]
    );
    assert_eq!(
        say(&mut b, "commission").last().unwrap(),
        "ok commissioned: not applied (a start, vf, set or defaults came first; settings unchanged)"
    );
    assert_eq!(*b.settings(), before);
}

/// A 20 N m brake on the rotor (a coupled load nobody removed) stalls the no-load test:
/// the torque it needed at the hold names the coupled load, the settings stay, and the
/// switches are off.
#[test]
fn a_failed_commissioning_reports_why_and_changes_nothing() {
    let mut b = Board::new(false);
    run(&mut b, 0.01);
    let before = *b.settings();
    assert!(
        say(&mut b, "commission 750 230 3.3 50 1500")[0].starts_with("ok commissioning started")
    );
    run(&mut b, 0.5);
    assert_eq!(say(&mut b, "load 20"), ["ok"]);
    let mut t = 0.5;
    while say(&mut b, "status")[0] == "ok state 5 fault 00" {
        assert!(t < 60.0);
        run(&mut b, 0.5);
        t += 0.5;
    }
    let r = say(&mut b, "commission");
    assert_eq!(
        r,
        [
            "err commissioning failed: a load seems coupled (no-load torque over 10 % of rated) \
          (uncouple the load and run again (or check the power)); settings unchanged"
        ]
    );
    assert_eq!(*b.settings(), before);
    assert_eq!(b.state(), DriveState::Idle);
    assert_eq!(say(&mut b, "status"), ["ok state 0 fault 00"]);
    // a refused result can never be applied
    assert!(say(&mut b, "commission apply")[0].starts_with("err nothing to apply"));
    assert_eq!(*b.settings(), before);
}

/// The new user's run: a 1.5 N m brake left on the shaft (30 % of the rated torque),
/// `stop`, then `commission`: refused as a coupled load with what to do, the settings
/// unchanged, so the next start runs on the settings it had rather than on a model with
/// L_M and J corrupted by the load.
#[test]
fn a_coupled_load_is_refused_with_what_to_do() {
    let mut b = Board::new(false);
    run(&mut b, 0.01);
    let before = *b.settings();
    assert_eq!(say(&mut b, "load 1.5"), ["ok"]);
    assert_eq!(say(&mut b, "stop"), ["ok"]);
    assert!(
        say(&mut b, "commission 750 230 3.3 50 1500")[0].starts_with("ok commissioning started")
    );
    let mut t = 0.0;
    while say(&mut b, "status")[0] == "ok state 5 fault 00" {
        assert!(t < 60.0);
        run(&mut b, 0.5);
        t += 0.5;
    }
    let r = say(&mut b, "commission");
    assert_eq!(
        r,
        [
            "err commissioning failed: a load seems coupled (no-load torque over 10 % of rated) \
          (uncouple the load and run again (or check the power)); settings unchanged"
        ]
    );
    assert!(r[0].len() < acim_firmware_core::protocol::LINE_CAPACITY - 16);
    assert_eq!(*b.settings(), before);
    assert_eq!(say(&mut b, "status"), ["ok state 0 fault 00"]);
}
