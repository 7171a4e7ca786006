//! `mtpcr register` on every point-cloud format it reads besides PLY: PCD, E57 (one file of
//! three scans), LAS, LAZ and XYZ, each written here with the crates the reader uses. Every
//! run is checked against a run on the same points written as PLY: the same points give
//! bit-identical transforms. A malformed file of each format is an error naming the file.

use assert_cmd::Command;
use mtpcr_core::io::{read_points, read_scans, write_ply};
use mtpcr_core::synthetic;
use std::path::{Path, PathBuf};

/// Small settings, the same for every run.
const SETTINGS: [&str; 9] = [
    "--seed",
    "3",
    "--population-size",
    "12",
    "--generations",
    "3",
    "--restarts",
    "1",
    "-q",
];

/// Exit statuses of a `register` that wrote its results: 0 (confident) or 3 (not confident).
const REGISTERED: &[i32] = &[0, 3];

/// The three overlapping views every test writes.
fn views() -> Vec<Vec<[f64; 3]>> {
    synthetic::three_views(7, 3000)
        .clouds
        .iter()
        .map(|c| c.points().to_vec())
        .collect()
}

fn mtpcr() -> Command {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_mtpcr"));
    cmd.env_remove("RUST_BACKTRACE");
    cmd
}

/// Runs `mtpcr register` on `inputs` into `out`; returns its result.json.
fn register(inputs: &[PathBuf], out: &Path) -> serde_json::Value {
    let assert = mtpcr()
        .arg("register")
        .args(inputs)
        .arg("--output")
        .arg(out)
        .args(SETTINGS)
        .assert()
        .code(REGISTERED);
    let stderr = String::from_utf8_lossy(&assert.get_output().stderr).into_owned();
    assert!(!stderr.contains("panicked"), "{stderr}");
    serde_json::from_str(&std::fs::read_to_string(out.join("result.json")).unwrap()).unwrap()
}

/// Registers `inputs` (files of format `name`, labelled `labels` in result.json, holding
/// `stored`: the points as the format stores them), and the same points written as PLY;
/// asserts both runs give the same transforms.
fn same_as_ply(
    dir: &Path,
    name: &str,
    inputs: &[PathBuf],
    labels: &[String],
    stored: &[Vec<[f64; 3]>],
) {
    let plys: Vec<PathBuf> = stored
        .iter()
        .enumerate()
        .map(|(i, points)| {
            let path = dir.join(format!("{name}-view{}.ply", i + 1));
            write_ply(&path, points, None).unwrap();
            path
        })
        .collect();
    let json = register(inputs, &dir.join(format!("out-{name}")));
    let ply_json = register(&plys, &dir.join(format!("out-{name}-ply")));

    assert_eq!(json["clouds"], serde_json::json!(labels), "{name}");
    let counts: Vec<usize> = stored.iter().map(Vec::len).collect();
    assert_eq!(json["points"], serde_json::json!(counts), "{name}");
    assert!(
        !json["transforms"].as_object().unwrap().is_empty(),
        "{name}"
    );
    assert_eq!(
        json["transforms"], ply_json["transforms"],
        "{name}: the same points as PLY give other transforms"
    );
    assert_eq!(json["poses"], ply_json["poses"], "{name}");
    assert_eq!(json["best_costs"], ply_json["best_costs"], "{name}");
}

fn labels_of(paths: &[PathBuf]) -> Vec<String> {
    paths.iter().map(|p| p.display().to_string()).collect()
}

// --- PCD (as in mtpcr-core's io/pcd.rs tests) ---

/// Writes `points` as x y z (f32) plus an intensity field with pcd-rs.
fn write_pcd(path: &Path, kind: pcd_rs::DataKind, points: &[[f32; 3]]) {
    use pcd_rs::{DynRecord, DynWriter, Field, Schema, ValueKind, WriterInit};
    let schema = Schema::from_iter([
        ("x", ValueKind::F32, 1),
        ("y", ValueKind::F32, 1),
        ("z", ValueKind::F32, 1),
        ("intensity", ValueKind::U16, 1),
    ]);
    let mut writer: DynWriter<_> = WriterInit {
        width: points.len() as u64,
        height: 1,
        viewpoint: Default::default(),
        data_kind: kind,
        schema: Some(schema),
        version: None,
    }
    .create(path)
    .unwrap();
    for (i, p) in points.iter().enumerate() {
        let record = DynRecord(vec![
            Field::F32(vec![p[0]]),
            Field::F32(vec![p[1]]),
            Field::F32(vec![p[2]]),
            Field::U16(vec![i as u16]),
        ]);
        writer.push(&record).unwrap();
    }
    writer.finish().unwrap();
}

fn to_f32(points: &[[f64; 3]]) -> Vec<[f32; 3]> {
    points
        .iter()
        .map(|p| [p[0] as f32, p[1] as f32, p[2] as f32])
        .collect()
}

// --- E57 (as in mtpcr-core's io/e57.rs tests) ---

/// Writes each `(name, points)` as a scan (double coordinates) of one E57 file, with the e57
/// crate; the scans get distinct poses (which `register` does not apply).
fn write_e57(path: &Path, scans: &[(String, Vec<[f64; 3]>)]) {
    use e57::{E57Writer, Record, RecordDataType, RecordName, RecordValue};
    let mut writer = E57Writer::from_file(path, "mtpcr-formats-test-file").unwrap();
    for (k, (name, points)) in scans.iter().enumerate() {
        let double = RecordDataType::Double {
            min: None,
            max: None,
        };
        let prototype = vec![
            Record {
                name: RecordName::CartesianX,
                data_type: double.clone(),
            },
            Record {
                name: RecordName::CartesianY,
                data_type: double.clone(),
            },
            Record {
                name: RecordName::CartesianZ,
                data_type: double,
            },
            Record {
                name: RecordName::CartesianInvalidState,
                data_type: RecordDataType::Integer { min: 0, max: 2 },
            },
        ];
        let mut pc = writer
            .add_pointcloud(&format!("mtpcr-formats-test-scan-{k}"), prototype)
            .unwrap();
        pc.set_name(Some(name.clone()));
        pc.set_transform(Some(e57::Transform {
            rotation: e57::Quaternion {
                w: 1.0,
                x: 0.0,
                y: 0.0,
                z: 0.0,
            },
            translation: e57::Translation {
                x: k as f64,
                y: -2.0 * k as f64,
                z: 0.5,
            },
        }));
        for p in points {
            pc.add_point(vec![
                RecordValue::Double(p[0]),
                RecordValue::Double(p[1]),
                RecordValue::Double(p[2]),
                RecordValue::Integer(0),
            ])
            .unwrap();
        }
        pc.finalize().unwrap();
    }
    writer.finalize().unwrap();
}

// --- LAS / LAZ (as in mtpcr-core's io/las.rs tests) ---

/// Scales of the LAS integers: 10 µm in x and y, 1 µm in z (the views are 0.15 m across).
const LAS_SCALES: [f64; 3] = [1e-5, 1e-5, 1e-6];

/// Writes points as LAS 1.2 point format 1 (LAZ when `compressed`) with the scales
/// [`LAS_SCALES`] and an offset, with the las crate.
fn write_las(path: &Path, points: &[[f64; 3]], compressed: bool) {
    use las::point::Format;
    use las::{Builder, Point, Transform, Vector, Writer};
    let mut builder = Builder::from((1, 2));
    builder.point_format = Format::new(1).unwrap();
    builder.point_format.is_compressed = compressed;
    builder.transforms = Vector {
        x: Transform {
            scale: LAS_SCALES[0],
            offset: 10.0,
        },
        y: Transform {
            scale: LAS_SCALES[1],
            offset: -5.0,
        },
        z: Transform {
            scale: LAS_SCALES[2],
            offset: 0.0,
        },
    };
    let header = builder.into_header().unwrap();
    let file = std::io::BufWriter::new(std::fs::File::create(path).unwrap());
    let mut writer = Writer::new(file, header).unwrap();
    for p in points {
        writer
            .write_point(Point {
                x: p[0],
                y: p[1],
                z: p[2],
                gps_time: Some(0.0),
                ..Default::default()
            })
            .unwrap();
    }
    // Finishes the file, then flushes it (with its error, unlike a drop).
    writer.into_inner().unwrap().into_inner().unwrap();
}

// --- XYZ ---

/// Writes points as XYZ text: a comment, column names, then `x y z intensity` rows
/// (Rust's shortest round-trip decimals: the text gives back the exact f64).
fn write_xyz(path: &Path, points: &[[f64; 3]]) {
    let mut text = String::from("# written by mtpcr's formats test\nx y z intensity\n");
    for (i, p) in points.iter().enumerate() {
        text.push_str(&format!("{} {} {} {}\n", p[0], p[1], p[2], i % 256));
    }
    std::fs::write(path, text).unwrap();
}

// --- The tests ---

#[test]
fn pcd_gives_the_transforms_of_its_points_as_ply() {
    let dir = tempfile::tempdir().unwrap();
    let mut inputs = Vec::new();
    let mut stored = Vec::new();
    for (i, view) in views().iter().enumerate() {
        let path = dir.path().join(format!("view{}.pcd", i + 1));
        let f32s = to_f32(view);
        write_pcd(&path, pcd_rs::DataKind::Binary, &f32s);
        let back = read_points(&path).unwrap().into_points();
        // Binary f32 comes back exactly.
        let want: Vec<[f64; 3]> = f32s
            .iter()
            .map(|p| [f64::from(p[0]), f64::from(p[1]), f64::from(p[2])])
            .collect();
        assert_eq!(back, want, "{}", path.display());
        inputs.push(path);
        stored.push(back);
    }
    same_as_ply(dir.path(), "pcd", &inputs, &labels_of(&inputs), &stored);
}

#[test]
fn e57_scans_give_the_transforms_of_their_points_as_ply() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("site.e57");
    let scans: Vec<(String, Vec<[f64; 3]>)> = views()
        .into_iter()
        .enumerate()
        .map(|(i, v)| (format!("station {}", i + 1), v))
        .collect();
    write_e57(&path, &scans);
    let back = read_scans(&path).unwrap();
    assert_eq!(back.len(), 3);
    for (b, (name, points)) in back.iter().zip(&scans) {
        assert_eq!(&b.name, name);
        // Doubles come back exactly, in the scan's own frame.
        assert_eq!(b.cloud.points(), &points[..], "{name}");
    }
    let stored: Vec<Vec<[f64; 3]>> = back.iter().map(|s| s.cloud.points().to_vec()).collect();
    let labels: Vec<String> = scans
        .iter()
        .map(|(name, _)| format!("{} [{name}]", path.display()))
        .collect();
    // One file of three scans is three clouds.
    same_as_ply(dir.path(), "e57", &[path], &labels, &stored);
}

#[test]
fn las_and_laz_give_the_transforms_of_their_points_as_ply() {
    let dir = tempfile::tempdir().unwrap();
    let views = views();
    let mut stored_las = Vec::new();
    for (compressed, ext) in [(false, "las"), (true, "laz")] {
        let mut inputs = Vec::new();
        let mut stored = Vec::new();
        for (i, view) in views.iter().enumerate() {
            let path = dir.path().join(format!("view{}.{ext}", i + 1));
            write_las(&path, view, compressed);
            let back = read_points(&path).unwrap().into_points();
            assert_eq!(back.len(), view.len());
            // Integers of the scale: within half a step of what was written.
            for (b, w) in back.iter().zip(view) {
                for k in 0..3 {
                    assert!(
                        (b[k] - w[k]).abs() <= LAS_SCALES[k] * (0.5 + 1e-6),
                        "{}: {b:?} for {w:?}",
                        path.display()
                    );
                }
            }
            inputs.push(path);
            stored.push(back);
        }
        same_as_ply(dir.path(), ext, &inputs, &labels_of(&inputs), &stored);
        stored_las.push(stored);
    }
    assert_eq!(stored_las[0], stored_las[1], "LAZ stores what LAS stores");
}

#[test]
fn xyz_gives_the_transforms_of_its_points_as_ply() {
    let dir = tempfile::tempdir().unwrap();
    let mut inputs = Vec::new();
    let mut stored = Vec::new();
    for (i, view) in views().iter().enumerate() {
        let path = dir.path().join(format!("view{}.xyz", i + 1));
        write_xyz(&path, view);
        let back = read_points(&path).unwrap().into_points();
        assert_eq!(&back, view, "{}", path.display());
        inputs.push(path);
        stored.push(back);
    }
    same_as_ply(dir.path(), "xyz", &inputs, &labels_of(&inputs), &stored);
}

#[test]
fn a_malformed_file_of_each_format_is_an_error_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let views = views();
    let plys: Vec<PathBuf> = views[1..]
        .iter()
        .enumerate()
        .map(|(i, v)| {
            let path = dir.path().join(format!("view{}.ply", i + 2));
            write_ply(&path, v, None).unwrap();
            path
        })
        .collect();
    let file = |name: &str| dir.path().join(name);
    let truncate = |path: &Path, keep: fn(usize) -> usize| {
        let bytes = std::fs::read(path).unwrap();
        std::fs::write(path, &bytes[..keep(bytes.len())]).unwrap();
    };

    write_pcd(
        &file("bad.pcd"),
        pcd_rs::DataKind::Binary,
        &to_f32(&views[0]),
    );
    truncate(&file("bad.pcd"), |n| n - 100);
    write_e57(
        &file("bad.e57"),
        &[("station".to_string(), views[0].clone())],
    );
    truncate(&file("bad.e57"), |_| 40);
    write_las(&file("bad.las"), &views[0], false);
    truncate(&file("bad.las"), |n| n - 100);
    write_las(&file("bad.laz"), &views[0], true);
    truncate(&file("bad.laz"), |n| n / 2);
    std::fs::write(file("bad.xyz"), "1 2 3\n4 five 6\n").unwrap();

    let out = dir.path().join("out");
    for (name, needle) in [
        ("bad.pcd", "binary data is too short"),
        ("bad.e57", "not a valid E57 file"),
        ("bad.las", "bad.las"),
        ("bad.laz", "bad.laz"),
        ("bad.xyz", "line 2: `five` is not a number"),
    ] {
        let assert = mtpcr()
            .arg("register")
            .arg(file(name))
            .args(&plys)
            .arg("--output")
            .arg(&out)
            .args(SETTINGS)
            .assert()
            .code(1);
        let stderr = String::from_utf8_lossy(&assert.get_output().stderr).into_owned();
        assert!(!stderr.contains("panicked"), "{stderr}");
        let line = stderr
            .lines()
            .find(|l| l.starts_with("error: "))
            .unwrap_or_else(|| panic!("{name}: no error line in {stderr}"));
        assert!(
            line.contains(&file(name).display().to_string()) && line.contains(needle),
            "{name}: {line}"
        );
        assert!(
            !out.exists(),
            "{name}: an output folder for a run that never started"
        );
    }
}
