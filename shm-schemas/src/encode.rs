//! The other way of [`crate::Schema::decode`]: a JSON value laid out as the
//! bytes of a sample, through the type's [`Schema`] — what `nerve pub` sends
//! into any input port, whatever crate defined the type.
//!
//! Strict, as a typed language would be: every field must be given (except
//! the ones the caller lets default to zero, such as padding), no unknown
//! field is accepted, integers must be whole and in range, arrays must have
//! their length, strings must fit. Each error names the field's path
//! (`fingers[2].force_n`) and what was expected.

use crate::schema::{Kind, Primitive, Schema};
use serde_json::Value;

/// Why a JSON value does not fit a schema.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum EncodeError {
    /// A field of the type is not in the JSON object.
    #[error("{type_name}: field `{path}` is missing; give every field ({fields})")]
    Missing {
        /// the type whose field is missing
        type_name: String,
        /// the field's path
        path: String,
        /// the fields of that struct
        fields: String,
    },
    /// The JSON object has a key the type has no field for.
    #[error("{type_name} has no field `{path}`; its fields: {fields}")]
    Unknown {
        /// the struct's type
        type_name: String,
        /// the key's path
        path: String,
        /// the fields of that struct
        fields: String,
    },
    /// A value of the wrong kind or out of range.
    #[error("field `{path}`: {what}")]
    Value {
        /// the field's path (empty for the whole value)
        path: String,
        /// what was expected and what was found
        what: String,
    },
}

/// Lays `value` out as `schema`'s bytes. A struct field missing from the
/// JSON is zero when `zero_if_missing(path)` says so (padding, a stamp the
/// caller fills in), else an error.
pub fn encode_json(
    schema: &Schema,
    value: &Value,
    zero_if_missing: &dyn Fn(&str) -> bool,
) -> Result<Vec<u8>, EncodeError> {
    if let Kind::Sequence { header, element } = &schema.kind {
        return encode_sequence(schema, header, element, value, zero_if_missing);
    }
    let mut out = vec![0u8; schema.size];
    write(schema, value, "", &mut out, zero_if_missing)?;
    Ok(out)
}

/// A sequence's sample ([`crate::seq`]) from `{"header": {...}, "items": [...]}`:
/// as long as its items make it. A header without fields may be left out.
fn encode_sequence(
    schema: &Schema,
    header: &Schema,
    element: &Schema,
    value: &Value,
    zero_if_missing: &dyn Fn(&str) -> bool,
) -> Result<Vec<u8>, EncodeError> {
    use crate::seq::{HEADER_FIELD, ITEMS_FIELD};
    let fields = || format!("{HEADER_FIELD}, {ITEMS_FIELD}");
    let Value::Object(map) = value else {
        return Err(bad(
            "",
            format!(
                "expected a JSON object {{\"header\": ..., \"items\": [...]}} for {}, got {value}",
                schema.type_name
            ),
        ));
    };
    if let Some(k) = map.keys().find(|k| *k != HEADER_FIELD && *k != ITEMS_FIELD) {
        return Err(EncodeError::Unknown { type_name: schema.type_name.clone(), path: k.clone(), fields: fields() });
    }
    let Some(Value::Array(items)) = map.get(ITEMS_FIELD) else {
        return Err(EncodeError::Missing {
            type_name: schema.type_name.clone(),
            path: ITEMS_FIELD.into(),
            fields: format!("{} (an array of {})", fields(), element.type_name),
        });
    };
    let shape = schema.sequence_shape().ok_or_else(|| bad("", "not a sequence".into()))?;
    let len = shape
        .len_of(items.len())
        .filter(|len| *len <= crate::schema::MAX_SIZE)
        .ok_or_else(|| bad(ITEMS_FIELD, format!("{} elements of {} bytes are too many", items.len(), element.size)))?;
    let mut out = vec![0u8; len];
    let head = out.get_mut(..header.size).ok_or_else(|| bad(HEADER_FIELD, "outside the sample".into()))?;
    match map.get(HEADER_FIELD) {
        Some(v) => write(header, v, HEADER_FIELD, head, zero_if_missing)?,
        None if header.size == 0 || zero_if_missing(HEADER_FIELD) => {}
        None => {
            return Err(EncodeError::Missing {
                type_name: schema.type_name.clone(),
                path: HEADER_FIELD.into(),
                fields: fields(),
            });
        }
    }
    for (i, v) in items.iter().enumerate() {
        let at = shape.len_of(i).ok_or_else(|| bad(ITEMS_FIELD, "too many elements".into()))?;
        let slot = out
            .get_mut(at..at.saturating_add(element.size))
            .ok_or_else(|| bad(ITEMS_FIELD, "outside the sample".into()))?;
        write(element, v, &format!("{ITEMS_FIELD}[{i}]"), slot, zero_if_missing)?;
    }
    Ok(out)
}

fn join(path: &str, name: &str) -> String {
    if path.is_empty() { name.to_owned() } else { format!("{path}.{name}") }
}

fn bad(path: &str, what: String) -> EncodeError {
    EncodeError::Value { path: if path.is_empty() { "(the value)".into() } else { path.to_owned() }, what }
}

fn write(
    schema: &Schema,
    value: &Value,
    path: &str,
    out: &mut [u8],
    zero_if_missing: &dyn Fn(&str) -> bool,
) -> Result<(), EncodeError> {
    // every slice below is within `out`, whose length is `schema.size`;
    // a schema whose fields lie outside it is refused, never indexed past
    let slot = |offset: usize, size: usize, out_len: usize| -> Result<std::ops::Range<usize>, EncodeError> {
        match offset.checked_add(size) {
            Some(end) if end <= out_len => Ok(offset..end),
            _ => Err(bad(path, format!("the schema of {} puts a field outside its size", schema.type_name))),
        }
    };
    match &schema.kind {
        Kind::Struct { fields } => {
            let Value::Object(map) = value else {
                return Err(bad(path, format!("expected a JSON object for {}, got {value}", schema.type_name)));
            };
            let names = || fields.iter().map(|f| f.name.as_str()).collect::<Vec<_>>().join(", ");
            if let Some(k) = map.keys().find(|k| !fields.iter().any(|f| &f.name == *k)) {
                return Err(EncodeError::Unknown {
                    type_name: schema.type_name.clone(),
                    path: join(path, k),
                    fields: names(),
                });
            }
            for f in fields {
                let p = join(path, &f.name);
                let r = slot(f.offset, f.schema.size, out.len())?;
                match map.get(&f.name) {
                    Some(v) => write(&f.schema, v, &p, &mut out[r], zero_if_missing)?,
                    None if zero_if_missing(&p) => {}
                    None => {
                        return Err(EncodeError::Missing {
                            type_name: schema.type_name.clone(),
                            path: p,
                            fields: names(),
                        });
                    }
                }
            }
            Ok(())
        }
        Kind::Array { len, element } => {
            let Value::Array(items) = value else {
                return Err(bad(path, format!("expected an array of {len} for {}, got {value}", schema.type_name)));
            };
            if items.len() != *len {
                return Err(bad(path, format!("expected {len} elements ({}), got {}", schema.type_name, items.len())));
            }
            for (i, v) in items.iter().enumerate() {
                let offset = i.saturating_mul(element.size);
                let r = slot(offset, element.size, out.len())?;
                write(element, v, &format!("{path}[{i}]"), &mut out[r], zero_if_missing)?;
            }
            Ok(())
        }
        Kind::String { capacity } => {
            let Value::String(s) = value else {
                return Err(bad(path, format!("expected a string, got {value}")));
            };
            if s.len() > *capacity {
                return Err(bad(path, format!("{} bytes do not fit in {capacity}", s.len())));
            }
            let n = u32::try_from(s.len()).map_err(|_| bad(path, "too long".into()))?;
            let r = slot(0, 4, out.len())?;
            out[r].copy_from_slice(&n.to_le_bytes());
            let r = slot(4, s.len(), out.len())?;
            out[r].copy_from_slice(s.as_bytes());
            Ok(())
        }
        Kind::Sequence { .. } => Err(bad(path, format!("{} is a sequence inside another type", schema.type_name))),
        Kind::Primitive { primitive } => {
            let bytes = primitive_bytes(*primitive, value).map_err(|what| bad(path, what))?;
            let r = slot(0, bytes.len(), out.len())?;
            out[r].copy_from_slice(&bytes);
            Ok(())
        }
    }
}

fn primitive_bytes(p: Primitive, v: &Value) -> Result<Vec<u8>, String> {
    macro_rules! int {
        ($t:ty) => {{
            let n = match v {
                Value::Number(n) => n
                    .as_i64()
                    .map(i128::from)
                    .or_else(|| n.as_u64().map(i128::from))
                    .ok_or_else(|| format!("expected a whole number for {}, got {v}", stringify!($t)))?,
                _ => return Err(format!("expected a number ({}), got {v}", stringify!($t))),
            };
            <$t>::try_from(n)
                .map_err(|_| format!("{n} is out of range for {} ({}..={})", stringify!($t), <$t>::MIN, <$t>::MAX))?
                .to_le_bytes()
                .to_vec()
        }};
    }
    let float = || -> Result<f64, String> {
        match v {
            Value::Number(n) => n.as_f64().ok_or_else(|| format!("not a number: {v}")),
            _ => Err(format!("expected a number, got {v}")),
        }
    };
    Ok(match p {
        Primitive::U8 => int!(u8),
        Primitive::U16 => int!(u16),
        Primitive::U32 => int!(u32),
        Primitive::U64 => int!(u64),
        Primitive::I8 => int!(i8),
        Primitive::I16 => int!(i16),
        Primitive::I32 => int!(i32),
        Primitive::I64 => int!(i64),
        Primitive::F64 => float()?.to_le_bytes().to_vec(),
        Primitive::F32 => {
            let f = float()?;
            if f.is_finite() && f.abs() > f64::from(f32::MAX) {
                return Err(format!("{f} is out of range for f32"));
            }
            (f as f32).to_le_bytes().to_vec()
        }
        Primitive::Bool => match v {
            Value::Bool(b) => vec![u8::from(*b)],
            _ => return Err(format!("expected true or false, got {v}")),
        },
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::payloads::{SonarScan, VelocityCommand};
    use crate::schema::Described;
    use serde_json::json;

    fn never(_: &str) -> bool {
        false
    }

    #[test]
    fn a_value_encodes_to_what_decode_reads_back() {
        let s = <VelocityCommand as Described>::schema();
        let v = json!({"v": 0.25, "omega": -0.5, "stamp_ns": 7});
        let bytes = encode_json(&s, &v, &never).expect("fits");
        assert_eq!(bytes.len(), s.size);
        let back = serde_json::to_value(s.decode(&bytes).expect("decodes")).expect("json");
        assert_eq!(back, v);
    }

    #[test]
    fn missing_unknown_and_wrong_fields_are_named() {
        let s = <VelocityCommand as Described>::schema();
        let e = encode_json(&s, &json!({"v": 0.1, "omega": 0}), &never).expect_err("stamp missing");
        assert!(e.to_string().contains("field `stamp_ns` is missing"), "{e}");
        assert!(encode_json(&s, &json!({"v": 0.1, "omega": 0}), &|p| p == "stamp_ns").is_ok());
        let e = encode_json(&s, &json!({"v": 0.1, "omega": 0, "stamp_ns": 1, "w": 2}), &never).expect_err("w");
        assert!(e.to_string().contains("has no field `w`; its fields: v, omega, stamp_ns"), "{e}");
        let e = encode_json(&s, &json!({"v": "fast", "omega": 0, "stamp_ns": 1}), &never).expect_err("a string");
        assert!(e.to_string().contains("field `v`: expected a number"), "{e}");
        let e = encode_json(&s, &json!({"v": 0, "omega": 0, "stamp_ns": -1}), &never).expect_err("negative");
        assert!(e.to_string().contains("out of range for u64"), "{e}");
        let e = encode_json(&s, &json!({"v": 0, "omega": 0, "stamp_ns": 1.5}), &never).expect_err("fraction");
        assert!(e.to_string().contains("whole number"), "{e}");
    }

    #[test]
    fn arrays_must_have_their_length() {
        let s = <SonarScan as Described>::schema();
        let mut v = serde_json::to_value(SonarScan::default()).expect("json");
        assert!(encode_json(&s, &v, &never).is_ok(), "the default scan round-trips");
        v["ranges_m"] = json!([1.0, 2.0]);
        let e = encode_json(&s, &v, &never).expect_err("short");
        assert!(e.to_string().contains("field `ranges_m`: expected 12 elements"), "{e}");
    }
}
