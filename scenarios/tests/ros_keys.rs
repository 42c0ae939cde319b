//! The team key at the door of `sgm ros`: a public key (the built-in default, one printed in the
//! book or the shipped configurations, in any spelling) is refused with what to do instead,
//! unless `--development-key` is given, which starts the node with a loud warning; a key file
//! open to others is refused; `sgm run` (in-process, no network) keeps the default silently.

mod ros_common;

use ros_common::{embedded_master, poll};
use std::io::Write;
use std::os::unix::fs::OpenOptionsExt;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};

/// `sgm ARGS` with `env` (and no SGM__ variables of the caller's), ROS pointed at `master`.
fn sgm(args: &[&str], env: &[(&str, &str)], master: &str) -> Command {
    let mut command = Command::new(env!("CARGO_BIN_EXE_sgm"));
    command.args(args).env("ROS_MASTER_URI", master).env("ROS_IP", "127.0.0.1").env("RUST_LOG", "info");
    for (name, _) in std::env::vars() {
        if name.starts_with("SGM__") {
            command.env_remove(name);
        }
    }
    command.env_remove("ROS_HOSTNAME").env_remove("ROS_NAMESPACE").envs(env.iter().copied());
    command
}

/// `sgm ros --robot alpha --scenario quickstart` with `env`: it must refuse to start; its stderr.
fn refused(env: &[(&str, &str)]) -> String {
    // Nothing listens there: a node that got as far as ROS would fail differently.
    let out: Output = sgm(&["ros", "--robot", "alpha", "--scenario", "quickstart"], env, "http://127.0.0.1:9")
        .output()
        .expect("sgm starts");
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert_eq!(out.status.code(), Some(2), "{env:?}: {err}");
    err
}

fn key_file(dir: &Path, name: &str, content: &str, mode: u32) -> PathBuf {
    let path = dir.join(name);
    let mut file = std::fs::OpenOptions::new().write(true).create_new(true).mode(mode).open(&path).unwrap();
    file.write_all(content.as_bytes()).unwrap();
    path
}

#[test]
fn public_keys_are_refused_with_what_to_do() {
    let err = refused(&[]);
    for needed in [
        "sgm ros: the team key is public (the built-in default (DEVELOPMENT_TEAM_KEY))",
        "head -c 32 /dev/urandom",
        "comms.team_key_file",
        "SGM__COMMS__TEAM_KEY_FILE=",
        "team_key_file:=",
        "sgm ros --development-key",
    ] {
        assert!(err.contains(needed), "no {needed:?} in: {err}");
    }
    assert!(!err.contains("sgm node up"), "{err}");
    // The development key's bytes in hex (argon2id, default salt): public all the same.
    let hex = "178984debcad4b8387b20e9405f600d1962300082e5eb49281673f14ec77ab0a";
    assert!(refused(&[("SGM__COMMS__TEAM_KEY", hex)]).contains("the built-in default"));
    // ... with a salt of the team's own too.
    let err = refused(&[("SGM__COMMS__TEAM_SALT", "our own team salt")]);
    assert!(err.contains("the built-in default"), "{err}");
    // The book's examples, and the passphrase earlier ROS configurations shipped, in a key file.
    let dir = tempfile::tempdir().unwrap();
    let example = key_file(dir.path(), "example.key", "sgm example fleet - replace this passphrase\n", 0o600);
    let err = refused(&[("SGM__COMMS__TEAM_KEY_FILE", example.to_str().unwrap())]);
    assert!(err.contains("the team key is public (the example configurations"), "{err}");
    let worked = "000102030405060708090a0b0c0d0e0f101112131415161718191a1b1c1d1e1f";
    assert!(refused(&[("SGM__COMMS__TEAM_KEY", worked)]).contains("book/src/wire.md"));
    // A key file others can read: refused, with the fix.
    let open = key_file(dir.path(), "open.key", &"7f".repeat(32), 0o644);
    let err = refused(&[("SGM__COMMS__TEAM_KEY_FILE", open.to_str().unwrap())]);
    let fix = format!(
        "comms.team_key_file = {0}: its mode 644 lets group or others at the team key; `chmod 600 {0}`",
        open.display()
    );
    assert!(err.contains(&fix), "{err}");
    // A key file and a key: refused.
    let own = key_file(dir.path(), "own.key", &"7f".repeat(32), 0o600);
    let err = refused(&[
        ("SGM__COMMS__TEAM_KEY_FILE", own.to_str().unwrap()),
        ("SGM__COMMS__TEAM_KEY", "a key set twice over"),
    ]);
    assert!(err.contains("comms.team_key is set too"), "{err}");
}

/// Kills the node if the test fails.
struct Node(Child, PathBuf);

impl Drop for Node {
    fn drop(&mut self) {
        if matches!(self.0.try_wait(), Ok(None)) {
            let _ = self.0.kill();
            let _ = self.0.wait();
            eprintln!("--- the node's log:\n{}", std::fs::read_to_string(&self.1).unwrap_or_default());
        }
    }
}

#[test]
fn the_development_flag_starts_with_a_loud_warning() {
    let dir = tempfile::tempdir().unwrap();
    let master = embedded_master();
    let log = dir.path().join("alpha.log");
    let home = dir.path().to_str().unwrap();
    let child = sgm(
        &["ros", "--robot", "alpha", "--scenario", "quickstart", "--development-key", "__ns:=/alpha"],
        &[("ROS_HOME", home)],
        &format!("http://{master}"),
    )
    .stdout(Stdio::null())
    .stderr(std::fs::File::create(&log).unwrap())
    .spawn()
    .expect("sgm ros starts");
    let mut node = Node(child, log.clone());
    let text = poll(
        60,
        || format!("the node did not come up: {}", std::fs::read_to_string(&log).unwrap_or_default()),
        || std::fs::read_to_string(&log).ok().filter(|t| t.contains("sgm node up")),
    );
    let warning = text.lines().find(|l| l.contains("DEVELOPMENT KEY")).unwrap_or_else(|| panic!("no warning: {text}"));
    assert!(warning.contains("WARN"), "{warning}");
    assert!(warning.contains("the team key is public (the built-in default"), "{warning}");
    assert!(warning.contains("Never use --development-key in the field"), "{warning}");
    let sent = Command::new("kill").args(["-INT", &node.0.id().to_string()]).status();
    assert!(sent.is_ok_and(|s| s.success()));
    let status = poll(20, || "the node did not exit on SIGINT".into(), || node.0.try_wait().ok().flatten());
    assert!(status.success(), "{status}");
}

#[test]
fn sgm_run_keeps_the_development_key_silently() {
    let dir = tempfile::tempdir().unwrap();
    let out_dir = dir.path().join("run");
    let out = sgm(
        &["run", "quickstart", "--quiet", "--out", out_dir.to_str().unwrap()],
        &[("SGM__SCENARIO__DURATION_S", "5"), ("RUST_LOG", "warn")],
        "http://127.0.0.1:9",
    )
    .output()
    .expect("sgm starts");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    assert!(err.trim().is_empty(), "sgm run wrote to stderr: {err}");
    assert!(out_dir.join("report.json").is_file());
}
