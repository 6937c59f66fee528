//! An agent's own arguments: what follows `--` on its command line
//! (`nerve start sonar -- --device /dev/ttyUSB0`), parsed with clap into the
//! agent's own `#[derive(clap::Parser)]` struct. [`crate::Setup::args`] is
//! what an agent calls; [`parse`] is the same parsing for a `main` that
//! looks at them before the SDK runs (the camera derives its period from
//! `--fps`).
//!
//! The usage and `--help` name the program as `nerve-KIND --` (the name of
//! the struct's package, or its `#[command(name = ...)]`, with ` --` added
//! when it lacks it), since these are the arguments that come after `--`.

/// Why an agent's own arguments gave no value.
#[derive(Debug, thiserror::Error)]
pub enum ArgsError {
    /// `--help` or `--version` was given: clap's text is to be printed,
    /// and the agent not started.
    #[error("{0}")]
    Help(#[source] clap::Error),
    /// clap refused them (an unknown option, a bad value, a missing one).
    #[error("agent {agent:?}: its own arguments (after `--`) are refused: {reason}; `{program} --help` lists them")]
    Refused {
        /// the agent's name
        agent: String,
        /// the program as usage names it: `nerve-sonar --`
        program: String,
        /// clap's first line, without its `error: `
        reason: String,
        /// clap's whole error
        #[source]
        source: clap::Error,
    },
}

/// Parses `args` (those after `--`) of agent `agent` into `T`.
pub fn parse<T: clap::Parser>(agent: &str, args: &[String]) -> Result<T, ArgsError> {
    // `nerve-sonar --`, whether the struct is named `nerve-sonar` (its
    // package, by default) or already `nerve-sonar --`
    let command = T::command();
    let program = format!("{} --", command.get_name().trim_end_matches("--").trim_end());
    T::try_parse_from(std::iter::once(program.clone()).chain(args.iter().cloned())).map_err(|source| {
        use clap::error::ErrorKind;
        match source.kind() {
            ErrorKind::DisplayHelp
            | ErrorKind::DisplayVersion
            | ErrorKind::DisplayHelpOnMissingArgumentOrSubcommand => ArgsError::Help(source),
            _ => {
                let text = source.to_string();
                // clap's first paragraph says what is wrong; usage and a
                // `--help` hint (which would name the common options) follow
                let first = text.split("\n\n").next().unwrap_or_default().trim();
                let reason = first.strip_prefix("error: ").unwrap_or(first).replace('\n', " ");
                ArgsError::Refused { agent: agent.to_owned(), program, reason, source }
            }
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::PathBuf;

    /// A device agent's arguments.
    #[derive(Debug, clap::Parser)]
    #[command(name = "nerve-sonar")]
    struct Args {
        /// Serial port of the sonar module.
        #[arg(long)]
        device: Option<PathBuf>,
        /// Scans per second.
        #[arg(long, default_value_t = 4)]
        rate: u32,
    }

    fn strings(a: &[&str]) -> Vec<String> {
        a.iter().map(|s| s.to_string()).collect()
    }

    #[test]
    fn the_arguments_after_the_dashes_are_parsed() {
        let a: Args = parse("sonar", &[]).expect("no arguments: the defaults");
        assert_eq!((a.device, a.rate), (None, 4));
        let a: Args = parse("sonar", &strings(&["--device", "/dev/ttyUSB0", "--rate=8"])).expect("parsed");
        assert_eq!((a.device, a.rate), (Some(PathBuf::from("/dev/ttyUSB0")), 8));
    }

    #[test]
    fn a_refusal_names_the_agent_the_option_and_what_to_do() {
        let e = parse::<Args>("front", &strings(&["--devise", "/dev/x"])).expect_err("unknown option");
        let msg = e.to_string();
        assert!(matches!(e, ArgsError::Refused { .. }), "{e:?}");
        assert!(msg.contains("agent \"front\""), "{msg}");
        assert!(msg.contains("--devise"), "names the bad option: {msg}");
        assert!(msg.contains("`nerve-sonar -- --help` lists them"), "{msg}");
        assert!(!msg.contains("Usage"), "one line: {msg}");
        let e = parse::<Args>("front", &strings(&["--rate", "fast"])).expect_err("not a number");
        assert!(e.to_string().contains("fast"), "{e}");
    }

    /// Named as some agents name theirs.
    #[derive(Debug, clap::Parser)]
    #[command(name = "nerve-odometry --")]
    struct Dashed {
        #[arg(long)]
        start: Option<String>,
    }

    #[test]
    fn the_program_is_named_with_the_dashes_once() {
        let e = parse::<Dashed>("odometry", &strings(&["--stat", "0"])).expect_err("unknown");
        assert!(e.to_string().contains("`nerve-odometry -- --help`"), "{e}");
    }

    #[test]
    fn help_lists_the_agents_own_options() {
        let e = parse::<Args>("front", &strings(&["--help"])).expect_err("help is not a value");
        let ArgsError::Help(help) = &e else { panic!("not help: {e:?}") };
        let text = help.to_string();
        assert!(text.contains("Usage: nerve-sonar -- [OPTIONS]"), "{text}");
        assert!(text.contains("--device") && text.contains("Serial port of the sonar module"), "{text}");
    }
}
