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

pub mod math;
pub mod model;
pub mod params;

pub use params::{MachineData, MachineParams, ParamError};
pub mod drive;
pub mod fixed;
pub mod flux;
pub mod frames;
pub mod full_order;
pub mod observer;
pub mod pi;
pub mod rs_estimator;
pub mod svpwm;

pub use drive::{
    CommandError, ConfigError, CurrentSensing, Drive, DriveConfig, DriveInputs, DriveState,
    DriveTelemetry, FaultReason, NoProbe, PwmOutput, StepProbe, StepRegion, Supervisor,
};
