//! Keeping a drone without a pose off the walls its depth camera sees.
//!
//! A drone whose SLAM pose is invalid hovers level with its altitude held (thesis Algorithm 7),
//! and drifts with the air: in the simulator's 0.1 m/s gusts, 4 of 7 wall collisions of twelve
//! missions came from a drone that had been without a pose for 0.9–3.8 s. The map cannot keep
//! it off a wall then (it does not know where on the map it is), but its camera still measures
//! how far the walls are. Like ArduPilot's proximity avoidance in AltHold (`AC_Avoid`, which
//! needs no position either), [`Proximity`] keeps the nearest range seen in each direction,
//! by IMU heading, for a few seconds (the camera sees ±31° at a time; a lost drone turns to
//! look for the map, and sees around), and [`Proximity::push`] leans the drone away from
//! walls nearer than a margin.
//!
//! The camera sees only ahead, and a drone drifts backward as often: while the drone still has
//! a pose, [`map_readings`] ranges the map's walls all round it, so the moment it goes blind
//! the memory already holds the walls behind it.
//!
//! A depth camera measures nothing nearer than its minimum range (0.4 m for a Kinect). A
//! direction that shows no wall is open only if the camera still measured something there: the
//! floor or the ceiling, which it sees in every unblocked direction from about two drone
//! heights on. One where it measured nothing at all is blocked by a wall too near to range
//! ([`Sight::Blocked`]). A drone drifting backward to a wall and then turning to face it sees
//! only that, and before this was told apart from an opening it was taken as clear.

use crate::Grid;
use crate::avoid::walls_near;
use crate::local::wrap_angle;
use std::f64::consts::{PI, TAU};

/// How near a wall may come, and how hard the drone leans away from it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProximityConfig {
    /// Points this far above or below the body (metres) are walls; floor and ceiling are not.
    pub band_m: f64,
    /// The width of a direction in a frame's readings, radians.
    pub bearing_step_rad: f64,
    /// Directions remembered, round the compass.
    pub sectors: usize,
    /// A range older than this is forgotten (the drone drifts on meanwhile), seconds.
    pub max_age_s: f64,
    /// A blocked direction ([`Sight::Blocked`]) is kept this long, seconds: while the camera
    /// faces the wall, not after. Kept as long as a range, the lean it gives (the strongest a
    /// camera gives) outlasted the wall's nearness: in SITL a drone leaned off one wall of the
    /// 1.4 m corridor was carried into the other, and back, three times in 30 s.
    pub blocked_max_age_s: f64,
    /// The drone leans away from walls nearer than this to its centre, metres…
    pub margin_m: f64,
    /// …with this much stick per metre inside the margin…
    pub gain: f64,
    /// …up to this much stick.
    pub max: f64,
    /// A blocked direction ([`Sight::Blocked`]) is taken to have a wall this far from the
    /// drone's centre, metres, unless one was ranged nearer: between touching (the drone's
    /// radius) and the camera's minimum range seen from the centre.
    pub blocked_m: f64,
    /// [`map_readings`] range the map's walls this far, metres.
    pub map_reach_m: f64,
}

impl Default for ProximityConfig {
    /// For the simulated drone (radius 0.2 m, a Kinect-like camera 0.1 m ahead of its centre,
    /// 0.01 stick holding about 0.06 m/s of air): a flat wall 0.5 m off leans it by 0.016
    /// stick, which balances a 0.1 m/s gust (the simulator's σ); 0.4 m off, by 0.035 stick,
    /// a 0.2 m/s gust, 0.2 m short of touching.
    fn default() -> Self {
        Self {
            band_m: 0.3,
            bearing_step_rad: 5f64.to_radians(),
            sectors: 36,
            max_age_s: 4.0,
            blocked_max_age_s: 1.0,
            margin_m: 0.6,
            gain: 0.25,
            max: 0.1,
            // Touching at 0.2 m; a Kinect 0.1 m ahead of the centre ranges from 0.5 m.
            blocked_m: 0.35,
            map_reach_m: 1.0,
        }
    }
}

/// The nearest wall in one direction, from a camera frame or the map.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Reading {
    /// The direction in the body frame, radians (0 ahead, counter-clockwise positive).
    pub bearing_rad: f64,
    /// What lies that way.
    pub sight: Sight,
}

/// What a camera frame (or the map) shows in one direction.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Sight {
    /// A wall, this far from the body's centre (horizontally), metres.
    Wall(f64),
    /// No wall within range, but the camera measured the floor or the ceiling that way.
    Open,
    /// Nothing measured at all, not even the floor: a wall nearer than the camera ranges fills
    /// its view that way.
    Blocked,
}

impl Sight {
    /// The wall's range, metres, if a wall was ranged.
    pub fn range_m(self) -> Option<f64> {
        match self {
            Sight::Wall(m) => Some(m),
            Sight::Open | Sight::Blocked => None,
        }
    }
}

/// The nearest wall in each direction of one camera frame, from its points in the body frame
/// (x forward, y left, z up, metres; every pixel with a depth, floor and ceiling included), the
/// camera's place on the body `camera_in_body` (x, y) and its horizontal field of view
/// `[right, left]` edge bearings (radians): every direction in view gets a reading. The
/// third-nearest point of the band counts as the wall, so a stray pixel does not; a direction
/// with no wall is [`Sight::Open`] if it has three points at any height, else
/// [`Sight::Blocked`].
///
/// Directions are the camera's (its image's columns), ranges the body centre's. Binned by
/// their bearing from the centre instead, a near wall's points at the edge of the view fall
/// inside it (what a camera 0.1 m ahead of the centre sees at ±31° on a wall 0.6 m off lies
/// ±27° from the centre), so the outermost direction measured nothing, read as a wall too near
/// to range, and pushed every blind drone near a wall off one that was not there.
pub fn readings(
    points_in_body: impl IntoIterator<Item = [f64; 3]>,
    camera_in_body: [f64; 2],
    fov_rad: [f64; 2],
    config: &ProximityConfig,
) -> Vec<Reading> {
    let step = config.bearing_step_rad;
    let [right, left] = fov_rad;
    if !(step > 0.0 && right.is_finite() && left.is_finite() && left > right) {
        return vec![];
    }
    let bins = ((left - right) / step).ceil().min(360.0) as usize;
    // The three nearest ranges of each direction, nearest first, and how many points it has.
    let mut nearest = vec![[f64::INFINITY; 3]; bins];
    let mut measured = vec![0usize; bins];
    for [x, y, z] in points_in_body {
        if !(x.is_finite() && y.is_finite() && z.is_finite()) {
            continue;
        }
        let bearing = (y - camera_in_body[1]).atan2(x - camera_in_body[0]);
        let i = ((bearing - right) / step).floor();
        if !(0.0..bins as f64).contains(&i) {
            continue;
        }
        measured[i as usize] += 1;
        if z.abs() > config.band_m {
            continue;
        }
        let three = &mut nearest[i as usize];
        let range = x.hypot(y);
        if range < three[2] {
            three[2] = range;
            three.sort_by(f64::total_cmp);
        }
    }
    nearest
        .iter()
        .zip(measured)
        .enumerate()
        .map(|(i, (three, measured))| Reading {
            bearing_rad: right + (i as f64 + 0.5) * step,
            sight: if three[2].is_finite() {
                Sight::Wall(three[2])
            } else if measured >= 3 {
                Sight::Open
            } else {
                Sight::Blocked
            },
        })
        .collect()
}

/// The nearest wall of `map` in each direction round a drone at `position` heading `yaw` (map
/// frame), as readings in the body frame: every direction gets one, `map_reach_m` where no wall
/// is nearer.
pub fn map_readings(
    map: &Grid,
    position: [f64; 2],
    yaw: f64,
    config: &ProximityConfig,
) -> Vec<Reading> {
    let step = config.bearing_step_rad;
    if !(step > 0.0 && yaw.is_finite() && config.map_reach_m > 0.0) {
        return vec![];
    }
    let bins = (TAU / step).ceil().min(360.0) as usize;
    let mut nearest = vec![config.map_reach_m; bins];
    for (away, distance) in walls_near(map, position, config.map_reach_m) {
        // `away` points from the wall to the drone.
        let bearing = wrap_angle((-away[1]).atan2(-away[0]) - yaw);
        let i = (((bearing + PI) / step).floor() as usize).min(bins - 1);
        nearest[i] = nearest[i].min(distance);
    }
    nearest
        .into_iter()
        .enumerate()
        .map(|(i, range)| Reading {
            bearing_rad: -PI + (i as f64 + 0.5) * step,
            sight: Sight::Wall(range),
        })
        .collect()
}

/// The nearest walls round a drone, by heading, as its camera ranged them lately and the map
/// had them while it had a pose.
#[derive(Debug, Clone, PartialEq)]
pub struct Proximity {
    /// Per sector (heading `k · 2π / n`, counter-clockwise from the IMU's zero): the range and
    /// until when it is kept.
    sectors: Vec<Option<(f64, f64)>>,
}

impl Proximity {
    /// Nothing seen yet, with `config.sectors` directions.
    pub fn new(config: &ProximityConfig) -> Self {
        Self {
            sectors: vec![None; config.sectors.max(1)],
        }
    }

    fn sector(&self, heading: f64) -> usize {
        let n = self.sectors.len();
        let turn = heading.rem_euclid(TAU) / TAU;
        ((turn * n as f64).round() as usize) % n
    }

    /// Takes the readings of a frame taken at `stamp` (seconds) while the IMU read `heading`
    /// (radians).
    pub fn observe(
        &mut self,
        stamp: f64,
        heading: f64,
        readings: &[Reading],
        config: &ProximityConfig,
    ) {
        if !(stamp.is_finite() && heading.is_finite()) {
            return;
        }
        // A frame's directions are finer than the sectors: the nearest wall of each sector's
        // and how long it is kept (`None` while only open directions fell in it).
        let mut seen: Vec<Option<Option<(f64, f64)>>> = vec![None; self.sectors.len()];
        for r in readings {
            let k = self.sector(heading + r.bearing_rad);
            let wall = match r.sight {
                Sight::Wall(m) => Some(m)
                    .filter(|m| m.is_finite())
                    .map(|m| (m, config.max_age_s)),
                Sight::Open => None,
                // Too near to range: nearer than it was ranged last, if that was nearer still
                // and is still kept (a range forgotten says nothing of the wall now).
                Sight::Blocked => Some((
                    self.sectors[k]
                        .filter(|&(_, until)| stamp <= until)
                        .map_or(config.blocked_m, |(m, _)| m.min(config.blocked_m)),
                    config.blocked_max_age_s,
                )),
            };
            seen[k] = Some(match (seen[k].flatten(), wall) {
                (Some(a), Some(b)) => Some(if b.0 < a.0 { b } else { a }),
                (a, b) => a.or(b),
            });
        }
        for (slot, seen) in self.sectors.iter_mut().zip(seen) {
            match seen {
                None => {}
                Some(Some((range, keep_s))) => *slot = Some((range, stamp + keep_s)),
                Some(None) => *slot = None,
            }
        }
    }

    /// The lean (body frame: forward, left; stick units) that keeps a drone heading `heading`
    /// (radians, IMU) at time `now` off the walls nearer than the margin: away from them, by
    /// the mean of the directions within the margin weighted by how far inside it they are,
    /// so a wall seen over many directions counts once and walls either side cancel.
    pub fn push(&self, now: f64, heading: f64, config: &ProximityConfig) -> [f64; 2] {
        if !heading.is_finite() {
            return [0.0; 2];
        }
        let n = self.sectors.len() as f64;
        let (mut sum, mut count) = ([0.0; 2], 0usize);
        for (k, slot) in self.sectors.iter().enumerate() {
            let Some((range, until)) = *slot else {
                continue;
            };
            let inside = config.margin_m - range;
            if inside <= 0.0 || now > until {
                continue;
            }
            let (s, c) = (k as f64 * TAU / n - heading).sin_cos();
            sum[0] -= inside * c;
            sum[1] -= inside * s;
            count += 1;
        }
        if count == 0 {
            return [0.0; 2];
        }
        let lean = sum.map(|v| config.gain * v / count as f64);
        let size = lean[0].hypot(lean[1]);
        if size > config.max {
            lean.map(|v| v * config.max / size)
        } else {
            lean
        }
    }

    /// The nearest range still kept at `now` (`max_age_s`, `blocked_max_age_s`), if nearer than
    /// `map_reach_m` (the map's ranges reach no further), metres: for logs.
    pub fn nearest(&self, now: f64, config: &ProximityConfig) -> Option<f64> {
        self.sectors
            .iter()
            .flatten()
            .filter(|(range, until)| now <= *until && *range < config.map_reach_m)
            .map(|(range, _)| *range)
            .reduce(f64::min)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::FRAC_PI_2;

    const FOV: [f64; 2] = [-0.54, 0.54];
    /// A camera at the body's centre.
    const CENTRE: [f64; 2] = [0.0, 0.0];

    /// The points of a flat wall `d` metres ahead of the body, across the camera's view, at
    /// heights from −1 to +1 m (floor and ceiling lines included).
    fn wall_ahead(d: f64) -> Vec<[f64; 3]> {
        let mut points = vec![];
        for i in -60..=60 {
            for j in -10..=10 {
                points.push([d, d * 0.6 * f64::from(i) / 60.0, f64::from(j) / 10.0]);
            }
        }
        points
    }

    /// The readings of a camera at the body's centre facing a flat wall `d` metres ahead.
    fn seen_ahead(d: f64, config: &ProximityConfig) -> Vec<Reading> {
        readings(wall_ahead(d), CENTRE, FOV, config)
    }

    #[test]
    fn a_wall_ahead_is_read_in_every_direction_in_view_at_its_slant_range() {
        let config = ProximityConfig::default();
        let r = readings(wall_ahead(1.0), CENTRE, FOV, &config);
        assert_eq!(r.len(), 13);
        for reading in &r {
            let range = reading
                .sight
                .range_m()
                .expect("every direction sees the wall");
            // Flat wall: range ≈ 1 / cos(bearing), within a bin's width.
            let expected = 1.0 / reading.bearing_rad.cos();
            assert!((range - expected).abs() < 0.03, "{reading:?}");
        }
    }

    #[test]
    fn a_camera_ahead_of_the_centre_reads_a_near_wall_across_its_whole_view() {
        let config = ProximityConfig::default();
        // A camera 0.1 m ahead of the body's centre, 0.5 m from a flat wall: its pixels'
        // rays, evenly across its view, with the wall's points on the body.
        let camera = [0.1, 0.0];
        let wall: Vec<[f64; 3]> = (0..=160)
            .flat_map(|u| {
                let bearing = FOV[0] + (FOV[1] - FOV[0]) * f64::from(u) / 160.0;
                (-10..=10).map(move |j| [0.6, 0.5 * bearing.tan(), f64::from(j) / 20.0])
            })
            .collect();
        let r = readings(wall.iter().copied(), camera, FOV, &config);
        assert_eq!(r.len(), 13);
        for reading in &r {
            // Every direction sees the wall, at its range from the centre.
            let centre_bearing = (0.5 * reading.bearing_rad.tan()).atan2(0.6);
            let expected = 0.6 / centre_bearing.cos();
            let range = reading.sight.range_m();
            assert!(
                range.is_some_and(|m| (m - expected).abs() < 0.03),
                "{reading:?} of {r:?}"
            );
        }
        // Binned from the centre, the outermost direction on the left saw nothing: a wall too
        // near to range where there is none.
        let from_centre = readings(wall, CENTRE, FOV, &config);
        assert_eq!(from_centre.last().map(|r| r.sight), Some(Sight::Blocked));
    }

    #[test]
    fn floor_ceiling_and_stray_points_are_not_walls() {
        let config = ProximityConfig::default();
        // Only floor and ceiling points, near: no wall read; open where they lie, ahead.
        let floor = (0..100).map(|i| [0.3 + f64::from(i) * 0.01, 0.0, -0.9]);
        let r = readings(floor, CENTRE, FOV, &config);
        assert!(r.iter().all(|r| r.sight.range_m().is_none()));
        assert!(
            r.iter()
                .any(|r| r.bearing_rad.abs() < 0.05 && r.sight == Sight::Open)
        );
        // Two stray pixels at 0.2 m in front of a wall at 2 m: the wall is read.
        let mut points = wall_ahead(2.0);
        points.push([0.2, 0.0, 0.0]);
        points.push([0.21, 0.0, 0.0]);
        let ahead = readings(points, CENTRE, FOV, &config)
            .into_iter()
            .find(|r| r.bearing_rad.abs() < 0.05)
            .expect("a direction ahead");
        assert!(
            (ahead.sight.range_m().expect("range") - 2.0).abs() < 0.01,
            "{ahead:?}"
        );
        // Garbage field of view or points: nothing, no panic.
        assert!(readings(wall_ahead(1.0), CENTRE, [0.5, -0.5], &config).is_empty());
        assert!(readings(wall_ahead(1.0), CENTRE, [f64::NAN, 0.5], &config).is_empty());
        let nan = readings([[f64::NAN, 0.0, 0.0]], CENTRE, FOV, &config);
        assert!(nan.iter().all(|r| r.sight == Sight::Blocked));
    }

    #[test]
    fn a_near_wall_ahead_leans_the_drone_back_and_a_far_one_does_not() {
        let config = ProximityConfig::default();
        let mut p = Proximity::new(&config);
        p.observe(0.0, 0.0, &seen_ahead(2.0, &config), &config);
        assert_eq!(p.push(0.1, 0.0, &config), [0.0, 0.0]);
        p.observe(1.0, 0.0, &seen_ahead(0.45, &config), &config);
        let [forward, left] = p.push(1.1, 0.0, &config);
        assert!(forward < -0.02, "leans back: {forward}");
        assert!(
            left.abs() < 0.2 * forward.abs(),
            "about straight back: {left}"
        );
        // Nearer, harder, up to the limit.
        p.observe(1.2, 0.0, &seen_ahead(0.3, &config), &config);
        let nearer = p.push(1.3, 0.0, &config);
        assert!(nearer[0] < forward, "{nearer:?}");
        assert!(nearer[0].hypot(nearer[1]) <= config.max + 1e-12);
    }

    #[test]
    fn a_wall_seen_before_a_turn_is_pushed_from_where_it_now_lies() {
        let config = ProximityConfig::default();
        let mut p = Proximity::new(&config);
        // Seen ahead at heading 0; the drone has since turned a quarter left: the wall is on
        // its right, so it leans left.
        p.observe(0.0, 0.0, &seen_ahead(0.4, &config), &config);
        let [forward, left] = p.push(0.5, FRAC_PI_2, &config);
        assert!(left > 0.02, "leans left: {left}");
        assert!(forward.abs() < 0.2 * left, "{forward}");
        // A heading that is no number (a broken IMU report) leans nowhere rather than NaN.
        assert_eq!(p.push(0.5, f64::NAN, &config), [0.0, 0.0]);
        assert_eq!(p.push(0.5, f64::INFINITY, &config), [0.0, 0.0]);
    }

    #[test]
    fn walls_either_side_cancel_and_old_ranges_are_forgotten() {
        let config = ProximityConfig::default();
        let mut p = Proximity::new(&config);
        p.observe(0.0, FRAC_PI_2, &seen_ahead(0.4, &config), &config);
        p.observe(0.0, -FRAC_PI_2, &seen_ahead(0.4, &config), &config);
        let [forward, left] = p.push(0.1, 0.0, &config);
        assert!(
            forward.abs() < 1e-9 && left.abs() < 1e-9,
            "{forward} {left}"
        );
        // One side only, old: forgotten.
        let mut q = Proximity::new(&config);
        q.observe(0.0, FRAC_PI_2, &seen_ahead(0.4, &config), &config);
        assert!(q.push(1.0, 0.0, &config)[1] < 0.0);
        assert_eq!(q.push(config.max_age_s + 0.1, 0.0, &config), [0.0, 0.0]);
        assert_eq!(q.nearest(config.max_age_s + 0.1, &config), None);
    }

    #[test]
    fn the_map_ranges_the_walls_behind_a_drone_that_its_camera_does_not_see() {
        let config = ProximityConfig::default();
        // A wall along x = 0.3–0.35 m (5 cm cells); the drone at the origin facing −x: the
        // wall is behind it, 0.3 m away.
        let mut map = Grid::new(40, 40, 0.05, [-1.0, -1.0], crate::Cell::Free);
        for y in 0..40 {
            map.set((26, y), crate::Cell::Occupied);
        }
        let r = map_readings(&map, [0.0, 0.0], PI, &config);
        assert_eq!(r.len(), 72);
        let behind = r
            .iter()
            .filter(|r| r.bearing_rad.abs() > PI - 0.05)
            .filter_map(|r| r.sight.range_m())
            .reduce(f64::min);
        assert!(behind.is_some_and(|m| (m - 0.3).abs() < 1e-9), "{behind:?}");
        let ahead = r
            .iter()
            .find(|r| r.bearing_rad.abs() < 0.05)
            .expect("ahead");
        assert_eq!(ahead.sight, Sight::Wall(config.map_reach_m));
        // Remembered by IMU heading (here 2.0 rad while the map had it at π): blind, the
        // drone leans forward, away from the wall.
        let mut p = Proximity::new(&config);
        p.observe(0.0, 2.0, &r, &config);
        let [forward, left] = p.push(1.0, 2.0, &config);
        assert!(
            forward > 0.02 && left.abs() < 0.2 * forward,
            "{forward} {left}"
        );
        assert!(
            p.nearest(1.0, &config)
                .is_some_and(|m| (m - 0.3).abs() < 1e-9)
        );
        // No map walls, no garbage: nothing near; a bad yaw: no readings.
        let open = Grid::new(40, 40, 0.05, [-1.0, -1.0], crate::Cell::Free);
        let clear = map_readings(&open, [0.0, 0.0], 0.0, &config);
        assert!(
            clear
                .iter()
                .all(|r| r.sight == Sight::Wall(config.map_reach_m))
        );
        let mut q = Proximity::new(&config);
        q.observe(0.0, 0.0, &clear, &config);
        assert_eq!(q.nearest(0.5, &config), None, "nothing near");
        assert!(map_readings(&map, [0.0, 0.0], f64::NAN, &config).is_empty());
    }

    /// The floor across the camera's view, from 2 to 4 m ahead, 0.9 m below the body: what
    /// it measures toward a wall beyond its range, or through a door.
    fn floor_ahead() -> Vec<[f64; 3]> {
        (-60..=60)
            .flat_map(|i| (0..20).map(move |j| (i, j)))
            .map(|(i, j)| {
                let d = 2.0 + f64::from(j) * 0.1;
                [d, d * 0.6 * f64::from(i) / 60.0, -0.9]
            })
            .collect()
    }

    #[test]
    fn a_direction_that_shows_nothing_at_all_is_blocked_by_a_wall_too_near_to_range() {
        let config = ProximityConfig::default();
        let nothing = readings(Vec::<[f64; 3]>::new(), CENTRE, FOV, &config);
        assert_eq!(nothing.len(), 13);
        assert!(nothing.iter().all(|r| r.sight == Sight::Blocked));
        // Never ranged near (it drifted to the wall backward, then turned to face it): a wall
        // at `blocked_m` ahead, so it leans back.
        let mut p = Proximity::new(&config);
        p.observe(0.0, 0.0, &nothing, &config);
        assert_eq!(p.nearest(0.1, &config), Some(config.blocked_m));
        let [forward, left] = p.push(0.1, 0.0, &config);
        assert!(forward < -0.05, "leans back: {forward}");
        assert!(left.abs() < 1e-9, "{left}");
        // Kept while the camera faces it, not for as long as a range: the lean would outlast
        // the wall's nearness.
        let gone = config.blocked_max_age_s + 0.1;
        assert!(gone < config.max_age_s);
        assert_eq!(p.nearest(gone, &config), None);
        assert_eq!(p.push(gone, 0.0, &config), [0.0, 0.0]);
        // Near, then nothing for longer than a range is kept: still pushed away, from the
        // nearer range.
        let mut q = Proximity::new(&config);
        q.observe(0.0, 0.0, &seen_ahead(0.3, &config), &config);
        for t in 1..=8 {
            q.observe(f64::from(t), 0.0, &nothing, &config);
        }
        assert_eq!(q.nearest(8.1, &config), Some(0.3));
        // Ranged near long ago, forgotten, then nothing: the wall is at `blocked_m`, not at
        // the forgotten range.
        let mut old = Proximity::new(&config);
        old.observe(0.0, 0.0, &seen_ahead(0.25, &config), &config);
        old.observe(10.0, 0.0, &nothing, &config);
        assert_eq!(old.nearest(10.1, &config), Some(config.blocked_m));
    }

    #[test]
    fn a_direction_that_shows_the_floor_and_no_wall_is_open() {
        let config = ProximityConfig::default();
        let open = readings(floor_ahead(), CENTRE, FOV, &config);
        assert_eq!(open.len(), 13);
        assert!(open.iter().all(|r| r.sight == Sight::Open), "{open:?}");
        // Near, then the floor beyond (the camera swept from a wall to a door, or the drone
        // left the wall): clear, no lean.
        let mut p = Proximity::new(&config);
        p.observe(0.0, 0.0, &seen_ahead(0.5, &config), &config);
        assert!(p.push(0.1, 0.0, &config)[0] < -0.01);
        p.observe(1.0, 0.0, &open, &config);
        assert_eq!(p.nearest(1.1, &config), None);
        assert_eq!(p.push(1.1, 0.0, &config), [0.0, 0.0]);
    }
}
