//! A drone's path for displays, shared by every snapshot without copying it: points are kept in
//! frozen chunks that snapshots share, and only the short open tail is copied when a snapshot
//! takes the trail. A snapshot per control tick of an hour-long flight then costs the same as
//! one of its first minute.

use std::sync::Arc;

/// Points per frozen chunk.
const CHUNK: usize = 256;

/// Where a drone has been (x, y in the map), oldest first; cheap to clone.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Trail {
    chunks: Vec<Arc<[[f64; 2]]>>,
    tail: Vec<[f64; 2]>,
}

impl Trail {
    /// A trail of these points.
    pub fn from_points(points: impl IntoIterator<Item = [f64; 2]>) -> Self {
        let mut trail = Self::default();
        for p in points {
            trail.push(p);
        }
        trail
    }

    /// Adds a point at the end.
    pub fn push(&mut self, point: [f64; 2]) {
        self.tail.push(point);
        if self.tail.len() == CHUNK {
            self.chunks.push(std::mem::take(&mut self.tail).into());
        }
    }

    /// The newest point.
    pub fn last(&self) -> Option<[f64; 2]> {
        self.tail
            .last()
            .or_else(|| self.chunks.last().and_then(|c| c.last()))
            .copied()
    }

    /// How many points it holds.
    pub fn len(&self) -> usize {
        self.chunks.len() * CHUNK + self.tail.len()
    }

    /// Whether it holds no point.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Every point, oldest first.
    pub fn iter(&self) -> impl Iterator<Item = [f64; 2]> + '_ {
        self.chunks
            .iter()
            .flat_map(|c| c.iter())
            .chain(&self.tail)
            .copied()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn points_come_back_in_order_across_chunks() {
        let points: Vec<[f64; 2]> = (0..CHUNK * 2 + 7)
            .map(|i| [i as f64, -(i as f64)])
            .collect();
        let trail = Trail::from_points(points.iter().copied());
        assert_eq!(trail.len(), points.len());
        assert_eq!(trail.iter().collect::<Vec<_>>(), points);
        assert_eq!(trail.last(), points.last().copied());
        assert!(Trail::default().is_empty());
        assert_eq!(Trail::default().last(), None);
        // The last point of a full chunk, with an empty tail.
        let full = Trail::from_points(points[..CHUNK].iter().copied());
        assert_eq!(full.last(), Some(points[CHUNK - 1]));
    }

    #[test]
    fn a_clone_shares_the_frozen_chunks_and_does_not_see_later_points() {
        let mut trail = Trail::from_points((0..CHUNK * 3).map(|i| [i as f64, 0.0]));
        let snapshot = trail.clone();
        assert!(Arc::ptr_eq(&trail.chunks[2], &snapshot.chunks[2]));
        trail.push([-1.0, -1.0]);
        assert_eq!(snapshot.len(), CHUNK * 3);
        assert_eq!(trail.len(), CHUNK * 3 + 1);
        assert_eq!(trail.last(), Some([-1.0, -1.0]));
    }
}
