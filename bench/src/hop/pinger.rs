//! A batch of round trips, whatever the transport ([`Pinger`]), and the
//! rows made of another row's pinger: under PM QoS ([`Row`]) and with this
//! thread kept on one CPU ([`Pinned`]).

use super::{PERIODIC, PINNED_CPU, TRANSPORTS, UNDER_PM_QOS};
use crate::procs::Robot;
use anyhow::{Context as _, Result};
use std::cell::RefCell;
use std::rc::Rc;
use std::time::Duration;

/// The ping side of every row: (payload size, row, pinger).
pub(crate) type Pingers = Vec<(usize, &'static str, Box<dyn Pinger>)>;

/// Something that runs a batch of round trips.
pub(crate) trait Pinger {
    fn batch(&mut self, robot: &Robot, count: usize) -> Result<Vec<u64>>;
    /// round trips of the last batch whose two ends shared a CPU, where known
    fn same_cpu(&self) -> Option<usize> {
        None
    }
}

/// A pinger measured in two rows: as it is, and under PM QoS.
pub(crate) type SharedPinger = Rc<RefCell<Box<dyn Pinger>>>;

/// The row of a [`SharedPinger`]: its batches run with or without this
/// process holding a PM QoS bound of 0 µs for the batch.
pub(crate) struct Row {
    pub(crate) pinger: SharedPinger,
    pub(crate) pm_qos: bool,
}

impl Row {
    /// The two rows of one pinger: as it is, and under PM QoS.
    pub(crate) fn both(p: Box<dyn Pinger>) -> (Row, Row) {
        let shared: SharedPinger = Rc::new(RefCell::new(p));
        (Row { pinger: Rc::clone(&shared), pm_qos: false }, Row { pinger: shared, pm_qos: true })
    }
}

impl Pinger for Row {
    fn batch(&mut self, robot: &Robot, count: usize) -> Result<Vec<u64>> {
        let _hold = if self.pm_qos {
            let h =
                agent_sdk::cpu_latency::hold(0).context("the -pmqos rows need /dev/cpu_dma_latency (run as root)")?;
            // idle CPUs re-pick their state when the bound changes
            std::thread::sleep(Duration::from_millis(2));
            Some(h)
        } else {
            None
        };
        self.pinger.borrow_mut().batch(robot, count)
    }

    fn same_cpu(&self) -> Option<usize> {
        self.pinger.borrow().same_cpu()
    }
}

/// Whether this process may hold a PM QoS bound; says so when not (the
/// `-pmqos` rows are left out, as a missing peer's are).
pub(crate) fn pm_qos_permitted(scenario: &str) -> bool {
    match agent_sdk::cpu_latency::hold(0) {
        Ok(_) => true,
        Err(e) => {
            eprintln!("{scenario}: warning: no -pmqos rows: {e}");
            false
        }
    }
}

/// A pinger whose batches run with this thread kept on [`PINNED_CPU`]
/// (the pong was started there): placement without PM QoS.
pub(crate) struct Pinned(pub(crate) Box<dyn Pinger>);

impl Pinger for Pinned {
    fn batch(&mut self, robot: &Robot, count: usize) -> Result<Vec<u64>> {
        let all =
            agent_sdk::rt::CpuList((0..std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1)).collect());
        agent_sdk::rt::set_affinity(&agent_sdk::rt::CpuList(vec![PINNED_CPU])).map_err(anyhow::Error::msg)?;
        let r = self.0.batch(robot, count);
        agent_sdk::rt::set_affinity(&all).map_err(anyhow::Error::msg)?;
        r
    }

    fn same_cpu(&self) -> Option<usize> {
        self.0.same_cpu()
    }
}

/// The rows of [`UNDER_PM_QOS`] measured twice: as they are, and as their
/// `-pmqos` row sharing the same pinger (when `permitted`).
pub(crate) fn with_pm_qos_rows(pingers: Pingers, permitted: bool) -> Pingers {
    pingers
        .into_iter()
        .flat_map(|(size, t, p)| {
            let Some(&pmqos) = UNDER_PM_QOS.iter().find(|x| **x == t && permitted) else {
                return vec![(size, t, p)];
            };
            let pmqos_name = TRANSPORTS
                .iter()
                .chain(PERIODIC.iter())
                .copied()
                .find(|x| x.strip_suffix("-pmqos") == Some(pmqos))
                .unwrap_or(t);
            let (plain, held) = Row::both(p);
            vec![(size, t, Box::new(plain) as Box<dyn Pinger>), (size, pmqos_name, Box::new(held))]
        })
        .collect()
}
