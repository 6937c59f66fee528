//! `nerve new`, as a new user runs it: make an agent project in a temp
//! folder, run its tests with `cargo test`, build it, and launch its
//! `launch.toml` as made, with data flowing from the ticker through it.
//!
//! The project builds into this workspace's own target folder, as `nerve
//! new` makes it (its `.cargo/config.toml`), and pins nerve's Cargo.lock,
//! profiles and features: its first `cargo test` must compile none of
//! nerve's crates.io dependencies again (iceoryx2, serde, syn, ...), only
//! nerve's own crates the agent uses (their package ids name another
//! workspace, so their build differs) and the agent. That needs the
//! workspace built first, as `.ci/run` does (`cargo build --workspace --bins
//! --tests`). These tests run one at a time in their own group, beside the
//! end-to-end runs of the demos, with cargo at nice 19 and one job: the
//! robot beside them keeps the CPU it asks for, and its resource manager,
//! which judges the whole machine's load (85 % of all cores is `high`),
//! does not see a build of both cores and slow the robot down.

use nerve_tests::{Robot, bin_dir};
use std::path::{Path, PathBuf};
use std::process::Command;

/// `cargo ARGS` in `dir`, offline, at nice 19 with one job; panics with its
/// output unless it succeeds.
fn cargo(dir: &Path, args: &[&str]) -> String {
    let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
    let out = Command::new("nice")
        .args(["-n", "19"])
        .arg(cargo)
        .args(args)
        .args(["--offline", "--jobs", "1"])
        .current_dir(dir)
        .env_remove("CARGO_TARGET_DIR")
        .env_remove("RUSTFLAGS")
        .output()
        .expect("run cargo");
    let text = format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    assert!(out.status.success(), "`cargo {}` in {} failed:\n{text}", args.join(" "), dir.display());
    text
}

/// Fails unless every crate cargo compiled (its `Compiling` lines in
/// `text`) is a path package: nerve's own crates and the project. A
/// crates.io dependency compiled again means that the project did not
/// reuse nerve's build of it: its profile, features or version differ from
/// the workspace's.
fn assert_compiled_no_dependency_again(text: &str) {
    let compiled: Vec<&str> = text.lines().map(str::trim).filter(|l| l.starts_with("Compiling ")).collect();
    let again: Vec<&&str> = compiled.iter().filter(|l| !l.contains(" (/")).collect();
    assert!(
        again.is_empty(),
        "the new project compiled {} of nerve's dependencies again instead of reusing the workspace's build \
         (a profile, feature or version differs; see launcher/src/cmd/new.rs): {again:#?}\n{text}",
        again.len()
    );
    // the project itself at least (nerve's crates only when no project
    // before it built them)
    assert!(!compiled.is_empty(), "cargo compiled the project:\n{text}");
}

/// Makes project `name` under the robot's home with `nerve new NAME EXTRA`,
/// building into the workspace's target folder; returns its folder.
fn make(r: &Robot, name: &str, extra: &[&str]) -> PathBuf {
    // the build goes where the project's `.cargo/config.toml` says (cargo()
    // removes CARGO_TARGET_DIR), so the launch file names the workspace's
    // target folder
    let made = r
        .command("nerve")
        .args(["new", name, "--dir"])
        .arg(&r.home)
        .args(extra)
        .env_remove("CARGO_TARGET_DIR")
        .output();
    let made = made.expect("nerve new");
    let out = String::from_utf8_lossy(&made.stdout).into_owned();
    assert!(made.status.success(), "nerve new failed: {}", String::from_utf8_lossy(&made.stderr));
    let dir = r.home.join(name);
    for f in ["Cargo.toml", "Cargo.lock", "src/main.rs", "launch.toml", "README.md", ".gitignore", ".cargo/config.toml"]
    {
        assert!(dir.join(f).is_file(), "{f} was not made: {out}");
    }
    let launch = std::fs::read_to_string(dir.join("launch.toml")).expect("launch.toml");
    let exe = format!("exe = \"{}\"", bin_dir().join(name).display());
    assert!(
        launch.contains(&exe),
        "the launch file runs the build in the workspace's target folder ({exe}):\n{launch}"
    );
    dir
}

/// `nerve param set NAME gain 5`, then the agent's output is its input
/// times 5 (and no longer times the launch file's 2).
fn gain_5_takes_effect(r: &Robot, name: &str) {
    r.ok(&["param", "set", name, "gain", "5"]);
    assert!(
        nerve_tests::wait_until(std::time::Duration::from_secs(5), || r
            .echo(&format!("{name}/out"), 1)
            .first()
            .and_then(|t| t["data"]["seq"].as_u64())
            .is_some_and(|s| s % 5 == 0 && s % 2 != 0)),
        "the new gain takes effect"
    );
}

/// The workspace's copy of a project's executable, removed when the test ends.
struct Built(PathBuf);

impl Drop for Built {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.0);
        let _ = std::fs::remove_file(self.0.with_extension("d"));
    }
}

#[test]
fn a_new_event_driven_agent_tests_builds_and_runs_from_its_launch_file() {
    let r = Robot::new("newev");
    let name = format!("scaler-{}", std::process::id());
    let dir = make(&r, &name, &["--event"]);
    let _built = Built(bin_dir().join(&name));
    let tests = cargo(&dir, &["test"]);
    assert_compiled_no_dependency_again(&tests);
    assert!(tests.contains("test result: ok. 3 passed"), "the generated tests ran:\n{tests}");
    assert!(tests.contains("the_agent_passes_ticks_on_multiplied_by_gain ... ok"), "the harness test ran:\n{tests}");
    cargo(&dir, &["build"]);
    let out = r.command("nerve").arg("launch").arg(dir.join("launch.toml")).output().expect("launch");
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    // the ticker's ticks, multiplied by the launch file's gain (2)
    let ticks = r.echo(&format!("{name}/out"), 3);
    let seqs: Vec<u64> = ticks.iter().filter_map(|t| t["data"]["seq"].as_u64()).collect();
    assert!(seqs.len() == 3 && seqs.iter().all(|s| s % 2 == 0), "gain 2 from the launch file: {seqs:?}");
    assert!(seqs.windows(2).all(|w| w[1] == w[0] + 2), "every tick, in order: {seqs:?}");
    let list = r.ok(&["param", "list", &name]);
    assert!(list.contains("gain is in [1, 1000]"), "{list}");
    gain_5_takes_effect(&r, &name);
    r.down_and_check_clean();
}

#[test]
fn a_new_periodic_agent_builds_and_describes_itself() {
    let r = Robot::new("newper");
    let name = format!("sampler-{}", std::process::id());
    let dir = make(&r, &name, &["--periodic", "50ms"]);
    let _built = Built(bin_dir().join(&name));
    let main = std::fs::read_to_string(dir.join("src/main.rs")).expect("main.rs");
    assert!(main.contains("Task::Periodic(Duration::from_nanos(50000000))"), "{main}");
    // the same tests, the harness one now driving it by its clock
    let tests = cargo(&dir, &["test"]);
    assert_compiled_no_dependency_again(&tests);
    assert!(tests.contains("the_agent_passes_ticks_on_multiplied_by_gain ... ok"), "the harness test ran:\n{tests}");
    cargo(&dir, &["build"]);
    let out = Command::new(bin_dir().join(&name)).arg("--describe").output().expect("describe");
    let d: serde_json::Value = serde_json::from_slice(&out.stdout).expect("--describe prints JSON");
    assert_eq!(d["default_period_ns"], 50_000_000, "{d}");
    assert_eq!(d["kind"], name.as_str());
}

#[test]
fn bad_requests_are_refused_with_what_to_do() {
    let r = Robot::new("newbad");
    let dir = r.home.to_str().expect("utf-8 path");
    let err = r.fails(&["new", "Gripper", "--dir", dir]);
    assert!(err.contains("gripper-driver"), "{err}");
    let err = r.fails(&["new", "Py", "--lang", "python", "--dir", dir]);
    assert!(err.contains("gripper-driver"), "{err}");
    let err = r.fails(&["new", "x", "--periodic", "soon", "--dir", dir]);
    assert!(err.contains("--periodic"), "{err}");
    r.ok(&["new", "twice", "--dir", dir]);
    let err = r.fails(&["new", "twice", "--dir", dir]);
    assert!(err.contains("already exists"), "{err}");
    let err = r.fails(&["new", "lost", "--dir", dir, "--nerve-src", "/nonexistent"]);
    assert!(err.contains("--nerve-src"), "{err}");
    // an executable in nerve's target folder must not overwrite nerve's
    for clash in ["nerve-ticker", "deps"] {
        let err = r.fails(&["new", clash, "--dir", dir]);
        assert!(err.contains("--own-target") && err.contains("target folder"), "{clash}: {err}");
        assert!(!r.home.join(clash).exists(), "{clash}: nothing is made");
    }
    r.ok(&["new", "nerve-mine", "--own-target", "--dir", dir]);
}

/// The launch file's `exe` is where the user's cargo builds: nerve's target
/// folder (the default), the project's own `target` (relative, with
/// `--own-target`), CARGO_TARGET_DIR, or a `build.target-dir` in a cargo
/// config above the project (`nerve new` asks `cargo metadata`, no build
/// needed).
#[test]
fn the_launch_file_finds_the_build_wherever_cargo_puts_it() {
    let r = Robot::new("newtgt");
    let exe_of = |dir: &Path, name: &str, target_dir: Option<&Path>| -> String {
        let mut c = r.command("nerve");
        c.args(["new", name, "--dir"]).arg(dir).env_remove("CARGO_TARGET_DIR");
        if name != "shared" && name != "moved" {
            c.arg("--own-target");
        }
        if let Some(t) = target_dir {
            c.env("CARGO_TARGET_DIR", t);
        }
        let out = c.output().expect("nerve new");
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        let launch = std::fs::read_to_string(dir.join(name).join("launch.toml")).expect("launch.toml");
        let exe = launch.lines().find_map(|l| l.strip_prefix("exe = ")).unwrap_or_else(|| panic!("no exe in {launch}"));
        exe.trim_matches('"').to_owned()
    };
    assert_eq!(exe_of(&r.home, "shared", None), bin_dir().join("shared").display().to_string());
    assert_eq!(exe_of(&r.home, "plain", None), "target/debug/plain");
    assert!(!r.home.join("plain/.cargo").exists(), "--own-target writes no cargo config");
    let elsewhere = r.home.join("builds");
    assert_eq!(exe_of(&r.home, "moved", Some(&elsewhere)), format!("{}/debug/moved", elsewhere.display()));
    // a cargo config above the project
    let nested = r.home.join("ws");
    std::fs::create_dir_all(nested.join(".cargo")).expect("mkdir");
    let configured = r.home.join("cfg-target");
    std::fs::write(nested.join(".cargo/config.toml"), format!("[build]\ntarget-dir = {:?}\n", configured))
        .expect("cargo config");
    assert_eq!(exe_of(&nested, "configured", None), format!("{}/debug/configured", configured.display()));
}

/// `nerve new --lang python`: the generated tests pass with the package's
/// Python, and the launch file runs with data flowing through the agent,
/// whose parameter changes at run time.
#[test]
fn a_new_python_agent_tests_and_runs_from_its_launch_file() {
    let (python, bin) = nerve_tests::py::python_with_nerve();
    let path = format!("{}:{}", bin.display(), std::env::var("PATH").unwrap_or_default());
    for (tag, extra) in [("pyev", &[][..]), ("pyper", &["--periodic", "20ms"][..])] {
        let r = Robot::new(tag);
        let name = format!("py-{tag}");
        r.ok(&[&["new", &name, "--lang", "python", "--dir"], &[r.home.to_str().expect("utf-8 path")][..], extra]
            .concat());
        let dir = r.home.join(&name);
        let module = name.replace('-', "_");
        for f in [format!("{module}.py"), format!("test_{module}.py"), "launch.toml".into(), "README.md".into()] {
            assert!(dir.join(&f).is_file(), "{f} was not made");
        }
        let out = Command::new(&python)
            .args(["-m", "unittest", "-v"])
            .current_dir(&dir)
            .env("PATH", &path)
            .env("NERVE_HOME", &r.home)
            .output()
            .expect("unittest");
        let text = String::from_utf8_lossy(&out.stderr);
        assert!(out.status.success() && text.contains("Ran 3 tests") && text.contains("OK"), "{text}");
        let out =
            r.command("nerve").arg("launch").arg(dir.join("launch.toml")).env("PATH", &path).output().expect("launch");
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        let seqs: Vec<u64> =
            r.echo(&format!("{name}/out"), 3).iter().filter_map(|t| t["data"]["seq"].as_u64()).collect();
        assert!(seqs.len() == 3 && seqs.iter().all(|s| s % 2 == 0 && *s > 0), "gain 2: {seqs:?}");
        assert!(seqs.windows(2).all(|w| w[1] > w[0]), "in order: {seqs:?}");
        gain_5_takes_effect(&r, &name);
        r.down_and_check_clean();
    }
}
