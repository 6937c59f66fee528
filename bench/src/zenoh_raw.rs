//! Raw Zenoh publish-subscribe between two plain processes: the floor the
//! bridge is measured against (hidden subcommands `__zenoh-pub` and
//! `__zenoh-sub`).
//!
//! Both open a session with exactly the bridge's settings: the
//! configuration comes from [`nerve_bridge::link::zenoh_config`] (peer mode,
//! the given tcp endpoints, multicast scouting off, the bridge's lease and
//! re-dialling), and the publisher is declared as the bridge declares its
//! own: `express`, `CongestionControl::Drop`. One key per payload size,
//! `nerve-bench/raw/<size>`; the payload is the sample's bytes alone, its
//! first 8 the sender's CLOCK_MONOTONIC stamp.
//!
//! Both are driven by lines on stdin and answer on stdout:
//!
//! | to | line | answer |
//! |---|---|---|
//! | pub | `send SIZE COUNT INTERVAL_US MAX_MS` | `sent N T_START T_END` once the batch is out |
//! | sub | `take SIZE COUNT WAIT_MS PATH` | `ok N` once COUNT samples arrived, or WAIT_MS passed and the key was quiet for 100 ms; the rows (stamp, 0, arrival) are in PATH |
//!
//! Both print `ready` once their session and declarations are up, and exit
//! at the end of stdin. Neither asks for real-time scheduling: Zenoh's
//! threads run SCHED_OTHER in the bridge too.

use crate::bridge_agents::{QUIET_NS, write_rows};
use crate::procs::{exit_status, parse_sub};
use agent_sdk::clock::{now_ns, sleep_until_ns};
use anyhow::{Context as _, Result, anyhow, bail};
use std::collections::HashMap;
use std::io::{BufRead as _, Write as _};
use std::path::PathBuf;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use zenoh::Wait as _;
use zenoh::qos::CongestionControl;

/// Arguments of `__zenoh-pub` and `__zenoh-sub`.
#[derive(Debug, clap::Parser)]
struct Args {
    /// endpoints to listen on (tcp/127.0.0.1:PORT)
    #[arg(long)]
    listen: Vec<String>,
    /// endpoints to connect to
    #[arg(long)]
    connect: Vec<String>,
    /// payload sizes, one key each
    #[arg(long, value_delimiter = ',', required = true)]
    sizes: Vec<usize>,
}

/// The key of a payload size.
pub fn key(size: usize) -> String {
    format!("nerve-bench/raw/{size}")
}

/// The bridge's Zenoh configuration for these endpoints.
fn config(a: &Args) -> Result<zenoh::Config> {
    // the bridge's own parser and settings; the import only makes the file valid
    let src = format!(
        "listen = {:?}\nconnect = {:?}\n[[import]]\nport = \"raw/pub/out\"\ntype = \"nerve::bench::Small8\"\n",
        a.listen, a.connect
    );
    let cfg = nerve_bridge::config::parse(&src, "raw-zenoh", &|_| true).map_err(|e| anyhow!("{e}"))?;
    nerve_bridge::link::zenoh_config(&cfg).map_err(|e| anyhow!("{e}"))
}

fn open(a: &Args) -> Result<zenoh::Session> {
    zenoh::open(config(a)?).wait().map_err(|e| anyhow!("cannot open the zenoh session: {e}"))
}

fn say(line: &str) -> Result<()> {
    let mut out = std::io::stdout().lock();
    writeln!(out, "{line}").context("stdout")?;
    out.flush().context("stdout")
}

fn num<T: std::str::FromStr>(w: Option<&str>, what: &str) -> Result<T> {
    w.and_then(|w| w.parse().ok()).ok_or_else(|| anyhow!("expected {what}"))
}

/// `__zenoh-pub`
pub fn pub_main(rest: Vec<String>) -> std::process::ExitCode {
    match parse_sub::<Args>("nerve-bench __zenoh-pub", rest) {
        Ok(a) => exit_status("raw zenoh pub", publish(&a)),
        Err(code) => code,
    }
}

fn publish(a: &Args) -> Result<()> {
    let session = open(a)?;
    let mut pubs = HashMap::new();
    for &size in &a.sizes {
        let p = session
            .declare_publisher(key(size))
            .congestion_control(CongestionControl::Drop)
            .express(true)
            .wait()
            .map_err(|e| anyhow!("cannot declare the publisher of {}: {e}", key(size)))?;
        pubs.insert(size, (p, vec![0u8; size.max(8)]));
    }
    say("ready")?;
    for line in std::io::stdin().lock().lines() {
        let line = line.context("stdin")?;
        let mut w = line.split_whitespace();
        match w.next() {
            Some("send") => {
                let size: usize = num(w.next(), "SIZE")?;
                let count: u64 = num(w.next(), "COUNT")?;
                let interval_ns = num::<u64>(w.next(), "INTERVAL_US")? * 1000;
                let max_ns = num::<u64>(w.next(), "MAX_MS")? * 1_000_000;
                let (p, buf) = pubs.get_mut(&size).ok_or_else(|| anyhow!("no publisher of {size} bytes"))?;
                let mut sent = 0u64;
                let t_start = now_ns();
                for i in 0..count {
                    if interval_ns > 0 {
                        sleep_until_ns(t_start + (i + 1) * interval_ns);
                    } else if now_ns() >= t_start + max_ns {
                        break;
                    }
                    buf[..8].copy_from_slice(&now_ns().to_le_bytes());
                    sent += u64::from(p.put(buf.clone()).wait().is_ok());
                }
                say(&format!("sent {sent} {t_start} {}", now_ns()))?;
            }
            Some(other) => bail!("unknown command {other:?}"),
            None => {}
        }
    }
    drop(pubs);
    let _ = session.close().wait();
    Ok(())
}

/// What the subscriber has received of one key.
#[derive(Default)]
struct Received {
    rows: Vec<[u64; 3]>,
    last_arrival: u64,
}

/// `__zenoh-sub`
pub fn sub_main(rest: Vec<String>) -> std::process::ExitCode {
    match parse_sub::<Args>("nerve-bench __zenoh-sub", rest) {
        Ok(a) => exit_status("raw zenoh sub", subscribe(&a)),
        Err(code) => code,
    }
}

fn subscribe(a: &Args) -> Result<()> {
    let session = open(a)?;
    let mut subs = Vec::new();
    let mut got: HashMap<usize, Arc<Mutex<Received>>> = HashMap::new();
    for &size in &a.sizes {
        let r = Arc::new(Mutex::new(Received::default()));
        got.insert(size, r.clone());
        let sub = session
            .declare_subscriber(key(size))
            .callback(move |s| {
                let t1 = now_ns();
                let mut stamp = [0u8; 8];
                let mut n = 0;
                for sl in s.payload().slices() {
                    let k = (8 - n).min(sl.len());
                    stamp[n..n + k].copy_from_slice(&sl[..k]);
                    n += k;
                    if n == 8 {
                        break;
                    }
                }
                let mut r = r.lock().unwrap_or_else(|p| p.into_inner());
                r.rows.push([u64::from_le_bytes(stamp), 0, t1]);
                r.last_arrival = t1;
            })
            .wait()
            .map_err(|e| anyhow!("cannot declare the subscriber of {}: {e}", key(size)))?;
        subs.push(sub);
    }
    say("ready")?;
    for line in std::io::stdin().lock().lines() {
        let line = line.context("stdin")?;
        let mut w = line.split_whitespace();
        match w.next() {
            Some("take") => {
                let size: usize = num(w.next(), "SIZE")?;
                let count: usize = num(w.next(), "COUNT")?;
                let wait = Duration::from_millis(num(w.next(), "WAIT_MS")?);
                let path = PathBuf::from(w.next().ok_or_else(|| anyhow!("expected PATH"))?);
                let r = got.get(&size).ok_or_else(|| anyhow!("no subscriber of {size} bytes"))?;
                let t0 = Instant::now();
                let rows = loop {
                    {
                        let mut g = r.lock().unwrap_or_else(|p| p.into_inner());
                        let quiet = now_ns().saturating_sub(g.last_arrival) >= QUIET_NS;
                        if g.rows.len() >= count || (t0.elapsed() >= wait && quiet) {
                            break std::mem::take(&mut g.rows);
                        }
                    }
                    std::thread::sleep(Duration::from_millis(1));
                };
                write_rows(&path, &rows).with_context(|| format!("cannot write {}", path.display()))?;
                say(&format!("ok {}", rows.len()))?;
            }
            Some(other) => bail!("unknown command {other:?}"),
            None => {}
        }
    }
    drop(subs);
    let _ = session.close().wait();
    Ok(())
}
