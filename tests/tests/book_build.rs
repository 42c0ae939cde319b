//! The design book builds with mdBook (as a library) and has no broken internal link: every
//! relative `href` in the rendered HTML names a file of the built book, and every `#fragment`
//! names an element id on that page. Every `{{#include}}` names a file that exists, and every
//! chapter is reachable from `SUMMARY.md`.

mod common;

use common::{chapters, files_with_extension, workspace};
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Component, Path, PathBuf};

fn book_root() -> PathBuf {
    workspace().join("book")
}

/// The values of every `attr="…"` in `html`, HTML entities for `&` undone.
fn attribute_values(html: &str, attr: &str) -> Vec<String> {
    let needle = format!(" {attr}=\"");
    html.match_indices(&needle)
        .filter_map(|(at, _)| {
            let rest = &html[at + needle.len()..];
            rest.find('"').map(|end| rest[..end].replace("&amp;", "&"))
        })
        .collect()
}

/// `base/relative` with `.` and `..` folded, without touching the file system.
fn join_lexically(base: &Path, relative: &str) -> PathBuf {
    let mut out = PathBuf::new();
    for component in base.join(relative).components() {
        match component {
            Component::ParentDir => {
                out.pop();
            }
            Component::CurDir => {}
            other => out.push(other),
        }
    }
    out
}

fn percent_decode(text: &str) -> String {
    let bytes = text.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        let hex = (bytes[i] == b'%' && i + 2 < bytes.len())
            .then(|| std::str::from_utf8(&bytes[i + 1..i + 3]).ok().and_then(|h| u8::from_str_radix(h, 16).ok()))
            .flatten();
        match hex {
            Some(b) => {
                out.push(b);
                i += 3;
            }
            None => {
                out.push(bytes[i]);
                i += 1;
            }
        }
    }
    String::from_utf8_lossy(&out).into_owned()
}

#[test]
fn the_book_builds_and_every_internal_link_resolves() {
    let root = book_root();
    let out = tempfile::tempdir().unwrap();
    let mut book = mdbook_driver::MDBook::load(&root).unwrap_or_else(|e| panic!("book/ does not load: {e:#}"));
    book.config.build.build_dir = out.path().to_path_buf();
    book.build().unwrap_or_else(|e| panic!("book/ does not build: {e:#}"));

    let pages = files_with_extension(out.path(), "html");
    let ids: BTreeMap<PathBuf, BTreeSet<String>> = pages
        .iter()
        .map(|page| {
            let html = std::fs::read_to_string(page).unwrap();
            (page.clone(), attribute_values(&html, "id").into_iter().collect())
        })
        .collect();
    // The chapters (not mdBook's own 404 and print pages) must be there.
    for chapter in ["introduction", "quickstart", "architecture", "wire", "ros", "configuration", "operations"] {
        assert!(out.path().join(format!("{chapter}.html")).exists(), "{chapter}.html was not built");
    }

    let mut broken = Vec::new();
    let mut checked = 0;
    for page in &pages {
        let name = page.file_name().and_then(|n| n.to_str()).unwrap_or("");
        // print.html repeats every chapter with rewritten links; 404.html is mdBook's.
        if name == "print.html" || name == "404.html" {
            continue;
        }
        let html = std::fs::read_to_string(page).unwrap();
        let dir = page.parent().unwrap();
        for href in attribute_values(&html, "href") {
            if href.contains("://") || href.starts_with("mailto:") || href.starts_with("javascript:") {
                continue;
            }
            let (path, fragment) = href.split_once('#').unwrap_or((&href, ""));
            let path = path.split('?').next().unwrap_or("");
            let target = if path.is_empty() { page.clone() } else { join_lexically(dir, &percent_decode(path)) };
            let target = if target.is_dir() { target.join("index.html") } else { target };
            checked += 1;
            let shown = page.strip_prefix(out.path()).unwrap_or(page).display().to_string();
            if !target.starts_with(out.path()) || !target.exists() {
                broken.push(format!("{shown}: `{href}`: no such file in the built book"));
                continue;
            }
            if fragment.is_empty() || target.extension().is_none_or(|e| e != "html") {
                continue;
            }
            let fragment = percent_decode(fragment);
            if !ids.get(&target).is_some_and(|set| set.contains(&fragment)) {
                broken.push(format!("{shown}: `{href}`: no element with id `{fragment}` on that page"));
            }
        }
    }
    assert!(checked > 100, "only {checked} links checked");
    assert!(broken.is_empty(), "broken links in the book:\n{}", broken.join("\n"));
}

#[test]
fn every_include_names_a_file() {
    let src = book_root().join("src");
    let mut includes = 0;
    for (name, text) in chapters() {
        for (at, _) in text.match_indices("{{#include ") {
            let rest = &text[at + "{{#include ".len()..];
            let spec = rest.split("}}").next().unwrap_or("").trim();
            // `path:anchor` or `path:from:to` select part of the file.
            let file = spec.split(':').next().unwrap_or("");
            includes += 1;
            assert!(src.join(file).is_file(), "{name}: `{{{{#include {spec}}}}}` names no file");
        }
    }
    assert!(includes > 0, "no includes found: the ROS chapter includes its launch file");
}

#[test]
fn every_chapter_is_in_the_summary() {
    let chapters: BTreeMap<String, String> = chapters().into_iter().collect();
    let summary = chapters.get("SUMMARY.md").expect("book/src/SUMMARY.md");
    for name in chapters.keys().filter(|n| *n != "SUMMARY.md") {
        assert!(summary.contains(&format!("({name})")), "book/src/{name} is not linked from SUMMARY.md");
    }
}

/// Every repository file the book names in backticks (`model/src/wire/envelope.rs`,
/// `tests/ros_interop.sh`, …) exists, and every bare `name.rs` is the name of a workspace
/// source file, so the map from equations to code cannot go stale.
#[test]
fn every_file_the_book_names_exists() {
    let repo = book_root().join("..");
    let extensions = [".rs", ".toml", ".sh", ".py", ".launch", ".xml"];
    let source_names: BTreeSet<String> = ["model", "actors", "bridge", "scenarios", "tests"]
        .iter()
        .flat_map(|dir| files_with_extension(&repo.join(dir), "rs"))
        .filter_map(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()))
        .collect();
    let mut named = 0;
    let mut missing = Vec::new();
    for (name, text) in chapters() {
        for (i, span) in text.split('`').enumerate() {
            // Odd pieces are inside backticks; a path has a slash, no spaces and a known extension.
            let path = span.split(':').next().unwrap_or("");
            let bare =
                i % 2 == 1 && !path.contains('/') && path.ends_with(".rs") && !path.contains(char::is_whitespace);
            if bare {
                named += 1;
                if !source_names.contains(path) {
                    missing.push(format!("book/src/{name}: `{path}` (no file of that name in the workspace)"));
                }
                continue;
            }
            let looks_like_file = i % 2 == 1
                && path.contains('/')
                && !path.contains(char::is_whitespace)
                && !path.contains(['*', '{', '$', '<'])
                && !path.starts_with('/')
                && !path.starts_with("..")
                && extensions.iter().any(|e| path.ends_with(e));
            if !looks_like_file {
                continue;
            }
            named += 1;
            if !repo.join(path).exists() {
                missing.push(format!("book/src/{name}: `{path}`"));
            }
        }
    }
    assert!(named > 30, "only {named} file names found");
    assert!(missing.is_empty(), "files the book names that do not exist:\n{}", missing.join("\n"));
}
