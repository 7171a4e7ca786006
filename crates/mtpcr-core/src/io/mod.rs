//! Files in and out: point clouds in PLY, PCD, E57, LAS/LAZ, XYZ and PTS (read through one
//! format-detecting entry point, [`read_scans`]), PLY out, transforms as text, and poses as
//! a `.log` trajectory or Open3D pose graph ([`trajectory_log`], [`pose_graph_json`])
//! (registration problems with ground truth are read by `eval::problem`).
//!
//! [`read_scans`] returns every scan of a file (E57 files hold several, each with its pose);
//! [`read_points`] is the one-scan shortcut. The format is told by the file's content first
//! (its signature) and by its extension second; see [`detect_format`]. Only `x y z` are read.
//! Every reader is strict about malformed files (an error naming the file and the problem,
//! with the line for text formats) and never allocates more than the file's size justifies.

#[cfg(test)]
mod corpus;
mod e57;
mod las;
mod pcd;
mod ply;
mod posegraph;
mod xyz;

pub use self::ply::{read_ply, read_ply_bytes, write_ply};
pub use self::posegraph::{pose_graph_json, trajectory_log};

use crate::cloud::PointCloud;
use crate::error::{Error, Result};
use crate::se3::Transform;
use std::fs::File;
use std::io::{BufReader, Cursor, Read, Seek, SeekFrom};
use std::path::Path;

/// One scan read from a file: points, plus the pose stored with it (E57 only) mapping scan
/// coordinates into the file's world frame.
#[derive(Clone, Debug, PartialEq)]
pub struct Scan {
    /// The scan's name: the name stored in the file (E57), else `scan K` (E57 scans without
    /// one, K from 1) or the file's stem (other formats).
    pub name: String,
    /// The points, in the scan's own coordinates (the pose is not applied).
    pub cloud: PointCloud,
    /// The stored pose, `x_world = pose x_scan` (E57 only; `None` when the file stores none).
    pub pose: Option<Transform>,
}

/// The point-cloud file formats [`read_scans`] reads.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Format {
    /// Stanford PLY, ASCII or binary (`.ply`); the `vertex` element's `x y z`.
    Ply,
    /// PCL's PCD, ascii, binary or binary_compressed (`.pcd`); non-finite points are dropped;
    /// a VIEWPOINT other than the default `0 0 0 1 0 0 0` gives the cloud its viewpoint
    /// ([`PointCloud::with_viewpoint`]: the VIEWPOINT's position `tx ty tz`).
    Pcd,
    /// ASTM E57 (`.e57`); every scan with its pose; invalid and non-finite points are dropped.
    E57,
    /// ASPRS LAS or LAZ (`.las`, `.laz`).
    Las,
    /// Text, one point per row, `x y z` first (`.xyz`, `.txt`, `.csv`).
    Xyz,
    /// Leica PTS text: a point count line, then rows like XYZ (`.pts`).
    Pts,
}

/// The formats and extensions, for error messages.
const SUPPORTED: &str = "PLY (.ply), PCD (.pcd), E57 (.e57), LAS/LAZ (.las, .laz), \
    XYZ text (.xyz, .txt, .csv), PTS (.pts)";

/// Bytes of a file's start that [`detect_format`] looks at.
const SIGNATURE_BYTES: usize = 64;

/// Tells a file's format from its first bytes (at least the first 64 when the file has them)
/// and, when they carry no signature, from its extension.
///
/// Signatures: `ply` on the first line (PLY), `ASTM-E57` (E57), `LASF` (LAS and LAZ), a
/// `# .PCD` comment or a `VERSION` line first (PCD). Extensions (case-insensitive): `.ply`,
/// `.pcd`, `.e57`, `.las`, `.laz`, `.xyz`, `.txt`, `.csv`, `.pts`. Anything else is an error
/// listing the supported formats.
pub fn detect_format(path: impl AsRef<Path>, first_bytes: &[u8]) -> Result<Format> {
    let path = path.as_ref();
    let starts = |s: &[u8]| first_bytes.starts_with(s);
    if starts(b"ply\n") || starts(b"ply\r\n") {
        return Ok(Format::Ply);
    }
    if starts(b"ASTM-E57") {
        return Ok(Format::E57);
    }
    if starts(b"LASF") {
        return Ok(Format::Las);
    }
    if starts(b"# .PCD") || starts(b"VERSION") {
        return Ok(Format::Pcd);
    }
    let extension = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    match extension.as_deref() {
        Some("ply") => Ok(Format::Ply),
        Some("pcd") => Ok(Format::Pcd),
        Some("e57") => Ok(Format::E57),
        Some("las" | "laz") => Ok(Format::Las),
        Some("xyz" | "txt" | "csv") => Ok(Format::Xyz),
        Some("pts") => Ok(Format::Pts),
        other => Err(Error::malformed(
            path,
            format!(
                "unknown point-cloud format: the file starts with no known signature and {}; \
                 supported formats: {SUPPORTED}",
                match other {
                    Some(e) => format!("its extension `.{e}` is not a known one"),
                    None => "it has no extension".to_string(),
                }
            ),
        )),
    }
}

/// Extensions of the files a folder given as input contributes (text formats `.txt`/`.csv`
/// are left out: scan folders hold text files that are not clouds, e.g. 3DMatch's
/// `cloud_bin_k.info.txt`; give such clouds by name).
const FOLDER_EXTENSIONS: [&str; 7] = ["ply", "pcd", "e57", "las", "laz", "xyz", "pts"];

/// The point-cloud files of a folder (not its subfolders), by extension
/// (`.ply .pcd .e57 .las .laz .xyz .pts`, any case), in natural order: `cloud_bin_2` before
/// `cloud_bin_10`. An error names the folder when it cannot be read or holds none.
pub fn cloud_files_in(dir: &Path) -> Result<Vec<std::path::PathBuf>> {
    let entries = std::fs::read_dir(dir).map_err(|e| Error::io(dir, e))?;
    let mut files = Vec::new();
    for entry in entries {
        let path = entry.map_err(|e| Error::io(dir, e))?.path();
        let known = path
            .extension()
            .and_then(|e| e.to_str())
            .is_some_and(|e| FOLDER_EXTENSIONS.contains(&e.to_ascii_lowercase().as_str()));
        if known && path.is_file() {
            files.push(path);
        }
    }
    if files.is_empty() {
        return Err(Error::InvalidInput(format!(
            "folder {} holds no point-cloud files (.{})",
            dir.display(),
            FOLDER_EXTENSIONS.join(", .")
        )));
    }
    files.sort_by(|a, b| natural_order(&a.to_string_lossy(), &b.to_string_lossy()));
    Ok(files)
}

/// Compares names with runs of digits compared as numbers (`scan2` < `scan10`).
fn natural_order(a: &str, b: &str) -> std::cmp::Ordering {
    fn chunks(s: &str) -> Vec<(bool, String)> {
        let mut out: Vec<(bool, String)> = Vec::new();
        for c in s.chars() {
            let digit = c.is_ascii_digit();
            match out.last_mut() {
                Some((d, text)) if *d == digit => text.push(c),
                _ => out.push((digit, c.to_string())),
            }
        }
        out
    }
    let (ca, cb) = (chunks(a), chunks(b));
    for ((da, ta), (db, tb)) in ca.iter().zip(&cb) {
        let order = if *da && *db {
            let (na, nb) = (ta.trim_start_matches('0'), tb.trim_start_matches('0'));
            na.len().cmp(&nb.len()).then_with(|| na.cmp(nb))
        } else {
            ta.cmp(tb)
        };
        if order != std::cmp::Ordering::Equal {
            return order;
        }
    }
    ca.len().cmp(&cb.len()).then_with(|| a.cmp(b))
}

/// The name of the single scan of a non-E57 file: the file's stem.
fn stem(path: &Path) -> String {
    path.file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "scan".to_string())
}

fn one_scan(path: &Path, cloud: PointCloud) -> Vec<Scan> {
    vec![Scan {
        name: stem(path),
        cloud,
        pose: None,
    }]
}

/// Reads every scan of a point-cloud file of any supported [`Format`] (told by
/// [`detect_format`]): all the scans of an E57 file, each with its pose; one scan for the
/// other formats.
///
/// Non-finite points are dropped from PCD and E57 files (missing returns of organised
/// sensors; for E57 also points flagged invalid) and kept from the others (registration
/// validates the clouds and reports them).
///
/// A cloud's viewpoint (the scanner's position, [`PointCloud::viewpoint`]) is set only
/// from what a file says: a PCD header's VIEWPOINT when it is not the default
/// `0 0 0 1 0 0 0`. Otherwise it is unknown (`None`).
pub fn read_scans(path: impl AsRef<Path>) -> Result<Vec<Scan>> {
    let path = path.as_ref();
    let mut file = File::open(path).map_err(|e| Error::io(path, e))?;
    let len = file.metadata().map_err(|e| Error::io(path, e))?.len();
    let mut first = Vec::with_capacity(SIGNATURE_BYTES);
    (&mut file)
        .take(SIGNATURE_BYTES as u64)
        .read_to_end(&mut first)
        .map_err(|e| Error::io(path, e))?;
    let format = detect_format(path, &first)?;
    file.seek(SeekFrom::Start(0))
        .map_err(|e| Error::io(path, e))?;
    match format {
        // The binary formats stream from the file.
        Format::E57 => e57::read_e57(path, BufReader::new(file), len),
        Format::Las => Ok(one_scan(
            path,
            las::read_las(path, BufReader::new(file), len)?,
        )),
        _ => {
            let mut bytes = Vec::new();
            file.read_to_end(&mut bytes)
                .map_err(|e| Error::io(path, e))?;
            read_format_bytes(format, path, &bytes)
        }
    }
}

/// [`read_scans`] on bytes already in memory; `path_hint` names the source in errors and its
/// extension helps tell the format.
pub fn read_scans_bytes(path_hint: impl AsRef<Path>, bytes: &[u8]) -> Result<Vec<Scan>> {
    let path = path_hint.as_ref();
    let format = detect_format(path, &bytes[..bytes.len().min(SIGNATURE_BYTES)])?;
    read_format_bytes(format, path, bytes)
}

fn read_format_bytes(format: Format, path: &Path, bytes: &[u8]) -> Result<Vec<Scan>> {
    let cloud = match format {
        Format::Ply => ply::read_ply_bytes(path, bytes)?,
        Format::Pcd => pcd::read_pcd_bytes(path, bytes)?,
        Format::Xyz => xyz::read_xyz_bytes(path, bytes, false)?,
        Format::Pts => xyz::read_xyz_bytes(path, bytes, true)?,
        Format::E57 => return e57::read_e57(path, Cursor::new(bytes), bytes.len() as u64),
        // las needs an owned ('static) source.
        Format::Las => las::read_las(path, Cursor::new(bytes.to_vec()), bytes.len() as u64)?,
    };
    Ok(one_scan(path, cloud))
}

/// Reads the points of a file that holds exactly one scan, of any supported [`Format`]. An
/// E57 file with several scans is an error (use [`read_scans`]); the pose of a single E57
/// scan is not applied (use [`read_scans`] to get it).
pub fn read_points(path: impl AsRef<Path>) -> Result<PointCloud> {
    let path = path.as_ref();
    single(path, read_scans(path)?)
}

fn single(path: &Path, mut scans: Vec<Scan>) -> Result<PointCloud> {
    match scans.len() {
        1 => Ok(scans.remove(0).cloud),
        0 => Err(Error::malformed(path, "the file holds no scan")),
        n => Err(Error::malformed(
            path,
            format!(
                "the file holds {n} scans; read_points reads files of one scan: use read_scans \
                 to read them all (each with its pose)"
            ),
        )),
    }
}

/// A transform as row-major nested lists (for JSON output).
pub fn matrix_rows(t: &Transform) -> [[f64; 4]; 4] {
    let mut rows = [[0.0; 4]; 4];
    for (i, row) in rows.iter_mut().enumerate() {
        for (j, v) in row.iter_mut().enumerate() {
            *v = t[(i, j)];
        }
    }
    rows
}

/// A transform as four aligned lines of text (fixed-width columns, signs lined up).
pub fn matrix_text(t: &Transform) -> String {
    let mut s = String::new();
    for i in 0..4 {
        let row: Vec<String> = (0..4).map(|j| format!("{:>13.9}", t[(i, j)])).collect();
        s.push_str(&row.join(" "));
        s.push('\n');
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_folder_gives_its_cloud_files_in_natural_order() {
        let dir = std::env::temp_dir().join(format!("mtpcr-folder-{}", std::process::id()));
        std::fs::create_dir_all(dir.join("sub.ply")).unwrap();
        for name in [
            "scan10.ply",
            "scan2.PLY",
            "scan1.pcd",
            "scan2.info.txt",
            "notes.md",
        ] {
            std::fs::write(dir.join(name), "x").unwrap();
        }
        let names: Vec<String> = cloud_files_in(&dir)
            .unwrap()
            .iter()
            .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
            .collect();
        assert_eq!(names, ["scan1.pcd", "scan2.PLY", "scan10.ply"]);
        let empty = dir.join("sub.ply");
        let e = cloud_files_in(&empty).unwrap_err().to_string();
        assert!(
            e.contains("holds no point-cloud files") && e.contains("sub.ply"),
            "{e}"
        );
        let e = cloud_files_in(&dir.join("missing"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("missing"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    fn tmp(name: &str) -> std::path::PathBuf {
        let dir = std::env::temp_dir().join(format!("mtpcr-io-mod-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        dir.join(name)
    }

    #[test]
    fn detect_format_reads_signatures_first_then_extensions() {
        let cases: [(&str, &[u8], Format); 14] = [
            ("a.xyz", b"ply\nformat ascii 1.0\n", Format::Ply),
            ("a", b"ply\r\nformat", Format::Ply),
            ("a.ply", b"ASTM-E57\x01\x00", Format::E57),
            ("a.txt", b"LASF\x00\x00", Format::Las),
            ("a.bin", b"# .PCD v0.7\nVERSION 0.7\n", Format::Pcd),
            ("a.bin", b"VERSION .7\nFIELDS x y z\n", Format::Pcd),
            ("a.PLY", b"", Format::Ply),
            ("a.pcd", b"garbage", Format::Pcd),
            ("a.E57", b"", Format::E57),
            ("a.laz", b"", Format::Las),
            ("a.xyz", b"1 2 3\n", Format::Xyz),
            ("a.txt", b"1 2 3\n", Format::Xyz),
            ("a.csv", b"x,y,z\n", Format::Xyz),
            ("a.pts", b"3\n", Format::Pts),
        ];
        for (name, bytes, want) in cases {
            assert_eq!(detect_format(name, bytes).unwrap(), want, "{name}");
        }
        for name in ["scan.obj", "scan"] {
            let e = detect_format(name, b"\x00\x01").unwrap_err().to_string();
            assert!(
                e.contains(name) && e.contains("unknown point-cloud format"),
                "{e}"
            );
            assert!(
                e.contains("PCD (.pcd)") && e.contains("LAS/LAZ") && e.contains(".pts"),
                "{e}"
            );
        }
    }

    #[test]
    fn read_scans_reads_every_format_from_files() {
        // The corpus' seeds, written to files: the E57 and LAS readers stream from the file.
        for (name, bytes, counts) in corpus::seeds() {
            let path = tmp(&format!("file-{name}"));
            std::fs::write(&path, &bytes).unwrap();
            let from_file = read_scans(&path).unwrap_or_else(|e| panic!("{name}: {e}"));
            let from_bytes = read_scans_bytes(&path, &bytes).unwrap();
            assert_eq!(from_file, from_bytes, "{name}");
            let got: Vec<usize> = from_file.iter().map(|s| s.cloud.len()).collect();
            assert_eq!(got, counts, "{name}");
            if counts.len() == 1 {
                assert_eq!(read_points(&path).unwrap(), from_file[0].cloud, "{name}");
                assert_eq!(
                    from_file[0].name,
                    format!("file-{name}").rsplit_once('.').unwrap().0
                );
                assert!(from_file[0].pose.is_none());
            }
        }
    }

    #[test]
    fn read_points_refuses_a_file_of_several_scans_and_says_what_to_use() {
        let path = tmp("several.e57");
        e57::tests::write_e57(&path, &e57::tests::sample_scans());
        let scans = read_scans(&path).unwrap();
        assert_eq!(scans.len(), 3);
        assert_eq!(
            scans.iter().map(|s| s.name.as_str()).collect::<Vec<_>>(),
            ["station A", "station B", "station C"]
        );
        assert!(scans[1].pose.is_some() && scans[2].pose.is_none());
        let e = read_points(&path).unwrap_err().to_string();
        assert!(
            e.contains("several.e57") && e.contains("3 scans") && e.contains("read_scans"),
            "{e}"
        );
        let e = read_scans("/nonexistent/nowhere.e57").unwrap_err();
        assert!(
            matches!(e, Error::Io { .. }) && e.to_string().contains("nowhere.e57"),
            "{e}"
        );
    }

    #[test]
    fn a_pcd_viewpoint_reaches_the_scans_and_points_read() {
        let text = "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 1\n\
            HEIGHT 1\nVIEWPOINT 0.5 -1 2 1 0 0 0\nPOINTS 1\nDATA ascii\n1 2 3\n";
        let path = tmp("viewpoint.pcd");
        std::fs::write(&path, text).unwrap();
        let scans = read_scans(&path).unwrap();
        assert_eq!(scans[0].cloud.viewpoint(), Some([0.5, -1.0, 2.0]));
        assert_eq!(
            read_points(&path).unwrap().viewpoint(),
            Some([0.5, -1.0, 2.0])
        );
        let scans = read_scans_bytes("viewpoint.pcd", text.as_bytes()).unwrap();
        assert_eq!(scans[0].cloud.viewpoint(), Some([0.5, -1.0, 2.0]));
        // Formats that store no viewpoint leave it unknown.
        let scans = read_scans_bytes("a.xyz", b"1 2 3\n4 5 6\n").unwrap();
        assert_eq!(scans[0].cloud.viewpoint(), None);
    }

    #[test]
    fn matrix_text_keeps_columns_aligned() {
        let mut t = Transform::identity();
        t[(1, 0)] = -0.5;
        let text = matrix_text(&t);
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines.len(), 4);
        assert!(lines.iter().all(|l| l.len() == lines[0].len()), "{text}");
        assert!(lines[1].starts_with(" -0.500000000"), "{text}");
    }
}
