//! One module per family of commands; [`dispatch`] routes the parsed command line.

pub mod bench;
pub mod bridge;
pub mod calibrate;
pub mod cooperate;
pub mod demo;
pub mod down;
pub mod drive;
mod echo;
mod inspect;
mod launch;
mod logs;
pub mod mem;
pub mod shm_space;
pub mod start;
pub mod tap;
mod wire;

use crate::cli::{Cli, Command};
use agent_sdk::World;
use anyhow::Result;
use std::process::ExitCode;

pub fn dispatch(cli: Cli) -> Result<ExitCode> {
    let world = World::new(&cli.robot)?;
    match cli.command {
        Command::Router(a) => start::router(&world, a),
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
        Command::Echo(a) => echo::echo(&world, a),
        Command::Hz(a) => echo::hz(&world, a),
        Command::Down(a) => down::down(&world, a),
        Command::Launch(a) => launch::launch(&cli.robot, cli.robot_explicit, a),
        Command::Logs(a) => logs::logs(&world, a),
        Command::Exec(a) => start::exec(&world, a),
        Command::Demo(c) => demo::demo(&cli.robot, c),
        Command::Calibrate(c) => calibrate::calibrate(&cli.robot, cli.robot_explicit, c),
        Command::Mem(c) => mem::mem(&world, c),
        Command::Cmd(a) => drive::cmd(&world, a),
        Command::Bench(a) => bench::bench(a),
        Command::Bridge(c) => bridge::bridge(&world, c),
    }
}
