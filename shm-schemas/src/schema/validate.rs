//! [`Schema::validate`]: the checks a schema from outside this build (an
//! MCAP file, Python's `nerve.Payload(...)`, an agent's registration, a
//! bridge peer) must pass before its size and alignment reach iceoryx2,
//! whose payload set-up trusts them in `unsafe` code (an alignment of 0
//! divides by zero; one that is not a power of two is undefined behaviour
//! in `Layout::from_size_align_unchecked`).
//!
//! A schema made by `#[derive(Payload)]` always passes: the compiler laid
//! the type out. The rules are those of a `#[repr(C)]` type:
//!
//! * `align` is a power of two in `1..=`[`MAX_ALIGN`];
//! * `size` is a multiple of `align` and at most [`MAX_SIZE`];
//! * a primitive has its own size and alignment; an array is `len`
//!   elements; a string holds its `u32` length and `capacity` bytes;
//! * a struct's fields lie inside it (`offset + size`, checked), each at an
//!   offset that is a multiple of its alignment, in declaration order
//!   without overlapping, with unique names, and the struct is at least as
//!   aligned as each field;
//! * nesting is at most [`MAX_DEPTH`] deep, a struct has at most
//!   [`MAX_FIELDS`] fields, and names are 1..=[`MAX_NAME_LEN`] bytes.

use super::{Kind, Primitive, Schema};
use std::collections::HashSet;

/// The largest alignment a schema may ask for, bytes (a page).
pub const MAX_ALIGN: usize = 4096;
/// The largest payload a schema may describe, bytes (64 MiB). The largest
/// built-in payload is a 1920x1080 RGB frame (6,220,800 B, the bench's);
/// large data (camera images) travels in short-term memory rings, not in
/// port payloads.
pub const MAX_SIZE: usize = 64 << 20;
/// How deeply types may nest (a struct in an array in a struct ... ).
pub const MAX_DEPTH: usize = 32;
/// The most fields a struct may have.
pub const MAX_FIELDS: usize = 4096;
/// The longest type or field name, bytes (iceoryx2 keeps type names in 256 bytes).
pub const MAX_NAME_LEN: usize = 256;

/// Why a [`Schema`] was refused by [`Schema::validate`]. Every message
/// names the schema's type, the field (a path such as `pose.x`, empty for
/// the type itself), what is wrong, and what to do.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum SchemaInvalid {
    /// `align` is 0, not a power of two, or above [`MAX_ALIGN`].
    #[error("schema {type_name}{}: align {align} is not a power of two (1..={MAX_ALIGN}){FIX}", at(path))]
    Align {
        /// the schema's type name (shortened)
        type_name: String,
        /// where in it
        path: String,
        /// the alignment given
        align: usize,
    },
    /// `size` is not a multiple of `align`.
    #[error("schema {type_name}{}: size {size} is not a multiple of align {align}{FIX}", at(path))]
    SizeNotAligned {
        /// the schema's type name (shortened)
        type_name: String,
        /// where in it
        path: String,
        /// the size given
        size: usize,
        /// the alignment given
        align: usize,
    },
    /// `size` is above [`MAX_SIZE`].
    #[error(
        "schema {type_name}{}: size {size} bytes is above the {MAX_SIZE}-byte cap: send large data (images) \
         through a short-term memory ring, not a port payload",
        at(path)
    )]
    TooLarge {
        /// the schema's type name (shortened)
        type_name: String,
        /// where in it
        path: String,
        /// the size given
        size: usize,
    },
    /// A primitive with another size or alignment than its own.
    #[error(
        "schema {type_name}{}: a {primitive:?} takes {want_size} bytes aligned to {want_align}, \
         the schema says {size} aligned to {align}{FIX}",
        at(path)
    )]
    Primitive {
        /// the schema's type name (shortened)
        type_name: String,
        /// where in it
        path: String,
        /// which primitive
        primitive: Primitive,
        /// the size given
        size: usize,
        /// the alignment given
        align: usize,
        /// its size
        want_size: usize,
        /// its alignment
        want_align: usize,
    },
    /// An array whose size is not `len` elements, or less aligned than its element.
    #[error(
        "schema {type_name}{}: an array of {len} elements of {element_size} bytes (align {element_align}) \
         cannot have size {size} and align {align}{FIX}",
        at(path)
    )]
    Array {
        /// the schema's type name (shortened)
        type_name: String,
        /// where in it
        path: String,
        /// its length
        len: usize,
        /// the element's size
        element_size: usize,
        /// the element's alignment
        element_align: usize,
        /// the size given
        size: usize,
        /// the alignment given
        align: usize,
    },
    /// A string whose length prefix and capacity do not fit its size.
    #[error(
        "schema {type_name}{}: a string of capacity {capacity} needs 4 + {capacity} bytes, the schema says {size}{FIX}",
        at(path)
    )]
    String {
        /// the schema's type name (shortened)
        type_name: String,
        /// where in it
        path: String,
        /// its capacity
        capacity: usize,
        /// the size given
        size: usize,
    },
    /// A field that ends past the end of its struct.
    #[error(
        "schema {type_name}{}: it ends at byte {}, past the end of its {size}-byte struct{FIX}",
        at(path),
        end.map_or_else(|| "beyond usize::MAX".to_string(), |e| e.to_string())
    )]
    FieldOutside {
        /// the schema's type name (shortened)
        type_name: String,
        /// the field
        path: String,
        /// where it ends (`None`: the sum overflows)
        end: Option<usize>,
        /// the struct's size
        size: usize,
    },
    /// A field at an offset that is not a multiple of its alignment, or
    /// more aligned than its struct.
    #[error(
        "schema {type_name}{}: offset {offset} in a struct of align {struct_align} does not keep its \
         align {align}{FIX}",
        at(path)
    )]
    FieldMisaligned {
        /// the schema's type name (shortened)
        type_name: String,
        /// the field
        path: String,
        /// its offset
        offset: usize,
        /// its alignment
        align: usize,
        /// the struct's alignment
        struct_align: usize,
    },
    /// A field that starts before the previous one ends (fields of a
    /// `#[repr(C)]` struct follow each other in declaration order).
    #[error(
        "schema {type_name}{}: offset {offset} overlaps the field before it, which ends at {previous_end}{FIX}",
        at(path)
    )]
    FieldOverlap {
        /// the schema's type name (shortened)
        type_name: String,
        /// the field
        path: String,
        /// its offset
        offset: usize,
        /// where the field before it ends
        previous_end: usize,
    },
    /// Two fields of a struct with the same name.
    #[error("schema {type_name}{}: two fields have this name{FIX}", at(path))]
    DuplicateField {
        /// the schema's type name (shortened)
        type_name: String,
        /// the second field
        path: String,
    },
    /// A struct with more than [`MAX_FIELDS`] fields.
    #[error("schema {type_name}{}: {count} fields, more than the {MAX_FIELDS} allowed{FIX}", at(path))]
    TooManyFields {
        /// the schema's type name (shortened)
        type_name: String,
        /// where in it
        path: String,
        /// how many
        count: usize,
    },
    /// Types nested more than [`MAX_DEPTH`] deep.
    #[error("schema {type_name}{}: types nest more than {MAX_DEPTH} deep{FIX}", at(path))]
    TooDeep {
        /// the schema's type name (shortened)
        type_name: String,
        /// where the limit was reached
        path: String,
    },
    /// A type or field name that is empty or longer than [`MAX_NAME_LEN`] bytes.
    #[error("schema {type_name}{}: the {what} name is {len} bytes, it must be 1..={MAX_NAME_LEN}{FIX}", at(path))]
    Name {
        /// the schema's type name (shortened)
        type_name: String,
        /// where in it
        path: String,
        /// `type` or `field`
        what: &'static str,
        /// its length, bytes
        len: usize,
    },
    /// A sequence ([`Kind::Sequence`]) that is not laid out as nerve lays
    /// one out.
    #[error("schema {type_name}{}: {what}{FIX}", at(path))]
    Sequence {
        /// the schema's type name (shortened)
        type_name: String,
        /// where in it
        path: String,
        /// what is wrong
        what: String,
    },
}

/// What to do, said once for every message.
const FIX: &str = ": a schema made by #[derive(Payload)] (or nerve.Payload from a valid layout) is always valid; \
     one read from a file may be damaged";

/// ` field pose.x` for a field, nothing for the type itself.
fn at(path: &str) -> String {
    if path.is_empty() { String::new() } else { format!(" field {path}") }
}

/// At most 80 characters of a name, for a message (a damaged name may be long).
fn shorten(name: &str) -> String {
    let mut s: String = name.chars().take(80).collect();
    if s.len() < name.len() {
        s.push('…');
    }
    s
}

impl Schema {
    /// Checks that this schema describes a layout a `#[repr(C)]` type could
    /// have (see the module's rules), so that its size and alignment may be
    /// handed to iceoryx2 and its fields decoded without reading past the
    /// sample. Every schema from outside this build goes through here.
    pub fn validate(&self) -> Result<(), SchemaInvalid> {
        let top = shorten(&self.type_name);
        Check { top: &top }.schema(self, "", 0)
    }
}

struct Check<'a> {
    top: &'a str,
}

impl Check<'_> {
    fn schema(&self, s: &Schema, path: &str, depth: usize) -> Result<(), SchemaInvalid> {
        let type_name = || self.top.to_string();
        let path_s = || path.to_string();
        if depth > MAX_DEPTH {
            return Err(SchemaInvalid::TooDeep { type_name: type_name(), path: path_s() });
        }
        if s.type_name.is_empty() || s.type_name.len() > MAX_NAME_LEN {
            return Err(SchemaInvalid::Name {
                type_name: type_name(),
                path: path_s(),
                what: "type",
                len: s.type_name.len(),
            });
        }
        if !s.align.is_power_of_two() || s.align > MAX_ALIGN {
            return Err(SchemaInvalid::Align { type_name: type_name(), path: path_s(), align: s.align });
        }
        if s.size > MAX_SIZE {
            return Err(SchemaInvalid::TooLarge { type_name: type_name(), path: path_s(), size: s.size });
        }
        if !s.size.is_multiple_of(s.align) {
            return Err(SchemaInvalid::SizeNotAligned {
                type_name: type_name(),
                path: path_s(),
                size: s.size,
                align: s.align,
            });
        }
        match &s.kind {
            Kind::Primitive { primitive } => {
                let (want_size, want_align) = primitive.layout();
                if (s.size, s.align) != (want_size, want_align) {
                    return Err(SchemaInvalid::Primitive {
                        type_name: type_name(),
                        path: path_s(),
                        primitive: *primitive,
                        size: s.size,
                        align: s.align,
                        want_size,
                        want_align,
                    });
                }
            }
            Kind::Array { len, element } => {
                let inner = if path.is_empty() { "<i>".to_string() } else { format!("{path}.<i>") };
                self.schema(element, &inner, depth + 1)?;
                if len.checked_mul(element.size) != Some(s.size) || s.align != element.align {
                    return Err(SchemaInvalid::Array {
                        type_name: type_name(),
                        path: path_s(),
                        len: *len,
                        element_size: element.size,
                        element_align: element.align,
                        size: s.size,
                        align: s.align,
                    });
                }
            }
            Kind::String { capacity } => {
                if capacity.checked_add(4).is_none_or(|need| need > s.size) {
                    return Err(SchemaInvalid::String {
                        type_name: type_name(),
                        path: path_s(),
                        capacity: *capacity,
                        size: s.size,
                    });
                }
            }
            Kind::Sequence { header, element } => {
                let bad = |what: String| SchemaInvalid::Sequence { type_name: type_name(), path: path_s(), what };
                if depth > 0 {
                    return Err(bad("a sequence may only be a port's payload itself, not a field or element".into()));
                }
                self.schema(header, crate::seq::HEADER_FIELD, depth + 1)?;
                self.schema(element, &format!("{}.<i>", crate::seq::ITEMS_FIELD), depth + 1)?;
                if element.size == 0 {
                    return Err(bad(format!("its element {} has no bytes", element.type_name)));
                }
                let want = Schema::sequence((**header).clone(), (**element).clone());
                if (s.size, s.align) != (want.size, want.align) {
                    return Err(bad(format!(
                        "its elements must start at {} (its header's size rounded up to the element's alignment), \
                         aligned to {}; the schema says size {} and align {}",
                        want.size, want.align, s.size, s.align
                    )));
                }
                if s.align > crate::seq::SEQ_MAX_ALIGN {
                    return Err(bad(format!(
                        "its header or element is aligned to {}, more than the {} bytes a sample starts at",
                        s.align,
                        crate::seq::SEQ_MAX_ALIGN
                    )));
                }
            }
            Kind::Struct { fields } => {
                if fields.len() > MAX_FIELDS {
                    return Err(SchemaInvalid::TooManyFields {
                        type_name: type_name(),
                        path: path_s(),
                        count: fields.len(),
                    });
                }
                let mut names = HashSet::with_capacity(fields.len());
                let mut previous_end = 0usize;
                for f in fields {
                    let field_path =
                        if path.is_empty() { shorten(&f.name) } else { format!("{path}.{}", shorten(&f.name)) };
                    if f.name.is_empty() || f.name.len() > MAX_NAME_LEN {
                        return Err(SchemaInvalid::Name {
                            type_name: type_name(),
                            path: field_path,
                            what: "field",
                            len: f.name.len(),
                        });
                    }
                    if !names.insert(f.name.as_str()) {
                        return Err(SchemaInvalid::DuplicateField { type_name: type_name(), path: field_path });
                    }
                    self.schema(&f.schema, &field_path, depth + 1)?;
                    let end = f.offset.checked_add(f.schema.size);
                    if end.is_none_or(|end| end > s.size) {
                        return Err(SchemaInvalid::FieldOutside {
                            type_name: type_name(),
                            path: field_path,
                            end,
                            size: s.size,
                        });
                    }
                    if !f.offset.is_multiple_of(f.schema.align) || f.schema.align > s.align {
                        return Err(SchemaInvalid::FieldMisaligned {
                            type_name: type_name(),
                            path: field_path,
                            offset: f.offset,
                            align: f.schema.align,
                            struct_align: s.align,
                        });
                    }
                    if f.offset < previous_end {
                        return Err(SchemaInvalid::FieldOverlap {
                            type_name: type_name(),
                            path: field_path,
                            offset: f.offset,
                            previous_end,
                        });
                    }
                    previous_end = end.unwrap_or(s.size);
                }
            }
        }
        Ok(())
    }
}

impl Primitive {
    /// Its size and alignment in this build (the ones `Described` reports).
    fn layout(self) -> (usize, usize) {
        use std::mem::{align_of, size_of};
        match self {
            Primitive::U8 => (size_of::<u8>(), align_of::<u8>()),
            Primitive::U16 => (size_of::<u16>(), align_of::<u16>()),
            Primitive::U32 => (size_of::<u32>(), align_of::<u32>()),
            Primitive::U64 => (size_of::<u64>(), align_of::<u64>()),
            Primitive::I8 => (size_of::<i8>(), align_of::<i8>()),
            Primitive::I16 => (size_of::<i16>(), align_of::<i16>()),
            Primitive::I32 => (size_of::<i32>(), align_of::<i32>()),
            Primitive::I64 => (size_of::<i64>(), align_of::<i64>()),
            Primitive::F32 => (size_of::<f32>(), align_of::<f32>()),
            Primitive::F64 => (size_of::<f64>(), align_of::<f64>()),
            Primitive::Bool => (size_of::<bool>(), align_of::<bool>()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::schema::{Described, Field};

    fn tick_with(f: impl FnOnce(&mut Schema)) -> Schema {
        let mut s = crate::payloads::Tick::schema();
        f(&mut s);
        s
    }

    fn fields(s: &mut Schema) -> &mut Vec<Field> {
        match &mut s.kind {
            Kind::Struct { fields } => fields,
            _ => panic!("a struct"),
        }
    }

    #[test]
    fn every_built_in_schema_is_valid() {
        let mut n = 0;
        macro_rules! each {
            ($t:ty) => {
                n += 1;
                let s = <$t as Described>::schema();
                assert_eq!(s.validate(), Ok(()), "{}", s.type_name);
            };
        }
        crate::for_each_payload!(each);
        assert!(n > 20, "the list of payloads was walked: {n}");
        assert_eq!(crate::FixedName::schema().validate(), Ok(()));
        assert_eq!(<[[f64; 3]; 4]>::schema().validate(), Ok(()));
        assert_eq!(<[u8; 0]>::schema().validate(), Ok(()));
    }

    #[test]
    fn a_bad_alignment_is_refused_with_what_to_do() {
        for align in [0, 3, 12, 1 << 20] {
            let e = tick_with(|s| s.align = align).validate().expect_err("refused");
            assert!(matches!(e, SchemaInvalid::Align { align: a, .. } if a == align), "{e:?}");
            let text = e.to_string();
            assert!(
                text.starts_with(&format!("schema nerve::Tick: align {align} is not a power of two (1..=4096)")),
                "{text}"
            );
            assert!(text.contains("#[derive(Payload)]"), "says what to do: {text}");
        }
        // a field's own alignment is checked too, with its path
        let e = tick_with(|s| fields(s)[1].schema.align = 0).validate().expect_err("refused");
        assert!(e.to_string().starts_with("schema nerve::Tick field stamp_ns: align 0"), "{e}");
    }

    #[test]
    fn sizes_must_be_aligned_bounded_and_hold_the_fields() {
        let e = tick_with(|s| s.size = 20).validate().expect_err("not a multiple");
        assert!(matches!(e, SchemaInvalid::SizeNotAligned { size: 20, align: 8, .. }), "{e:?}");
        let e = tick_with(|s| s.size = MAX_SIZE + 8).validate().expect_err("too large");
        assert!(matches!(e, SchemaInvalid::TooLarge { .. }), "{e:?}");
        assert!(e.to_string().contains("ring"), "{e}");
        // shrunk below its fields: the second field is outside
        let e = tick_with(|s| s.size = 8).validate().expect_err("outside");
        assert!(
            matches!(&e, SchemaInvalid::FieldOutside { path, end: Some(16), size: 8, .. } if path == "stamp_ns"),
            "{e:?}"
        );
        // an offset past the end, and one whose end overflows
        let e = tick_with(|s| fields(s)[1].offset = 16).validate().expect_err("outside");
        assert!(matches!(e, SchemaInvalid::FieldOutside { end: Some(24), .. }), "{e:?}");
        let e = tick_with(|s| fields(s)[1].offset = usize::MAX - 7).validate().expect_err("overflows");
        assert!(matches!(e, SchemaInvalid::FieldOutside { end: None, .. }), "{e:?}");
        assert!(e.to_string().contains("beyond usize::MAX"), "{e}");
        // misaligned, overlapping, duplicated
        let e = tick_with(|s| fields(s)[1].offset = 4).validate().expect_err("misaligned");
        assert!(matches!(e, SchemaInvalid::FieldMisaligned { offset: 4, align: 8, .. }), "{e:?}");
        let e = tick_with(|s| fields(s)[1].offset = 0).validate().expect_err("overlaps");
        assert!(matches!(e, SchemaInvalid::FieldOverlap { offset: 0, previous_end: 8, .. }), "{e:?}");
        let e = tick_with(|s| fields(s)[1].name = "seq".into()).validate().expect_err("twice");
        assert!(matches!(e, SchemaInvalid::DuplicateField { .. }), "{e:?}");
        let e = tick_with(|s| s.align = 4).validate().expect_err("less aligned than a field");
        assert!(matches!(e, SchemaInvalid::FieldMisaligned { struct_align: 4, .. }), "{e:?}");
    }

    #[test]
    fn primitives_arrays_and_strings_keep_their_own_layout() {
        let e = tick_with(|s| fields(s)[0].schema.size = 16).validate().expect_err("a u64 of 16 bytes");
        assert!(matches!(e, SchemaInvalid::Primitive { want_size: 8, size: 16, .. }), "{e:?}");
        let mut a = <[f32; 3]>::schema();
        a.size = 16;
        assert!(matches!(a.validate(), Err(SchemaInvalid::Array { len: 3, element_size: 4, size: 16, .. })));
        if let Kind::Array { len, .. } = &mut a.kind {
            *len = usize::MAX;
        }
        assert!(matches!(a.validate(), Err(SchemaInvalid::Array { .. })), "len * size overflows");
        let mut name = crate::FixedName::schema();
        name.kind = Kind::String { capacity: usize::MAX };
        assert!(matches!(name.validate(), Err(SchemaInvalid::String { .. })));
    }

    #[test]
    fn depth_field_count_and_names_are_bounded() {
        let mut deep = <u8>::schema();
        for _ in 0..=MAX_DEPTH {
            deep = Schema {
                type_name: "d".into(),
                size: 1,
                align: 1,
                kind: Kind::Struct { fields: vec![Field { name: "x".into(), offset: 0, schema: deep }] },
            };
        }
        let e = deep.validate().expect_err("too deep");
        assert!(matches!(e, SchemaInvalid::TooDeep { .. }), "{e:?}");
        let many = Schema {
            type_name: "m".into(),
            size: 0,
            align: 1,
            kind: Kind::Struct {
                fields: (0..=MAX_FIELDS)
                    .map(|i| Field { name: format!("f{i}"), offset: 0, schema: <[u8; 0]>::schema() })
                    .collect(),
            },
        };
        assert!(matches!(many.validate(), Err(SchemaInvalid::TooManyFields { .. })));
        let e = tick_with(|s| s.type_name = "x".repeat(MAX_NAME_LEN + 1)).validate().expect_err("long");
        assert!(matches!(e, SchemaInvalid::Name { what: "type", .. }), "{e:?}");
        assert!(e.to_string().len() < 400, "a long name is shortened in the message: {e}");
        let e = tick_with(|s| s.type_name.clear()).validate().expect_err("empty");
        assert!(matches!(e, SchemaInvalid::Name { len: 0, .. }), "{e:?}");
        let e = tick_with(|s| fields(s)[0].name.clear()).validate().expect_err("empty field");
        assert!(matches!(e, SchemaInvalid::Name { what: "field", .. }), "{e:?}");
    }
}
