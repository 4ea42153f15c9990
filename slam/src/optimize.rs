//! Levenberg–Marquardt (and Gauss–Newton) on pose graphs, with faer's sparse Cholesky. The
//! sparsity pattern of the normal equations is fixed by the graph's edges, so it is analysed once
//! (symbolic factorisation) and only refilled with numbers each iteration.

use std::time::Instant;

use faer::Side;
use faer::linalg::solvers::Solve;
use faer::sparse::linalg::solvers::{Llt, SymbolicLlt};
use faer::sparse::{Pair, SparseColMat, SymbolicSparseColMat};

use crate::posegraph::{Edge, Graph, Pose, quad};

/// A robust kernel ρ applied to each edge's squared error s = eᵀΩe.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Kernel {
    /// ρ(s) = s: plain least squares.
    None,
    /// Quadratic up to δ², linear beyond: ρ(s) = 2δ√s − δ².
    Huber(f64),
    /// ρ(s) = c² ln(1 + s/c²): large errors count almost nothing.
    Cauchy(f64),
}

impl Kernel {
    /// ρ(s).
    pub fn cost(self, s: f64) -> f64 {
        match self {
            Kernel::None => s,
            Kernel::Huber(d) if s > d * d => 2.0 * d * s.sqrt() - d * d,
            Kernel::Huber(_) => s,
            Kernel::Cauchy(c) => c * c * (s / (c * c)).ln_1p(),
        }
    }

    /// ρ'(s): the weight of the edge in the reweighted normal equations.
    pub fn weight(self, s: f64) -> f64 {
        match self {
            Kernel::None => 1.0,
            Kernel::Huber(d) if s > d * d => d / s.sqrt(),
            Kernel::Huber(_) => 1.0,
            Kernel::Cauchy(c) => 1.0 / (1.0 + s / (c * c)),
        }
    }
}

/// Optimiser settings.
#[derive(Debug, Clone)]
pub struct Options {
    /// Robust kernel on every edge.
    pub kernel: Kernel,
    /// After converging, switch off loop closures (edges other than `i → i + 1`) whose χ² is
    /// above this, and optimise again without them.
    pub outlier_chi2: Option<f64>,
    /// Gauss–Newton (no damping) instead of Levenberg–Marquardt.
    pub gauss_newton: bool,
    /// At most this many iterations.
    pub max_iterations: usize,
    /// Stop when an iteration lowers the cost by less than this fraction.
    pub relative_tolerance: f64,
}

impl Default for Options {
    fn default() -> Self {
        Self {
            kernel: Kernel::None,
            outlier_chi2: None,
            gauss_newton: false,
            max_iterations: 100,
            relative_tolerance: 1e-9,
        }
    }
}

/// What an optimisation did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Report {
    /// Cost before: Σ ρ(eᵀΩe) (χ² without a kernel).
    pub initial_cost: f64,
    /// Cost after.
    pub final_cost: f64,
    /// Loop closures switched off by the outlier guard.
    pub rejected_edges: usize,
    /// Iterations accepted.
    pub iterations: usize,
    /// Wall time, seconds.
    pub time_s: f64,
}

/// Why an optimisation could not run.
#[derive(Debug, thiserror::Error)]
pub enum OptimizeError {
    /// The linear algebra failed (a disconnected graph, or memory).
    #[error("the normal equations could not be factorised: {0} (is the graph connected?)")]
    Factorization(String),
}

/// The fixed structure of one graph's normal equations.
struct Pattern {
    n: usize,
    symbolic: SymbolicSparseColMat<usize>,
    argsort: faer::sparse::Argsort<usize>,
    llt: SymbolicLlt<usize>,
}

/// Vertex 0 is the anchor (fixed); vertex k ≥ 1 is variable k − 1.
fn var(k: usize) -> Option<usize> {
    k.checked_sub(1)
}

/// Lower-triangle entries, in the order `fill` writes values: the diagonal blocks, then one block
/// per edge between two variables.
fn entries<P: Pose>(g: &Graph<P>) -> Vec<Pair<usize, usize>> {
    let d = P::DOF;
    let mut out = Vec::new();
    for v in 0..g.poses.len().saturating_sub(1) {
        for r in 0..d {
            for c in 0..=r {
                out.push(Pair::new(v * d + r, v * d + c));
            }
        }
    }
    for e in &g.edges {
        if let (Some(a), Some(b)) = (var(e.i), var(e.j)) {
            let (hi, lo) = if a > b { (a, b) } else { (b, a) };
            for r in 0..d {
                for c in 0..d {
                    out.push(Pair::new(hi * d + r, lo * d + c));
                }
            }
        }
    }
    out
}

impl Pattern {
    fn new<P: Pose>(g: &Graph<P>) -> Result<Self, OptimizeError> {
        let n = g.poses.len().saturating_sub(1) * P::DOF;
        let (symbolic, argsort) = SymbolicSparseColMat::try_new_from_indices(n, n, &entries(g))
            .map_err(|e| OptimizeError::Factorization(format!("{e:?}")))?;
        let llt = SymbolicLlt::try_new(symbolic.as_ref(), Side::Lower)
            .map_err(|e| OptimizeError::Factorization(format!("{e:?}")))?;
        Ok(Self {
            n,
            symbolic,
            argsort,
            llt,
        })
    }
}

/// The linearised system at the current estimate: H blocks (in `entries` order) and the gradient.
struct Linear {
    diag: Vec<f64>,
    off: Vec<f64>,
    b: Vec<f64>,
}

/// The linear system at the current estimate, with the edges shared out over the cores.
fn linearize<P: Pose>(g: &Graph<P>, kernel: Kernel) -> Linear {
    let threads = std::thread::available_parallelism()
        .map_or(1, |n| n.get())
        .clamp(1, 8);
    let chunk = g.edges.len().div_ceil(threads).max(1);
    let parts: Vec<Linear> = std::thread::scope(|scope| {
        let handles: Vec<_> = g
            .edges
            .chunks(chunk)
            .map(|edges| scope.spawn(move || linearize_edges(g, edges, kernel)))
            .collect();
        handles
            .into_iter()
            .map(|h| h.join().unwrap_or_else(|e| std::panic::resume_unwind(e)))
            .collect()
    });
    let mut parts = parts.into_iter();
    let Some(mut total) = parts.next() else {
        return linearize_edges(g, &[], kernel);
    };
    for part in parts {
        total
            .diag
            .iter_mut()
            .zip(&part.diag)
            .for_each(|(a, b)| *a += b);
        total.b.iter_mut().zip(&part.b).for_each(|(a, b)| *a += b);
        // Off-diagonal blocks stay in edge order, as `entries` laid them out.
        total.off.extend_from_slice(&part.off);
    }
    total
}

fn linearize_edges<P: Pose>(g: &Graph<P>, edges: &[Edge<P>], kernel: Kernel) -> Linear {
    let d = P::DOF;
    let nv = g.poses.len().saturating_sub(1);
    let mut diag = vec![0.0; nv * d * d];
    let mut off = Vec::new();
    let mut b = vec![0.0; nv * d];
    let mut e0 = vec![0.0; d];
    let (mut ji, mut jj) = (vec![0.0; d * d], vec![0.0; d * d]);
    let mut jac = vec![0.0; d * 2 * d]; // d rows × 2d columns (row-major)
    for edge in edges {
        let (xi, xj) = (&g.poses[edge.i], &g.poses[edge.j]);
        P::error(xi, xj, &edge.z, &mut e0);
        let weight = kernel.weight(quad(&edge.info, &e0, d));
        P::jacobians(xi, xj, &edge.z, &e0, &mut ji, &mut jj);
        for r in 0..d {
            jac[r * 2 * d..r * 2 * d + d].copy_from_slice(&ji[r * d..(r + 1) * d]);
            jac[r * 2 * d + d..(r + 1) * 2 * d].copy_from_slice(&jj[r * d..(r + 1) * d]);
        }
        // JᵀΩ (2d × d), then JᵀΩJ and JᵀΩe.
        let mut jt_omega = vec![0.0; 2 * d * d];
        for a in 0..2 * d {
            for c in 0..d {
                let mut s = 0.0;
                for r in 0..d {
                    s += jac[r * 2 * d + a] * edge.info[r * d + c];
                }
                jt_omega[a * d + c] = weight * s;
            }
        }
        let block = |a: usize, bcol: usize| -> f64 {
            let mut s = 0.0;
            for r in 0..d {
                s += jt_omega[a * d + r] * jac[r * 2 * d + bcol];
            }
            s
        };
        let vars = [var(edge.i), var(edge.j)];
        for (side, v) in vars.iter().enumerate() {
            let Some(v) = v else { continue };
            for r in 0..d {
                let mut g_r = 0.0;
                for c in 0..d {
                    g_r += jt_omega[(side * d + r) * d + c] * e0[c];
                }
                b[v * d + r] += g_r;
                for c in 0..d {
                    diag[v * d * d + r * d + c] += block(side * d + r, side * d + c);
                }
            }
        }
        if let [Some(a), Some(bv)] = vars {
            // The block at (max, min) of the two variables.
            let (hi_side, lo_side) = if a > bv { (0, 1) } else { (1, 0) };
            for r in 0..d {
                for c in 0..d {
                    off.push(block(hi_side * d + r, lo_side * d + c));
                }
            }
        }
    }
    Linear { diag, off, b }
}

/// Solves (H + λ·diag(H)) δ = −b on the fixed pattern.
fn solve(p: &Pattern, lin: &Linear, d: usize, lambda: f64) -> Result<Vec<f64>, OptimizeError> {
    let nv = p.n / d.max(1);
    let mut values = Vec::with_capacity(nv * d * (d + 1) / 2 + lin.off.len());
    for v in 0..nv {
        for r in 0..d {
            for c in 0..=r {
                let mut x = lin.diag[v * d * d + r * d + c];
                if r == c {
                    x += lambda * x.max(1e-9);
                }
                values.push(x);
            }
        }
    }
    values.extend_from_slice(&lin.off);
    let mat = SparseColMat::new_from_argsort(p.symbolic.clone(), &p.argsort, &values)
        .map_err(|e| OptimizeError::Factorization(format!("{e:?}")))?;
    let llt = Llt::try_new_with_symbolic(p.llt.clone(), mat.as_ref(), Side::Lower)
        .map_err(|e| OptimizeError::Factorization(format!("{e:?}")))?;
    let mut rhs = faer::Mat::<f64>::from_fn(p.n, 1, |r, _| -lin.b[r]);
    llt.solve_in_place(rhs.as_mut());
    Ok((0..p.n).map(|r| rhs[(r, 0)]).collect())
}

/// Σ ρ(eᵀΩe) over the edges at `poses`.
fn cost<P: Pose>(poses: &[P], edges: &[Edge<P>], kernel: Kernel) -> f64 {
    let d = P::DOF;
    let mut e = vec![0.0; d];
    edges
        .iter()
        .map(|edge| {
            P::error(&poses[edge.i], &poses[edge.j], &edge.z, &mut e);
            kernel.cost(quad(&edge.info, &e, d))
        })
        .sum()
}

fn apply<P: Pose>(poses: &[P], delta: &[f64]) -> Vec<P> {
    let d = P::DOF;
    poses
        .iter()
        .enumerate()
        .map(|(k, x)| match var(k) {
            Some(v) => x.retract(&delta[v * d..(v + 1) * d]),
            None => x.clone(),
        })
        .collect()
}

/// Optimises the graph in place (vertex 0 fixed). With an outlier guard, loop closures that still
/// disagree after convergence are removed from `g.edges` and the graph is optimised again.
pub fn optimize<P: Pose>(g: &mut Graph<P>, options: &Options) -> Result<Report, OptimizeError> {
    let start = Instant::now();
    let mut report = run_lm(g, options)?;
    if let Some(limit) = options.outlier_chi2 {
        let d = P::DOF;
        let mut e = vec![0.0; d];
        let before = g.edges.len();
        let poses = &g.poses;
        g.edges.retain(|edge| {
            P::error(&poses[edge.i], &poses[edge.j], &edge.z, &mut e);
            edge.j == edge.i + 1 || quad(&edge.info, &e, d) <= limit
        });
        let rejected = before - g.edges.len();
        if rejected > 0 {
            let again = run_lm(g, options)?;
            report = Report {
                final_cost: again.final_cost,
                iterations: report.iterations + again.iterations,
                rejected_edges: rejected,
                ..report
            };
        }
    }
    report.time_s = start.elapsed().as_secs_f64();
    Ok(report)
}

fn run_lm<P: Pose>(g: &mut Graph<P>, options: &Options) -> Result<Report, OptimizeError> {
    let start = Instant::now();
    let kernel = options.kernel;
    let initial_cost = cost(&g.poses, &g.edges, kernel);
    if g.poses.len() < 2 || g.edges.is_empty() {
        return Ok(Report {
            initial_cost,
            final_cost: initial_cost,
            rejected_edges: 0,
            iterations: 0,
            time_s: 0.0,
        });
    }
    let pattern = Pattern::new(g)?;
    let d = P::DOF;
    let mut current = initial_cost;
    // Levenberg–Marquardt that tries the undamped (Gauss–Newton) step first and damps only when
    // a step fails: near the minimum any lasting damping slows weakly determined directions to
    // linear convergence (parking-garage: 22 iterations damped, 5 undamped).
    let mut lambda = 0.0;
    let mut iterations = 0;
    'outer: while iterations < options.max_iterations {
        let lin = linearize(g, kernel);
        loop {
            let step = match solve(&pattern, &lin, d, lambda) {
                Ok(s) if s.iter().all(|x| x.is_finite()) => s,
                Ok(_) | Err(_) if !options.gauss_newton && lambda < 1e8 => {
                    lambda = (lambda * 10.0).max(1e-6);
                    continue;
                }
                Ok(_) => {
                    return Err(OptimizeError::Factorization(
                        "the step is not finite".into(),
                    ));
                }
                Err(e) => return Err(e),
            };
            let trial = apply(&g.poses, &step);
            let new_cost = cost(&trial, &g.edges, kernel);
            if new_cost < current || options.gauss_newton {
                g.poses = trial;
                let improvement = (current - new_cost) / current.max(f64::MIN_POSITIVE);
                current = new_cost;
                iterations += 1;
                lambda = if lambda < 1e-7 { 0.0 } else { lambda / 10.0 };
                if improvement.abs() < options.relative_tolerance {
                    break 'outer;
                }
                break;
            }
            lambda = if lambda == 0.0 { 1e-5 } else { lambda * 10.0 };
            if lambda > 1e8 {
                break 'outer; // no step lowers the cost: a minimum
            }
        }
    }
    Ok(Report {
        initial_cost,
        final_cost: current,
        rejected_edges: 0,
        iterations,
        time_s: start.elapsed().as_secs_f64(),
    })
}

/// Solves the linear least-squares problem `min ‖A x − b‖²` given as rows of
/// `(&[(column, coefficient)], rhs)`, through its normal equations and a sparse Cholesky.
fn least_squares(n: usize, rows: &[(Vec<(usize, f64)>, f64)]) -> Result<Vec<f64>, OptimizeError> {
    let fail = |e: String| OptimizeError::Factorization(e);
    let mut triplets = Vec::new();
    let mut atb = vec![0.0; n];
    for (coefs, rhs) in rows {
        for &(a, ca) in coefs {
            atb[a] += ca * rhs;
            for &(b, cb) in coefs {
                if a >= b {
                    triplets.push(faer::sparse::Triplet::new(a, b, ca * cb));
                }
            }
        }
    }
    let ata = SparseColMat::<usize, f64>::try_new_from_triplets(n, n, &triplets)
        .map_err(|e| fail(format!("{e:?}")))?;
    let symbolic =
        SymbolicLlt::try_new(ata.symbolic(), Side::Lower).map_err(|e| fail(format!("{e:?}")))?;
    let llt = Llt::try_new_with_symbolic(symbolic, ata.as_ref(), Side::Lower)
        .map_err(|e| fail(format!("{e:?}")))?;
    let mut rhs = faer::Mat::<f64>::from_fn(n, 1, |r, _| atb[r]);
    llt.solve_in_place(rhs.as_mut());
    Ok((0..n).map(|r| rhs[(r, 0)]).collect())
}

/// Chordal initialisation (Carlone et al. 2015): relax `R_j = R_i R̃_ij` to a linear problem in the
/// rotation matrices' entries, project each onto SO(3), then solve the translations with the
/// rotations fixed. Vertex 0 keeps its pose. Far better than chained odometry on graphs like torus3D.
pub fn chordal_init(g: &mut Graph<nalgebra::Isometry3<f64>>) -> Result<(), OptimizeError> {
    use nalgebra::{Matrix3, Rotation3, Translation3, UnitQuaternion, Vector3};
    let n = g.poses.len();
    if n < 2 {
        return Ok(());
    }
    let r0 = *g.poses[0].rotation.to_rotation_matrix().matrix();
    let t0 = g.poses[0].translation.vector;
    // Rotations: unknown entries of R_v (v ≥ 1), row-major, 9 per vertex.
    let rot = |v: usize, r: usize, c: usize| (v - 1) * 9 + r * 3 + c;
    let mut rows = Vec::with_capacity(g.edges.len() * 9);
    for e in &g.edges {
        let rz = *e.z.rotation.to_rotation_matrix().matrix();
        for r in 0..3 {
            for c in 0..3 {
                // R_j[r,c] − Σ_k R_i[r,k] R̃[k,c] = 0
                let mut coefs = Vec::with_capacity(4);
                let mut rhs = 0.0;
                if e.j == 0 {
                    rhs -= r0[(r, c)];
                } else {
                    coefs.push((rot(e.j, r, c), 1.0));
                }
                for k in 0..3 {
                    if e.i == 0 {
                        rhs += r0[(r, k)] * rz[(k, c)];
                    } else {
                        coefs.push((rot(e.i, r, k), -rz[(k, c)]));
                    }
                }
                rows.push((coefs, rhs));
            }
        }
    }
    let x = least_squares((n - 1) * 9, &rows)?;
    let mut rotations = vec![r0];
    for v in 1..n {
        let m = Matrix3::from_fn(|r, c| x[rot(v, r, c)]);
        let svd = m.svd(true, true);
        let (Some(u), Some(vt)) = (svd.u, svd.v_t) else {
            return Err(OptimizeError::Factorization(
                "a rotation could not be projected".into(),
            ));
        };
        let mut s = Matrix3::identity();
        if (u * vt).determinant() < 0.0 {
            s[(2, 2)] = -1.0;
        }
        rotations.push(u * s * vt);
    }
    // Translations: t_j − t_i = R_i t̃_ij.
    let tr = |v: usize, a: usize| (v - 1) * 3 + a;
    let mut rows = Vec::with_capacity(g.edges.len() * 3);
    for e in &g.edges {
        let rhs_v: Vector3<f64> = rotations[e.i] * e.z.translation.vector;
        for a in 0..3 {
            let mut coefs = Vec::with_capacity(2);
            let mut rhs = rhs_v[a];
            if e.j == 0 {
                rhs -= t0[a];
            } else {
                coefs.push((tr(e.j, a), 1.0));
            }
            if e.i == 0 {
                rhs += t0[a];
            } else {
                coefs.push((tr(e.i, a), -1.0));
            }
            rows.push((coefs, rhs));
        }
    }
    let t = least_squares((n - 1) * 3, &rows)?;
    for v in 1..n {
        let r =
            UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(rotations[v]));
        g.poses[v] = nalgebra::Isometry3::from_parts(
            Translation3::new(t[tr(v, 0)], t[tr(v, 1)], t[tr(v, 2)]),
            r,
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::posegraph::tests::data;
    use crate::posegraph::{AnyGraph, chi2, read_g2o, se_sync_objective};

    fn run(file: &str) -> (f64, Report) {
        let mut g = read_g2o(data(file)).unwrap();
        let report = match &mut g {
            AnyGraph::Se2(g) => optimize(g, &Options::default()).unwrap(),
            AnyGraph::Se3(g) => optimize(g, &Options::default()).unwrap(),
        };
        (se_sync_objective(&g), report)
    }

    #[test]
    fn tiny_grid_returns_to_its_minimum_and_gn_agrees() {
        let AnyGraph::Se3(mut g) = read_g2o(data("tinyGrid3D.g2o")).unwrap() else {
            panic!("3D")
        };
        let mut gn = g.clone();
        let r = optimize(&mut g, &Options::default()).unwrap();
        assert!(r.final_cost < r.initial_cost / 10.0, "{r:?}");
        let r_gn = optimize(
            &mut gn,
            &Options {
                gauss_newton: true,
                ..Options::default()
            },
        )
        .unwrap();
        assert!(
            (r_gn.final_cost - r.final_cost).abs() < 1e-6 * r.final_cost,
            "{r_gn:?} vs {r:?}"
        );
        // Knock every pose off the minimum: the optimiser brings it back.
        for (k, p) in g.poses.iter_mut().enumerate().skip(1) {
            let s = 0.05 * ((k * 7 % 5) as f64 - 2.0);
            *p = p.retract(&[s, -s, s, 0.5 * s, -0.5 * s, 0.5 * s]);
        }
        assert!(chi2(&g) > r.final_cost * 1.5);
        let again = optimize(&mut g, &Options::default()).unwrap();
        assert!(
            (again.final_cost - r.final_cost).abs() < 1e-6 * r.final_cost,
            "{again:?} vs {r:?}"
        );
    }

    #[test]
    fn every_shared_graph_reaches_the_published_optimum() {
        // (file, SE-Sync's F*, GTSAM's local optimum as chi² = 2 × its error, where published)
        for (file, f_star, gtsam) in [
            ("manhattan.g2o", 6.432e3, None),
            ("parking-garage.g2o", 1.263e0, Some(2.0 * 0.6342)),
            ("sphere2500.g2o", 1.687e3, Some(2.0 * 675.70)),
        ] {
            let (f, r) = run(file);
            assert!(
                f <= f_star * 1.05,
                "{file}: F = {f} vs F* = {f_star}, {r:?}"
            );
            if let Some(c) = gtsam {
                assert!(
                    r.final_cost <= c * 1.001,
                    "{file}: chi² {} vs GTSAM {c}",
                    r.final_cost
                );
            }
        }
    }

    #[test]
    fn torus_from_a_chordal_start_reaches_the_published_optimum() {
        let AnyGraph::Se3(mut g) = read_g2o(data("torus3D.g2o")).unwrap() else {
            panic!("3D")
        };
        chordal_init(&mut g).unwrap();
        let r = optimize(&mut g, &Options::default()).unwrap();
        let f = se_sync_objective(&AnyGraph::Se3(g));
        // SE-Sync's F* = 2.423e4; GTSAM from a chordal start: error 12117.6 = chi² 24235.2.
        assert!(f <= 2.423e4 * 1.05, "F = {f}, {r:?}");
        assert!(r.final_cost <= 2.0 * 12117.6 * 1.001, "{r:?}");
    }

    #[test]
    fn false_loop_closures_do_not_bend_the_map() {
        let AnyGraph::Se2(clean) = read_g2o(data("intel.g2o")).unwrap() else {
            panic!("2D")
        };
        let mut reference = clean.clone();
        optimize(&mut reference, &Options::default()).unwrap();
        // 25 confident but wrong loop closures between random far-apart poses.
        let mut corrupted = clean.clone();
        let loop_info = corrupted
            .edges
            .iter()
            .find(|e| e.j != e.i + 1)
            .map(|e| e.info.clone())
            .unwrap();
        let mut x: u64 = 42;
        let mut next = |m: usize| {
            x = x
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((x >> 33) as usize) % m
        };
        let n = corrupted.poses.len();
        for _ in 0..25 {
            let i = next(n - 200);
            let j = i + 100 + next(100);
            let z = nalgebra::Isometry2::new(nalgebra::Vector2::new(0.5, -0.3), 0.4);
            corrupted.edges.push(crate::posegraph::Edge {
                i,
                j,
                z,
                info: loop_info.clone(),
            });
        }
        let error = |g: &Graph<nalgebra::Isometry2<f64>>| {
            let sq: f64 = g
                .poses
                .iter()
                .zip(&reference.poses)
                .map(|(a, b)| (a.translation.vector - b.translation.vector).norm_squared())
                .sum();
            (sq / n as f64).sqrt()
        };
        let mut plain = corrupted.clone();
        optimize(&mut plain, &Options::default()).unwrap();
        let mut robust = corrupted.clone();
        let r = optimize(
            &mut robust,
            &Options {
                kernel: Kernel::Cauchy(1.0),
                outlier_chi2: Some(16.27),
                ..Options::default()
            },
        )
        .unwrap();
        let (e_plain, e_robust) = (error(&plain), error(&robust));
        eprintln!("false closures: plain {e_plain:.3} m, robust {e_robust:.4} m, {r:?}");
        assert!(
            e_plain > 0.5,
            "the false closures should bend a plain solution: {e_plain} m"
        );
        assert!(
            e_robust < 0.05,
            "robust solution off by {e_robust} m ({r:?})"
        );
        assert!(r.rejected_edges >= 25, "{r:?}");
    }

    #[test]
    fn kernels_shape_large_errors() {
        assert_eq!(Kernel::Huber(1.0).cost(0.25), 0.25);
        assert_eq!(Kernel::Huber(1.0).cost(4.0), 3.0);
        assert!((Kernel::Cauchy(1.0).cost(1e6) - (1e6f64).ln_1p()).abs() < 1e-9);
        assert!(Kernel::Cauchy(1.0).weight(100.0) < 0.01 && Kernel::None.weight(100.0) == 1.0);
    }

    #[test]
    fn intel_reaches_the_published_optimum() {
        let (f, r) = run("intel.g2o");
        // SE-Sync's F* = 52.35; GTSAM's local optimum: error 22.502 = chi² 45.0.
        assert!(f <= 52.35 * 1.05, "F = {f}, {r:?}");
        assert!(r.final_cost <= 45.004 * 1.001, "{r:?}");
    }
}
