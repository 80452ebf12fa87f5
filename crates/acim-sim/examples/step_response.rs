//! Orientation-step response over 3 s (development aid for docs/robustness.md): the
//! `stability` measurement with a longer record, printing the rms deviation of the
//! orientation error in 0.25 s windows after a 2 degree step of the plant's rotor flux.
//! `cargo run --release -p acim-sim --example step_response -- <rpm> <load N m> <off|running> [controller Rs factor]`
use acim::math::RPM_TO_RAD_S;
use acim::{Drive, DriveInputs, DriveState};
use acim_plant::{LoadTorque, PwmPreload};
use acim_sim::scenario::{LoadKind, LoadPoint, RsMode, SpeedPoint};

fn main() {
    let a: Vec<String> = std::env::args().skip(1).collect();
    let (rpm, load): (f32, f32) = (a[0].parse().unwrap(), a[1].parse().unwrap());
    let mut sc = acim_sim::stability::ideal_scenario("step");
    sc.duration_s = 10.0;
    sc.sensors.adc_bits = 16;
    sc.drive.loops.speed_ramp_rpm_s = 2000.0;
    if a[2] == "running" {
        sc.drive.estimation.rs_estimation = true;
        sc.drive.estimation.rs_estimation_mode = RsMode::Running;
    }
    if let Some(f) = a.get(3) {
        sc.controller.rs_ohm = f.parse::<f32>().unwrap() * sc.plant.rs_ohm;
    }
    sc.speed_profile = vec![SpeedPoint { t_s: 0.0, rpm }];
    sc.load_profile = vec![LoadPoint {
        t_s: 0.0,
        kind: LoadKind::Active,
        torque_nm: load,
    }];
    let v = sc.validate().unwrap();
    let mut plant = acim_sim::sim::build_plant_pub(&sc, &v);
    let mut drive = Drive::new(v.drive).unwrap();
    let ts = sc.drive.loops.control_period_s;
    let _ = drive.set_speed_target(rpm * RPM_TO_RAD_S);
    let _ = drive.start();
    let mut pwm = PwmPreload::new();
    let (settle, obs) = (3.0f32, 3.0f32);
    let n = ((settle + obs) / ts) as usize;
    let mut dev = Vec::new();
    let mut eq = 0.0;
    let mut loaded = false;
    for step in 0..n {
        let t = step as f32 * ts;
        if !loaded && drive.state() == DriveState::Running && t > 0.3 + rpm.abs() / 2000.0 {
            loaded = true;
        }
        if (t - settle).abs() < 0.5 * ts {
            let mut st = plant.machine().state();
            let (s, c) = (2.0f32.to_radians().sin(), 2.0f32.to_radians().cos());
            let (x, y) = (st.psi_alpha, st.psi_beta);
            st.psi_alpha = c * x - s * y;
            st.psi_beta = s * x + c * y;
            plant.machine_mut().set_state(st);
        }
        let meas = plant.sample();
        let out = drive.step(&DriveInputs {
            phase_currents: meas.phase_currents,
            dc_bus: meas.dc_bus,
        });
        if drive.state() == DriveState::Fault {
            println!("fault at {t:.3} s: {:?}", drive.fault());
            return;
        }
        let lam = plant.machine().lambda_r();
        let mut err = (drive.telemetry().angle - lam.beta.atan2(lam.alpha)).to_degrees() % 360.0;
        if err > 180.0 {
            err -= 360.0
        } else if err < -180.0 {
            err += 360.0
        }
        if t >= settle - 0.02 && t < settle {
            eq += err * ts / 0.02;
        }
        if t >= settle {
            dev.push(err - eq);
        }
        let applied = pwm.advance(out);
        let l = if loaded {
            LoadTorque::Active { torque: load }
        } else {
            LoadTorque::None
        };
        plant.run_pwm_period(applied, l);
    }
    let w = (0.25 / ts) as usize;
    let rms: Vec<String> = dev
        .chunks(w)
        .map(|c| {
            format!(
                "{:.3}",
                (c.iter().map(|x| x * x).sum::<f32>() / c.len() as f32).sqrt()
            )
        })
        .collect();
    println!("rms deviation (deg) per 0.25 s: {}", rms.join(" "));
    println!(
        "Rs estimate {:.3} ohm (machine {:.3})",
        drive.telemetry().stator_resistance_estimate,
        sc.plant.rs_ohm
    );
}
