//! The test harness for Python agents (`nerve.testing.Harness`): the
//! SDK's `agent_sdk::testing::Harness` running a Python agent in the test's
//! own process, with its ports bound to in-memory queues and a clock the
//! test moves. Calls cross as bytes of their layouts (`nerve/testing.py`
//! makes and reads them): the test calls the agent's services and answers
//! the calls the agent makes.

use crate::call::kind_of;
use crate::{MAKING, PyAgent, kind_and_task, period, seconds, to_py_err};
use agent_sdk::port::{CallError, CallId};
use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyBytes;

fn harness_err(e: impl std::fmt::Display) -> PyErr {
    PyRuntimeError::new_err(e.to_string())
}

/// A sample an output sent in a test: sender, sequence number, stamp, bytes.
type Sent<'py> = (String, u64, u64, Bound<'py, pyo3::types::PyBytes>);

/// An agent run in the test's own process (the SDK's
/// `agent_sdk::testing::Harness`): ports bound to in-memory queues, a
/// clock the test moves, no router and no shared memory.
#[pyclass(unsendable, module = "nerve._native")]
pub(crate) struct Harness {
    /// None once stopped
    h: Option<agent_sdk::testing::Harness<PyAgent>>,
}

impl Harness {
    fn get(&mut self) -> PyResult<&mut agent_sdk::testing::Harness<PyAgent>> {
        self.h.as_mut().ok_or_else(|| PyRuntimeError::new_err("the harness's agent was stopped"))
    }
}

#[pymethods]
impl Harness {
    #[new]
    #[pyo3(signature = (class, kind, period_s, name, args, params, period_override_s, suspended))]
    #[allow(clippy::too_many_arguments)]
    fn py_new(
        py: Python<'_>,
        class: Py<PyAny>,
        kind: String,
        period_s: Option<f64>,
        name: Option<String>,
        args: Vec<String>,
        params: Vec<(String, String)>,
        period_override_s: Option<f64>,
        suspended: bool,
    ) -> PyResult<Self> {
        let (kind, task) = kind_and_task(kind, period_s)?;
        let mut b = agent_sdk::testing::Harness::<PyAgent>::builder().args(args);
        if let Some(n) = &name {
            b = b.name(n);
        }
        for (k, v) in &params {
            b = b.param(k, v);
        }
        if let Some(p) = period_override_s {
            b = b.period(period(p)?);
        }
        if suspended {
            b = b.suspended();
        }
        MAKING.with(|m| *m.borrow_mut() = Some((kind, task, class.clone_ref(py))));
        let made = b.start();
        MAKING.with(|m| *m.borrow_mut() = None);
        Ok(Harness { h: Some(made.map_err(harness_err)?) })
    }

    /// The Python agent object.
    #[getter]
    fn agent(&mut self, py: Python<'_>) -> PyResult<Py<PyAny>> {
        Ok(self.get()?.agent().obj.clone_ref(py))
    }

    /// Queues `data` (the layout's bytes) on input `input` from `sender`.
    fn send_bytes(&mut self, input: &str, sender: &str, data: &[u8]) -> PyResult<()> {
        self.get()?.send_bytes_from(input, sender, data).map_err(harness_err)
    }

    /// What output `port` sent since the last call: (sender, seq, stamp_ns, bytes).
    fn output_bytes<'py>(&mut self, py: Python<'py>, port: &str) -> PyResult<Vec<Sent<'py>>> {
        let got = self.get()?.output_bytes(port).map_err(harness_err)?;
        Ok(got
            .into_iter()
            .map(|(m, b)| (m.sender.as_str().to_owned(), m.seq, m.stamp_ns, pyo3::types::PyBytes::new(py, &b)))
            .collect())
    }

    /// Calls service `service` of the agent with `data` (the request
    /// layout's bytes); the agent's step answers it. Returns the call's id.
    fn call_bytes(&mut self, service: &str, data: &[u8]) -> PyResult<u64> {
        self.get()?.call(service, data.to_vec()).map(|id| id.0).map_err(harness_err)
    }

    /// The answers service `service` gave the test's calls since the last
    /// look: (id, answer bytes, None, None) or (id, None, error kind, message).
    fn answers_bytes<'py>(&mut self, py: Python<'py>, service: &str) -> PyResult<Vec<crate::call::Taken<'py>>> {
        let got = self.get()?.answers::<Vec<u8>>(service).map_err(harness_err)?;
        Ok(got
            .into_iter()
            .map(|(id, r)| match r {
                Ok(b) => (id.0, Some(PyBytes::new(py, &b)), None, None),
                Err(e) => (id.0, None, Some(kind_of(&e)), Some(e.to_string())),
            })
            .collect())
    }

    /// The calls the agent made through client `client` since the last
    /// look: (id, request bytes).
    fn requests_bytes<'py>(&mut self, py: Python<'py>, client: &str) -> PyResult<Vec<(u64, Bound<'py, PyBytes>)>> {
        let got = self.get()?.requests::<Vec<u8>>(client).map_err(harness_err)?;
        Ok(got.into_iter().map(|(id, b)| (id.0, PyBytes::new(py, &b))).collect())
    }

    /// Answers the agent's call `id` through client `client` with `data`
    /// (the answer layout's bytes), or, with `error` (`server_gone`,
    /// `timed_out`), ends it so.
    #[pyo3(signature = (client, id, data, error=None))]
    fn answer_bytes(&mut self, client: &str, id: u64, data: Option<&[u8]>, error: Option<&str>) -> PyResult<()> {
        let (c, s) = (client.to_owned(), "test".to_owned());
        let answer = match (data, error) {
            (Some(b), None) => Ok(b.to_vec()),
            (None, Some("server_gone")) => Err(CallError::ServerGone { client: c, service: s }),
            (None, Some("timed_out")) => {
                Err(CallError::TimedOut { client: c, service: s, timeout: std::time::Duration::ZERO })
            }
            (None, Some(other)) => {
                return Err(PyValueError::new_err(format!(
                    "error {other:?}: a test ends a call with \"server_gone\" or \"timed_out\""
                )));
            }
            _ => return Err(PyValueError::new_err("answer with the answer's bytes or an error, one of them")),
        };
        self.get()?.answer(client, CallId(id), answer).map_err(harness_err)
    }

    /// Runs one step (a periodic agent's clock jumps to its next deadline).
    fn step(&mut self) -> PyResult<()> {
        self.get()?.step().map_err(harness_err)
    }

    /// Moves the clock on by `s` seconds, running every step due; returns how many ran.
    fn advance(&mut self, s: f64) -> PyResult<u64> {
        let d = seconds(s)?;
        self.get()?.advance(d).map_err(harness_err)
    }

    /// Runs `n` steps.
    fn run_cycles(&mut self, n: u64) -> PyResult<()> {
        self.get()?.run_cycles(n).map_err(harness_err)
    }

    /// Sets a parameter as `nerve param set` does (ValueError: its refusal).
    fn set_param(&mut self, key: &str, value: &str) -> PyResult<()> {
        self.get()?.set_param(key, value).map_err(PyValueError::new_err)
    }

    /// A parameter's value as `nerve param get` shows it.
    fn param(&mut self, key: &str) -> PyResult<String> {
        self.get()?.param(key).map_err(PyValueError::new_err)
    }

    /// Changes the period, as `nerve rate` does.
    fn set_period(&mut self, s: f64) -> PyResult<()> {
        let d = period(s)?;
        self.get()?.set_period(d);
        Ok(())
    }

    /// Suspends the agent, as `nerve suspend` does.
    fn suspend(&mut self) -> PyResult<()> {
        self.get()?.suspend();
        Ok(())
    }

    /// Resumes it, as `nerve resume` does.
    fn resume(&mut self) -> PyResult<()> {
        self.get()?.resume().map_err(harness_err)
    }

    /// The clock the agent sees, ns.
    #[getter]
    fn now_ns(&mut self) -> PyResult<u64> {
        Ok(self.get()?.now_ns())
    }

    /// How many steps ran.
    #[getter]
    fn cycles(&mut self) -> PyResult<u64> {
        Ok(self.get()?.cycles())
    }

    /// How many steps failed.
    #[getter]
    fn errors(&mut self) -> PyResult<u64> {
        Ok(self.get()?.errors())
    }

    /// Whether a step asked to stop.
    #[getter]
    fn stop_requested(&mut self) -> PyResult<bool> {
        Ok(self.get()?.stop_requested())
    }

    /// The period in seconds; None for an event-driven agent.
    #[getter]
    fn period(&mut self) -> PyResult<Option<f64>> {
        Ok(self.get()?.period().map(|p| p.as_secs_f64()))
    }

    /// What each input counts about each source, as JSON (`nerve ps --json`'s `inputs`).
    fn input_stats(&mut self) -> PyResult<String> {
        serde_json::to_string(&self.get()?.input_stats()).map_err(to_py_err)
    }

    /// Runs the agent's `stop`; the harness is spent.
    fn stop(&mut self) -> PyResult<()> {
        if let Some(h) = self.h.take() {
            drop(h.stop());
        }
        Ok(())
    }
}
