//! ASPRS LAS and LAZ (LASzip-compressed LAS) files, read with the `las` crate (its `laz`
//! feature decodes LAZ in pure Rust).
//!
//! Coordinates come back scaled and offset as the header says (LAS stores integers). Points
//! are read in chunks, never all at once from the header's count, and that count is checked
//! against the file's size first. `laz` 0.13 trusts parts of the LAZ header that fuzzing
//! showed can crash it (a chunk count that reserves gigabytes, item sizes that do not match
//! the record, a chunk table that does not cover the points): they are checked here first.
//!
//! Known limit, not fixable outside `laz` 0.13: its GPS-time decoder recurses once per
//! "switch sequence" symbol, and corrupt LAZ data can produce such symbols almost without
//! consuming input, so a corrupt LAZ file can overflow the stack (the process aborts). Valid
//! files and LAS (uncompressed) files are not affected.

use crate::cloud::PointCloud;
use crate::error::{Error, Result};
use std::io::{Read, Seek, SeekFrom};
use std::path::Path;

/// Points decoded per call into `las` (bounded memory per step).
const CHUNK: u64 = 1 << 16;

/// LASzip spends a fraction of a bit on a point that repeats its predecessor; 200 points per
/// byte is far beyond any real file, and a header that claims more is refused before reading.
const MAX_LAZ_POINTS_PER_BYTE: u64 = 200;

/// Reads a little-endian integer of `N` bytes at `at`; `None` past the end.
fn read_at<R: Read + Seek, const N: usize>(source: &mut R, at: u64) -> Option<[u8; N]> {
    let mut buf = [0u8; N];
    source.seek(SeekFrom::Start(at)).ok()?;
    source.read_exact(&mut buf).ok()?;
    Some(buf)
}

/// The `laz` crate reserves memory for the chunk table's declared number of chunks before it
/// reads them (16 bytes each, up to 4 G chunks): check that count against the file's size
/// first. It finds the table as `laz` does: through the offset at the start of the point data,
/// or the one in the file's last 8 bytes when that one is not past the point data's start.
/// Anything else that is wrong is left to `las` and `laz` to report.
fn check_laz_chunk_table<R: Read + Seek>(path: &Path, source: &mut R, len: u64) -> Result<()> {
    let (Some(offset), Some([format_id])) =
        (read_at::<R, 4>(source, 96), read_at::<R, 1>(source, 104))
    else {
        return Ok(());
    };
    if format_id & 0x80 == 0 {
        return Ok(()); // not compressed
    }
    let data_start = u64::from(u32::from_le_bytes(offset));
    let after = |table: Option<[u8; 8]>| {
        table
            .map(i64::from_le_bytes)
            .and_then(|t| u64::try_from(t).ok())
            .filter(|&t| t > data_start)
    };
    let table = after(read_at::<R, 8>(source, data_start)).or_else(|| {
        len.checked_sub(8)
            .and_then(|end| after(read_at::<R, 8>(source, end)))
    });
    if let Some(chunks) = table
        .and_then(|t| read_at::<R, 4>(source, t.saturating_add(4)))
        .map(u32::from_le_bytes)
    {
        if u64::from(chunks) > len {
            return Err(Error::malformed(
                path,
                format!(
                    "the LAZ chunk table declares {chunks} chunks, more than a file of {len} \
                     bytes can hold"
                ),
            ));
        }
    }
    Ok(())
}

/// Checks what `laz` 0.13 trusts without checking (it panics otherwise): that the LAZ items
/// add up to the point record's length, and, for variable-size chunks, that the compressor
/// is a chunked one and that the chunk table covers every declared point.
fn check_laz<R: Read + Seek>(
    path: &Path,
    header: &las::Header,
    source: &mut R,
    declared: u64,
) -> Result<()> {
    let format = header.point_format();
    let record_len = u64::from(format.len());
    let vlr = header
        .laz_vlr()
        .map_err(|e| Error::malformed(path, format!("bad LAZ description: {}", one_line(&e))))?;
    let items: u64 = vlr.items().iter().map(|i| u64::from(i.size())).sum();
    if items != record_len {
        return Err(Error::malformed(
            path,
            format!(
                "the LAZ items add up to {items} bytes per point, but point format {} has \
                 {record_len}",
                format.to_u8().unwrap_or(0)
            ),
        ));
    }
    if vlr.uses_variable_size_chunks() {
        // The compressor type is the LASzip record's first u16 (1: point-wise, unchunked).
        let compressor = header
            .vlrs()
            .iter()
            .find(|v| las::laz::is_laszip_vlr(v))
            .and_then(|v| v.data.get(0..2))
            .map(|b| u16::from_le_bytes([b[0], b[1]]));
        if compressor == Some(1) {
            return Err(Error::malformed(
                path,
                "the LAZ description asks for variable-size chunks without chunks",
            ));
        }
        let data_start = read_at::<R, 4>(source, 96).map(u32::from_le_bytes);
        let table = data_start
            .and_then(|start| source.seek(SeekFrom::Start(u64::from(start))).ok())
            .ok_or_else(|| Error::malformed(path, "the LAZ point data is missing"))
            .and_then(|_| {
                laz::laszip::ChunkTable::read_from(&mut *source, &vlr).map_err(|e| {
                    Error::malformed(
                        path,
                        format!(
                            "variable-size LAZ chunks need a readable chunk table: {}",
                            one_line(&e)
                        ),
                    )
                })
            })?;
        let covered = table
            .as_ref()
            .iter()
            .fold(0u64, |sum, c| sum.saturating_add(c.point_count));
        if covered < declared || table.as_ref().iter().any(|c| c.point_count == 0) {
            return Err(Error::malformed(
                path,
                format!(
                    "the LAZ chunk table covers {covered} points in {} chunks, but the header \
                     declares {declared}",
                    table.len()
                ),
            ));
        }
    }
    Ok(())
}

/// An error's text on one line.
fn one_line(e: &dyn std::fmt::Display) -> String {
    e.to_string().lines().collect::<Vec<_>>().join(" ")
}

/// Reads the points of a LAS or LAZ file from `source` (`len` bytes long); `path` names it in
/// errors.
pub(crate) fn read_las<R: Read + Seek + Send + Sync + 'static>(
    path: &Path,
    mut source: R,
    len: u64,
) -> Result<PointCloud> {
    let las_error =
        |what: &str, e: las::Error| Error::malformed(path, format!("{what}: {}", one_line(&e)));
    let rewind = |source: &mut R| {
        source
            .seek(SeekFrom::Start(0))
            .map(|_| ())
            .map_err(|e| Error::io(path, e))
    };
    // The header's claims are checked before las and laz act on them.
    check_laz_chunk_table(path, &mut source, len)?;
    rewind(&mut source)?;
    let header =
        las::Header::new(&mut source).map_err(|e| las_error("not a valid LAS/LAZ file", e))?;
    let declared = header.number_of_points();
    let format = header.point_format();
    let record_len = u64::from(format.len());
    let fits = if format.is_compressed {
        declared <= len.saturating_mul(MAX_LAZ_POINTS_PER_BYTE)
    } else {
        declared
            .checked_mul(record_len)
            .is_some_and(|bytes| bytes <= len)
    };
    if !fits {
        return Err(Error::malformed(
            path,
            format!(
                "the header declares {declared} points of {record_len} bytes, more than a file \
                 of {len} bytes can hold"
            ),
        ));
    }
    if format.is_compressed {
        check_laz(path, &header, &mut source, declared)?;
    }
    rewind(&mut source)?;
    let mut reader =
        las::Reader::new(source).map_err(|e| las_error("not a valid LAS/LAZ file", e))?;
    let mut points: Vec<[f64; 3]> =
        Vec::with_capacity(usize::try_from(declared.min(CHUNK)).unwrap_or(0));
    while (points.len() as u64) < declared {
        let want = (declared - points.len() as u64).min(CHUNK);
        let data = reader.read_points(want).map_err(|e| {
            las_error(
                &format!(
                    "cannot read points {}..{}",
                    points.len(),
                    points.len() as u64 + want
                ),
                e,
            )
        })?;
        if data.is_empty() {
            return Err(Error::malformed(
                path,
                format!(
                    "the file ends after {} of the {declared} points the header declares",
                    points.len()
                ),
            ));
        }
        points.extend(
            data.x()
                .zip(data.y())
                .zip(data.z())
                .map(|((x, y), z)| [x, y, z]),
        );
    }
    Ok(PointCloud::new(points))
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use las::point::Format;
    use las::{Builder, Point, Transform, Vector, Writer};
    use std::io::Cursor;

    /// Writes points as LAS 1.2 point format 1 (LAZ when `compressed`) with a millimetre
    /// scale and an offset, with the las crate; returns the file's bytes.
    pub(crate) fn write_las(points: &[[f64; 3]], compressed: bool) -> Vec<u8> {
        let mut builder = Builder::from((1, 2));
        builder.point_format = Format::new(1).unwrap();
        builder.point_format.is_compressed = compressed;
        builder.transforms = Vector {
            x: Transform {
                scale: 0.001,
                offset: 1000.0,
            },
            y: Transform {
                scale: 0.001,
                offset: -50.0,
            },
            z: Transform {
                scale: 0.01,
                offset: 0.0,
            },
        };
        let header = builder.into_header().unwrap();
        let mut writer = Writer::new(Cursor::new(Vec::new()), header).unwrap();
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
        writer.into_inner().unwrap().into_inner()
    }

    pub(crate) fn sample() -> Vec<[f64; 3]> {
        (0..3000)
            .map(|i| {
                let t = i as f64;
                [
                    1000.0 + (t * 0.37).sin() * 20.0,
                    -50.0 + t * 0.013,
                    (t * 0.1).cos() * 3.0,
                ]
            })
            .collect()
    }

    fn read(name: &str, bytes: &[u8]) -> Result<PointCloud> {
        read_las(
            Path::new(name),
            Cursor::new(bytes.to_vec()),
            bytes.len() as u64,
        )
    }

    #[test]
    fn las_and_laz_give_back_the_points_to_the_scale() {
        let pts = sample();
        for compressed in [false, true] {
            let bytes = write_las(&pts, compressed);
            let cloud = read(if compressed { "a.laz" } else { "a.las" }, &bytes).unwrap();
            assert_eq!(cloud.len(), pts.len());
            for (a, b) in cloud.points().iter().zip(&pts) {
                // Stored as integers of 1 mm (x, y) and 1 cm (z).
                assert!((a[0] - b[0]).abs() <= 0.0005 + 1e-9, "{a:?} {b:?}");
                assert!((a[1] - b[1]).abs() <= 0.0005 + 1e-9, "{a:?} {b:?}");
                assert!((a[2] - b[2]).abs() <= 0.005 + 1e-9, "{a:?} {b:?}");
            }
        }
        let las = read("a.las", &write_las(&pts, false)).unwrap();
        let laz = read("a.laz", &write_las(&pts, true)).unwrap();
        assert_eq!(las, laz);
    }

    #[test]
    fn broken_files_give_errors_that_name_the_file_and_the_problem() {
        let pts = sample();
        let las = write_las(&pts, false);
        let laz = write_las(&pts, true);
        // Point count at offset 107 (legacy) in a LAS 1.2 header.
        let mut lying = las.clone();
        lying[107..111].copy_from_slice(&u32::MAX.to_le_bytes());
        let mut chunks = laz.clone();
        let data_start = u32::from_le_bytes(laz[96..100].try_into().unwrap()) as usize;
        let table =
            i64::from_le_bytes(laz[data_start..data_start + 8].try_into().unwrap()) as usize;
        chunks[table + 4..table + 8].copy_from_slice(&u32::MAX.to_le_bytes());
        let cases: Vec<(&str, Vec<u8>, &str)> = vec![
            (
                "chunks.laz",
                chunks,
                "the LAZ chunk table declares 4294967295 chunks",
            ),
            ("head.las", las[..50].to_vec(), "not a valid LAS/LAZ file"),
            ("short.las", las[..las.len() - 100].to_vec(), "points"),
            ("count.las", lying, "more than a file of"),
            ("short.laz", laz[..laz.len() / 2].to_vec(), "a.laz"),
        ];
        for (name, bytes, needle) in cases {
            let needle = needle.replace("a.laz", name);
            let e = read(name, &bytes).unwrap_err();
            let msg = e.to_string();
            assert!(matches!(e, Error::MalformedFile { .. }), "{name}: {msg}");
            assert!(msg.contains(name) && msg.contains(&needle), "{name}: {msg}");
        }
    }
}
