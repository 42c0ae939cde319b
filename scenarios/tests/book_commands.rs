//! Every `sgm` command shown in a shell block of the book or the README parses: its
//! subcommand, flags and enumerated values exist. Each is run as `sgm ARGS --help`, which makes
//! clap check everything before it and then print help instead of running; ROS remappings
//! (`__ns:=/alpha`) are left out, as they are for rosrust, not clap.

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
