//! The team key: every envelope carries a MAC under it, so a radio outside the team can neither
//! inject nor alter messages. The MAC is keyed BLAKE3 (the `blake3` crate) truncated to 128 bits.
//!
//! A key is 32 bytes, written as 64 hexadecimal digits, or derived from a passphrase with
//! argon2id (RFC 9106; the `argon2` crate) at OWASP's minimum cost for it, m = 19 456 KiB,
//! t = 2, p = 1, 32 bytes out, salted with the team's salt. The derivation is slow and
//! memory-hard on purpose (a guess costs an attacker as much as it costs us), so each process
//! derives a (passphrase, salt) pair once and remembers the key ([`TeamKey::from_passphrase`]).

use std::collections::HashMap;
use std::fmt;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Mutex, OnceLock, PoisonError};

/// Memory of one passphrase derivation, KiB (OWASP's argon2id minimum: 19 MiB).
pub const KDF_MEMORY_KIB: u32 = 19_456;
/// Passes over that memory (OWASP: 2 with 19 MiB).
pub const KDF_PASSES: u32 = 2;
/// Lanes (OWASP: 1).
pub const KDF_LANES: u32 = 1;
/// Shortest team passphrase, characters.
pub const MIN_PASSPHRASE_CHARS: usize = 12;
/// Shortest team salt, bytes (argon2's minimum, `argon2::MIN_SALT_LEN`).
pub const MIN_SALT_BYTES: usize = argon2::MIN_SALT_LEN;

/// A 256-bit secret shared by the team. `Debug` never prints it.
#[derive(Clone, PartialEq, Eq)]
pub struct TeamKey([u8; 32]);

/// A key that could not be read.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TeamKeyError {
    #[error("a team key is 64 hexadecimal digits; got {0} characters")]
    Length(usize),
    #[error("a team key is 64 hexadecimal digits; character {0} is not one")]
    Digit(usize),
    #[error("a team passphrase needs at least 12 characters; got {0}")]
    ShortPassphrase(usize),
    #[error("a team salt needs at least 8 bytes (argon2's minimum); got {0}")]
    ShortSalt(usize),
    #[error("argon2id refused the passphrase: {0}")]
    Kdf(String),
}

impl TeamKey {
    pub const fn from_bytes(bytes: [u8; 32]) -> Self {
        Self(bytes)
    }

    /// From 64 hexadecimal digits.
    pub fn from_hex(text: &str) -> Result<Self, TeamKeyError> {
        let text = text.trim();
        if text.len() != 64 {
            return Err(TeamKeyError::Length(text.chars().count()));
        }
        let mut bytes = [0u8; 32];
        for (k, byte) in bytes.iter_mut().enumerate() {
            let pair = text.get(2 * k..2 * k + 2).ok_or(TeamKeyError::Digit(2 * k))?;
            *byte = u8::from_str_radix(pair, 16).map_err(|_| TeamKeyError::Digit(2 * k))?;
        }
        Ok(Self(bytes))
    }

    /// Whether `text` is read as a hexadecimal key (exactly 64 hexadecimal digits) rather than
    /// a passphrase.
    pub fn is_hex(text: &str) -> bool {
        text.len() == 64 && text.bytes().all(|c| c.is_ascii_hexdigit())
    }

    /// `text` as the configuration reads it: exactly 64 hexadecimal digits are the key's bytes,
    /// anything else is a passphrase, derived with `salt` ([`TeamKey::from_passphrase`]).
    pub fn from_text(text: &str, salt: &str) -> Result<Self, TeamKeyError> {
        if Self::is_hex(text) {
            Self::from_hex(text)
        } else {
            Self::from_passphrase(text, salt)
        }
    }

    /// Derived from a passphrase of at least [`MIN_PASSPHRASE_CHARS`] characters and a salt of
    /// at least [`MIN_SALT_BYTES`] bytes: argon2id (version 0x13, no secret, no associated
    /// data) with m = [`KDF_MEMORY_KIB`], t = [`KDF_PASSES`], p = [`KDF_LANES`], 32 bytes out.
    /// The first derivation of a pair in a process runs the KDF; later ones return the key it
    /// gave (scenarios start many robots with one key).
    pub fn from_passphrase(passphrase: &str, salt: &str) -> Result<Self, TeamKeyError> {
        let n = passphrase.chars().count();
        if n < MIN_PASSPHRASE_CHARS {
            return Err(TeamKeyError::ShortPassphrase(n));
        }
        if salt.len() < MIN_SALT_BYTES {
            return Err(TeamKeyError::ShortSalt(salt.len()));
        }
        static DERIVED: OnceLock<Derivations> = OnceLock::new();
        DERIVED.get_or_init(Derivations::default).derive(passphrase, salt)
    }

    /// The 16-byte tag of `bytes`.
    pub fn mac(&self, bytes: &[u8]) -> [u8; 16] {
        let full = blake3::keyed_hash(&self.0, bytes);
        let mut tag = [0u8; 16];
        tag.copy_from_slice(&full.as_bytes()[..16]);
        tag
    }

    /// Whether `tag` is the MAC of `bytes`, compared in constant time.
    pub fn verify(&self, bytes: &[u8], tag: &[u8]) -> bool {
        let expected = self.mac(bytes);
        tag.len() == expected.len() && expected.iter().zip(tag).fold(0u8, |acc, (a, b)| acc | (a ^ b)) == 0
    }
}

impl fmt::Debug for TeamKey {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("TeamKey(<redacted>)")
    }
}

/// One argon2id run (no cache).
fn argon2id(passphrase: &str, salt: &str) -> Result<TeamKey, TeamKeyError> {
    let kdf = |e: argon2::Error| TeamKeyError::Kdf(e.to_string());
    let params = argon2::Params::new(KDF_MEMORY_KIB, KDF_PASSES, KDF_LANES, Some(32)).map_err(kdf)?;
    let argon2 = argon2::Argon2::new(argon2::Algorithm::Argon2id, argon2::Version::V0x13, params);
    let mut key = [0u8; 32];
    argon2.hash_password_into(passphrase.as_bytes(), salt.as_bytes(), &mut key).map_err(kdf)?;
    Ok(TeamKey(key))
}

/// The keys derived so far in this process, indexed by a BLAKE3 hash of (passphrase, salt):
/// the passphrase itself is never kept.
#[derive(Default)]
struct Derivations {
    keys: Mutex<HashMap<[u8; 32], TeamKey>>,
    /// KDF runs, for the tests.
    runs: AtomicUsize,
}

impl Derivations {
    fn derive(&self, passphrase: &str, salt: &str) -> Result<TeamKey, TeamKeyError> {
        let mut index = blake3::Hasher::new_derive_key("sgm team key derivation cache v1");
        index.update(&(passphrase.len() as u64).to_le_bytes());
        index.update(passphrase.as_bytes());
        index.update(salt.as_bytes());
        let index = *index.finalize().as_bytes();
        // Held through the derivation: robots starting at once with one key wait for the
        // first derivation instead of each running their own.
        let mut keys = self.keys.lock().unwrap_or_else(PoisonError::into_inner);
        if let Some(key) = keys.get(&index) {
            return Ok(key.clone());
        }
        let key = argon2id(passphrase, salt)?;
        self.runs.fetch_add(1, Ordering::Relaxed);
        keys.insert(index, key.clone());
        Ok(key)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hex_and_passphrase_keys() {
        let hex = "00112233445566778899aabbccddeeff00112233445566778899aabbccddeeff";
        let key = TeamKey::from_hex(hex).unwrap();
        assert_eq!(key.0[1], 0x11);
        assert_eq!(TeamKey::from_text(hex, "sgm team").unwrap(), key);
        assert_eq!(TeamKey::from_hex("abc"), Err(TeamKeyError::Length(3)));
        assert_eq!(TeamKey::from_hex(&hex.replace("ff0", "fg0")), Err(TeamKeyError::Digit(30)));
        assert_eq!(TeamKey::from_passphrase("short", "sgm team"), Err(TeamKeyError::ShortPassphrase(5)));
        assert_eq!(TeamKey::from_passphrase("correct horse battery", "short"), Err(TeamKeyError::ShortSalt(5)));
        let a = TeamKey::from_passphrase("correct horse battery", "sgm team").unwrap();
        assert_ne!(a, TeamKey::from_passphrase("correct horse battery!", "sgm team").unwrap());
        assert_ne!(a, TeamKey::from_passphrase("correct horse battery", "sgm team 2").unwrap());
        // 63 hex digits and a letter: a passphrase.
        assert!(!TeamKey::is_hex(&hex.replace("ff0", "fg0")));
        assert_eq!(format!("{a:?}"), "TeamKey(<redacted>)");
        // The messages spell the limits out; they follow the constants.
        let short = format!("a team passphrase needs at least {MIN_PASSPHRASE_CHARS} characters; got 5");
        assert_eq!(TeamKeyError::ShortPassphrase(5).to_string(), short);
        let salt = format!("a team salt needs at least {MIN_SALT_BYTES} bytes (argon2's minimum); got 5");
        assert_eq!(TeamKeyError::ShortSalt(5).to_string(), salt);
    }

    /// Against the reference C implementation of argon2 (through Python's argon2-cffi 25.1.0,
    /// argon2-cffi-bindings 26.2.0), computed with
    /// `python3 -m venv /tmp/argon2-venv && /tmp/argon2-venv/bin/pip install argon2-cffi`, then
    /// `/tmp/argon2-venv/bin/python -c "from argon2.low_level import hash_secret_raw, Type;
    /// print(hash_secret_raw(secret=PASSPHRASE, salt=SALT, time_cost=2, memory_cost=19456,
    /// parallelism=1, hash_len=32, type=Type.ID).hex())"`.
    #[test]
    fn passphrases_follow_argon2id_at_owasp_minimum() {
        let cases = [
            (
                "correct horse battery staple",
                "sgm team",
                "964d733089073dc4b4ad62947d5f8ce5ff4d0d0ce162d1217210598402fb7dd9",
            ),
            (
                "sgm development team key - replace me",
                "sgm team",
                "178984debcad4b8387b20e9405f600d1962300082e5eb49281673f14ec77ab0a",
            ),
            (
                "correct horse battery staple",
                "field team 2024",
                "294693175975f0815e957f36ffa808f546d8239d12e04171c1c9b985f7551593",
            ),
        ];
        for (passphrase, salt, expected) in cases {
            let expected = TeamKey::from_hex(expected).unwrap();
            assert_eq!(TeamKey::from_passphrase(passphrase, salt).unwrap(), expected, "{passphrase:?} {salt:?}");
            assert_eq!(argon2id(passphrase, salt).unwrap(), expected, "uncached {passphrase:?} {salt:?}");
        }
    }

    /// RFC 9106 §5.3, the published argon2id test vector (with secret and associated data):
    /// the crate and version we build on compute argon2id as specified.
    #[test]
    fn argon2id_matches_rfc_9106() {
        let params = argon2::ParamsBuilder::new()
            .m_cost(32)
            .t_cost(3)
            .p_cost(4)
            .data(argon2::AssociatedData::new(&[4; 12]).unwrap())
            .output_len(32)
            .build()
            .unwrap();
        let argon2 =
            argon2::Argon2::new_with_secret(&[3; 8], argon2::Algorithm::Argon2id, argon2::Version::V0x13, params)
                .unwrap();
        let mut tag = [0u8; 32];
        argon2.hash_password_into(&[1; 32], &[2; 16], &mut tag).unwrap();
        let expected = TeamKey::from_hex("0d640df58d78766c08c037a34a8b53c9d01ef0452d75b65eb52520e96b01e659").unwrap();
        assert_eq!(TeamKey(tag), expected);
    }

    #[test]
    fn each_pair_is_derived_once_per_cache() {
        let cache = Derivations::default();
        let a = cache.derive("a passphrase for the cache test", "sgm team").unwrap();
        let again = cache.derive("a passphrase for the cache test", "sgm team").unwrap();
        assert_eq!((a.clone(), cache.runs.load(Ordering::Relaxed)), (again, 1));
        let salted = cache.derive("a passphrase for the cache test", "another team").unwrap();
        assert_ne!(a, salted);
        // Length-prefixed: ("ab", "c…") and ("abc", "…") are different entries.
        let b = cache.derive("a passphrase for the cache tes", "tsgm team").unwrap();
        assert_ne!(a, b);
        assert_eq!(cache.runs.load(Ordering::Relaxed), 3);
        // The process-wide cache gives the same keys.
        assert_eq!(TeamKey::from_passphrase("a passphrase for the cache test", "sgm team").unwrap(), a);
    }

    #[test]
    fn mac_detects_changes_and_wrong_keys() {
        let key = TeamKey::from_bytes([7; 32]);
        let tag = key.mac(b"object data");
        assert!(key.verify(b"object data", &tag));
        assert!(!key.verify(b"object dats", &tag));
        assert!(!TeamKey::from_bytes([8; 32]).verify(b"object data", &tag));
        assert!(!key.verify(b"object data", &tag[..15]));
        // The published keyed-BLAKE3 construction, independently: the first 16 bytes of
        // blake3::keyed_hash.
        assert_eq!(&tag[..], &blake3::keyed_hash(&[7; 32], b"object data").as_bytes()[..16]);
    }
}
