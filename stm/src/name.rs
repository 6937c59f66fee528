//! Ring names: a number (`id-42`) or one to six characters `[a-z0-9_]` (`cam`),
//! as the thesis names its circular buffers "with an unsigned long integer, or
//! a six characters name", and the file each name maps to.

use shm_schemas::RobotName;
use shm_schemas::fixed::FixedName;
use shm_schemas::ring::RingNotice;
use std::fmt;
use std::path::{Path, PathBuf};

/// Longest textual ring name.
pub const RING_NAME_MAX_LEN: usize = 6;

/// What the text of a numbered ring starts with: `id-42` is ring number 42.
/// `-` is not allowed in a textual name, so the two forms never collide.
pub const RING_ID_PREFIX: &str = "id-";

/// A ring name that is not allowed, with the rule it breaks.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum RingNameError {
    /// The name is empty.
    #[error(
        "ring name is empty; use 1 to 6 characters from a-z, 0-9 and '_' (e.g. cam), or a number written id-<N> (e.g. id-42)"
    )]
    Empty,
    /// The name is longer than six characters.
    #[error(
        "ring name {name:?} is {len} characters long; at most 6 are allowed (a-z, 0-9 and '_'), or use a number written id-<N>"
    )]
    TooLong {
        /// the offending name
        name: String,
        /// its length in characters
        len: usize,
    },
    /// The name contains a character outside `[a-z0-9_]`.
    #[error(
        "ring name {name:?} contains {ch:?}; only lowercase letters a-z, digits 0-9 and '_' are allowed (or write a number as id-<N>)"
    )]
    BadChar {
        /// the offending name
        name: String,
        /// the first bad character
        ch: char,
    },
    /// Text starting with `id-` that is not followed by a number.
    #[error("{text:?} is not a ring number; write id-<N> with N a decimal number from 0 to 18446744073709551615")]
    BadId {
        /// the offending text
        text: String,
    },
}

/// The name of a ring within a robot: a `u64` id or one to six characters
/// from `[a-z0-9_]`. Validated on construction, so every value is usable as
/// part of a file name.
#[derive(Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct RingName(Repr);

#[derive(Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
enum Repr {
    Id(u64),
    Text { len: u8, bytes: [u8; RING_NAME_MAX_LEN] },
}

impl RingName {
    /// A numbered ring. Every `u64` is allowed.
    pub const fn id(id: u64) -> Self {
        RingName(Repr::Id(id))
    }

    /// A named ring: 1 to 6 characters from `[a-z0-9_]`.
    pub fn text(name: &str) -> Result<Self, RingNameError> {
        if name.is_empty() {
            return Err(RingNameError::Empty);
        }
        if let Some(ch) = name.chars().find(|c| !(c.is_ascii_lowercase() || c.is_ascii_digit() || *c == '_')) {
            return Err(RingNameError::BadChar { name: name.into(), ch });
        }
        // only ASCII from here on: bytes == characters
        if name.len() > RING_NAME_MAX_LEN {
            return Err(RingNameError::TooLong { name: name.into(), len: name.len() });
        }
        let mut bytes = [0u8; RING_NAME_MAX_LEN];
        bytes[..name.len()].copy_from_slice(name.as_bytes());
        Ok(RingName(Repr::Text { len: name.len() as u8, bytes }))
    }

    /// Parses the text form: `id-<N>` for a numbered ring, else a name.
    pub fn parse(text: &str) -> Result<Self, RingNameError> {
        match text.strip_prefix(RING_ID_PREFIX) {
            Some(num) => {
                // u64::from_str accepts a leading '+'; the canonical text has none
                if num.is_empty() || !num.bytes().all(|b| b.is_ascii_digit()) {
                    return Err(RingNameError::BadId { text: text.into() });
                }
                num.parse::<u64>().map(RingName::id).map_err(|_| RingNameError::BadId { text: text.into() })
            }
            None => RingName::text(text),
        }
    }

    /// The ring named by a notice.
    pub fn from_notice(notice: &RingNotice) -> Result<Self, RingNameError> {
        RingName::parse(notice.ring.as_str())
    }

    /// The number of a numbered ring.
    pub fn as_id(&self) -> Option<u64> {
        match self.0 {
            Repr::Id(id) => Some(id),
            Repr::Text { .. } => None,
        }
    }

    /// The text of a named ring.
    pub fn as_text(&self) -> Option<&str> {
        match &self.0 {
            Repr::Id(_) => None,
            // validated ASCII on construction
            Repr::Text { len, bytes } => std::str::from_utf8(&bytes[..*len as usize]).ok(),
        }
    }

    /// The name as stored in headers and notices (`cam`, `id-42`).
    pub fn to_fixed(&self) -> FixedName {
        FixedName::new(&self.to_string())
    }

    /// The file name of this ring of `robot`: `nerve_<uid>_<robot>_stm_<name>`.
    ///
    /// The prefix `nerve_<uid>_<robot>_` is how nerve finds (and cleans) everything
    /// a robot keeps in shared memory.
    pub fn file_name(&self, robot: &RobotName) -> String {
        format!("{}{}{}", robot.shm_prefix(), STM_INFIX, self)
    }

    /// The full path of this ring's file under `base_dir`.
    pub fn path_in(&self, base_dir: &Path, robot: &RobotName) -> PathBuf {
        base_dir.join(self.file_name(robot))
    }
}

/// What follows the robot prefix in every ring file name.
pub(crate) const STM_INFIX: &str = "stm_";

impl fmt::Display for RingName {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.0 {
            Repr::Id(id) => write!(f, "{RING_ID_PREFIX}{id}"),
            Repr::Text { .. } => f.write_str(self.as_text().unwrap_or("?")),
        }
    }
}

impl fmt::Debug for RingName {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "RingName({self})")
    }
}

impl std::str::FromStr for RingName {
    type Err = RingNameError;
    fn from_str(s: &str) -> Result<Self, RingNameError> {
        RingName::parse(s)
    }
}

impl From<u64> for RingName {
    fn from(id: u64) -> Self {
        RingName::id(id)
    }
}

impl serde::Serialize for RingName {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.collect_str(self)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn good_names() {
        for n in ["cam", "a", "img_01", "123456", "_"] {
            let r = RingName::parse(n).expect(n);
            assert_eq!(r.to_string(), n);
            assert_eq!(r.as_text(), Some(n));
        }
        let r = RingName::parse("id-42").expect("id");
        assert_eq!(r.as_id(), Some(42));
        assert_eq!(r, RingName::id(42));
        assert_eq!(RingName::id(u64::MAX).to_string(), format!("id-{}", u64::MAX));
        assert_eq!(RingName::parse(&RingName::id(u64::MAX).to_string()), Ok(RingName::id(u64::MAX)));
        assert_ne!(RingName::parse("42"), Ok(RingName::id(42)));
    }

    #[test]
    fn bad_names_say_what_is_allowed() {
        assert_eq!(RingName::parse(""), Err(RingNameError::Empty));
        assert!(RingName::parse("camera").is_ok());
        assert!(matches!(RingName::parse("camera1"), Err(RingNameError::TooLong { len: 7, .. })));
        assert!(matches!(RingName::parse("Cam"), Err(RingNameError::BadChar { ch: 'C', .. })));
        assert!(matches!(RingName::parse("a-b"), Err(RingNameError::BadChar { ch: '-', .. })));
        assert!(matches!(RingName::parse("a/b"), Err(RingNameError::BadChar { ch: '/', .. })));
        assert!(matches!(RingName::parse("é"), Err(RingNameError::BadChar { ch: 'é', .. })));
        assert!(matches!(RingName::parse("id-"), Err(RingNameError::BadId { .. })));
        assert!(matches!(RingName::parse("id-+1"), Err(RingNameError::BadId { .. })));
        assert!(matches!(RingName::parse("id-99999999999999999999"), Err(RingNameError::BadId { .. })));
        let msg = RingName::parse("Cam").expect_err("bad").to_string();
        assert!(msg.contains("a-z, digits 0-9 and '_'"), "{msg}");
        let msg = RingName::parse("camera1").expect_err("bad").to_string();
        assert!(msg.contains("at most 6"), "{msg}");
    }

    #[test]
    fn file_names_keep_the_robot_prefix() {
        let robot = RobotName::new("h1").expect("robot");
        let uid = shm_schemas::names::effective_uid();
        assert_eq!(RingName::parse("cam").expect("ok").file_name(&robot), format!("nerve_{uid}_h1_stm_cam"));
        assert_eq!(RingName::id(7).file_name(&robot), format!("nerve_{uid}_h1_stm_id-7"));
    }
}
