//! `nerve new NAME`: a ready agent project outside nerve's workspace, as
//! `cargo new` makes a crate: the agent (one input, one output, one checked
//! parameter, periodic or event-driven), tests of its algorithm, a launch
//! file that wires it to a ticker, a README. `cargo test`, `cargo build` and
//! `nerve launch launch.toml` work on it as made. `--lang python` makes a
//! Python agent on the `nerve` package instead (an executable script, its
//! `unittest` tests, a launch file, a README). `--lang c` and `--lang cpp`
//! make a CMake project on nerve's C API ([`native`]). The templates are
//! `launcher/templates/{rust,python}/*.in` and `new/native/*.in`, built
//! into the `nerve` program.
//!
//! A Rust project's first `cargo test` reuses what nerve's own build
//! compiled: it builds into nerve's target folder (`.cargo/config.toml`),
//! with nerve's `Cargo.lock`, nerve's profiles (copied from its root
//! `Cargo.toml`) and the features nerve's workspace builds its dependencies
//! with. Only nerve's own crates it uses (their package ids name another
//! workspace) and the agent are compiled. `--own-target` builds in the
//! project's `./target` instead, compiling everything once.

mod native;
mod reuse;

use anyhow::{Context as _, Result, bail};
use shm_schemas::AgentName;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

/// `nerve new`
#[derive(Debug, clap::Args)]
pub struct NewArgs {
    /// The agent's name: its folder, crate, executable, kind and name in the
    /// launch file (lowercase letters, digits and `-`, starting with a letter).
    pub name: String,
    /// A periodic agent, run every PERIOD (10ms, 1s, 100hz) on the newest input.
    #[arg(long, value_name = "PERIOD", conflicts_with = "event")]
    pub periodic: Option<String>,
    /// An event-driven agent, woken by every input sample (the default).
    #[arg(long)]
    pub event: bool,
    /// The language of the agent.
    #[arg(long, value_enum, default_value_t = Lang::Rust)]
    pub lang: Lang,
    /// Where to make the project: DIR/NAME (default: the current folder).
    #[arg(long, value_name = "DIR")]
    pub dir: Option<PathBuf>,
    /// nerve's source tree, which the project depends on by path (default:
    /// the one this `nerve` was built from).
    #[arg(long, value_name = "PATH", env = "NERVE_SRC")]
    pub nerve_src: Option<PathBuf>,
    /// Build in the project's own `./target` instead of nerve's target
    /// folder: nothing nerve compiled is reused, so the first build compiles
    /// iceoryx2 and every other dependency (minutes).
    #[arg(long)]
    pub own_target: bool,
}

/// The language of a new agent.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Lang {
    /// A Rust crate on nerve's agent SDK.
    Rust,
    /// A Python agent on the `nerve` Python package (`python/`).
    Python,
    /// A C agent on libnerve (`agent-sdk-c/`), built with CMake.
    C,
    /// A C++17 agent on `nerve.hpp` over libnerve, built with CMake.
    Cpp,
}

const CARGO_TOML: &str = include_str!("../../templates/rust/Cargo.toml.in");
const MAIN_RS: &str = include_str!("../../templates/rust/main.rs.in");
const LAUNCH_TOML: &str = include_str!("../../templates/rust/launch.toml.in");
const README_MD: &str = include_str!("../../templates/rust/README.md.in");
const GITIGNORE: &str = include_str!("../../templates/rust/gitignore.in");
const PY_AGENT: &str = include_str!("../../templates/python/agent.py.in");
const PY_TEST: &str = include_str!("../../templates/python/test_agent.py.in");
const PY_LAUNCH_TOML: &str = include_str!("../../templates/python/launch.toml.in");
const PY_README_MD: &str = include_str!("../../templates/python/README.md.in");
const PY_GITIGNORE: &str = include_str!("../../templates/python/gitignore.in");

/// Names the generated code already uses: a struct of one of these names
/// would clash, so it gets `Agent` appended.
const TAKEN: [&str; 9] = ["Agent", "AgentError", "Context", "Input", "Output", "Param", "Setup", "Task", "Tick"];

/// How the new agent's task is driven.
#[derive(Debug, Clone, PartialEq, Eq)]
enum Drive {
    Event,
    /// the period as written, and as a duration
    Periodic(String, std::time::Duration),
}

pub fn new(a: NewArgs) -> Result<ExitCode> {
    check_name(&a.name)?;
    let drive = match &a.periodic {
        Some(p) => {
            let d = agent_sdk::clock::parse_duration(p).map_err(anyhow::Error::msg).context("--periodic")?;
            Drive::Periodic(p.clone(), d)
        }
        None => Drive::Event,
    };
    let dir = a.dir.clone().unwrap_or_else(|| PathBuf::from("."));
    let root = dir.join(&a.name);
    if root.exists() {
        bail!("{} already exists; choose another name, or another folder with --dir", root.display());
    }
    if a.lang == Lang::Python {
        return new_python(&a.name, &drive, &root);
    }
    if let Some(lang) = match a.lang {
        Lang::C => Some(native::Native::C),
        Lang::Cpp => Some(native::Native::Cpp),
        Lang::Rust | Lang::Python => None,
    } {
        let nerve = nerve_source(a.nerve_src.as_deref())?;
        let found = native::find(&nerve, &nerve_target(&nerve, a.nerve_src.is_some()));
        return native::new_native(&a.name, &drive, &root, lang, &nerve, &found);
    }
    let nerve = nerve_source(a.nerve_src.as_deref())?;
    let shared = if a.own_target { None } else { Some(nerve_target(&nerve, a.nerve_src.is_some())) };
    if let Some(t) = &shared {
        check_shared_name(&a.name, t)?;
    }
    let profiles = nerve_profiles(&nerve);
    let all_profiles = profiles_text(profiles.as_ref(), None);
    let mut files = render(&a.name, &drive, &nerve, "target/debug", &all_profiles, "");
    if let Some(t) = &shared {
        files.push((".cargo/config.toml".into(), cargo_config(&nerve, t)));
    }
    for (path, text) in &files {
        let p = root.join(path);
        if let Some(folder) = p.parent() {
            std::fs::create_dir_all(folder).with_context(|| format!("cannot create {}", folder.display()))?;
        }
        std::fs::write(&p, text).with_context(|| format!("cannot write {}", p.display()))?;
    }
    // the versions nerve is built and tested with, so that the first build
    // resolves nothing anew (and works offline when nerve has been built),
    // and reuses nerve's build of them
    let lock = nerve.join("Cargo.lock");
    if lock.is_file() {
        std::fs::copy(&lock, root.join("Cargo.lock")).with_context(|| format!("cannot copy {}", lock.display()))?;
    }
    let write_manifest = |profiles: &str, pins: &str| -> Result<()> {
        let rendered = render(&a.name, &drive, &nerve, "target/debug", profiles, pins);
        let text = rendered.iter().find(|(p, _)| p == "Cargo.toml").map(|(_, t)| t.as_str()).unwrap_or_default();
        let p = root.join("Cargo.toml");
        std::fs::write(&p, text).with_context(|| format!("cannot write {}", p.display()))
    };
    // nerve's features for the dependencies whose features differ here
    let pins = match &shared {
        Some(_) => match pin_features(&nerve, &root, |pins| write_manifest(&all_profiles, pins)) {
            Ok(pins) => pins,
            Err(error) => {
                println!(
                    "cannot read the features of nerve's build ({error:#}): the first build may compile some of \
                     nerve's dependencies again"
                );
                write_manifest(&all_profiles, "")?;
                String::new()
            }
        },
        None => String::new(),
    };
    let meta = metadata(&root);
    // the launch file's `exe` where this user's cargo will put the build:
    // nerve's target folder, CARGO_TARGET_DIR or a `build.target-dir` moves
    // it out of ./target; and nerve's profiles for the packages this
    // project builds only (cargo warns of every other one)
    let debug = meta.target.join("debug");
    let rendered = render(
        &a.name,
        &drive,
        &nerve,
        &debug.display().to_string(),
        &profiles_text(profiles.as_ref(), meta.packages.as_ref()),
        &pins,
    );
    for (path, text) in rendered.iter().filter(|(p, _)| p == "launch.toml" || p == "Cargo.toml") {
        let p = root.join(path);
        std::fs::write(&p, text).with_context(|| format!("cannot write {}", p.display()))?;
    }
    if debug != Path::new("target/debug") {
        println!("cargo builds into {}: launch.toml's exe is there", debug.display());
    }
    println!("made agent {} ({}) in {}:", a.name, drive_words(&drive), root.display());
    for (path, _) in &files {
        println!("  {path}");
    }
    println!(
        "next:\n  cd {}\n  cargo test\n  cargo build && nerve launch launch.toml\n  nerve echo {}/out --count 3",
        root.display(),
        a.name
    );
    Ok(ExitCode::SUCCESS)
}

/// `nerve new --lang python`: the agent as an executable script, its tests
/// (`python3 -m unittest`), a launch file and a README.
fn new_python(name: &str, drive: &Drive, root: &Path) -> Result<ExitCode> {
    let files = render_python(name, drive);
    std::fs::create_dir_all(root).with_context(|| format!("cannot create {}", root.display()))?;
    for (path, text) in &files {
        let p = root.join(path);
        std::fs::write(&p, text).with_context(|| format!("cannot write {}", p.display()))?;
    }
    // the agent is started as any agent is: an executable
    let script = root.join(format!("{}.py", module_name(name)));
    use std::os::unix::fs::PermissionsExt as _;
    std::fs::set_permissions(&script, std::fs::Permissions::from_mode(0o755))
        .with_context(|| format!("cannot make {} executable", script.display()))?;
    println!("made Python agent {name} ({}) in {}:", drive_words(drive), root.display());
    for (path, _) in &files {
        println!("  {path}");
    }
    println!(
        "next (with the Python that has the nerve package, see nerve's docs/python.md):\n  cd {}\n  python3 -m unittest\n  nerve launch launch.toml\n  nerve echo {name}/out --count 3",
        root.display()
    );
    Ok(ExitCode::SUCCESS)
}

fn drive_words(drive: &Drive) -> String {
    match drive {
        Drive::Event => "event-driven".to_owned(),
        Drive::Periodic(p, _) => format!("periodic, every {p}"),
    }
}

/// `gripper-driver` → `gripper_driver`: the Python module of the agent.
fn module_name(name: &str) -> String {
    name.replace('-', "_")
}

/// The Python project's files, by path in it.
fn render_python(name: &str, drive: &Drive) -> Vec<(String, String)> {
    let (what, period, step, period_line, task_words) = match drive {
        Drive::Event => (
            "an event-driven agent that sends every tick arriving on `in` on `out`, its sequence number multiplied by the parameter `gain`.".to_owned(),
            "None".to_owned(),
            "        # every waiting sample, read in place in shared memory\n        for tick in self.input.drain():\n            self.out.send(seq=transform(int(tick.seq), gain), stamp_ns=int(tick.stamp_ns))".to_owned(),
            String::new(),
            "event-driven: woken by every sample on `in`".to_owned(),
        ),
        Drive::Periodic(p, d) => (
            format!(
                "a periodic agent that, every {p}, sends the newest tick that arrived on `in` on `out`, its sequence number multiplied by the parameter `gain`."
            ),
            format!("{}  # seconds; `--period`, a launch file's `period` and `nerve rate` change it", d.as_secs_f64()),
            "        # the newest sample since the last cycle, if any\n        tick = self.input.latest()\n        if tick is not None:\n            self.out.send(seq=transform(int(tick.seq), gain), stamp_ns=int(tick.stamp_ns))".to_owned(),
            format!("period = \"{p}\"\n"),
            format!("periodic, every {p} by default"),
        ),
    };
    let module = module_name(name);
    let fill = |t: &str| {
        t.replace("{{what}}", &what)
            .replace("{{period}}", &period)
            .replace("{{step}}", &step)
            .replace("{{period_line}}", &period_line)
            .replace("{{task_words}}", &task_words)
            .replace("{{type}}", &type_name(name))
            .replace("{{module}}", &module)
            .replace("{{name}}", name)
    };
    vec![
        (format!("{module}.py"), fill(PY_AGENT)),
        (format!("test_{module}.py"), fill(PY_TEST)),
        ("launch.toml".into(), fill(PY_LAUNCH_TOML)),
        ("README.md".into(), fill(PY_README_MD)),
        (".gitignore".into(), fill(PY_GITIGNORE)),
    ]
}

/// An agent name that is also a Cargo package and executable name.
fn check_name(name: &str) -> Result<()> {
    let ok = name.chars().next().is_some_and(|c| c.is_ascii_lowercase())
        && name.chars().all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '-')
        && !name.ends_with('-');
    if !ok {
        bail!(
            "{name:?} cannot name an agent project: use lowercase letters, digits and `-`, starting with a letter (e.g. gripper-driver)"
        );
    }
    AgentName::new(name)?;
    Ok(())
}

/// nerve's source tree: given, or the one this program was built from.
fn nerve_source(given: Option<&Path>) -> Result<PathBuf> {
    let dir = match given {
        Some(d) => d.to_path_buf(),
        None => Path::new(env!("CARGO_MANIFEST_DIR")).join(".."),
    };
    let sdk = dir.join("agent-sdk").join("Cargo.toml");
    if !sdk.is_file() {
        bail!(
            "cannot find nerve's source tree at {} (no agent-sdk/Cargo.toml there); give it with --nerve-src PATH or NERVE_SRC",
            dir.display()
        );
    }
    dir.canonicalize().with_context(|| format!("cannot resolve {}", dir.display()))
}

/// The features nerve's build compiled the project's dependencies with,
/// for those whose features differ in the project, as the lines `Cargo.toml`
/// takes after its own dependencies (see [`reuse`]); `write` writes the
/// manifest with them, and they are read again until they agree (a pinned
/// feature may bring in one more crate).
fn pin_features(nerve: &Path, root: &Path, write: impl Fn(&str) -> Result<()>) -> Result<String> {
    let theirs = reuse::features(nerve, true)?;
    let mut pins = reuse::Sides::default();
    let mut text = String::new();
    for _ in 0..4 {
        let ours = reuse::features(root, false)?;
        let more = reuse::differences(&theirs, &ours);
        if more.target.is_empty() && more.host.is_empty() {
            tracing::debug!(
                target = pins.target.len(),
                host = pins.host.len(),
                "features pinned as nerve's build has them"
            );
            return Ok(text);
        }
        pins.target.extend(more.target);
        pins.host.extend(more.host);
        text = pins_text(&pins);
        write(&text)?;
    }
    bail!("the features of the project's dependencies still differ from nerve's after 4 rounds")
}

/// The pins, as `Cargo.toml` lines after the project's own dependencies.
fn pins_text(pins: &reuse::Sides) -> String {
    let mut out = String::from(
        "\n# The features nerve's build compiled these dependencies with, which\n\
         # `nerve new` read from `cargo tree`: cargo reuses nerve's build of a\n\
         # crate only when its features are the same, so keep them as they are\n\
         # (to use one of these crates, keep its line and add what you need).\n",
    );
    out.push_str(&reuse::lines(&pins.target));
    if !pins.host.is_empty() {
        out.push_str("\n# ... and of build scripts and proc-macros (the host side).\n[build-dependencies]\n");
        out.push_str(&reuse::lines(&pins.host));
    }
    out
}

/// The target folder of the nerve this project builds against, which holds
/// nerve's build of every dependency: the one this program was built in
/// (`.../target/debug/nerve`, a folder with cargo's `CACHEDIR.TAG`), unless
/// another source tree was given; else the tree's `target`.
fn nerve_target(nerve: &Path, src_given: bool) -> PathBuf {
    let built_in = std::env::current_exe()
        .ok()
        .and_then(|exe| exe.parent().and_then(Path::parent).map(Path::to_path_buf))
        .filter(|t| t.join("CACHEDIR.TAG").is_file());
    match built_in {
        Some(t) if !src_given => t,
        _ => nerve.join("target"),
    }
}

/// Folders cargo keeps in a profile's output folder: an executable of one of
/// these names cannot be written there.
const CARGO_FOLDERS: [&str; 4] = ["build", "deps", "examples", "incremental"];

/// A name whose executable, in nerve's target folder, would overwrite one of
/// nerve's own programs (`nerve`, `nerve-KIND`) or clash with cargo's folders.
fn check_shared_name(name: &str, target: &Path) -> Result<()> {
    if name == "nerve" || name.starts_with("nerve-") || CARGO_FOLDERS.contains(&name) {
        bail!(
            "{name:?} cannot name an agent that builds into nerve's target folder {}: its executable would \
             overwrite {}; choose another name (e.g. gripper-driver), or build in the project's own folder \
             with --own-target",
            target.display(),
            if CARGO_FOLDERS.contains(&name) { "cargo's folder of that name" } else { "one of nerve's programs" }
        );
    }
    Ok(())
}

/// `.cargo/config.toml`: the project builds into nerve's target folder.
fn cargo_config(nerve: &Path, target: &Path) -> String {
    let dir = toml::Value::String(target.display().to_string());
    format!(
        "# Made by `nerve new`: this project builds into the target folder of nerve\n\
         # ({nerve}), where cargo finds every dependency nerve's build compiled\n\
         # (iceoryx2 and the rest): the first `cargo test` compiles only nerve's\n\
         # crates that the agent uses, and the agent. `cargo clean` here would\n\
         # empty nerve's build too: use `cargo clean -p <this package>`. Delete\n\
         # this file to build in ./target instead (and change launch.toml's exe).\n\
         [build]\ntarget-dir = {dir}\n",
        nerve = nerve.display()
    )
}

/// nerve's `[profile]` table, from its root `Cargo.toml`; `None` (and a
/// warning) when it cannot be read.
fn nerve_profiles(nerve: &Path) -> Option<toml::Table> {
    let path = nerve.join("Cargo.toml");
    let read = std::fs::read_to_string(&path)
        .map_err(|e| e.to_string())
        .and_then(|text| text.parse::<toml::Table>().map_err(|e| e.to_string()));
    match read {
        Ok(mut t) => match t.remove("profile") {
            Some(toml::Value::Table(p)) => Some(p),
            _ => None,
        },
        Err(error) => {
            tracing::warn!(manifest = %path.display(), %error, "cannot read nerve's profiles; the project gets the defaults");
            None
        }
    }
}

/// The `[profile.*]` sections of the project: nerve's own, so that cargo
/// reuses nerve's build of the dependencies; of the per-package settings
/// only those of packages the project builds when `packages` is known.
/// Without nerve's profiles, the workspace's main settings.
fn profiles_text(profiles: Option<&toml::Table>, packages: Option<&std::collections::BTreeSet<String>>) -> String {
    const DEFAULT: &str =
        "[profile.dev]\nopt-level = 1\n\n[profile.dev.package.\"*\"]\nopt-level = 2\ndebug = \"line-tables-only\"\n";
    let Some(profiles) = profiles else { return DEFAULT.to_owned() };
    let mut profiles = profiles.clone();
    if let Some(packages) = packages {
        for (_, profile) in profiles.iter_mut() {
            if let Some(per) = profile.get_mut("package").and_then(toml::Value::as_table_mut) {
                let unused: Vec<String> =
                    per.keys().filter(|name| *name != "*" && !packages.contains(*name)).cloned().collect();
                for name in unused {
                    per.remove(&name);
                }
            }
        }
    }
    let mut top = toml::Table::new();
    top.insert("profile".into(), toml::Value::Table(profiles));
    toml::to_string(&top).unwrap_or_else(|error| {
        tracing::warn!(%error, "cannot write nerve's profiles; the project gets the defaults");
        DEFAULT.to_owned()
    })
}

/// What cargo says of the project at `root`.
#[derive(Debug)]
struct Meta {
    /// where it builds (see [`target_of`])
    target: PathBuf,
    /// the names of the packages it builds, when cargo could resolve them
    /// offline
    packages: Option<std::collections::BTreeSet<String>>,
}

/// `cargo metadata` of the project at `root`, offline: with its
/// dependencies resolved (the lock file nerve's), else without them.
fn metadata(root: &Path) -> Meta {
    let run = |extra: &[&str]| {
        let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
        std::process::Command::new(cargo)
            .args(["metadata", "--format-version", "1", "--offline"])
            .args(extra)
            .current_dir(root)
            .stderr(std::process::Stdio::null())
            .output()
            .ok()
            .filter(|o| o.status.success())
            .and_then(|o| serde_json::from_slice::<serde_json::Value>(&o.stdout).ok())
    };
    let full = run(&[]);
    let packages = full.as_ref().and_then(|v| v["packages"].as_array()).map(|ps| {
        ps.iter().filter_map(|p| p["name"].as_str().map(str::to_owned)).collect::<std::collections::BTreeSet<_>>()
    });
    let value = full.or_else(|| run(&["--no-deps"]));
    let from_cargo = value.and_then(|v| v["target_directory"].as_str().map(PathBuf::from));
    Meta { target: target_of(root, from_cargo), packages }
}

/// Where cargo builds the project at `root`, as `cargo metadata` said
/// (it honours CARGO_TARGET_DIR and a `build.target-dir` in any cargo
/// config): `target` when that is the project's own `target` folder (the
/// launch file then stays relative and the project can move), else the
/// absolute folder. Without a working cargo: CARGO_TARGET_DIR, or `target`.
fn target_of(root: &Path, from_cargo: Option<PathBuf>) -> PathBuf {
    let found = match from_cargo {
        Some(d) => d,
        None => {
            tracing::debug!(project = %root.display(), "cargo metadata failed; using CARGO_TARGET_DIR or ./target");
            match std::env::var_os("CARGO_TARGET_DIR") {
                Some(d) => PathBuf::from(d),
                None => return PathBuf::from("target"),
            }
        }
    };
    let own = root.canonicalize().map(|r| r.join("target")).ok();
    if own.as_deref() == Some(found.as_path()) {
        PathBuf::from("target")
    } else if found.is_relative() {
        // CARGO_TARGET_DIR=relative is the folder cargo was started in's
        std::env::current_dir().map(|d| d.join(&found)).unwrap_or(found)
    } else {
        found
    }
}

/// `gripper-driver` → `GripperDriver`, with `Agent` appended to a name the
/// generated code already uses.
fn type_name(name: &str) -> String {
    let camel: String = name
        .split('-')
        .filter(|p| !p.is_empty())
        .map(|p| {
            let mut c = p.chars();
            c.next().map(|f| f.to_ascii_uppercase().to_string() + c.as_str()).unwrap_or_default()
        })
        .collect();
    if TAKEN.contains(&camel.as_str()) { camel + "Agent" } else { camel }
}

/// The project's files, by path in it.
/// `debug` is the folder cargo's debug build lands in: `target/debug`, or
/// an absolute folder when the user's cargo builds elsewhere.
/// `profiles` is the `[profile.*]` sections of `Cargo.toml`, `pins` the
/// lines after its own dependencies (see [`pins_text`]).
fn render(name: &str, drive: &Drive, nerve: &Path, debug: &str, profiles: &str, pins: &str) -> Vec<(String, String)> {
    let (what, task, step, imports, period_line, task_words) = match drive {
        Drive::Event => (
            "an event-driven agent that sends every tick arriving on `in` on `out`, its sequence number multiplied by the parameter `gain`.".to_owned(),
            "Task::EventDriven".to_owned(),
            "        // every waiting sample, in place; a failed send ends the step with its error\n        self.input.try_drain(|_, tick| self.out.send(transform(tick, gain)))?;".to_owned(),
            String::new(),
            String::new(),
            "event-driven: woken by every sample on `in`".to_owned(),
        ),
        Drive::Periodic(p, d) => (
            format!(
                "a periodic agent that, every {p}, sends the newest tick that arrived on `in` on `out`, its sequence number multiplied by the parameter `gain`."
            ),
            format!(
                "// every {p} by default; `--period`, a launch file's `period` and\n        // `nerve rate` change it\n        Task::Periodic(Duration::from_nanos({}))",
                d.as_nanos()
            ),
            "        // the newest sample since the last cycle, if any\n        if let Some((_, tick)) = self.input.latest() {\n            self.out.send(transform(&tick, gain))?;\n        }".to_owned(),
            "use std::time::Duration;\n".to_owned(),
            format!("period = \"{p}\"\n"),
            format!("periodic, every {p} by default"),
        ),
    };
    let fill = |t: &str| {
        t.replace("{{what}}", &what)
            .replace("{{task}}", &task)
            .replace("{{step}}", &step)
            .replace("{{imports}}", &imports)
            .replace("{{period_line}}", &period_line)
            .replace("{{task_words}}", &task_words)
            .replace("{{type}}", &type_name(name))
            .replace("{{nerve}}", &nerve.display().to_string())
            .replace("{{debug}}", debug)
            .replace("{{profiles}}", profiles)
            .replace("{{pins}}", pins)
            .replace("{{name}}", name)
    };
    vec![
        ("Cargo.toml".into(), fill(CARGO_TOML)),
        ("src/main.rs".into(), fill(MAIN_RS)),
        ("launch.toml".into(), fill(LAUNCH_TOML)),
        ("README.md".into(), fill(README_MD)),
        (".gitignore".into(), fill(GITIGNORE)),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_become_types_that_clash_with_nothing() {
        assert_eq!(type_name("gripper-driver"), "GripperDriver");
        assert_eq!(type_name("scaler"), "Scaler");
        assert_eq!(type_name("tick"), "TickAgent");
        assert_eq!(type_name("agent"), "AgentAgent");
    }

    #[test]
    fn bad_names_are_refused_with_an_example() {
        for bad in ["Gripper", "9lives", "a_b", "a b", "", "x-", "a/b"] {
            assert!(check_name(bad).is_err(), "{bad:?} must be refused");
        }
        check_name("gripper-2").expect("a good name");
        assert!(format!("{:#}", check_name("Gripper").expect_err("capital")).contains("gripper-driver"));
    }

    #[test]
    fn the_project_gets_nerves_profiles_for_the_packages_it_builds() {
        let nerve: toml::Table = toml::from_str(
            "[profile.release]\npanic = \"abort\"\n[profile.dev]\nopt-level = 1\n\
             [profile.dev.package.\"*\"]\nopt-level = 2\n[profile.dev.package.syn]\nopt-level = 0\n\
             [profile.dev.package.pyo3-macros]\nopt-level = 0\n",
        )
        .expect("profiles");
        let profiles = nerve["profile"].as_table().expect("a table");
        let used = ["syn".to_owned(), "iceoryx2".to_owned()].into_iter().collect();
        let text = profiles_text(Some(profiles), Some(&used));
        let back: toml::Table = toml::from_str(&text).expect("valid TOML");
        let dev = &back["profile"]["dev"];
        assert_eq!(dev["opt-level"].as_integer(), Some(1), "{text}");
        assert_eq!(dev["package"]["*"]["opt-level"].as_integer(), Some(2), "{text}");
        assert_eq!(dev["package"]["syn"]["opt-level"].as_integer(), Some(0), "{text}");
        assert!(dev["package"].get("pyo3-macros").is_none(), "a package the project does not build: {text}");
        assert_eq!(back["profile"]["release"]["panic"].as_str(), Some("abort"), "{text}");
        // unknown packages: every setting kept; no profiles: the defaults
        assert!(profiles_text(Some(profiles), None).contains("pyo3-macros"));
        assert!(profiles_text(None, None).contains("opt-level = 1"));
    }

    #[test]
    fn names_of_nerves_programs_are_refused_in_its_target_folder() {
        for bad in ["nerve-ticker", "nerve-x", "deps", "build"] {
            let e = format!("{:#}", check_shared_name(bad, Path::new("/t")).expect_err(bad));
            assert!(e.contains("--own-target") && e.contains("/t"), "{e}");
        }
        check_shared_name("gripper", Path::new("/t")).expect("a name of its own");
    }

    #[test]
    fn every_placeholder_is_filled() {
        for drive in [Drive::Event, Drive::Periodic("50ms".into(), std::time::Duration::from_millis(50))] {
            for (path, text) in render("my-agent", &drive, Path::new("/src/nerve"), "target/debug", "", "") {
                assert!(!text.contains("{{"), "{path} keeps a placeholder:\n{text}");
            }
            for (path, text) in render_python("my-agent", &drive) {
                assert!(!text.contains("{{"), "{path} keeps a placeholder:\n{text}");
            }
        }
    }
}
