//! The team key: every envelope carries a MAC under it, so a radio outside the team can neither
//! inject nor alter messages. The MAC is keyed BLAKE3 (the `blake3` crate) truncated to 128 bits.

use std::fmt;

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

    /// Derived from a passphrase (BLAKE3 key derivation with a fixed context string).
    pub fn from_passphrase(passphrase: &str) -> Result<Self, TeamKeyError> {
        let n = passphrase.chars().count();
        if n < 12 {
            return Err(TeamKeyError::ShortPassphrase(n));
        }
        Ok(Self(blake3::derive_key("sgm team key v1", passphrase.as_bytes())))
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hex_and_passphrase_keys() {
        let hex = "00112233445566778899aabbccddeeff00112233445566778899aabbccddeeff";
        let key = TeamKey::from_hex(hex).unwrap();
        assert_eq!(key.0[1], 0x11);
        assert_eq!(TeamKey::from_hex("abc"), Err(TeamKeyError::Length(3)));
        assert_eq!(TeamKey::from_hex(&hex.replace("ff0", "fg0")), Err(TeamKeyError::Digit(30)));
        assert_eq!(TeamKey::from_passphrase("short"), Err(TeamKeyError::ShortPassphrase(5)));
        let a = TeamKey::from_passphrase("correct horse battery").unwrap();
        assert_ne!(a, TeamKey::from_passphrase("correct horse battery!").unwrap());
        assert_eq!(format!("{a:?}"), "TeamKey(<redacted>)");
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
