//! `via-path`: a hand-driven source of `nerve::ViaPath` (output `path`, a
//! sequence: as many points as given, up to `VIA_PATH_MAX_LEN`),
//! to drive robot 2's mission agent or target achiever without robot 1, and
//! to script the multi-process tests. It publishes the path given with
//! `-- --points "X,Y[,KIND];..."` (KIND: `checkpoint`, `target-approach`,
//! `target`, `waypoint`; default `waypoint`) as path `--path-id N`
//! (default 1), once a period (default 1 s), as the map builder repeats its
//! path. Parameter `path_id` changes the id at run time (a new path).
//!
//! ```sh
//! nerve start via-path --name plan -- --points "-3,0;-2.4,0,target"
//! nerve connect plan/path mission/path_in
//! ```

use agent_sdk::{Agent, AgentError, Context, Param, SeqOutput, Setup, Task};
use shm_schemas::payloads::{VIA_PATH_MAX_LEN, ViaKind, ViaPathBuf, ViaPathHeader, ViaPoint};
use std::time::Duration;

/// Arguments after `--`.
#[derive(Debug, clap::Parser)]
#[command(name = "nerve-via-path")]
struct Args {
    /// The points, `X,Y[,KIND];...` (metres, world frame; may start with a minus).
    #[arg(long, allow_hyphen_values = true)]
    points: String,
    /// The path's id (from 1).
    #[arg(long, default_value_t = 1)]
    path_id: u32,
}

/// Parses `X,Y[,KIND];...` into a path.
fn parse_points(s: &str, path_id: u32) -> Result<ViaPathBuf, String> {
    let mut p = ViaPathBuf::new(path_id, 0);
    for (i, item) in s.split(';').map(str::trim).filter(|t| !t.is_empty()).enumerate() {
        if i >= VIA_PATH_MAX_LEN {
            return Err(format!("more than {VIA_PATH_MAX_LEN} points"));
        }
        let f: Vec<&str> = item.split(',').map(str::trim).collect();
        let num = |k: usize| -> Result<f64, String> {
            f.get(k)
                .ok_or_else(|| format!("point {} ({item:?}) needs X,Y", i + 1))?
                .parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| format!("point {} ({item:?}): {:?} is not a number", i + 1, f[k]))
        };
        let k = f.get(2).copied().unwrap_or("waypoint");
        let kind = ViaKind::ALL.into_iter().find(|v| v.name() == k).ok_or_else(|| {
            format!(
                "point {} ({item:?}): unknown kind {k:?}; use checkpoint, target-approach, target or waypoint",
                i + 1
            )
        })?;
        if f.len() > 3 {
            return Err(format!("point {} ({item:?}): X,Y[,KIND] only", i + 1));
        }
        let xy = [num(0)?, num(1)?];
        p.points.push(ViaPoint::new(xy, kind, 0, xy));
    }
    if p.points.is_empty() {
        return Err("no points: give `-- --points \"X,Y[,KIND];...\"`".into());
    }
    if path_id == 0 {
        return Err("--path-id is at least 1".into());
    }
    Ok(p)
}

struct ViaPathSource {
    out: SeqOutput<ViaPoint, ViaPathHeader>,
    path: ViaPathBuf,
    path_id: Param<u32>,
}

impl Agent for ViaPathSource {
    const KIND: &'static str = "via-path";

    fn task() -> Task {
        Task::Periodic(Duration::from_secs(1))
    }

    fn new(setup: &mut Setup) -> Result<Self, AgentError> {
        let args: Args = setup.args()?;
        let path =
            parse_points(&args.points, args.path_id).map_err(|e| AgentError::Config(format!("--points: {e}")))?;
        Ok(ViaPathSource {
            out: setup.output_seq("path", VIA_PATH_MAX_LEN)?,
            path,
            path_id: setup.param_checked("path_id", args.path_id, |v| {
                if *v >= 1 { Ok(()) } else { Err("path_id is at least 1".into()) }
            }),
        })
    }

    fn step(&mut self, ctx: &mut Context) -> Result<(), AgentError> {
        let header = ViaPathHeader { stamp_ns: ctx.now_ns(), path_id: self.path_id.get(), ..self.path.header };
        self.out.send(&header, &self.path.points)?;
        Ok(())
    }
}

fn main() -> std::process::ExitCode {
    agent_sdk::run::<ViaPathSource>()
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    #[test]
    fn points_parse_with_kinds_and_bad_ones_are_named() {
        let p = parse_points("-3,0; -2.4, 0.5, target", 2).unwrap();
        assert_eq!((p.path_id(), p.points.len()), (2, 2));
        assert_eq!(p.points[1].point, [-2.4, 0.5]);
        assert_eq!(p.points[0].kind, ViaKind::Waypoint as u8);
        assert_eq!(p.points[1].kind, ViaKind::Target as u8);
        assert!(parse_points("", 1).unwrap_err().contains("no points"));
        assert!(parse_points("1", 1).unwrap_err().contains("needs X,Y"));
        assert!(parse_points("1,x", 1).unwrap_err().contains("not a number"));
        assert!(parse_points("1,2,door", 1).unwrap_err().contains("unknown kind"));
        assert!(parse_points("1,2", 0).unwrap_err().contains("at least 1"));
    }
}
