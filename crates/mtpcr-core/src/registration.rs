//! The public entry: [`Config`], [`PreparedProblem`], [`register`] and its [`Registration`].

use crate::cloud::{PointCloud, Sampling};
use crate::error::{Error, Result};
use crate::evolve::{self, SearchBox, Tasks};
use crate::fitness::{CappedDistanceLoss, IndexedCloud, InlierLoss, Loss, SearchMethod};
use crate::refine::{self, RefineCloud};
use crate::se3::{invert_rigid, translation, Rigid, Transform};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use std::ops::ControlFlow;
use std::time::Instant;

/// The evolutionary algorithm of a run. All share the six task losses.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Method {
    /// MTPCR: six populations with bi-channel knowledge sharing (the paper's method).
    Mtpcr,
    /// MFEA (Gupta et al. 2016): one population over the six tasks (baseline).
    Mfea,
    /// G-MFEA (Ding et al. 2019): MFEA with decision-variable translation (baseline).
    Gmfea,
}

/// Fewest points a cloud may have (and fewest kept by downsampling).
pub const MIN_POINTS: usize = 10;

/// Every setting of a run. `Config::default()` is the setting recommended for users;
/// [`Config::paper()`] reproduces the authors' reference implementation step for step. Each
/// field's doc gives its paper value; the default differs in five (see `Config::default`).
/// The field names are the same in Rust, Python keyword arguments, CLI flags and config files.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Config {
    /// The evolutionary algorithm: `mtpcr` (the paper's method), or the baselines `mfea`,
    /// `gmfea`. Paper: mtpcr.
    pub method: Method,
    /// Individuals per population (`n`; six populations). At least 4. Paper: 100.
    pub population_size: usize,
    /// Generations after the initial one (`G`). Paper: 60.
    pub generations: usize,
    /// Fraction of each cloud's points kept by downsampling, in (0, 1]. Paper: 0.05.
    pub sample_ratio: f64,
    /// Downsampling method. Paper: farthest-point sampling.
    pub sampling: Sampling,
    /// Probability per generation and task pair of intra-task sharing (aiding <-> original
    /// elites), in [0, 1]. Paper: 0.5.
    pub p_intra: f64,
    /// Probability per generation and task of inter-task sharing (the estimate composed from
    /// the other two tasks' bests), in [0, 1]. Paper: 0.5.
    pub p_inter: f64,
    /// Fraction of a population kept as elites (and shared per channel), in (0, 1]. Paper: 0.1.
    pub top_ratio: f64,
    /// Differential-evolution scale factor `F`, in (0, 2]. Paper: 0.5.
    pub scale_factor: f64,
    /// SBX distribution index at the first generation (>= 0). Paper: 2.
    pub sbx_eta_start: f64,
    /// SBX distribution index approached at the last generation (>= 0). Paper: 10.
    pub sbx_eta_end: f64,
    /// Weight of the loop-closure term `alpha * tanh(||C - I||_F)` in the original tasks' loss
    /// (>= 0). Paper: 0.05.
    pub alpha: f64,
    /// The aiding loss caps each point's distance at this fraction of `shift` (the largest
    /// bounding-box side), in (0, 10]. Paper: 0.1.
    pub aiding_cap_ratio: f64,
    /// Aiding loss in both directions (source -> target and target -> source). Paper: false.
    pub two_way_aiding: bool,
    /// Divide the loop term's translations by `shift` so the term has no unit. Paper: false.
    pub unit_free_loop_term: bool,
    /// Recompute the parents' loop terms each generation from the new bests. Paper: false
    /// (parents keep the loss they were scored with).
    pub refresh_loop_term: bool,
    /// Search structure of the losses. `fast` gives the same inlier counts as `exact`.
    pub search: SearchMethod,
    /// Independent evolutions (each with its own seed derived from `seed`); the one with the
    /// lowest sum of final original-task costs is kept (beyond the paper). At least 1. Paper: 1.
    pub restarts: usize,
    /// Iterations of the joint trimmed point-to-plane ICP of the three clouds after the
    /// evolution, which closes the loop exactly (beyond the paper); 0 = off. Paper: 0.
    pub refine_iterations: usize,
    /// Worker threads for the loss evaluations; 0 = all cores. The result does not depend on it.
    pub num_threads: usize,
    /// Seed of the run; `None` draws one (reported in the result).
    pub seed: Option<u64>,
}

impl Config {
    /// The authors' reference setting (the paper's Section IV-C).
    pub fn paper() -> Config {
        Config {
            method: Method::Mtpcr,
            population_size: 100,
            generations: 60,
            sample_ratio: 0.05,
            sampling: Sampling::Farthest,
            p_intra: 0.5,
            p_inter: 0.5,
            top_ratio: 0.1,
            scale_factor: 0.5,
            sbx_eta_start: 2.0,
            sbx_eta_end: 10.0,
            alpha: 0.05,
            aiding_cap_ratio: 0.1,
            two_way_aiding: false,
            unit_free_loop_term: false,
            refresh_loop_term: false,
            search: SearchMethod::Fast,
            restarts: 1,
            refine_iterations: 0,
            num_threads: 0,
            seed: None,
        }
    }

    /// Checks every field; the error names the first bad one.
    pub fn validate(&self) -> Result<()> {
        fn unit(field: &'static str, v: f64) -> Result<()> {
            if (0.0..=1.0).contains(&v) {
                Ok(())
            } else {
                Err(Error::config(field, format!("must be in [0, 1], got {v}")))
            }
        }
        if self.population_size < 4 || self.population_size > 1_000_000 {
            return Err(Error::config(
                "population_size",
                format!("must be in 4..=1000000, got {}", self.population_size),
            ));
        }
        if self.generations > 1_000_000 {
            return Err(Error::config(
                "generations",
                format!("must be at most 1000000, got {}", self.generations),
            ));
        }
        if !(self.sample_ratio > 0.0 && self.sample_ratio <= 1.0) {
            return Err(Error::config(
                "sample_ratio",
                format!("must be in (0, 1], got {}", self.sample_ratio),
            ));
        }
        unit("p_intra", self.p_intra)?;
        unit("p_inter", self.p_inter)?;
        if !(self.top_ratio > 0.0 && self.top_ratio <= 1.0) {
            return Err(Error::config(
                "top_ratio",
                format!("must be in (0, 1], got {}", self.top_ratio),
            ));
        }
        if !(self.scale_factor > 0.0 && self.scale_factor <= 2.0) {
            return Err(Error::config(
                "scale_factor",
                format!("must be in (0, 2], got {}", self.scale_factor),
            ));
        }
        for (field, v) in [
            ("sbx_eta_start", self.sbx_eta_start),
            ("sbx_eta_end", self.sbx_eta_end),
        ] {
            if !(v.is_finite() && (0.0..=1000.0).contains(&v)) {
                return Err(Error::config(
                    field,
                    format!("must be in [0, 1000], got {v}"),
                ));
            }
        }
        if !(self.alpha.is_finite() && self.alpha >= 0.0) {
            return Err(Error::config(
                "alpha",
                format!("must be finite and >= 0, got {}", self.alpha),
            ));
        }
        if !(self.aiding_cap_ratio > 0.0 && self.aiding_cap_ratio <= 10.0) {
            return Err(Error::config(
                "aiding_cap_ratio",
                format!("must be in (0, 10], got {}", self.aiding_cap_ratio),
            ));
        }
        if self.restarts == 0 || self.restarts > 1000 {
            return Err(Error::config(
                "restarts",
                format!("must be in 1..=1000, got {}", self.restarts),
            ));
        }
        if self.refine_iterations > 10_000 {
            return Err(Error::config(
                "refine_iterations",
                format!("must be at most 10000, got {}", self.refine_iterations),
            ));
        }
        if self.num_threads > 4096 {
            return Err(Error::config(
                "num_threads",
                format!(
                    "must be at most 4096 (0 = all cores), got {}",
                    self.num_threads
                ),
            ));
        }
        Ok(())
    }

    /// Loss evaluations of a complete run: per restart `6 n + G 6 2n` for MTPCR, and
    /// `36 n + G 12 n` for the baselines (their initial population of 6n is scored on all
    /// six tasks).
    pub fn evaluations(&self) -> usize {
        let (n, g) = (self.population_size, self.generations);
        let per_run = match self.method {
            Method::Mtpcr => 6 * n * (1 + 2 * g),
            Method::Mfea | Method::Gmfea => 6 * n * (6 + 2 * g),
        };
        self.restarts * per_run
    }
}

impl Default for Config {
    /// The recommended setting: the paper's method with five measured changes (RESULTS.md
    /// has the numbers): 4 independent evolutions of 30 generations instead of one of 60,
    /// a two-directional aiding loss capped at 0.3 shift instead of 0.1, and a final joint
    /// ICP refinement of the loop (20 iterations).
    fn default() -> Self {
        Config {
            restarts: 4,
            generations: 30,
            aiding_cap_ratio: 0.3,
            two_way_aiding: true,
            refine_iterations: 20,
            ..Config::paper()
        }
    }
}

/// Reported to the observer after each generation.
#[derive(Clone, Debug, PartialEq)]
pub struct Progress {
    /// Generations finished (1-based).
    pub generation: usize,
    /// Generations of the complete run.
    pub generations: usize,
    /// Best cost of each task, in the order of [`crate::TASK_NAMES`].
    pub best_costs: [f64; 6],
    /// Loss evaluations so far.
    pub evaluations: usize,
}

/// A per-generation callback: return `ControlFlow::Break(())` to stop the run.
pub type Observer<'a> = &'a mut dyn FnMut(&Progress) -> ControlFlow<()>;

/// Best final costs of the six tasks.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct BestCosts {
    /// Original tasks J1-o, J2-o, J3-o (local part plus loop term).
    pub original: [f64; 3],
    /// Aiding tasks J1-a, J2-a, J3-a.
    pub aiding: [f64; 3],
}

/// The result of a registration. `transforms[0]` is T12: it maps points of cloud 1 into the
/// frame of cloud 2 (`x_2 = T12 x_1`); likewise T23 and T31. All in the clouds' original frames.
#[derive(Clone, Debug, PartialEq)]
pub struct Registration {
    /// `[T12, T23, T31]`.
    pub transforms: [Transform; 3],
    /// Best final cost of each task.
    pub best_costs: BestCosts,
    /// Best cost of each task after the initial population (row 0) and after every generation,
    /// in the order of [`crate::TASK_NAMES`].
    pub history: Vec<[f64; 6]>,
    /// Loss evaluations made.
    pub evaluations: usize,
    /// Generations run (less than configured when the observer stopped the run).
    pub generations_run: usize,
    /// False when the observer stopped the run early.
    pub completed: bool,
    /// Wall-clock seconds of the whole call (preparation included for [`register`]).
    pub seconds: f64,
    /// The seed that reproduces this result.
    pub seed: u64,
    /// Inlier radius eps and shift of the prepared problem, in data units.
    pub eps: f64,
    /// Largest bounding-box side of the prepared clouds.
    pub shift: f64,
}

impl Registration {
    /// `||T31 T23 T12 - I||_F`: how far the three transforms are from closing the loop.
    pub fn loop_residual(&self) -> f64 {
        let [t12, t23, t31] = self.transforms;
        (t31 * t23 * t12 - Transform::identity()).norm()
    }

    /// Each cloud's transform into cloud 1's frame: `[I, T12^-1, T31]` (ready to merge).
    pub fn poses(&self) -> [Transform; 3] {
        [
            Transform::identity(),
            invert_rigid(&self.transforms[0]),
            self.transforms[2],
        ]
    }
}

/// Three clouds downsampled, centred and indexed once, ready to be registered with any seed or
/// evolution setting.
#[derive(Debug)]
pub struct PreparedProblem {
    clouds: [IndexedCloud; 3],
    /// Full-resolution centred clouds for the refinement (built only when it is on).
    full: Option<[RefineCloud; 3]>,
    centroids: [[f64; 3]; 3],
    eps: f64,
    shift: f64,
    sample_ratio: f64,
    sampling: Sampling,
    search: SearchMethod,
    aiding_cap_ratio: f64,
    seconds: f64,
}

impl PreparedProblem {
    /// Validates the clouds and the config, downsamples (random sampling uses `config.seed`, or
    /// 0 without one), centres, derives eps and shift, and builds the search structures.
    pub fn new(clouds: &[PointCloud; 3], config: &Config) -> Result<PreparedProblem> {
        let start = Instant::now();
        let clouds_in = clouds;
        config.validate()?;
        for (i, c) in clouds.iter().enumerate() {
            c.validate(&format!("cloud {}", i + 1), MIN_POINTS)?;
        }
        let pool = thread_pool(config.num_threads)?;
        let sampled: Vec<PointCloud> = pool.install(|| {
            use rayon::prelude::*;
            clouds
                .par_iter()
                .enumerate()
                .map(|(i, c)| {
                    let count = ((c.len() as f64 * config.sample_ratio).round() as usize)
                        .max(MIN_POINTS)
                        .min(c.len());
                    match config.sampling {
                        Sampling::Farthest => c.farthest_point_sample(count),
                        Sampling::Random => {
                            let seed = config.seed.unwrap_or(0) ^ (0x5eed_0000 + i as u64);
                            c.random_sample(count, &mut ChaCha8Rng::seed_from_u64(seed))
                        }
                    }
                })
                .collect()
        });
        let centroids: [[f64; 3]; 3] = std::array::from_fn(|i| sampled[i].centroid());
        let centred: Vec<PointCloud> = sampled
            .iter()
            .zip(&centroids)
            .map(|(c, m)| c.translated([-m[0], -m[1], -m[2]]))
            .collect();
        for (i, c) in centred.iter().enumerate() {
            c.validate(&format!("cloud {} after downsampling", i + 1), 2)?;
        }
        let d = centred
            .iter()
            .map(PointCloud::mean_nearest_neighbor_distance)
            .sum::<f64>()
            / 3.0;
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
        let clouds: [IndexedCloud; 3] = indexed
            .try_into()
            .map_err(|_| Error::InvalidInput("three clouds are needed".to_string()))?;
        let full = (config.refine_iterations > 0).then(|| {
            pool.install(|| {
                let [a, b, c] = std::array::from_fn(|i| {
                    let m = centroids[i];
                    clouds_full_centred(&clouds_in[i], m)
                });
                let ((ra, rb), rc) = rayon::join(
                    || rayon::join(|| RefineCloud::new(a), || RefineCloud::new(b)),
                    || RefineCloud::new(c),
                );
                [ra, rb, rc]
            })
        });
        Ok(PreparedProblem {
            clouds,
            full,
            centroids,
            eps,
            shift,
            sample_ratio: config.sample_ratio,
            sampling: config.sampling,
            search,
            aiding_cap_ratio: config.aiding_cap_ratio,
            seconds: start.elapsed().as_secs_f64(),
        })
    }

    /// The prepared (downsampled, centred) clouds.
    pub fn clouds(&self) -> &[IndexedCloud; 3] {
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

    /// Seconds spent preparing.
    pub fn seconds(&self) -> f64 {
        self.seconds
    }

    /// The losses of task `task` (0..3: T12, T23, T31) for a transform given in the ORIGINAL
    /// frames: `(aiding loss, original local loss)` (the loop term needs the other tasks and
    /// is left out). `two_way` selects the two-directional aiding loss.
    pub fn task_losses(&self, task: usize, t: &Transform, two_way: bool) -> (f64, f64) {
        let (s, d) = (task % 3, (task + 1) % 3);
        let inner = crate::se3::Rigid::from_matrix(&self.to_centred(s, d, t));
        let aiding = CappedDistanceLoss {
            source: &self.clouds[s],
            target: &self.clouds[d],
            method: self.search,
            two_way,
        }
        .evaluate(&inner);
        let original = InlierLoss {
            source: &self.clouds[s],
            target: &self.clouds[d],
            method: self.search,
        }
        .evaluate(&inner);
        (aiding, original)
    }

    /// Poses of the three clouds in cloud 1's centred frame from the two of the three
    /// evolved pairs (a spanning tree of the loop) whose loop-closed result has the lowest
    /// total local loss, so one poorly solved pair does not spoil the start of the refinement.
    fn consistent_start(&self, pairs: &[Rigid; 3]) -> [Rigid; 3] {
        let m: [Transform; 3] = std::array::from_fn(|j| pairs[j].to_matrix());
        let id = Transform::identity();
        // Each tree leaves out one pair; poses W_k map cloud k into cloud 1.
        let trees: [[Transform; 3]; 3] = [
            [id, m[2] * m[1], m[2]],                                 // without T12
            [id, invert_rigid(&m[0]), m[2]],                         // without T23
            [id, invert_rigid(&m[0]), invert_rigid(&(m[1] * m[0]))], // without T31
        ];
        let loss = |w: &[Transform; 3]| -> f64 {
            (0..3)
                .map(|i| {
                    let j = (i + 1) % 3;
                    let t = crate::se3::Rigid::from_matrix(&(invert_rigid(&w[j]) * w[i]));
                    InlierLoss {
                        source: &self.clouds[i],
                        target: &self.clouds[j],
                        method: self.search,
                    }
                    .evaluate(&t)
                })
                .sum()
        };
        let best = trees
            .iter()
            .min_by(|a, b| loss(a).total_cmp(&loss(b)))
            .expect("three trees");
        std::array::from_fn(|k| Rigid::from_matrix(&best[k]))
    }

    fn to_centred(&self, s: usize, d: usize, t: &Transform) -> Transform {
        let cs = self.centroids[s];
        let ct = self.centroids[d];
        translation([-ct[0], -ct[1], -ct[2]]) * t * translation(cs)
    }

    fn to_original(&self, s: usize, d: usize, t: &Transform) -> Transform {
        let cs = self.centroids[s];
        let ct = self.centroids[d];
        translation(ct) * t * translation([-cs[0], -cs[1], -cs[2]])
    }

    /// Refines given pairwise transforms T12, T23, T31 (original frames, e.g. an earlier
    /// result or the user's own guess) by `config.refine_iterations` steps of the joint ICP
    /// that `register` ends with. The result closes the loop exactly. The problem must have
    /// been prepared with `refine_iterations > 0`.
    pub fn refine(&self, transforms: &[Transform; 3], config: &Config) -> Result<[Transform; 3]> {
        config.validate()?;
        if config.refine_iterations == 0 {
            return Err(Error::config(
                "refine_iterations",
                "must be at least 1 to refine",
            ));
        }
        for (j, t) in transforms.iter().enumerate() {
            if !t.iter().all(|v| v.is_finite()) {
                return Err(Error::InvalidInput(format!(
                    "T{} has a non-finite entry",
                    ["12", "23", "31"][j]
                )));
            }
        }
        let pool = thread_pool(config.num_threads)?;
        let centred: [Rigid; 3] = std::array::from_fn(|j| {
            Rigid::from_matrix(&self.to_centred(j, (j + 1) % 3, &transforms[j]))
        });
        let refined = self.refine_centred(&centred, config.refine_iterations, &pool)?;
        Ok(std::array::from_fn(|j| {
            self.to_original(j, (j + 1) % 3, &refined[j].to_matrix())
        }))
    }

    /// The joint ICP from the best spanning tree of `pairs` (centred frames); returns the
    /// loop-closed pairwise transforms.
    fn refine_centred(
        &self,
        pairs: &[Rigid; 3],
        iterations: usize,
        pool: &rayon::ThreadPool,
    ) -> Result<[Rigid; 3]> {
        let full = self.full.as_ref().ok_or_else(|| {
            Error::config(
                "refine_iterations",
                "this problem was prepared without refinement; prepare it again",
            )
        })?;
        let start = self.consistent_start(pairs);
        let poses = refine::refine_loop(full, start, self.eps, iterations, pool);
        // T_ij = W_j^-1 W_i with W_k mapping cloud k into cloud 1's (centred) frame.
        Ok(std::array::from_fn(|i| {
            let j = (i + 1) % 3;
            Rigid::from_matrix(&(invert_rigid(&poses[j].to_matrix()) * poses[i].to_matrix()))
        }))
    }

    /// Runs the evolution. `config`'s preparation settings (sampling, search, aiding cap) must
    /// be those this problem was prepared with.
    pub fn register(
        &self,
        config: &Config,
        observer: Option<Observer<'_>>,
    ) -> Result<Registration> {
        let start = Instant::now();
        config.validate()?;
        let mismatch = |field: &'static str| {
            Err(Error::config(
                field,
                "differs from the value this problem was prepared with; prepare it again",
            ))
        };
        if config.sample_ratio != self.sample_ratio {
            return mismatch("sample_ratio");
        }
        if config.sampling != self.sampling {
            return mismatch("sampling");
        }
        if config.search != self.search {
            return mismatch("search");
        }
        if config.aiding_cap_ratio != self.aiding_cap_ratio {
            return mismatch("aiding_cap_ratio");
        }
        let seed = config.seed.unwrap_or_else(rand::random);
        let pool = thread_pool(config.num_threads)?;
        let c = &self.clouds;
        let aiding: Vec<CappedDistanceLoss<'_>> = (0..3)
            .map(|j| CappedDistanceLoss {
                source: &c[j],
                target: &c[(j + 1) % 3],
                method: self.search,
                two_way: config.two_way_aiding,
            })
            .collect();
        let original: Vec<InlierLoss<'_>> = (0..3)
            .map(|j| InlierLoss {
                source: &c[j],
                target: &c[(j + 1) % 3],
                method: self.search,
            })
            .collect();
        let tasks = Tasks {
            losses: [
                &aiding[0],
                &aiding[1],
                &aiding[2],
                &original[0],
                &original[1],
                &original[2],
            ],
            search_box: SearchBox::for_shift(self.shift),
            shift: self.shift,
        };
        let mut keep_going = |_: &Progress| ControlFlow::Continue(());
        let observer = observer.unwrap_or(&mut keep_going);
        let total_generations = config.restarts * config.generations;
        let mut best: Option<evolve::Outcome> = None;
        let mut evaluations = 0;
        let mut generations_run = 0;
        let mut completed = true;
        for r in 0..config.restarts {
            // Restart 0 uses the seed itself, so one restart is exactly the paper's run.
            let run_seed = if r == 0 {
                seed
            } else {
                derive_seed(seed, r as u64)
            };
            let offset = generations_run;
            let done_before = evaluations;
            let mut forward = |p: &Progress| {
                observer(&Progress {
                    generation: offset + p.generation,
                    generations: total_generations,
                    evaluations: done_before + p.evaluations,
                    ..p.clone()
                })
            };
            let out = match config.method {
                Method::Mtpcr => evolve::run_mtpcr(&tasks, config, run_seed, &pool, &mut forward),
                Method::Mfea => {
                    crate::mfea::run_mfea(&tasks, config, run_seed, &pool, &mut forward, false)
                }
                Method::Gmfea => {
                    crate::mfea::run_mfea(&tasks, config, run_seed, &pool, &mut forward, true)
                }
            };
            evaluations += out.evaluations;
            generations_run += out.generations_run;
            let stopped = !out.completed;
            let total = |o: &evolve::Outcome| o.best_costs[3..].iter().sum::<f64>();
            if best.as_ref().is_none_or(|b| total(&out) < total(b)) {
                best = Some(out);
            }
            if stopped {
                completed = false;
                break;
            }
        }
        let out = best.expect("at least one restart runs");
        let centred: [Rigid; 3] = std::array::from_fn(|j| Rigid::from_individual(&out.best[3 + j]));
        let centred = if config.refine_iterations > 0 {
            self.refine_centred(&centred, config.refine_iterations, &pool)?
        } else {
            centred
        };
        let transforms: [Transform; 3] =
            std::array::from_fn(|j| self.to_original(j, (j + 1) % 3, &centred[j].to_matrix()));
        Ok(Registration {
            transforms,
            best_costs: BestCosts {
                aiding: [out.best_costs[0], out.best_costs[1], out.best_costs[2]],
                original: [out.best_costs[3], out.best_costs[4], out.best_costs[5]],
            },
            history: out.history,
            evaluations,
            generations_run,
            completed,
            seconds: start.elapsed().as_secs_f64(),
            seed,
            eps: self.eps,
            shift: self.shift,
        })
    }
}

/// A well-mixed seed for restart `r` (splitmix64 of the pair).
fn derive_seed(seed: u64, r: u64) -> u64 {
    let mut z = seed ^ r.wrapping_mul(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

fn clouds_full_centred(cloud: &PointCloud, centroid: [f64; 3]) -> Vec<[f64; 3]> {
    cloud
        .points()
        .iter()
        .map(|p| [p[0] - centroid[0], p[1] - centroid[1], p[2] - centroid[2]])
        .collect()
}

fn thread_pool(num_threads: usize) -> Result<rayon::ThreadPool> {
    rayon::ThreadPoolBuilder::new()
        .num_threads(num_threads)
        .build()
        .map_err(|e| Error::InvalidInput(format!("cannot start {num_threads} threads: {e}")))
}

/// Registers three overlapping clouds that form a loop, with no initial guess.
///
/// Returns T12, T23, T31 (T_ij maps cloud i into cloud j's frame) in the clouds' original
/// frames. `observer`, if given, is called after every generation and may stop the run.
pub fn register(
    clouds: &[PointCloud; 3],
    config: &Config,
    observer: Option<Observer<'_>>,
) -> Result<Registration> {
    let start = Instant::now();
    let mut config = config.clone();
    config.validate()?;
    config.seed = Some(config.seed.unwrap_or_else(rand::random));
    let prepared = PreparedProblem::new(clouds, &config)?;
    let mut result = prepared.register(&config, observer)?;
    result.seconds = start.elapsed().as_secs_f64();
    Ok(result)
}
