//! Simulator benchmarks: `cargo bench -p sitl` (add `-- --quick` for a short run).
//!
//! * time to render one RGB-D frame at 320×240 and 640×480 in the default apartment;
//! * real-time factor of `Sitl` (physics, sensors, MAVLink autopilots, cameras at 10 Hz) run as
//!   fast as the machine can, with 2 and 8 vehicles flying, 320×240 cameras on.

use std::hint::black_box;
use std::sync::Arc;
use std::time::{Duration, Instant};

use link::Sticks;
use sitl::render::render;
use sitl::world::DEFAULT_WORLD;
use sitl::{Camera, SimConfig, Sitl, SitlConfig, World};

fn main() {
    let quick = std::env::args().any(|a| a == "--quick");
    println!(
        "sitl benchmarks ({} run), {} cores\n",
        if quick { "quick" } else { "full" },
        cores()
    );
    let world = Arc::new(World::load(DEFAULT_WORLD).expect("built-in world"));
    for (w, h) in [(320, 240), (640, 480)] {
        render_time(&world, w, h, if quick { 20 } else { 100 });
    }
    println!();
    for n in [2, 8] {
        real_time_factor(&world, n, if quick { 10.0 } else { 60.0 });
    }
}

fn cores() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get())
}

fn render_time(world: &World, w: u32, h: u32, n: usize) {
    let camera = Camera::kinect(w, h);
    let sim = sitl::Sim::new(Arc::new(world.clone()), 8, SimConfig::default()).expect("sim");
    // Views from every start position, 1.2 m up, in turn.
    let poses: Vec<_> = (0..8)
        .map(|k| {
            let mut p = sim.vehicle(k).map_from_camera();
            p.translation.z += 1.2;
            p
        })
        .collect();
    let t = Instant::now();
    for i in 0..n {
        black_box(render(world, &poses[i % 8], &camera, Some((1, i as u64))));
    }
    let per = t.elapsed().as_secs_f64() / n as f64;
    println!(
        "render one RGB-D frame {w}×{h} (one core)          {:>8.2} ms",
        per * 1e3
    );
}

fn real_time_factor(world: &Arc<World>, n: usize, sim_seconds: f64) {
    let sitl = Sitl::start(SitlConfig {
        world: world.clone(),
        sim: SimConfig::default(), // 320×240 at 10 Hz, turbulence on
        vehicles: (0..n)
            .map(|_| "mavlink@udpin:127.0.0.1:0".parse().expect("endpoint"))
            .collect(),
        camera: None,
        speed: f64::INFINITY,
        signing_key: None,
    })
    .expect("start the simulator");
    let frames = sitl.subscribe();
    // Everyone takes off and then flies slow circles.
    sitl.with_sim(|sim| {
        for k in 0..sim.len() {
            let v = sim.vehicle_mut(k);
            v.set_mode(link::FlightMode::AltHold);
            v.set_armed(true);
        }
    });
    let t = Instant::now();
    let t_sim = sitl.time();
    let mut received = 0usize;
    while (sitl.time() - t_sim).as_secs_f64() < sim_seconds {
        while let Ok(f) = frames.try_recv() {
            received += 1;
            black_box(f);
        }
        // The autopilot re-applies its RC inputs every tick; write straight to the vehicles.
        sitl.with_sim(|sim| {
            let climb = if sim.time().as_secs_f64() < 1.5 {
                0.8
            } else {
                0.0
            };
            for k in 0..sim.len() {
                sim.vehicle_mut(k).set_sticks(Sticks {
                    pitch: 0.2,
                    yaw: 0.3,
                    throttle: climb,
                    roll: 0.0,
                });
            }
        });
        std::thread::sleep(Duration::from_millis(5));
    }
    let wall = t.elapsed().as_secs_f64();
    let simulated = (sitl.time() - t_sim).as_secs_f64();
    println!(
        "real-time factor, {n} vehicles, 320×240 cameras at 10 Hz  {:>8.1}×   ({simulated:.1} s simulated in {wall:.1} s, {received} frames received)",
        simulated / wall
    );
}
