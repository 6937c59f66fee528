//! The head every scenario's report starts with, and the report around a
//! scenario's own results: `Report<T>` is written as one flat JSON object
//! (`scenario`, `command`, `machine`, then the fields of `T`), the shape the
//! result files have always had.

use crate::machine::{Machine, command_line};
use serde::Serialize;

/// What every report says first: which scenario, the command that produced
/// it, and the machine it ran on.
#[derive(Debug, Clone, Serialize)]
pub struct Head {
    /// the scenario's name (`hop`, `jitter`...); the control scenario's
    /// files never had one, and still have none
    #[serde(skip_serializing_if = "Option::is_none")]
    pub scenario: Option<&'static str>,
    /// the command that produced it
    pub command: String,
    /// the machine
    pub machine: Machine,
}

/// A scenario's report: the [`Head`], then the scenario's results `T`,
/// flattened into one JSON object. It reads as `T` (`report.rounds`).
#[derive(Debug, Clone, Serialize)]
pub struct Report<T> {
    /// scenario, command, machine
    #[serde(flatten)]
    pub head: Head,
    /// the scenario's own results
    #[serde(flatten)]
    pub body: T,
}

impl<T> Report<T> {
    /// The report of `scenario` run by this process's command line on `machine`.
    pub fn new(scenario: &'static str, machine: Machine, body: T) -> Self {
        Report { head: Head { scenario: Some(scenario), command: command_line(), machine }, body }
    }

    /// A report without a scenario field (the control scenario's shape).
    pub fn unnamed(machine: Machine, body: T) -> Self {
        Report { head: Head { scenario: None, command: command_line(), machine }, body }
    }
}

impl<T> std::ops::Deref for Report<T> {
    type Target = T;

    fn deref(&self) -> &T {
        &self.body
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, Clone, Serialize)]
    struct Body {
        rounds: usize,
        seconds: f64,
    }

    #[test]
    fn a_report_is_one_flat_object_with_the_head_first() {
        let r = Report::new("hop", Machine::probe(), Body { rounds: 3, seconds: 1.5 });
        let text = serde_json::to_string(&r).expect("a report encodes");
        let at: Vec<usize> = ["\"scenario\":", "\"command\":", "\"machine\":", "\"rounds\":", "\"seconds\":"]
            .iter()
            .map(|k| text.find(k).unwrap_or_else(|| panic!("{k} missing in {text}")))
            .collect();
        assert!(at.windows(2).all(|w| w[0] < w[1]), "fields out of order: {text}");
        let v: serde_json::Value = serde_json::from_str(&text).expect("JSON");
        assert_eq!(v["scenario"], "hop");
        assert!(v["machine"]["nproc"].is_u64());
        assert_eq!(r.rounds, 3);
        let unnamed = serde_json::to_value(Report::unnamed(Machine::probe(), Body { rounds: 1, seconds: 0.0 }))
            .expect("a report encodes");
        assert!(unnamed.get("scenario").is_none(), "the control scenario's files have no scenario field");
    }
}
