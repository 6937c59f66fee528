//! `nerve types [NAME]`: every payload type known to the robot and to this
//! build, with its fields, offsets, sizes, units where the field's name says
//! them, and its layout fingerprint — what `ros2 interface show` is to ROS 2.
//!
//! Two sources: the built-in payloads this build of nerve has
//! (`shm_schemas::for_each_payload!`), and the schemas the agents of the
//! robot registered with its router (a Python agent's or a team's own type),
//! when a router runs. A type registered with another layout than the
//! built-in one of its name (a stale build) is listed once per layout, so the
//! difference shows.

use crate::client::RouterSession;
use crate::cmd::inspect::emit;
use agent_sdk::World;
use anyhow::{Result, bail};
use serde_json::{Value, json};
use shm_schemas::control::cli_to_router::{CliRequest, RouterReply};
use shm_schemas::schema::{Described, Kind};
use shm_schemas::{Payload, Schema};
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::process::ExitCode;

/// `nerve types`
#[derive(Debug, clap::Args)]
pub struct TypesArgs {
    /// One type's whole layout (`nerve::Odometry`, or `Odometry` for a
    /// built-in one); without it, the list of every type.
    pub name: Option<String>,
    /// Print JSON instead of text.
    #[arg(long)]
    pub json: bool,
    /// Print the built-in types as the Markdown tables of docs/payloads.md.
    #[arg(long, conflicts_with_all = ["json", "name"])]
    pub markdown: bool,
}

/// A type and where it was seen.
struct Known {
    schema: Schema,
    /// "built-in", or the agent/port names that registered it
    sources: Vec<String>,
}

/// Every type of this build and of the robot's running agents, by name and
/// fingerprint.
fn gather(world: &World) -> (Vec<Known>, Option<String>) {
    let mut known: BTreeMap<(String, u64), Known> = BTreeMap::new();
    macro_rules! builtin {
        ($t:ty) => {
            let s = <$t as Described>::schema();
            known.insert(
                (s.type_name.clone(), <$t as Payload>::layout_fingerprint()),
                Known { schema: s, sources: vec!["built-in".into()] },
            );
        };
    }
    shm_schemas::for_each_payload!(builtin);
    let note = match RouterSession::open(world).and_then(|s| s.call(CliRequest::Ps)) {
        Ok(RouterReply::Agents(agents)) => {
            for a in &agents {
                for p in a.outputs.iter().chain(&a.inputs) {
                    let Some(schema) = a.schema_for(p.fingerprint) else { continue };
                    let e = known
                        .entry((p.type_name.clone(), p.fingerprint))
                        .or_insert_with(|| Known { schema, sources: Vec::new() });
                    let who = format!("{}/{}", a.name, p.name);
                    if !e.sources.contains(&who) {
                        e.sources.push(who);
                    }
                }
            }
            None
        }
        Ok(_) => Some("the router's answer was not a list of agents: built-in types only".to_owned()),
        Err(_) => Some(format!("no router runs on robot {}: built-in types only", world.robot())),
    };
    (known.into_values().collect(), note)
}

/// The unit a field's name says, by nerve's naming conventions
/// (docs/payloads.md): a suffix (`range_m`, `stamp_ns`, `bearing_rad`), or
/// one of the pose and velocity names every payload uses alike.
pub fn unit_of(field: &str) -> Option<&'static str> {
    const SUFFIXES: [(&str, &str); 9] = [
        ("_ns", "ns"),
        ("_us", "µs"),
        ("_ms", "ms"),
        ("_rad", "rad"),
        ("_m", "m"),
        ("_mm", "mm"),
        ("_bytes", "bytes"),
        ("_percent", "%"),
        ("_hz", "Hz"),
    ];
    match field {
        "x" | "y" => return Some("m"),
        "theta" => return Some("rad"),
        "v" => return Some("m/s"),
        "omega" => return Some("rad/s"),
        _ => {}
    }
    SUFFIXES.iter().find(|(s, _)| field.ends_with(s)).map(|(_, u)| *u)
}

/// The fields of `schema`, as JSON, recursively.
fn fields_json(schema: &Schema) -> Value {
    match &schema.kind {
        Kind::Struct { fields } => Value::Array(
            fields
                .iter()
                .map(|f| {
                    json!({
                        "name": f.name, "offset": f.offset, "size": f.schema.size,
                        "type": f.schema.type_name, "unit": unit_of(&f.name),
                        "fields": fields_json(&f.schema),
                    })
                })
                .collect(),
        ),
        Kind::Array { element, .. } => fields_json(element),
        _ => Value::Array(Vec::new()),
    }
}

/// The layout as indented text, one field a line: offset, size, type, name, unit.
fn tree(schema: &Schema, base: usize, depth: usize, out: &mut String) {
    let fields = match &schema.kind {
        Kind::Struct { fields } => fields,
        Kind::Array { element, .. } => return tree(element, base, depth, out),
        _ => return,
    };
    for f in fields {
        let unit = unit_of(&f.name).map(|u| format!("  [{u}]")).unwrap_or_default();
        let at = base.saturating_add(f.offset);
        let _ = writeln!(
            out,
            "  {at:>6}  {:>6}  {}{}: {}{unit}",
            f.schema.size,
            "  ".repeat(depth),
            f.name,
            f.schema.type_name
        );
        // the element of an array is shown at the array's first slot
        tree(&f.schema, at, depth + 1, out);
    }
}

fn to_json(k: &Known) -> Value {
    json!({
        "type_name": k.schema.type_name,
        "size": k.schema.size,
        "align": k.schema.align,
        "fingerprint": format!("{:#018x}", k.schema.fingerprint()),
        "sources": k.sources,
        "fields": fields_json(&k.schema),
        "schema": k.schema,
    })
}

pub fn types(world: &World, a: TypesArgs) -> Result<ExitCode> {
    if a.markdown {
        emit(&builtin_markdown())?;
        return Ok(ExitCode::SUCCESS);
    }
    let (known, note) = gather(world);
    if let Some(n) = &note {
        eprintln!("note: {n}");
    }
    let Some(name) = &a.name else {
        if a.json {
            emit(&format!("{}\n", serde_json::to_string_pretty(&known.iter().map(to_json).collect::<Vec<_>>())?))?;
        } else {
            let mut out = format!("{:<28} {:>7}  {:<18}  {:>6}  SEEN ON\n", "TYPE", "SIZE", "FINGERPRINT", "FIELDS");
            for k in &known {
                let n = match &k.schema.kind {
                    Kind::Struct { fields } => fields.len(),
                    _ => 0,
                };
                let _ = writeln!(
                    out,
                    "{:<28} {:>7}  {:#018x}  {n:>6}  {}",
                    k.schema.type_name,
                    k.schema.size,
                    k.schema.fingerprint(),
                    k.sources.join(", ")
                );
            }
            out.push_str("(`nerve types NAME` shows a type's fields)\n");
            emit(&out)?;
        }
        return Ok(ExitCode::SUCCESS);
    };
    let wanted = |t: &str| t == name || t.strip_prefix("nerve::") == Some(name.as_str());
    let found: Vec<&Known> = known.iter().filter(|k| wanted(&k.schema.type_name)).collect();
    if found.is_empty() {
        let lower = name.to_ascii_lowercase();
        let close: Vec<&str> = known
            .iter()
            .map(|k| k.schema.type_name.as_str())
            .filter(|t| t.to_ascii_lowercase().contains(&lower))
            .collect();
        if close.is_empty() {
            bail!("no type named {name:?} is known to this build or the robot's agents; `nerve types` lists them");
        }
        bail!("no type named {name:?}; did you mean {}?", close.join(", "));
    }
    if a.json {
        let v: Vec<Value> = found.iter().map(|k| to_json(k)).collect();
        emit(&format!("{}\n", serde_json::to_string_pretty(&v)?))?;
        return Ok(ExitCode::SUCCESS);
    }
    let mut out = String::new();
    if found.len() > 1 {
        let _ = writeln!(out, "{} layouts of {name} are in use: the agents' builds differ\n", found.len());
    }
    for k in found {
        let _ = writeln!(
            out,
            "{}  (size {} B, align {}, fingerprint {:#018x}; {})",
            k.schema.type_name,
            k.schema.size,
            k.schema.align,
            k.schema.fingerprint(),
            k.sources.join(", ")
        );
        let _ = writeln!(out, "  {:>6}  {:>6}  FIELD: TYPE  [UNIT]", "OFFSET", "SIZE");
        tree(&k.schema, 0, 0, &mut out);
        out.push('\n');
    }
    emit(&out)?;
    Ok(ExitCode::SUCCESS)
}

/// The table of every built-in payload for `docs/payloads.md` (kept
/// current by a test): a section per type with its fields, offsets, sizes
/// and units.
pub fn builtin_markdown() -> String {
    let mut all: Vec<Schema> = Vec::new();
    macro_rules! push {
        ($t:ty) => {
            all.push(<$t as Described>::schema());
        };
    }
    shm_schemas::for_each_payload!(push);
    all.sort_by(|a, b| a.type_name.cmp(&b.type_name));
    let mut out = String::new();
    let _ = writeln!(out, "| type | size (B) | fingerprint | fields |\n|---|---:|---|---|");
    for s in &all {
        let names = match &s.kind {
            Kind::Struct { fields } => fields.iter().map(|f| f.name.as_str()).collect::<Vec<_>>().join(", "),
            _ => String::new(),
        };
        let _ = writeln!(out, "| `{}` | {} | `{:#018x}` | {names} |", s.type_name, s.size, s.fingerprint());
    }
    for s in &all {
        let _ = writeln!(
            out,
            "\n### `{}`\n\n| offset | size | field | type | unit |\n|---:|---:|---|---|---|",
            s.type_name
        );
        fn rows(schema: &Schema, base: usize, prefix: &str, out: &mut String) {
            let fields = match &schema.kind {
                Kind::Struct { fields } => fields,
                Kind::Array { element, .. } => return rows(element, base, &format!("{prefix}[i]."), out),
                _ => return,
            };
            for f in fields {
                let at = base.saturating_add(f.offset);
                let unit = unit_of(&f.name).unwrap_or("");
                let _ = writeln!(
                    out,
                    "| {at} | {} | `{prefix}{}` | `{}` | {unit} |",
                    f.schema.size, f.name, f.schema.type_name
                );
                if matches!(f.schema.kind, Kind::Struct { .. })
                    || matches!(&f.schema.kind, Kind::Array { element, .. } if matches!(element.kind, Kind::Struct { .. }))
                {
                    rows(&f.schema, at, &format!("{prefix}{}.", f.name), out);
                }
            }
        }
        rows(s, 0, "", &mut out);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// docs/payloads.md lists the built-in types as this build has them:
    /// `NERVE_BLESS=1` rewrites the section after a change of a payload.
    #[test]
    fn the_table_of_built_in_types_in_the_docs_is_current() {
        const BEGIN: &str = "<!-- built-in types: generated by `nerve types`' test; NERVE_BLESS=1 rewrites it -->\n";
        const END: &str = "<!-- end of built-in types -->";
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/payloads.md");
        let doc = std::fs::read_to_string(&path).expect("docs/payloads.md");
        let (Some(b), Some(e)) = (doc.find(BEGIN), doc.find(END)) else {
            panic!("docs/payloads.md lacks the markers of the generated section")
        };
        let want = builtin_markdown();
        let have = &doc[b + BEGIN.len()..e];
        if have != want {
            if std::env::var_os("NERVE_BLESS").is_some() {
                let new = format!("{}{want}{}", &doc[..b + BEGIN.len()], &doc[e..]);
                std::fs::write(&path, new).expect("write docs/payloads.md");
            } else {
                panic!(
                    "docs/payloads.md's table of built-in types is stale: run `NERVE_BLESS=1 cargo nextest run -p nerve -E 'test(the_table_of_built_in)'`"
                );
            }
        }
    }

    #[test]
    fn units_follow_the_field_names() {
        assert_eq!(unit_of("range_m"), Some("m"));
        assert_eq!(unit_of("ranges_m"), Some("m"));
        assert_eq!(unit_of("stamp_ns"), Some("ns"));
        assert_eq!(unit_of("bearing_rad"), Some("rad"));
        assert_eq!(unit_of("omega"), Some("rad/s"));
        assert_eq!(unit_of("seq"), None);
        assert_eq!(unit_of("rss_bytes"), Some("bytes"));
    }

    #[test]
    fn a_tree_shows_nested_fields_at_their_offsets() {
        let s = <shm_schemas::payloads::SonarScan as Described>::schema();
        let mut out = String::new();
        tree(&s, 0, 0, &mut out);
        assert!(out.contains("ranges_m: [f32; 12]  [m]"), "{out}");
        assert!(out.lines().count() >= 3, "{out}");
    }
}
