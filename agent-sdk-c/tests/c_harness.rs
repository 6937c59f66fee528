//! The C test harness (`nerve_harness_*`) as a C program uses it: the C
//! relay's own test (`examples/c/relay_test.c`, which includes `relay.c`)
//! built with gcc and run, plain and under AddressSanitizer and
//! UndefinedBehaviorSanitizer (with LeakSanitizer), which must report
//! nothing. A last program shows the sanitizers are live and that the
//! harness's samples are heap copies freed when the step returns: a
//! sample pointer kept past its step is reported as a use after free.
//! No router, no shared memory. Needs `cargo build --workspace --lib
//! --bins` first, and gcc (libasan and libubsan come with it).

mod common;

use nerve_testkit::Robot;
use std::path::{Path, PathBuf};
use std::process::Output;

const SANITIZE: &[&str] = &["-std=c11", "-g", "-fsanitize=address,undefined", "-fno-omit-frame-pointer"];

fn relay_test() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("examples").join("c").join("relay_test.c")
}

/// Runs `exe` in robot `r`'s home, with the sanitizers' options: every
/// error fatal, leaks checked.
fn run(r: &Robot, exe: &Path) -> Output {
    r.command(exe.to_str().expect("utf-8 path"))
        .env("ASAN_OPTIONS", "detect_leaks=1:abort_on_error=0:halt_on_error=1")
        .env("UBSAN_OPTIONS", "halt_on_error=1:print_stacktrace=1")
        .current_dir(&r.home)
        .output()
        .unwrap_or_else(|e| panic!("run {}: {e}", exe.display()))
}

/// What a sanitizer says when it finds something.
fn sanitizer_reports(stderr: &str) -> bool {
    ["AddressSanitizer", "LeakSanitizer", "runtime error:", "UndefinedBehaviorSanitizer"]
        .iter()
        .any(|s| stderr.contains(s))
}

fn passes(out: &Output) {
    let (stdout, stderr) = (String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    assert!(out.status.success() && stdout.contains("PASSED: 0 failure(s)"), "relay_test failed:\n{stdout}\n{stderr}");
    assert!(!stdout.contains("FAIL"), "{stdout}");
    // the relay's stop ran when each harness was freed
    assert!(stderr.contains("crelay: stopping after 3 ticks"), "{stderr}");
}

#[test]
fn the_c_relay_passes_its_harness_test() {
    let r = Robot::new("chtest");
    let exe = common::compile("gcc", &["-std=c11", "-pedantic"], &relay_test(), &r.home, "relay_test");
    let out = run(&r, &exe);
    passes(&out);
    let stdout = String::from_utf8_lossy(&out.stdout);
    // misuse is a status with a message, named in the output
    for said in ["send(wrong size): input \"in\" carries nerve::Tick of 16 bytes", "it has [\"in\"]", "was used after"]
    {
        assert!(stdout.contains(said), "no {said:?} in:\n{stdout}");
    }
}

/// The sequence-and-call agent's harness test (`examples/c/seq_call_test.c`):
/// sequences of 0, 1 and 401 elements in, 0, 1 and 400 out at their own
/// length, loans past `max_len` refused, the test's calls of its services
/// answered (a sequence written in place by the agent, one past its
/// `max_len` refused, a fixed answer), and the misuse of every sequence
/// and call function a status with a message; plain, then under ASan and
/// UBSan with nothing reported.
#[test]
fn the_c_sequence_agent_passes_its_harness_test_clean_under_asan() {
    let r = Robot::new("chseq");
    let source = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("examples").join("c").join("seq_call_test.c");
    for (flags, name) in [(&["-std=c11", "-pedantic"][..], "seq_call_test"), (SANITIZE, "seq_call_test_asan")] {
        let exe = common::compile("gcc", flags, &source, &r.home, name);
        let out = run(&r, &exe);
        let (stdout, stderr) = (String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
        assert!(!sanitizer_reports(&stderr), "{name}: a sanitizer reported:\n{stderr}");
        assert!(out.status.success() && stdout.contains("PASSED: 0 failure(s)"), "{name} failed:\n{stdout}\n{stderr}");
        for said in [
            "1001 elements are more than its max_len of 1000",
            "not a sequence",
            "was used after",
            "ok a sequence answer of 3 elements, written in place by the agent",
            "refused its answer of 501 elements",
        ] {
            assert!(stdout.contains(said), "no {said:?} in:\n{stdout}");
        }
    }
}

/// Sequences and calls through `nerve.hpp` (`examples/cpp/seq_test.cpp`):
/// typed sequence ports of own element and header types, read with a
/// range-for in place, written in place, a loan past `max_len` thrown as
/// `nerve::error(NERVE_TOO_LONG)`; a service and a client declared by
/// their payload structs, served with a lambda; a sequence service and
/// client (`serve_seq`, `client_seq`), served with a lambda that loans.
#[test]
fn the_cpp_sequence_agent_passes_its_harness_test() {
    let r = Robot::new("chcppseq");
    let source = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("examples").join("cpp").join("seq_test.cpp");
    let exe = common::compile("g++", &["-std=c++17", "-pedantic"], &source, &r.home, "seq_test");
    let out = run(&r, &exe);
    let (stdout, stderr) = (String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    assert!(out.status.success() && stdout.contains("PASSED: 0 failure(s)"), "seq_test failed:\n{stdout}\n{stderr}");
}

#[test]
fn the_c_relay_harness_test_runs_clean_under_asan_and_ubsan() {
    let r = Robot::new("chasan");
    let exe = common::compile("gcc", SANITIZE, &relay_test(), &r.home, "relay_test_asan");
    let out = run(&r, &exe);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!sanitizer_reports(&stderr), "a sanitizer reported:\n{stderr}");
    passes(&out);
}

/// A step that keeps a sample's pointer and reads it after the step.
const STALE: &str = r#"
#define NERVE_NO_MAIN
#include "RELAY"
static const nerve_Tick *kept = NULL;
static int keeping_step(nerve_ctx *ctx, void *user) {
  relay *r = user;
  const void *data = NULL;
  size_t len = 0;
  if (nerve_take(ctx, r->in, &data, &len) == NERVE_OK) kept = data;
  return 0;
}
int main(void) {
  relay r = {0};
  nerve_agent_vtable vt = relay_agent;
  vt.step = keeping_step;
  nerve_harness *h = NULL;
  nerve_Tick t = {.seq = 7, .stamp_ns = 0};
  if (nerve_harness_new(&vt, &r, NULL, 0, &h) != NERVE_OK || nerve_harness_send(h, "in", &t, sizeof t) != NERVE_OK ||
      nerve_harness_step(h) != NERVE_OK || kept == NULL) {
    printf("setup failed: %s\n", nerve_last_error());
    return 3;
  }
  printf("kept seq %llu\n", (unsigned long long)kept->seq);
  nerve_harness_free(h);
  return 0;
}
"#;

#[test]
fn a_sample_pointer_kept_past_its_step_is_a_use_after_free_asan_reports() {
    let r = Robot::new("chstale");
    let source = r.home.join("stale.c");
    let relay = relay_test().with_file_name("relay.c");
    std::fs::write(&source, STALE.replace("RELAY", relay.to_str().expect("utf-8 path"))).expect("write stale.c");
    let exe = common::compile("gcc", SANITIZE, &source, &r.home, "stale");
    let out = run(&r, &exe);
    let (stdout, stderr) = (String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    assert!(!stdout.contains("setup failed"), "{stdout}");
    assert!(
        !out.status.success() && stderr.contains("heap-use-after-free"),
        "the stale read was not reported:\n{stdout}\n{stderr}"
    );
}

/// The `nerve.pc` the build of libnerve writes beside it: the relay's test
/// built with gcc and nothing but `pkg-config --cflags --libs nerve`'s
/// flags (no -I or -L of its own) passes.
#[test]
fn the_c_relay_test_builds_with_pkg_config_alone() {
    let r = Robot::new("chpkg");
    let lib = common::libnerve_dir();
    let flags = std::process::Command::new("pkg-config")
        .args(["--cflags", "--libs", "nerve"])
        .env("PKG_CONFIG_PATH", &lib)
        .output()
        .unwrap_or_else(|e| panic!("run pkg-config (scripts/setup.sh --test installs it): {e}"));
    assert!(
        flags.status.success(),
        "pkg-config finds no nerve.pc in {} (agent-sdk-c/build.rs writes it): {}",
        lib.display(),
        String::from_utf8_lossy(&flags.stderr)
    );
    let flags = String::from_utf8(flags.stdout).expect("UTF-8 flags");
    let exe = r.home.join("relay_test_pc");
    let out = std::process::Command::new("gcc")
        .args(["-std=c11", "-Wall", "-Wextra", "-Werror"])
        .arg(relay_test())
        .args(flags.split_whitespace())
        .arg("-o")
        .arg(&exe)
        .output()
        .expect("run gcc");
    assert!(out.status.success(), "gcc with {flags:?} failed: {}", String::from_utf8_lossy(&out.stderr));
    passes(&run(&r, &exe));
}
