//! A drive for your own motor from its nameplate alone:
//! `cargo run --release -p acim --example own_motor`.
//!
//! The path a user takes with a motor nobody measured: the nameplate and the power board
//! are all that is known; self-commissioning (`acim::commissioning`, the same kind of
//! per-period step as the drive) identifies the inverse-Gamma model (Rs, R_R, L_sigma,
//! L_M at rated flux), the inverter's dead time and the inertia; `acim::nameplate`
//! turns that model, the nameplate and the board into a complete, validated
//! `DriveConfig` (flux current, limits, trips, bandwidths, observer poles: nothing of the
//! paper's machine is left in a default). A nameplate that does not add up is rejected
//! with the field and the rule it breaks.
//!
//! "Your motor" here is motulator's 2.2 kW, 400 V, 4-pole machine on a 540 V bus, played
//! by the motor model with its T-model data (which the drive never sees), a 1.5 us dead
//! time and 1 V device drop, 12-bit sensors with noise. The timing model (sample, step,
//! duties act over the next period) is `closed_loop.rs`'s. Commissioning turns the rotor
//! (its no-load test), so the motor must be free to turn, uncoupled from its load.
use acim::commissioning::{Commissioning, Stage};
use acim::math::{RAD_S_TO_RPM, RPM_TO_RAD_S};
use acim::nameplate::{drive_config, Board, Nameplate};
use acim::{Drive, DriveInputs, DriveState, InverseGamma, MachineData, MachineParams};
use acim_plant::{
    Adc, BusSensorConfig, BusVoltageSensor, CurrentChannels, CurrentSensorConfig, CurrentSensors,
    InductionMachine, Inverter, InverterConfig, LoadTorque, Plant, PwmPreload,
};

fn main() {
    // what the user knows: the nameplate and the board
    let nameplate = Nameplate {
        power_w: 2200.0,
        voltage_v: 400.0, // line-to-line rms
        current_a: 5.0,   // rms
        frequency_hz: 50.0,
        speed_rpm: None, // not printed: the synchronous speed counts
        power_factor: None,
        pole_pairs: Some(2),
    };
    let mut board = Board::with_bus(540.0, 20.0); // 540 V bus, +/-20 A current sensing
    board.bus_full_scale_v = 810.0;

    // the motor the drive does not know (motulator's 2.2 kW example, T-model)
    let truth = MachineParams::new(MachineData {
        stator_resistance: 3.7,
        rotor_resistance: 2.296875,
        stator_inductance: 0.245,
        rotor_inductance: 0.245,
        mutual_inductance: 0.234265,
        pole_pairs: 2,
        inertia: 0.015,
        viscous_friction: 0.002,
    })
    .expect("consistent machine data");
    let mut plant = Plant::new(
        InductionMachine::new(truth),
        Inverter::new(InverterConfig::default(), board.dc_bus_v),
        CurrentSensors::new(
            CurrentSensorConfig {
                adc: Adc {
                    bits: 12,
                    full_scale: 20.0,
                    bipolar: true,
                },
                channels: CurrentChannels::Two,
                noise_std: 0.005,
                ..CurrentSensorConfig::default()
            },
            7,
        ),
        BusVoltageSensor::new(
            BusSensorConfig {
                adc: Adc {
                    bits: 12,
                    full_scale: 810.0,
                    bipolar: false,
                },
                ..BusSensorConfig::default()
            },
            8,
        ),
    );
    let mut pwm = PwmPreload::new();
    let ts = 1.0 / board.pwm_frequency_hz;

    // 1. self-commissioning: one step per control period, then the fits
    let mut com = Commissioning::new(&nameplate, &board).expect("a consistent nameplate");
    let mut t = 0.0;
    while !matches!(com.stage(), Stage::Done | Stage::Failed(_)) {
        assert!(t < 60.0, "commissioning should end within 60 s");
        let m = plant.sample();
        let out = com.step(&DriveInputs {
            phase_currents: m.phase_currents,
            dc_bus: m.dc_bus,
        });
        plant.run_pwm_period(pwm.advance(out), LoadTorque::None);
        t += ts;
    }
    let id = com.identify().expect("commissioning identifies the motor");
    println!(
        "commissioned in {t:.1} s: Rs {:.3} ohm ({:.3}), R_R {:.3} ohm ({:.3}), L_sigma {:.1} mH \
         ({:.1}), L_M {:.1} mH, dead time {:.2} us (1.50), J {:.4} kg m^2 (0.0150); true in brackets",
        id.stator_resistance,
        truth.stator_resistance(),
        id.rotor_resistance,
        truth.referred_rotor_resistance(),
        id.leakage_inductance * 1e3,
        truth.transient_inductance() * 1e3,
        id.magnetizing_inductance * 1e3,
        id.dead_time * 1e6,
        id.inertia.unwrap_or(f32::NAN),
    );

    // 2. the drive from the identified model, the nameplate and the board
    let model = MachineParams::from_inverse_gamma(InverseGamma {
        stator_resistance: id.stator_resistance,
        rotor_resistance: id.rotor_resistance,
        leakage_inductance: id.leakage_inductance,
        magnetizing_inductance: id.magnetizing_inductance,
        pole_pairs: 2,
        inertia: id.inertia.expect("a resolved inertia"),
        viscous_friction: id.viscous_friction,
    })
    .expect("a plausible identified model");
    board.dead_time_s = id.dead_time; // compensate what was measured
    let config = match drive_config(model, &nameplate, &board) {
        Ok(c) => c,
        Err(e) => panic!("configuration rejected: {e}"), // names the field and the rule
    };
    let mut drive = Drive::new(config).expect("drive_config validated it");

    // 3. idle for a second (the drive measures the current-sensor offsets with the
    //    switches off), then start: the rotor still coasts from the no-load test, and the
    //    start catches it (flying start); then a third of rated speed and rated torque
    //    (2200 W at the synchronous 1500 rpm: 14.0 N m)
    for _ in 0..(1.0 / ts) as usize {
        let m = plant.sample();
        let out = drive.step(&DriveInputs {
            phase_currents: m.phase_currents,
            dc_bus: m.dc_bus,
        });
        plant.run_pwm_period(pwm.advance(out), LoadTorque::None);
    }
    println!(
        "rotor at the start command: {:.1} rpm",
        plant.speed() * RAD_S_TO_RPM
    );
    drive.start().expect("idle drive starts");
    drive
        .set_speed_target(500.0 * RPM_TO_RAD_S)
        .expect("finite");
    let rated_torque = 2200.0 / (1500.0 * RPM_TO_RAD_S);
    let steps = (4.0 / ts) as usize;
    for k in 0..steps {
        let m = plant.sample();
        let out = drive.step(&DriveInputs {
            phase_currents: m.phase_currents,
            dc_bus: m.dc_bus,
        });
        let load = if k * 2 > steps {
            LoadTorque::Passive {
                torque: rated_torque,
            }
        } else {
            LoadTorque::None
        };
        plant.run_pwm_period(pwm.advance(out), load);
    }

    let speed_rpm = plant.speed() * RAD_S_TO_RPM;
    let tel = drive.telemetry();
    println!(
        "drive after 4 s: {:?}, speed {speed_rpm:.1} rpm (target 500), estimate {:.1} rpm, \
         load estimate {:.2} N m (true {rated_torque:.2})",
        drive.state(),
        tel.speed_estimate * RAD_S_TO_RPM,
        tel.load_torque_estimate,
    );
    assert_eq!(drive.state(), DriveState::Running);
    assert!((id.stator_resistance / truth.stator_resistance() - 1.0).abs() < 0.02);
    assert!((speed_rpm - 500.0).abs() < 15.0, "speed {speed_rpm} rpm"); // 1 % of rated
    assert!((tel.speed_estimate * RAD_S_TO_RPM - speed_rpm).abs() < 15.0);
    assert!((tel.load_torque_estimate - rated_torque).abs() < 0.1 * rated_torque);
}
