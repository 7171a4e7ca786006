//! Pose hypotheses for a pair of scans from local features: FPFH descriptors (Rusu et al.,
//! ICRA 2009) matched in descriptor space and verified by RANSAC, as Open3D's
//! `registration_ransac_based_on_feature_matching`, but keeping a short ranked list of
//! DISTINCT poses instead of one. The evolution samples around these candidates, so a pair
//! scanned far apart (where it would rarely sample near the truth) starts next to it; the
//! caller verifies them with its own loss.
//!
//! Pipeline, per cloud then per pair:
//! 1. [`describe`]: voxel-downsample (one point per occupied voxel, the mean of its points),
//!    estimate normals by local plane fits, orient them ([`NormalOrientation`]), compute the
//!    33-bin FPFH of every keypoint;
//! 2. [`candidates`]: match descriptors by nearest neighbour ([`Matching`]); RANSAC on
//!    triples of matches, each draw pruned by the edge-length, distance and normal checks
//!    before all matches are counted; where RANSAC does not reach its confidence (few
//!    inliers), hypotheses from the matches' compatibility graph too (up to 1000 seed
//!    matches, each fitted with the 30 matches sharing the most compatible matches with it,
//!    as SC2-PCR); keeping the best DISTINCT hypotheses (3 per candidate asked for;
//!    [`PairMatches::candidates_where`] keeps only poses a caller's rule accepts); refine each by least squares on the matches it fits, then point-to-plane
//!    ICP on the keypoints; rank by the matches fitted within half the inlier distance; drop
//!    any candidate within 10 degrees and 2 voxels of a better one.
//!
//! Beyond Open3D's recipe, measured on the Stanford turntable scans (see
//! `experiments/features-candidates.md`): matches taken both ways instead of mutual, the
//! normal check, the ICP with a shrinking pairing distance and the tight ranking score each
//! add true poses at 96 degrees apart, where the overlap is 6-35 %.
//!
//! **Convention.** A candidate's `t_target_source` maps source points into the target frame:
//! `x_target = T x_source`.
//!
//! **Cost.** [`describe`] is run once per cloud and reused for every pair it is part of.
//! Both steps use the current rayon pool; their results do not depend on its size (every
//! random number is drawn on one thread, parallel results are collected in order).
//!
//! ```
//! use mtpcr_core::features::{candidates, describe, FeatureConfig};
//! use mtpcr_core::se3::rotation_error_deg;
//! let problem = mtpcr_core::synthetic::three_views(7, 6000);
//! let (a, b) = (problem.clouds[0].points(), problem.clouds[1].points());
//! let config = FeatureConfig::for_clouds(&[a, b], 0.02).unwrap();
//! let (fa, fb) = (describe(a, &config).unwrap(), describe(b, &config).unwrap());
//! let found = candidates(&fa, &fb, &config).unwrap();
//! let best = &found[0]; // maps cloud 1 into cloud 2's frame, best first
//! assert!(rotation_error_deg(&best.t_target_source, &problem.ground_truth[0]) < 5.0);
//! assert!(best.fitness > 0.2 && best.fitness <= 1.0);
//! ```

mod describe;
mod ransac;
#[cfg(test)]
mod tests;

use crate::error::{Error, Result};
use crate::se3::{Rigid, Transform};

pub use describe::pca_diagonal;

/// Bins of one FPFH angle feature.
pub const BINS_PER_FEATURE: usize = 11;
/// Length of an FPFH descriptor: three angle features of [`BINS_PER_FEATURE`] bins.
pub const DESCRIPTOR_LEN: usize = 3 * BINS_PER_FEATURE;

/// An FPFH descriptor: three histograms of 11 bins (the angle `theta` of the Darboux frame,
/// `alpha`, `phi`), each summing to 200 (the point's own SPFH plus the distance-weighted
/// mean of its neighbours', each normalised to 100).
pub type Descriptor = [f32; DESCRIPTOR_LEN];

/// How the sign of each normal is chosen. FPFH depends on it, so both clouds of a pair must
/// use the same rule; both rules are invariant to rigid motions of the cloud.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum NormalOrientation {
    /// Normals point away from the keypoints' centroid: outwards on a scan of an object.
    AwayFromCentroid,
    /// Normals point towards the keypoints' centroid: towards the sensor in a scan of a room
    /// taken from inside it.
    TowardsCentroid,
}

/// Which descriptor matches RANSAC draws from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Matching {
    /// Each source keypoint with its nearest target keypoint in descriptor space (Open3D with
    /// `mutual_filter = false`).
    Forward,
    /// Only pairs that are each other's nearest (Open3D's `mutual_filter = true`); falls back
    /// to [`Matching::Forward`] when fewer than [`MIN_MUTUAL_MATCHES`] remain. Fewest matches,
    /// cleanest, but it loses most true matches when the overlap is small.
    Mutual,
    /// Both one-way lists together: each source keypoint with its nearest target keypoint and
    /// each target keypoint with its nearest source keypoint (the default: the most true
    /// matches at small overlaps, for about twice the RANSAC work).
    BothWays,
}

/// Settings of [`describe`] and [`candidates`]. Lengths are in the data's units.
/// [`FeatureConfig::for_spacing`] gives the defaults for a voxel size.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FeatureConfig {
    /// Voxel size of the downsampling that picks the keypoints (> 0). About 2 % of the
    /// scans' size suits object scans ([`FeatureConfig::for_clouds`]). The keypoints grow as
    /// 1 / voxel^2 and the matching costs (source keypoints) x (target keypoints).
    pub voxel: f64,
    /// Radius of the plane fits that give the normals (> 0; default 2 voxels).
    pub normal_radius: f64,
    /// Most neighbours used in a plane fit, nearest first (>= 3; default 30).
    pub normal_max_neighbours: usize,
    /// Sign rule of the normals (default [`NormalOrientation::AwayFromCentroid`]).
    pub orientation: NormalOrientation,
    /// Radius of the FPFH neighbourhood (> 0; default 5 voxels).
    pub feature_radius: f64,
    /// Most neighbours used in an FPFH, nearest first (>= 1; default 100).
    pub feature_max_neighbours: usize,
    /// Which descriptor matches are used (default [`Matching::BothWays`]).
    pub matching: Matching,
    /// Seed matches of the compatibility-graph hypotheses (0 turns them off; default 1000):
    /// the matches compatible with the most others, each fitted with the matches sharing the
    /// most compatible matches with it. Where RANSAC's triples are mostly outliers (scene
    /// pairs at 10-30 % overlap) they find the true pose far more often.
    pub consensus_seeds: usize,
    /// Most RANSAC draws (>= 1; default 100000).
    pub max_iterations: usize,
    /// RANSAC stops early once a draw of three inliers would have been seen with this
    /// probability, given the best inlier ratio among the matches (in (0, 1]; 1 never stops
    /// early; default 0.999).
    pub confidence: f64,
    /// Edge-length checker: a draw is kept only when every edge of the source triangle and
    /// the matching target edge differ by less than this ratio (in (0, 1); default 0.9).
    pub edge_length_ratio: f64,
    /// A match (or a moved keypoint and its nearest target keypoint) is an inlier within this
    /// distance (> 0; default 1.5 voxels). Also the distance checker's bound.
    pub inlier_distance: f64,
    /// ... and when the two normals, the source one turned by the pose, differ by at most this
    /// angle (degrees, in (0, 180]; 180 turns the check off; default 60). On the turntable
    /// scans this check is what ranks the true pose first at small overlaps.
    pub max_normal_angle_deg: f64,
    /// Rounds of point-to-plane ICP on the keypoints that refine each kept hypothesis after
    /// its refits on the matches (default 15; 0 keeps the refits on the matches only, which
    /// are a few degrees less accurate).
    pub icp_iterations: usize,
    /// Seed of the RANSAC draws.
    pub seed: u64,
    /// Most candidates returned (>= 1; default 10).
    pub num_candidates: usize,
    /// Two poses closer than this angle (degrees, > 0; default 10) and
    /// [`FeatureConfig::nms_distance`] are the same candidate; the better one is kept.
    pub nms_angle_deg: f64,
    /// Distance between the source centroid moved by two poses under which they are the same
    /// candidate (> 0; default 2 voxels).
    pub nms_distance: f64,
}

/// Fewest keypoints a described cloud keeps (fewer give empty features).
const MIN_KEYPOINTS: usize = 10;

/// [`FeatureConfig::consensus_seeds`] by default. On 150 3DLoMatch pairs (seed 1) 100 seeds
/// put a right pose among 30 candidates for 47 % of them, 300 for 55 %, none 34 %; most
/// pairs have fewer distinct seeds than 1000 (see `ransac::consensus_hypotheses`).
pub const DEFAULT_CONSENSUS_SEEDS: usize = 1000;

/// Fewest mutual matches [`Matching::Mutual`] keeps before falling back to one-way matches.
pub const MIN_MUTUAL_MATCHES: usize = 30;

/// Fraction of the scans' size (mean PCA-box diagonal) used as the voxel by
/// [`FeatureConfig::for_clouds`]: the Stanford turntable scans give the same hit rates from
/// 0.015 to 0.025, and the time per pair halves from 0.015 to 0.02.
pub const DEFAULT_VOXEL_FRACTION: f64 = 0.02;

impl FeatureConfig {
    /// The defaults for keypoints `voxel` apart, Open3D's usual recipe where it has one:
    /// normals over 2 voxels (30 neighbours), FPFH over 5 voxels (100 neighbours), inliers
    /// within 1.5 voxels, 100000 draws at confidence 0.999, edge-length checker 0.9; then
    /// matches both ways, 1000 compatibility-graph seeds, normals within 60 degrees, 15 rounds
    /// of ICP, 10 candidates at least 10 degrees or 2 voxels apart; seed 0.
    pub fn for_spacing(voxel: f64) -> FeatureConfig {
        FeatureConfig {
            voxel,
            normal_radius: 2.0 * voxel,
            normal_max_neighbours: 30,
            orientation: NormalOrientation::AwayFromCentroid,
            feature_radius: 5.0 * voxel,
            feature_max_neighbours: 100,
            matching: Matching::BothWays,
            consensus_seeds: DEFAULT_CONSENSUS_SEEDS,
            max_iterations: 100_000,
            confidence: 0.999,
            edge_length_ratio: 0.9,
            inlier_distance: 1.5 * voxel,
            max_normal_angle_deg: 60.0,
            icp_iterations: 15,
            seed: 0,
            num_candidates: 10,
            nms_angle_deg: 10.0,
            nms_distance: 2.0 * voxel,
        }
    }

    /// [`FeatureConfig::for_spacing`] with the voxel `fraction` times the mean PCA-box
    /// diagonal of `clouds` (a size that does not change when a cloud is moved). Fails when
    /// no cloud has an extent or `fraction` is not positive.
    pub fn for_clouds(clouds: &[&[[f64; 3]]], fraction: f64) -> Result<FeatureConfig> {
        if !(fraction.is_finite() && fraction > 0.0) {
            return Err(Error::config(
                "voxel",
                format!("fraction must be > 0, got {fraction}"),
            ));
        }
        let sizes: Vec<f64> = clouds
            .iter()
            .map(|c| pca_diagonal(c))
            .filter(|d| *d > 0.0)
            .collect();
        if sizes.is_empty() {
            return Err(Error::InvalidInput(
                "no cloud has an extent to derive the feature voxel from".into(),
            ));
        }
        let size = sizes.iter().sum::<f64>() / sizes.len() as f64;
        let config = FeatureConfig::for_spacing(fraction * size);
        config.validate()?;
        Ok(config)
    }

    /// Checks every field's range; the error names the first bad field.
    pub fn validate(&self) -> Result<()> {
        let positive = |v: f64| v.is_finite() && v > 0.0;
        Error::check_setting(positive(self.voxel), "voxel", "finite and > 0", self.voxel)?;
        Error::check_setting(
            positive(self.normal_radius),
            "normal_radius",
            "finite and > 0",
            self.normal_radius,
        )?;
        let k = self.normal_max_neighbours;
        Error::check_setting(k >= 3, "normal_max_neighbours", ">= 3", k)?;
        Error::check_setting(
            positive(self.feature_radius),
            "feature_radius",
            "finite and > 0",
            self.feature_radius,
        )?;
        let k = self.feature_max_neighbours;
        Error::check_setting(k >= 1, "feature_max_neighbours", ">= 1", k)?;
        Error::check_setting(
            self.max_iterations >= 1,
            "max_iterations",
            ">= 1",
            self.max_iterations,
        )?;
        let c = self.confidence;
        Error::check_setting(c > 0.0 && c <= 1.0, "confidence", "in (0, 1]", c)?;
        let e = self.edge_length_ratio;
        Error::check_setting(e > 0.0 && e < 1.0, "edge_length_ratio", "in (0, 1)", e)?;
        let d = self.inlier_distance;
        Error::check_setting(positive(d), "inlier_distance", "finite and > 0", d)?;
        let a = self.max_normal_angle_deg;
        Error::check_setting(
            a > 0.0 && a <= 180.0,
            "max_normal_angle_deg",
            "in (0, 180]",
            a,
        )?;
        Error::check_setting(
            self.num_candidates >= 1,
            "num_candidates",
            ">= 1",
            self.num_candidates,
        )?;
        let a = self.nms_angle_deg;
        Error::check_setting(a > 0.0 && a <= 180.0, "nms_angle_deg", "in (0, 180]", a)?;
        Error::check_setting(
            positive(self.nms_distance),
            "nms_distance",
            "finite and > 0",
            self.nms_distance,
        )?;
        Ok(())
    }
}

/// One cloud's keypoints with their unit normals and FPFH descriptors (equal lengths), as
/// made by [`describe`]. Keypoints without enough neighbours for a normal or a descriptor are
/// left out; a flat, linear or tiny cloud gives no keypoints.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Features {
    /// Keypoints: the mean of the cloud's points in each occupied voxel, in voxel order.
    pub points: Vec<[f64; 3]>,
    /// Unit normal of each keypoint, oriented by [`FeatureConfig::orientation`].
    pub normals: Vec<[f64; 3]>,
    /// FPFH of each keypoint.
    pub descriptors: Vec<Descriptor>,
}

impl Features {
    /// Number of keypoints.
    pub fn len(&self) -> usize {
        self.points.len()
    }

    /// True when there is no keypoint.
    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }
}

/// A candidate pose of a pair, with the numbers that say how much to believe it.
#[derive(Clone, Debug, PartialEq)]
pub struct Candidate {
    /// Maps source points into the target frame (`x_target = T x_source`).
    pub t_target_source: Transform,
    /// Source keypoints that the pose moves within [`FeatureConfig::inlier_distance`] of
    /// their nearest target keypoint, the two normals agreeing
    /// ([`FeatureConfig::max_normal_angle_deg`]). Breaks ties of [`Candidate::matches`].
    pub inliers: usize,
    /// `inliers` / number of source keypoints (Open3D's fitness).
    pub fitness: f64,
    /// Root mean square distance of those inliers to their nearest target keypoints.
    pub rmse: f64,
    /// Descriptor matches that the pose maps within HALF the inlier distance, normals
    /// agreeing: the score candidates are ranked by (a true pose aligns the overlap tightly;
    /// the wrong poses of a near-symmetric object often explain as many matches loosely).
    pub matches: usize,
}

/// Keypoints, normals and FPFH descriptors of one cloud (see the module docs). Non-finite
/// points are ignored; a cloud too small, flat or linear to describe gives empty features.
/// Fails only on an invalid `config`.
pub fn describe(points: &[[f64; 3]], config: &FeatureConfig) -> Result<Features> {
    config.validate()?;
    Ok(describe::describe(points, config))
}

/// Candidate poses mapping `source` into `target`, best first, pairwise distinct (no two
/// within [`FeatureConfig::nms_angle_deg`] and [`FeatureConfig::nms_distance`]), at most
/// [`FeatureConfig::num_candidates`]. Empty when nothing can be matched or verified (too
/// few keypoints or matches, degenerate geometry). `config` must be the one both features
/// were described with (its voxel sets the scale of every distance). Fails only on an
/// invalid `config`, or on features whose lengths differ or that hold a non-finite value.
pub fn candidates(
    source: &Features,
    target: &Features,
    config: &FeatureConfig,
) -> Result<Vec<Candidate>> {
    let matches = PairMatches::new(source, target, config)?;
    Ok(matches.candidates(source, target))
}

/// The descriptor matches of a pair of described clouds: what [`candidates`] searches, kept
/// to measure how many of them any pose explains (its support), the same score that ranks
/// the candidates. A true pose of real scans explains many more matches than any other
/// pose; a pair whose best poses explain about as many is ambiguous.
pub struct PairMatches {
    set: ransac::PairMatchSet,
    config: FeatureConfig,
}

impl PairMatches {
    /// Matches the descriptors of `source` and `target` (see [`candidates`] for `config`
    /// and the errors).
    pub fn new(
        source: &Features,
        target: &Features,
        config: &FeatureConfig,
    ) -> Result<PairMatches> {
        config.validate()?;
        for (name, f) in [("source", source), ("target", target)] {
            if f.normals.len() != f.points.len() || f.descriptors.len() != f.points.len() {
                return Err(Error::InvalidInput(format!(
                    "{name} features: {} points, {} normals, {} descriptors (must be equal)",
                    f.points.len(),
                    f.normals.len(),
                    f.descriptors.len()
                )));
            }
            let finite = |v: &[[f64; 3]]| v.iter().flatten().all(|c| c.is_finite());
            let finite_descriptors = f.descriptors.iter().flatten().all(|c| c.is_finite());
            if !(finite(&f.points) && finite(&f.normals) && finite_descriptors) {
                return Err(Error::InvalidInput(format!(
                    "{name} features hold a non-finite value"
                )));
            }
        }
        Ok(PairMatches {
            set: ransac::match_pair(source, target, config),
            config: config.clone(),
        })
    }

    /// [`candidates`] from these matches (`source` and `target` as given to
    /// [`PairMatches::new`]).
    pub fn candidates(&self, source: &Features, target: &Features) -> Vec<Candidate> {
        let pool = ransac::POOL_PER_CANDIDATE;
        ransac::candidates(&self.set, source, target, &self.config, &|_| true, pool)
    }

    /// [`PairMatches::candidates`] for the pair screening of a set of scans: fewer RANSAC
    /// poses refined ([`ransac::SCREENING_POOL_PER_CANDIDATE`]).
    pub(crate) fn screening_candidates(
        &self,
        source: &Features,
        target: &Features,
    ) -> Vec<Candidate> {
        let pool = ransac::SCREENING_POOL_PER_CANDIDATE;
        ransac::candidates(&self.set, source, target, &self.config, &|_| true, pool)
    }

    /// [`PairMatches::candidates`] searched only among the poses `keep` accepts (maps source
    /// into target, as the candidates): a rule the matches cannot see, such as free space,
    /// keeps the search's room for poses that can be right.
    pub fn candidates_where(
        &self,
        source: &Features,
        target: &Features,
        keep: &(dyn Fn(&Transform) -> bool + Sync),
    ) -> Vec<Candidate> {
        let keep = |r: &Rigid| keep(&r.to_matrix());
        let pool = ransac::POOL_PER_CANDIDATE;
        ransac::candidates(&self.set, source, target, &self.config, &keep, pool)
    }

    /// Matches that `t_target_source` maps within half the inlier distance, their normals
    /// agreeing ([`Candidate::matches`] of a pose).
    pub fn support(&self, t_target_source: &Transform) -> usize {
        self.set.support(&Rigid::from_matrix(t_target_source))
    }

    /// Matches that `t_target_source` maps within a quarter of the inlier distance, their
    /// normals agreeing ([`PairMatches::support`] at half its distance).
    pub fn tight_support(&self, t_target_source: &Transform) -> usize {
        self.set.tight_support(&Rigid::from_matrix(t_target_source))
    }

    /// Matches whose source keypoint `t_target_source` puts where `on_target` holds (a
    /// test on the target's frame, such as "on its surface"), whether it meets its matched
    /// keypoint or not.
    pub fn landed(
        &self,
        t_target_source: &Transform,
        on_target: impl Fn(&[f64; 3]) -> bool,
    ) -> usize {
        self.set
            .landed(&Rigid::from_matrix(t_target_source), on_target)
    }

    /// Are two poses the same candidate (within [`FeatureConfig::nms_angle_deg`] and
    /// [`FeatureConfig::nms_distance`] of each other)?
    pub fn same_pose(&self, a: &Transform, b: &Transform) -> bool {
        self.set
            .same(&Rigid::from_matrix(a), &Rigid::from_matrix(b), &self.config)
    }
}
