//! PCD point clouds (PCL's format: `ascii`, `binary` and `binary_compressed` data), read with
//! the `pcd-rs` crate.
//!
//! Only the `x y z` fields are read (any numeric type, as f64). Points with a non-finite
//! coordinate are dropped: organised sensors store NaN points for missing returns. The header
//! is checked against the file's size before any data is read, so a header count cannot make
//! the reader allocate more than the file can hold.
//!
//! The header's `VIEWPOINT tx ty tz qw qx qy qz` (the sensor's pose in the cloud's frame)
//! gives the cloud its viewpoint ([`PointCloud::with_viewpoint`]): its position `tx ty tz`.
//! The default `0 0 0 1 0 0 0` means "not given" (PCL writes it for every file, maps in a
//! world frame included) and leaves the viewpoint unknown.

use crate::cloud::PointCloud;
use crate::error::{Error, Result};
use pcd_rs::{DataKind, DynReader, Field, PcdMeta, ViewPoint};
use std::io::Cursor;
use std::path::Path;

/// The best LZF can do is about 88 output bytes per input byte (a 264-byte back reference
/// takes 3 bytes); a larger claimed ratio is a corrupt header.
const MAX_LZF_RATIO: u64 = 90;

fn first_value(field: &Field) -> Option<f64> {
    Some(match field {
        Field::I8(v) => *v.first()? as f64,
        Field::I16(v) => *v.first()? as f64,
        Field::I32(v) => *v.first()? as f64,
        Field::I64(v) => *v.first()? as f64,
        Field::U8(v) => *v.first()? as f64,
        Field::U16(v) => *v.first()? as f64,
        Field::U32(v) => *v.first()? as f64,
        Field::U64(v) => *v.first()? as f64,
        Field::F32(v) => *v.first()? as f64,
        Field::F64(v) => *v.first()?,
    })
}

/// `pcd-rs`' error text, on one line and without its "parsing error at line" prefix when it
/// gives no useful line.
fn describe(e: &pcd_rs::Error) -> String {
    e.to_string().lines().collect::<Vec<_>>().join(" ")
}

/// The scanner's position from a header's VIEWPOINT: its translation, or `None` for the
/// default `0 0 0 1 0 0 0` ("not given"). A non-finite value is an error naming the file.
fn viewpoint(path: &Path, vp: &ViewPoint) -> Result<Option<[f64; 3]>> {
    let values = [vp.tx, vp.ty, vp.tz, vp.qw, vp.qx, vp.qy, vp.qz];
    if values.iter().any(|v| !v.is_finite()) {
        return Err(Error::malformed(
            path,
            format!(
                "the PCD header's VIEWPOINT must hold 7 finite numbers (tx ty tz qw qx qy qz), \
                 got {}",
                values.map(|v| v.to_string()).join(" ")
            ),
        ));
    }
    Ok((*vp != ViewPoint::default()).then_some([vp.tx, vp.ty, vp.tz]))
}

/// Reads a PCD file held in `bytes`; `path` names it in errors.
///
/// The cloud's viewpoint is the position (`tx ty tz`) of the header's `VIEWPOINT tx ty tz qw
/// qx qy qz` when that is not the default `0 0 0 1 0 0 0`; with the default (which PCL
/// writes for every file) or no VIEWPOINT line it is unknown (`None`). A VIEWPOINT with a
/// non-finite value is an error.
pub(crate) fn read_pcd_bytes(path: &Path, bytes: &[u8]) -> Result<PointCloud> {
    let mut cursor = Cursor::new(bytes);
    let meta = PcdMeta::from_reader(&mut cursor)
        .map_err(|e| Error::malformed(path, format!("bad PCD header: {}", describe(&e))))?;
    let viewpoint = viewpoint(path, &meta.viewpoint)?;
    let data_start = usize::try_from(cursor.position()).unwrap_or(usize::MAX);
    let header_lines = bytes[..data_start.min(bytes.len())]
        .iter()
        .filter(|&&b| b == b'\n')
        .count();
    let available = bytes.len().saturating_sub(data_start) as u64;

    // Where x, y and z are in a record (padding fields `_` are not returned by pcd-rs).
    let fields: Vec<_> = meta.field_defs.iter().filter(|f| !f.is_padding()).collect();
    let mut slots = [0usize; 3];
    for (slot, axis) in slots.iter_mut().zip(["x", "y", "z"]) {
        let Some(index) = fields.iter().position(|f| f.name == axis) else {
            return Err(Error::malformed(
                path,
                format!("the PCD file has no `{axis}` field"),
            ));
        };
        if fields[index].count != 1 {
            return Err(Error::malformed(
                path,
                format!(
                    "the PCD field `{axis}` has COUNT {}; a coordinate needs 1",
                    fields[index].count
                ),
            ));
        }
        *slot = index;
    }

    // Sizes from the header, checked against the file before pcd-rs reads (and allocates).
    let too_big = || {
        Error::malformed(
            path,
            "the PCD header's SIZE/COUNT/POINTS describe more data than any file can hold",
        )
    };
    let mut record_size = 0u64;
    let mut values_per_row = 0u64;
    for f in meta.field_defs.iter() {
        record_size = (f.kind.byte_size() as u64)
            .checked_mul(f.count)
            .and_then(|s| s.checked_add(record_size))
            .ok_or_else(too_big)?;
        values_per_row = values_per_row.checked_add(f.count).ok_or_else(too_big)?;
    }
    let data_size = record_size
        .checked_mul(meta.num_points)
        .ok_or_else(too_big)?;
    match meta.data {
        DataKind::Ascii => {
            // A row of n values takes at least 2n - 1 bytes.
            if meta.num_points > 0 && values_per_row > available.saturating_add(1) / 2 {
                return Err(Error::malformed(
                    path,
                    format!(
                        "the PCD header declares {values_per_row} values per point, more than \
                         the {available} bytes of data can hold"
                    ),
                ));
            }
        }
        DataKind::Binary => {
            if data_size > available {
                return Err(Error::malformed(
                    path,
                    format!(
                        "the binary data is too short: POINTS {} of {record_size} bytes need \
                         {data_size} bytes, but {available} follow the header",
                        meta.num_points
                    ),
                ));
            }
        }
        DataKind::BinaryCompressed => {
            let data = &bytes[data_start.min(bytes.len())..];
            let (Some(c), Some(u)) = (data.get(0..4), data.get(4..8)) else {
                return Err(Error::malformed(
                    path,
                    "the compressed PCD data is missing its size words",
                ));
            };
            let compressed = u32::from_le_bytes([c[0], c[1], c[2], c[3]]) as u64;
            let uncompressed = u32::from_le_bytes([u[0], u[1], u[2], u[3]]) as u64;
            if compressed > available - 8 {
                return Err(Error::malformed(
                    path,
                    format!(
                        "the compressed PCD data is too short: {compressed} bytes declared, {} \
                         present",
                        available - 8
                    ),
                ));
            }
            if uncompressed != data_size {
                return Err(Error::malformed(
                    path,
                    format!(
                        "the compressed PCD data unpacks to {uncompressed} bytes, but POINTS {} \
                         of {record_size} bytes need {data_size}",
                        meta.num_points
                    ),
                ));
            }
            if uncompressed > compressed.saturating_mul(MAX_LZF_RATIO) {
                return Err(Error::malformed(
                    path,
                    format!(
                        "the compressed PCD data claims to unpack {compressed} bytes into \
                         {uncompressed}, more than LZF can"
                    ),
                ));
            }
        }
    }

    let reader = DynReader::from_bytes(bytes)
        .map_err(|e| Error::malformed(path, format!("bad PCD data: {}", describe(&e))))?;
    let count = usize::try_from(meta.num_points).unwrap_or(usize::MAX);
    let mut points = Vec::with_capacity(count.min(bytes.len() / 6 + 1));
    for (index, record) in reader.enumerate() {
        let record = record.map_err(|e| {
            let what = match (&e, meta.data) {
                (pcd_rs::Error::TextTokenMismatchError { found: 0, .. }, DataKind::Ascii) => {
                    format!(
                        "an empty row, or the end of the file after {index} of the {} points \
                         the header declares",
                        meta.num_points
                    )
                }
                (pcd_rs::Error::TextTokenMismatchError { expect, found }, DataKind::Ascii) => {
                    format!("a point row has {found} values, but the header declares {expect}")
                }
                _ => describe(&e),
            };
            match meta.data {
                DataKind::Ascii => {
                    Error::malformed(path, format!("line {}: {what}", header_lines + index + 1))
                }
                _ => Error::malformed(path, format!("bad data at point {index}: {what}")),
            }
        })?;
        let value = |slot: usize| record.0.get(slot).and_then(first_value);
        let (Some(x), Some(y), Some(z)) = (value(slots[0]), value(slots[1]), value(slots[2]))
        else {
            return Err(Error::malformed(
                path,
                format!("point {index} lacks a coordinate"),
            ));
        };
        // NaN points are missing returns of organised sensors: dropped.
        if x.is_finite() && y.is_finite() && z.is_finite() {
            points.push([x, y, z]);
        }
    }
    let cloud = PointCloud::new(points);
    Ok(match viewpoint {
        Some(v) => cloud.with_viewpoint(v),
        None => cloud,
    })
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use pcd_rs::{DynRecord, DynWriter, Schema, ValueKind, WriterInit};

    fn tmp(name: &str) -> std::path::PathBuf {
        let dir = std::env::temp_dir().join(format!("mtpcr-io-pcd-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        dir.join(name)
    }

    /// Writes `points` as x y z (f32) plus an intensity field with pcd-rs.
    pub(crate) fn write_pcd(path: &Path, kind: DataKind, points: &[[f32; 3]]) {
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

    pub(crate) fn sample() -> Vec<[f32; 3]> {
        (0..500)
            .map(|i| {
                let t = i as f32 * 0.37;
                [t.sin() * 3.0, t.cos() * -2.0 + 0.125, t * 0.01 - 1.5]
            })
            .collect()
    }

    #[test]
    fn ascii_binary_and_compressed_give_back_the_points() {
        let mut pts = sample();
        pts[7] = [f32::NAN, f32::NAN, f32::NAN]; // a missing return
        pts[9][2] = f32::INFINITY;
        let expected: Vec<[f64; 3]> = pts
            .iter()
            .filter(|p| p.iter().all(|v| v.is_finite()))
            .map(|p| [p[0] as f64, p[1] as f64, p[2] as f64])
            .collect();
        assert_eq!(expected.len(), 498);
        for (name, kind) in [
            ("a.pcd", DataKind::Ascii),
            ("b.pcd", DataKind::Binary),
            ("c.pcd", DataKind::BinaryCompressed),
        ] {
            let path = tmp(name);
            write_pcd(&path, kind, &pts);
            let bytes = std::fs::read(&path).unwrap();
            let cloud = read_pcd_bytes(&path, &bytes).unwrap();
            if kind == DataKind::Ascii {
                // Text keeps f32 precision only up to its printed digits.
                assert_eq!(cloud.len(), expected.len());
                for (a, b) in cloud.points().iter().zip(&expected) {
                    for k in 0..3 {
                        assert!(
                            (a[k] - b[k]).abs() <= 1e-6 * b[k].abs().max(1.0),
                            "{a:?} {b:?}"
                        );
                    }
                }
            } else {
                assert_eq!(cloud.points(), &expected[..], "{name}");
            }
        }
    }

    #[test]
    fn reads_a_hand_written_file_with_padding_double_and_comments() {
        let text = "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS _ x y z\n\
            SIZE 1 8 8 8\nTYPE U F F F\nCOUNT 1 1 1 1\nWIDTH 2\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\n\
            POINTS 2\nDATA ascii\r\n7 0.1 0.2 0.3\r\n7 -1e300 2 3\r\n";
        let c = read_pcd_bytes(Path::new("pad.pcd"), text.as_bytes()).unwrap();
        assert_eq!(c.points(), &[[0.1, 0.2, 0.3], [-1e300, 2.0, 3.0]]);
    }

    /// A small ascii PCD file with the given VIEWPOINT line (none when `None`).
    fn with_viewpoint_line(viewpoint: Option<&str>) -> String {
        let line = viewpoint.map_or(String::new(), |v| format!("VIEWPOINT {v}\n"));
        format!(
            "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 2\n\
             HEIGHT 1\n{line}POINTS 2\nDATA ascii\n1 2 3\n4 5 6\n"
        )
    }

    #[test]
    fn a_non_default_viewpoint_gives_the_clouds_viewpoint() {
        let cases: [(Option<&str>, Option<[f64; 3]>); 6] = [
            (Some("1.5 -2 0.25 1 0 0 0"), Some([1.5, -2.0, 0.25])),
            // A rotated sensor at the origin is a given viewpoint too.
            (Some("0 0 0 0.7071068 0 0.7071068 0"), Some([0.0, 0.0, 0.0])),
            (Some("3 4 5 0.5 0.5 0.5 0.5"), Some([3.0, 4.0, 5.0])),
            // The default (PCL writes it for every file) and no line at all: not given.
            (Some("0 0 0 1 0 0 0"), None),
            (Some("0.0 0.0 0.0 1.0 0.0 0.0 0.0"), None),
            (None, None),
        ];
        for (line, want) in cases {
            let text = with_viewpoint_line(line);
            let c = read_pcd_bytes(Path::new("vp.pcd"), text.as_bytes()).unwrap();
            assert_eq!(c.viewpoint(), want, "VIEWPOINT {line:?}");
            assert_eq!(c.points(), &[[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]);
        }
        // Written by pcd-rs in binary: the viewpoint survives the round trip.
        let path = tmp("viewpoint.pcd");
        let mut writer: DynWriter<_> = WriterInit {
            width: 1,
            height: 1,
            viewpoint: ViewPoint {
                tx: -0.5,
                ty: 7.0,
                tz: 1e3,
                ..Default::default()
            },
            data_kind: DataKind::Binary,
            schema: Some(Schema::from_iter([
                ("x", ValueKind::F32, 1),
                ("y", ValueKind::F32, 1),
                ("z", ValueKind::F32, 1),
            ])),
            version: None,
        }
        .create(&path)
        .unwrap();
        let record = DynRecord(vec![
            Field::F32(vec![1.0]),
            Field::F32(vec![2.0]),
            Field::F32(vec![3.0]),
        ]);
        writer.push(&record).unwrap();
        writer.finish().unwrap();
        let bytes = std::fs::read(&path).unwrap();
        let c = read_pcd_bytes(&path, &bytes).unwrap();
        assert_eq!(c.viewpoint(), Some([-0.5, 7.0, 1e3]));
        // The files written with the default VIEWPOINT leave it unknown.
        let path = tmp("default-viewpoint.pcd");
        write_pcd(&path, DataKind::Binary, &sample());
        let c = read_pcd_bytes(&path, &std::fs::read(&path).unwrap()).unwrap();
        assert_eq!(c.viewpoint(), None);
    }

    #[test]
    fn a_non_finite_viewpoint_is_an_error_naming_it() {
        for line in ["nan 0 0 1 0 0 0", "0 inf 0 1 0 0 0", "0 0 0 NaN 0 0 0"] {
            let text = with_viewpoint_line(Some(line));
            let e = read_pcd_bytes(Path::new("badvp.pcd"), text.as_bytes()).unwrap_err();
            let msg = e.to_string();
            assert!(matches!(e, Error::MalformedFile { .. }), "{line}: {msg}");
            assert!(
                msg.contains("badvp.pcd") && msg.contains("VIEWPOINT must hold 7 finite"),
                "{line}: {msg}"
            );
        }
    }

    /// Malformed PCD files, each with a piece of the message it must give. Shared with the
    /// regression corpus.
    pub(crate) fn malformed_cases() -> Vec<(&'static str, Vec<u8>, &'static str)> {
        let head = |fields: &str, points: u64, data: &str| {
            format!(
                "VERSION 0.7\nFIELDS {fields}\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH {points}\n\
                 HEIGHT 1\nPOINTS {points}\nDATA {data}\n"
            )
        };
        let mut short_binary = head("x y z", 3, "binary").into_bytes();
        short_binary.extend_from_slice(&[0u8; 20]);
        let mut huge_binary = head("x y z", u64::MAX / 4, "binary").into_bytes();
        huge_binary.extend_from_slice(&[0u8; 12]);
        let mut lying_lzf = head("x y z", 1000, "binary_compressed").into_bytes();
        lying_lzf.extend_from_slice(&4u32.to_le_bytes());
        lying_lzf.extend_from_slice(&12000u32.to_le_bytes());
        lying_lzf.extend_from_slice(&[0, 0, 0, 0]);
        let mut wrong_size_lzf = head("x y z", 2, "binary_compressed").into_bytes();
        wrong_size_lzf.extend_from_slice(&2u32.to_le_bytes());
        wrong_size_lzf.extend_from_slice(&12u32.to_le_bytes());
        wrong_size_lzf.extend_from_slice(&[0, 0]);
        let mut no_words = head("x y z", 2, "binary_compressed").into_bytes();
        no_words.extend_from_slice(&[1, 2, 3]);
        let cases: Vec<(&str, Vec<u8>, &str)> = vec![
            (
                "nover.pcd",
                b"FIELDS x y z\nDATA ascii\n".to_vec(),
                "bad PCD header",
            ),
            (
                "noz.pcd",
                head("x y w", 1, "ascii").into_bytes(),
                "no `z` field",
            ),
            ("short.pcd", short_binary, "binary data is too short"),
            ("huge.pcd", huge_binary, "more data than any file can hold"),
            ("lzf-ratio.pcd", lying_lzf, "more than LZF can"),
            (
                "lzf-size.pcd",
                wrong_size_lzf,
                "unpacks to 12 bytes, but POINTS 2",
            ),
            ("lzf-words.pcd", no_words, "missing its size words"),
            (
                "extra.pcd",
                (head("x y z", 2, "ascii") + "1 2 3\n4 5 6 7\n").into_bytes(),
                "line 11: a point row has 4 values, but the header declares 3",
            ),
            (
                "few.pcd",
                (head("x y z", 3, "ascii") + "1 2 3\n").into_bytes(),
                "line 11: an empty row, or the end of the file after 1 of the 3 points",
            ),
            (
                "word.pcd",
                (head("x y z", 1, "ascii") + "1 two 3\n").into_bytes(),
                "line 10: invalid float literal",
            ),
        ];
        cases
    }

    #[test]
    fn malformed_files_give_errors_that_name_the_file_and_the_problem() {
        for (name, bytes, needle) in malformed_cases() {
            let e = read_pcd_bytes(Path::new(name), &bytes).unwrap_err();
            let msg = e.to_string();
            assert!(matches!(e, Error::MalformedFile { .. }), "{name}: {msg}");
            assert!(msg.contains(name) && msg.contains(needle), "{name}: {msg}");
            assert!(!msg.contains('\n'), "{name}: {msg}");
        }
    }
}
