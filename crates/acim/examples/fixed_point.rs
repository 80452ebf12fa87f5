//! The fixed-point drive (Q7.24, for cores without an FPU) closed loop, next to the f32
//! drive on an identical plant: `cargo run --release -p acim --example fixed_point`.
//!
//! `FixedDrive` is the same cascade as `Drive` instantiated with the `Q24` number type; its
//! design is converted once from the f32 design with per-unit bases (`PerUnitBases::PAPER`:
//! 10 A, 400 V, 2000 rpm, ...), and `with_bases` rejects a configuration whose limits do
//! not fit them. On a microcontroller you call `step` with per-unit `Q24` samples and get
//! Q15 timer codes (`PwmOutput::q15`); on the host the `_si` methods convert at the
//! boundary, as here. The timing model is `closed_loop.rs`'s.
use acim::fixed::{FixedDrive, PerUnitBases};
use acim::math::{RAD_S_TO_RPM, RPM_TO_RAD_S};
use acim::{Drive, DriveConfig, DriveInputs, DriveState};
use acim_plant::{LoadTorque, Plant, PwmPreload};

fn main() {
    let config = DriveConfig::paper_defaults();
    let mut fixed = FixedDrive::with_bases(config, PerUnitBases::PAPER).expect("fits the bases");
    let mut float = Drive::new(config).expect("valid");
    // two identical plants (same noise seed), one per drive
    let (mut plant_fx, mut plant_fl) = (Plant::paper_default(3), Plant::paper_default(3));
    let (mut pwm_fx, mut pwm_fl) = (PwmPreload::new(), PwmPreload::new());

    fixed.start().expect("idle");
    float.start().expect("idle");
    fixed
        .set_speed_target_si(120.0 * RPM_TO_RAD_S)
        .expect("finite");
    float
        .set_speed_target(120.0 * RPM_TO_RAD_S)
        .expect("finite");
    let load = LoadTorque::Passive { torque: 1.5 };
    let steps = (3.0 / config.loops.control_period) as usize;
    let mut worst_diff_rpm = 0.0f32;
    for k in 0..steps {
        let (m_fx, m_fl) = (plant_fx.sample(), plant_fl.sample());
        let out_fx = fixed.step_si(&DriveInputs {
            phase_currents: m_fx.phase_currents,
            dc_bus: m_fx.dc_bus,
        });
        let out_fl = float.step(&DriveInputs {
            phase_currents: m_fl.phase_currents,
            dc_bus: m_fl.dc_bus,
        });
        plant_fx.run_pwm_period(pwm_fx.advance(out_fx), load);
        plant_fl.run_pwm_period(pwm_fl.advance(out_fl), load);
        if k * 3 > steps * 2 {
            let diff = fixed.telemetry_si().speed_estimate - float.telemetry().speed_estimate;
            worst_diff_rpm = worst_diff_rpm.max(diff.abs() * RAD_S_TO_RPM);
        }
    }

    let (s_fx, s_fl) = (
        plant_fx.speed() * RAD_S_TO_RPM,
        plant_fl.speed() * RAD_S_TO_RPM,
    );
    println!(
        "120 rpm with 1.5 N m after 3 s: fixed point {s_fx:.2} rpm ({:?}), f32 {s_fl:.2} rpm ({:?}); \
         largest speed-estimate difference over the last second {worst_diff_rpm:.3} rpm",
        fixed.state(),
        float.state(),
    );
    assert_eq!(fixed.state(), DriveState::Running);
    assert!((s_fx - 120.0).abs() < 5.0, "fixed-point speed {s_fx} rpm");
    assert!(worst_diff_rpm < 2.0, "fixed vs f32: {worst_diff_rpm} rpm");
}
