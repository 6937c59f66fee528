//! A C agent's own payload type (`examples/c/reading.c`: `lab::Reading`,
//! declared with a NERVE_FIELD table) under a real router: its layout is
//! registered (`nerve echo` decodes its fields by name), two agents of the
//! same layout connect and exchange samples, and one built with another
//! layout of the same type name (`-DREADING_DRIFT`) is refused on connect,
//! the refusal naming both layouts. Needs `cargo build --workspace --lib
//! --bins` first, and gcc.

mod common;

use nerve_testkit::{Robot, wait_until};
use std::path::PathBuf;
use std::time::Duration;

#[test]
fn a_c_struct_of_its_own_is_type_checked_by_the_router() {
    let r = Robot::new("cown");
    let source = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("examples").join("c").join("reading.c");
    let same = common::compile("gcc", &["-std=c11", "-pedantic"], &source, &r.home, "creading");
    let drift = common::compile("gcc", &["-std=c11", "-pedantic", "-DREADING_DRIFT"], &source, &r.home, "cdrift");
    let file = r.launch_file(
        "own.toml",
        &format!(
            "robot = \"x\"\n\
             [[agent]]\nname = \"a\"\nexe = \"{same}\"\n\n\
             [[agent]]\nname = \"b\"\nexe = \"{same}\"\n\n\
             [[agent]]\nname = \"d\"\nexe = \"{drift}\"\n\n\
             [[connect]]\nfrom = \"a/out\"\nto = \"b/in\"\n",
            same = same.display(),
            drift = drift.display()
        ),
    );
    r.ok(&["launch", file.to_str().expect("utf-8 path")]);

    // the router knows the layout: echo decodes the C struct's fields
    let got = r.echo("a/out", 1);
    let data = &got.first().expect("a Reading")["data"];
    assert!(data["value"].is_number() && data["samples"].as_array().is_some_and(|a| a.len() == 3), "{got:?}");
    assert_eq!(data["samples"][0].as_f64(), Some(1.5), "{got:?}");

    // same layout: connected, and b takes what a sends
    let taken = || r.echo("b/out", 1).first().and_then(|v| v["data"]["id"].as_u64()).unwrap_or(0);
    assert!(wait_until(Duration::from_secs(5), || taken() > 0), "b took no Reading from a");

    // another layout of lab::Reading: refused, naming both sides
    let why = r.fails(&["connect", "a/out", "d/in"]);
    assert!(why.contains("lab::Reading") && why.contains("different definitions"), "a layout mismatch: {why}");
    assert!(why.contains("a/out") && why.contains("d/in"), "the refusal names both ports: {why}");
    let why = r.fails(&["connect", "d/out", "b/in"]);
    assert!(why.contains("lab::Reading"), "{why}");
    r.down_and_check_clean();
}

/// A C struct given the name of a Rust agent's own type (`acme::Gripper`
/// of the test agent `gripper`, tests/src/bin/gripper.rs) with another
/// layout: the router refuses to connect them either way, naming the type,
/// both ports and both fingerprints; the Rust agent's own type still
/// connects to itself.
#[test]
fn a_c_struct_laid_out_unlike_the_rust_type_of_its_name_is_refused_on_connect() {
    let r = Robot::new("crust");
    let source = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("examples").join("c").join("reading.c");
    let c = common::compile(
        "gcc",
        &["-std=c11", "-pedantic", "-DREADING_TYPE_NAME=\"acme::Gripper\""],
        &source,
        &r.home,
        "cgripper",
    );
    r.router();
    r.ok(&["start", "gripper", "--name", "rust"]);
    r.ok(&["start", c.to_str().expect("utf-8 path"), "--name", "c"]);
    let fingerprint = |agent: &str, dir: &str| {
        let a = r.agent(agent).unwrap_or_else(|| panic!("{agent} is listed: {:?}", r.ps()));
        let port = &a[dir][0];
        assert_eq!(port["type_name"], "acme::Gripper", "{a}");
        port["fingerprint"].as_u64().expect("fingerprint")
    };
    let (fp_rust, fp_c) = (fingerprint("rust", "outputs"), fingerprint("c", "outputs"));
    assert_ne!(fp_rust, fp_c, "the C layout is not the Rust one");

    let why = r.fails(&["connect", "c/out", "rust/cmd"]);
    assert!(why.contains("acme::Gripper") && why.contains("different definitions"), "{why}");
    assert!(why.contains("c/out") && why.contains("rust/cmd"), "the refusal names both ports: {why}");
    assert!(why.contains(&format!("{fp_c:#018x}")) && why.contains(&format!("{fp_rust:#018x}")), "{why}");
    let why = r.fails(&["connect", "rust/state", "c/in"]);
    assert!(why.contains("acme::Gripper") && why.contains("rust/state") && why.contains("c/in"), "{why}");
    assert!(r.graph()["connections"].as_array().is_some_and(|c| c.is_empty()), "nothing was connected");
    r.ok(&["connect", "rust/state", "rust/cmd"]);
    r.down_and_check_clean();
}

/// A C++ agent's own type through nerve.hpp (`examples/cpp/reading.cpp`,
/// `NERVE_HPP_OWN_TYPE`): its own harness test passes (`-DREADING_TEST`),
/// and under a real router it connects to the C agent's `lab::Reading` of
/// the same layout both ways (each takes what the other sends) and is
/// refused by the C agent's drifted layout of that name.
#[test]
fn a_cpp_own_type_through_nerve_hpp_connects_to_the_c_layout_and_refuses_a_drift() {
    let r = Robot::new("cppown");
    let examples = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("examples");
    let cpp_source = examples.join("cpp").join("reading.cpp");
    let test = common::compile("g++", &["-std=c++17", "-pedantic", "-DREADING_TEST"], &cpp_source, &r.home, "cpptest");
    let out = r.command(test.to_str().expect("utf-8 path")).output().expect("run the C++ harness test");
    assert!(out.status.success(), "{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));

    let cpp = common::compile("g++", &["-std=c++17", "-pedantic"], &cpp_source, &r.home, "cppreading");
    let c_source = examples.join("c").join("reading.c");
    let c = common::compile("gcc", &["-std=c11", "-pedantic"], &c_source, &r.home, "creading");
    let drift = common::compile("gcc", &["-std=c11", "-pedantic", "-DREADING_DRIFT"], &c_source, &r.home, "cdrift");
    r.router();
    for (exe, name) in [(&cpp, "cpp"), (&c, "c"), (&drift, "d")] {
        r.ok(&["start", exe.to_str().expect("utf-8 path"), "--name", name]);
    }
    r.ok(&["connect", "cpp/out", "c/in"]);
    r.ok(&["connect", "c/out", "cpp/in"]);
    let taken =
        |agent: &str| r.echo(&format!("{agent}/out"), 1).first().and_then(|v| v["data"]["id"].as_u64()).unwrap_or(0);
    assert!(wait_until(Duration::from_secs(5), || taken("c") > 0), "c took no reading from cpp");
    assert!(wait_until(Duration::from_secs(5), || taken("cpp") > 0), "cpp took no reading from c");
    let got = r.echo("cpp/out", 1);
    assert_eq!(got.first().map(|v| v["data"]["samples"][2].as_f64()), Some(Some(3.5)), "{got:?}");

    let why = r.fails(&["connect", "cpp/out", "d/in"]);
    assert!(why.contains("lab::Reading") && why.contains("different definitions"), "{why}");
    assert!(why.contains("cpp/out") && why.contains("d/in"), "the refusal names both ports: {why}");
    r.down_and_check_clean();
}
