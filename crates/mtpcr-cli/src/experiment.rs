//! `mtpcr experiment`: the paper's experiment suites (Table 2 accuracy, Table 3 noise,
//! Table 4 solution quality with convergence figures, and the parameter sensitivity studies of
//! Section VI: alpha, sharing probability, sample ratio) over problem files.
//!
//! Every run is one JSON line of `DIR/runs.jsonl`, keyed by (suite, variant, problem, seed);
//! a rerun skips the keys already there, so an interrupted experiment resumes. Runs execute
//! `--jobs` at a time on one thread each (the results do not depend on the thread count).
//! `DIR/RESULTS.md` and the convergence figures are regenerated from the file every time.

use crate::error::{outln, CliResult, Failure};
use crate::{plots, progress};
use clap::{Args, ValueEnum};
use mtpcr_core::eval::{mean_std, run_moved};
use mtpcr_core::io::Problem;
use mtpcr_core::{Config, Method, PointCloud, Transform, TASK_NAMES};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use std::collections::{BTreeMap, HashSet};
use std::fmt::Write as _;
use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{mpsc, Mutex};
use std::time::Instant;

/// The paper's MTPCR Err_R x1000 (mean, std) on Bunny-a/b/c (Table 2).
const PAPER_ERR_R: [(&str, f64, f64); 3] = [
    ("bunny-a", 3.73, 0.64),
    ("bunny-b", 4.76, 1.38),
    ("bunny-c", 6.63, 1.65),
];

/// Noise levels of Table 3 (standard deviation in normalised coordinates).
const NOISE_SIGMAS: [f64; 3] = [0.01, 0.02, 0.03];

/// Loop-term weights of the alpha study, with the paper's Table (Err_R, Err_T x1000 on
/// Bunny-a, Bunny-b, Bunny-c; 20 runs).
const PAPER_ALPHA: [(f64, [(f64, f64); 3]); 6] = [
    (0.5, [(141.06, 9.78), (1657.15, 99.23), (1622.86, 71.65)]),
    (0.2, [(6.92, 0.27), (260.17, 15.14), (303.77, 16.59)]),
    (0.1, [(7.22, 0.37), (105.88, 4.09), (508.85, 21.11)]),
    (0.05, [(6.71, 0.29), (10.48, 0.67), (179.35, 9.39)]),
    (0.02, [(8.19, 0.32), (11.18, 0.57), (188.29, 9.83)]),
    (0.01, [(7.72, 0.32), (105.25, 5.63), (314.65, 7.81)]),
];

/// Sharing probabilities of the sharing study (p_intra = p_inter).
const SHARING_PROBABILITIES: [f64; 7] = [0.0, 0.2, 0.4, 0.5, 0.6, 0.8, 1.0];

/// Sample ratios of the sample-ratio study.
const SAMPLE_RATIOS: [f64; 10] = [0.01, 0.02, 0.03, 0.04, 0.05, 0.1, 0.2, 0.3, 0.4, 0.5];

/// The paper's Bunny problems (the alpha and sample-ratio studies use them).
const BUNNIES: [&str; 3] = ["bunny-a", "bunny-b", "bunny-c"];

/// A "No. of Best" cell counts when the method's mean is within this fraction of the best.
const BEST_TOLERANCE: f64 = 0.01;

#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, ValueEnum)]
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
    fn name(self) -> &'static str {
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
    fn default_runs(self) -> usize {
        match self {
            Suite::Quality | Suite::Alpha | Suite::Sharing => 20,
            Suite::Accuracy | Suite::Noise | Suite::Sampling => 10,
        }
    }

    /// The problems the paper ran the suite on (used unless `--problems` is given); `None`:
    /// every problem.
    fn paper_problems(self) -> Option<&'static [&'static str]> {
        match self {
            Suite::Alpha | Suite::Sampling => Some(&BUNNIES),
            Suite::Sharing => Some(&BUNNIES[2..]),
            Suite::Accuracy | Suite::Quality | Suite::Noise => None,
        }
    }

    /// The variants of the suite: key, label for the tables, settings, noise sigma.
    fn variants(self) -> Vec<Variant> {
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

struct Variant {
    key: String,
    label: String,
    config: Config,
    noise: Option<f64>,
}

/// Arguments of `mtpcr experiment`.
#[derive(Args, Clone, Debug)]
pub struct ExperimentArgs {
    /// Suites to run: accuracy (Table 2), quality (Table 4), noise (Table 3), and the
    /// sensitivity studies alpha, sharing, sampling.
    #[arg(required = true, value_enum, value_name = "SUITE")]
    pub suites: Vec<Suite>,
    /// Output folder: runs.jsonl (one line per run, resumable), RESULTS.md, figures.
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// Runs (seeds 0..N) per problem and variant [default: 10 for accuracy and noise, 20 for
    /// quality].
    #[arg(long, value_name = "N")]
    pub runs: Option<usize>,
    /// Problem files, for every suite [default: ../shared/problems/*.json, sorted; the
    /// sensitivity suites use the paper's Bunny problems among them].
    #[arg(long, value_name = "FILE", num_args = 1..)]
    pub problems: Vec<PathBuf>,
    /// Folder the scan paths are relative to [default: the parent of each problem's folder].
    #[arg(long, value_name = "DIR")]
    pub data_root: Option<PathBuf>,
    /// Override the generations of every variant (for quick checks).
    #[arg(long, value_name = "G")]
    pub generations: Option<usize>,
    /// Runs executed at once, each on one thread.
    #[arg(long, value_name = "J", default_value_t = 2)]
    pub jobs: usize,
    /// No progress display on stderr.
    #[arg(long, short)]
    pub quiet: bool,
    /// Compute nothing: write RESULTS.md from the runs already in runs.jsonl (every table
    /// says how many runs each cell holds).
    #[arg(long)]
    pub report_only: bool,
}

/// Final best costs of a run.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
struct FinalCosts {
    original: [f64; 3],
    aiding: [f64; 3],
}

/// One line of `runs.jsonl`.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
struct RunLine {
    suite: String,
    variant: String,
    problem: String,
    seed: u64,
    settings: Config,
    success: bool,
    err_r: f64,
    err_t: f64,
    rot_deg: [f64; 3],
    final_costs: FinalCosts,
    history: Vec<[f64; 6]>,
    seconds: f64,
}

type Key = (String, String, String, u64);

impl RunLine {
    fn key(&self) -> Key {
        (
            self.suite.clone(),
            self.variant.clone(),
            self.problem.clone(),
            self.seed,
        )
    }
}

/// One planned run.
struct Work {
    suite: Suite,
    variant: usize,
    problem: usize,
    seed: u64,
}

struct LoadedProblem {
    problem: Problem,
    /// Read on first use by a pending run.
    scans: Option<[PointCloud; 3]>,
    truth: [Transform; 3],
}

fn default_problems() -> CliResult<Vec<PathBuf>> {
    let dir = Path::new("../shared/problems");
    let entries = std::fs::read_dir(dir).map_err(|e| {
        Failure(format!(
            "{}: cannot list the default problems ({e}); pass --problems FILE...",
            dir.display()
        ))
    })?;
    let mut files: Vec<PathBuf> = entries
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "json"))
        .collect();
    files.sort();
    if files.is_empty() {
        return Err(Failure(format!("{}: no problem files", dir.display())));
    }
    Ok(files)
}

/// Reads `runs.jsonl`: the complete records, and cuts off a truncated last line (an
/// interrupted write) so that new lines start cleanly.
fn read_runs(path: &Path) -> CliResult<Vec<RunLine>> {
    let text = match std::fs::read_to_string(path) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Vec::new()),
        Err(e) => return Err(Failure(format!("{}: {e}", path.display()))),
    };
    let complete = text.rfind('\n').map_or(0, |i| i + 1);
    if complete < text.len() {
        let file = std::fs::OpenOptions::new()
            .write(true)
            .open(path)
            .map_err(|e| Failure(format!("{}: {e}", path.display())))?;
        file.set_len(complete as u64)
            .map_err(|e| Failure(format!("{}: {e}", path.display())))?;
        eprintln!(
            "{}: ignoring a truncated last line (an interrupted run is redone)",
            path.display()
        );
    }
    let mut runs = Vec::new();
    for (n, line) in text[..complete].lines().enumerate() {
        if line.trim().is_empty() {
            continue;
        }
        match serde_json::from_str::<RunLine>(line) {
            Ok(r) => runs.push(r),
            Err(e) => eprintln!(
                "{}:{}: ignoring an unreadable line: {e}",
                path.display(),
                n + 1
            ),
        }
    }
    Ok(runs)
}

/// One run: optional noise (seeded from the run seed), a seeded random motion, registration.
fn execute(
    variant: &Variant,
    problem: &LoadedProblem,
    suite: Suite,
    seed: u64,
    generations: Option<usize>,
) -> Result<RunLine, String> {
    let scans = problem
        .scans
        .as_ref()
        .ok_or_else(|| format!("{}: scans not loaded", problem.problem.name))?;
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
            let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x6e_6f69_7365);
            let mut out = Vec::with_capacity(3);
            for c in scans {
                out.push(
                    c.with_normalized_noise(sigma, &mut rng)
                        .map_err(|e| e.to_string())?,
                );
            }
            noisy = <[PointCloud; 3]>::try_from(out).map_err(|_| "three clouds".to_string())?;
            &noisy
        }
        None => scans,
    };
    let (result, scores) =
        run_moved(clouds, &problem.truth, &config, seed).map_err(|e| e.to_string())?;
    Ok(RunLine {
        suite: suite.name().to_string(),
        variant: variant.key.clone(),
        problem: problem.problem.name.clone(),
        seed,
        settings: config,
        success: scores.success,
        err_r: scores.err_r,
        err_t: scores.err_t,
        rot_deg: scores.rot_deg,
        final_costs: FinalCosts {
            original: result.best_costs.original,
            aiding: result.best_costs.aiding,
        },
        history: result.history,
        seconds: result.seconds,
    })
}

/// Runs `mtpcr experiment`.
pub fn run(args: &ExperimentArgs) -> CliResult<()> {
    let started = Instant::now();
    if args.jobs == 0 {
        return Err(Failure("--jobs must be at least 1".to_string()));
    }
    if args.runs == Some(0) {
        return Err(Failure("--runs must be at least 1".to_string()));
    }
    let mut suites = args.suites.clone();
    suites.sort();
    suites.dedup();
    let files = if args.problems.is_empty() {
        default_problems()?
    } else {
        args.problems.clone()
    };
    let mut problems: Vec<LoadedProblem> = Vec::new();
    for f in &files {
        let problem = Problem::load(f, args.data_root.as_deref())?;
        let truth = problem.ground_truth();
        problems.push(LoadedProblem {
            problem,
            scans: None,
            truth,
        });
    }
    let variants: BTreeMap<Suite, Vec<Variant>> =
        suites.iter().map(|&s| (s, s.variants())).collect();
    for vs in variants.values() {
        for v in vs {
            let mut c = v.config.clone();
            if let Some(g) = args.generations {
                c.generations = g;
            }
            c.validate()
                .map_err(|e| Failure(format!("{}: {e}", v.key)))?;
        }
    }

    std::fs::create_dir_all(&args.out)
        .map_err(|e| Failure(format!("{}: {e}", args.out.display())))?;
    let runs_path = args.out.join("runs.jsonl");
    let done: HashSet<Key> = read_runs(&runs_path)?.iter().map(RunLine::key).collect();

    // The plan of this invocation: every (suite, variant, problem, seed); pending = not done.
    let mut plan: HashSet<Key> = HashSet::new();
    let mut pending = Vec::new();
    for &suite in &suites {
        let runs = args.runs.unwrap_or_else(|| suite.default_runs());
        for (vi, v) in variants[&suite].iter().enumerate() {
            for (pi, p) in problems.iter().enumerate() {
                let name = &p.problem.name;
                if args.problems.is_empty()
                    && suite
                        .paper_problems()
                        .is_some_and(|names| !names.contains(&name.as_str()))
                {
                    continue;
                }
                for seed in 0..runs as u64 {
                    let key = (
                        suite.name().to_string(),
                        v.key.clone(),
                        p.problem.name.clone(),
                        seed,
                    );
                    if !done.contains(&key) {
                        pending.push(Work {
                            suite,
                            variant: vi,
                            problem: pi,
                            seed,
                        });
                    }
                    plan.insert(key);
                }
            }
        }
    }
    let skipped = plan.len() - pending.len();
    if !args.quiet {
        eprintln!(
            "experiment: {} runs planned, {skipped} already in {}, {} to do{}",
            plan.len(),
            runs_path.display(),
            pending.len(),
            if args.report_only {
                " (not run: --report-only)".to_string()
            } else {
                format!(" with {} jobs", args.jobs)
            }
        );
    }
    let missing = if args.report_only {
        std::mem::take(&mut pending).len()
    } else {
        0
    };
    let needed: HashSet<usize> = pending.iter().map(|w| w.problem).collect();
    for (pi, p) in problems.iter_mut().enumerate() {
        if needed.contains(&pi) {
            let scans = p.problem.read_scans()?;
            for (c, path) in scans.iter().zip(&p.problem.scans) {
                c.validate(
                    &path.display().to_string(),
                    mtpcr_core::registration::MIN_POINTS,
                )?;
            }
            p.scans = Some(scans);
        }
    }

    let computed = execute_all(args, &variants, &problems, pending, &runs_path)?;
    let wall = started.elapsed().as_secs_f64();

    let all = read_runs(&runs_path)?;
    let mut records: BTreeMap<Key, RunLine> = BTreeMap::new();
    for r in all {
        let k = r.key();
        if plan.contains(&k) {
            records.insert(k, r);
        }
    }
    let info = RunInfo {
        wall,
        computed,
        skipped,
        missing,
    };
    let report = write_report(args, &suites, &variants, &problems, &records, &info)?;
    outln!("wrote {}", report.display());
    Ok(())
}

/// Seconds of the runs computed by this invocation, per suite.
type Computed = BTreeMap<Suite, (usize, f64)>;

/// Runs the pending work `args.jobs` at a time; appends each finished run to `runs_path`.
fn execute_all(
    args: &ExperimentArgs,
    variants: &BTreeMap<Suite, Vec<Variant>>,
    problems: &[LoadedProblem],
    pending: Vec<Work>,
    runs_path: &Path,
) -> CliResult<Computed> {
    let mut computed: Computed = BTreeMap::new();
    if pending.is_empty() {
        return Ok(computed);
    }
    let total = pending.len();
    let mut file = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(runs_path)
        .map_err(|e| Failure(format!("{}: {e}", runs_path.display())))?;
    let bar = progress::run_bar(total, args.quiet, "experiment");
    bar.set_message(format!("{} jobs", args.jobs));
    let queue = Mutex::new(pending.into_iter());
    let stop = AtomicBool::new(false);
    let (tx, rx) = mpsc::channel::<(Work, Result<RunLine, String>)>();
    let mut failure: Option<Failure> = None;
    std::thread::scope(|scope| {
        for _ in 0..args.jobs.min(total) {
            let tx = tx.clone();
            let (queue, stop) = (&queue, &stop);
            scope.spawn(move || loop {
                if stop.load(Ordering::Relaxed) {
                    break;
                }
                let next = queue.lock().map(|mut q| q.next()).unwrap_or(None);
                let Some(w) = next else { break };
                let v = &variants[&w.suite][w.variant];
                let out = execute(v, &problems[w.problem], w.suite, w.seed, args.generations);
                if tx.send((w, out)).is_err() {
                    break;
                }
            });
        }
        drop(tx);
        for (finished, (w, out)) in (1..).zip(rx) {
            let name = &problems[w.problem].problem.name;
            let vkey = &variants[&w.suite][w.variant].key;
            let line = match out {
                Ok(line) => line,
                Err(e) => {
                    stop.store(true, Ordering::Relaxed);
                    failure.get_or_insert(Failure(format!(
                        "{} {vkey} {name} seed {}: {e}",
                        w.suite.name(),
                        w.seed
                    )));
                    continue;
                }
            };
            let written = serde_json::to_string(&line)
                .map_err(|e| e.to_string())
                .and_then(|s| {
                    writeln!(file, "{s}")
                        .and_then(|_| file.flush())
                        .map_err(|e| e.to_string())
                });
            if let Err(e) = written {
                stop.store(true, Ordering::Relaxed);
                failure.get_or_insert(Failure(format!("{}: {e}", runs_path.display())));
                continue;
            }
            let entry = computed.entry(w.suite).or_insert((0, 0.0));
            entry.0 += 1;
            entry.1 += line.seconds;
            bar.inc(1);
            if !args.quiet {
                bar.suspend(|| {
                    eprintln!(
                        "[{finished}/{total}] {} {vkey} {name} seed {}: {} rot {:.2} {:.2} {:.2} \
                         deg, Err_R x1000 {:.2}, J-o {:.4} {:.4} {:.4}, {:.1} s",
                        w.suite.name(),
                        w.seed,
                        if line.success { "ok  " } else { "FAIL" },
                        line.rot_deg[0],
                        line.rot_deg[1],
                        line.rot_deg[2],
                        line.err_r * 1000.0,
                        line.final_costs.original[0],
                        line.final_costs.original[1],
                        line.final_costs.original[2],
                        line.seconds
                    )
                });
            }
        }
    });
    bar.finish_and_clear();
    match failure {
        Some(f) => Err(f),
        None => Ok(computed),
    }
}

struct RunInfo {
    wall: f64,
    computed: Computed,
    skipped: usize,
    /// Planned runs not in `runs.jsonl` (only with `--report-only`).
    missing: usize,
}

fn pm(values: &[f64], scale: f64, decimals: usize) -> String {
    let scaled: Vec<f64> = values.iter().map(|v| v * scale).collect();
    let (m, s) = mean_std(&scaled);
    if values.is_empty() {
        "–".to_string()
    } else {
        format!("{m:.decimals$} ± {s:.decimals$}")
    }
}

/// What one suite's part of the report is made from.
struct Section<'a> {
    suite: Suite,
    /// The output folder (figures are written there).
    out: &'a Path,
    variants: &'a [Variant],
    /// The problems with at least one record of the suite.
    problems: Vec<&'a LoadedProblem>,
    records: &'a BTreeMap<Key, RunLine>,
}

impl Section<'_> {
    /// The records of one (variant, problem), by seed.
    fn cell(&self, variant: &str, problem: &str) -> Vec<&RunLine> {
        self.records
            .values()
            .filter(|r| {
                r.suite == self.suite.name() && r.variant == variant && r.problem == problem
            })
            .collect()
    }
}

fn shell_quote(arg: &str) -> String {
    if !arg.is_empty()
        && arg
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || "-_./=:,+@".contains(c))
    {
        arg.to_string()
    } else {
        format!("'{}'", arg.replace('\'', r"'\''"))
    }
}

fn machine() -> String {
    let cpus = std::thread::available_parallelism().map_or(0, |n| n.get());
    let kernel = std::fs::read_to_string("/proc/sys/kernel/osrelease")
        .map(|s| format!(" {}", s.trim()))
        .unwrap_or_default();
    let model = std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|t| {
            t.lines()
                .find(|l| l.starts_with("model name"))
                .and_then(|l| l.split(':').nth(1))
                .map(|m| format!(", {}", m.trim()))
        })
        .unwrap_or_default();
    format!(
        "{}{kernel} {} ({}), {cpus} logical CPUs{model}",
        std::env::consts::OS,
        std::env::consts::ARCH,
        std::env::consts::FAMILY
    )
}

/// A column of published numbers beside ours: header, and the cell for (variant, problem).
type PaperColumn<'a> = (&'a str, &'a dyn Fn(&Variant, &str) -> String);

fn median(values: &[f64]) -> f64 {
    let mut v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    let m = v.len() / 2;
    if v.len() % 2 == 1 {
        v[m]
    } else {
        0.5 * (v[m - 1] + v[m])
    }
}

/// The problems with at least one record of the suite.
fn problems_in<'a>(
    records: &BTreeMap<Key, RunLine>,
    suite: Suite,
    problems: &'a [LoadedProblem],
) -> Vec<&'a LoadedProblem> {
    problems
        .iter()
        .filter(|p| {
            records
                .values()
                .any(|r| r.suite == suite.name() && r.problem == p.problem.name)
        })
        .collect()
}

/// Err_R / Err_T rows, problem-major: successes, mean ± std and median over the runs.
fn error_table(md: &mut String, section: &Section<'_>, paper: Option<PaperColumn<'_>>) {
    let paper_col = paper.map_or(String::new(), |(h, _)| format!(" {h} |"));
    let _ = writeln!(
        md,
        "| problem | variant | runs | successes | Err_R ×1000 | Err_T ×1000 | median Err_R \
         ×1000 |{paper_col} mean s/run |"
    );
    let _ = writeln!(
        md,
        "|---|---|---:|---:|---:|---:|---:|{}---:|",
        if paper.is_some() { "---:|" } else { "" }
    );
    for p in &section.problems {
        let name = &p.problem.name;
        for v in section.variants {
            let rs = section.cell(&v.key, name);
            let er: Vec<f64> = rs.iter().map(|r| r.err_r).collect();
            let et: Vec<f64> = rs.iter().map(|r| r.err_t).collect();
            let secs: Vec<f64> = rs.iter().map(|r| r.seconds).collect();
            let ok = rs.iter().filter(|r| r.success).count();
            let paper = paper.map_or(String::new(), |(_, f)| format!(" {} |", f(v, name)));
            let med = if er.is_empty() {
                "–".to_string()
            } else {
                format!("{:.2}", median(&er) * 1000.0)
            };
            let seconds = if secs.is_empty() {
                "–".to_string()
            } else {
                format!("{:.1}", mean_std(&secs).0)
            };
            let _ = writeln!(
                md,
                "| {name} | {} | {} | {ok}/{} | {} | {} | {med} |{paper} {seconds} |",
                v.label,
                rs.len(),
                rs.len(),
                pm(&er, 1000.0, 2),
                pm(&et, 1000.0, 2),
            );
        }
    }
}

/// One convergence figure per problem (`<prefix><problem>.png`), a line per variant, and
/// its Markdown link.
fn convergence_figures(
    md: &mut String,
    section: &Section<'_>,
    (prefix, what): (&str, &str),
) -> CliResult<()> {
    for p in &section.problems {
        let name = &p.problem.name;
        let lines: Vec<(String, Vec<[f64; 6]>)> = section
            .variants
            .iter()
            .map(|v| (v.label.clone(), mean_history(&section.cell(&v.key, name))))
            .filter(|(_, h)| !h.is_empty())
            .collect();
        if lines.is_empty() {
            continue;
        }
        let file = format!("{prefix}{name}.png");
        plots::methods_convergence_png(
            &lines,
            &format!("{name}: best cost per generation, mean over runs, by {what}"),
            &section.out.join(&file),
        )?;
        let _ = writeln!(md, "![{name} convergence by {what}]({file})\n");
    }
    Ok(())
}

/// Mean over runs of the history rows (cut to the shortest history).
fn mean_history(rs: &[&RunLine]) -> Vec<[f64; 6]> {
    let len = rs.iter().map(|r| r.history.len()).min().unwrap_or(0);
    (0..len)
        .map(|g| {
            std::array::from_fn(|t| {
                rs.iter().map(|r| r.history[g][t]).sum::<f64>() / rs.len() as f64
            })
        })
        .collect()
}

fn quality_section(md: &mut String, section: &Section<'_>) -> CliResult<()> {
    let _ = writeln!(
        md,
        "Final best cost of each original task (1 − inlier fraction + loop term; lower is \
         better), as B.Cost (the lowest over the runs) / Avg.Cost (mean ± std over the runs). \
         All methods use `Config::paper()` apart from the method or the sharing \
         probabilities. As in the paper, a B.Cost or an Avg.Cost is **bold** when it is the \
         best of its row or within {:.0} % of it; **No. of Best** counts the bold B.Cost / \
         Avg.Cost cells of each method.\n",
        BEST_TOLERANCE * 100.0
    );
    let mut header = "| problem | task | runs |".to_string();
    let mut rule = "|---|---|---:|".to_string();
    for v in section.variants {
        let _ = write!(header, " {} |", v.label);
        rule.push_str("---:|");
    }
    let _ = writeln!(md, "{header}\n{rule}");
    let near_best =
        |value: f64, best: f64| best.is_finite() && value <= best + BEST_TOLERANCE * best.abs();
    let bold = |text: String, on: bool| if on { format!("**{text}**") } else { text };
    // Per method: bold B.Cost cells, bold Avg.Cost cells.
    let mut wins = vec![(0usize, 0usize); section.variants.len()];
    for p in &section.problems {
        let name = &p.problem.name;
        let cells: Vec<Vec<&RunLine>> = section
            .variants
            .iter()
            .map(|v| section.cell(&v.key, name))
            .collect();
        for task in 0..3 {
            let costs: Vec<Vec<f64>> = cells
                .iter()
                .map(|rs| rs.iter().map(|r| r.final_costs.original[task]).collect())
                .collect();
            let lowest: Vec<f64> = costs
                .iter()
                .map(|c| c.iter().copied().fold(f64::INFINITY, f64::min))
                .collect();
            let means: Vec<f64> = costs.iter().map(|c| mean_std(c).0).collect();
            let best_of = |xs: &[f64]| {
                xs.iter()
                    .copied()
                    .filter(|m| m.is_finite())
                    .fold(f64::INFINITY, f64::min)
            };
            let (best_lowest, best_mean) = (best_of(&lowest), best_of(&means));
            let runs = cells.iter().map(Vec::len).max().unwrap_or(0);
            let mut row = format!("| {name} | {} | {runs} |", TASK_NAMES[3 + task]);
            for (m, c) in costs.iter().enumerate() {
                if c.is_empty() {
                    row.push_str(" – |");
                    continue;
                }
                let (b, a) = (
                    near_best(lowest[m], best_lowest),
                    near_best(means[m], best_mean),
                );
                wins[m].0 += usize::from(b);
                wins[m].1 += usize::from(a);
                let _ = write!(
                    row,
                    " {} / {} |",
                    bold(format!("{:.4}", lowest[m]), b),
                    bold(pm(c, 1.0, 4), a)
                );
            }
            let _ = writeln!(md, "{row}");
        }
    }
    let mut row = "| **No. of Best** (B.Cost / Avg.Cost) | | |".to_string();
    for (b, a) in &wins {
        let _ = write!(row, " {b} / {a} |");
    }
    let _ = writeln!(md, "{row}\n");

    let _ = writeln!(
        md,
        "Convergence: mean over the runs of the best cost per generation of the six tasks \
         (generation 0 is the initial population); aiding tasks left, original right.\n"
    );
    convergence_figures(md, section, ("convergence-", "method"))
}

/// The alpha study: the error table beside the paper's, and convergence by alpha.
fn alpha_section(md: &mut String, section: &Section<'_>) -> CliResult<()> {
    let _ = writeln!(
        md,
        "`Config::paper()` with the loop-term weight alpha changed (paper: 0.05). The paper \
         column is its Table of average errors (Err_R / Err_T ×1000, 20 runs).\n"
    );
    let paper = |v: &Variant, name: &str| {
        let Some(k) = BUNNIES.iter().position(|b| b.eq_ignore_ascii_case(name)) else {
            return "–".to_string();
        };
        PAPER_ALPHA
            .iter()
            .find(|(a, _)| *a == v.config.alpha)
            .map_or("–".to_string(), |(_, e)| {
                format!("{:.2} / {:.2}", e[k].0, e[k].1)
            })
    };
    error_table(md, section, Some(("paper Err_R / Err_T ×1000", &paper)));
    md.push('\n');
    convergence_figures(md, section, ("alpha-convergence-", "alpha"))
}

/// The sharing-probability study: errors and convergence by p_intra = p_inter.
fn sharing_section(md: &mut String, section: &Section<'_>) -> CliResult<()> {
    let _ = writeln!(
        md,
        "`Config::paper()` with p_intra = p_inter = p (paper: 0.5; 0 is MTPCR-NKS). The paper \
         shows only the convergence curves (Bunny-c, 20 runs).\n"
    );
    error_table(md, section, None);
    md.push('\n');
    convergence_figures(md, section, ("sharing-convergence-", "sharing probability"))
}

/// The sample-ratio study: errors by ratio, as a table and a chart (a line per problem).
fn sampling_section(md: &mut String, section: &Section<'_>) -> CliResult<()> {
    let _ = writeln!(
        md,
        "`Config::paper()` with the farthest-point sample ratio changed (paper: 0.05); eps \
         follows the sampled clouds. The paper shows Err_R and Err_T against the ratio as a \
         figure without numbers.\n"
    );
    error_table(md, section, None);
    md.push('\n');
    if section.problems.is_empty() {
        return Ok(());
    }
    let x_labels: Vec<String> = section
        .variants
        .iter()
        .map(|v| format!("{}", v.config.sample_ratio))
        .collect();
    let by_problem = |measure: fn(&RunLine) -> f64, average: fn(&[f64]) -> f64| {
        section
            .problems
            .iter()
            .map(|p| {
                let name = &p.problem.name;
                let values = section
                    .variants
                    .iter()
                    .map(|v| {
                        let xs: Vec<f64> = section
                            .cell(&v.key, name)
                            .iter()
                            .map(|r| measure(r) * 1000.0)
                            .collect();
                        if xs.is_empty() {
                            f64::NAN
                        } else {
                            average(&xs)
                        }
                    })
                    .collect();
                (name.clone(), values)
            })
            .collect::<Vec<_>>()
    };
    let mean = |xs: &[f64]| mean_std(xs).0;
    let panels = vec![
        plots::CategoryPanel {
            title: "Err_R ×1000, mean over runs".to_string(),
            y_desc: "Err_R ×1000 (log)".to_string(),
            series: by_problem(|r| r.err_r, mean),
        },
        plots::CategoryPanel {
            title: "Err_T ×1000, mean over runs".to_string(),
            y_desc: "Err_T ×1000 (log)".to_string(),
            series: by_problem(|r| r.err_t, mean),
        },
        plots::CategoryPanel {
            title: "Err_R ×1000, median over runs".to_string(),
            y_desc: "Err_R ×1000 (log)".to_string(),
            series: by_problem(|r| r.err_r, median),
        },
    ];
    let file = "sampling-errors.png";
    plots::categories_log_png(
        "sample ratio",
        &x_labels,
        &panels,
        "Registration errors by sample ratio (Config::paper() otherwise)",
        &section.out.join(file),
    )?;
    let _ = writeln!(md, "![errors by sample ratio]({file})\n");
    Ok(())
}

fn write_report(
    args: &ExperimentArgs,
    suites: &[Suite],
    variants: &BTreeMap<Suite, Vec<Variant>>,
    problems: &[LoadedProblem],
    records: &BTreeMap<Key, RunLine>,
    info: &RunInfo,
) -> CliResult<PathBuf> {
    let mut md = String::new();
    let command: Vec<String> = std::env::args().map(|a| shell_quote(&a)).collect();
    let _ = writeln!(md, "# MTPCR experiments\n");
    let _ = writeln!(
        md,
        "Generated by `mtpcr experiment` from `runs.jsonl` (one JSON line per run; rerunning \
         the command skips the runs already there).\n"
    );
    let _ = writeln!(md, "- Command: `{}`", command.join(" "));
    let _ = writeln!(
        md,
        "- Working directory: `{}`",
        std::env::current_dir()
            .map(|d| d.display().to_string())
            .unwrap_or_default()
    );
    let _ = writeln!(md, "- Machine: {}", machine());
    let _ = writeln!(
        md,
        "- Jobs: {} at once, 1 thread each; seeds 0..N-1 per problem and variant; each run's \
         scans are moved by a seeded random motion (`eval::run_moved`)",
        args.jobs
    );
    if let Some(g) = args.generations {
        let _ = writeln!(
            md,
            "- **Generations overridden to {g}** (not the paper's setting)"
        );
    }
    let n_computed: usize = info.computed.values().map(|c| c.0).sum();
    // fold from +0.0: an empty f64 sum is -0.0, printed "-0.0".
    let cpu = info.computed.values().fold(0.0, |sum, c| sum + c.1);
    let _ = writeln!(
        md,
        "- This invocation: {n_computed} runs computed, {} reused from `runs.jsonl`, wall time \
         {:.1} s, CPU time (sum of run seconds) {cpu:.1} s, CPU / wall {}",
        info.skipped,
        info.wall,
        if n_computed > 0 && info.wall > 0.0 {
            format!("{:.2}", cpu / info.wall)
        } else {
            "n/a (nothing computed)".to_string()
        }
    );
    if info.missing > 0 {
        let _ = writeln!(
            md,
            "- **{} planned runs are not in `runs.jsonl`** (written with `--report-only`); \
             the `runs` column of each table says how many runs a cell holds",
            info.missing
        );
    }
    for (suite, (n, secs)) in &info.computed {
        let _ = writeln!(
            md,
            "  - {}: {n} runs, {secs:.1} s of run time, {:.2} × the invocation's wall time \
             (suites share one job queue)",
            suite.name(),
            secs / info.wall.max(1e-9)
        );
    }
    // The report may gather runs of several invocations: their total run time per suite.
    let _ = writeln!(md, "- All runs in this report (any invocation):");
    for &suite in suites {
        let secs: Vec<f64> = records
            .values()
            .filter(|r| r.suite == suite.name())
            .map(|r| r.seconds)
            .collect();
        let total: f64 = secs.iter().sum();
        let _ = writeln!(
            md,
            "  - {}: {} runs, {total:.0} s of run time (about {:.0} s of wall time at {} jobs)",
            suite.name(),
            secs.len(),
            total / args.jobs as f64,
            args.jobs
        );
    }
    md.push('\n');

    for &suite in suites {
        let vs = &variants[&suite];
        let section = Section {
            suite,
            out: &args.out,
            variants: vs,
            problems: problems_in(records, suite, problems),
            records,
        };
        match suite {
            Suite::Accuracy => {
                let _ = writeln!(md, "## Accuracy (paper Table 2)\n");
                let _ = writeln!(
                    md,
                    "Err_R = mean over the three pairs of ‖R_est − R_gt‖_F, Err_T = mean of \
                     ‖t_est − t_gt‖ (data units), both ×1000, mean ± std over the runs; a run \
                     succeeds when every pair is within 5°. The paper column is the published \
                     MTPCR Err_R ×1000.\n"
                );
                let paper = |_: &Variant, name: &str| {
                    PAPER_ERR_R
                        .iter()
                        .find(|(n, _, _)| n.eq_ignore_ascii_case(name))
                        .map_or("–".to_string(), |(_, m, s)| format!("{m:.2} ± {s:.2}"))
                };
                error_table(&mut md, &section, Some(("paper MTPCR Err_R ×1000", &paper)));
                md.push('\n');
            }
            Suite::Noise => {
                let _ = writeln!(md, "## Noise robustness (paper Table 3)\n");
                let _ = writeln!(
                    md,
                    "Gaussian noise of the given sigma added to every scan in normalised \
                     coordinates (`PointCloud::with_normalized_noise`, seeded from the run \
                     seed) before the run; `Config::default()` and `Config::paper()`.\n"
                );
                error_table(&mut md, &section, None);
                md.push('\n');
            }
            Suite::Quality => {
                let _ = writeln!(md, "## Solution quality (paper Table 4)\n");
                quality_section(&mut md, &section)?;
            }
            Suite::Alpha => {
                let _ = writeln!(md, "## Sensitivity to alpha (paper Section VI)\n");
                alpha_section(&mut md, &section)?;
            }
            Suite::Sharing => {
                let _ = writeln!(
                    md,
                    "## Sensitivity to the sharing probabilities (paper Section VI)\n"
                );
                sharing_section(&mut md, &section)?;
            }
            Suite::Sampling => {
                let _ = writeln!(
                    md,
                    "## Sensitivity to the sample ratio (paper Section VI)\n"
                );
                sampling_section(&mut md, &section)?;
            }
        }
    }
    let path = args.out.join("RESULTS.md");
    std::fs::write(&path, md).map_err(|e| Failure(format!("{}: {e}", path.display())))?;
    Ok(path)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn truncated_last_line_is_cut_and_ignored() {
        let dir = std::env::temp_dir().join(format!("mtpcr-cli-exp-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("runs.jsonl");
        let line = RunLine {
            suite: "quality".into(),
            variant: "mfea".into(),
            problem: "p".into(),
            seed: 3,
            settings: Config::paper(),
            success: true,
            err_r: 0.1,
            err_t: 0.2,
            rot_deg: [1.0, 2.0, 3.0],
            final_costs: FinalCosts {
                original: [0.5; 3],
                aiding: [0.01; 3],
            },
            history: vec![[1.0; 6], [0.5; 6]],
            seconds: 1.5,
        };
        let text = serde_json::to_string(&line).unwrap();
        std::fs::write(&path, format!("{text}\n{}", &text[..20])).unwrap();
        let runs = read_runs(&path).unwrap();
        assert_eq!(runs.len(), 1);
        assert_eq!(runs[0].key(), line.key());
        assert_eq!(std::fs::read_to_string(&path).unwrap(), format!("{text}\n"));
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn variants_have_distinct_keys_and_valid_settings() {
        for s in Suite::value_variants() {
            let s = *s;
            let vs = s.variants();
            let keys: HashSet<&str> = vs.iter().map(|v| v.key.as_str()).collect();
            assert_eq!(keys.len(), vs.len());
            for v in &vs {
                v.config.validate().unwrap();
            }
        }
        assert_eq!(Suite::Quality.variants().len(), 6);
        assert_eq!(Suite::Noise.variants()[1].key, "noise-0.02");
        assert_eq!(Suite::Noise.variants()[4].key, "noise-paper-0.02");
        assert_eq!(Suite::Alpha.variants()[3].config.alpha, 0.05);
        assert_eq!(Suite::Sampling.variants()[9].config.sample_ratio, 0.5);
        let sharing = &Suite::Sharing.variants()[2].config;
        assert_eq!((sharing.p_intra, sharing.p_inter), (0.4, 0.4));
    }

    #[test]
    fn median_of_even_and_odd_counts() {
        assert_eq!(median(&[3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(&[4.0, 1.0, 2.0, 3.0]), 2.5);
        assert!(median(&[]).is_nan());
    }
}
