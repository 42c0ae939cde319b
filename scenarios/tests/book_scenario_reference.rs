//! The book's scenario reference (`book/src/scenarios.md`) against the code: every key of the
//! scenario's own sections and of a robot entry is listed with its true default, nothing listed
//! is unknown, and every TOML example in the chapter loads.

use serde_json::Value;
use sgm_scenarios::scenario::{RobotSpec, Scenario};
use std::collections::BTreeMap;

const CHAPTER: &str = include_str!("../../book/src/scenarios.md");
const OWN_SECTIONS: [&str; 6] = ["scenario", "world", "lidar", "camera", "odometry", "radio"];
/// Tables documented as a whole rather than key by key.
const WHOLE: [&str; 2] = ["world.objects", "robots[].route"];

fn flatten(prefix: &str, value: &Value, out: &mut BTreeMap<String, Value>) {
    match value {
        Value::Object(map) if !WHOLE.contains(&prefix) => {
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

#[test]
fn book_scenario_reference() {
    let mut defaults = BTreeMap::new();
    let scenario = serde_json::to_value(Scenario::default()).unwrap();
    for section in OWN_SECTIONS {
        flatten(section, &scenario[section], &mut defaults);
    }
    flatten("robots[]", &serde_json::to_value(RobotSpec::default()).unwrap(), &mut defaults);
    let mut listed = BTreeMap::new();
    let reference = CHAPTER.split("## Scenario file reference").nth(1).unwrap_or("");
    for line in reference.lines() {
        let cells: Vec<&str> = line.split('|').map(str::trim).collect();
        let (Some(key), Some(default)) = (cells.get(1), cells.get(2)) else { continue };
        if let Some(key) = key.strip_prefix('`').and_then(|k| k.strip_suffix('`')) {
            listed.insert(key.to_string(), default.to_string());
        }
    }
    for (key, value) in &defaults {
        let text = listed.get(key).unwrap_or_else(|| panic!("`{key}` is not in book/src/scenarios.md"));
        if WHOLE.contains(&key.as_str()) {
            continue;
        }
        let written = parse_toml_value(text).unwrap_or_else(|| panic!("`{key}`: default {text:?} is not a TOML value"));
        assert!(same(&written, value), "`{key}`: the book says {text}, the code {value}");
    }
    for key in listed.keys() {
        assert!(defaults.contains_key(key), "the book lists `{key}`, which the scenario file does not have");
    }
    assert!(defaults.len() > 30, "{} keys", defaults.len());
}

#[test]
fn every_toml_example_in_the_chapter_loads() {
    let blocks: Vec<&str> = CHAPTER.split("```toml\n").skip(1).filter_map(|b| b.split("```").next()).collect();
    assert!(!blocks.is_empty());
    for block in blocks {
        if let Err(e) = Scenario::from_toml(block, "book", "SGM_BOOK_SCENARIO_TEST") {
            panic!("{e}\n{block}");
        }
    }
}
