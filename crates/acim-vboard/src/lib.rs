//! # acim-vboard: the virtual board
//!
//! The self-test firmware's control loop on the host: [`acim_firmware_core`]'s
//! `ControlLoop` (the interrupt body) and `SimulatedStage` (the motor model behind the
//! board's ADC), with the firmware's own command handling and reply texts
//! ([`acim_firmware_core::dispatch`]), speaking the firmware's protocol (docs/protocol.md) on a local TCP port in real time, a multiple of
//! it, or as fast as the host runs it. Every host tool that talks to the board's UART
//! talks to this the same way.
//!
//! - [`board`]: the board without its link (also [`board::replay`], the reference trace
//!   of a run from its command log);
//! - [`server`]: the TCP server (`acim-sim serve`).
//!
//! ```no_run
//! let listener = std::net::TcpListener::bind("127.0.0.1:7878")?;
//! let server = acim_vboard::server::start(listener, Default::default())?;
//! server.wait();
//! # Ok::<(), std::io::Error>(())
//! ```
#![forbid(unsafe_code)]

pub mod board;
pub mod server;

/// The protocol's bounds that command-line tools check too.
pub mod protocol_limits {
    pub use acim_firmware_core::protocol::{MAX_RATE_PERIODS, MIN_RATE_PERIODS};
}
