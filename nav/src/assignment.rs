//! Assigning robots to frontiers: the Hungarian algorithm (exact, O(n²·m), in its shortest
//! augmenting path form) and the greedy nearest-pair baseline.

/// Minimum-cost assignment of rows (robots) to columns (frontiers): each row gets at most one
/// column, each column at most one row, as many pairs as the smaller side, least total cost.
/// Entries should be finite (a row of infinities gets nothing). Returns, per row, its column.
pub fn hungarian(cost: &[Vec<f64>]) -> Vec<Option<usize>> {
    let rows = cost.len();
    let cols = cost.first().map_or(0, Vec::len);
    if rows == 0 || cols == 0 {
        return vec![None; rows];
    }
    if rows > cols {
        // Solve the transpose: columns choose rows.
        let t: Vec<Vec<f64>> = (0..cols)
            .map(|c| (0..rows).map(|r| cost[r][c]).collect())
            .collect();
        let by_col = hungarian(&t);
        let mut out = vec![None; rows];
        for (c, r) in by_col.into_iter().enumerate() {
            if let Some(r) = r {
                out[r] = Some(c);
            }
        }
        return out;
    }
    let flat: Vec<f64> = cost.iter().flat_map(|r| r.iter().copied()).collect();
    solve(rows, cols, &flat)
}

/// Shortest augmenting paths with dual potentials (Crouse 2016, the method SciPy's
/// `linear_sum_assignment` uses) on a flat row-major matrix with `rows ≤ cols`. Each row's search
/// only visits the columns not yet in its tree, so the inner loops shrink as it goes.
fn solve(rows: usize, cols: usize, cost: &[f64]) -> Vec<Option<usize>> {
    const NONE: usize = usize::MAX;
    let mut u = vec![0.0f64; rows];
    let mut v = vec![0.0f64; cols];
    let mut shortest = vec![f64::INFINITY; cols];
    let mut path = vec![NONE; cols];
    let mut col4row = vec![NONE; rows];
    let mut row4col = vec![NONE; cols];
    let mut in_rows = vec![false; rows];
    let mut in_cols = vec![false; cols];
    let mut remaining: Vec<usize> = Vec::with_capacity(cols);
    for cur_row in 0..rows {
        // Dijkstra-like search for the cheapest augmenting path from `cur_row`.
        remaining.clear();
        remaining.extend((0..cols).rev());
        in_rows.fill(false);
        in_cols.fill(false);
        shortest.fill(f64::INFINITY);
        let mut min_val = 0.0;
        let mut i = cur_row;
        let sink = loop {
            in_rows[i] = true;
            let row = &cost[i * cols..(i + 1) * cols];
            let ui = u[i];
            let mut lowest = f64::INFINITY;
            let mut index = NONE;
            for (it, &j) in remaining.iter().enumerate() {
                let r = min_val + row[j] - ui - v[j];
                if r < shortest[j] {
                    path[j] = i;
                    shortest[j] = r;
                }
                if shortest[j] < lowest || (shortest[j] == lowest && row4col[j] == NONE) {
                    lowest = shortest[j];
                    index = it;
                }
            }
            if index == NONE {
                // Only with non-finite costs: no augmenting path exists.
                return col4row
                    .into_iter()
                    .map(|c| (c != NONE).then_some(c))
                    .collect();
            }
            min_val = lowest;
            let j = remaining.swap_remove(index);
            in_cols[j] = true;
            if row4col[j] == NONE {
                break j;
            }
            i = row4col[j];
        };
        // Update the potentials.
        u[cur_row] += min_val;
        for r in 0..rows {
            if in_rows[r] && r != cur_row {
                u[r] += min_val - shortest[col4row[r]];
            }
        }
        for c in 0..cols {
            if in_cols[c] {
                v[c] -= min_val - shortest[c];
            }
        }
        // Augment along the path.
        let mut j = sink;
        loop {
            let r = path[j];
            row4col[j] = r;
            std::mem::swap(&mut col4row[r], &mut j);
            if r == cur_row {
                break;
            }
        }
    }
    col4row
        .into_iter()
        .map(|c| (c != NONE).then_some(c))
        .collect()
}

/// The greedy baseline: repeatedly give the cheapest remaining (robot, frontier) pair.
pub fn greedy(cost: &[Vec<f64>]) -> Vec<Option<usize>> {
    let mut pairs: Vec<(f64, usize, usize)> = cost
        .iter()
        .enumerate()
        .flat_map(|(r, row)| row.iter().enumerate().map(move |(c, &x)| (x, r, c)))
        .collect();
    pairs.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut out = vec![None; cost.len()];
    let mut taken = vec![false; cost.first().map_or(0, Vec::len)];
    for (_, r, c) in pairs {
        if out[r].is_none() && !taken[c] {
            out[r] = Some(c);
            taken[c] = true;
        }
    }
    out
}

/// Robots to frontiers spread over regions (`region[f]` is frontier f's, e.g. from
/// [`crate::frontier::regions`]), each round solved by `solve` ([`hungarian`] or [`greedy`]):
/// first every robot to a region of its own (its cost to a region: to the region's cheapest
/// frontier, which is the one it gets), least total cost — so two robots do not head for two
/// pieces of one room's frontier while another room waits; then robots left over, when there are
/// more robots than regions, to the frontiers no robot has yet. A robot may still be left
/// without a frontier when there are more robots than frontiers. With every frontier a region of
/// its own this is `solve(cost)`.
pub fn spread(
    cost: &[Vec<f64>],
    region: &[usize],
    solve: fn(&[Vec<f64>]) -> Vec<Option<usize>>,
) -> Vec<Option<usize>> {
    let regions = region.iter().map(|&g| g + 1).max().unwrap_or(0);
    // Per robot and region: its cheapest frontier there.
    let best: Vec<Vec<Option<usize>>> = cost
        .iter()
        .map(|row| {
            let mut best: Vec<Option<usize>> = vec![None; regions];
            for (f, (&c, &g)) in row.iter().zip(region).enumerate() {
                if best[g].is_none_or(|b| c < row[b]) {
                    best[g] = Some(f);
                }
            }
            best
        })
        .collect();
    let by_region: Vec<Vec<f64>> = best
        .iter()
        .zip(cost)
        .map(|(b, row)| {
            b.iter()
                .map(|f| f.map_or(f64::INFINITY, |f| row[f]))
                .collect()
        })
        .collect();
    let mut out: Vec<Option<usize>> = solve(&by_region)
        .into_iter()
        .zip(&best)
        .map(|(g, b)| g.and_then(|g| b[g]))
        .collect();
    let mut taken = vec![false; region.len()];
    out.iter().flatten().for_each(|&f| taken[f] = true);
    let idle: Vec<usize> = (0..cost.len()).filter(|&r| out[r].is_none()).collect();
    let free: Vec<usize> = (0..region.len()).filter(|&f| !taken[f]).collect();
    if !idle.is_empty() && !free.is_empty() {
        let rest: Vec<Vec<f64>> = idle
            .iter()
            .map(|&r| free.iter().map(|&f| cost[r][f]).collect())
            .collect();
        for (&r, f) in idle.iter().zip(solve(&rest)) {
            out[r] = f.map(|f| free[f]);
        }
    }
    out
}

/// Total cost of an assignment.
pub fn total(cost: &[Vec<f64>], assignment: &[Option<usize>]) -> f64 {
    assignment
        .iter()
        .enumerate()
        .filter_map(|(r, c)| c.map(|c| cost[r][c]))
        .sum()
}

/// Pads a matrix to square with `fill` (dummy frontiers or dummy robots).
pub fn pad_square(cost: &[Vec<f64>], fill: f64) -> Vec<Vec<f64>> {
    let rows = cost.len();
    let cols = cost.first().map_or(0, Vec::len);
    let n = rows.max(cols);
    (0..n)
        .map(|r| {
            (0..n)
                .map(|c| {
                    if r < rows && c < cols {
                        cost[r][c]
                    } else {
                        fill
                    }
                })
                .collect()
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn brute_force(cost: &[Vec<f64>]) -> f64 {
        let rows = cost.len();
        let cols = cost[0].len();
        let k = rows.min(cols);
        let mut best = f64::INFINITY;
        // Every injective map from the smaller side to the larger.
        fn rec(
            cost: &[Vec<f64>],
            r: usize,
            used: &mut Vec<bool>,
            acc: f64,
            best: &mut f64,
            transpose: bool,
            k: usize,
        ) {
            if r == k {
                *best = best.min(acc);
                return;
            }
            for c in 0..used.len() {
                if !used[c] {
                    used[c] = true;
                    let x = if transpose { cost[c][r] } else { cost[r][c] };
                    rec(cost, r + 1, used, acc + x, best, transpose, k);
                    used[c] = false;
                }
            }
        }
        let transpose = rows > cols;
        let mut used = vec![false; rows.max(cols)];
        rec(cost, 0, &mut used, 0.0, &mut best, transpose, k);
        best
    }

    #[test]
    fn classic_example() {
        let c = vec![
            vec![4.0, 1.0, 3.0],
            vec![2.0, 0.0, 5.0],
            vec![3.0, 2.0, 2.0],
        ];
        let a = hungarian(&c);
        assert_eq!(total(&c, &a), 5.0);
        // Greedy takes the 0 first and pays for it.
        assert_eq!(total(&c, &greedy(&c)), 6.0);
    }

    #[test]
    fn robots_spread_over_regions_before_a_region_gets_a_second() {
        // Frontiers 0 and 1 are two pieces of one room's frontier, near both robots; frontier 2
        // is another room, further. By least total cost both robots take the near room.
        let c = vec![vec![1.0, 2.0, 6.0], vec![2.0, 1.0, 5.0]];
        assert_eq!(hungarian(&c), vec![Some(0), Some(1)]);
        let region = [0, 0, 1];
        for solve in [hungarian, greedy] {
            let a = spread(&c, &region, solve);
            // One to each room: robot 0 to the near room (1 + 5 = 6 beats 2 + 6 = 8).
            assert_eq!(a, vec![Some(0), Some(2)]);
        }
        // A third robot, with no region left, takes the frontier no robot has.
        let c3 = vec![c[0].clone(), c[1].clone(), vec![1.5, 1.6, 9.0]];
        assert_eq!(
            spread(&c3, &region, hungarian),
            vec![Some(0), Some(2), Some(1)]
        );
        // More robots than frontiers: the last hovers.
        let c4 = vec![
            c3[0].clone(),
            c3[1].clone(),
            c3[2].clone(),
            vec![9.0, 9.0, 9.0],
        ];
        assert_eq!(spread(&c4, &region, hungarian)[3], None);
    }

    #[test]
    fn padding_makes_square() {
        let p = pad_square(&[vec![1.0, 2.0, 3.0]], 0.0);
        assert_eq!(p.len(), 3);
        assert!(p.iter().all(|r| r.len() == 3));
        assert_eq!(p[2], vec![0.0, 0.0, 0.0]);
    }

    proptest! {
        #[test]
        fn hungarian_equals_brute_force(
            rows in 1usize..=6, cols in 1usize..=6,
            values in proptest::collection::vec(0u32..1000, 36),
        ) {
            let cost: Vec<Vec<f64>> = (0..rows).map(|r| (0..cols).map(|c| f64::from(values[r * 6 + c]) / 10.0).collect()).collect();
            let a = hungarian(&cost);
            // A valid assignment of min(rows, cols) pairs, no column twice.
            let mut seen = std::collections::HashSet::new();
            prop_assert_eq!(a.iter().flatten().count(), rows.min(cols));
            for c in a.iter().flatten() {
                prop_assert!(seen.insert(*c));
            }
            prop_assert!((total(&cost, &a) - brute_force(&cost)).abs() < 1e-9);
            prop_assert!(total(&cost, &greedy(&cost)) >= total(&cost, &a) - 1e-9);
            // Padding to square with zero-cost dummies (the thesis's way) reaches the same optimum.
            let square = pad_square(&cost, 0.0);
            prop_assert!((total(&square, &hungarian(&square)) - total(&cost, &a)).abs() < 1e-9);
        }

        #[test]
        fn spreading_gives_every_robot_its_own_frontier_and_each_region_one_first(
            rows in 1usize..=6, cols in 1usize..=6,
            values in proptest::collection::vec(0u32..1000, 36),
            labels in proptest::collection::vec(0usize..3, 6),
        ) {
            let cost: Vec<Vec<f64>> = (0..rows).map(|r| (0..cols).map(|c| f64::from(values[r * 6 + c]) / 10.0).collect()).collect();
            // Region ids 0..k, each used.
            let mut ids = std::collections::BTreeMap::new();
            let region: Vec<usize> = labels[..cols].iter().map(|l| { let n = ids.len(); *ids.entry(*l).or_insert(n) }).collect();
            let regions = ids.len();
            let a = spread(&cost, &region, hungarian);
            prop_assert_eq!(a.iter().flatten().count(), rows.min(cols));
            let mut seen = std::collections::HashSet::new();
            for c in a.iter().flatten() {
                prop_assert!(seen.insert(*c));
            }
            // Every region has a robot before any has two.
            let mut per_region = vec![0; regions];
            a.iter().flatten().for_each(|&f| per_region[region[f]] += 1);
            if per_region.iter().any(|&n| n > 1) {
                prop_assert!(per_region.iter().all(|&n| n >= 1), "{:?}", per_region);
            }
            // Each frontier a region of its own: the plain least-cost assignment.
            let own: Vec<usize> = (0..cols).collect();
            prop_assert!((total(&cost, &spread(&cost, &own, hungarian)) - total(&cost, &hungarian(&cost))).abs() < 1e-9);
        }
    }
}
