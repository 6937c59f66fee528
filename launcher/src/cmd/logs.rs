//! `nerve logs NAME [--lines N] [--follow]`: an agent's log. The whole log
//! is copied through a fixed buffer; `--lines N` and `--follow` read it
//! through [`crate::agent_logs`], which never loads a whole file.

use crate::agent_logs::{Tail, last_lines};
use crate::interrupt;
use agent_sdk::World;
use anyhow::{Context as _, Result, bail};
use std::io::{Read, Write};
use std::process::ExitCode;
use std::time::Duration;

/// `nerve logs`
#[derive(Debug, clap::Args)]
pub struct LogsArgs {
    /// Agent name (or `router`).
    pub name: String,
    /// Keep printing new lines.
    #[arg(long, short)]
    pub follow: bool,
    /// Only the last N lines.
    #[arg(long, short = 'n')]
    pub lines: Option<usize>,
}

pub fn logs(world: &World, a: LogsArgs) -> Result<ExitCode> {
    let path = world.log_file(&a.name);
    if !path.exists() {
        let known: Vec<String> = std::fs::read_dir(world.logs_dir())
            .map(|rd| {
                rd.filter_map(|e| e.ok())
                    .filter_map(|e| e.path().file_stem().map(|s| s.to_string_lossy().into_owned()))
                    .collect()
            })
            .unwrap_or_default();
        bail!(
            "no log for {:?} in {} (logs exist for: {}); agents started with --daemon log there",
            a.name,
            world.logs_dir().display(),
            if known.is_empty() { "none".into() } else { known.join(", ") }
        );
    }
    let mut f = std::fs::File::open(&path).with_context(|| format!("cannot read {}", path.display()))?;
    let mut out = std::io::stdout().lock();
    let end = match a.lines {
        Some(n) => {
            let (bytes, end) = last_lines(&mut f, n).with_context(|| format!("cannot read {}", path.display()))?;
            out.write_all(&bytes)?;
            end
        }
        None => {
            // what is there now, through a fixed buffer; lines written
            // meanwhile come with --follow
            let end = f.metadata()?.len();
            std::io::copy(&mut (&mut f).take(end), &mut out)?;
            end
        }
    };
    out.flush()?;
    drop(out);
    if a.follow {
        interrupt::catch();
        let mut tail = Tail::new(path, end);
        while !interrupt::requested() {
            for l in tail.poll() {
                println!("{l}");
            }
            std::thread::sleep(Duration::from_millis(100));
        }
    }
    Ok(ExitCode::SUCCESS)
}
