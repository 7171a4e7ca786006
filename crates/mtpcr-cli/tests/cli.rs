//! Tests of the real `mtpcr` binary: outputs, exit codes and error messages. Runs use small
//! settings; their accuracy is not checked here (the engine's tests do that).

use assert_cmd::Command;
use mtpcr_core::io::{read_ply, write_ply};
use mtpcr_core::{synthetic, Config};
use std::path::{Path, PathBuf};

/// Settings that make a registration take a fraction of a second.
const FAST: [&str; 5] = ["--generations", "3", "--population-size", "8", "-q"];

const PNG_SIGNATURE: &[u8] = b"\x89PNG\r\n\x1a\n";

fn mtpcr() -> Command {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_mtpcr"));
    cmd.env_remove("RUST_BACKTRACE");
    cmd
}

/// Three small overlapping synthetic views written as PLY files into `dir`.
fn write_views(dir: &Path) -> [PathBuf; 3] {
    let problem = synthetic::three_views(5, 3000);
    std::array::from_fn(|i| {
        let path = dir.join(format!("view{}.ply", i + 1));
        write_ply(&path, problem.clouds[i].points(), None).unwrap();
        path
    })
}

/// Exit statuses of a `register` that wrote its results: 0 (confident) or 3 (not
/// confident; tiny test settings often are not).
const REGISTERED: &[i32] = &[0, 3];

fn args_of(paths: &[PathBuf]) -> Vec<String> {
    paths.iter().map(|p| p.display().to_string()).collect()
}

/// Runs `cmd`, expects exit code `code`, an `error: ` line naming every needle, no panic.
fn fails_with(cmd: &mut Command, code: i32, needles: &[&str]) -> String {
    let out = cmd.assert().code(code).get_output().clone();
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(!stderr.contains("panicked"), "{stderr}");
    if code == 1 {
        assert!(stderr.starts_with("error: "), "{stderr}");
    }
    for n in needles {
        assert!(stderr.contains(n), "`{n}` not in: {stderr}");
    }
    stderr
}

fn read_json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

#[test]
fn version_prints_the_package_version() {
    mtpcr()
        .arg("--version")
        .assert()
        .success()
        .stdout(format!("mtpcr {}\n", env!("CARGO_PKG_VERSION")));
}

#[test]
fn dump_config_prints_parseable_defaults() {
    for (flag, expected) in [
        (None, Config::default()),
        (Some("--paper"), Config::paper()),
    ] {
        let mut cmd = mtpcr();
        cmd.arg("dump-config").args(flag);
        let out = cmd.assert().success().get_output().stdout.clone();
        let text = String::from_utf8(out).unwrap();
        assert!(text.contains("# Individuals per population"), "{text}");
        let parsed: Config = toml::from_str(&text).unwrap();
        assert_eq!(parsed, expected);
    }
}

#[test]
fn dump_config_round_trips_through_config() {
    let dir = tempfile::tempdir().unwrap();
    let views = write_views(dir.path());
    let dumped = mtpcr()
        .arg("dump-config")
        .assert()
        .success()
        .get_output()
        .stdout
        .clone();
    let file = dir.path().join("my.toml");
    std::fs::write(&file, dumped).unwrap();
    let out = dir.path().join("out");
    mtpcr()
        .arg("register")
        .args(args_of(&views))
        .args([
            "--config",
            file.to_str().unwrap(),
            "--seed",
            "3",
            "--output",
        ])
        .arg(&out)
        .args(FAST)
        .assert()
        .code(REGISTERED);
    let json = read_json(&out.join("result.json"));
    let used: Config = serde_json::from_value(json["settings"].clone()).unwrap();
    let expected = Config {
        generations: 3,
        population_size: 8,
        seed: Some(3),
        ..Config::default()
    };
    assert_eq!(used, expected);

    // The results folder's config.toml repeats the run exactly.
    let again = dir.path().join("again");
    mtpcr()
        .arg("register")
        .args(args_of(&views))
        .arg("--config")
        .arg(out.join("config.toml"))
        .arg("--output")
        .arg(&again)
        .arg("-q")
        .assert()
        .code(REGISTERED);
    let json2 = read_json(&again.join("result.json"));
    assert_eq!(json2["settings"], json["settings"]);
    assert_eq!(json2["transforms"], json["transforms"]);
}

#[test]
fn demo_prints_its_lines_and_exits_by_the_2_degree_rule() {
    let out = mtpcr()
        .args(["demo", "--seed", "1", "--generations", "15"])
        // Every restart runs, so the evaluations are known.
        .args(["--stop-when-restarts-agree", "false"])
        .output()
        .unwrap();
    let stdout = String::from_utf8(out.stdout).unwrap();
    let lines: Vec<&str> = stdout.lines().collect();
    assert_eq!(lines.len(), 6, "{stdout}");
    assert_eq!(
        lines[0],
        "demo: three synthetic views of 20000 points each, moved by random rigid motions (seed 1)"
    );
    for (line, pair) in lines[1..4].iter().zip(["T12", "T23", "T31"]) {
        assert!(
            line.starts_with(&format!("  {pair}: rotation error ")),
            "{line}"
        );
        assert!(line.ends_with(" (shape size 0.15)"), "{line}");
    }
    assert!(lines[4].starts_with("  loop residual "), "{}", lines[4]);
    assert!(lines[4].contains(&format!(
        "{} evaluations",
        Config {
            generations: 15,
            ..Config::default()
        }
        .evaluations(6)
    )));
    let passed = lines[5] == "demo passed: every pair under 2 degrees";
    let failed = lines[5] == "demo FAILED: some pair is 2 degrees or more off";
    assert!(passed || failed, "{}", lines[5]);
    assert_eq!(out.status.code(), Some(if passed { 0 } else { 1 }));
    assert!(!String::from_utf8_lossy(&out.stderr).contains("panicked"));
}

#[test]
fn demo_reads_the_config_file_and_flags_override_it() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("small.toml");
    std::fs::write(
        &file,
        "generations = 2\npopulation_size = 8\nseed = 4\nstop_when_restarts_agree = false\n",
    )
    .unwrap();
    let run = |extra: &[&str]| {
        let out = mtpcr()
            .args(["demo", "--points", "2000", "-q", "--config"])
            .arg(&file)
            .args(extra)
            .output()
            .unwrap();
        assert!(matches!(out.status.code(), Some(0 | 1)), "{out:?}");
        String::from_utf8(out.stdout).unwrap()
    };
    let evaluations = |g: usize| {
        Config {
            generations: g,
            population_size: 8,
            ..Config::default()
        }
        .evaluations(6)
    };
    let stdout = run(&[]);
    assert!(stdout.contains("(seed 4)"), "{stdout}");
    assert!(
        stdout.contains(&format!(" {} evaluations", evaluations(2))),
        "{stdout}"
    );
    let stdout = run(&["--generations", "3", "--seed", "6"]);
    assert!(stdout.contains("(seed 6)"), "{stdout}");
    assert!(
        stdout.contains(&format!(" {} evaluations", evaluations(3))),
        "{stdout}"
    );
}

#[test]
fn register_writes_every_output_file() {
    let dir = tempfile::tempdir().unwrap();
    let views = write_views(dir.path());
    let out = dir.path().join("out");
    let assert = mtpcr()
        .arg("register")
        .args(args_of(&views))
        .arg("--output")
        .arg(&out)
        .args(["--seed", "11"])
        .args(FAST)
        .assert()
        .code(REGISTERED)
        .stderr("");
    let stdout = String::from_utf8_lossy(&assert.get_output().stdout).into_owned();
    for needle in [
        "T12 (cloud 1 -> cloud 2 frame) =",
        "T31",
        "loop residual",
        "seed 11",
        "wrote ",
    ] {
        assert!(stdout.contains(needle), "`{needle}` not in {stdout}");
    }
    for name in [
        "result.json",
        "config.toml",
        "transforms.txt",
        "merged.ply",
        "convergence.png",
        "views.png",
        "view.html",
        "poses.log",
        "pose_graph.json",
    ] {
        let len = std::fs::metadata(out.join(name))
            .map(|m| m.len())
            .unwrap_or(0);
        assert!(len > 0, "{name} is missing or empty");
    }
    for png in ["convergence.png", "views.png"] {
        assert!(
            std::fs::read(out.join(png))
                .unwrap()
                .starts_with(PNG_SIGNATURE),
            "{png}"
        );
    }

    let json = read_json(&out.join("result.json"));
    for key in [
        "inputs",
        "convention",
        "transforms",
        "loop_residual",
        "best_costs",
        "evaluations",
        "seconds",
        "seed",
        "settings",
        "history",
        "task_names",
    ] {
        assert!(json.get(key).is_some(), "result.json has no `{key}`");
    }
    assert_eq!(json["inputs"].as_array().unwrap().len(), 3);
    for t in ["T12", "T23", "T31"] {
        let rows = json["transforms"][t].as_array().unwrap();
        assert_eq!(rows.len(), 4);
        assert!(rows.iter().all(|r| r.as_array().unwrap().len() == 4));
        assert_eq!(rows[3], serde_json::json!([0.0, 0.0, 0.0, 1.0]));
    }
    assert_eq!(json["best_costs"]["original"].as_array().unwrap().len(), 3);
    assert_eq!(json["best_costs"]["aiding"].as_array().unwrap().len(), 3);
    assert_eq!(json["seed"], 11);
    assert_eq!(json["settings"]["seed"], 11);
    assert_eq!(json["settings"]["generations"], 3);
    let history = json["history"].as_array().unwrap();
    assert_eq!(history.len(), 4, "the initial population and 3 generations");
    assert!(history.iter().all(|r| r.as_array().unwrap().len() == 6));
    assert_eq!(
        json["task_names"],
        serde_json::json!(["J1-a", "J2-a", "J3-a", "J1-o", "J2-o", "J3-o"])
    );

    let text = std::fs::read_to_string(out.join("transforms.txt")).unwrap();
    for needle in [
        "T_ij maps points of cloud i into the frame of cloud j",
        "T12 (",
        "T23 (",
        "T31 (",
    ] {
        assert!(text.contains(needle), "`{needle}` not in {text}");
    }
    let merged = read_ply(out.join("merged.ply")).unwrap();
    assert_eq!(merged.len(), 9000);
    // Written under temporary names and renamed: only the results remain.
    let mut names = file_names(&out);
    names.sort();
    let mut expected = [
        "config.toml",
        "convergence.png",
        "merged.ply",
        "pose_graph.json",
        "poses.log",
        "result.json",
        "transforms.txt",
        "view.html",
        "views.png",
    ];
    expected.sort();
    assert_eq!(names, expected);
}

/// Four or more scans are placed without an evolution (no tasks, no costs to print): the
/// command must still print every pose and write its folder (it panicked on the cost table).
/// The scans are given as their folder: its cloud files in natural order.
#[test]
fn register_places_four_scans_in_no_known_order() {
    let dir = tempfile::tempdir().unwrap();
    let scans = dir.path().join("scans");
    std::fs::create_dir(&scans).unwrap();
    let views = synthetic::views_around(3, 4, 3000);
    for (i, c) in views.clouds.iter().enumerate() {
        write_ply(scans.join(format!("scan{}.ply", i + 1)), c.points(), None).unwrap();
    }
    std::fs::write(scans.join("scan1.info.txt"), "not a cloud").unwrap();
    let out = dir.path().join("out");
    let run = mtpcr()
        .arg("register")
        .arg(&scans)
        .args(["-o", out.to_str().unwrap(), "--seed", "1", "-q"])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert!(REGISTERED.contains(&run.status.code().unwrap()), "{stderr}");
    let stdout = String::from_utf8_lossy(&run.stdout);
    assert!(stdout.contains("verdict"), "{stdout}");
    let result = read_json(&out.join("result.json"));
    assert_eq!(
        result["poses"].as_array().map(Vec::len),
        Some(4),
        "{result}"
    );
}

/// A scan that cannot be placed is left out of the merged cloud and the 3-D view, and the
/// command still writes every file (the view's writer panicked on it).
#[test]
fn register_writes_its_files_when_a_scan_is_not_placed() {
    let dir = tempfile::tempdir().unwrap();
    let views = synthetic::views_around(14, 5, 4000);
    // Another object of the same size: the near half of a wavy torus.
    let stranger: Vec<[f64; 3]> = (0..4000)
        .map(|i| {
            let (u, v) = (
                (i as f64 * 0.618_034).fract() * std::f64::consts::TAU,
                (i as f64 / 4000.0) * std::f64::consts::PI,
            );
            let r = 0.02 + 0.004 * (5.0 * u).sin();
            [
                (0.05 + r * v.cos()) * u.cos(),
                (0.05 + r * v.cos()) * u.sin(),
                r * v.sin(),
            ]
        })
        .collect();
    let mut paths = Vec::new();
    for (i, c) in views.clouds.iter().enumerate() {
        let path = dir.path().join(format!("scan{}.ply", i + 1));
        write_ply(&path, c.points(), None).unwrap();
        paths.push(path);
    }
    let odd = dir.path().join("stranger.ply");
    write_ply(&odd, &stranger, None).unwrap();
    paths.insert(2, odd);
    let out = dir.path().join("out");
    let run = mtpcr()
        .arg("register")
        .args(args_of(&paths))
        .args(["-o", out.to_str().unwrap(), "--seed", "1", "-q"])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert_eq!(run.status.code(), Some(3), "not confident: {stderr}");
    let stdout = String::from_utf8_lossy(&run.stdout);
    assert!(stdout.contains("cloud 3 NOT PLACED"), "{stdout}");
    let html = std::fs::read_to_string(out.join("view.html")).unwrap();
    assert!(
        html.contains("not placed"),
        "the view says what it leaves out"
    );
    assert!(
        !html.contains("stranger.ply"),
        "the unplaced scan is not drawn"
    );
    let merged = read_ply(out.join("merged.ply")).unwrap();
    assert_eq!(merged.len(), 5 * 4000);
}

/// The names in a folder.
fn file_names(dir: &Path) -> Vec<String> {
    std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect()
}

#[test]
fn register_defaults_to_a_new_timestamped_folder() {
    let dir = tempfile::tempdir().unwrap();
    let views = write_views(dir.path());
    for _ in 0..2 {
        mtpcr()
            .current_dir(dir.path())
            .arg("register")
            .args(args_of(&views))
            .args(FAST)
            .assert()
            .code(REGISTERED);
    }
    let runs: Vec<PathBuf> = std::fs::read_dir(dir.path().join("results"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    assert_eq!(runs.len(), 2, "two runs, two folders: {runs:?}");
    for r in runs {
        assert!(r.join("result.json").is_file(), "{}", r.display());
    }
}

#[test]
fn register_refuses_a_non_empty_folder_without_force() {
    let dir = tempfile::tempdir().unwrap();
    let views = write_views(dir.path());
    let out = dir.path().join("out");
    std::fs::create_dir(&out).unwrap();
    std::fs::write(out.join("notes.txt"), "keep me").unwrap();
    let run = |force: bool| {
        let mut cmd = mtpcr();
        cmd.arg("register")
            .args(args_of(&views))
            .arg("--output")
            .arg(&out)
            .args(FAST);
        if force {
            cmd.arg("--force");
        }
        cmd
    };
    fails_with(&mut run(false), 1, &["not empty", "--force", "out"]);
    assert!(!out.join("result.json").exists());
    run(true).assert().code(REGISTERED);
    assert!(out.join("result.json").is_file());
    assert_eq!(
        std::fs::read_to_string(out.join("notes.txt")).unwrap(),
        "keep me"
    );
}

#[test]
fn register_never_overwrites_an_input() {
    let dir = tempfile::tempdir().unwrap();
    let views = write_views(dir.path());
    let input = dir.path().join("merged.ply");
    std::fs::copy(&views[0], &input).unwrap();
    let before = std::fs::read(&input).unwrap();
    fails_with(
        mtpcr()
            .arg("register")
            .arg(&input)
            .args(args_of(&views[1..]))
            .arg("--output")
            .arg(dir.path())
            .arg("--force")
            .args(FAST),
        1,
        &["merged.ply", "overwritten"],
    );
    assert_eq!(std::fs::read(&input).unwrap(), before);
}

/// `out/NAME` made another name of `input` by `link`, then `register --force` into `out`: an
/// error naming both, and the input untouched.
fn refuses_an_output_name_linked_to_an_input(
    name: &str,
    link: fn(&Path, &Path) -> std::io::Result<()>,
) {
    let dir = tempfile::tempdir().unwrap();
    let views = write_views(dir.path());
    let out = dir.path().join("out");
    std::fs::create_dir(&out).unwrap();
    link(&views[1], &out.join(name)).unwrap();
    let before = std::fs::read(&views[1]).unwrap();
    fails_with(
        mtpcr()
            .arg("register")
            .args(args_of(&views))
            .arg("--output")
            .arg(&out)
            .arg("--force")
            .args(FAST),
        1,
        &[name, "view2.ply", "link", "another --output"],
    );
    assert_eq!(std::fs::read(&views[1]).unwrap(), before);
    assert_eq!(file_names(&out), [name], "nothing written");
}

#[test]
fn register_refuses_an_output_file_hard_linked_to_an_input() {
    refuses_an_output_name_linked_to_an_input("merged.ply", |a, b| std::fs::hard_link(a, b));
}

#[cfg(unix)]
#[test]
fn register_refuses_an_output_file_symlinked_to_an_input() {
    refuses_an_output_name_linked_to_an_input("result.json", |a, b| {
        std::os::unix::fs::symlink(a, b)
    });
}

#[test]
fn a_planar_cloud_is_registered_with_a_warning() {
    let dir = tempfile::tempdir().unwrap();
    let mut views = write_views(dir.path()).to_vec();
    // Cloud 2 flattened onto z = 0.
    let flat: Vec<[f64; 3]> = read_ply(&views[1])
        .unwrap()
        .points()
        .iter()
        .map(|p| [p[0], p[1], 0.0])
        .collect();
    views[1] = dir.path().join("flat.ply");
    write_ply(&views[1], &flat, None).unwrap();
    let out = dir.path().join("out");
    let assert = mtpcr()
        .arg("register")
        .args(args_of(&views))
        .arg("--output")
        .arg(&out)
        .args(FAST)
        .assert()
        // Tiny settings and a drawn seed: confident (0) or not (3), results written either way.
        .code(REGISTERED);
    let stderr = String::from_utf8_lossy(&assert.get_output().stderr).into_owned();
    assert_eq!(
        stderr.lines().collect::<Vec<_>>(),
        [format!(
            "warning: cloud 2 is planar: its rotation about the plane normal is weakly \
             determined ({})",
            views[1].display()
        )],
        "one warning, for cloud 2 only"
    );
    assert!(out.join("result.json").is_file());
}

#[test]
fn a_collinear_cloud_or_huge_coordinates_are_errors() {
    let dir = tempfile::tempdir().unwrap();
    let views = write_views(dir.path());
    let line = dir.path().join("line.ply");
    let points: Vec<[f64; 3]> = (0..100)
        .map(|i| {
            let t = f64::from(i) * 0.01;
            [t, 2.0 * t - 1.0, 0.5 * t]
        })
        .collect();
    write_ply(&line, &points, None).unwrap();
    let huge = dir.path().join("huge.ply");
    let mut points = read_ply(&views[0]).unwrap().into_points();
    points[5][2] = 1e300;
    write_ply(&huge, &points, None).unwrap();
    let out = dir.path().join("out");
    for (bad, needles) in [
        (&line, ["line.ply", "on one line"]),
        (&huge, ["huge.ply", "point 5"]),
    ] {
        let stderr = fails_with(
            mtpcr()
                .arg("register")
                .arg(bad)
                .args(args_of(&views[1..]))
                .arg("--output")
                .arg(&out)
                .args(FAST),
            1,
            &needles,
        );
        assert!(!stderr.contains("NaN"), "{stderr}");
        assert!(!out.exists(), "no folder for a run that never started");
    }
}

/// Starts `mtpcr register` on `views` with settings that take minutes, in `cwd`, with `extra`
/// arguments; sends SIGINT once it has read its clouds (its handler is installed and its
/// output folder exists by then); returns its exit code and stderr.
#[cfg(unix)]
fn interrupted_register(cwd: &Path, views: &[PathBuf], extra: &[&str]) -> (Option<i32>, String) {
    use nix::sys::signal::{kill, Signal};
    use nix::unistd::Pid;
    use std::io::BufRead;
    use std::time::{Duration, Instant};
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_mtpcr"))
        .current_dir(cwd)
        .arg("register")
        .args(args_of(views))
        .args(["--generations", "1000000", "--population-size", "2000"])
        .args(extra)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let stderr = child.stderr.take().unwrap();
    let (tx, rx) = std::sync::mpsc::channel();
    let reader = std::thread::spawn(move || {
        let mut all = String::new();
        for line in std::io::BufReader::new(stderr).lines() {
            let line = line.unwrap();
            let _ = tx.send(line.clone());
            all.push_str(&line);
            all.push('\n');
        }
        all
    });
    let last = views.last().unwrap().display().to_string();
    let deadline = Instant::now() + Duration::from_secs(120);
    loop {
        let line = rx
            .recv_timeout(deadline.saturating_duration_since(Instant::now()))
            .expect("the run never reported reading its last cloud");
        if line.starts_with(&format!("read {last}")) {
            break;
        }
    }
    let pid = Pid::from_raw(i32::try_from(child.id()).unwrap());
    kill(pid, Signal::SIGINT).unwrap();
    let deadline = Instant::now() + Duration::from_secs(60);
    let status = loop {
        if let Some(status) = child.try_wait().unwrap() {
            break status;
        }
        if Instant::now() > deadline {
            child.kill().unwrap();
            panic!("the run did not stop within 60 s of SIGINT");
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    (status.code(), reader.join().unwrap())
}

#[cfg(unix)]
#[test]
fn ctrl_c_removes_the_folder_it_created_and_exits_130() {
    let dir = tempfile::tempdir().unwrap();
    let views = write_views(dir.path());
    // A given folder, with a parent this run creates too.
    let out = dir.path().join("new").join("out");
    let (code, stderr) =
        interrupted_register(dir.path(), &views, &["--output", out.to_str().unwrap()]);
    assert_eq!(code, Some(130), "{stderr}");
    assert!(stderr.ends_with("interrupted\n"), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert!(
        !dir.path().join("new").exists(),
        "the folders it created remain"
    );

    // The default folder results/<timestamp>, and results/ itself.
    let (code, stderr) = interrupted_register(dir.path(), &views, &[]);
    assert_eq!(code, Some(130), "{stderr}");
    assert!(
        !dir.path().join("results").exists(),
        "an empty results folder remains"
    );
}

#[cfg(unix)]
#[test]
fn ctrl_c_keeps_a_folder_it_did_not_create_as_it_was() {
    let dir = tempfile::tempdir().unwrap();
    let views = write_views(dir.path());
    let out = dir.path().join("out");
    std::fs::create_dir(&out).unwrap();
    let (code, stderr) = interrupted_register(dir.path(), &views, &["--output", "out"]);
    assert_eq!(code, Some(130), "{stderr}");
    assert!(out.is_dir());
    assert!(file_names(&out).is_empty(), "{:?}", file_names(&out));

    std::fs::write(out.join("notes.txt"), "keep me").unwrap();
    let (code, stderr) = interrupted_register(dir.path(), &views, &["--output", "out", "--force"]);
    assert_eq!(code, Some(130), "{stderr}");
    assert_eq!(file_names(&out), ["notes.txt"]);
}

#[test]
fn bad_input_files_are_named_in_the_error() {
    let dir = tempfile::tempdir().unwrap();
    let views = write_views(dir.path());
    let out = dir.path().join("out");
    let register_with = |first: &Path| {
        let mut cmd = mtpcr();
        cmd.arg("register")
            .arg(first)
            .args(args_of(&views[1..]))
            .arg("--output")
            .arg(&out)
            .args(FAST);
        cmd
    };
    let missing = dir.path().join("missing.ply");
    fails_with(
        &mut register_with(&missing),
        1,
        &["missing.ply", "No such file"],
    );

    let malformed = dir.path().join("malformed.ply");
    std::fs::write(&malformed, "hello\nthis is not a point cloud\n").unwrap();
    fails_with(
        &mut register_with(&malformed),
        1,
        &["malformed.ply", "not a PLY file"],
    );

    let truncated = dir.path().join("truncated.ply");
    let mut bytes = std::fs::read(&views[0]).unwrap();
    bytes.truncate(bytes.len() / 2);
    std::fs::write(&truncated, bytes).unwrap();
    fails_with(&mut register_with(&truncated), 1, &["truncated.ply"]);

    let tiny = dir.path().join("tiny.ply");
    write_ply(
        &tiny,
        &[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
        None,
    )
    .unwrap();
    fails_with(
        &mut register_with(&tiny),
        1,
        &["tiny.ply", "3 points", "at least"],
    );

    // One file of one cloud: nothing to register it to.
    fails_with(
        mtpcr()
            .arg("register")
            .arg(&views[0])
            .arg("--output")
            .arg(&out)
            .args(FAST),
        1,
        &["at least two clouds", "got 1", "view1.ply"],
    );
    assert!(
        !out.exists(),
        "no output folder for a run that never started"
    );
}

/// `points` as an ascii PCD file (f64, printed to round trip) with the header line
/// `VIEWPOINT {viewpoint}`.
fn write_pcd_with_viewpoint(path: &Path, points: &[[f64; 3]], viewpoint: &str) {
    let n = points.len();
    let mut text = format!(
        "VERSION 0.7\nFIELDS x y z\nSIZE 8 8 8\nTYPE F F F\nCOUNT 1 1 1\nWIDTH {n}\nHEIGHT 1\n\
         VIEWPOINT {viewpoint}\nPOINTS {n}\nDATA ascii\n"
    );
    for p in points {
        text.push_str(&format!("{} {} {}\n", p[0], p[1], p[2]));
    }
    std::fs::write(path, text).unwrap();
}

/// `--viewpoint` sets each cloud's viewpoint (result.json records them): `file`, the
/// default, takes a PCD header's VIEWPOINT (PLY has none); `origin` puts every scanner at
/// its file's origin; `none` drops what a file says.
#[test]
fn register_sets_the_viewpoints_as_the_option_says() {
    let dir = tempfile::tempdir().unwrap();
    let [one, two, three] = write_views(dir.path());
    let pcd = dir.path().join("view2.pcd");
    write_pcd_with_viewpoint(&pcd, read_ply(&two).unwrap().points(), "0.5 -1 2 1 0 0 0");
    let inputs = [one, pcd, three];
    let from_file = serde_json::json!([null, [0.5, -1.0, 2.0], null]);
    let cases = [
        (None, from_file.clone()),
        (Some("file"), from_file),
        (
            Some("origin"),
            serde_json::json!([[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]]),
        ),
        (Some("none"), serde_json::json!([null, null, null])),
    ];
    for (k, (flag, want)) in cases.into_iter().enumerate() {
        let out = dir.path().join(format!("out{k}"));
        let mut cmd = mtpcr();
        cmd.arg("register")
            .args(args_of(&inputs))
            .arg("--output")
            .arg(&out)
            .args(["--seed", "5"])
            .args(FAST);
        if let Some(flag) = flag {
            cmd.args(["--viewpoint", flag]);
        }
        let assert = cmd.assert().code(REGISTERED);
        let stderr = String::from_utf8_lossy(&assert.get_output().stderr).into_owned();
        assert!(!stderr.contains("panicked"), "{flag:?}: {stderr}");
        let json = read_json(&out.join("result.json"));
        assert_eq!(json["viewpoints"], want, "--viewpoint {flag:?}");
        assert_eq!(json["points"], serde_json::json!([3000, 3000, 3000]));
    }
}

#[test]
fn a_bad_viewpoint_value_is_a_usage_error_listing_the_choices() {
    fails_with(
        mtpcr().args(["register", "a.ply", "b.ply", "--viewpoint", "sideways"]),
        2,
        &[
            "invalid value 'sideways'",
            "--viewpoint",
            "origin",
            "file",
            "none",
        ],
    );
    let help = mtpcr()
        .args(["register", "--help"])
        .assert()
        .success()
        .get_output()
        .stdout
        .clone();
    let help = String::from_utf8_lossy(&help);
    assert!(
        help.contains("--viewpoint <WHERE>") && help.contains("free-space check"),
        "{help}"
    );
}

#[test]
fn usage_errors_exit_with_2() {
    fails_with(
        mtpcr().args(["register", "a.ply", "b.ply", "c.ply", "--no-such-flag"]),
        2,
        &["--no-such-flag"],
    );
    fails_with(mtpcr().args(["register"]), 2, &["CLOUD"]);
    fails_with(
        mtpcr().args(["demo", "--generations", "many"]),
        2,
        &["--generations"],
    );
    fails_with(
        mtpcr().args(["demo", "--sampling", "sideways"]),
        2,
        &["farthest", "random"],
    );
    fails_with(&mut mtpcr(), 2, &["Usage"]);
}

#[test]
fn bad_setting_values_name_the_field() {
    fails_with(
        mtpcr().args(["demo", "--population-size", "2", "-q"]),
        1,
        &["population_size", "--population-size"],
    );
    fails_with(
        mtpcr().args(["demo", "--sample-ratio", "1.5", "-q"]),
        1,
        &["sample_ratio"],
    );
    fails_with(
        mtpcr().args(["eval", "x.json", "--p-intra", "2"]),
        1,
        &["p_intra"],
    );

    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("bad.toml");
    std::fs::write(&file, "generations = 5\nalpha = -1.0\n").unwrap();
    let views = write_views(dir.path());
    fails_with(
        mtpcr()
            .arg("register")
            .args(args_of(&views))
            .arg("--config")
            .arg(&file)
            .arg("-q"),
        1,
        &["alpha", "bad.toml"],
    );
    // A flag overrides the file, so the same file with --alpha works.
    let out = dir.path().join("out");
    mtpcr()
        .arg("register")
        .args(args_of(&views))
        .arg("--config")
        .arg(&file)
        .args([
            "--alpha",
            "0.05",
            "--population-size",
            "8",
            "-q",
            "--output",
        ])
        .arg(&out)
        .assert()
        .code(REGISTERED);
    assert_eq!(
        read_json(&out.join("result.json"))["settings"]["generations"],
        5
    );
}

#[test]
fn bad_config_files_are_named_in_the_error() {
    let dir = tempfile::tempdir().unwrap();
    let write = |name: &str, text: &str| {
        let p = dir.path().join(name);
        std::fs::write(&p, text).unwrap();
        p
    };
    let unknown = write("unknown.toml", "generations = 5\npopulation = 20\n");
    let wrong_type = write("type.toml", "generations = \"many\"\n");
    let not_toml = write("broken.toml", "generations = = 5\n");
    for sub in [&["demo"][..], &["eval", "problem.json"][..]] {
        fails_with(
            mtpcr().args(sub).arg("--config").arg(&unknown),
            1,
            &["unknown.toml", "population"],
        );
    }
    fails_with(
        mtpcr().arg("demo").arg("--config").arg(&wrong_type),
        1,
        &["type.toml", "generations"],
    );
    fails_with(
        mtpcr().arg("demo").arg("--config").arg(&not_toml),
        1,
        &["broken.toml", "line 1"],
    );
    fails_with(
        mtpcr()
            .arg("demo")
            .arg("--config")
            .arg(dir.path().join("absent.toml")),
        1,
        &["absent.toml", "cannot read the config file"],
    );
}

#[test]
fn an_unwritable_output_folder_is_an_error_not_a_panic() {
    let dir = tempfile::tempdir().unwrap();
    let views = write_views(dir.path());
    let file = dir.path().join("a-file");
    std::fs::write(&file, "x").unwrap();
    fails_with(
        mtpcr()
            .arg("register")
            .args(args_of(&views))
            .arg("--output")
            .arg(&file)
            .args(FAST),
        1,
        &["a-file", "not a folder"],
    );
    fails_with(
        mtpcr()
            .arg("register")
            .args(args_of(&views))
            .arg("--output")
            .arg(file.join("sub"))
            .args(FAST),
        1,
        &["cannot create the output folder"],
    );
}

#[test]
fn eval_runs_a_problem_file_and_reports_each_run() {
    let dir = tempfile::tempdir().unwrap();
    let views = write_views(dir.path());
    let truth = synthetic::three_views(5, 3000).ground_truth;
    // Poses in view 1's frame: x_1 = pose_i x_i, so pose_2 = T12^-1 and pose_3 = T31.
    let poses = [
        mtpcr_core::Transform::identity(),
        mtpcr_core::se3::invert_rigid(&truth[0]),
        truth[2],
    ];
    let problem = serde_json::json!({
        "name": "synthetic",
        "scans": ["view1.ply", "view2.ply", "view3.ply"],
        "poses": poses.iter().map(mtpcr_core::io::matrix_rows).collect::<Vec<_>>(),
    });
    let file = dir.path().join("problem.json");
    std::fs::write(&file, problem.to_string()).unwrap();
    let report = dir.path().join("report.json");
    let out = mtpcr()
        .arg("eval")
        .arg(&file)
        .arg("--data-root")
        .arg(dir.path())
        .args([
            "--runs",
            "2",
            "--seed",
            "4",
            "--generations",
            "3",
            "--population-size",
            "8",
            "--json",
        ])
        .arg(&report)
        .assert()
        .success()
        .get_output()
        .clone();
    let stdout = String::from_utf8(out.stdout).unwrap();
    let lines: Vec<&str> = stdout.lines().collect();
    assert!(
        lines[0].starts_with("problem ") && lines[0].contains("Err_R x1000"),
        "{stdout}"
    );
    assert!(
        lines[1].starts_with("synthetic ") && lines[1].contains(" 2 "),
        "{stdout}"
    );
    assert_eq!(lines[2], format!("wrote {}", report.display()));
    let stderr = String::from_utf8(out.stderr).unwrap();
    assert!(stderr.contains("synthetic run 1/2 seed 4: "), "{stderr}");
    assert!(stderr.contains("synthetic run 2/2 seed 5: "), "{stderr}");
    let json = read_json(&report);
    assert_eq!(json["problems"][0]["runs"].as_array().unwrap().len(), 2);
    assert_eq!(views.len(), 3);

    // With noise: the same seeds, other scans, so other transforms; a bad sigma is named.
    let noisy = dir.path().join("noisy.json");
    let eval_with = |extra: &[&str]| {
        let mut cmd = mtpcr();
        cmd.arg("eval")
            .arg(&file)
            .arg("--data-root")
            .arg(dir.path())
            .args(["--runs", "1", "--seed", "4", "-q"])
            .args(["--generations", "3", "--population-size", "8"])
            .args(extra);
        cmd
    };
    eval_with(&["--noise", "0.01", "--json", noisy.to_str().unwrap()])
        .assert()
        .success();
    let first = |j: &serde_json::Value| j["problems"][0]["runs"][0]["transforms"].clone();
    assert_ne!(first(&read_json(&noisy)), first(&json));
    fails_with(
        &mut eval_with(&["--noise=-0.5"]),
        1,
        &["noise sigma must be finite and >= 0, got -0.5"],
    );

    // Four scans are scored by their poses from moved scans only.
    let four = dir.path().join("four.json");
    let mut problem4 = problem.clone();
    problem4["scans"] = serde_json::json!(["view1.ply", "view2.ply", "view3.ply", "view1.ply"]);
    problem4["poses"] = serde_json::json!([poses[0], poses[1], poses[2], poses[0]]
        .iter()
        .map(mtpcr_core::io::matrix_rows)
        .collect::<Vec<_>>());
    std::fs::write(&four, problem4.to_string()).unwrap();
    fails_with(
        mtpcr()
            .arg("eval")
            .arg(&four)
            .arg("--data-root")
            .arg(dir.path())
            .arg("--ground-truth-frame"),
        1,
        &["--ground-truth-frame applies to problems of two or three scans; synthetic has 4"],
    );
    // Its JSON holds the poses it scored, carried back to the scans as given: each one's
    // rotation error against the truth in the first placed scan's frame is the run's.
    let four_report = dir.path().join("four-report.json");
    mtpcr()
        .arg("eval")
        .arg(&four)
        .arg("--data-root")
        .arg(dir.path())
        .args(["--runs", "1", "--seed", "2", "-q", "--json"])
        .arg(&four_report)
        .assert()
        .success();
    let run = read_json(&four_report)["problems"][0]["runs"][0].clone();
    let matrix = |v: &serde_json::Value| -> Option<mtpcr_core::Transform> {
        let rows: Vec<Vec<f64>> = serde_json::from_value(v.clone()).ok()?;
        Some(mtpcr_core::Transform::from_fn(|r, c| rows[r][c]))
    };
    let given: Vec<Option<mtpcr_core::Transform>> = run["poses_as_given"]
        .as_array()
        .expect("poses_as_given")
        .iter()
        .map(matrix)
        .collect();
    let truth4 = [poses[0], poses[1], poses[2], poses[0]];
    let first = given
        .iter()
        .position(Option::is_some)
        .expect("a placed scan");
    let mut scored = 0;
    for (k, pose) in given.iter().enumerate() {
        let Some(pose) = pose else { continue };
        let truth_k = mtpcr_core::se3::invert_rigid(&truth4[first]) * truth4[k];
        let error = mtpcr_core::se3::rotation_error_deg(pose, &truth_k);
        let reported = run["rot_deg"][k].as_f64().expect("a placed scan's error");
        assert!(
            (error - reported).abs() < 1e-6,
            "scan {k}: {error} {reported}"
        );
        scored += 1;
    }
    assert!(scored >= 2, "{run}");
    // The best anchor is a placed scan; it sees itself near the truth.
    let anchor = &run["best_anchor"];
    let scan = anchor["scan"].as_u64().expect("best_anchor.scan") as usize;
    assert!(given[scan].is_some(), "{anchor}");
    let near = anchor["near"].as_u64().expect("best_anchor.near") as usize;
    assert!((1..=scored).contains(&near), "{anchor}");
    assert!(anchor["wrong"].as_u64().expect("best_anchor.wrong") as usize <= scored - near);
    fails_with(
        mtpcr().arg("eval").arg(dir.path().join("none.json")),
        1,
        &["none.json"],
    );
}
