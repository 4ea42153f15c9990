//! Pose graphs in SE(2) and SE(3): g2o files, the error of an edge as g2o defines it, and
//! SE-Sync's objective F for comparing against published optima.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use nalgebra::{
    Isometry2, Isometry3, Matrix2, Matrix3, Quaternion, SMatrix, SVector, Translation3,
    UnitQuaternion, Vector2, Vector3,
};

/// A pose type the optimiser can work with.
pub trait Pose: Clone + Send + Sync + 'static {
    /// Degrees of freedom (3 for SE(2), 6 for SE(3)).
    const DOF: usize;
    /// `self ⊞ delta`: a right perturbation (translation in the pose's own frame first).
    fn retract(&self, delta: &[f64]) -> Self;
    /// The error of measurement `z` between `xi` and `xj`: translation, then rotation (angle for
    /// SE(2), rotation vector for SE(3)).
    fn error(xi: &Self, xj: &Self, z: &Self, out: &mut [f64]);
    /// `a · b`.
    fn compose(a: &Self, b: &Self) -> Self;
    /// The identity.
    fn identity() -> Self;
    /// The Jacobians of [`Pose::error`] with respect to right perturbations of `xi` and `xj`
    /// (row-major, DOF × DOF each), at the error `e` already computed.
    fn jacobians(xi: &Self, xj: &Self, z: &Self, e: &[f64], ji: &mut [f64], jj: &mut [f64]);
    /// (‖R_j − R_i R̃‖²_F, ‖t_j − t_i − R_i t̃‖²) for SE-Sync's objective.
    fn chordal_residuals(xi: &Self, xj: &Self, z: &Self) -> (f64, f64);
    /// SE-Sync's isotropic weights (κ, τ) from an edge's information matrix.
    fn se_sync_weights(info: &[f64]) -> (f64, f64);
}

impl Pose for Isometry2<f64> {
    const DOF: usize = 3;
    fn retract(&self, d: &[f64]) -> Self {
        let t = self.translation.vector + self.rotation * Vector2::new(d[0], d[1]);
        Isometry2::new(t, self.rotation.angle() + d[2])
    }
    fn error(xi: &Self, xj: &Self, z: &Self, out: &mut [f64]) {
        let e = z.inverse() * (xi.inverse() * xj);
        out[0] = e.translation.vector.x;
        out[1] = e.translation.vector.y;
        out[2] = e.rotation.angle();
    }
    fn compose(a: &Self, b: &Self) -> Self {
        a * b
    }
    fn identity() -> Self {
        Isometry2::identity()
    }
    fn jacobians(xi: &Self, xj: &Self, z: &Self, _e: &[f64], ji: &mut [f64], jj: &mut [f64]) {
        // e_t = R_zᵀ(R_iᵀ(t_j − t_i) − t_z), e_θ = θ_j − θ_i − θ_z.
        let rz_t = z.rotation.inverse().to_rotation_matrix().into_inner();
        let ri_t = xi.rotation.inverse().to_rotation_matrix().into_inner();
        let rj = xj.rotation.to_rotation_matrix().into_inner();
        let dt = xj.translation.vector - xi.translation.vector;
        let (s, c) = xi.rotation.angle().sin_cos();
        // d(R_iᵀ)/dθ · (t_j − t_i)
        let a = rz_t * Vector2::new(-s * dt.x + c * dt.y, -c * dt.x - s * dt.y);
        let b = rz_t * ri_t * rj;
        ji.copy_from_slice(&[
            -rz_t[(0, 0)],
            -rz_t[(0, 1)],
            a.x,
            -rz_t[(1, 0)],
            -rz_t[(1, 1)],
            a.y,
            0.0,
            0.0,
            -1.0,
        ]);
        jj.copy_from_slice(&[
            b[(0, 0)],
            b[(0, 1)],
            0.0,
            b[(1, 0)],
            b[(1, 1)],
            0.0,
            0.0,
            0.0,
            1.0,
        ]);
    }
    fn chordal_residuals(xi: &Self, xj: &Self, z: &Self) -> (f64, f64) {
        let rot = |p: &Self| p.rotation.to_rotation_matrix().into_inner();
        let tr = |p: &Self| p.translation.vector;
        residuals(&rot(xi), &rot(xj), &rot(z), &tr(xi), &tr(xj), &tr(z))
    }
    fn se_sync_weights(info: &[f64]) -> (f64, f64) {
        let tt = Matrix2::new(info[0], info[1], info[3], info[4]);
        let tau = tt.try_inverse().map_or(0.0, |inv| 2.0 / inv.trace());
        (info[8], tau)
    }
}

impl Pose for Isometry3<f64> {
    const DOF: usize = 6;
    fn retract(&self, d: &[f64]) -> Self {
        let t = self.translation.vector + self.rotation * Vector3::new(d[0], d[1], d[2]);
        let mut r =
            self.rotation * UnitQuaternion::from_scaled_axis(Vector3::new(d[3], d[4], d[5]));
        // Products round the norm off 1; iterations must not let that build up.
        r.renormalize_fast();
        Isometry3::from_parts(Translation3::from(t), r)
    }
    fn error(xi: &Self, xj: &Self, z: &Self, out: &mut [f64]) {
        // Translation and rotation vector of Z⁻¹·Xi⁻¹·Xj. The information's rotation block weighs
        // the rotation vector, as GTSAM and SE-Sync read g2o files (g2o itself weighs the
        // quaternion's vector part, about half the angle, which shifts the optimum when the
        // information is anisotropic).
        let e = z.inverse() * (xi.inverse() * xj);
        let w = e.rotation.scaled_axis();
        out[0] = e.translation.vector.x;
        out[1] = e.translation.vector.y;
        out[2] = e.translation.vector.z;
        out[3] = w.x;
        out[4] = w.y;
        out[5] = w.z;
    }
    fn compose(a: &Self, b: &Self) -> Self {
        a * b
    }
    fn identity() -> Self {
        Isometry3::identity()
    }
    fn jacobians(xi: &Self, xj: &Self, z: &Self, e: &[f64], ji: &mut [f64], jj: &mut [f64]) {
        // e_t = R_zᵀ(R_iᵀ(t_j − t_i) − t_z), e_r = Log(R_zᵀ R_iᵀ R_j).
        let rz_t = z.rotation.inverse().to_rotation_matrix().into_inner();
        let ri = xi.rotation.to_rotation_matrix().into_inner();
        let rj = xj.rotation.to_rotation_matrix().into_inner();
        let local = ri.transpose() * (xj.translation.vector - xi.translation.vector);
        let jr_inv = right_jacobian_inverse(&Vector3::new(e[3], e[4], e[5]));
        let dt_dti = -rz_t;
        let dt_dri = rz_t * local.cross_matrix();
        let dt_dtj = rz_t * ri.transpose() * rj;
        let dr_dri = -jr_inv * rj.transpose() * ri;
        let dr_drj = jr_inv;
        for r in 0..3 {
            for c in 0..3 {
                ji[r * 6 + c] = dt_dti[(r, c)];
                ji[r * 6 + 3 + c] = dt_dri[(r, c)];
                ji[(3 + r) * 6 + c] = 0.0;
                ji[(3 + r) * 6 + 3 + c] = dr_dri[(r, c)];
                jj[r * 6 + c] = dt_dtj[(r, c)];
                jj[r * 6 + 3 + c] = 0.0;
                jj[(3 + r) * 6 + c] = 0.0;
                jj[(3 + r) * 6 + 3 + c] = dr_drj[(r, c)];
            }
        }
    }
    fn chordal_residuals(xi: &Self, xj: &Self, z: &Self) -> (f64, f64) {
        let rot = |p: &Self| p.rotation.to_rotation_matrix().into_inner();
        let tr = |p: &Self| p.translation.vector;
        residuals(&rot(xi), &rot(xj), &rot(z), &tr(xi), &tr(xj), &tr(z))
    }
    fn se_sync_weights(info: &[f64]) -> (f64, f64) {
        let block = |o: usize| Matrix3::from_fn(|r, c| info[(o + r) * 6 + o + c]);
        let tau = block(0).try_inverse().map_or(0.0, |inv| 3.0 / inv.trace());
        let kappa = block(3)
            .try_inverse()
            .map_or(0.0, |inv| 3.0 / (2.0 * inv.trace()));
        (kappa, tau)
    }
}

/// A relative-pose measurement between two vertices.
#[derive(Debug, Clone)]
pub struct Edge<P> {
    /// Index of the first vertex.
    pub i: usize,
    /// Index of the second vertex.
    pub j: usize,
    /// The measured `xi⁻¹ · xj`.
    pub z: P,
    /// Information matrix (DOF × DOF, row-major).
    pub info: Vec<f64>,
}

/// A pose graph.
#[derive(Debug, Clone)]
pub struct Graph<P> {
    /// The vertices' g2o ids, in index order.
    pub ids: Vec<u64>,
    /// The current estimate.
    pub poses: Vec<P>,
    /// The measurements.
    pub edges: Vec<Edge<P>>,
}

/// (‖R_j − R_i R̃‖²_F, ‖t_j − t_i − R_i t̃‖²) in D dimensions.
fn residuals<const D: usize>(
    ri: &SMatrix<f64, D, D>,
    rj: &SMatrix<f64, D, D>,
    rz: &SMatrix<f64, D, D>,
    ti: &SVector<f64, D>,
    tj: &SVector<f64, D>,
    tz: &SVector<f64, D>,
) -> (f64, f64) {
    (
        (rj - ri * rz).norm_squared(),
        (tj - ti - ri * tz).norm_squared(),
    )
}

/// The inverse right Jacobian of SO(3) at the rotation vector `phi`.
fn right_jacobian_inverse(phi: &Vector3<f64>) -> Matrix3<f64> {
    let theta = phi.norm();
    let w = phi.cross_matrix();
    let coef = if theta < 1e-4 {
        1.0 / 12.0 + theta * theta / 720.0
    } else {
        1.0 / (theta * theta) - (1.0 + theta.cos()) / (2.0 * theta * theta.sin())
    };
    Matrix3::identity() + 0.5 * w + coef * w * w
}

/// The robot a vertex id belongs to. Multi-robot graphs use GTSAM's `Symbol` keys: the robot's
/// letter in the top 8 bits, the pose number in the rest (`a0`, `a1`, … `b0`, …, as in the DGS
/// multi-robot datasets); a plain id belongs to robot 0.
pub fn robot_of_id(id: u64) -> u8 {
    (id >> 56) as u8
}

/// The vertex id of pose `number` of `robot` (robot 0: the plain number).
pub fn vertex_id(robot: u8, number: u64) -> u64 {
    (u64::from(robot) << 56) | (number & ((1 << 56) - 1))
}

impl<P: Pose> Graph<P> {
    /// The robot of vertex `index`.
    pub fn robot(&self, index: usize) -> u8 {
        self.ids.get(index).copied().map_or(0, robot_of_id)
    }

    /// The estimate split per robot: `(robot, [(vertex id, pose)])`, robots in order.
    pub fn trajectories(&self) -> Vec<(u8, Vec<(u64, P)>)> {
        let mut out: std::collections::BTreeMap<u8, Vec<(u64, P)>> =
            std::collections::BTreeMap::new();
        for (id, p) in self.ids.iter().zip(&self.poses) {
            out.entry(robot_of_id(*id))
                .or_default()
                .push((*id, p.clone()));
        }
        out.into_iter().collect()
    }
}

/// A g2o graph of either kind.
#[derive(Debug, Clone)]
pub enum AnyGraph {
    /// `VERTEX_SE2` / `EDGE_SE2`.
    Se2(Graph<Isometry2<f64>>),
    /// `VERTEX_SE3:QUAT` / `EDGE_SE3:QUAT`.
    Se3(Graph<Isometry3<f64>>),
}

/// A g2o file that could not be read.
#[derive(Debug, thiserror::Error)]
pub enum G2oError {
    /// The file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// A malformed line.
    #[error("{path}:{line}: {reason}")]
    Line {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// What is wrong.
        reason: String,
    },
    /// The graph as a whole is unusable.
    #[error("{path}: {reason}")]
    Graph {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
}

/// Reads a g2o file. Files with edges only get an initial guess by chaining the odometry edges
/// (`j = i + 1`) from the identity.
pub fn read_g2o(path: impl AsRef<Path>) -> Result<AnyGraph, G2oError> {
    let path = path.as_ref();
    let text = std::fs::read_to_string(path).map_err(|source| G2oError::Io {
        path: path.into(),
        source,
    })?;
    parse_g2o(&text, path)
}

struct Raw {
    kind: u8, // 2 or 3
    vertices: Vec<(u64, Vec<f64>)>,
    edges: Vec<(u64, u64, Vec<f64>, Vec<f64>)>,
}

/// Parses g2o text; `path` is only used in error messages.
pub fn parse_g2o(text: &str, path: &Path) -> Result<AnyGraph, G2oError> {
    let mut raw = Raw {
        kind: 0,
        vertices: vec![],
        edges: vec![],
    };
    for (n, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let fail = |reason: String| G2oError::Line {
            path: path.into(),
            line: n + 1,
            reason,
        };
        let mut words = line.split_whitespace();
        let tag = words.next().unwrap_or_default();
        let rest: Vec<&str> = words.collect();
        let (kind, is_vertex, values) = match tag {
            "VERTEX_SE2" => (2, true, 3),
            "EDGE_SE2" => (2, false, 3 + 6),
            "VERTEX_SE3:QUAT" => (3, true, 7),
            "EDGE_SE3:QUAT" => (3, false, 7 + 21),
            "FIX" => continue, // the optimiser anchors the first vertex anyway
            other => {
                return Err(fail(format!(
                    "unknown tag {other:?} (SE2 and SE3:QUAT vertices and edges are supported)"
                )));
            }
        };
        if raw.kind != 0 && raw.kind != kind {
            return Err(fail("2D and 3D elements in one file".into()));
        }
        raw.kind = kind;
        let ids = if is_vertex { 1 } else { 2 };
        if rest.len() != ids + values {
            return Err(fail(format!(
                "{tag} needs {} fields, found {}",
                ids + values,
                rest.len()
            )));
        }
        let id = |s: &str| {
            s.parse::<u64>()
                .map_err(|_| fail(format!("{s:?} is not a vertex id")))
        };
        let nums: Vec<f64> = rest[ids..]
            .iter()
            .map(|s| {
                s.parse::<f64>()
                    .ok()
                    .filter(|v| v.is_finite())
                    .ok_or_else(|| fail(format!("{s:?} is not a finite number")))
            })
            .collect::<Result<_, _>>()?;
        if is_vertex {
            raw.vertices.push((id(rest[0])?, nums));
        } else {
            let (i, j) = (id(rest[0])?, id(rest[1])?);
            if i == j {
                return Err(fail("an edge from a vertex to itself".into()));
            }
            let split = if kind == 2 { 3 } else { 7 };
            raw.edges
                .push((i, j, nums[..split].to_vec(), nums[split..].to_vec()));
        }
    }
    let graph_err = |reason: String| G2oError::Graph {
        path: path.into(),
        reason,
    };
    match raw.kind {
        2 => build(raw, se2_from, info_from_upper::<3>, path).map(AnyGraph::Se2),
        3 => build(raw, se3_from, info_from_upper::<6>, path).map(AnyGraph::Se3),
        _ => Err(graph_err("no vertices or edges".into())),
    }
}

fn se2_from(v: &[f64]) -> Option<Isometry2<f64>> {
    Some(Isometry2::new(Vector2::new(v[0], v[1]), v[2]))
}

fn se3_from(v: &[f64]) -> Option<Isometry3<f64>> {
    let q = Quaternion::new(v[6], v[3], v[4], v[5]);
    (q.norm() > 1e-9).then(|| {
        Isometry3::from_parts(
            Translation3::new(v[0], v[1], v[2]),
            UnitQuaternion::from_quaternion(q),
        )
    })
}

fn info_from_upper<const D: usize>(u: &[f64]) -> Vec<f64> {
    let mut m = vec![0.0; D * D];
    let mut k = 0;
    for r in 0..D {
        for c in r..D {
            m[r * D + c] = u[k];
            m[c * D + r] = u[k];
            k += 1;
        }
    }
    m
}

fn build<P: Pose>(
    raw: Raw,
    pose_from: fn(&[f64]) -> Option<P>,
    info_from: fn(&[f64]) -> Vec<f64>,
    path: &Path,
) -> Result<Graph<P>, G2oError> {
    let graph_err = |reason: String| G2oError::Graph {
        path: path.into(),
        reason,
    };
    let mut ids: Vec<u64> = raw.vertices.iter().map(|v| v.0).collect();
    let mut poses: Vec<P> = Vec::new();
    for (id, v) in &raw.vertices {
        poses.push(
            pose_from(v).ok_or_else(|| graph_err(format!("vertex {id} has a zero quaternion")))?,
        );
    }
    if ids.is_empty() {
        // Edges only: vertices are the ids the edges name; chain odometry for the initial guess.
        let mut all: Vec<u64> = raw.edges.iter().flat_map(|e| [e.0, e.1]).collect();
        all.sort_unstable();
        all.dedup();
        ids = all;
    }
    let index: std::collections::HashMap<u64, usize> =
        ids.iter().enumerate().map(|(k, id)| (*id, k)).collect();
    if index.len() != ids.len() {
        return Err(graph_err("a vertex id appears twice".into()));
    }
    let mut edges = Vec::with_capacity(raw.edges.len());
    for (i, j, z, info) in &raw.edges {
        let (Some(&a), Some(&b)) = (index.get(i), index.get(j)) else {
            return Err(graph_err(format!(
                "edge {i}–{j} names a vertex that is not in the file"
            )));
        };
        let z =
            pose_from(z).ok_or_else(|| graph_err(format!("edge {i}–{j} has a zero quaternion")))?;
        edges.push(Edge {
            i: a,
            j: b,
            z,
            info: info_from(info),
        });
    }
    if poses.is_empty() {
        poses = vec![P::identity(); ids.len()];
        let mut known = vec![false; ids.len()];
        known[0] = true;
        let mut odometry: Vec<&Edge<P>> = edges.iter().filter(|e| e.j == e.i + 1).collect();
        odometry.sort_by_key(|e| e.i);
        for e in odometry {
            if known[e.i] && !known[e.j] {
                poses[e.j] = P::compose(&poses[e.i], &e.z);
                known[e.j] = true;
            }
        }
        if let Some(k) = known.iter().position(|k| !k) {
            return Err(graph_err(format!(
                "no odometry chain reaches vertex {}: give VERTEX lines",
                ids[k]
            )));
        }
    }
    Ok(Graph { ids, poses, edges })
}

/// g2o text for a graph (every vertex, then every edge).
pub fn format_g2o(graph: &AnyGraph) -> String {
    let mut s = String::new();
    match graph {
        AnyGraph::Se2(g) => {
            for (id, p) in g.ids.iter().zip(&g.poses) {
                let t = p.translation.vector;
                let _ = writeln!(s, "VERTEX_SE2 {id} {} {} {}", t.x, t.y, p.rotation.angle());
            }
            for e in &g.edges {
                let t = e.z.translation.vector;
                let _ = write!(
                    s,
                    "EDGE_SE2 {} {} {} {} {}",
                    g.ids[e.i],
                    g.ids[e.j],
                    t.x,
                    t.y,
                    e.z.rotation.angle()
                );
                upper(&mut s, &e.info, 3);
            }
        }
        AnyGraph::Se3(g) => {
            for (id, p) in g.ids.iter().zip(&g.poses) {
                let (t, q) = (p.translation.vector, p.rotation);
                let _ = writeln!(
                    s,
                    "VERTEX_SE3:QUAT {id} {} {} {} {} {} {} {}",
                    t.x, t.y, t.z, q.i, q.j, q.k, q.w
                );
            }
            for e in &g.edges {
                let (t, q) = (e.z.translation.vector, e.z.rotation);
                let _ = write!(
                    s,
                    "EDGE_SE3:QUAT {} {} {} {} {} {} {} {} {}",
                    g.ids[e.i], g.ids[e.j], t.x, t.y, t.z, q.i, q.j, q.k, q.w
                );
                upper(&mut s, &e.info, 6);
            }
        }
    }
    s
}

fn upper(s: &mut String, m: &[f64], d: usize) {
    for r in 0..d {
        for c in r..d {
            let _ = write!(s, " {}", m[r * d + c]);
        }
    }
    s.push('\n');
}

/// Writes a graph as g2o.
pub fn write_g2o(path: impl AsRef<Path>, graph: &AnyGraph) -> Result<(), G2oError> {
    let path = path.as_ref();
    std::fs::write(path, format_g2o(graph)).map_err(|source| G2oError::Io {
        path: path.into(),
        source,
    })
}

/// The chi² of a graph: Σ eᵀ Ω e with [`Pose::error`].
pub fn chi2<P: Pose>(g: &Graph<P>) -> f64 {
    let d = P::DOF;
    let mut e = vec![0.0; d];
    g.edges
        .iter()
        .map(|edge| {
            P::error(&g.poses[edge.i], &g.poses[edge.j], &edge.z, &mut e);
            quad(&edge.info, &e, d)
        })
        .sum()
}

pub(crate) fn quad(m: &[f64], e: &[f64], d: usize) -> f64 {
    let mut s = 0.0;
    for r in 0..d {
        for c in 0..d {
            s += e[r] * m[r * d + c] * e[c];
        }
    }
    s
}

/// SE-Sync's objective F (Rosen et al., IJRR 2019) at the graph's estimate, with isotropic weights
/// from each edge's information: F = Σ κ‖R_j − R_i R̃_ij‖²_F + τ‖t_j − t_i − R_i t̃_ij‖².
pub fn se_sync_objective(graph: &AnyGraph) -> f64 {
    fn f<P: Pose>(g: &Graph<P>) -> f64 {
        g.edges
            .iter()
            .map(|e| {
                let (kappa, tau) = P::se_sync_weights(&e.info);
                let (rot, tr) = P::chordal_residuals(&g.poses[e.i], &g.poses[e.j], &e.z);
                kappa * rot + tau * tr
            })
            .sum()
    }
    match graph {
        AnyGraph::Se2(g) => f(g),
        AnyGraph::Se3(g) => f(g),
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    pub(crate) fn data(name: &str) -> PathBuf {
        PathBuf::from(env!("CARGO_MANIFEST_DIR"))
            .join("../../shared/data/posegraph")
            .join(name)
    }

    #[test]
    fn every_shared_graph_parses_with_its_published_size() {
        for (file, v, e) in [
            ("intel.g2o", 1728, 2512),
            ("manhattan.g2o", 3500, 5453),
            ("parking-garage.g2o", 1661, 6275),
            ("sphere2500.g2o", 2500, 4949),
            ("torus3D.g2o", 5000, 9048),
            ("tinyGrid3D.g2o", 9, 11),
        ] {
            let (nv, ne) = match read_g2o(data(file)).unwrap() {
                AnyGraph::Se2(g) => (g.poses.len(), g.edges.len()),
                AnyGraph::Se3(g) => (g.poses.len(), g.edges.len()),
            };
            assert_eq!((nv, ne), (v, e), "{file}");
        }
    }

    fn numeric<P: Pose>(xi: &P, xj: &P, z: &P) -> (Vec<f64>, Vec<f64>) {
        let d = P::DOF;
        let (mut ji, mut jj) = (vec![0.0; d * d], vec![0.0; d * d]);
        let (mut ep, mut em) = (vec![0.0; d], vec![0.0; d]);
        let h = 1e-6;
        for k in 0..2 * d {
            let mut delta = vec![0.0; d];
            delta[k % d] = h;
            let (pi, pj) = if k < d {
                (xi.retract(&delta), xj.clone())
            } else {
                (xi.clone(), xj.retract(&delta))
            };
            P::error(&pi, &pj, z, &mut ep);
            delta[k % d] = -h;
            let (mi, mj) = if k < d {
                (xi.retract(&delta), xj.clone())
            } else {
                (xi.clone(), xj.retract(&delta))
            };
            P::error(&mi, &mj, z, &mut em);
            for r in 0..d {
                let v = (ep[r] - em[r]) / (2.0 * h);
                if k < d {
                    ji[r * d + k] = v
                } else {
                    jj[r * d + k - d] = v
                }
            }
        }
        (ji, jj)
    }

    fn check_jacobians<P: Pose>(
        xi: &P,
        xj: &P,
        z: &P,
    ) -> Result<(), proptest::test_runner::TestCaseError> {
        let d = P::DOF;
        let mut e = vec![0.0; d];
        P::error(xi, xj, z, &mut e);
        let (mut ji, mut jj) = (vec![0.0; d * d], vec![0.0; d * d]);
        P::jacobians(xi, xj, z, &e, &mut ji, &mut jj);
        let (ni, nj) = numeric(xi, xj, z);
        for k in 0..d * d {
            proptest::prop_assert!(
                (ji[k] - ni[k]).abs() < 1e-5,
                "d/dxi [{}]: {} vs {}",
                k,
                ji[k],
                ni[k]
            );
            proptest::prop_assert!(
                (jj[k] - nj[k]).abs() < 1e-5,
                "d/dxj [{}]: {} vs {}",
                k,
                jj[k],
                nj[k]
            );
        }
        Ok(())
    }

    proptest::proptest! {
        #[test]
        fn analytic_jacobians_match_central_differences(
            a in proptest::collection::vec(-2.0f64..2.0, 18),
        ) {
            let se2 = |o: usize| Isometry2::new(Vector2::new(a[o], a[o + 1]), a[o + 2]);
            check_jacobians(&se2(0), &se2(3), &se2(6))?;
            let se3 = |o: usize| Isometry3::new(Vector3::new(a[o], a[o + 1], a[o + 2]), Vector3::new(a[o + 3], a[o + 4], a[o + 5]) * 0.5);
            check_jacobians(&se3(0), &se3(6), &se3(12))?;
        }
    }

    #[test]
    fn robots_are_read_from_symbol_keys() {
        let a = vertex_id(b'a', 0);
        let b = vertex_id(b'b', 3);
        let text = format!(
            "VERTEX_SE2 {a} 0 0 0\nVERTEX_SE2 {b} 1 0 0\nVERTEX_SE2 7 2 0 0\nEDGE_SE2 {a} {b} 1 0 0 1 0 0 1 0 1\n"
        );
        let AnyGraph::Se2(g) = parse_g2o(&text, Path::new("m.g2o")).unwrap() else {
            panic!("2D")
        };
        assert_eq!((g.robot(0), g.robot(1), g.robot(2)), (b'a', b'b', 0));
        let split = g.trajectories();
        assert_eq!(
            split.iter().map(|(r, t)| (*r, t.len())).collect::<Vec<_>>(),
            vec![(0, 1), (b'a', 1), (b'b', 1)]
        );
        assert_eq!(split[2].1[0].0 & 0xff, 3);
    }

    #[test]
    fn round_trip_and_errors() {
        let g = read_g2o(data("tinyGrid3D.g2o")).unwrap();
        let text = format_g2o(&g);
        let back = parse_g2o(&text, Path::new("x.g2o")).unwrap();
        assert!((se_sync_objective(&g) - se_sync_objective(&back)).abs() < 1e-9);
        let bad = |t: &str| parse_g2o(t, Path::new("bad.g2o")).unwrap_err().to_string();
        assert!(bad("VERTEX_SE2 0 1 2\n").contains("bad.g2o:1: VERTEX_SE2 needs 4 fields"));
        assert!(bad("VERTEX_XYZ 0 1 2\n").contains("unknown tag"));
        assert!(bad("VERTEX_SE2 0 0 0 nan\n").contains("not a finite number"));
        assert!(
            bad("VERTEX_SE2 0 0 0 0\nEDGE_SE2 0 5 1 0 0 1 0 0 1 0 1\n").contains("not in the file")
        );
        assert!(bad("").contains("no vertices"));
    }
}
