//! ROS 2 interface definitions: a parser of `.msg` files and the RIHS01
//! type hash of REP-2016 ("ROS Interface Hashing Standard", version 01).
//!
//! The hash is the SHA-256 of a canonical JSON text of the type's
//! description (`type_description_interfaces/msg/TypeDescription`): the
//! type's own fields and, sorted by name, every type it refers to,
//! directly or not. Each field is its name and its type: a numeric type id,
//! the array or sequence capacity, the string bound and the nested type's
//! name. Default values, constants and comments are not part of it. The JSON
//! is written with `", "` and `": "` between items, keys in the order of
//! the message definitions of `type_description_interfaces`.
//!
//! This file uses `std` only: `build.rs` includes it with `#[path]` to
//! compute the hashes of the vendored messages (`msg/`) at build time.

use std::collections::BTreeMap;
use std::fmt::Write as _;

/// A field's element type.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Base {
    /// `bool`
    Bool,
    /// `byte`
    Byte,
    /// `char`
    Char,
    /// `float32`
    Float32,
    /// `float64`
    Float64,
    /// `int8`
    Int8,
    /// `uint8`
    Uint8,
    /// `int16`
    Int16,
    /// `uint16`
    Uint16,
    /// `int32`
    Int32,
    /// `uint32`
    Uint32,
    /// `int64`
    Int64,
    /// `uint64`
    Uint64,
    /// `string` or `string<=N`
    String(Option<u64>),
    /// `wstring` or `wstring<=N`
    WString(Option<u64>),
    /// another message, by its full name `pkg/msg/Name`
    Nested(String),
}

/// How many elements a field holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Arity {
    /// one
    Single,
    /// `T[N]`: exactly N
    Array(u64),
    /// `T[<=N]`: up to N
    Bounded(u64),
    /// `T[]`: any number
    Unbounded,
}

/// One field of a message.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Field {
    /// its name
    pub name: String,
    /// its element type
    pub base: Base,
    /// array, sequence or single
    pub arity: Arity,
}

/// A parsed message definition.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MsgDef {
    /// `pkg/msg/Name`
    pub type_name: String,
    /// the fields in order (constants left out)
    pub fields: Vec<Field>,
}

/// Why a `.msg` text or a set of them could not be used.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum IdlError {
    /// A line of a `.msg` file is not a field or a constant.
    Parse {
        /// `pkg/msg/Name`
        type_name: String,
        /// 1-based line number
        line: usize,
        /// what is wrong
        reason: String,
    },
    /// A type refers to a type that is not among the definitions.
    Unknown {
        /// the type that refers to it
        by: String,
        /// the missing type
        missing: String,
    },
}

impl std::fmt::Display for IdlError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            IdlError::Parse { type_name, line, reason } => {
                write!(
                    f,
                    "{type_name}.msg line {line}: {reason}; a field is `TYPE NAME [DEFAULT]`, a constant `TYPE NAME=VALUE`"
                )
            }
            IdlError::Unknown { by, missing } => {
                write!(f, "{by} refers to {missing}, which is not vendored: add its .msg under agents/ros2/msg/")
            }
        }
    }
}

impl std::error::Error for IdlError {}

fn parse_u64(s: &str) -> Option<u64> {
    if s.is_empty() || !s.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    s.parse().ok()
}

fn parse_base(package: &str, t: &str) -> Result<Base, String> {
    let bounded = |rest: &str| -> Result<Option<u64>, String> {
        if rest.is_empty() {
            return Ok(None);
        }
        rest.strip_prefix("<=").and_then(parse_u64).map(Some).ok_or_else(|| format!("bad string bound {rest:?}"))
    };
    Ok(match t {
        "bool" => Base::Bool,
        "byte" => Base::Byte,
        "char" => Base::Char,
        "float32" => Base::Float32,
        "float64" => Base::Float64,
        "int8" => Base::Int8,
        "uint8" => Base::Uint8,
        "int16" => Base::Int16,
        "uint16" => Base::Uint16,
        "int32" => Base::Int32,
        "uint32" => Base::Uint32,
        "int64" => Base::Int64,
        "uint64" => Base::Uint64,
        _ if t.starts_with("wstring") => Base::WString(bounded(&t["wstring".len()..])?),
        _ if t.starts_with("string") => Base::String(bounded(&t["string".len()..])?),
        _ => {
            let ok = |s: &str| !s.is_empty() && s.bytes().all(|b| b.is_ascii_alphanumeric() || b == b'_');
            match t.split('/').collect::<Vec<_>>().as_slice() {
                [name] if ok(name) => Base::Nested(format!("{package}/msg/{name}")),
                [pkg, name] if ok(pkg) && ok(name) => Base::Nested(format!("{pkg}/msg/{name}")),
                [pkg, "msg", name] if ok(pkg) && ok(name) => Base::Nested(format!("{pkg}/msg/{name}")),
                _ => return Err(format!("unknown type {t:?}")),
            }
        }
    })
}

fn parse_type(package: &str, t: &str) -> Result<(Base, Arity), String> {
    let Some(open) = t.find('[') else { return Ok((parse_base(package, t)?, Arity::Single)) };
    let inner =
        t[open..].strip_prefix('[').and_then(|s| s.strip_suffix(']')).ok_or_else(|| format!("bad array {t:?}"))?;
    let arity = if inner.is_empty() {
        Arity::Unbounded
    } else if let Some(n) = inner.strip_prefix("<=") {
        Arity::Bounded(parse_u64(n).ok_or_else(|| format!("bad sequence bound {t:?}"))?)
    } else {
        Arity::Array(parse_u64(inner).ok_or_else(|| format!("bad array size {t:?}"))?)
    };
    Ok((parse_base(package, &t[..open])?, arity))
}

/// Parses the text of `package/msg/name.msg`.
pub fn parse_msg(package: &str, name: &str, text: &str) -> Result<MsgDef, IdlError> {
    let type_name = format!("{package}/msg/{name}");
    let mut fields = Vec::new();
    for (i, raw) in text.lines().enumerate() {
        let err = |reason: String| IdlError::Parse { type_name: type_name.clone(), line: i + 1, reason };
        // a comment runs to the end of the line (the vendored files have no
        // `#` inside string defaults)
        let line = raw.split('#').next().unwrap_or_default().trim();
        if line.is_empty() {
            continue;
        }
        let mut parts = line.splitn(2, char::is_whitespace);
        let (Some(ty), Some(rest)) = (parts.next(), parts.next()) else {
            return Err(err(format!("{line:?} has a type and no name")));
        };
        let rest = rest.trim();
        let name_end = rest.find(|c: char| c.is_whitespace() || c == '=').unwrap_or(rest.len());
        let field = &rest[..name_end];
        if field.is_empty() || !field.bytes().all(|b| b.is_ascii_alphanumeric() || b == b'_') {
            return Err(err(format!("bad field name {field:?}")));
        }
        let (base, arity) = parse_type(package, ty).map_err(err)?;
        if rest[name_end..].trim_start().starts_with('=') {
            continue; // a constant: not part of the type's layout or hash
        }
        fields.push(Field { name: field.to_owned(), base, arity });
    }
    Ok(MsgDef { type_name, fields })
}

/// The field type id of `type_description_interfaces/msg/FieldType`.
fn type_id(f: &Field) -> u64 {
    let base = match &f.base {
        Base::Nested(_) => 1,
        Base::Int8 => 2,
        Base::Uint8 => 3,
        Base::Int16 => 4,
        Base::Uint16 => 5,
        Base::Int32 => 6,
        Base::Uint32 => 7,
        Base::Int64 => 8,
        Base::Uint64 => 9,
        Base::Float32 => 10,
        Base::Float64 => 11,
        Base::Char => 13,
        Base::Bool => 15,
        Base::Byte => 16,
        Base::String(None) => 17,
        Base::WString(None) => 18,
        Base::String(Some(_)) => 21,
        Base::WString(Some(_)) => 22,
    };
    base + match f.arity {
        Arity::Single => 0,
        Arity::Array(_) => 48,
        Arity::Bounded(_) => 96,
        Arity::Unbounded => 144,
    }
}

fn json_str(out: &mut String, s: &str) {
    out.push('"');
    for c in s.chars() {
        match c {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            c if (c as u32) < 0x20 || (c as u32) > 0x7e => {
                let _ = write!(out, "\\u{:04x}", c as u32);
            }
            c => out.push(c),
        }
    }
    out.push('"');
}

fn json_type(out: &mut String, def: &MsgDef) {
    out.push_str("{\"type_name\": ");
    json_str(out, &def.type_name);
    out.push_str(", \"fields\": [");
    let dummy = [Field { name: "structure_needs_at_least_one_member".into(), base: Base::Uint8, arity: Arity::Single }];
    let fields = if def.fields.is_empty() { &dummy[..] } else { &def.fields[..] };
    for (i, f) in fields.iter().enumerate() {
        if i > 0 {
            out.push_str(", ");
        }
        let capacity = match f.arity {
            Arity::Array(n) | Arity::Bounded(n) => n,
            _ => 0,
        };
        let string_capacity = match f.base {
            Base::String(Some(n)) | Base::WString(Some(n)) => n,
            _ => 0,
        };
        let nested = match &f.base {
            Base::Nested(n) => n.as_str(),
            _ => "",
        };
        out.push_str("{\"name\": ");
        json_str(out, &f.name);
        let _ = write!(
            out,
            ", \"type\": {{\"type_id\": {}, \"capacity\": {capacity}, \"string_capacity\": {string_capacity}, \"nested_type_name\": ",
            type_id(f)
        );
        json_str(out, nested);
        out.push_str("}}");
    }
    out.push_str("]}");
}

/// Every type `root` refers to, directly or not, sorted by name.
fn referenced<'a>(root: &str, defs: &'a BTreeMap<String, MsgDef>) -> Result<Vec<&'a MsgDef>, IdlError> {
    let mut seen: BTreeMap<&str, &MsgDef> = BTreeMap::new();
    let mut todo = vec![root.to_owned()];
    while let Some(t) = todo.pop() {
        let def = defs.get(&t).ok_or_else(|| IdlError::Unknown { by: root.to_owned(), missing: t.clone() })?;
        for f in &def.fields {
            if let Base::Nested(n) = &f.base
                && !seen.contains_key(n.as_str())
            {
                let d = defs.get(n).ok_or_else(|| IdlError::Unknown { by: t.clone(), missing: n.clone() })?;
                seen.insert(d.type_name.as_str(), d);
                todo.push(n.clone());
            }
        }
    }
    Ok(seen.into_values().collect())
}

/// The canonical JSON text of `root`'s type description, the input of its
/// RIHS01 hash.
pub fn type_description_json(root: &str, defs: &BTreeMap<String, MsgDef>) -> Result<String, IdlError> {
    let def = defs.get(root).ok_or_else(|| IdlError::Unknown { by: root.to_owned(), missing: root.to_owned() })?;
    let mut out = String::from("{\"type_description\": ");
    json_type(&mut out, def);
    out.push_str(", \"referenced_type_descriptions\": [");
    for (i, d) in referenced(root, defs)?.into_iter().enumerate() {
        if i > 0 {
            out.push_str(", ");
        }
        json_type(&mut out, d);
    }
    out.push_str("]}");
    Ok(out)
}

/// `RIHS01_<sha256 hex>` of `root`.
pub fn rihs01(root: &str, defs: &BTreeMap<String, MsgDef>) -> Result<String, IdlError> {
    let json = type_description_json(root, defs)?;
    let mut s = String::from("RIHS01_");
    for b in sha256(json.as_bytes()) {
        let _ = write!(s, "{b:02x}");
    }
    Ok(s)
}

const K: [u32; 64] = [
    0x428a2f98, 0x71374491, 0xb5c0fbcf, 0xe9b5dba5, 0x3956c25b, 0x59f111f1, 0x923f82a4, 0xab1c5ed5, 0xd807aa98,
    0x12835b01, 0x243185be, 0x550c7dc3, 0x72be5d74, 0x80deb1fe, 0x9bdc06a7, 0xc19bf174, 0xe49b69c1, 0xefbe4786,
    0x0fc19dc6, 0x240ca1cc, 0x2de92c6f, 0x4a7484aa, 0x5cb0a9dc, 0x76f988da, 0x983e5152, 0xa831c66d, 0xb00327c8,
    0xbf597fc7, 0xc6e00bf3, 0xd5a79147, 0x06ca6351, 0x14292967, 0x27b70a85, 0x2e1b2138, 0x4d2c6dfc, 0x53380d13,
    0x650a7354, 0x766a0abb, 0x81c2c92e, 0x92722c85, 0xa2bfe8a1, 0xa81a664b, 0xc24b8b70, 0xc76c51a3, 0xd192e819,
    0xd6990624, 0xf40e3585, 0x106aa070, 0x19a4c116, 0x1e376c08, 0x2748774c, 0x34b0bcb5, 0x391c0cb3, 0x4ed8aa4a,
    0x5b9cca4f, 0x682e6ff3, 0x748f82ee, 0x78a5636f, 0x84c87814, 0x8cc70208, 0x90befffa, 0xa4506ceb, 0xbef9a3f7,
    0xc67178f2,
];

/// SHA-256 (FIPS 180-4) of `data`: a few short texts at build time and
/// per entity at start, so a plain implementation, not a dependency.
pub fn sha256(data: &[u8]) -> [u8; 32] {
    let mut h: [u32; 8] =
        [0x6a09e667, 0xbb67ae85, 0x3c6ef372, 0xa54ff53a, 0x510e527f, 0x9b05688c, 0x1f83d9ab, 0x5be0cd19];
    let bit_len = (data.len() as u64).wrapping_mul(8);
    let mut msg = data.to_vec();
    msg.push(0x80);
    while msg.len() % 64 != 56 {
        msg.push(0);
    }
    msg.extend_from_slice(&bit_len.to_be_bytes());
    for block in msg.chunks_exact(64) {
        let mut w = [0u32; 64];
        for (i, c) in block.chunks_exact(4).enumerate() {
            w[i] = u32::from_be_bytes([c[0], c[1], c[2], c[3]]);
        }
        for i in 16..64 {
            let s0 = w[i - 15].rotate_right(7) ^ w[i - 15].rotate_right(18) ^ (w[i - 15] >> 3);
            let s1 = w[i - 2].rotate_right(17) ^ w[i - 2].rotate_right(19) ^ (w[i - 2] >> 10);
            w[i] = w[i - 16].wrapping_add(s0).wrapping_add(w[i - 7]).wrapping_add(s1);
        }
        let [mut a, mut b, mut c, mut d, mut e, mut f, mut g, mut hh] = h;
        for i in 0..64 {
            let s1 = e.rotate_right(6) ^ e.rotate_right(11) ^ e.rotate_right(25);
            let ch = (e & f) ^ (!e & g);
            let t1 = hh.wrapping_add(s1).wrapping_add(ch).wrapping_add(K[i]).wrapping_add(w[i]);
            let s0 = a.rotate_right(2) ^ a.rotate_right(13) ^ a.rotate_right(22);
            let maj = (a & b) ^ (a & c) ^ (b & c);
            let t2 = s0.wrapping_add(maj);
            hh = g;
            g = f;
            f = e;
            e = d.wrapping_add(t1);
            d = c;
            c = b;
            b = a;
            a = t1.wrapping_add(t2);
        }
        for (x, y) in h.iter_mut().zip([a, b, c, d, e, f, g, hh]) {
            *x = x.wrapping_add(y);
        }
    }
    let mut out = [0u8; 32];
    for (i, x) in h.iter().enumerate() {
        out[i * 4..i * 4 + 4].copy_from_slice(&x.to_be_bytes());
    }
    out
}
