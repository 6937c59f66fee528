//! Variable-size payloads: a fixed header followed by one sequence of a
//! fixed-size element (issue 42), `Seq<T, H>`.
//!
//! A sample of a sequence port is laid out in shared memory as
//!
//! ```text
//! [ H (size_of H) | padding to align_of T | T; n ]
//! ```
//!
//! where `n` is the sample's own length, any number from 0 up to the
//! maximum its output port declares. The sample's length in bytes (which
//! iceoryx2 keeps in every sample's header) says `n`; nothing else does.
//! The port's [`Schema`] is a [`Kind::Sequence`] of the header's and the
//! element's schemas, so its fingerprint describes both, and tools decode
//! it as `{ header: {...}, items: [...] }` (`nerve echo --field items[3].x`).
//!
//! The element and the header are plain data of any bits ([`SeqPart`]):
//! a `#[derive(Payload)]` struct, a number, a fixed array. A string of any
//! length is a `Seq<u8>` of its UTF-8 bytes; [`NoHeader`] is the header of
//! a sequence that needs none.
//!
//! A sample starts at an 8-byte boundary in shared memory (after nerve's
//! [`crate::SampleHeader`]), so a sequence's header and element may be
//! aligned to at most [`SEQ_MAX_ALIGN`] bytes; [`Schema::validate`] refuses
//! more.

use crate::schema::{AnyBitPattern, Described, Kind, Schema};
use serde::Serialize;
use std::marker::PhantomData;

/// The largest alignment a sequence's header or element may have: where
/// iceoryx2 places a sample's payload (after the 8-aligned [`crate::SampleHeader`]).
pub const SEQ_MAX_ALIGN: usize = 8;

/// The name of the header's field in a decoded sequence sample.
pub const HEADER_FIELD: &str = "header";
/// The name of the elements' field in a decoded sequence sample.
pub const ITEMS_FIELD: &str = "items";

/// A part of a sequence sample: its header or its element. Any
/// `#[derive(Payload)]` type, number or fixed array of them is one.
pub trait SeqPart: Described + AnyBitPattern + Send + Sync {}
impl<T: Described + AnyBitPattern + Send + Sync> SeqPart for T {}

/// The header of a sequence that needs none: no bytes.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
#[repr(C)]
pub struct NoHeader;

impl Described for NoHeader {
    fn schema() -> Schema {
        Schema { type_name: "nerve::NoHeader".into(), size: 0, align: 1, kind: Kind::Struct { fields: Vec::new() } }
    }
}

// SAFETY: a zero-sized type: no bytes, so no bit pattern and no padding
unsafe impl AnyBitPattern for NoHeader {}

/// The type of a sequence port's samples: header `H`, then any number of
/// `T` (see the module). A marker: samples are written through the SDK's
/// sequence ports and read as `(&H, &[T])`, in place.
pub struct Seq<T, H = NoHeader>(PhantomData<fn() -> (T, H)>);

impl<T: SeqPart, H: SeqPart> std::fmt::Debug for Seq<T, H> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&Self::schema().type_name)
    }
}

impl<T: SeqPart, H: SeqPart> Described for Seq<T, H> {
    fn schema() -> Schema {
        Schema::sequence(H::schema(), T::schema())
    }
}

/// Where a sequence sample's parts lie, from its [`Schema`]
/// ([`Schema::sequence_shape`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SeqShape {
    /// where the elements start: the header's size rounded up to the
    /// element's alignment (the schema's `size`), bytes
    pub items_at: usize,
    /// one element's size, bytes (never 0 in a valid schema)
    pub element: usize,
    /// the sample's alignment, bytes
    pub align: usize,
}

impl SeqShape {
    /// The bytes of a sample of `n` elements; `None` if it overflows.
    pub fn len_of(&self, n: usize) -> Option<usize> {
        n.checked_mul(self.element)?.checked_add(self.items_at)
    }

    /// The most elements a sample of at most `bytes` bytes holds.
    pub fn count_of_at_most(&self, bytes: usize) -> usize {
        bytes.saturating_sub(self.items_at).checked_div(self.element).unwrap_or(0)
    }

    /// The elements in a sample of `len` bytes; `None` if `len` is not a
    /// header and a whole number of elements.
    pub fn count_of(&self, len: usize) -> Option<usize> {
        let rest = len.checked_sub(self.items_at)?;
        if self.element == 0 || !rest.is_multiple_of(self.element) {
            return None;
        }
        Some(rest / self.element)
    }
}

impl Schema {
    /// The schema of a sequence sample: `header`, then any number of
    /// `element` (see [`crate::seq`]).
    pub fn sequence(header: Schema, element: Schema) -> Schema {
        let align = header.align.max(element.align).max(1);
        let step = element.align.max(1);
        let size = header.size.div_ceil(step).saturating_mul(step);
        Schema {
            type_name: format!("nerve::Seq<{}, {}>", element.type_name, header.type_name),
            size,
            align,
            kind: Kind::Sequence { header: Box::new(header), element: Box::new(element) },
        }
    }

    /// Where a sample's parts lie, if this is a sequence's schema.
    pub fn sequence_shape(&self) -> Option<SeqShape> {
        match &self.kind {
            Kind::Sequence { element, .. } => {
                Some(SeqShape { items_at: self.size, element: element.size, align: self.align })
            }
            _ => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::payloads::Tick;
    use crate::schema::Value;

    #[derive(Debug, Clone, Copy, Default, Serialize, crate::Payload)]
    #[repr(C)]
    #[payload(name = "test::Det")]
    struct Det {
        x: f32,
        y: f32,
        score: f32,
    }

    fn bytes_of<T: Copy>(v: &[T]) -> Vec<u8> {
        // SAFETY: the bytes of Copy #[repr(C)] values without padding
        unsafe { std::slice::from_raw_parts(v.as_ptr().cast::<u8>(), std::mem::size_of_val(v)) }.to_vec()
    }

    #[test]
    fn a_sequence_schema_lays_out_header_then_elements_and_decodes_any_length() {
        let s = Seq::<Det, Tick>::schema();
        assert_eq!(s.validate(), Ok(()));
        assert_eq!(s.type_name, "nerve::Seq<test::Det, nerve::Tick>");
        let shape = s.sequence_shape().expect("a sequence");
        assert_eq!(shape, SeqShape { items_at: 16, element: 12, align: 8 });
        assert_eq!((shape.len_of(3), shape.count_of(16 + 36), shape.count_of(17)), (Some(52), Some(3), None));
        assert_eq!(shape.count_of(8), None, "shorter than the header");
        let mut sample = bytes_of(&[Tick { seq: 4, stamp_ns: 5 }]);
        for n in 0..3 {
            let v = s.decode(&sample).expect("decodes");
            let Value::Struct(parts) = &v else { panic!("{v:?}") };
            assert_eq!(parts[0].0, HEADER_FIELD);
            assert_eq!(parts[1], (ITEMS_FIELD.into(), Value::Array((0..n).map(|i| det_value(i as f32)).collect())));
            sample.extend(bytes_of(&[Det { x: n as f32, y: 0.5, score: 1.0 }]));
        }
        assert_eq!(s.decode_path("items[2].x", &sample), Some(Value::F32(2.0)));
        assert_eq!(s.decode_path("items.1.x", &sample), Some(Value::F32(1.0)));
        assert_eq!(s.decode_path("header.seq", &sample), Some(Value::Unsigned(4)));
        assert_eq!(s.decode_path("items[3].x", &sample), None, "past the sample's length");
        assert!(matches!(s.decode_path("items", &sample), Some(Value::Array(a)) if a.len() == 3));
        assert!(s.has_path("items[7].score") && !s.has_path("items[1].z") && !s.has_path("nothing"));
        // the fingerprint describes the header and the element
        assert_ne!(s.fingerprint(), Seq::<Det>::schema().fingerprint());
        assert_ne!(s.fingerprint(), Seq::<Tick, Tick>::schema().fingerprint());
        // a string of any length
        let text = Seq::<u8>::schema();
        assert_eq!(text.validate(), Ok(()));
        assert_eq!(text.sequence_shape().map(|s| s.items_at), Some(0));
    }

    /// `nerve pub` of a sequence: `{"header": ..., "items": [...]}` lays
    /// out a sample as long as its items, which decodes back to the same.
    #[test]
    fn a_sequence_encodes_from_json_at_its_own_length() {
        let s = Seq::<Det, Tick>::schema();
        let json = serde_json::json!({"header": {"seq": 1, "stamp_ns": 2},
            "items": [{"x": 1.0, "y": 2.0, "score": 0.5}, {"x": 3.0, "y": 4.0, "score": 1.0}]});
        let bytes = crate::encode::encode_json(&s, &json, &|_| false).expect("encodes");
        assert_eq!(bytes.len(), 16 + 2 * 12);
        assert_eq!(serde_json::to_value(s.decode(&bytes).expect("decodes")).expect("json"), json);
        let empty = crate::encode::encode_json(
            &s,
            &serde_json::json!({"header": {"seq": 1, "stamp_ns": 2}, "items": []}),
            &|_| false,
        );
        assert_eq!(empty.map(|b| b.len()), Ok(16));
        let e = crate::encode::encode_json(&s, &serde_json::json!({"items": [], "extra": 1}), &|_| false)
            .expect_err("unknown");
        assert!(e.to_string().contains("extra"), "{e}");
        let e = crate::encode::encode_json(&s, &serde_json::json!({"header": {"seq": 1, "stamp_ns": 2}}), &|_| false)
            .expect_err("no items");
        assert!(e.to_string().contains("items"), "{e}");
    }

    fn det_value(x: f32) -> Value {
        Value::Struct(vec![
            ("x".into(), Value::F32(x)),
            ("y".into(), Value::F32(0.5)),
            ("score".into(), Value::F32(1.0)),
        ])
    }

    #[test]
    fn a_sequence_that_is_not_laid_out_as_nerve_lays_it_out_is_refused() {
        let good = Seq::<Det, Tick>::schema();
        let mut nested = Tick::schema();
        nested.kind = Kind::Array { len: 1, element: Box::new(good.clone()) };
        assert!(nested.validate().is_err(), "a sequence inside another type");
        let mut wrong = good.clone();
        wrong.size = 24;
        assert!(wrong.validate().is_err(), "items elsewhere than after the header");
        let mut zero = good.clone();
        if let Kind::Sequence { element, .. } = &mut zero.kind {
            **element = NoHeader::schema();
        }
        assert!(zero.validate().is_err(), "a zero-sized element");
        let wide = Schema::sequence(Tick::schema(), {
            let mut s = u64::schema();
            s.align = 16;
            s.size = 16;
            s
        });
        let e = wide.validate().expect_err("aligned past 8");
        assert!(e.to_string().contains("8"), "{e}");
    }
}
