//! Computes the RIHS01 type hash (REP-2016) of every vendored message in
//! `msg/<package>/<Name>.msg` and writes them to `$OUT_DIR/type_hashes.rs`
//! as `TYPE_HASHES: &[(&str, &str)]`, sorted by type name; and the full
//! `ros2msg` definition of each (its text, then each message it uses, as
//! rosbag2 writes them in a bag's schemas) as `MSG_DEFINITIONS`.

#[allow(dead_code)]
#[path = "src/idl.rs"]
mod idl;

use std::collections::BTreeMap;
use std::path::Path;

fn main() {
    println!("cargo:rerun-if-changed=msg");
    println!("cargo:rerun-if-changed=src/idl.rs");
    let root = Path::new("msg");
    let mut defs = BTreeMap::new();
    let mut texts: BTreeMap<String, String> = BTreeMap::new();
    let mut packages: Vec<_> = std::fs::read_dir(root)
        .unwrap_or_else(|e| panic!("agents/ros2/msg: {e}"))
        .filter_map(Result::ok)
        .map(|e| e.path())
        .filter(|p| p.is_dir())
        .collect();
    packages.sort();
    for dir in packages {
        println!("cargo:rerun-if-changed={}", dir.display());
        let package = dir.file_name().and_then(|s| s.to_str()).unwrap_or_default().to_owned();
        for entry in std::fs::read_dir(&dir).unwrap_or_else(|e| panic!("{}: {e}", dir.display())).filter_map(Result::ok)
        {
            let path = entry.path();
            if path.extension().and_then(|s| s.to_str()) != Some("msg") {
                continue;
            }
            let name = path.file_stem().and_then(|s| s.to_str()).unwrap_or_default().to_owned();
            let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
            let def = idl::parse_msg(&package, &name, &text).unwrap_or_else(|e| panic!("{e}"));
            texts.insert(def.type_name.clone(), text);
            defs.insert(def.type_name.clone(), def);
        }
    }
    let mut out = String::from(
        "/// `(type name, RIHS01 hash)` of every vendored message, sorted by name (build.rs).\npub const TYPE_HASHES: &[(&str, &str)] = &[\n",
    );
    for name in defs.keys() {
        let hash = idl::rihs01(name, &defs).unwrap_or_else(|e| panic!("{e}"));
        out.push_str(&format!("    ({name:?}, {hash:?}),\n"));
    }
    out.push_str("];\n");
    out.push_str(
        "/// `(type name, ros2msg definition)` of every vendored message, sorted by name (build.rs): its text, then each message it uses (depth first, once) after a line of 80 `=` and `MSG: pkg/Name`, as rosbag2 writes a bag's schemas.\npub const MSG_DEFINITIONS: &[(&str, &str)] = &[\n",
    );
    for name in defs.keys() {
        let mut used = Vec::new();
        uses(name, &defs, &mut used);
        let mut full = texts[name].trim_end().to_owned();
        full.push('\n');
        for dep in used.iter().filter(|d| *d != name) {
            full.push_str(&"=".repeat(80));
            full.push_str(&format!("\nMSG: {}\n", dep.replace("/msg/", "/")));
            full.push_str(texts[dep].trim_end());
            full.push('\n');
        }
        out.push_str(&format!("    ({name:?}, {full:?}),\n"));
    }
    out.push_str("];\n");
    let dest = Path::new(&std::env::var("OUT_DIR").unwrap_or_else(|e| panic!("OUT_DIR: {e}"))).join("type_hashes.rs");
    std::fs::write(&dest, out).unwrap_or_else(|e| panic!("{}: {e}", dest.display()));
}

/// `root` and the messages it uses, depth first, each once, in `out`.
fn uses(root: &str, defs: &BTreeMap<String, idl::MsgDef>, out: &mut Vec<String>) {
    if out.iter().any(|d| d == root) {
        return;
    }
    out.push(root.to_owned());
    let Some(def) = defs.get(root) else { panic!("{root} is used but not vendored in agents/ros2/msg") };
    for f in &def.fields {
        if let idl::Base::Nested(n) = &f.base {
            uses(n, defs, out);
        }
    }
}
