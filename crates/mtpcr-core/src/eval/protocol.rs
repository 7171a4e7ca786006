//! The evaluation protocol of `mtpcr experiment` and `mtpcr.evaluate`: the paper's suites
//! and their variants, noise injection with its seed, one run of a suite, and the run record.
//! Both front-ends call [`run_one`], so they give the same numbers for the same suite,
//! variant, problem and seed.

use crate::cloud::PointCloud;
use crate::config::{Config, Method};
use crate::error::{Error, Result};
use crate::eval::run_moved;
use crate::se3::Transform;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

/// The paper's MTPCR Err_R x1000 (mean, std) on Bunny-a/b/c (Table 2).
pub const PAPER_ERR_R: [(&str, f64, f64); 3] = [
    ("bunny-a", 3.73, 0.64),
    ("bunny-b", 4.76, 1.38),
    ("bunny-c", 6.63, 1.65),
];

/// Noise levels of Table 3 (standard deviation in normalised coordinates).
pub const NOISE_SIGMAS: [f64; 3] = [0.01, 0.02, 0.03];

/// Loop-term weights of the alpha study, with the paper's Table (Err_R, Err_T x1000 on
/// Bunny-a, Bunny-b, Bunny-c; 20 runs).
pub const PAPER_ALPHA: [(f64, [(f64, f64); 3]); 6] = [
    (0.5, [(141.06, 9.78), (1657.15, 99.23), (1622.86, 71.65)]),
    (0.2, [(6.92, 0.27), (260.17, 15.14), (303.77, 16.59)]),
    (0.1, [(7.22, 0.37), (105.88, 4.09), (508.85, 21.11)]),
    (0.05, [(6.71, 0.29), (10.48, 0.67), (179.35, 9.39)]),
    (0.02, [(8.19, 0.32), (11.18, 0.57), (188.29, 9.83)]),
    (0.01, [(7.72, 0.32), (105.25, 5.63), (314.65, 7.81)]),
];

/// Sharing probabilities of the sharing study (p_intra = p_inter).
pub const SHARING_PROBABILITIES: [f64; 7] = [0.0, 0.2, 0.4, 0.5, 0.6, 0.8, 1.0];

/// Sample ratios of the sample-ratio study.
pub const SAMPLE_RATIOS: [f64; 10] = [0.01, 0.02, 0.03, 0.04, 0.05, 0.1, 0.2, 0.3, 0.4, 0.5];

/// The paper's Bunny problems (the alpha and sample-ratio studies use them).
pub const BUNNIES: [&str; 3] = ["bunny-a", "bunny-b", "bunny-c"];

/// An experiment suite of the paper.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Suite {
    /// Table 2: Err_R / Err_T of MTPCR with Config::default() and Config::paper().
    Accuracy,
    /// Table 4: final original-task costs of MTPCR, MFEA, G-MFEA and the ablations, with
    /// convergence figures.
    Quality,
    /// Table 3: Err_R / Err_T under Gaussian noise (sigma 0.01, 0.02, 0.03), default and
    /// paper settings.
    Noise,
    /// Sensitivity to alpha (loop-term weight), paper settings, on Bunny-a/b/c.
    Alpha,
    /// Sensitivity to the sharing probabilities (p_intra = p_inter), paper settings, on
    /// Bunny-c.
    Sharing,
    /// Sensitivity to the sample ratio, paper settings, on Bunny-a/b/c.
    Sampling,
}

impl Suite {
    /// The suite's name (`accuracy`, `quality`, ...).
    pub fn name(self) -> &'static str {
        match self {
            Suite::Accuracy => "accuracy",
            Suite::Quality => "quality",
            Suite::Noise => "noise",
            Suite::Alpha => "alpha",
            Suite::Sharing => "sharing",
            Suite::Sampling => "sampling",
        }
    }

    /// Runs per problem and variant, as in the paper.
    pub fn default_runs(self) -> usize {
        match self {
            Suite::Quality | Suite::Alpha | Suite::Sharing => 20,
            Suite::Accuracy | Suite::Noise | Suite::Sampling => 10,
        }
    }

    /// The problems the paper ran the suite on (used unless `--problems` is given); `None`:
    /// every problem.
    pub fn paper_problems(self) -> Option<&'static [&'static str]> {
        match self {
            Suite::Alpha | Suite::Sampling => Some(&BUNNIES),
            Suite::Sharing => Some(&BUNNIES[2..]),
            Suite::Accuracy | Suite::Quality | Suite::Noise => None,
        }
    }

    /// The variants of the suite: key, label for the tables, settings, noise sigma.
    pub fn variants(self) -> Vec<Variant> {
        let paper = Config::paper;
        let with = |key: &str, label: &str, config: Config| Variant {
            key: key.to_string(),
            label: label.to_string(),
            config,
            noise: None,
        };
        match self {
            Suite::Accuracy => vec![
                with("mtpcr-default", "MTPCR (default)", Config::default()),
                with("mtpcr-paper", "MTPCR (paper)", paper()),
            ],
            Suite::Quality => vec![
                with("mtpcr", "MTPCR", paper()),
                with(
                    "mfea",
                    "MFEA",
                    Config {
                        method: Method::Mfea,
                        ..paper()
                    },
                ),
                with(
                    "gmfea",
                    "G-MFEA",
                    Config {
                        method: Method::Gmfea,
                        ..paper()
                    },
                ),
                with(
                    "mtpcr-intra",
                    "MTPCR-Intra",
                    Config {
                        p_inter: 0.0,
                        ..paper()
                    },
                ),
                with(
                    "mtpcr-inter",
                    "MTPCR-Inter",
                    Config {
                        p_intra: 0.0,
                        ..paper()
                    },
                ),
                with(
                    "mtpcr-nks",
                    "MTPCR-NKS",
                    Config {
                        p_intra: 0.0,
                        p_inter: 0.0,
                        ..paper()
                    },
                ),
            ],
            Suite::Noise => {
                let noisy = |key: String, label: String, config: Config, sigma: f64| Variant {
                    key,
                    label,
                    config,
                    noise: Some(sigma),
                };
                let default = NOISE_SIGMAS.iter().map(|&s| {
                    noisy(
                        format!("noise-{s:.2}"),
                        format!("default, sigma {s:.2}"),
                        Config::default(),
                        s,
                    )
                });
                let paper_noise = NOISE_SIGMAS.iter().map(|&s| {
                    noisy(
                        format!("noise-paper-{s:.2}"),
                        format!("paper, sigma {s:.2}"),
                        paper(),
                        s,
                    )
                });
                default.chain(paper_noise).collect()
            }
            Suite::Alpha => PAPER_ALPHA
                .iter()
                .map(|&(alpha, _)| {
                    with(
                        &format!("alpha-{alpha}"),
                        &format!("alpha {alpha}"),
                        Config { alpha, ..paper() },
                    )
                })
                .collect(),
            Suite::Sharing => SHARING_PROBABILITIES
                .iter()
                .map(|&p| {
                    with(
                        &format!("sharing-{p:.1}"),
                        &format!("p {p:.1}"),
                        Config {
                            p_intra: p,
                            p_inter: p,
                            ..paper()
                        },
                    )
                })
                .collect(),
            Suite::Sampling => SAMPLE_RATIOS
                .iter()
                .map(|&r| {
                    with(
                        &format!("ratio-{r}"),
                        &format!("ratio {r}"),
                        Config {
                            sample_ratio: r,
                            ..paper()
                        },
                    )
                })
                .collect(),
        }
    }
}

/// One setting of a suite: its key in the run records, its label in the tables, the
/// settings, and the noise added to the scans (if any).
#[derive(Clone, Debug, PartialEq)]
pub struct Variant {
    /// Key in the run records (`mtpcr-default`, `noise-0.02`, ...).
    pub key: String,
    /// Label in the report's tables.
    pub label: String,
    /// The settings.
    pub config: Config,
    /// Standard deviation of the Gaussian noise added to the scans (normalised units).
    pub noise: Option<f64>,
}

impl Suite {
    /// Every suite, in report order.
    pub const ALL: [Suite; 6] = [
        Suite::Accuracy,
        Suite::Quality,
        Suite::Noise,
        Suite::Alpha,
        Suite::Sharing,
        Suite::Sampling,
    ];

    /// The suite of a name ([`Suite::name`]).
    pub fn from_name(name: &str) -> Result<Suite> {
        Suite::ALL
            .into_iter()
            .find(|s| s.name() == name)
            .ok_or_else(|| {
                Error::InvalidInput(format!(
                    "unknown suite `{name}` (suites are: {})",
                    Suite::ALL.map(Suite::name).join(", ")
                ))
            })
    }

    /// One sentence on what the suite measures.
    pub fn description(self) -> &'static str {
        match self {
            Suite::Accuracy => "Table 2: Err_R / Err_T of MTPCR with Config::default() and Config::paper()",
            Suite::Quality => "Table 4: final original-task costs of MTPCR, MFEA, G-MFEA and the ablations, with convergence figures",
            Suite::Noise => "Table 3: Err_R / Err_T under Gaussian noise (sigma 0.01, 0.02, 0.03), default and paper settings",
            Suite::Alpha => "sensitivity to alpha (the loop-term weight), paper settings, on Bunny-a/b/c",
            Suite::Sharing => "sensitivity to the sharing probabilities (p_intra = p_inter), paper settings, on Bunny-c",
            Suite::Sampling => "sensitivity to the sample ratio, paper settings, on Bunny-a/b/c",
        }
    }

    /// The variant of a key, if the suite has it.
    pub fn variant(self, key: &str) -> Option<Variant> {
        self.variants().into_iter().find(|v| v.key == key)
    }
}

/// Final best costs of a run's evolution (before refinement), by edge.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FinalCosts {
    /// The original tasks' costs.
    pub original: Vec<f64>,
    /// The aiding tasks' costs.
    pub aiding: Vec<f64>,
}

/// The record of one run (one line of `runs.jsonl`).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RunRecord {
    /// The suite's name.
    pub suite: String,
    /// The variant's key.
    pub variant: String,
    /// The problem's name.
    pub problem: String,
    /// The run's seed (noise, motions and search).
    pub seed: u64,
    /// The settings of the run (seed and threads included).
    pub settings: Config,
    /// Every edge under 5 degrees.
    pub success: bool,
    /// The paper's Err_R (unscaled).
    pub err_r: f64,
    /// The paper's Err_T (unscaled).
    pub err_t: f64,
    /// Rotation error of each edge in degrees.
    pub rot_deg: Vec<f64>,
    /// The evolution's final costs.
    pub final_costs: FinalCosts,
    /// Best cost of each task per generation of the kept evolution.
    pub history: Vec<Vec<f64>>,
    /// Seconds of the registration.
    pub seconds: f64,
}

/// The seed of a run's noise, derived from the run seed.
pub const NOISE_SEED_SALT: u64 = 0x6e_6f69_7365;

/// The scans with the noise of the protocol (`PointCloud::with_normalized_noise`, one RNG
/// seeded from the run seed, the scans in order).
pub fn add_noise(scans: &[PointCloud], sigma: f64, seed: u64) -> Result<Vec<PointCloud>> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ NOISE_SEED_SALT);
    scans
        .iter()
        .map(|c| c.with_normalized_noise(sigma, &mut rng))
        .collect()
}

/// One run of the protocol: the variant's noise (seeded from `seed`), a seeded random motion
/// of each scan, registration on one thread with `seed`, scores. `generations` overrides the
/// variant's generations (quick checks).
pub fn run_one(
    suite: Suite,
    variant: &Variant,
    problem: &str,
    scans: &[PointCloud],
    truth: &[Transform],
    seed: u64,
    generations: Option<usize>,
) -> Result<RunRecord> {
    let mut config = Config {
        num_threads: 1,
        seed: Some(seed),
        ..variant.config.clone()
    };
    if let Some(g) = generations {
        config.generations = g;
    }
    let noisy;
    let clouds = match variant.noise {
        Some(sigma) => {
            noisy = add_noise(scans, sigma, seed)?;
            &noisy[..]
        }
        None => scans,
    };
    let (result, scores) = run_moved(clouds, truth, &config, seed)?;
    let costs = result.best_costs();
    let edges = result.edges.len();
    Ok(RunRecord {
        suite: suite.name().to_string(),
        variant: variant.key.clone(),
        problem: problem.to_string(),
        seed,
        settings: config,
        success: scores.success,
        err_r: scores.err_r,
        err_t: scores.err_t,
        rot_deg: scores.rot_deg,
        final_costs: FinalCosts {
            original: costs[edges..].to_vec(),
            aiding: costs[..edges].to_vec(),
        },
        history: result.history,
        seconds: result.seconds,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::HashSet;

    #[test]
    fn variants_have_distinct_keys_and_valid_settings() {
        for s in Suite::ALL {
            let vs = s.variants();
            let keys: HashSet<&str> = vs.iter().map(|v| v.key.as_str()).collect();
            assert_eq!(keys.len(), vs.len());
            for v in &vs {
                v.config.validate().unwrap();
            }
            assert_eq!(Suite::from_name(s.name()).unwrap(), s);
        }
        assert!(Suite::from_name("acuracy").is_err());
        assert_eq!(Suite::Quality.variants().len(), 6);
        assert_eq!(Suite::Noise.variants()[1].key, "noise-0.02");
        assert_eq!(Suite::Noise.variants()[4].key, "noise-paper-0.02");
        assert_eq!(Suite::Alpha.variants()[3].config.alpha, 0.05);
        assert_eq!(Suite::Sampling.variants()[9].config.sample_ratio, 0.5);
        let sharing = &Suite::Sharing.variants()[2].config;
        assert_eq!((sharing.p_intra, sharing.p_inter), (0.4, 0.4));
    }

    #[test]
    fn noise_is_seeded_by_the_run() {
        let p = crate::synthetic::three_views(1, 500);
        let a = add_noise(&p.clouds, 0.02, 3).unwrap();
        assert_eq!(a, add_noise(&p.clouds, 0.02, 3).unwrap());
        assert_ne!(a, add_noise(&p.clouds, 0.02, 4).unwrap());
        assert_ne!(a[0], p.clouds[0]);
    }
}
