//! The evolutionary machinery shared by MTPCR and the baselines: the search box of an
//! individual, SBX, the tasks to score, parallel scoring, progress reports and the outcome.
//!
//! All random numbers are drawn on the calling thread in a fixed order; only the loss
//! evaluations run in parallel, and their results are collected in order. Every outcome is
//! therefore bit-identical for any number of threads.

pub(crate) mod mfea;
pub(crate) mod mtpcr;

use crate::config::Config;
use crate::graph::{TaskKind, ViewGraph};
use crate::loss::{loop_term, Loss};
use crate::se3::{decode, Individual, Rigid, Transform};
use rand::RngExt;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use std::ops::ControlFlow;

/// Reported to the observer after each generation, or each batch of pairs screened.
#[derive(Clone, Debug, PartialEq)]
pub struct Progress {
    /// What is being counted.
    pub stage: Stage,
    /// Steps finished: generations (1-based, counted across restarts), or pairs screened.
    pub generation: usize,
    /// Steps of the complete stage: generations of the run (all restarts), or pairs to screen.
    pub generations: usize,
    /// Best cost of each task of the current evolution, in task-slot order (the order of
    /// [`ViewGraph::task_names`]); empty while screening pairs.
    pub best_costs: Vec<f64>,
    /// Loss evaluations so far.
    pub evaluations: usize,
}

/// The stage a [`Progress`] report counts.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stage {
    /// Generations of the evolution (two or three scans, or scans in loop order).
    Generation,
    /// Pairs screened for feature hypotheses (four or more scans in no known order).
    PairScreening,
}

/// A progress callback (after each generation, or each batch of pairs screened): return
/// `ControlFlow::Break(())` to stop the run.
pub type Observer<'a> = &'a mut dyn FnMut(&Progress) -> ControlFlow<()>;

/// A child is redrawn when it leaves the box by more than this fraction of the upper bound.
const REDRAW_BEYOND: f64 = 0.1;

/// The search box of one individual.
#[derive(Clone, Copy, Debug)]
pub(crate) struct SearchBox {
    pub lower: Individual,
    pub upper: Individual,
}

impl SearchBox {
    /// Angles in [-180, 180] degrees, translations in [-shift, shift].
    pub fn for_shift(shift: f64) -> SearchBox {
        SearchBox {
            lower: [-180.0, -180.0, -180.0, -shift, -shift, -shift],
            upper: [180.0, 180.0, 180.0, shift, shift, shift],
        }
    }

    pub fn sample(&self, rng: &mut ChaCha8Rng) -> Individual {
        std::array::from_fn(|d| self.uniform(d, rng))
    }

    /// The point of the box at fractions `u` of each side (`u` in the unit cube `[0, 1]^6`
    /// gives a point of the box; the unified space of MFEA and G-MFEA).
    pub fn decode_unit(&self, u: &[f64; 6]) -> Individual {
        std::array::from_fn(|d| self.at(d, u[d]))
    }

    fn at(&self, d: usize, r: f64) -> f64 {
        self.lower[d] + (self.upper[d] - self.lower[d]) * r
    }

    fn uniform(&self, d: usize, rng: &mut ChaCha8Rng) -> f64 {
        self.at(d, rng.random::<f64>())
    }

    /// The bound rule: far outside -> redraw, slightly outside -> clip.
    pub fn repair(&self, x: &mut Individual, rng: &mut ChaCha8Rng) {
        for (d, v) in x.iter_mut().enumerate() {
            let (lo, hi) = (self.lower[d], self.upper[d]);
            let slack = REDRAW_BEYOND * hi.abs();
            if *v > hi + slack || *v < lo - slack {
                *v = self.uniform(d, rng);
            } else {
                *v = v.clamp(lo, hi);
            }
        }
    }
}

/// What an evolution needs to score an individual of each task.
pub(crate) struct Tasks<'a> {
    /// The view graph whose edges the tasks solve.
    pub graph: &'a ViewGraph,
    /// The loss of each task slot (aiding slots, then the original tasks' local parts).
    pub losses: Vec<&'a dyn Loss>,
    pub search_box: SearchBox,
    /// Translations are divided by this in the unit-free loop term.
    pub shift: f64,
    /// Individuals placed in each edge's initial populations (both of them) in place of
    /// the first random ones: pose hypotheses found elsewhere (empty: none).
    pub seeds: Vec<Vec<Individual>>,
    /// Stops the search between generations.
    pub interrupt: &'a crate::interrupt::Interrupt,
}

impl Tasks<'_> {
    /// The initial population of `slot`: `random`, with the edge's seeds in front.
    pub fn seeded(&self, slot: usize, mut random: Vec<Individual>) -> Vec<Individual> {
        let edge = self.graph.task(slot).edge;
        if let Some(seeds) = self.seeds.get(edge) {
            for (x, s) in random.iter_mut().zip(seeds) {
                *x = *s;
            }
        }
        random
    }

    /// Number of task slots.
    pub fn count(&self) -> usize {
        self.losses.len()
    }

    /// The loop term of an original task's candidate `x` for edge `edge`, with the other
    /// edges' bests; 0 without a loop.
    pub fn loop_term(
        &self,
        edge: usize,
        x: &Transform,
        bests: &[Transform],
        config: &Config,
    ) -> f64 {
        let unit_free = config.unit_free_loop_term.then_some(self.shift);
        self.graph
            .loop_product(edge, x, bests)
            .map_or(0.0, |c| loop_term(&c, config.alpha, unit_free))
    }
}

/// Result of one evolution, in the centred frames of the prepared clouds.
pub(crate) struct Outcome {
    /// The best individual of each task slot.
    pub best: Vec<Individual>,
    pub best_costs: Vec<f64>,
    pub history: Vec<Vec<f64>>,
    pub evaluations: usize,
    pub generations_run: usize,
    pub completed: bool,
}

impl Outcome {
    /// Sum of the original tasks' final costs (how restarts are compared).
    pub fn original_total(&self) -> f64 {
        let e = self.best_costs.len() / 2;
        self.best_costs[e..].iter().sum::<f64>()
    }
}

/// The number of elites (and of shared individuals per channel): `round(top_ratio * n)`, at
/// least 1.
pub(crate) fn elite_count(config: &Config) -> usize {
    ((config.top_ratio * config.population_size as f64).round() as usize)
        .clamp(1, config.population_size)
}

/// Records a generation's best costs in `history` and reports them to the observer; true
/// when the observer asks to stop.
pub(crate) fn end_of_generation(
    history: &mut Vec<Vec<f64>>,
    best_costs: Vec<f64>,
    generation: usize,
    generations: usize,
    evaluations: usize,
    observer: &mut dyn FnMut(&Progress) -> ControlFlow<()>,
) -> bool {
    history.push(best_costs.clone());
    observer(&Progress {
        stage: Stage::Generation,
        generation: generation + 1,
        generations,
        best_costs,
        evaluations,
    })
    .is_break()
}

/// SBX spread factor for a uniform draw `u` and index `eta`.
pub(crate) fn sbx_beta(u: f64, eta: f64) -> f64 {
    let e = 1.0 / (eta + 1.0);
    if u <= 0.5 {
        (2.0 * u).powf(e)
    } else {
        (1.0 / (2.0 - 2.0 * u)).powf(e)
    }
}

/// The two SBX children of one variable: `(x + y)/2 -+ beta (y - x)/2` (the first is the
/// one nearer `x` when `beta < 1`).
#[inline]
pub(crate) fn sbx_children(x: f64, y: f64, beta: f64) -> (f64, f64) {
    let mid = 0.5 * (x + y);
    let half = 0.5 * beta * (y - x);
    (mid - half, mid + half)
}

/// The SBX index of generation `g` (0-based): from `sbx_eta_start` linearly towards
/// `sbx_eta_end`, `start + (end - start) g / G`.
pub(crate) fn sbx_eta(config: &Config, g: usize) -> f64 {
    config.sbx_eta_start
        + (config.sbx_eta_end - config.sbx_eta_start) * g as f64 / config.generations as f64
}

/// Scores `(cost, local)` of `jobs` (task slot, individual in the box), in parallel on `pool`
/// and returned in order. `bests` (the original tasks' bests by edge) = None leaves the loop
/// term out. A job whose cost is certainly >= `limits[slot]` stops early and scores infinity
/// (pass infinite limits to evaluate everything in full).
pub(crate) fn score_all(
    tasks: &Tasks<'_>,
    config: &Config,
    pool: &rayon::ThreadPool,
    jobs: &[(usize, Individual)],
    bests: Option<&[Transform]>,
    limits: &[f64],
) -> Vec<(f64, f64)> {
    pool.install(|| {
        jobs.par_iter()
            .map(|(slot, x)| {
                let task = tasks.graph.task(*slot);
                let lp = match (bests, task.kind) {
                    (Some(b), TaskKind::Original) => {
                        tasks.loop_term(task.edge, &decode(x), b, config)
                    }
                    _ => 0.0,
                };
                // The margin covers rounding in `local + lp`, so pruning never drops a child
                // that full evaluation would have kept.
                let limit = limits[*slot] - lp + 1e-12;
                match tasks.losses[*slot].evaluate_below(&Rigid::from_individual(x), limit) {
                    Some(local) => (local + lp, local),
                    None => (f64::INFINITY, f64::INFINITY),
                }
            })
            .collect()
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn sbx_beta_is_one_at_the_middle_and_spreads_with_low_eta() {
        assert!((sbx_beta(0.5, 2.0) - 1.0).abs() < 1e-12);
        assert!(sbx_beta(0.99, 2.0) > sbx_beta(0.99, 10.0));
        assert!(sbx_beta(0.01, 2.0) < sbx_beta(0.01, 10.0));
    }

    #[test]
    fn repair_clips_near_misses_and_redraws_far_ones() {
        let b = SearchBox::for_shift(1.0);
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let mut x = [185.0, -190.0, 250.0, 1.05, -1.2, 0.5];
        b.repair(&mut x, &mut rng);
        assert_eq!(x[0], 180.0, "5 degrees over (< 18) is clipped");
        assert_eq!(x[1], -180.0, "10 degrees under is clipped");
        assert!(
            x[2] != 180.0 && (-180.0..=180.0).contains(&x[2]),
            "70 over is redrawn"
        );
        assert_eq!(x[3], 1.0);
        assert!(x[4] != -1.0 && (-1.0..=1.0).contains(&x[4]));
        assert_eq!(x[5], 0.5);
    }
}
