//! A drive for your own motor, from its equivalent-circuit parameters:
//! `cargo run --release -p acim --example own_motor`.
//!
//! Commissioning (identifying these parameters from a nameplate and a few standstill and
//! no-load tests) is a separate issue that has not landed; until then you enter the
//! parameters yourself, as here. Every derived gain (current and speed PIs, observer,
//! flux model, limits) is computed by `DriveDesign` from them, and a parameter or setting
//! that does not make sense is rejected with the field and the rule it breaks.
//!
//! The motor here has plausible values for a 0.75 kW, 4-pole, 230 V / 50 Hz machine, smaller
//! and faster than the paper's: it runs to 1000 rpm and takes a 2 N m load, against the
//! motor model with the same parameters (the timing model is `closed_loop.rs`'s).
use acim::math::{RAD_S_TO_RPM, RPM_TO_RAD_S};
use acim::{Drive, DriveConfig, DriveInputs, DriveState, MachineData, MachineParams};
use acim_plant::{
    BusSensorConfig, BusVoltageSensor, CurrentChannels, CurrentSensors, InductionMachine, Inverter,
    LoadTorque, Plant, PwmPreload,
};

fn main() {
    let motor = MachineParams::new(MachineData {
        stator_resistance: 3.35,   // ohm, per phase (star equivalent)
        rotor_resistance: 1.99,    // ohm, referred to the stator
        stator_inductance: 0.1707, // H, Lm + stator leakage
        rotor_inductance: 0.1707,  // H, Lm + rotor leakage
        mutual_inductance: 0.1638, // H
        pole_pairs: 2,
        inertia: 0.003,         // kg m^2, motor and coupling
        viscous_friction: 5e-4, // N m s/rad
    })
    .expect("physically consistent parameters (Lm^2 < Ls Lr, all positive)");

    let mut config = DriveConfig::paper_defaults(); // 5 kHz, 325 V bus, paper's bandwidths
    config.machine = motor;
    config.rs_initial = motor.stator_resistance();
    config.flux_current = 2.5; // A peak: about 2/3 of rated flux, leaves voltage headroom
    config.current_limit = 6.0; // A peak: about 1.4x rated current
    config.overcurrent_trip = 8.0; // A: below the 10 A sensor full scale
    let mut drive = match Drive::new(config) {
        Ok(d) => d,
        Err(e) => panic!("configuration rejected: {e}"), // names the field and the rule
    };

    // the same motor as the plant, on the default inverter and G474-like sensors
    let mut plant = Plant::new(
        InductionMachine::new(motor),
        Inverter::default(),
        CurrentSensors::g474(CurrentChannels::Two, 7),
        BusVoltageSensor::new(BusSensorConfig::default(), 8),
    );
    let mut pwm = PwmPreload::new();
    drive.start().expect("idle drive starts");
    drive
        .set_speed_target(1000.0 * RPM_TO_RAD_S)
        .expect("finite");
    let steps = (4.0 / config.control_period) as usize;
    for k in 0..steps {
        let m = plant.sample();
        let out = drive.step(&DriveInputs {
            phase_currents: m.phase_currents,
            dc_bus: m.dc_bus,
        });
        let load = if k * 2 > steps {
            LoadTorque::Passive { torque: 2.0 }
        } else {
            LoadTorque::None
        };
        plant.run_pwm_period(pwm.advance(out), load);
    }

    let speed_rpm = plant.speed() * RAD_S_TO_RPM;
    let tel = drive.telemetry();
    println!(
        "own motor after 4 s: {:?}, speed {speed_rpm:.1} rpm (target 1000), estimate {:.1} rpm, \
         load estimate {:.2} N m (true 2.00), i_sq {:.2} A",
        drive.state(),
        tel.speed_estimate * RAD_S_TO_RPM,
        tel.load_torque_estimate,
        tel.current.q,
    );
    assert_eq!(drive.state(), DriveState::Running);
    assert!((speed_rpm - 1000.0).abs() < 10.0, "speed {speed_rpm} rpm");
    assert!((tel.load_torque_estimate - 2.0).abs() < 0.2);
}
