//! XYZ and PTS text point clouds.
//!
//! One point per row; the first three numbers of a row are `x y z`, anything after them
//! (intensity, colour, normals) is ignored. Values are separated by white space, or by commas
//! when the row has any (CSV). Empty lines and comment lines (`#` or `//`) are skipped, and so
//! is a first row of column names (a row in which none of the first three values is a number,
//! such as `x,y,z`). A PTS file is the same with a point count on a line of its own before its
//! rows; a file may hold several such blocks one after the other. Non-finite values (`nan`,
//! `inf`) are kept: registration validates the cloud and reports them.

use crate::cloud::PointCloud;
use crate::error::{Error, Result};
use std::path::Path;

/// The values of a row: comma-separated when it has a comma, else white-space separated.
fn fields(line: &str) -> Vec<&str> {
    if line.contains(',') {
        line.split(',').map(str::trim).collect()
    } else {
        line.split_ascii_whitespace().collect()
    }
}

fn is_comment(line: &str) -> bool {
    line.starts_with('#') || line.starts_with("//")
}

/// Parses a row's `x y z`.
fn parse_row(path: &Path, line_no: usize, line: &str) -> Result<[f64; 3]> {
    let values = fields(line);
    if values.len() < 3 {
        return Err(Error::malformed(
            path,
            format!(
                "line {line_no}: a point row needs 3 values (x y z), found {} in `{}`",
                values.len(),
                shorten(line)
            ),
        ));
    }
    let mut xyz = [0.0f64; 3];
    for (k, slot) in xyz.iter_mut().enumerate() {
        *slot = values[k].parse::<f64>().map_err(|_| {
            Error::malformed(
                path,
                format!(
                    "line {line_no}: `{}` is not a number (value {} of the row)",
                    shorten(values[k]),
                    k + 1
                ),
            )
        })?;
    }
    Ok(xyz)
}

/// At most 60 characters of `s`, for error messages.
fn shorten(s: &str) -> String {
    if s.chars().count() <= 60 {
        s.to_string()
    } else {
        format!("{}...", s.chars().take(60).collect::<String>())
    }
}

/// True for a row of column names: none of its first three values is a number.
fn is_column_names(line: &str) -> bool {
    let values = fields(line);
    !values.is_empty() && values.iter().take(3).all(|v| v.parse::<f64>().is_err())
}

/// Reads an XYZ (`pts == false`) or PTS (`pts == true`) file held in `bytes`.
pub(crate) fn read_xyz_bytes(path: &Path, bytes: &[u8], pts: bool) -> Result<PointCloud> {
    let text = std::str::from_utf8(bytes).map_err(|e| {
        let line = 1 + bytes[..e.valid_up_to()]
            .iter()
            .filter(|&&b| b == b'\n')
            .count();
        Error::malformed(
            path,
            format!("line {line}: not text (the file is not UTF-8; is it binary?)"),
        )
    })?;
    // Rows take some 24 bytes or more: a reservation bounded by the file's size.
    let mut points = Vec::with_capacity(bytes.len() / 24 + 1);
    let mut first_row = true;
    // PTS: points still expected in the current block, and the line of its count.
    let mut block: Option<(usize, usize, usize)> = None; // (declared, read, line)
    for (index, raw) in text.lines().enumerate() {
        let line_no = index + 1;
        let line = raw.trim();
        if line.is_empty() || is_comment(line) {
            continue;
        }
        if pts {
            match block {
                Some((declared, read, _)) if read < declared => {}
                _ => {
                    let values = fields(line);
                    match (values.len(), values.first().map(|v| v.parse::<u64>())) {
                        (1, Some(Ok(count))) => {
                            block =
                                Some((usize::try_from(count).unwrap_or(usize::MAX), 0, line_no));
                            continue;
                        }
                        _ => {
                            return Err(Error::malformed(
                                path,
                                match block {
                                    None => format!(
                                        "line {line_no}: a PTS file starts with its point count \
                                         on a line of its own, found `{}`",
                                        shorten(line)
                                    ),
                                    Some((declared, _, at)) => format!(
                                        "line {line_no}: more rows than the {declared} points \
                                         declared on line {at} (expected a new point count, \
                                         found `{}`)",
                                        shorten(line)
                                    ),
                                },
                            ));
                        }
                    }
                }
            }
        } else if first_row && is_column_names(line) {
            first_row = false;
            continue;
        }
        first_row = false;
        points.push(parse_row(path, line_no, line)?);
        if let Some((_, read, _)) = block.as_mut() {
            *read += 1;
        }
    }
    if let Some((declared, read, at)) = block {
        if read < declared {
            return Err(Error::malformed(
                path,
                format!(
                    "the file ends after {read} of the {declared} points declared on line {at}"
                ),
            ));
        }
    }
    Ok(PointCloud::new(points))
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    fn read(name: &str, text: &str, pts: bool) -> Result<PointCloud> {
        read_xyz_bytes(Path::new(name), text.as_bytes(), pts)
    }

    #[test]
    fn reads_whitespace_and_comma_rows_with_comments_and_extra_columns() {
        let text = "# exported\n// by hand\n\n1 2 3\n4\t5\t6 0.5 255 0 0\r\n-7e-1,8.25,9,42\n  \n";
        let c = read("a.xyz", text, false).unwrap();
        assert_eq!(
            c.points(),
            &[[1.0, 2.0, 3.0], [4.0, 5.0, 6.0], [-0.7, 8.25, 9.0]]
        );
    }

    #[test]
    fn skips_a_header_row_of_column_names_and_keeps_non_finite_values() {
        let c = read("a.csv", "x,y,z,intensity\n1,2,3,4\nnan,inf,0,1\n", false).unwrap();
        assert_eq!(c.points()[0], [1.0, 2.0, 3.0]);
        assert!(c.points()[1][0].is_nan() && c.points()[1][1] == f64::INFINITY);
        assert_eq!(c.len(), 2);
    }

    #[test]
    fn reads_pts_blocks() {
        let text = "2\n1 2 3 10 1 2 3\n4 5 6 10 1 2 3\n1\n7 8 9\n";
        let c = read("a.pts", text, true).unwrap();
        assert_eq!(
            c.points(),
            &[[1.0, 2.0, 3.0], [4.0, 5.0, 6.0], [7.0, 8.0, 9.0]]
        );
    }

    /// Malformed XYZ/PTS files (name, text, is PTS, a piece of the message). Shared with the
    /// regression corpus.
    pub(crate) fn malformed_cases() -> Vec<(&'static str, &'static str, bool, &'static str)> {
        vec![
            (
                "short.xyz",
                "1 2 3\n4 5\n",
                false,
                "line 2: a point row needs 3 values",
            ),
            (
                "word.xyz",
                "1 2 3\n\n4 five 6\n",
                false,
                "line 3: `five` is not a number",
            ),
            (
                "names-late.csv",
                "1,2,3\nx,y,z\n",
                false,
                "line 2: `x` is not a number",
            ),
            (
                "empty-field.csv",
                "1,,3\n",
                false,
                "line 1: `` is not a number",
            ),
            (
                "nocount.pts",
                "1 2 3\n",
                true,
                "line 1: a PTS file starts with its point count",
            ),
            (
                "toomany.pts",
                "1\n1 2 3\n4 5 6\n",
                true,
                "line 3: more rows than the 1 points",
            ),
            (
                "toofew.pts",
                "# c\n3\n1 2 3\n",
                true,
                "ends after 1 of the 3 points declared on line 2",
            ),
        ]
    }

    #[test]
    fn errors_name_the_file_the_line_and_the_problem() {
        for (name, text, pts, needle) in malformed_cases() {
            let e = read(name, text, pts).unwrap_err();
            let msg = e.to_string();
            assert!(matches!(e, Error::MalformedFile { .. }), "{name}: {msg}");
            assert!(msg.contains(name) && msg.contains(needle), "{name}: {msg}");
        }
        let e = read_xyz_bytes(Path::new("bin.xyz"), b"1 2 3\n\xff\xfe\x00", false).unwrap_err();
        assert!(e.to_string().contains("line 2: not text"), "{e}");
    }
}
