//! # acim-monitor: watch and drive the board live
//!
//! A terminal UI for the firmware's protocol (docs/protocol.md) over a serial port or the
//! virtual board's TCP port (`acim-sim serve`): live charts of speed (reference,
//! estimate, and the motor model's true speed on the virtual board), d/q currents and
//! their references, flux, Rs estimate, load-torque estimate, bus voltage and interrupt
//! time; command entry; parameters read and written with the board's validation errors
//! shown; CSV recording that survives a reconnection.
//!
//! - [`link`]: the connection thread (reconnects with a backoff);
//! - [`app`]: the monitor's state, fed by link events and key presses;
//! - [`record`]: the CSV recording;
//! - [`ui`]: the screen, and [`ui::screenshot`] (the screen as text);
//! - [`script`]: the headless mode's command schedule.
#![forbid(unsafe_code)]

pub mod app;
pub mod link;
pub mod record;
pub mod script;
pub mod ui;
