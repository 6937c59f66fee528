//! `nerve`: the command line of the nerve framework. A thin `main`: parse,
//! dispatch, print the error with what to do, exit with a meaningful code
//! (0 success, 1 failure, 2 bad usage).

mod agent_logs;
mod bring;
mod cli;
mod client;
mod cmd;
mod interrupt;
mod kinds;
mod launch_file;
#[cfg(test)]
mod proptests;
mod sim_time;

use agent_sdk::World;
use anyhow::Result;
use clap::{CommandFactory, FromArgMatches};
use cli::{Cli, Command};
use cmd::{
    bench, bridge, demo, down, drive, echo, inspect, iox2, launch, logs, mem, record, replay, shm_space, start, wire,
};
use std::process::ExitCode;

fn main() -> ExitCode {
    // the router's threads, and every command's, end the process on a panic
    agent_sdk::abort_on_panic();
    let matches = Cli::command().get_matches();
    let mut args = match Cli::from_arg_matches(&matches) {
        Ok(a) => a,
        Err(e) => e.exit(),
    };
    // a robot named on the command line (or in NERVE_ROBOT) wins over the
    // one a launch file names; the default does not
    args.robot_explicit = matches!(
        matches.value_source("robot"),
        Some(clap::parser::ValueSource::CommandLine | clap::parser::ValueSource::EnvVariable)
    );
    agent_sdk::world::quiet_iceoryx2();
    match dispatch(args) {
        Ok(code) => code,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(1)
        }
    }
}

/// Runs the command of the parsed command line. Afterwards, a robot that
/// no process runs is left without a trace of the command (iceoryx2's
/// management file and empty node folders; review F7).
fn dispatch(cli: Cli) -> Result<ExitCode> {
    let world = World::new(&cli.robot)?;
    let result = run(cli, &world);
    world.forget_if_unused();
    result
}

fn run(cli: Cli, world: &World) -> Result<ExitCode> {
    let world = world.clone();
    match cli.command {
        Command::Router(a) => start::router(&world, a),
        Command::New(a) => cmd::new::new(a),
        Command::Ui(a) => cmd::ui::ui(&world, a),
        Command::Foxglove(a) => cmd::foxglove::foxglove(&world, a),
        Command::Start(a) => start::start(&world, a),
        Command::Ps(a) => inspect::ps(&world, a),
        Command::Graph(a) => inspect::graph(&world, a),
        Command::Connect(a) => {
            shm_space::ensure_shm_space("connect")?;
            wire::connect(&world, a)
        }
        Command::Disconnect(a) => wire::disconnect(&world, a),
        Command::Rate { name, period } => wire::rate(&world, &name, &period),
        Command::Suspend { name } => wire::simple(&world, wire::Simple::Suspend, &name),
        Command::Resume { name } => wire::simple(&world, wire::Simple::Resume, &name),
        Command::Stop { name } => wire::simple(&world, wire::Simple::Stop, &name),
        Command::Kill { name } => wire::simple(&world, wire::Simple::Kill, &name),
        Command::Param(p) => wire::param(&world, p),
        Command::Echo(a) => {
            // a subscriber maps a connection segment: on a full /dev/shm, SIGBUS (review R14)
            shm_space::ensure_shm_space("echo")?;
            echo::echo(&world, a)
        }
        Command::Hz(a) => {
            shm_space::ensure_shm_space("hz")?;
            echo::hz(&world, a)
        }
        Command::Types(a) => crate::cmd::types::types(&world, a),
        Command::Pub(a) => {
            shm_space::ensure_shm_space("pub")?;
            crate::cmd::publish::publish(&world, a)
        }
        Command::Call(a) => crate::cmd::call::call(&world, a),
        Command::Iox2Config => iox2::iox2_config(&world),
        Command::Record(a) => {
            shm_space::ensure_shm_space("record")?;
            record::record(&world, a)
        }
        Command::Replay(a) => {
            shm_space::ensure_shm_space("replay")?;
            replay::replay(&world, a)
        }
        Command::Plot(a) => cmd::plot::plot(&world, a),
        Command::Snapshot(a) => cmd::snapshot::snapshot(&world, a),
        Command::Export(a) => cmd::export::export(a),
        Command::Down(a) => down::down(&world, a),
        Command::Launch(a) => launch::launch(&cli.robot, cli.robot_explicit, a),
        Command::Logs(a) => logs::logs(&world, a),
        Command::Exec(a) => start::exec(&world, a),
        Command::Demo(a) => demo::run("demo", cli.robot_explicit.then_some(cli.robot.as_str()), a),
        Command::Calibrate(a) => demo::run("calibrate", cli.robot_explicit.then_some(cli.robot.as_str()), a),
        Command::Mem(c) => mem::mem(&world, c),
        Command::Cmd(a) => drive::cmd(&world, a),
        Command::Bench(a) => bench::bench(a),
        Command::Bridge(c) => bridge::bridge(&world, c),
    }
}
