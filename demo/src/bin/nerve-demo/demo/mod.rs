//! `nerve demo`: the experiments of the thesis from one command, each in
//! its module ([`explore`]: section 4.2, [`cooperate`]: section 4.3). Both
//! derive the run's launch files from templates of the source tree, bring
//! the robots up and down with the `nerve` executable ([`crate::nerve`]),
//! record the run through taps and hand what they recorded to this crate's
//! library, which analyses it and writes the figures. What they share is
//! here: finding the templates, deriving launch files, how a run ended.

mod cooperate;
mod explore;

use anyhow::{Context as _, Result, bail};
use std::path::{Path, PathBuf};
use std::process::ExitCode;

/// `nerve demo ...`
#[derive(Debug, clap::Subcommand)]
pub enum DemoCmd {
    /// The exploration experiment (thesis 4.2): through a crowded room and a
    /// doorway to a person with a red object, who leads the robot into a U-turn.
    Explore(explore::ExploreArgs),
    /// The cooperation experiment (thesis 4.3): robot 1 finds the target and
    /// sends robot 2 a path over the bridge; robot 2 follows it, corrected at
    /// the checkpoints, and grasps.
    Cooperate(cooperate::CooperateArgs),
}

/// Runs a demo.
pub fn demo(robot: &str, cmd: DemoCmd) -> Result<ExitCode> {
    match cmd {
        DemoCmd::Explore(a) => explore::explore(robot, a),
        DemoCmd::Cooperate(a) => cooperate::cooperate(a),
    }
}

/// Finds `rel` relative to the current directory, else above the running
/// executable (`<tree>/target/<profile>/nerve-demo`), else in the source
/// tree this program was compiled from.
fn find_file(rel: &Path, what: &str) -> Result<PathBuf> {
    if rel.is_absolute() || rel.exists() {
        return std::fs::canonicalize(rel).with_context(|| format!("cannot use {what} {}", rel.display()));
    }
    let exe = std::env::current_exe().context("cannot find the nerve-demo executable")?;
    // the source tree this program was built from (also when CARGO_TARGET_DIR is elsewhere)
    let built_from = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    for dir in exe.ancestors().skip(1).chain(std::iter::once(built_from.as_path())) {
        let p = dir.join(rel);
        if p.exists() {
            return std::fs::canonicalize(&p).with_context(|| format!("cannot use {what} {}", p.display()));
        }
    }
    bail!(
        "cannot find {what} {} (looked in the current directory and above {}); run from the nerve source tree or give its path",
        rel.display(),
        exe.display()
    )
}

/// Sets `--flag value` in an argument list (replacing or appending).
fn set_flag(args: &mut Vec<toml::Value>, flag: &str, value: String) {
    if let Some(i) = args.iter().position(|a| a.as_str() == Some(flag)) {
        if i + 1 < args.len() {
            args[i + 1] = toml::Value::String(value);
            return;
        }
        args.truncate(i);
    }
    args.push(toml::Value::String(flag.to_owned()));
    args.push(toml::Value::String(value));
}

/// Makes relative paths among `args` that exist under `base` absolute
/// (daemons may run from any directory).
fn absolutize_args(args: &mut [toml::Value], base: &Path) {
    for v in args.iter_mut() {
        if let Some(s) = v.as_str() {
            let p = Path::new(s);
            if s.contains('/') && !s.starts_with('-') && !s.contains('{') && p.is_relative() && base.join(p).exists() {
                *v = toml::Value::String(base.join(p).display().to_string());
            }
        }
    }
}

/// How a run ended.
#[derive(Debug, Clone, PartialEq)]
enum End {
    /// The experiment did what it shows; the text says what.
    Goal(&'static str),
    TimeLimit,
    Interrupted,
    Stalled(String),
}

impl End {
    /// The run's `end_reason` in `summary.json`.
    fn reason(&self) -> String {
        match self {
            End::Goal(what) => (*what).into(),
            End::TimeLimit => "time limit".into(),
            End::Interrupted => "interrupted".into(),
            End::Stalled(why) => format!("stalled: {why}"),
        }
    }

    /// Lists the figures written, under the `wrote ...` line, and gives the
    /// command's exit code: 1 for a run that stalled.
    fn finish(&self, figures: &[std::path::PathBuf]) -> std::process::ExitCode {
        for f in figures {
            println!("  {}", f.display());
        }
        if let End::Stalled(why) = self {
            eprintln!("error: the run stalled: {why}");
            return std::process::ExitCode::from(1);
        }
        std::process::ExitCode::SUCCESS
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flags_are_replaced_or_appended() {
        let mut v: Vec<toml::Value> =
            ["--world", "a", "--x"].iter().map(|s| toml::Value::String((*s).into())).collect();
        set_flag(&mut v, "--world", "b".into());
        set_flag(&mut v, "--seed", "3".into());
        let s: Vec<&str> = v.iter().filter_map(|x| x.as_str()).collect();
        assert_eq!(s, ["--world", "b", "--x", "--seed", "3"]);
    }
}
