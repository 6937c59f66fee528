//! Launch-file arguments, includes and conditions (issue 46) through real
//! `nerve launch` processes: defaults and `NAME=VALUE` overrides reach the
//! agents, an include's agents come up under its prefix and wired, a
//! condition leaves an agent and its connection out, the file's
//! `sim_time`/`time_scale` put the robot on simulated time, and every bad
//! input is refused with FILE:LINE before anything starts.

use nerve_tests::{Robot, wait_until};
use std::path::{Path, PathBuf};
use std::time::Duration;

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// `nerve launch FILE ARGS...`; panics unless it succeeds. Returns its stderr.
fn launch(r: &Robot, file: &Path, args: &[&str]) -> String {
    let out = r.command("nerve").arg("launch").arg(file).args(args).output().expect("run nerve launch");
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    if !out.status.success() {
        r.dump_logs();
    }
    assert!(out.status.success(), "nerve launch {} {args:?} failed:\n{err}", file.display());
    err
}

/// `nerve launch FILE ARGS...` must fail: returns its stderr, after checking
/// that nothing was started (no router, no shared memory).
fn refused(r: &Robot, file: &Path, args: &[&str]) -> String {
    let out = r.command("nerve").arg("launch").arg(file).args(args).output().expect("run nerve launch");
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(!out.status.success(), "accepted: nerve launch {} {args:?}\n{err}", file.display());
    assert!(err.contains("nothing was started"), "{err}");
    assert!(r.shm_files().is_empty(), "shared memory was created: {err}");
    let ps = r.nerve(&["ps"]);
    assert!(!ps.status.success(), "a router was started by a refused launch: {err}");
    // `nerve ps` joined the robot's world to look: clean that up for the next case
    r.ok(&["down"]);
    err
}

fn names(r: &Robot) -> Vec<String> {
    let mut v: Vec<String> = r.ps().iter().filter_map(|a| a["name"].as_str().map(str::to_owned)).collect();
    v.sort();
    v
}

fn period_ns(r: &Robot, name: &str) -> u64 {
    r.agent(name).and_then(|a| a["period_ns"].as_u64()).unwrap_or_else(|| panic!("{name} has no period in ps"))
}

/// The example file with its defaults, then with `period=20ms step=4
/// second=false`: the period and parameter reach the ticker, and the
/// condition leaves r2 and its connection out.
#[test]
fn arguments_take_their_defaults_or_the_command_line() {
    let r = Robot::new("largs");
    let body = std::fs::read_to_string(repo().join("launch/pipeline-args.toml")).expect("launch/pipeline-args.toml");
    let file = r.launch_file("pipeline-args.toml", &body);

    launch(&r, &file, &[]);
    assert_eq!(names(&r), ["r1", "r2", "t1"]);
    assert_eq!(period_ns(&r, "t1"), 10_000_000);
    assert_eq!(r.ok(&["param", "get", "t1", "step"]).trim(), "1");
    assert_eq!(r.edges(), ["t1/tick -> r1/in", "t1/tick -> r2/in"]);
    assert_eq!(r.echo("r2/out", 2).len(), 2);
    r.down_and_check_clean();

    launch(&r, &file, &["period=20ms", "step=4", "second=false"]);
    assert_eq!(names(&r), ["r1", "t1"], "the condition leaves r2 out");
    assert_eq!(period_ns(&r, "t1"), 20_000_000);
    assert_eq!(r.ok(&["param", "get", "t1", "step"]).trim(), "4");
    assert_eq!(r.edges(), ["t1/tick -> r1/in"], "and its connection");
    assert_eq!(r.echo("r1/out", 2).len(), 2);
    r.down_and_check_clean();
}

/// `sim_time` and `time_scale` in the file (issue 46), `sim_time` set from
/// an argument: by default the robot runs on the wall clock; `sim=true`
/// puts it on simulated time at the file's scale (the clock's page made,
/// the agent on it); `--time-scale` on the command line wins over the file.
#[test]
fn sim_time_in_the_file_puts_the_robot_on_simulated_time() {
    let r = Robot::new("lsim");
    let body = "sim_time = \"{arg.sim}\"\ntime_scale = 4\n[args]\nsim = false\n[[agent]]\nname = \"t1\"\nkind = \"ticker\"\nperiod = \"10ms\"\n";
    let file = r.launch_file("sim.toml", body);
    let page = r.home.join(&r.name).join(agent_sdk::simclock::PAGE_FILE);
    let log = r.home.join(&r.name).join("logs/t1.log");
    let on_sim_time = |scale: &str| {
        wait_until(Duration::from_secs(10), || {
            std::fs::read_to_string(&log).is_ok_and(|l| l.contains("on simulated time") && l.contains(scale))
        })
    };

    let err = launch(&r, &file, &[]);
    assert!(!err.contains("simulated time") && !page.exists(), "sim=false ran on simulated time:\n{err}");
    r.down_and_check_clean();

    let err = launch(&r, &file, &["sim=true"]);
    assert!(err.contains("runs on simulated time at 4x"), "{err}");
    assert!(page.exists(), "no clock page at {}", page.display());
    assert!(on_sim_time("scale=4"), "t1 is not on the clock:\n{}", std::fs::read_to_string(&log).unwrap_or_default());
    r.down_and_check_clean();
    let _ = std::fs::remove_file(&log);

    let err = launch(&r, &file, &["--time-scale", "2", "--sim-time"]);
    assert!(err.contains("runs on simulated time at 2x"), "the flag does not win over the file:\n{err}");
    assert!(on_sim_time("scale=2"), "t1 is not at 2x:\n{}", std::fs::read_to_string(&log).unwrap_or_default());
    r.down_and_check_clean();
}

/// One file included twice with different arguments and prefixes: every
/// agent comes up under its prefix, the included file's own connection is
/// wired between its prefixed agents, and the including file connects to
/// them by their prefixed names.
#[test]
fn an_include_takes_arguments_and_prefixes_its_agents() {
    let r = Robot::new("linc");
    std::fs::create_dir_all(r.home.join("parts")).expect("a folder for the part");
    std::fs::write(
        r.home.join("parts/chain.toml"),
        "[args]\nperiod = {}\n\n[[agent]]\nname = \"t\"\nkind = \"ticker\"\nperiod = \"{arg.period}\"\n\n[[agent]]\nname = \"r\"\nkind = \"relay\"\n\n[[connect]]\nfrom = \"t/tick\"\nto = \"r/in\"\n",
    )
    .expect("write the included file");
    let file = r.launch_file(
        "top.toml",
        "robot = \"x\"\n[args]\nslow = \"30ms\"\n\n[[include]]\nfile = \"parts/chain.toml\"\nargs = { period = \"10ms\" }\nprefix = \"a_\"\n\n[[include]]\nfile = \"parts/chain.toml\"\nargs = { period = \"{arg.slow}\" }\nprefix = \"b_\"\n\n[[agent]]\nname = \"sink\"\nkind = \"relay\"\n\n[[connect]]\nfrom = \"b_t/tick\"\nto = \"sink/in\"\n",
    );
    launch(&r, &file, &[]);
    assert_eq!(names(&r), ["a_r", "a_t", "b_r", "b_t", "sink"]);
    assert_eq!(period_ns(&r, "a_t"), 10_000_000);
    assert_eq!(period_ns(&r, "b_t"), 30_000_000);
    assert_eq!(r.edges(), ["a_t/tick -> a_r/in", "b_t/tick -> b_r/in", "b_t/tick -> sink/in"]);
    assert_eq!(r.echo("a_r/out", 2).len(), 2);
    assert_eq!(r.echo("sink/out", 2).len(), 2);
    r.down_and_check_clean();
}

/// Each bad input is refused with the file and line it is in (the included
/// file's own for a problem inside it), and nothing starts.
#[test]
fn bad_arguments_includes_and_conditions_are_refused_with_file_and_line() {
    let r = Robot::new("lbad");
    let agent = "[[agent]]\nname = \"t1\"\nkind = \"ticker\"\n";
    let with_args =
        format!("robot = \"x\"\n[args]\nperiod = \"10ms\"\ncam = \"true\"\n{agent}period = \"{{arg.period}}\"\n");
    let file = r.launch_file("args.toml", &with_args);
    let at = |f: &Path, line: usize| format!("{}:{line}:", f.display());

    // a NAME=VALUE the file does not declare (reported at its [args])
    let err = refused(&r, &file, &["perod=5ms"]);
    assert!(err.contains(&format!("{} the command line sets perod=5ms", at(&file, 2))), "{err}");
    // a bad condition value
    let cond = r.launch_file("cond.toml", &format!("{with_args}if = \"{{arg.cam}}\"\n"));
    let err = refused(&r, &cond, &["cam=maybe"]);
    assert!(err.contains(&format!("{} `if` is \"maybe\"", at(&cond, 9))), "{err}");
    // a condition on an unknown argument
    let unknown_cond = r.launch_file("ucond.toml", &format!("robot = \"x\"\n{agent}if = \"{{arg.camera}}\"\n"));
    let err = refused(&r, &unknown_cond, &[]);
    assert!(err.contains(&format!("{} unknown argument \"camera\"", at(&unknown_cond, 5))), "{err}");
    // an unknown {arg.x} in a value
    let unknown = r.launch_file("unknown.toml", &format!("robot = \"x\"\n{agent}period = \"{{arg.rate}}\"\n"));
    let err = refused(&r, &unknown, &[]);
    assert!(err.contains(&format!("{} unknown argument \"rate\"", at(&unknown, 5))), "{err}");
    // an argument never given
    let need = r.launch_file(
        "need.toml",
        &format!("robot = \"x\"\n[args]\nperiod = {{}}\n{agent}period = \"{{arg.period}}\"\n"),
    );
    let err = refused(&r, &need, &[]);
    assert!(err.contains(&format!("{} argument period has no default", at(&need, 3))), "{err}");
    // an include loop, reported in the file whose include closes it
    let a = r.home.join("loop-a.toml");
    let b = r.home.join("loop-b.toml");
    std::fs::write(&a, format!("robot = \"x\"\n{agent}[[include]]\nfile = \"loop-b.toml\"\n")).expect("loop-a");
    std::fs::write(&b, "[[include]]\nfile = \"loop-a.toml\"\n").expect("loop-b");
    let err = refused(&r, &a, &[]);
    assert!(err.contains(&format!("{} include loop", at(&b, 2))), "{err}");
    // a problem inside an included file, at its own path and line
    let inner = r.home.join("inner.toml");
    std::fs::write(&inner, format!("[args]\np = \"1ms\"\n{agent}period = \"{{arg.q}}\"\n")).expect("inner");
    let outer = r.launch_file("outer.toml", "robot = \"x\"\n[[include]]\nfile = \"inner.toml\"\nprefix = \"in_\"\n");
    let err = refused(&r, &outer, &[]);
    assert!(err.contains(&format!("{} unknown argument \"q\"", at(&inner, 6))), "{err}");
    // a command-line argument that is not NAME=VALUE
    let out = r.command("nerve").arg("launch").arg(&file).arg("period").output().expect("run nerve launch");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("is not NAME=VALUE"), "{err}");
}
