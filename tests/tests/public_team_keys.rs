//! Every team key printed where anyone can read it — the book, the README, the scenario library,
//! the ROS package's configurations and launch files — is on `sgm_actors::config::PUBLIC_TEAM_KEYS`,
//! so `sgm ros` refuses it. A key added to the docs later without being listed fails here.
//! Found as TOML (`team_key = "…"`, either quote) and as environment assignments
//! (`SGM__COMMS__TEAM_KEY=…`); `…` marks a placeholder.

mod common;

use common::{files_with_extension, workspace};
use sgm_actors::config::{CommsConfig, PUBLIC_TEAM_KEYS};
use std::path::PathBuf;

/// Whether `text[at]` starts a new word (not part of `my_team_key`).
fn word_start(text: &str, at: usize) -> bool {
    text[..at].chars().next_back().is_none_or(|c| !(c.is_ascii_alphanumeric() || c == '_'))
}

/// A quoted value at the start of `rest` (`"…"` or `'…'`), or, if `bare`, the word there.
fn value(rest: &str, bare: bool) -> Option<String> {
    let quote = rest.chars().next()?;
    if quote == '"' || quote == '\'' {
        let body = &rest[1..];
        return body.find(quote).map(|end| body[..end].to_string());
    }
    let word: String = rest.chars().take_while(|c| !c.is_whitespace() && !matches!(c, ';' | '&' | '|' | '`')).collect();
    (bare && !word.is_empty()).then_some(word)
}

/// The team keys written in `text`; a value with `…` in it is a placeholder, not a key.
fn keys_in(text: &str) -> Vec<String> {
    let mut out = Vec::new();
    for (at, _) in text.match_indices("team_key") {
        let rest = &text[at + "team_key".len()..];
        let Some(rest) = rest.trim_start_matches([' ', '\t']).strip_prefix('=') else { continue };
        if word_start(text, at) {
            out.extend(value(rest.trim_start_matches([' ', '\t']), false));
        }
    }
    for (at, _) in text.match_indices("SGM__COMMS__TEAM_KEY=") {
        if word_start(text, at) {
            out.extend(value(&text[at + "SGM__COMMS__TEAM_KEY=".len()..], true));
        }
    }
    out.retain(|key| !key.contains('…'));
    out
}

fn published_files() -> Vec<PathBuf> {
    let root = workspace();
    let mut files = vec![root.join("README.md")];
    files.extend(files_with_extension(&root.join("book/src"), "md"));
    files.extend(files_with_extension(&root.join("scenarios/library"), "toml"));
    files.extend(files_with_extension(&root.join("bridge/ros/sgm/config"), "toml"));
    files.extend(files_with_extension(&root.join("bridge/ros/sgm/launch"), "launch"));
    files
}

/// The public list's entry `key` is, compared on the derived key.
fn public(key: &str) -> Result<Option<&'static str>, String> {
    let comms = CommsConfig { team_key: key.into(), ..CommsConfig::default() };
    comms.public_team_key().map(|p| p.map(|p| p.text)).map_err(|e| e.to_string())
}

#[test]
fn every_published_team_key_is_on_the_public_list() {
    let mut found = Vec::new();
    for path in published_files() {
        let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        for key in keys_in(&text) {
            let name = path.strip_prefix(workspace()).unwrap_or(&path).display().to_string();
            match public(&key) {
                Ok(Some(_)) => found.push((name, key)),
                Ok(None) => panic!(
                    "{name} prints the team key {key:?}, which is not on sgm_actors::config::PUBLIC_TEAM_KEYS: \
                     add it there (sgm ros then refuses it)"
                ),
                Err(e) => panic!("{name} prints the team key {key:?}, which is not a valid key: {e}"),
            }
        }
    }
    // The worked envelope example at least (its bytes need a printed key).
    assert!(found.iter().any(|(file, _)| file == "book/src/wire.md"), "{found:?}");
}

#[test]
fn the_scanner_finds_keys_as_written() {
    let text = r#"
[comms]
team_key = "a key added later"
team_key='single quoted key'
team_key_file = "/etc/sgm/team.key"
my_team_key = "not ours"
SGM__COMMS__TEAM_KEY=0123 sgm ros --robot a
SGM__COMMS__TEAM_KEY="quoted passphrase here" sgm run
SGM__COMMS__TEAM_KEY_FILE=/etc/sgm/team.key sgm ros
`team_key = "…"` and `SGM__COMMS__TEAM_KEY=…` in prose
"#;
    assert_eq!(
        keys_in(text),
        ["a key added later", "single quoted key", "0123", "quoted passphrase here"].map(String::from)
    );
    // ... and a key that is not listed is caught.
    assert_eq!(public("a key added later"), Ok(None));
    for listed in PUBLIC_TEAM_KEYS {
        assert_eq!(public(listed.text), Ok(Some(listed.text)));
    }
}
