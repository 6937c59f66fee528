//! dora-rs's rows, when `scripts/setup.sh --bench` has built its nodes
//! ([`crate::dora`]): `dora` (ping-pong round trips, one `dora run` per
//! batch), `dora-5ms` and `dora-5ms-pinned` (dora's own pattern, one way, a
//! sample every 5 ms), and beside them nerve in the same pattern
//! (`nerve-5ms`, `nerve-5ms-pinned`: [`super::nerve::NervePeriodic`]).

use super::nerve::{NervePeriodic, agent_name};
use super::pinger::{Pinger, Pingers};
use super::{HopOpts, PERIODIC_PAIRS, PINNED_CPU};
use crate::dora::{DoraPeer, Pattern};
use crate::procs::Robot;
use anyhow::Result;
use std::rc::Rc;

/// dora, when built (said on stderr either way).
pub(super) fn find_peer(opts: &HopOpts) -> Option<Rc<DoraPeer>> {
    match DoraPeer::find(&opts.work, opts.verbose) {
        Ok(p) => {
            eprintln!("hop: {} with its nodes from {}", p.version, p.cache.display());
            Some(Rc::new(p))
        }
        Err(e) => {
            eprintln!("hop: warning: no dora rows ({e:#}); `scripts/setup.sh --bench` builds dora");
            None
        }
    }
}

/// The rows in dora's pattern of `size` (nerve's, then dora's), and dora's round trips.
pub(super) fn push_pingers(
    pingers: &mut Pingers,
    size: usize,
    opts: &HopOpts,
    peer: &Rc<DoraPeer>,
    periodic_count: usize,
) {
    for (src, sink, row, _) in PERIODIC_PAIRS {
        let (src, sink) = (agent_name(src, size), agent_name(sink, size));
        let (src_dir, sink_dir) = (opts.work.join(&src), opts.work.join(&sink));
        let p = NervePeriodic { src, sink, src_dir, sink_dir, count: periodic_count, next: 0 };
        pingers.push((size, row, Box::new(p)));
    }
    for (pattern, count) in [(Pattern::PingPong, None), (Pattern::Periodic, Some(periodic_count))] {
        let p = DoraPinger { peer: Rc::clone(peer), size, pattern, count, cpu: None };
        pingers.push((size, pattern.transport(), Box::new(p)));
    }
    if peer.can_pin() {
        let p = DoraPinger {
            peer: Rc::clone(peer),
            size,
            pattern: Pattern::Periodic,
            count: Some(periodic_count),
            cpu: Some(PINNED_CPU),
        };
        pingers.push((size, "dora-5ms-pinned", Box::new(p)));
    } else if size == opts.sizes[0] {
        eprintln!("hop: warning: no dora-5ms-pinned rows: `taskset` (util-linux) is not on PATH");
    }
}

/// A dora batch: one `dora run` (see [`crate::dora`]).
struct DoraPinger {
    peer: Rc<DoraPeer>,
    size: usize,
    pattern: Pattern,
    count: Option<usize>,
    /// both nodes kept on this CPU
    cpu: Option<usize>,
}

impl Pinger for DoraPinger {
    fn batch(&mut self, _robot: &Robot, count: usize) -> Result<Vec<u64>> {
        self.peer.batch(self.size, self.pattern, self.count.unwrap_or(count), self.cpu)
    }
}
