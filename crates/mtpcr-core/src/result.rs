//! What a registration returns: one estimate per edge of the view graph (named by its
//! direction), one pose per view, and the record of the search.

use crate::graph::Edge;
use crate::se3::{invert_rigid, Rigid, Transform};
use crate::verdict::Verdict;

/// The estimate of one edge. `t_target_source` maps points of view `source` into the frame of
/// view `target` (`x_target = T x_source`), in the clouds' original frames.
#[derive(Clone, Debug, PartialEq)]
pub struct EdgeEstimate {
    /// The view whose points are moved (numbered from 0).
    pub source: usize,
    /// The view they are moved into.
    pub target: usize,
    /// The transform (after refinement, when it ran).
    pub t_target_source: Transform,
    /// The evolution's best cost of the edge's original task (before refinement).
    pub original_cost: f64,
    /// The evolution's best cost of the edge's aiding task (before refinement).
    pub aiding_cost: f64,
}

impl EdgeEstimate {
    /// The edge as a pair of views.
    pub fn edge(&self) -> Edge {
        Edge {
            source: self.source,
            target: self.target,
        }
    }
}

/// A scan that could not be placed, and why.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Unplaced {
    /// The scan (numbered from 0).
    pub view: usize,
    /// Why, in one sentence.
    pub reason: String,
}

/// The result of a registration.
#[derive(Clone, Debug, PartialEq)]
pub struct Registration {
    /// One estimate per edge of the view graph, in task order (for the three-view loop:
    /// T12, T23, T31).
    pub edges: Vec<EdgeEstimate>,
    /// Each view's transform into view 0's frame (`poses[0]` is the identity); ready to merge.
    /// `None` for a view that could not be placed (see `unplaced`). When view 0 itself is not
    /// placed (scans in no known order: it was not in the largest group of scans that could
    /// be joined), the frame is that of the first placed view, whose pose is the identity.
    pub poses: Vec<Option<Transform>>,
    /// The views that could not be placed, with the reason (only scans in no known order).
    pub unplaced: Vec<Unplaced>,
    /// Whether the result can be believed, with the measures behind it.
    pub verdict: Verdict,
    /// The task names, in slot order (the columns of `history`).
    pub task_names: Vec<String>,
    /// Best cost of each task of the kept evolution after its initial population (row 0) and
    /// after every generation, in slot order.
    pub history: Vec<Vec<f64>>,
    /// The history of every restart, in the order they ran (`history` is the kept one's).
    pub restart_histories: Vec<Vec<Vec<f64>>>,
    /// Which restart was kept (index into `restart_histories`): the one with the lowest sum
    /// of final original-task costs.
    pub kept_restart: usize,
    /// Points of each cloud after downsampling (what the search scored).
    pub sampled_points: Vec<usize>,
    /// Loss evaluations made (all restarts).
    pub evaluations: usize,
    /// Generations run (all restarts; less than configured when the observer stopped the run).
    pub generations_run: usize,
    /// Restarts run (fewer than configured when two agreed early, see
    /// `stop_when_restarts_agree`, or when the observer stopped the run).
    pub restarts_run: usize,
    /// False when the observer stopped the run early.
    pub completed: bool,
    /// Wall-clock seconds of the whole call (preparation included for [`crate::register`]).
    pub seconds: f64,
    /// The seed that reproduces this result.
    pub seed: u64,
    /// Inlier radius eps of the prepared problem, in data units.
    pub eps: f64,
    /// Largest bounding-box side of the prepared clouds.
    pub shift: f64,
}

impl Registration {
    /// The name of edge `k`'s transform, views numbered from 1 (`T12` maps view 1 into view 2).
    pub fn edge_name(&self, k: usize) -> String {
        crate::graph::transform_name(self.edges[k].edge(), self.poses.len())
    }

    /// The edges' transforms in task order (`[T12, T23, T31]` for the three-view loop).
    pub fn transforms(&self) -> Vec<Transform> {
        self.edges.iter().map(|e| e.t_target_source).collect()
    }

    /// The view whose frame `poses` are in (its pose is the identity): view 0, or the first
    /// placed view when view 0 could not be placed; `None` when no view is placed.
    pub fn reference_view(&self) -> Option<usize> {
        self.poses.iter().position(Option::is_some)
    }

    /// The placed views' poses, or `None` when some view is unplaced.
    pub fn all_poses(&self) -> Option<Vec<Transform>> {
        self.poses.iter().copied().collect()
    }

    /// `[T12, T23, T31]` when the problem is the three-view loop, else `None`.
    pub fn loop_transforms(&self) -> Option<[Transform; 3]> {
        match self.edges.as_slice() {
            [a, b, c] if self.poses.len() == 3 => {
                Some([a.t_target_source, b.t_target_source, c.t_target_source])
            }
            _ => None,
        }
    }

    /// The transform mapping view `source` into view `target`'s frame: the edge's own
    /// estimate when `(source, target)` is an edge (its inverse when reversed), else composed
    /// from the poses; `None` when a view is unplaced or out of range.
    pub fn t_target_source(&self, target: usize, source: usize) -> Option<Transform> {
        for e in &self.edges {
            if (e.source, e.target) == (source, target) {
                return Some(e.t_target_source);
            }
            if (e.source, e.target) == (target, source) {
                return Some(invert_rigid(&e.t_target_source));
            }
        }
        let (wt, ws) = ((*self.poses.get(target)?)?, (*self.poses.get(source)?)?);
        Some(invert_rigid(&wt) * ws)
    }

    /// `points` of view `view` mapped into view 0's frame (see `poses`) by the view's pose; `None` when
    /// the view is unplaced or out of range.
    pub fn place(&self, view: usize, points: &[[f64; 3]]) -> Option<Vec<[f64; 3]>> {
        let pose = Rigid::from_matrix(&(*self.poses.get(view)?)?);
        Some(points.iter().map(|p| pose.apply(p)).collect())
    }

    /// The views' points (`clouds[k]` of view k) merged in view 0's frame (see `poses`), and the view each
    /// point came from; unplaced views are left out. `None` when the number of clouds is not
    /// the number of views.
    pub fn merge(&self, clouds: &[&[[f64; 3]]]) -> Option<(Vec<[f64; 3]>, Vec<usize>)> {
        if clouds.len() != self.poses.len() {
            return None;
        }
        let mut points = Vec::with_capacity(clouds.iter().map(|c| c.len()).sum());
        let mut views = Vec::with_capacity(points.capacity());
        for (k, cloud) in clouds.iter().enumerate() {
            if let Some(placed) = self.place(k, cloud) {
                views.extend(std::iter::repeat_n(k, placed.len()));
                points.extend(placed);
            }
        }
        Some((points, views))
    }

    /// `||M_{n-1} ... M_0 - I||_F` for the edges of a ring (how far the transforms are from
    /// closing the loop; ~0 after refinement); `None` without a loop.
    pub fn loop_residual(&self) -> Option<f64> {
        let n = self.edges.len();
        let ring = self
            .edges
            .iter()
            .enumerate()
            .all(|(k, e)| e.source == k && e.target == (k + 1) % n);
        if n < 3 || self.poses.len() != n || !ring {
            return None;
        }
        let mut product = self.edges[n - 1].t_target_source;
        for e in self.edges[..n - 1].iter().rev() {
            product *= &e.t_target_source;
        }
        Some((product - Transform::identity()).norm())
    }

    /// The evolution's final best cost of every task, in slot order (aiding tasks, then
    /// original tasks).
    pub fn best_costs(&self) -> Vec<f64> {
        self.edges
            .iter()
            .map(|e| e.aiding_cost)
            .chain(self.edges.iter().map(|e| e.original_cost))
            .collect()
    }
}
