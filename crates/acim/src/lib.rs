//! # acim: sensorless field-oriented control of induction machines
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
pub mod flux;
pub mod frames;
pub mod math;
pub mod num;
pub mod observer;
pub mod orientation;
pub mod params;
pub mod pi;
pub mod rs_estimator;
pub mod speed_search;
pub mod svpwm;

// the cascade: configuration and design, supervision, the staged drive
pub mod controller;
pub mod design;
pub mod drive;
pub mod nameplate;
pub mod supervisor;

// the fixed-point arithmetic, and the paper's baseline observer
pub mod fixed;
pub mod full_order;

pub use controller::Controller;
pub use design::{ConfigError, CurrentSensing, DriveCoeffs, DriveConfig, DriveDesign, VfConfig};
pub use drive::{
    Applied, Drive, DriveInputs, DriveTelemetry, Estimate, Measured, NoProbe, PwmOutput, StepProbe,
    StepRegion,
};
pub use num::Num;
pub use observer::{SpeedEstimate, SpeedObserver, SpeedObserverInputs};
pub use params::{InverseGamma, MachineData, MachineParams, ParamError};
pub use supervisor::{CommandError, DriveState, FaultReason, Supervisor};
pub use svpwm::{Modulator, Svpwm};
