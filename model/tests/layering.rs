//! The module layering `lib.rs` documents: each module of `sgm-model` uses only modules below it
//! in `LAYERS`, so nothing reaches sideways-up (read from the sources, `crate::` paths).

use std::path::Path;

/// Lowest first. Modules on one line are peers that do not use each other.
const LAYERS: &[&[&str]] = &[
    &["geometry"],
    &["spatial", "pcd", "snapshot"],
    &["scene_graph"],
    &["perception"],
    &["matching", "optim"],
    &["wire", "eval"],
];

fn layer_of(module: &str) -> Option<usize> {
    LAYERS.iter().position(|layer| layer.contains(&module))
}

fn sources(dir: &Path, out: &mut Vec<std::path::PathBuf>) {
    for entry in std::fs::read_dir(dir).expect("model/src is readable").flatten() {
        let path = entry.path();
        if path.is_dir() {
            sources(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

#[test]
fn no_module_uses_one_above_or_beside_it() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    sources(&src, &mut files);
    let mut offences = Vec::new();
    for file in files {
        let relative = file.strip_prefix(&src).expect("under src");
        let own = relative.components().next().and_then(|c| c.as_os_str().to_str()).unwrap_or("");
        let own = own.trim_end_matches(".rs");
        let Some(own_layer) = layer_of(own) else { continue };
        let text = std::fs::read_to_string(&file).expect("source is UTF-8");
        for (n, line) in text.lines().enumerate() {
            for (at, _) in line.match_indices("crate::") {
                let used: String =
                    line[at + 7..].chars().take_while(|c| c.is_ascii_alphanumeric() || *c == '_').collect();
                let Some(used_layer) = layer_of(&used) else { continue };
                if used != own && used_layer >= own_layer {
                    offences.push(format!("{}:{}: {own} uses {used}", relative.display(), n + 1));
                }
            }
        }
    }
    assert!(offences.is_empty(), "modules reaching sideways or up:\n{}", offences.join("\n"));
}

#[test]
fn every_module_has_a_layer() {
    let lib = std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("src/lib.rs")).expect("lib.rs");
    let modules: Vec<&str> = lib.lines().filter_map(|l| l.strip_prefix("pub mod ")?.strip_suffix(';')).collect();
    assert!(modules.len() >= 9, "lib.rs declares its modules: {modules:?}");
    for module in modules {
        assert!(layer_of(module).is_some(), "{module} is in no layer of this test");
    }
}
