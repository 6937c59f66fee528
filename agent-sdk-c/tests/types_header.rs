//! `include/nerve_types.h` is the C layout of every built-in payload type,
//! generated here from its schema in `shm-schemas`: a struct per type (and
//! per nested struct or string), its type name and layout fingerprint as
//! constants, and a static assert on its size, alignment and every field's
//! offset. One test regenerates the header and fails if the committed one
//! differs (`NERVE_BLESS=1` writes it); another compiles it with gcc as C11
//! and with g++ as C++17, so each static assert checks the C compiler's
//! layout against the Rust one.

use shm_schemas::schema::{Kind, Primitive, Schema, built_in_named};
use std::collections::BTreeSet;
use std::fmt::Write as _;
use std::path::PathBuf;
use std::process::Command;

/// C and C++ keywords a field must not be named (the header is for both).
const KEYWORDS: &[&str] = &[
    "auto",
    "bool",
    "break",
    "case",
    "char",
    "class",
    "const",
    "continue",
    "default",
    "delete",
    "do",
    "double",
    "else",
    "enum",
    "extern",
    "float",
    "for",
    "goto",
    "if",
    "int",
    "long",
    "new",
    "operator",
    "private",
    "protected",
    "public",
    "register",
    "return",
    "short",
    "signed",
    "sizeof",
    "static",
    "struct",
    "switch",
    "template",
    "this",
    "typedef",
    "union",
    "unsigned",
    "void",
    "volatile",
    "while",
];

/// `nerve::Tick` -> `nerve_Tick`.
fn c_ident(type_name: &str) -> String {
    type_name.chars().map(|c| if c.is_ascii_alphanumeric() { c } else { '_' }).collect::<String>().replace("__", "_")
}

/// `nerve_SonarScan` -> `NERVE_SONAR_SCAN`.
fn c_macro(ident: &str) -> String {
    let mut out = String::new();
    let mut prev_lower = false;
    for c in ident.chars() {
        if c.is_ascii_uppercase() && prev_lower {
            out.push('_');
        }
        prev_lower = c.is_ascii_lowercase() || c.is_ascii_digit();
        out.push(c.to_ascii_uppercase());
    }
    out
}

fn primitive(p: Primitive) -> &'static str {
    match p {
        Primitive::U8 => "uint8_t",
        Primitive::U16 => "uint16_t",
        Primitive::U32 => "uint32_t",
        Primitive::U64 => "uint64_t",
        Primitive::I8 => "int8_t",
        Primitive::I16 => "int16_t",
        Primitive::I32 => "int32_t",
        Primitive::I64 => "int64_t",
        Primitive::F32 => "float",
        Primitive::F64 => "double",
        Primitive::Bool => "bool",
    }
}

/// The C name of a string's struct: its type's (`nerve_FixedName`), or
/// one per capacity for an unnamed one.
fn string_ident(s: &Schema, capacity: usize) -> String {
    if s.type_name.contains("::") { c_ident(&s.type_name) } else { format!("nerve_string{capacity}") }
}

/// The header's text, with the structs in dependency order.
struct Gen {
    out: String,
    done: BTreeSet<String>,
}

impl Gen {
    /// The C element type and array dimensions of `s` for a field,
    /// emitting the structs it needs first.
    fn field_type(&mut self, s: &Schema) -> (String, String) {
        // if-lets, not a match: a kind added to shm-schemas (a variable-size
        // payload is never a field) fails here by name, not at compile time
        if let Kind::Primitive { primitive: p } = &s.kind {
            (primitive(*p).to_owned(), String::new())
        } else if let Kind::Array { len, element } = &s.kind {
            let (t, dims) = self.field_type(element);
            (t, format!("[{len}]{dims}"))
        } else if let Kind::String { capacity } = &s.kind {
            let name = string_ident(s, *capacity);
            if self.done.insert(name.clone()) {
                let _ = write!(
                    self.out,
                    "/* A UTF-8 string of at most {capacity} bytes: `len`, then the bytes (not NUL-terminated). */\n\
                     typedef struct {name} {{\n  uint32_t len;\n  uint8_t bytes[{capacity}];\n}} {name};\n"
                );
                self.asserts(&name, s, &[("len", 0), ("bytes", 4)]);
            }
            (name, String::new())
        } else if let Kind::Struct { .. } = &s.kind {
            (self.structure(s), String::new())
        } else {
            panic!("{}: a field of a kind nerve_types.h cannot lay out: {:?}", s.type_name, s.kind)
        }
    }

    /// Emits struct `s` (once) and returns its C name.
    fn structure(&mut self, s: &Schema) -> String {
        let name = c_ident(&s.type_name);
        if self.done.contains(&name) {
            return name;
        }
        let Kind::Struct { fields } = &s.kind else { unreachable!("a struct") };
        let mut body = String::new();
        for f in fields {
            assert!(!KEYWORDS.contains(&f.name.as_str()), "{}.{} is a C or C++ keyword", s.type_name, f.name);
            let (t, dims) = self.field_type(&f.schema);
            let _ = writeln!(body, "  {t} {}{dims};", f.name);
        }
        self.done.insert(name.clone());
        let _ = write!(self.out, "/* {} */\ntypedef struct {name} {{\n{body}}} {name};\n", s.type_name);
        let offsets: Vec<(&str, usize)> = fields.iter().map(|f| (f.name.as_str(), f.offset)).collect();
        self.asserts(&name, s, &offsets);
        name
    }

    fn asserts(&mut self, name: &str, s: &Schema, offsets: &[(&str, usize)]) {
        let t = &s.type_name;
        let _ = writeln!(self.out, "NERVE_STATIC_ASSERT(sizeof({name}) == {}, \"{t} is {} bytes\");", s.size, s.size);
        let _ = writeln!(
            self.out,
            "NERVE_STATIC_ASSERT(NERVE_ALIGNOF({name}) == {}, \"{t} is aligned to {} bytes\");",
            s.align, s.align
        );
        for (field, offset) in offsets {
            let _ = writeln!(
                self.out,
                "NERVE_STATIC_ASSERT(offsetof({name}, {field}) == {offset}, \"{t}.{field} is at byte {offset}\");"
            );
        }
        self.out.push('\n');
    }
}

/// The text of `include/nerve_types.h` for this build's built-in types.
fn generate() -> String {
    let mut g = Gen {
        out: String::from(
            "/* nerve_types.h: the built-in payload types of nerve as C structs.\n \
             * Generated from their schemas (shm-schemas) by agent-sdk-c/tests/types_header.rs:\n \
             * do not edit; regenerate with\n \
             * NERVE_BLESS=1 cargo nextest run -p nerve-agent-c -E 'test(types_header)'.\n \
             *\n \
             * For each type T (nerve::Tick is nerve_Tick): the struct, T_TYPE_NAME\n \
             * (\"nerve::Tick\") and T_FINGERPRINT (its layout's fingerprint, as nerve\n \
             * checks it), and static asserts that this compiler lays it out as nerve\n \
             * does. Declare a port with NERVE_SETUP_INPUT(setup, \"in\", nerve_Tick, &port)\n \
             * (and NERVE_SETUP_OUTPUT): the type's name, size, alignment and fingerprint\n \
             * are passed for nerve to check. NERVE_BUILTIN_PAYLOADS(X) calls X(T) for\n \
             * every type. Valid C11 and C++17. */\n\
             #ifndef NERVE_TYPES_H\n#define NERVE_TYPES_H\n\n\
             #include <stddef.h>\n#include <stdint.h>\n#ifndef __cplusplus\n#include <stdbool.h>\n#endif\n\n\
             #ifdef __cplusplus\n\
             #define NERVE_STATIC_ASSERT(cond, msg) static_assert(cond, msg)\n\
             #define NERVE_ALIGNOF(T) alignof(T)\n\
             #else\n\
             #define NERVE_STATIC_ASSERT(cond, msg) _Static_assert(cond, msg)\n\
             #define NERVE_ALIGNOF(T) _Alignof(T)\n\
             #endif\n\n\
             /* Declares input NAME of payload struct T on SETUP (in `init`), handle in *PORT. */\n\
             #define NERVE_SETUP_INPUT(setup, name, T, port) \\\n  \
             nerve_setup_input((setup), (name), T##_TYPE_NAME, sizeof(T), NERVE_ALIGNOF(T), T##_FINGERPRINT, (port))\n\
             /* Declares output NAME of payload struct T on SETUP (in `init`), handle in *PORT. */\n\
             #define NERVE_SETUP_OUTPUT(setup, name, T, port) \\\n  \
             nerve_setup_output((setup), (name), T##_TYPE_NAME, sizeof(T), NERVE_ALIGNOF(T), T##_FINGERPRINT, (port))\n\n\
             /* Your own payload struct S, for nerve_setup_input_type/nerve_setup_output_type:\n \
             *   static const nerve_field reading_fields[] = {\n \
             *       NERVE_FIELD(reading, value, NERVE_F64), NERVE_FIELD_ARRAY(reading, samples, NERVE_F32)};\n \
             *   static const nerve_type reading_type = NERVE_TYPE(reading, \"lab::Reading\", reading_fields);\n \
             * Field names, types and order as the Rust or Python type of that name has them. */\n\
             #define NERVE_FIELD(S, field, primitive) {#field, (primitive), offsetof(S, field), 0}\n\
             #define NERVE_FIELD_ARRAY(S, field, primitive) \\\n  \
             {#field, (primitive), offsetof(S, field), sizeof(((S *)0)->field) / sizeof(((S *)0)->field[0])}\n\
             #define NERVE_TYPE(S, name, fields) {(name), sizeof(S), NERVE_ALIGNOF(S), (fields), sizeof(fields) / sizeof((fields)[0])}\n\n\
             /* A built-in payload struct T of this header as a nerve_type, for the parts of a\n \
             * sequence or a call (nerve_setup_output_seq, nerve_setup_serve):\n \
             *   static const nerve_type tick_type = NERVE_BUILTIN(nerve_Tick);\n \
             * and a primitive by its Rust name: NERVE_BUILTIN_PRIMITIVE(uint8_t, \"u8\"). */\n\
             #define NERVE_BUILTIN(T) {T##_TYPE_NAME, sizeof(T), NERVE_ALIGNOF(T), NULL, 0}\n\
             #define NERVE_BUILTIN_PRIMITIVE(C, name) {(name), sizeof(C), NERVE_ALIGNOF(C), NULL, 0}\n\n",
        ),
        done: BTreeSet::new(),
    };
    let mut payloads = Vec::new();
    for type_name in shm_schemas::payloads::known_type_names() {
        let s = built_in_named(type_name).expect("every known type has a schema");
        if !matches!(s.kind, Kind::Struct { .. }) {
            // a variable-size payload: the C API has no port for one yet
            let _ = writeln!(g.out, "/* {type_name}: not a fixed-size struct, not in this header yet */\n");
            continue;
        }
        let name = g.structure(&s);
        let m = c_macro(&name);
        let _ = write!(
            g.out,
            "#define {name}_TYPE_NAME \"{type_name}\"\n#define {name}_FINGERPRINT UINT64_C({:#018x})\n\
             #define {m}_FINGERPRINT {name}_FINGERPRINT\n\n",
            s.fingerprint()
        );
        payloads.push(name);
    }
    g.out.push_str("/* X(T) for every built-in payload type T. */\n#define NERVE_BUILTIN_PAYLOADS(X)");
    for p in &payloads {
        let _ = write!(g.out, " \\\n  X({p})");
    }
    g.out.push_str("\n\n#endif /* NERVE_TYPES_H */\n");
    g.out
}

fn header_path() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("include").join("nerve_types.h")
}

#[test]
fn the_committed_types_header_is_the_generated_one() {
    let generated = generate();
    let path = header_path();
    if std::env::var_os("NERVE_BLESS").is_some() {
        std::fs::write(&path, &generated).expect("write include/nerve_types.h");
        return;
    }
    let committed = std::fs::read_to_string(&path).unwrap_or_default();
    assert!(
        committed == generated,
        "{} is not what the schemas of shm-schemas make now: regenerate it with \
         NERVE_BLESS=1 cargo nextest run -p nerve-agent-c -E 'test(types_header)' and commit it",
        path.display()
    );
}

/// The committed header compiles as C11 (gcc) and C++17 (g++), with
/// `nerve.h` before it: every size, alignment and offset nerve's schemas
/// give is this compiler's too (a wrong one fails a static assert).
#[test]
fn the_types_header_compiles_as_c_and_cpp_with_the_schemas_layout() {
    let include = header_path().parent().expect("include/").to_path_buf();
    for (compiler, std, lang) in [("gcc", "-std=c11", "c"), ("g++", "-std=c++17", "c++")] {
        let mut child = Command::new(compiler)
            .args([std, "-Wall", "-Wextra", "-Werror", "-pedantic", "-fsyntax-only", "-x", lang, "-I"])
            .arg(&include)
            .arg("-")
            .stdin(std::process::Stdio::piped())
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap_or_else(|e| panic!("run {compiler} (scripts/setup.sh --test installs it): {e}"));
        let src = "#include \"nerve.h\"\n#include \"nerve_types.h\"\n\
                   #define CHECK(T) NERVE_STATIC_ASSERT(sizeof(T##_TYPE_NAME) > 1 && T##_FINGERPRINT != 0, #T);\n\
                   NERVE_BUILTIN_PAYLOADS(CHECK)\nint main(void) { return 0; }\n";
        std::io::Write::write_all(child.stdin.as_mut().expect("stdin"), src.as_bytes()).expect("write the source");
        drop(child.stdin.take());
        let out = child.wait_with_output().expect("wait for the compiler");
        assert!(out.status.success(), "{compiler} refused nerve_types.h: {}", String::from_utf8_lossy(&out.stderr));
    }
}
