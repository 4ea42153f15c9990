//! The I/O-shield servo protocol of the source thesis (see `link/PROTOCOL.md`): the wire format,
//! a firmware emulator, and the station-side link.

pub mod emulator;
pub mod link;
pub mod wire;

/// The throttle stick of the shield's landing (a `land` command's, a failsafe's): a slow descent
/// in the flight controller's altitude hold.
pub const LAND_THROTTLE: f32 = -0.3;

pub use emulator::{EmulatorConfig, EmulatorServer, Sensors, ShieldEmulator};
pub use link::{ShieldConfig, ShieldLink};
