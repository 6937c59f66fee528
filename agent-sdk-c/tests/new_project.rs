//! `nerve new NAME --lang c` and `--lang cpp`, as a user runs them: the
//! generated CMake project configures and builds against the nerve tree's
//! headers and libnerve.so, its `ctest` passes, and its own launch file
//! runs it under a real router behind a ticker, its output the ticks'
//! sequence numbers times the parameter `gain` (2 in the launch file).
//! Its ctest runs `--describe` and the project's own test of the agent on
//! the C test harness (`test_NAME.c`, `test_NAME.cpp`).
//! Needs `cargo build --workspace --lib --bins` first, gcc, g++ and cmake
//! (`scripts/setup.sh --test`).

mod common;

use nerve_testkit::Robot;
use std::path::Path;
use std::process::Command;

/// Runs `program args` in `dir` and returns its output; panics with it on a failure.
fn run(dir: &Path, program: &str, args: &[&str]) -> String {
    let out = Command::new(program)
        .args(args)
        .current_dir(dir)
        .output()
        .unwrap_or_else(|e| panic!("run {program} (scripts/setup.sh --test installs cmake): {e}"));
    assert!(
        out.status.success(),
        "{program} {args:?} failed in {}:\n{}{}",
        dir.display(),
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// Makes, builds, tests and launches agent `name` in language `lang`.
fn new_build_and_launch(lang: &str, name: &str, extra: &[&str]) {
    common::libnerve_dir();
    let r = Robot::new(name);
    let dir = r.home.to_str().expect("utf-8 path").to_owned();
    let mut args = vec!["new", name, "--lang", lang, "--dir", &dir];
    args.extend_from_slice(extra);
    r.ok(&args);
    let root = r.home.join(name);
    run(&root, "cmake", &["-S", ".", "-B", "build"]);
    run(&root, "cmake", &["--build", "build"]);
    let tests = run(&root.join("build"), "ctest", &["--output-on-failure"]);
    // both: what it declares, and its own init and step in the C test harness
    for test in ["describe", "harness"] {
        assert!(tests.lines().any(|l| l.contains(test) && l.contains("Passed")), "ctest ran no {test}:\n{tests}");
    }

    r.ok(&["launch", root.join("launch.toml").to_str().expect("utf-8 path")]);
    let got = r.echo(&format!("{name}/out"), 3);
    let seqs: Vec<u64> = got.iter().filter_map(|v| v["data"]["seq"].as_u64()).collect();
    assert_eq!(seqs.len(), 3, "three samples with a seq: {got:?}");
    // gain 2 on ticks numbered from 1: even, growing
    assert!(seqs.iter().all(|s| *s >= 2 && s % 2 == 0), "the ticks' seq times 2: {seqs:?}");
    assert!(seqs.windows(2).all(|w| w[1] > w[0]), "in order: {seqs:?}");
    r.down_and_check_clean();
}

#[test]
fn nerve_new_lang_c_builds_with_cmake_passes_ctest_and_runs_from_its_launch_file() {
    new_build_and_launch("c", "cnew", &[]);
}

#[test]
fn nerve_new_lang_cpp_periodic_builds_with_cmake_passes_ctest_and_runs_from_its_launch_file() {
    new_build_and_launch("cpp", "cppnew", &["--periodic", "20ms"]);
}
