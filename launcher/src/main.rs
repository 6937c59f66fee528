//! `nerve`: the command line of the nerve framework. A thin `main`: parse,
//! dispatch, print the error with what to do, exit with a meaningful code
//! (0 success, 1 failure, 2 bad usage).

mod cli;
mod client;
mod cmd;
mod kinds;
mod launch_file;

use clap::Parser;
use std::process::ExitCode;

fn main() -> ExitCode {
    let args = cli::Cli::parse();
    agent_sdk::world::quiet_iceoryx2();
    match cmd::dispatch(args) {
        Ok(code) => code,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(1)
        }
    }
}
