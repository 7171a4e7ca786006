//! `mtpcr eval FOLDER`: pair benchmarks in the 3DMatch layout (`mtpcr_core::eval::pairs`):
//! runs the pairs, appends each record to a resumable JSON-lines file, prints per-scene and
//! overall tables.

use crate::error::{outln, CliResult, Failure};
use crate::progress;
use crate::settings::{self, RunArgs};
use mtpcr_core::eval::pairs::{
    run_benchmark, summarize, PairBenchmark, PairRecord, PairStep, PairSummary,
};
use std::io::Write;
use std::ops::ControlFlow;
use std::path::{Path, PathBuf};

/// The options of `mtpcr eval` that apply to pair benchmarks.
#[derive(clap::Args, Clone, Debug, Default)]
pub struct PairArgs {
    /// Pair benchmarks: run a seeded sample of this many pairs of each benchmark (the same
    /// pairs for the same --seed) [default: every pair].
    #[arg(long, value_name = "N")]
    pub pairs: Option<usize>,
    /// Pair benchmarks: only the scenes whose folder name contains one of these
    /// (comma-separated).
    #[arg(long, value_delimiter = ',', value_name = "NAME")]
    pub scenes: Vec<String>,
    /// Pair benchmarks: move each source fragment by a seeded random rigid motion first (the
    /// errors are still measured in the fragment's own frame, as the benchmark defines them).
    #[arg(long)]
    pub moved: bool,
    /// Pair benchmarks: append every pair's record to this JSON-lines file, and skip the
    /// pairs it already holds for the same benchmark, seed and motion (resumable).
    #[arg(long, value_name = "FILE")]
    pub records: Option<PathBuf>,
}

/// The records already in `path` (none when it does not exist).
fn read_records(path: &Path) -> CliResult<Vec<PairRecord>> {
    let text = match std::fs::read_to_string(path) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Vec::new()),
        Err(e) => return Err(Failure(format!("{}: {e}", path.display()))),
    };
    text.lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty())
        .map(|(i, l)| {
            serde_json::from_str(l).map_err(|e| {
                Failure(format!(
                    "{} line {}: not a pair record ({e}); use another --records file",
                    path.display(),
                    i + 1
                ))
            })
        })
        .collect()
}

/// Appends `record` as one JSON line.
fn append_record(f: &mut std::fs::File, record: &PairRecord) -> CliResult<()> {
    let line = serde_json::to_string(record)
        .map_err(|e| Failure(format!("cannot serialise a record: {e}")))?;
    writeln!(f, "{line}").map_err(|e| Failure(format!("records file: {e}")))
}

/// A pair's outcome on one line: `scene/i-j: ok   RE 1.01 deg TE 0.039, confident, 0.20 s`.
fn record_line(record: &PairRecord) -> String {
    format!(
        "{}: {} RE {:.2} deg TE {:.3}, {}, {:.2} s",
        record.pair,
        if record.registered { "ok  " } else { "FAIL" },
        record.re_deg,
        record.te,
        if record.confident {
            "confident"
        } else {
            "doubted"
        },
        record.seconds
    )
}

#[allow(clippy::too_many_arguments)]
pub fn eval_pairs(
    folders: &[PathBuf],
    runs: Option<usize>,
    seed: Option<u64>,
    data_root: Option<&Path>,
    json: Option<&Path>,
    (ground_truth_frame, noise): (bool, Option<f64>),
    args: &PairArgs,
    run: &RunArgs,
) -> CliResult<()> {
    if let Some(p) = folders.iter().find(|p| !p.is_dir()) {
        return Err(Failure(format!(
            "{}: pair benchmark folders and problem files cannot be mixed in one eval",
            p.display()
        )));
    }
    if runs.is_some_and(|r| r != 1) || ground_truth_frame || noise.is_some() {
        return Err(Failure(
            "pair benchmarks run every pair once, as given (or --moved): --runs, \
             --ground-truth-frame and --noise apply to problem files"
                .to_string(),
        ));
    }
    let mut config = settings::resolve(run, None)?;
    let seed = seed.or(config.seed).unwrap_or(0);
    config.seed = None;
    let mut benchmarks = Vec::new();
    for f in folders {
        let mut b = PairBenchmark::load(f, data_root)?;
        b.retain_scenes(&args.scenes)?;
        if let Some(n) = args.pairs {
            b.sample(n, seed);
        }
        benchmarks.push(b);
    }
    let earlier = match &args.records {
        Some(p) => read_records(p)?,
        None => Vec::new(),
    };
    let mut out = match &args.records {
        Some(p) => Some(
            std::fs::OpenOptions::new()
                .create(true)
                .append(true)
                .open(p)
                .map_err(|e| Failure(format!("{}: {e}", p.display())))?,
        ),
        None => None,
    };
    let total: usize = benchmarks.iter().map(|b| b.cases.len()).sum();
    let bar = progress::run_bar(total, run.quiet, "pairs");
    let mut tables = Vec::new();
    for b in &benchmarks {
        // A records file that cannot be written stops the run with the error.
        let mut failure = None;
        let records = run_benchmark(b, &config, seed, args.moved, &earlier, &mut |step| {
            let (record, reused) = match step {
                PairStep::Running(case) => {
                    bar.set_message(format!("{} {}", b.name, case.key()));
                    return ControlFlow::Continue(());
                }
                PairStep::Done { record, reused } => (record, reused),
            };
            if !reused {
                if let Some(f) = out.as_mut() {
                    if let Err(e) = append_record(f, record) {
                        failure = Some(e);
                        return ControlFlow::Break(());
                    }
                }
                if !run.quiet {
                    bar.suspend(|| eprintln!("{} {}", b.name, record_line(record)));
                }
            }
            bar.inc(1);
            ControlFlow::Continue(())
        })?;
        if let Some(e) = failure {
            return Err(e);
        }
        let records: Vec<(String, PairRecord)> = b
            .cases
            .iter()
            .map(|c| c.scene.clone())
            .zip(records)
            .collect();
        tables.push((b.name.clone(), records));
    }
    bar.finish_and_clear();
    let mut report = Vec::new();
    outln!(
        "{:<12} {:<52} {:>5} {:>7} {:>7} {:>7} {:>7} {:>15} {:>16}",
        "benchmark",
        "scene",
        "pairs",
        "RR %",
        "RE deg",
        "TE",
        "s/pair",
        "failed+confid.",
        "registered+doubt"
    );
    for (name, records) in &tables {
        let mut scenes: Vec<&str> = records.iter().map(|(s, _)| s.as_str()).collect();
        scenes.dedup();
        let mut rows: Vec<(String, PairSummary)> = scenes
            .iter()
            .map(|s| {
                let of_scene = records.iter().filter(|(x, _)| x == s).map(|(_, r)| r);
                (s.to_string(), summarize(of_scene))
            })
            .collect();
        rows.push(("all".to_string(), summarize(records.iter().map(|(_, r)| r))));
        for (scene, s) in &rows {
            outln!(
                "{:<12} {:<52} {:>5} {:>7.1} {:>7} {:>7} {:>7.2} {:>15} {:>16}",
                name,
                scene,
                s.pairs,
                s.recall,
                or_dash(s.re_deg, 2),
                or_dash(s.te, 3),
                s.median_seconds,
                format!("{}/{}", s.failed_confident, s.failed),
                format!("{}/{}", s.registered_doubted, s.registered)
            );
        }
        report.push(serde_json::json!({
            "benchmark": name,
            "scenes": rows.iter().map(|(s, sum)| serde_json::json!({"scene": s, "summary": sum})).collect::<Vec<_>>(),
            "records": records.iter().map(|(_, r)| r).collect::<Vec<_>>(),
        }));
    }
    if let Some(path) = json {
        let doc = serde_json::json!({
            "settings": config, "seed": seed, "moved": args.moved, "benchmarks": report,
        });
        let text = serde_json::to_string_pretty(&doc)
            .map_err(|e| Failure(format!("cannot serialise the report: {e}")))?;
        std::fs::write(path, text).map_err(|e| Failure(format!("{}: {e}", path.display())))?;
        outln!("wrote {}", path.display());
    }
    Ok(())
}

/// `v` with `decimals`, or "-" when there is none (a mean over no registered pair).
fn or_dash(v: f64, decimals: usize) -> String {
    if v.is_finite() {
        format!("{v:.decimals$}")
    } else {
        "-".to_string()
    }
}
