//! Every `sgm` command shown in a shell block of the book or the README parses: its
//! subcommand, flags and enumerated values exist. Each is run as `sgm ARGS --help`, which makes
//! clap check everything before it and then print help instead of running; ROS remappings
//! (`__ns:=/alpha`) are left out, as they are for rosrust, not clap.
//!
//! The prose's inline `sgm …` spans are synopses (`[--json FILE]`, `ascii|binary`): each
//! subcommand in one must exist, and each flag and enumerated value must be in that
//! subcommand's `--help`.

use std::path::{Path, PathBuf};
use std::process::Command;

/// The book's chapters and the README.
fn documents() -> Vec<PathBuf> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let mut out = vec![root.join("README.md")];
    let src = root.join("book/src");
    let mut chapters: Vec<PathBuf> = std::fs::read_dir(&src)
        .unwrap_or_else(|e| panic!("{}: {e}", src.display()))
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|e| e == "md"))
        .collect();
    chapters.sort();
    out.extend(chapters);
    out
}

/// The lines of every ```bash/sh/shell/console block, continuation lines joined.
fn shell_lines(text: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut in_shell = false;
    let mut pending = String::new();
    for line in text.lines() {
        let trimmed = line.trim_start();
        if let Some(info) = trimmed.strip_prefix("```") {
            in_shell = !in_shell && matches!(info.trim(), "bash" | "sh" | "shell" | "console");
            continue;
        }
        if !in_shell {
            continue;
        }
        let line = trimmed.strip_prefix("$ ").unwrap_or(trimmed);
        match line.strip_suffix('\\') {
            Some(head) => pending.push_str(head),
            None => {
                pending.push_str(line);
                out.push(std::mem::take(&mut pending));
            }
        }
    }
    out
}

/// Words of one shell command, quotes removed (enough for documentation examples).
fn words(command: &str) -> Vec<String> {
    let (mut out, mut word, mut quote, mut started) = (Vec::new(), String::new(), None, false);
    for c in command.chars() {
        match (quote, c) {
            (Some(q), c) if c == q => quote = None,
            (Some(_), c) => word.push(c),
            (None, '"' | '\'') => {
                quote = Some(c);
                started = true;
            }
            (None, c) if c.is_whitespace() => {
                if started || !word.is_empty() {
                    out.push(std::mem::take(&mut word));
                }
                started = false;
            }
            (None, c) => word.push(c),
        }
    }
    if started || !word.is_empty() {
        out.push(word);
    }
    out
}

/// The arguments after `sgm` of every command in `line` that runs it.
fn sgm_invocations(line: &str) -> Vec<Vec<String>> {
    let line = line.split(" #").next().unwrap_or("");
    let line = if line.trim_start().starts_with('#') { "" } else { line };
    line.split("&&")
        .flat_map(|c| c.split(';'))
        .flat_map(|c| c.split('|'))
        .filter_map(|segment| {
            // Redirections (`> log`, `2>&1`, `<in`) and a trailing `&` are the shell's.
            let mut w = Vec::new();
            let mut tokens = words(segment).into_iter();
            while let Some(t) = tokens.next() {
                let redirect = ["<", ">", "2>", "&>"].iter().any(|r| t.starts_with(r));
                if redirect {
                    if matches!(t.as_str(), "<" | ">" | ">>" | "2>" | "2>>" | "&>") {
                        tokens.next();
                    }
                } else if t != "&" {
                    w.push(t);
                }
            }
            let mut rest = &w[..];
            // Environment assignments and wrappers before the program.
            while let Some(first) = rest.first() {
                let wrapper = matches!(first.as_str(), "time" | "sudo" | "exec" | "/usr/bin/time" | "-v");
                let assignment = first.contains('=') && !first.starts_with('-');
                if wrapper || assignment {
                    rest = &rest[1..];
                } else {
                    break;
                }
            }
            let program = rest.first()?;
            let args: Vec<String> = if Path::new(program).file_name().is_some_and(|n| n == "sgm") {
                rest[1..].to_vec()
            } else if program == "cargo" && rest.get(1).is_some_and(|a| a == "run") {
                let runs_sgm = rest
                    .windows(2)
                    .any(|p| (p[0] == "--bin" && p[1] == "sgm") || (p[0] == "-p" && p[1] == "sgm-scenarios"));
                let dashes = rest.iter().position(|a| a == "--");
                match (runs_sgm, dashes) {
                    (true, Some(i)) => rest[i + 1..].to_vec(),
                    (true, None) => Vec::new(),
                    _ => return None,
                }
            } else {
                return None;
            };
            Some(args.into_iter().filter(|a| !a.contains(":=")).collect())
        })
        .collect()
}

#[test]
fn every_sgm_command_in_the_book_and_readme_parses() {
    let mut checked = 0;
    let mut failures = Vec::new();
    for document in documents() {
        let text = std::fs::read_to_string(&document).unwrap_or_else(|e| panic!("{}: {e}", document.display()));
        let name = document.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
        for line in shell_lines(&text) {
            for args in sgm_invocations(&line) {
                checked += 1;
                let out =
                    Command::new(env!("CARGO_BIN_EXE_sgm")).args(&args).arg("--help").output().expect("sgm starts");
                if !out.status.success() {
                    failures.push(format!(
                        "{name}: `{}`\n  {}",
                        line.trim(),
                        String::from_utf8_lossy(&out.stderr).trim()
                    ));
                }
            }
        }
    }
    assert!(checked >= 10, "only {checked} sgm commands found in the book and README");
    assert!(failures.is_empty(), "commands that do not parse:\n{}", failures.join("\n"));
}

/// `sgm SUBCOMMAND… --help`: the help text, or None when the path is not a command.
fn help(path: &[String]) -> Option<String> {
    let out = Command::new(env!("CARGO_BIN_EXE_sgm")).args(path).arg("--help").output().expect("sgm starts");
    out.status.success().then(|| String::from_utf8_lossy(&out.stdout).into_owned())
}

/// The subcommands a help text lists under `Commands:`.
fn subcommands(help: &str) -> Vec<String> {
    help.lines()
        .skip_while(|l| !l.starts_with("Commands:"))
        .skip(1)
        .take_while(|l| l.starts_with("  "))
        .filter_map(|l| l.split_whitespace().next().map(str::to_string))
        .collect()
}

/// Every inline code span of `text` that starts with `sgm `, outside fenced blocks.
fn inline_spans(text: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut fenced = false;
    for line in text.lines() {
        if line.trim_start().starts_with("```") {
            fenced = !fenced;
            continue;
        }
        if fenced {
            continue;
        }
        // Odd pieces between backticks are code spans.
        for (k, piece) in line.split('`').enumerate() {
            if k % 2 == 1 && piece.starts_with("sgm ") {
                out.push(piece.to_string());
            }
        }
    }
    out
}

/// What is wrong with the synopsis `span` (`sgm bench messages [--duration S] [--json FILE]`),
/// if anything: an unknown subcommand, or a flag or value its `--help` does not list. A span
/// that names no subcommand first (`sgm node up`, a log line) or holds a placeholder for one
/// (`sgm bench <name>`, `sgm bench …`) is not a command and is skipped.
fn synopsis_problem(span: &str, top: &[String]) -> Option<String> {
    let words: Vec<String> =
        span.split_whitespace().skip(1).map(|w| w.trim_matches(|c| c == '[' || c == ']').to_string()).collect();
    let first = words.first()?;
    if !top.contains(first) {
        return None;
    }
    let mut path = vec![first.clone()];
    let mut text = help(&path)?;
    for w in &words[1..] {
        let subs = subcommands(&text);
        if subs.is_empty() {
            break;
        }
        if w.starts_with('<') || w.contains('…') {
            return None;
        }
        if !subs.contains(w) {
            return Some(format!("`sgm {}` has no subcommand `{w}`", path.join(" ")));
        }
        path.push(w.clone());
        text = help(&path)?;
    }
    let mut after_flag = false;
    for w in words.iter().skip(path.len()) {
        if w.starts_with("--") {
            let flag = w.split('=').next().unwrap_or(w);
            if !text.contains(&format!("{flag} ")) && !text.contains(&format!("{flag}\n")) && !text.ends_with(flag) {
                return Some(format!("`sgm {}` has no flag `{flag}`", path.join(" ")));
            }
            after_flag = true;
        } else if after_flag && w.contains('|') {
            // Enumerated values: each must be a possible value.
            for value in w.split('|').filter(|v| !v.is_empty()) {
                if !text.contains(value) {
                    return Some(format!("`sgm {}` does not list the value `{value}`", path.join(" ")));
                }
            }
            after_flag = false;
        } else {
            after_flag = false;
        }
    }
    None
}

#[test]
fn every_sgm_synopsis_in_the_prose_names_real_subcommands_and_flags() {
    let top = subcommands(&help(&[]).expect("sgm --help"));
    assert!(top.contains(&"run".to_string()), "{top:?}");
    let (mut checked, mut failures) = (0, Vec::new());
    for document in documents() {
        let text = std::fs::read_to_string(&document).unwrap_or_else(|e| panic!("{}: {e}", document.display()));
        let name = document.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
        for span in inline_spans(&text) {
            checked += 1;
            if let Some(problem) = synopsis_problem(&span, &top) {
                failures.push(format!("{name}: `{span}`: {problem}"));
            }
        }
    }
    assert!(checked >= 20, "only {checked} inline sgm spans found");
    assert!(failures.is_empty(), "synopses the binary rejects:\n{}", failures.join("\n"));
    // The check can fail: a flag and a value the binary does not have.
    assert!(synopsis_problem("sgm bench matching --duration 20", &top).is_some_and(|p| p.contains("--duration")));
    assert!(synopsis_problem("sgm pcd-convert A B --format ascii|xml", &top).is_some_and(|p| p.contains("xml")));
    assert!(synopsis_problem("sgm bench nope", &top).is_some());
    assert!(synopsis_problem("sgm node up", &top).is_none());
}

/// `--help` after the arguments does not hide a wrong flag, subcommand or value.
#[test]
fn help_after_wrong_arguments_still_fails() {
    for args in [&["run", "--no-such-flag"][..], &["no-such-command"], &["optimize", "a.g2o", "--robust", "nope"]] {
        let out = Command::new(env!("CARGO_BIN_EXE_sgm")).args(args).arg("--help").output().expect("sgm starts");
        assert!(!out.status.success(), "sgm {args:?} --help succeeded");
    }
}

#[test]
fn the_command_extractor_reads_shell_as_written() {
    let line = r#"RUST_LOG=debug ./target/release/sgm run quickstart --out "runs/a b" > log 2>&1 && cat log"#;
    assert_eq!(sgm_invocations(line), vec![vec!["run", "quickstart", "--out", "runs/a b"]]);
    let cargo = "cargo run --release --bin sgm -- run   # the main job";
    assert_eq!(sgm_invocations(cargo), vec![vec!["run"]]);
    let ros = "sgm ros --robot alpha --config alpha.toml __ns:=/alpha";
    assert_eq!(sgm_invocations(ros), vec![vec!["ros", "--robot", "alpha", "--config", "alpha.toml"]]);
    assert!(sgm_invocations("cargo test --workspace").is_empty());
    assert!(sgm_invocations("# sgm run").is_empty());
    let block = "```bash\nsgm run \\\n  --quiet\n```\n```text\nsgm nonsense\n```\n";
    assert_eq!(shell_lines(block), vec!["sgm run --quiet"]);
}
