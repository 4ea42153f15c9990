//! Vehicle links for the ground station.
//!
//! The mission runtime flies every drone through [`VehicleLink`], whatever is behind it:
//!
//! * [`shield`]: the I/O-shield servo protocol of the source thesis (a serial board that turns
//!   commands into 1000–2000 µs pulses for a DJI Naza-class flight controller), specified in
//!   `link/PROTOCOL.md`;
//! * [`mavlink`]: MAVLink autopilots (ArduPilot, PX4), acting as a ground station.
//!
//! Both run over a [`Transport`] named by an [`Address`] string (`serial:PATH:BAUD`,
//! `tcpout:HOST:PORT`, `tcpin:ADDR:PORT`, `udpin:ADDR:PORT`, `udpout:HOST:PORT`) and reconnect
//! on their own. [`tlog`] reads and writes MAVLink telemetry logs; [`camera`] carries RGB-D frames
//! from a camera to the station.

pub mod address;
pub mod camera;
pub mod heartbeat;
pub mod mavlink;
pub mod rc;
pub mod shield;
pub mod tlog;
pub mod transport;
pub mod vehicle;

pub use address::{Address, AddressError};
pub use heartbeat::{HeartbeatMonitor, LinkState, VehicleClock};
pub use rc::{Axis, Channel, ChannelMap, Pulses, Sticks};
pub use transport::{Connection, Transport, TransportError};
pub use vehicle::{
    Attitude, Battery, Command, CommandError, FlightMode, LinkStatus, StatusText, Telemetry,
    VehicleLink,
};
