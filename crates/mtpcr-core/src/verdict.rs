//! Whether a registration can be believed: measures of every edge at the returned
//! transforms, and the decision (`confident`) with its reasons.
//!
//! Per edge, on the refinement's surface points (full resolution, plane-projected, with
//! normals) moved by the returned transform, both directions:
//! - **overlap**: the fraction of points with a point of the other scan within eps;
//! - **residual**: the median distance of those points to the other scan's local plane,
//!   relative to eps. Surfaces that really coincide lie on each other's planes (residual ~
//!   the scan noise); a wrong pose that only brings surfaces near each other crosses them
//!   (residual ~ 0.4, uniform within eps);
//! - with feature keypoints, **constraint**: how firmly the surfaces where the scans'
//!   keypoints meet hold the pose against a slide ([`MIN_CONSTRAINT`]).

use crate::graph::Edge;
use crate::refine::RefineCloud;
use crate::se3::Rigid;
use rayon::prelude::*;

/// An edge is trusted only if at least this fraction of its points overlap.
pub const MIN_OVERLAP: f64 = 0.1;
/// An edge is trusted only if its residual (median point-to-plane distance of the
/// overlapping points, relative to eps) is at most this.
pub const MAX_RESIDUAL: f64 = 0.25;

/// An edge is trusted only if its residual is at most this many times the scans' residual
/// against themselves ([`EdgeCheck::self_residual`]), or under [`NEGLIGIBLE_RESIDUAL`]. Right
/// answers measured 0.9-3.6 times after refinement (clean, noisy and synthetic scans), up to
/// 9 on 96-degree pairs of 10 % overlap, up to 6 unrefined; wrong ones 11-18 on real scans
/// and 40-60 for unrelated smooth shapes laid on each other, which the absolute limit misses.
pub const SELF_RESIDUAL_RATIO: f64 = 10.0;
/// A residual under this fraction of eps is never doubted (scans that lie exactly on their
/// planes have a self-residual of ~0, and any ratio to it is noise).
pub const NEGLIGIBLE_RESIDUAL: f64 = 0.05;

/// With three or more edges, an edge is trusted only if its residual is at most this many
/// times the median residual of all edges: pairs of one scan set share the scans' noise, so
/// a pose whose surfaces cross stands out even where the absolute limit is lenient (clean,
/// smooth surfaces).
pub const RELATIVE_RESIDUAL: f64 = 4.0;

/// A pair registered alone is trusted only if its transform explains at least this many of
/// the pair's descriptor matches ([`crate::features::PairMatches::support`]). On scenes,
/// walls, floors and tables make a wrong overlay overlap well and lie flat on the other scan,
/// so overlap and residual look right; the matches do not. Measured on pairs of the visible
/// 3DMatch scenes (120 + 120 pairs, seed 0): the right pose explained 39-214 matches
/// (quartile to 90th percentile), a wrong one 7-15 (quartiles).
pub const MIN_SUPPORT: usize = 25;
/// ... and at least this many times as many as any feature hypothesis that is a different
/// pose: where two places of a room fit about as well, the matches cannot tell which is right
/// (right answers: median ratio 3.7 on 3DMatch, 1.8 on 3DLoMatch; wrong ones 1.3). Checked on
/// 300 + 300 other pairs (seed 1): 10 of 271 failed pairs confident, 107 of 329 registered
/// pairs doubted (with 1.5: 20 and 86). Not used in a loop, whose closure verifies its edges
/// (an edge found through the loop may explain fewer matches than a wrong pose of the pair).
pub const RIVAL_RATIO: f64 = 2.0;

/// A feature hypothesis of a pair or loop that puts more than this share of one scan's
/// points (among those in front of or on the other's surface, seen from the other's
/// viewpoint) where the other scanner saw through is dropped ([`crate::freespace`]; only
/// with viewpoints). Measured on the hypotheses of 1084 3DMatch and 3DLoMatch pairs of the
/// kitchen and the lab (8506 poses): right poses median 0.02, 95th percentile 0.19; wrong
/// ones 5th percentile 0.14, median 0.41; dropping above 0.15 keeps 93 % of the right poses
/// and drops 95 % of the wrong ones.
pub const HYPOTHESIS_FREE_SPACE: f64 = 0.15;
/// The feature search keeps a pose among its best only if it puts at most this share in
/// free space (as [`HYPOTHESIS_FREE_SPACE`], before the pose is refined, hence more lenient):
/// on 150 3DLoMatch pairs the true pose was among the 10 candidates for 72 of them instead
/// of 61 (0.2: 62, 0.5: 69).
pub const SEARCH_FREE_SPACE: f64 = 0.3;
/// An edge whose free space is known but whose feature matches are not (a room's pairs after
/// placement) is trusted only if its free space (as for [`HYPOTHESIS_FREE_SPACE`]) is at most
/// this; a scene pair with both weighs them with the other cues ([`SceneOdds`]).
pub const MAX_FREE_SPACE: f64 = 0.05;

/// With viewpoints (scenes), a pair's cues are weighed together rather than each against its
/// own limit: the log-odds that the pose is right (rotation under 15 degrees, translation
/// under 30 cm), a logistic fit over the records of every visible 3DMatch and 3DLoMatch pair
/// (2419, seed 0, as read; RESULTS.md, 2026-12-06, seventh session):
///
/// ```text
/// 0.27 + 0.945 ln(1 + support) - 1.144 ln(1 + rival) - 19.2 min(free space, 0.3)
///      + 1.766 ln(constraint + 0.001) + 6.01 overlap - 19.2 residual
///      - 98.8 min(free share, 0.3) + 0.839 ln(1 + landed) + 0.712 ln(1 + tight support)
/// ```
///
/// One cue no longer decides alone: with the other cues as a typical confident pair's
/// ([`TYPICAL_SCENE_PAIR`]), a pose that puts a few percent in free space is trusted when
/// many matches agree with it and doubted when few do. The pair is trusted at
/// [`SceneOdds::trusted_at`] and above. The last three cues (the share of all of a scan's
/// points in the other's free space, the matches the pose lands on the other scan, those it
/// maps closely) took the doubted registered pairs of those records from 12.0 % to 10.0 % at
/// 4.5 % of the failed pairs confident; a check without them (a room's screened pairs, whose
/// matches are not kept, and a room's bridges, where the three let a wrong one through) is
/// weighed by [`SCREENED_SCENE_ODDS`], the six-cue fit before them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SceneOdds {
    /// The log-odds of a pose with no match, rival, free space or overlap (the intercept).
    pub base: f64,
    /// Per `ln(1 + support)` ([`EdgeCheck::support`]).
    pub support: f64,
    /// Per `ln(1 + rival_support)` ([`EdgeCheck::rival_support`]).
    pub rival: f64,
    /// Per unit of free space ([`EdgeCheck::free_space`], counted up to
    /// [`SceneOdds::FREE_SPACE_CAP`]).
    pub free_space: f64,
    /// Per `ln(constraint + 0.001)` ([`EdgeCheck::constraint`]; none counts as 0).
    pub constraint: f64,
    /// Per unit of overlap ([`EdgeCheck::overlap`]).
    pub overlap: f64,
    /// Per unit of residual ([`EdgeCheck::residual`], relative to eps).
    pub residual: f64,
    /// Per unit of free share ([`EdgeCheck::free_share`], counted up to
    /// [`SceneOdds::FREE_SPACE_CAP`]; none counts as 0).
    pub free_share: f64,
    /// Per `ln(1 + landed)` ([`EdgeCheck::landed`]; none counts as 0).
    pub landed: f64,
    /// Per `ln(1 + tight_support)` ([`EdgeCheck::tight_support`]; none counts as 0).
    pub tight_support: f64,
    /// A pose is trusted at this log-odds and above.
    pub trusted_at: f64,
}

impl SceneOdds {
    /// Free space beyond this counts as this (a pose that far in free space is wrong
    /// whatever else; the fit saw few of them).
    pub const FREE_SPACE_CAP: f64 = 0.3;

    /// The weights for `e`: [`SCENE_ODDS`] when its matches' landing is measured (a pair
    /// registered alone), else [`SCREENED_SCENE_ODDS`].
    pub fn for_check(e: &EdgeCheck) -> &'static SceneOdds {
        if e.landed.is_some() {
            &SCENE_ODDS
        } else {
            &SCREENED_SCENE_ODDS
        }
    }

    /// Each cue's term in [`SceneOdds::log_odds`], in the order support, rival, free space,
    /// constraint, overlap, residual, free share, landed, tight support.
    pub fn terms(&self, e: &EdgeCheck) -> [f64; 9] {
        let support = e.support.unwrap_or(0) as f64;
        let rival = e.rival_support.unwrap_or(0) as f64;
        let free = e.free_space.unwrap_or(0.0).min(Self::FREE_SPACE_CAP);
        let constraint = e.constraint.unwrap_or(0.0).max(0.0);
        let free_share = e.free_share.unwrap_or(0.0).min(Self::FREE_SPACE_CAP);
        [
            self.support * support.ln_1p(),
            self.rival * rival.ln_1p(),
            self.free_space * free,
            self.constraint * (constraint + 0.001).ln(),
            self.overlap * e.overlap,
            self.residual * e.residual,
            self.free_share * free_share,
            self.landed * (e.landed.unwrap_or(0) as f64).ln_1p(),
            self.tight_support * (e.tight_support.unwrap_or(0) as f64).ln_1p(),
        ]
    }

    /// The log-odds that `e`'s pose is right.
    pub fn log_odds(&self, e: &EdgeCheck) -> f64 {
        self.base + self.terms(e).iter().sum::<f64>()
    }

    /// The most [`SceneOdds::log_odds`] `e`'s pose can reach whatever its overlap (in
    /// [0, 1]) and residual (at least 0) turn out to be: a pair below
    /// [`SceneOdds::trusted_at`] by this is doubted before its surfaces are measured.
    pub fn at_best(&self, e: &EdgeCheck) -> f64 {
        if self.residual > 0.0 {
            return f64::INFINITY;
        }
        let terms = self.terms(&EdgeCheck {
            overlap: 0.0,
            residual: 0.0,
            ..e.clone()
        });
        self.base + terms.iter().sum::<f64>() + self.overlap.max(0.0)
    }
}

/// The weights of [`SceneOdds`] for a pair registered alone (see there), trusted at odds of
/// 5.7 : 1: on the records of the fit it lets 22 of 556 failed pairs through (4.0 %) and
/// doubts 203 of 1863 registered (10.9 %); run with it (every visible pair, seed 0, where it
/// also decides which pairs take a second look and which look's answer is kept): 25 of 559
/// (4.5 %) and 188 of 1860 (10.1 %), against 26 of 556 and 218 of 1863 with the six cues; with
/// random motions 32 of 586 (5.5 %) and 174 of 1833 (9.5 %), against 5.7 % and 11.0 %. At 5.4 :
/// 1 the pairs as read gave 4.7 % and 9.7 %, but the moved ones 6.3 % confident failures.
pub const SCENE_ODDS: SceneOdds = SceneOdds {
    base: 0.266,
    support: 0.945,
    rival: -1.144,
    free_space: -19.22,
    constraint: 1.766,
    overlap: 6.01,
    residual: -19.25,
    free_share: -98.8,
    landed: 0.839,
    tight_support: 0.712,
    trusted_at: 1.74,
};

/// The weights of [`SceneOdds`] for a check whose matches' landing is not measured (a room's
/// screened pairs): the six-cue fit over 4838 records of every visible 3DMatch and 3DLoMatch
/// pair (seed 0, as read and with random motions; RESULTS.md, 2026-12-04, fourth session),
/// trusted at odds of 6.4 : 1 (3 % of the failed pairs of the fit through, 4.3 % on a scene
/// left out of it). There the weighed cues called 21 of 677 failed pairs confident (3.1 %)
/// and doubted 216 of 1742 registered (12.4 %), where the separate limits had 31 (4.6 %)
/// and 277 (15.9 %).
pub const SCREENED_SCENE_ODDS: SceneOdds = SceneOdds {
    base: 7.07,
    support: 1.21,
    rival: -0.98,
    free_space: -43.6,
    constraint: 1.90,
    overlap: 3.75,
    residual: -17.7,
    free_share: 0.0,
    landed: 0.0,
    tight_support: 0.0,
    trusted_at: 1.86,
};

/// What a confident scene pair typically measures (medians over the records of
/// [`SceneOdds`]): the reason of a doubt names the cue that falls farthest below it.
pub const TYPICAL_SCENE_PAIR: EdgeCheck = EdgeCheck {
    source: 0,
    target: 1,
    overlap: 0.48,
    residual: 0.126,
    self_residual: 0.0,
    constraint: Some(0.11),
    support: Some(42),
    rival_support: Some(0),
    free_space: Some(0.007),
    free_share: Some(0.002),
    landed: Some(1763),
    tight_support: Some(9),
};

/// An edge is trusted only if its overlapping surfaces hold it against a slide this firmly
/// ([`EdgeCheck::constraint`]; a scene pair's constraint is weighed by [`SCENE_ODDS`]
/// instead, the limit serving objects and rooms). On scenes a wrong pose often slides the right overlay along a
/// wall and floor by 30-45 cm, where overlap, residual, free space and matches all look right:
/// on 300 + 300 3DMatch / 3DLoMatch pairs (seed 1), the 9 failed pairs called confident had
/// 0.006-0.11 (median 0.019; 6 of them 33-45 cm off), the 375 registered and confident
/// 0.042 at the 5th percentile, median 0.116. With 0.02: 4 confident failures instead of 9,
/// 70 registered pairs doubted instead of 68; on 300 + 300 other pairs (seed 0): 7 of 158
/// instead of 12, and 72 of 442 instead of 71. (Letting well-supported poses put up to 10 %
/// in free space as well: seed 1, 7 and 51; seed 0, 11 and 58: not kept.)
pub const MIN_CONSTRAINT: f64 = 0.02;

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
    /// The larger of the two scans' residuals against themselves (each scan's surface
    /// points against the planes of its own neighbours), relative to eps: what a perfect
    /// fit would leave.
    pub self_residual: f64,
    /// How firmly the overlapping surfaces hold the pose against a slide: the smallest
    /// eigenvalue of the mean `n nᵀ` of the keypoint normals where the two scans' keypoints
    /// meet (both directions; 1/3 for normals spread evenly, 0 for one plane or surfaces along
    /// one line); `None` without feature keypoints. See [`MIN_CONSTRAINT`].
    pub constraint: Option<f64>,
    /// Descriptor matches of the pair that the transform explains (see
    /// [`crate::features::PairMatches::support`]); `None` without feature matching.
    pub support: Option<usize>,
    /// The most matches explained by a feature hypothesis that is a different pose (with
    /// viewpoints: among those kept out of free space, each discounted by the free space it
    /// violates, as in the choice of the pose).
    pub rival_support: Option<usize>,
    /// The share of one scan's points put where the other scanner saw through (the larger
    /// direction; weighed with the other cues by [`SCENE_ODDS`]), 1 when one scanner stands
    /// behind a surface the other saw (see [`crate::freespace`]); `None` without viewpoints.
    pub free_space: Option<f64>,
    /// The share of all of one scan's points put where the other scanner saw through (the
    /// larger direction; unlike `free_space` counted over every point, seen by the other
    /// scanner or not): measured for a scene pair registered alone, `None` otherwise.
    pub free_share: Option<f64>,
    /// Descriptor matches whose source keypoint the transform puts on the other scan's
    /// surface (within two eps), whether it meets its matched keypoint or not: how much of
    /// what was matched lies in the overlap. Measured for a scene pair registered alone
    /// ([`SCENE_ODDS`]), `None` otherwise.
    pub landed: Option<usize>,
    /// Descriptor matches the transform maps within a quarter of the inlier distance (half
    /// of `support`'s), their normals agreeing; measured with `landed`.
    pub tight_support: Option<usize>,
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

impl EdgeCheck {
    /// This check without the cues only a pair registered alone measures (`free_share`,
    /// `landed`, `tight_support`): judged as a room's screened pair is, by
    /// [`SCREENED_SCENE_ODDS`].
    pub fn as_screened(&self) -> EdgeCheck {
        EdgeCheck {
            free_share: None,
            landed: None,
            tight_support: None,
            ..self.clone()
        }
    }

    /// The log-odds that this pose is right, by the weights its cues call for
    /// ([`SceneOdds::for_check`]): how two answers for the same scene pair are compared.
    pub fn scene_log_odds(&self) -> f64 {
        SceneOdds::for_check(self).log_odds(self)
    }
}

/// Measures `edge` at its transform `t_target_source` (centred frames).
pub(crate) fn check_edge(
    clouds: &[RefineCloud],
    edge: Edge,
    t_target_source: &Rigid,
    eps: f64,
) -> EdgeCheck {
    // The clouds' grids answer exactly only within their reach (three eps they were made for).
    debug_assert!(clouds.iter().all(|c| eps <= c.grid().reach()));
    // In the current rayon pool; the residuals keep the points' order whatever its size.
    let one_way = |s: usize, t: usize, to_t: Rigid| -> (usize, usize, Vec<f64>) {
        let (src, dst) = (&clouds[s], &clouds[t]);
        let residuals: Vec<f64> = src
            .points()
            .par_iter()
            .with_min_len(256)
            .filter_map(|p| {
                let q = to_t.apply(p);
                let (m, _) = dst.grid().nearest_within(&q, eps * eps).hit?;
                let (y, n) = (dst.points()[m], dst.normals()[m]);
                Some((0..3).map(|k| n[k] * (q[k] - y[k])).sum::<f64>().abs() / eps)
            })
            .collect();
        (residuals.len(), src.points().len(), residuals)
    };
    let ((a, na, mut ra), (b, nb, rb)) = rayon::join(
        || one_way(edge.source, edge.target, *t_target_source),
        || one_way(edge.target, edge.source, t_target_source.inverse()),
    );
    ra.extend(rb);
    let overlap = 0.5 * (a as f64 / na.max(1) as f64 + b as f64 / nb.max(1) as f64);
    EdgeCheck {
        source: edge.source,
        target: edge.target,
        overlap,
        residual: median(&mut ra).unwrap_or(f64::INFINITY),
        self_residual: clouds[edge.source]
            .self_residual()
            .max(clouds[edge.target].self_residual())
            / eps,
        constraint: None,
        support: None,
        rival_support: None,
        free_space: None,
        free_share: None,
        landed: None,
        tight_support: None,
    }
}

fn median(v: &mut [f64]) -> Option<f64> {
    if v.is_empty() {
        return None;
    }
    v.sort_by(f64::total_cmp);
    Some(v[v.len() / 2])
}

/// Why each edge is not trusted (`None`: trusted), see [`MIN_OVERLAP`], [`MAX_RESIDUAL`],
/// [`SELF_RESIDUAL_RATIO`] and [`RELATIVE_RESIDUAL`].
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
                    "clouds {name} overlap by {:.3} only (at least {MIN_OVERLAP} expected)",
                    e.overlap
                ))
            } else if e.residual > MAX_RESIDUAL {
                Some(format!(
                    "clouds {name} meet but do not lie on each other (residual {:.2} of eps, at most {MAX_RESIDUAL} expected)",
                    e.residual
                ))
            } else if e.residual > NEGLIGIBLE_RESIDUAL
                && e.residual > SELF_RESIDUAL_RATIO * e.self_residual
            {
                Some(format!(
                    "clouds {name} lie on each other {:.0} times less closely than each scan on itself (at most {SELF_RESIDUAL_RATIO} expected): near, but not the same surface",
                    e.residual / e.self_residual.max(f64::MIN_POSITIVE)
                ))
            } else if e.free_space.is_some_and(|f| f >= 1.0) {
                Some(format!(
                    "clouds {name}: every point of one scan lies where the other scanner saw through, or one scanner stands behind a surface the other saw: the scans cannot both be there"
                ))
            } else if let Some(why) = cue_doubt(e, &name) {
                Some(why)
            } else if e.residual > NEGLIGIBLE_RESIDUAL
                && typical.is_some_and(|m| e.residual > RELATIVE_RESIDUAL * m)
            {
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

/// The doubt from the free space, slide and feature cues. A pair with free space and feature
/// matches measured (a scene pair) has them weighed together ([`scene_doubt`]); otherwise
/// each against its own limit: free space above [`MAX_FREE_SPACE`] (a room's pairs, whose
/// matches are not measured), a slide below [`MIN_CONSTRAINT`], fewer matches than
/// [`MIN_SUPPORT`] or a rival within [`RIVAL_RATIO`] (objects, without viewpoints).
fn cue_doubt(e: &EdgeCheck, name: &str) -> Option<String> {
    if e.free_space.is_some() && e.support.is_some() {
        return scene_doubt(e, name);
    }
    if let Some(free) = e.free_space.filter(|&f| f > MAX_FREE_SPACE) {
        Some(format!(
            "clouds {name}: {:.0} % of one scan's points lie where the other scanner saw through (at most {:.0} % expected): the surfaces cannot both be there",
            100.0 * free,
            100.0 * MAX_FREE_SPACE
        ))
    } else if let Some(c) = e.constraint.filter(|&c| c < MIN_CONSTRAINT) {
        Some(format!(
            "clouds {name}: the overlapping surfaces barely hold the pose against a slide (smallest spread of their normals {c:.3}, at least {MIN_CONSTRAINT} expected): it may be shifted along them"
        ))
    } else if let Some(support) = e.support.filter(|&s| s < MIN_SUPPORT) {
        Some(format!(
            "clouds {name}: only {support} feature matches agree with the pose (at least {MIN_SUPPORT} expected)"
        ))
    } else {
        e.support
            .zip(e.rival_support)
            .filter(|&(s, r)| (s as f64) < RIVAL_RATIO * r as f64)
            .map(|(support, rival)| format!(
                "clouds {name}: another pose explains {rival} feature matches against this one's {support} (at least {RIVAL_RATIO} times fewer expected): ambiguous"
            ))
    }
}

/// The doubt of a scene pair (free space and matches measured) by [`SceneOdds::for_check`], naming the
/// cue that falls farthest below a typical confident pair's; `None` when trusted.
fn scene_doubt(e: &EdgeCheck, name: &str) -> Option<String> {
    let weights = SceneOdds::for_check(e);
    let odds = weights.log_odds(e);
    if odds >= weights.trusted_at {
        return None;
    }
    let (terms, typical) = (weights.terms(e), weights.terms(&TYPICAL_SCENE_PAIR));
    let weakest = (0..terms.len())
        .min_by(|&a, &b| (terms[a] - typical[a]).total_cmp(&(terms[b] - typical[b])))
        .unwrap_or(0);
    let support = e.support.unwrap_or(0);
    let rival = e.rival_support.unwrap_or(0);
    let cue = match weakest {
        0 => format!("only {support} feature matches agree with the pose"),
        1 => format!("another pose explains {rival} feature matches against this one's {support}"),
        2 => format!(
            "{:.0} % of one scan's points lie where the other scanner saw through",
            100.0 * e.free_space.unwrap_or(0.0)
        ),
        3 => match e.constraint {
            Some(c) => format!(
                "the overlapping surfaces barely hold the pose against a slide (smallest spread of their normals {c:.3})"
            ),
            None => "too few keypoints meet to hold the pose against a slide".to_string(),
        },
        4 => format!("the scans overlap by {:.2} only", e.overlap),
        5 => format!("the surfaces lie on each other loosely (residual {:.2} of eps)", e.residual),
        6 => format!(
            "{:.0} % of all of one scan's points lie where the other scanner saw through",
            100.0 * e.free_share.unwrap_or(0.0)
        ),
        7 => format!(
            "only {} feature matches land on the other scan",
            e.landed.unwrap_or(0)
        ),
        _ => format!(
            "only {} feature matches agree closely with the pose",
            e.tight_support.unwrap_or(0)
        ),
    };
    Some(format!(
        "clouds {name}: {cue}; with the other cues the pose is right at odds of {:.2} : 1 only (at least {:.1} : 1 expected)",
        odds.exp(),
        weights.trusted_at.exp()
    ))
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

#[cfg(test)]
mod tests {
    use super::*;

    fn edge(overlap: f64, residual: f64, self_residual: f64) -> EdgeCheck {
        EdgeCheck {
            source: 0,
            target: 1,
            overlap,
            residual,
            self_residual,
            constraint: None,
            support: None,
            rival_support: None,
            free_space: None,
            free_share: None,
            landed: None,
            tight_support: None,
        }
    }

    /// A scene pair as the records' typical confident one (free space known).
    fn scene(support: usize, rival: usize, free: f64, constraint: f64) -> EdgeCheck {
        EdgeCheck {
            support: Some(support),
            rival_support: Some(rival),
            free_space: Some(free),
            constraint: Some(constraint),
            ..edge(0.48, 0.126, 0.05)
        }
    }

    #[test]
    fn a_pose_that_puts_a_surface_in_free_space_is_doubted() {
        let d = |e: EdgeCheck| doubts(&[e]).remove(0);
        assert_eq!(d(scene(42, 0, 0.007, 0.11)), None);
        let why = d(scene(42, 0, 0.4, 0.11)).unwrap();
        assert!(why.contains("40 % of one scan's points"), "{why}");
        let why = d(scene(42, 0, 1.0, 0.11)).unwrap();
        assert!(why.contains("behind a surface the other saw"), "{why}");
        // Weighed, not a limit of its own: 10 % in free space is doubted for a pose 8
        // matches support, not for one that 150 do.
        let why = d(scene(8, 0, 0.1, 0.11)).unwrap();
        assert!(why.contains("10 % of one scan's points"), "{why}");
        assert_eq!(d(scene(150, 0, 0.1, 0.11)), None);
    }

    #[test]
    fn a_scene_pair_is_doubted_by_its_weakest_cue_and_names_it() {
        let d = |e: EdgeCheck| doubts(&[e]).remove(0);
        let why = d(scene(3, 0, 0.03, 0.05)).unwrap();
        assert!(why.contains("only 3 feature matches"), "{why}");
        let why = d(scene(15, 14, 0.02, 0.05)).unwrap();
        assert!(why.contains("another pose explains 14"), "{why}");
        let why = d(scene(20, 0, 0.007, 0.004)).unwrap();
        assert!(
            why.contains("against a slide") && why.contains("0.004"),
            "{why}"
        );
        assert!(
            why.contains("odds of 0.95 : 1 only (at least 6.4 : 1"),
            "{why}"
        );
        // The odds rise with every cue that improves.
        let base = scene(12, 2, 0.02, 0.05);
        let odds = |e: &EdgeCheck| SCREENED_SCENE_ODDS.log_odds(e);
        for better in [
            scene(13, 2, 0.02, 0.05),
            scene(12, 1, 0.02, 0.05),
            scene(12, 2, 0.01, 0.05),
            scene(12, 2, 0.02, 0.06),
            EdgeCheck {
                overlap: 0.5,
                ..base.clone()
            },
            EdgeCheck {
                residual: 0.12,
                ..base.clone()
            },
        ] {
            assert!(odds(&better) > odds(&base), "{better:?}");
        }
        // Without viewpoints the separate limits hold (objects): 12 matches are too few.
        let why = d(EdgeCheck {
            free_space: None,
            ..scene(12, 0, 0.0, 0.11)
        })
        .unwrap();
        assert!(
            why.contains("only 12 feature matches") && why.contains("at least 25"),
            "{why}"
        );
    }

    #[test]
    fn a_pose_the_overlap_does_not_hold_against_a_slide_is_doubted() {
        let d = |constraint: Option<f64>| {
            doubts(&[EdgeCheck {
                constraint,
                ..edge(0.5, 0.05, 0.03)
            }])
            .remove(0)
        };
        assert_eq!(d(None), None);
        assert_eq!(d(Some(MIN_CONSTRAINT)), None);
        assert_eq!(d(Some(0.3)), None);
        let why = d(Some(0.004)).unwrap();
        assert!(why.contains("against a slide"), "{why}");
        assert!(why.contains("0.004"), "{why}");
    }

    #[test]
    fn each_limit_doubts_its_own_case_and_only_it() {
        let d = |e: EdgeCheck| doubts(&[e]).remove(0);
        // A right fit of real scans (bunny-a, refined) and of clean synthetic ones.
        assert_eq!(d(edge(0.9, 0.042, 0.029)), None);
        assert_eq!(d(edge(0.75, 0.006, 0.006)), None);
        // Surfaces exactly on their planes: no ratio to a zero self-residual.
        assert_eq!(d(edge(0.75, 0.03, 0.0)), None);
        assert!(d(edge(0.05, 0.04, 0.03))
            .unwrap()
            .contains("overlap by 0.05"));
        assert!(d(edge(0.3, 0.36, 0.023))
            .unwrap()
            .contains("do not lie on each other"));
        // Unrelated smooth shapes: close in absolute terms, 40x their own residual.
        let why = d(edge(0.88, 0.214, 0.005)).unwrap();
        assert!(why.contains("43 times less closely"), "{why}");
    }

    #[test]
    fn a_pose_few_matches_agree_with_or_a_close_rival_is_doubted() {
        let d = |support: usize, rival: usize| {
            doubts(&[EdgeCheck {
                support: Some(support),
                rival_support: Some(rival),
                ..edge(0.5, 0.1, 0.05)
            }])
            .remove(0)
        };
        assert_eq!(d(64, 13), None);
        assert_eq!(d(MIN_SUPPORT, 0), None);
        let why = d(MIN_SUPPORT - 1, 0).unwrap();
        assert!(why.contains("only 24 feature matches"), "{why}");
        let why = d(50, 30).unwrap();
        assert!(why.contains("another pose explains 30"), "{why}");
        assert_eq!(d(60, 30), None);
        // No feature matching (in a loop, or without hypotheses): no such doubt.
        assert_eq!(doubts(&[edge(0.5, 0.1, 0.05)]).remove(0), None);
    }

    #[test]
    fn one_edge_far_worse_than_the_others_is_doubted() {
        let edges = [
            edge(0.8, 0.02, 0.01),
            edge(0.8, 0.021, 0.01),
            edge(0.8, 0.095, 0.01),
        ];
        let d = doubts(&edges);
        assert_eq!((d[0].is_some(), d[1].is_some()), (false, false));
        assert!(d[2].as_ref().unwrap().contains("far less closely"), "{d:?}");
        // Scans lying exactly on their planes (synthetic ones) have residuals of rounding
        // error, whose ratios mean nothing.
        let exact = [
            edge(0.8, 1e-17, 0.0),
            edge(0.8, 2e-17, 0.0),
            edge(0.8, 3e-16, 0.0),
        ];
        assert!(
            doubts(&exact).iter().all(Option::is_none),
            "{:?}",
            doubts(&exact)
        );
    }

    #[test]
    fn a_scene_pair_at_best_is_never_below_its_log_odds() {
        // Whatever the overlap and residual measure, the bound holds, and it is reached.
        let mut reached = false;
        for (support, rival, free, constraint) in [
            (3, 2, 0.2, 0.01),
            (42, 0, 0.007, 0.11),
            (8, 6, 0.1, 0.05),
            (150, 0, 0.0, 0.3),
        ] {
            let cues = scene(support, rival, free, constraint);
            let best = SCREENED_SCENE_ODDS.at_best(&cues);
            for overlap in [0.0, 0.1, 0.48, 1.0] {
                for residual in [0.0, 0.05, 0.126, 0.25, 3.0] {
                    let odds = SCREENED_SCENE_ODDS.log_odds(&EdgeCheck {
                        overlap,
                        residual,
                        ..cues.clone()
                    });
                    assert!(odds <= best + 1e-12, "{odds} > {best}");
                    reached |= (odds - best).abs() < 1e-12;
                }
            }
        }
        assert!(reached);
        // A pose that few matches explain and that puts a fifth in free space is doubted
        // whatever its surfaces; the typical confident pair is not.
        assert!(
            SCREENED_SCENE_ODDS.at_best(&scene(3, 2, 0.2, 0.01)) < SCREENED_SCENE_ODDS.trusted_at
        );
        assert!(
            SCREENED_SCENE_ODDS.at_best(&scene(42, 0, 0.007, 0.11))
                >= SCREENED_SCENE_ODDS.trusted_at
        );
    }

    #[test]
    fn a_pair_registered_alone_is_weighed_with_its_matches_landing_and_its_free_share() {
        // A check with the matches' landing measured is weighed by the nine cues, one without
        // by the six.
        let alone = |free_share: f64, landed: usize, tight: usize| EdgeCheck {
            free_share: Some(free_share),
            landed: Some(landed),
            tight_support: Some(tight),
            ..scene(42, 0, 0.007, 0.11)
        };
        assert_eq!(SceneOdds::for_check(&alone(0.0, 1763, 9)), &SCENE_ODDS);
        assert_eq!(
            SceneOdds::for_check(&alone(0.0, 1763, 9).as_screened()),
            &SCREENED_SCENE_ODDS
        );
        assert_eq!(
            SceneOdds::for_check(&scene(42, 0, 0.007, 0.11)),
            &SCREENED_SCENE_ODDS
        );
        let d = |e: EdgeCheck| doubts(&[e]).remove(0);
        // The typical confident pair is trusted; the same pose with a tenth of all its points
        // in the other's free space is not, and the reason names that cue.
        assert_eq!(d(alone(0.002, 1763, 9)), None);
        let why = d(alone(0.1, 1763, 9)).unwrap();
        assert!(why.contains("10 % of all of one scan's points"), "{why}");
        let why = d(EdgeCheck {
            support: Some(12),
            ..alone(0.002, 5, 1)
        })
        .unwrap();
        assert!(
            why.contains("feature matches land on the other scan"),
            "{why}"
        );
        // The odds rise with every new cue that improves.
        let base = alone(0.02, 300, 3);
        let odds = |e: &EdgeCheck| SceneOdds::for_check(e).log_odds(e);
        for better in [
            alone(0.01, 300, 3),
            alone(0.02, 400, 3),
            alone(0.02, 300, 4),
        ] {
            assert!(odds(&better) > odds(&base), "{better:?}");
        }
    }
}
