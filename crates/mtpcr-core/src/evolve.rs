//! The six-population evolution of MTPCR (DESIGN.md, "One generation").
//!
//! All random numbers are drawn on the calling thread in a fixed order; only the loss
//! evaluations run in parallel, and their results are collected in order. The outcome is
//! therefore bit-identical for any number of threads.

use crate::fitness::Loss;
use crate::registration::{Config, Progress};
use crate::se3::{decode, encode, invert_rigid, Individual, Rigid, Transform};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use std::ops::ControlFlow;

/// Slots of the six tasks: aiding tasks 0..3, then original tasks 3..6 (task j pairs
/// cloud j with cloud j+1).
pub const TASK_NAMES: [&str; 6] = ["J1-a", "J2-a", "J3-a", "J1-o", "J2-o", "J3-o"];

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

    fn sample(&self, rng: &mut ChaCha8Rng) -> Individual {
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
    fn repair(&self, x: &mut Individual, rng: &mut ChaCha8Rng) {
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

/// What the evolution needs to score an individual of each task.
pub(crate) struct Tasks<'a> {
    /// Losses of the six slots (aiding 0..3, original local parts 3..6).
    pub losses: [&'a dyn Loss; 6],
    pub search_box: SearchBox,
    /// Translations are divided by this in the unit-free loop term.
    pub shift: f64,
}

/// Result of one evolution, in the centred frames of the prepared clouds.
pub(crate) struct Outcome {
    pub best: [Individual; 6],
    pub best_costs: [f64; 6],
    pub history: Vec<[f64; 6]>,
    pub evaluations: usize,
    pub generations_run: usize,
    pub completed: bool,
}

/// One population, kept sorted by cost (best first) between generations.
#[derive(Clone)]
struct Population {
    x: Vec<Individual>,
    cost: Vec<f64>,
    /// The loss without the loop term (equal to `cost` for aiding tasks).
    local: Vec<f64>,
}

impl Population {
    /// Keeps the `n` best of the current members and `children` (stable: ties keep parents,
    /// then children in order).
    fn select(&mut self, children: Vec<Individual>, scores: &[(f64, f64)], n: usize) {
        self.x.extend(children);
        self.cost.extend(scores.iter().map(|s| s.0));
        self.local.extend(scores.iter().map(|s| s.1));
        self.sort_truncate(n);
    }

    fn sort_truncate(&mut self, n: usize) {
        let mut order: Vec<usize> = (0..self.x.len()).collect();
        order.sort_by(|&a, &b| self.cost[a].total_cmp(&self.cost[b]));
        order.truncate(n);
        self.x = order.iter().map(|&i| self.x[i]).collect();
        self.cost = order.iter().map(|&i| self.cost[i]).collect();
        self.local = order.iter().map(|&i| self.local[i]).collect();
    }
}

/// `alpha * tanh(||C - I||_F)` for the loop product `C` with `t` in slot `task` and the other
/// original tasks' bests in theirs.
pub(crate) fn loop_term(
    task: usize,
    t: &Transform,
    bests: &[Transform; 3],
    alpha: f64,
    unit_free_shift: Option<f64>,
) -> f64 {
    let c = match task {
        0 => bests[2] * bests[1] * t,
        1 => bests[2] * t * bests[0],
        _ => t * bests[1] * bests[0],
    };
    let mut d = c - Transform::identity();
    if let Some(s) = unit_free_shift {
        for i in 0..3 {
            d[(i, 3)] /= s;
        }
    }
    alpha * d.norm().tanh()
}

/// The number of elites (and of shared individuals per channel): `round(top_ratio * n)`, at
/// least 1.
pub(crate) fn elite_count(config: &Config) -> usize {
    ((config.top_ratio * config.population_size as f64).round() as usize)
        .clamp(1, config.population_size)
}

/// Draws an index in `0..n` different from every index in `not`.
fn draw_other(rng: &mut ChaCha8Rng, n: usize, not: &[usize]) -> usize {
    loop {
        let r = rng.random_range(0..n);
        if !not.contains(&r) {
            return r;
        }
    }
}

/// DE/pbest/1 mutants of a population: `e_b + F (x_r1 - x_r2)`.
fn mutants(pop: &Population, elites: usize, f: f64, rng: &mut ChaCha8Rng) -> Vec<Individual> {
    let n = pop.x.len();
    (0..n)
        .map(|i| {
            let b = rng.random_range(0..elites);
            let r1 = draw_other(rng, n, &[i]);
            let r2 = draw_other(rng, n, &[i, r1]);
            std::array::from_fn(|d| pop.x[b][d] + f * (pop.x[r1][d] - pop.x[r2][d]))
        })
        .collect()
}

/// Records a generation's best costs in `history` and reports them to the observer; true
/// when the observer asks to stop. Shared by MTPCR and the baselines.
pub(crate) fn end_of_generation(
    history: &mut Vec<[f64; 6]>,
    best_costs: [f64; 6],
    generation: usize,
    generations: usize,
    evaluations: usize,
    observer: &mut dyn FnMut(&Progress) -> ControlFlow<()>,
) -> bool {
    history.push(best_costs);
    observer(&Progress {
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
/// and returned in order. `bests` = None leaves the loop term out of the original tasks' cost.
/// A job whose cost is certainly >= `limits[slot]` stops early and scores infinity (pass
/// infinite limits to evaluate everything in full).
pub(crate) fn score_all(
    tasks: &Tasks<'_>,
    config: &Config,
    pool: &rayon::ThreadPool,
    jobs: &[(usize, Individual)],
    bests: Option<&[Transform; 3]>,
    limits: &[f64; 6],
) -> Vec<(f64, f64)> {
    let unit_free = config.unit_free_loop_term.then_some(tasks.shift);
    pool.install(|| {
        jobs.par_iter()
            .map(|(slot, x)| {
                let lp = match (bests, *slot >= 3) {
                    (Some(b), true) => loop_term(*slot - 3, &decode(x), b, config.alpha, unit_free),
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

/// Runs MTPCR. `observer` is called after every generation on the calling thread; a
/// `Break` stops the run after that generation.
pub(crate) fn run_mtpcr(
    tasks: &Tasks<'_>,
    config: &Config,
    seed: u64,
    pool: &rayon::ThreadPool,
    observer: &mut dyn FnMut(&Progress) -> ControlFlow<()>,
) -> Outcome {
    run_mtpcr_with(tasks, config, seed, pool, observer, true)
}

/// [`run_mtpcr`]; `prune = false` evaluates every child in full (for the tests that show
/// pruning changes nothing).
fn run_mtpcr_with(
    tasks: &Tasks<'_>,
    config: &Config,
    seed: u64,
    pool: &rayon::ThreadPool,
    observer: &mut dyn FnMut(&Progress) -> ControlFlow<()>,
    prune: bool,
) -> Outcome {
    let n = config.population_size;
    let k = elite_count(config);
    let generations = config.generations;
    let unit_free = config.unit_free_loop_term.then_some(tasks.shift);
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let sbox = tasks.search_box;

    // Initialisation: populations in slot order, uniform in the box; no loop term.
    let init: Vec<Vec<Individual>> = (0..6)
        .map(|_| (0..n).map(|_| sbox.sample(&mut rng)).collect())
        .collect();
    let jobs: Vec<(usize, Individual)> = init
        .iter()
        .enumerate()
        .flat_map(|(s, xs)| xs.iter().map(move |x| (s, *x)))
        .collect();
    let scores = score_all(tasks, config, pool, &jobs, None, &[f64::INFINITY; 6]);
    let mut evaluations = jobs.len();
    let mut pops: Vec<Population> = init
        .into_iter()
        .enumerate()
        .map(|(s, x)| {
            let sc = &scores[s * n..(s + 1) * n];
            let mut p = Population {
                x,
                cost: sc.iter().map(|v| v.0).collect(),
                local: sc.iter().map(|v| v.1).collect(),
            };
            p.sort_truncate(n);
            p
        })
        .collect();
    let best_costs = |pops: &[Population]| -> [f64; 6] { std::array::from_fn(|s| pops[s].cost[0]) };
    let mut history = vec![best_costs(&pops)];

    let mut generations_run = 0;
    let mut completed = true;
    for g in 0..generations {
        // The loop term and the inter-task channel use the bests at the end of the previous
        // generation, for all three tasks alike.
        let bests: [Transform; 3] = std::array::from_fn(|j| decode(&pops[3 + j].x[0]));
        if config.refresh_loop_term {
            for j in 0..3 {
                let p = &mut pops[3 + j];
                for i in 0..n {
                    let t = decode(&p.x[i]);
                    p.cost[i] = p.local[i] + loop_term(j, &t, &bests, config.alpha, unit_free);
                }
                p.sort_truncate(n);
            }
        }
        let eta = sbx_eta(config, g);

        let mut children: Vec<Vec<Individual>> = vec![Vec::new(); 6];
        for j in 0..3 {
            let (aid, orig) = (&pops[j], &pops[3 + j]);
            let mut v_aid = mutants(aid, k, config.scale_factor, &mut rng);
            let mut v_orig = mutants(orig, k, config.scale_factor, &mut rng);

            // Bi-channel sharing inside the mutant pool.
            let picks: Vec<usize> = (0..2 * k).map(|_| rng.random_range(0..n)).collect();
            let inter = rng.random::<f64>() < config.p_inter;
            let intra = rng.random::<f64>() < config.p_intra;
            if inter {
                let estimate = invert_rigid(&(bests[(j + 2) % 3] * bests[(j + 1) % 3]));
                let x = encode(&estimate);
                for &i in &picks[..k] {
                    v_aid[i] = x;
                    v_orig[i] = x;
                }
            }
            if intra {
                for (m, &i) in picks[k..].iter().enumerate() {
                    v_aid[i] = orig.x[m];
                    v_orig[i] = aid.x[m];
                }
            }

            // SBX between each member and its mutant, both children kept; the pair shares u.
            let mut c_aid = vec![[0.0; 6]; 2 * n];
            let mut c_orig = vec![[0.0; 6]; 2 * n];
            for i in 0..n {
                for d in 0..6 {
                    let beta = sbx_beta(rng.random::<f64>(), eta);
                    for (pop, v, c) in [(aid, &v_aid, &mut c_aid), (orig, &v_orig, &mut c_orig)] {
                        let (lo, hi) = sbx_children(pop.x[i][d], v[i][d], beta);
                        c[i][d] = lo;
                        c[n + i][d] = hi;
                    }
                }
            }
            for c in c_aid.iter_mut().chain(c_orig.iter_mut()) {
                sbox.repair(c, &mut rng);
            }
            children[j] = c_aid;
            children[3 + j] = c_orig;
        }

        let jobs: Vec<(usize, Individual)> = children
            .iter()
            .enumerate()
            .flat_map(|(s, xs)| xs.iter().map(move |x| (s, *x)))
            .collect();
        let limits: [f64; 6] = if prune {
            std::array::from_fn(|s| pops[s].cost[n - 1])
        } else {
            [f64::INFINITY; 6]
        };
        // A child whose cost is certainly >= the worst parent's cost can never be selected: it
        // stops early and scores infinity; selection is unchanged.
        let scores = score_all(tasks, config, pool, &jobs, Some(&bests), &limits);
        evaluations += jobs.len();
        for (s, kids) in children.into_iter().enumerate() {
            let sc = &scores[s * 2 * n..(s + 1) * 2 * n];
            pops[s].select(kids, sc, n);
        }
        generations_run = g + 1;
        let best = best_costs(&pops);
        if end_of_generation(&mut history, best, g, generations, evaluations, observer) {
            completed = g + 1 == generations;
            break;
        }
    }

    Outcome {
        best: std::array::from_fn(|s| pops[s].x[0]),
        best_costs: best_costs(&pops),
        history,
        evaluations,
        generations_run,
        completed,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pruned_evaluation_gives_the_same_run() {
        use crate::fitness::{CappedDistanceLoss, IndexedCloud, InlierLoss, SearchMethod};
        let problem = crate::synthetic::three_views(5, 3000);
        let clouds: Vec<IndexedCloud> = problem
            .clouds
            .iter()
            .map(|c| {
                let m = c.centroid();
                let pts = c
                    .farthest_point_sample(300)
                    .translated([-m[0], -m[1], -m[2]]);
                IndexedCloud::new(pts.into_points(), 0.004, 0.015, SearchMethod::Fast)
            })
            .collect();
        for two_way in [false, true] {
            let aid: Vec<_> = (0..3)
                .map(|j| CappedDistanceLoss {
                    source: &clouds[j],
                    target: &clouds[(j + 1) % 3],
                    method: SearchMethod::Fast,
                    two_way,
                })
                .collect();
            let ori: Vec<_> = (0..3)
                .map(|j| InlierLoss {
                    source: &clouds[j],
                    target: &clouds[(j + 1) % 3],
                    method: SearchMethod::Fast,
                })
                .collect();
            let tasks = Tasks {
                losses: [&aid[0], &aid[1], &aid[2], &ori[0], &ori[1], &ori[2]],
                search_box: SearchBox::for_shift(0.15),
                shift: 0.15,
            };
            let config = Config {
                population_size: 30,
                generations: 15,
                refresh_loop_term: two_way,
                ..Config::paper()
            };
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(2)
                .build()
                .unwrap();
            let mut go = |_: &Progress| ControlFlow::Continue(());
            let a = run_mtpcr_with(&tasks, &config, 3, &pool, &mut go, true);
            let b = run_mtpcr_with(&tasks, &config, 3, &pool, &mut go, false);
            assert_eq!(a.best, b.best);
            assert_eq!(a.history, b.history);
        }
    }

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

    #[test]
    fn loop_term_is_zero_for_a_consistent_loop() {
        let t12 = decode(&[10.0, 20.0, 30.0, 0.1, 0.2, 0.3]);
        let t23 = decode(&[-40.0, 5.0, 60.0, -0.3, 0.0, 0.1]);
        let t31 = invert_rigid(&(t23 * t12));
        let bests = [t12, t23, t31];
        for (j, t) in bests.iter().enumerate() {
            assert!(loop_term(j, t, &bests, 0.05, None) < 1e-12);
        }
        let wrong = decode(&[0.0, 0.0, 90.0, 0.0, 0.0, 0.0]);
        let v = loop_term(0, &wrong, &bests, 0.05, None);
        assert!(v > 0.01 && v <= 0.05, "{v}");
    }

    #[test]
    fn select_keeps_the_best_and_prefers_parents_on_ties() {
        let mut p = Population {
            x: vec![[1.0; 6], [2.0; 6]],
            cost: vec![0.5, 0.7],
            local: vec![0.5, 0.7],
        };
        p.select(vec![[3.0; 6], [4.0; 6]], &[(0.5, 0.5), (0.1, 0.1)], 2);
        assert_eq!(p.x, vec![[4.0; 6], [1.0; 6]]);
        assert_eq!(p.cost, vec![0.1, 0.5]);
    }
}
