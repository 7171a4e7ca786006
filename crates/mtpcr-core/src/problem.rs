//! Preparation: the clouds of a view graph downsampled, centred and indexed once, with the
//! inlier radius eps and the translation bound shift, ready to be searched with any seed or
//! evolution setting.

use crate::cloud::{PointCloud, Sampling};
use crate::config::{Config, Order};
use crate::error::{Error, Result};
use crate::features::{describe, FeatureConfig, Features, PairMatches};
use crate::freespace::{free_share, rough_violation, violation, FreeSpace};
use crate::graph::{Edge, ViewGraph};
use crate::interrupt::Interrupt;
use crate::loss::{CappedDistanceLoss, InlierLoss, Loss};
use crate::refine::RefineCloud;
use crate::se3::{translation, Rigid, Transform};
use crate::search::{IndexedCloud, NearestGrid, SearchMethod};
use crate::verdict::{check_edge, EdgeCheck, SceneOdds, HYPOTHESIS_FREE_SPACE, SEARCH_FREE_SPACE};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use std::time::Instant;

/// Fewest points a cloud may have (and fewest kept by downsampling).
pub const MIN_POINTS: usize = 10;
/// With `max_sample_points`, farthest-point sampling starts from an even subset of at most
/// this many times the sample (the farthest points of a dense scan are the same, and the
/// cost no longer grows with the scan's size). 4 samples bunny-a in a third of the time
/// (0.03 s against 0.08 s) but lost a 48-degree triple (dragon48-k00, seed 2) that 16 keeps.
const PRE_SAMPLE: usize = 16;

/// The clouds of a view graph, downsampled, centred and indexed (see the module docs).
#[derive(Debug)]
pub struct PreparedProblem {
    graph: ViewGraph,
    clouds: Vec<IndexedCloud>,
    /// Full-resolution centred surface points for the refinement and the verdict.
    full: Vec<RefineCloud>,
    centroids: Vec<[f64; 3]>,
    eps: f64,
    shift: f64,
    sample_ratio: f64,
    max_sample_points: usize,
    sampling: Sampling,
    search: SearchMethod,
    aiding_cap_ratio: f64,
    /// Keypoint features of each centred full-resolution cloud (only with hypotheses).
    features: Option<(FeatureConfig, Vec<Features>)>,
    /// The centred full-resolution clouds (only with hypotheses and a viewpoint): the second
    /// look of a doubted pair or of a room's bridge describes them again at finer keypoints
    /// ([`PreparedProblem::pair_hypotheses_finer`]).
    pair_points: Option<Vec<Vec<[f64; 3]>>>,
    /// What each scanner saw through (centred frames); empty when no scan has a viewpoint.
    free_space: Vec<FreeSpace>,
    feature_voxel_ratio: f64,
    /// Checked between the steps of preparing and registering.
    interrupt: Interrupt,
    seconds: f64,
}

/// The second look of a doubted pair describes its scans at keypoints this many times as far
/// apart as the first look's ([`PreparedProblem::pair_hypotheses_finer`]). Finer keypoints
/// alone register about as many pairs (every visible 3DLoMatch pair: 52.2 % against 52.0),
/// but not the same ones (113 gained, 111 lost): RESULTS.md, 2026-12-05, fourth session.
pub(crate) const FINER_KEYPOINTS: f64 = 0.75;

/// A descriptor match has landed on the other scan ([`EdgeCheck::landed`]) when its source
/// keypoint lies within this many eps of that scan's surface.
const LANDED_EPS: f64 = 2.0;

/// Keypoints of two scans meet (for [`PreparedProblem::slide_constraint`]) within this many
/// keypoint voxels...
const SLIDE_RADIUS_VOXELS: f64 = 1.5;
/// ...and the constraint is measured only where at least this many meet.
const SLIDE_MIN_MATCHES: usize = 10;

impl PreparedProblem {
    /// Prepares clouds as `config.order` says: two clouds are one pair, three (or more in
    /// `given` order) a ring ([`ViewGraph::for_views`]), four or more in `auto` order a set
    /// with no known edges ([`ViewGraph::general`]).
    pub fn new(clouds: &[PointCloud], config: &Config) -> Result<PreparedProblem> {
        PreparedProblem::new_with_interrupt(clouds, config, Interrupt::new())
    }

    /// [`PreparedProblem::new`] that stops once `interrupt` is set.
    pub fn new_with_interrupt(
        clouds: &[PointCloud],
        config: &Config,
        interrupt: Interrupt,
    ) -> Result<PreparedProblem> {
        let graph = match (config.order, clouds.len()) {
            (Order::Auto, n) if n >= 4 => ViewGraph::general(n, Vec::new())?,
            (_, n) => ViewGraph::for_views(n)?,
        };
        PreparedProblem::with_interrupt(clouds, graph, config, interrupt)
    }

    /// Validates the clouds and the config, downsamples (random sampling uses `config.seed`, or
    /// 0 without one), centres, derives eps and shift, and builds the search structures.
    pub fn with_graph(
        clouds: &[PointCloud],
        graph: ViewGraph,
        config: &Config,
    ) -> Result<PreparedProblem> {
        PreparedProblem::with_interrupt(clouds, graph, config, Interrupt::new())
    }

    /// [`PreparedProblem::with_graph`] that stops with [`Error::Interrupted`] once
    /// `interrupt` is set (checked during preparation and by every later registration of
    /// this problem).
    pub fn with_interrupt(
        clouds: &[PointCloud],
        graph: ViewGraph,
        config: &Config,
        interrupt: Interrupt,
    ) -> Result<PreparedProblem> {
        let start = Instant::now();
        config.validate()?;
        if clouds.len() != graph.views() {
            return Err(Error::InvalidInput(format!(
                "{} clouds given for a view graph of {} views",
                clouds.len(),
                graph.views()
            )));
        }
        for (i, c) in clouds.iter().enumerate() {
            c.validate(&format!("cloud {}", i + 1), MIN_POINTS)?;
        }
        let pool = thread_pool(config.num_threads)?;
        let stop = || interrupt.is_set();
        let sampled: Vec<Option<PointCloud>> = pool.install(|| {
            use rayon::prelude::*;
            clouds
                .par_iter()
                .enumerate()
                .map(|(i, c)| {
                    let mut count = ((c.len() as f64 * config.sample_ratio).round() as usize)
                        .max(MIN_POINTS)
                        .min(c.len());
                    if config.max_sample_points > 0 {
                        count = count.min(config.max_sample_points.max(MIN_POINTS));
                    }
                    match config.sampling {
                        // With a cap, a huge cloud is first thinned to an even stride subset
                        // of PRE_SAMPLE times the sample, so sampling costs the same at any
                        // input size.
                        Sampling::Farthest
                            if config.max_sample_points > 0 && c.len() > PRE_SAMPLE * count =>
                        {
                            let stride = c.len().div_ceil(PRE_SAMPLE * count);
                            let thin: Vec<usize> = (0..c.len()).step_by(stride).collect();
                            let thin = c.select(&thin);
                            let picked = thin.farthest_point_indices_until(count, &stop)?;
                            Some(thin.select(&picked))
                        }
                        Sampling::Farthest => {
                            Some(c.select(&c.farthest_point_indices_until(count, &stop)?))
                        }
                        Sampling::Random => {
                            let seed = config.seed.unwrap_or(0) ^ (0x5eed_0000 + i as u64);
                            Some(c.random_sample(count, &mut ChaCha8Rng::seed_from_u64(seed)))
                        }
                    }
                })
                .collect()
        });
        let sampled: Vec<PointCloud> = sampled
            .into_iter()
            .collect::<Option<_>>()
            .ok_or(Error::Interrupted)?;
        // Stray points (far from every surface) would stretch the extent, eps and the
        // search box; farthest-point sampling always keeps them, so drop them here.
        let sampled: Vec<PointCloud> = pool.install(|| {
            use rayon::prelude::*;
            sampled.par_iter().map(|c| c.without_strays().0).collect()
        });
        let centroids: Vec<[f64; 3]> = sampled.iter().map(PointCloud::centroid).collect();
        let centred: Vec<PointCloud> = sampled
            .iter()
            .zip(&centroids)
            .map(|(c, m)| c.translated([-m[0], -m[1], -m[2]]))
            .collect();
        for (i, c) in centred.iter().enumerate() {
            c.validate(&format!("cloud {} after downsampling", i + 1), 2)?;
        }
        let spacings: Vec<f64> = pool.install(|| {
            use rayon::prelude::*;
            centred
                .par_iter()
                .map(PointCloud::mean_nearest_neighbor_distance)
                .collect()
        });
        let d = spacings.iter().sum::<f64>() / centred.len() as f64;
        let eps = std::f64::consts::FRAC_1_SQRT_2 * d;
        let shift = centred
            .iter()
            .map(PointCloud::largest_side)
            .fold(0.0, f64::max);
        if !(eps > 0.0 && shift > 0.0) {
            return Err(Error::DegenerateCloud {
                cloud: "the downsampled clouds".to_string(),
            });
        }
        let cap = config.aiding_cap_ratio * shift;
        let search = config.search;
        let indexed: Vec<IndexedCloud> = pool.install(|| {
            use rayon::prelude::*;
            centred
                .into_par_iter()
                .map(|c| IndexedCloud::new(c.into_points(), eps, cap, search))
                .collect()
        });
        // The refinement's surface points: also what the verdict measures, so always built.
        let full = pool.install(|| {
            use rayon::prelude::*;
            clouds
                .par_iter()
                .zip(&centroids)
                .map(|(c, m)| {
                    RefineCloud::new(c.translated([-m[0], -m[1], -m[2]]).into_points(), eps)
                })
                .collect()
        });
        interrupt.check()?;
        let (features, pair_points) = if config.hypotheses > 0 {
            let full: Vec<Vec<[f64; 3]>> = clouds
                .iter()
                .zip(&centroids)
                .map(|(c, m)| c.translated([-m[0], -m[1], -m[2]]).into_points())
                .collect();
            // The keypoint spacing follows the size of the samples (stray points removed).
            let centred_samples: Vec<PointCloud> = sampled
                .iter()
                .zip(&centroids)
                .map(|(c, m)| c.translated([-m[0], -m[1], -m[2]]))
                .collect();
            let refs: Vec<&[[f64; 3]]> = centred_samples.iter().map(PointCloud::points).collect();
            let feature_config = FeatureConfig::for_clouds(&refs, config.feature_voxel_ratio)?;
            let described: Vec<Features> = pool.install(|| {
                use rayon::prelude::*;
                full.par_iter()
                    .map(|c| describe(c, &feature_config))
                    .collect::<Result<_>>()
            })?;
            // Only where a second look can happen (a doubted pair, a room's bridges; see
            // `register`): not for objects.
            let second_look = clouds.iter().any(|c| c.viewpoint().is_some());
            let kept = second_look.then_some(full);
            (Some((feature_config, described)), kept)
        } else {
            (None, None)
        };
        let free_space = if clouds.iter().any(|c| c.viewpoint().is_some()) {
            pool.install(|| {
                use rayon::prelude::*;
                clouds
                    .par_iter()
                    .zip(&centroids)
                    .map(|(c, m)| {
                        let c = c.translated([-m[0], -m[1], -m[2]]);
                        FreeSpace::new(c.points(), c.viewpoint())
                    })
                    .collect()
            })
        } else {
            Vec::new()
        };
        Ok(PreparedProblem {
            graph,
            free_space,
            clouds: indexed,
            full,
            centroids,
            eps,
            shift,
            sample_ratio: config.sample_ratio,
            max_sample_points: config.max_sample_points,
            sampling: config.sampling,
            search,
            aiding_cap_ratio: config.aiding_cap_ratio,
            features,
            pair_points,
            feature_voxel_ratio: config.feature_voxel_ratio,
            interrupt,
            seconds: start.elapsed().as_secs_f64(),
        })
    }

    /// The view graph.
    pub fn graph(&self) -> &ViewGraph {
        &self.graph
    }

    /// The prepared (downsampled, centred) clouds.
    pub fn clouds(&self) -> &[IndexedCloud] {
        &self.clouds
    }

    /// Inlier radius `sqrt(2)/2 * d`.
    pub fn eps(&self) -> f64 {
        self.eps
    }

    /// Largest bounding-box side of the prepared clouds (the translation bound).
    pub fn shift(&self) -> f64 {
        self.shift
    }

    /// Cloud `v`'s centroid (subtracted from its points when preparing).
    pub(crate) fn centroid(&self, v: usize) -> [f64; 3] {
        self.centroids[v]
    }

    /// Cloud `v`'s keypoint features (`None` when prepared without hypotheses).
    pub(crate) fn features_of(&self, v: usize) -> Option<&Features> {
        self.features.as_ref().map(|(_, f)| &f[v])
    }

    /// The flag this problem's registrations stop on.
    pub(crate) fn interrupt(&self) -> &Interrupt {
        &self.interrupt
    }

    /// Seconds spent preparing.
    pub fn seconds(&self) -> f64 {
        self.seconds
    }

    /// The full-resolution surface points of the refinement and the verdict.
    pub(crate) fn refine_clouds(&self) -> &[RefineCloud] {
        &self.full
    }

    /// The losses of edge `edge` for a transform given in the ORIGINAL frames:
    /// `(aiding loss, original local loss)` (the loop term needs the other edges and is left
    /// out). `two_way` selects the two-directional aiding loss.
    pub fn edge_losses(&self, edge: usize, t: &Transform, two_way: bool) -> (f64, f64) {
        let e = self.graph.edges()[edge];
        let inner = Rigid::from_matrix(&self.to_centred(e.source, e.target, t));
        let aiding = self.aiding_loss(edge, two_way).evaluate(&inner);
        let original = self.inlier_loss(e.source, e.target).evaluate(&inner);
        (aiding, original)
    }

    /// The original task's local loss between two prepared clouds.
    pub(crate) fn inlier_loss(&self, source: usize, target: usize) -> InlierLoss<'_> {
        InlierLoss {
            source: &self.clouds[source],
            target: &self.clouds[target],
        }
    }

    /// The aiding loss of an edge.
    pub(crate) fn aiding_loss(&self, edge: usize, two_way: bool) -> CappedDistanceLoss<'_> {
        let e = self.graph.edges()[edge];
        self.pair_aiding_loss(e.source, e.target, two_way)
    }

    /// The aiding loss between two prepared clouds.
    pub(crate) fn pair_aiding_loss(
        &self,
        source: usize,
        target: usize,
        two_way: bool,
    ) -> CappedDistanceLoss<'_> {
        CappedDistanceLoss {
            source: &self.clouds[source],
            target: &self.clouds[target],
            two_way,
        }
    }

    /// Fails with the name of the first preparation setting of `config` that differs from the
    /// one this problem was prepared with.
    pub(crate) fn check_prepared_with(&self, config: &Config) -> Result<()> {
        let differs = [
            ("sample_ratio", config.sample_ratio != self.sample_ratio),
            (
                "max_sample_points",
                config.max_sample_points != self.max_sample_points,
            ),
            ("sampling", config.sampling != self.sampling),
            ("search", config.search != self.search),
            (
                "aiding_cap_ratio",
                config.aiding_cap_ratio != self.aiding_cap_ratio,
            ),
            (
                "hypotheses",
                (config.hypotheses > 0) != self.features.is_some(),
            ),
            (
                "feature_voxel_ratio",
                self.features.is_some() && config.feature_voxel_ratio != self.feature_voxel_ratio,
            ),
        ];
        match differs.iter().find(|(_, d)| *d) {
            Some((field, _)) => Err(Error::config(
                field,
                "differs from the value this problem was prepared with; prepare it again",
            )),
            None => Ok(()),
        }
    }

    /// The descriptor matches of a pair and its candidate poses from them (centred frames,
    /// at most `count`, best first, searched as `search` says); `None` without features.
    pub(crate) fn pair_hypotheses(
        &self,
        source: usize,
        target: usize,
        count: usize,
        search: HypothesisSearch,
    ) -> Result<Option<(PairMatches, Vec<Rigid>)>> {
        let Some((config, features)) = &self.features else {
            return Ok(None);
        };
        self.hypotheses_from(
            source,
            target,
            (&features[source], &features[target]),
            config,
            count,
            search,
        )
        .map(Some)
    }

    /// [`PreparedProblem::pair_hypotheses`] of a pair from keypoints [`FINER_KEYPOINTS`] times
    /// as far apart as the first ones, described anew: the second look of a pair the verdict
    /// doubts. `None` without hypotheses or without a viewpoint.
    pub(crate) fn pair_hypotheses_finer(
        &self,
        source: usize,
        target: usize,
        count: usize,
        pool: &rayon::ThreadPool,
    ) -> Result<Option<(PairMatches, Vec<Rigid>)>> {
        let (Some((first, _)), Some(points)) = (&self.features, &self.pair_points) else {
            return Ok(None);
        };
        let config = FeatureConfig::for_spacing(first.voxel * FINER_KEYPOINTS);
        config.validate()?;
        let described: Vec<Features> = pool.install(|| {
            use rayon::prelude::*;
            [source, target]
                .par_iter()
                .map(|&v| describe(&points[v], &config))
                .collect::<Result<_>>()
        })?;
        self.interrupt.check()?;
        self.hypotheses_from(
            source,
            target,
            (&described[0], &described[1]),
            &config,
            count,
            HypothesisSearch::Pair,
        )
        .map(Some)
    }

    /// The matches of two scans' `features` (`config`) and their `count` best poses (centred
    /// frames, source -> target) found as `search` says.
    fn hypotheses_from(
        &self,
        source: usize,
        target: usize,
        (s, t): (&Features, &Features),
        config: &FeatureConfig,
        count: usize,
        search: HypothesisSearch,
    ) -> Result<(PairMatches, Vec<Rigid>)> {
        let consensus_seeds = match search {
            HypothesisSearch::Pair => config.consensus_seeds,
            HypothesisSearch::Screening => 0,
        };
        let config = FeatureConfig {
            num_candidates: count,
            consensus_seeds,
            ..config.clone()
        };
        let matches = PairMatches::new(s, t, &config)?;
        let candidates = if search == HypothesisSearch::Pair && !self.free_space.is_empty() {
            // The search keeps room only for poses that can be right.
            let keep = |r: &Transform| {
                rough_violation(
                    &self.free_space[source],
                    &self.free_space[target],
                    &Rigid::from_matrix(r),
                )
                .is_none_or(|v| v <= SEARCH_FREE_SPACE)
            };
            matches.candidates_where(s, t, &keep)
        } else if search == HypothesisSearch::Screening {
            matches.screening_candidates(s, t)
        } else {
            matches.candidates(s, t)
        };
        let poses = candidates
            .iter()
            .map(|c| Rigid::from_matrix(&c.t_target_source))
            .collect();
        Ok((matches, poses))
    }

    /// Whether any scan's viewpoint is known (free space is measured).
    pub(crate) fn has_viewpoints(&self) -> bool {
        !self.free_space.is_empty()
    }

    /// The share of one scan's points that `t` (cloud `s` -> cloud `d`, centred frames) puts
    /// where the other's scanner saw through (see [`crate::freespace`]); `None` without
    /// viewpoints.
    pub(crate) fn free_space_violation(&self, s: usize, d: usize, t: &Rigid) -> Option<f64> {
        if self.free_space.is_empty() {
            return None;
        }
        violation(&self.free_space[s], &self.free_space[d], t)
    }

    /// The share of all probes of one scan that `t` (cloud `s` -> cloud `d`, centred frames)
    /// puts in the other's free space ([`crate::freespace::free_share`]); `None` without
    /// viewpoints.
    pub(crate) fn free_space_share(&self, s: usize, d: usize, t: &Rigid) -> Option<f64> {
        if self.free_space.is_empty() {
            return None;
        }
        free_share(&self.free_space[s], &self.free_space[d], t)
    }

    /// `check` of a scene pair registered alone at `t` (centred frames) with the cues its
    /// descriptor `matches` and free space add ([`EdgeCheck::free_share`],
    /// [`EdgeCheck::landed`], [`EdgeCheck::tight_support`]); `check` as it is without
    /// viewpoints.
    pub(crate) fn with_scene_cues(
        &self,
        check: EdgeCheck,
        matches: &PairMatches,
        t: &Rigid,
    ) -> EdgeCheck {
        let Some(free_share) = self.free_space_share(check.source, check.target, t) else {
            return check;
        };
        let target = self.full[check.target].grid();
        let (near, m) = ((LANDED_EPS * self.eps).powi(2), t.to_matrix());
        EdgeCheck {
            free_share: Some(free_share),
            landed: Some(matches.landed(&m, |q| target.nearest_within(q, near).hit.is_some())),
            tight_support: Some(matches.tight_support(&m)),
            ..check
        }
    }

    /// How far `t` (cloud `s` -> cloud `d`, centred frames) keeps out of free space: 1 with
    /// none violated or without viewpoints, falling linearly to 0 at
    /// [`HYPOTHESIS_FREE_SPACE`] and beyond (on 300 3DLoMatch pairs, choosing by support times
    /// this instead of support among the clear poses registers 13 more).
    pub(crate) fn free_space_clearance(&self, s: usize, d: usize, t: &Rigid) -> f64 {
        self.free_space_violation(s, d, t)
            .map_or(1.0, |v| (1.0 - v / HYPOTHESIS_FREE_SPACE).max(0.0))
    }

    /// The verdict's measures of `edge` at `t` (centred frames), free space included.
    pub(crate) fn check_edge(&self, edge: Edge, t: &Rigid) -> EdgeCheck {
        // Independent measures, in the current rayon pool.
        let ((free_space, constraint), surfaces) = rayon::join(
            || self.edge_cues(edge, t),
            || check_edge(&self.full, edge, t, self.eps),
        );
        EdgeCheck {
            free_space,
            constraint,
            ..surfaces
        }
    }

    /// The free space and slide constraint of `edge` at `t` (centred frames): the measures
    /// of [`PreparedProblem::check_edge`] beside the surfaces.
    fn edge_cues(&self, edge: Edge, t: &Rigid) -> (Option<f64>, Option<f64>) {
        rayon::join(
            || self.free_space_violation(edge.source, edge.target, t),
            || self.slide_constraint(edge.source, edge.target, t),
        )
    }

    /// [`PreparedProblem::check_edge`] of a pose that `support` descriptor matches and a
    /// rival `rival` explain, or `None` when its free space, slide constraint and matches
    /// doubt it whatever its overlap and residual ([`crate::verdict::SceneOdds::at_best`] below
    /// [`SceneOdds::trusted_at`]): then its surfaces, most of a check's time, are not measured.
    /// With `None` the verdict doubts the pose, as it would have with the full check.
    pub(crate) fn check_scene_edge(
        &self,
        edge: Edge,
        t: &Rigid,
        support: usize,
        rival: usize,
    ) -> Option<EdgeCheck> {
        let (free_space, constraint) = self.edge_cues(edge, t);
        let cues = EdgeCheck {
            source: edge.source,
            target: edge.target,
            overlap: 0.0,
            residual: 0.0,
            self_residual: 0.0,
            constraint,
            support: Some(support),
            rival_support: Some(rival),
            free_space,
            free_share: None,
            landed: None,
            tight_support: None,
        };
        // Only a pair with free space measured is judged by the weighed cues.
        let weights = SceneOdds::for_check(&cues);
        if free_space.is_some() && weights.at_best(&cues) < weights.trusted_at {
            return None;
        }
        let surfaces = check_edge(&self.full, edge, t, self.eps);
        Some(EdgeCheck {
            overlap: surfaces.overlap,
            residual: surfaces.residual,
            self_residual: surfaces.self_residual,
            ..cues
        })
    }

    /// [`EdgeCheck::constraint`] of cloud `s` -> cloud `d` at `t` (centred frames): keypoints
    /// meet where one lies within [`SLIDE_RADIUS_VOXELS`] keypoint voxels of the other's
    /// nearest; `None` without features or with fewer than [`SLIDE_MIN_MATCHES`] meeting.
    pub(crate) fn slide_constraint(&self, s: usize, d: usize, t: &Rigid) -> Option<f64> {
        let (config, features) = self.features.as_ref()?;
        let radius = SLIDE_RADIUS_VOXELS * config.voxel;
        // Normals in d's frame, of both directions' meeting keypoints.
        let mut scatter = nalgebra::Matrix3::<f64>::zeros();
        let mut count = 0usize;
        let r_sd = nalgebra::Matrix3::from_fn(|i, j| t.r[i][j]);
        for (from, to, pose, rotate) in [(s, d, *t, false), (d, s, t.inverse(), true)] {
            let (a, b) = (&features[from], &features[to]);
            let grid = NearestGrid::new(&b.points, radius);
            for p in &a.points {
                let Some((m, d2)) = grid.nearest(&pose.apply(p)).hit else {
                    continue;
                };
                if d2 > radius * radius {
                    continue;
                }
                let mut n = nalgebra::Vector3::from(b.normals[m]);
                if rotate {
                    n = r_sd * n;
                }
                scatter += n * n.transpose();
                count += 1;
            }
        }
        (count >= SLIDE_MIN_MATCHES).then(|| {
            (scatter / count as f64)
                .symmetric_eigenvalues()
                .min()
                .max(0.0)
        })
    }

    /// The `poses` (cloud `s` -> cloud `d`, centred frames) that put no surface where a
    /// scanner saw through ([`HYPOTHESIS_FREE_SPACE`]); all of them when every one does (for the
    /// verdict to say so) or without viewpoints.
    pub(crate) fn clear_of_free_space(&self, s: usize, d: usize, poses: Vec<Rigid>) -> Vec<Rigid> {
        let clear: Vec<Rigid> = poses
            .iter()
            .filter(|r| {
                self.free_space_violation(s, d, r)
                    .is_none_or(|v| v <= HYPOTHESIS_FREE_SPACE)
            })
            .copied()
            .collect();
        if clear.is_empty() {
            poses
        } else {
            clear
        }
    }

    /// `t` (cloud `s` -> cloud `d`, original frames) in the centred frames.
    pub(crate) fn to_centred(&self, s: usize, d: usize, t: &Transform) -> Transform {
        let cs = self.centroids[s];
        let ct = self.centroids[d];
        translation([-ct[0], -ct[1], -ct[2]]) * t * translation(cs)
    }

    /// `t` (cloud `s` -> cloud `d`, centred frames) in the original frames.
    pub(crate) fn to_original(&self, s: usize, d: usize, t: &Transform) -> Transform {
        let cs = self.centroids[s];
        let ct = self.centroids[d];
        translation(ct) * t * translation([-cs[0], -cs[1], -cs[2]])
    }
}

/// How a pair's hypotheses are searched.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum HypothesisSearch {
    /// A pair or a loop, which must be solved: compatibility-graph seeds (the features'
    /// [`FeatureConfig::consensus_seeds`]) and RANSAC, the search kept clear of free space.
    Pair,
    /// One of the many pairs of a scan set, most of which do not overlap: RANSAC alone, no
    /// free-space filter. On the 3DMatch rooms the seeds made screening 4-5 times slower and
    /// placed no more scans (lab, seed 0: 5 placed, 2 wrong, 122 s; without: 4, 1, 12 s),
    /// and the filter let a non-overlapping pair's wrong poses, which see no free space, stand
    /// out (home, seed 0: 15 wrong scans instead of 2). Fewer RANSAC poses are refined
    /// ([`PairMatches::screening_candidates`]).
    Screening,
}

/// More workers than this many per core only add overhead (4096 threads made a 0.1 s run
/// take a minute); results never depend on the count, so larger requests are clamped.
const MAX_THREADS_PER_CORE: usize = 4;

/// A pool of `num_threads` workers (0 = all cores), at most [`MAX_THREADS_PER_CORE`] per core.
pub(crate) fn thread_pool(num_threads: usize) -> Result<rayon::ThreadPool> {
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let num_threads = num_threads.min(MAX_THREADS_PER_CORE * cores);
    rayon::ThreadPoolBuilder::new()
        .num_threads(num_threads)
        .build()
        .map_err(|e| Error::InvalidInput(format!("cannot start {num_threads} threads: {e}")))
}

#[cfg(test)]
mod slide_tests {
    use super::*;

    /// A floor and a back wall (they meet along x: nothing holds a slide along it), and
    /// optionally a side wall that does.
    fn room(side_wall: bool) -> PointCloud {
        let mut points = crate::freespace::tests::corner();
        if side_wall {
            for j in 0..=80 {
                for k in 0..=80 {
                    points.push([-1.0, -1.0 + j as f64 * 0.025, 1.0 + k as f64 * 0.025]);
                }
            }
        }
        PointCloud::new(points)
    }

    fn constraint(side_wall: bool) -> f64 {
        let clouds = [room(side_wall), room(side_wall)];
        let prepared = PreparedProblem::new(&clouds, &Config::default()).unwrap();
        prepared
            .slide_constraint(0, 1, &Rigid::from_matrix(&Transform::identity()))
            .expect("keypoints meet")
    }

    #[test]
    fn two_planes_do_not_hold_a_slide_along_their_line_and_three_do() {
        let two = constraint(false);
        let three = constraint(true);
        assert!(two < 0.005, "floor and one wall: {two}");
        assert!(three > 0.1, "floor and two walls: {three}");
        assert!(three > crate::verdict::MIN_CONSTRAINT && two < crate::verdict::MIN_CONSTRAINT);
    }
}
