//! `nerve-ros2-router`: a Zenoh router, what ROS 2's `rmw_zenohd` is, for a
//! machine without ROS (and for the tests): the `ros2` agent and ROS 2 nodes
//! on rmw_zenoh meet through it.
//!
//! `nerve-ros2-router [--listen tcp/127.0.0.1:7447]...`: listens on the
//! endpoints (rmw_zenohd's default when none is given), multicast scouting
//! off, prints `ready` on stdout once it is (and what it listens on to
//! stderr), and runs until it is killed (SIGTERM or SIGINT end it; it keeps
//! no state).

use clap::Parser;
use std::process::ExitCode;
use zenoh::Wait;

#[derive(Debug, Parser)]
#[command(name = "nerve-ros2-router", about = "A Zenoh router for ROS 2 nodes on rmw_zenoh and nerve's ros2 agent")]
struct Args {
    /// An endpoint to listen on (repeatable).
    #[arg(long, value_name = "ENDPOINT", default_value = "tcp/127.0.0.1:7447")]
    listen: Vec<String>,
}

fn main() -> ExitCode {
    let args = Args::parse();
    let endpoints: Vec<String> = args.listen.iter().map(|s| format!("{s:?}")).collect();
    let endpoints = format!("[{}]", endpoints.join(","));
    let mut cfg = zenoh::Config::default();
    for (key, value) in [
        ("mode", "\"router\"".to_string()),
        ("listen/endpoints", endpoints.clone()),
        ("listen/exit_on_failure", "true".into()),
        ("scouting/multicast/enabled", "false".into()),
    ] {
        if let Err(e) = cfg.insert_json5(key, &value) {
            eprintln!("nerve-ros2-router: zenoh configuration {key} = {value}: {e}");
            return ExitCode::from(2);
        }
    }
    let session = match zenoh::open(cfg).wait() {
        Ok(s) => s,
        Err(e) => {
            eprintln!("nerve-ros2-router: cannot listen on {endpoints}: {e} (is another router there?)");
            return ExitCode::from(1);
        }
    };
    println!("ready");
    eprintln!("nerve-ros2-router: listening on {endpoints} (zid {})", session.zid());
    loop {
        std::thread::park();
    }
}
