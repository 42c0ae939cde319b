//! PCD v0.7 (Point Cloud Library) read and write: `ascii`, `binary` (array of structures,
//! little-endian) and `binary_compressed` (u32 compressed size, u32 raw size, then LZF of the
//! data laid out field by field — a structure of arrays). Any field layout; values are held as
//! f64 columns (exact for every PCD type but 64-bit integers beyond 2⁵³).
//!
//! Malformed files give a [`PcdError`] naming the header line or the data problem; sizes are
//! checked against the bytes present before anything is allocated.

pub mod lzf;

use nalgebra::Point3;
use std::fmt::Write as _;

/// Value type of a field: signed, unsigned, float.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FieldKind {
    Signed,
    Unsigned,
    Float,
}

/// One PCD field (`FIELDS`/`SIZE`/`TYPE`/`COUNT`).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct PcdField {
    pub name: String,
    pub size: usize,
    pub kind: FieldKind,
    pub count: usize,
}

/// How the data section is stored.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DataFormat {
    Ascii,
    Binary,
    BinaryCompressed,
}

/// A point cloud with any fields: `columns[c]` holds element c of the fields in order (a field
/// with COUNT 3 has three columns), one value per point.
#[derive(Clone, Debug, PartialEq)]
pub struct PointCloud {
    pub fields: Vec<PcdField>,
    pub width: usize,
    pub height: usize,
    /// tx ty tz qw qx qy qz.
    pub viewpoint: [f64; 7],
    pub columns: Vec<Vec<f64>>,
}

/// What is wrong with a PCD file.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PcdError {
    #[error("header line {line}: {message}")]
    Header { line: usize, message: String },
    #[error("data: {0}")]
    Data(String),
    #[error("the cloud has no {0} field")]
    MissingField(&'static str),
}

/// Largest number of points read (bounds memory).
pub const MAX_POINTS: usize = 200_000_000;
/// Most values per point, all fields' COUNTs together (PCL's largest descriptor, SHOT with
/// colour, has 1 344).
pub const MAX_VALUES_PER_POINT: usize = 4096;

fn header_error(line: usize, message: impl Into<String>) -> PcdError {
    PcdError::Header { line, message: message.into() }
}

impl PointCloud {
    /// A cloud of float x, y, z.
    pub fn from_points(points: &[Point3<f64>]) -> Self {
        let field = |name: &str| PcdField { name: name.into(), size: 4, kind: FieldKind::Float, count: 1 };
        Self {
            fields: vec![field("x"), field("y"), field("z")],
            width: points.len(),
            height: 1,
            viewpoint: [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0],
            columns: (0..3).map(|k| points.iter().map(|p| p[k]).collect()).collect(),
        }
    }

    pub fn len(&self) -> usize {
        self.width * self.height
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Index of the first column of field `name`.
    pub fn column_of(&self, name: &str) -> Option<usize> {
        let mut column = 0;
        for f in &self.fields {
            if f.name == name {
                return Some(column);
            }
            column += f.count;
        }
        None
    }

    /// All points' x, y, z (NaN kept: organised clouds mark missing returns so).
    pub fn points(&self) -> Result<Vec<Point3<f64>>, PcdError> {
        let x = self.column_of("x").ok_or(PcdError::MissingField("x"))?;
        let y = self.column_of("y").ok_or(PcdError::MissingField("y"))?;
        let z = self.column_of("z").ok_or(PcdError::MissingField("z"))?;
        Ok((0..self.len()).map(|k| Point3::new(self.columns[x][k], self.columns[y][k], self.columns[z][k])).collect())
    }

    /// Points with finite coordinates only.
    pub fn finite_points(&self) -> Result<Vec<Point3<f64>>, PcdError> {
        Ok(self.points()?.into_iter().filter(|p| p.coords.iter().all(|v| v.is_finite())).collect())
    }

    fn point_bytes(&self) -> usize {
        self.fields.iter().map(|f| f.size * f.count).sum()
    }
}

struct Header {
    fields: Vec<PcdField>,
    width: usize,
    height: usize,
    viewpoint: [f64; 7],
    points: usize,
    format: DataFormat,
    data_offset: usize,
}

fn parse_header(bytes: &[u8]) -> Result<Header, PcdError> {
    let (mut names, mut sizes, mut kinds, mut counts) = (None, None, None, None);
    let (mut width, mut height, mut points) = (None, None, None);
    let mut viewpoint = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0];
    let mut offset = 0;
    let mut line = 0;
    loop {
        line += 1;
        let end = bytes[offset..].iter().position(|&b| b == b'\n').map(|p| offset + p + 1);
        let Some(end) = end else {
            return Err(header_error(line, "the header ends before a DATA line"));
        };
        let text = std::str::from_utf8(&bytes[offset..end]).map_err(|_| header_error(line, "not text"))?;
        offset = end;
        let mut words = text.split_whitespace();
        let Some(key) = words.next() else { continue };
        if key.starts_with('#') {
            continue;
        }
        let values: Vec<&str> = words.collect();
        let number =
            |v: &str| v.parse::<usize>().map_err(|_| header_error(line, format!("{key}: {v:?} is not a whole number")));
        match key {
            "VERSION" => {}
            "FIELDS" | "COLUMNS" => names = Some(values.iter().map(|s| s.to_string()).collect::<Vec<_>>()),
            "SIZE" => sizes = Some(values.iter().map(|v| number(v)).collect::<Result<Vec<_>, _>>()?),
            "TYPE" => {
                let parsed: Result<Vec<FieldKind>, PcdError> = values
                    .iter()
                    .map(|v| match *v {
                        "I" => Ok(FieldKind::Signed),
                        "U" => Ok(FieldKind::Unsigned),
                        "F" => Ok(FieldKind::Float),
                        other => Err(header_error(line, format!("TYPE {other:?} is not I, U or F"))),
                    })
                    .collect();
                kinds = Some(parsed?);
            }
            "COUNT" => counts = Some(values.iter().map(|v| number(v)).collect::<Result<Vec<_>, _>>()?),
            "WIDTH" => width = Some(number(values.first().copied().unwrap_or(""))?),
            "HEIGHT" => height = Some(number(values.first().copied().unwrap_or(""))?),
            "POINTS" => points = Some(number(values.first().copied().unwrap_or(""))?),
            "VIEWPOINT" => {
                if values.len() != 7 {
                    return Err(header_error(line, "VIEWPOINT needs 7 numbers"));
                }
                for (k, v) in values.iter().enumerate() {
                    viewpoint[k] =
                        v.parse().map_err(|_| header_error(line, format!("VIEWPOINT: {v:?} is not a number")))?;
                }
            }
            "DATA" => {
                let format = match values.first().copied() {
                    Some("ascii") => DataFormat::Ascii,
                    Some("binary") => DataFormat::Binary,
                    Some("binary_compressed") => DataFormat::BinaryCompressed,
                    other => {
                        return Err(header_error(
                            line,
                            format!("DATA {other:?} is not ascii, binary or binary_compressed"),
                        ))
                    }
                };
                let names = names.ok_or(header_error(line, "no FIELDS before DATA"))?;
                let sizes = sizes.ok_or(header_error(line, "no SIZE before DATA"))?;
                let kinds = kinds.ok_or(header_error(line, "no TYPE before DATA"))?;
                if names.is_empty() {
                    // A point of no field has no bytes: the data could not be walked point by point.
                    return Err(header_error(line, "FIELDS names no field: a point needs at least 1 value"));
                }
                let counts = counts.unwrap_or_else(|| vec![1; names.len()]);
                if sizes.len() != names.len() || kinds.len() != names.len() || counts.len() != names.len() {
                    return Err(header_error(
                        line,
                        format!(
                            "FIELDS has {} entries but SIZE {}, TYPE {}, COUNT {}",
                            names.len(),
                            sizes.len(),
                            kinds.len(),
                            counts.len()
                        ),
                    ));
                }
                let values: usize = counts.iter().fold(0usize, |a, c| a.saturating_add(*c));
                if values > MAX_VALUES_PER_POINT {
                    return Err(header_error(
                        line,
                        format!("COUNT totals {values} values per point, at most {MAX_VALUES_PER_POINT} accepted"),
                    ));
                }
                let mut fields = Vec::with_capacity(names.len());
                for (((name, size), kind), count) in names.into_iter().zip(sizes).zip(kinds).zip(counts) {
                    let valid = match kind {
                        FieldKind::Float => size == 4 || size == 8,
                        _ => matches!(size, 1 | 2 | 4 | 8),
                    };
                    if !valid || count == 0 {
                        return Err(header_error(
                            line,
                            format!("field {name}: size {size}, type {kind:?}, count {count} is not a PCD type"),
                        ));
                    }
                    fields.push(PcdField { name, size, kind, count });
                }
                let width = width.ok_or(header_error(line, "no WIDTH"))?;
                let height = height.ok_or(header_error(line, "no HEIGHT"))?;
                let total = width.checked_mul(height).ok_or(header_error(line, "WIDTH × HEIGHT overflows"))?;
                let points = points.unwrap_or(total);
                if points != total {
                    return Err(header_error(line, format!("POINTS {points} ≠ WIDTH × HEIGHT = {total}")));
                }
                if points > MAX_POINTS {
                    return Err(header_error(line, format!("{points} points exceed the limit of {MAX_POINTS}")));
                }
                return Ok(Header { fields, width, height, viewpoint, points, format, data_offset: offset });
            }
            other => return Err(header_error(line, format!("unknown header entry {other:?}"))),
        }
    }
}

fn read_value(bytes: &[u8], kind: FieldKind) -> f64 {
    let mut b8 = [0u8; 8];
    b8[..bytes.len()].copy_from_slice(bytes);
    match (kind, bytes.len()) {
        (FieldKind::Float, 4) => f32::from_le_bytes([b8[0], b8[1], b8[2], b8[3]]) as f64,
        (FieldKind::Float, _) => f64::from_le_bytes(b8),
        (FieldKind::Unsigned, _) => u64::from_le_bytes(b8) as f64,
        (FieldKind::Signed, n) => {
            let shift = 64 - 8 * n as u32;
            ((i64::from_le_bytes(b8) << shift) >> shift) as f64
        }
    }
}

fn write_value(out: &mut Vec<u8>, v: f64, field: &PcdField) {
    match (field.kind, field.size) {
        (FieldKind::Float, 4) => out.extend_from_slice(&(v as f32).to_le_bytes()),
        (FieldKind::Float, _) => out.extend_from_slice(&v.to_le_bytes()),
        (FieldKind::Unsigned, n) => out.extend_from_slice(&(v as u64).to_le_bytes()[..n]),
        (FieldKind::Signed, n) => out.extend_from_slice(&(v as i64).to_le_bytes()[..n]),
    }
}

/// Parses a PCD file.
pub fn read_pcd(bytes: &[u8]) -> Result<PointCloud, PcdError> {
    let h = parse_header(bytes)?;
    let data = &bytes[h.data_offset..];
    let columns_total: usize = h.fields.iter().map(|f| f.count).sum();
    let point_bytes: usize = h.fields.iter().map(|f| f.size * f.count).sum();
    let raw_len = h.points.checked_mul(point_bytes).ok_or(PcdError::Data("size overflows".into()))?;
    let mut columns: Vec<Vec<f64>> = Vec::with_capacity(columns_total);
    match h.format {
        DataFormat::Ascii => {
            columns.resize_with(columns_total, || Vec::with_capacity(h.points.min(data.len() / 2 + 1)));
            let single_precision: Vec<bool> = h
                .fields
                .iter()
                .flat_map(|f| std::iter::repeat_n(f.kind == FieldKind::Float && f.size == 4, f.count))
                .collect();
            let text = std::str::from_utf8(data).map_err(|_| PcdError::Data("ascii data is not text".into()))?;
            let mut rows = text.lines().filter(|l| !l.trim().is_empty());
            for k in 0..h.points {
                let row = rows
                    .next()
                    .ok_or(PcdError::Data(format!("ascii data has {k} points, the header declares {}", h.points)))?;
                let values: Vec<&str> = row.split_whitespace().collect();
                if values.len() != columns_total {
                    return Err(PcdError::Data(format!(
                        "point {k}: {} values, expected {columns_total}",
                        values.len()
                    )));
                }
                for ((c, v), single) in values.iter().enumerate().zip(&single_precision) {
                    let bad = || PcdError::Data(format!("point {k}: {v:?} is not a number"));
                    // A 4-byte float is read as f32, exactly as the binary formats store it.
                    let parsed = if *single {
                        v.parse::<f32>().map_err(|_| bad())? as f64
                    } else {
                        v.parse::<f64>().map_err(|_| bad())?
                    };
                    columns[c].push(parsed);
                }
            }
        }
        DataFormat::Binary => {
            let body = data
                .get(..raw_len)
                .ok_or(PcdError::Data(format!("binary data has {} bytes, {raw_len} expected", data.len())))?;
            columns.resize_with(columns_total, || Vec::with_capacity(h.points));
            for point in body.chunks_exact(point_bytes) {
                let (mut at, mut c) = (0, 0);
                for f in &h.fields {
                    for _ in 0..f.count {
                        columns[c].push(read_value(&point[at..at + f.size], f.kind));
                        at += f.size;
                        c += 1;
                    }
                }
            }
        }
        DataFormat::BinaryCompressed => {
            let word = |k: usize| -> Result<usize, PcdError> {
                let b = data
                    .get(4 * k..4 * k + 4)
                    .ok_or(PcdError::Data("binary_compressed data is missing its sizes".into()))?;
                Ok(u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize)
            };
            let (compressed, raw) = (word(0)?, word(1)?);
            if raw != raw_len {
                return Err(PcdError::Data(format!("uncompressed size {raw}, the header implies {raw_len}")));
            }
            let packed = data
                .get(8..8 + compressed)
                .ok_or(PcdError::Data(format!("compressed size {compressed} exceeds the file")))?;
            let body = lzf::decompress(packed, raw).map_err(|e| PcdError::Data(format!("LZF: {e}")))?;
            // Structure of arrays: each field's values for all points, in field order.
            let mut at = 0;
            for f in &h.fields {
                let first = columns.len();
                columns.resize_with(first + f.count, || Vec::with_capacity(h.points));
                for _ in 0..h.points {
                    for e in 0..f.count {
                        columns[first + e].push(read_value(&body[at..at + f.size], f.kind));
                        at += f.size;
                    }
                }
            }
        }
    }
    Ok(PointCloud { fields: h.fields, width: h.width, height: h.height, viewpoint: h.viewpoint, columns })
}

/// Writes a PCD file (v0.7) in `format`.
pub fn write_pcd(cloud: &PointCloud, format: DataFormat) -> Vec<u8> {
    let mut header = String::from("# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\n");
    let list = |f: &dyn Fn(&PcdField) -> String| cloud.fields.iter().map(f).collect::<Vec<_>>().join(" ");
    let _ = writeln!(header, "FIELDS {}", list(&|f| f.name.clone()));
    let _ = writeln!(header, "SIZE {}", list(&|f| f.size.to_string()));
    let _ = writeln!(
        header,
        "TYPE {}",
        list(&|f| match f.kind {
            FieldKind::Signed => "I",
            FieldKind::Unsigned => "U",
            FieldKind::Float => "F",
        }
        .into())
    );
    let _ = writeln!(header, "COUNT {}", list(&|f| f.count.to_string()));
    let v = cloud.viewpoint;
    let _ = writeln!(
        header,
        "WIDTH {}\nHEIGHT {}\nVIEWPOINT {} {} {} {} {} {} {}\nPOINTS {}",
        cloud.width,
        cloud.height,
        v[0],
        v[1],
        v[2],
        v[3],
        v[4],
        v[5],
        v[6],
        cloud.len()
    );
    let name = match format {
        DataFormat::Ascii => "ascii",
        DataFormat::Binary => "binary",
        DataFormat::BinaryCompressed => "binary_compressed",
    };
    let _ = writeln!(header, "DATA {name}");
    let mut out = header.into_bytes();
    let element_fields: Vec<&PcdField> = cloud.fields.iter().flat_map(|f| std::iter::repeat_n(f, f.count)).collect();
    match format {
        DataFormat::Ascii => {
            let mut text = String::new();
            for k in 0..cloud.len() {
                for (c, f) in element_fields.iter().enumerate() {
                    let value = cloud.columns[c][k];
                    if c > 0 {
                        text.push(' ');
                    }
                    match f.kind {
                        FieldKind::Float if f.size == 4 => {
                            let _ = write!(text, "{}", value as f32);
                        }
                        _ => {
                            let _ = write!(text, "{value}");
                        }
                    }
                }
                text.push('\n');
            }
            out.extend_from_slice(text.as_bytes());
        }
        DataFormat::Binary => {
            for k in 0..cloud.len() {
                for (c, f) in element_fields.iter().enumerate() {
                    write_value(&mut out, cloud.columns[c][k], f);
                }
            }
        }
        DataFormat::BinaryCompressed => {
            let mut raw = Vec::with_capacity(cloud.len() * cloud.point_bytes());
            let mut c = 0;
            for f in &cloud.fields {
                for k in 0..cloud.len() {
                    for e in 0..f.count {
                        write_value(&mut raw, cloud.columns[c + e][k], f);
                    }
                }
                c += f.count;
            }
            let packed = lzf::compress(&raw);
            out.extend_from_slice(&(packed.len() as u32).to_le_bytes());
            out.extend_from_slice(&(raw.len() as u32).to_le_bytes());
            out.extend_from_slice(&packed);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn shared(name: &str) -> Vec<u8> {
        std::fs::read(std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/data/clouds").join(name))
            .expect("shared data beside the repo")
    }

    #[test]
    fn shared_clouds_load_with_their_point_counts() {
        let bunny = read_pcd(&shared("bun0.pcd")).unwrap();
        assert_eq!(bunny.len(), 397);
        assert_eq!(bunny.fields.len(), 7);
        assert!((bunny.points().unwrap()[0] - Point3::new(0.0054215998, 0.11349, 0.040748999)).norm() < 1e-7);
        let kinect = read_pcd(&shared("kinect_frame_20121214T142255.814212.pcd")).unwrap();
        assert_eq!((kinect.width, kinect.height, kinect.len()), (640, 480, 307_200));
        let finite = kinect.finite_points().unwrap();
        assert!(finite.len() > 100_000 && finite.len() < 307_200, "{}", finite.len());
        // Depth camera: every finite point is in front of it, within a few metres.
        assert!(finite.iter().all(|p| p.z > 0.2 && p.z < 10.0));
        let rgba = kinect.column_of("rgba").unwrap();
        assert!(kinect.columns[rgba].iter().all(|v| *v >= 0.0 && *v <= u32::MAX as f64));
    }

    #[test]
    fn every_format_round_trips() {
        let kinect = read_pcd(&shared("kinect_frame_20121214T142255.814212.pcd")).unwrap();
        for format in [DataFormat::Ascii, DataFormat::Binary, DataFormat::BinaryCompressed] {
            let back = read_pcd(&write_pcd(&kinect, format)).unwrap();
            assert_eq!(back.fields, kinect.fields);
            for (a, b) in back.columns.iter().zip(&kinect.columns) {
                assert!(a.iter().zip(b).all(|(x, y)| x == y || (x.is_nan() && y.is_nan())), "{format:?}");
            }
        }
        let mixed = PointCloud {
            fields: vec![
                PcdField { name: "x".into(), size: 8, kind: FieldKind::Float, count: 1 },
                PcdField { name: "label".into(), size: 2, kind: FieldKind::Signed, count: 2 },
                PcdField { name: "y".into(), size: 1, kind: FieldKind::Unsigned, count: 1 },
            ],
            width: 2,
            height: 1,
            viewpoint: [1.0, 2.0, 3.0, 1.0, 0.0, 0.0, 0.0],
            columns: vec![vec![0.1, -2.5], vec![-300.0, 7.0], vec![5.0, -32768.0], vec![0.0, 255.0]],
        };
        for format in [DataFormat::Ascii, DataFormat::Binary, DataFormat::BinaryCompressed] {
            assert_eq!(read_pcd(&write_pcd(&mixed, format)).unwrap(), mixed, "{format:?}");
        }
    }

    #[test]
    fn malformed_files_say_what_and_where() {
        let head = "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 2\nHEIGHT 1\nPOINTS 2\n";
        let cases: [(String, &str); 9] = [
            ("VERSION 0.7\nFIELDS x\n".into(), "ends before a DATA line"),
            (format!("{head}DATA zip\n"), "is not ascii, binary or binary_compressed"),
            (head.replace("TYPE F F F", "TYPE F F Q") + "DATA ascii\n", "line 4: TYPE \"Q\""),
            (head.replace("SIZE 4 4 4", "SIZE 4 4 3") + "DATA ascii\n", "field z: size 3"),
            (head.replace("POINTS 2", "POINTS 5") + "DATA ascii\n", "POINTS 5 ≠ WIDTH × HEIGHT = 2"),
            (head.replace("WIDTH 2", "WIDTH two") + "DATA ascii\n", "line 6: WIDTH: \"two\""),
            (format!("{head}DATA ascii\n1 2 3\n"), "ascii data has 1 points"),
            (format!("{head}DATA binary\n\0\0\0"), "binary data has 3 bytes, 24 expected"),
            (format!("{head}DATA binary_compressed\n\x05\0\0\0\x18\0\0\0\x01"), "compressed size 5 exceeds the file"),
        ];
        for (text, fragment) in cases {
            let e = read_pcd(text.as_bytes()).unwrap_err();
            assert!(e.to_string().contains(fragment), "{fragment}: got {e}");
        }
        let no_xyz = read_pcd(b"FIELDS a\nSIZE 4\nTYPE F\nWIDTH 1\nHEIGHT 1\nDATA ascii\n1\n").unwrap();
        assert_eq!(no_xyz.points(), Err(PcdError::MissingField("x")));
    }
}
