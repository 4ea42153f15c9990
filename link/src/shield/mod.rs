//! The I/O-shield servo protocol of the source thesis (see `link/PROTOCOL.md`): the wire format,
//! a firmware emulator, and the station-side link.

pub mod emulator;
pub mod link;
pub mod wire;

pub use emulator::{EmulatorConfig, EmulatorServer, Sensors, ShieldEmulator};
pub use link::{ShieldConfig, ShieldLink};
