//! One small interface to run any drive of this crate in a closed loop with SI samples:
//! the simulator, the tests and the host tools drive an f32 drive with any speed observer,
//! or the fixed-point drive behind its SI boundary, through [`Controller`] alone.

use crate::design::DriveConfig;
use crate::drive::{Drive, DriveInputs, DriveTelemetry, PwmOutput};
use crate::fixed::Q24;
use crate::frames::SinCos;
use crate::inverter_test::InverterTestOutcome;
use crate::observer::SpeedObserver;
use crate::rr_estimator::RrReport;
use crate::supervisor::{CommandError, DriveState, FaultReason};
use crate::svpwm::Modulator;

/// A drive as its owner sees it: commands, one step of SI samples in and duties out, state
/// and SI telemetry.
pub trait Controller {
    /// Idle -> Magnetizing (sensorless speed control after the flux is built).
    fn start(&mut self) -> Result<(), CommandError>;
    /// Idle -> OpenLoop (V/f).
    fn start_open_loop(&mut self) -> Result<(), CommandError>;
    /// Any active state -> Idle (switches off at once).
    fn stop(&mut self);
    /// Fault -> Idle.
    fn reset_fault(&mut self) -> Result<(), CommandError>;
    /// The speed target, rad/s mechanical.
    fn set_speed_target(&mut self, speed: f32) -> Result<(), CommandError>;
    /// One control step: phase currents (A) and bus (V) in, duties out.
    fn step(&mut self, inp: &DriveInputs) -> PwmOutput;
    /// Forces a fault from outside (hardware break, missed deadline).
    fn trip(&mut self, reason: FaultReason) -> PwmOutput;
    /// Present state.
    fn state(&self) -> DriveState;
    /// The latched fault, if any.
    fn fault(&self) -> Option<FaultReason>;
    /// What the last step computed, SI.
    fn telemetry(&self) -> DriveTelemetry;
    /// The configuration the drive was built with.
    fn config(&self) -> &DriveConfig;
    /// The inverter test at start: its last outcome and the dead time the drive now
    /// compensates, s (the configured one plus the test's correction; the configured
    /// device drop counted as known).
    fn inverter_test(&self) -> (InverterTestOutcome, f32);
    /// The rotor-resistance adaptation in SI ([`crate::rr_estimator`]).
    fn rotor_resistance(&self) -> RrReport;
    /// The current channels' gain ratio g_a / g_b as calibrated
    /// ([`crate::gain_calibration`]; 1 before any calibration).
    fn current_gain_correction(&self) -> f32;
}

impl<S: SinCos, O: SpeedObserver, M: Modulator> Controller for Drive<S, f32, O, M> {
    fn start(&mut self) -> Result<(), CommandError> {
        Drive::start(self)
    }
    fn start_open_loop(&mut self) -> Result<(), CommandError> {
        Drive::start_open_loop(self)
    }
    fn stop(&mut self) {
        Drive::stop(self)
    }
    fn reset_fault(&mut self) -> Result<(), CommandError> {
        Drive::reset_fault(self)
    }
    fn set_speed_target(&mut self, speed: f32) -> Result<(), CommandError> {
        Drive::set_speed_target(self, speed)
    }
    fn step(&mut self, inp: &DriveInputs) -> PwmOutput {
        Drive::step(self, inp)
    }
    fn trip(&mut self, reason: FaultReason) -> PwmOutput {
        Drive::trip(self, reason)
    }
    fn state(&self) -> DriveState {
        Drive::state(self)
    }
    fn fault(&self) -> Option<FaultReason> {
        Drive::fault(self)
    }
    fn telemetry(&self) -> DriveTelemetry {
        *Drive::telemetry(self)
    }
    fn config(&self) -> &DriveConfig {
        Drive::config(self)
    }
    fn inverter_test(&self) -> (InverterTestOutcome, f32) {
        let t = Drive::inverter_test(self);
        let c = Drive::config(self);
        (
            t.outcome,
            c.inverter.dead_time + t.correction_duty * c.loops.control_period,
        )
    }
    fn rotor_resistance(&self) -> RrReport {
        self.rotor_resistance_estimator()
            .report(self.design().model.referred_rotor_resistance, 1.0)
    }
    fn current_gain_correction(&self) -> f32 {
        Drive::current_gain_correction(self)
    }
}

impl<S: SinCos<Q24>, O: SpeedObserver<Q24>, M: Modulator<Q24>> Controller for Drive<S, Q24, O, M> {
    fn start(&mut self) -> Result<(), CommandError> {
        Drive::start(self)
    }
    fn start_open_loop(&mut self) -> Result<(), CommandError> {
        Drive::start_open_loop(self)
    }
    fn stop(&mut self) {
        Drive::stop(self)
    }
    fn reset_fault(&mut self) -> Result<(), CommandError> {
        Drive::reset_fault(self)
    }
    fn set_speed_target(&mut self, speed: f32) -> Result<(), CommandError> {
        self.set_speed_target_si(speed)
    }
    fn step(&mut self, inp: &DriveInputs) -> PwmOutput {
        self.step_si(inp)
    }
    fn trip(&mut self, reason: FaultReason) -> PwmOutput {
        Drive::trip(self, reason);
        PwmOutput::OFF
    }
    fn state(&self) -> DriveState {
        Drive::state(self)
    }
    fn fault(&self) -> Option<FaultReason> {
        Drive::fault(self)
    }
    fn telemetry(&self) -> DriveTelemetry {
        self.telemetry_si()
    }
    fn config(&self) -> &DriveConfig {
        Drive::config(self)
    }
    fn inverter_test(&self) -> (InverterTestOutcome, f32) {
        let t = Drive::inverter_test(self);
        let c = Drive::config(self);
        (
            t.outcome,
            c.inverter.dead_time
                + crate::fixed::q::from_q24(t.correction_duty.0) * c.loops.control_period,
        )
    }
    fn rotor_resistance(&self) -> RrReport {
        self.rotor_resistance_estimator().report(
            self.design().model.referred_rotor_resistance,
            self.bases().resistance(),
        )
    }
    fn current_gain_correction(&self) -> f32 {
        crate::fixed::q::from_q24(Drive::current_gain_correction(self).0)
    }
}
