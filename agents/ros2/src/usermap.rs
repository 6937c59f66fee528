//! A nerve payload of any layout (a user's own type, declared in the
//! configuration's `[[type]]`, or a built-in one) published as a vendored
//! ROS message, field by field as its `[[publish]]`'s `fields` table says:
//! `"ROS field" = "nerve field"`, dotted paths on both sides.
//!
//! Everything is checked when the configuration is read, before anything
//! starts ([`UserMap::new`]): a ROS field or a nerve field that does not
//! exist, or one whose value cannot be carried by the other's type (a
//! float into an integer, an `int64` into an `int32`, an array of another
//! length), is refused with the field's line in the file. Without `fields`,
//! every field of the nerve type goes to the ROS field of the same name,
//! and a nerve field with no such ROS field is refused.
//!
//! ROS fields that nothing is mapped to are zero, empty or `false`; a
//! `std_msgs/Header`'s `stamp` is the sample's time and its `frame_id`
//! the `[[publish]]`'s `frame_id`, unless mapped. Each sample is then
//! written as CDR from a plan made once ([`UserMap::encode`]).

use crate::cdr::{CdrError, Writer};
use crate::idl::{Arity, Base, MsgDef};
use crate::msgs::Time;
use shm_schemas::schema::{Field, Kind, Primitive, Schema};
use std::collections::BTreeMap;

/// The vendored ROS message types, for messages that name them.
fn vendored() -> String {
    crate::MSG_DEFINITIONS.iter().map(|(n, _)| *n).collect::<Vec<_>>().join(", ")
}

/// The definitions of `ros_type` and every message it uses, parsed from
/// the vendored text ([`crate::MSG_DEFINITIONS`]).
pub fn ros_definitions(ros_type: &str) -> Result<BTreeMap<String, MsgDef>, String> {
    let i = crate::MSG_DEFINITIONS
        .binary_search_by(|(n, _)| (*n).cmp(ros_type))
        .map_err(|_| format!("{ros_type} is not a vendored ROS message (agents/ros2/msg has {})", vendored()))?;
    let text = crate::MSG_DEFINITIONS[i].1;
    let mut defs = BTreeMap::new();
    let sep = "=".repeat(80);
    for (k, part) in text.split(&format!("{sep}\n")).enumerate() {
        let (name, body) = if k == 0 {
            (ros_type.to_owned(), part)
        } else {
            let (first, body) = part.split_once('\n').unwrap_or((part, ""));
            let short = first.strip_prefix("MSG: ").unwrap_or(first);
            let (pkg, msg) = short.split_once('/').unwrap_or(("", short));
            (format!("{pkg}/msg/{msg}"), body)
        };
        let (pkg, msg) = name.split_once("/msg/").unwrap_or(("", &name));
        let def = crate::idl::parse_msg(pkg, msg, body).map_err(|e| e.to_string())?;
        defs.insert(name, def);
    }
    Ok(defs)
}

/// A field type of `[[type]]`: `u8` ... `f64`, `bool`, `[T; N]`, or the
/// name of a built-in payload or of a `[[type]]` declared before.
fn field_schema(t: &str, declared: &BTreeMap<String, Schema>) -> Result<Schema, String> {
    let t = t.trim();
    let prim = |p: Primitive, size: usize| Schema {
        type_name: t.to_owned(),
        size,
        align: size,
        kind: Kind::Primitive { primitive: p },
    };
    Ok(match t {
        "u8" => prim(Primitive::U8, 1),
        "u16" => prim(Primitive::U16, 2),
        "u32" => prim(Primitive::U32, 4),
        "u64" => prim(Primitive::U64, 8),
        "i8" => prim(Primitive::I8, 1),
        "i16" => prim(Primitive::I16, 2),
        "i32" => prim(Primitive::I32, 4),
        "i64" => prim(Primitive::I64, 8),
        "f32" => prim(Primitive::F32, 4),
        "f64" => prim(Primitive::F64, 8),
        "bool" => prim(Primitive::Bool, 1),
        _ if t.starts_with('[') && t.ends_with(']') => {
            let inner = &t[1..t.len() - 1];
            let (elem, n) = inner.rsplit_once(';').ok_or_else(|| format!("{t:?}: an array is [TYPE; N]"))?;
            let len: usize = n.trim().parse().map_err(|_| format!("{t:?}: {:?} is not an array length", n.trim()))?;
            let element = field_schema(elem, declared)?;
            let size = element.size.checked_mul(len).ok_or_else(|| format!("{t:?}: too large"))?;
            Schema {
                type_name: format!("[{}; {len}]", element.type_name),
                size,
                align: element.align,
                kind: Kind::Array { len, element: Box::new(element) },
            }
        }
        _ => match declared.get(t).cloned().or_else(|| shm_schemas::schema::built_in_named(t)) {
            Some(s) => s,
            None => {
                return Err(format!(
                    "{t:?} is no field type: u8, u16, u32, u64, i8, i16, i32, i64, f32, f64, bool, [TYPE; N], \
                     a built-in payload (nerve::...) or a [[type]] declared above"
                ));
            }
        },
    })
}

/// The layout of a `#[repr(C)]` struct of `fields` (name, type) in order,
/// as the Rust compiler lays it out: each field at the next multiple of its
/// alignment, the size a multiple of the largest one (what the Python
/// SDK's `nerve.payload` computes, so that the schemas are equal).
///
/// Implicit padding is refused, as `#[derive(Payload)]` refuses it, so
/// that a Rust agent can declare the same type: every gap, before a field
/// or after the last one, is named (offset and size) with the `_pad` field
/// that fills it. Fields named `_pad…` of type `[u8; N]` are explicit
/// padding: they take their bytes but stay out of the schema, as the
/// derive leaves them out (the fingerprint is that of the padded layout).
pub fn struct_layout(
    type_name: &str,
    fields: &[(String, String)],
    declared: &BTreeMap<String, Schema>,
) -> Result<Schema, String> {
    let round = |at: usize, align: usize| at.div_ceil(align).checked_mul(align);
    let too_large = || format!("{type_name}: a layout too large");
    let (mut at, mut align) = (0usize, 1usize);
    let mut laid = Vec::with_capacity(fields.len());
    for (name, t) in fields {
        let schema = field_schema(t, declared).map_err(|e| format!("field {name:?}: {e}"))?;
        let offset = round(at, schema.align.max(1)).ok_or_else(too_large)?;
        if offset != at {
            let gap = offset - at;
            return Err(format!(
                "{gap} bytes of implicit padding at offset {at}, before field {name:?} (at {offset}): \
                 a Rust agent's #[derive(Payload)] refuses padding, so add a field [\"_pad{at}\", \"[u8; {gap}]\"] \
                 before {name:?}"
            ));
        }
        at = offset.checked_add(schema.size).ok_or_else(too_large)?;
        align = align.max(schema.align);
        if name.starts_with("_pad") {
            let bytes = matches!(&schema.kind, Kind::Array { element, .. }
                if matches!(element.kind, Kind::Primitive { primitive: Primitive::U8 }));
            if !bytes {
                return Err(format!("field {name:?}: a _pad field is explicit padding: its type must be [u8; N]"));
            }
            continue;
        }
        laid.push(Field { name: name.clone(), offset, schema });
    }
    let size = round(at, align).ok_or_else(too_large)?;
    if size != at {
        let gap = size - at;
        return Err(format!(
            "{gap} bytes of implicit padding at offset {at}, after the last field (the size is \
             rounded up to {size}, a multiple of the alignment {align}): a Rust agent's #[derive(Payload)] refuses \
             padding, so add a last field [\"_pad{at}\", \"[u8; {gap}]\"]"
        ));
    }
    let s = Schema { type_name: type_name.to_owned(), size, align, kind: Kind::Struct { fields: laid } };
    s.validate().map_err(|e| format!("{type_name}: {e}"))?;
    Ok(s)
}

/// Where one value of the ROS message comes from.
#[derive(Debug, Clone, PartialEq, Eq)]
enum Src {
    /// zero, empty, false
    Zero,
    /// a primitive of the sample at this offset
    At(usize, Primitive),
    /// the sample's time: seconds (`header.stamp.sec`)
    StampSec,
    /// the sample's time: nanoseconds (`header.stamp.nanosec`)
    StampNanosec,
}

/// One step of writing the message.
#[derive(Debug, Clone, PartialEq, Eq)]
enum Op {
    /// a number or a bool
    Prim(Base, Src),
    /// a string: empty, the `[[publish]]`'s frame_id, or a nerve string
    Str(StrSrc),
    /// a sequence's count
    Count(usize),
}

#[derive(Debug, Clone, PartialEq, Eq)]
enum StrSrc {
    Empty,
    Frame,
    /// a fixed string (u32 length, then at most `capacity` bytes) at this offset
    At(usize, usize),
}

/// A leaf of a ROS message a nerve field may be mapped to: a number, a
/// bool, a string, or an array or sequence of numbers.
#[derive(Debug, Clone)]
pub(crate) struct Leaf {
    pub(crate) base: Base,
    pub(crate) arity: Arity,
}

fn base_name(b: &Base) -> String {
    match b {
        Base::Bool => "bool".into(),
        Base::Byte => "byte".into(),
        Base::Char => "char".into(),
        Base::Float32 => "float32".into(),
        Base::Float64 => "float64".into(),
        Base::Int8 => "int8".into(),
        Base::Uint8 => "uint8".into(),
        Base::Int16 => "int16".into(),
        Base::Uint16 => "uint16".into(),
        Base::Int32 => "int32".into(),
        Base::Uint32 => "uint32".into(),
        Base::Int64 => "int64".into(),
        Base::Uint64 => "uint64".into(),
        Base::String(_) => "string".into(),
        Base::WString(_) => "wstring".into(),
        Base::Nested(n) => n.clone(),
    }
}

pub(crate) fn leaf_name(l: &Leaf) -> String {
    let b = base_name(&l.base);
    match l.arity {
        Arity::Single => b,
        Arity::Array(n) => format!("{b}[{n}]"),
        Arity::Bounded(n) => format!("{b}[<={n}]"),
        Arity::Unbounded => format!("{b}[]"),
    }
}

/// Every leaf field of ROS type `ty` (nested paths `a.b`), by path.
pub(crate) fn ros_leaves(ty: &str, defs: &BTreeMap<String, MsgDef>) -> BTreeMap<String, Leaf> {
    let mut all = BTreeMap::new();
    leaves(ty, defs, "", &mut all);
    all
}

/// `path (type), ...` of `leaves`: what a mapping error lists on the ROS side.
pub(crate) fn leaf_list(leaves: &BTreeMap<String, Leaf>) -> String {
    leaves.iter().map(|(p, l)| format!("{p} ({})", leaf_name(l))).collect::<Vec<_>>().join(", ")
}

/// `path (type), ...` of a nerve type's fields outside arrays: what a
/// mapping error lists on the nerve side.
pub(crate) fn nerve_fields(schema: &Schema) -> String {
    let mut out = Vec::new();
    schema.visit_fields(|p, s, _| {
        if !p.contains("<i>") {
            out.push(format!("{p} ({})", s.type_name));
        }
    });
    out.join(", ")
}

/// Every leaf of `ty` by its dotted path.
pub(crate) fn leaves(ty: &str, defs: &BTreeMap<String, MsgDef>, prefix: &str, out: &mut BTreeMap<String, Leaf>) {
    let Some(def) = defs.get(ty) else { return };
    for f in &def.fields {
        let path = if prefix.is_empty() { f.name.clone() } else { format!("{prefix}.{}", f.name) };
        match (&f.base, f.arity) {
            (Base::Nested(n), Arity::Single) => leaves(n, defs, &path, out),
            (Base::Nested(_), _) | (Base::WString(_), _) => {}
            (Base::String(_), Arity::Single) => {
                out.insert(path, Leaf { base: f.base.clone(), arity: f.arity });
            }
            (Base::String(_), _) => {}
            _ => {
                out.insert(path, Leaf { base: f.base.clone(), arity: f.arity });
            }
        }
    }
}

/// The range of values of a ROS integer: (min, max), as i128.
pub(crate) fn int_range(b: &Base) -> Option<(i128, i128)> {
    Some(match b {
        Base::Int8 => (i8::MIN.into(), i8::MAX.into()),
        Base::Uint8 | Base::Byte | Base::Char => (0, u8::MAX.into()),
        Base::Int16 => (i16::MIN.into(), i16::MAX.into()),
        Base::Uint16 => (0, u16::MAX.into()),
        Base::Int32 => (i32::MIN.into(), i32::MAX.into()),
        Base::Uint32 => (0, u32::MAX.into()),
        Base::Int64 => (i64::MIN.into(), i64::MAX.into()),
        Base::Uint64 => (0, u64::MAX.into()),
        _ => return None,
    })
}

pub(crate) fn prim_range(p: Primitive) -> Option<(i128, i128)> {
    Some(match p {
        Primitive::U8 | Primitive::Bool => (0, u8::MAX.into()),
        Primitive::U16 => (0, u16::MAX.into()),
        Primitive::U32 => (0, u32::MAX.into()),
        Primitive::U64 => (0, u64::MAX.into()),
        Primitive::I8 => (i8::MIN.into(), i8::MAX.into()),
        Primitive::I16 => (i16::MIN.into(), i16::MAX.into()),
        Primitive::I32 => (i32::MIN.into(), i32::MAX.into()),
        Primitive::I64 => (i64::MIN.into(), i64::MAX.into()),
        Primitive::F32 | Primitive::F64 => return None,
    })
}

/// Whether a nerve primitive always fits a ROS primitive; why not if not.
fn fits(p: Primitive, b: &Base) -> Result<(), String> {
    match b {
        Base::Float32 | Base::Float64 => Ok(()),
        Base::Bool if matches!(p, Primitive::Bool | Primitive::U8) => Ok(()),
        Base::Bool => Err("a ROS bool takes a nerve bool or u8".into()),
        _ => match (prim_range(p), int_range(b)) {
            (Some((lo, hi)), Some((rlo, rhi))) if lo >= rlo && hi <= rhi => Ok(()),
            (Some(_), Some(_)) => Err("not every value of the nerve integer fits the ROS integer".into()),
            (None, Some(_)) => Err("a float does not go into a ROS integer".into()),
            _ => Err("no number goes there".into()),
        },
    }
}

pub(crate) fn prim_of(s: &Schema) -> Option<Primitive> {
    match s.kind {
        Kind::Primitive { primitive } => Some(primitive),
        _ => None,
    }
}

/// A `[[publish]]`'s field-by-field mapping, checked, with its plan.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct UserMap {
    /// the nerve layout the input is declared with
    pub schema: Schema,
    /// `pkg/msg/Name`
    pub ros_type: String,
    ops: Vec<Op>,
}

/// A field of the mapping that cannot be used: which one (its line in the
/// configuration is found from `key`) and why.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MapError {
    /// the ROS field of the entry (`None`: the mapping as a whole)
    pub key: Option<String>,
    /// what is wrong and what to write instead
    pub what: String,
}

impl UserMap {
    /// Checks `fields` (`ROS field -> nerve field`; `None`: every nerve
    /// field to the ROS field of its name) of `schema` into `ros_type`, and
    /// plans the writing.
    pub fn new(schema: Schema, ros_type: &str, fields: Option<&[(String, String)]>) -> Result<UserMap, MapError> {
        let whole = |what: String| MapError { key: None, what };
        let defs = ros_definitions(ros_type).map_err(whole)?;
        let all = ros_leaves(ros_type, &defs);
        let ros_list = || leaf_list(&all);
        let nerve_list = nerve_fields(&schema);
        let pairs: Vec<(String, String)> = match fields {
            Some(f) => f.to_vec(),
            None => match &schema.kind {
                Kind::Struct { fields } => fields.iter().map(|f| (f.name.clone(), f.name.clone())).collect(),
                _ => return Err(whole(format!("{} is not a struct: name its fields in `fields`", schema.type_name))),
            },
        };
        if pairs.is_empty() {
            return Err(whole(format!("no field is mapped; {ros_type} has {}", ros_list())));
        }
        let mut mapped: BTreeMap<String, (usize, Schema)> = BTreeMap::new();
        for (ros, nerve) in &pairs {
            let err = |what: String| MapError { key: Some(ros.clone()), what };
            let (offset, ns) = schema.field(nerve).ok_or_else(|| {
                err(if fields.is_none() {
                    format!(
                        "{} field {nerve:?} has no counterpart in {ros_type} (no field of that name; map it in \
                         `fields`, as \"ROS field\" = \"nerve field\"); {ros_type} has {}",
                        schema.type_name,
                        ros_list()
                    )
                } else {
                    format!("{} has no field {nerve:?}; it has {nerve_list}", schema.type_name)
                })
            })?;
            let leaf = all.get(ros).ok_or_else(|| {
                err(if fields.is_none() {
                    format!(
                        "{} field {nerve:?} has no counterpart in {ros_type} (no field of that name; map it in \
                         `fields`, as \"ROS field\" = \"nerve field\"); {ros_type} has {}",
                        schema.type_name,
                        ros_list()
                    )
                } else {
                    format!("{ros_type} has no field {ros:?} that a nerve field can fill; it has {}", ros_list())
                })
            })?;
            let mismatch = |why: String| {
                err(format!(
                    "{ros_type} field {ros} ({}) cannot take {} field {nerve} ({}): {why}",
                    leaf_name(leaf),
                    schema.type_name,
                    ns.type_name
                ))
            };
            match (&leaf.base, leaf.arity, &ns.kind) {
                (Base::String(bound), Arity::Single, Kind::String { capacity }) => {
                    if let Some(b) = bound
                        && (*capacity as u64) > *b
                    {
                        return Err(mismatch(format!("up to {capacity} bytes into a string<={b}")));
                    }
                }
                (Base::String(_), _, _) => return Err(mismatch("a string takes a nerve string".into())),
                (b, Arity::Single, Kind::Primitive { primitive }) => fits(*primitive, b).map_err(mismatch)?,
                (b, arity, Kind::Array { len, element }) if arity != Arity::Single => {
                    let p = prim_of(element).ok_or_else(|| mismatch("an array of numbers takes numbers".into()))?;
                    fits(p, b).map_err(mismatch)?;
                    match arity {
                        Arity::Array(n) if n != *len as u64 => {
                            return Err(mismatch(format!("{len} values for {n} places")));
                        }
                        Arity::Bounded(n) if *len as u64 > n => {
                            return Err(mismatch(format!("{len} values for at most {n}")));
                        }
                        _ => {}
                    }
                }
                (_, Arity::Single, _) => return Err(mismatch("one value takes one number or bool".into())),
                _ => return Err(mismatch("an array takes a nerve array of numbers".into())),
            }
            if mapped.insert(ros.clone(), (offset, ns.clone())).is_some() {
                return Err(err(format!("{ros} is mapped twice")));
            }
        }
        let mut ops = Vec::new();
        plan(ros_type, &defs, "", false, &mapped, &mut ops);
        Ok(UserMap { schema, ros_type: ros_type.to_owned(), ops })
    }

    /// One sample's `bytes` as the CDR of the ROS message, stamped `stamp`,
    /// in frame `frame` (a `std_msgs/Header`'s fields not mapped).
    pub fn encode(&self, bytes: &[u8], stamp: Time, frame: &str) -> Result<Vec<u8>, CdrError> {
        if bytes.len() < self.schema.size {
            return Err(CdrError::Short { need: self.schema.size, have: bytes.len() });
        }
        let mut w = Writer::with_capacity(self.schema.size.saturating_mul(2));
        for op in &self.ops {
            match op {
                Op::Count(n) => w.count("sequence", *n)?,
                Op::Str(StrSrc::Empty) => w.string("")?,
                Op::Str(StrSrc::Frame) => w.string(frame)?,
                Op::Str(StrSrc::At(at, cap)) => {
                    let len = read_num(bytes, *at, Primitive::U32).as_int().clamp(0, *cap as i128) as usize;
                    let raw = bytes.get(at + 4..at + 4 + len).unwrap_or_default();
                    w.string(&String::from_utf8_lossy(raw))?;
                }
                Op::Prim(b, src) => {
                    let n = match src {
                        Src::Zero => Num::I(0),
                        Src::StampSec => Num::I(stamp.sec.into()),
                        Src::StampNanosec => Num::I(stamp.nanosec.into()),
                        Src::At(at, p) => read_num(bytes, *at, *p),
                    };
                    write_num(&mut w, b, n);
                }
            }
        }
        Ok(w.finish())
    }
}

/// Appends the steps that write message `ty` at `prefix`; `in_header`:
/// inside a `std_msgs/Header` (its stamp and frame_id default to the
/// sample's time and the `[[publish]]`'s frame).
fn plan(
    ty: &str,
    defs: &BTreeMap<String, MsgDef>,
    prefix: &str,
    in_header: bool,
    mapped: &BTreeMap<String, (usize, Schema)>,
    ops: &mut Vec<Op>,
) {
    let Some(def) = defs.get(ty) else { return };
    let header = ty == "std_msgs/msg/Header";
    for f in &def.fields {
        let path = if prefix.is_empty() { f.name.clone() } else { format!("{prefix}.{}", f.name) };
        let m = mapped.get(&path);
        match (&f.base, f.arity) {
            (Base::Nested(n), Arity::Single) => {
                let stamp = (in_header || header) && n == "builtin_interfaces/msg/Time";
                plan(n, defs, &path, stamp, mapped, ops)
            }
            (Base::Nested(n), Arity::Array(k)) => {
                for i in 0..k {
                    plan(n, defs, &format!("{path}.{i}"), false, mapped, ops);
                }
            }
            (Base::String(_), Arity::Single) => ops.push(Op::Str(match m {
                Some((at, s)) => match s.kind {
                    Kind::String { capacity } => StrSrc::At(*at, capacity),
                    _ => StrSrc::Empty,
                },
                None if header && f.name == "frame_id" => StrSrc::Frame,
                None => StrSrc::Empty,
            })),
            (Base::String(_) | Base::WString(_), Arity::Array(k)) => {
                for _ in 0..k {
                    ops.push(Op::Str(StrSrc::Empty));
                }
            }
            (_, Arity::Single) => {
                let src = match m {
                    Some((at, s)) => prim_of(s).map_or(Src::Zero, |p| Src::At(*at, p)),
                    None if in_header && f.name == "sec" => Src::StampSec,
                    None if in_header && f.name == "nanosec" => Src::StampNanosec,
                    None => Src::Zero,
                };
                ops.push(Op::Prim(f.base.clone(), src));
            }
            (_, Arity::Array(k)) => {
                let elems = array_srcs(m, k as usize);
                ops.extend(elems.into_iter().map(|s| Op::Prim(f.base.clone(), s)));
            }
            (Base::Nested(_) | Base::String(_) | Base::WString(_), _) => ops.push(Op::Count(0)),
            (_, _) => {
                let n = m.map_or(0, |(_, s)| if let Kind::Array { len, .. } = s.kind { len } else { 0 });
                ops.push(Op::Count(n));
                ops.extend(array_srcs(m, n).into_iter().map(|s| Op::Prim(f.base.clone(), s)));
            }
        }
    }
}

/// The sources of `n` elements of a mapped nerve array (zeros if unmapped).
fn array_srcs(m: Option<&(usize, Schema)>, n: usize) -> Vec<Src> {
    match m {
        Some((at, Schema { kind: Kind::Array { element, .. }, .. })) => match prim_of(element) {
            Some(p) => (0..n).map(|i| Src::At(at + i * element.size, p)).collect(),
            None => vec![Src::Zero; n],
        },
        _ => vec![Src::Zero; n],
    }
}

/// A number read from a sample.
#[derive(Debug, Clone, Copy)]
enum Num {
    I(i128),
    F(f64),
}

impl Num {
    fn as_int(self) -> i128 {
        match self {
            Num::I(i) => i,
            // refused when the mapping is checked; kept total anyway
            Num::F(f) => f as i128,
        }
    }
    fn as_f64(self) -> f64 {
        match self {
            Num::I(i) => i as f64,
            Num::F(f) => f,
        }
    }
}

fn read_num(bytes: &[u8], at: usize, p: Primitive) -> Num {
    fn le<const N: usize>(b: &[u8], at: usize) -> [u8; N] {
        let mut a = [0u8; N];
        if let Some(s) = at.checked_add(N).and_then(|end| b.get(at..end)) {
            a.copy_from_slice(s);
        }
        a
    }
    match p {
        Primitive::U8 | Primitive::Bool => Num::I(le::<1>(bytes, at)[0].into()),
        Primitive::I8 => Num::I(i8::from_le_bytes(le(bytes, at)).into()),
        Primitive::U16 => Num::I(u16::from_le_bytes(le(bytes, at)).into()),
        Primitive::I16 => Num::I(i16::from_le_bytes(le(bytes, at)).into()),
        Primitive::U32 => Num::I(u32::from_le_bytes(le(bytes, at)).into()),
        Primitive::I32 => Num::I(i32::from_le_bytes(le(bytes, at)).into()),
        Primitive::U64 => Num::I(u64::from_le_bytes(le(bytes, at)).into()),
        Primitive::I64 => Num::I(i64::from_le_bytes(le(bytes, at)).into()),
        Primitive::F32 => Num::F(f32::from_le_bytes(le(bytes, at)).into()),
        Primitive::F64 => Num::F(f64::from_le_bytes(le(bytes, at))),
    }
}

fn write_num(w: &mut Writer, b: &Base, n: Num) {
    // the ranges were checked with the mapping: these conversions are exact
    let i = n.as_int();
    match b {
        Base::Float32 => w.f32(n.as_f64() as f32),
        Base::Float64 => w.f64(n.as_f64()),
        Base::Bool => w.bool(i != 0),
        Base::Byte | Base::Char | Base::Uint8 => w.u8(u8::try_from(i).unwrap_or_default()),
        Base::Int8 => w.i8(i8::try_from(i).unwrap_or_default()),
        Base::Int16 => w.i16(i16::try_from(i).unwrap_or_default()),
        Base::Uint16 => w.u16(u16::try_from(i).unwrap_or_default()),
        Base::Int32 => w.i32(i32::try_from(i).unwrap_or_default()),
        Base::Uint32 => w.u32(u32::try_from(i).unwrap_or_default()),
        Base::Int64 => w.i64(i64::try_from(i).unwrap_or_default()),
        Base::Uint64 => w.u64(u64::try_from(i).unwrap_or_default()),
        Base::String(_) | Base::WString(_) | Base::Nested(_) => {}
    }
}

#[cfg(test)]
#[path = "usermap_tests.rs"]
mod tests;
