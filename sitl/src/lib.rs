//! The simulator (SITL): a building, multirotors behind stabilising flight controllers, their
//! sensors, and endpoints that speak to the station exactly like hardware.
//!
//! * [`world`]: floor plans (world text, `map_server`, HouseExpo) extruded to a ceiling;
//! * [`vehicle`]: the multirotor and its flight controller; [`battery`]: its LiPo pack;
//!   [`sensors`]: sonar, IMU yaw, battery;
//! * [`render`]: the RGB-D camera;
//! * [`sim`]: vehicles in a world, stepped in simulated time, deterministic for a seed;
//! * [`autopilot`]: an ArduPilot-Copter-like autopilot speaking MAVLink;
//! * [`runner`]: the simulator running in real time or faster, with each vehicle served over its
//!   own transport (shield firmware or MAVLink autopilot) and cameras streamed ([`stream`]);
//! * [`bridge`]: cameras for autopilots flown elsewhere (ArduPilot SITL), rendered at the pose
//!   each reports.

pub mod autopilot;
pub mod battery;
pub mod bridge;
pub mod render;
pub mod rng;
pub mod runner;
pub mod sensors;
pub mod sim;
pub mod stream;
pub mod vehicle;
pub mod world;

pub use render::Camera;
pub use runner::{EndpointSpec, Protocol, SimClock, Sitl, SitlConfig, SitlError};
pub use sim::{CameraFrame, Shots, Sim, SimConfig, SimError};
pub use vehicle::{Vehicle, VehicleEvent, VehicleParams, VehicleState};
pub use world::{Material, Plan, World, WorldError};
