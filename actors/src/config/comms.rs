//! `[comms]`: the team key (and its file), pacing, request bounds, retries and wire limits.

use super::error::{check, positive, ConfigError};
use crate::protocol::RetryConfig;
use serde::{Deserialize, Serialize};
use sgm_model::wire::team_key::{TeamKeyError, MIN_SALT_BYTES};
use sgm_model::wire::{TeamKey, WireLimits};
use std::path::{Path, PathBuf};

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CommsConfig {
    /// Team secret: 64 hex digits (the key's 32 bytes), or a passphrase of ≥ 12 characters
    /// (derived with argon2id and `team_salt`). Default: [`DEVELOPMENT_TEAM_KEY`], which is
    /// public: `sgm ros` refuses it and every other key of [`PUBLIC_TEAM_KEYS`] unless started
    /// with `--development-key`. `Debug` prints `<redacted>`.
    pub team_key: Secret,
    /// A file holding the team key instead (64 hex digits or a passphrase; one trailing newline
    /// is stripped), readable and writable by its owner only (mode 600, like an ssh private
    /// key). A relative path is resolved against the current directory of the process. Not
    /// allowed together with a `team_key` other than the default. Default: none.
    pub team_key_file: Option<PathBuf>,
    /// The salt of passphrase derivation (argon2id), at least 8 bytes. Not secret, but give each
    /// team its own, so that a precomputed table of passphrases for the default salt is no use.
    /// Hex keys do not use it. Default "sgm team".
    pub team_salt: String,
    /// Shortest interval between two ObjectData broadcasts, s. Default 2.
    pub object_data_interval_s: f64,
    /// ObjectData is broadcast again, unchanged, after this long without a broadcast, so a lost
    /// one is made good and neighbours keep hearing us (keep it below `link_timeout_s`); a
    /// neighbour first heard or back from silence gets it at the next `object_data_interval_s`,
    /// s. Default 10.
    pub object_data_refresh_s: f64,
    /// Objects whose centroid moved farther than this count as a significant change, m; so does
    /// an alignment that would move an object 10 m away from us by more. Default 0.5.
    pub significant_move_m: f64,
    /// Our alignments (the `Alignments` message) are broadcast again, unchanged, after this long
    /// without a broadcast, so a lost one is made good; besides, they go out when one is made or
    /// moves and when a neighbour is first heard or back, at most once per
    /// `object_data_interval_s`, s. Default 30.
    pub alignments_refresh_s: f64,
    /// Centroid quantum of ObjectData, mm. Default 20.
    pub centroid_resolution_mm: u16,
    /// Keyframe requests are coalesced over this window before being sent, s. Default 0.5.
    pub request_window_s: f64,
    /// Keyframes requested but not yet received, per neighbour, at most. Default 32.
    pub max_keyframes_in_flight: usize,
    /// Keyframes waiting to be requested, per neighbour, at most; more are reported unavailable
    /// (reason busy) to the Matcher at once. Default 1024.
    pub max_keyframes_waiting: usize,
    /// Keyframe ids per KeyframeRequest, at most. Default 16.
    pub max_keyframes_per_request: usize,
    /// Keyframe responses sent per tick, at most (the outgoing budget). Default 16.
    pub max_responses_per_tick: usize,
    /// A neighbour silent for this long is down: requests to it wait, neither retried nor given
    /// up, and are asked afresh when it is heard again, s. Default 30.
    pub link_timeout_s: f64,
    /// Cloud quantum of keyframe responses, m. Default 0.01.
    pub cloud_resolution_m: f64,
    /// Voxel side a served keyframe cloud is thinned to before it is encoded (the centroid of
    /// each occupied voxel, as the requester's registration thins it again at its
    /// `matcher.keyframe_voxel_m`: set it to that, or finer), m. 0: the whole scan. Default 0.
    pub keyframe_cloud_voxel_m: f64,
    pub retry: RetryConfig,
    pub limits: WireLimits,
    /// `[comms.pose_updates]`: keyframes we served, told again when our solves move them.
    pub pose_updates: PoseUpdatesConfig,
}

/// `[comms.pose_updates]`: a neighbour holding keyframes we served ties them to its anchor of
/// our map by our estimate of them when they left. When our later solves move one of them (a
/// loop closure, an alignment) by more than `move_m` or `turn_deg` from what the neighbour was
/// last told, the neighbour is told the new pose (`KeyframePoses`, 25–29 bytes a keyframe), at
/// most once per `interval_s` per neighbour, and only to a neighbour heard within
/// `link_timeout_s`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PoseUpdatesConfig {
    /// Default true.
    pub enabled: bool,
    /// Shortest interval between two updates to one neighbour, s. Default 10.
    pub interval_s: f64,
    /// A served keyframe that moved farther than this from what the neighbour was told is told
    /// again, m. Default 0.05.
    pub move_m: f64,
    /// Or that turned by more than this, degrees. Default 0.1.
    pub turn_deg: f64,
    /// Tell (and serve) what our own measurements alone say of each keyframe — a second solve
    /// of our graph without the neighbours (`KeyframeGraph::own_poses`) — instead of the joint
    /// solve's pose, which holds the neighbours' own factors and echoes them back. Default
    /// false: the echo keeps each robot's copy of a neighbour's map closer to that map, which
    /// the outdoor teams measured better (book: Optimiser, keyframe pose updates).
    pub own_estimates: bool,
}

impl Default for PoseUpdatesConfig {
    fn default() -> Self {
        Self { enabled: true, interval_s: 10.0, move_m: 0.05, turn_deg: 0.1, own_estimates: false }
    }
}

/// The key every build knows: fine in simulation, never in the field.
pub const DEVELOPMENT_TEAM_KEY: &str = "sgm development team key - replace me";

/// The default `comms.team_salt`.
pub const DEFAULT_TEAM_SALT: &str = "sgm team";

/// A team key anyone can read: the default, and every key printed in the book, the scenario
/// library or the shipped ROS configurations (a test scans them and fails on one missing
/// here). `sgm ros` refuses them without `--development-key`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PublicTeamKey {
    /// As written: 64 hex digits or a passphrase.
    pub text: &'static str,
    /// Where it is published.
    pub published: &'static str,
}

/// Every public team key (see [`PublicTeamKey`]).
pub const PUBLIC_TEAM_KEYS: &[PublicTeamKey] = &[
    PublicTeamKey { text: DEVELOPMENT_TEAM_KEY, published: "the built-in default (DEVELOPMENT_TEAM_KEY)" },
    PublicTeamKey {
        text: "sgm example fleet - replace this passphrase",
        published: "the example configurations of earlier versions of the ROS package (bridge/ros/sgm/config)",
    },
    PublicTeamKey {
        text: "correct horse battery staple",
        published: "the book's configuration example (book/src/configuration.md)",
    },
    PublicTeamKey {
        text: "000102030405060708090a0b0c0d0e0f101112131415161718191a1b1c1d1e1f",
        published: "the book's worked envelope example (book/src/wire.md)",
    },
];

/// A secret string from the configuration: (de)serialised as the plain string (the
/// configuration layers need it), never shown by `Debug`.
#[derive(Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(transparent)]
pub struct Secret(String);

impl Secret {
    pub fn new(text: impl Into<String>) -> Self {
        Self(text.into())
    }

    /// The secret itself: for deriving the key, never for printing.
    pub fn expose(&self) -> &str {
        &self.0
    }
}

impl From<&str> for Secret {
    fn from(text: &str) -> Self {
        Self(text.into())
    }
}

impl std::fmt::Debug for Secret {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("<redacted>")
    }
}

impl Default for CommsConfig {
    fn default() -> Self {
        Self {
            team_key: DEVELOPMENT_TEAM_KEY.into(),
            team_key_file: None,
            team_salt: DEFAULT_TEAM_SALT.into(),
            object_data_interval_s: 2.0,
            object_data_refresh_s: 10.0,
            significant_move_m: 0.5,
            alignments_refresh_s: 30.0,
            centroid_resolution_mm: 20,
            request_window_s: 0.5,
            max_keyframes_in_flight: 32,
            max_keyframes_waiting: 1024,
            max_keyframes_per_request: 16,
            max_responses_per_tick: 16,
            link_timeout_s: 30.0,
            cloud_resolution_m: 0.01,
            keyframe_cloud_voxel_m: 0.0,
            retry: RetryConfig::default(),
            limits: WireLimits::default(),
            pose_updates: PoseUpdatesConfig::default(),
        }
    }
}

impl CommsConfig {
    /// Checks every `comms.*` key against its allowed range, the team key first.
    pub fn validate(&self) -> Result<(), ConfigError> {
        let c = self;
        c.team_key()?;
        check(positive(c.object_data_interval_s), "comms.object_data_interval_s", c.object_data_interval_s, "> 0")?;
        check(
            c.object_data_refresh_s.is_finite() && c.object_data_refresh_s >= c.object_data_interval_s,
            "comms.object_data_refresh_s",
            c.object_data_refresh_s,
            "finite, ≥ comms.object_data_interval_s",
        )?;
        check(positive(c.significant_move_m), "comms.significant_move_m", c.significant_move_m, "> 0")?;
        check(
            c.alignments_refresh_s.is_finite() && c.alignments_refresh_s >= c.object_data_interval_s,
            "comms.alignments_refresh_s",
            c.alignments_refresh_s,
            "finite, ≥ comms.object_data_interval_s",
        )?;
        check(c.centroid_resolution_mm >= 1, "comms.centroid_resolution_mm", c.centroid_resolution_mm, "1–65535")?;
        check(
            c.request_window_s.is_finite() && c.request_window_s >= 0.0,
            "comms.request_window_s",
            c.request_window_s,
            "≥ 0",
        )?;
        check(c.max_keyframes_in_flight >= 1, "comms.max_keyframes_in_flight", c.max_keyframes_in_flight, "≥ 1")?;
        check(c.max_keyframes_waiting >= 1, "comms.max_keyframes_waiting", c.max_keyframes_waiting, "≥ 1")?;
        check(
            (1..=c.limits.max_ids).contains(&c.max_keyframes_per_request),
            "comms.max_keyframes_per_request",
            c.max_keyframes_per_request,
            "1 – comms.limits.max_ids",
        )?;
        check(c.max_responses_per_tick >= 1, "comms.max_responses_per_tick", c.max_responses_per_tick, "≥ 1")?;
        check(positive(c.link_timeout_s), "comms.link_timeout_s", c.link_timeout_s, "> 0")?;
        check(positive(c.cloud_resolution_m), "comms.cloud_resolution_m", c.cloud_resolution_m, "> 0")?;
        let voxel = c.keyframe_cloud_voxel_m;
        check(
            voxel == 0.0 || (voxel.is_finite() && voxel >= c.cloud_resolution_m && voxel <= 5.0),
            "comms.keyframe_cloud_voxel_m",
            voxel,
            "0 (the whole scan) or comms.cloud_resolution_m ≤ x ≤ 5 m",
        )?;
        check(positive(c.retry.timeout_s), "comms.retry.timeout_s", c.retry.timeout_s, "> 0")?;
        check(c.retry.backoff.is_finite() && c.retry.backoff >= 1.0, "comms.retry.backoff", c.retry.backoff, "≥ 1")?;
        check(
            c.limits.max_envelope_bytes >= 1024,
            "comms.limits.max_envelope_bytes",
            c.limits.max_envelope_bytes,
            "≥ 1024",
        )?;
        let u = &c.pose_updates;
        check(positive(u.interval_s), "comms.pose_updates.interval_s", u.interval_s, "> 0")?;
        check(positive(u.move_m), "comms.pose_updates.move_m", u.move_m, "> 0")?;
        check(positive(u.turn_deg), "comms.pose_updates.turn_deg", u.turn_deg, "> 0")?;
        Ok(())
    }

    /// The team key: read from `team_key_file` if it is set, else `team_key`; a passphrase is
    /// derived with `team_salt` (once per process: [`TeamKey::from_passphrase`]).
    pub fn team_key(&self) -> Result<TeamKey, ConfigError> {
        check(
            self.team_salt.len() >= MIN_SALT_BYTES,
            "comms.team_salt",
            format!("{:?}", self.team_salt),
            "at least 8 bytes (argon2's shortest salt); set a value of the team's own",
        )?;
        let invalid = |key: &str, value: String, e: TeamKeyError| ConfigError::Invalid {
            key: key.into(),
            value,
            allowed: e.to_string(),
        };
        match &self.team_key_file {
            Some(path) => {
                if self.team_key.expose() != DEVELOPMENT_TEAM_KEY {
                    return Err(ConfigError::KeyFile {
                        path: path.display().to_string(),
                        problem: "comms.team_key is set too: give the key in one place only (remove comms.team_key)"
                            .into(),
                    });
                }
                let text = read_key_file(path)?;
                TeamKey::from_text(text.expose(), &self.team_salt)
                    .map_err(|e| invalid("comms.team_key_file", path.display().to_string(), e))
            }
            None => TeamKey::from_text(self.team_key.expose(), &self.team_salt)
                .map_err(|e| invalid("comms.team_key", "<secret>".into(), e)),
        }
    }

    /// The entry of [`PUBLIC_TEAM_KEYS`] the team key is, if any. Compared on the key itself,
    /// so a hex spelling of a public passphrase's key is caught, with this team's salt or the
    /// default one.
    pub fn public_team_key(&self) -> Result<Option<&'static PublicTeamKey>, ConfigError> {
        let key = self.team_key()?;
        let salts = [self.team_salt.as_str(), DEFAULT_TEAM_SALT];
        Ok(PUBLIC_TEAM_KEYS
            .iter()
            .find(|public| salts.iter().any(|salt| TeamKey::from_text(public.text, salt).is_ok_and(|k| k == key))))
    }
}

/// The content of a team key file, checked: a regular file, private to its owner, not empty.
fn read_key_file(path: &Path) -> Result<Secret, ConfigError> {
    let refused = |problem: String| ConfigError::KeyFile { path: path.display().to_string(), problem };
    if path.as_os_str().is_empty() {
        return Err(refused("an empty path names no file".into()));
    }
    let metadata = std::fs::metadata(path).map_err(|e| refused(format!("cannot be read: {e}")))?;
    if !metadata.is_file() {
        return Err(refused("is not a file".into()));
    }
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        let mode = metadata.permissions().mode() & 0o777;
        if mode & 0o077 != 0 {
            return Err(refused(format!(
                "its mode {mode:03o} lets group or others at the team key; `chmod 600 {}` makes it its owner's alone",
                path.display()
            )));
        }
    }
    let text = std::fs::read_to_string(path).map_err(|e| refused(format!("cannot be read: {e}")))?;
    let text = match text.strip_suffix('\n') {
        Some(line) => line.strip_suffix('\r').unwrap_or(line),
        None => &text,
    };
    if text.is_empty() {
        return Err(refused("is empty: it must hold the team key (64 hex digits or a passphrase)".into()));
    }
    Ok(Secret::new(text))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::RobotConfig;
    use std::path::Path;

    #[test]
    fn team_keys_hex_or_passphrase() {
        let mut c = CommsConfig { team_key: Secret::new("ab".repeat(32)), ..CommsConfig::default() };
        assert_eq!(c.team_key().unwrap(), TeamKey::from_bytes([0xab; 32]));
        c.team_key = "short".into();
        assert!(c.team_key().unwrap_err().to_string().starts_with("comms.team_key = <secret>: allowed"));
        c.team_key = "a passphrase of our own".into();
        let ours = c.team_key().unwrap();
        assert_eq!(ours, TeamKey::from_passphrase("a passphrase of our own", DEFAULT_TEAM_SALT).unwrap());
        // The salt changes a passphrase's key, not a hex key's.
        c.team_salt = "field team 7".into();
        assert_ne!(c.team_key().unwrap(), ours);
        c.team_key = Secret::new("ab".repeat(32));
        assert_eq!(c.team_key().unwrap(), TeamKey::from_bytes([0xab; 32]));
        c.team_salt = "short".into();
        assert_eq!(
            c.team_key().unwrap_err().to_string(),
            "comms.team_salt = \"short\": allowed at least 8 bytes (argon2's shortest salt); set a value of the team's own"
        );
    }

    #[test]
    fn debug_prints_never_show_the_team_key() {
        let passphrase = "our secret fleet passphrase";
        let mut config = RobotConfig::default();
        config.comms.team_key = passphrase.into();
        for text in [format!("{config:?}"), format!("{:?}", config.comms), format!("{config:#?}")] {
            assert!(!text.contains(passphrase), "{text}");
            assert!(text.contains("team_key: <redacted>"), "{text}");
        }
        config.comms.team_key = Secret::new("5e".repeat(32));
        assert!(!format!("{config:?}").contains(&"5e".repeat(32)));
        // Serialised as the plain string: the configuration layers read it back.
        let layer = config::Config::try_from(&config.comms).unwrap();
        assert_eq!(layer.get_string("team_key").unwrap(), "5e".repeat(32));
    }

    /// A file in `dir` holding `content`, with `mode`.
    fn key_file(dir: &Path, name: &str, content: &str, mode: u32) -> PathBuf {
        use std::os::unix::fs::PermissionsExt;
        let path = dir.join(name);
        std::fs::write(&path, content).unwrap();
        std::fs::set_permissions(&path, std::fs::Permissions::from_mode(mode)).unwrap();
        path
    }

    #[test]
    fn team_key_files_are_read_and_checked() {
        let dir = tempfile::tempdir().unwrap();
        let from_file = |path: &Path| CommsConfig { team_key_file: Some(path.into()), ..CommsConfig::default() };
        let hex = "c0ffee".repeat(10) + "abcd";
        let path = key_file(dir.path(), "hex.key", &format!("{hex}\n"), 0o600);
        assert_eq!(from_file(&path).team_key().unwrap(), TeamKey::from_hex(&hex).unwrap());
        let path = key_file(dir.path(), "phrase.key", "a passphrase in a file\r\n", 0o400);
        let phrase = TeamKey::from_passphrase("a passphrase in a file", DEFAULT_TEAM_SALT).unwrap();
        assert_eq!(from_file(&path).team_key().unwrap(), phrase);
        // One newline is stripped, no more.
        let path = key_file(dir.path(), "two.key", "a passphrase in a file\n\n", 0o600);
        let two = from_file(&path).team_key().unwrap();
        assert_ne!(two, phrase);
        assert_eq!(two, TeamKey::from_passphrase("a passphrase in a file\n", DEFAULT_TEAM_SALT).unwrap());
        // Relative to the current directory.
        let here = tempfile::NamedTempFile::new_in(".").unwrap();
        std::fs::write(here.path(), &hex).unwrap();
        let relative = PathBuf::from(here.path().file_name().unwrap());
        assert!(relative.is_relative());
        assert_eq!(from_file(&relative).team_key().unwrap(), TeamKey::from_hex(&hex).unwrap());

        let refused = |path: &Path| from_file(path).team_key().unwrap_err().to_string();
        let missing = dir.path().join("missing.key");
        let e = refused(&missing);
        assert!(e.starts_with(&format!("comms.team_key_file = {}: cannot be read: ", missing.display())), "{e}");
        let e = refused(dir.path());
        assert_eq!(e, format!("comms.team_key_file = {}: is not a file", dir.path().display()));
        for content in ["", "\n"] {
            let path = key_file(dir.path(), "empty.key", content, 0o600);
            assert!(refused(&path).ends_with(": is empty: it must hold the team key (64 hex digits or a passphrase)"));
        }
        for mode in [0o644, 0o640, 0o604, 0o620, 0o602, 0o610] {
            let path = key_file(dir.path(), "open.key", &hex, mode);
            let e = refused(&path);
            assert_eq!(
                e,
                format!(
                    "comms.team_key_file = {0}: its mode {mode:03o} lets group or others at the team key; \
                     `chmod 600 {0}` makes it its owner's alone",
                    path.display()
                )
            );
        }
        let path = key_file(dir.path(), "short.key", "short\n", 0o600);
        assert_eq!(
            refused(&path),
            format!(
                "comms.team_key_file = {}: allowed a team passphrase needs at least 12 characters; got 5",
                path.display()
            )
        );
        // Both places at once: refused, whatever the file holds.
        let path = key_file(dir.path(), "both.key", &hex, 0o600);
        let both = CommsConfig { team_key: "another passphrase".into(), ..from_file(&path) };
        assert_eq!(
            both.team_key().unwrap_err().to_string(),
            format!(
                "comms.team_key_file = {}: comms.team_key is set too: give the key in one place only \
                 (remove comms.team_key)",
                path.display()
            )
        );
        // Through the loader and the environment, as `sgm ros` reads it.
        std::env::set_var("SGM_TEST_KEYFILE__COMMS__TEAM_KEY_FILE", dir.path().join("hex.key"));
        let loaded = RobotConfig::load_with_env(None, "SGM_TEST_KEYFILE").unwrap();
        assert_eq!(loaded.comms.team_key().unwrap(), TeamKey::from_hex(&hex).unwrap());
        std::env::set_var("SGM_TEST_KEYFILE_OPEN__COMMS__TEAM_KEY_FILE", dir.path().join("open.key"));
        let e = RobotConfig::load_with_env(None, "SGM_TEST_KEYFILE_OPEN").unwrap_err().to_string();
        assert!(e.contains("chmod 600"), "{e}");
    }

    #[test]
    fn public_keys_are_known_whatever_their_spelling() {
        let public = |c: &CommsConfig| c.public_team_key().unwrap().map(|p| p.text);
        let default = CommsConfig::default();
        assert_eq!(public(&default), Some(DEVELOPMENT_TEAM_KEY));
        for listed in PUBLIC_TEAM_KEYS {
            let c = CommsConfig { team_key: listed.text.into(), ..CommsConfig::default() };
            assert_eq!(public(&c), Some(listed.text));
        }
        // The development key's derived bytes, spelt in hex (argon2id with the default salt,
        // model/src/wire/team_key.rs has the reference).
        let hex = "178984debcad4b8387b20e9405f600d1962300082e5eb49281673f14ec77ab0a";
        let c = CommsConfig { team_key: hex.into(), ..CommsConfig::default() };
        assert_eq!(public(&c), Some(DEVELOPMENT_TEAM_KEY));
        // ... also when the team has its own salt; and a public passphrase under that salt.
        let salted = CommsConfig { team_salt: "our own team salt".into(), ..c };
        assert_eq!(public(&salted), Some(DEVELOPMENT_TEAM_KEY));
        let salted = CommsConfig { team_key: DEVELOPMENT_TEAM_KEY.into(), ..salted };
        assert_eq!(public(&salted), Some(DEVELOPMENT_TEAM_KEY));
        // In a key file.
        let dir = tempfile::tempdir().unwrap();
        let path = key_file(dir.path(), "team.key", "sgm example fleet - replace this passphrase\n", 0o600);
        let c = CommsConfig { team_key_file: Some(path), ..CommsConfig::default() };
        assert_eq!(public(&c), Some("sgm example fleet - replace this passphrase"));
        // A key of our own is not public.
        let ours = CommsConfig { team_key: Secret::new("3c".repeat(32)), ..CommsConfig::default() };
        assert_eq!(public(&ours), None);
        let ours = CommsConfig { team_key: "a passphrase nobody printed".into(), ..CommsConfig::default() };
        assert_eq!(public(&ours), None);
    }
}
