//! The drive's state machine and every fault decision of the control step.
//!
//! The [`Supervisor`] is the only place that decides a fault: raw-sample checks
//! (non-finite, over-current, bus window), estimator plausibility (non-finite state, Rs at
//! its bound, an implausible load estimate that persists, over-speed) and the stall
//! detector. Each decision is a method that reads the design's
//! [`SupervisionLimits`] and returns `Some(reason)`; the cascade then switches off in the
//! same step. The counters the decisions need live here too, so resetting the supervisor
//! resets them all.

use crate::config::CurrentSensing;
use crate::frames::{AlphaBeta, Dq};
use crate::num::DivSqrt;
use crate::num::Num;
use crate::num::PerUnitBases;
use crate::num::Units;

/// Limits and step counts the [`crate::Supervisor`] judges against: every fault decision
/// of the step reads only these.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SupervisionLimits<N: Num = f32> {
    /// Measured phases (the third current is derived with two shunts).
    pub current_sensing: CurrentSensing,
    /// Phase current trip, A.
    pub overcurrent_trip: N,
    /// Lowest DC bus while active, V.
    pub dc_bus_min: N,
    /// Highest DC bus, V.
    pub dc_bus_max: N,
    /// Over-speed trip on the estimated speed, rad/s.
    pub max_speed: N,
    /// Largest plausible |T_L_hat|, N m.
    pub max_load_torque: N,
    /// Steps an implausible load estimate may persist.
    pub implausible_steps: u32,
    /// Steps the stall condition may persist.
    pub stall_steps: u32,
    /// Steps the overload condition may persist (leaky): [`LimitSettings::overload_time`](crate::LimitSettings::overload_time).
    pub overload_steps: u32,
    /// Overload: speed error beyond this fraction of |reference| ([`OVERLOAD_FRACTION`](crate::design::OVERLOAD_FRACTION)).
    pub overload_fraction: N,
    /// ... and beyond this floor, rad/s ([`OVERLOAD_FRACTION`](crate::design::OVERLOAD_FRACTION) of 100 rpm, so that a
    /// reversal through zero does not count).
    pub overload_speed_floor: N,
    /// Torque at its limit with |w_s| below this, rad/s electrical (the orientation
    /// correction's fade-in start: no information below it) ...
    pub blind_frequency: N,
    /// ... for longer than this, steps (one rotor time constant): `Overload`.
    pub blind_steps: u32,
    /// Stall: speed estimate below this fraction of the reference ([`STALL_SPEED_FRACTION`](crate::design::STALL_SPEED_FRACTION)).
    pub stall_fraction: N,
    /// Whether an Rs estimate at its clamp bound faults (only while it adapts).
    pub rs_bound_faults: bool,
    /// The control monitor's leaky-mean gain Ts / T_f, T_f =
    /// [`MONITOR_FILTER_LOOP_CONSTANTS`](crate::design::MONITOR_FILTER_LOOP_CONSTANTS) / current_bandwidth.
    pub monitor_filter: N::Gain,
    /// The same leaky mean's gain per slow period (with a slow task, which updates it
    /// once per slow period on the period's means: [`ControlMonitor::judge`]),
    /// 1 - (1 - `monitor_filter`)^D.
    pub slow_monitor_filter: N::Gain,
    /// Largest mean |i* - i|, A: [`CURRENT_ERROR_FRACTION`](crate::design::CURRENT_ERROR_FRACTION) i_sd*.
    pub current_error_limit: N,
    /// Largest mean |a + b + c| with three shunts, A: [`CURRENT_SUM_FRACTION`](crate::design::CURRENT_SUM_FRACTION) of the trip.
    pub current_sum_limit: N,
    /// Largest mean current-loop integral |I_d| + |I_q|, V: [`RESIDUAL_RS_TOLERANCE`](crate::design::RESIDUAL_RS_TOLERANCE) Rs
    /// current_limit + [`RESIDUAL_VOLTAGE_FRACTION`](crate::design::RESIDUAL_VOLTAGE_FRACTION) of the linear limit at `dc_bus_max`.
    pub model_residual_limit: N,
    /// What the q integral may carry per |w_s| before it counts, V per rad/s electrical:
    /// [`RESIDUAL_FLUX_FRACTION`](crate::design::RESIDUAL_FLUX_FRACTION) of the rated
    /// rotor flux, the back-EMF an inductance error of the designed class leaves
    /// unexplained.
    pub residual_per_frequency: N::Gain,
    /// Longest magnetizing, steps: the Rs identification timeout (when it runs) plus
    /// [`MAGNETIZING_TIMEOUT_TAU_R`](crate::design::MAGNETIZING_TIMEOUT_TAU_R) tau_r, plus the flying start's speed search (when
    /// it runs).
    pub magnetizing_timeout_steps: u32,
    /// Periods after a switch-off before a start is accepted: [`DEMAGNETIZE_TAU_R`](crate::design::DEMAGNETIZE_TAU_R) tau_r.
    pub demagnetize_steps: u32,
    /// Idle offset means after the measurement: leaky-mean gain Ts /
    /// [`OFFSET_FILTER_TIME`](crate::design::OFFSET_FILTER_TIME).
    pub offset_filter: N::Gain,
    /// Idle samples averaged with equal weights, after which the offset means are trusted
    /// ([`OFFSET_MEASUREMENT_TIME`](crate::design::OFFSET_MEASUREMENT_TIME)).
    pub offset_settle_steps: u32,
    /// Idle periods after a switch-off whose samples are not taken
    /// ([`OFFSET_SWITCH_OFF_SKIP_TIME`](crate::design::OFFSET_SWITCH_OFF_SKIP_TIME), >= 1).
    pub offset_skip_steps: u32,
    /// Whether the speed-oscillation check runs ([`LimitSettings::speed_oscillation_check`](crate::LimitSettings::speed_oscillation_check)).
    pub oscillation_check: bool,
    /// The speed-oscillation check's block, steps ([`OSCILLATION_BLOCK_TIME`](crate::design::OSCILLATION_BLOCK_TIME)).
    pub oscillation_steps: u32,
    /// Its low-pass gain on the speed estimate's error, Ts /
    /// [`OSCILLATION_FILTER_TIME`](crate::design::OSCILLATION_FILTER_TIME).
    pub oscillation_filter: N::Gain,
    /// Largest swing (peak to peak) of the speed estimate's error over a block with the
    /// reference steady, rad/s: [`OSCILLATION_FRACTION`](crate::design::OSCILLATION_FRACTION) of `max_speed`.
    pub oscillation_swing: N,
    /// Largest idle offset of a channel, A: [`OFFSET_FRACTION`](crate::design::OFFSET_FRACTION) of the trip (also the
    /// largest DC component of the running alpha-beta current).
    pub offset_limit: N,
    /// The running offset check's leaky-mean gain Ts / [`RUNNING_OFFSET_FILTER_TIME`](crate::design::RUNNING_OFFSET_FILTER_TIME).
    pub running_offset_filter: N::Gain,
    /// ... and per slow period, 1 - (1 - `running_offset_filter`)^D.
    pub slow_running_offset_filter: N::Gain,
    /// The running offset check counts only above this |w_s|, rad/s electrical:
    /// 4 I_max / (offset_limit T), where the AC current's ripple through the mean plus the
    /// transient of a current that starts at that frequency, at most 2 I_max / (|w_s| T),
    /// stays below half the limit.
    pub running_offset_min_frequency: N,
    /// Largest resistance the current-response check allows, ohm:
    /// (1 + [`RESIDUAL_RS_TOLERANCE`](crate::design::RESIDUAL_RS_TOLERANCE)) Rs + R_R (while the flux builds with the frame
    /// held, d lambda_r/dt = R_R i_sd - lambda_r/tau_r adds up to R_R |i|).
    pub impedance_resistance: N,
    /// Largest inductance the current-response check allows, H: Ls (the machine's
    /// impedance is below Rs_max + |w_s| Ls at any slip).
    pub impedance_inductance: N::Gain,
    /// The current-response check judges only above this mean voltage, V: Rs
    /// current_limit (the voltage of the largest current at standstill).
    pub impedance_voltage_floor: N,
}

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
    /// The measured current does not follow its reference (open phase, dead or stuck
    /// current sensor, voltage saturation): judged on the measurements, not the estimates.
    CurrentRegulation,
    /// The current loops need a voltage the machine model does not explain (the speed or
    /// flux estimate is wrong: runaway under an overhauling load, lost orientation).
    LossOfControl,
    /// A current channel fails: one that stands still where the applied voltage moves
    /// the current (dead or stuck, [`crate::sensor_check`]), three phase currents that do
    /// not sum to zero, or an offset beyond its limit.
    CurrentSensor,
    /// Torque at its limit with the speed far from its reference for longer than the
    /// speed loop settles: a load beyond the drive's torque capability (or control lost
    /// where the machine is unobservable).
    Overload,
    /// Magnetizing did not finish within its timeout (flux never settled).
    MagnetizingTimeout,
    /// The applied voltage drives far less measured current than the machine's largest
    /// impedance allows: current sensing dead (all channels at zero) or motor disconnected.
    NoCurrentResponse,
    /// The speed estimate swings around a steady reference block after block: a limit
    /// cycle (a current-sensor offset the tracker does not hold, a model error at low
    /// speed), which the other checks see only as a moderate error ([`SpeedOscillation`]).
    SpeedOscillation,
}

/// Consecutive oscillating blocks that fault ([`SpeedOscillation`]).
pub const OSCILLATION_BLOCKS: u32 = 3;

/// A limit cycle around a steady reference: the speed estimate's error (Omega_hat -
/// Omega*), low-pass filtered over `oscillation_filter` (10 ms: an observer's noise of
/// +/-20 rpm out, a 1-6 Hz cycle kept), is watched over blocks of `oscillation_steps` periods; a block whose swing
/// (peak to peak) exceeds `oscillation_swing` counts, [`OSCILLATION_BLOCKS`] such blocks
/// in a row fault [`FaultReason::SpeedOscillation`]. A block with the reference moving
/// (a ramp) starts the count again: a load step's transient lasts one block, a limit
/// cycle all of them. Detection within `OSCILLATION_BLOCKS + 1` blocks of the cycle's
/// start (4 s by default).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SpeedOscillation<N: Num = f32> {
    /// The error, low-pass filtered (the estimate's noise out), rad/s.
    filtered: N,
    steps: u32,
    low: N,
    high: N,
    blocks: u32,
}

impl<N: Num + DivSqrt> SpeedOscillation<N> {
    /// One period: `error` = Omega_hat - Omega* (rad/s); `steady` false while the
    /// reference ramps (or the drive magnetizes), which restarts the count. Never
    /// reports with the check off.
    pub fn update(
        &mut self,
        limits: &SupervisionLimits<N>,
        error: N,
        steady: bool,
    ) -> Option<FaultReason> {
        if !limits.oscillation_check || !steady {
            *self = Self {
                filtered: error,
                ..Self::default()
            };
            return None;
        }
        self.filtered = self.filtered + N::gain(limits.oscillation_filter, error - self.filtered);
        let e = self.filtered;
        if self.steps == 0 {
            self.low = e;
            self.high = e;
        } else if e < self.low {
            self.low = e;
        } else if e > self.high {
            self.high = e;
        }
        self.steps += 1;
        if self.steps < limits.oscillation_steps {
            return None;
        }
        // (a block's end: one call of `oscillation_steps`, marked cold)
        core::hint::cold_path();
        self.steps = 0;
        if self.high - self.low > limits.oscillation_swing {
            self.blocks += 1;
        } else {
            self.blocks = 0;
        }
        (self.blocks >= OSCILLATION_BLOCKS).then_some(FaultReason::SpeedOscillation)
    }
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
    /// A current channel's zero offset, measured with the switches off while idle, is
    /// beyond its limit: the start is refused and the drive faults (`CurrentSensor`).
    SensorOffset,
    /// The switches turned off less than [`crate::design::DEMAGNETIZE_TAU_R`] rotor time
    /// constants ago: the rotor flux of the last run has not decayed. Retry after that
    /// time; nothing changed.
    Demagnetizing,
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
    overload_steps: u32,
    blind_steps: u32,
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
            overload_steps: 0,
            blind_steps: 0,
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
        self.overload_steps = 0;
        self.blind_steps = 0;
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
    pub fn gate<N: Num + DivSqrt>(
        &mut self,
        limits: &SupervisionLimits<N>,
        currents: [N; 3],
        dc_bus: N,
    ) -> Gate {
        // (the switched-off and faulting arms are marked cold: the running period's path
        // falls through, the others jump; the outcome is the same)
        match self.state {
            DriveState::Fault => {
                core::hint::cold_path();
                Gate::Off(None)
            }
            DriveState::Idle => {
                core::hint::cold_path();
                match check_samples(limits, currents, dc_bus) {
                    Some(r @ (FaultReason::NonFiniteInput | FaultReason::OverCurrent)) => {
                        self.trip(r);
                        Gate::Off(Some(r))
                    }
                    _ => Gate::Off(None),
                }
            }
            state => match check_samples(limits, currents, dc_bus) {
                Some(r) => {
                    core::hint::cold_path();
                    self.trip(r);
                    Gate::Off(Some(r))
                }
                None => Gate::Run(state),
            },
        }
    }

    /// The part of [`Self::plausibility`] that runs every control period: the estimates
    /// finite and the Rs estimate off its bounds (with `rs_bound_faults`);
    /// `EstimatorOutOfRange` otherwise.
    #[inline(always)]
    pub fn estimates_valid<N: Num + DivSqrt>(
        limits: &SupervisionLimits<N>,
        h: &EstimatorHealth<N>,
    ) -> Option<FaultReason> {
        if !N::all_finite([h.speed, h.load_torque, h.current])
            || (limits.rs_bound_faults && h.rs_at_bound)
        {
            core::hint::cold_path();
            Some(FaultReason::EstimatorOutOfRange)
        } else {
            None
        }
    }

    /// Estimator plausibility: a non-finite state, or Rs at its bound while it adapts,
    /// faults at once; an implausible load estimate must persist for
    /// `implausible_steps` (a current transient, e.g. a short, must trip on over-current
    /// first), and while the speed PI is saturated it means a stall; an estimated speed
    /// beyond `max_speed` is over-speed.
    #[inline(always)]
    pub fn plausibility<N: Num + DivSqrt>(
        &mut self,
        limits: &SupervisionLimits<N>,
        h: &EstimatorHealth<N>,
        speed_pi_saturated: bool,
    ) -> Option<FaultReason> {
        if let Some(reason) = Self::estimates_valid(limits, h) {
            return Some(reason);
        }
        self.implausible_steps = if h.load_torque.abs() > limits.max_load_torque {
            core::hint::cold_path();
            self.implausible_steps.saturating_add(1)
        } else {
            0
        };
        if self.implausible_steps > limits.implausible_steps {
            core::hint::cold_path();
            return Some(if speed_pi_saturated {
                FaultReason::Stall
            } else {
                FaultReason::EstimatorOutOfRange
            });
        }
        if h.speed.abs() > limits.max_speed {
            core::hint::cold_path();
            return Some(FaultReason::OverSpeed);
        }
        None
    }

    /// Magnetizing timeout: the flux (and the standstill Rs identification) must settle
    /// within `magnetizing_timeout_steps`.
    #[inline(always)]
    pub fn magnetizing<N: Num + DivSqrt>(
        &self,
        limits: &SupervisionLimits<N>,
        magnetizing_steps: u32,
    ) -> Option<FaultReason> {
        if magnetizing_steps > limits.magnetizing_timeout_steps {
            Some(FaultReason::MagnetizingTimeout)
        } else {
            None
        }
    }

    /// Torque at its limit (speed PI saturated) while the frame's stator frequency sits
    /// below `blind_frequency`, where no fundamental-model estimator sees the rotor (the
    /// orientation correction has no information there either), integrated with a leak
    /// beyond `blind_steps` (one rotor time constant: the time on which the flux model's
    /// error grows when the frame stands still): `Overload`. This is the signature of an
    /// overhauling load beyond what the drive holds at low speed: the estimate settles
    /// where the regenerating slip cancels it (w_s = 0, DC stator currents, which fit any
    /// rotor speed) while the rotor runs away. A reversal at the torque limit crosses the
    /// band in a few milliseconds.
    #[inline(always)]
    pub fn blind<N: Num + DivSqrt>(
        &mut self,
        limits: &SupervisionLimits<N>,
        speed_pi_saturated: bool,
        stator_frequency: N,
    ) -> Option<FaultReason> {
        let blind = speed_pi_saturated && stator_frequency.abs() < limits.blind_frequency;
        self.blind_steps = if blind {
            self.blind_steps.saturating_add(1)
        } else {
            self.blind_steps.saturating_sub(1)
        };
        if self.blind_steps > limits.blind_steps {
            core::hint::cold_path();
            Some(FaultReason::Overload)
        } else {
            None
        }
    }

    /// Stall: torque at its limit (speed PI saturated) while the speed estimate stays
    /// below 10 % of the reference, integrated with a leak (up one step while stalled,
    /// down one step otherwise) beyond `stall_steps`.
    #[inline(always)]
    pub fn stall<N: Num + DivSqrt>(
        &mut self,
        limits: &SupervisionLimits<N>,
        speed_pi_saturated: bool,
        speed_estimate: N,
        speed_reference: N,
    ) -> Option<FaultReason> {
        let stalled = speed_pi_saturated
            && speed_estimate.abs() < limits.stall_fraction * speed_reference.abs();
        // leaky integration: a step out of the stall condition drains one step instead of
        // clearing the count, so a load that pushes the speed estimate over the threshold
        // now and then cannot hold the detector off
        self.stall_steps = if stalled {
            self.stall_steps.saturating_add(1)
        } else {
            self.stall_steps.saturating_sub(1)
        };
        // overload: torque at its limit while the speed is more than half the reference
        // away from it, longer than the speed loop takes to settle (the load beats the
        // drive, or the drive lost the machine where it is unobservable)
        let band = speed_reference.abs() * limits.overload_fraction;
        let band = if band > limits.overload_speed_floor {
            band
        } else {
            limits.overload_speed_floor
        };
        let overloaded = speed_pi_saturated && (speed_estimate - speed_reference).abs() > band;
        self.overload_steps = if overloaded {
            self.overload_steps.saturating_add(1)
        } else {
            self.overload_steps.saturating_sub(1)
        };
        if self.stall_steps > limits.stall_steps {
            Some(FaultReason::Stall)
        } else if self.overload_steps > limits.overload_steps {
            // with no speed at all it is a stall, found sooner
            Some(if stalled {
                FaultReason::Stall
            } else {
                FaultReason::Overload
            })
        } else {
            None
        }
    }
}

/// What the control monitor reads each step ([`ControlMonitor::check`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ControlMonitorInputs<N: Num = f32> {
    /// This step's current reference, A.
    pub i_ref: Dq<N>,
    /// This step's measured current, A.
    pub i: Dq<N>,
    /// This step's voltage command, V.
    pub v: Dq<N>,
    /// The current loops' integrals (the model's voltage residual), V.
    pub residual: Dq<N>,
    /// a + b + c as measured (three shunts; 0 with two), A.
    pub current_sum: N,
    /// The stator frequency w_s (only to bound the impedance), rad/s electrical.
    pub stator_frequency: N,
    /// A current loop's output is at the voltage limit: an unmet reference is the
    /// machine's limit, not a fault, and the regulation error holds.
    pub voltage_limited: bool,
}

/// Estimate-independent consistency of the running control, judged on the measured
/// currents, the current references and the voltage the current loops need beyond the
/// machine model (their integrators: in steady state the feed-forward of eq. 9a-9b
/// holds the model's voltage, so the integral is the part the model does not explain).
/// Each signal is a leaky mean over `monitor_filter` (first order, time constant from
/// the design); see [`SupervisionLimits`] for how each threshold follows from the
/// configuration.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ControlMonitor<N: Num = f32> {
    /// Leaky mean of |i_sd* - i_sd| + |i_sq* - i_sq|, A.
    pub current_error: N,
    /// Leaky mean of |I_d| + |I_q|, the current-loop integrals (model voltage residual),
    /// the steady part of I_q less [`SupervisionLimits::residual_per_frequency`] |w_s|, V.
    pub model_residual: N,
    /// Leaky mean of I_q (signed), the q integral's steady part, V.
    pub q_residual: N,
    /// Leaky mean of |a + b + c| (three shunts; 0 with two), A.
    pub current_sum: N,
    /// Leaky mean of the commanded |v_d| + |v_q|, V.
    pub voltage: N,
    /// Leaky mean of the voltage the measured current can account for,
    /// (Rs_max + |w_s| Ls)(|i_d| + |i_q|), V.
    pub explained_voltage: N,
    /// Leaky mean of the measured alpha-beta current over about a second, counted only
    /// where the stator frequency makes the true current AC (running offset check), A.
    pub dc_current: AlphaBeta<N>,
    /// With a slow task: the signals' means over the slow period so far.
    pub means: MonitorMeans<N>,
}

/// The control monitor's signals of one period (or their means over a slow period).
#[derive(Clone, Copy, Debug, PartialEq)]
struct Signals<N: Num> {
    /// |i_sd* - i_sd| + |i_sq* - i_sq|, A.
    current_error: N,
    /// |a + b + c|, A.
    current_sum: N,
    /// |v_d| + |v_q|, V.
    voltage: N,
    /// (Rs_max + |w_s| Ls)(|i_d| + |i_q|), V.
    explained_voltage: N,
}

impl<N: Num> Signals<N> {
    /// This period's signals from the monitor's inputs `x`.
    #[inline(always)]
    fn of(limits: &SupervisionLimits<N>, x: &ControlMonitorInputs<N>) -> Self {
        let (i_ref, i, v) = (x.i_ref, x.i, x.v);
        let i_mag = i.d.abs() + i.q.abs();
        Self {
            current_error: (i_ref.d - i.d).abs() + (i_ref.q - i.q).abs(),
            current_sum: x.current_sum.abs(),
            voltage: v.d.abs() + v.q.abs(),
            explained_voltage: limits.impedance_resistance * i_mag
                + N::gain_mul(limits.impedance_inductance, x.stator_frequency.abs(), i_mag),
        }
    }
}

/// What the fast path gathers for the control monitor over a slow period
/// ([`ControlMonitor::gather`]): each period's signal times 1/D, summed (D the drive's
/// `slow_divider`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MonitorMeans<N: Num = f32> {
    /// The means of the monitor's signals.
    signals: Signals<N>,
    /// A period of the slow period had a current loop at the voltage limit (the
    /// regulation error's mean then holds).
    pub voltage_limited: bool,
    /// Mean alpha-beta current, A.
    pub current: AlphaBeta<N>,
}

impl<N: Num> MonitorMeans<N> {
    /// Nothing gathered.
    pub fn zero() -> Self {
        Self {
            signals: Signals {
                current_error: N::ZERO,
                current_sum: N::ZERO,
                voltage: N::ZERO,
                explained_voltage: N::ZERO,
            },
            voltage_limited: false,
            current: AlphaBeta {
                alpha: N::ZERO,
                beta: N::ZERO,
            },
        }
    }
}

impl<N: Num + DivSqrt> Default for ControlMonitor<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<N: Num + DivSqrt> ControlMonitor<N> {
    /// All means at zero.
    pub fn new() -> Self {
        Self {
            current_error: N::ZERO,
            model_residual: N::ZERO,
            q_residual: N::ZERO,
            current_sum: N::ZERO,
            voltage: N::ZERO,
            explained_voltage: N::ZERO,
            dc_current: AlphaBeta {
                alpha: N::ZERO,
                beta: N::ZERO,
            },
            means: MonitorMeans::zero(),
        }
    }

    /// The fast path's half of [`ControlMonitor::check`] and
    /// [`ControlMonitor::check_offset_drift`] in a drive with a slow task: this period's
    /// signals, weighted by `weight` = 1/D, added to [`ControlMonitor::means`]; `i_ab` the
    /// measured alpha-beta current, A.
    #[inline(always)]
    pub fn gather(
        &mut self,
        limits: &SupervisionLimits<N>,
        x: &ControlMonitorInputs<N>,
        i_ab: AlphaBeta<N>,
        weight: N::Gain,
    ) {
        let sig = Signals::of(limits, x);
        let m = &mut self.means;
        let add = |mean: N, x: N| mean + N::gain(weight, x);
        let s = &mut m.signals;
        s.current_error = add(s.current_error, sig.current_error);
        s.current_sum = add(s.current_sum, sig.current_sum);
        s.voltage = add(s.voltage, sig.voltage);
        s.explained_voltage = add(s.explained_voltage, sig.explained_voltage);
        m.voltage_limited |= x.voltage_limited;
        m.current.alpha = add(m.current.alpha, i_ab.alpha);
        m.current.beta = add(m.current.beta, i_ab.beta);
    }

    /// The slow task's half ([`ControlMonitor::gather`]): the leaky means moved once by
    /// the slow period's means (with [`SupervisionLimits::slow_monitor_filter`]; the
    /// regulation error holds if a current loop was at the voltage limit in the period,
    /// the running offset check's mean counts if |w_s| at the tick, `stator_frequency`
    /// (rad/s electrical), is above its threshold), `residual` the current loops'
    /// integrals at the tick (V), then the checks of [`ControlMonitor::check`] and
    /// [`ControlMonitor::check_offset_drift`], in that order. The means start again.
    pub fn judge(
        &mut self,
        limits: &SupervisionLimits<N>,
        residual: Dq<N>,
        stator_frequency: N,
    ) -> Option<FaultReason> {
        let m = self.means;
        self.means = MonitorMeans::zero();
        self.filter(
            limits,
            limits.slow_monitor_filter,
            &m.signals,
            residual,
            stator_frequency,
            m.voltage_limited,
        );
        if let Some(reason) = self.verdict(limits) {
            return Some(reason);
        }
        let g = limits.slow_running_offset_filter;
        self.move_dc(limits, g, m.current, stator_frequency);
        self.offset_verdict(limits)
    }

    /// The leaky means moved by `sig` with gain `g`, the regulation error held while
    /// `voltage_limited`; `residual` the current loops' integrals, V, at the stator
    /// frequency `stator_frequency` (rad/s electrical: the q integral's allowance).
    #[inline(always)]
    fn filter(
        &mut self,
        limits: &SupervisionLimits<N>,
        g: N::Gain,
        sig: &Signals<N>,
        residual: Dq<N>,
        stator_frequency: N,
        voltage_limited: bool,
    ) {
        let lp = |mean: N, x: N| mean + N::gain(g, x - mean);
        if !voltage_limited {
            self.current_error = lp(self.current_error, sig.current_error);
        }
        // the q integral's steady part less the back-EMF an inductance error leaves on it
        // (its feed-forward holds w_s lambda_hat: [`SupervisionLimits::residual_per_frequency`]),
        // and what moves around that steady part, in full
        self.q_residual = lp(self.q_residual, residual.q);
        let steady =
            self.q_residual.abs() - N::gain(limits.residual_per_frequency, stator_frequency.abs());
        let steady = if steady > N::ZERO { steady } else { N::ZERO };
        let q = steady + (residual.q - self.q_residual).abs();
        self.model_residual = lp(self.model_residual, residual.d.abs() + q);
        self.current_sum = lp(self.current_sum, sig.current_sum);
        self.voltage = lp(self.voltage, sig.voltage);
        self.explained_voltage = lp(self.explained_voltage, sig.explained_voltage);
    }

    /// The running offset check's mean moved by `i_ab` (A) with gain `g` where
    /// |`stator_frequency`| makes the true current AC.
    #[inline(always)]
    fn move_dc(
        &mut self,
        limits: &SupervisionLimits<N>,
        g: N::Gain,
        i_ab: AlphaBeta<N>,
        stator_frequency: N,
    ) {
        if stator_frequency.abs() >= limits.running_offset_min_frequency {
            let dc = &mut self.dc_current;
            dc.alpha = dc.alpha + N::gain(g, i_ab.alpha - dc.alpha);
            dc.beta = dc.beta + N::gain(g, i_ab.beta - dc.beta);
        }
    }

    /// The running offset check's verdict on its mean.
    #[inline(always)]
    fn offset_verdict(&self, limits: &SupervisionLimits<N>) -> Option<FaultReason> {
        let dc = self.dc_current;
        if dc.alpha.abs() > limits.offset_limit || dc.beta.abs() > limits.offset_limit {
            Some(FaultReason::CurrentSensor)
        } else {
            None
        }
    }

    /// The checks on the leaky means, in the order of the evidence's directness: the
    /// current sum (a sensor fault), the current response to the voltage (dead sensing),
    /// the current following its reference, then the voltage residual.
    #[inline(always)]
    fn verdict(&self, limits: &SupervisionLimits<N>) -> Option<FaultReason> {
        // (the faults' arms marked cold: a healthy drive's checks fall through)
        if self.current_sum > limits.current_sum_limit {
            core::hint::cold_path();
            Some(FaultReason::CurrentSensor)
        } else if self.voltage > limits.impedance_voltage_floor
            && self.explained_voltage < self.voltage.half()
        {
            core::hint::cold_path();
            Some(FaultReason::NoCurrentResponse)
        } else if self.current_error > limits.current_error_limit {
            core::hint::cold_path();
            Some(FaultReason::CurrentRegulation)
        } else if self.model_residual > limits.model_residual_limit {
            core::hint::cold_path();
            Some(FaultReason::LossOfControl)
        } else {
            None
        }
    }

    /// Running offset check: above `running_offset_min_frequency` every true phase
    /// current is AC, so the mean of the measured alpha-beta current over about a second
    /// is the channels' offset (an offset o on channel a shows as (o, o/sqrt 3), on
    /// channel b as (0, 2 o/sqrt 3)); beyond `offset_limit` on either axis it is a
    /// sensor fault (an amplifier drifting while the drive runs, which the start check
    /// cannot see). `i_ab`: the measured current after the idle-offset compensation, A.
    #[inline(always)]
    pub fn check_offset_drift(
        &mut self,
        limits: &SupervisionLimits<N>,
        i_ab: AlphaBeta<N>,
        stator_frequency: N,
    ) -> Option<FaultReason> {
        self.move_dc(limits, limits.running_offset_filter, i_ab, stator_frequency);
        self.offset_verdict(limits)
    }

    /// One step of the checks on `x`, in the order of the evidence's directness: the
    /// current sum (a sensor fault), the current response to the voltage (dead sensing),
    /// the current following its reference, then the voltage residual.
    #[inline(always)]
    pub fn check(
        &mut self,
        limits: &SupervisionLimits<N>,
        x: &ControlMonitorInputs<N>,
    ) -> Option<FaultReason> {
        let sig = Signals::of(limits, x);
        self.filter(
            limits,
            limits.monitor_filter,
            &sig,
            x.residual,
            x.stator_frequency,
            x.voltage_limited,
        );
        self.verdict(limits)
    }
}

/// The current channels' zero offsets, measured while the drive is idle with the switches
/// off (every true phase current is then zero): per channel, the mean of the first
/// `offset_settle_steps` samples (equal weights), then a leaky mean over `offset_filter`
/// that follows a drift. Checked at every start against `offset_limit` (a drifting or broken
/// amplifier) and, when settled, subtracted from the samples while the drive runs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OffsetMonitor<N: Num = f32> {
    /// Mean of each channel while idle, A.
    pub offsets: [N; 3],
    /// Idle samples seen (saturating).
    pub idle_steps: u32,
}

impl<N: Num + DivSqrt> Default for OffsetMonitor<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<N: Num + DivSqrt> OffsetMonitor<N> {
    /// Nothing measured yet.
    pub fn new() -> Self {
        Self {
            offsets: [N::ZERO; 3],
            idle_steps: 0,
        }
    }

    /// One sample taken with the switches off (non-finite samples are skipped: the gate
    /// faults on them).
    #[inline(always)]
    pub fn idle_sample(&mut self, limits: &SupervisionLimits<N>, currents: [N; 3]) {
        if !(currents[0].is_finite() && currents[1].is_finite() && currents[2].is_finite()) {
            return;
        }
        let n = self.idle_steps;
        for (o, x) in self.offsets.iter_mut().zip(currents) {
            *o = if n < limits.offset_settle_steps {
                // the running mean of the samples so far (n + 1 >= 1)
                *o + N::per_count(x - *o, n + 1)
            } else {
                *o + N::gain(limits.offset_filter, x - *o)
            };
        }
        self.idle_steps = self.idle_steps.saturating_add(1);
    }

    /// Whether enough idle samples were seen for the means to be trusted.
    pub fn settled(&self, limits: &SupervisionLimits<N>) -> bool {
        self.idle_steps >= limits.offset_settle_steps
    }

    /// The offsets to subtract: the settled means, or zero.
    pub fn compensation(&self, limits: &SupervisionLimits<N>) -> [N; 3] {
        if self.settled(limits) {
            self.offsets
        } else {
            [N::ZERO; 3]
        }
    }
}

impl Supervisor {
    /// Start check of the current sensors: a settled idle offset beyond `offset_limit`
    /// on a measured channel is a sensor fault.
    pub fn check_offsets<N: Num + DivSqrt>(
        &self,
        limits: &SupervisionLimits<N>,
        m: &OffsetMonitor<N>,
    ) -> Option<FaultReason> {
        let measured = match limits.current_sensing {
            CurrentSensing::TwoPhase => 2,
            CurrentSensing::ThreePhase => 3,
        };
        let bad = m.offsets[..measured]
            .iter()
            .any(|o| o.abs() > limits.offset_limit);
        if m.settled(limits) && bad {
            Some(FaultReason::CurrentSensor)
        } else {
            None
        }
    }
}

/// Checks on the raw samples, before anything uses them: non-finite, over-current (the
/// third phase derived with two shunts), bus window.
#[inline(always)]
pub fn check_samples<N: Num + DivSqrt>(
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
fn classify_bad_samples<N: Num + DivSqrt>(
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

impl SupervisionLimits<f32> {
    /// These limits in the arithmetic `N` with the bases `b`; fails naming the setting
    /// the value depends on.
    pub fn convert<N: Num + Units>(
        &self,
        b: &PerUnitBases,
    ) -> Result<SupervisionLimits<N>, &'static str> {
        let g = crate::num::gain_in::<N>;
        let pu =
            |x: f32, base: f32, field: &'static str| N::checked_from_f32(x / base).ok_or(field);
        let r = b.resistance();
        Ok(SupervisionLimits {
            current_sensing: self.current_sensing,
            overcurrent_trip: pu(self.overcurrent_trip, b.current, "limits.overcurrent_trip")?,
            dc_bus_min: pu(self.dc_bus_min, b.voltage, "limits.dc_bus_min")?,
            dc_bus_max: pu(self.dc_bus_max, b.voltage, "limits.dc_bus_max")?,
            max_speed: pu(self.max_speed, b.speed, "limits.max_speed")?,
            max_load_torque: pu(
                self.max_load_torque,
                b.torque,
                "limits.max_load_torque_estimate",
            )?,
            implausible_steps: self.implausible_steps,
            stall_steps: self.stall_steps,
            overload_steps: self.overload_steps,
            overload_fraction: N::from_f32(self.overload_fraction),
            overload_speed_floor: pu(self.overload_speed_floor, b.speed, "loops.speed_bandwidth")?,
            blind_frequency: pu(
                self.blind_frequency,
                b.frequency,
                "estimation.orientation_fade",
            )?,
            blind_steps: self.blind_steps,
            stall_fraction: N::from_f32(self.stall_fraction),
            rs_bound_faults: self.rs_bound_faults,
            monitor_filter: g(self.monitor_filter, "loops.current_bandwidth")?,
            slow_monitor_filter: g(self.slow_monitor_filter, "loops.current_bandwidth")?,
            current_error_limit: pu(self.current_error_limit, b.current, "loops.flux_current")?,
            current_sum_limit: pu(self.current_sum_limit, b.current, "limits.overcurrent_trip")?,
            model_residual_limit: pu(self.model_residual_limit, b.voltage, "limits.dc_bus_max")?,
            residual_per_frequency: g(
                self.residual_per_frequency * b.frequency / b.voltage,
                "loops.flux_current",
            )?,
            magnetizing_timeout_steps: self.magnetizing_timeout_steps,
            demagnetize_steps: self.demagnetize_steps,
            offset_filter: g(self.offset_filter, "loops.control_period")?,
            offset_settle_steps: self.offset_settle_steps,
            offset_skip_steps: self.offset_skip_steps,
            oscillation_steps: self.oscillation_steps,
            oscillation_filter: g(self.oscillation_filter, "loops.control_period")?,
            oscillation_check: self.oscillation_check,
            oscillation_swing: pu(self.oscillation_swing, b.speed, "limits.max_speed")?,
            offset_limit: pu(self.offset_limit, b.current, "limits.overcurrent_trip")?,
            running_offset_filter: g(self.running_offset_filter, "loops.control_period")?,
            slow_running_offset_filter: g(self.slow_running_offset_filter, "loops.slow_period")?,
            running_offset_min_frequency: pu(
                self.running_offset_min_frequency,
                b.frequency,
                "limits.overcurrent_trip",
            )?,
            impedance_resistance: pu(self.impedance_resistance, r, "machine.stator_resistance")?,
            impedance_inductance: g(
                self.impedance_inductance * b.frequency * b.current / b.voltage,
                "machine.stator_inductance",
            )?,
            impedance_voltage_floor: pu(
                self.impedance_voltage_floor,
                b.voltage,
                "limits.current_limit",
            )?,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn oscillation_limits() -> SupervisionLimits {
        let mut l = crate::design::DriveDesign::new(crate::DriveConfig::paper_defaults())
            .unwrap()
            .limits;
        // blocks of one period of the 5 Hz swing below
        l.oscillation_steps = 1000;
        l
    }

    /// A 40 rad/s (380 rpm) swing at 5 Hz around a steady reference faults after three
    /// blocks; the same with the reference ramping, or a swing below the bound, never.
    #[test]
    fn a_sustained_speed_swing_is_a_limit_cycle() {
        let l = oscillation_limits();
        let swing = |amp: f32, k: u32| amp * (core::f32::consts::TAU * 5.0 * k as f32 * 2e-4).sin();
        let mut o = SpeedOscillation::default();
        let mut at = None;
        for k in 0..10_000 {
            if let Some(r) = o.update(&l, swing(20.0, k), true) {
                at = Some((k, r));
                break;
            }
        }
        let (k, r) = at.expect("no fault");
        assert_eq!(r, FaultReason::SpeedOscillation);
        assert_eq!(k + 1, 3 * l.oscillation_steps, "three blocks");
        let mut o = SpeedOscillation::default();
        for k in 0..10_000 {
            // ramping every other block: the count restarts
            let steady = (k / 1000) % 2 == 0;
            assert_eq!(o.update(&l, swing(20.0, k), steady), None);
        }
        let small = 0.4 * l.oscillation_swing;
        let mut o = SpeedOscillation::default();
        for k in 0..10_000 {
            assert_eq!(o.update(&l, swing(small, k), true), None);
        }
        // switched off: the large swing never faults
        let off = SupervisionLimits {
            oscillation_check: false,
            ..l
        };
        let mut o = SpeedOscillation::default();
        for k in 0..10_000 {
            assert_eq!(o.update(&off, swing(20.0, k), true), None);
        }
    }
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

    /// A stall interrupted by single steps above the threshold still trips (the count
    /// leaks instead of resetting), only later by the interrupted steps.
    #[test]
    fn stall_integrates_with_a_leak() {
        let l = limits();
        let mut s = Supervisor::new();
        let mut tripped_at = None;
        for k in 0..(4 * l.stall_steps) {
            // every fourth step the estimate pokes above 10 % of the reference
            let est = if k % 4 == 3 { 50.0 } else { 1.0 };
            if s.stall(&l, true, est, 100.0).is_some() {
                tripped_at = Some(k);
                break;
            }
        }
        let k = tripped_at.expect("an interrupted stall must still trip");
        // the overload timer (0.2 s) sees it first; the leak slows it by the interruptions
        assert!(k > l.overload_steps && k <= 2 * l.overload_steps + 4, "{k}");
        // a clean run drains the count
        let mut s = Supervisor::new();
        for _ in 0..l.overload_steps / 2 {
            assert_eq!(s.stall(&l, true, 1.0, 100.0), None);
        }
        for _ in 0..l.overload_steps {
            assert_eq!(s.stall(&l, false, 100.0, 100.0), None);
        }
        for _ in 0..l.overload_steps {
            assert_eq!(s.stall(&l, true, 1.0, 100.0), None);
        }
        assert_eq!(s.stall(&l, true, 1.0, 100.0), Some(FaultReason::Stall));
    }

    /// Torque at the limit with the speed estimate well above the reference (an
    /// overhauling load beyond the capability) is an overload after 5 speed-loop time
    /// constants; a speed error inside the band is not.
    #[test]
    fn a_dc_component_of_the_running_current_is_an_offset_fault() {
        let l = limits();
        let ts = 200e-6f32;
        let run = |offset: f32, w: f32, seconds: f32| {
            let mut m = ControlMonitor::new();
            let steps = (seconds / ts) as usize;
            (0..steps).position(|k| {
                let th = w * k as f32 * ts;
                // the current limit's amplitude, the worst case for the ripple
                let i = AlphaBeta {
                    alpha: 4.67 * th.cos() + offset,
                    beta: 4.67 * th.sin() + offset / 3f32.sqrt(),
                };
                m.check_offset_drift(&l, i, w).is_some()
            })
        };
        let w_min = l.running_offset_min_frequency;
        // AC current at the lowest counted frequency: no fault in 10 s
        assert_eq!(run(0.0, w_min, 10.0), None);
        // an offset at the limit's double: found within a filter time constant (the mean
        // reaches half the offset after T ln 2)
        let k = run(2.0 * l.offset_limit, 2.0 * w_min, 5.0).expect("found");
        let t = crate::design::RUNNING_OFFSET_FILTER_TIME;
        assert!((k as f32) * ts < t, "{k}");
        // below the counted frequency the mean holds: nothing is judged there
        assert_eq!(run(2.0 * l.offset_limit, 0.5 * w_min, 5.0), None);
    }

    #[test]
    fn torque_limit_at_a_blind_stator_frequency_is_an_overload() {
        let l = limits();
        let mut s = Supervisor::new();
        let w = 0.5 * l.blind_frequency;
        // a reversal crossing the band at the torque limit does not count
        for _ in 0..l.blind_steps / 2 {
            assert_eq!(s.blind(&l, true, w), None);
        }
        for _ in 0..l.blind_steps / 2 {
            assert_eq!(s.blind(&l, true, 3.0 * l.blind_frequency), None);
        }
        // neither does a blind frequency below the torque limit
        for _ in 0..4 * l.blind_steps {
            assert_eq!(s.blind(&l, false, 0.0), None);
        }
        // persisting one rotor time constant does
        let n = (0..4 * l.blind_steps)
            .position(|_| s.blind(&l, true, -w).is_some())
            .unwrap() as u32;
        assert!(n >= l.blind_steps && n <= l.blind_steps + 1, "{n}");
    }

    #[test]
    fn overload_needs_a_large_persistent_speed_error() {
        let l = limits();
        let mut s = Supervisor::new();
        for _ in 0..4 * l.overload_steps {
            assert_eq!(s.stall(&l, true, 140.0, 100.0), None);
        }
        let mut s = Supervisor::new();
        let k = (0..4 * l.overload_steps)
            .find(|_| s.stall(&l, true, 180.0, 100.0).is_some())
            .unwrap();
        assert_eq!(k, l.overload_steps);
        let mut s = Supervisor::new();
        for _ in 0..l.overload_steps {
            let _ = s.stall(&l, true, 180.0, 100.0);
        }
        assert_eq!(s.stall(&l, true, 180.0, 100.0), Some(FaultReason::Overload));
    }

    fn dq(d: f32, q: f32) -> Dq<f32> {
        Dq { d, q }
    }

    /// Runs the monitor `n` steps on constant signals; returns the first fault and its step.
    fn monitor_run(
        n: u32,
        i_ref: Dq<f32>,
        i: Dq<f32>,
        v: Dq<f32>,
        residual: Dq<f32>,
        sum: f32,
        limited: bool,
    ) -> Option<(u32, FaultReason)> {
        let l = limits();
        let mut m = ControlMonitor::new();
        (0..n).find_map(|k| {
            m.check(
                &l,
                &ControlMonitorInputs {
                    i_ref,
                    i,
                    v,
                    residual,
                    current_sum: sum,
                    stator_frequency: 60.0,
                    voltage_limited: limited,
                },
            )
            .map(|r| (k, r))
        })
    }

    #[test]
    fn healthy_control_passes_the_monitor() {
        // running near 500 rpm: currents on reference, model voltage explained
        let r = monitor_run(
            10_000,
            dq(1.5, 2.0),
            dq(1.49, 2.02),
            dq(20.0, 90.0),
            dq(1.0, 3.0),
            0.01,
            false,
        );
        assert_eq!(r, None);
    }

    #[test]
    fn dead_current_sensing_is_no_current_response() {
        // voltage wound up, nothing measured
        let r = monitor_run(
            10_000,
            dq(1.5, 0.0),
            dq(0.0, 0.0),
            dq(150.0, 20.0),
            dq(100.0, 20.0),
            0.0,
            true,
        );
        let (k, reason) = r.unwrap();
        assert_eq!(reason, FaultReason::NoCurrentResponse);
        assert!(k < 50, "{k} steps"); // within 10 ms at 5 kHz
    }

    #[test]
    fn unmet_reference_is_a_regulation_fault_unless_voltage_limited() {
        let run = |limited| {
            monitor_run(
                10_000,
                dq(1.5, 3.0),
                dq(0.5, 2.0),
                dq(20.0, 60.0),
                dq(2.0, 2.0),
                0.0,
                limited,
            )
        };
        let (k, reason) = run(false).unwrap();
        assert_eq!(reason, FaultReason::CurrentRegulation);
        assert!(k < 100, "{k} steps");
        // at the voltage limit the machine, not the drive, limits the current
        assert_eq!(run(true), None);
    }

    #[test]
    fn unexplained_voltage_is_loss_of_control() {
        let l = limits();
        let big = l.model_residual_limit;
        let (_, reason) = monitor_run(
            10_000,
            dq(1.5, 3.0),
            dq(1.5, 3.0),
            dq(20.0, 150.0),
            dq(0.0, 1.5 * big),
            0.0,
            false,
        )
        .unwrap();
        assert_eq!(reason, FaultReason::LossOfControl);
    }

    /// The back-EMF an inductance error leaves on the q integral (the feed-forward holds
    /// w_s lambda_hat) is allowed up to `residual_per_frequency` |w_s| on top of the
    /// limit; the same voltage on the d integral is lost control.
    #[test]
    fn an_inductance_errors_back_emf_on_the_q_integral_is_not_loss_of_control() {
        let l = limits();
        // monitor_run's stator frequency, 60 rad/s
        let allowance = l.residual_per_frequency * 60.0;
        assert!(allowance > 0.1 * l.model_residual_limit);
        let r = l.model_residual_limit + 0.9 * allowance;
        let run = |residual| {
            monitor_run(
                10_000,
                dq(1.5, 3.0),
                dq(1.5, 3.0),
                dq(20.0, 150.0),
                residual,
                0.0,
                false,
            )
        };
        assert_eq!(run(dq(0.0, r)), None);
        assert_eq!(
            run(dq(r, 0.0)).map(|x| x.1),
            Some(FaultReason::LossOfControl)
        );
        assert_eq!(
            run(dq(0.0, r + 0.2 * allowance)).map(|x| x.1),
            Some(FaultReason::LossOfControl)
        );
    }

    #[test]
    fn three_shunts_must_sum_to_zero() {
        let l = limits();
        let (_, reason) = monitor_run(
            10_000,
            dq(1.5, 3.0),
            dq(1.5, 3.0),
            dq(20.0, 90.0),
            dq(1.0, 1.0),
            2.0 * l.current_sum_limit,
            false,
        )
        .unwrap();
        assert_eq!(reason, FaultReason::CurrentSensor);
    }

    /// With a slow task of D = 5 periods the fast path gathers and the slow task judges
    /// the slow period's means: every case of the tests above gets the same verdict, at
    /// most a slow period after the per-period monitor's (and a healthy drive none).
    #[test]
    fn the_slow_task_judges_the_means_as_the_monitor_judges_each_period() {
        let mut cfg = DriveConfig::paper_defaults();
        cfg.loops.slow_period = 1e-3;
        let l = DriveDesign::new(cfg).unwrap().limits;
        const D: u32 = 5;
        let big = l.model_residual_limit;
        let cases = [
            (
                dq(1.5, 2.0),
                dq(1.49, 2.02),
                dq(20.0, 90.0),
                dq(1.0, 3.0),
                0.01,
                false,
            ),
            (
                dq(1.5, 0.0),
                dq(0.0, 0.0),
                dq(150.0, 20.0),
                dq(100.0, 20.0),
                0.0,
                true,
            ),
            (
                dq(1.5, 3.0),
                dq(0.5, 2.0),
                dq(20.0, 60.0),
                dq(2.0, 2.0),
                0.0,
                false,
            ),
            (
                dq(1.5, 3.0),
                dq(0.5, 2.0),
                dq(20.0, 60.0),
                dq(2.0, 2.0),
                0.0,
                true,
            ),
            (
                dq(1.5, 3.0),
                dq(1.5, 3.0),
                dq(20.0, 150.0),
                dq(0.0, 1.5 * big),
                0.0,
                false,
            ),
            (
                dq(1.5, 3.0),
                dq(1.5, 3.0),
                dq(20.0, 90.0),
                dq(1.0, 1.0),
                2.0 * l.current_sum_limit,
                false,
            ),
        ];
        for (i_ref, i, v, residual, sum, limited) in cases {
            let once = monitor_run(10_000, i_ref, i, v, residual, sum, limited);
            let mut m = ControlMonitor::new();
            let x = ControlMonitorInputs {
                i_ref,
                i,
                v,
                residual,
                current_sum: sum,
                stator_frequency: 60.0,
                voltage_limited: limited,
            };
            let ab = AlphaBeta {
                alpha: 0.0,
                beta: 0.0,
            };
            let slow = (1..=10_000u32).find_map(|k| {
                m.gather(&l, &x, ab, 1.0 / D as f32);
                if k % D == 0 {
                    m.judge(&l, residual, 60.0).map(|r| (k - 1, r))
                } else {
                    None
                }
            });
            match (once, slow) {
                (None, None) => {}
                (Some((a, ra)), Some((b, rb))) => {
                    assert_eq!(ra, rb, "{i_ref:?} {i:?}");
                    assert!(b + 1 >= a && b <= a + D, "{ra:?}: {a} {b}");
                }
                other => panic!("{i_ref:?} {i:?}: {other:?}"),
            }
        }
        // the running offset check on the means: an offset at twice the limit is found,
        // none at the lowest counted frequency without one
        let w = 2.0 * l.running_offset_min_frequency;
        let run = |offset: f32| {
            let mut m = ControlMonitor::new();
            (1..=25_000u32).position(|k| {
                let th = w * k as f32 * 200e-6;
                let x = ControlMonitorInputs {
                    i_ref: dq(1.5, 2.0),
                    i: dq(1.5, 2.0),
                    v: dq(20.0, 90.0),
                    residual: dq(1.0, 1.0),
                    current_sum: 0.0,
                    stator_frequency: w,
                    voltage_limited: false,
                };
                let ab = AlphaBeta {
                    alpha: 4.67 * th.cos() + offset,
                    beta: 4.67 * th.sin() + offset / 3f32.sqrt(),
                };
                m.gather(&l, &x, ab, 1.0 / D as f32);
                k % D == 0 && m.judge(&l, x.residual, w).is_some()
            })
        };
        assert_eq!(run(0.0), None);
        let k = run(2.0 * l.offset_limit).expect("found");
        assert!(
            (k as f32) * 200e-6 < crate::design::RUNNING_OFFSET_FILTER_TIME,
            "{k}"
        );
    }

    #[test]
    fn magnetizing_times_out() {
        let l = limits();
        let s = Supervisor::new();
        assert_eq!(s.magnetizing(&l, l.magnetizing_timeout_steps), None);
        assert_eq!(
            s.magnetizing(&l, l.magnetizing_timeout_steps + 1),
            Some(FaultReason::MagnetizingTimeout)
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
