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
use clap::Args;
use mtpcr_core::eval::mean_std;
use mtpcr_core::eval::problem::Problem;
use mtpcr_core::eval::protocol::{
    run_one, RunRecord, Suite, Variant, BUNNIES, PAPER_ALPHA, PAPER_ERR_R,
};
use mtpcr_core::{PointCloud, Transform, ViewGraph};
use std::collections::{BTreeMap, HashSet};
use std::fmt::Write as _;
use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{mpsc, Mutex};
use std::time::Instant;

/// A "No. of Best" cell counts when the method's mean is within this fraction of the best.
const BEST_TOLERANCE: f64 = 0.01;

/// Parses a suite name for clap.
fn parse_suite(name: &str) -> Result<Suite, String> {
    Suite::from_name(name).map_err(|e| e.to_string())
}

/// Arguments of `mtpcr experiment`.
#[derive(Args, Clone, Debug)]
pub struct ExperimentArgs {
    /// Suites to run: accuracy (Table 2), quality (Table 4), noise (Table 3), and the
    /// sensitivity studies alpha, sharing, sampling.
    #[arg(required = true, value_name = "SUITE", value_parser = parse_suite)]
    pub suites: Vec<Suite>,
    /// Output folder: runs.jsonl (one line per run, resumable), RESULTS.md, figures.
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// Runs (seeds 0..N) per problem and variant [default: 10 for accuracy and noise, 20 for
    /// quality].
    #[arg(long, value_name = "N")]
    pub runs: Option<usize>,
    /// Problem files, for every suite [default: the shared data's problems/*.json, sorted; the
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

type RunLine = RunRecord;

type Key = (String, String, String, u64);

/// The record's key: (suite, variant, problem, seed).
fn key(r: &RunLine) -> Key {
    (
        r.suite.clone(),
        r.variant.clone(),
        r.problem.clone(),
        r.seed,
    )
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
    scans: Option<Vec<PointCloud>>,
    truth: Vec<Transform>,
}

fn default_problems() -> CliResult<Vec<PathBuf>> {
    let shared = mtpcr_core::eval::shared::find_shared_dir().ok_or_else(|| {
        Failure(
            "no shared data found ($MTPCR_SHARED_DIR, or a shared/ folder beside this one or \
             an ancestor); pass --problems FILE..."
                .to_string(),
        )
    })?;
    let dir = &shared.join("problems");
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

/// One run of the protocol (`mtpcr_core::eval::protocol::run_one`).
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
    run_one(
        suite,
        variant,
        &problem.problem.name,
        scans,
        &problem.truth,
        seed,
        generations,
    )
    .map_err(|e| e.to_string())
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
        let truth = problem.ground_truth()?;
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
    let done: HashSet<Key> = read_runs(&runs_path)?.iter().map(key).collect();

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
                c.validate(&path.display().to_string(), mtpcr_core::MIN_POINTS)?;
            }
            p.scans = Some(scans);
        }
    }

    let computed = execute_all(args, &variants, &problems, pending, &runs_path)?;
    let wall = started.elapsed().as_secs_f64();

    let all = read_runs(&runs_path)?;
    let mut records: BTreeMap<Key, RunLine> = BTreeMap::new();
    for r in all {
        let k = key(&r);
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
                        "[{finished}/{total}] {} {vkey} {name} seed {}: {} rot {} deg, \
                         Err_R x1000 {:.2}, J-o {}, {:.1} s",
                        w.suite.name(),
                        w.seed,
                        if line.success { "ok  " } else { "FAIL" },
                        joined(&line.rot_deg, 2),
                        line.err_r * 1000.0,
                        joined(&line.final_costs.original, 4),
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

/// Values joined by spaces with `decimals` decimals.
fn joined(values: &[f64], decimals: usize) -> String {
    let parts: Vec<String> = values.iter().map(|v| format!("{v:.decimals$}")).collect();
    parts.join(" ")
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
        let lines: Vec<(String, Vec<Vec<f64>>)> = section
            .variants
            .iter()
            .map(|v| (v.label.clone(), mean_history(&section.cell(&v.key, name))))
            .filter(|(_, h)| !h.is_empty())
            .collect();
        if lines.is_empty() {
            continue;
        }
        let file = format!("{prefix}{name}.png");
        let names = ViewGraph::for_views(p.problem.scans.len())?.task_names();
        plots::methods_convergence_png(
            &lines,
            &names,
            &format!("{name}: best cost per generation, mean over runs, by {what}"),
            &section.out.join(&file),
        )?;
        let _ = writeln!(md, "![{name} convergence by {what}]({file})\n");
    }
    Ok(())
}

/// Mean over runs of the history rows (cut to the shortest history).
fn mean_history(rs: &[&RunLine]) -> Vec<Vec<f64>> {
    let len = rs.iter().map(|r| r.history.len()).min().unwrap_or(0);
    let tasks = rs
        .first()
        .map_or(0, |r| r.history.first().map_or(0, Vec::len));
    (0..len)
        .map(|g| {
            (0..tasks)
                .map(|t| rs.iter().map(|r| r.history[g][t]).sum::<f64>() / rs.len() as f64)
                .collect()
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
        let names = ViewGraph::for_views(p.problem.scans.len())?.task_names();
        let edges = names.len() / 2;
        for task in 0..edges {
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
            let mut row = format!("| {name} | {} | {runs} |", names[edges + task]);
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
    // The command as typed, without machine paths: the program is `mtpcr`, absolute
    // paths below the working directory are written relative to it.
    let cwd = std::env::current_dir().unwrap_or_default();
    let command: Vec<String> = std::iter::once("mtpcr".to_string())
        .chain(std::env::args().skip(1).map(|a| {
            let rel = Path::new(&a)
                .strip_prefix(&cwd)
                .map(|r| r.display().to_string())
                .unwrap_or(a);
            shell_quote(&rel)
        }))
        .collect();
    let _ = writeln!(md, "# MTPCR experiments\n");
    let _ = writeln!(
        md,
        "Generated by `mtpcr experiment` from `runs.jsonl` (one JSON line per run; rerunning \
         the command skips the runs already there).\n"
    );
    let _ = writeln!(md, "- Command: `{}`", command.join(" "));
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
            settings: mtpcr_core::Config::paper(),
            success: true,
            err_r: 0.1,
            err_t: 0.2,
            rot_deg: vec![1.0, 2.0, 3.0],
            final_costs: mtpcr_core::eval::protocol::FinalCosts {
                original: vec![0.5; 3],
                aiding: vec![0.01; 3],
            },
            history: vec![vec![1.0; 6], vec![0.5; 6]],
            seconds: 1.5,
        };
        let text = serde_json::to_string(&line).unwrap();
        std::fs::write(&path, format!("{text}\n{}", &text[..20])).unwrap();
        let runs = read_runs(&path).unwrap();
        assert_eq!(runs.len(), 1);
        assert_eq!(key(&runs[0]), key(&line));
        assert_eq!(std::fs::read_to_string(&path).unwrap(), format!("{text}\n"));
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn median_of_even_and_odd_counts() {
        assert_eq!(median(&[3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(&[4.0, 1.0, 2.0, 3.0]), 2.5);
        assert!(median(&[]).is_nan());
    }
}
