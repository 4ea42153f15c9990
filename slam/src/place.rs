//! Place recognition: which earlier keyframes look like this one, without any idea of where the
//! camera is. Each binary descriptor is hashed to visual words by sampling fixed bits of it (a
//! locality-sensitive hash, so no vocabulary needs training and descriptors from every drone hash
//! alike); a keyframe is a bag of words; an inverted index scores every keyframe that shares words
//! with a query by tf-idf cosine similarity. Candidates still need geometric verification.

use std::collections::HashMap;

use crate::features::Descriptor;

/// Hash tables per descriptor.
const TABLES: usize = 3;
/// Bits per word.
const BITS: usize = 12;

/// The descriptor bits each table samples (fixed, spread over the 256 bits).
fn bit_positions() -> [[u8; BITS]; TABLES] {
    let mut out = [[0u8; BITS]; TABLES];
    let mut state = 0x0051_ACE5_EED5_u64;
    for table in &mut out {
        for bit in table.iter_mut() {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            *bit = (state >> 56) as u8;
        }
    }
    out
}

/// The words of one descriptor, one per table.
fn words(d: &Descriptor, positions: &[[u8; BITS]; TABLES]) -> [u32; TABLES] {
    let mut out = [0u32; TABLES];
    for (t, table) in positions.iter().enumerate() {
        let mut w = t as u32;
        for &b in table {
            let bit = (d[usize::from(b) / 64] >> (b % 64)) & 1;
            w = (w << 1) | bit as u32;
        }
        out[t] = w;
    }
    out
}

/// One indexed keyframe.
#[derive(Debug, Clone)]
struct Entry {
    /// The caller's key.
    key: usize,
    /// Its words and their counts.
    bag: Vec<(u32, u16)>,
    /// Norm of its tf-idf vector.
    norm: f32,
}

/// An inverted index of keyframes' visual words.
#[derive(Debug, Clone)]
pub struct PlaceIndex {
    positions: [[u8; BITS]; TABLES],
    /// Word → (entry, count in that entry).
    postings: HashMap<u32, Vec<(usize, u16)>>,
    /// Every indexed keyframe.
    entries: Vec<Entry>,
    /// Index size when every entry's norm was last computed (idf drifts as the index grows).
    normed_at: usize,
}

impl Default for PlaceIndex {
    fn default() -> Self {
        Self::new()
    }
}

impl PlaceIndex {
    /// An empty index.
    pub fn new() -> Self {
        Self {
            positions: bit_positions(),
            postings: HashMap::new(),
            entries: vec![],
            normed_at: 0,
        }
    }

    /// Keyframes indexed so far.
    pub fn len(&self) -> usize {
        self.entries.len()
    }

    /// Whether nothing is indexed.
    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    fn bag(&self, descriptors: &[Descriptor]) -> HashMap<u32, u16> {
        let mut bag: HashMap<u32, u16> = HashMap::new();
        for d in descriptors {
            for w in words(d, &self.positions) {
                let c = bag.entry(w).or_default();
                *c = c.saturating_add(1);
            }
        }
        bag
    }

    /// Indexes a keyframe's descriptors under `key`.
    pub fn add(&mut self, key: usize, descriptors: &[Descriptor]) {
        let bag: Vec<(u32, u16)> = self.bag(descriptors).into_iter().collect();
        let entry = self.entries.len();
        for &(w, c) in &bag {
            self.postings.entry(w).or_default().push((entry, c));
        }
        self.entries.push(Entry {
            key,
            bag,
            norm: 1.0,
        });
        // Norms follow the idf weights: the new entry's now, everyone's again whenever the
        // index has grown by a quarter (amortised constant work per entry).
        if self.entries.len() >= self.normed_at + self.normed_at.div_ceil(4).max(1) {
            for e in 0..self.entries.len() {
                self.entries[e].norm = self.norm(&self.entries[e].bag);
            }
            self.normed_at = self.entries.len();
        } else {
            self.entries[entry].norm = self.norm(&self.entries[entry].bag);
        }
    }

    /// How little word `w` says about which keyframe this is (log of entries over entries
    /// with it; 0 for unknown words).
    fn idf(&self, w: u32) -> f32 {
        self.postings.get(&w).map_or(0.0, |list| {
            (self.entries.len() as f32 / list.len() as f32).ln()
        })
    }

    fn norm(&self, bag: &[(u32, u16)]) -> f32 {
        bag.iter()
            .map(|&(w, c)| (f32::from(c) * self.idf(w)).powi(2))
            .sum::<f32>()
            .sqrt()
            .max(1e-6)
    }

    /// The `k` keyframes most like `descriptors` among those `accept` lets through, best first,
    /// with their similarity (0–1).
    pub fn query(
        &self,
        descriptors: &[Descriptor],
        k: usize,
        accept: impl Fn(usize) -> bool,
    ) -> Vec<(usize, f32)> {
        if self.entries.is_empty() || k == 0 {
            return vec![];
        }
        let bag = self.bag(descriptors);
        let n = self.entries.len() as f32;
        let mut scores = vec![0.0f32; self.entries.len()];
        let mut query_norm = 0.0f32;
        for (w, &qc) in &bag {
            let Some(list) = self.postings.get(w) else {
                continue;
            };
            // Words found in many keyframes say little about which one this is.
            let idf = (n / list.len() as f32).ln();
            let q = f32::from(qc) * idf;
            query_norm += q * q;
            for &(entry, c) in list {
                scores[entry] += q * f32::from(c) * idf;
            }
        }
        let query_norm = query_norm.sqrt().max(1e-6);
        let mut ranked: Vec<(usize, f32)> = scores
            .iter()
            .enumerate()
            .filter(|&(_, &s)| s > 0.0)
            .map(|(e, &s)| {
                (
                    self.entries[e].key,
                    (s / (query_norm * self.entries[e].norm)).min(1.0),
                )
            })
            .filter(|&(key, _)| accept(key))
            .collect();
        ranked.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
        ranked.truncate(k);
        ranked
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dataset::Dataset;
    use crate::frontend::{FrontendConfig, observe};
    use std::path::Path;

    #[test]
    fn a_revisited_view_ranks_above_unrelated_views() {
        // fr1/rpy turns back and forth: frame 140 looks like the early frames around it in
        // viewing direction far more than like a random other scene.
        let dir = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../shared/data/rgbd/tum_fr1_rpy_first150");
        let ds = Dataset::open(&dir).unwrap();
        let config = FrontendConfig::default();
        let mut index = PlaceIndex::new();
        let obs = |i: usize| {
            let (g, d) = ds.load(i).unwrap();
            observe(&g, &d, ds.depth_scale, &ds.camera, &config)
        };
        for i in (0..120).step_by(10) {
            index.add(i, &obs(i).descriptors);
        }
        // The same frame is its own best match, with similarity near 1.
        let again = index.query(&obs(30).descriptors, 3, |_| true);
        assert_eq!(again[0].0, 30, "{again:?}");
        assert!(again[0].1 > 0.9, "{again:?}");
        // A frame between indexed ones finds one of the three that look most the same way
        // (by motion capture; fr1/rpy turns back and forth, so time order says little).
        let gt = ds.ground_truth.as_ref().expect("ground truth");
        let rotation_at = |i: usize| {
            gt.iter()
                .min_by(|a, b| {
                    (a.t - ds.frames[i].stamp)
                        .abs()
                        .total_cmp(&(b.t - ds.frames[i].stamp).abs())
                })
                .expect("poses")
                .pose
                .rotation
        };
        let mut by_view: Vec<(usize, f64)> = (0..120)
            .step_by(10)
            .map(|i| (i, rotation_at(i).angle_to(&rotation_at(55))))
            .collect();
        by_view.sort_by(|a, b| a.1.total_cmp(&b.1));
        let near = index.query(&obs(55).descriptors, 1, |_| true);
        assert!(
            by_view[..3].iter().any(|&(k, _)| k == near[0].0),
            "frame 55 → {near:?}; closest views {by_view:?}"
        );
        // The filter is honoured.
        let filtered = index.query(&obs(30).descriptors, 3, |k| k != 30);
        assert!(filtered.iter().all(|&(k, _)| k != 30));
        assert!(
            PlaceIndex::new()
                .query(&obs(30).descriptors, 3, |_| true)
                .is_empty()
        );
    }
}
