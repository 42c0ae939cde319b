//! The book's configuration reference (`book/src/configuration.md`) against the code: every key
//! of `RobotConfig` is listed with its true default, nothing listed is unknown, and every TOML
//! example in the chapter loads.

use serde_json::Value;
use sgm_actors::config::RobotConfig;
use std::collections::BTreeMap;

const CHAPTER: &str = include_str!("../../book/src/configuration.md");

/// Dotted key → default value; arrays are leaves; the class table is one key.
fn flatten(prefix: &str, value: &Value, out: &mut BTreeMap<String, Value>) {
    match value {
        Value::Object(map) if prefix != "fusion.classes" => {
            for (k, v) in map {
                let key = if prefix.is_empty() { k.clone() } else { format!("{prefix}.{k}") };
                flatten(&key, v, out);
            }
        }
        _ => {
            out.insert(prefix.to_string(), value.clone());
        }
    }
}

/// A default as written in the book (a TOML value), as JSON.
fn parse_toml_value(text: &str) -> Option<Value> {
    let source = config::File::from_str(&format!("v = {text}"), config::FileFormat::Toml);
    config::Config::builder().add_source(source).build().ok()?.get::<Value>("v").ok()
}

fn same(a: &Value, b: &Value) -> bool {
    match (a, b) {
        (Value::Number(x), Value::Number(y)) => {
            let (x, y) = (x.as_f64().unwrap_or(f64::NAN), y.as_f64().unwrap_or(f64::NAN));
            (x - y).abs() <= 1e-12 * x.abs().max(y.abs())
        }
        (Value::Array(x), Value::Array(y)) => x.len() == y.len() && x.iter().zip(y).all(|(x, y)| same(x, y)),
        _ => a == b,
    }
}

/// (key, default text) of every table row whose first cell is a key in backticks. Rows of the
/// ICP table (relative keys, "matcher / loop closure" defaults) expand to both sections.
fn documented() -> Vec<(String, String)> {
    let mut rows = Vec::new();
    let mut in_icp = false;
    for line in CHAPTER.lines() {
        if line.starts_with("## ") {
            in_icp = line == "## ICP tables";
        }
        let cells: Vec<&str> = line.split('|').map(str::trim).collect();
        let (Some(key), Some(default)) = (cells.get(1), cells.get(2)) else { continue };
        let Some(key) = key.strip_prefix('`').and_then(|k| k.strip_suffix('`')) else { continue };
        if key.ends_with(".*") {
            continue;
        }
        if in_icp {
            let (matcher, loops) = default.split_once(" / ").unwrap_or((default, default));
            rows.push((format!("matcher.icp.{key}"), matcher.to_string()));
            rows.push((format!("tracker.loop_closure.icp.{key}"), loops.to_string()));
        } else {
            rows.push((key.to_string(), default.to_string()));
        }
    }
    rows
}

#[test]
fn book_configuration_reference() {
    let mut defaults = BTreeMap::new();
    flatten("", &serde_json::to_value(RobotConfig::default()).unwrap(), &mut defaults);
    let rows = documented();
    let listed: BTreeMap<&str, &str> = rows.iter().map(|(k, d)| (k.as_str(), d.as_str())).collect();
    for (key, value) in &defaults {
        let Some(text) = listed.get(key.as_str()) else { panic!("`{key}` is not in book/src/configuration.md") };
        if key == "fusion.classes" {
            continue;
        }
        let written = parse_toml_value(text).unwrap_or_else(|| panic!("`{key}`: default {text:?} is not a TOML value"));
        assert!(same(&written, value), "`{key}`: the book says {text}, the code {value}");
    }
    for (key, _) in &rows {
        assert!(defaults.contains_key(key), "the book lists `{key}`, which RobotConfig does not have");
    }
    assert!(defaults.len() > 50, "{} keys flattened", defaults.len());
}

#[test]
fn every_toml_example_in_the_chapter_loads() {
    let blocks: Vec<&str> = CHAPTER.split("```toml\n").skip(1).filter_map(|b| b.split("```").next()).collect();
    assert!(blocks.len() >= 2);
    for block in blocks {
        let file = tempfile::Builder::new().suffix(".toml").tempfile().unwrap();
        std::fs::write(file.path(), block).unwrap();
        if let Err(e) = RobotConfig::load_with_env(Some(file.path()), "SGM_BOOK_TEST") {
            panic!("{e}\n{block}");
        }
    }
}
