//! `mtpcr`: the command-line front-end. It parses, shows progress on stderr, writes results;
//! all registration logic lives in `mtpcr-core`.

use clap::{Args, Parser, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};
use mtpcr_core::eval::{mean_std, run_moved, score, Scores};
use mtpcr_core::io::{matrix_rows, read_ply, Problem};
use mtpcr_core::{synthetic, Config, Progress, Registration, Sampling, SearchMethod};
use std::ops::ControlFlow;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

#[derive(Parser)]
#[command(name = "mtpcr", version, about = "Register three overlapping point clouds with no initial guess (MTPCR)")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Generate a shape, cut three overlapping views, move them randomly, register them.
    Demo {
        /// Seed of the shape, the motions and the run.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Points per generated view.
        #[arg(long, default_value_t = 20000)]
        points: usize,
        #[command(flatten)]
        settings: SettingsArgs,
    },
    /// Register three PLY files; writes result.json into the output folder.
    Register {
        /// The three clouds, in loop order (T12, T23, T31).
        #[arg(num_args = 3, required = true)]
        clouds: Vec<PathBuf>,
        /// Output folder (default: results/<timestamp>); must be new or empty unless --force.
        #[arg(long)]
        output: Option<PathBuf>,
        /// Write into a non-empty output folder (files of the same name are replaced).
        #[arg(long)]
        force: bool,
        /// Seed of the run (default: drawn and reported).
        #[arg(long)]
        seed: Option<u64>,
        #[command(flatten)]
        settings: SettingsArgs,
    },
    /// Evaluate on problem files (shared/problems format) against their ground truth.
    Eval {
        /// Problem files.
        #[arg(required = true)]
        problems: Vec<PathBuf>,
        /// Runs per problem.
        #[arg(long, default_value_t = 10)]
        runs: usize,
        /// Seed of the first run; run r uses seed + r.
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// Folder the scan paths are relative to (default: the parent of each problem's folder).
        #[arg(long)]
        data_root: Option<PathBuf>,
        /// Write every run's numbers to this JSON file.
        #[arg(long)]
        json: Option<PathBuf>,
        #[command(flatten)]
        settings: SettingsArgs,
    },
}

/// Settings flags, named like the config fields.
#[derive(Args, Clone, Debug)]
struct SettingsArgs {
    /// Start from Config::paper() (the authors' reference) instead of Config::default().
    #[arg(long)]
    paper: bool,
    /// Worker threads; 0 = all cores (the result does not depend on it).
    #[arg(long, alias = "num-threads", default_value_t = 0)]
    threads: usize,
    /// Individuals per population.
    #[arg(long)]
    population_size: Option<usize>,
    /// Generations.
    #[arg(long)]
    generations: Option<usize>,
    /// Fraction of points kept by downsampling, in (0, 1].
    #[arg(long)]
    sample_ratio: Option<f64>,
    /// Downsampling: farthest or random.
    #[arg(long, value_parser = parse_sampling)]
    sampling: Option<Sampling>,
    /// Intra-task sharing probability.
    #[arg(long)]
    p_intra: Option<f64>,
    /// Inter-task sharing probability.
    #[arg(long)]
    p_inter: Option<f64>,
    /// Fraction of elites.
    #[arg(long)]
    top_ratio: Option<f64>,
    /// DE scale factor F.
    #[arg(long)]
    scale_factor: Option<f64>,
    /// SBX index at the first generation.
    #[arg(long)]
    sbx_eta_start: Option<f64>,
    /// SBX index at the last generation.
    #[arg(long)]
    sbx_eta_end: Option<f64>,
    /// Weight of the loop term.
    #[arg(long)]
    alpha: Option<f64>,
    /// Aiding-loss distance cap as a fraction of shift.
    #[arg(long)]
    aiding_cap_ratio: Option<f64>,
    /// Aiding loss in both directions.
    #[arg(long)]
    two_way_aiding: Option<bool>,
    /// Loop term without units (translations divided by shift).
    #[arg(long)]
    unit_free_loop_term: Option<bool>,
    /// Recompute parents' loop terms every generation.
    #[arg(long)]
    refresh_loop_term: Option<bool>,
    /// Independent evolutions; the best (lowest original costs) is kept.
    #[arg(long)]
    restarts: Option<usize>,
    /// Trimmed-ICP iterations refining each pair after the evolution (0 = off).
    #[arg(long)]
    refine_iterations: Option<usize>,
    /// Search structure: fast or exact.
    #[arg(long, value_parser = parse_search)]
    search: Option<SearchMethod>,
    /// No progress bar.
    #[arg(long, short)]
    quiet: bool,
}

fn parse_sampling(s: &str) -> Result<Sampling, String> {
    match s {
        "farthest" => Ok(Sampling::Farthest),
        "random" => Ok(Sampling::Random),
        _ => Err(format!("expected `farthest` or `random`, got `{s}`")),
    }
}

fn parse_search(s: &str) -> Result<SearchMethod, String> {
    match s {
        "fast" => Ok(SearchMethod::Fast),
        "exact" => Ok(SearchMethod::Exact),
        _ => Err(format!("expected `fast` or `exact`, got `{s}`")),
    }
}

impl SettingsArgs {
    fn config(&self, seed: Option<u64>) -> Config {
        let mut c = if self.paper { Config::paper() } else { Config::default() };
        macro_rules! set {
            ($($f:ident),*) => { $( if let Some(v) = self.$f { c.$f = v; } )* };
        }
        set!(
            population_size, generations, sample_ratio, sampling, p_intra, p_inter, top_ratio,
            scale_factor, sbx_eta_start, sbx_eta_end, alpha, aiding_cap_ratio, two_way_aiding,
            unit_free_loop_term, refresh_loop_term, search, restarts, refine_iterations
        );
        c.num_threads = self.threads;
        c.seed = seed;
        c
    }
}

/// A progress bar over the generations of one run, on stderr.
fn generation_bar(generations: usize, quiet: bool, label: &str) -> ProgressBar {
    if quiet {
        return ProgressBar::hidden();
    }
    let bar = ProgressBar::new(generations as u64);
    bar.set_style(
        ProgressStyle::with_template("{prefix} [{bar:30}] gen {pos}/{len} {msg} ETA {eta}")
            .expect("valid template")
            .progress_chars("=> "),
    );
    bar.set_prefix(label.to_string());
    bar
}

fn observe(bar: &ProgressBar) -> impl FnMut(&Progress) -> ControlFlow<()> + '_ {
    move |p: &Progress| {
        bar.set_position(p.generation as u64);
        bar.set_message(format!(
            "best original {:.4} {:.4} {:.4}",
            p.best_costs[3], p.best_costs[4], p.best_costs[5]
        ));
        ControlFlow::Continue(())
    }
}

fn run_with_bar(
    clouds: &[mtpcr_core::PointCloud; 3],
    config: &Config,
    quiet: bool,
    label: &str,
) -> mtpcr_core::Result<Registration> {
    let bar = generation_bar(config.generations, quiet, label);
    let mut obs = observe(&bar);
    let r = mtpcr_core::register(clouds, config, Some(&mut obs));
    bar.finish_and_clear();
    r
}

fn print_pairs(scores: &Scores, truth_available: bool) {
    let names = ["T12", "T23", "T31"];
    if truth_available {
        for (i, n) in names.iter().enumerate() {
            println!("  {n}: rotation error {:.3} deg", scores.rot_deg[i]);
        }
    }
}

fn demo(seed: u64, points: usize, settings: &SettingsArgs) -> Result<bool, String> {
    let problem = synthetic::three_views(seed, points);
    let config = settings.config(Some(seed));
    println!(
        "demo: three synthetic views of {points} points each, moved by random rigid motions (seed {seed})"
    );
    let result = run_with_bar(&problem.clouds, &config, settings.quiet, "demo").map_err(|e| e.to_string())?;
    let s = score(&result.transforms, &problem.ground_truth);
    let names = ["T12", "T23", "T31"];
    for i in 0..3 {
        let t = mtpcr_core::se3::translation_error(&result.transforms[i], &problem.ground_truth[i]);
        println!(
            "  {}: rotation error {:.3} deg, translation error {:.2e} (shape size 0.15)",
            names[i], s.rot_deg[i], t
        );
    }
    println!(
        "  loop residual {:.2e}, {} evaluations, {:.2} s",
        result.loop_residual(),
        result.evaluations,
        result.seconds
    );
    let ok = s.rot_deg.iter().all(|&d| d < 2.0);
    println!("{}", if ok { "demo passed: every pair under 2 degrees" } else { "demo FAILED: some pair is 2 degrees or more off" });
    Ok(ok)
}

fn timestamp() -> String {
    let secs = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_secs())
        .unwrap_or(0);
    let days = (secs / 86400) as i64;
    let rem = secs % 86400;
    // Civil date from days since 1970-01-01 (Howard Hinnant's algorithm).
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + i64::from(m <= 2);
    format!("{y:04}{m:02}{d:02}-{:02}{:02}{:02}", rem / 3600, rem % 3600 / 60, rem % 60)
}

/// Creates (or accepts) the output folder: new, or empty, or `force`.
fn prepare_output(dir: &Path, inputs: &[PathBuf], force: bool) -> Result<(), String> {
    if dir.exists() {
        if !dir.is_dir() {
            return Err(format!("{}: exists and is not a folder", dir.display()));
        }
        let non_empty = std::fs::read_dir(dir)
            .map_err(|e| format!("{}: {e}", dir.display()))?
            .next()
            .is_some();
        if non_empty && !force {
            return Err(format!(
                "{}: the output folder is not empty (use --force to write into it)",
                dir.display()
            ));
        }
    }
    std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let out = std::fs::canonicalize(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    for input in inputs {
        if let Ok(p) = std::fs::canonicalize(input) {
            if p.parent() == Some(out.as_path()) && p.file_name().is_some_and(|n| n == "result.json") {
                return Err(format!("{}: an input would be overwritten", input.display()));
            }
        }
    }
    Ok(())
}

fn register_files(
    clouds: &[PathBuf],
    output: Option<PathBuf>,
    force: bool,
    seed: Option<u64>,
    settings: &SettingsArgs,
) -> Result<(), String> {
    let config = settings.config(seed);
    config.validate().map_err(|e| e.to_string())?;
    let loaded: Vec<mtpcr_core::PointCloud> = clouds
        .iter()
        .map(|p| {
            let c = read_ply(p).map_err(|e| e.to_string())?;
            c.validate(&p.display().to_string(), mtpcr_core::registration::MIN_POINTS)
                .map_err(|e| e.to_string())?;
            Ok(c)
        })
        .collect::<Result<_, String>>()?;
    let loaded: [mtpcr_core::PointCloud; 3] = loaded.try_into().map_err(|_| "three clouds are needed".to_string())?;
    let dir = output.unwrap_or_else(|| PathBuf::from("results").join(timestamp()));
    prepare_output(&dir, clouds, force)?;
    let result = run_with_bar(&loaded, &config, settings.quiet, "register").map_err(|e| e.to_string())?;
    let [t12, t23, t31] = result.transforms;
    let json = serde_json::json!({
        "inputs": clouds.iter().map(|p| p.display().to_string()).collect::<Vec<_>>(),
        "convention": "T_ij maps points of cloud i into the frame of cloud j (x_j = T_ij x_i); row-major 4x4",
        "transforms": { "T12": matrix_rows(&t12), "T23": matrix_rows(&t23), "T31": matrix_rows(&t31) },
        "loop_residual": result.loop_residual(),
        "best_costs": { "original": result.best_costs.original, "aiding": result.best_costs.aiding },
        "evaluations": result.evaluations,
        "seconds": result.seconds,
        "seed": result.seed,
        "settings": Config { seed: Some(result.seed), ..config.clone() },
    });
    let path = dir.join("result.json");
    std::fs::write(&path, serde_json::to_string_pretty(&json).expect("serialisable"))
        .map_err(|e| format!("{}: {e}", path.display()))?;
    for (name, t) in [("T12", t12), ("T23", t23), ("T31", t31)] {
        println!("{name} =\n{}", mtpcr_core::io::matrix_text(&t));
    }
    println!(
        "loop residual {:.3e}, best original costs {:.4} {:.4} {:.4}, {} evaluations, {:.2} s, seed {}",
        result.loop_residual(),
        result.best_costs.original[0],
        result.best_costs.original[1],
        result.best_costs.original[2],
        result.evaluations,
        result.seconds,
        result.seed
    );
    println!("wrote {}", path.display());
    Ok(())
}

fn eval(
    problems: &[PathBuf],
    runs: usize,
    seed: u64,
    data_root: Option<&Path>,
    json: Option<&Path>,
    settings: &SettingsArgs,
) -> Result<(), String> {
    let config = settings.config(None);
    config.validate().map_err(|e| e.to_string())?;
    if runs == 0 {
        return Err("--runs must be at least 1".to_string());
    }
    let mut report = Vec::new();
    let mut rows = Vec::new();
    for path in problems {
        let problem = Problem::load(path, data_root).map_err(|e| e.to_string())?;
        let clouds = problem.read_scans().map_err(|e| e.to_string())?;
        let truth = problem.ground_truth();
        let mut run_json = Vec::new();
        let mut all = Vec::new();
        for r in 0..runs {
            let s = seed + r as u64;
            let bar = generation_bar(config.generations, settings.quiet, &format!("{} run {}/{}", problem.name, r + 1, runs));
            let _ = &bar;
            let (result, scores) = run_moved(&clouds, &truth, &config, s).map_err(|e| e.to_string())?;
            bar.finish_and_clear();
            if !settings.quiet {
                eprintln!(
                    "{} run {}/{} seed {}: {} rot {:.2} {:.2} {:.2} deg, Err_R x1000 {:.2}, {:.2} s",
                    problem.name,
                    r + 1,
                    runs,
                    s,
                    if scores.success { "ok  " } else { "FAIL" },
                    scores.rot_deg[0],
                    scores.rot_deg[1],
                    scores.rot_deg[2],
                    scores.err_r * 1000.0,
                    result.seconds
                );
            }
            run_json.push(serde_json::json!({
                "seed": s, "success": scores.success, "err_r": scores.err_r, "err_t": scores.err_t,
                "rot_deg": scores.rot_deg, "seconds": result.seconds,
            }));
            all.push((scores, result.seconds));
        }
        print_pairs(&all[0].0, false);
        rows.push((problem.name.clone(), all));
        report.push(serde_json::json!({ "name": problem.name, "runs": run_json }));
    }
    println!(
        "{:<12} {:>5} {:>9} {:>18} {:>18} {:>10} {:>8}",
        "problem", "runs", "successes", "Err_R x1000", "Err_T x1000", "rot deg", "seconds"
    );
    for (name, all) in &rows {
        let er: Vec<f64> = all.iter().map(|(s, _)| s.err_r * 1000.0).collect();
        let et: Vec<f64> = all.iter().map(|(s, _)| s.err_t * 1000.0).collect();
        let deg: Vec<f64> = all.iter().map(|(s, _)| s.rot_deg.iter().sum::<f64>() / 3.0).collect();
        let secs: Vec<f64> = all.iter().map(|(_, t)| *t).collect();
        let ok = all.iter().filter(|(s, _)| s.success).count();
        let (mr, sr) = mean_std(&er);
        let (mt, st) = mean_std(&et);
        println!(
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
    if let Some(out) = json {
        let doc = serde_json::json!({ "settings": config, "problems": report });
        std::fs::write(out, serde_json::to_string_pretty(&doc).expect("serialisable"))
            .map_err(|e| format!("{}: {e}", out.display()))?;
        println!("wrote {}", out.display());
    }
    Ok(())
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let outcome = match &cli.command {
        Command::Demo { seed, points, settings } => demo(*seed, *points, settings).map(|ok| {
            if ok {
                ExitCode::SUCCESS
            } else {
                ExitCode::FAILURE
            }
        }),
        Command::Register { clouds, output, force, seed, settings } => {
            register_files(clouds, output.clone(), *force, *seed, settings).map(|_| ExitCode::SUCCESS)
        }
        Command::Eval { problems, runs, seed, data_root, json, settings } => eval(
            problems,
            *runs,
            *seed,
            data_root.as_deref(),
            json.as_deref(),
            settings,
        )
        .map(|_| ExitCode::SUCCESS),
    };
    match outcome {
        Ok(code) => code,
        Err(msg) => {
            eprintln!("error: {msg}");
            ExitCode::FAILURE
        }
    }
}
