//! Sequence ports for Python agents (issue 42): a header and any number of
//! a fixed-size element ([`shm_schemas::seq`]), the layout a Rust agent's
//! `setup.output_seq::<T, H>(port, max_len)` makes.
//!
//! The ports themselves are the byte ports every Python port is
//! ([`agent_sdk::dynamic`]): `Setup::output_of` and `Setup::input_of` with
//! a sequence's schema already carry samples of any length on iceoryx2's
//! slice service, growing its memory with the largest sample. What this
//! module adds is the layout (`sequence_schema`, the schema
//! `Seq::<T, H>::schema()` is) and [`SeqOutput`]: a loan of the length a
//! step asks for, refused past the maximum the agent declared, before
//! anything is loaned. A loaned or received sample is the lib's
//! [`Loan`]/[`Received`], exported to numpy through the buffer protocol
//! at the sample's own length (zero copy).

use crate::{Loan, LoanState, Output, Setup, schema_from, to_py_err, valid};
use agent_sdk::PortError;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use shm_schemas::{Described, NoHeader, Schema, SeqShape};
use std::sync::Mutex;

/// The layout (JSON) of a sequence of `element` (layout JSON) after
/// `header` (layout JSON; None: no header, `nerve::NoHeader`), as
/// `Seq::<T, H>::schema()` lays it out in Rust: the same type name
/// (`nerve::Seq<T, H>`) and fingerprint.
#[pyfunction]
#[pyo3(signature = (element, header=None))]
fn sequence_schema(element: &str, header: Option<&str>) -> PyResult<String> {
    let element = schema_from(element)?;
    let header = match header {
        Some(h) => schema_from(h)?,
        None => NoHeader::schema(),
    };
    if matches!(element.kind, shm_schemas::schema::Kind::Sequence { .. })
        || matches!(header.kind, shm_schemas::schema::Kind::Sequence { .. })
    {
        return Err(PyValueError::new_err(
            "a sequence's header and element are fixed-size types, not sequences (a sample ends in one sequence)",
        ));
    }
    let s = valid(Schema::sequence(header, element))?;
    serde_json::to_string(&s).map_err(to_py_err)
}

/// Where a sequence sample's parts lie: (elements' offset, element size,
/// alignment), bytes; ValueError if `schema` is not a sequence's.
#[pyfunction]
fn sequence_shape(schema: &str) -> PyResult<(usize, usize, usize)> {
    let s = shape_of(&schema_from(schema)?)?;
    Ok((s.items_at, s.element, s.align))
}

fn shape_of(schema: &Schema) -> PyResult<SeqShape> {
    schema.sequence_shape().ok_or_else(|| {
        PyValueError::new_err(format!(
            "{} is not a sequence: declare it with setup.output, or make a sequence with nerve.sequence",
            schema.type_name
        ))
    })
}

/// Declares output `port` of the sequence layout `schema` (JSON) taking at
/// most `max_len` elements a sample.
#[pyfunction]
fn output_seq(
    py: Python<'_>,
    setup: &Bound<'_, Setup>,
    port: &str,
    schema: &str,
    max_len: usize,
) -> PyResult<SeqOutput> {
    let schema = schema_from(schema)?;
    let shape = shape_of(&schema)?;
    // the 64 MiB every payload is bounded to
    let bound = shape.count_of_at_most(shm_schemas::schema::MAX_SIZE);
    if max_len > bound {
        return Err(PyValueError::new_err(format!(
            "port {port:?}: max_len {max_len} elements of {} bytes are more than a sample's 64 MiB; give at most {bound}",
            shape.element
        )));
    }
    let output = setup.borrow_mut().get()?.output_of(port, schema).map_err(to_py_err)?;
    Ok(SeqOutput { output: Py::new(py, Output { output })?, shape, max_len })
}

/// An output port of a sequence: samples of a header and any number of
/// elements up to `max_len`.
#[pyclass(module = "nerve._native")]
struct SeqOutput {
    /// the byte port, which sends a loaned sample of any length
    output: Py<Output>,
    shape: SeqShape,
    max_len: usize,
}

#[pymethods]
impl SeqOutput {
    /// A sample of `n` elements to write in place: zeroed, or
    /// (`zeroed=False`) holding what its slot last held. Refused
    /// (ValueError, nothing loaned) past `max_len`.
    #[pyo3(signature = (n, zeroed = true))]
    fn loan(&self, py: Python<'_>, n: usize, zeroed: bool) -> PyResult<Loan> {
        let out = self.output.borrow(py);
        let service = out.output.service();
        let len = self.shape.len_of(n).filter(|_| n <= self.max_len).ok_or_else(|| {
            PyValueError::new_err(
                PortError::TooLong { service: service.to_owned(), len: n, max_len: self.max_len }.to_string(),
            )
        })?;
        let loan = out.output.loan_len(len, zeroed).map_err(to_py_err)?;
        Ok(Loan { state: Mutex::new(LoanState { loan: Some(loan), exports: 0 }) })
    }

    /// The byte port (`send`, `send_bytes`, `service`).
    #[getter]
    fn port(&self, py: Python<'_>) -> Py<Output> {
        self.output.clone_ref(py)
    }

    /// The most elements a sample may hold.
    #[getter]
    fn max_len(&self) -> usize {
        self.max_len
    }
}

/// Registers this module's functions and classes in `nerve._native`.
pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<SeqOutput>()?;
    m.add_function(wrap_pyfunction!(sequence_schema, m)?)?;
    m.add_function(wrap_pyfunction!(sequence_shape, m)?)?;
    m.add_function(wrap_pyfunction!(output_seq, m)?)?;
    Ok(())
}
