//! What a payload says about itself: its [`Schema`], the field-by-field
//! layout of a `#[repr(C)]` type (names, offsets, primitive types, fixed
//! arrays, fixed strings, nested structs), and the [`Schema::fingerprint`]
//! of that layout.
//!
//! A payload gets its schema from `#[derive(Payload)]` (the
//! `shm-schemas-derive` crate), which reads the offsets from the compiler
//! (`core::mem::offset_of!`), so a schema cannot drift from the type it
//! describes. A tool that holds only the bytes of a sample and the schema
//! can decode it ([`Schema::decode`]), whatever crate defined the type: that
//! is what makes a port self-describing.
//!
//! Enums travel as their integer (the payloads store `u8` codes), so the
//! schema has no enum kind.
//!
//! A payload of your own, in any crate that depends on `shm-schemas`:
//!
//! ```
//! use shm_schemas::{Described, Payload};
//!
//! #[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize, Payload)]
//! #[repr(C)]
//! #[payload(name = "lab::Gripper")]
//! pub struct Gripper {
//!     pub width_m: f32,
//!     pub force_n: f32,
//!     pub closed: u8,
//!     // explicit padding, left out of the schema (see below)
//!     #[serde(skip)]
//!     pub _pad: [u8; 3],
//! }
//!
//! assert_eq!(Gripper::stable_type_name(), "lab::Gripper");
//! let schema = Gripper::schema();
//! assert_eq!(schema.field("force_n").map(|(offset, _)| offset), Some(4));
//! assert_eq!(Gripper::layout_fingerprint(), schema.fingerprint());
//! ```
//!
//! A layout the compiler may reorder is refused:
//!
//! ```compile_fail
//! #[derive(Debug, Clone, Copy, serde::Serialize, shm_schemas::Payload)]
//! #[payload(name = "lab::Loose")]
//! pub struct Loose {
//!     pub a: u8,
//! }
//! ```
//!
//! and so is a payload without its stable name:
//!
//! ```compile_fail
//! #[derive(Debug, Clone, Copy, serde::Serialize, shm_schemas::Payload)]
//! #[repr(C)]
//! pub struct Nameless {
//!     pub a: u8,
//! }
//! ```
//!
//! A sample's bytes may come from a recording, a bridge peer or Python, not
//! only from Rust, so every field must be valid for any bytes
//! ([`AnyBitPattern`]). A `bool` is refused (store a `u8`, or a [`Bool`]):
//!
//! ```compile_fail
//! #[derive(Debug, Clone, Copy, serde::Serialize, shm_schemas::Payload)]
//! #[repr(C)]
//! #[payload(name = "lab::Flag")]
//! pub struct Flag {
//!     pub closed: bool,
//! }
//! ```
//!
//! so is a `char`, in an array too:
//!
//! ```compile_fail
//! #[derive(Debug, Clone, Copy, serde::Serialize, shm_schemas::Payload)]
//! #[repr(C)]
//! #[payload(name = "lab::Letters")]
//! pub struct Letters {
//!     pub letters: [char; 4],
//! }
//! ```
//!
//! and an enum, even one that claims to be sendable and describes itself:
//!
//! ```compile_fail
//! #[derive(Debug, Clone, Copy, serde::Serialize)]
//! #[repr(u8)]
//! pub enum Phase { Open = 0, Closed = 1 }
//! // SAFETY: (not enough: a byte 2 is no Phase)
//! unsafe impl shm_schemas::__private::ZeroCopySend for Phase {}
//! impl shm_schemas::Described for Phase {
//!     fn schema() -> shm_schemas::Schema { <u8 as shm_schemas::Described>::schema() }
//! }
//! #[derive(Debug, Clone, Copy, serde::Serialize, shm_schemas::Payload)]
//! #[repr(C)]
//! #[payload(name = "lab::Phased")]
//! pub struct Phased {
//!     pub phase: Phase,
//! }
//! ```
//!
//! Implicit padding is refused too: Rust never writes padding bytes, so a
//! copy of a sample's bytes would read uninitialised memory. Here the
//! compiler pads 3 bytes after `closed`:
//!
//! ```compile_fail
//! #[derive(Debug, Clone, Copy, serde::Serialize, shm_schemas::Payload)]
//! #[repr(C)]
//! #[payload(name = "lab::Padded")]
//! pub struct Padded {
//!     pub closed: u8,
//!     pub force_n: f32,
//! }
//! ```
//!
//! Written out as a `_pad` field, the padding is a field like the others,
//! left out of the schema (the layout fingerprint stays what it was):
//!
//! ```
//! use shm_schemas::{Described, Payload, schema::Bool};
//!
//! #[derive(Debug, Clone, Copy, Default, serde::Serialize, Payload)]
//! #[repr(C)]
//! #[payload(name = "lab::Padded")]
//! pub struct Padded {
//!     pub closed: Bool,
//!     #[serde(skip)]
//!     pub _pad: [u8; 3],
//!     pub force_n: f32,
//! }
//!
//! let schema = Padded::schema();
//! assert_eq!((schema.size, schema.field("force_n").map(|(o, _)| o)), (8, Some(4)));
//! assert!(schema.field("_pad").is_none());
//! ```

use serde::{Deserialize, Serialize};

pub mod compat;
mod plain;
mod validate;
pub use plain::{AnyBitPattern, Bool};
pub use validate::{MAX_ALIGN, MAX_DEPTH, MAX_FIELDS, MAX_NAME_LEN, MAX_SIZE, SchemaInvalid};

/// The layout of a type that can be part of a payload.
///
/// Deserialising one is bounded in depth ([`MAX_DECODE_DEPTH`]): schemas
/// arrive from other processes (registrations, the tool socket) and files,
/// and a schema nested tens of thousands deep in a few hundred kilobytes of
/// postcard would otherwise recurse until the decoding thread's stack
/// overflowed, aborting the router before [`Schema::validate`] could refuse
/// it.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct Schema {
    /// The stable type name (`nerve::Tick`; `u64` for a primitive, `[f32; 3]` for an array).
    pub type_name: String,
    /// `size_of`, bytes.
    pub size: usize,
    /// `align_of`, bytes.
    pub align: usize,
    /// What it is made of.
    pub kind: Kind,
}

/// How deep a schema may be nested when it is deserialised: twice what
/// [`Schema::validate`] accepts ([`MAX_DEPTH`]), so that a deep schema is
/// still refused by `validate` with its own message, and a few kilobytes of
/// stack at most.
pub const MAX_DECODE_DEPTH: usize = 2 * MAX_DEPTH;

thread_local! {
    /// Schemas being deserialised on this thread, one inside the other.
    static DECODE_DEPTH: std::cell::Cell<usize> = const { std::cell::Cell::new(0) };
}

/// The fields of [`Schema`] as serde derives them (same names and order,
/// so every format reads what it read before).
#[derive(Deserialize)]
#[serde(rename = "Schema")]
struct SchemaFields {
    type_name: String,
    size: usize,
    align: usize,
    kind: Kind,
}

impl<'de> Deserialize<'de> for Schema {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        /// Leaves the level on every way out, errors included.
        struct Level;
        impl Drop for Level {
            fn drop(&mut self) {
                DECODE_DEPTH.with(|n| n.set(n.get().saturating_sub(1)));
            }
        }
        let depth = DECODE_DEPTH.with(|n| {
            n.set(n.get().saturating_add(1));
            n.get()
        });
        let _level = Level;
        if depth > MAX_DECODE_DEPTH {
            return Err(serde::de::Error::custom(format!(
                "a schema nested more than {MAX_DECODE_DEPTH} deep (nerve accepts {MAX_DEPTH}): refused before it is read further"
            )));
        }
        let SchemaFields { type_name, size, align, kind } = SchemaFields::deserialize(d)?;
        Ok(Schema { type_name, size, align, kind })
    }
}

/// What a [`Schema`] describes. Externally tagged (`{"struct": {...}}` in
/// JSON): the control protocol's postcard cannot carry internally tagged
/// enums.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Kind {
    /// A number or a bool.
    Primitive {
        /// which one
        primitive: Primitive,
    },
    /// `[T; N]`
    Array {
        /// `N`
        len: usize,
        /// `T`
        element: Box<Schema>,
    },
    /// A UTF-8 string of at most `capacity` bytes, stored inline as a `u32`
    /// length followed by the bytes ([`crate::FixedName`]).
    String {
        /// the most bytes it holds
        capacity: usize,
    },
    /// A `#[repr(C)]` struct.
    Struct {
        /// Its fields in declaration order.
        fields: Vec<Field>,
    },
    /// A variable-size payload ([`crate::seq`]): `header`, then as many
    /// `element`s as the sample's length holds, starting at the schema's
    /// `size`. Only a port's payload itself is one, never a field.
    Sequence {
        /// the fixed part at the start
        header: Box<Schema>,
        /// the type of each element
        element: Box<Schema>,
    },
}

/// A field of a struct.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Field {
    /// Its name.
    pub name: String,
    /// Its offset from the start of the struct, bytes.
    pub offset: usize,
    /// Its type.
    pub schema: Schema,
}

/// The primitive types a payload may hold (little-endian, as on every
/// machine nerve runs on).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
#[allow(missing_docs)]
pub enum Primitive {
    U8,
    U16,
    U32,
    U64,
    I8,
    I16,
    I32,
    I64,
    F32,
    F64,
    Bool,
}

/// The schema of the built-in payload type with layout `fingerprint`, for
/// tools that meet a port of a type whose agent registered no schema.
pub fn built_in(fingerprint: u64) -> Option<Schema> {
    let mut found = None;
    macro_rules! look {
        ($t:ty) => {
            if found.is_none() && <$t as crate::Payload>::layout_fingerprint() == fingerprint {
                found = Some(<$t as Described>::schema());
            }
        };
    }
    crate::for_each_payload!(look);
    found
}

/// The schema of the built-in payload type named `type_name` (its
/// `stable_type_name`, e.g. `nerve::Twist`), for the C and Python SDKs that
/// declare ports by type name.
pub fn built_in_named(type_name: &str) -> Option<Schema> {
    let mut found = None;
    macro_rules! look {
        ($t:ty) => {
            if found.is_none() && <$t as crate::Payload>::stable_type_name() == type_name {
                found = Some(<$t as Described>::schema());
            }
        };
    }
    crate::for_each_payload!(look);
    found
}

/// A type that knows its [`Schema`]. Implemented for the primitives, fixed
/// arrays and [`crate::FixedName`] here, and by `#[derive(Payload)]`.
pub trait Described {
    /// The type's layout.
    fn schema() -> Schema;
}

macro_rules! primitive {
    ($($t:ty => $p:ident),* $(,)?) => {$(
        impl Described for $t {
            fn schema() -> Schema {
                Schema {
                    type_name: stringify!($t).into(),
                    size: std::mem::size_of::<$t>(),
                    align: std::mem::align_of::<$t>(),
                    kind: Kind::Primitive { primitive: Primitive::$p },
                }
            }
        }
    )*};
}

primitive!(u8 => U8, u16 => U16, u32 => U32, u64 => U64, i8 => I8, i16 => I16, i32 => I32, i64 => I64,
    f32 => F32, f64 => F64, bool => Bool);

impl<T: Described, const N: usize> Described for [T; N] {
    fn schema() -> Schema {
        let element = T::schema();
        Schema {
            type_name: format!("[{}; {N}]", element.type_name),
            size: std::mem::size_of::<[T; N]>(),
            align: std::mem::align_of::<[T; N]>(),
            kind: Kind::Array { len: N, element: Box::new(element) },
        }
    }
}

/// A value decoded from a sample's bytes through its [`Schema`]. It
/// serializes as the payload itself would with serde (a struct as a map in
/// field order, an `f32` as an `f32`), and displays in a compact human form.
#[derive(Debug, Clone, PartialEq)]
pub enum Value {
    /// a bool
    Bool(bool),
    /// an unsigned integer
    Unsigned(u64),
    /// a signed integer
    Signed(i64),
    /// an `f32`
    F32(f32),
    /// an `f64`
    Float(f64),
    /// a string (invalid UTF-8 is replaced)
    String(String),
    /// an array
    Array(Vec<Value>),
    /// a struct's fields in order
    Struct(Vec<(String, Value)>),
}

impl Serialize for Value {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        use serde::ser::{SerializeMap, SerializeSeq};
        match self {
            Value::Bool(b) => s.serialize_bool(*b),
            Value::Unsigned(u) => s.serialize_u64(*u),
            Value::Signed(i) => s.serialize_i64(*i),
            Value::F32(f) => s.serialize_f32(*f),
            Value::Float(f) => s.serialize_f64(*f),
            Value::String(t) => s.serialize_str(t),
            Value::Array(a) => {
                let mut seq = s.serialize_seq(Some(a.len()))?;
                for v in a {
                    seq.serialize_element(v)?;
                }
                seq.end()
            }
            Value::Struct(fields) => {
                let mut map = s.serialize_map(Some(fields.len()))?;
                for (k, v) in fields {
                    map.serialize_entry(k, v)?;
                }
                map.end()
            }
        }
    }
}

impl std::fmt::Display for Value {
    /// `{ seq: 7, pose: { x: 1.5, y: -2.0 }, name: "motor", ranges_m: [1.0, 2.0] }`
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Value::Bool(b) => write!(f, "{b}"),
            Value::Unsigned(u) => write!(f, "{u}"),
            Value::Signed(i) => write!(f, "{i}"),
            // `{:?}` keeps a float a float: 20.0, not 20 (which reads as an integer)
            Value::F32(x) => write!(f, "{x:?}"),
            Value::Float(x) => write!(f, "{x:?}"),
            Value::String(t) => write!(f, "{t:?}"),
            Value::Array(a) => {
                f.write_str("[")?;
                for (i, v) in a.iter().enumerate() {
                    if i > 0 {
                        f.write_str(", ")?;
                    }
                    write!(f, "{v}")?;
                }
                f.write_str("]")
            }
            Value::Struct(fields) => {
                f.write_str("{ ")?;
                for (i, (k, v)) in fields.iter().enumerate() {
                    if i > 0 {
                        f.write_str(", ")?;
                    }
                    write!(f, "{k}: {v}")?;
                }
                f.write_str(" }")
            }
        }
    }
}

/// Why bytes could not be decoded through a schema.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum DecodeError {
    /// Fewer bytes than the schema's size.
    #[error("{type_name} takes {size} bytes, the sample has {got}: the port's type does not match its schema")]
    Short {
        /// the type
        type_name: String,
        /// its size
        size: usize,
        /// the bytes given
        got: usize,
    },
}

impl Schema {
    /// The fingerprint of the layout (64-bit FNV-1a over the type name,
    /// size, alignment, and each field's name, offset and schema, in
    /// order): two builds that disagree on any of them get different
    /// fingerprints, so a stale build is refused instead of misread.
    pub fn fingerprint(&self) -> u64 {
        let mut h = Fnv::new();
        self.feed(&mut h);
        h.0
    }

    fn feed(&self, h: &mut Fnv) {
        h.bytes(self.type_name.as_bytes());
        h.bytes(&[0]);
        h.bytes(&(self.size as u64).to_le_bytes());
        h.bytes(&(self.align as u64).to_le_bytes());
        match &self.kind {
            Kind::Primitive { primitive } => h.bytes(&[1, *primitive as u8]),
            Kind::Array { len, element } => {
                h.bytes(&[2]);
                h.bytes(&(*len as u64).to_le_bytes());
                element.feed(h);
            }
            Kind::String { capacity } => {
                h.bytes(&[3]);
                h.bytes(&(*capacity as u64).to_le_bytes());
            }
            Kind::Struct { fields } => {
                h.bytes(&[4]);
                h.bytes(&(fields.len() as u64).to_le_bytes());
                for f in fields {
                    h.bytes(f.name.as_bytes());
                    h.bytes(&[0]);
                    h.bytes(&(f.offset as u64).to_le_bytes());
                    f.schema.feed(h);
                }
            }
            Kind::Sequence { header, element } => {
                h.bytes(&[5]);
                header.feed(h);
                element.feed(h);
            }
        }
    }

    /// Decodes `bytes` (at least [`Schema::size`] of them, as a sample's
    /// payload) into a [`Value`].
    pub fn decode(&self, bytes: &[u8]) -> Result<Value, DecodeError> {
        let Some(fixed) = bytes.get(..self.size) else {
            return Err(DecodeError::Short { type_name: self.type_name.clone(), size: self.size, got: bytes.len() });
        };
        match &self.kind {
            // a sequence's sample is as long as its elements make it
            Kind::Sequence { .. } => Ok(self.decode_exact(bytes)),
            _ => Ok(self.decode_exact(fixed)),
        }
    }

    /// Decodes `bytes`, which are exactly `self.size` long (checked by the caller).
    fn decode_exact(&self, bytes: &[u8]) -> Value {
        match &self.kind {
            Kind::Primitive { primitive } => primitive.decode(bytes),
            Kind::Array { len, element } => {
                // a schema may come from another process: never trust its
                // figures beyond the bytes at hand
                let n = bytes.len().checked_div(element.size).map_or(0, |fit| fit.min(*len));
                Value::Array(bytes.chunks_exact(element.size.max(1)).take(n).map(|b| element.decode_exact(b)).collect())
            }
            Kind::String { capacity } => {
                let len = bytes.get(..4).map_or(0, |b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize);
                let end = 4usize.saturating_add(len.min(*capacity)).min(bytes.len());
                let text = bytes.get(4..end).unwrap_or_default();
                Value::String(String::from_utf8_lossy(text).into_owned())
            }
            Kind::Struct { fields } => Value::Struct(
                fields
                    .iter()
                    .filter_map(|f| {
                        let b = bytes.get(f.offset..f.offset.checked_add(f.schema.size)?)?;
                        Some((f.name.clone(), f.schema.decode_exact(b)))
                    })
                    .collect(),
            ),
            Kind::Sequence { header, element } => {
                let head = bytes.get(..header.size).map_or(Value::Struct(Vec::new()), |b| header.decode_exact(b));
                let items = bytes.get(self.size..).unwrap_or_default();
                let items = match element.size {
                    0 => Vec::new(),
                    n => items.chunks_exact(n).map(|b| element.decode_exact(b)).collect(),
                };
                Value::Struct(vec![
                    (crate::seq::HEADER_FIELD.into(), head),
                    (crate::seq::ITEMS_FIELD.into(), Value::Array(items)),
                ])
            }
        }
    }

    /// The value of the field at `path` in a sample's `bytes`; `None` when
    /// the type has no such field or the bytes are too short.
    pub fn decode_field(&self, path: &str, bytes: &[u8]) -> Option<Value> {
        let (offset, schema) = self.field(path)?;
        let b = bytes.get(offset..offset.checked_add(schema.size)?)?;
        Some(schema.decode_exact(b))
    }

    /// Like [`Schema::decode_field`], and for a sequence's sample also
    /// `items` (all its elements, as an array): what `nerve echo --field`
    /// prints. `None` when the type has no such field or the sample is
    /// too short (an element past the sample's length).
    pub fn decode_path(&self, path: &str, bytes: &[u8]) -> Option<Value> {
        if let Kind::Sequence { element, .. } = &self.kind
            && path_parts(path).eq([crate::seq::ITEMS_FIELD])
        {
            let items = bytes.get(self.size..)?;
            let n = element.size.max(1);
            return Some(Value::Array(items.chunks_exact(n).map(|b| element.decode_exact(b)).collect()));
        }
        self.decode_field(path, bytes)
    }

    /// Whether [`Schema::decode_path`] knows `path` (for a sequence, an
    /// element of any index).
    pub fn has_path(&self, path: &str) -> bool {
        match &self.kind {
            Kind::Sequence { .. } if path_parts(path).eq([crate::seq::ITEMS_FIELD]) => true,
            _ => self.field(path).is_some(),
        }
    }

    /// Calls `visit(path, schema, lens)` for every field inside this type,
    /// depth first in declaration order: `path` as [`Schema::field`] takes
    /// it with `<i>` for an array's element (`fingers`, `fingers.<i>`,
    /// `fingers.<i>.force_n`), `lens` the lengths of the arrays crossed to
    /// get there, the last one that of the array an `<i>` node is the
    /// element of. Empty arrays are not entered. For the lists tools print
    /// when a path is wrong.
    pub fn visit_fields(&self, mut visit: impl FnMut(&str, &Schema, &[usize])) {
        fn walk(s: &Schema, prefix: &str, lens: &[usize], visit: &mut dyn FnMut(&str, &Schema, &[usize])) {
            let join = |name: &str| if prefix.is_empty() { name.to_string() } else { format!("{prefix}.{name}") };
            match &s.kind {
                Kind::Struct { fields } => {
                    for f in fields {
                        let path = join(&f.name);
                        visit(&path, &f.schema, lens);
                        walk(&f.schema, &path, lens, visit);
                    }
                }
                Kind::Array { len, element } if *len > 0 => {
                    let path = join("<i>");
                    let lens = [lens, &[*len]].concat();
                    visit(&path, element, &lens);
                    walk(element, &path, &lens, visit);
                }
                Kind::Sequence { header, element } => {
                    let path = join(crate::seq::HEADER_FIELD);
                    visit(&path, header, lens);
                    walk(header, &path, lens, visit);
                    let path = format!("{}.<i>", join(crate::seq::ITEMS_FIELD));
                    visit(&path, element, lens);
                    walk(element, &path, lens, visit);
                }
                _ => {}
            }
        }
        walk(self, "", &[], &mut visit);
    }

    /// The schema of the field at `path` (`pose.x`, `ranges_m.3` or
    /// `ranges_m[3]` for an array element; `header.seq`, `items[3].x` in a
    /// sequence's sample), with its offset from the start of this type.
    pub fn field(&self, path: &str) -> Option<(usize, &Schema)> {
        let mut at = (0usize, self);
        let mut parts = path_parts(path);
        while let Some(part) = parts.next() {
            let (offset, schema) = at;
            at = match &schema.kind {
                Kind::Sequence { header, .. } if part == crate::seq::HEADER_FIELD => (offset, header.as_ref()),
                Kind::Sequence { element, .. } if part == crate::seq::ITEMS_FIELD => {
                    let i: usize = parts.next()?.parse().ok()?;
                    (offset.checked_add(schema.size)?.checked_add(i.checked_mul(element.size)?)?, element.as_ref())
                }
                Kind::Struct { fields } => {
                    let f = fields.iter().find(|f| f.name == part)?;
                    (offset.checked_add(f.offset)?, &f.schema)
                }
                Kind::Array { len, element } => {
                    let i: usize = part.parse().ok().filter(|i| i < len)?;
                    (offset.checked_add(i.checked_mul(element.size)?)?, element.as_ref())
                }
                _ => return None,
            };
        }
        Some(at)
    }
}

impl Primitive {
    fn decode(self, b: &[u8]) -> Value {
        // a schema from another process may give a primitive too few
        // bytes: the missing ones read as zero
        fn le<const N: usize>(b: &[u8]) -> [u8; N] {
            let mut a = [0u8; N];
            let n = b.len().min(N);
            a[..n].copy_from_slice(&b[..n]);
            a
        }
        match self {
            Primitive::U8 => Value::Unsigned(u64::from(le::<1>(b)[0])),
            Primitive::U16 => Value::Unsigned(u64::from(u16::from_le_bytes(le(b)))),
            Primitive::U32 => Value::Unsigned(u64::from(u32::from_le_bytes(le(b)))),
            Primitive::U64 => Value::Unsigned(u64::from_le_bytes(le(b))),
            Primitive::I8 => Value::Signed(i64::from(le::<1>(b)[0] as i8)),
            Primitive::I16 => Value::Signed(i64::from(i16::from_le_bytes(le(b)))),
            Primitive::I32 => Value::Signed(i64::from(i32::from_le_bytes(le(b)))),
            Primitive::I64 => Value::Signed(i64::from_le_bytes(le(b))),
            Primitive::F32 => Value::F32(f32::from_le_bytes(le(b))),
            Primitive::F64 => Value::Float(f64::from_le_bytes(le(b))),
            Primitive::Bool => Value::Bool(le::<1>(b)[0] != 0),
        }
    }
}

/// The parts of a field path: `items[3].x` and `items.3.x` are both
/// `items`, `3`, `x`.
fn path_parts(path: &str) -> impl Iterator<Item = &str> {
    path.split(['.', '[', ']']).filter(|p| !p.is_empty())
}

/// 64-bit FNV-1a.
struct Fnv(u64);

impl Fnv {
    fn new() -> Self {
        Fnv(0xcbf2_9ce4_8422_2325)
    }

    fn bytes(&mut self, b: &[u8]) {
        for &x in b {
            self.0 ^= u64::from(x);
            self.0 = self.0.wrapping_mul(0x0000_0100_0000_01b3);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::FixedName;
    use crate::payloads::{AgentLoad, ResourceHeader, ResourceReport, SonarScan, Tick, resources::report_bytes};

    fn bytes_of<T: Copy>(v: &T) -> Vec<u8> {
        // SAFETY: reading the bytes of a Copy #[repr(C)] value; its padding
        // is whatever it is, and the decoder reads fields only
        unsafe { std::slice::from_raw_parts((v as *const T).cast::<u8>(), std::mem::size_of::<T>()) }.to_vec()
    }

    #[test]
    fn every_built_in_payload_is_found_by_its_name_and_an_unknown_name_is_not() {
        let mut n = 0;
        macro_rules! each {
            ($t:ty) => {
                n += 1;
                let name = <$t as crate::Payload>::stable_type_name();
                assert_eq!(built_in_named(name), Some(<$t as Described>::schema()), "{name}");
            };
        }
        crate::for_each_payload!(each);
        assert!(n > 20, "the list of payloads was walked: {n}");
        assert_eq!(built_in_named("nerve::NoSuchType"), None);
        assert_eq!(built_in_named(""), None);
    }

    #[test]
    fn a_sample_decodes_through_its_schema_alone() {
        let tick = Tick { seq: 7, stamp_ns: 123_456_789 };
        let v = Tick::schema().decode(&bytes_of(&tick)).expect("decodes");
        assert_eq!(
            v,
            Value::Struct(vec![("seq".into(), Value::Unsigned(7)), ("stamp_ns".into(), Value::Unsigned(123_456_789))])
        );
        // nested structs, arrays of structs and fixed strings
        #[derive(Debug, Clone, Copy, Default, PartialEq, crate::Payload, serde::Serialize)]
        #[repr(C)]
        #[payload(name = "test::Loads")]
        struct Loads {
            cpus: u32,
            _pad: [u8; 4],
            agents: [AgentLoad; 2],
        }
        let mut loads = Loads { cpus: 2, ..Default::default() };
        loads.agents[1] = AgentLoad { name: FixedName::new("motor"), cpu_percent: 12.5, ..Default::default() };
        let schema = Loads::schema();
        let v = schema.decode(&bytes_of(&loads)).expect("decodes");
        let json = serde_json_like(&v);
        assert!(json.contains(r#""cpus":2"#) && json.contains(r#""name":"motor""#) && json.contains("12.5"), "{json}");
        let (offset, s) = schema.field("agents.1.cpu_percent").expect("a nested field");
        assert_eq!(s.kind, Kind::Primitive { primitive: Primitive::F32 });
        assert_eq!(s.decode(&bytes_of(&loads)[offset..]).expect("the field"), Value::F32(12.5));
        assert!(schema.field("agents.99.name").is_none(), "out of the array");
        assert!(schema.field("nothing").is_none());
        let scan = SonarScan::schema();
        assert!(matches!(scan.field("ranges_m"), Some((_, Schema { kind: Kind::Array { .. }, .. }))));
    }

    /// What `nerve echo --json` prints through the schema is what serde
    /// prints of the typed value, for every payload this build knows.
    #[test]
    fn every_payload_decodes_to_the_json_serde_gives_it() {
        fn check<T: crate::Payload>() {
            // a payload is plain data: all-zero bytes are a valid value of it
            // (bools false, strings empty); then a byte pattern on the numbers
            // SAFETY: payloads are #[repr(C)] plain data of numbers, bools,
            // arrays and FixedName, for which all-zero bytes are valid
            let zero: T = unsafe { std::mem::zeroed() };
            let typed = serde_json::to_value(zero).expect("serde");
            let decoded = serde_json::to_value(T::schema().decode(&bytes_of(&zero)).expect("decodes")).expect("json");
            assert_eq!(typed, decoded, "{}", T::stable_type_name());
            assert_eq!(
                serde_json::to_string(&zero).expect("serde"),
                serde_json::to_string(&T::schema().decode(&bytes_of(&zero)).expect("decodes")).expect("json"),
                "{}: the same text, fields in the same order",
                T::stable_type_name()
            );
        }
        macro_rules! each {
            ($t:ty) => {
                check::<$t>();
            };
        }
        crate::for_each_payload!(each);
        let tick = Tick { seq: 3, stamp_ns: 9 };
        assert_eq!(
            serde_json::to_string(&Tick::schema().decode(&bytes_of(&tick)).expect("decodes")).expect("json"),
            r#"{"seq":3,"stamp_ns":9}"#
        );
        // a sequence: the header and the elements, as serde gives them
        let header = ResourceHeader { cpus: 2, agents: 1, ..Default::default() };
        let load = AgentLoad { name: FixedName::new("motor"), cpu_percent: 0.1, ..Default::default() };
        let decoded = ResourceReport::schema().decode(&report_bytes(&header, &[load])).expect("decodes");
        assert_eq!(
            serde_json::to_string(&decoded).expect("json"),
            format!(
                r#"{{"header":{},"items":[{}]}}"#,
                serde_json::to_string(&header).expect("serde"),
                serde_json::to_string(&load).expect("serde")
            )
        );
        assert!(decoded.to_string().contains(r#"name: "motor", cpu_percent: 0.1"#), "{decoded}");
    }

    #[test]
    fn too_few_bytes_are_refused_and_a_lying_schema_never_panics() {
        let e = Tick::schema().decode(&[0u8; 8]).expect_err("short");
        assert!(e.to_string().contains("16 bytes, the sample has 8"), "{e}");
        // a schema from another process may claim anything
        let lying = Schema {
            type_name: "x".into(),
            size: 8,
            align: 8,
            kind: Kind::Array {
                len: usize::MAX,
                element: Box::new(Schema {
                    type_name: "f64".into(),
                    size: 0,
                    align: 8,
                    kind: Kind::Primitive { primitive: Primitive::F64 },
                }),
            },
        };
        assert_eq!(lying.decode(&[0u8; 8]).expect("decodes"), Value::Array(vec![]));
        let short_field = Schema {
            type_name: "y".into(),
            size: 4,
            align: 4,
            kind: Kind::Struct { fields: vec![Field { name: "a".into(), offset: usize::MAX, schema: f64::schema() }] },
        };
        assert_eq!(short_field.decode(&[1u8; 4]).expect("decodes"), Value::Struct(vec![]));
        let string = Schema { type_name: "s".into(), size: 6, align: 4, kind: Kind::String { capacity: 1 << 40 } };
        assert_eq!(string.decode(&[200, 0, 0, 0, b'h', b'i']).expect("decodes"), Value::String("hi".into()));
    }

    /// A schema from another process is read only so deep: nested past
    /// [`MAX_DECODE_DEPTH`] it is refused with an error, not by recursing
    /// until the stack overflows; within it, it round-trips.
    #[test]
    fn deserialising_is_bounded_in_depth() {
        let nest = |levels: usize| {
            let mut s = u8::schema();
            for _ in 0..levels {
                s = Schema {
                    type_name: format!("[{}; 1]", s.type_name),
                    size: 1,
                    align: 1,
                    kind: Kind::Array { len: 1, element: Box::new(s) },
                };
            }
            s
        };
        let ok = nest(MAX_DECODE_DEPTH - 1);
        let bytes = postcard::to_allocvec(&ok).expect("encodes");
        assert_eq!(postcard::from_bytes::<Schema>(&bytes).expect("within the bound"), ok);
        let deep = postcard::to_allocvec(&nest(MAX_DECODE_DEPTH + 5)).expect("encodes");
        assert!(postcard::from_bytes::<Schema>(&deep).is_err(), "refused past the bound");
        // the depth count is left as it was, errors and all
        assert_eq!(postcard::from_bytes::<Schema>(&bytes).expect("reads again"), ok);
    }

    /// The human form keeps a float a float (issue 46: `20.0` printed as `20`).
    #[test]
    fn floats_print_as_floats() {
        let v = Value::Struct(vec![
            ("a".into(), Value::F32(20.0)),
            ("b".into(), Value::Float(-2.0)),
            ("c".into(), Value::F32(0.25)),
            ("n".into(), Value::Unsigned(20)),
        ]);
        assert_eq!(v.to_string(), "{ a: 20.0, b: -2.0, c: 0.25, n: 20 }");
    }

    /// A compact JSON-ish rendering for assertions (shm-schemas has no serde_json).
    fn serde_json_like(v: &Value) -> String {
        match v {
            Value::Bool(b) => b.to_string(),
            Value::Unsigned(u) => u.to_string(),
            Value::Signed(i) => i.to_string(),
            Value::Float(f) => f.to_string(),
            Value::F32(f) => f.to_string(),
            Value::String(s) => format!("{s:?}"),
            Value::Array(a) => format!("[{}]", a.iter().map(serde_json_like).collect::<Vec<_>>().join(",")),
            Value::Struct(f) => {
                format!(
                    "{{{}}}",
                    f.iter().map(|(k, v)| format!("{k:?}:{}", serde_json_like(v))).collect::<Vec<_>>().join(",")
                )
            }
        }
    }
}
