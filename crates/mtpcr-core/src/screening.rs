//! A set of scans' pair screening as plain data, so that it can be computed in pieces (on
//! many machines: `mtpcr.distributed.register_scene`) and handed to the registration, which
//! then skips it. Screening is most of a room's time (89 % on the lab), and each pair's
//! hypotheses depend only on the prepared problem, so pieces give exactly a local run's poses.
//!
//! The poses are in the prepared problem's centred frames: a screening is valid only for the
//! same clouds prepared with the same settings, which its fingerprint checks.

use crate::error::{Error, Result};
use crate::problem::PreparedProblem;
use crate::se3::Transform;

/// One pair's hypotheses, as the screening found them.
#[derive(Debug, Clone, PartialEq)]
pub struct ScreenedPair {
    /// The source scan (numbered from 0).
    pub source: usize,
    /// The target scan, `source < target`.
    pub target: usize,
    /// Hypotheses `T_target_source` in the prepared problem's centred frames, best overlap
    /// first.
    pub poses: Vec<Transform>,
    /// Each hypothesis's overlap (1 - the original task's inlier loss), in `poses` order.
    pub overlaps: Vec<f64>,
    /// The descriptor matches each hypothesis explains, in `poses` order.
    pub supports: Vec<usize>,
}

/// The screening of some or all pairs of a set of scans.
#[derive(Debug, Clone, PartialEq)]
pub struct Screening {
    /// Identifies the preparation (clouds, sampling, features) and the hypothesis count the
    /// poses belong to (a hash of the prepared clouds and the hypothesis count).
    pub fingerprint: u64,
    /// Screened pairs, each at most once; a pair not listed has no hypotheses.
    pub pairs: Vec<ScreenedPair>,
}

impl Screening {
    /// Joins the screenings of disjoint sets of pairs of the same problem (in the given
    /// order). Fails when they belong to different preparations or share a pair.
    pub fn merge(parts: Vec<Screening>) -> Result<Screening> {
        let Some(fingerprint) = parts.first().map(|p| p.fingerprint) else {
            return Err(Error::InvalidInput(
                "no screening to merge (give at least one)".to_string(),
            ));
        };
        if parts.iter().any(|p| p.fingerprint != fingerprint) {
            return Err(Error::InvalidInput(
                "the screenings to merge belong to different clouds or settings \
                 (their fingerprints differ)"
                    .to_string(),
            ));
        }
        let merged = Screening {
            fingerprint,
            pairs: parts.into_iter().flat_map(|p| p.pairs).collect(),
        };
        if let Some((s, t)) = first_repeat(&merged.pairs) {
            return Err(Error::InvalidInput(format!(
                "pair ({s}, {t}) is screened more than once"
            )));
        }
        Ok(merged)
    }

    /// Checks the screening against `prepared` and the hypothesis count: the fingerprint,
    /// every pair's scans and its lists. Returns, for every pair `(s, t)` with `s < t` in
    /// row order, the index of its entry (`None`: not screened).
    pub(crate) fn index_for(
        &self,
        prepared: &PreparedProblem,
        hypotheses: usize,
    ) -> Result<Vec<Option<usize>>> {
        if self.fingerprint != fingerprint(prepared, hypotheses) {
            return Err(Error::InvalidInput(
                "the screening was made for other clouds or settings (its fingerprint differs \
                 from these clouds prepared with this config; screen them with the same \
                 clouds, seed and settings)"
                    .to_string(),
            ));
        }
        let n = prepared.clouds().len();
        let mut index = vec![None; n * (n - 1) / 2];
        for (k, p) in self.pairs.iter().enumerate() {
            let (s, t) = (p.source, p.target);
            if s >= t || t >= n {
                return Err(Error::InvalidInput(format!(
                    "screened pair ({s}, {t}) is not a pair of the {n} clouds (source < target, \
                     numbered from 0)"
                )));
            }
            let lists = [p.poses.len(), p.overlaps.len(), p.supports.len()];
            if lists.iter().any(|&l| l != p.poses.len()) || p.poses.len() > hypotheses {
                return Err(Error::InvalidInput(format!(
                    "screened pair ({s}, {t}) has {} poses, {} overlaps and {} supports \
                     (equal counts, at most hypotheses = {hypotheses}, are needed)",
                    lists[0], lists[1], lists[2]
                )));
            }
            let finite = p.poses.iter().all(|m| m.iter().all(|v| v.is_finite()))
                && p.overlaps.iter().all(|v| v.is_finite());
            if !finite {
                return Err(Error::InvalidInput(format!(
                    "screened pair ({s}, {t}) has a non-finite pose or overlap"
                )));
            }
            let slot = &mut index[pair_index(n, s, t)];
            if slot.is_some() {
                return Err(Error::InvalidInput(format!(
                    "pair ({s}, {t}) is screened more than once"
                )));
            }
            *slot = Some(k);
        }
        Ok(index)
    }
}

/// The position of pair `(s, t)`, `s < t < n`, among all pairs in row order.
pub(crate) fn pair_index(n: usize, s: usize, t: usize) -> usize {
    s * n - s * (s + 1) / 2 + (t - s - 1)
}

pub(crate) fn first_repeat(pairs: &[ScreenedPair]) -> Option<(usize, usize)> {
    let mut seen = std::collections::HashSet::new();
    pairs
        .iter()
        .map(|p| (p.source, p.target))
        .find(|&key| !seen.insert(key))
}

/// A 64-bit FNV-1a hash of what a screening depends on: the number of hypotheses, each
/// cloud's centroid, sample and keypoints, eps and shift. Equal for the same clouds, seed
/// and settings on any machine running the same mtpcr.
pub(crate) fn fingerprint(prepared: &PreparedProblem, hypotheses: usize) -> u64 {
    let mut hash = Fnv(0xcbf2_9ce4_8422_2325);
    hash.word(hypotheses as u64);
    hash.word(prepared.eps().to_bits());
    hash.word(prepared.shift().to_bits());
    for (v, cloud) in prepared.clouds().iter().enumerate() {
        hash.word(cloud.points().len() as u64);
        for x in prepared.centroid(v) {
            hash.word(x.to_bits());
        }
        for p in cloud.points().iter().take(4) {
            p.iter().for_each(|x| hash.word(x.to_bits()));
        }
        if let Some(f) = prepared.features_of(v) {
            hash.word(f.len() as u64);
            for p in f.points.iter().take(4) {
                p.iter().for_each(|x| hash.word(x.to_bits()));
            }
        }
    }
    hash.0
}

struct Fnv(u64);

impl Fnv {
    fn word(&mut self, w: u64) {
        for b in w.to_le_bytes() {
            self.0 = (self.0 ^ b as u64).wrapping_mul(0x0000_0100_0000_01b3);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pair(s: usize, t: usize) -> ScreenedPair {
        ScreenedPair {
            source: s,
            target: t,
            poses: vec![Transform::identity()],
            overlaps: vec![0.5],
            supports: vec![10],
        }
    }

    #[test]
    fn pair_index_counts_pairs_in_row_order() {
        let n = 7;
        let mut k = 0;
        for s in 0..n {
            for t in s + 1..n {
                assert_eq!(pair_index(n, s, t), k);
                k += 1;
            }
        }
    }

    #[test]
    fn merging_refuses_other_problems_and_repeated_pairs() {
        let a = Screening {
            fingerprint: 1,
            pairs: vec![pair(0, 1), pair(0, 2)],
        };
        let b = Screening {
            fingerprint: 1,
            pairs: vec![pair(1, 2)],
        };
        let merged = Screening::merge(vec![a.clone(), b.clone()]).unwrap();
        assert_eq!(merged.pairs.len(), 3);
        let other = Screening {
            fingerprint: 2,
            ..b.clone()
        };
        let e = Screening::merge(vec![a.clone(), other]).unwrap_err();
        assert!(e.to_string().contains("fingerprints differ"), "{e}");
        let e = Screening::merge(vec![a.clone(), a]).unwrap_err();
        assert!(
            e.to_string().contains("(0, 1) is screened more than once"),
            "{e}"
        );
        assert!(Screening::merge(Vec::new()).is_err());
    }
}
