//! # acim: sensorless field-oriented control of induction machines
//!
//! Closed loop against the motor model of the `acim-plant` crate (the paper's machine),
//! seeing only sampled phase currents and bus voltage; duties computed from the samples
//! of period k act over period k + 1 (`PwmPreload`, preloaded timer compare registers):
//!
//! ```
//! use acim::math::{RAD_S_TO_RPM, RPM_TO_RAD_S};
//! use acim::{Drive, DriveConfig, DriveInputs, DriveState};
//! use acim_plant::{LoadTorque, Plant, PwmPreload};
//!
//! // a bad configuration is a `ConfigError` naming the field and the rule
//! let mut drive = Drive::new(DriveConfig::paper_defaults()).expect("valid configuration");
//! let (mut plant, mut pwm) = (Plant::paper_default(1), PwmPreload::new());
//! // measure the current offsets (0.1 s, switches off), magnetize, then run
//! drive.start().expect("an idle drive starts");
//! drive.set_speed_target(300.0 * RPM_TO_RAD_S).expect("a finite target");
//! for _ in 0..10_000 {
//!     // 2 s at 5 kHz
//!     let m = plant.sample(); // at the period boundary
//!     let out = drive.step(&DriveInputs { phase_currents: m.phase_currents, dc_bus: m.dc_bus });
//!     plant.run_pwm_period(pwm.advance(out), LoadTorque::None); // over the next period
//! }
//! assert_eq!(drive.state(), DriveState::Running);
//! assert!((plant.speed() * RAD_S_TO_RPM - 300.0).abs() < 5.0);
//! ```
//!
//! More in `crates/acim/examples/`: `closed_loop` (the timing model explained, with a load
//! step), `own_motor` (a drive for your motor's parameters) and `fixed_point` (the Q7.24
//! drive for cores without an FPU), each run by CI with
//! `cargo run --release -p acim --example <name>`.
//!
//! A `no_std`, allocation-free, HAL-free implementation of Kianinezhad, Nahid-Mobarakeh,
//! Betin and Capolino (2009), "Robust sensorless vector control of induction machines":
//! indirect field-oriented control (eq. 8, 13) whose speed comes from a reduced-order
//! linear observer of i_sq, speed and load torque (eq. 12), with an online
//! stator-resistance estimator (eq. 19-20).
//!
//! Conventions (kept everywhere): SI units in f32; speeds in rad/s mechanical unless a name
//! says `_rpm` or `_elec`; amplitude-invariant Clarke/Park (dq values are phase peak
//! values), so Te = 1.5 p lambda_r i_sq in field orientation; lambda_r is the rotor flux
//! referred to the stator (inverse-Gamma), lambda_r = (Lm/Lr)|psi_r|.
#![no_std]
#![forbid(unsafe_code)]
#![warn(missing_docs)]

// control blocks
pub mod field_weakening;
pub mod flux;
pub mod frames;
pub mod gain_calibration;
pub mod hardware_trip;
pub mod inverter_test;
pub mod inverter_tracker;
pub mod math;
pub mod num;
pub mod observer;
pub mod offset_tracker;
pub mod orientation;
pub mod params;
pub mod pi;
pub mod rr_estimator;
pub mod rs_estimator;
pub mod sensor_check;
pub mod speed_loop;
pub mod speed_search;
pub mod start_sequence;
pub mod svpwm;
pub mod thermal;

// the cascade: configuration and design, supervision, the staged drive
pub mod commissioning;
pub mod config;
pub mod controller;
pub mod current_loop;
pub mod design;
pub mod drive;
pub mod nameplate;
pub mod supervisor;

// the fixed-point arithmetic, and the paper's baseline observer
pub mod fixed;
pub mod flux_observer;
pub mod full_order;
pub mod speed_observer;

pub use controller::Controller;
pub use design::{
    ConfigError, CurrentSensing, DriveCoeffs, DriveConfig, DriveDesign, EstimationSettings,
    FieldWeakeningSettings, InverterSettings, LimitSettings, LoopSettings, ObserverChoice,
    RsEstimationMode, StartSettings, TrackerSettings, VfSettings, ZeroSpeedPolicy,
    ZeroSpeedSettings,
};
pub use drive::{
    Applied, Drive, DriveInputs, DriveTelemetry, Estimate, Measured, NoProbe, PwmOutput, StepProbe,
    StepRegion, TelemetryRate,
};
pub use num::{Arithmetic, DivSqrt, FineIntegrator, Num, Units};
pub use observer::{SpeedEstimate, SpeedObserver, SpeedObserverInputs};
pub use params::{InverseGamma, MachineData, MachineParams, ParamError};
pub use speed_observer::DriveObserver;
pub use supervisor::{CommandError, DriveState, FaultReason, Supervisor};
pub use svpwm::{Modulator, Overmodulation, Svpwm};
