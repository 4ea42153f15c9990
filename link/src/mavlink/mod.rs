//! MAVLink autopilots (ArduPilot, PX4): the station acts as a ground station (system 255,
//! component 190). NED is converted to the map frame here and nowhere else.

pub mod frame;
pub mod keys;
pub mod link;
pub mod modes;

pub use ::mavlink::MavlinkVersion;
pub use ::mavlink::dialects::ardupilotmega::MavMessage;
pub use keys::{KeyError, KeyStore};
pub use link::{MavlinkConfig, MavlinkLink, MavlinkVehicle, SigningKey};
