//! The module layering inside a crate: each module of `sgm-model` and of the `sgm-scenarios`
//! library uses only modules below it in its crate's layers, so nothing reaches sideways-up and
//! no two modules depend on each other (read from the sources, `crate::` paths; each crate's
//! `lib.rs` documents its order).

use std::path::Path;

type Layers = &'static [&'static [&'static str]];

/// Lowest first. Modules on one line are peers that do not use each other.
const MODEL: Layers = &[
    &["geometry", "workers"],
    &["spatial", "pcd", "snapshot"],
    &["scene_graph"],
    &["perception"],
    &["matching", "optim", "odometry"],
    &["wire", "eval"],
];

/// The library of `sgm-scenarios` (the binary's `bench` and `cli` sit on top of all of it).
const SCENARIOS: Layers = &[
    &["memory", "object_file", "observation", "output_error", "settings", "threads"],
    &["scenario"],
    &["sim"],
    &["record", "bag_out", "bag_odometry"],
    &["report", "team", "front_end"],
    &["result_bag"],
    &["runner", "replay"],
];

fn layer_of(layers: Layers, module: &str) -> Option<usize> {
    layers.iter().position(|layer| layer.contains(&module))
}

fn crate_src(name: &str) -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..").join(name).join("src")
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

/// Every `crate::` path from a module to one at or above its own layer.
fn offences(src: &Path, layers: Layers) -> Vec<String> {
    let mut files = Vec::new();
    sources(src, &mut files);
    let mut offences = Vec::new();
    for file in files {
        let relative = file.strip_prefix(src).expect("under src");
        let own = relative.components().next().and_then(|c| c.as_os_str().to_str()).unwrap_or("");
        let own = own.trim_end_matches(".rs");
        let Some(own_layer) = layer_of(layers, own) else { continue };
        let text = std::fs::read_to_string(&file).expect("source is UTF-8");
        for (n, line) in text.lines().enumerate() {
            for (at, _) in line.match_indices("crate::") {
                let used: String =
                    line[at + 7..].chars().take_while(|c| c.is_ascii_alphanumeric() || *c == '_').collect();
                let Some(used_layer) = layer_of(layers, &used) else { continue };
                if used != own && used_layer >= own_layer {
                    offences.push(format!("{}:{}: {own} uses {used}", relative.display(), n + 1));
                }
            }
        }
    }
    offences
}

#[test]
fn no_module_of_the_model_uses_one_above_or_beside_it() {
    let offences = offences(&crate_src("model"), MODEL);
    assert!(offences.is_empty(), "modules reaching sideways or up:\n{}", offences.join("\n"));
}

#[test]
fn no_module_of_the_scenarios_library_uses_one_above_or_beside_it() {
    let offences = offences(&crate_src("scenarios"), SCENARIOS);
    assert!(offences.is_empty(), "modules reaching sideways or up:\n{}", offences.join("\n"));
}

#[test]
fn every_module_has_a_layer() {
    for (name, layers) in [("model", MODEL), ("scenarios", SCENARIOS)] {
        let lib = std::fs::read_to_string(crate_src(name).join("lib.rs")).expect("lib.rs");
        let modules: Vec<&str> = lib.lines().filter_map(|l| l.strip_prefix("pub mod ")?.strip_suffix(';')).collect();
        assert!(modules.len() >= 9, "{name}'s lib.rs declares its modules: {modules:?}");
        for module in modules {
            assert!(layer_of(layers, module).is_some(), "{name}: {module} is in no layer of this test");
        }
    }
}

/// The modules of `src` each module uses (`crate::` paths, doc comments included).
fn uses(src: &Path) -> std::collections::BTreeMap<String, std::collections::BTreeSet<String>> {
    let lib = std::fs::read_to_string(src.join("lib.rs")).expect("lib.rs");
    let modules: std::collections::BTreeSet<String> = lib
        .lines()
        .filter_map(|l| l.trim_start_matches("pub ").strip_prefix("mod ")?.strip_suffix(';'))
        .map(String::from)
        .collect();
    let mut files = Vec::new();
    sources(src, &mut files);
    let mut graph: std::collections::BTreeMap<String, std::collections::BTreeSet<String>> =
        modules.iter().map(|m| (m.clone(), Default::default())).collect();
    for file in files {
        let relative = file.strip_prefix(src).expect("under src");
        let own = relative.components().next().and_then(|c| c.as_os_str().to_str()).unwrap_or("");
        let own = own.trim_end_matches(".rs").to_string();
        if !modules.contains(&own) {
            continue;
        }
        let text = std::fs::read_to_string(&file).expect("source is UTF-8");
        for (at, _) in text.match_indices("crate::") {
            let used: String = text[at + 7..].chars().take_while(|c| c.is_ascii_alphanumeric() || *c == '_').collect();
            if used != own && modules.contains(&used) {
                graph.entry(own.clone()).or_default().insert(used);
            }
        }
    }
    graph
}

/// A cycle among the modules of `graph`, if there is one.
fn cycle(graph: &std::collections::BTreeMap<String, std::collections::BTreeSet<String>>) -> Option<Vec<String>> {
    fn visit(
        node: &str,
        graph: &std::collections::BTreeMap<String, std::collections::BTreeSet<String>>,
        path: &mut Vec<String>,
        done: &mut std::collections::BTreeSet<String>,
    ) -> Option<Vec<String>> {
        if let Some(at) = path.iter().position(|p| p == node) {
            return Some(path[at..].iter().cloned().chain([node.to_string()]).collect());
        }
        if done.contains(node) {
            return None;
        }
        path.push(node.to_string());
        for next in graph.get(node).into_iter().flatten() {
            if let Some(found) = visit(next, graph, path, done) {
                return Some(found);
            }
        }
        path.pop();
        done.insert(node.to_string());
        None
    }
    let mut done = std::collections::BTreeSet::new();
    graph.keys().find_map(|node| visit(node, graph, &mut Vec::new(), &mut done))
}

/// The actors and the bridge have no fixed layer table, but no two of their modules depend on
/// each other, directly or around a loop.
#[test]
fn the_actors_and_the_bridge_have_no_module_cycle() {
    for name in ["actors", "bridge", "model", "scenarios"] {
        let graph = uses(&crate_src(name));
        assert!(graph.len() >= 9, "{name}: {graph:?}");
        if let Some(found) = cycle(&graph) {
            panic!("{name}: modules in a cycle: {}", found.join(" → "));
        }
    }
    // The check finds a cycle where there is one.
    let mut looped = uses(&crate_src("actors"));
    looped.entry("clock".into()).or_default().insert("supervisor".into());
    assert!(cycle(&looped).is_some_and(|c| c.contains(&"clock".to_string())));
}
