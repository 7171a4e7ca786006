//! PLY point clouds: read ASCII and binary (both byte orders, any scalar type), write binary.
//!
//! Real scans are messy. Stanford range scans carry an extra `range_grid` element after the
//! vertices and some have non-standard header lines (`bye`); the reader skips header lines it
//! does not know, so they all load. It is strict about everything else: a property or element
//! declared twice, a data row with more or fewer values than the header declares, rows after
//! the last declared one (ASCII) and data shorter than the header's counts are errors whose
//! one-line message gives the line of the original file where there is one. Allocations are
//! bounded by the file's size, whatever the header's counts say.
//!
//! The header is read here; binary payloads are decoded by `ply-rs-bw`, ASCII payloads row by
//! row here (so that every row's value count can be checked against the header).

use crate::cloud::PointCloud;
use crate::error::{Error, Result};
use ply_rs_bw::parser::{Parser, Reader};
use ply_rs_bw::ply::{
    Addable, ElementDef, Encoding, Header, Property, PropertyAccess, PropertyDef, PropertyType,
    ScalarType,
};
use ply_rs_bw::writer::Writer;
use std::io::{BufWriter, Cursor, Write};
use std::path::Path;

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

/// One `element` of the header, with the line that declared it.
struct ElementInfo {
    def: ElementDef,
    line: usize,
}

/// The parsed header: encoding, elements in file order, where the payload starts.
struct PlyHeader {
    encoding: Encoding,
    elements: Vec<ElementInfo>,
    /// Byte offset of the payload.
    data_start: usize,
    /// Line number (1-based, of the original file) of the first payload line.
    data_line: usize,
}

/// The next line of `bytes` from `pos`: its content without the line end and where the next
/// line starts; `None` at the end of the data. A last line without `\n` counts as a line.
fn next_line(bytes: &[u8], pos: usize) -> Option<(&[u8], usize)> {
    if pos >= bytes.len() {
        return None;
    }
    let rest = &bytes[pos..];
    match rest.iter().position(|&b| b == b'\n') {
        Some(len) => Some((&rest[..len], pos + len + 1)),
        None => Some((rest, bytes.len())),
    }
}

fn scalar_type(name: &str) -> Option<ScalarType> {
    Some(match name {
        "char" | "int8" => ScalarType::Char,
        "uchar" | "uint8" => ScalarType::UChar,
        "short" | "int16" => ScalarType::Short,
        "ushort" | "uint16" => ScalarType::UShort,
        "int" | "int32" => ScalarType::Int,
        "uint" | "uint32" => ScalarType::UInt,
        "float" | "float32" => ScalarType::Float,
        "double" | "float64" => ScalarType::Double,
        _ => return None,
    })
}

fn scalar_size(t: &ScalarType) -> usize {
    match t {
        ScalarType::Char | ScalarType::UChar => 1,
        ScalarType::Short | ScalarType::UShort => 2,
        ScalarType::Int | ScalarType::UInt | ScalarType::Float => 4,
        ScalarType::Double => 8,
    }
}

fn scalar_name(t: &ScalarType) -> &'static str {
    match t {
        ScalarType::Char => "char",
        ScalarType::UChar => "uchar",
        ScalarType::Short => "short",
        ScalarType::UShort => "ushort",
        ScalarType::Int => "int",
        ScalarType::UInt => "uint",
        ScalarType::Float => "float",
        ScalarType::Double => "double",
    }
}

/// Reads the header. Lines with a keyword PLY does not define are skipped; everything else
/// must be well formed.
fn parse_header(path: &Path, bytes: &[u8]) -> Result<PlyHeader> {
    let err = |line: usize, msg: String| Error::malformed(path, format!("line {line}: {msg}"));
    let mut pos = 0usize;
    let mut line_no = 0usize;
    let mut encoding: Option<Encoding> = None;
    let mut elements: Vec<ElementInfo> = Vec::new();
    // (element index, property name) -> declaring line, to report duplicates.
    let mut property_lines: Vec<Vec<(String, usize)>> = Vec::new();
    loop {
        let Some((raw, next)) = next_line(bytes, pos) else {
            return Err(Error::malformed(
                path,
                if line_no == 0 {
                    "not a PLY file (it does not start with a `ply` line)"
                } else {
                    "the PLY header has no `end_header` line"
                },
            ));
        };
        pos = next;
        line_no += 1;
        let text = String::from_utf8_lossy(raw);
        let line = text.trim();
        if line_no == 1 {
            if line != "ply" {
                return Err(Error::malformed(
                    path,
                    "not a PLY file (it does not start with a `ply` line)",
                ));
            }
            continue;
        }
        let tokens: Vec<&str> = line.split_ascii_whitespace().collect();
        let Some(&keyword) = tokens.first() else {
            continue;
        };
        match keyword {
            "comment" | "obj_info" => {}
            "format" => {
                if encoding.is_some() {
                    return Err(err(line_no, "a second `format` line".into()));
                }
                let enc = match tokens.get(1).copied() {
                    Some("ascii") => Encoding::Ascii,
                    Some("binary_little_endian") => Encoding::BinaryLittleEndian,
                    Some("binary_big_endian") => Encoding::BinaryBigEndian,
                    _ => {
                        return Err(err(
                            line_no,
                            format!(
                                "unknown format `{line}` (expected ascii, binary_little_endian \
                                 or binary_big_endian)"
                            ),
                        ))
                    }
                };
                let version_ok = tokens.len() == 3
                    && tokens[2].split_once('.').is_some_and(|(a, b)| {
                        !a.is_empty()
                            && !b.is_empty()
                            && a.bytes().all(|c| c.is_ascii_digit())
                            && b.bytes().all(|c| c.is_ascii_digit())
                    });
                if !version_ok {
                    return Err(err(
                        line_no,
                        format!("bad `format` line `{line}` (expected e.g. `format ascii 1.0`)"),
                    ));
                }
                encoding = Some(enc);
            }
            "element" => {
                if tokens.len() != 3 {
                    return Err(err(
                        line_no,
                        format!("bad `element` line `{line}` (expected `element NAME COUNT`)"),
                    ));
                }
                let name = tokens[1];
                let Ok(count) = tokens[2].parse::<usize>() else {
                    return Err(err(
                        line_no,
                        format!("element `{name}` has a bad count `{}`", tokens[2]),
                    ));
                };
                if let Some(first) = elements.iter().find(|e| e.def.name == name) {
                    return Err(err(
                        line_no,
                        format!(
                            "element `{name}` is declared twice (first on line {})",
                            first.line
                        ),
                    ));
                }
                let mut def = ElementDef::new(name.to_string());
                def.count = count;
                elements.push(ElementInfo { def, line: line_no });
                property_lines.push(Vec::new());
            }
            "property" => {
                let (Some(element), Some(seen)) = (elements.last_mut(), property_lines.last_mut())
                else {
                    return Err(err(
                        line_no,
                        "a `property` line before any `element`".into(),
                    ));
                };
                let (data_type, name) = match tokens.as_slice() {
                    [_, "list", count_type, item_type, name] => {
                        let (Some(c), Some(i)) = (scalar_type(count_type), scalar_type(item_type))
                        else {
                            return Err(err(line_no, format!("unknown type in `{line}`")));
                        };
                        if matches!(c, ScalarType::Float | ScalarType::Double) {
                            return Err(err(
                                line_no,
                                format!("a list count must be an integer type in `{line}`"),
                            ));
                        }
                        (PropertyType::List(c, i), *name)
                    }
                    [_, ty, name] => {
                        let Some(t) = scalar_type(ty) else {
                            return Err(err(line_no, format!("unknown type in `{line}`")));
                        };
                        (PropertyType::Scalar(t), *name)
                    }
                    _ => {
                        return Err(err(
                            line_no,
                            format!(
                                "bad `property` line `{line}` (expected `property TYPE NAME` or \
                                 `property list COUNT_TYPE ITEM_TYPE NAME`)"
                            ),
                        ))
                    }
                };
                if let Some((_, first)) = seen.iter().find(|(n, _)| n == name) {
                    return Err(err(
                        line_no,
                        format!(
                            "property `{name}` of element `{}` is declared twice (first on line \
                             {first})",
                            element.def.name
                        ),
                    ));
                }
                seen.push((name.to_string(), line_no));
                element
                    .def
                    .properties
                    .add(PropertyDef::new(name.to_string(), data_type));
            }
            "end_header" => {
                if tokens.len() != 1 {
                    return Err(err(line_no, format!("bad `end_header` line `{line}`")));
                }
                let Some(encoding) = encoding else {
                    return Err(Error::malformed(
                        path,
                        "the PLY header has no `format` line",
                    ));
                };
                return Ok(PlyHeader {
                    encoding,
                    elements,
                    data_start: pos,
                    data_line: line_no + 1,
                });
            }
            // Non-standard header lines (Stanford's `bye`) are skipped.
            _ => {}
        }
    }
}

/// Reads the `vertex` element's `x y z` of a PLY file (ASCII, binary little or big endian;
/// any scalar type). Values of other properties and elements are not kept, but in ASCII files
/// every row of every element must match the header (no missing or extra values, nothing but
/// white space after the last row). Header lines with unknown keywords (Stanford's `bye`) are
/// skipped; errors give the line of the file where there is one.
pub fn read_ply(path: impl AsRef<Path>) -> Result<PointCloud> {
    let path = path.as_ref();
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    read_ply_bytes(path, &bytes)
}

/// [`read_ply`] on bytes already in memory; `path` only names the source in errors.
pub fn read_ply_bytes(path: &Path, bytes: &[u8]) -> Result<PointCloud> {
    let header = parse_header(path, bytes)?;
    let Some(vertex_index) = header.elements.iter().position(|e| e.def.name == "vertex") else {
        return Err(Error::malformed(
            path,
            "the PLY file has no `vertex` element",
        ));
    };
    let vertex_def = &header.elements[vertex_index].def;
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
    let points = match header.encoding {
        Encoding::Ascii => read_ascii(path, bytes, &header, vertex_index)?,
        Encoding::BinaryLittleEndian | Encoding::BinaryBigEndian => {
            read_binary(path, bytes, &header, vertex_index)?
        }
    };
    Ok(PointCloud::new(points))
}

/// Parses one ASCII value of type `t`; `None` when it is not one.
fn parse_ascii_scalar(token: &str, t: &ScalarType) -> Option<f64> {
    Some(match t {
        ScalarType::Char => token.parse::<i8>().ok()? as f64,
        ScalarType::UChar => token.parse::<u8>().ok()? as f64,
        ScalarType::Short => token.parse::<i16>().ok()? as f64,
        ScalarType::UShort => token.parse::<u16>().ok()? as f64,
        ScalarType::Int => token.parse::<i32>().ok()? as f64,
        ScalarType::UInt => token.parse::<u32>().ok()? as f64,
        ScalarType::Float => token.parse::<f32>().ok()? as f64,
        ScalarType::Double => token.parse::<f64>().ok()?,
    })
}

/// Reads every element of an ASCII payload (one row per line) and checks that nothing but
/// white space follows the last row; returns the vertices.
fn read_ascii(
    path: &Path,
    bytes: &[u8],
    header: &PlyHeader,
    vertex_index: usize,
) -> Result<Vec<[f64; 3]>> {
    let err = |line: usize, msg: String| Error::malformed(path, format!("line {line}: {msg}"));
    let mut pos = header.data_start;
    let mut line_no = header.data_line;
    let remaining = bytes.len().saturating_sub(pos);
    let vertex_count = header.elements[vertex_index].def.count;
    // A vertex row takes at least 6 bytes ("0 0 0\n"): never reserve more than the file holds.
    let mut points = Vec::with_capacity(vertex_count.min(remaining / 6 + 1));
    for (index, element) in header.elements.iter().enumerate() {
        let def = &element.def;
        let is_vertex = index == vertex_index;
        // Which value of a vertex row goes to which axis.
        let slots: Vec<Option<usize>> = def
            .properties
            .keys()
            .map(|k| match k.as_str() {
                "x" if is_vertex => Some(0),
                "y" if is_vertex => Some(1),
                "z" if is_vertex => Some(2),
                _ => None,
            })
            .collect();
        for row in 0..def.count {
            let Some((raw, next)) = next_line(bytes, pos) else {
                return Err(err(
                    line_no,
                    format!(
                        "the file ends after {row} of the {} `{}` rows the header declares",
                        def.count, def.name
                    ),
                ));
            };
            pos = next;
            let Ok(text) = std::str::from_utf8(raw) else {
                return Err(err(
                    line_no,
                    format!("a `{}` row is not text (is the file binary?)", def.name),
                ));
            };
            let mut tokens = text.split_ascii_whitespace();
            let mut used = 0usize;
            let mut xyz = [0.0f64; 3];
            for ((name, prop), slot) in def.properties.iter().zip(&slots) {
                let mut next_value = |t: &ScalarType, what: &str| -> Result<f64> {
                    let Some(token) = tokens.next() else {
                        return Err(err(
                            line_no,
                            format!(
                                "a `{}` row has {used} values, but the header declares more \
                                 (`{name}` is missing)",
                                def.name
                            ),
                        ));
                    };
                    used += 1;
                    parse_ascii_scalar(token, t).ok_or_else(|| {
                        err(
                            line_no,
                            format!(
                                "`{token}` is not a valid {} ({what} `{name}` of element `{}`)",
                                scalar_name(t),
                                def.name
                            ),
                        )
                    })
                };
                match &prop.data_type {
                    PropertyType::Scalar(t) => {
                        let v = next_value(t, "property")?;
                        if let Some(s) = slot {
                            xyz[*s] = v;
                        }
                    }
                    PropertyType::List(count_type, item_type) => {
                        let n = next_value(count_type, "the count of list")?;
                        if n < 0.0 {
                            return Err(err(
                                line_no,
                                format!("list `{name}` has a negative count {n}"),
                            ));
                        }
                        for _ in 0..n as usize {
                            next_value(item_type, "an item of list")?;
                        }
                    }
                }
            }
            let extra = tokens.count();
            if extra > 0 {
                return Err(err(
                    line_no,
                    format!(
                        "a `{}` row has {} values, but the header declares {used}",
                        def.name,
                        used + extra
                    ),
                ));
            }
            if is_vertex {
                points.push(xyz);
            }
            line_no += 1;
        }
    }
    // Only white space may follow the last declared row.
    if let Some(offset) = bytes[pos.min(bytes.len())..]
        .iter()
        .position(|b| !b.is_ascii_whitespace())
    {
        let line = line_no
            + bytes[pos..pos + offset]
                .iter()
                .filter(|&&b| b == b'\n')
                .count();
        let counts: Vec<String> = header
            .elements
            .iter()
            .map(|e| format!("{} `{}`", e.def.count, e.def.name))
            .collect();
        return Err(err(
            line,
            format!(
                "data after the last row the header declares ({} rows)",
                counts.join(", ")
            ),
        ));
    }
    Ok(points)
}

/// The smallest number of bytes a binary row of `def` can take (lists counted as empty).
fn min_row_size(def: &ElementDef) -> usize {
    def.properties
        .values()
        .map(|p| match &p.data_type {
            PropertyType::Scalar(t) => scalar_size(t),
            PropertyType::List(c, _) => scalar_size(c),
        })
        .sum()
}

/// Reads the elements of a binary payload up to and including `vertex` with `ply-rs-bw`.
fn read_binary(
    path: &Path,
    bytes: &[u8],
    header: &PlyHeader,
    vertex_index: usize,
) -> Result<Vec<[f64; 3]>> {
    let available = bytes.len().saturating_sub(header.data_start);
    // Check the counts against the file's size first: it bounds every allocation below.
    let mut needed = 0usize;
    for element in &header.elements[..=vertex_index] {
        let def = &element.def;
        needed = min_row_size(def)
            .checked_mul(def.count)
            .and_then(|n| n.checked_add(needed))
            .filter(|&n| n <= available)
            .ok_or_else(|| {
                Error::malformed(
                    path,
                    format!(
                        "the binary data is too short: the header declares {} `{}` rows of at \
                         least {} bytes (line {}), but only {available} bytes follow the header",
                        def.count,
                        def.name,
                        min_row_size(def),
                        element.line
                    ),
                )
            })?;
    }
    let mut ply_header = Header::new();
    ply_header.encoding = header.encoding;
    for element in &header.elements {
        ply_header.elements.add(element.def.clone());
    }
    let parser = Parser::<Vertex>::new();
    let mut reader = Reader::new(Cursor::new(&bytes[header.data_start..]));
    for element in &header.elements[..=vertex_index] {
        let def = &element.def;
        if def.properties.is_empty() {
            // Rows of no bytes: nothing to read, however many (found by fuzzing: ply-rs-bw
            // would build one empty row per count, gigabytes for a count of 10^8).
            continue;
        }
        let rows = parser
            .read_payload_for_element(&mut reader, def, &ply_header)
            .map_err(|e| {
                // ply-rs-bw's messages are multi-line dumps with line numbers of its own:
                // keep the first line of the message only.
                let message = e.to_string();
                let first = message.lines().next().unwrap_or("").trim();
                let first = match (e.line(), first.split_once(": ")) {
                    (Some(_), Some((prefix, rest))) if prefix.starts_with("Line ") => rest,
                    _ => first,
                };
                Error::malformed(
                    path,
                    format!("bad binary data in element `{}`: {first}", def.name),
                )
            })?;
        if def.name == "vertex" {
            return Ok(rows.into_iter().map(|v| v.xyz).collect());
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

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use std::path::PathBuf;

    fn tmp(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("mtpcr-io-ply-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        dir.join(name)
    }

    pub(crate) const STANFORD: &str =
        "ply\nformat ascii 1.0\nobj_info num_cols 2\nbye\nbye\nelement vertex 3\n\
        property float x\nproperty float y\nproperty float z\nelement range_grid 4\n\
        property list uchar int vertex_indices\nend_header\n\
        0.5 1 2 \n3 4 5 \n-1e-3 0 7.25 \n1 0\n0\n1 1\n1 2\n";

    fn stanford_points() -> [[f64; 3]; 3] {
        [
            [0.5, 1.0, 2.0],
            [3.0, 4.0, 5.0],
            [-1e-3f32 as f64, 0.0, 7.25],
        ]
    }

    #[test]
    fn reads_a_stanford_style_ascii_file_with_bye_lines_and_range_grid() {
        let p = tmp("stanford.ply");
        std::fs::write(&p, STANFORD).unwrap();
        let c = read_ply(&p).unwrap();
        assert_eq!(c.points(), &stanford_points());
        // The same with CRLF line ends.
        let crlf = STANFORD.replace('\n', "\r\n");
        let c = read_ply_bytes(Path::new("crlf.ply"), crlf.as_bytes()).unwrap();
        assert_eq!(c.points(), &stanford_points());
    }

    #[test]
    fn binary_round_trip_with_colours() {
        let pts = vec![[0.1, 0.2, 0.3], [-1.0, 1e-9, 12345.678901234]];
        let p = tmp("rt.ply");
        write_ply(&p, &pts, Some(&[[255, 0, 0], [0, 0, 255]])).unwrap();
        assert_eq!(read_ply(&p).unwrap().points(), &pts[..]);
    }

    #[test]
    fn reads_binary_float_little_and_big_endian_with_an_element_before_vertex() {
        let mut bytes = b"ply\r\nformat binary_little_endian 1.0\r\ncomment x\r\nelement vertex 2\r\nproperty float x\r\nproperty float y\r\nproperty float z\r\nend_header\n".to_vec();
        for v in [1.0f32, 2.0, 3.0, 4.0, 5.0, 6.5] {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
        let c = read_ply_bytes(Path::new("mem.ply"), &bytes).unwrap();
        assert_eq!(c.points(), &[[1.0, 2.0, 3.0], [4.0, 5.0, 6.5]]);

        let mut bytes = b"ply\nformat binary_big_endian 1.0\nelement camera 1\nproperty list uchar short k\n\
            element vertex 1\nproperty uchar red\nproperty double z\nproperty int y\nproperty short x\nend_header\n"
            .to_vec();
        bytes.extend_from_slice(&[2, 0, 7, 0, 9]); // camera: a list of two shorts
        bytes.push(200);
        bytes.extend_from_slice(&(-2.5f64).to_be_bytes());
        bytes.extend_from_slice(&(-70000i32).to_be_bytes());
        bytes.extend_from_slice(&(-3i16).to_be_bytes());
        let c = read_ply_bytes(Path::new("be.ply"), &bytes).unwrap();
        assert_eq!(c.points(), &[[-3.0, -70000.0, -2.5]]);
    }

    #[test]
    fn a_huge_binary_element_without_properties_costs_nothing() {
        let mut bytes = b"ply\nformat binary_little_endian 1.0\nelement nothing 4000000000000\n\
            element vertex 1\nproperty float x\nproperty float y\nproperty float z\nend_header\n"
            .to_vec();
        for v in [1.0f32, 2.0, 3.0] {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
        let c = read_ply_bytes(Path::new("nothing.ply"), &bytes).unwrap();
        assert_eq!(c.points(), &[[1.0, 2.0, 3.0]]);
    }

    #[test]
    fn ascii_keeps_non_finite_values_and_reads_all_scalar_types() {
        let text = "ply\nformat ascii 1.0\nelement vertex 2\nproperty double x\nproperty int y\n\
            property uchar z\nproperty list int float normals\nend_header\nnan -7 255 2 0.5 1\n\
            inf 8 0 0\n";
        let c = read_ply_bytes(Path::new("nan.ply"), text.as_bytes()).unwrap();
        assert!(c.points()[0][0].is_nan());
        assert_eq!(&c.points()[0][1..], &[-7.0, 255.0]);
        assert_eq!(c.points()[1], [f64::INFINITY, 8.0, 0.0]);
    }

    /// Malformed PLY files, each with a piece of the message it must give (the message must
    /// also name the file and fit on one line). Shared with the regression corpus.
    pub(crate) fn malformed_cases() -> Vec<(&'static str, Vec<u8>, &'static str)> {
        let header = |body: &str| format!("ply\nformat ascii 1.0\n{body}end_header\n");
        let xyz = "element vertex 2\nproperty float x\nproperty float y\nproperty float z\n";
        let mut dup_binary =
            b"ply\nformat binary_little_endian 1.0\nelement vertex 2\nproperty float x\n\
            property float y\nproperty float z\nproperty float x\nend_header\n"
                .to_vec();
        dup_binary.extend_from_slice(&[0u8; 32]);
        let mut huge_binary =
            b"ply\nformat binary_little_endian 1.0\nelement vertex 4000000000000000000\n\
            property double x\nproperty double y\nproperty double z\nend_header\n"
                .to_vec();
        huge_binary.extend_from_slice(&[0u8; 24]);
        let mut negative_list = b"ply\nformat binary_little_endian 1.0\nelement face 1\n\
            property list int int v\nelement vertex 1\nproperty float x\nproperty float y\n\
            property float z\nend_header\n"
            .to_vec();
        negative_list.extend_from_slice(&(-5i32).to_le_bytes());
        negative_list.extend_from_slice(&[0u8; 12]);
        let mut not_text = (header(xyz) + "1 2 3\n").into_bytes();
        not_text.extend_from_slice(b"\xff\xfe\x00\n");
        let bye = "ply\nformat ascii 1.0\nobj_info a\nbye\nbye\nbye\nelement vertex 2\n\
            property float x\nproperty float y\nproperty float z\nend_header\n1 2 3\n4 x 6\n";
        vec![
            ("notply.ply", b"hello\nworld\n".to_vec(), "not a PLY file"),
            ("empty.ply", Vec::new(), "not a PLY file"),
            (
                "noend.ply",
                b"ply\nformat ascii 1.0\nelement vertex 1\n".to_vec(),
                "end_header",
            ),
            (
                "novertex.ply",
                header("element face 0\nproperty list uchar int v\n").into_bytes(),
                "no `vertex`",
            ),
            (
                "noz.ply",
                (header("element vertex 1\nproperty float x\nproperty float y\n") + "1 2\n")
                    .into_bytes(),
                "`z`",
            ),
            (
                "listx.ply",
                header("element vertex 0\nproperty list uchar float x\nproperty float y\nproperty float z\n")
                    .into_bytes(),
                "`x` is a list",
            ),
            (
                "short.ply",
                (header(xyz) + "1 2 3\n").into_bytes(),
                "line 9: the file ends after 1 of the 2 `vertex` rows",
            ),
            ("dup-binary.ply", dup_binary, "line 7: property `x` of element `vertex` is declared twice (first on line 4)"),
            (
                "two-vertex.ply",
                (header(&format!("{xyz}{xyz}")) + "1 2 3\n4 5 6\n1 2 3\n4 5 6\n").into_bytes(),
                "line 7: element `vertex` is declared twice (first on line 3)",
            ),
            (
                "extra.ply",
                (header(xyz) + "1 2 3\n4 5 6 7\n").into_bytes(),
                "line 9: a `vertex` row has 4 values, but the header declares 3",
            ),
            (
                "fewer.ply",
                (header(xyz) + "1 2 3\n4 5\n").into_bytes(),
                "line 9: a `vertex` row has 2 values, but the header declares more",
            ),
            (
                "more-rows.ply",
                (header(xyz) + "1 2 3\n4 5 6\n\n7 8 9\n").into_bytes(),
                "line 11: data after the last row the header declares (2 `vertex` rows)",
            ),
            (
                "bye-lines.ply",
                bye.as_bytes().to_vec(),
                "line 13: `x` is not a valid float (property `y` of element `vertex`)",
            ),
            (
                "bad-list.ply",
                (header("element vertex 1\nproperty float x\nproperty float y\nproperty float z\nelement g 1\nproperty list uchar int v\n")
                    + "1 2 3\n3 1 2\n")
                    .into_bytes(),
                "line 11: a `g` row has 3 values, but the header declares more (`v` is missing)",
            ),
            (
                "neg-list.ply",
                (header("element vertex 1\nproperty float x\nproperty float y\nproperty float z\nelement g 1\nproperty list char int v\n")
                    + "1 2 3\n-1\n")
                    .into_bytes(),
                "line 11: list `v` has a negative count",
            ),
            ("huge-binary.ply", huge_binary, "the binary data is too short"),
            ("negative-list.ply", negative_list, "bad binary data in element `face`"),
            (
                "binary-short.ply",
                b"ply\nformat binary_little_endian 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\nend_header\n\x00\x00".to_vec(),
                "the binary data is too short",
            ),
            ("noformat.ply", b"ply\nelement vertex 0\nend_header\n".to_vec(), "no `format` line"),
            ("badformat.ply", header("").replace("ascii 1.0", "ascii").into_bytes(), "line 2: bad `format` line"),
            ("encoding.ply", header("").replace("ascii", "utf8").into_bytes(), "line 2: unknown format"),
            ("twoformats.ply", header("format ascii 1.0\n").into_bytes(), "line 3: a second `format` line"),
            ("orphan.ply", header("property float x\n").into_bytes(), "line 3: a `property` line before any `element`"),
            ("type.ply", header("element vertex 0\nproperty real x\n").into_bytes(), "line 4: unknown type"),
            ("count.ply", header("element vertex -1\n").into_bytes(), "line 3: element `vertex` has a bad count"),
            ("listcount.ply", header("element f 0\nproperty list float int v\n").into_bytes(), "line 4: a list count must be an integer type"),
            ("notext.ply", not_text, "line 9: a `vertex` row is not text"),
        ]
    }

    #[test]
    fn malformed_files_give_one_line_errors_that_name_the_file_and_the_problem() {
        let e = read_ply("/nonexistent/nowhere.ply").unwrap_err();
        assert!(
            matches!(e, Error::Io { .. }) && e.to_string().contains("nowhere.ply"),
            "{e}"
        );
        let mut wrong = Vec::new();
        for (name, bytes, needle) in malformed_cases() {
            match read_ply_bytes(Path::new(name), &bytes) {
                Err(e @ Error::MalformedFile { .. }) => {
                    let msg = e.to_string();
                    if !(msg.contains(name) && msg.contains(needle) && !msg.contains('\n')) {
                        wrong.push(format!("{name}: got `{msg}`, want `{needle}`"));
                    }
                }
                other => wrong.push(format!("{name}: {other:?}")),
            }
        }
        assert!(wrong.is_empty(), "{}", wrong.join("\n"));
    }
}
