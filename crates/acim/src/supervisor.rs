//! The drive's state machine and every fault decision of the control step.
//!
//! The [`Supervisor`] is the only place that decides a fault: raw-sample checks
//! (non-finite, over-current, bus window), estimator plausibility (non-finite state, Rs at
//! its bound, an implausible load estimate that persists, over-speed) and the stall
//! detector. Each decision is a method that reads the design's
//! [`SupervisionLimits`] and returns `Some(reason)`; the cascade then switches off in the
//! same step. The counters the decisions need live here too, so resetting the supervisor
//! resets them all.

use crate::design::{CurrentSensing, SupervisionLimits};
use crate::num::Num;

/// Operating state of the drive.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum DriveState {
    /// Switches off, waiting for a start command.
    Idle,
    /// Building the rotor flux at zero torque, frame held.
    Magnetizing,
    /// Sensorless speed control.
    Running,
    /// Open-loop V/f (commissioning).
    OpenLoop,
    /// Switches off after a fault, until a deliberate reset.
    Fault,
}

impl DriveState {
    /// Small integer code for logs and CSV files: 0 idle, 1 magnetizing, 2 running,
    /// 3 open loop, 4 fault.
    pub fn code(self) -> u8 {
        match self {
            DriveState::Idle => 0,
            DriveState::Magnetizing => 1,
            DriveState::Running => 2,
            DriveState::OpenLoop => 3,
            DriveState::Fault => 4,
        }
    }
}

/// Why the drive faulted.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum FaultReason {
    /// A phase current exceeded the trip level (or an ADC saturated).
    OverCurrent,
    /// DC bus above its maximum (e.g. regenerative braking without a chopper).
    DcBusOverVoltage,
    /// DC bus below its minimum while active.
    DcBusUnderVoltage,
    /// Estimated speed beyond the over-speed limit.
    OverSpeed,
    /// A current or bus sample was NaN or infinite.
    NonFiniteInput,
    /// An estimator left its plausible range (Rs at a clamp bound, observer non-finite or
    /// load estimate implausible).
    EstimatorOutOfRange,
    /// The hardware break input (gate-driver fault, external over-current) fired.
    HardwareBreak,
    /// The control step did not finish before the next conversion.
    DeadlineMissed,
    /// Torque at its limit with no speed for `stall_time`, or a load estimate beyond the
    /// plausible range while the torque is at its limit: locked rotor or overload.
    Stall,
}

/// Commands refused by the drive.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum CommandError {
    /// The command does not apply in the present state (e.g. start while faulted).
    WrongState(DriveState),
    /// The value is not finite.
    NotFinite,
    /// The value is outside its documented range.
    OutOfRange,
}

/// What the estimation stage hands the supervisor's plausibility check.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EstimatorHealth<N = f32> {
    /// Omega_hat, rad/s.
    pub speed: N,
    /// T_L_hat, N m.
    pub load_torque: N,
    /// i_sq_hat, A.
    pub current: N,
    /// Whether the Rs estimate sits at a clamp bound.
    pub rs_at_bound: bool,
}

/// What the step should do after the supervisor's gate.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Gate {
    /// Switches off this step; `Some` when the gate itself just faulted.
    Off(Option<FaultReason>),
    /// Run the cascade in this state (`Magnetizing`, `Running` or `OpenLoop`).
    Run(DriveState),
}

/// The drive's state machine, fault latch and fault decisions, shared by the f32
/// [`crate::Drive`] and the fixed-point drive so that both obey the same commands: start
/// only from `Idle`, stop to `Idle` unless faulted, the first fault reason latched until
/// a deliberate reset.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Supervisor {
    state: DriveState,
    fault: Option<FaultReason>,
    implausible_steps: u32,
    stall_steps: u32,
}

impl Default for Supervisor {
    fn default() -> Self {
        Self::new()
    }
}

impl Supervisor {
    /// Idle, no fault.
    pub const fn new() -> Self {
        Self {
            state: DriveState::Idle,
            fault: None,
            implausible_steps: 0,
            stall_steps: 0,
        }
    }
    /// Present state.
    #[inline(always)]
    pub fn state(&self) -> DriveState {
        self.state
    }
    /// The latched fault, if any.
    pub fn fault(&self) -> Option<FaultReason> {
        self.fault
    }
    /// Idle -> `to` (`Magnetizing` or `OpenLoop`); any other state refuses. Clears the
    /// detectors' counters.
    pub fn start(&mut self, to: DriveState) -> Result<(), CommandError> {
        if self.state != DriveState::Idle {
            return Err(CommandError::WrongState(self.state));
        }
        self.state = to;
        self.implausible_steps = 0;
        self.stall_steps = 0;
        Ok(())
    }
    /// Any active state -> Idle; a faulted drive stays faulted.
    pub fn stop(&mut self) {
        if self.state != DriveState::Fault {
            self.state = DriveState::Idle;
        }
    }
    /// Fault -> Idle, clearing the latched reason.
    pub fn reset_fault(&mut self) -> Result<(), CommandError> {
        if self.state != DriveState::Fault {
            return Err(CommandError::WrongState(self.state));
        }
        self.fault = None;
        self.state = DriveState::Idle;
        Ok(())
    }
    /// Enters Fault; the first reason is kept.
    pub fn trip(&mut self, reason: FaultReason) {
        self.state = DriveState::Fault;
        if self.fault.is_none() {
            self.fault = Some(reason);
        }
    }
    /// Magnetizing -> Running (flux settled).
    pub fn magnetized(&mut self) {
        if self.state == DriveState::Magnetizing {
            self.state = DriveState::Running;
        }
    }

    /// The gate at the top of every step: in `Fault` switch off; in `Idle` switch off but
    /// still fault on a non-finite or over-current sample (bus limits apply only when the
    /// drive is about to switch); otherwise check the raw samples and run.
    #[inline(always)]
    pub fn gate<N: Num>(
        &mut self,
        limits: &SupervisionLimits<N>,
        currents: [N; 3],
        dc_bus: N,
    ) -> Gate {
        match self.state {
            DriveState::Fault => Gate::Off(None),
            DriveState::Idle => match check_samples(limits, currents, dc_bus) {
                Some(r @ (FaultReason::NonFiniteInput | FaultReason::OverCurrent)) => {
                    self.trip(r);
                    Gate::Off(Some(r))
                }
                _ => Gate::Off(None),
            },
            state => match check_samples(limits, currents, dc_bus) {
                Some(r) => {
                    self.trip(r);
                    Gate::Off(Some(r))
                }
                None => Gate::Run(state),
            },
        }
    }

    /// Estimator plausibility: a non-finite state, or Rs at its bound while it adapts,
    /// faults at once; an implausible load estimate must persist for
    /// `implausible_steps` (a current transient, e.g. a short, must trip on over-current
    /// first), and while the speed PI is saturated it means a stall; an estimated speed
    /// beyond `max_speed` is over-speed.
    #[inline(always)]
    pub fn plausibility<N: Num>(
        &mut self,
        limits: &SupervisionLimits<N>,
        h: &EstimatorHealth<N>,
        speed_pi_saturated: bool,
    ) -> Option<FaultReason> {
        if !(h.speed.is_finite() && h.load_torque.is_finite() && h.current.is_finite())
            || (limits.rs_bound_faults && h.rs_at_bound)
        {
            return Some(FaultReason::EstimatorOutOfRange);
        }
        self.implausible_steps = if h.load_torque.abs() > limits.max_load_torque {
            self.implausible_steps.saturating_add(1)
        } else {
            0
        };
        if self.implausible_steps > limits.implausible_steps {
            return Some(if speed_pi_saturated {
                FaultReason::Stall
            } else {
                FaultReason::EstimatorOutOfRange
            });
        }
        if h.speed.abs() > limits.max_speed {
            return Some(FaultReason::OverSpeed);
        }
        None
    }

    /// Stall: torque at its limit (speed PI saturated) while the speed estimate stays
    /// below 10 % of the reference for more than `stall_steps`.
    #[inline(always)]
    pub fn stall<N: Num>(
        &mut self,
        limits: &SupervisionLimits<N>,
        speed_pi_saturated: bool,
        speed_estimate: N,
        speed_reference: N,
    ) -> Option<FaultReason> {
        let stalled = speed_pi_saturated
            && speed_estimate.abs() < limits.stall_fraction * speed_reference.abs();
        self.stall_steps = if stalled {
            self.stall_steps.saturating_add(1)
        } else {
            0
        };
        if self.stall_steps > limits.stall_steps {
            Some(FaultReason::Stall)
        } else {
            None
        }
    }
}

/// Checks on the raw samples, before anything uses them: non-finite, over-current (the
/// third phase derived with two shunts), bus window.
#[inline(always)]
pub fn check_samples<N: Num>(
    limits: &SupervisionLimits<N>,
    currents: [N; 3],
    dc_bus: N,
) -> Option<FaultReason> {
    let [a, b, c_meas] = currents;
    let c = match limits.current_sensing {
        CurrentSensing::TwoPhase => -a - b,
        CurrentSensing::ThreePhase => c_meas,
    };
    // fast path: five comparisons, each false for NaN, so a good sample costs only these;
    // the reason of a bad one is sorted out off the hot path
    let trip = limits.overcurrent_trip;
    if a.abs() <= trip
        && b.abs() <= trip
        && c.abs() <= trip
        && dc_bus <= limits.dc_bus_max
        && dc_bus >= limits.dc_bus_min
    {
        return None;
    }
    classify_bad_samples(limits, a, b, c, dc_bus)
}

#[cold]
#[inline(never)]
fn classify_bad_samples<N: Num>(
    limits: &SupervisionLimits<N>,
    a: N,
    b: N,
    c: N,
    dc_bus: N,
) -> Option<FaultReason> {
    if !(a.is_finite() && b.is_finite() && c.is_finite() && dc_bus.is_finite()) {
        return Some(FaultReason::NonFiniteInput);
    }
    let trip = limits.overcurrent_trip;
    if a.abs() > trip || b.abs() > trip || c.abs() > trip {
        return Some(FaultReason::OverCurrent);
    }
    if dc_bus > limits.dc_bus_max {
        return Some(FaultReason::DcBusOverVoltage);
    }
    if dc_bus < limits.dc_bus_min {
        return Some(FaultReason::DcBusUnderVoltage);
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::design::{DriveConfig, DriveDesign};

    fn limits() -> SupervisionLimits<f32> {
        DriveDesign::new(DriveConfig::paper_defaults())
            .unwrap()
            .limits
    }

    #[test]
    fn samples_are_classified_by_cause() {
        let l = limits();
        assert_eq!(check_samples(&l, [0.0; 3], 325.0), None);
        assert_eq!(
            check_samples(&l, [f32::NAN, 0.0, 0.0], 325.0),
            Some(FaultReason::NonFiniteInput)
        );
        assert_eq!(
            check_samples(&l, [9.0, 0.0, 0.0], 325.0),
            Some(FaultReason::OverCurrent)
        );
        // two shunts: c = -a - b = -9 A trips although a and b are within the trip
        assert_eq!(
            check_samples(&l, [4.5, 4.5, 0.0], 325.0),
            Some(FaultReason::OverCurrent)
        );
        assert_eq!(
            check_samples(&l, [0.0; 3], 450.0),
            Some(FaultReason::DcBusOverVoltage)
        );
        assert_eq!(
            check_samples(&l, [0.0; 3], 150.0),
            Some(FaultReason::DcBusUnderVoltage)
        );
    }

    #[test]
    fn idle_gate_ignores_the_bus_but_not_overcurrent() {
        let l = limits();
        let mut s = Supervisor::new();
        assert_eq!(s.gate(&l, [0.0; 3], 0.0), Gate::Off(None));
        assert_eq!(s.state(), DriveState::Idle);
        assert_eq!(
            s.gate(&l, [9.0, 0.0, 0.0], 325.0),
            Gate::Off(Some(FaultReason::OverCurrent))
        );
        assert_eq!(s.fault(), Some(FaultReason::OverCurrent));
        // latched: a later, different fault does not replace the first
        s.trip(FaultReason::OverSpeed);
        assert_eq!(s.fault(), Some(FaultReason::OverCurrent));
    }

    #[test]
    fn implausible_load_must_persist_and_names_stall_when_saturated() {
        let l = limits();
        let mut s = Supervisor::new();
        s.start(DriveState::Magnetizing).unwrap();
        let bad = EstimatorHealth {
            speed: 10.0,
            load_torque: 2.0 * l.max_load_torque,
            current: 1.0,
            rs_at_bound: false,
        };
        for _ in 0..l.implausible_steps {
            assert_eq!(s.plausibility(&l, &bad, true), None);
        }
        assert_eq!(s.plausibility(&l, &bad, true), Some(FaultReason::Stall));
        let mut s = Supervisor::new();
        for _ in 0..l.implausible_steps {
            assert_eq!(s.plausibility(&l, &bad, false), None);
        }
        assert_eq!(
            s.plausibility(&l, &bad, false),
            Some(FaultReason::EstimatorOutOfRange)
        );
    }

    #[test]
    fn stall_counter_saturates_instead_of_overflowing() {
        let mut l = limits();
        l.stall_steps = u32::MAX;
        let mut s = Supervisor::new();
        s.stall_steps = u32::MAX - 1;
        for _ in 0..3 {
            assert_eq!(s.stall(&l, true, 0.0, 100.0), None);
        }
        assert_eq!(s.stall_steps, u32::MAX);
    }
}
