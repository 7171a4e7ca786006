//! Pair benchmarks of scene fragments in the 3DMatch layout (3DMatch, 3DLoMatch): the
//! official pair lists (`<scene>/gt.log`), every pair registered with no initial guess, and
//! scored as in the literature (PointDSC, SC2-PCR, MAC): a pair is registered when its
//! rotation error is under [`RE_LIMIT_DEG`] and its translation error under [`TE_LIMIT`];
//! registration recall (RR) is the fraction of registered pairs, RE and TE are the mean
//! errors over the registered pairs. [`run_benchmark`] runs a benchmark's pairs (resuming
//! from done records) for the front-ends (`mtpcr eval FOLDER`, `mtpcr.evaluate_pairs`).
//!
//! Layout: a benchmark folder holds one folder per scene with a `gt.log` (blocks of five
//! lines, `i j n` then the 4x4 `T` with `x_i = T x_j`), and the fragments are
//! `<data root>/<scene>/cloud_bin_<k>.ply` (the data root defaults to the benchmark folder's
//! grandparent, as in `shared/data/3dmatch/benchmarks/3DMatch`). A folder that holds a
//! `gt.log` itself is one scene.

use crate::cloud::PointCloud;
use crate::config::Config;
use crate::error::{Error, Result};
use crate::io::read_points;
use crate::register::register;
use crate::se3::{random_rigid, rotation_error_deg, translation_error, Transform};
use crate::verdict::Verdict;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use std::collections::HashMap;
use std::ops::ControlFlow;
use std::path::{Path, PathBuf};

/// A pair is registered when its rotation error is under this (degrees)...
pub const RE_LIMIT_DEG: f64 = 15.0;
/// ...and its translation error under this (the data's units: 30 cm in 3DMatch).
pub const TE_LIMIT: f64 = 0.3;

/// One pair of a benchmark: `t_target_source` maps the source fragment into the target's
/// frame (gt.log's `i j`: target `i`, source `j`).
#[derive(Clone, Debug, PartialEq)]
pub struct PairCase {
    /// The scene's folder name.
    pub scene: String,
    /// Source fragment (gt.log's `j`).
    pub source: usize,
    /// Target fragment (gt.log's `i`).
    pub target: usize,
    /// Ground truth: `x_target = T x_source`.
    pub t_target_source: Transform,
}

impl PairCase {
    /// A key that names the pair in a benchmark: `scene/target-source`.
    pub fn key(&self) -> String {
        format!("{}/{}-{}", self.scene, self.target, self.source)
    }
}

/// The pairs of a benchmark folder, with where their fragments are.
#[derive(Clone, Debug, PartialEq)]
pub struct PairBenchmark {
    /// The benchmark's name (its folder's name: `3DMatch`, `3DLoMatch`).
    pub name: String,
    /// The folder holding `<scene>/cloud_bin_<k>.ply`.
    pub data_root: PathBuf,
    /// Every pair, scene by scene in name order, in each scene's gt.log order.
    pub cases: Vec<PairCase>,
}

/// Is `dir` a pair benchmark (a `gt.log` in it, or in one of its sub-folders)?
pub fn is_pair_benchmark(dir: &Path) -> bool {
    dir.is_dir() && !scene_logs(dir).is_empty()
}

/// The scenes' gt.log files under `dir`: `(scene name, path)`, by name.
fn scene_logs(dir: &Path) -> Vec<(String, PathBuf)> {
    let own = dir.join("gt.log");
    if own.is_file() {
        let name = dir
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        return vec![(name, own)];
    }
    let mut found: Vec<(String, PathBuf)> = std::fs::read_dir(dir)
        .into_iter()
        .flatten()
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.join("gt.log").is_file())
        .map(|p| {
            let name = p
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default();
            (name, p.join("gt.log"))
        })
        .collect();
    found.sort();
    found
}

impl PairBenchmark {
    /// Reads the pair lists of the benchmark folder `dir` (or of one scene's folder).
    /// `data_root` holds the scenes' fragments; by default the grandparent of the benchmark
    /// folder (of the scene's benchmark folder when `dir` is one scene).
    pub fn load(dir: impl AsRef<Path>, data_root: Option<&Path>) -> Result<PairBenchmark> {
        let dir = dir.as_ref();
        // A missing folder is said to be missing, not to hold no gt.log.
        std::fs::metadata(dir).map_err(|e| Error::io(dir, e))?;
        let logs = scene_logs(dir);
        if logs.is_empty() {
            return Err(Error::InvalidInput(format!(
                "{}: no gt.log in it or in its sub-folders: not a pair benchmark folder",
                dir.display()
            )));
        }
        let one_scene = dir.join("gt.log").is_file();
        let bench_dir = if one_scene { dir.parent() } else { Some(dir) };
        let name = bench_dir
            .and_then(Path::file_name)
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_else(|| "pairs".to_string());
        let data_root = match data_root {
            Some(r) => r.to_path_buf(),
            None => bench_dir
                .and_then(Path::parent)
                .and_then(Path::parent)
                .map(Path::to_path_buf)
                .unwrap_or_default(),
        };
        let mut cases = Vec::new();
        for (scene, log) in logs {
            let text = std::fs::read_to_string(&log).map_err(|e| Error::io(&log, e))?;
            cases.extend(parse_gt_log(&scene, &log, &text)?);
        }
        Ok(PairBenchmark {
            name,
            data_root,
            cases,
        })
    }

    /// The file of fragment `k` of `scene`.
    pub fn fragment_path(&self, scene: &str, k: usize) -> PathBuf {
        self.data_root
            .join(scene)
            .join(format!("cloud_bin_{k}.ply"))
    }

    /// Keeps only the scenes whose name contains one of `parts` (all when empty); fails
    /// when none is left.
    pub fn retain_scenes(&mut self, parts: &[String]) -> Result<()> {
        if parts.is_empty() {
            return Ok(());
        }
        self.cases
            .retain(|c| parts.iter().any(|p| c.scene.contains(p.as_str())));
        if self.cases.is_empty() {
            return Err(Error::InvalidInput(format!(
                "no scene of {} matches {}",
                self.name,
                parts.join(", ")
            )));
        }
        Ok(())
    }

    /// Keeps a seeded sample of `count` pairs (all when `count` is at least the number of
    /// pairs), in their original order: the same seed and count give the same pairs.
    pub fn sample(&mut self, count: usize, seed: u64) {
        if count >= self.cases.len() {
            return;
        }
        let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x7061_6972);
        let chosen = rand::seq::index::sample(&mut rng, self.cases.len(), count);
        let mut keep: Vec<usize> = chosen.into_iter().collect();
        keep.sort_unstable();
        self.cases = keep.iter().map(|&i| self.cases[i].clone()).collect();
    }
}

/// The pairs of one scene's gt.log text (`path` names the file in errors).
fn parse_gt_log(scene: &str, path: &Path, text: &str) -> Result<Vec<PairCase>> {
    let lines: Vec<&str> = text.lines().filter(|l| !l.trim().is_empty()).collect();
    if lines.len() % 5 != 0 {
        return Err(Error::malformed(
            path,
            format!(
                "{} non-empty lines: a gt.log holds blocks of five (`i j n` and a 4x4 matrix)",
                lines.len()
            ),
        ));
    }
    let numbers = |line: usize, want: usize| -> Result<Vec<f64>> {
        let v: Vec<f64> = lines[line]
            .split(|c: char| c.is_whitespace() || c == ',')
            .filter(|s| !s.is_empty())
            .map(str::parse)
            .collect::<std::result::Result<_, _>>()
            .map_err(|e| Error::malformed(path, format!("line {}: {e}", line + 1)))?;
        if v.len() < want || v.iter().any(|x| !x.is_finite()) {
            return Err(Error::malformed(
                path,
                format!("line {}: {want} finite numbers expected", line + 1),
            ));
        }
        Ok(v)
    };
    lines
        .chunks(5)
        .enumerate()
        .map(|(b, _)| {
            let head = numbers(5 * b, 2)?;
            let index = |v: f64| -> Result<usize> {
                if v >= 0.0 && v.fract() == 0.0 {
                    Ok(v as usize)
                } else {
                    Err(Error::malformed(
                        path,
                        format!("line {}: fragment numbers must be whole", 5 * b + 1),
                    ))
                }
            };
            let mut t = Transform::identity();
            for r in 0..4 {
                let row = numbers(5 * b + 1 + r, 4)?;
                for c in 0..4 {
                    t[(r, c)] = row[c];
                }
            }
            Ok(PairCase {
                scene: scene.to_string(),
                target: index(head[0])?,
                source: index(head[1])?,
                t_target_source: t,
            })
        })
        .collect()
}

/// One pair's run and its scores.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PairRecord {
    /// The benchmark's name.
    pub benchmark: String,
    /// [`PairCase::key`].
    pub pair: String,
    /// The run's seed (it also seeds the motion of the source).
    pub seed: u64,
    /// The source fragment was moved by a seeded random rigid motion first.
    pub moved: bool,
    /// Rotation error, degrees.
    pub re_deg: f64,
    /// Translation error, the data's units.
    pub te: f64,
    /// Under both limits.
    pub registered: bool,
    /// The verdict's `confident`.
    pub confident: bool,
    /// The verdict's reasons (empty when confident).
    pub reasons: Vec<String>,
    /// The verdict's overlap of the pair ([`crate::verdict::EdgeCheck`]).
    #[serde(default)]
    pub overlap: f64,
    /// The verdict's residual of the pair, relative to eps.
    #[serde(default)]
    pub residual: f64,
    /// How firmly the overlap holds the pose against a slide
    /// ([`crate::verdict::EdgeCheck::constraint`]).
    #[serde(default)]
    pub constraint: Option<f64>,
    /// Feature matches the estimate explains.
    #[serde(default)]
    pub support: Option<usize>,
    /// The most feature matches a hypothesis that is a different pose explains (discounted
    /// by its free space, see [`crate::verdict::EdgeCheck::rival_support`]).
    #[serde(default)]
    pub rival_support: Option<usize>,
    /// The share of one fragment put where the other's camera saw through (see
    /// [`crate::verdict::EdgeCheck::free_space`]; absent in records of older versions).
    #[serde(default)]
    pub free_space: Option<f64>,
    /// The share of all of one fragment's points put where the other's camera saw through
    /// ([`crate::verdict::EdgeCheck::free_share`]; absent in records of older versions).
    #[serde(default)]
    pub free_share: Option<f64>,
    /// Feature matches the estimate puts on the other fragment's surface
    /// ([`crate::verdict::EdgeCheck::landed`]; absent in records of older versions).
    #[serde(default)]
    pub landed: Option<usize>,
    /// Feature matches the estimate maps within a quarter of the inlier distance
    /// ([`crate::verdict::EdgeCheck::tight_support`]; absent in records of older versions).
    #[serde(default)]
    pub tight_support: Option<usize>,
    /// Seconds of the registration (reading the files excluded).
    pub seconds: f64,
    /// The estimate, rows of the 4x4 matrix (the moved source into the target).
    pub t_target_source: [[f64; 4]; 4],
}

/// A seeded rigid motion of a source fragment for pair `key` (uniform rotation, translation
/// up to `extent`): the same for every run with `seed`, different for every pair.
pub fn pair_motion(key: &str, seed: u64, extent: f64) -> Transform {
    // FNV-1a of the key: stable across platforms and versions.
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in key.bytes() {
        h = (h ^ b as u64).wrapping_mul(0x0100_0000_01b3);
    }
    let mut rng = ChaCha8Rng::seed_from_u64(h ^ seed.wrapping_mul(0x9e37_79b9_7f4a_7c15));
    random_rigid(&mut rng, extent)
}

/// Rotation error (degrees) and translation error of `estimate`, which maps the source moved
/// by `motion` into the target, against `truth`, which maps the source as read. Both are
/// measured in the source's own frame (the estimate carried back through the motion), as the
/// benchmark measures them: the translation error at the fragment's origin, its camera. At the
/// moved frame's origin, up to a fragment's size from its points, a rotation error of a
/// degree adds several centimetres (on every visible pair, 56 registered pairs were
/// counted as failed that way).
pub fn pair_errors(estimate: &Transform, motion: &Transform, truth: &Transform) -> (f64, f64) {
    let in_source_frame = estimate * motion;
    (
        rotation_error_deg(&in_source_frame, truth),
        translation_error(&in_source_frame, truth),
    )
}

/// Registers one pair (`source`, `target`: the case's fragments as read) with
/// `config.seed = Some(seed)`; with `moved`, the source is first moved by [`pair_motion`]
/// (translation up to its largest side).
pub fn run_pair(
    benchmark: &str,
    case: &PairCase,
    source: &PointCloud,
    target: &PointCloud,
    config: &Config,
    seed: u64,
    moved: bool,
) -> Result<(PairRecord, Verdict)> {
    let key = case.key();
    let (source, motion) = if moved {
        let m = pair_motion(&key, seed, source.largest_side());
        (source.transformed(&m), m)
    } else {
        (source.clone(), Transform::identity())
    };
    let config = Config {
        seed: Some(seed),
        ..config.clone()
    };
    let result = register(&[source, target.clone()], &config, None)?;
    let estimate = result.edges[0].t_target_source;
    let (re_deg, te) = pair_errors(&estimate, &motion, &case.t_target_source);
    let check = result.verdict.edges.first();
    let record = PairRecord {
        benchmark: benchmark.to_string(),
        pair: key,
        seed,
        moved,
        re_deg,
        te,
        registered: re_deg < RE_LIMIT_DEG && te < TE_LIMIT,
        confident: result.verdict.confident,
        reasons: result.verdict.reasons.clone(),
        overlap: check.map_or(0.0, |c| c.overlap),
        residual: check.map_or(0.0, |c| c.residual),
        constraint: check.and_then(|c| c.constraint),
        support: check.and_then(|c| c.support),
        rival_support: check.and_then(|c| c.rival_support),
        free_space: check.and_then(|c| c.free_space),
        free_share: check.and_then(|c| c.free_share),
        landed: check.and_then(|c| c.landed),
        tight_support: check.and_then(|c| c.tight_support),
        seconds: result.seconds,
        t_target_source: crate::io::matrix_rows(&estimate),
    };
    Ok((record, result.verdict))
}

/// The scores of a set of pair records.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct PairSummary {
    /// Pairs run.
    pub pairs: usize,
    /// Pairs registered.
    pub registered: usize,
    /// Registration recall, percent.
    pub recall: f64,
    /// Mean rotation error over the registered pairs, degrees.
    pub re_deg: f64,
    /// Mean translation error over the registered pairs.
    pub te: f64,
    /// Median seconds per pair.
    pub median_seconds: f64,
    /// Failed pairs called confident.
    pub failed_confident: usize,
    /// Failed pairs.
    pub failed: usize,
    /// Registered pairs doubted (not confident).
    pub registered_doubted: usize,
}

/// Summarises records.
pub fn summarize<'a>(records: impl IntoIterator<Item = &'a PairRecord>) -> PairSummary {
    let records: Vec<&PairRecord> = records.into_iter().collect();
    let ok: Vec<&&PairRecord> = records.iter().filter(|r| r.registered).collect();
    let mean = |v: Vec<f64>| {
        if v.is_empty() {
            f64::NAN
        } else {
            v.iter().sum::<f64>() / v.len() as f64
        }
    };
    let mut seconds: Vec<f64> = records.iter().map(|r| r.seconds).collect();
    seconds.sort_by(f64::total_cmp);
    PairSummary {
        pairs: records.len(),
        registered: ok.len(),
        recall: 100.0 * ok.len() as f64 / records.len().max(1) as f64,
        re_deg: mean(ok.iter().map(|r| r.re_deg).collect()),
        te: mean(ok.iter().map(|r| r.te).collect()),
        median_seconds: seconds.get(seconds.len() / 2).copied().unwrap_or(f64::NAN),
        failed_confident: records
            .iter()
            .filter(|r| !r.registered && r.confident)
            .count(),
        failed: records.len() - ok.len(),
        registered_doubted: ok.iter().filter(|r| !r.confident).count(),
    }
}

/// Reads the fragments of a scene on demand and keeps them (a scene's fragments are shared
/// by many pairs).
#[derive(Debug, Default)]
pub struct FragmentCache {
    scene: String,
    clouds: std::collections::HashMap<usize, PointCloud>,
}

impl FragmentCache {
    /// Fragment `k` of `scene` of `benchmark` (reading it the first time; a new scene
    /// empties the cache).
    pub fn get(&mut self, benchmark: &PairBenchmark, scene: &str, k: usize) -> Result<&PointCloud> {
        if self.scene != scene {
            self.scene = scene.to_string();
            self.clouds.clear();
        }
        use std::collections::hash_map::Entry;
        Ok(match self.clouds.entry(k) {
            Entry::Occupied(known) => known.into_mut(),
            // 3DMatch fragments lie in their reference camera's frame (every point
            // 0.5-3.5 m in front of it): the viewpoint is the origin.
            Entry::Vacant(slot) => slot
                .insert(read_points(benchmark.fragment_path(scene, k))?.with_viewpoint([0.0; 3])),
        })
    }
}

/// What [`run_benchmark`] tells its caller, pair by pair.
#[derive(Clone, Copy, Debug)]
pub enum PairStep<'a> {
    /// This pair is about to be registered.
    Running(&'a PairCase),
    /// A pair's record: registered just now, or (`reused`) taken from the done records.
    Done {
        /// The record.
        record: &'a PairRecord,
        /// Taken from the done records, not run.
        reused: bool,
    },
}

/// Runs the pairs of `benchmark` in order with `seed` (and `moved`, see [`run_pair`]),
/// reading the fragments once per scene, and returns their records in case order. A pair
/// whose record is in `done` (same benchmark name, pair, seed and `moved`; the last one
/// when several) is not run: that record is used. `on_step` hears of every pair before it
/// runs and of every record; [`ControlFlow::Break`] stops the run there, and the records
/// so far are returned.
pub fn run_benchmark(
    benchmark: &PairBenchmark,
    config: &Config,
    seed: u64,
    moved: bool,
    done: &[PairRecord],
    on_step: &mut dyn FnMut(PairStep<'_>) -> ControlFlow<()>,
) -> Result<Vec<PairRecord>> {
    let done: HashMap<&str, &PairRecord> = done
        .iter()
        .filter(|r| r.benchmark == benchmark.name && r.seed == seed && r.moved == moved)
        .map(|r| (r.pair.as_str(), r))
        .collect();
    let mut cache = FragmentCache::default();
    let mut records = Vec::with_capacity(benchmark.cases.len());
    for case in &benchmark.cases {
        let (record, reused) = match done.get(case.key().as_str()) {
            Some(&r) => (r.clone(), true),
            None => {
                if on_step(PairStep::Running(case)).is_break() {
                    break;
                }
                let source = cache.get(benchmark, &case.scene, case.source)?.clone();
                let target = cache.get(benchmark, &case.scene, case.target)?;
                let (record, _) =
                    run_pair(&benchmark.name, case, &source, target, config, seed, moved)?;
                (record, false)
            }
        };
        records.push(record);
        let step = PairStep::Done {
            record: &records[records.len() - 1],
            reused,
        };
        if on_step(step).is_break() {
            break;
        }
    }
    Ok(records)
}

#[cfg(test)]
mod tests {
    use super::*;

    const LOG: &str = "0\t 1\t 60\t\n 1 0 0 0.5\n 0 1 0 0\n 0 0 1 0\n 0 0 0 1\n\
                       2 7 60\n 0 -1 0 0\n 1 0 0 0\n 0 0 1 2\n 0 0 0 1\n";

    #[test]
    fn gt_log_blocks_name_target_then_source() {
        let cases = parse_gt_log("kitchen", Path::new("gt.log"), LOG).unwrap();
        assert_eq!(cases.len(), 2);
        assert_eq!((cases[0].target, cases[0].source), (0, 1));
        assert_eq!(cases[0].t_target_source[(0, 3)], 0.5);
        assert_eq!((cases[1].target, cases[1].source), (2, 7));
        assert_eq!(cases[1].t_target_source[(1, 0)], 1.0);
        assert_eq!(cases[1].key(), "kitchen/2-7");
    }

    #[test]
    fn malformed_logs_are_errors_that_name_the_line() {
        let short = "0 1 60\n1 0 0 0\n";
        assert!(parse_gt_log("s", Path::new("gt.log"), short)
            .unwrap_err()
            .to_string()
            .contains("blocks of five"));
        let bad = LOG.replace("0 1 0 0\n", "0 one 0 0\n");
        let e = parse_gt_log("s", Path::new("gt.log"), &bad).unwrap_err();
        assert!(e.to_string().contains("line 3"), "{e}");
    }

    #[test]
    fn summary_counts_the_confusion_of_the_verdict() {
        let rec = |registered: bool, confident: bool, re: f64| PairRecord {
            benchmark: "b".into(),
            pair: "s/0-1".into(),
            seed: 0,
            moved: false,
            re_deg: re,
            te: 0.1,
            registered,
            confident,
            reasons: Vec::new(),
            overlap: 0.5,
            residual: 0.1,
            constraint: None,
            support: Some(40),
            rival_support: Some(5),
            free_space: Some(0.01),
            free_share: Some(0.002),
            landed: Some(900),
            tight_support: Some(10),
            seconds: 1.0,
            t_target_source: [[0.0; 4]; 4],
        };
        let records = [
            rec(true, true, 1.0),
            rec(true, false, 3.0),
            rec(false, true, 90.0),
            rec(false, false, 40.0),
        ];
        let s = summarize(&records);
        assert_eq!((s.pairs, s.registered, s.failed), (4, 2, 2));
        assert_eq!((s.failed_confident, s.registered_doubted), (1, 1));
        assert!((s.recall - 50.0).abs() < 1e-12);
        assert!((s.re_deg - 2.0).abs() < 1e-12);
    }

    fn record(benchmark: &str, pair: &str, seed: u64, moved: bool) -> PairRecord {
        PairRecord {
            benchmark: benchmark.into(),
            pair: pair.into(),
            seed,
            moved,
            re_deg: 1.0,
            te: 0.1,
            registered: true,
            confident: true,
            reasons: Vec::new(),
            overlap: 0.5,
            residual: 0.1,
            constraint: None,
            support: None,
            rival_support: None,
            free_space: None,
            free_share: None,
            landed: None,
            tight_support: None,
            seconds: 1.0,
            t_target_source: [[0.0; 4]; 4],
        }
    }

    /// Three pairs of scene `s` whose fragments are nowhere: any pair that is run fails
    /// reading its fragment.
    fn fragmentless_benchmark() -> PairBenchmark {
        let case = |target, source| PairCase {
            scene: "s".into(),
            source,
            target,
            t_target_source: Transform::identity(),
        };
        PairBenchmark {
            name: "B".into(),
            data_root: PathBuf::from("/nonexistent/mtpcr-fragments"),
            cases: vec![case(0, 1), case(0, 2), case(1, 2)],
        }
    }

    #[test]
    fn run_benchmark_reuses_the_done_records_of_the_same_benchmark_seed_and_motion() {
        let b = fragmentless_benchmark();
        let mut done = vec![
            record("B", "s/1-2", 4, false),
            record("B", "s/0-1", 4, false),
            record("B", "s/0-2", 4, false),
        ];
        let mut heard = Vec::new();
        let records = run_benchmark(&b, &Config::default(), 4, false, &done, &mut |step| {
            match step {
                PairStep::Running(case) => heard.push(format!("running {}", case.key())),
                PairStep::Done { record, reused, .. } => {
                    heard.push(format!("{} {reused}", record.pair))
                }
            }
            ControlFlow::Continue(())
        })
        .expect("every pair is done: no fragment is read");
        let pairs: Vec<&str> = records.iter().map(|r| r.pair.as_str()).collect();
        assert_eq!(pairs, ["s/0-1", "s/0-2", "s/1-2"], "case order");
        assert_eq!(heard, ["s/0-1 true", "s/0-2 true", "s/1-2 true"]);

        // Break on the first record: only it is returned.
        let first = run_benchmark(&b, &Config::default(), 4, false, &done, &mut |_| {
            ControlFlow::Break(())
        })
        .unwrap();
        assert_eq!(first.len(), 1);

        // Another seed, motion or benchmark is not the same run: the pair is run (and here
        // fails reading its fragment, which names the file).
        for other in [
            record("B", "s/1-2", 5, false),
            record("B", "s/1-2", 4, true),
            record("C", "s/1-2", 4, false),
        ] {
            done[0] = other;
            let mut steps = 0;
            let e = run_benchmark(&b, &Config::default(), 4, false, &done, &mut |_| {
                steps += 1;
                ControlFlow::Continue(())
            })
            .unwrap_err();
            assert!(e.to_string().contains("cloud_bin_"), "{e}");
            assert_eq!(
                steps, 3,
                "two reused records, then the start of the third pair"
            );
        }

        // Break before a pair runs: nothing is read.
        done[0] = record("B", "s/0-0", 4, false);
        let none = run_benchmark(
            &b,
            &Config::default(),
            4,
            false,
            &done,
            &mut |step| match step {
                PairStep::Running(_) => ControlFlow::Break(()),
                PairStep::Done { .. } => ControlFlow::Continue(()),
            },
        )
        .unwrap();
        assert_eq!(none.len(), 2);
    }

    #[test]
    fn a_missing_benchmark_folder_is_an_io_error_naming_it() {
        let e = PairBenchmark::load("/nonexistent/mtpcr-benchmark", None).unwrap_err();
        assert!(matches!(e, Error::Io { .. }), "{e:?}");
        assert!(
            e.to_string().contains("/nonexistent/mtpcr-benchmark"),
            "{e}"
        );
    }

    #[test]
    fn errors_are_measured_in_the_source_frame_as_read() {
        use crate::se3::invert_rigid;
        // A source moved 3 units along x; an estimate that is right but for 2 degrees about
        // the source's own z axis: 2 degrees, no translation error (at the moved frame's
        // origin, 3 units from the axis, the same estimate is 10 cm off).
        let truth = pair_motion("s/0-1", 9, 1.0);
        let mut motion = Transform::identity();
        motion[(0, 3)] = 3.0;
        let turn =
            nalgebra::Rotation3::from_axis_angle(&nalgebra::Vector3::z_axis(), 2f64.to_radians());
        let mut off = Transform::identity();
        off.fixed_view_mut::<3, 3>(0, 0).copy_from(turn.matrix());
        let estimate = truth * off * invert_rigid(&motion);
        let (re, te) = pair_errors(&estimate, &motion, &truth);
        assert!((re - 2.0).abs() < 1e-9, "{re}");
        assert!(te < 1e-9, "{te}");
        let at_moved_origin = translation_error(&estimate, &(truth * invert_rigid(&motion)));
        assert!(at_moved_origin > 0.09, "{at_moved_origin}");
        // Unmoved: the estimate itself.
        let (re, te) = pair_errors(&truth, &Transform::identity(), &truth);
        assert!(re < 1e-6 && te < 1e-12);
    }

    #[test]
    fn motions_differ_per_pair_and_repeat_per_seed() {
        let a = pair_motion("s/0-1", 3, 1.0);
        assert_eq!(a, pair_motion("s/0-1", 3, 1.0));
        assert_ne!(a, pair_motion("s/0-2", 3, 1.0));
        assert_ne!(a, pair_motion("s/0-1", 4, 1.0));
    }
}
