//! `nerve new NAME`: a ready agent project outside nerve's workspace, as
//! `cargo new` makes a crate: the agent (one input, one output, one checked
//! parameter, periodic or event-driven), tests of its algorithm, a launch
//! file that wires it to a ticker, a README. `cargo test`, `cargo build` and
//! `nerve launch launch.toml` work on it as made. `--lang python` makes a
//! Python agent on the `nerve` package instead (an executable script, its
//! `unittest` tests, a launch file, a README). The templates are
//! `launcher/templates/{rust,python}/*.in`, built into the `nerve` program.

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
}

/// The language of a new agent.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Lang {
    /// A Rust crate on nerve's agent SDK.
    Rust,
    /// A Python agent on the `nerve` Python package (`python/`).
    Python,
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
    let nerve = nerve_source(a.nerve_src.as_deref())?;
    let files = render(&a.name, &drive, &nerve, "target/debug");
    std::fs::create_dir_all(root.join("src")).with_context(|| format!("cannot create {}", root.display()))?;
    for (path, text) in &files {
        let p = root.join(path);
        std::fs::write(&p, text).with_context(|| format!("cannot write {}", p.display()))?;
    }
    // the launch file's `exe` where this user's cargo will put the build:
    // CARGO_TARGET_DIR or a `build.target-dir` moves it out of ./target
    let debug = target_dir(&root).join("debug");
    let files = if debug == Path::new("target/debug") {
        files
    } else {
        let files = render(&a.name, &drive, &nerve, &debug.display().to_string());
        let launch = root.join("launch.toml");
        let text = files.iter().find(|(p, _)| p == "launch.toml").map(|(_, t)| t.as_str()).unwrap_or_default();
        std::fs::write(&launch, text).with_context(|| format!("cannot write {}", launch.display()))?;
        println!("cargo builds into {}: launch.toml's exe is there", debug.display());
        files
    };
    // the versions nerve is built and tested with, so that the first build
    // resolves nothing anew (and works offline when nerve has been built)
    let lock = nerve.join("Cargo.lock");
    if lock.is_file() {
        std::fs::copy(&lock, root.join("Cargo.lock")).with_context(|| format!("cannot copy {}", lock.display()))?;
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

/// Where cargo builds the project at `root`, as `cargo metadata` says
/// (it honours CARGO_TARGET_DIR and a `build.target-dir` in any cargo
/// config): `target` when that is the project's own `target` folder (the
/// launch file then stays relative and the project can move), else the
/// absolute folder. Without a working cargo: CARGO_TARGET_DIR, or `target`.
fn target_dir(root: &Path) -> PathBuf {
    let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
    let meta = std::process::Command::new(cargo)
        .args(["metadata", "--format-version", "1", "--no-deps", "--offline"])
        .current_dir(root)
        .stderr(std::process::Stdio::null())
        .output();
    let from_cargo = meta
        .ok()
        .filter(|o| o.status.success())
        .and_then(|o| serde_json::from_slice::<serde_json::Value>(&o.stdout).ok())
        .and_then(|v| v["target_directory"].as_str().map(PathBuf::from));
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
fn render(name: &str, drive: &Drive, nerve: &Path, debug: &str) -> Vec<(String, String)> {
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
    fn every_placeholder_is_filled() {
        for drive in [Drive::Event, Drive::Periodic("50ms".into(), std::time::Duration::from_millis(50))] {
            for (path, text) in render("my-agent", &drive, Path::new("/src/nerve"), "target/debug") {
                assert!(!text.contains("{{"), "{path} keeps a placeholder:\n{text}");
            }
            for (path, text) in render_python("my-agent", &drive) {
                assert!(!text.contains("{{"), "{path} keeps a placeholder:\n{text}");
            }
        }
    }
}
