//! `nerve demo explore|cooperate ...` and `nerve calibrate checkpoint ...`:
//! the experiments of the thesis and the checkpoint sensor's calibration,
//! which live in the program `nerve-demo` (crate `demo/`). These commands
//! run it in place of this process, found next to `nerve` or on `PATH` (as
//! `nerve bench` runs `nerve-bench`), so that its progress, files, exit
//! status and Ctrl-C behave exactly as if it had been called directly; it
//! brings robots up and down with this very `nerve` (`NERVE_BIN`).
//! `nerve demo --help` and `nerve calibrate --help` are its help.

use super::bench::exec_program;
use anyhow::Result;
use std::process::ExitCode;

/// The program that holds the demos and the calibrations.
const DEMO_PROGRAM: &str = "nerve-demo";

/// How to build it, for the error where it is missing.
const BUILD_HINT: &str = "build it with `cargo build --release -p nerve-demo -p nerve --bins` (with the agents the \
                          demo launches: `bash scripts/demo.sh` builds all of them) and run target/release/nerve";

/// `nerve demo` and `nerve calibrate`: everything after the command, for `nerve-demo`.
#[derive(Debug, clap::Args)]
#[command(disable_help_flag = true)]
pub struct DemoArgs {
    /// `explore` or `cooperate` (`nerve calibrate`: `checkpoint`) and its
    /// options; `--help` lists them.
    #[arg(trailing_var_arg = true, allow_hyphen_values = true)]
    pub args: Vec<String>,
}

/// Replaces this process with `nerve-demo [--robot ROBOT] COMMAND ARGS...`
/// (`COMMAND` is `demo` or `calibrate`); the robot is passed on where it was
/// named on the command line (`NERVE_ROBOT` passes on by itself).
pub fn run(command: &str, robot: Option<&str>, a: DemoArgs) -> Result<ExitCode> {
    let mut args: Vec<String> = Vec::new();
    if let Some(r) = robot {
        args.extend(["--robot".to_owned(), r.to_owned()]);
    }
    args.push(command.to_owned());
    args.extend(a.args);
    exec_program(DEMO_PROGRAM, BUILD_HINT, &args)
}
