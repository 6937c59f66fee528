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
