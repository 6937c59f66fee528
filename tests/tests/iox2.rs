//! iceoryx2's own tools see a nerve robot: `nerve iox2-config` gives the
//! configuration `iox2` (`iceoryx2-cli` 0.10, installed by `.ci/run` into
//! `target/iox2`) needs, and then `iox2 service list` lists the robot's
//! ports and `iox2 service details` shows nerve's attributes of a port.

use nerve_tests::Robot;
use std::path::PathBuf;
use std::process::Command;

/// The `iox2` that `.ci/run` installs.
fn iox2_bin() -> PathBuf {
    let bin = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..").join("target").join("iox2").join("bin");
    assert!(
        bin.join("iox2").exists(),
        "no iox2 in {}: `cargo install iceoryx2-cli --version 0.10.0 --locked --root target/iox2` (.ci/run does it)",
        bin.display()
    );
    bin
}

#[test]
fn iceoryx2s_own_tool_lists_a_robots_ports_and_their_attributes() {
    let bin = iox2_bin();
    let r = Robot::new("iox");
    r.router();
    r.ok(&["start", "gripper", "--name", "g"]);
    let dir = r.home.join("iox2");
    std::fs::create_dir_all(dir.join("config")).expect("config dir");
    std::fs::write(dir.join("config").join("iceoryx2.toml"), r.ok(&["iox2-config"])).expect("config");
    let path = format!("{}:{}", bin.display(), std::env::var("PATH").unwrap_or_default());
    let iox2 = |args: &[&str]| {
        let out =
            Command::new(bin.join("iox2")).args(args).current_dir(&dir).env("PATH", &path).output().expect("iox2");
        let text = format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
        assert!(out.status.success(), "iox2 {} failed: {text}", args.join(" "));
        text
    };
    let service = format!("nerve/{}/g/state", r.name);
    let list = iox2(&["service", "list"]);
    assert!(list.contains(&service), "{service} not in:\n{list}");
    assert!(list.contains(&format!("nerve/{}/g/ctl", r.name)), "the control service not in:\n{list}");
    let details = iox2(&["service", "details", &service]);
    let fp = r.agent("g").expect("g")["outputs"][0]["fingerprint"].as_u64().expect("fingerprint");
    for want in
        ["nerve.type", "acme::Gripper", "nerve.fingerprint", &format!("{fp:#018x}"), "nerve.agent", "nerve.port"]
    {
        assert!(details.contains(want), "{want} not in:\n{details}");
    }
    r.down_and_check_clean();
}
