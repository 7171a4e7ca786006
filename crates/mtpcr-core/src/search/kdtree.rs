//! The exact index: a KD-tree (kiddo) answering both questions by a nearest-neighbour query.
//! Slow, and the reference every other index is checked against.

use super::{DistanceIndex, InlierIndex};
use kiddo::{ImmutableKdTree, SquaredEuclidean};

/// A KD-tree over a cloud's points, for the radius `eps` and the cap `cap`.
#[derive(Debug)]
pub struct KdTreeIndex {
    tree: ImmutableKdTree<f64, 3>,
    eps: f64,
    eps2: f64,
    cap: f64,
}

impl KdTreeIndex {
    /// The tree of `points` (non-empty and finite).
    pub fn new(points: &[[f64; 3]], eps: f64, cap: f64) -> KdTreeIndex {
        let tree = ImmutableKdTree::<f64, 3>::new_from_slice(points)
            .expect("a non-empty finite cloud always builds a KD-tree");
        KdTreeIndex {
            tree,
            eps,
            eps2: eps * eps,
            cap,
        }
    }

    /// The tree itself.
    pub fn tree(&self) -> &ImmutableKdTree<f64, 3> {
        &self.tree
    }

    /// Squared distance from `p` to the nearest point.
    #[inline]
    pub fn nearest2(&self, p: &[f64; 3]) -> f64 {
        self.tree
            .query(p)
            .nearest_one::<SquaredEuclidean<f64>>()
            .execute()
            .distance
    }
}

impl InlierIndex for KdTreeIndex {
    fn eps(&self) -> f64 {
        self.eps
    }

    #[inline]
    fn has_point_within(&self, p: &[f64; 3]) -> bool {
        self.nearest2(p) <= self.eps2
    }
}

impl DistanceIndex for KdTreeIndex {
    fn cap(&self) -> f64 {
        self.cap
    }

    #[inline]
    fn capped_distance(&self, p: &[f64; 3]) -> f64 {
        self.nearest2(p).sqrt().min(self.cap)
    }
}
