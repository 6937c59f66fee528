//! The one rule for whether an input may read what an output sends
//! ([`check`], and [`compatible`] for two layouts), used by the launch
//! file's check before anything starts, by the router before it connects,
//! and by the agent before it subscribes.
//!
//! Two ports are compatible when they carry the same type name laid out
//! the same way: the same fields, names, offsets, types, sizes and order
//! (the same [`Schema`], so the same [`Schema::fingerprint`], which the
//! port's iceoryx2 service also carries). Anything else would misread
//! every sample, so nothing looser is accepted.
//!
//! A refusal lists what differs, field by field ([`Mismatch`]), and names
//! the two sides by what they are (an agent's port); it never guesses which
//! side is the "older" one: a Python agent's executable is the interpreter,
//! and two definitions of one type may both be new.

use super::{Kind, Schema};
use std::fmt;

/// What one side of a connection declares for its port: the type name,
/// the layout fingerprint when known, and the layout itself when known (a
/// registration too large for its schemas, a tool's port or a command
/// from the router carry less).
#[derive(Debug, Clone, Copy)]
pub struct Declared<'a> {
    /// the stable type name (`nerve::Tick`)
    pub type_name: &'a str,
    /// [`Schema::fingerprint`] of the layout, when known
    pub fingerprint: Option<u64>,
    /// the layout, when known
    pub schema: Option<&'a Schema>,
}

impl<'a> Declared<'a> {
    /// A port known by its layout.
    pub fn of(schema: &'a Schema) -> Self {
        Declared { type_name: &schema.type_name, fingerprint: Some(schema.fingerprint()), schema: Some(schema) }
    }
}

/// Why an input may not read an output ([`check`]).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum Incompatible {
    /// Two different type names.
    #[error("the output sends {output} but the input takes {input}")]
    Type {
        /// the output's type name
        output: String,
        /// the input's type name
        input: String,
    },
    /// One type name, laid out differently on the two sides.
    #[error("both carry {type_name}, laid out differently{}", fields_or_prints(.fields, .output_fingerprint, .input_fingerprint))]
    Layout {
        /// the type name both carry
        type_name: String,
        /// the output's layout fingerprint, when known
        output_fingerprint: Option<u64>,
        /// the input's layout fingerprint, when known
        input_fingerprint: Option<u64>,
        /// what differs, when both layouts are known
        fields: Option<Mismatch>,
    },
}

fn fields_or_prints(fields: &Option<Mismatch>, out: &Option<u64>, inp: &Option<u64>) -> String {
    match (fields, out, inp) {
        (Some(m), _, _) => format!(":\n{m}"),
        (None, Some(o), Some(i)) => format!(" (layout {o:#018x} in the output, {i:#018x} in the input)"),
        _ => String::new(),
    }
}

impl Incompatible {
    /// The refusal for connecting `from` (an output, `AGENT/PORT`) to `to`
    /// (an input): what differs, one line per field, naming the two ports,
    /// and what to do.
    pub fn refusal(&self, from: &str, to: &str) -> String {
        match self {
            Incompatible::Type { output, input } => {
                format!("cannot connect {from} to {to}: {from} sends {output} but {to} takes {input}")
            }
            Incompatible::Layout { type_name, output_fingerprint, input_fingerprint, fields } => {
                let what = match (fields, output_fingerprint, input_fingerprint) {
                    (Some(m), _, _) => format!(":\n{}", m.list(from, to)),
                    (None, Some(o), Some(i)) => format!(" ({from} has layout {o:#018x}, {to} has {i:#018x})"),
                    _ => String::new(),
                };
                format!(
                    "cannot connect {from} to {to}: both declare {type_name}, but laid out differently{what}\n\
                     make both declare the same layout of {type_name} (the same fields, types and order)"
                )
            }
        }
    }
}

/// Whether an input declared as `inp` may read an output declared as
/// `out`: the same type name, and the same layout (field by field when
/// both layouts are known, else by fingerprint when both are known).
pub fn check(out: Declared<'_>, inp: Declared<'_>) -> Result<(), Incompatible> {
    if out.type_name != inp.type_name {
        return Err(Incompatible::Type { output: out.type_name.into(), input: inp.type_name.into() });
    }
    let layout = |fields| Incompatible::Layout {
        type_name: out.type_name.into(),
        output_fingerprint: out.schema.map(Schema::fingerprint).or(out.fingerprint),
        input_fingerprint: inp.schema.map(Schema::fingerprint).or(inp.fingerprint),
        fields,
    };
    match (out.schema, inp.schema, out.fingerprint, inp.fingerprint) {
        (Some(o), Some(i), _, _) => compatible(o, i).map_err(|m| layout(Some(m))),
        (_, _, Some(o), Some(i)) if o != i => Err(layout(None)),
        _ => Ok(()),
    }
}

/// Whether an input laid out as `inp` may read samples laid out as `out`:
/// only when the two layouts are the same; if not, every difference.
pub fn compatible(out: &Schema, inp: &Schema) -> Result<(), Mismatch> {
    if out == inp {
        return Ok(());
    }
    let mut differences = Vec::new();
    compare("", out, inp, &mut differences);
    Err(Mismatch { type_name: out.type_name.clone(), differences })
}

/// How two layouts of one type differ ([`compatible`]).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Mismatch {
    /// the output's type name
    pub type_name: String,
    /// every difference, the output's fields first in declaration order
    pub differences: Vec<Difference>,
}

/// Which side of a connection.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Side {
    /// the output (the sender)
    Output,
    /// the input (the reader)
    Input,
}

/// One difference between two layouts. `path` names a field as
/// [`Schema::field`] does (`pose.x`; `<i>` for an array's element); empty
/// for the payload itself.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Difference {
    /// Another type at `path` (a field of `f32` on one side, `u32` on the other).
    Type {
        /// where
        path: String,
        /// the output's type name there
        output: String,
        /// its size, bytes
        output_size: usize,
        /// the input's type name there
        input: String,
        /// its size, bytes
        input_size: usize,
    },
    /// The same type name at `path`, of another size.
    Size {
        /// where
        path: String,
        /// the output's size, bytes
        output: usize,
        /// the input's size, bytes
        input: usize,
    },
    /// The same type name at `path`, of another alignment.
    Align {
        /// where
        path: String,
        /// the output's alignment, bytes
        output: usize,
        /// the input's alignment, bytes
        input: usize,
    },
    /// The field `path` at another offset.
    Offset {
        /// where
        path: String,
        /// its offset in the output, bytes from the start of its struct
        output: usize,
        /// its offset in the input
        input: usize,
    },
    /// The same field (type and offset) under another name.
    Name {
        /// its path in the output
        output: String,
        /// its path in the input
        input: String,
        /// its offset, bytes from the start of its struct
        offset: usize,
        /// its type
        type_name: String,
    },
    /// A field on one side only.
    Missing {
        /// where
        path: String,
        /// the side that has it
        only_in: Side,
        /// its offset, bytes from the start of its struct
        offset: usize,
        /// its type
        type_name: String,
        /// its size, bytes
        size: usize,
    },
    /// The same type name at `path` made of other things (an array's
    /// length, a string's capacity, a struct against a number).
    Shape {
        /// where
        path: String,
        /// what the output's is
        output: String,
        /// what the input's is
        input: String,
    },
    /// The same fields at `path`, declared in another order.
    Order {
        /// where
        path: String,
    },
}

/// `field \`pose.x\`` or `the payload`.
fn subject(path: &str) -> String {
    if path.is_empty() { "the payload".into() } else { format!("field `{path}`") }
}

impl Difference {
    /// The difference in one line, the output called `out` and the input `inp`.
    pub fn line(&self, out: &str, inp: &str) -> String {
        match self {
            Difference::Type { path, output, output_size, input, input_size } => format!(
                "{}: {output} ({output_size} bytes) in {out}, {input} ({input_size} bytes) in {inp}",
                subject(path)
            ),
            Difference::Size { path, output, input } => {
                format!("size of {}: {output} bytes in {out}, {input} bytes in {inp}", subject(path))
            }
            Difference::Align { path, output, input } => {
                format!("alignment of {}: {output} bytes in {out}, {input} bytes in {inp}", subject(path))
            }
            Difference::Offset { path, output, input } => {
                format!("{}: at offset {output} in {out}, at offset {input} in {inp}", subject(path))
            }
            Difference::Name { output, input, offset, type_name } => {
                format!("the {type_name} at offset {offset}: named `{output}` in {out}, `{input}` in {inp}")
            }
            Difference::Missing { path, only_in, offset, type_name, size } => {
                let side = match only_in {
                    Side::Output => out,
                    Side::Input => inp,
                };
                format!("{} ({type_name}, {size} bytes at offset {offset}): only in {side}", subject(path))
            }
            Difference::Shape { path, output, input } => {
                format!("{}: {output} in {out}, {input} in {inp}", subject(path))
            }
            Difference::Order { path } => {
                format!("{}: the same fields in {out} and {inp}, declared in another order", subject(path))
            }
        }
    }
}

impl Mismatch {
    /// Every difference, one per line (each indented by two spaces), the
    /// output called `out` and the input `inp` (`t1/tick`, `scale/tick`).
    pub fn list(&self, out: &str, inp: &str) -> String {
        let lines: Vec<String> = self.differences.iter().map(|d| format!("  {}", d.line(out, inp))).collect();
        lines.join("\n")
    }
}

impl fmt::Display for Mismatch {
    /// Every difference, one per line, the sides called "the output" and "the input".
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.list("the output", "the input"))
    }
}

impl std::error::Error for Mismatch {}

fn join(path: &str, name: &str) -> String {
    if path.is_empty() { name.to_owned() } else { format!("{path}.{name}") }
}

/// What a schema is made of, for a [`Difference::Shape`].
fn shape(s: &Schema) -> String {
    match &s.kind {
        Kind::Primitive { primitive } => format!("a {primitive:?}").to_lowercase(),
        Kind::Array { len, element } => format!("an array of {len} {}", element.type_name),
        Kind::String { capacity } => format!("a string of capacity {capacity}"),
        Kind::Struct { fields } => format!("a struct of {} field(s)", fields.len()),
        Kind::Sequence { header, element } => {
            format!("a sequence of {} after a {}", element.type_name, header.type_name)
        }
    }
}

/// Adds to `out` how `a` (the output's, at `path`) differs from `b` (the input's).
fn compare(path: &str, a: &Schema, b: &Schema, out: &mut Vec<Difference>) {
    if a == b {
        return;
    }
    let before = out.len();
    if a.type_name != b.type_name {
        out.push(Difference::Type {
            path: path.into(),
            output: a.type_name.clone(),
            output_size: a.size,
            input: b.type_name.clone(),
            input_size: b.size,
        });
        return;
    }
    if a.size != b.size {
        out.push(Difference::Size { path: path.into(), output: a.size, input: b.size });
    }
    if a.align != b.align {
        out.push(Difference::Align { path: path.into(), output: a.align, input: b.align });
    }
    match (&a.kind, &b.kind) {
        (Kind::Struct { fields: fa }, Kind::Struct { fields: fb }) => {
            compare_fields(path, fa, fb, out);
        }
        (Kind::Array { len: la, element: ea }, Kind::Array { len: lb, element: eb }) if la == lb => {
            compare(&join(path, "<i>"), ea, eb, out);
        }
        (Kind::Sequence { header: ha, element: ea }, Kind::Sequence { header: hb, element: eb }) => {
            compare(&join(path, crate::seq::HEADER_FIELD), ha, hb, out);
            compare(&join(path, &format!("{}.<i>", crate::seq::ITEMS_FIELD)), ea, eb, out);
        }
        (ka, kb) if ka != kb => {
            out.push(Difference::Shape { path: path.into(), output: shape(a), input: shape(b) });
        }
        _ => {}
    }
    if out.len() == before {
        // the same fields by name, offset and layout: only their order differs
        out.push(Difference::Order { path: path.into() });
    }
}

/// The fields of two structs of one name: by name first; the fields left
/// over on both sides at one offset with one layout are a renamed field;
/// the rest are on one side only.
fn compare_fields(path: &str, fa: &[super::Field], fb: &[super::Field], out: &mut Vec<Difference>) {
    let mut only_b: Vec<&super::Field> = fb.iter().filter(|g| !fa.iter().any(|f| f.name == g.name)).collect();
    let mut only_a = Vec::new();
    for f in fa {
        match fb.iter().find(|g| g.name == f.name) {
            Some(g) => {
                let here = join(path, &f.name);
                if f.offset != g.offset {
                    out.push(Difference::Offset { path: here.clone(), output: f.offset, input: g.offset });
                }
                compare(&here, &f.schema, &g.schema, out);
            }
            None => only_a.push(f),
        }
    }
    for f in only_a {
        match only_b.iter().position(|g| g.offset == f.offset && g.schema == f.schema) {
            Some(at) => {
                let g = only_b.remove(at);
                out.push(Difference::Name {
                    output: join(path, &f.name),
                    input: join(path, &g.name),
                    offset: f.offset,
                    type_name: f.schema.type_name.clone(),
                });
            }
            None => out.push(Difference::Missing {
                path: join(path, &f.name),
                only_in: Side::Output,
                offset: f.offset,
                type_name: f.schema.type_name.clone(),
                size: f.schema.size,
            }),
        }
    }
    for g in only_b {
        out.push(Difference::Missing {
            path: join(path, &g.name),
            only_in: Side::Input,
            offset: g.offset,
            type_name: g.schema.type_name.clone(),
            size: g.schema.size,
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Described;
    use crate::schema::{Field, Primitive};

    /// A struct `name` of `fields` laid out as `#[repr(C)]` would.
    fn strukt(name: &str, fields: &[(&str, Schema)]) -> Schema {
        let mut at = 0usize;
        let mut align = 1usize;
        let mut laid = Vec::new();
        for (n, s) in fields {
            let offset = at.div_ceil(s.align) * s.align;
            at = offset + s.size;
            align = align.max(s.align);
            laid.push(Field { name: (*n).into(), offset, schema: s.clone() });
        }
        Schema { type_name: name.into(), size: at.div_ceil(align) * align, align, kind: Kind::Struct { fields: laid } }
    }

    fn smoothed() -> Schema {
        strukt("lab::Smoothed", &[("seq", u64::schema()), ("value", f32::schema()), ("weight", f32::schema())])
    }

    fn differences(a: &Schema, b: &Schema) -> Vec<Difference> {
        compatible(a, b).expect_err("the layouts differ").differences
    }

    #[test]
    fn the_same_layout_is_compatible_and_every_built_in_payload_with_itself() {
        assert_eq!(compatible(&smoothed(), &smoothed()), Ok(()));
        macro_rules! each {
            ($t:ty) => {
                assert_eq!(compatible(&<$t>::schema(), &<$t>::schema()), Ok(()));
            };
        }
        crate::for_each_payload!(each);
    }

    #[test]
    fn a_field_on_one_side_only_is_listed_with_its_type_offset_and_side() {
        let mut extra = smoothed();
        let Kind::Struct { fields } = &mut extra.kind else { unreachable!() };
        fields.push(Field { name: "spread".into(), offset: 16, schema: f64::schema() });
        extra.size = 24;
        extra.align = 8;
        let m = compatible(&smoothed(), &extra).expect_err("one more field");
        assert_eq!(
            m.differences,
            vec![
                Difference::Size { path: String::new(), output: 16, input: 24 },
                Difference::Missing {
                    path: "spread".into(),
                    only_in: Side::Input,
                    offset: 16,
                    type_name: "f64".into(),
                    size: 8
                },
            ]
        );
        let text = m.list("t1/out", "py/in");
        assert_eq!(
            text,
            "  size of the payload: 16 bytes in t1/out, 24 bytes in py/in\n  \
             field `spread` (f64, 8 bytes at offset 16): only in py/in"
        );
        assert!(!text.contains("older") && !text.contains("rebuild"), "{text}");
        // the other way round, the field is the output's
        let back = differences(&extra, &smoothed());
        assert!(back.iter().any(|d| matches!(d, Difference::Missing { only_in: Side::Output, .. })), "{back:?}");
        // Display: one line per difference
        assert_eq!(m.to_string().lines().count(), 2);
    }

    #[test]
    fn a_field_of_another_type_is_listed_with_both_types() {
        let other =
            strukt("lab::Smoothed", &[("seq", u64::schema()), ("value", u32::schema()), ("weight", f32::schema())]);
        assert_eq!(
            differences(&smoothed(), &other),
            vec![Difference::Type {
                path: "value".into(),
                output: "f32".into(),
                output_size: 4,
                input: "u32".into(),
                input_size: 4
            }]
        );
        let wider =
            strukt("lab::Smoothed", &[("seq", u64::schema()), ("value", f64::schema()), ("weight", f32::schema())]);
        let d = differences(&smoothed(), &wider);
        // the type, the offset it pushes the next field to, and the size
        assert!(d.contains(&Difference::Size { path: String::new(), output: 16, input: 24 }), "{d:?}");
        assert!(d.contains(&Difference::Offset { path: "weight".into(), output: 12, input: 16 }), "{d:?}");
        assert!(d.iter().any(|x| matches!(x, Difference::Type { path, .. } if path == "value")), "{d:?}");
    }

    #[test]
    fn a_field_at_another_offset_and_fields_in_another_order_are_told_apart() {
        // value and weight swapped: same names, other offsets
        let swapped =
            strukt("lab::Smoothed", &[("seq", u64::schema()), ("weight", f32::schema()), ("value", f32::schema())]);
        assert_eq!(
            differences(&smoothed(), &swapped),
            vec![
                Difference::Offset { path: "value".into(), output: 8, input: 12 },
                Difference::Offset { path: "weight".into(), output: 12, input: 8 },
            ]
        );
        // the same offsets, listed in another order
        let mut reordered = smoothed();
        let Kind::Struct { fields } = &mut reordered.kind else { unreachable!() };
        fields.swap(1, 2);
        assert_ne!(reordered.fingerprint(), smoothed().fingerprint());
        assert_eq!(differences(&smoothed(), &reordered), vec![Difference::Order { path: String::new() }]);
    }

    #[test]
    fn a_renamed_field_is_one_difference_not_two() {
        let renamed =
            strukt("lab::Smoothed", &[("seq", u64::schema()), ("mean", f32::schema()), ("weight", f32::schema())]);
        let d = differences(&smoothed(), &renamed);
        assert_eq!(
            d,
            vec![Difference::Name { output: "value".into(), input: "mean".into(), offset: 8, type_name: "f32".into() }]
        );
        assert_eq!(d[0].line("a/o", "b/i"), "the f32 at offset 8: named `value` in a/o, `mean` in b/i");
    }

    #[test]
    fn nested_fields_arrays_strings_and_alignment_are_named_by_their_path() {
        let finger = |force: Schema| strukt("lab::Finger", &[("force", force)]);
        let hand = |force: Schema| {
            let f = finger(force);
            let arr = Schema {
                type_name: format!("[{}; 2]", f.type_name),
                size: f.size * 2,
                align: f.align,
                kind: Kind::Array { len: 2, element: Box::new(f) },
            };
            strukt("lab::Hand", &[("fingers", arr)])
        };
        let d = differences(&hand(f32::schema()), &hand(u32::schema()));
        assert_eq!(
            d,
            vec![Difference::Type {
                path: "fingers.<i>.force".into(),
                output: "f32".into(),
                output_size: 4,
                input: "u32".into(),
                input_size: 4
            }]
        );
        // an array of another length is another type name
        let short = strukt("lab::Arr", &[("a", <[u8; 2]>::schema())]);
        let long = strukt("lab::Arr", &[("a", <[u8; 3]>::schema())]);
        assert!(
            differences(&short, &long).iter().any(
                |x| matches!(x, Difference::Type { output, input, .. } if output == "[u8; 2]" && input == "[u8; 3]")
            )
        );
        // a string of another capacity under one name
        let s = |capacity| Schema {
            type_name: "name".into(),
            size: 4 + capacity,
            align: 4,
            kind: Kind::String { capacity },
        };
        let d = differences(&strukt("lab::S", &[("n", s(8))]), &strukt("lab::S", &[("n", s(12))]));
        assert!(d.contains(&Difference::Size { path: "n".into(), output: 12, input: 16 }), "{d:?}");
        assert!(
            d.iter().any(|x| matches!(x, Difference::Shape { output, input, .. }
                if output == "a string of capacity 8" && input == "a string of capacity 12")),
            "{d:?}"
        );
        // the alignment of the payload itself
        let mut aligned = smoothed();
        aligned.align = 16;
        aligned.size = 16;
        assert_eq!(
            differences(&smoothed(), &aligned),
            vec![Difference::Align { path: String::new(), output: 8, input: 16 }]
        );
        // a number against a struct of one name
        let num = Schema {
            type_name: "lab::N".into(),
            size: 4,
            align: 4,
            kind: Kind::Primitive { primitive: Primitive::U32 },
        };
        let st = strukt("lab::N", &[("x", u32::schema())]);
        assert!(matches!(differences(&num, &st).as_slice(), [Difference::Shape { .. }]));
    }

    #[test]
    fn check_refuses_other_names_and_other_layouts_and_says_what_to_do() {
        let tick = crate::payloads::Tick::schema();
        let e = check(Declared::of(&tick), Declared::of(&smoothed())).expect_err("two names");
        assert_eq!(e, Incompatible::Type { output: "nerve::Tick".into(), input: "lab::Smoothed".into() });
        assert_eq!(
            e.refusal("t/tick", "s/in"),
            "cannot connect t/tick to s/in: t/tick sends nerve::Tick but s/in takes lab::Smoothed"
        );

        let mut extra = smoothed();
        let Kind::Struct { fields } = &mut extra.kind else { unreachable!() };
        fields.push(Field { name: "spread".into(), offset: 16, schema: f32::schema() });
        extra.size = 24;
        let e = check(Declared::of(&smoothed()), Declared::of(&extra)).expect_err("one more field");
        let text = e.refusal("rs/out", "py/in");
        assert!(
            text.starts_with("cannot connect rs/out to py/in: both declare lab::Smoothed, but laid out differently:\n"),
            "{text}"
        );
        assert!(text.contains("\n  field `spread` (f32, 4 bytes at offset 16): only in py/in\n"), "{text}");
        assert!(
            text.ends_with("make both declare the same layout of lab::Smoothed (the same fields, types and order)"),
            "{text}"
        );
        assert!(!text.contains("older"), "{text}");

        // layouts unknown: the fingerprints decide, and the refusal names them
        let by_print = |o, i| {
            check(
                Declared { type_name: "lab::Smoothed", fingerprint: o, schema: None },
                Declared { type_name: "lab::Smoothed", fingerprint: i, schema: None },
            )
        };
        let e = by_print(Some(1), Some(2)).expect_err("two fingerprints");
        assert!(e.refusal("a/o", "b/i").contains("(a/o has layout 0x0000000000000001, b/i has 0x0000000000000002)"));
        assert_eq!(by_print(Some(3), Some(3)), Ok(()));
        // a side that says nothing of its layout is judged by its name (an
        // agent's check of the router's command, which carries the name only)
        assert_eq!(by_print(None, Some(3)), Ok(()));
        // one layout known, the other only by fingerprint
        let half = check(
            Declared::of(&smoothed()),
            Declared { type_name: "lab::Smoothed", fingerprint: Some(extra.fingerprint()), schema: None },
        );
        assert!(matches!(half, Err(Incompatible::Layout { fields: None, .. })), "{half:?}");
        assert_eq!(
            check(
                Declared::of(&smoothed()),
                Declared { type_name: "lab::Smoothed", fingerprint: Some(smoothed().fingerprint()), schema: None }
            ),
            Ok(())
        );
    }
}
