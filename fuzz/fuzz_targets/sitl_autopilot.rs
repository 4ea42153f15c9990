//! The simulated autopilot on arbitrary bytes from the wire: every frame found is handled, and the
//! autopilot runs between chunks, as in `sitl run`.
#![no_main]

use std::sync::OnceLock;
use std::time::Duration;

use libfuzzer_sys::fuzz_target;
use link::mavlink::frame::FrameScanner;
use sitl::autopilot::{Autopilot, AutopilotConfig};
use sitl::sensors::Readings;
use sitl::{Vehicle, VehicleParams, World};

fn world() -> &'static World {
    static WORLD: OnceLock<World> = OnceLock::new();
    WORLD.get_or_init(|| World::load("apartment").expect("built-in world"))
}

fuzz_target!(|data: &[u8]| {
    let world = world();
    let [x, y] = world.starts()[0];
    let mut vehicle = Vehicle::new(VehicleParams::default(), x, y, 0.0);
    let mut ap = Autopilot::new(AutopilotConfig::default());
    let mut scanner = FrameScanner::new();
    let mut now = Duration::ZERO;
    for chunk in data.chunks(64) {
        scanner.push(chunk);
        while let Some(f) = scanner.next_frame() {
            ap.handle(now, &f, &mut vehicle);
        }
        now += Duration::from_millis(10);
        vehicle.step(world, 0.01);
        let events = vehicle.take_events();
        let readings = Readings {
            sonar: Some(vehicle.state().position[2]),
            yaw: vehicle.state().yaw,
            battery_v: vehicle.battery_voltage(),
            battery_pct: vehicle.battery_remaining(),
        };
        ap.update(now, &mut vehicle, &readings, &events);
        let _ = ap.take_output();
    }
});
