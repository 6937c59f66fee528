//! `nerve-demo`: the experiments of the thesis and the calibration of the
//! checkpoint sensor, as programs beside the middleware's command line.
//! `nerve demo ...` and `nerve calibrate ...` run this program in their
//! place (as `nerve bench` runs `nerve-bench`), with `NERVE_BIN` naming the
//! `nerve` executable, so their names, flags, output and exit codes are
//! this program's:
//!
//! * [`demo`]: `nerve demo explore` (section 4.2) and `nerve demo cooperate` (4.3);
//! * [`calibrate`]: `nerve calibrate checkpoint` (Appendix A).
//!
//! Robots are brought up and down by running that `nerve` ([`nerve`]:
//! `nerve --robot R launch FILE`, `nerve --robot R down`), and observed
//! through the ports and the router's socket for tools, as a user would;
//! the analysis and figures are this crate's library.
//!
//! Exit codes: 0 done, 1 failure (the error says what to do), 2 bad usage.

mod calibrate;
mod demo;
mod nerve;

use clap::{CommandFactory as _, FromArgMatches as _, Parser, Subcommand};
use std::process::ExitCode;

/// nerve: a robot's control system as a society of agents (the demos and calibrations).
#[derive(Debug, Parser)]
#[command(name = "nerve", bin_name = "nerve", version, about, long_about = None, propagate_version = true)]
struct Cli {
    /// Robot (isolated world) to work on.
    #[arg(long, global = true, env = "NERVE_ROBOT", default_value = agent_sdk::world::DEFAULT_ROBOT)]
    robot: String,
    /// The command.
    #[command(subcommand)]
    command: Command,
}

/// The commands of this program, as `nerve` names them.
#[derive(Debug, Subcommand)]
enum Command {
    /// Reproduce an experiment of the thesis (`nerve demo explore`).
    #[command(subcommand)]
    Demo(demo::DemoCmd),
    /// Calibrate a sensor (`nerve calibrate checkpoint`: Appendix A, in the simulator or from samples).
    #[command(subcommand)]
    Calibrate(calibrate::CalibrateCmd),
}

fn main() -> ExitCode {
    agent_sdk::abort_on_panic();
    let matches = Cli::command().get_matches();
    let cli = match Cli::from_arg_matches(&matches) {
        Ok(a) => a,
        Err(e) => e.exit(),
    };
    // a robot named on the command line (or in NERVE_ROBOT), not defaulted
    let explicit = matches!(
        matches.value_source("robot"),
        Some(clap::parser::ValueSource::CommandLine | clap::parser::ValueSource::EnvVariable)
    );
    agent_sdk::world::quiet_iceoryx2();
    let result = match cli.command {
        Command::Demo(c) => demo::demo(&cli.robot, c),
        Command::Calibrate(c) => calibrate::calibrate(&cli.robot, explicit, c),
    };
    match result {
        Ok(code) => code,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(1)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_command_line_is_consistent() {
        Cli::command().debug_assert();
    }
}
