//! The simulated RGB-D camera: a ray caster over the extruded floor plan.
//!
//! Every pixel's ray is traced through the plan's cells (a DDA that jumps across open space using
//! the world's clearance map) until it meets a wall, the floor or the ceiling. Surfaces carry
//! procedural textures so a corner detector finds features: blocks of varying shade on walls
//! (each wall line its own pattern), tiles on the floor, panels on the ceiling; featureless walls
//! are a flat colour. Glass is seen through: the colour is tinted and the depth is invalid. Depth
//! is valid between the camera's minimum and maximum range and carries Kinect-like noise that
//! grows with the square of the distance.

use link::camera::{Intrinsics, RgbdFrame};
use nalgebra::{Isometry3, Point3, Vector3};

use crate::rng::{hash2, hash3, unit};
use crate::world::{Material, World};

/// A pinhole RGB-D camera.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Camera {
    /// Image width, pixels.
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
    /// Intrinsics, pixels.
    pub intrinsics: Intrinsics,
    /// Nearest valid depth, metres.
    pub min_range: f64,
    /// Farthest valid depth, metres.
    pub max_range: f64,
}

impl Camera {
    /// A Kinect-like camera of `width × height` (fx = 525 at 640×480), valid from 0.4 to 4 m.
    pub fn kinect(width: u32, height: u32) -> Self {
        Self {
            width,
            height,
            intrinsics: Intrinsics::kinect(width, height),
            min_range: 0.4,
            max_range: 4.0,
        }
    }

    /// Standard deviation of the depth noise at `depth` metres (Nguyen et al., Kinect).
    pub fn depth_sigma(depth: f64) -> f64 {
        0.0012 + 0.0019 * (depth - 0.4).powi(2)
    }
}

/// What a ray met.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Surface {
    /// A wall face: its material, whether it faces along x (a line x = const), the wall line's
    /// index, and the coordinate along the face.
    Wall {
        material: Material,
        x_face: bool,
        line: i64,
        along: f64,
    },
    Floor,
    Ceiling,
}

/// A ray's first opaque hit.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Hit {
    /// Ray parameter: with a direction whose optical-axis component is 1, this is the depth.
    s: f64,
    surface: Surface,
    point: [f64; 3],
    through_glass: bool,
}

/// Renders one frame from `map_from_camera` (camera optical frame: x right, y down, z forward).
/// `noise` is `(seed, frame number)`; `None` renders the exact scene.
pub fn render(
    world: &World,
    map_from_camera: &Isometry3<f64>,
    camera: &Camera,
    noise: Option<(u64, u64)>,
) -> (Vec<u8>, Vec<u16>) {
    let (w, h) = (camera.width as usize, camera.height as usize);
    let k = camera.intrinsics;
    let rot = map_from_camera.rotation.to_rotation_matrix();
    let origin = map_from_camera.translation.vector;
    let o = [origin.x, origin.y, origin.z];
    let mut rgb = vec![0u8; w * h * 3];
    let mut depth = vec![0u16; w * h];
    let noise_key = noise.map(|(seed, frame)| hash2(seed, frame));
    for v in 0..h {
        for u in 0..w {
            let ray_in_camera = Vector3::new(
                (u as f64 - f64::from(k.cx)) / f64::from(k.fx),
                (v as f64 - f64::from(k.cy)) / f64::from(k.fy),
                1.0,
            );
            let d = rot * ray_in_camera;
            let hit = trace(world, o, [d.x, d.y, d.z]);
            let i = v * w + u;
            let pixel_hash = noise_key.map(|key| hash2(key, i as u64));
            let mut c = shade(&hit);
            if let Some(hash) = pixel_hash {
                let n = (unit(hash) - 0.5) * 6.0;
                for ch in &mut c {
                    *ch = (*ch + n).clamp(0.0, 255.0);
                }
            }
            rgb[i * 3] = c[0] as u8;
            rgb[i * 3 + 1] = c[1] as u8;
            rgb[i * 3 + 2] = c[2] as u8;
            if !hit.through_glass && hit.s >= camera.min_range && hit.s <= camera.max_range {
                let mut z = hit.s;
                if let Some(hash) = pixel_hash {
                    z += Camera::depth_sigma(z) * gaussian(mix_bits(hash));
                }
                depth[i] = (z * 1000.0).round().clamp(1.0, 65535.0) as u16;
            }
        }
    }
    (rgb, depth)
}

/// Renders a frame as an [`RgbdFrame`].
pub fn render_frame(
    world: &World,
    map_from_camera: &Isometry3<f64>,
    camera: &Camera,
    noise: Option<(u64, u64)>,
    vehicle: u8,
    stamp: std::time::Duration,
) -> RgbdFrame {
    let (rgb, depth_mm) = render(world, map_from_camera, camera, noise);
    RgbdFrame {
        vehicle,
        stamp,
        width: camera.width,
        height: camera.height,
        intrinsics: camera.intrinsics,
        rgb,
        depth_mm,
    }
}

/// Back-projects a depth pixel to a point in the camera frame (for tests and consumers).
pub fn point_in_camera(k: &Intrinsics, u: f64, v: f64, depth: f64) -> Point3<f64> {
    Point3::new(
        (u - f64::from(k.cx)) / f64::from(k.fx) * depth,
        (v - f64::from(k.cy)) / f64::from(k.fy) * depth,
        depth,
    )
}

fn mix_bits(h: u64) -> u64 {
    h.rotate_left(29) ^ 0x5851_F42D_4C95_7F2D
}

/// An approximately standard normal number from 64 random bits (sum of four uniforms).
fn gaussian(bits: u64) -> f64 {
    let sum: f64 = (0..4)
        .map(|k| ((bits >> (16 * k)) & 0xFFFF) as f64 / 65535.0)
        .sum();
    (sum - 2.0) * (3.0f64).sqrt()
}

/// Traces a ray from `o` along `d` (any length) to its first opaque surface.
fn trace(world: &World, o: [f64; 3], d: [f64; 3]) -> Hit {
    let res = world.resolution();
    let org = world.origin();
    let ceiling = world.ceiling();
    // Where the ray meets the floor or the ceiling.
    let s_plane = if d[2] < -1e-12 {
        (0.0 - o[2]) / d[2]
    } else if d[2] > 1e-12 {
        (ceiling - o[2]) / d[2]
    } else {
        f64::INFINITY
    };
    let s_limit = s_plane.clamp(0.0, 1e4);
    if !o.iter().chain(&d).all(|v| v.is_finite()) {
        return Hit {
            s: 0.0,
            surface: Surface::Floor,
            point: [0.0; 3],
            through_glass: false,
        };
    }
    let at = |s: f64| [o[0] + s * d[0], o[1] + s * d[1], o[2] + s * d[2]];
    let plane_hit = |through_glass| Hit {
        s: s_limit,
        surface: if d[2] < 0.0 {
            Surface::Floor
        } else {
            Surface::Ceiling
        },
        point: at(s_limit),
        through_glass,
    };
    // Position and direction in cell units.
    let (gx, gy) = ((o[0] - org[0]) / res, (o[1] - org[1]) / res);
    let (dx, dy) = (d[0] / res, d[1] / res);
    let speed = (dx * dx + dy * dy).sqrt();
    let mut through_glass = false;
    let mut s = 0.0;
    let (mut ix, mut iy) = (floor(gx), floor(gy));
    let start = world.material(ix, iy);
    if start.is_solid() && start != Material::Glass {
        return Hit {
            s: 0.0,
            surface: Surface::Wall {
                material: start,
                x_face: true,
                line: ix,
                along: o[1],
            },
            point: o,
            through_glass,
        };
    }
    if speed < 1e-12 {
        return plane_hit(false);
    }
    let (step_x, step_y) = (if dx > 0.0 { 1 } else { -1 }, if dy > 0.0 { 1 } else { -1 });
    let delta_x = if dx != 0.0 {
        1.0 / dx.abs()
    } else {
        f64::INFINITY
    };
    let delta_y = if dy != 0.0 {
        1.0 / dy.abs()
    } else {
        f64::INFINITY
    };
    // Ray parameter at the next x and y cell boundary, from the position at parameter `s`.
    let boundaries = |s: f64, ix: i64, iy: i64| {
        let (px, py) = (gx + s * dx, gy + s * dy);
        let nx = if dx > 0.0 {
            (ix + 1) as f64 - px
        } else {
            px - ix as f64
        };
        let ny = if dy > 0.0 {
            (iy + 1) as f64 - py
        } else {
            py - iy as f64
        };
        (s + nx.max(0.0) * delta_x, s + ny.max(0.0) * delta_y)
    };
    let (mut next_x, mut next_y) = boundaries(s, ix, iy);
    loop {
        // Jump across open space: nothing solid is nearer than the clearance (less the chamfer's
        // 8.3 % overestimate and the distance from the cell's centre to its corner).
        let clear = f64::from(world.clearance(ix, iy)) * 0.92 - 1.25;
        if clear > 4.0 {
            s += clear / speed;
            if s >= s_limit {
                return plane_hit(through_glass);
            }
            ix = floor(gx + s * dx);
            iy = floor(gy + s * dy);
            (next_x, next_y) = boundaries(s, ix, iy);
            continue;
        }
        let x_face = next_x < next_y;
        s = if x_face { next_x } else { next_y };
        if s >= s_limit {
            return plane_hit(through_glass);
        }
        if x_face {
            ix += step_x;
            next_x += delta_x;
        } else {
            iy += step_y;
            next_y += delta_y;
        }
        match world.material(ix, iy) {
            Material::Free => {}
            Material::Glass => through_glass = true,
            material => {
                let p = at(s);
                return Hit {
                    s,
                    surface: Surface::Wall {
                        material,
                        x_face,
                        line: if x_face { ix } else { iy },
                        along: if x_face { p[1] } else { p[0] },
                    },
                    point: p,
                    through_glass,
                };
            }
        }
    }
}

/// `x.floor()` as an integer, without the libm call that `f64::floor` costs on baseline x86-64
/// (saturating for huge values, 0 for NaN).
fn floor(x: f64) -> i64 {
    let i = x as i64;
    if (i as f64) > x { i - 1 } else { i }
}

/// The fractional part in [0, 1).
fn fract(x: f64) -> f64 {
    x - floor(x) as f64
}

/// A shade in [0, 1) for integer block coordinates of one surface pattern.
fn block(salt: u64, a: f64, b: f64) -> f64 {
    unit(hash3(salt, floor(a) as u64, floor(b) as u64))
}

/// Wall tints: pale paints, one per wall line.
const PAINTS: [[f64; 3]; 6] = [
    [1.0, 0.95, 0.85],
    [0.85, 0.95, 1.0],
    [0.9, 1.0, 0.88],
    [1.0, 0.88, 0.88],
    [0.95, 0.92, 1.0],
    [1.0, 1.0, 0.95],
];

fn shade(hit: &Hit) -> [f64; 3] {
    let [x, y, z] = hit.point;
    let mut c = match hit.surface {
        Surface::Wall {
            material,
            x_face,
            line,
            along,
        } => {
            let light = if x_face { 0.88 } else { 1.0 };
            match material {
                Material::Plain => [205.0 * light, 200.0 * light, 190.0 * light],
                _ => {
                    let salt = hash2(u64::from(x_face), line as u64);
                    let paint = PAINTS[(salt % PAINTS.len() as u64) as usize];
                    // Posters and panels: 0.3 m blocks, with 0.075 m detail inside.
                    let coarse = 60.0 + 170.0 * block(salt, along / 0.3, z / 0.3);
                    let fine = 50.0 * (block(salt ^ 1, along / 0.075, z / 0.075) - 0.5);
                    let g = (coarse + fine) * light;
                    [g * paint[0], g * paint[1], g * paint[2]]
                }
            }
        }
        Surface::Floor => {
            // 0.4 m tiles with dark grout and a speckle.
            let (fx, fy) = (fract(x / 0.4), fract(y / 0.4));
            if fx < 0.04 || fy < 0.04 {
                [50.0, 45.0, 40.0]
            } else {
                let g = 110.0
                    + 100.0 * block(7, x / 0.4, y / 0.4)
                    + 30.0 * (block(8, x / 0.1, y / 0.1) - 0.5);
                [g, g * 0.85, g * 0.7]
            }
        }
        Surface::Ceiling => {
            let (fx, fy) = (fract(x / 0.6), fract(y / 0.6));
            let g = if fx < 0.03 || fy < 0.03 {
                170.0
            } else {
                220.0 + 20.0 * block(9, x / 0.6, y / 0.6)
            };
            [g, g, g]
        }
    };
    if hit.through_glass {
        for (ch, tint) in c.iter_mut().zip([150.0, 200.0, 210.0]) {
            *ch = 0.75 * *ch + 0.25 * tint;
        }
    }
    c
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion};

    /// The camera optical frame's axes in the body frame (x forward, y left, z up).
    fn body_from_camera() -> UnitQuaternion<f64> {
        let m = nalgebra::Matrix3::new(0.0, 0.0, 1.0, -1.0, 0.0, 0.0, 0.0, -1.0, 0.0);
        UnitQuaternion::from_matrix(&m)
    }

    fn camera_at(x: f64, y: f64, z: f64, yaw: f64) -> Isometry3<f64> {
        Isometry3::from_parts(
            Translation3::new(x, y, z),
            UnitQuaternion::from_euler_angles(0.0, 0.0, yaw) * body_from_camera(),
        )
    }

    /// A 4 m × 3 m room with 0.1 m cells, walls all round.
    fn room() -> World {
        let mut text = String::from("resolution 0.1\nceiling 2.5\n---\n");
        for y in 0..32 {
            for x in 0..42 {
                text.push(if x == 0 || y == 0 || x == 41 || y == 31 {
                    '#'
                } else {
                    '.'
                });
            }
            text.push('\n');
        }
        World::parse_text("room", &text).unwrap()
    }

    #[test]
    fn depth_is_the_distance_to_the_wall_along_the_optical_axis() {
        let w = room();
        let cam = Camera::kinect(64, 48);
        // At x = 1.0 facing +x: the far wall's face is at x = 4.1.
        let pose = camera_at(1.0, 1.6, 1.25, 0.0);
        let (_, depth) = render(&w, &pose, &cam, None);
        let centre = depth[24 * 64 + 32];
        assert!((i32::from(centre) - 3100).abs() <= 1, "{centre}");
        // Every pixel of a frontal wall has the same z-depth (not range); the outer columns see
        // the side walls.
        let row: Vec<u16> = (16..48).map(|u| depth[24 * 64 + u]).collect();
        assert!(
            row.iter().all(|d| (i32::from(*d) - 3100).abs() <= 1),
            "{row:?}"
        );
        // Back-projected pixels lie on the wall plane.
        let k = cam.intrinsics;
        for (u, v) in [(0, 0), (63, 47), (10, 40)] {
            let d = f64::from(depth[v * 64 + u]) / 1000.0;
            if d > 0.0 {
                let p = pose * point_in_camera(&k, u as f64, v as f64, d);
                let on_wall = (p.x - 4.1).abs() < 0.002;
                let on_floor = p.z.abs() < 0.002;
                let on_ceiling = (p.z - 2.5).abs() < 0.002;
                let on_side = (p.y - 0.1).abs() < 0.002 || (p.y - 3.1).abs() < 0.002;
                assert!(on_wall || on_floor || on_ceiling || on_side, "{p:?}");
            }
        }
    }

    #[test]
    fn depth_is_invalid_beyond_range_and_noisy_within() {
        let w = room();
        let mut cam = Camera::kinect(64, 48);
        cam.max_range = 3.0;
        let pose = camera_at(1.0, 1.6, 1.25, 0.0);
        let (_, depth) = render(&w, &pose, &cam, None);
        assert_eq!(depth[24 * 64 + 32], 0, "3.1 m is beyond a 3 m range");
        let cam = Camera::kinect(64, 48);
        let (_, a) = render(&w, &pose, &cam, Some((1, 0)));
        let (_, b) = render(&w, &pose, &cam, Some((1, 1)));
        let (_, a2) = render(&w, &pose, &cam, Some((1, 0)));
        assert_eq!(a, a2, "same seed and frame, same noise");
        assert_ne!(a, b, "a new frame has new noise");
        let errs: Vec<f64> = (16..48)
            .map(|u| f64::from(a[24 * 64 + u]) / 1000.0 - 3.1)
            .collect();
        let rms = (errs.iter().map(|e| e * e).sum::<f64>() / errs.len() as f64).sqrt();
        let sigma = Camera::depth_sigma(3.1);
        assert!(
            rms > 0.3 * sigma && rms < 3.0 * sigma,
            "rms {rms} vs sigma {sigma}"
        );
    }

    #[test]
    fn glass_is_seen_through_with_invalid_depth_and_plain_walls_are_flat() {
        let mut text = String::from("resolution 0.1\n---\n");
        for y in 0..20 {
            for x in 0..40 {
                text.push(match (x, y) {
                    (0, _) | (_, 0) | (_, 19) => '#',
                    (39, _) => '+',
                    (20, _) => '~',
                    _ => '.',
                });
            }
            text.push('\n');
        }
        let w = World::parse_text("glass", &text).unwrap();
        let cam = Camera::kinect(64, 48);
        let (rgb, depth) = render(&w, &camera_at(1.0, 1.0, 1.3, 0.0), &cam, None);
        // Looking straight at the glass at x = 2.0: no depth, and the plain wall shows through.
        let c = 24 * 64 + 32;
        assert_eq!(depth[c], 0);
        assert!(rgb[c * 3] > 100, "tinted plain wall seen through the glass");
        // The plain wall seen without glass has one colour across the image's wall pixels.
        let (rgb, depth) = render(&w, &camera_at(2.5, 1.0, 1.3, 0.0), &cam, None);
        assert!((i32::from(depth[c]) - 1400).abs() <= 1, "{}", depth[c]);
        let wall: std::collections::HashSet<[u8; 3]> = (20..28)
            .flat_map(|v| (20..44).map(move |u| v * 64 + u))
            .map(|i| [rgb[i * 3], rgb[i * 3 + 1], rgb[i * 3 + 2]])
            .collect();
        assert_eq!(wall.len(), 1, "{wall:?}");
    }

    #[test]
    fn textured_walls_have_contrast_for_a_corner_detector() {
        let w = World::load(crate::world::DEFAULT_WORLD).unwrap();
        let cam = Camera::kinect(320, 240);
        let (rgb, _) = render(
            &w,
            &camera_at(13.1, 2.1, 1.2, std::f64::consts::PI),
            &cam,
            None,
        );
        let grey: Vec<f64> = rgb
            .chunks(3)
            .map(|p| (f64::from(p[0]) + f64::from(p[1]) + f64::from(p[2])) / 3.0)
            .collect();
        // Count strong horizontal and vertical gradients together (a crude corner measure).
        let mut corners = 0;
        for v in 1..239 {
            for u in 1..319 {
                let i = v * 320 + u;
                let gx = (grey[i + 1] - grey[i - 1]).abs();
                let gy = (grey[i + 320] - grey[i - 320]).abs();
                if gx > 20.0 && gy > 20.0 {
                    corners += 1;
                }
            }
        }
        assert!(corners > 200, "only {corners} corner-like pixels");
    }

    #[test]
    fn rays_from_inside_a_wall_or_outside_the_plan_do_not_panic() {
        let w = room();
        let cam = Camera::kinect(16, 12);
        for pose in [
            camera_at(0.05, 0.05, 1.0, 0.3),
            camera_at(-5.0, -5.0, 1.0, 1.0),
            camera_at(1.0, 1.0, -1.0, 0.0),
            camera_at(1.0, 1.0, 10.0, 0.0),
            camera_at(f64::NAN, 1.0, 1.0, 0.0),
        ] {
            let (rgb, depth) = render(&w, &pose, &cam, Some((0, 0)));
            assert_eq!((rgb.len(), depth.len()), (16 * 12 * 3, 16 * 12));
        }
    }
}
