//! Helpers shared by the cross-process tests.

use std::sync::Arc;

use sitl::{SimConfig, Sitl, SitlConfig, World};

/// One simulated ArduCopter on `address`, in real time, without cameras.
pub fn copter(address: &str) -> Sitl {
    Sitl::start(SitlConfig {
        world: Arc::new(World::load("apartment").expect("built-in world")),
        sim: SimConfig::default(),
        vehicles: vec![format!("mavlink@{address}").parse().expect("endpoint")],
        camera: None,
        speed: 1.0,
        signing_key: None,
    })
    .expect("the simulator starts")
}
