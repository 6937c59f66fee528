//! A vendored ROS message received as a nerve payload of any layout (a
//! user's own type, declared in the configuration's `[[type]]`, or a
//! built-in one), field by field as its `[[subscribe]]`'s `fields` table
//! says: `"nerve field" = "ROS field"`, dotted paths on both sides. In
//! both directions the key is the field being filled and the value the
//! field it is filled from (`[[publish]]`: `"ROS field" = "nerve field"`).
//!
//! Everything that can be known before a message arrives is checked when
//! the configuration is read ([`UserSub::new`]): a field that does not
//! exist on either side, and a ROS value the nerve field's type cannot
//! always carry (a float into an integer, an `int32` into a `u16`, a number
//! into a `bool`, a fixed ROS array into a nerve array of another length, a
//! `string<=N` into a shorter nerve string), refused with the entry's line.
//! Without `fields`, every leaf of the nerve type (nested paths included)
//! is filled from the ROS field of the same path, and one without such a
//! field is refused.
//!
//! What only the message tells is checked as each arrives
//! ([`UserSub::decode`]): a finite `float64` beyond `f32`'s range, a
//! sequence longer than the nerve array, a string longer than the nerve
//! string. Such a message is refused whole and counted (the agent's
//! `refused/TOPIC` figure), never wrapped or cut. A shorter sequence fills
//! the front of the nerve array, the rest is zero. Nerve fields nothing is
//! mapped to are zero. A `float64` into an `f32` rounds to the nearest
//! `f32`, an integer into a float to the nearest float, as a cast does.
//!
//! The sample is the nerve type's `#[repr(C)]` layout
//! ([`crate::usermap::struct_layout`]), as a Rust or Python agent of that
//! type reads it, decoded from the CDR by a plan made once.

use crate::cdr::{CdrError, Reader};
use crate::idl::{Arity, Base, MsgDef};
use crate::usermap::{
    Leaf, MapError, int_range, leaf_list, leaf_name, nerve_fields, prim_of, prim_range, ros_definitions, ros_leaves,
};
use shm_schemas::schema::{Kind, Primitive, Schema};
use std::collections::BTreeMap;

/// Where a ROS value goes in the sample.
#[derive(Debug, Clone, PartialEq, Eq)]
enum To {
    /// a number or bool at this offset
    Prim(usize, Primitive),
    /// a nerve string (u32 length, then at most `capacity` bytes) at this offset
    Str(usize, usize),
    /// a nerve array of `len` numbers of `size` bytes at this offset
    Array { at: usize, element: Primitive, size: usize, len: usize },
}

/// One destination and the mapping entry it comes from (for messages).
#[derive(Debug, Clone, PartialEq, Eq)]
struct Dest {
    to: To,
    /// index into [`UserSub::entries`]
    entry: usize,
}

/// One step of reading the message.
#[derive(Debug, Clone, PartialEq, Eq)]
enum Op {
    /// one number or bool
    Prim(Base, Vec<Dest>),
    /// one string
    Str(Vec<Dest>),
    /// numbers: a fixed array of `Some(k)`, or a sequence (its count first)
    Nums { base: Base, fixed: Option<usize>, to: Vec<Dest> },
    /// messages or strings repeated, read and not kept: a fixed array of
    /// `Some(k)`, or a sequence (its count first)
    Repeat { fixed: Option<usize>, body: Vec<Op> },
}

/// A `[[subscribe]]`'s field-by-field mapping, checked, with its plan.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct UserSub {
    /// the nerve layout the output is declared with
    pub schema: Schema,
    /// `pkg/msg/Name`
    pub ros_type: String,
    /// (nerve field, ROS field) of each entry
    entries: Vec<(String, String)>,
    ops: Vec<Op>,
}

/// Why one message could not be delivered.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SubError {
    /// Not the message's CDR (another type, cut short, malformed).
    #[error("not a {ros_type}: {source}")]
    Cdr {
        /// the subscription's type
        ros_type: String,
        /// what the reader found
        #[source]
        source: CdrError,
    },
    /// A value the nerve field cannot carry: the message is refused whole.
    #[error("{ros_type} field {ros} = {value} does not fit {nerve}: {why}; the message is refused")]
    DoesNotFit {
        /// the subscription's type
        ros_type: String,
        /// the ROS field
        ros: String,
        /// its value, as text
        value: String,
        /// the nerve field and its type
        nerve: String,
        /// what is wrong
        why: &'static str,
    },
}

/// A number read from the message.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Num {
    I(i128),
    F(f64),
}

impl std::fmt::Display for Num {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Num::I(i) => write!(f, "{i}"),
            // 1e300, not 301 digits
            Num::F(x) => write!(f, "{x:?}"),
        }
    }
}

fn prim_name(p: Primitive) -> &'static str {
    match p {
        Primitive::U8 => "u8",
        Primitive::U16 => "u16",
        Primitive::U32 => "u32",
        Primitive::U64 => "u64",
        Primitive::I8 => "i8",
        Primitive::I16 => "i16",
        Primitive::I32 => "i32",
        Primitive::I64 => "i64",
        Primitive::F32 => "f32",
        Primitive::F64 => "f64",
        Primitive::Bool => "bool",
    }
}

/// Whether a nerve primitive can carry every value of a ROS primitive (a
/// `float64` into an `f32`: every value in `f32`'s range, checked as each
/// message arrives); why not if not.
fn takes(p: Primitive, b: &Base) -> Result<(), String> {
    let float = matches!(p, Primitive::F32 | Primitive::F64);
    match b {
        Base::Float32 | Base::Float64 if float => Ok(()),
        Base::Float32 | Base::Float64 => Err("a ROS float does not go into a nerve integer or bool".into()),
        Base::Bool => Ok(()),
        _ if p == Primitive::Bool => Err("a nerve bool takes a ROS bool".into()),
        _ if float => Ok(()),
        _ => match (int_range(b), prim_range(p)) {
            (Some((lo, hi)), Some((nlo, nhi))) if lo >= nlo && hi <= nhi => Ok(()),
            (Some(_), Some(_)) => Err(format!(
                "not every value of the ROS integer fits a nerve {}; declare a wider nerve type",
                prim_name(p)
            )),
            _ => Err("no number goes there".into()),
        },
    }
}

/// Where a ROS leaf may go: checks the pair and says where.
fn dest_of(leaf: &Leaf, at: usize, ns: &Schema) -> Result<To, String> {
    match (&leaf.base, leaf.arity, &ns.kind) {
        (Base::String(bound), Arity::Single, Kind::String { capacity }) => {
            if let Some(b) = bound
                && *b > *capacity as u64
            {
                return Err(format!("a string<={b} into {capacity} bytes"));
            }
            Ok(To::Str(at, *capacity))
        }
        (Base::String(_), _, _) => Err("a ROS string goes into a nerve string".into()),
        (_, _, Kind::String { .. }) => Err("a nerve string takes a ROS string".into()),
        (b, Arity::Single, Kind::Primitive { primitive }) => takes(*primitive, b).map(|()| To::Prim(at, *primitive)),
        (b, arity, Kind::Array { len, element }) if arity != Arity::Single => {
            let p = prim_of(element).ok_or("a ROS array goes into a nerve array of numbers")?;
            takes(p, b)?;
            match arity {
                Arity::Array(n) if n != *len as u64 => return Err(format!("{n} values into {len} places")),
                Arity::Bounded(n) if n > *len as u64 => return Err(format!("up to {n} values into {len} places")),
                _ => {}
            }
            Ok(To::Array { at, element: p, size: element.size, len: *len })
        }
        (_, Arity::Single, Kind::Struct { .. }) => {
            Err("a nerve struct is filled field by field: map each of its fields (e.g. \"pose.x\")".into())
        }
        (_, Arity::Single, _) => Err("one value goes into one number or bool".into()),
        _ => Err("a ROS array goes into a nerve array of numbers".into()),
    }
}

/// The leaves of a nerve type a ROS field can fill, by path: numbers,
/// bools, strings and arrays of numbers; structs are entered; `bad` gets
/// the first one that cannot be filled at all (an array of structs).
fn nerve_leaves(schema: &Schema) -> (Vec<String>, Option<String>) {
    let (mut out, mut bad) = (Vec::new(), None);
    schema.visit_fields(|p, s, _| {
        if p.contains("<i>") {
            return;
        }
        match &s.kind {
            Kind::Primitive { .. } | Kind::String { .. } => out.push(p.to_owned()),
            Kind::Array { element, .. } if prim_of(element).is_some() => out.push(p.to_owned()),
            Kind::Struct { .. } => {}
            _ => {
                bad.get_or_insert_with(|| p.to_owned());
            }
        }
    });
    (out, bad)
}

impl UserSub {
    /// Checks `fields` (`nerve field -> ROS field`; `None`: every leaf of
    /// the nerve type from the ROS field of its path) of `ros_type` into
    /// `schema`, and plans the reading. A refusal's `key` is the nerve
    /// field of the entry.
    pub fn new(schema: Schema, ros_type: &str, fields: Option<&[(String, String)]>) -> Result<UserSub, MapError> {
        let whole = |what: String| MapError { key: None, what };
        let defs = ros_definitions(ros_type).map_err(whole)?;
        if let Some(w) = defs.values().find(|d| d.fields.iter().any(|f| matches!(f.base, Base::WString(_)))) {
            return Err(whole(format!("{ros_type} uses {}, which has a wstring: not supported", w.type_name)));
        }
        let all = ros_leaves(ros_type, &defs);
        let ros_list = || leaf_list(&all);
        let nerve_list = nerve_fields(&schema);
        let entries: Vec<(String, String)> = match fields {
            Some(f) => f.to_vec(),
            None if matches!(schema.kind, Kind::Struct { .. }) => {
                let (paths, bad) = nerve_leaves(&schema);
                if let Some(b) = bad {
                    return Err(MapError {
                        key: Some(b.clone()),
                        what: format!(
                            "{} field {b:?} is an array of structs, which no ROS field fills by name; map the \
                             fields in `fields`, as \"nerve field\" = \"ROS field\"",
                            schema.type_name
                        ),
                    });
                }
                paths.into_iter().map(|p| (p.clone(), p)).collect()
            }
            None => return Err(whole(format!("{} is not a struct: name its fields in `fields`", schema.type_name))),
        };
        if entries.is_empty() {
            return Err(whole(format!("no field is mapped; {ros_type} has {}", ros_list())));
        }
        let mut by_ros: BTreeMap<String, Vec<Dest>> = BTreeMap::new();
        for (i, (nerve, ros)) in entries.iter().enumerate() {
            let err = |what: String| MapError { key: Some(nerve.clone()), what };
            let no_counterpart = || {
                format!(
                    "{} field {nerve:?} has no counterpart in {ros_type} (no field of that path; map it in \
                     `fields`, as \"nerve field\" = \"ROS field\"); {ros_type} has {}",
                    schema.type_name,
                    ros_list()
                )
            };
            let (at, ns) = schema.field(nerve).ok_or_else(|| {
                err(if fields.is_none() {
                    no_counterpart()
                } else {
                    format!("{} has no field {nerve:?}; it has {nerve_list}", schema.type_name)
                })
            })?;
            let leaf = all.get(ros).ok_or_else(|| {
                err(if fields.is_none() {
                    no_counterpart()
                } else {
                    format!("{ros_type} has no field {ros:?} that can fill a nerve field; it has {}", ros_list())
                })
            })?;
            let to = dest_of(leaf, at, ns).map_err(|why| {
                err(format!(
                    "{} field {nerve} ({}) cannot take {ros_type} field {ros} ({}): {why}",
                    schema.type_name,
                    ns.type_name,
                    leaf_name(leaf)
                ))
            })?;
            by_ros.entry(ros.clone()).or_default().push(Dest { to, entry: i });
        }
        let mut ops = Vec::new();
        plan(ros_type, &defs, "", &by_ros, &mut ops);
        Ok(UserSub { schema, ros_type: ros_type.to_owned(), entries, ops })
    }

    /// One message's CDR as a sample of the nerve layout (its size; fields
    /// nothing is mapped to zero), or why it is refused.
    pub fn decode(&self, cdr: &[u8]) -> Result<Vec<u8>, SubError> {
        let mut out = vec![0u8; self.schema.size];
        let mut r = Reader::new(cdr).map_err(|e| self.cdr(e))?;
        self.run(&self.ops, &mut r, &mut out)?;
        r.finish().map_err(|e| self.cdr(e))?;
        Ok(out)
    }

    fn cdr(&self, source: CdrError) -> SubError {
        SubError::Cdr { ros_type: self.ros_type.clone(), source }
    }

    fn misfit(&self, d: &Dest, value: String, why: &'static str) -> SubError {
        let (nerve, ros) = self.entries.get(d.entry).cloned().unwrap_or_default();
        let ty = self.schema.field(&nerve).map_or_else(String::new, |(_, s)| s.type_name.clone());
        SubError::DoesNotFit { ros_type: self.ros_type.clone(), ros, value, nerve: format!("{nerve} ({ty})"), why }
    }

    fn run(&self, ops: &[Op], r: &mut Reader<'_>, out: &mut [u8]) -> Result<(), SubError> {
        for op in ops {
            match op {
                Op::Prim(b, to) => {
                    let n = read_num(r, b).map_err(|e| self.cdr(e))?;
                    for d in to {
                        if let To::Prim(at, p) = d.to {
                            put(out, at, p, n).map_err(|why| self.misfit(d, n.to_string(), why))?;
                        }
                    }
                }
                Op::Str(to) => {
                    let s = r.string().map_err(|e| self.cdr(e))?;
                    for d in to {
                        if let To::Str(at, cap) = d.to {
                            if s.len() > cap {
                                return Err(self.misfit(
                                    d,
                                    format!("{} bytes", s.len()),
                                    "longer than the nerve string",
                                ));
                            }
                            let len = u32::try_from(s.len()).unwrap_or(u32::MAX).to_le_bytes();
                            write(out, at, &len)
                                .and_then(|()| write(out, at.saturating_add(4), s.as_bytes()))
                                .map_err(|why| self.misfit(d, format!("{} bytes", s.len()), why))?;
                        }
                    }
                }
                Op::Nums { base, fixed, to } => {
                    let n = self.count(r, *fixed)?;
                    for d in to {
                        if let To::Array { len, .. } = d.to
                            && n > len
                        {
                            return Err(self.misfit(
                                d,
                                format!("{n} values"),
                                "more values than the nerve array holds",
                            ));
                        }
                    }
                    for i in 0..n {
                        let v = read_num(r, base).map_err(|e| self.cdr(e))?;
                        for d in to {
                            if let To::Array { at, element, size, .. } = d.to {
                                let at = at.saturating_add(i.saturating_mul(size));
                                put(out, at, element, v).map_err(|why| self.misfit(d, v.to_string(), why))?;
                            }
                        }
                    }
                }
                Op::Repeat { fixed, body } => {
                    for _ in 0..self.count(r, *fixed)? {
                        self.run(body, r, out)?;
                    }
                }
            }
        }
        Ok(())
    }

    /// A fixed array's length, or a sequence's count read from the wire,
    /// no more than the bytes left (every element takes at least one).
    fn count(&self, r: &mut Reader<'_>, fixed: Option<usize>) -> Result<usize, SubError> {
        if let Some(k) = fixed {
            return Ok(k);
        }
        let n = r.u32().map_err(|e| self.cdr(e))? as usize;
        if n > r.remaining() {
            return Err(self.cdr(CdrError::Truncated { what: "sequence", at: 0, need: n, have: r.remaining() }));
        }
        Ok(n)
    }
}

/// Appends the steps that read message `ty` at `prefix`.
fn plan(
    ty: &str,
    defs: &BTreeMap<String, MsgDef>,
    prefix: &str,
    by_ros: &BTreeMap<String, Vec<Dest>>,
    ops: &mut Vec<Op>,
) {
    let Some(def) = defs.get(ty) else { return };
    for f in &def.fields {
        let path = if prefix.is_empty() { f.name.clone() } else { format!("{prefix}.{}", f.name) };
        let to = by_ros.get(&path).cloned().unwrap_or_default();
        let fixed = match f.arity {
            Arity::Array(k) => Some(usize::try_from(k).unwrap_or(usize::MAX)),
            _ => None,
        };
        match (&f.base, f.arity) {
            (Base::Nested(n), Arity::Single) => plan(n, defs, &path, by_ros, ops),
            (Base::Nested(n), _) => {
                let mut body = Vec::new();
                plan(n, defs, &path, &BTreeMap::new(), &mut body);
                ops.push(Op::Repeat { fixed, body });
            }
            (Base::String(_) | Base::WString(_), Arity::Single) => ops.push(Op::Str(to)),
            (Base::String(_) | Base::WString(_), _) => {
                ops.push(Op::Repeat { fixed, body: vec![Op::Str(Vec::new())] });
            }
            (b, Arity::Single) => ops.push(Op::Prim(b.clone(), to)),
            (b, _) => ops.push(Op::Nums { base: b.clone(), fixed, to }),
        }
    }
}

fn read_num(r: &mut Reader<'_>, b: &Base) -> Result<Num, CdrError> {
    Ok(match b {
        Base::Bool => Num::I(r.bool()?.into()),
        Base::Byte | Base::Char | Base::Uint8 => Num::I(r.u8()?.into()),
        Base::Int8 => Num::I(r.i8()?.into()),
        Base::Uint16 => Num::I(r.u16()?.into()),
        Base::Int16 => Num::I(r.i16()?.into()),
        Base::Uint32 => Num::I(r.u32()?.into()),
        Base::Int32 => Num::I(r.i32()?.into()),
        Base::Uint64 => Num::I(r.u64()?.into()),
        Base::Int64 => Num::I(r.i64()?.into()),
        Base::Float32 => Num::F(r.f32()?.into()),
        Base::Float64 => Num::F(r.f64()?),
        // not planned as numbers
        Base::String(_) | Base::WString(_) | Base::Nested(_) => Num::I(0),
    })
}

/// Writes `n` as primitive `p` at `at`, or says why it does not fit.
fn put(out: &mut [u8], at: usize, p: Primitive, n: Num) -> Result<(), &'static str> {
    fn int<T: TryFrom<i128>>(n: Num) -> Result<T, &'static str> {
        match n {
            Num::I(i) => T::try_from(i).map_err(|_| "out of the nerve integer's range"),
            Num::F(_) => Err("a float into an integer"),
        }
    }
    fn le<const N: usize>(b: [u8; N]) -> ([u8; 8], usize) {
        let mut a = [0u8; 8];
        a[..N].copy_from_slice(&b);
        (a, N)
    }
    let f = match n {
        Num::I(i) => i as f64,
        Num::F(x) => x,
    };
    let (bytes, len) = match p {
        Primitive::U8 => le(int::<u8>(n)?.to_le_bytes()),
        Primitive::Bool => le([u8::from(int::<i128>(n)? != 0)]),
        Primitive::I8 => le(int::<i8>(n)?.to_le_bytes()),
        Primitive::U16 => le(int::<u16>(n)?.to_le_bytes()),
        Primitive::I16 => le(int::<i16>(n)?.to_le_bytes()),
        Primitive::U32 => le(int::<u32>(n)?.to_le_bytes()),
        Primitive::I32 => le(int::<i32>(n)?.to_le_bytes()),
        Primitive::U64 => le(int::<u64>(n)?.to_le_bytes()),
        Primitive::I64 => le(int::<i64>(n)?.to_le_bytes()),
        Primitive::F64 => le(f.to_le_bytes()),
        Primitive::F32 => {
            if f.is_finite() && f.abs() > f64::from(f32::MAX) {
                return Err("beyond the range of an f32");
            }
            le((f as f32).to_le_bytes())
        }
    };
    write(out, at, &bytes[..len])
}

/// Copies `bytes` into the sample at `at` (inside it by the layout; checked
/// all the same).
fn write(out: &mut [u8], at: usize, bytes: &[u8]) -> Result<(), &'static str> {
    let place = at.checked_add(bytes.len()).and_then(|end| out.get_mut(at..end)).ok_or("outside the sample")?;
    place.copy_from_slice(bytes);
    Ok(())
}

#[cfg(test)]
#[path = "usersub_tests.rs"]
mod tests;
