//! Simulated power stage for the hardware-free self-test: the motor model
//! (`acim_plant::Plant`) behind this board's ADC (the inverse of [`Converter`], so the
//! firmware's real count-to-unit path is exercised) and the plant's PWM timing model
//! ([`PwmPreload`]: duties computed at step k act over the next period, as with TIM1's
//! preloaded compare registers; a switch-off acts at once).
//!
//! This is the only file that uses the model's API.

use crate::convert::{Converter, RawSample};
use acim::math::RAD_S_TO_RPM;
use acim::{MachineParams, PwmOutput};
use acim_plant::{
    BusVoltageSensor, CurrentSensors, InductionMachine, Inverter, LoadTorque, Plant, PwmPreload,
};

/// RK4 steps per period of the self-test's motor model (review D7: with the plant's
/// default of 10 the interrupt executed about 23 100 instructions, mostly the model's RK4
/// from flash, against a 200 us period). Two steps of 100 us against the machine's
/// fastest time constant sigma Ls / Rseq = 2.1 ms keep RK4's error far below the sensor
/// resolution.
pub const SELFTEST_SUBSTEPS: u32 = 2;

/// Motor model + simulated ADC + one-period PWM preload.
pub struct SimulatedStage {
    plant: Plant,
    conv: Converter,
    /// The compare registers' preload.
    pwm: PwmPreload,
    load: LoadTorque,
}

impl SimulatedStage {
    /// The paper's machine on the model's default inverter (325 V bus, 1.5 us dead time),
    /// sampled through `conv` (the board's nominal conversion: ideal offsets).
    pub fn new(conv: Converter) -> Self {
        let mut plant = Plant::new(
            InductionMachine::new(MachineParams::paper_table1()),
            Inverter::default(),
            CurrentSensors::ideal(),
            BusVoltageSensor::ideal(),
        );
        plant.set_substeps(SELFTEST_SUBSTEPS);
        Self {
            plant,
            conv,
            pwm: PwmPreload::new(),
            load: LoadTorque::None,
        }
    }

    /// Sets the load torque applied from the next period on.
    pub fn set_load(&mut self, load: LoadTorque) {
        self.load = load;
    }

    /// A brake (passive load, opposing the motion) of `nm` N m from the next period on, as
    /// the paper's powder brake (the `load` command); 0 removes it.
    pub fn set_brake_nm(&mut self, nm: f32) {
        self.load = if nm == 0.0 {
            LoadTorque::None
        } else {
            LoadTorque::Passive { torque: nm.abs() }
        };
    }

    /// What the ADC would convert at this sampling instant (true phase currents and bus
    /// through the board's gains, rounded and clamped to 12 bits). Never inlined, like
    /// [`SimulatedStage::run_period`].
    #[inline(never)]
    pub fn sample(&self) -> RawSample {
        let i = self.plant.phase_currents();
        RawSample {
            currents: [
                self.conv.amps_to_counts(0, i[0]),
                self.conv.amps_to_counts(1, i[1]),
                self.conv.amps_to_counts(2, i[2]),
            ],
            dc_bus: self.conv.volts_to_counts(self.plant.inverter().dc_bus()),
        }
    }

    /// Runs the present period with the command written one step earlier (all off at
    /// once if `next` switches off), then preloads `next` (what the compare registers and
    /// MOE would hold from the next update event).
    ///
    /// Never inlined: the self-test's motor model is not control code, and out of line it
    /// stays in flash with the plant (`firmware/ccmram.x`), leaving the CCM SRAM to the
    /// control step.
    #[inline(never)]
    pub fn run_period(&mut self, next: PwmOutput) {
        let applied = self.pwm.advance(next);
        self.plant.run_pwm_period(applied, self.load);
    }

    /// Replaces the preloaded command with all switches off (what clearing MOE does).
    pub fn switch_off(&mut self) {
        self.pwm.switch_off();
    }

    /// The model's true mechanical speed, rpm.
    pub fn speed_rpm(&self) -> f32 {
        self.plant.speed() * RAD_S_TO_RPM
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::board::{drive_config, POWER_STAGE};
    use crate::control::{ControlCommand, ControlLoop};
    use acim::{Drive, DriveState};

    /// The self-test's interrupt body, closed loop on the host: start, 500 rpm.
    #[test]
    fn closed_loop_through_the_adc_path() {
        let conv = Converter::new(&POWER_STAGE);
        let mut sim = SimulatedStage::new(conv);
        let mut ctl = ControlLoop::new(Drive::new(drive_config()).unwrap(), conv, 500);
        assert!(ctl.apply(ControlCommand::SpeedRpm(500.0)).result.is_ok());
        assert!(ctl.apply(ControlCommand::Start).result.is_ok());
        let mut last = None;
        for _ in 0..(5000 * 4) {
            let raw = sim.sample();
            let out = ctl.step(&raw);
            sim.run_period(out);
            if let Some(t) = ctl.finish_period(0, sim.speed_rpm()) {
                last = Some(t);
            }
        }
        let t = last.unwrap();
        assert_eq!(
            ctl.state(),
            DriveState::Running,
            "fault code {}",
            ctl.fault_code()
        );
        assert!((t.plant_speed_rpm - 500.0).abs() < 25.0, "{t:?}");
        assert!((t.speed_est_rpm - t.plant_speed_rpm).abs() < 25.0, "{t:?}");
    }
}
