//! The view graph: the views (clouds) of a problem, the directed edges (pairs of views)
//! registered between them, and the tasks of the evolution, indexed by (edge, kind).
//!
//! Two topologies are searched jointly: a single edge (two views; no loop) and a ring of
//! `n >= 3` views (edge `k` registers view `k` into view `k + 1`, the last edge closes the
//! loop into view 0). The paper's problem is the ring of three views.

use crate::error::{Error, Result};
use crate::se3::{invert_rigid, Transform};

/// A directed edge: the transform of this edge maps points of view `source` into the frame of
/// view `target` (`x_target = T_target_source x_source`). Views are numbered from 0.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct Edge {
    /// The view whose points are moved.
    pub source: usize,
    /// The view they are moved into.
    pub target: usize,
}

/// The two tasks of an edge.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TaskKind {
    /// The easier aiding task (capped mean distance).
    Aiding,
    /// The original task (inlier ratio, plus the loop term on a ring).
    Original,
}

/// A task of the evolution: one edge, one kind.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Task {
    /// The edge's index in [`ViewGraph::edges`].
    pub edge: usize,
    /// Aiding or original.
    pub kind: TaskKind,
}

/// Views and the edges registered between them (see the module docs).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ViewGraph {
    views: usize,
    edges: Vec<Edge>,
    ring: bool,
}

impl ViewGraph {
    /// Two views, one edge `0 -> 1`, no loop.
    pub fn pair() -> ViewGraph {
        ViewGraph {
            views: 2,
            edges: vec![Edge {
                source: 0,
                target: 1,
            }],
            ring: false,
        }
    }

    /// A ring of `views >= 3` views: edge `k` is `k -> (k + 1) % views`.
    pub fn ring(views: usize) -> Result<ViewGraph> {
        if views < 3 {
            return Err(Error::InvalidInput(format!(
                "a ring needs at least 3 views, got {views}"
            )));
        }
        Ok(ViewGraph {
            views,
            edges: (0..views)
                .map(|k| Edge {
                    source: k,
                    target: (k + 1) % views,
                })
                .collect(),
            ring: true,
        })
    }

    /// Any set of edges between `views` views, with no loop searched jointly (each edge is
    /// its own pair of tasks): the candidate pairs of an unordered scan set.
    pub fn general(views: usize, edges: Vec<Edge>) -> Result<ViewGraph> {
        if let Some(e) = edges
            .iter()
            .find(|e| e.source >= views || e.target >= views || e.source == e.target)
        {
            return Err(Error::InvalidInput(format!(
                "edge {} -> {} is not between two of the {views} views",
                e.source, e.target
            )));
        }
        Ok(ViewGraph {
            views,
            edges,
            ring: false,
        })
    }

    /// The single edge `source -> target` of this graph's views, as a graph of its own (the
    /// same view numbers): for searching one pair of a larger set.
    pub fn single(&self, edge: Edge) -> ViewGraph {
        ViewGraph {
            views: self.views,
            edges: vec![edge],
            ring: false,
        }
    }

    /// The graph searched for `views` clouds given in loop order: a pair for two, a ring
    /// for more.
    pub fn for_views(views: usize) -> Result<ViewGraph> {
        match views {
            0 | 1 => Err(Error::InvalidInput(format!(
                "at least two clouds are needed, got {views}"
            ))),
            2 => Ok(ViewGraph::pair()),
            n => ViewGraph::ring(n),
        }
    }

    /// Number of views.
    pub fn views(&self) -> usize {
        self.views
    }

    /// The edges, in task order.
    pub fn edges(&self) -> &[Edge] {
        &self.edges
    }

    /// True when the edges form one loop through every view (a ring).
    pub fn is_ring(&self) -> bool {
        self.ring
    }

    /// Number of tasks: two per edge.
    pub fn task_count(&self) -> usize {
        2 * self.edges.len()
    }

    /// The population slot of a task: aiding tasks first (slot = edge), then original tasks
    /// (slot = edges + edge).
    pub fn slot(&self, task: Task) -> usize {
        match task.kind {
            TaskKind::Aiding => task.edge,
            TaskKind::Original => self.edges.len() + task.edge,
        }
    }

    /// The task of a population slot (the inverse of [`ViewGraph::slot`]).
    pub fn task(&self, slot: usize) -> Task {
        let e = self.edges.len();
        if slot < e {
            Task {
                edge: slot,
                kind: TaskKind::Aiding,
            }
        } else {
            Task {
                edge: slot - e,
                kind: TaskKind::Original,
            }
        }
    }

    /// Names of the tasks in slot order: `J1-a`, `J2-a`, ..., then `J1-o`, `J2-o`, ... (the
    /// paper's names for the three-view loop).
    pub fn task_names(&self) -> Vec<String> {
        let e = self.edges.len();
        (0..2 * e)
            .map(|s| format!("J{}-{}", s % e + 1, if s < e { "a" } else { "o" }))
            .collect()
    }

    /// The paper's name of edge `e`'s transform, with views numbered from 1: `T12` maps view 1
    /// into view 2 (`T3_10` style, with an underscore, beyond nine views).
    pub fn edge_name(&self, e: usize) -> String {
        transform_name(self.edges[e], self.views)
    }

    /// The loop product of a ring, `M_{n-1} ... M_1 M_0` with `M_k = bests[k]` except
    /// `M_edge = t` (the identity for a loop-consistent set); `None` when the graph has no
    /// loop.
    pub fn loop_product(
        &self,
        edge: usize,
        t: &Transform,
        bests: &[Transform],
    ) -> Option<Transform> {
        if !self.ring {
            return None;
        }
        let n = self.edges.len();
        let m = |k: usize| if k == edge { t } else { &bests[k] };
        let mut product = *m(n - 1);
        for k in (0..n - 1).rev() {
            product *= m(k);
        }
        Some(product)
    }

    /// The estimate of edge `edge` composed from the rest of the loop,
    /// `(M_{e+n-1} ... M_{e+1})^-1` with `M_k = bests[k]` (indices mod n): the inter-task
    /// channel's message. `None` when the graph has no loop.
    pub fn loop_estimate(&self, edge: usize, bests: &[Transform]) -> Option<Transform> {
        if !self.ring {
            return None;
        }
        let n = self.edges.len();
        let mut rest = bests[(edge + n - 1) % n];
        for k in (1..n - 1).rev() {
            rest *= &bests[(edge + k) % n];
        }
        Some(invert_rigid(&rest))
    }

    /// The transform of every edge from scan-to-world poses (`x_world = pose_v x_v`):
    /// `T_target_source = pose_target^-1 pose_source`.
    pub fn edge_transforms(&self, poses: &[Transform]) -> Vec<Transform> {
        self.edges
            .iter()
            .map(|e| invert_rigid(&poses[e.target]) * poses[e.source])
            .collect()
    }

    /// Poses of every view in view 0's frame (`W_v` maps view v into view 0) from the edge
    /// transforms of a ring, using every edge but `left_out` (a spanning path). Views before
    /// the left-out edge are reached forwards (`W_v = (M_{v-1} ... M_0)^-1`), the others
    /// backwards through the closing edge (`W_v = M_{n-1} ... M_v`).
    pub fn ring_poses(&self, transforms: &[Transform], left_out: usize) -> Vec<Transform> {
        let n = self.views;
        let mut poses = vec![Transform::identity(); n];
        let mut forward = Transform::identity();
        for v in 1..=left_out {
            forward = if v == 1 {
                transforms[0]
            } else {
                transforms[v - 1] * forward
            };
            poses[v] = invert_rigid(&forward);
        }
        let mut backward = Transform::identity();
        for v in (left_out + 1..n).rev() {
            backward = if v == n - 1 {
                transforms[n - 1]
            } else {
                backward * transforms[v]
            };
            poses[v] = backward;
        }
        poses
    }
}

/// The paper's name of the transform of `edge` among `views` views, numbered from 1: `T12`
/// maps view 1 into view 2 (`T3_10`, with an underscore, beyond nine views).
pub fn transform_name(edge: Edge, views: usize) -> String {
    if views <= 9 {
        format!("T{}{}", edge.source + 1, edge.target + 1)
    } else {
        format!("T{}_{}", edge.source + 1, edge.target + 1)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::se3::decode;

    fn ring_of(n: usize) -> (ViewGraph, Vec<Transform>) {
        let g = ViewGraph::ring(n).unwrap();
        let poses: Vec<Transform> = (0..n)
            .map(|v| {
                decode(&[
                    10.0 * v as f64,
                    -7.0 * v as f64,
                    3.0,
                    0.1 * v as f64,
                    0.2,
                    -0.3,
                ])
            })
            .collect();
        let t = g.edge_transforms(&poses);
        (g, t)
    }

    #[test]
    fn tasks_and_slots_round_trip() {
        let g = ViewGraph::ring(3).unwrap();
        assert_eq!(
            g.task_names(),
            ["J1-a", "J2-a", "J3-a", "J1-o", "J2-o", "J3-o"]
        );
        for s in 0..6 {
            assert_eq!(g.slot(g.task(s)), s);
        }
        assert_eq!(g.edge_name(2), "T31");
        assert_eq!(ViewGraph::pair().task_names(), ["J1-a", "J1-o"]);
        assert!(ViewGraph::for_views(1).is_err() && ViewGraph::ring(2).is_err());
    }

    #[test]
    fn a_consistent_ring_closes_and_estimates_every_edge() {
        for n in [3, 4, 7] {
            let (g, t) = ring_of(n);
            for e in 0..n {
                let c = g.loop_product(e, &t[e], &t).unwrap();
                assert!((c - Transform::identity()).norm() < 1e-12);
                let est = g.loop_estimate(e, &t).unwrap();
                assert!((est - t[e]).norm() < 1e-12, "n {n} edge {e}");
            }
            for left_out in 0..n {
                let w = g.ring_poses(&t, left_out);
                for (e, edge) in g.edges().iter().enumerate() {
                    let rel = invert_rigid(&w[edge.target]) * w[edge.source];
                    assert!((rel - t[e]).norm() < 1e-12, "n {n} left out {left_out}");
                }
            }
        }
        assert!(ViewGraph::pair()
            .loop_product(0, &Transform::identity(), &[])
            .is_none());
    }

    #[test]
    fn three_view_products_are_the_papers() {
        // Bit for bit the expressions of the three-view code: task 1: T31 T23 T; task 2:
        // T31 T T12; task 3: T T23 T12; inter: (T_(j+2) T_(j+1))^-1.
        let (g, b) = ring_of(3);
        let t = decode(&[1.0, 2.0, 3.0, 0.0, 0.0, 0.1]);
        assert_eq!(g.loop_product(0, &t, &b).unwrap(), b[2] * b[1] * t);
        assert_eq!(g.loop_product(1, &t, &b).unwrap(), b[2] * t * b[0]);
        assert_eq!(g.loop_product(2, &t, &b).unwrap(), t * b[1] * b[0]);
        for j in 0..3 {
            let paper = invert_rigid(&(b[(j + 2) % 3] * b[(j + 1) % 3]));
            assert_eq!(g.loop_estimate(j, &b).unwrap(), paper);
        }
        let id = Transform::identity();
        assert_eq!(g.ring_poses(&b, 0), vec![id, b[2] * b[1], b[2]]);
        assert_eq!(g.ring_poses(&b, 1), vec![id, invert_rigid(&b[0]), b[2]]);
        assert_eq!(
            g.ring_poses(&b, 2),
            vec![id, invert_rigid(&b[0]), invert_rigid(&(b[1] * b[0]))]
        );
    }
}
