//! `detector`: an agent with a variable-size output (issue 42), as a team's
//! detector would have: `dets`, a header and any number of detections
//! (`Seq<Detection, DetectionsHeader>`, at most 1,000 a sample), and an
//! input `dets_in` of the same type.
//!
//! Periodic (20 ms). Step `n` sends `LENGTHS[(n - 1) % 4]` detections
//! (0, 1, 400, 401: the third is larger than the port's first memory, so
//! the port grows, and the fourth is the largest seen plus one), detection
//! `j` at `x = j`, `y = n`, `id = j`; and tries 1,001, past its maximum,
//! which is refused (nothing sent). Its figures: `refused` (how many were),
//! `refusal` (the last message), and of what `dets_in` read: `received`,
//! `largest` (elements) and `bad` (samples whose elements were not the ones sent).

use agent_sdk::{Agent, AgentError, Context, PortError, SeqInput, SeqOutput, Setup, Task};
use shm_schemas::Payload;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

/// One detection.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize, Payload)]
#[payload(name = "acme::Detection")]
#[repr(C)]
pub struct Detection {
    /// position, m
    pub x: f32,
    /// position, m
    pub y: f32,
    /// its number
    pub id: u32,
}

/// What comes before the detections.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize, Payload)]
#[payload(name = "acme::DetectionsHeader")]
#[repr(C)]
pub struct DetectionsHeader {
    /// the step that sent it
    pub frame: u64,
    /// how many detections follow (the sample's length says it too)
    pub count: u32,
    /// explicit padding
    #[serde(skip)]
    pub _pad: [u8; 4],
}

/// The lengths sent, in turn.
const LENGTHS: [usize; 4] = [0, 1, 400, 401];
/// The most detections a sample may hold.
const MAX: usize = 1000;

#[derive(Default)]
struct Seen {
    received: AtomicU64,
    largest: AtomicU64,
    bad: AtomicU64,
    refused: AtomicU64,
    refusal: Mutex<String>,
}

struct Detector {
    dets: SeqOutput<Detection, DetectionsHeader>,
    dets_in: SeqInput<Detection, DetectionsHeader>,
    seen: Arc<Seen>,
    n: u64,
}

impl Agent for Detector {
    const KIND: &'static str = "detector";

    fn task() -> Task {
        Task::Periodic(Duration::from_millis(20))
    }

    fn new(setup: &mut Setup) -> Result<Self, AgentError> {
        let seen = Arc::new(Seen::default());
        let figures = seen.clone();
        setup.figures(move || {
            let refusal = figures.refusal.lock().map(|r| r.clone()).unwrap_or_default();
            vec![
                ("received".into(), figures.received.load(Ordering::Relaxed).to_string()),
                ("largest".into(), figures.largest.load(Ordering::Relaxed).to_string()),
                ("bad".into(), figures.bad.load(Ordering::Relaxed).to_string()),
                ("refused".into(), figures.refused.load(Ordering::Relaxed).to_string()),
                ("refusal".into(), refusal),
            ]
        });
        Ok(Detector { dets: setup.output_seq("dets", MAX)?, dets_in: setup.input_seq("dets_in")?, seen, n: 0 })
    }

    fn step(&mut self, _ctx: &mut Context) -> Result<(), AgentError> {
        let seen = &self.seen;
        self.dets_in.drain(|_, header, items| {
            seen.received.fetch_add(1, Ordering::Relaxed);
            seen.largest.fetch_max(items.len() as u64, Ordering::Relaxed);
            let right = header.count as usize == items.len()
                && items.iter().enumerate().all(|(j, d)| d.id as usize == j && d.y == header.frame as f32);
            if !right {
                seen.bad.fetch_add(1, Ordering::Relaxed);
            }
        });
        self.n += 1;
        let (frame, len) = (self.n, LENGTHS[(self.n as usize - 1) % LENGTHS.len()]);
        self.dets.send_with(len, |header, items| {
            *header = DetectionsHeader { frame, count: len as u32, _pad: [0; 4] };
            for (j, d) in items.iter_mut().enumerate() {
                *d = Detection { x: j as f32, y: frame as f32, id: j as u32 };
            }
        })?;
        match self.dets.send_with(MAX + 1, |_, _| {}) {
            Err(e @ PortError::TooLong { .. }) => {
                seen.refused.fetch_add(1, Ordering::Relaxed);
                if let Ok(mut r) = seen.refusal.lock() {
                    *r = e.to_string();
                }
                Ok(())
            }
            Err(e) => Err(e.into()),
            Ok(()) => Err(AgentError::Config(format!("{} detections were sent past the maximum {MAX}", MAX + 1))),
        }
    }
}

fn main() -> std::process::ExitCode {
    agent_sdk::run::<Detector>()
}
