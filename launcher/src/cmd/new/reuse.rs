//! The features a new project must ask of its dependencies so that cargo
//! reuses nerve's build of them. Cargo reuses a compiled crate only when
//! its version, profile and features are the same; a project outside
//! nerve's workspace resolves the features of its (fewer) dependencies
//! alone, so `syn` lacks `fold`, `tracing-subscriber` lacks `json`, and
//! those crates, and every crate above them (iceoryx2 among them), would be
//! compiled again. `nerve new` reads the features of both builds from
//! `cargo tree` (target and host sides apart: build scripts and proc-macros
//! get their own) and pins nerve's in the project: the target side's in
//! `[dependencies]`, the host side's in `[build-dependencies]`, repeated
//! until the two agree (a pinned feature can bring in one more crate).

use anyhow::{Context as _, Result, bail};
use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

/// A package, as `cargo tree` names it: `syn v2.0.119`.
type Package = String;

/// Features per package, on the target side and on the host side (build
/// scripts, proc-macros and what they use).
#[derive(Debug, Default, Clone, PartialEq, Eq)]
pub(super) struct Sides {
    pub target: BTreeMap<Package, BTreeSet<String>>,
    pub host: BTreeMap<Package, BTreeSet<String>>,
}

/// The features of every crates.io package built for the project (or, with
/// `workspace`, for nerve's whole workspace with its tests), from `cargo
/// tree`, offline.
pub(super) fn features(dir: &Path, workspace: bool) -> Result<Sides> {
    let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
    let mut c = std::process::Command::new(cargo);
    c.args(["tree", "--offline", "-e", "normal,build,dev", "-f", "{p}|{f}"]).current_dir(dir);
    if workspace {
        c.arg("--workspace");
    }
    let out = c.output().with_context(|| format!("cannot run `cargo tree` in {}", dir.display()))?;
    if !out.status.success() {
        bail!(
            "`cargo tree` failed in {} (offline: are nerve's dependencies downloaded?): {}",
            dir.display(),
            String::from_utf8_lossy(&out.stderr).trim()
        );
    }
    Ok(parse_tree(&String::from_utf8_lossy(&out.stdout)))
}

/// Parses `cargo tree -e normal,build,dev -f '{p}|{f}'` (indented). A node
/// is on the host side when it is a proc-macro, sits under a
/// `[build-dependencies]` header, or under a host node. Path packages
/// (nerve's own crates, the project) are left out: cargo compiles them
/// again anyway.
pub(super) fn parse_tree(text: &str) -> Sides {
    let mut sides = Sides::default();
    // by depth: whether the last node there is on the host side, and
    // whether the nodes that follow at that depth are build-dependencies
    let mut host_at: Vec<bool> = Vec::new();
    let mut build_header: Vec<bool> = Vec::new();
    for line in text.lines() {
        let start = line.find(|c: char| !matches!(c, '│' | '├' | '└' | '─' | ' ' | '\u{a0}'));
        let Some(start) = start else { continue };
        let depth = line[..start].chars().count() / 4;
        let body = &line[start..];
        if body.starts_with('[') {
            set(&mut build_header, depth + 1, body.starts_with("[build-dependencies]"));
            continue;
        }
        set(&mut build_header, depth + 1, false);
        let Some((package, features)) =
            body.replace(" (*)", "").split_once('|').map(|(p, f)| (p.to_owned(), f.to_owned()))
        else {
            continue;
        };
        let macro_ = package.contains("(proc-macro)");
        let package = package.replace(" (proc-macro)", "").trim().to_owned();
        let host = macro_
            || (depth > 0
                && (host_at.get(depth - 1).copied().unwrap_or(false)
                    || build_header.get(depth).copied().unwrap_or(false)));
        set(&mut host_at, depth, host);
        if package.contains(" (") {
            continue; // a path (or git) package
        }
        let features: BTreeSet<String> = features.split(',').filter(|f| !f.is_empty()).map(str::to_owned).collect();
        let side = if host { &mut sides.host } else { &mut sides.target };
        side.entry(package).or_default().extend(features);
    }
    sides
}

fn set(v: &mut Vec<bool>, at: usize, value: bool) {
    if v.len() <= at {
        v.resize(at + 1, false);
    }
    v[at] = value;
}

/// The packages whose features in `project` differ from `nerve`'s, with
/// nerve's features: what to pin. Packages nerve does not build are left
/// as they are (nothing of nerve's to reuse).
pub(super) fn differences(nerve: &Sides, project: &Sides) -> Sides {
    let diff = |ours: &BTreeMap<Package, BTreeSet<String>>, theirs: &BTreeMap<Package, BTreeSet<String>>| {
        ours.iter()
            .filter_map(|(p, f)| theirs.get(p).filter(|t| *t != f).map(|t| (p.clone(), t.clone())))
            .collect::<BTreeMap<_, _>>()
    };
    Sides { target: diff(&project.target, &nerve.target), host: diff(&project.host, &nerve.host) }
}

/// The pins as `Cargo.toml` lines: `name = { version = "=X.Y.Z",
/// default-features = false, features = [...] }`, renamed `name-MAJOR`
/// (`name-0-MINOR`) when two versions of one crate are pinned.
pub(super) fn lines(pins: &BTreeMap<Package, BTreeSet<String>>) -> String {
    let split = |p: &str| {
        let (name, version) = p.split_once(' ').unwrap_or((p, ""));
        let version = version.trim_start_matches('v');
        (name.to_owned(), version.split('+').next().unwrap_or(version).to_owned())
    };
    let names: Vec<String> = pins.keys().map(|p| split(p).0).collect();
    let mut out = String::new();
    for (p, features) in pins {
        let (name, version) = split(p);
        let mut parts = version.split('.');
        let (major, minor) = (parts.next().unwrap_or("0"), parts.next().unwrap_or("0"));
        let key = if names.iter().filter(|n| **n == name).count() == 1 {
            name.clone()
        } else if major == "0" {
            format!("{name}-0-{minor}")
        } else {
            format!("{name}-{major}")
        };
        let package = if key == name { String::new() } else { format!("package = \"{name}\", ") };
        let features: Vec<String> = features.iter().map(|f| format!("\"{f}\"")).collect();
        out.push_str(&format!(
            "{key} = {{ {package}version = \"={version}\", default-features = false, features = [{}] }}\n",
            features.join(", ")
        ));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    const TREE: &str = "\
probe v0.1.0 (/tmp/probe)
├── agent-sdk v0.1.0 (/src/nerve/agent-sdk)
│   ├── libc v0.2.191|default,std
│   ├── serde v1.0.229|derive,std
│   │   └── serde_derive v1.0.229 (proc-macro)|default
│   │       └── syn v2.0.119|full,parsing
│   └── flatbuffers v25.12.19|
│       └── bitflags v2.13.2|
│       [build-dependencies]
│       └── rustc_version v0.4.1|
│           └── semver v1.0.28|default,std
└── bitflags v2.13.2| (*)
[dev-dependencies]
└── either v1.19.0|std
";

    #[test]
    fn the_tree_splits_into_target_and_host_sides() {
        let s = parse_tree(TREE);
        let names = |m: &BTreeMap<Package, BTreeSet<String>>| m.keys().cloned().collect::<Vec<_>>();
        assert_eq!(
            names(&s.target),
            ["bitflags v2.13.2", "either v1.19.0", "flatbuffers v25.12.19", "libc v0.2.191", "serde v1.0.229"]
        );
        assert_eq!(names(&s.host), ["rustc_version v0.4.1", "semver v1.0.28", "serde_derive v1.0.229", "syn v2.0.119"]);
        assert_eq!(s.host["syn v2.0.119"].iter().collect::<Vec<_>>(), ["full", "parsing"]);
        assert!(s.target["bitflags v2.13.2"].is_empty());
    }

    #[test]
    fn only_differing_packages_are_pinned_with_nerves_features() {
        let f = |l: &[&str]| l.iter().map(|s| (*s).to_owned()).collect::<BTreeSet<_>>();
        let mut nerve = Sides::default();
        nerve.target.insert("a v1.0.0".into(), f(&["std", "json"]));
        nerve.target.insert("b v1.0.0".into(), f(&["std"]));
        nerve.host.insert("syn v2.0.1".into(), f(&["full", "fold"]));
        let mut project = Sides::default();
        project.target.insert("a v1.0.0".into(), f(&["std"]));
        project.target.insert("b v1.0.0".into(), f(&["std"]));
        project.target.insert("mine v3.0.0".into(), f(&[]));
        project.host.insert("syn v2.0.1".into(), f(&["full"]));
        let d = differences(&nerve, &project);
        assert_eq!(d.target.keys().collect::<Vec<_>>(), ["a v1.0.0"]);
        assert_eq!(d.host["syn v2.0.1"], f(&["fold", "full"]));
        assert!(differences(&nerve, &nerve).target.is_empty());
    }

    #[test]
    fn two_versions_of_a_crate_get_names_of_their_own() {
        let mut pins = BTreeMap::new();
        pins.insert("syn v2.0.119".to_owned(), ["full".to_owned()].into_iter().collect());
        pins.insert("syn v3.0.9".to_owned(), BTreeSet::new());
        pins.insert("toml v0.9.12+spec-1.1.0".to_owned(), ["std".to_owned()].into_iter().collect());
        let text = lines(&pins);
        assert!(
            text.contains(
                r#"syn-2 = { package = "syn", version = "=2.0.119", default-features = false, features = ["full"] }"#
            ),
            "{text}"
        );
        assert!(
            text.contains(
                r#"syn-3 = { package = "syn", version = "=3.0.9", default-features = false, features = [] }"#
            ),
            "{text}"
        );
        assert!(
            text.contains(r#"toml = { version = "=0.9.12", default-features = false, features = ["std"] }"#),
            "{text}"
        );
        let parsed: toml::Table = toml::from_str(&text).expect("valid TOML");
        assert_eq!(parsed.len(), 3);
    }
}
