//! Calls for Python agents (issue 42): a service the agent answers and a
//! client it calls through, declared by the layouts of the request and
//! the answer ([`agent_sdk::dynamic::SchemaServer`] and
//! [`agent_sdk::dynamic::SchemaClient`]): the very iceoryx2 service a Rust
//! agent's `setup.serve::<Req, Resp>` makes, so Python and Rust call each
//! other and `nerve call` calls either.
//!
//! Requests and answers cross as bytes (copies: a call is small), which
//! the Python half (`nerve/call.py`) views as numpy records.

use crate::{Setup, schema_from, seconds, to_py_err};
use agent_sdk::dynamic::{SchemaClient, SchemaServer, ServeError};
use agent_sdk::port::{CallError, CallOptions};
use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyBytes;

pyo3::create_exception!(
    _native,
    CallRefused,
    PyRuntimeError,
    "A call refused before anything was sent: the client is not wired, no server answers, or too many are in flight."
);

/// Declares service `port` of requests `request` answered with `response`
/// (layouts, JSON): fixed-size answers, or with `max_len` sequences of at
/// most that many elements (`response` a sequence's schema).
#[pyfunction]
#[pyo3(signature = (setup, port, request, response, max_len=None))]
fn serve(
    setup: &Bound<'_, Setup>,
    port: &str,
    request: &str,
    response: &str,
    max_len: Option<usize>,
) -> PyResult<CallServer> {
    let (request, response) = (schema_from(request)?, schema_from(response)?);
    let mut setup = setup.borrow_mut();
    let setup = setup.get()?;
    let server = match max_len {
        Some(max_len) => setup.serve_seq_of(port, request, response, max_len),
        None => setup.serve_of(port, request, response),
    }
    .map_err(to_py_err)?;
    Ok(CallServer { server })
}

/// Declares client `port` of a service of `request` answered with
/// `response` (layouts, JSON): each call waits at most `timeout_s` for its
/// answer, and at most `max_in_flight` (1 to 64) are in flight at once.
#[pyfunction]
fn client(
    setup: &Bound<'_, Setup>,
    port: &str,
    request: &str,
    response: &str,
    timeout_s: f64,
    max_in_flight: usize,
) -> PyResult<CallClient> {
    let (request, response) = (schema_from(request)?, schema_from(response)?);
    if !(1..=agent_sdk::port::call::MAX_IN_FLIGHT).contains(&max_in_flight) {
        return Err(PyValueError::new_err(format!(
            "client {port:?}: max_in_flight {max_in_flight}: give 1 to {}",
            agent_sdk::port::call::MAX_IN_FLIGHT
        )));
    }
    let options = CallOptions { timeout: seconds(timeout_s)?, max_in_flight };
    let client = setup.borrow_mut().get()?.client_of(port, request, response, options).map_err(to_py_err)?;
    Ok(CallClient { client })
}

/// A service the agent answers.
#[pyclass(module = "nerve._native")]
struct CallServer {
    server: SchemaServer,
}

#[pymethods]
impl CallServer {
    /// Answers each waiting request (at most `max`) with what `answer`
    /// returns for it: `answer(request: bytes) -> bytes`, of exactly the
    /// answer's size, or for a sequence service a whole sample (the
    /// header's bytes, then whole elements from the items' offset), loaned
    /// at its length and copied in. Returns how many were answered. An
    /// exception of `answer` is raised here; its request goes unanswered
    /// (its caller sees the server gone), the others wait for the next
    /// step. A sequence answer past `max_len` is refused (its caller sees
    /// `refused_too_long`) and raised here (ValueError) once the rest are
    /// answered.
    fn serve<'py>(&self, py: Python<'py>, max: usize, answer: &Bound<'py, PyAny>) -> PyResult<usize> {
        let schema = self.server.response_schema();
        let type_name = &schema.type_name;
        let answer_bytes = |request: &[u8]| -> PyResult<Bound<'py, PyBytes>> {
            let got = answer.call1((PyBytes::new(py, request),))?;
            got.cast_into::<PyBytes>().map_err(|e| {
                PyValueError::new_err(format!(
                    "an answer of {type_name} is bytes, not {}",
                    type_name_of(&e.into_inner())
                ))
            })
        };
        let done = match schema.sequence_shape() {
            None => {
                let size = schema.size;
                self.server.serve_up_to(max, |request, out| -> PyResult<()> {
                    let got = answer_bytes(request)?;
                    let bytes = got.as_bytes();
                    if bytes.len() != size {
                        return Err(PyValueError::new_err(format!(
                            "a {}-byte answer for the {size}-byte {type_name}",
                            bytes.len()
                        )));
                    }
                    out.copy_from_slice(bytes);
                    Ok(())
                })
            }
            Some(shape) => self.server.serve_seq_up_to(max, |request, loan| -> PyResult<()> {
                let got = answer_bytes(request)?;
                let bytes = got.as_bytes();
                let items = bytes.get(shape.items_at..).unwrap_or_default();
                if bytes.len() < shape.items_at || items.len() % shape.element.max(1) != 0 {
                    return Err(PyValueError::new_err(format!(
                        "a {}-byte answer is not a {type_name} ({}-byte header and whole {}-byte elements)",
                        bytes.len(),
                        shape.items_at,
                        shape.element
                    )));
                }
                let n = items.len() / shape.element.max(1);
                match loan.loan(n) {
                    Ok((header, elements)) => {
                        header.copy_from_slice(&bytes[..header.len()]);
                        elements.copy_from_slice(items);
                        Ok(())
                    }
                    // refused past max_len: the loan answers with the refusal
                    Err(CallError::AnswerTooLong { .. }) => Ok(()),
                    Err(e) => Err(to_py_err(e)),
                }
            }),
        };
        match done {
            Ok(n) => Ok(n),
            Err(ServeError::Answer(e)) => Err(e),
            Err(ServeError::Call(e @ CallError::AnswerTooLong { .. })) => Err(PyValueError::new_err(e.to_string())),
            Err(ServeError::Call(e)) => Err(to_py_err(e)),
        }
    }

    /// How many requests it answered so far.
    #[getter]
    fn answered(&self) -> u64 {
        self.server.answered()
    }

    /// The iceoryx2 service name.
    #[getter]
    fn service(&self) -> String {
        self.server.service().to_owned()
    }
}

fn type_name_of(v: &Bound<'_, PyAny>) -> String {
    v.get_type().name().map(|n| n.to_string()).unwrap_or_else(|_| "?".into())
}

/// What a finished call hands Python: (id, answer bytes or None, error kind
/// or None, error message or None).
pub(crate) type Taken<'py> = (u64, Option<Bound<'py, PyBytes>>, Option<&'static str>, Option<String>);

/// The kind of a call's error, as Python names it.
pub(crate) fn kind_of(e: &CallError) -> &'static str {
    match e {
        CallError::TimedOut { .. } => "timed_out",
        CallError::ServerGone { .. } => "server_gone",
        CallError::Unwired { .. } => "unwired",
        CallError::NotWired { .. } => "not_wired",
        CallError::TooManyInFlight { .. } => "too_many_in_flight",
        CallError::NoServer { .. } => "no_server",
        CallError::Malformed { .. } => "malformed",
        CallError::RefusedTooLong { .. } => "refused_too_long",
        _ => "failed",
    }
}

/// A client the agent calls a service through.
#[pyclass(module = "nerve._native")]
struct CallClient {
    client: SchemaClient,
}

#[pymethods]
impl CallClient {
    /// Sends `request` (bytes of exactly the request's size) and returns
    /// the call's id at once. CallRefused (with nothing sent) when the
    /// client is not wired, no server answers, or past `max_in_flight`;
    /// its `args[1]` is the kind (`not_wired`, `no_server`, `too_many_in_flight`).
    fn call(&self, request: &[u8]) -> PyResult<u64> {
        let size = self.client.request_schema().size;
        if request.len() != size {
            return Err(PyValueError::new_err(format!(
                "a {}-byte request for the {size}-byte {}",
                request.len(),
                self.client.request_schema().type_name
            )));
        }
        self.client.call(request).map(|id| id.0).map_err(|e| CallRefused::new_err((e.to_string(), kind_of(&e))))
    }

    /// The next finished call, oldest first, or None: (id, answer bytes,
    /// None, None) or (id, None, error kind, error message).
    fn take<'py>(&self, py: Python<'py>) -> Option<Taken<'py>> {
        self.client.take().map(|(id, got)| match got {
            Ok(bytes) => (id.0, Some(PyBytes::new(py, &bytes)), None, None),
            Err(e) => (id.0, None, Some(kind_of(&e)), Some(e.to_string())),
        })
    }

    /// How many calls are in flight.
    #[getter]
    fn in_flight(&self) -> usize {
        self.client.in_flight()
    }

    /// Whether the client is wired to a service now.
    #[getter]
    fn wired(&self) -> bool {
        self.client.is_wired()
    }

    /// Each call's timeout, seconds.
    #[getter]
    fn timeout(&self) -> f64 {
        self.client.options().timeout.as_secs_f64()
    }

    /// The most calls in flight at once.
    #[getter]
    fn max_in_flight(&self) -> usize {
        self.client.options().max_in_flight
    }
}

/// Registers this module's functions and classes in `nerve._native`.
pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<CallServer>()?;
    m.add_class::<CallClient>()?;
    m.add("CallRefused", m.py().get_type::<CallRefused>())?;
    m.add_function(wrap_pyfunction!(serve, m)?)?;
    m.add_function(wrap_pyfunction!(client, m)?)?;
    Ok(())
}
