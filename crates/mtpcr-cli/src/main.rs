//! `mtpcr`: the command-line front-end. It parses, shows progress on stderr, writes results;
//! all registration logic lives in `mtpcr-core`.
//!
//! Exit codes: 0 success, 1 failure (a message `error: ...` on stderr), 2 usage error, 3
//! registered and written but not confident (the verdict's reasons are printed), 130
//! `register` interrupted by Ctrl-C (see [`interrupt`]).

mod error;
mod experiment;
mod interrupt;
mod output;
mod pairs;
mod plots;
mod progress;
mod settings;
mod viewer;

use clap::{CommandFactory, FromArgMatches, Parser, Subcommand};
use error::{outln, CliResult, Failure};
use mtpcr_core::eval::problem::Problem;
use mtpcr_core::eval::{mean_std, run_moved, score};
use mtpcr_core::io::read_scans;
use mtpcr_core::{synthetic, Config, PointCloud, MIN_POINTS};
use settings::RunArgs;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

#[derive(Parser)]
#[command(
    name = "mtpcr",
    version,
    about = "Register overlapping point clouds with no initial guess (MTPCR)",
    long_about = "Register overlapping point clouds (two, or three or more in loop order) with no \
        initial guess (MTPCR).\n\n\
        Convention: T_ij maps points of cloud i into the frame of cloud j (x_j = T_ij x_i).\n\
        Settings come from Config::default() (or --paper), then --config FILE, then the flags.",
    after_help = "Examples:\n  \
        mtpcr demo\n  \
        mtpcr register A.ply B.ply C.ply --output out/ --seed 1\n  \
        mtpcr dump-config > my.toml && mtpcr register A.ply B.ply C.ply --config my.toml\n  \
        mtpcr eval ../shared/problems/*.json --runs 10\n  \
        mtpcr experiment accuracy quality noise --out eval/experiments"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Generate a shape, cut three overlapping views, move them randomly, register them.
    ///
    /// Exits 0 when every pair is registered within 2 degrees, 1 otherwise.
    Demo {
        /// Seed of the shape, the motions and the run [default: the config file's seed, else 1].
        #[arg(long)]
        seed: Option<u64>,
        /// Points per generated view.
        #[arg(long, default_value_t = 20000)]
        points: usize,
        #[command(flatten)]
        run: RunArgs,
    },
    /// Register two point clouds or more and write a results folder.
    ///
    /// Each file is PLY, PCD, E57 (every scan in it is a cloud), LAS/LAZ or XYZ text; a
    /// folder stands for its .ply/.pcd/.e57/.las/.laz/.xyz/.pts files in natural order. Two
    /// clouds give T12; more give each cloud's pose in cloud 1's frame (or, when cloud 1
    /// cannot be placed, in the first placed cloud's; with --order given: clouds in loop
    /// order, T12, T23, ..., Tn1). The folder holds
    /// result.json, config.toml (the settings, to repeat the run), transforms.txt, poses.log
    /// (each placed cloud's pose in cloud 1's frame, the 3DMatch/Redwood trajectory format),
    /// pose_graph.json (Open3D's pose graph: open3d.io.read_pose_graph), merged.ply (the
    /// clouds in cloud 1's frame, one colour per view), convergence.png, views.png and
    /// view.html (an interactive 3-D view that opens offline).
    Register {
        /// The point-cloud files or folders of them (one E57 file of several scans is enough).
        #[arg(num_args = 1.., required = true, value_name = "CLOUD")]
        clouds: Vec<PathBuf>,
        /// Output folder [default: results/<UTC timestamp>]; must be new or empty unless --force.
        #[arg(long, short, value_name = "DIR")]
        output: Option<PathBuf>,
        /// Write into a non-empty output folder (files of the same name are replaced).
        #[arg(long)]
        force: bool,
        /// Seed of the run [default: the config file's, else drawn and reported].
        #[arg(long)]
        seed: Option<u64>,
        /// Where each scanner stood, for the free-space check (a right pose puts no scan's
        /// surface where another scanner saw through).
        #[arg(long, value_enum, default_value_t = Viewpoints::File, value_name = "WHERE")]
        viewpoint: Viewpoints,
        #[command(flatten)]
        run: RunArgs,
    },
    /// Evaluate on problem files (shared/problems format) or pair benchmarks against their
    /// ground truth.
    ///
    /// A folder is a pair benchmark in the 3DMatch layout (a gt.log per scene folder, e.g.
    /// ../shared/data/3dmatch/benchmarks/3DLoMatch): every pair registered once and scored as
    /// in the literature (registered: rotation error < 15 deg and translation error < 0.3),
    /// with per-scene and overall recall, errors, seconds and the verdict's confusion.
    Eval {
        /// Problem files, or pair benchmark folders.
        #[arg(required = true, value_name = "PROBLEM")]
        problems: Vec<PathBuf>,
        /// Runs per problem [default: 10; pair benchmarks: 1 per pair].
        #[arg(long)]
        runs: Option<usize>,
        /// Seed of the first run; run r uses seed + r [default: the config file's, else 0].
        #[arg(long)]
        seed: Option<u64>,
        /// Folder the scan paths are relative to [default: the parent of each problem's folder].
        #[arg(long, value_name = "DIR")]
        data_root: Option<PathBuf>,
        /// Write every run's numbers to this JSON file (for four or more scans also each run's
        /// poses: `poses` of the moved scans as registered, `poses_as_given` carried back to the
        /// scans as given, in the first placed scan's frame, as scored against the truth).
        #[arg(long, value_name = "FILE")]
        json: Option<PathBuf>,
        /// Start every run from the scans placed by their ground-truth poses (relative
        /// rotations near zero) instead of moving each by a seeded random rigid motion
        /// (problems of two or three scans).
        #[arg(long)]
        ground_truth_frame: bool,
        /// Add Gaussian noise of this sigma to every scan first, as the paper's Table 3 (scan
        /// centred and scaled to unit size; seeded from each run's seed).
        #[arg(long, value_name = "SIGMA")]
        noise: Option<f64>,
        #[command(flatten)]
        pairs: pairs::PairArgs,
        #[command(flatten)]
        run: RunArgs,
    },
    /// Run the paper's experiment suites (accuracy, quality, noise, and the sensitivity
    /// studies alpha, sharing, sampling) into a resumable folder.
    ///
    /// Every run is a line of DIR/runs.jsonl (runs already there are skipped); DIR/RESULTS.md
    /// and DIR/convergence-<problem>.png are regenerated from it.
    Experiment(experiment::ExperimentArgs),
    /// Print the default settings as TOML (a starting point for --config FILE).
    DumpConfig {
        /// Print Config::paper() (the authors' reference) instead of Config::default().
        #[arg(long)]
        paper: bool,
    },
}

/// Where the scanners stood (`register --viewpoint`): each cloud's viewpoint, the
/// scanner's position in the cloud's own frame, lets the engine check free space.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
enum Viewpoints {
    /// Every scan was taken from its own file's origin (depth-camera frames, 3DMatch
    /// fragments).
    Origin,
    /// Only what the files say (a PCD header's VIEWPOINT other than the default).
    File,
    /// No viewpoint, even where a file gives one (the free-space check is off).
    #[value(name = "none")]
    Ignore,
}

impl Viewpoints {
    /// The cloud with its viewpoint set as chosen.
    fn apply(self, cloud: PointCloud) -> PointCloud {
        match self {
            Viewpoints::Origin => cloud.with_viewpoint([0.0; 3]),
            Viewpoints::File => cloud,
            Viewpoints::Ignore => PointCloud::new(cloud.into_points()),
        }
    }
}

fn demo(seed: Option<u64>, points: usize, run: &RunArgs) -> CliResult<bool> {
    let mut config = settings::resolve(run, seed)?;
    let seed = config.seed.unwrap_or(1);
    config.seed = Some(seed);
    if points < MIN_POINTS {
        return Err(Failure(format!(
            "--points must be at least {MIN_POINTS}, got {points}"
        )));
    }
    let problem = synthetic::three_views(seed, points);
    outln!(
        "demo: three synthetic views of {points} points each, moved by random rigid motions \
         (seed {seed})"
    );
    let result = progress::register_with_bar(&problem.clouds, &config, run.quiet, "demo")?;
    let transforms = result.transforms();
    let s = score(&transforms, &problem.ground_truth);
    let names = ["T12", "T23", "T31"];
    for (i, name) in names.iter().enumerate() {
        let t = mtpcr_core::se3::translation_error(&transforms[i], &problem.ground_truth[i]);
        outln!(
            "  {name}: rotation error {:.3} deg, translation error {t:.2e} (shape size 0.15)",
            s.rot_deg[i]
        );
    }
    outln!(
        "  loop residual {:.2e}, {} evaluations, {:.2} s",
        result.loop_residual().unwrap_or(f64::NAN),
        result.evaluations,
        result.seconds
    );
    let ok = s.rot_deg.iter().all(|&d| d < 2.0);
    outln!(
        "{}",
        if ok {
            "demo passed: every pair under 2 degrees"
        } else {
            "demo FAILED: some pair is 2 degrees or more off"
        }
    );
    Ok(ok)
}

/// A seed that is easy to type back (below 2^32) and fits a TOML integer.
fn draw_seed() -> u64 {
    use std::hash::BuildHasher;
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_nanos())
        .unwrap_or(0);
    std::collections::hash_map::RandomState::new().hash_one((nanos, std::process::id()))
        & 0xffff_ffff
}

/// The warning for a planar cloud (see [`PointCloud::is_planar`]), `number` counted from 1.
fn planar_warning(number: usize, label: &str) -> String {
    format!(
        "warning: cloud {number} is planar: its rotation about the plane normal is weakly \
         determined ({label})"
    )
}

/// Reads every scan of every file (an E57 file may hold several), validated; returns the
/// clouds and a label per cloud (the file, and the scan's name when a file holds several).
/// A planar cloud is accepted with a warning on stderr (even with `--quiet`). Each cloud's
/// viewpoint is set as `viewpoints` says.
fn read_clouds(
    paths: &[PathBuf],
    viewpoints: Viewpoints,
    quiet: bool,
) -> CliResult<(Vec<PointCloud>, Vec<String>)> {
    let mut clouds = Vec::with_capacity(paths.len());
    let mut labels = Vec::with_capacity(paths.len());
    for p in paths {
        let scans = read_scans(p)?;
        let several = scans.len() > 1;
        for scan in scans {
            let label = if several {
                format!("{} [{}]", p.display(), scan.name)
            } else {
                p.display().to_string()
            };
            scan.cloud.validate(&label, MIN_POINTS)?;
            if scan.cloud.is_planar() {
                eprintln!("{}", planar_warning(clouds.len() + 1, &label));
            }
            if !quiet {
                eprintln!("read {label}: {} points", scan.cloud.len());
            }
            clouds.push(viewpoints.apply(scan.cloud));
            labels.push(label);
        }
    }
    if clouds.len() < 2 {
        return Err(Failure(format!(
            "at least two clouds are needed, got {} ({}); give two files or more, or an E57 \
             file of several scans",
            clouds.len(),
            labels.join(", ")
        )));
    }
    Ok((clouds, labels))
}

/// Exit status of `register` when the clouds were registered and the results written, but
/// the verdict is not confident.
const NOT_CONFIDENT: u8 = 3;

/// Registers the files and writes the results folder; returns the verdict's `confident`.
fn register_files(
    inputs: &[PathBuf],
    output: Option<&Path>,
    force: bool,
    seed: Option<u64>,
    viewpoints: Viewpoints,
    run: &RunArgs,
) -> CliResult<bool> {
    let mut config = settings::resolve(run, seed)?;
    config.seed = Some(config.seed.unwrap_or_else(draw_seed));
    interrupt::install()?;
    // A folder given stands for its point-cloud files, in natural order.
    let mut files = Vec::with_capacity(inputs.len());
    for input in inputs {
        if input.is_dir() {
            files.extend(mtpcr_core::io::cloud_files_in(input)?);
        } else {
            files.push(input.clone());
        }
    }
    let inputs = &files[..];
    // The folder is checked before the (possibly long) reading.
    let dir = output::prepare_output(output, inputs, force)?;
    let (clouds, labels) = match read_clouds(inputs, viewpoints, run.quiet) {
        Ok(c) => c,
        Err(e) => {
            dir.discard_if_unused();
            return Err(e);
        }
    };
    let result = match progress::register_with_bar(&clouds, &config, run.quiet, "register") {
        Ok(r) => r,
        Err(e) => {
            dir.discard_if_unused();
            return Err(e.into());
        }
    };
    if !run.quiet {
        eprintln!("writing {}", dir.path.display());
    }
    let help = settings::field_help();
    let record = output::RunRecord {
        inputs,
        labels: &labels,
        clouds: &clouds,
        config: &config,
        result: &result,
        field_help: &help,
    };
    let written = output::write_results(&dir.path, &record)?;
    interrupt::release();

    let edges = result.edges.len();
    for (k, e) in result.edges.iter().enumerate() {
        outln!(
            "{} (cloud {} -> cloud {} frame) =\n{}",
            result.edge_name(k),
            e.source + 1,
            e.target + 1,
            mtpcr_core::io::matrix_text(&e.t_target_source)
        );
    }
    // Scans in no known order are placed from verified hypotheses: no evolution, no tasks.
    if result.task_names.len() == 2 * edges {
        outln!(
            "{:<6} {:>14} {:>12}   (the evolution's best costs, before refinement)",
            "pair",
            "best original",
            "best aiding"
        );
        for (k, e) in result.edges.iter().enumerate() {
            outln!(
                "{:<6} {:>14.6} {:>12.6}   ({} / {})",
                result.edge_name(k),
                e.original_cost,
                e.aiding_cost,
                result.task_names[edges + k],
                result.task_names[k]
            );
        }
    }
    for u in &result.unplaced {
        outln!("cloud {} NOT PLACED: {}", u.view + 1, u.reason);
    }
    if let Some(v) = result.reference_view().filter(|&v| v > 0) {
        outln!(
            "poses are in the frame of cloud {} (cloud 1 is not placed)",
            v + 1
        );
    }
    if result.verdict.confident {
        outln!("verdict: confident (every pair overlaps and its surfaces lie on each other)");
    } else {
        outln!(
            "verdict: NOT CONFIDENT: {}",
            result.verdict.reasons.join("; ")
        );
    }
    let residual = result
        .loop_residual()
        .map_or("none (no loop)".to_string(), |r| format!("{r:.3e}"));
    outln!(
        "loop residual {residual}, {} evaluations, {:.2} s, seed {}",
        result.evaluations,
        result.seconds,
        result.seed
    );
    let mut folder = dir.path.display().to_string();
    if !folder.ends_with('/') {
        folder.push('/');
    }
    outln!("wrote {folder} ({})", written.join(", "));
    Ok(result.verdict.confident)
}

/// How each evaluation run starts.
#[derive(Clone, Copy)]
struct RunStart {
    /// From the scans placed by their ground-truth poses, not moved.
    ground_truth_frame: bool,
    /// Noise sigma added to every scan first.
    noise: Option<f64>,
}

/// The scans with the noise of the paper's protocol (`eval::protocol::add_noise`, seeded
/// from the run's seed), or as they are.
fn with_noise(
    clouds: &[PointCloud],
    noise: Option<f64>,
    seed: u64,
) -> CliResult<std::borrow::Cow<'_, [PointCloud]>> {
    Ok(match noise {
        Some(sigma) => {
            std::borrow::Cow::Owned(mtpcr_core::eval::protocol::add_noise(clouds, sigma, seed)?)
        }
        None => std::borrow::Cow::Borrowed(clouds),
    })
}

fn eval(
    problems: &[PathBuf],
    runs: usize,
    seed: Option<u64>,
    data_root: Option<&Path>,
    json: Option<&Path>,
    start: RunStart,
    run: &RunArgs,
) -> CliResult<()> {
    let RunStart {
        ground_truth_frame,
        noise,
    } = start;
    let mut config = settings::resolve(run, None)?;
    let seed = seed.or(config.seed).unwrap_or(0);
    config.seed = None;
    if runs == 0 {
        return Err(Failure("--runs must be at least 1".to_string()));
    }
    let loaded: Vec<Problem> = problems
        .iter()
        .map(|p| Problem::load(p, data_root))
        .collect::<Result<_, _>>()?;
    if let Some(p) = loaded
        .iter()
        .find(|p| ground_truth_frame && p.scans.len() >= 4)
    {
        return Err(Failure(format!(
            "--ground-truth-frame applies to problems of two or three scans; {} has {}",
            p.name,
            p.scans.len()
        )));
    }
    let bar = progress::run_bar(loaded.len() * runs, run.quiet, "eval");
    let mut report = Vec::new();
    let mut rows = Vec::new();
    let mut view_rows = Vec::new();
    for problem in &loaded {
        bar.set_message(format!("{}: reading the scans", problem.name));
        let clouds = problem.read_scans()?;
        // Four scans or more are scored by their poses (every scan under 1 degree), in any order.
        if clouds.len() >= 4 {
            let runs_json = eval_views(
                problem,
                &clouds,
                runs,
                seed,
                noise,
                &config,
                &bar,
                run.quiet,
                &mut view_rows,
            )?;
            report.push(serde_json::json!({ "name": problem.name, "runs": runs_json }));
            continue;
        }
        let truth = problem.ground_truth()?;
        let mut run_json = Vec::new();
        let mut all = Vec::new();
        for r in 0..runs {
            let s = seed.wrapping_add(r as u64);
            bar.set_message(format!(
                "{} run {}/{} (seed {s})",
                problem.name,
                r + 1,
                runs
            ));
            let clouds = with_noise(&clouds, noise, s)?;
            let (result, scores) = if ground_truth_frame {
                mtpcr_core::eval::run_in_ground_truth_frame(&clouds, &problem.poses, &config, s)?
            } else {
                run_moved(&clouds, &truth, &config, s)?
            };
            bar.inc(1);
            if !run.quiet {
                bar.suspend(|| {
                    let rot: Vec<String> =
                        scores.rot_deg.iter().map(|d| format!("{d:.2}")).collect();
                    eprintln!(
                        "{} run {}/{} seed {}: {} rot {} deg, Err_R x1000 {:.2}, {:.2} s",
                        problem.name,
                        r + 1,
                        runs,
                        s,
                        if scores.success { "ok  " } else { "FAIL" },
                        rot.join(" "),
                        scores.err_r * 1000.0,
                        result.seconds
                    )
                });
            }
            run_json.push(serde_json::json!({
                "seed": s, "success": scores.success, "err_r": scores.err_r, "err_t": scores.err_t,
                "rot_deg": scores.rot_deg, "seconds": result.seconds,
                "transforms": result.transforms().iter().map(mtpcr_core::io::matrix_rows).collect::<Vec<_>>(),
                "verdict": result.verdict,
            }));
            all.push((scores, result.seconds));
        }
        rows.push((problem.name.clone(), all));
        report.push(serde_json::json!({ "name": problem.name, "runs": run_json }));
    }
    bar.finish_and_clear();
    if !view_rows.is_empty() {
        print_view_rows(&view_rows);
    }
    if rows.is_empty() {
        return write_eval_json(json, &config, seed, runs, report);
    }
    outln!(
        "{:<12} {:>5} {:>9} {:>18} {:>18} {:>10} {:>8}",
        "problem",
        "runs",
        "successes",
        "Err_R x1000",
        "Err_T x1000",
        "rot deg",
        "seconds"
    );
    for (name, all) in &rows {
        let er: Vec<f64> = all.iter().map(|(s, _)| s.err_r * 1000.0).collect();
        let et: Vec<f64> = all.iter().map(|(s, _)| s.err_t * 1000.0).collect();
        let deg: Vec<f64> = all
            .iter()
            .map(|(s, _)| s.rot_deg.iter().sum::<f64>() / s.rot_deg.len() as f64)
            .collect();
        let secs: Vec<f64> = all.iter().map(|(_, t)| *t).collect();
        let ok = all.iter().filter(|(s, _)| s.success).count();
        let (mr, sr) = mean_std(&er);
        let (mt, st) = mean_std(&et);
        outln!(
            "{:<12} {:>5} {:>9} {:>18} {:>18} {:>10.3} {:>8.2}",
            name,
            all.len(),
            ok,
            format!("{mr:.2} +- {sr:.2}"),
            format!("{mt:.2} +- {st:.2}"),
            mean_std(&deg).0,
            mean_std(&secs).0
        );
    }
    write_eval_json(json, &config, seed, runs, report)
}

fn write_eval_json(
    json: Option<&Path>,
    config: &Config,
    seed: u64,
    runs: usize,
    report: Vec<serde_json::Value>,
) -> CliResult<()> {
    if let Some(out) = json {
        let doc = serde_json::json!({
            "settings": config, "first_seed": seed, "runs": runs, "problems": report,
        });
        let text = serde_json::to_string_pretty(&doc)
            .map_err(|e| Failure(format!("cannot serialise the report: {e}")))?;
        std::fs::write(out, text).map_err(|e| Failure(format!("{}: {e}", out.display())))?;
        outln!("wrote {}", out.display());
    }
    Ok(())
}

/// One problem's row of the multi-view table: name, scans, and per run (success, placed
/// scans, worst and mean rotation error in degrees, seconds).
type ViewRow = (String, usize, Vec<ViewRun>);

/// One run of a problem of four or more scans, as the tables show it.
struct ViewRun {
    seed: u64,
    success: bool,
    confident: bool,
    placed: usize,
    worst: f64,
    mean: f64,
    seconds: f64,
    /// Placed scans off by the problem's pair bounds (15 degrees / 0.3 m for 3DMatch rooms).
    wrong: usize,
    /// Placed scans within 3, 5, 10 degrees; within 0.05, 0.1, 0.25 units.
    within_degrees: [usize; 3],
    within_translation: [usize; 3],
    pairs: Vec<mtpcr_core::eval::PairSetScore>,
    /// Wrong and near scans from the best anchor (see `mtpcr_core::eval::best_anchor`).
    best_anchor: Option<mtpcr_core::eval::AnchorScore>,
}

const WITHIN_DEGREES: [f64; 3] = [3.0, 5.0, 10.0];
const WITHIN_TRANSLATION: [f64; 3] = [0.05, 0.1, 0.25];

/// The runs of a problem of four or more scans in no known order: every scan's pose in the
/// first scan's frame against the truth (success: all placed and under 1 degree).
#[allow(clippy::too_many_arguments)]
fn eval_views(
    problem: &Problem,
    clouds: &[PointCloud],
    runs: usize,
    seed: u64,
    noise: Option<f64>,
    config: &Config,
    bar: &indicatif::ProgressBar,
    quiet: bool,
    rows: &mut Vec<ViewRow>,
) -> CliResult<Vec<serde_json::Value>> {
    let mut run_json = Vec::new();
    let mut all = Vec::new();
    for r in 0..runs {
        let s = seed.wrapping_add(r as u64);
        bar.set_message(format!(
            "{} run {}/{} (seed {s})",
            problem.name,
            r + 1,
            runs
        ));
        let clouds = with_noise(clouds, noise, s)?;
        let mtpcr_core::eval::ViewsRun {
            result,
            poses_as_given,
            scores,
            pairs,
            best_anchor,
        } = mtpcr_core::eval::run_moved_views(
            &clouds,
            &problem.poses,
            &problem.pair_sets,
            problem.pair_success,
            config,
            s,
        )?;
        bar.inc(1);
        let placed: Vec<f64> = scores.rot_deg.iter().flatten().copied().collect();
        let worst = placed.iter().copied().fold(0.0, f64::max);
        let mean = placed.iter().sum::<f64>() / placed.len().max(1) as f64;
        let bounds = problem.pair_success;
        let run = ViewRun {
            seed: s,
            success: scores.success,
            confident: result.verdict.confident,
            placed: placed.len(),
            worst,
            mean,
            seconds: result.seconds,
            wrong: scores.wrong(bounds.degrees, bounds.translation),
            within_degrees: WITHIN_DEGREES.map(|d| scores.within_degrees(d)),
            within_translation: WITHIN_TRANSLATION.map(|d| scores.within_translation(d)),
            pairs,
            best_anchor,
        };
        if !quiet {
            bar.suspend(|| {
                eprintln!(
                    "{} run {}/{} seed {s}: {} {} of {} scans placed ({} wrong), rotation error worst {worst:.2} mean {mean:.2} deg, {:.2} s",
                    problem.name,
                    r + 1,
                    runs,
                    if scores.success { "ok  " } else { "FAIL" },
                    placed.len(),
                    clouds.len(),
                    run.wrong,
                    result.seconds
                )
            });
        }
        run_json.push(serde_json::json!({
            "seed": s, "success": scores.success, "rot_deg": scores.rot_deg,
            "trans_rel": scores.trans, "translation": scores.translation,
            "wrong": run.wrong, "pair_sets": run.pairs, "seconds": result.seconds,
            "best_anchor": run.best_anchor,
            "unplaced": result.unplaced.iter().map(|u| u.view).collect::<Vec<_>>(),
            "unplaced_reasons": result.unplaced.iter().map(|u| u.reason.clone()).collect::<Vec<_>>(),
            "verdict": result.verdict,
            "poses": result.poses.iter().map(|p| p.as_ref().map(mtpcr_core::io::matrix_rows)).collect::<Vec<_>>(),
            "poses_as_given": poses_as_given.iter().map(|p| p.as_ref().map(mtpcr_core::io::matrix_rows)).collect::<Vec<_>>(),
        }));
        all.push(run);
    }
    rows.push((problem.name.clone(), clouds.len(), all));
    Ok(run_json)
}

fn print_view_rows(rows: &[ViewRow]) {
    outln!(
        "{:<14} {:>5} {:>5} {:>9} {:>12} {:>16} {:>15} {:>8}",
        "problem",
        "scans",
        "runs",
        "successes",
        "mean placed",
        "worst rot deg",
        "mean rot deg",
        "seconds"
    );
    for (name, scans, all) in rows {
        let ok = all.iter().filter(|r| r.success).count();
        let placed: Vec<f64> = all.iter().map(|r| r.placed as f64).collect();
        let worst: Vec<f64> = all.iter().map(|r| r.worst).collect();
        let mean: Vec<f64> = all.iter().map(|r| r.mean).collect();
        let secs: Vec<f64> = all.iter().map(|r| r.seconds).collect();
        outln!(
            "{:<14} {:>5} {:>5} {:>9} {:>12.1} {:>16} {:>15.3} {:>8.2}",
            name,
            scans,
            all.len(),
            ok,
            mean_std(&placed).0,
            format!(
                "{:.2} (max {:.2})",
                mean_std(&worst).0,
                worst.iter().copied().fold(0.0, f64::max)
            ),
            mean_std(&mean).0,
            mean_std(&secs).0
        );
    }
    // Scenes: each run's placement and the pairs its poses recover.
    let rooms: Vec<_> = rows
        .iter()
        .filter(|(_, _, all)| all.iter().any(|r| !r.pairs.is_empty()))
        .collect();
    if rooms.is_empty() {
        return;
    }
    outln!(
        "\n{:<14} {:>5} {:>7} {:>6} {:>13} {:>17} {:>9} {:>22}  pairs recovered",
        "problem",
        "seed",
        "placed",
        "wrong",
        "<3/5/10 deg",
        "<0.05/0.1/0.25",
        "confident",
        "best anchor wrong/near"
    );
    for (name, scans, all) in rooms {
        for r in all {
            let pairs: Vec<String> = r
                .pairs
                .iter()
                .map(|p| format!("{} {}/{}", p.name, p.recovered, p.total))
                .collect();
            let [d3, d5, d10] = r.within_degrees;
            let [t5, t10, t25] = r.within_translation;
            // From the best anchor (numbered from 1, as the fragments).
            let anchored = r.best_anchor.map_or("-".to_string(), |a| {
                format!("{}/{} (scan {})", a.wrong, a.near, a.scan + 1)
            });
            outln!(
                "{:<14} {:>5} {:>7} {:>6} {:>13} {:>17} {:>9} {:>22}  {}",
                name,
                r.seed,
                format!("{}/{scans}", r.placed),
                r.wrong,
                format!("{d3}/{d5}/{d10}"),
                format!("{t5}/{t10}/{t25}"),
                r.confident,
                anchored,
                pairs.join(", ")
            );
        }
    }
}

fn dump_config(paper: bool) -> CliResult<()> {
    let (config, title) = if paper {
        (
            Config::paper(),
            "mtpcr settings: Config::paper() (the authors' reference)",
        )
    } else {
        (Config::default(), "mtpcr settings: Config::default()")
    };
    let text = settings::config_toml(&config, &settings::field_help(), title)?;
    outln!("{}", text.trim_end());
    Ok(())
}

fn main() -> ExitCode {
    // The settings flags' help comes from the core's field documentation.
    let matches = settings::document(Cli::command()).get_matches();
    let cli = Cli::from_arg_matches(&matches).unwrap_or_else(|e| e.exit());
    let outcome = match &cli.command {
        Command::Demo { seed, points, run } => demo(*seed, *points, run).map(|ok| {
            if ok {
                ExitCode::SUCCESS
            } else {
                ExitCode::FAILURE
            }
        }),
        Command::Register {
            clouds,
            output,
            force,
            seed,
            viewpoint,
            run,
        } => register_files(clouds, output.as_deref(), *force, *seed, *viewpoint, run).map(
            |confident| {
                if confident {
                    ExitCode::SUCCESS
                } else {
                    ExitCode::from(NOT_CONFIDENT)
                }
            },
        ),
        Command::Eval {
            problems,
            runs,
            seed,
            data_root,
            json,
            ground_truth_frame,
            noise,
            pairs: pair_args,
            run,
        } => if problems.iter().any(|p| p.is_dir()) {
            pairs::eval_pairs(
                problems,
                *runs,
                *seed,
                data_root.as_deref(),
                json.as_deref(),
                (*ground_truth_frame, *noise),
                pair_args,
                run,
            )
        } else {
            eval(
                problems,
                runs.unwrap_or(10),
                *seed,
                data_root.as_deref(),
                json.as_deref(),
                RunStart {
                    ground_truth_frame: *ground_truth_frame,
                    noise: *noise,
                },
                run,
            )
        }
        .map(|_| ExitCode::SUCCESS),
        Command::Experiment(args) => experiment::run(args).map(|_| ExitCode::SUCCESS),
        Command::DumpConfig { paper } => dump_config(*paper).map(|_| ExitCode::SUCCESS),
    };
    match outcome {
        Ok(code) => code,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}
