//! A C agent's own payload types (issue 43): a C struct described to nerve
//! by its type name, size, alignment and fields ([`nerve_type`], filled by
//! the `NERVE_TYPE`/`NERVE_FIELD` macros of `nerve_types.h`), turned into
//! the same [`Schema`] a Rust type of that layout derives. Its fingerprint
//! is then the Rust type's when the layouts agree, so the router connects
//! a C port to a Rust or Python port of the same type name only when they
//! agree, and refuses a layout that drifted naming both.

use crate::error::Failure;
use shm_schemas::Schema;
use shm_schemas::schema::{Described, Field, Kind};
use std::ffi::{CStr, c_char};

/// `nerve_field::primitive`: an unsigned 8-bit integer (`uint8_t`).
pub const NERVE_U8: u32 = 1;
/// `uint16_t`.
pub const NERVE_U16: u32 = 2;
/// `uint32_t`.
pub const NERVE_U32: u32 = 3;
/// `uint64_t`.
pub const NERVE_U64: u32 = 4;
/// `int8_t`.
pub const NERVE_I8: u32 = 5;
/// `int16_t`.
pub const NERVE_I16: u32 = 6;
/// `int32_t`.
pub const NERVE_I32: u32 = 7;
/// `int64_t`.
pub const NERVE_I64: u32 = 8;
/// `float`.
pub const NERVE_F32: u32 = 9;
/// `double`.
pub const NERVE_F64: u32 = 10;
/// `bool` (one byte, 0 or 1).
pub const NERVE_BOOL: u32 = 11;

/// One field of a C struct: its name, primitive type, offset and count.
#[repr(C)]
#[allow(non_camel_case_types)]
#[derive(Debug, Clone, Copy)]
pub struct nerve_field {
    /// The field's name, as the Rust or Python type names it.
    pub name: *const c_char,
    /// One of `NERVE_U8` ... `NERVE_BOOL`.
    pub primitive: u32,
    /// `offsetof(struct, field)`.
    pub offset: usize,
    /// 0 for one value; N for an array `[N]` of them.
    pub count: usize,
}

/// A C struct's layout, for a port of a type of the agent's own
/// (`nerve_setup_input_type`). Read during the call only; nothing is kept.
#[repr(C)]
#[allow(non_camel_case_types)]
#[derive(Debug, Clone, Copy)]
pub struct nerve_type {
    /// The type's stable name (`"lab::Reading"`): ports connect only to
    /// ports of the same name and layout.
    pub type_name: *const c_char,
    /// `sizeof(struct)`.
    pub size: usize,
    /// `_Alignof(struct)`.
    pub align: usize,
    /// Its fields, in declaration order.
    pub fields: *const nerve_field,
    /// How many `fields` there are.
    pub field_count: usize,
}

/// The schema of one primitive code, or why not.
fn primitive(code: u32, field: &str) -> Result<Schema, Failure> {
    Ok(match code {
        NERVE_U8 => u8::schema(),
        NERVE_U16 => u16::schema(),
        NERVE_U32 => u32::schema(),
        NERVE_U64 => u64::schema(),
        NERVE_I8 => i8::schema(),
        NERVE_I16 => i16::schema(),
        NERVE_I32 => i32::schema(),
        NERVE_I64 => i64::schema(),
        NERVE_F32 => f32::schema(),
        NERVE_F64 => f64::schema(),
        NERVE_BOOL => bool::schema(),
        other => {
            return Err(Failure::Invalid(format!(
                "field {field:?}: primitive {other} is none of NERVE_U8 ... NERVE_BOOL (1 to 11)"
            )));
        }
    })
}

/// A C string as UTF-8, or the failure naming `what`.
///
/// # Safety
/// `p` is null or a NUL-terminated string.
unsafe fn text(p: *const c_char, what: &'static str) -> Result<String, Failure> {
    if p.is_null() {
        return Err(Failure::Null(what));
    }
    // SAFETY: not null, NUL-terminated by the caller's contract
    let s = unsafe { CStr::from_ptr(p) };
    s.to_str().map(str::to_owned).map_err(|_| Failure::NotUtf8(what))
}

/// The schema `t` describes, checked as any schema from outside is
/// ([`Schema::validate`]: fields inside the struct, aligned, in order and
/// not overlapping, a size that is a multiple of the alignment), and
/// against the built-in type of its name if there is one.
///
/// # Safety
/// `t` is null or points at a `nerve_type` whose `type_name` and field
/// names are null or NUL-terminated strings and whose `fields` is null or
/// holds `field_count` fields.
pub(crate) unsafe fn schema_of(t: *const nerve_type, port: &str) -> Result<Schema, Failure> {
    // SAFETY: the caller's contract
    let t = unsafe { t.as_ref() }.ok_or(Failure::Null("type"))?;
    // SAFETY: the caller's contract
    let type_name = unsafe { text(t.type_name, "type->type_name") }?;
    if t.field_count > shm_schemas::schema::MAX_FIELDS {
        return Err(Failure::Invalid(format!(
            "{type_name}: {} fields, more than nerve's {}",
            t.field_count,
            shm_schemas::schema::MAX_FIELDS
        )));
    }
    if t.field_count > 0 && t.fields.is_null() {
        return Err(Failure::Null("type->fields"));
    }
    let mut fields = Vec::with_capacity(t.field_count);
    for i in 0..t.field_count {
        // SAFETY: `fields` holds `field_count` fields by the caller's contract
        let f = unsafe { *t.fields.add(i) };
        // SAFETY: the caller's contract
        let name = unsafe { text(f.name, "type->fields[i].name") }?;
        let one = primitive(f.primitive, &name)?;
        let schema = if f.count == 0 {
            one
        } else {
            let size = one
                .size
                .checked_mul(f.count)
                .ok_or_else(|| Failure::Invalid(format!("{type_name}.{name}: {} elements are too many", f.count)))?;
            Schema {
                type_name: format!("[{}; {}]", one.type_name, f.count),
                size,
                align: one.align,
                kind: Kind::Array { len: f.count, element: Box::new(one) },
            }
        };
        fields.push(Field { name, offset: f.offset, schema });
    }
    let schema = Schema { type_name: type_name.clone(), size: t.size, align: t.align, kind: Kind::Struct { fields } };
    schema.validate().map_err(|source| Failure::Schema { type_name: type_name.clone(), source })?;
    if let Some(built_in) = shm_schemas::schema::built_in_named(&type_name)
        && built_in.fingerprint() != schema.fingerprint()
    {
        return Err(Failure::Layout {
            port: port.to_owned(),
            type_name,
            size: schema.size,
            align: schema.align,
            fingerprint: schema.fingerprint(),
            their_size: built_in.size,
            their_align: built_in.align,
            their_fingerprint: built_in.fingerprint(),
        });
    }
    Ok(schema)
}

/// The schema of one part of a sequence or a call (an element, a header,
/// a request, an answer) that `t` names: with no fields (`fields` NULL,
/// `field_count` 0), the built-in payload type or the primitive (`"u8"`,
/// `"f32"`, ...) of its name, checked against its size and alignment
/// (`NERVE_BUILTIN` of `nerve_types.h` fills it so); with fields, the
/// agent's own type, as [`schema_of`] makes it.
///
/// # Safety
/// As for [`schema_of`].
pub(crate) unsafe fn part_schema(t: *const nerve_type, port: &str, what: &'static str) -> Result<Schema, Failure> {
    // SAFETY: the caller's contract
    let d = unsafe { t.as_ref() }.ok_or(Failure::Null(what))?;
    if !d.fields.is_null() || d.field_count > 0 {
        // SAFETY: the caller's contract
        return unsafe { schema_of(t, port) };
    }
    // SAFETY: the caller's contract
    let type_name = unsafe { text(d.type_name, "type->type_name") }?;
    let schema = shm_schemas::schema::built_in_named(&type_name)
        .or_else(|| primitive_named(&type_name))
        .ok_or_else(|| Failure::UnknownType(type_name.clone()))?;
    if schema.size != d.size || schema.align != d.align {
        return Err(Failure::Layout {
            port: port.to_owned(),
            type_name,
            size: d.size,
            align: d.align,
            fingerprint: 0,
            their_size: schema.size,
            their_align: schema.align,
            their_fingerprint: schema.fingerprint(),
        });
    }
    Ok(schema)
}

/// The schema of the primitive named as Rust names it (`"u8"`, `"f64"`, `"bool"`).
fn primitive_named(name: &str) -> Option<Schema> {
    let code = match name {
        "u8" => NERVE_U8,
        "u16" => NERVE_U16,
        "u32" => NERVE_U32,
        "u64" => NERVE_U64,
        "i8" => NERVE_I8,
        "i16" => NERVE_I16,
        "i32" => NERVE_I32,
        "i64" => NERVE_I64,
        "f32" => NERVE_F32,
        "f64" => NERVE_F64,
        "bool" => NERVE_BOOL,
        _ => return None,
    };
    primitive(code, name).ok()
}

#[cfg(test)]
mod tests {
    use super::*;
    use shm_schemas::Payload;
    use shm_schemas::payloads::Tick;

    fn field(name: &'static CStr, primitive: u32, offset: usize, count: usize) -> nerve_field {
        nerve_field { name: name.as_ptr(), primitive, offset, count }
    }

    fn of(type_name: &CStr, size: usize, align: usize, fields: &[nerve_field]) -> Result<Schema, Failure> {
        let t = nerve_type {
            type_name: type_name.as_ptr(),
            size,
            align,
            fields: fields.as_ptr(),
            field_count: fields.len(),
        };
        // SAFETY: every pointer is a live CStr or slice of this frame
        unsafe { schema_of(&t, "p") }
    }

    /// A C description of nerve::Tick's layout is the schema Rust derives
    /// for it, so its fingerprint is the one the router compares.
    #[test]
    fn a_c_description_of_a_rust_layout_has_its_fingerprint() {
        let fields = [field(c"seq", NERVE_U64, 0, 0), field(c"stamp_ns", NERVE_U64, 8, 0)];
        let s = of(c"nerve::Tick", 16, 8, &fields).expect("Tick's layout");
        assert_eq!(s.fingerprint(), Tick::layout_fingerprint());
        // an array field is named as Rust names `[f32; 3]`
        let fields = [field(c"value", NERVE_F64, 0, 0), field(c"samples", NERVE_F32, 8, 2)];
        let s = of(c"lab::Pair", 16, 8, &fields).expect("a layout of its own");
        let Kind::Struct { fields } = &s.kind else { panic!("a struct: {s:?}") };
        assert_eq!(fields[1].schema.type_name, "[f32; 2]");
    }

    #[test]
    fn drifted_built_ins_misaligned_fields_and_bad_codes_are_refused_with_their_reason() {
        // nerve::Tick with a field renamed: refused, both fingerprints named
        let fields = [field(c"sequence", NERVE_U64, 0, 0), field(c"stamp_ns", NERVE_U64, 8, 0)];
        let e = of(c"nerve::Tick", 16, 8, &fields).expect_err("drifted");
        assert!(matches!(e, Failure::Layout { .. }), "{e}");
        assert!(e.to_string().contains(&format!("{:#x}", Tick::layout_fingerprint())), "{e}");
        // a u32 at an offset that is no multiple of 4 (a packed struct)
        let fields = [field(c"a", NERVE_U8, 0, 0), field(c"b", NERVE_U32, 1, 0)];
        assert!(matches!(of(c"lab::Packed", 8, 4, &fields), Err(Failure::Schema { .. })));
        let fields = [field(c"a", 99, 0, 0)];
        assert!(of(c"lab::Odd", 1, 1, &fields).expect_err("code 99").to_string().contains("99"));
        let t =
            nerve_type { type_name: c"lab::X".as_ptr(), size: 8, align: 8, fields: std::ptr::null(), field_count: 1 };
        // SAFETY: a null `fields` is refused before it is read
        assert!(matches!(unsafe { schema_of(&t, "p") }, Err(Failure::Null("type->fields"))));
    }

    /// The exported functions answer a status for NULL arguments, never crash.
    #[test]
    fn own_type_ports_with_null_arguments_are_statuses() {
        use crate::{nerve_setup_input_type, nerve_setup_output_type, nerve_status};
        let mut port = 0;
        for f in [nerve_setup_input_type, nerve_setup_output_type] {
            // SAFETY: NULL is a valid argument of each: it is refused
            let s = unsafe { f(std::ptr::null_mut(), c"in".as_ptr(), std::ptr::null(), &mut port) };
            assert_eq!(s, nerve_status::NERVE_NULL_POINTER);
            // SAFETY: as above
            let s = unsafe { f(std::ptr::null_mut(), std::ptr::null(), std::ptr::null(), std::ptr::null_mut()) };
            assert_eq!(s, nerve_status::NERVE_NULL_POINTER);
        }
        // SAFETY: a null type is refused before anything is read
        assert!(matches!(unsafe { schema_of(std::ptr::null(), "p") }, Err(Failure::Null("type"))));
    }
}
