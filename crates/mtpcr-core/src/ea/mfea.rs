//! The baselines of the paper's Table 4: MFEA (Gupta et al. 2016) and G-MFEA (Ding et al.
//! 2019), over the same task losses as MTPCR.
//!
//! One population of `Kn` members (`K` tasks: two per edge of the view graph, six for the
//! three-view loop; the numbers below are for `K = 6`) lives in the unified space `[0, 1]^6`,
//! decoded into the search box (angles in [-180, 180] degrees, translations in
//! [-shift, shift]) only to be scored. Each member has a skill factor (the task slot 0..K it is
//! evaluated on) and a factorial cost per task (infinity where it was not evaluated).
//!
//! The choices the sources leave open:
//! - **Initial population**: `6n` uniform members, each evaluated on **all six** tasks (standard
//!   MFEA; the paper notes that the baselines' first best cost of each task is picked from `6n`
//!   individuals). Skill factor = the task of its best factorial rank (ties: lowest slot). No
//!   loop term in this evaluation, as in MTPCR.
//! - **Children per generation**: `12n`, from `6n` matings (two rounds; each round shuffles the
//!   population and pairs its halves, so every member mates twice per generation). This is
//!   exactly MTPCR's number of new individuals per generation (six populations x `2n`), which
//!   the paper says its population of 600 ensures. Each child is evaluated on its skill factor's
//!   task only.
//! - **Evaluations**: `36n + 12n G` per run (`6n x 6` initial, then `12n` per generation):
//!   75,600 with the defaults, against MTPCR's 72,600 (the same after the initial population).
//! - **Mating**: if both parents have the same skill factor, or `rand < 0.5` (rmp), SBX with
//!   every variable crossed (index from `sbx_eta_start` to `sbx_eta_end` linearly over the
//!   generations, as MTPCR), two children, each imitating a random parent's skill factor;
//!   otherwise each parent is mutated into one child that keeps its skill factor. Children are
//!   clipped into `[0, 1]^6`.
//! - **Mutation**: polynomial mutation (index 5, as MTO-Platform's MFEA) in its bounded form
//!   `x + delta x` / `x + delta (1 - x)`, which stays in `[0, 1]`; each variable mutates with
//!   probability 1/6 and one random variable always does, so no child is a copy of its parent.
//! - **Selection**: parents + children are ranked within each task among the members
//!   evaluated on it (ties in cost: earlier member first); scalar fitness `1 / min rank`; the `6n`
//!   fittest are kept (ties: parents first, then children in order) and their skill factors
//!   updated. Every task's best member has fitness 1, so best costs never get worse (save for
//!   `refresh_loop_term`, which rescores the original tasks' loop terms, as in MTPCR).
//! - **Loop term**: a child of an original task adds the loop term with the best transforms of
//!   the other two original tasks at the end of the previous generation, as MTPCR.
//! - **G-MFEA translation**: at generation `g` (0-based) with `g >= 10` and `(g - 10) % 5 == 0`,
//!   each task's translation becomes `d_k = (g / G)^2 (0.5 - m_k)`, `m_k` the mean (unified
//!   space) of the best 40% (by cost on `k`) of the members with skill factor `k`; it is zero
//!   before. In a cross-task SBX the parents are shifted by their own task's `d` before
//!   crossing, and each child is shifted back by the `d` of the task it imitates (the one it is
//!   evaluated on), then clipped. Shuffling does nothing for equal dimensions.
//!
//! Random numbers are all drawn on the calling thread in a fixed order; evaluations run in
//! parallel and are collected in order, so the outcome is bit-identical for any thread count.
//! Children are not pruned (no early exit): whether a child survives depends on the ranks of
//! the whole pool, so no cost limit is known in advance.

use super::{
    end_of_generation, sbx_beta, sbx_children, sbx_eta, score_all, Outcome, Progress, Tasks,
};
use crate::config::Config;
use crate::se3::DOF;
use crate::se3::{decode, Individual, Transform};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::ops::ControlFlow;

/// Random mating probability (paper, Section IV-C).
const RMP: f64 = 0.5;
/// Distribution index of the polynomial mutation.
const MUTATION_INDEX: f64 = 5.0;
/// First generation (0-based) at which G-MFEA computes its translations.
const TRANSLATION_START: usize = 10;
/// G-MFEA recomputes its translations every this many generations.
const TRANSLATION_INTERVAL: usize = 5;
/// Fraction of each task's members whose mean gives its translation.
const TRANSLATION_TOP: f64 = 0.4;

/// A point of the unified space `[0, 1]^6`.
type Unit = [f64; DOF];

/// One member of the single population.
#[derive(Clone, Debug)]
struct Member {
    u: Unit,
    /// Factorial costs by task slot (local part plus loop term); infinity where not evaluated.
    cost: Vec<f64>,
    /// Costs without the loop term (equal to `cost` for aiding tasks).
    local: Vec<f64>,
    /// The task slot the member is evaluated on (its best rank).
    skill: usize,
}

impl Member {
    fn evaluated_on(&self, s: usize) -> bool {
        // Not evaluated is +infinity; a NaN cost (degenerate input) still counts as
        // evaluated, ranked last by `total_cmp`, so every task keeps a member.
        self.local[s] != f64::INFINITY
    }
}

/// Keeps the `keep` members of highest scalar fitness `1 / min rank` (stable) and sets each
/// one's skill factor to the task of its best rank (ties: lowest slot).
fn select(mut pool: Vec<Member>, keep: usize) -> Vec<Member> {
    let m = pool.len();
    let tasks = pool.first().map_or(0, |member| member.cost.len());
    let mut best_rank = vec![usize::MAX; m];
    let mut best_task = vec![usize::MAX; m];
    for s in 0..tasks {
        let mut order: Vec<usize> = (0..m).filter(|&i| pool[i].evaluated_on(s)).collect();
        order.sort_by(|&a, &b| pool[a].cost[s].total_cmp(&pool[b].cost[s]));
        for (r, &i) in order.iter().enumerate() {
            if r < best_rank[i] {
                best_rank[i] = r;
                best_task[i] = s;
            }
        }
    }
    for (member, &s) in pool.iter_mut().zip(&best_task) {
        if s < tasks {
            member.skill = s;
        }
    }
    let mut order: Vec<usize> = (0..m).collect();
    order.sort_by_key(|&i| best_rank[i]);
    order.truncate(keep);
    let mut slots: Vec<Option<Member>> = pool.into_iter().map(Some).collect();
    order
        .iter()
        .map(|&i| slots[i].take().expect("each index once"))
        .collect()
}

/// Index of the member with the lowest cost on task `s` (the first of equals).
fn best_of(pop: &[Member], s: usize) -> usize {
    (0..pop.len())
        .filter(|&i| pop[i].evaluated_on(s))
        .min_by(|&a, &b| pop[a].cost[s].total_cmp(&pop[b].cost[s]))
        .expect("every task keeps its best member")
}

/// G-MFEA's translation of each task at generation `g` of `generations`:
/// `(g / G)^2 (0.5 - m_k)`, `m_k` the mean of the best 40% (at least one) of the members with
/// skill factor `k`; zero for a task without members.
fn translations(pop: &[Member], tasks: usize, g: usize, generations: usize) -> Vec<Unit> {
    let scale = (g as f64 / generations as f64).powi(2);
    (0..tasks).map(|k| translation_of(pop, k, scale)).collect()
}

/// One task's G-MFEA translation (see [`translations`]).
fn translation_of(pop: &[Member], k: usize, scale: f64) -> Unit {
    {
        let mut of_k: Vec<&Member> = pop.iter().filter(|m| m.skill == k).collect();
        if of_k.is_empty() {
            return [0.0; DOF];
        }
        of_k.sort_by(|a, b| a.cost[k].total_cmp(&b.cost[k]));
        let top = ((TRANSLATION_TOP * of_k.len() as f64).ceil() as usize).clamp(1, of_k.len());
        std::array::from_fn(|d| {
            let mean = of_k[..top].iter().map(|m| m.u[d]).sum::<f64>() / top as f64;
            scale * (0.5 - mean)
        })
    }
}

/// Polynomial mutation in `[0, 1]`: each variable with probability 1/6, and variable
/// `forced` (drawn first) always.
fn mutate(u: &Unit, rng: &mut ChaCha8Rng) -> Unit {
    let forced = rng.random_range(0..DOF);
    let e = 1.0 / (MUTATION_INDEX + 1.0);
    let mut x = *u;
    for (d, v) in x.iter_mut().enumerate() {
        let hit = rng.random::<f64>() < 1.0 / DOF as f64;
        if hit || d == forced {
            let r = rng.random::<f64>();
            *v = if r <= 0.5 {
                *v + ((2.0 * r).powf(e) - 1.0) * *v
            } else {
                *v + (1.0 - (2.0 * (1.0 - r)).powf(e)) * (1.0 - *v)
            };
        }
    }
    x
}

fn add(u: &Unit, d: &Unit) -> Unit {
    std::array::from_fn(|k| u[k] + d[k])
}

/// `u - d` clipped into `[0, 1]^6`.
fn sub_clipped(u: &Unit, d: &Unit) -> Unit {
    std::array::from_fn(|k| (u[k] - d[k]).clamp(0.0, 1.0))
}

/// A random permutation of `0..n` (Fisher-Yates, on the calling thread).
fn permutation(n: usize, rng: &mut ChaCha8Rng) -> Vec<usize> {
    let mut p: Vec<usize> = (0..n).collect();
    for i in (1..n).rev() {
        let j = rng.random_range(0..=i);
        p.swap(i, j);
    }
    p
}

/// SBX of two parents (every variable crossed, index `eta`) into two children, each imitating
/// a random parent's skill factor. With `shifts` and parents of different tasks (G-MFEA), each
/// parent is shifted by its task's translation first and each child shifted back by the
/// translation of the task it imitates. Children are clipped into `[0, 1]^6`.
fn crossover(
    a: &Member,
    b: &Member,
    eta: f64,
    shifts: Option<&[Unit]>,
    rng: &mut ChaCha8Rng,
) -> [(Unit, usize); 2] {
    let shifts = shifts.filter(|_| a.skill != b.skill);
    let (xa, xb) = match shifts {
        Some(d) => (add(&a.u, &d[a.skill]), add(&b.u, &d[b.skill])),
        None => (a.u, b.u),
    };
    let mut c = [[0.0; DOF]; 2];
    for d in 0..DOF {
        let beta = sbx_beta(rng.random::<f64>(), eta);
        (c[0][d], c[1][d]) = sbx_children(xa[d], xb[d], beta);
    }
    c.map(|child| {
        let s = if rng.random::<f64>() < 0.5 {
            a.skill
        } else {
            b.skill
        };
        let back = shifts.map_or([0.0; DOF], |d| d[s]);
        (sub_clipped(&child, &back), s)
    })
}

/// The `2 * pop.len()` children of one generation with their skill factors: two rounds, each
/// pairing the halves of a random permutation (see the module docs).
fn offspring(
    pop: &[Member],
    eta: f64,
    shifts: Option<&[Unit]>,
    rng: &mut ChaCha8Rng,
) -> Vec<(Unit, usize)> {
    let size = pop.len();
    let half = size / 2;
    let mut children = Vec::with_capacity(2 * size);
    for _round in 0..2 {
        let order = permutation(size, rng);
        for i in 0..half {
            let (a, b) = (&pop[order[i]], &pop[order[half + i]]);
            if a.skill == b.skill || rng.random::<f64>() < RMP {
                children.extend(crossover(a, b, eta, shifts, rng));
            } else {
                for p in [a, b] {
                    children.push((mutate(&p.u, rng), p.skill));
                }
            }
        }
    }
    children
}

/// Runs MFEA, or G-MFEA when `generalized`. `observer` is called after every generation on the
/// calling thread; a `Break` stops the run after that generation. See the module docs for the
/// operators and the evaluation count (`36n + 12n G`).
pub(crate) fn run_mfea(
    tasks: &Tasks<'_>,
    config: &Config,
    seed: u64,
    pool: &rayon::ThreadPool,
    observer: &mut dyn FnMut(&Progress) -> ControlFlow<()>,
    generalized: bool,
) -> Outcome {
    let slots = tasks.count();
    let edges = slots / 2;
    let size = slots * config.population_size;
    let generations = config.generations;
    let sbox = tasks.search_box;
    let no_limits = vec![f64::INFINITY; slots];
    let mut rng = ChaCha8Rng::seed_from_u64(seed);

    // Initialisation: every member on every task, no loop term.
    let init: Vec<Unit> = (0..size)
        .map(|_| std::array::from_fn(|_| rng.random::<f64>()))
        .collect();
    let jobs: Vec<(usize, Individual)> = init
        .iter()
        .flat_map(|u| {
            let x = sbox.decode_unit(u);
            (0..slots).map(move |s| (s, x))
        })
        .collect();
    let scores = score_all(tasks, config, pool, &jobs, None, &no_limits);
    let mut evaluations = jobs.len();
    let members: Vec<Member> = init
        .into_iter()
        .zip(scores.chunks(slots))
        .map(|(u, sc)| Member {
            u,
            cost: sc.iter().map(|v| v.0).collect(),
            local: sc.iter().map(|v| v.1).collect(),
            skill: 0,
        })
        .collect();
    let mut pop = select(members, size);
    let best_costs =
        |pop: &[Member]| -> Vec<f64> { (0..slots).map(|s| pop[best_of(pop, s)].cost[s]).collect() };
    let mut history = vec![best_costs(&pop)];

    let mut shifts = vec![[0.0; DOF]; slots];
    let mut generations_run = 0;
    let mut completed = true;
    for g in 0..generations {
        let bests: Vec<Transform> = (0..edges)
            .map(|j| decode(&sbox.decode_unit(&pop[best_of(&pop, edges + j)].u)))
            .collect();
        if config.refresh_loop_term {
            for m in pop.iter_mut() {
                let t = decode(&sbox.decode_unit(&m.u));
                for j in 0..edges {
                    if m.evaluated_on(edges + j) {
                        m.cost[edges + j] =
                            m.local[edges + j] + tasks.loop_term(j, &t, &bests, config);
                    }
                }
            }
        }
        if generalized
            && g >= TRANSLATION_START
            && (g - TRANSLATION_START) % TRANSLATION_INTERVAL == 0
        {
            shifts = translations(&pop, slots, g, generations);
        }
        let children = offspring(
            &pop,
            sbx_eta(config, g),
            generalized.then_some(&shifts[..]),
            &mut rng,
        );

        let jobs: Vec<(usize, Individual)> = children
            .iter()
            .map(|(u, s)| (*s, sbox.decode_unit(u)))
            .collect();
        let scores = score_all(tasks, config, pool, &jobs, Some(&bests), &no_limits);
        evaluations += jobs.len();
        let mut merged = pop;
        merged.extend(children.into_iter().zip(scores).map(|((u, s), sc)| {
            let mut cost = vec![f64::INFINITY; slots];
            let mut local = vec![f64::INFINITY; slots];
            (cost[s], local[s]) = sc;
            Member {
                u,
                cost,
                local,
                skill: s,
            }
        }));
        pop = select(merged, size);
        generations_run = g + 1;
        let best = best_costs(&pop);
        if end_of_generation(&mut history, best, g, generations, evaluations, observer) {
            completed = g + 1 == generations;
            break;
        }
    }

    Outcome {
        best: (0..slots)
            .map(|s| sbox.decode_unit(&pop[best_of(&pop, s)].u))
            .collect(),
        best_costs: best_costs(&pop),
        history,
        evaluations,
        generations_run,
        completed,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn member(u: f64, cost: [f64; 6], skill: usize) -> Member {
        Member {
            u: [u; 6],
            cost: cost.to_vec(),
            local: cost.to_vec(),
            skill,
        }
    }

    const INF: f64 = f64::INFINITY;

    #[test]
    fn selection_keeps_the_best_of_every_task_and_updates_skill_factors() {
        let pool = vec![
            // Evaluated everywhere: rank 1 on task 2 (cost 0.1), so skill factor 2.
            member(0.0, [0.9, 0.9, 0.1, 0.9, 0.9, 0.9], 0),
            member(0.1, [INF, INF, INF, 0.3, INF, INF], 3),
            member(0.2, [INF, INF, INF, 0.2, INF, INF], 3),
            member(0.3, [0.5, INF, INF, INF, INF, INF], 0),
            member(0.4, [INF, INF, INF, INF, INF, 0.7], 5),
        ];
        let kept = select(pool, 4);
        let u: Vec<f64> = kept.iter().map(|m| m.u[0]).collect();
        // Rank 1 on tasks 0, 1, 2, 3, 4, 5: 0.3 (task 0), 0.0 (tasks 1, 2, 4), 0.2 (task 3),
        // 0.4 (task 5); 0.1 has rank 2 at best and is dropped.
        assert_eq!(u, vec![0.0, 0.2, 0.3, 0.4]);
        assert_eq!(kept[0].skill, 1, "ties between ranks go to the lowest slot");
        assert_eq!(kept[1].skill, 3);
    }

    #[test]
    fn translation_moves_each_task_mean_towards_the_centre() {
        let mut pop = Vec::new();
        // Task 0: five members at 0.1 .. 0.5 with costs 1 .. 5; the best 40% are 0.1 and 0.2.
        for i in 0..5 {
            let mut c = [INF; 6];
            c[0] = 1.0 + i as f64;
            pop.push(member(0.1 * (i + 1) as f64, c, 0));
        }
        let mut c = [INF; 6];
        c[4] = 0.3;
        pop.push(member(0.9, c, 4));
        let d = translations(&pop, 6, 30, 60);
        for k in 0..6 {
            assert!((d[0][k] - 0.25 * (0.5 - 0.15)).abs() < 1e-12, "{:?}", d[0]);
            assert!((d[4][k] - 0.25 * (0.5 - 0.9)).abs() < 1e-12);
            assert_eq!(d[1][k], 0.0, "no member, no translation");
        }
        let shifted = add(&pop[0].u, &d[0]);
        assert!((shifted[0] - (0.1 + 0.0875)).abs() < 1e-12);
        let back = sub_clipped(&shifted, &d[4]);
        assert!((back[0] - (0.1 + 0.0875 + 0.1)).abs() < 1e-12);
        assert_eq!(sub_clipped(&[0.99; 6], &[-0.1; 6]), [1.0; 6]);
    }

    #[test]
    fn cross_task_crossover_shifts_the_parents_and_shifts_each_child_back() {
        let a = member(0.2, [1.0, INF, INF, INF, INF, INF], 0);
        let b = member(0.6, [INF, 1.0, INF, INF, INF, INF], 1);
        let mut shifts = vec![[0.0; DOF]; 6];
        shifts[0] = [0.05; 6];
        shifts[1] = [-0.15; 6];
        let eta = 2.0;
        for seed in 0..20 {
            let kids = crossover(
                &a,
                &b,
                eta,
                Some(&shifts[..]),
                &mut ChaCha8Rng::seed_from_u64(seed),
            );
            // The same draws by hand: six betas, then the two imitations; the parents
            // shifted to 0.2 + 0.05 and 0.6 - 0.15.
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            let betas: Vec<f64> = (0..6).map(|_| sbx_beta(rng.random::<f64>(), eta)).collect();
            for (c, kid) in kids.iter().enumerate() {
                let s = if rng.random::<f64>() < 0.5 { 0 } else { 1 };
                assert_eq!(kid.1, s);
                for d in 0..6 {
                    let (c1, c2) = sbx_children(0.2 + 0.05, 0.6 + -0.15, betas[d]);
                    let v = [c1, c2][c] - shifts[s][d];
                    assert_eq!(kid.0[d], v.clamp(0.0, 1.0));
                }
            }
            let plain = crossover(&a, &b, eta, None, &mut ChaCha8Rng::seed_from_u64(seed));
            assert_ne!(kids, plain, "the translation changes the children");
            let zero = [[0.0; 6]; 6];
            let same = crossover(
                &a,
                &b,
                eta,
                Some(&zero[..]),
                &mut ChaCha8Rng::seed_from_u64(seed),
            );
            assert_eq!(same, plain, "zero translations change nothing");
            // Parents of one task are never translated.
            let a2 = member(0.6, [2.0, INF, INF, INF, INF, INF], 0);
            let t = crossover(
                &a,
                &a2,
                eta,
                Some(&shifts[..]),
                &mut ChaCha8Rng::seed_from_u64(seed),
            );
            let p = crossover(&a, &a2, eta, None, &mut ChaCha8Rng::seed_from_u64(seed));
            assert_eq!(t, p);
        }
    }

    #[test]
    fn mutation_stays_in_the_unit_cube_and_changes_the_parent() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        for u in [[0.0; 6], [1.0; 6], [0.3, 0.9, 0.5, 0.01, 0.99, 0.5]] {
            for _ in 0..200 {
                let m = mutate(&u, &mut rng);
                assert!(m.iter().all(|v| (0.0..=1.0).contains(v)), "{m:?}");
                if u != [0.0; 6] && u != [1.0; 6] {
                    assert_ne!(m, u);
                }
            }
        }
    }
}
