//! Registration problems with ground truth, as in `shared/problems/*.json`: a name, two or
//! more scan files and each scan's ground-truth scan-to-world pose.

use crate::cloud::PointCloud;
use crate::error::{Error, Result};
use crate::graph::ViewGraph;
use crate::io::read_points;
use crate::se3::{is_rigid, nearest_rigid, Transform};
use std::path::{Path, PathBuf};

/// A pose is accepted when it is rigid to this tolerance (data sets print poses with a few
/// digits: a 3DMatch pose is orthonormal to ~1e-4); beyond [`EXACT_TOLERANCE`] it is
/// replaced by the nearest rigid transform, with a note.
pub const POSE_TOLERANCE: f64 = 1e-3;
/// Poses rigid to this tolerance are used exactly as written.
pub const EXACT_TOLERANCE: f64 = 1e-6;

/// A registration problem with ground truth.
#[derive(Clone, Debug, PartialEq)]
pub struct Problem {
    /// Short name (`bunny-a`).
    pub name: String,
    /// The scans, resolved against the data root.
    pub scans: Vec<PathBuf>,
    /// Ground-truth scan-to-world poses: `x_world = pose_i x_i`.
    pub poses: Vec<Transform>,
    /// What loading changed (poses re-orthonormalised), one sentence each.
    pub notes: Vec<String>,
    /// Named lists of scan pairs (scan indices) scored from the returned poses, e.g. a 3DMatch
    /// scene's benchmark pairs (`pair_sets` in the file; empty when absent).
    pub pair_sets: Vec<PairSet>,
    /// When a pair of [`Problem::pair_sets`] counts as recovered.
    pub pair_success: PairSuccess,
    /// Where each scan's scanner stood, in the scan's frame (`viewpoints` in the file: the
    /// string `"origin"`, or one `[x, y, z]` or `null` per scan; `None` when absent).
    pub viewpoints: Vec<Option<[f64; 3]>>,
}

/// A named list of scan pairs of a problem.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct PairSet {
    /// The list's name (`3DMatch`).
    pub name: String,
    /// Scan index pairs (0-based).
    pub pairs: Vec<(usize, usize)>,
}

/// A pair is recovered when the relative pose of its scans is within both bounds of the truth.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PairSuccess {
    /// Rotation error bound in degrees.
    pub degrees: f64,
    /// Translation error bound in the data's units.
    pub translation: f64,
}

impl Default for PairSuccess {
    /// The 3DMatch benchmarks' criterion: 15 degrees and 0.3 (metres).
    fn default() -> Self {
        PairSuccess {
            degrees: 15.0,
            translation: 0.3,
        }
    }
}

#[derive(serde::Deserialize)]
struct ProblemFile {
    name: String,
    scans: Vec<String>,
    poses: Vec<[[f64; 4]; 4]>,
    #[serde(default)]
    pair_sets: std::collections::BTreeMap<String, Vec<(usize, usize)>>,
    pair_success: Option<PairSuccess>,
    viewpoints: Option<ViewpointsField>,
}

#[derive(serde::Deserialize)]
#[serde(untagged)]
enum ViewpointsField {
    Named(String),
    Each(Vec<Option<[f64; 3]>>),
}

impl Problem {
    /// Reads a problem file. Scan paths are resolved against `data_root` when given, else
    /// against the parent of the folder that holds the problem file (the layout of `shared/`);
    /// absolute paths are kept.
    pub fn load(path: impl AsRef<Path>, data_root: Option<&Path>) -> Result<Problem> {
        let path = path.as_ref();
        let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
        let file: ProblemFile = serde_json::from_str(&text)
            .map_err(|e| Error::malformed(path, format!("not a valid problem file: {e}")))?;
        if file.scans.len() < 2 || file.scans.len() != file.poses.len() {
            return Err(Error::malformed(
                path,
                format!(
                    "a problem needs at least 2 scans and one pose per scan, found {} scans and {} poses",
                    file.scans.len(),
                    file.poses.len()
                ),
            ));
        }
        let root: PathBuf = match data_root {
            Some(r) => r.to_path_buf(),
            None => path
                .parent()
                .and_then(Path::parent)
                .map(Path::to_path_buf)
                .unwrap_or_else(|| PathBuf::from(".")),
        };
        let mut poses = Vec::with_capacity(file.poses.len());
        let mut notes = Vec::new();
        for (k, p) in file.poses.iter().enumerate() {
            let m = Transform::from_fn(|i, j| p[i][j]);
            if is_rigid(&m, EXACT_TOLERANCE) {
                poses.push(m);
            } else if is_rigid(&m, POSE_TOLERANCE) {
                notes.push(format!(
                    "pose {} is rigid only to {POSE_TOLERANCE:e}; replaced by the nearest rigid transform",
                    k + 1
                ));
                poses.push(nearest_rigid(&m));
            } else {
                return Err(Error::malformed(
                    path,
                    format!(
                        "pose {} is not a rigid transform (not even to {POSE_TOLERANCE:e})",
                        k + 1
                    ),
                ));
            }
        }
        let n = file.scans.len();
        let mut pair_sets = Vec::new();
        for (name, pairs) in file.pair_sets {
            if let Some(&(i, j)) = pairs.iter().find(|&&(i, j)| i >= n || j >= n || i == j) {
                return Err(Error::malformed(
                    path,
                    format!(
                        "pair ({i}, {j}) of pair set {name} is not two different scans of 0..{n}"
                    ),
                ));
            }
            pair_sets.push(PairSet { name, pairs });
        }
        let pair_success = file.pair_success.unwrap_or_default();
        if !(pair_success.degrees > 0.0 && pair_success.translation > 0.0) {
            return Err(Error::malformed(
                path,
                "pair_success needs positive degrees and translation".to_string(),
            ));
        }
        let viewpoints = match file.viewpoints {
            None => vec![None; n],
            Some(ViewpointsField::Named(w)) if w == "origin" => vec![Some([0.0; 3]); n],
            Some(ViewpointsField::Named(w)) => {
                return Err(Error::malformed(
                    path,
                    format!(
                    "viewpoints must be \"origin\" or one [x, y, z] or null per scan, got \"{w}\""
                ),
                ))
            }
            Some(ViewpointsField::Each(v)) => {
                if v.len() != n || v.iter().flatten().flatten().any(|x| !x.is_finite()) {
                    return Err(Error::malformed(
                        path,
                        format!("viewpoints must list one finite [x, y, z] or null per scan ({n} scans, {} given)", v.len()),
                    ));
                }
                v
            }
        };
        Ok(Problem {
            name: file.name,
            scans: file.scans.iter().map(|s| root.join(s)).collect(),
            poses,
            notes,
            pair_sets,
            pair_success,
            viewpoints,
        })
    }

    /// The view graph of the scans in file order (a pair, or a ring).
    pub fn graph(&self) -> Result<ViewGraph> {
        ViewGraph::for_views(self.scans.len())
    }

    /// The ground truth of every edge of [`Problem::graph`] (`T_ts = pose_t^-1 pose_s`; for
    /// three scans `[T12, T23, T31]`).
    pub fn ground_truth(&self) -> Result<Vec<Transform>> {
        Ok(self.graph()?.edge_transforms(&self.poses))
    }

    /// Reads the scans (any format of [`crate::io::read_points`]), with the problem's
    /// viewpoints where it gives them.
    pub fn read_scans(&self) -> Result<Vec<PointCloud>> {
        self.scans
            .iter()
            .zip(&self.viewpoints)
            .map(|(path, v)| {
                let cloud = read_points(path)?;
                Ok(match v {
                    Some(v) => cloud.with_viewpoint(*v),
                    None => cloud,
                })
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::se3::decode;

    fn write(name: &str, text: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("mtpcr-problem-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join(name);
        std::fs::write(&p, text).unwrap();
        p
    }

    fn rows(t: &Transform) -> String {
        serde_json::to_string(&crate::io::matrix_rows(t)).unwrap()
    }

    #[test]
    fn poses_rigid_to_a_thousandth_are_accepted_and_garbage_is_not() {
        let good = decode(&[10.0, 20.0, 30.0, 0.1, 0.2, 0.3]);
        let mut rough = good;
        rough[(0, 0)] += 4e-4; // as printed by a data set
        let text = format!(
            r#"{{"name": "p", "scans": ["a.ply", "/abs/b.ply"], "poses": [{}, {}]}}"#,
            rows(&good),
            rows(&rough)
        );
        let p = Problem::load(write("ok.json", &text), None).unwrap();
        assert_eq!(p.poses[0], good, "exactly rigid poses are kept as written");
        assert!(is_rigid(&p.poses[1], 1e-12) && (p.poses[1] - good).norm() < 1e-3);
        assert_eq!(p.notes.len(), 1, "{:?}", p.notes);
        assert_eq!(p.scans[1], PathBuf::from("/abs/b.ply"));
        assert_eq!(p.ground_truth().unwrap().len(), 1, "two scans: one edge");

        let mut bad = good;
        bad[(0, 0)] += 0.1;
        let text = format!(
            r#"{{"name": "p", "scans": ["a.ply", "b.ply"], "poses": [{}, {}]}}"#,
            rows(&good),
            rows(&bad)
        );
        let e = Problem::load(write("bad.json", &text), None).unwrap_err();
        assert!(e.to_string().contains("pose 2 is not a rigid"), "{e}");
        let e = Problem::load(
            write("one.json", r#"{"name": "p", "scans": ["a"], "poses": []}"#),
            None,
        )
        .unwrap_err();
        assert!(e.to_string().contains("at least 2 scans"), "{e}");
    }

    #[test]
    fn viewpoints_are_read_and_checked() {
        let pose = rows(&decode(&[0.0; 6]));
        let file = |v: &str| {
            format!(r#"{{"name": "room", "scans": ["a", "b"], "poses": [{pose}, {pose}]{v}}}"#)
        };
        let load = |name: &str, v: &str| Problem::load(write(name, &file(v)), None);
        assert_eq!(load("v0.json", "").unwrap().viewpoints, [None, None]);
        let origin = load("v1.json", r#", "viewpoints": "origin""#).unwrap();
        assert_eq!(origin.viewpoints, [Some([0.0; 3]), Some([0.0; 3])]);
        let each = load("v2.json", r#", "viewpoints": [[1, 2, 3], null]"#).unwrap();
        assert_eq!(each.viewpoints, [Some([1.0, 2.0, 3.0]), None]);
        let e = load("v3.json", r#", "viewpoints": "above""#).unwrap_err();
        assert!(e.to_string().contains(r#"got "above""#), "{e}");
        let e = load("v4.json", r#", "viewpoints": [[1, 2, 3]]"#).unwrap_err();
        assert!(e.to_string().contains("2 scans, 1 given"), "{e}");
    }

    #[test]
    fn pair_sets_are_read_and_checked() {
        let pose = rows(&decode(&[0.0; 6]));
        let file = |sets: &str| {
            format!(
                r#"{{"name": "room", "scans": ["a", "b", "c"], "poses": [{pose}, {pose}, {pose}]{sets}}}"#
            )
        };
        let p = Problem::load(write("plain.json", &file("")), None).unwrap();
        assert!(p.pair_sets.is_empty());
        assert_eq!(p.pair_success, PairSuccess::default());
        let p = Problem::load(
            write(
                "sets.json",
                &file(r#", "pair_sets": {"near": [[0, 1], [1, 2]], "far": [[0, 2]]}, "pair_success": {"degrees": 5, "translation": 0.1}"#),
            ),
            None,
        )
        .unwrap();
        let names: Vec<&str> = p.pair_sets.iter().map(|s| s.name.as_str()).collect();
        assert_eq!(names, ["far", "near"]);
        assert_eq!(p.pair_sets[1].pairs, [(0, 1), (1, 2)]);
        assert_eq!(p.pair_success.degrees, 5.0);
        let e = Problem::load(
            write(
                "badpair.json",
                &file(r#", "pair_sets": {"near": [[0, 3]]}"#),
            ),
            None,
        )
        .unwrap_err();
        assert!(
            e.to_string().contains("pair (0, 3) of pair set near"),
            "{e}"
        );
        let e = Problem::load(
            write(
                "badbounds.json",
                &file(r#", "pair_sets": {}, "pair_success": {"degrees": 0, "translation": 0.3}"#),
            ),
            None,
        )
        .unwrap_err();
        assert!(e.to_string().contains("pair_success"), "{e}");
    }
}
