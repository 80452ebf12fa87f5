//! The self-test firmware's interrupt, period for period, on the host: the same
//! `ControlLoop` (software sin/cos), `SimulatedStage` and default settings, with the
//! commands applied in the periods the firmware applied them. Prints, per period, the
//! words of the firmware's `FIL_PROBE` (firmware/src/control_isr.rs) in hex, one period a
//! line, for the firmware-in-the-loop test that compares them bit for bit
//! (firmware/fil/test_fil.py, class `BitExact`).
//!
//!   cargo run -p acim-firmware-core --example hostloop -- <periods> [<schedule file>]
//!
//! The schedule has one `period code argument_bits` line (decimal, decimal, hex) per
//! command, with the codes of `FIL_PROBE`.
use acim::Drive;
use acim_firmware_core::board::{POWER_STAGE, TELEMETRY_DECIMATION};
use acim_firmware_core::control::{ControlCommand, ControlLoop};
use acim_firmware_core::convert::Converter;
use acim_firmware_core::settings::Settings;
use acim_firmware_core::sim::SimulatedStage;
use std::io::Write;

fn main() {
    let mut args = std::env::args().skip(1);
    let periods: u32 = args.next().and_then(|a| a.parse().ok()).unwrap_or(10_000);
    let mut schedule = std::collections::BTreeMap::new();
    if let Some(path) = args.next() {
        let text = std::fs::read_to_string(&path).expect("schedule file");
        for line in text.lines().filter(|l| !l.trim().is_empty()) {
            let w: Vec<&str> = line.split_whitespace().collect();
            let period: u32 = w[0].parse().expect("period");
            let code: u32 = w[1].parse().expect("code");
            let arg = f32::from_bits(u32::from_str_radix(w[2], 16).expect("argument bits"));
            let cmd = match code {
                1 => ControlCommand::Start,
                2 => ControlCommand::SpeedRpm(arg),
                3 => ControlCommand::PlantLoad(arg),
                4 => ControlCommand::Stop,
                5 => ControlCommand::StartOpenLoop,
                6 => ControlCommand::ResetFault,
                8 => ControlCommand::Rate(arg as u16),
                _ => panic!("unknown command code {code}"),
            };
            schedule.insert(period, (code, arg, cmd));
        }
    }
    let cfg = Settings::defaults()
        .drive_config()
        .expect("default settings");
    let conv = Converter::new(&POWER_STAGE);
    let mut ctl = ControlLoop::new(Drive::new(cfg).expect("drive"), conv, TELEMETRY_DECIMATION);
    let mut sim = SimulatedStage::new(conv);
    let out = std::io::stdout();
    let mut out = std::io::BufWriter::new(out.lock());
    for k in 0..periods {
        let (code, arg) = match schedule.get(&k) {
            Some(&(code, arg, cmd)) => {
                if let ControlCommand::PlantLoad(nm) = cmd {
                    sim.set_brake_nm(nm);
                }
                ctl.apply(cmd);
                (code, arg)
            }
            None => (0, 0.0),
        };
        let raw = sim.sample();
        let pwm = ctl.step(&raw);
        sim.run_period(pwm);
        let t = ctl.drive().telemetry();
        let words = [
            k,
            code,
            arg.to_bits(),
            pwm.duties[0].to_bits(),
            pwm.duties[1].to_bits(),
            pwm.duties[2].to_bits(),
            pwm.enabled as u32,
            t.speed_estimate.to_bits(),
            t.rotor_flux.to_bits(),
            sim.speed_rpm().to_bits(),
        ];
        let line: Vec<String> = words.iter().map(|w| format!("{w:08x}")).collect();
        writeln!(out, "{}", line.join(" ")).expect("stdout");
        ctl.finish_period(0, sim.speed_rpm());
    }
}
