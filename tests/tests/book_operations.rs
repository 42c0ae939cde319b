//! `book/src/operations.md` against the code. Every message its troubleshooting table quotes
//! (the inline code of the table's "message" column, `…` standing for what the code fills in)
//! is the text of one string literal of the workspace's source, fixed parts in order; every log
//! target the chapter names (`sgm_actors::matcher`, …) is a module of a workspace crate that
//! logs, and every module that logs is named; every `RUST_LOG=` setting it shows parses.
//!
//! The sources are read at test time from `model/src`, `actors/src`, `bridge/src` and
//! `scenarios/src`, without their unit-test modules (whose expected strings would otherwise
//! vouch for themselves).

mod common;

use common::{files_with_extension, table_cells, workspace};
use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

const OPERATIONS: &str = include_str!("../../book/src/operations.md");
/// Crate name (as in a log target) and its directory.
const CRATES: [(&str, &str); 4] =
    [("sgm_model", "model"), ("sgm_actors", "actors"), ("sgm_bridge", "bridge"), ("sgm_scenarios", "scenarios")];
const LEVELS: [&str; 6] = ["trace", "debug", "info", "warn", "error", "off"];
const LOG_MACROS: [&str; 5] =
    ["tracing::trace!", "tracing::debug!", "tracing::info!", "tracing::warn!", "tracing::error!"];

/// (crate directory, path under it, source without its unit tests) of every source file.
fn sources() -> Vec<(&'static str, PathBuf, String)> {
    let mut out = Vec::new();
    for (_, dir) in CRATES {
        let src = workspace().join(dir).join("src");
        for file in files_with_extension(&src, "rs") {
            let text = std::fs::read_to_string(&file).unwrap_or_else(|e| panic!("{}: {e}", file.display()));
            // The unit-test module closes every file that has one.
            let code = text.split("#[cfg(test)]").next().unwrap_or("").to_string();
            let relative = file.strip_prefix(&src).unwrap_or(&file).to_path_buf();
            out.push((dir, relative, code));
        }
    }
    assert!(out.len() > 100, "only {} source files found", out.len());
    out
}

/// The module path of `relative` (under a crate's `src/`): `matcher.rs` → `["matcher"]`,
/// `bag/mod.rs` → `["bag"]`, `lib.rs` → `[]`.
fn module_of(relative: &Path) -> Vec<String> {
    let mut parts: Vec<String> = relative.iter().map(|p| p.to_string_lossy().into_owned()).collect();
    if let Some(last) = parts.pop() {
        let stem = last.trim_end_matches(".rs");
        if !matches!(stem, "mod" | "lib" | "main") {
            parts.push(stem.to_string());
        }
    }
    parts
}

/// Reads the body of a `"…"` literal starting after its opening quote; returns the unescaped
/// text and the index after the closing quote.
fn cooked_string(chars: &[char], mut i: usize) -> (String, usize) {
    let mut text = String::new();
    while let Some(&c) = chars.get(i) {
        i += 1;
        match c {
            '"' => break,
            '\\' => {
                let Some(&e) = chars.get(i) else { break };
                i += 1;
                match e {
                    'n' => text.push('\n'),
                    't' => text.push('\t'),
                    'r' => text.push('\r'),
                    '0' => text.push('\0'),
                    '\n' => {
                        // A line continuation: the newline and the next line's indentation go.
                        while chars.get(i).is_some_and(|c| c.is_whitespace()) {
                            i += 1;
                        }
                    }
                    'u' => {
                        let end = chars[i..].iter().position(|c| *c == '}').map_or(i, |p| i + p);
                        let hex: String = chars.get(i + 1..end).unwrap_or(&[]).iter().collect();
                        text.extend(u32::from_str_radix(&hex, 16).ok().and_then(char::from_u32));
                        i = end + 1;
                    }
                    'x' => {
                        let hex: String = chars.get(i..i + 2).unwrap_or(&[]).iter().collect();
                        text.extend(u8::from_str_radix(&hex, 16).ok().map(char::from));
                        i += 2;
                    }
                    other => text.push(other),
                }
            }
            other => text.push(other),
        }
    }
    (text, i)
}

/// Every string literal of `source`, unescaped: `"…"`, `b"…"`, `r"…"`, `r#"…"#`, `br"…"`.
/// Comments, character literals and lifetimes are skipped.
fn string_literals(source: &str) -> Vec<String> {
    let chars: Vec<char> = source.chars().collect();
    let at = |k: usize| chars.get(k).copied().unwrap_or('\0');
    let mut out = Vec::new();
    let mut i = 0;
    while i < chars.len() {
        let c = at(i);
        if c == '/' && at(i + 1) == '/' {
            while i < chars.len() && at(i) != '\n' {
                i += 1;
            }
        } else if c == '/' && at(i + 1) == '*' {
            i += 2;
            while i < chars.len() && !(at(i) == '*' && at(i + 1) == '/') {
                i += 1;
            }
            i += 2;
        } else if c.is_alphanumeric() || c == '_' {
            // A whole word, so that a word ending in `r` or `b` is not read as a prefix.
            let start = i;
            while at(i).is_alphanumeric() || at(i) == '_' {
                i += 1;
            }
            let word: String = chars[start..i].iter().collect();
            let hashes = chars[i..].iter().take_while(|c| **c == '#').count();
            if matches!(word.as_str(), "r" | "br") && at(i + hashes) == '"' {
                let body = i + hashes + 1;
                let closing: Vec<char> = std::iter::once('"').chain(std::iter::repeat_n('#', hashes)).collect();
                let end = (body..chars.len()).find(|&k| chars[k..].starts_with(&closing)).unwrap_or(chars.len());
                out.push(chars[body..end].iter().collect());
                i = end + closing.len();
            }
            // `b"…"`: the quote is read next as an ordinary string.
        } else if c == '\'' {
            i += if at(i + 1) == '\\' {
                // '\n', '\'', '\u{…}': up to the quote after the escaped character.
                4 + chars.get(i + 3..).unwrap_or(&[]).iter().position(|c| *c == '\'').unwrap_or(0)
            } else if at(i + 2) == '\'' {
                3
            } else {
                1 // a lifetime
            };
        } else if c == '"' {
            let (text, next) = cooked_string(&chars, i + 1);
            out.push(text);
            i = next;
        } else {
            i += 1;
        }
    }
    out
}

/// Whether `literal` holds the fixed parts of `quote` (split at `…`) in order.
fn matches_literal(quote: &str, literal: &str) -> bool {
    let mut rest = literal;
    for fragment in quote.split('…').filter(|f| !f.is_empty()) {
        match rest.find(fragment) {
            Some(at) => rest = &rest[at + fragment.len()..],
            None => return false,
        }
    }
    true
}

/// The inline code spans of `text` (CommonMark: a run of n backticks up to the next run of
/// exactly n; one space stripped from each end when both ends have one).
fn code_spans(text: &str) -> Vec<String> {
    let chars: Vec<char> = text.chars().collect();
    let run = |k: usize| chars[k..].iter().take_while(|c| **c == '`').count();
    let mut out = Vec::new();
    let mut i = 0;
    while i < chars.len() {
        if chars[i] != '`' {
            i += 1;
            continue;
        }
        let n = run(i);
        let start = i + n;
        let mut k = start;
        let mut end = None;
        while k < chars.len() {
            if chars[k] == '`' {
                let m = run(k);
                if m == n {
                    end = Some(k);
                    break;
                }
                k += m;
            } else {
                k += 1;
            }
        }
        let Some(end) = end else { break };
        let content: String = chars[start..end].iter().collect();
        let stripped = match content.strip_prefix(' ').and_then(|c| c.strip_suffix(' ')) {
            Some(inner) if !inner.trim().is_empty() => inner.to_string(),
            _ => content,
        };
        out.push(stripped);
        i = end + n;
    }
    out
}

/// The troubleshooting table's rows, each as its cells.
fn troubleshooting_rows() -> Vec<Vec<String>> {
    let section = OPERATIONS.split("\n## Troubleshooting\n").nth(1).expect("a `## Troubleshooting` section");
    let section = section.split("\n## ").next().unwrap_or(section);
    let mut rows: Vec<Vec<String>> = section.lines().filter(|l| l.starts_with('|')).map(table_cells).collect();
    assert!(rows.len() > 2, "no troubleshooting table");
    let header = rows.remove(0);
    assert_eq!(header, ["symptom", "message", "likely cause", "check / do"], "the table's columns");
    assert!(rows.first().is_some_and(|r| r.iter().all(|c| c.chars().all(|ch| ch == '-' || ch == ':'))));
    rows.remove(0);
    for row in &rows {
        assert_eq!(row.len(), 4, "a row with {} cells (a `|` inside a cell?): {row:?}", row.len());
    }
    rows
}

#[test]
fn the_extractors_read_what_they_should() {
    let source = r###"
        // "not a literal" in a comment
        let c = '"'; let q = '\''; fn f<'a>(x: &'a str) {}
        tracing::warn!(topic, "message refused: {e}");
        format!("frame `{got}`, \
                 `{expected}` expected");
        let raw = r#"raw "quoted" text"#; let b = b"bytes"; let br = br"raw bytes";
        let s = "tab\there \u{2264} \"q\"";
        let number = 12r; let r#type = 1; let for_r = "after r";
    "###;
    let literals = string_literals(source);
    assert_eq!(
        literals,
        [
            "message refused: {e}",
            "frame `{got}`, `{expected}` expected",
            r#"raw "quoted" text"#,
            "bytes",
            "raw bytes",
            "tab\there ≤ \"q\"",
            "after r"
        ]
    );
    assert!(matches_literal("frame `…`, `…` expected", &literals[1]));
    assert!(!matches_literal("frame `…` expected, `…`", &literals[1]));
    assert!(matches_literal("message refused: …", &literals[0]));
    assert_eq!(code_spans("a `one` and `` two `x` `` and ```t``` end"), ["one", "two `x`", "t"]);
    assert_eq!(module_of(Path::new("bag/mod.rs")), ["bag"]);
    assert_eq!(module_of(Path::new("report/plots.rs")), ["report", "plots"]);
    assert!(module_of(Path::new("lib.rs")).is_empty());
}

/// Every message quoted in the troubleshooting table is one string literal of the source.
#[test]
fn every_quoted_message_is_in_the_source() {
    let literals: Vec<String> = sources().iter().flat_map(|(_, _, code)| string_literals(code)).collect();
    assert!(literals.len() > 1000, "only {} string literals read", literals.len());
    let mut quoted = 0;
    let mut missing = Vec::new();
    for row in troubleshooting_rows() {
        let message = &row[1];
        let spans = code_spans(message);
        assert!(!spans.is_empty() || message == "—", "a message cell without a quote and not `—`: {row:?}");
        for quote in spans {
            let fixed: String = quote.split('…').collect();
            assert!(
                fixed.chars().filter(|c| !c.is_whitespace()).count() >= 4,
                "`{quote}`: too little fixed text to check"
            );
            quoted += 1;
            if !literals.iter().any(|l| matches_literal(&quote, l)) {
                missing.push(format!("`{quote}` (symptom: {})", row[0]));
            }
        }
    }
    assert!(quoted >= 40, "only {quoted} messages quoted in the troubleshooting table");
    assert!(missing.is_empty(), "messages the chapter quotes that no source literal holds:\n{}", missing.join("\n"));
}

/// `sgm_crate::module` paths named anywhere in the chapter.
fn named_targets() -> BTreeSet<String> {
    let mut out = BTreeSet::new();
    for (at, _) in OPERATIONS.match_indices("sgm_") {
        let preceded = OPERATIONS[..at].chars().next_back().is_some_and(|c| c.is_alphanumeric() || c == '_');
        let token: String = OPERATIONS[at..]
            .chars()
            .take_while(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || *c == '_' || *c == ':')
            .collect();
        let token = token.trim_end_matches(':');
        if !preceded && token.contains("::") {
            out.insert(token.to_string());
        }
    }
    out
}

/// Every log target the chapter names is a module that logs, and every module that logs is
/// named (a new log source must be documented).
#[test]
fn every_log_target_is_a_module_that_logs() {
    let sources = sources();
    let logging: BTreeSet<String> = sources
        .iter()
        .filter(|(_, _, code)| LOG_MACROS.iter().any(|m| code.contains(m)))
        .map(|(dir, relative, _)| {
            let (name, _) = CRATES.iter().find(|(_, d)| d == dir).copied().unwrap_or(("?", ""));
            std::iter::once(name.to_string()).chain(module_of(relative)).collect::<Vec<_>>().join("::")
        })
        .collect();
    assert!(logging.len() >= 8, "only {} modules log: {logging:?}", logging.len());
    let named = named_targets();
    for target in &named {
        let (krate, path) = target.split_once("::").unwrap_or((target, ""));
        let Some((_, dir)) = CRATES.iter().find(|(name, _)| *name == krate) else {
            panic!("`{target}`: no workspace crate is called {krate}");
        };
        let module = path.replace("::", "/");
        let src = workspace().join(dir).join("src");
        let exists = src.join(format!("{module}.rs")).is_file() || src.join(&module).join("mod.rs").is_file();
        assert!(exists, "`{target}` names no module: neither {dir}/src/{module}.rs nor {dir}/src/{module}/mod.rs");
        assert!(logging.contains(target), "`{target}` is a module, but it logs nothing");
    }
    let unnamed: Vec<&String> = logging.difference(&named).collect();
    assert!(unnamed.is_empty(), "modules that log but are not in the chapter's Logging table: {unnamed:?}");
}

/// Every `RUST_LOG=…` the chapter shows is a valid filter over known targets.
#[test]
fn every_rust_log_setting_parses() {
    let mut settings = 0;
    for (at, _) in OPERATIONS.match_indices("RUST_LOG=") {
        let value: String =
            OPERATIONS[at + "RUST_LOG=".len()..].chars().take_while(|c| !c.is_whitespace() && *c != '`').collect();
        settings += 1;
        for directive in value.split(',') {
            let (target, level) = directive.rsplit_once('=').unwrap_or(("", directive));
            assert!(LEVELS.contains(&level), "RUST_LOG={value}: `{level}` is not a level");
            let known = target.is_empty()
                || target == "rosrust"
                || CRATES.iter().any(|(name, _)| target == *name || target.starts_with(&format!("{name}::")));
            assert!(known, "RUST_LOG={value}: `{target}` is no target of SGM or rosrust");
        }
    }
    assert!(settings >= 3, "only {settings} RUST_LOG settings in the chapter");
}
