//! The book's reference chapters against the code. `book/src/configuration.md`: every key of
//! `RobotConfig` is listed with its true default, nothing listed is unknown, and every TOML
//! example loads. `book/src/scenarios.md`: the same for the scenario file's own sections and a
//! robot entry. `book/src/ros.md`: the `[ros]` section's keys. Every TOML example anywhere in
//! the book loads as the file it shows.

mod common;

use common::{chapters, workspace};
use serde_json::Value;
use sgm_actors::config::RobotConfig;
use sgm_bridge::config::RosConfig;
use sgm_bridge::node::NodeConfig;
use sgm_scenarios::scenario::{FalseFactorSpec, RobotSpec, Scenario};
use std::collections::BTreeMap;

const CONFIGURATION: &str = include_str!("../../book/src/configuration.md");
const SCENARIOS: &str = include_str!("../../book/src/scenarios.md");
const ROS: &str = include_str!("../../book/src/ros.md");
const OWN_SECTIONS: [&str; 10] =
    ["scenario", "world", "terrain", "platforms", "lidar", "camera", "segmentation", "imu", "odometry", "radio"];
/// Tables documented as a whole rather than key by key.
const WHOLE: [&str; 7] = [
    "fusion.classes",
    "classes.map",
    "classes.palette",
    "ros.frames.aliases",
    "world.objects",
    "robots[].route",
    "segmentation.confusion",
];

/// Dotted key → default value; arrays and the `WHOLE` tables are leaves.
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

/// A default as written in the book (a TOML value, or "unset" for an absent option), as JSON.
fn parse_toml_value(text: &str) -> Option<Value> {
    if text == "unset" {
        return Some(Value::Null);
    }
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

/// Every key of `defaults` is listed with its default, and every listed key exists.
fn check_reference(chapter: &str, listed: &[(String, String)], defaults: &BTreeMap<String, Value>) {
    let by_key: BTreeMap<&str, &str> = listed.iter().map(|(k, d)| (k.as_str(), d.as_str())).collect();
    for (key, value) in defaults {
        let Some(text) = by_key.get(key.as_str()) else { panic!("`{key}` is not in book/src/{chapter}") };
        if WHOLE.contains(&key.as_str()) {
            continue;
        }
        // An optional key without a default: "none" in the book, null in the code.
        if *text == "none" {
            assert!(value.is_null(), "`{key}`: the book says none, the code {value}");
            continue;
        }
        let written = parse_toml_value(text).unwrap_or_else(|| panic!("`{key}`: default {text:?} is not a TOML value"));
        assert!(same(&written, value), "`{key}`: the book says {text}, the code {value}");
    }
    for (key, _) in listed {
        assert!(defaults.contains_key(key), "book/src/{chapter} lists `{key}`, which the code does not have");
    }
}

/// (key, default text) of every table row whose first cell is a key in backticks.
fn rows(text: &str) -> Vec<(String, String)> {
    text.lines()
        .filter_map(|line| {
            let cells: Vec<&str> = line.split('|').map(str::trim).collect();
            let key = cells.get(1)?.strip_prefix('`')?.strip_suffix('`')?;
            Some((key.to_string(), cells.get(2)?.to_string()))
        })
        .collect()
}

/// The ```toml blocks of a chapter.
fn toml_blocks(chapter: &str) -> Vec<&str> {
    chapter.split("```toml\n").skip(1).filter_map(|b| b.split("```").next()).collect()
}

/// Rows of the configuration chapter; the ICP table's relative keys ("matcher / loop closure"
/// defaults) expand to both sections, and `section.icp.*` pointers are skipped.
fn configuration_rows() -> Vec<(String, String)> {
    let (main, icp) = CONFIGURATION.split_once("## ICP tables").unwrap_or((CONFIGURATION, ""));
    let mut out: Vec<(String, String)> = rows(main).into_iter().filter(|(k, _)| !k.ends_with(".*")).collect();
    for (key, default) in rows(icp) {
        let (matcher, loops) = default.split_once(" / ").unwrap_or((&default, &default));
        out.push((format!("matcher.icp.{key}"), matcher.to_string()));
        out.push((format!("tracker.loop_closure.icp.{key}"), loops.to_string()));
    }
    out
}

#[test]
fn book_configuration_reference() {
    let mut defaults = BTreeMap::new();
    flatten("", &serde_json::to_value(RobotConfig::default()).unwrap(), &mut defaults);
    assert!(defaults.len() > 50, "{} keys flattened", defaults.len());
    check_reference("configuration.md", &configuration_rows(), &defaults);
}

#[test]
fn book_scenario_reference() {
    let mut defaults = BTreeMap::new();
    let scenario = serde_json::to_value(Scenario::default()).unwrap();
    for section in OWN_SECTIONS {
        flatten(section, &scenario[section], &mut defaults);
    }
    flatten("robots[]", &serde_json::to_value(RobotSpec::default()).unwrap(), &mut defaults);
    flatten("false_factors[]", &serde_json::to_value(FalseFactorSpec::default()).unwrap(), &mut defaults);
    assert!(defaults.len() > 30, "{} keys", defaults.len());
    let reference = SCENARIOS.split("## Scenario file reference").nth(1).unwrap_or("");
    check_reference("scenarios.md", &rows(reference), &defaults);
}

#[test]
fn book_ros_reference() {
    let mut defaults = BTreeMap::new();
    flatten("ros", &serde_json::to_value(RosConfig::default()).unwrap(), &mut defaults);
    assert!(defaults.len() > 20, "{} keys", defaults.len());
    let section = ROS.split("## The `[ros]` section").nth(1).unwrap_or("");
    let section = section.split("\n## ").next().unwrap_or("");
    check_reference("ros.md", &rows(section), &defaults);
}

/// A block's text, with a whole-block `{{#include FILE}}` replaced by the file.
fn resolve_include(block: &str) -> String {
    let trimmed = block.trim();
    match trimmed.strip_prefix("{{#include ").and_then(|r| r.strip_suffix("}}")) {
        Some(file) => {
            let path = workspace().join("book/src").join(file.trim());
            std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        }
        None => block.to_string(),
    }
}

/// Every ```toml block in the book loads as what it shows: a scenario file (it has a
/// `[scenario]` table), a node configuration (it has `[ros]` tables), or else a robot
/// configuration.
#[test]
fn every_toml_example_in_the_book_loads() {
    let (mut scenarios, mut nodes, mut robots) = (0, 0, 0);
    for (chapter, text) in chapters() {
        for block in toml_blocks(&text) {
            let block = resolve_include(block);
            let has_table = |name: &str| {
                block.lines().any(|l| l.trim() == format!("[{name}]") || l.trim().starts_with(&format!("[{name}.")))
            };
            let result = if has_table("scenario") {
                scenarios += 1;
                Scenario::from_toml(&block, "book", "SGM_BOOK_SCENARIO_TEST").map(|_| ()).map_err(|e| e.to_string())
            } else {
                let file = tempfile::Builder::new().suffix(".toml").tempfile().unwrap();
                std::fs::write(file.path(), &block).unwrap();
                if has_table("ros") {
                    nodes += 1;
                    NodeConfig::load(Some(file.path())).map(|_| ()).map_err(|e| e.to_string())
                } else {
                    robots += 1;
                    RobotConfig::load_with_env(Some(file.path()), "SGM_BOOK_TEST")
                        .map(|_| ())
                        .map_err(|e| e.to_string())
                }
            };
            if let Err(e) = result {
                panic!("book/src/{chapter}: a TOML example does not load: {e}\n{block}");
            }
        }
    }
    assert!(scenarios >= 1 && nodes >= 1 && robots >= 2, "{scenarios} scenario, {nodes} node, {robots} robot examples");
}
