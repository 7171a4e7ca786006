//! Files: PLY point clouds (read ASCII and binary, write binary) and transforms out.
//!
//! Real scans are messy. Stanford range scans carry an extra `range_grid` element after the
//! vertices and some have non-standard header lines (`bye`); the reader skips header lines
//! it does not know and reads only the `vertex` element, so they all load.

use crate::cloud::PointCloud;
use crate::error::{Error, Result};
use crate::se3::Transform;
use ply_rs_bw::parser::{Parser, Reader};
use ply_rs_bw::ply::{
    Addable, ElementDef, Encoding, Header, Property, PropertyAccess, PropertyDef, PropertyType,
    ScalarType,
};
use ply_rs_bw::writer::Writer;
use std::io::{BufReader, BufWriter, Cursor, Read, Write};
use std::path::Path;
#[cfg(test)]
use std::path::PathBuf;

/// Header keywords of the PLY format; any other header line is skipped.
const PLY_KEYWORDS: [&str; 6] = [
    "format",
    "comment",
    "obj_info",
    "element",
    "property",
    "end_header",
];

#[derive(Default)]
struct Vertex {
    xyz: [f64; 3],
    rgb: [u8; 3],
}

fn property_as_f64(p: &Property) -> Option<f64> {
    Some(match *p {
        Property::Char(v) => v as f64,
        Property::UChar(v) => v as f64,
        Property::Short(v) => v as f64,
        Property::UShort(v) => v as f64,
        Property::Int(v) => v as f64,
        Property::UInt(v) => v as f64,
        Property::Float(v) => v as f64,
        Property::Double(v) => v,
        _ => return None,
    })
}

impl PropertyAccess for Vertex {
    fn new() -> Self {
        Vertex::default()
    }
    fn set_property(
        &mut self,
        name: &str,
        property: Property,
    ) -> ply_rs_bw::ply::PropertyAccessResult {
        let slot = match name {
            "x" => 0,
            "y" => 1,
            "z" => 2,
            _ => return ply_rs_bw::ply::PropertyAccessResult::Ignored,
        };
        if let Some(v) = property_as_f64(&property) {
            self.xyz[slot] = v;
        }
        ply_rs_bw::ply::PropertyAccessResult::Set
    }
    fn get_double(&self, name: &str) -> Option<f64> {
        match name {
            "x" => Some(self.xyz[0]),
            "y" => Some(self.xyz[1]),
            "z" => Some(self.xyz[2]),
            _ => None,
        }
    }
    fn get_uchar(&self, name: &str) -> Option<u8> {
        match name {
            "red" => Some(self.rgb[0]),
            "green" => Some(self.rgb[1]),
            "blue" => Some(self.rgb[2]),
            _ => None,
        }
    }
}

/// Splits the file into a cleaned header (unknown lines dropped, line ends normalised) and
/// the byte offset where the payload starts.
fn clean_header(path: &Path, bytes: &[u8]) -> Result<(String, usize)> {
    let mut pos = 0usize;
    let mut header = String::new();
    let mut first = true;
    loop {
        let Some(len) = bytes[pos..].iter().position(|&b| b == b'\n') else {
            return Err(Error::malformed(
                path,
                if first {
                    "not a PLY file (it does not start with a `ply` line)".to_string()
                } else {
                    "the PLY header has no `end_header` line".to_string()
                },
            ));
        };
        let raw = &bytes[pos..pos + len];
        pos += len + 1;
        let line = String::from_utf8_lossy(raw);
        let line = line.trim_end_matches('\r').trim();
        if first {
            if line != "ply" {
                return Err(Error::malformed(
                    path,
                    "not a PLY file (it does not start with a `ply` line)",
                ));
            }
            header.push_str("ply\n");
            first = false;
            continue;
        }
        let keyword = line.split_whitespace().next().unwrap_or("");
        if PLY_KEYWORDS.contains(&keyword) {
            header.push_str(line);
            header.push('\n');
            if keyword == "end_header" {
                return Ok((header, pos));
            }
        }
    }
}

/// Reads the `vertex` element's `x y z` of a PLY file (ASCII, binary little or big endian;
/// any scalar type). Other elements and properties are ignored.
pub fn read_ply(path: impl AsRef<Path>) -> Result<PointCloud> {
    let path = path.as_ref();
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    read_ply_bytes(path, &bytes)
}

/// [`read_ply`] on bytes already in memory; `path` only names the source in errors.
pub fn read_ply_bytes(path: &Path, bytes: &[u8]) -> Result<PointCloud> {
    let (header_text, payload_start) = clean_header(path, bytes)?;
    let parser = Parser::<Vertex>::new();
    let source = Cursor::new(header_text.into_bytes()).chain(&bytes[payload_start..]);
    let mut reader = Reader::new(BufReader::new(source));
    let header = parser
        .read_header(&mut reader)
        .map_err(|e| Error::malformed(path, format!("bad PLY header: {e}")))?;
    let Some(vertex_def) = header.elements.get("vertex") else {
        return Err(Error::malformed(
            path,
            "the PLY file has no `vertex` element",
        ));
    };
    for axis in ["x", "y", "z"] {
        match vertex_def.properties.get(axis) {
            Some(PropertyDef {
                data_type: PropertyType::Scalar(_),
                ..
            }) => {}
            Some(_) => {
                return Err(Error::malformed(
                    path,
                    format!("vertex property `{axis}` is a list, not a number"),
                ))
            }
            None => {
                return Err(Error::malformed(
                    path,
                    format!("the vertex element has no `{axis}` property"),
                ))
            }
        }
    }
    // Elements are stored in order: read (and drop) the ones before `vertex`, stop after it.
    for (name, def) in &header.elements {
        let elements = parser
            .read_payload_for_element(&mut reader, def, &header)
            .map_err(|e| Error::malformed(path, format!("bad data in element `{name}`: {e}")))?;
        if name == "vertex" {
            let points = elements.into_iter().map(|v| v.xyz).collect();
            return Ok(PointCloud::new(points));
        }
    }
    Err(Error::malformed(
        path,
        "the PLY file has no `vertex` element",
    ))
}

/// Writes points (and optional per-point RGB colours) as a binary little-endian PLY file with
/// double coordinates. The file is created or truncated.
pub fn write_ply(
    path: impl AsRef<Path>,
    points: &[[f64; 3]],
    colors: Option<&[[u8; 3]]>,
) -> Result<()> {
    let path = path.as_ref();
    if let Some(c) = colors {
        if c.len() != points.len() {
            return Err(Error::InvalidInput(format!(
                "{} colours given for {} points",
                c.len(),
                points.len()
            )));
        }
    }
    let mut header = Header::new();
    header.encoding = Encoding::BinaryLittleEndian;
    header.comments.push("written by mtpcr".to_string());
    let mut vertex = ElementDef::new("vertex".to_string());
    vertex.count = points.len();
    for axis in ["x", "y", "z"] {
        vertex.properties.add(PropertyDef::new(
            axis.to_string(),
            PropertyType::Scalar(ScalarType::Double),
        ));
    }
    if colors.is_some() {
        for ch in ["red", "green", "blue"] {
            vertex.properties.add(PropertyDef::new(
                ch.to_string(),
                PropertyType::Scalar(ScalarType::UChar),
            ));
        }
    }
    header.elements.add(vertex.clone());
    let elements: Vec<Vertex> = points
        .iter()
        .enumerate()
        .map(|(i, p)| Vertex {
            xyz: *p,
            rgb: colors.map_or([0; 3], |c| c[i]),
        })
        .collect();
    let file = std::fs::File::create(path).map_err(|e| Error::io(path, e))?;
    let mut out = BufWriter::new(file);
    let writer = Writer::<Vertex>::new();
    writer
        .write_header(&mut out, &header)
        .and_then(|_| writer.write_payload_of_element(&mut out, &elements, &vertex, &header))
        .map_err(|e| Error::io(path, e))?;
    out.flush().map_err(|e| Error::io(path, e))
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

    fn tmp(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("mtpcr-io-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        dir.join(name)
    }

    #[test]
    fn reads_a_stanford_style_ascii_file_with_bye_lines_and_range_grid() {
        let text = "ply\nformat ascii 1.0\nobj_info num_cols 2\nbye\nbye\nelement vertex 3\n\
            property float x\nproperty float y\nproperty float z\nelement range_grid 4\n\
            property list uchar int vertex_indices\nend_header\n\
            0.5 1 2 \n3 4 5 \n-1e-3 0 7.25 \n1 0\n0\n1 1\n1 2\n";
        let p = tmp("stanford.ply");
        std::fs::write(&p, text).unwrap();
        let c = read_ply(&p).unwrap();
        assert_eq!(
            c.points(),
            &[
                [0.5, 1.0, 2.0],
                [3.0, 4.0, 5.0],
                [-1e-3f32 as f64, 0.0, 7.25]
            ]
        );
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

    #[test]
    fn binary_round_trip_with_colours() {
        let pts = vec![[0.1, 0.2, 0.3], [-1.0, 1e-9, 12345.678901234]];
        let p = tmp("rt.ply");
        write_ply(&p, &pts, Some(&[[255, 0, 0], [0, 0, 255]])).unwrap();
        assert_eq!(read_ply(&p).unwrap().points(), &pts[..]);
    }

    #[test]
    fn reads_binary_float_little_endian() {
        let mut bytes = b"ply\r\nformat binary_little_endian 1.0\r\ncomment x\r\nelement vertex 2\r\nproperty float x\r\nproperty float y\r\nproperty float z\r\nend_header\n".to_vec();
        for v in [1.0f32, 2.0, 3.0, 4.0, 5.0, 6.5] {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
        let c = read_ply_bytes(Path::new("mem.ply"), &bytes).unwrap();
        assert_eq!(c.points(), &[[1.0, 2.0, 3.0], [4.0, 5.0, 6.5]]);
    }

    #[test]
    fn errors_name_the_file_and_the_problem() {
        let e = read_ply("/nonexistent/nowhere.ply").unwrap_err();
        assert!(
            matches!(e, Error::Io { .. }) && e.to_string().contains("nowhere.ply"),
            "{e}"
        );
        let cases: [(&str, &[u8], &str); 5] = [
            ("notply.ply", b"hello\nworld\n", "not a PLY file"),
            ("noend.ply", b"ply\nformat ascii 1.0\nelement vertex 1\n", "end_header"),
            ("novertex.ply", b"ply\nformat ascii 1.0\nelement face 0\nproperty list uchar int v\nend_header\n", "no `vertex`"),
            ("noz.ply", b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nend_header\n1 2\n", "`z`"),
            ("short.ply", b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nend_header\n1 2 3\n", "vertex"),
        ];
        for (name, bytes, needle) in cases {
            let e = read_ply_bytes(Path::new(name), bytes).unwrap_err();
            let msg = e.to_string();
            assert!(matches!(e, Error::MalformedFile { .. }), "{name}: {msg}");
            assert!(msg.contains(name) && msg.contains(needle), "{name}: {msg}");
        }
        let trunc = b"ply\nformat binary_little_endian 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\nend_header\n\x00\x00";
        assert!(read_ply_bytes(Path::new("trunc.ply"), trunc).is_err());
    }
}
