//! E57 files (ASTM E2807), read with the `e57` crate: every scan of the file, each with the
//! pose stored with it.
//!
//! Points are returned in the scan's own coordinates; the pose (`x_world = pose x_scan`) is
//! returned beside them, not applied. Spherical-only scans are converted to Cartesian.
//! Points whose Cartesian coordinate is not valid (`cartesianInvalidState` 1 or 2: direction
//! only or no return) and points with a non-finite coordinate are dropped.

use super::Scan;
use crate::cloud::PointCloud;
use crate::error::{Error, Result};
use crate::se3::Transform;
use e57::{CartesianCoordinate, E57Reader};
use nalgebra::{Quaternion, UnitQuaternion, Vector3};
use std::io::{Read, Seek};
use std::path::Path;

/// No real scan stores fewer than one point per byte on average (even a scan of constant
/// 0-bit fields pays for its packets); a larger claim is a corrupt file, refused before
/// reading so that it cannot make the reader loop or allocate without end.
const MAX_POINTS_PER_BYTE: u64 = 8;

/// The pose of a scan as a 4x4 matrix (`x_world = pose x_scan`); the quaternion is
/// normalised.
fn pose_matrix(path: &Path, scan: &str, t: &e57::Transform) -> Result<Transform> {
    let q = &t.rotation;
    let v = &t.translation;
    let values = [q.w, q.x, q.y, q.z, v.x, v.y, v.z];
    let norm = (q.w * q.w + q.x * q.x + q.y * q.y + q.z * q.z).sqrt();
    if values.iter().any(|x| !x.is_finite()) || norm < 1e-9 {
        return Err(Error::malformed(
            path,
            format!(
                "scan `{scan}` has an invalid pose (rotation {} {} {} {}, translation {} {} {})",
                q.w, q.x, q.y, q.z, v.x, v.y, v.z
            ),
        ));
    }
    let rotation = UnitQuaternion::from_quaternion(Quaternion::new(q.w, q.x, q.y, q.z));
    let mut m = rotation.to_homogeneous();
    m.fixed_view_mut::<3, 1>(0, 3)
        .copy_from(&Vector3::new(v.x, v.y, v.z));
    Ok(m)
}

/// Reads every scan of an E57 file from `source` (`len` bytes long); `path` names it in
/// errors.
pub(crate) fn read_e57<R: Read + Seek>(path: &Path, source: R, len: u64) -> Result<Vec<Scan>> {
    let e57_error = |what: &str, e: e57::Error| {
        let text = e.to_string().lines().collect::<Vec<_>>().join(" ");
        Error::malformed(path, format!("{what}: {text}"))
    };
    let mut reader = E57Reader::new(source).map_err(|e| e57_error("not a valid E57 file", e))?;
    let descriptors = reader.pointclouds();
    let mut scans = Vec::with_capacity(descriptors.len());
    let mut total = 0u64;
    for (k, pc) in descriptors.iter().enumerate() {
        let name = pc
            .name
            .clone()
            .filter(|n| !n.trim().is_empty())
            .unwrap_or_else(|| format!("scan {}", k + 1));
        total = total.saturating_add(pc.records);
        if total > len.saturating_mul(MAX_POINTS_PER_BYTE) {
            return Err(Error::malformed(
                path,
                format!(
                    "scan `{name}` declares {} points, more than a file of {len} bytes can hold",
                    pc.records
                ),
            ));
        }
        let pose = pc
            .transform
            .as_ref()
            .map(|t| pose_matrix(path, &name, t))
            .transpose()?;
        let mut points_in = reader
            .pointcloud_simple(pc)
            .map_err(|e| e57_error(&format!("cannot read scan `{name}`"), e))?;
        points_in.apply_pose(false);
        points_in.spherical_to_cartesian(true);
        points_in.intensity_to_color(false);
        points_in.normalize_color(false);
        points_in.normalize_intensity(false);
        let mut points = Vec::with_capacity(usize::try_from(pc.records).unwrap_or(0).min(1 << 20));
        for point in points_in {
            let point = point.map_err(|e| e57_error(&format!("bad data in scan `{name}`"), e))?;
            if let CartesianCoordinate::Valid { x, y, z } = point.cartesian {
                if x.is_finite() && y.is_finite() && z.is_finite() {
                    points.push([x, y, z]);
                }
            }
        }
        scans.push(Scan {
            name,
            cloud: PointCloud::new(points),
            pose,
        });
    }
    Ok(scans)
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use e57::{E57Writer, Record, RecordDataType, RecordName, RecordValue};
    use std::io::Cursor;

    fn tmp(name: &str) -> std::path::PathBuf {
        let dir = std::env::temp_dir().join(format!("mtpcr-io-e57-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        dir.join(name)
    }

    /// One scan to write: name, pose (unit quaternion w x y z, translation), points; a point
    /// with `invalid` set is written with `cartesianInvalidState` 2.
    pub(crate) struct TestScan {
        pub name: &'static str,
        pub pose: Option<([f64; 4], [f64; 3])>,
        pub points: Vec<([f64; 3], bool)>,
    }

    pub(crate) fn sample_scans() -> Vec<TestScan> {
        let half = std::f64::consts::FRAC_1_SQRT_2;
        let grid = |offset: f64| -> Vec<([f64; 3], bool)> {
            (0..40)
                .map(|i| {
                    let t = i as f64;
                    ([t * 0.1 + offset, (t * 0.7).sin(), -t * 0.05], false)
                })
                .collect()
        };
        let mut second = grid(2.0);
        second[3].1 = true; // no return: dropped by the reader
        second[5].0 = [f64::NAN, 0.0, 0.0]; // non-finite: dropped by the reader
        vec![
            TestScan {
                name: "station A",
                pose: Some(([1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0])),
                points: grid(0.0),
            },
            TestScan {
                name: "station B",
                pose: Some(([half, 0.0, 0.0, half], [10.0, -2.5, 0.75])),
                points: second,
            },
            TestScan {
                name: "station C",
                pose: None,
                points: grid(-1.0),
            },
        ]
    }

    /// Writes the scans as an E57 file (double coordinates) with the e57 crate.
    pub(crate) fn write_e57(path: &Path, scans: &[TestScan]) {
        let mut writer = E57Writer::from_file(path, "mtpcr-test-file").unwrap();
        for (k, scan) in scans.iter().enumerate() {
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
                .add_pointcloud(&format!("mtpcr-test-scan-{k}"), prototype)
                .unwrap();
            pc.set_name(Some(scan.name.to_string()));
            pc.set_transform(scan.pose.map(|(q, t)| e57::Transform {
                rotation: e57::Quaternion {
                    w: q[0],
                    x: q[1],
                    y: q[2],
                    z: q[3],
                },
                translation: e57::Translation {
                    x: t[0],
                    y: t[1],
                    z: t[2],
                },
            }));
            for (p, invalid) in &scan.points {
                pc.add_point(vec![
                    RecordValue::Double(p[0]),
                    RecordValue::Double(p[1]),
                    RecordValue::Double(p[2]),
                    RecordValue::Integer(if *invalid { 2 } else { 0 }),
                ])
                .unwrap();
            }
            pc.finalize().unwrap();
        }
        writer.finalize().unwrap();
    }

    #[test]
    fn every_scan_comes_back_with_its_pose_and_valid_points_only() {
        let path = tmp("three.e57");
        let written = sample_scans();
        write_e57(&path, &written);
        let bytes = std::fs::read(&path).unwrap();
        let scans = read_e57(&path, Cursor::new(&bytes[..]), bytes.len() as u64).unwrap();
        assert_eq!(scans.len(), 3);
        for (scan, w) in scans.iter().zip(&written) {
            assert_eq!(scan.name, w.name);
            let expected: Vec<[f64; 3]> = w
                .points
                .iter()
                .filter(|(p, invalid)| !invalid && p.iter().all(|v| v.is_finite()))
                .map(|(p, _)| *p)
                .collect();
            assert_eq!(scan.cloud.points(), &expected[..], "{}", w.name);
            match (&scan.pose, w.pose) {
                (None, None) => {}
                (Some(m), Some((q, t))) => {
                    let r =
                        UnitQuaternion::from_quaternion(Quaternion::new(q[0], q[1], q[2], q[3]));
                    let p = Vector3::new(1.0, 2.0, 3.0);
                    let moved = m * p.push(1.0);
                    let want = r * p + Vector3::new(t[0], t[1], t[2]);
                    assert!((moved.xyz() - want).norm() < 1e-12, "{m}");
                    assert_eq!(
                        m.row(3).iter().copied().collect::<Vec<_>>(),
                        [0.0, 0.0, 0.0, 1.0]
                    );
                }
                other => panic!("pose mismatch for {}: {other:?}", w.name),
            }
        }
        assert_eq!(scans[1].cloud.len(), 38);
        // The second pose: 90 degrees about z, then (10, -2.5, 0.75).
        let m = scans[1].pose.unwrap();
        assert!(
            (m[(0, 1)] + 1.0).abs() < 1e-12 && (m[(1, 0)] - 1.0).abs() < 1e-12,
            "{m}"
        );
        assert_eq!((m[(0, 3)], m[(1, 3)], m[(2, 3)]), (10.0, -2.5, 0.75));
    }

    #[test]
    fn broken_files_give_errors_that_name_the_problem() {
        let path = tmp("one.e57");
        write_e57(&path, &sample_scans()[..1]);
        let bytes = std::fs::read(&path).unwrap();
        let read = |b: &[u8]| read_e57(Path::new("broken.e57"), Cursor::new(b), b.len() as u64);
        let e = read(&bytes[..40]).unwrap_err().to_string();
        assert!(
            e.contains("broken.e57") && e.contains("not a valid E57 file"),
            "{e}"
        );
        let mut corrupt = bytes.clone();
        corrupt[1100] ^= 0xff; // inside a CRC-checked page
        let e = read(&corrupt).unwrap_err().to_string();
        assert!(e.contains("broken.e57") && !e.contains('\n'), "{e}");
        let e = read(&bytes[..bytes.len() - 100]).unwrap_err().to_string();
        assert!(e.contains("broken.e57"), "{e}");
    }
}
