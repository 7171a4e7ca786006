//! Whether a registration can be believed: measures of every edge at the returned
//! transforms, and the decision (`confident`) with its reasons.
//!
//! Per edge, on the refinement's surface points (full resolution, plane-projected, with
//! normals) moved by the returned transform, both directions:
//! - **overlap**: the fraction of points with a point of the other scan within eps;
//! - **residual**: the median distance of those points to the other scan's local plane,
//!   relative to eps. Surfaces that really coincide lie on each other's planes (residual ~
//!   the scan noise); a wrong pose that only brings surfaces near each other crosses them
//!   (residual ~ 0.4, uniform within eps).

use crate::graph::Edge;
use crate::refine::RefineCloud;
use crate::se3::Rigid;
use kiddo::SquaredEuclidean;

/// An edge is trusted only if at least this fraction of its points overlap.
pub const MIN_OVERLAP: f64 = 0.1;
/// An edge is trusted only if its residual (median point-to-plane distance of the
/// overlapping points, relative to eps) is at most this.
pub const MAX_RESIDUAL: f64 = 0.25;

/// With three or more edges, an edge is trusted only if its residual is at most this many
/// times the median residual of all edges: pairs of one scan set share the scans' noise, so
/// a pose whose surfaces cross stands out even where the absolute limit is lenient (clean,
/// smooth surfaces).
pub const RELATIVE_RESIDUAL: f64 = 4.0;

/// The measures of one edge at the returned transform.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct EdgeCheck {
    /// The edge (views numbered from 0).
    pub source: usize,
    /// The edge's target view.
    pub target: usize,
    /// Mean over both directions of the fraction of points within eps of the other scan.
    pub overlap: f64,
    /// Median point-to-plane distance of those points, relative to eps.
    pub residual: f64,
}

/// The judgement of a registration.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Verdict {
    /// True when nothing below argues against the result.
    pub confident: bool,
    /// Why not, one sentence each (empty when confident).
    pub reasons: Vec<String>,
    /// The measures of every edge.
    pub edges: Vec<EdgeCheck>,
}

/// Measures `edge` at its transform `t_target_source` (centred frames).
pub(crate) fn check_edge(
    clouds: &[RefineCloud],
    edge: Edge,
    t_target_source: &Rigid,
    eps: f64,
) -> EdgeCheck {
    let one_way = |s: usize, t: usize, to_t: Rigid| -> (usize, usize, Vec<f64>) {
        let (src, dst) = (&clouds[s], &clouds[t]);
        let mut residuals = Vec::new();
        for p in src.points() {
            let q = to_t.apply(p);
            let nn = dst
                .tree()
                .query(&q)
                .nearest_one::<SquaredEuclidean<f64>>()
                .execute();
            if nn.distance <= eps * eps {
                let m = nn.item as usize;
                let (y, n) = (dst.points()[m], dst.normals()[m]);
                let r = (0..3).map(|k| n[k] * (q[k] - y[k])).sum::<f64>().abs();
                residuals.push(r / eps);
            }
        }
        (residuals.len(), src.points().len(), residuals)
    };
    let (a, na, mut ra) = one_way(edge.source, edge.target, *t_target_source);
    let (b, nb, rb) = one_way(edge.target, edge.source, t_target_source.inverse());
    ra.extend(rb);
    let overlap = 0.5 * (a as f64 / na.max(1) as f64 + b as f64 / nb.max(1) as f64);
    EdgeCheck {
        source: edge.source,
        target: edge.target,
        overlap,
        residual: median(&mut ra).unwrap_or(f64::INFINITY),
    }
}

fn median(v: &mut [f64]) -> Option<f64> {
    if v.is_empty() {
        return None;
    }
    v.sort_by(f64::total_cmp);
    Some(v[v.len() / 2])
}

/// Why each edge is not trusted (`None`: trusted), see [`MIN_OVERLAP`], [`MAX_RESIDUAL`]
/// and [`RELATIVE_RESIDUAL`].
pub(crate) fn doubts(edges: &[EdgeCheck]) -> Vec<Option<String>> {
    let mut residuals: Vec<f64> = edges.iter().map(|e| e.residual).collect();
    let typical = if edges.len() >= 3 {
        median(&mut residuals)
    } else {
        None
    };
    edges
        .iter()
        .map(|e| {
            let name = format!("{} -> {}", e.source + 1, e.target + 1);
            if e.overlap < MIN_OVERLAP {
                Some(format!(
                    "clouds {name} overlap by {:.2} only (at least {MIN_OVERLAP} expected)",
                    e.overlap
                ))
            } else if e.residual > MAX_RESIDUAL {
                Some(format!(
                    "clouds {name} meet but do not lie on each other (residual {:.2} of eps, at most {MAX_RESIDUAL} expected)",
                    e.residual
                ))
            } else if typical.is_some_and(|m| e.residual > RELATIVE_RESIDUAL * m) {
                Some(format!(
                    "clouds {name} lie on each other far less closely than the other pairs (residual {:.3} of eps against a median of {:.3})",
                    e.residual,
                    typical.unwrap_or(0.0)
                ))
            } else {
                None
            }
        })
        .collect()
}

/// The verdict from the edges' measures (names views from 1 in the reasons).
pub(crate) fn judge(edges: Vec<EdgeCheck>, mut reasons: Vec<String>) -> Verdict {
    reasons.extend(doubts(&edges).into_iter().flatten());
    Verdict {
        confident: reasons.is_empty(),
        reasons,
        edges,
    }
}
