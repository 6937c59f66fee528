//! `nerve`: the command line of the nerve framework. A thin `main`: parse,
//! dispatch, print the error with what to do, exit with a meaningful code
//! (0 success, 1 failure, 2 bad usage).

mod cli;
mod client;
mod cmd;
mod interrupt;
mod kinds;
mod launch_file;

use clap::{CommandFactory, FromArgMatches};
use std::process::ExitCode;

fn main() -> ExitCode {
    let matches = cli::Cli::command().get_matches();
    let mut args = match cli::Cli::from_arg_matches(&matches) {
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
    match cmd::dispatch(args) {
        Ok(code) => code,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(1)
        }
    }
}
