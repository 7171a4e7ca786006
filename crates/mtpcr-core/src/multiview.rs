//! Scans in no known order: find which pairs overlap, keep the pair poses that agree around
//! three-view loops, place every scan by a spanning tree of the verified pairs, and refine
//! all scans jointly.
//!
//! 1. **Screening**: every pair gets up to `hypotheses` pose hypotheses from the clouds'
//!    features, each scored by the original task's inlier fraction (the pair's overlap).
//! 2. **Verification**: for every triangle of scans, the combination of one hypothesis per
//!    side whose loop product is near the identity (the paper's three-view loop as a
//!    verifier) votes for its three hypotheses. A pair is verified when one hypothesis has a
//!    vote and passes the verdict's surface test (`crate::verdict`); that one is its pose.
//! 3. **Placement**: a maximum spanning tree of the verified pairs (by overlap) from the first
//!    scan places every scan it reaches; verified pairs that agree with the tree and overlap
//!    well are loop closures. Scans the tree does not reach are reported unplaced, with the
//!    reason.
//! 4. **Refinement**: the joint ICP of all placed scans over the tree and the closures.

use crate::config::Config;
use crate::error::{Error, Result};
use crate::graph::Edge;
use crate::loss::Loss;
use crate::problem::PreparedProblem;
use crate::refine::refine_poses;
use crate::result::{EdgeEstimate, Registration, Unplaced};
use crate::se3::{invert_rigid, rotation_error_deg, translation_error, Rigid, Transform};
use crate::verdict::{check_edge, doubts, judge, EdgeCheck, MAX_RESIDUAL, MIN_OVERLAP};
use rayon::prelude::*;

/// Hypotheses per pair compared around each triangle.
const PER_SIDE: usize = 5;
/// A triangle of poses closes when its loop product turns by less than this...
const LOOP_DEGREES: f64 = 5.0;
/// ...and moves by less than this fraction of the largest cloud side.
const LOOP_SHIFT_FRACTION: f64 = 0.05;
/// A verified pair outside the tree is a loop closure when it agrees with the tree's poses
/// this well (degrees; translation as [`LOOP_SHIFT_FRACTION`]).
const CLOSURE_DEGREES: f64 = 5.0;
/// ...and overlap at least this much. Weakly overlapping pairs bias the joint ICP: on
/// dragon-all (15 scans) the worst scan is 1.20 degrees off with every agreeing pair, 0.78
/// with pairs of overlap >= 0.3, 0.51 with >= 0.5; on bunny-all 0.31 / 0.29 / 0.20.
const CLOSURE_MIN_OVERLAP: f64 = 0.5;

/// One pair's hypotheses (centred frames, source -> target), best overlap first.
struct Pair {
    edge: Edge,
    /// `(pose, overlap)`: overlap = 1 - the original task's local loss.
    poses: Vec<(Transform, f64)>,
}

/// Rounds of placement: a pair whose fit fails at the refined poses is rejected and the
/// spanning tree built again without it.
const MAX_ROUNDS: usize = 4;

/// Registers the prepared clouds (a general graph; its edges are ignored) as an unordered
/// set. Needs feature hypotheses (`config.hypotheses > 0`).
pub(crate) fn register_unordered(
    prepared: &PreparedProblem,
    config: &Config,
    pool: &rayon::ThreadPool,
    seed: u64,
) -> Result<Registration> {
    let start = std::time::Instant::now();
    if config.hypotheses == 0 {
        return Err(Error::config(
            "hypotheses",
            "must be at least 1 to register scans in no known order (or give them in loop order)",
        ));
    }
    let n = prepared.clouds().len();
    let pairs = screen(prepared, config.hypotheses, pool)?;
    prepared.interrupt().check()?;
    let tolerance = loop_tolerance(prepared);
    let chosen = verify(&pairs, n, tolerance);
    // A verified pose must also pass the verdict's surface test.
    let mut rejected: Vec<bool> = pool.install(|| {
        (0..pairs.len())
            .into_par_iter()
            .map(|p| {
                chosen[p].is_none_or(|h| {
                    let c = check_edge(
                        prepared.refine_clouds(),
                        pairs[p].edge,
                        &Rigid::from_matrix(&pairs[p].poses[h].0),
                        prepared.eps(),
                    );
                    !(c.overlap >= MIN_OVERLAP && c.residual <= MAX_RESIDUAL)
                })
            })
            .collect()
    });
    let mut dropped: Vec<(usize, String)> = Vec::new();
    let mut round = 0;
    let (placed, used, refined) = loop {
        round += 1;
        let (mut placed, mut used, poses) = place(&pairs, &chosen, &rejected, n, tolerance);
        let refined = refine_placed(prepared, config, pool, &pairs, &used, &placed, &poses);
        prepared.interrupt().check()?;
        let checks: Vec<EdgeCheck> = used
            .iter()
            .map(|&p| measure(prepared, &pairs[p], &refined))
            .collect();
        let failing: Vec<usize> = used
            .iter()
            .zip(doubts(&checks))
            .filter(|(_, d)| d.is_some())
            .map(|(&p, _)| p)
            .collect();
        if failing.is_empty() {
            break (placed, used, refined);
        }
        for &p in &failing {
            rejected[p] = true;
        }
        if round < MAX_ROUNDS {
            continue;
        }
        // Last round: drop the failing pairs and the scans only they connected.
        used.retain(|p| !failing.contains(p));
        let reach = reachable(&pairs, &used, n);
        used.retain(|&p| reach[pairs[p].edge.source] && reach[pairs[p].edge.target]);
        for v in 0..n {
            if placed[v] && !reach[v] {
                placed[v] = false;
                dropped.push((
                    v,
                    format!(
                        "scan {}'s fit to the others did not hold at fine scale (its surfaces do not lie on theirs)",
                        v + 1
                    ),
                ));
            }
        }
        let refined = refine_placed(prepared, config, pool, &pairs, &used, &placed, &poses);
        break (placed, used, refined);
    };

    let edges: Vec<EdgeEstimate> = used
        .iter()
        .map(|&p| {
            let Edge {
                source: s,
                target: t,
            } = pairs[p].edge;
            let (ws, wt) = (refined[s].expect("placed"), refined[t].expect("placed"));
            let centred = invert_rigid(&wt) * ws;
            let r = Rigid::from_matrix(&centred);
            EdgeEstimate {
                source: s,
                target: t,
                t_target_source: prepared.to_original(s, t, &centred),
                original_cost: prepared.inlier_loss(s, t).evaluate(&r),
                aiding_cost: prepared
                    .pair_aiding_loss(s, t, config.two_way_aiding)
                    .evaluate(&r),
            }
        })
        .collect();
    let checks = used
        .iter()
        .map(|&p| measure(prepared, &pairs[p], &refined))
        .collect();
    let unplaced: Vec<Unplaced> = (0..n)
        .filter(|&v| !placed[v])
        .map(|v| Unplaced {
            view: v,
            reason: dropped.iter().find(|(d, _)| *d == v).map_or_else(
                || unplaced_reason(v, &pairs, &chosen, &rejected),
                |(_, r)| r.clone(),
            ),
        })
        .collect();
    let poses = (0..n)
        .map(|v| {
            refined[v]
                .filter(|_| placed[v])
                .map(|w| prepared.to_original(v, 0, &w))
        })
        .collect();
    let reasons = unplaced
        .iter()
        .map(|u| format!("cloud {} is not placed", u.view + 1))
        .collect();
    let verdict = judge(checks, reasons);
    Ok(Registration {
        edges,
        poses,
        unplaced,
        verdict,
        task_names: Vec::new(),
        history: Vec::new(),
        restart_histories: Vec::new(),
        kept_restart: 0,
        sampled_points: prepared.clouds().iter().map(|c| c.points().len()).collect(),
        evaluations: pairs.iter().map(|p| p.poses.len()).sum(),
        generations_run: 0,
        restarts_run: 0,
        completed: true,
        seconds: start.elapsed().as_secs_f64(),
        seed,
        eps: prepared.eps(),
        shift: prepared.shift(),
    })
}

/// The verdict's measures of a pair at refined poses.
fn measure(prepared: &PreparedProblem, pair: &Pair, refined: &[Option<Transform>]) -> EdgeCheck {
    let Edge {
        source: s,
        target: t,
    } = pair.edge;
    let (ws, wt) = (refined[s].expect("placed"), refined[t].expect("placed"));
    check_edge(
        prepared.refine_clouds(),
        pair.edge,
        &Rigid::from_matrix(&(invert_rigid(&wt) * ws)),
        prepared.eps(),
    )
}

/// The scans connected to scan 0 through the `used` pairs.
fn reachable(pairs: &[Pair], used: &[usize], n: usize) -> Vec<bool> {
    let mut reach = vec![false; n];
    reach[0] = true;
    let mut grew = true;
    while grew {
        grew = false;
        for &p in used {
            let Edge {
                source: s,
                target: t,
            } = pairs[p].edge;
            if reach[s] != reach[t] {
                reach[s] = true;
                reach[t] = true;
                grew = true;
            }
        }
    }
    reach
}

/// The maximum spanning tree (by overlap) of the verified, not rejected pairs from scan 0:
/// which scans it places, the pairs used (tree and agreeing, well-overlapping closures) and
/// the poses (centred, into scan 0's frame) along the tree.
fn place(
    pairs: &[Pair],
    chosen: &[Option<usize>],
    rejected: &[bool],
    n: usize,
    tolerance: f64,
) -> (Vec<bool>, Vec<usize>, Vec<Option<Transform>>) {
    let pose_of = |p: usize| pairs[p].poses[chosen[p].expect("verified")];
    let mut order: Vec<usize> = (0..pairs.len())
        .filter(|&p| chosen[p].is_some() && !rejected[p])
        .collect();
    order.sort_by(|&a, &b| pose_of(b).1.total_cmp(&pose_of(a).1).then(a.cmp(&b)));
    let mut component: Vec<usize> = (0..n).collect();
    fn find(c: &mut [usize], v: usize) -> usize {
        let mut r = v;
        while c[r] != r {
            r = c[r];
        }
        c[v] = r;
        r
    }
    let mut tree = Vec::new();
    for &p in &order {
        let (a, b) = (
            find(&mut component, pairs[p].edge.source),
            find(&mut component, pairs[p].edge.target),
        );
        if a != b {
            component[a.max(b)] = a.min(b);
            tree.push(p);
        }
    }
    let root = find(&mut component, 0);
    let placed: Vec<bool> = (0..n).map(|v| find(&mut component, v) == root).collect();
    let mut poses: Vec<Option<Transform>> = vec![None; n];
    poses[0] = Some(Transform::identity());
    let mut grew = true;
    while grew {
        grew = false;
        for &p in &tree {
            let Edge {
                source: s,
                target: t,
            } = pairs[p].edge;
            let t_ts = pose_of(p).0;
            match (poses[s], poses[t]) {
                (Some(ws), None) => {
                    poses[t] = Some(ws * invert_rigid(&t_ts));
                    grew = true;
                }
                (None, Some(wt)) => {
                    poses[s] = Some(wt * t_ts);
                    grew = true;
                }
                _ => {}
            }
        }
    }
    let mut used = tree.clone();
    for &p in &order {
        if tree.contains(&p) || pose_of(p).1 < CLOSURE_MIN_OVERLAP {
            continue;
        }
        let Edge {
            source: s,
            target: t,
        } = pairs[p].edge;
        if let (Some(ws), Some(wt)) = (poses[s], poses[t]) {
            let implied = invert_rigid(&wt) * ws;
            let own = pose_of(p).0;
            if rotation_error_deg(&implied, &own) < CLOSURE_DEGREES
                && translation_error(&implied, &own) < tolerance
            {
                used.push(p);
            }
        }
    }
    used.sort_unstable();
    (placed, used, poses)
}

/// The poses (centred, into scan 0's frame) of the placed scans after the joint ICP over the
/// `used` pairs (the start poses when refinement is off); `None` for the others.
fn refine_placed(
    prepared: &PreparedProblem,
    config: &Config,
    pool: &rayon::ThreadPool,
    pairs: &[Pair],
    used: &[usize],
    placed: &[bool],
    poses: &[Option<Transform>],
) -> Vec<Option<Transform>> {
    let n = placed.len();
    let mut all: Vec<Option<Transform>> = (0..n).map(|v| poses[v].filter(|_| placed[v])).collect();
    if config.refine_iterations == 0 {
        return all;
    }
    let full = prepared.refine_clouds();
    let index: Vec<usize> = (0..n).filter(|&v| placed[v]).collect();
    let local = |v: usize| index.iter().position(|&x| x == v).expect("placed");
    let clouds: Vec<_> = index.iter().map(|&v| &full[v]).collect();
    let edges: Vec<Edge> = used
        .iter()
        .map(|&p| Edge {
            source: local(pairs[p].edge.source),
            target: local(pairs[p].edge.target),
        })
        .collect();
    let start_poses: Vec<Rigid> = index
        .iter()
        .map(|&v| Rigid::from_matrix(&poses[v].expect("placed")))
        .collect();
    let interrupt = prepared.interrupt();
    let out = refine_poses(
        &clouds,
        &edges,
        start_poses,
        prepared.eps(),
        config.refine_iterations,
        pool,
        &|| interrupt.is_set(),
    );
    for (k, &v) in index.iter().enumerate() {
        all[v] = Some(out[k].to_matrix());
    }
    all
}

/// Every pair's hypotheses, scored by overlap, in parallel (results in pair order).
fn screen(prepared: &PreparedProblem, count: usize, pool: &rayon::ThreadPool) -> Result<Vec<Pair>> {
    let n = prepared.clouds().len();
    let edges: Vec<Edge> = (0..n)
        .flat_map(|s| {
            (s + 1..n).map(move |t| Edge {
                source: s,
                target: t,
            })
        })
        .collect();
    pool.install(|| {
        edges
            .par_iter()
            .map(|&edge| {
                let loss = prepared.inlier_loss(edge.source, edge.target);
                let mut poses: Vec<(Transform, f64)> = prepared
                    .hypotheses(edge.source, edge.target, count)?
                    .iter()
                    .map(|r| (r.to_matrix(), 1.0 - loss.evaluate(r)))
                    .collect();
                poses.sort_by(|a, b| b.1.total_cmp(&a.1));
                Ok(Pair { edge, poses })
            })
            .collect()
    })
}

/// For each pair, the hypothesis its triangles vote for (`None`: no triangle closes with it).
fn verify(pairs: &[Pair], n: usize, tolerance: f64) -> Vec<Option<usize>> {
    let index = |a: usize, b: usize| -> usize {
        // Pairs are listed (0,1), (0,2), ..., (1,2), ...: the position of (a, b), a < b.
        a * (2 * n - a - 1) / 2 + (b - a - 1)
    };
    let mut votes: Vec<Vec<f64>> = pairs.iter().map(|p| vec![0.0; p.poses.len()]).collect();
    for i in 0..n {
        for j in i + 1..n {
            for k in j + 1..n {
                let (ij, jk, ik) = (index(i, j), index(j, k), index(i, k));
                let best = best_closing_triple(
                    &pairs[ij].poses,
                    &pairs[jk].poses,
                    &pairs[ik].poses,
                    tolerance,
                );
                if let Some((score, [a, b, c])) = best {
                    votes[ij][a] += score;
                    votes[jk][b] += score;
                    votes[ik][c] += score;
                }
            }
        }
    }
    votes
        .iter()
        .map(|v| {
            v.iter()
                .enumerate()
                .filter(|(_, w)| **w > 0.0)
                .max_by(|a, b| a.1.total_cmp(b.1).then(b.0.cmp(&a.0)))
                .map(|(h, _)| h)
        })
        .collect()
}

/// Among the first [`PER_SIDE`] hypotheses `(pose, overlap)` of three pairs i -> j, j -> k
/// and i -> k, the combination that closes the loop (`T_kj T_ji ~ T_ki`) with the highest
/// total overlap: `(total, [a, b, c])` indices into the three lists.
pub(crate) fn best_closing_triple(
    ij: &[(Transform, f64)],
    jk: &[(Transform, f64)],
    ik: &[(Transform, f64)],
    tolerance: f64,
) -> Option<(f64, [usize; 3])> {
    let mut best: Option<(f64, [usize; 3])> = None;
    for (a, (t_ji, oa)) in ij.iter().take(PER_SIDE).enumerate() {
        for (b, (t_kj, ob)) in jk.iter().take(PER_SIDE).enumerate() {
            let via_j = t_kj * t_ji;
            for (c, (t_ki, oc)) in ik.iter().take(PER_SIDE).enumerate() {
                if rotation_error_deg(&via_j, t_ki) < LOOP_DEGREES
                    && translation_error(&via_j, t_ki) < tolerance
                {
                    let score = oa + ob + oc;
                    if best.is_none_or(|(s, _)| score > s) {
                        best = Some((score, [a, b, c]));
                    }
                }
            }
        }
    }
    best
}

/// The loop-closing tolerance on translations for a problem (a fraction of its shift).
pub(crate) fn loop_tolerance(prepared: &PreparedProblem) -> f64 {
    LOOP_SHIFT_FRACTION * prepared.shift()
}

/// Why scan `v` could not be placed.
fn unplaced_reason(
    v: usize,
    pairs: &[Pair],
    chosen: &[Option<usize>],
    rejected: &[bool],
) -> String {
    let mine: Vec<usize> = (0..pairs.len())
        .filter(|&p| pairs[p].edge.source == v || pairs[p].edge.target == v)
        .collect();
    let best = mine
        .iter()
        .filter_map(|&p| pairs[p].poses.first().map(|h| h.1))
        .fold(0.0, f64::max);
    if mine.iter().any(|&p| chosen[p].is_some() && !rejected[p]) {
        format!(
            "scan {} overlaps others only in a group not connected to scan 1",
            v + 1
        )
    } else {
        format!(
            "no pose of scan {} against another scan was confirmed by a three-scan loop (best overlap found {:.2})",
            v + 1,
            best
        )
    }
}
