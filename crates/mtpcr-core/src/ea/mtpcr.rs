//! MTPCR: two populations per edge of the view graph (the original task and its aiding
//! task), evolved together with bi-channel knowledge sharing (the paper's "One generation"):
//! intra-task (elites swapped between the two populations of an edge) and inter-task (the
//! estimate composed from the rest of the loop, on a ring).

use super::{
    elite_count, end_of_generation, sbx_beta, sbx_children, sbx_eta, score_all, Outcome, Progress,
    Tasks,
};
use crate::config::Config;
use crate::se3::{decode, encode, Individual, Transform};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::ops::ControlFlow;

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
    let slots = tasks.count();
    let edges = slots / 2;
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let sbox = tasks.search_box;

    // Initialisation: populations in slot order, uniform in the box; no loop term.
    let init: Vec<Vec<Individual>> = (0..slots)
        .map(|s| tasks.seeded(s, (0..n).map(|_| sbox.sample(&mut rng)).collect()))
        .collect();
    let jobs: Vec<(usize, Individual)> = init
        .iter()
        .enumerate()
        .flat_map(|(s, xs)| xs.iter().map(move |x| (s, *x)))
        .collect();
    let scores = score_all(
        tasks,
        config,
        pool,
        &jobs,
        None,
        &vec![f64::INFINITY; slots],
    );
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
    let best_costs = |pops: &[Population]| -> Vec<f64> { pops.iter().map(|p| p.cost[0]).collect() };
    let mut history = vec![best_costs(&pops)];

    let mut generations_run = 0;
    let mut completed = true;
    for g in 0..generations {
        // The loop term and the inter-task channel use the bests at the end of the previous
        // generation, for all three tasks alike.
        let bests: Vec<Transform> = (0..edges).map(|j| decode(&pops[edges + j].x[0])).collect();
        if config.refresh_loop_term {
            for j in 0..edges {
                let p = &mut pops[edges + j];
                for i in 0..n {
                    let t = decode(&p.x[i]);
                    p.cost[i] = p.local[i] + tasks.loop_term(j, &t, &bests, config);
                }
                p.sort_truncate(n);
            }
        }
        let eta = sbx_eta(config, g);

        let mut children: Vec<Vec<Individual>> = vec![Vec::new(); slots];
        for j in 0..edges {
            let (aid, orig) = (&pops[j], &pops[edges + j]);
            let mut v_aid = mutants(aid, k, config.scale_factor, &mut rng);
            let mut v_orig = mutants(orig, k, config.scale_factor, &mut rng);

            // Bi-channel sharing inside the mutant pool.
            let picks: Vec<usize> = (0..2 * k).map(|_| rng.random_range(0..n)).collect();
            let inter = rng.random::<f64>() < config.p_inter;
            let intra = rng.random::<f64>() < config.p_intra;
            // A single edge has no loop, so no inter-task message (the draw is still made).
            if let Some(estimate) = inter
                .then(|| tasks.graph.loop_estimate(j, &bests))
                .flatten()
            {
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
            children[edges + j] = c_orig;
        }

        let jobs: Vec<(usize, Individual)> = children
            .iter()
            .enumerate()
            .flat_map(|(s, xs)| xs.iter().map(move |x| (s, *x)))
            .collect();
        let limits: Vec<f64> = if prune {
            pops.iter().map(|p| p.cost[n - 1]).collect()
        } else {
            vec![f64::INFINITY; slots]
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
        best: pops.iter().map(|p| p.x[0]).collect(),
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
    use crate::ea::SearchBox;
    use crate::graph::ViewGraph;
    use crate::loss::{CappedDistanceLoss, InlierLoss, Loss};
    use crate::search::{IndexedCloud, SearchMethod};

    fn sample_clouds(views: usize) -> Vec<IndexedCloud> {
        let problem = crate::synthetic::three_views(5, 3000);
        problem.clouds[..views]
            .iter()
            .map(|c| {
                let m = c.centroid();
                let pts = c
                    .farthest_point_sample(300)
                    .translated([-m[0], -m[1], -m[2]]);
                IndexedCloud::new(pts.into_points(), 0.004, 0.015, SearchMethod::Fast)
            })
            .collect()
    }

    #[test]
    fn pruned_evaluation_gives_the_same_run() {
        for (graph, two_way) in [
            (ViewGraph::ring(3).unwrap(), false),
            (ViewGraph::ring(3).unwrap(), true),
            (ViewGraph::pair(), true),
        ] {
            let clouds = sample_clouds(graph.views());
            let edges = graph.edges();
            let aid: Vec<_> = edges
                .iter()
                .map(|e| CappedDistanceLoss {
                    source: &clouds[e.source],
                    target: &clouds[e.target],
                    two_way,
                })
                .collect();
            let ori: Vec<_> = edges
                .iter()
                .map(|e| InlierLoss {
                    source: &clouds[e.source],
                    target: &clouds[e.target],
                })
                .collect();
            let mut losses: Vec<&dyn Loss> = aid.iter().map(|l| l as &dyn Loss).collect();
            losses.extend(ori.iter().map(|l| l as &dyn Loss));
            let tasks = Tasks {
                graph: &graph,
                losses,
                search_box: SearchBox::for_shift(0.15),
                shift: 0.15,
                seeds: Vec::new(),
                interrupt: &crate::interrupt::Interrupt::new(),
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
            assert_eq!(a.history[0].len(), graph.task_count());
            assert!(
                a.history.last().unwrap()[0] < a.history[0][0],
                "the search improves"
            );
        }
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
