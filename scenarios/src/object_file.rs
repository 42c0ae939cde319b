//! The object-graph file of `sgm match` (a stable contract):
//! `{"robot": "a", "objects": [{"id": 3, "label": "chair", "centroid": [x, y, z], "size": [dx, dy, dz]}]}`
//! `size` is optional, labels are strings, ids are unique u32 within a file. Unknown fields are
//! ignored so that exporters may add their own.

use serde::Deserialize;
use sgm_model::matching::{GraphError, GraphObject, LabelSimilarity, MatcherConfig, ObjectGraph};
use sgm_model::scene_graph::{LabelId, ObjectId};
use std::collections::BTreeSet;
use std::path::Path;

#[derive(Debug, Deserialize)]
pub struct ObjectFile {
    pub robot: String,
    pub objects: Vec<ObjectEntry>,
}

#[derive(Debug, Deserialize)]
pub struct ObjectEntry {
    pub id: u32,
    pub label: String,
    pub centroid: [f64; 3],
    #[serde(default)]
    pub size: Option<[f64; 3]>,
}

/// Largest object file read, bytes (bounds memory before parsing).
pub const MAX_FILE_BYTES: u64 = 64 << 20;

/// An object file that cannot be used; the message names the file and what is wrong.
#[derive(Debug, thiserror::Error)]
#[error("{path}: {message}")]
pub struct ObjectFileError {
    pub path: String,
    pub message: String,
}

impl ObjectFile {
    /// Reads and checks a file: readable, bounded, valid JSON of the right shape, finite numbers,
    /// unique ids.
    pub fn load(path: &Path) -> Result<Self, ObjectFileError> {
        let err = |message: String| ObjectFileError { path: path.display().to_string(), message };
        let meta = std::fs::metadata(path).map_err(|e| err(format!("cannot read: {e}")))?;
        if meta.len() > MAX_FILE_BYTES {
            return Err(err(format!("file is {} bytes, more than the limit of {MAX_FILE_BYTES}", meta.len())));
        }
        let bytes = std::fs::read(path).map_err(|e| err(format!("cannot read: {e}")))?;
        let file: ObjectFile = serde_json::from_slice(&bytes).map_err(|e| err(format!("invalid object file: {e}")))?;
        let mut seen = BTreeSet::new();
        for (k, o) in file.objects.iter().enumerate() {
            if !seen.insert(o.id) {
                return Err(err(format!("objects[{k}]: duplicate id {}", o.id)));
            }
            if o.centroid.iter().any(|v| !v.is_finite()) {
                return Err(err(format!("objects[{k}] (id {}): centroid is not finite", o.id)));
            }
            if let Some(size) = o.size {
                if size.iter().any(|v| !v.is_finite() || *v < 0.0) {
                    return Err(err(format!("objects[{k}] (id {}): size must be finite and non-negative", o.id)));
                }
            }
            if o.label.is_empty() {
                return Err(err(format!("objects[{k}] (id {}): empty label", o.id)));
            }
        }
        Ok(file)
    }
}

/// Label names to ids, in sorted order so that ids do not depend on file order.
#[derive(Debug, Clone, Default)]
pub struct LabelTable {
    names: Vec<String>,
}

impl LabelTable {
    pub fn new<'a>(names: impl IntoIterator<Item = &'a str>) -> Self {
        let set: BTreeSet<&str> = names.into_iter().collect();
        Self { names: set.into_iter().map(str::to_owned).collect() }
    }

    pub fn id(&self, name: &str) -> Option<LabelId> {
        self.names.binary_search_by(|n| n.as_str().cmp(name)).ok().map(|k| LabelId(k as u16))
    }

    pub fn len(&self) -> usize {
        self.names.len()
    }

    pub fn is_empty(&self) -> bool {
        self.names.is_empty()
    }

    /// d_v over this table from the matcher configuration.
    pub fn similarity(&self, config: &MatcherConfig) -> LabelSimilarity {
        let mut s = LabelSimilarity::uniform(self.len(), config.mislabel_similarity);
        for c in &config.label_confusion {
            if let (Some(a), Some(b)) = (self.id(&c.a), self.id(&c.b)) {
                s.set(a, b, c.similarity);
            }
        }
        s
    }
}

/// Two object files that do not make graphs.
#[derive(Debug, thiserror::Error)]
pub enum GraphsError {
    #[error("{count} distinct labels, more than {}", u16::MAX)]
    TooManyLabels { count: usize },
    #[error("robot {robot:?}: {source}")]
    Graph { robot: String, source: GraphError },
}

/// Two object files as graphs over one label table.
pub fn graphs_from_files(
    local: &ObjectFile,
    remote: &ObjectFile,
    config: &MatcherConfig,
) -> Result<(ObjectGraph, ObjectGraph, LabelSimilarity), GraphsError> {
    let names = local.objects.iter().chain(&remote.objects).map(|o| o.label.as_str());
    let table = LabelTable::new(names);
    if table.len() > u16::MAX as usize {
        return Err(GraphsError::TooManyLabels { count: table.len() });
    }
    let to_graph = |file: &ObjectFile| {
        let objects = file
            .objects
            .iter()
            .map(|o| GraphObject {
                id: ObjectId(o.id),
                label: table.id(&o.label).unwrap_or(LabelId(0)),
                centroid: o.centroid.into(),
                size: o.size.map(Into::into),
            })
            .collect();
        ObjectGraph::new(objects, config.max_objects)
            .map_err(|source| GraphsError::Graph { robot: file.robot.clone(), source })
    };
    Ok((to_graph(local)?, to_graph(remote)?, table.similarity(config)))
}
