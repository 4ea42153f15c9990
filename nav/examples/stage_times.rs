//! Times each stage of one planner step on willow-full with 8 robots (a profiling aid).
use nav::*;
use std::time::Instant;
fn main() {
    let world = Grid::load(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../shared/data/maps/willow-full.yaml"
    ))
    .expect("map");
    let free: Vec<usize> = (0..world.cells().len())
        .filter(|&i| world.cells()[i] == Cell::Free)
        .collect();
    let seeds: Vec<[f64; 2]> = (0..8)
        .map(|k| world.center_of(world.xy(free[free.len() * (2 * k + 1) / 16])))
        .collect();
    let known = explored_part(&world, &seeds, 10.0);
    for _ in 0..3 {
        let t = Instant::now();
        let inf = inflate::inflate(&known, 0.3);
        let t1 = t.elapsed();
        let fr = frontier::frontiers(&inf, 5);
        let t2 = t.elapsed();
        let fields: Vec<_> = seeds
            .iter()
            .map(|s| search::dijkstra(&inf, inf.cell_of(*s).expect("in")))
            .collect();
        let t3 = t.elapsed();
        let p = plan(
            &known,
            &seeds.iter().copied().map(Some).collect::<Vec<_>>(),
            &PlannerConfig::default(),
        )
        .expect("plan");
        let t4 = t.elapsed();
        println!(
            "inflate {:?} frontiers {:?} ({}) 8×dijkstra {:?} whole plan {:?} [{}]",
            t1,
            t2 - t1,
            fr.len(),
            t3 - t2,
            t4 - t3,
            fields.len() + p.frontiers.len()
        );
    }
}
