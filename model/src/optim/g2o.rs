//! g2o text format: `VERTEX_SE2 id x y θ`, `EDGE_SE2 i j x y θ` + 6 upper-triangular information
//! entries over (x, y, θ); `VERTEX_SE3:QUAT id x y z qx qy qz qw`, `EDGE_SE3:QUAT i j x y z qx qy
//! qz qw` + 21 upper-triangular information entries over (x, y, z, qx, qy, qz); `FIX id`.
//!
//! g2o orders the SE(3) information (translation, rotation); our tangent is (rotation,
//! translation), so the blocks are swapped on reading and writing, exactly as GTSAM's `readG2o`.
//! Keys are u64 (multi-robot files put the robot letter in the top byte). Malformed lines give a
//! [`G2oError`] with the line number and what is wrong; nothing is partially loaded.

use super::factors::Between;
use super::graph::{Graph2, Graph3, PoseGraph};
use super::manifold::Manifold;
use nalgebra::{Isometry2, Isometry3, Quaternion, SMatrix, Translation2, Translation3, UnitComplex, UnitQuaternion};
use std::collections::{HashMap, HashSet};
use std::fmt::Write as _;

/// A g2o file's graph: planar or spatial.
#[derive(Clone, Debug, PartialEq)]
pub enum G2oGraph {
    Planar(Graph2),
    Spatial(Graph3),
}

/// What is wrong with a g2o text, and where.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("line {line}: {message}")]
pub struct G2oError {
    pub line: usize,
    pub message: String,
}

enum Kind {
    Unknown,
    Planar,
    Spatial,
}

struct Builder<G, const D: usize> {
    graph: PoseGraph<G, D>,
    index: HashMap<u64, usize>,
    /// Edges by (from, to) key pair, to count an edge repeated across robot files once.
    seen_edges: HashSet<(u64, u64)>,
    /// (file, line, from, to, measurement, information)
    pending_edges: Vec<(usize, usize, u64, u64, G, SMatrix<f64, D, D>)>,
    /// (file, line, key)
    fixes: Vec<(usize, usize, u64)>,
}

impl<G: Manifold<D>, const D: usize> Builder<G, D> {
    fn new() -> Self {
        Self {
            graph: PoseGraph::default(),
            index: HashMap::new(),
            seen_edges: HashSet::new(),
            pending_edges: Vec::new(),
            fixes: Vec::new(),
        }
    }

    fn vertex(&mut self, line: usize, key: u64, pose: G) -> Result<(), G2oError> {
        if let Some(&k) = self.index.get(&key) {
            // The same vertex in two robot files: keep the first, which must agree.
            let d = self.graph.values[k].inverse().compose(&pose).log().norm();
            if d > 1e-6 {
                return Err(G2oError { line, message: format!("vertex {key} defined twice with different poses") });
            }
            return Ok(());
        }
        self.index.insert(key, self.graph.values.len());
        self.graph.keys.push(key);
        self.graph.values.push(pose);
        self.graph.fixed.push(false);
        Ok(())
    }

    fn finish(mut self) -> Result<PoseGraph<G, D>, (usize, G2oError)> {
        for (file, line, from, to, measured, information) in std::mem::take(&mut self.pending_edges) {
            let lookup = |key: u64| {
                self.index
                    .get(&key)
                    .copied()
                    .ok_or((file, G2oError { line, message: format!("edge refers to unknown vertex {key}") }))
            };
            let (i, j) = (lookup(from)?, lookup(to)?);
            if i == j {
                return Err((file, G2oError { line, message: format!("edge from vertex {from} to itself") }));
            }
            if !self.seen_edges.insert((from, to)) {
                continue;
            }
            let sqrt_information = information
                .cholesky()
                .ok_or((file, G2oError { line, message: "information matrix is not positive definite".into() }))?
                .l()
                .transpose();
            self.graph.betweens.push(Between { from: i, to: j, measured, sqrt_information });
        }
        for (file, line, key) in std::mem::take(&mut self.fixes) {
            let k = self
                .index
                .get(&key)
                .copied()
                .ok_or((file, G2oError { line, message: format!("FIX of unknown vertex {key}") }))?;
            self.graph.fixed[k] = true;
        }
        Ok(self.graph)
    }
}

fn numbers(line: usize, fields: &[&str], count: usize, what: &str) -> Result<Vec<f64>, G2oError> {
    if fields.len() != count {
        return Err(G2oError { line, message: format!("{what} needs {count} numbers, found {}", fields.len()) });
    }
    fields
        .iter()
        .map(|f| match f.parse::<f64>() {
            Ok(v) if v.is_finite() => Ok(v),
            Ok(_) => Err(G2oError { line, message: format!("{what}: {f:?} is not finite") }),
            Err(_) => Err(G2oError { line, message: format!("{what}: {f:?} is not a number") }),
        })
        .collect()
}

fn key(line: usize, field: Option<&&str>) -> Result<u64, G2oError> {
    let field = field.ok_or(G2oError { line, message: "missing vertex id".into() })?;
    field.parse::<u64>().map_err(|_| G2oError { line, message: format!("{field:?} is not a vertex id (u64)") })
}

fn upper_triangular<const D: usize>(values: &[f64]) -> SMatrix<f64, D, D> {
    let mut m = SMatrix::<f64, D, D>::zeros();
    let mut k = 0;
    for r in 0..D {
        for c in r..D {
            m[(r, c)] = values[k];
            m[(c, r)] = values[k];
            k += 1;
        }
    }
    m
}

/// Swaps the (translation, rotation) blocks of a 6 × 6 matrix to (rotation, translation).
fn swap_blocks(m: &SMatrix<f64, 6, 6>) -> SMatrix<f64, 6, 6> {
    let p = SMatrix::<f64, 6, 6>::from_fn(|r, c| if (r + 3) % 6 == c { 1.0 } else { 0.0 });
    p * m * p.transpose()
}

fn quaternion(line: usize, q: &[f64]) -> Result<UnitQuaternion<f64>, G2oError> {
    let raw = Quaternion::new(q[3], q[0], q[1], q[2]);
    if raw.norm() < 1e-9 {
        return Err(G2oError { line, message: "quaternion has zero norm".into() });
    }
    Ok(UnitQuaternion::from_quaternion(raw))
}

/// Parses one or more g2o texts (several robots' files) into one graph. Edges repeated across
/// files (an inter-robot edge in both robots' files) count once.
pub fn read_g2o(texts: &[&str]) -> Result<G2oGraph, (usize, G2oError)> {
    let mut kind = Kind::Unknown;
    let mut planar: Builder<Isometry2<f64>, 3> = Builder::new();
    let mut spatial: Builder<Isometry3<f64>, 6> = Builder::new();
    for (file, text) in texts.iter().enumerate() {
        for (n, raw) in text.lines().enumerate() {
            let line = n + 1;
            let at = |e: G2oError| (file, e);
            let fields: Vec<&str> = raw.split_whitespace().collect();
            let Some(tag) = fields.first() else { continue };
            if tag.starts_with('#') {
                continue;
            }
            let mut expect = |want: Kind, what: &str| -> Result<(), (usize, G2oError)> {
                match (&kind, &want) {
                    (Kind::Unknown, _) => {
                        kind = want;
                        Ok(())
                    }
                    (Kind::Planar, Kind::Planar) | (Kind::Spatial, Kind::Spatial) => Ok(()),
                    _ => Err((file, G2oError { line, message: format!("{what} mixes SE(2) and SE(3) elements") })),
                }
            };
            match *tag {
                "VERTEX_SE2" => {
                    expect(Kind::Planar, tag)?;
                    let id = key(line, fields.get(1)).map_err(at)?;
                    let v = numbers(line, &fields[2..], 3, tag).map_err(at)?;
                    let pose = Isometry2::from_parts(Translation2::new(v[0], v[1]), UnitComplex::new(v[2]));
                    planar.vertex(line, id, pose).map_err(at)?;
                }
                "EDGE_SE2" => {
                    expect(Kind::Planar, tag)?;
                    let (i, j) = (key(line, fields.get(1)).map_err(at)?, key(line, fields.get(2)).map_err(at)?);
                    let v = numbers(line, fields.get(3..).unwrap_or(&[]), 9, tag).map_err(at)?;
                    let measured = Isometry2::from_parts(Translation2::new(v[0], v[1]), UnitComplex::new(v[2]));
                    planar.pending_edges.push((file, line, i, j, measured, upper_triangular::<3>(&v[3..])));
                }
                "VERTEX_SE3:QUAT" => {
                    expect(Kind::Spatial, tag)?;
                    let id = key(line, fields.get(1)).map_err(at)?;
                    let v = numbers(line, &fields[2..], 7, tag).map_err(at)?;
                    let pose = Isometry3::from_parts(
                        Translation3::new(v[0], v[1], v[2]),
                        quaternion(line, &v[3..]).map_err(at)?,
                    );
                    spatial.vertex(line, id, pose).map_err(at)?;
                }
                "EDGE_SE3:QUAT" => {
                    expect(Kind::Spatial, tag)?;
                    let (i, j) = (key(line, fields.get(1)).map_err(at)?, key(line, fields.get(2)).map_err(at)?);
                    let v = numbers(line, fields.get(3..).unwrap_or(&[]), 28, tag).map_err(at)?;
                    let measured = Isometry3::from_parts(
                        Translation3::new(v[0], v[1], v[2]),
                        quaternion(line, &v[3..7]).map_err(at)?,
                    );
                    let information = swap_blocks(&upper_triangular::<6>(&v[7..]));
                    spatial.pending_edges.push((file, line, i, j, measured, information));
                }
                "FIX" => {
                    for f in &fields[1..] {
                        let id = key(line, Some(f)).map_err(at)?;
                        planar.fixes.push((file, line, id));
                        spatial.fixes.push((file, line, id));
                    }
                }
                other => {
                    return Err((file, G2oError { line, message: format!("unknown element {other:?}") }));
                }
            }
        }
    }
    match kind {
        Kind::Spatial => Ok(G2oGraph::Spatial(spatial.finish()?)),
        Kind::Planar | Kind::Unknown => Ok(G2oGraph::Planar(planar.finish()?)),
    }
}

fn write_upper<const D: usize>(out: &mut String, m: &SMatrix<f64, D, D>) {
    for r in 0..D {
        for c in r..D {
            let _ = write!(out, " {}", m[(r, c)]);
        }
    }
}

/// Writes a graph back as g2o text (vertices at their current values).
pub fn write_g2o(graph: &G2oGraph) -> String {
    let mut out = String::new();
    match graph {
        G2oGraph::Planar(g) => {
            for (k, v) in g.keys.iter().zip(&g.values) {
                let t = v.translation.vector;
                let _ = writeln!(out, "VERTEX_SE2 {k} {} {} {}", t.x, t.y, v.rotation.angle());
            }
            for e in &g.betweens {
                let t = e.measured.translation.vector;
                let _ = write!(
                    out,
                    "EDGE_SE2 {} {} {} {} {}",
                    g.keys[e.from],
                    g.keys[e.to],
                    t.x,
                    t.y,
                    e.measured.rotation.angle()
                );
                write_upper(&mut out, &(e.sqrt_information.transpose() * e.sqrt_information));
                out.push('\n');
            }
            write_fixes(&mut out, &g.keys, &g.fixed);
        }
        G2oGraph::Spatial(g) => {
            for (k, v) in g.keys.iter().zip(&g.values) {
                let (t, q) = (v.translation.vector, v.rotation.coords);
                let _ = writeln!(out, "VERTEX_SE3:QUAT {k} {} {} {} {} {} {} {}", t.x, t.y, t.z, q.x, q.y, q.z, q.w);
            }
            for e in &g.betweens {
                let (t, q) = (e.measured.translation.vector, e.measured.rotation.coords);
                let _ = write!(
                    out,
                    "EDGE_SE3:QUAT {} {} {} {} {} {} {} {} {}",
                    g.keys[e.from], g.keys[e.to], t.x, t.y, t.z, q.x, q.y, q.z, q.w
                );
                write_upper(&mut out, &swap_blocks(&(e.sqrt_information.transpose() * e.sqrt_information)));
                out.push('\n');
            }
            write_fixes(&mut out, &g.keys, &g.fixed);
        }
    }
    out
}

fn write_fixes(out: &mut String, keys: &[u64], fixed: &[bool]) {
    for (k, f) in keys.iter().zip(fixed) {
        if *f {
            let _ = writeln!(out, "FIX {k}");
        }
    }
}
