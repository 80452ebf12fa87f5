//! # acim-firmware-core: the hardware-independent half of the STM32G474 firmware
//!
//! Everything here is `no_std`, allocation-free, free of `unsafe` and host-tested (plain
//! `cargo test` at the repository root runs these tests; the firmware binary itself is
//! only built for `thumbv7em-none-eabihf`):
//!
//! - [`clock`]: the core clock checked from the registers read back after set-up;
//! - [`board`]: the board description (power stage gains, pin map, PWM and ADC timing) and
//!   the drive configuration derived from it;
//! - [`profile`]: the board profiles as `const` data (gate pins and polarity, enables,
//!   fault input, ADC plan, measurement chain, ratings), checked at compile time;
//! - [`convert`]: ADC counts to amperes and volts, offset calibration, duty to compare
//!   counts: the one place where raw numbers become SI units;
//! - [`command`]: the bounded command parser (start, stop, speed, reset, params, ...);
//! - [`commission`]: the `commission` command (self-commissioning from a typed nameplate)
//!   and how its result becomes the settings;
//! - [`dispatch`]: the command handling (a parsed line in, its action, the reply lines
//!   out) that the firmware's main loop and the virtual board share, over a trait for
//!   what differs between them;
//! - [`telemetry`]: the decimated telemetry sample and its text framing;
//! - [`protocol`]: protocol version 1 (framed commands and replies, hello, rate, the
//!   telemetry extension), shared with the host tools (docs/protocol.md);
//! - [`timing`]: cycle-count statistics and the telemetry decimator;
//! - [`rtt`]: the RTT log channel's ring arithmetic (where a non-blocking write goes);
//! - [`settings`]: the serial-settable limits and machine parameters, their flash record
//!   (version, sequence number, CRC) and validation by the library's constructors;
//! - [`store`]: the settings' two flash pages written alternately (the newest valid record
//!   wins at boot; a save never erases the record it replaces before the new one
//!   verifies), over a flash trait, host-tested with a power cut at every operation;
//! - [`sim`]: the motor model behind this board's ADC, for the self-test;
//! - [`control`]: the per-period control loop (conversion, faults, drive step, telemetry)
//!   that the firmware's interrupt calls, generic over the sin/cos provider;
//! - [`stage`]: the interrupt's period sequence (ADC flags, break, MOE arming, deadline)
//!   over a register trait, host-tested against a register model.
//!
//! Code reachable from [`control::ControlLoop::step`] and
//! [`control::ControlLoop::finish_period`] runs in the 5 kHz interrupt: it must not panic
//! and uses f32 only (the firmware's `check.sh` verifies this on the linked binary).
#![no_std]
#![forbid(unsafe_code)]
#![warn(missing_docs)]

pub mod board;
pub mod clock;
pub mod command;
pub mod commission;
pub mod control;
pub mod convert;
pub mod dispatch;
pub mod profile;
pub mod protocol;
pub mod rtt;
pub mod settings;
pub mod sim;
pub mod stage;
pub mod store;
pub mod telemetry;
pub mod timing;
