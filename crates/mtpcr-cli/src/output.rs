//! The results folder of `mtpcr register`: choosing and guarding it, and writing its files.

use crate::error::{CliResult, Failure};
use crate::interrupt;
use crate::plots;
use mtpcr_core::io::{matrix_rows, matrix_text, pose_graph_json, trajectory_log, write_ply};
use mtpcr_core::{Config, PointCloud, Registration};
use std::path::{Path, PathBuf};

/// The files a run writes, in the order they are written.
pub const OUTPUT_FILES: [&str; 9] = [
    "result.json",
    "config.toml",
    "transforms.txt",
    "poses.log",
    "pose_graph.json",
    "merged.ply",
    "convergence.png",
    "views.png",
    "view.html",
];

/// The direction convention, in one sentence.
pub const CONVENTION: &str =
    "T_ij maps points of cloud i into the frame of cloud j (x_j = T_ij x_i); row-major 4x4";

/// A results folder ready to be written. From its creation on, Ctrl-C cleans it up (see
/// [`crate::interrupt`]).
#[derive(Debug)]
pub struct OutputDir {
    /// The folder.
    pub path: PathBuf,
    /// The folders this run created: the results folder first, then its new parents (so they
    /// are removed again if the run fails or is interrupted before writing).
    created: Vec<PathBuf>,
}

impl OutputDir {
    /// Removes the folder (and the parents this run created) if this run created it and
    /// nothing was written into it.
    pub fn discard_if_unused(&self) {
        interrupt::discard(&self.path, &self.created);
    }
}

/// UTC time as `YYYYMMDD-HHMMSS`.
pub fn timestamp() -> String {
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
    format!(
        "{y:04}{m:02}{d:02}-{:02}{:02}{:02}",
        rem / 3600,
        rem % 3600 / 60,
        rem % 60
    )
}

fn is_empty_dir(dir: &Path) -> CliResult<bool> {
    Ok(std::fs::read_dir(dir)
        .map_err(|e| {
            Failure(format!(
                "{}: cannot read the output folder: {e}",
                dir.display()
            ))
        })?
        .next()
        .is_none())
}

/// Chooses and creates the output folder. Given: it must be new or empty unless `force`.
/// Not given: `results/<timestamp>`, with a `-2`, `-3`, ... suffix if that is taken. An
/// output file may never replace an input, and the folder must be writable.
pub fn prepare_output(dir: Option<&Path>, inputs: &[PathBuf], force: bool) -> CliResult<OutputDir> {
    let path = match dir {
        Some(d) => {
            if d.exists() {
                if !d.is_dir() {
                    return Err(Failure(format!(
                        "{}: the output path exists and is not a folder",
                        d.display()
                    )));
                }
                if !force && !is_empty_dir(d)? {
                    return Err(Failure(format!(
                        "{}: the output folder is not empty (use --force to write into it; files of the same name are replaced)",
                        d.display()
                    )));
                }
            }
            d.to_path_buf()
        }
        None => {
            let base = PathBuf::from("results").join(timestamp());
            let mut candidate = base.clone();
            let mut k = 2;
            while candidate.exists() && !(candidate.is_dir() && is_empty_dir(&candidate)?) {
                candidate = PathBuf::from(format!("{}-{k}", base.display()));
                k += 1;
            }
            candidate
        }
    };
    // The folders this run creates, the results folder first; guarded before they exist, so
    // Ctrl-C at any moment from here on leaves no empty folder behind.
    let created: Vec<PathBuf> = path
        .ancestors()
        .take_while(|a| !a.as_os_str().is_empty() && !a.exists())
        .map(Path::to_path_buf)
        .collect();
    interrupt::guard(&path, created.clone());
    let out = OutputDir { path, created };
    if let Err(e) = std::fs::create_dir_all(&out.path) {
        out.discard_if_unused();
        return Err(Failure(format!(
            "{}: cannot create the output folder: {e}",
            out.path.display()
        )));
    }
    if let Err(e) = check_output(&out.path, inputs) {
        out.discard_if_unused();
        return Err(e);
    }
    Ok(out)
}

/// What makes two names the same file: device and inode on unix (so a hard link or a
/// symbolic link matches its target), the canonical path elsewhere.
#[cfg(unix)]
fn file_identity(path: &Path) -> Option<(u64, u64)> {
    use std::os::unix::fs::MetadataExt;
    let meta = std::fs::metadata(path).ok()?;
    Some((meta.dev(), meta.ino()))
}

/// What makes two names the same file: the canonical path (hard links are not detected).
#[cfg(not(unix))]
fn file_identity(path: &Path) -> Option<PathBuf> {
    std::fs::canonicalize(path).ok()
}

fn check_output(dir: &Path, inputs: &[PathBuf]) -> CliResult<()> {
    let canonical = std::fs::canonicalize(dir).map_err(|e| {
        Failure(format!(
            "{}: cannot open the output folder: {e}",
            dir.display()
        ))
    })?;
    for input in inputs {
        let Ok(p) = std::fs::canonicalize(input) else {
            continue;
        };
        if p.parent() == Some(canonical.as_path())
            && p.file_name()
                .is_some_and(|n| OUTPUT_FILES.iter().any(|o| n == *o))
        {
            return Err(Failure(format!(
                "{}: this input would be overwritten by the output; choose another --output folder",
                input.display()
            )));
        }
    }
    // An output name already in the folder may be another name of an input: a hard link, or
    // a symbolic link to it. (Files are replaced by renaming, which would leave the input
    // intact, but the user surely did not mean to write results over an input.)
    for name in OUTPUT_FILES {
        let existing = dir.join(name);
        let Some(id) = file_identity(&existing) else {
            continue;
        };
        if let Some(input) = inputs
            .iter()
            .find(|i| file_identity(i).as_ref() == Some(&id))
        {
            return Err(Failure(format!(
                "{}: this output file is the input {} under another name (a hard or symbolic \
                 link); choose another --output folder or remove the link",
                existing.display(),
                input.display()
            )));
        }
    }
    // Fail now, not after a long run, if the folder cannot be written.
    let probe = interrupt::temporary_name(&dir.join("write-check"));
    std::fs::write(&probe, b"").map_err(|e| {
        Failure(format!(
            "{}: cannot write into the output folder: {e}",
            dir.display()
        ))
    })?;
    let _ = std::fs::remove_file(&probe);
    Ok(())
}

/// What a run used and produced, for the files.
pub struct RunRecord<'a> {
    /// The input files, in the order given.
    pub inputs: &'a [PathBuf],
    /// One label per cloud (its file, and the scan's name when a file holds several).
    pub labels: &'a [String],
    /// The clouds as read, with the viewpoints `--viewpoint` gave them.
    pub clouds: &'a [PointCloud],
    /// The settings of the run (its seed is filled in from the result).
    pub config: &'a Config,
    /// The registration.
    pub result: &'a Registration,
    /// `dump-config`-style help for `config.toml`.
    pub field_help: &'a std::collections::BTreeMap<String, String>,
}

/// Writes `path` completely or not at all: `write` fills a temporary file in the same folder
/// ([`interrupt::temporary_name`]), which is then renamed to `path` (replacing a file of that
/// name, or a link, never what a link points to). Ctrl-C waits for the rename; on a failure the
/// temporary file is removed and `path` is left as it was. Errors name `path`.
pub fn write_atomically(path: &Path, write: impl FnOnce(&Path) -> CliResult<()>) -> CliResult<()> {
    let _lock = interrupt::writing();
    let tmp = interrupt::temporary_name(path);
    let outcome = write(&tmp).and_then(|()| {
        std::fs::rename(&tmp, path).map_err(|e| Failure(format!("{}: {e}", path.display())))
    });
    if outcome.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    outcome.map_err(|Failure(message)| {
        Failure(message.replace(&tmp.display().to_string(), &path.display().to_string()))
    })
}

fn write_file(path: &Path, contents: &[u8]) -> CliResult<()> {
    write_atomically(path, |tmp| {
        std::fs::write(tmp, contents).map_err(|e| Failure(format!("{}: {e}", tmp.display())))
    })
}

/// The name of each edge (`T12`: cloud 1 into cloud 2), in edge order.
fn edge_names(r: &Registration) -> Vec<String> {
    (0..r.edges.len()).map(|k| r.edge_name(k)).collect()
}

/// The content of `result.json`. Clouds are numbered from 1, as in the transform names.
pub fn result_json(rec: &RunRecord<'_>) -> serde_json::Value {
    let r = rec.result;
    let names = edge_names(r);
    let edges: Vec<serde_json::Value> = r
        .edges
        .iter()
        .zip(&names)
        .map(|(e, name)| {
            serde_json::json!({
                "name": name,
                "source": e.source + 1,
                "target": e.target + 1,
                "t_target_source": matrix_rows(&e.t_target_source),
                "evolution_costs": { "original": e.original_cost, "aiding": e.aiding_cost },
            })
        })
        .collect();
    let transforms: serde_json::Map<String, serde_json::Value> = r
        .edges
        .iter()
        .zip(&names)
        .map(|(e, name)| {
            (
                name.clone(),
                serde_json::json!(matrix_rows(&e.t_target_source)),
            )
        })
        .collect();
    serde_json::json!({
        "mtpcr_version": env!("CARGO_PKG_VERSION"),
        "inputs": rec.inputs.iter().map(|p| p.display().to_string()).collect::<Vec<_>>(),
        "clouds": rec.labels,
        "points": rec.clouds.iter().map(PointCloud::len).collect::<Vec<_>>(),
        "viewpoints": rec.clouds.iter().map(PointCloud::viewpoint).collect::<Vec<_>>(),
        "convention": CONVENTION,
        "completed": r.completed,
        "confident": r.verdict.confident,
        "verdict": r.verdict,
        "edges": edges,
        "transforms": transforms,
        "poses": r.poses.iter().map(|p| p.as_ref().map(matrix_rows)).collect::<Vec<_>>(),
        "poses_note": format!("poses[k] maps cloud k+1 into the frame of cloud {}; null when the cloud could not be placed", r.reference_view().map_or(1, |v| v + 1)),
        "unplaced": r.unplaced.iter().map(|u| serde_json::json!({"cloud": u.view + 1, "reason": u.reason})).collect::<Vec<_>>(),
        "loop_residual": r.loop_residual(),
        "best_costs": {
            "original": r.edges.iter().map(|e| e.original_cost).collect::<Vec<_>>(),
            "aiding": r.edges.iter().map(|e| e.aiding_cost).collect::<Vec<_>>(),
        },
        "best_costs_note": "the evolution's final best cost of each edge's tasks, before refinement",
        "evaluations": r.evaluations,
        "generations_run": r.generations_run,
        "seconds": r.seconds,
        "seed": r.seed,
        "settings": Config { seed: Some(r.seed), ..rec.config.clone() },
        "task_names": r.task_names,
        "sampled_points": r.sampled_points,
        "restarts_run": r.restarts_run,
        "kept_restart": r.kept_restart + 1,
        "history": r.history,
        "history_note": "best cost of each task per generation of the kept restart (kept_restart, numbered from 1: the lowest final original costs), before refinement; generations_run counts every restart's generations; restart_histories holds each restart's",
        "restart_histories": r.restart_histories,
    })
}

/// The content of `transforms.txt`.
pub fn transforms_text(rec: &RunRecord<'_>) -> String {
    let mut s = format!("# {CONVENTION}.\n");
    for (i, label) in rec.labels.iter().enumerate() {
        s.push_str(&format!("# cloud {}: {label}\n", i + 1));
    }
    for (e, name) in rec.result.edges.iter().zip(edge_names(rec.result)) {
        s.push_str(&format!(
            "\n{name} (maps cloud {} into the frame of cloud {}):\n{}",
            e.source + 1,
            e.target + 1,
            matrix_text(&e.t_target_source)
        ));
    }
    s
}

/// Writes the files of [`OUTPUT_FILES`] into `dir` (all but `convergence.png` when no
/// evolution ran); returns their names.
pub fn write_results(dir: &Path, rec: &RunRecord<'_>) -> CliResult<Vec<String>> {
    let path = |name: &str| dir.join(name);
    let json = serde_json::to_string_pretty(&result_json(rec))
        .map_err(|e| Failure(format!("cannot serialise the result: {e}")))?;
    write_file(&path("result.json"), json.as_bytes())?;

    let seeded = Config {
        seed: Some(rec.result.seed),
        ..rec.config.clone()
    };
    let toml = crate::settings::config_toml(
        &seeded,
        rec.field_help,
        "Settings of this run (mtpcr register ... --config config.toml repeats it)",
    )?;
    write_file(&path("config.toml"), toml.as_bytes())?;

    write_file(&path("transforms.txt"), transforms_text(rec).as_bytes())?;
    // The poses for the next tool: a 3DMatch/Redwood trajectory and an Open3D pose graph.
    write_file(
        &path("poses.log"),
        trajectory_log(&rec.result.poses).as_bytes(),
    )?;
    let graph =
        serde_json::to_string_pretty(&pose_graph_json(&rec.result.poses, &rec.result.edges))
            .map_err(|e| Failure(format!("cannot serialise the pose graph: {e}")))?;
    write_file(&path("pose_graph.json"), graph.as_bytes())?;

    // Unplaced clouds are left out of the merged cloud and the "after" pictures.
    let moved: Vec<Vec<[f64; 3]>> = rec
        .clouds
        .iter()
        .enumerate()
        .map(|(k, c)| rec.result.place(k, c.points()).unwrap_or_default())
        .collect();
    let points = moved.concat();
    let colors: Vec<_> = (0..moved.len())
        .flat_map(|k| std::iter::repeat_n(plots::view_color(k), moved[k].len()))
        .collect();
    write_atomically(&path("merged.ply"), |tmp| {
        Ok(write_ply(tmp, &points, Some(&colors))?)
    })?;

    let run = rec.result.restart_histories.len();
    let title = if run > 1 {
        format!(
            "Best cost per generation of each task: restart {} of the {run} run (lowest final original costs), others grey",
            rec.result.kept_restart + 1
        )
    } else {
        "Best cost per generation of each task".to_string()
    };
    // No convergence to draw without generations (the default, and scans in no known order).
    let with_history = rec.result.history.len() > 1;
    if with_history {
        write_atomically(&path("convergence.png"), |tmp| {
            plots::convergence_png(
                &rec.result.restart_histories,
                rec.result.kept_restart,
                &rec.result.task_names,
                &title,
                tmp,
            )
        })?;
    }

    let labels: Vec<String> = rec
        .labels
        .iter()
        .enumerate()
        .map(|(i, label)| {
            // The file name without its folder (and the scan's name, if any).
            let short = std::path::Path::new(label)
                .file_name()
                .map_or_else(|| label.clone(), |n| n.to_string_lossy().into_owned());
            format!("cloud {}: {short}", i + 1)
        })
        .collect();
    let before: Vec<&[[f64; 3]]> = rec.clouds.iter().map(PointCloud::points).collect();
    let after: Vec<&[[f64; 3]]> = moved.iter().map(Vec::as_slice).collect();
    write_atomically(&path("views.png"), |tmp| {
        let reference = rec.result.reference_view().unwrap_or(0);
        plots::views_png(&before, &after, reference, &labels, tmp)
    })?;
    // The 3-D view shows the placed scans only (an unplaced one has no "after").
    let placed: Vec<usize> = (0..rec.clouds.len())
        .filter(|&k| rec.result.poses.get(k).is_some_and(Option::is_some))
        .collect();
    let title = match rec.clouds.len() - placed.len() {
        0 => "mtpcr: registered scans".to_string(),
        missing => format!("mtpcr: registered scans ({missing} not placed, not shown)"),
    };
    let html = crate::viewer::viewer_html(
        &placed.iter().map(|&k| before[k]).collect::<Vec<_>>(),
        &placed.iter().map(|&k| after[k]).collect::<Vec<_>>(),
        &placed
            .iter()
            .map(|&k| labels[k].clone())
            .collect::<Vec<_>>(),
        "",
        &title,
    );
    write_file(&path("view.html"), html.as_bytes())?;
    Ok(OUTPUT_FILES
        .iter()
        .filter(|n| with_history || **n != "convergence.png")
        .map(|n| n.to_string())
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn atomic_writes_leave_the_old_file_or_the_new_one() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("result.json");
        std::fs::write(&path, "old").unwrap();
        // A writer that fails halfway: the old file stays, no temporary file remains, the
        // error names the file asked for.
        let e = write_atomically(&path, |tmp| {
            std::fs::write(tmp, "half").unwrap();
            Err(Failure(format!("{}: disk full", tmp.display())))
        })
        .unwrap_err();
        assert_eq!(e.0, format!("{}: disk full", path.display()));
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "old");
        let names = |d: &Path| -> Vec<String> {
            std::fs::read_dir(d)
                .unwrap()
                .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
                .collect()
        };
        assert_eq!(names(dir.path()), ["result.json"]);
        // While the writer runs, the file still holds the old content.
        write_atomically(&path, |tmp| {
            std::fs::write(tmp, "new").unwrap();
            assert_eq!(std::fs::read_to_string(&path).unwrap(), "old");
            Ok(())
        })
        .unwrap();
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "new");
        assert_eq!(names(dir.path()), ["result.json"]);
    }

    #[test]
    fn timestamps_look_like_dates() {
        let t = timestamp();
        assert_eq!(t.len(), 15, "{t}");
        assert!(t.starts_with("20") && t.as_bytes()[8] == b'-', "{t}");
    }
}
