//! Plain-text point tables (`.xyz`, `.txt`, `.csv`, `.pts`): one point a line.
//!
//! Values are separated by spaces, tabs, commas or semicolons. A first line that is
//! not all numbers is a header: its column names place `x y z` and an integer
//! `part` or `label` column (the ground truth); without one the first three columns
//! are `x y z` and the others are skipped. Blank lines and lines starting with `#` or
//! `//` are skipped, as is a `.pts` file's first line when it holds the point count
//! alone. A NaN coordinate is no point (dropped); anything else that is not a number
//! is an error naming the line.

use glam::Vec3;

use super::ply::{part_label, PlyCloud};
use crate::error::{Error, Result};

fn input(file: &str, problem: impl Into<String>) -> Error {
    Error::input(file, problem)
}

fn split(line: &str) -> impl Iterator<Item = &str> {
    line.split(|c: char| c.is_whitespace() || c == ',' || c == ';')
        .filter(|w| !w.is_empty())
}

fn number(w: &str) -> Option<f64> {
    w.parse::<f64>()
        .ok()
        .or_else(|| w.eq_ignore_ascii_case("-nan").then_some(f64::NAN))
}

/// Reads a text point table (see the module doc).
pub fn read_text_cloud(bytes: &[u8], file: &str) -> Result<PlyCloud> {
    let text = std::str::from_utf8(bytes).map_err(|_| {
        input(
            file,
            "not a text point table: the file is binary (or not UTF-8 text)",
        )
    })?;
    let mut lines = text
        .lines()
        .enumerate()
        .map(|(i, l)| (i + 1, l.trim()))
        .filter(|(_, l)| !l.is_empty() && !l.starts_with('#') && !l.starts_with("//"))
        .peekable();
    // Columns of x, y, z and the label; a header names them.
    let (mut cols, mut label) = ([0usize, 1, 2], None);
    if let Some(&(n, first)) = lines.peek() {
        let words: Vec<&str> = split(first).collect();
        if words.iter().any(|w| number(w).is_none()) {
            let names: Vec<String> = words
                .iter()
                .map(|w| w.trim_matches('"').trim_matches('\'').to_ascii_lowercase())
                .collect();
            let at = |want: &[&str]| names.iter().position(|n| want.contains(&n.as_str()));
            match (at(&["x"]), at(&["y"]), at(&["z"])) {
                (Some(x), Some(y), Some(z)) => cols = [x, y, z],
                _ => {
                    return Err(input(
                        file,
                        format!(
                            "line {n}: the header ({}) names no x, y and z columns",
                            names.join(", ")
                        ),
                    ))
                }
            }
            label = at(&["part", "label"]);
            lines.next();
        } else if words.len() == 1 {
            // A .pts file's point count.
            lines.next();
        }
    }
    let need = cols.iter().chain(label.iter()).max().copied().unwrap_or(2) + 1;
    let mut cloud = PlyCloud {
        points: Vec::new(),
        labels: label.map(|_| Vec::new()),
        faces: None,
    };
    for (n, line) in lines {
        let words: Vec<&str> = split(line).collect();
        if words.len() < need {
            return Err(input(
                file,
                format!(
                    "line {n} has {} values, the table needs {need}: '{line}'",
                    words.len()
                ),
            ));
        }
        let v = |c: usize| {
            number(words[c])
                .ok_or_else(|| input(file, format!("line {n}: '{}' is not a number", words[c])))
        };
        let p = [v(cols[0])?, v(cols[1])?, v(cols[2])?];
        if p.iter().any(|c| c.is_nan()) {
            continue;
        }
        if p.iter().any(|c| c.is_infinite()) {
            return Err(input(file, format!("line {n}: infinite coordinate")));
        }
        cloud
            .points
            .push(Vec3::new(p[0] as f32, p[1] as f32, p[2] as f32));
        if let (Some(c), Some(out)) = (label, cloud.labels.as_mut()) {
            let l = v(c)?;
            out.push(part_label(l).ok_or_else(|| {
                input(
                    file,
                    format!("line {n}: part label {l} is not a non-negative integer"),
                )
            })?);
        }
    }
    Ok(cloud)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tables_with_and_without_a_header() {
        let plain = read_text_cloud(b"# scan\n0 1 2 255 0 0\n\n3\t4\t5 0 0 0\n", "a.xyz").unwrap();
        assert_eq!(
            plain.points,
            vec![Vec3::new(0., 1., 2.), Vec3::new(3., 4., 5.)]
        );
        assert_eq!(plain.labels, None);
        let csv = read_text_cloud(b"part,z,y,x\n1,2,1,0\n2,5,4,3\n", "b.csv").unwrap();
        assert_eq!(
            csv.points,
            vec![Vec3::new(0., 1., 2.), Vec3::new(3., 4., 5.)]
        );
        assert_eq!(csv.labels, Some(vec![1, 2]));
        let pts = read_text_cloud(b"2\n0;1;2\nnan;0;0\n3;4;5\n", "c.pts").unwrap();
        assert_eq!(pts.points.len(), 2);
    }

    #[test]
    fn bad_tables_are_named() {
        let e = |b: &[u8]| read_text_cloud(b, "t.txt").unwrap_err().to_string();
        assert!(e(b"a b c\n1 2 3\n").contains("line 1: the header (a, b, c) names no x, y and z"));
        assert!(e(b"1 2 3\n4 5\n").contains("line 2 has 2 values"));
        assert!(e(b"1 2 3\n4 5 six\n").contains("line 2: 'six' is not a number"));
        assert!(e(b"1 2 3\n4 5 inf\n").contains("infinite"));
        assert!(e(b"x y z label\n1 2 3 -1\n").contains("part label -1"));
        assert!(e(&[0xff, 0xfe, 0, 1]).contains("binary"));
    }
}
