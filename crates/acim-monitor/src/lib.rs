//! # acim-monitor: watch and drive the board live
//!
//! A terminal UI for the firmware's protocol (docs/protocol.md) over a serial port or the
//! virtual board's TCP port (`acim-sim serve`): live charts of speed (reference,
//! estimate, and the motor model's true speed on the virtual board), d/q currents and
//! their references, flux, Rs estimate, load-torque estimate, bus voltage and interrupt
//! time; command entry; parameters read and written with the board's validation errors
//! shown; CSV recording that survives a reconnection.
//!
//! ## The screen
//!
//! It is usable from 80 columns by 24 rows: the compact layout shows the speed, current
//! and torque charts and a readout of the other values; from 120 x 40 on, all seven
//! charts; below 80 x 24, a banner asking for a larger terminal (see [`ui`]). The status
//! line starts with the drive state and the fault, so a narrow terminal cuts the rest.
//!
//! Values that are not fresh are drawn dim grey, and the chart's border (the readout's
//! title) names the reason (`held: link down`, `held: no telemetry`, `held: paused`, and,
//! when only the drive's own estimates hold, `held: commissioning`, `held: fault`,
//! `held: drive off`; see [`app::Held`]). On the virtual board the interrupt-time chart is the host's step
//! time in microseconds (that board times its control step on the host); on a board, the
//! control interrupt's time in 170 MHz core cycles.
//!
//! ## Keys
//!
//! | key | does |
//! |---|---|
//! | typing, Enter | sends the command line to the board (`:` lines act on the monitor) |
//! | Up / Down | the command history |
//! | PgUp / PgDn | scroll the board's replies a page back / forward (they are wrapped, never cut) |
//! | Home / End | the oldest reply kept / the newest (the pane follows new replies again) |
//! | Esc | sends `stop` |
//! | F1 or `:help` | the help |
//! | Ctrl-C / Ctrl-Q | quits (the recording is closed) |
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
