//! `nerve._native`: the agent SDK for Python agents, as PyO3 bindings.
//!
//! The Python package (`python/nerve/__init__.py`) is what authors use; this
//! module is the part it stands on. A Python agent is an ordinary SDK agent
//! ([`PyAgent`]) whose `new`, `start`, `step` and `stop` call the Python
//! object's: the SDK's runtime (message checker, task thread, registration,
//! rewiring, period, suspend/resume, statistics, clean stop) is the one
//! every Rust agent runs. Its ports are declared by layout
//! ([`agent_sdk::dynamic`]), so a Python agent and a Rust agent built with
//! a type of the same layout read each other's samples in place.
//!
//! Samples reach Python zero copy: a received sample ([`Received`]) and a
//! loaned one ([`Loan`]) export their shared-memory bytes through the
//! buffer protocol, and the package views them as numpy records.

use agent_sdk::clock::MAX_DURATION;
use agent_sdk::dynamic::{SchemaInput, SchemaOutput};
use agent_sdk::{Agent, AgentError, CommonArgs, Context as SdkContext, Param, Setup as SdkSetup, Task};
use pyo3::exceptions::{PyBufferError, PyRuntimeError, PyValueError};
use pyo3::ffi;
use pyo3::prelude::*;
use shm_schemas::{Described, Schema};
use std::os::raw::c_int;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Mutex, OnceLock};
use std::time::Duration;

mod call;
mod harness;
mod seq;

/// The Python agent this process runs: set once by [`run`].
struct Spec {
    kind: &'static str,
    task: Task,
    /// the agent's class, called with no argument to make the agent
    class: Py<PyAny>,
}

static SPEC: OnceLock<Spec> = OnceLock::new();

/// How many threads the interpreter ran when `run` was asked to make the
/// agent a daemon (0: not a daemon, or one thread). The SDK's daemonize
/// forks, which is safe in a single-threaded process only; an interpreter
/// that imported numpy runs its BLAS pool already (review B13). The
/// daemon says so in its log ([`warn_threads_at_fork`]).
static THREADS_AT_FORK: AtomicUsize = AtomicUsize::new(0);

/// The threads of this process now (`/proc/self/task`), if readable.
fn thread_count() -> Option<usize> {
    std::fs::read_dir("/proc/self/task").ok().map(|d| d.count())
}

/// Tells the daemon's log that it was forked from a multi-threaded
/// interpreter, once, with what to do if that ever hangs it.
fn warn_threads_at_fork() {
    let n = THREADS_AT_FORK.swap(0, Ordering::Relaxed);
    if n > 1 {
        eprintln!(
            "warning: this Python agent became a daemon (--daemon) by a fork while its interpreter ran {n} threads \
             (numpy's BLAS pool, threads an import started); only the forking thread goes on, so a lock another held \
             at that instant would stay taken. numpy's pool is fork-safe; if an agent ever hangs at start, start no \
             thread before nerve.run (OPENBLAS_NUM_THREADS=1 for numpy's), or run it without --daemon under systemd"
        );
    }
}

thread_local! {
    /// The agent a test harness is making in this thread ([`Harness`]):
    /// a test makes many, of several classes, where `run` makes one.
    static MAKING: std::cell::RefCell<Option<(&'static str, Task, Py<PyAny>)>> = const { std::cell::RefCell::new(None) };
}

/// The kind, task and class of the agent being made: a harness's, else `run`'s.
fn making() -> Option<(&'static str, Task, Py<PyAny>)> {
    let harness = MAKING.with(|m| m.borrow().as_ref().map(|(k, t, c)| (*k, *t, Python::attach(|py| c.clone_ref(py)))));
    harness.or_else(|| SPEC.get().map(|s| (s.kind, s.task, Python::attach(|py| s.class.clone_ref(py)))))
}

/// An SDK agent whose algorithm is a Python object.
struct PyAgent {
    obj: Py<PyAny>,
}

/// A Python exception as an agent error, with its traceback.
fn agent_error(py: Python<'_>, e: PyErr) -> AgentError {
    let trace = e.traceback(py).and_then(|tb| tb.format().ok()).map(|t| format!("\n{t}")).unwrap_or_default();
    AgentError::Other(format!("{}{trace}", e.value(py)))
}

impl Agent for PyAgent {
    const KIND: &'static str = "python";

    fn kind() -> &'static str {
        making().map_or(Self::KIND, |s| s.0)
    }

    fn task() -> Task {
        making().map_or(Task::EventDriven, |s| s.1)
    }

    fn new(setup: &mut SdkSetup) -> Result<Self, AgentError> {
        let (_, _, class) =
            making().ok_or_else(|| AgentError::Other("no Python agent class was given to nerve.run".into()))?;
        Python::attach(|py| {
            let obj = class.call0(py).map_err(|e| agent_error(py, e))?;
            let handle = Py::new(py, Setup { ptr: setup as *mut SdkSetup }).map_err(|e| agent_error(py, e))?;
            let done = obj.call_method1(py, "_nerve_new", (handle.clone_ref(py),));
            // the setup lives only for this call: a handle kept by the agent goes dead
            handle.borrow_mut(py).ptr = std::ptr::null_mut();
            done.map_err(|e| agent_error(py, e))?;
            Ok(PyAgent { obj })
        })
    }

    fn start(&mut self, ctx: &mut SdkContext) -> Result<(), AgentError> {
        if MAKING.with(|m| m.borrow().is_none()) {
            keep_thread_state();
            warn_threads_at_fork();
        }
        self.call("_nerve_start", ctx)
    }

    fn step(&mut self, ctx: &mut SdkContext) -> Result<(), AgentError> {
        self.call("_nerve_step", ctx)
    }

    fn stop(&mut self, ctx: &mut SdkContext) {
        if let Err(e) = self.call("_nerve_stop", ctx) {
            eprintln!("error: the agent's stop failed: {e}");
        }
    }
}

/// Gives the task thread a Python thread state for its whole life, without
/// holding the interpreter's lock. Without it every step's attach made a
/// thread state and tore it down again (PyGILState_Ensure on a thread
/// Python does not know), a large share of a Python agent's hop; with it an
/// attach only takes the lock. Only for the runtime's task thread: a test
/// harness steps the agent in the test's own, already attached, thread.
fn keep_thread_state() {
    // SAFETY: called once, in the task thread, which holds neither the lock
    // nor a thread state: PyGILState_Ensure makes the thread state and takes
    // the lock, and PyEval_SaveThread gives the lock back while the state
    // stays registered for the thread (its gilstate count stays 1, never
    // released), so that later PyGILState_Ensure calls reuse it.
    unsafe {
        let _state = ffi::PyGILState_Ensure();
        ffi::PyEval_SaveThread();
    }
}

impl PyAgent {
    /// Calls the Python agent's `method` with the cycle's context.
    fn call(&mut self, method: &str, ctx: &mut SdkContext) -> Result<(), AgentError> {
        Python::attach(|py| {
            let handle = Py::new(py, Context { ptr: ctx as *mut SdkContext }).map_err(|e| agent_error(py, e))?;
            let done = self.obj.call_method1(py, method, (handle.clone_ref(py),));
            handle.borrow_mut(py).ptr = std::ptr::null_mut();
            done.map(|_| ()).map_err(|e| agent_error(py, e))
        })
    }
}

fn dead(what: &str) -> PyErr {
    PyRuntimeError::new_err(format!(
        "this {what} was given to one call of the agent (new, or one step) and is no longer valid"
    ))
}

/// A layout (JSON) from Python, parsed and [validated](Schema::validate):
/// ValueError with what is wrong, before it reaches a port.
fn schema_from(json: &str) -> PyResult<Schema> {
    let schema: Schema =
        serde_json::from_str(json).map_err(|e| PyValueError::new_err(format!("not a payload layout: {e}")))?;
    valid(schema)
}

/// `schema` if it is valid, else a ValueError saying why.
fn valid(schema: Schema) -> PyResult<Schema> {
    schema.validate().map_err(|e| PyValueError::new_err(e.to_string()))?;
    Ok(schema)
}

fn to_py_err(e: impl std::fmt::Display) -> PyErr {
    PyRuntimeError::new_err(e.to_string())
}

/// What `new` declares ports and parameters on (the SDK's `Setup`), valid
/// during that call only.
#[pyclass(unsendable, module = "nerve._native")]
struct Setup {
    ptr: *mut SdkSetup,
}

impl Setup {
    fn get(&mut self) -> PyResult<&mut SdkSetup> {
        // SAFETY: `ptr` is the setup `PyAgent::new` holds a unique borrow
        // of for the whole Python call it was made for; it is nulled when
        // that call returns, and the handle never leaves this thread
        // (unsendable).
        unsafe { self.ptr.as_mut() }.ok_or_else(|| dead("setup"))
    }
}

#[pymethods]
impl Setup {
    /// The agent's name.
    #[getter]
    fn name(&mut self) -> PyResult<String> {
        Ok(self.get()?.name().to_owned())
    }

    /// The robot's name.
    #[getter]
    fn robot(&mut self) -> PyResult<String> {
        Ok(self.get()?.world().robot().to_string())
    }

    /// The arguments after `--` on the agent's command line.
    #[getter]
    fn args(&mut self) -> PyResult<Vec<String>> {
        Ok(self.get()?.raw_args().to_vec())
    }

    /// Declares input `port` of the layout `schema` (JSON).
    fn input(&mut self, port: &str, schema: &str) -> PyResult<Input> {
        let schema = schema_from(schema)?;
        let input = self.get()?.input_of(port, schema).map_err(to_py_err)?;
        Ok(Input { input })
    }

    /// Declares output `port` of the layout `schema` (JSON).
    fn output(&mut self, port: &str, schema: &str) -> PyResult<Output> {
        let schema = schema_from(schema)?;
        let output = self.get()?.output_of(port, schema).map_err(to_py_err)?;
        Ok(Output { output })
    }

    /// Declares parameter `key` with `default` (a float, int, bool or str:
    /// the parameter keeps that type). A float or int parameter may have
    /// bounds, `min` and `max` (inclusive, either or both): a value outside
    /// them is refused at start (`--param`), by `nerve param set` and by the
    /// Harness, with a message naming the range, which `nerve param list`
    /// shows.
    #[pyo3(signature = (key, default, min=None, max=None))]
    fn param(
        &mut self,
        key: &str,
        default: &Bound<'_, PyAny>,
        min: Option<&Bound<'_, PyAny>>,
        max: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<ParamHandle> {
        let setup = self.get()?;
        let bounded = min.is_some() || max.is_some();
        // bool first: a Python bool is also an int
        let param = if let Ok(b) = default.cast::<pyo3::types::PyBool>() {
            no_bounds(key, "bool", bounded)?;
            AnyParam::Bool(setup.param(key, b.is_true()))
        } else if let Ok(i) = default.cast::<pyo3::types::PyInt>() {
            let default = i.extract::<i64>()?;
            let range = Range::of(key, min, max, |b| b.extract::<i64>().ok(), "an int")?;
            match range {
                Some(r) => {
                    r.check(&default).map_err(|e| default_out_of_range(key, e))?;
                    AnyParam::Int(setup.param_checked(key, default, move |v| r.check(v)))
                }
                None => AnyParam::Int(setup.param(key, default)),
            }
        } else if let Ok(f) = default.cast::<pyo3::types::PyFloat>() {
            let default = f.value();
            // an int bound of a float parameter is the float it equals
            let range = Range::of(key, min, max, |b| b.extract::<f64>().ok().filter(|x| !x.is_nan()), "a number")?;
            match range {
                Some(r) => {
                    r.check(&default).map_err(|e| default_out_of_range(key, e))?;
                    AnyParam::Float(setup.param_checked(key, default, move |v| r.check(v)))
                }
                None => AnyParam::Float(setup.param(key, default)),
            }
        } else if let Ok(s) = default.extract::<String>() {
            no_bounds(key, "str", bounded)?;
            AnyParam::Text(setup.param(key, s))
        } else {
            return Err(PyValueError::new_err(format!(
                "parameter {key:?}: a default of type {} (give a float, int, bool or str)",
                default.get_type().name()?
            )));
        };
        Ok(ParamHandle { param })
    }
}

fn no_bounds(key: &str, type_name: &str, bounded: bool) -> PyResult<()> {
    if bounded {
        Err(PyValueError::new_err(format!(
            "parameter {key:?} is a {type_name}: only float and int parameters take min and max (remove them)"
        )))
    } else {
        Ok(())
    }
}

fn default_out_of_range(key: &str, refusal: String) -> PyErr {
    PyValueError::new_err(format!("parameter {key:?}: its default is out of its own bounds ({refusal})"))
}

/// The inclusive bounds of a Python number parameter; its refusal names the
/// parameter and the range, as the SDK's `in_range` does ("gain is in [0, 10]").
#[derive(Clone)]
struct Range<T> {
    key: String,
    min: Option<T>,
    max: Option<T>,
}

impl<T: PartialOrd + std::fmt::Display + Copy> Range<T> {
    /// `None` without bounds; a ValueError for a bound of the wrong type or
    /// `min > max`.
    fn of(
        key: &str,
        min: Option<&Bound<'_, PyAny>>,
        max: Option<&Bound<'_, PyAny>>,
        extract: impl Fn(&Bound<'_, PyAny>) -> Option<T>,
        what: &str,
    ) -> PyResult<Option<Self>> {
        let bound = |b: Option<&Bound<'_, PyAny>>, name: &str| -> PyResult<Option<T>> {
            match b {
                None => Ok(None),
                Some(b) if b.is_none() => Ok(None),
                Some(b) => extract(b).map(Some).ok_or_else(|| {
                    PyValueError::new_err(format!("parameter {key:?}: {name} must be {what}, like its default"))
                }),
            }
        };
        let (min, max) = (bound(min, "min")?, bound(max, "max")?);
        if let (Some(lo), Some(hi)) = (min, max)
            && lo > hi
        {
            return Err(PyValueError::new_err(format!("parameter {key:?}: min {lo} is above max {hi}")));
        }
        Ok((min.is_some() || max.is_some()).then(|| Range { key: key.to_owned(), min, max }))
    }

    /// Refuses a value outside the bounds (and NaN, which is outside every range).
    fn check(&self, v: &T) -> Result<(), String> {
        let above = self.min.is_none_or(|lo| *v >= lo);
        let below = self.max.is_none_or(|hi| *v <= hi);
        if above && below {
            return Ok(());
        }
        let key = &self.key;
        Err(match (self.min, self.max) {
            (Some(lo), Some(hi)) => format!("{key} is in [{lo}, {hi}]"),
            (Some(lo), None) => format!("{key} must be >= {lo}"),
            (None, Some(hi)) => format!("{key} must be <= {hi}"),
            (None, None) => format!("{key} is unbounded"),
        })
    }
}

enum AnyParam {
    Float(Param<f64>),
    Int(Param<i64>),
    Bool(Param<bool>),
    Text(Param<String>),
}

/// A parameter: its value changes when `nerve param set` changes it.
#[pyclass(module = "nerve._native")]
struct ParamHandle {
    param: AnyParam,
}

#[pymethods]
impl ParamHandle {
    /// The current value.
    fn get<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        Ok(match &self.param {
            AnyParam::Float(p) => p.get().into_pyobject(py)?.into_any(),
            AnyParam::Int(p) => p.get().into_pyobject(py)?.into_any(),
            AnyParam::Bool(p) => p.get().into_pyobject(py)?.to_owned().into_any(),
            AnyParam::Text(p) => p.get().into_pyobject(py)?.into_any(),
        })
    }

    /// Changes the value from inside the agent.
    fn set(&self, value: &Bound<'_, PyAny>) -> PyResult<()> {
        match &self.param {
            AnyParam::Float(p) => p.set(value.extract()?),
            AnyParam::Int(p) => p.set(value.extract()?),
            AnyParam::Bool(p) => p.set(value.extract()?),
            AnyParam::Text(p) => p.set(value.extract()?),
        }
        Ok(())
    }
}

/// What each step gets (the SDK's `Context`), valid during that call only.
#[pyclass(unsendable, module = "nerve._native")]
struct Context {
    ptr: *mut SdkContext,
}

impl Context {
    fn get(&mut self) -> PyResult<&mut SdkContext> {
        // SAFETY: as for `Setup::get`: the context `PyAgent::call` holds a
        // unique borrow of during the Python call, nulled after it.
        unsafe { self.ptr.as_mut() }.ok_or_else(|| dead("context"))
    }
}

#[pymethods]
impl Context {
    /// The agent's name.
    #[getter]
    fn name(&mut self) -> PyResult<String> {
        Ok(self.get()?.name().to_owned())
    }

    /// How many steps ran before this one.
    #[getter]
    fn cycle(&mut self) -> PyResult<u64> {
        Ok(self.get()?.cycle())
    }

    /// When this step started (CLOCK_MONOTONIC, ns).
    #[getter]
    fn now_ns(&mut self) -> PyResult<u64> {
        Ok(self.get()?.now_ns())
    }

    /// The period now, in seconds; None for an event-driven agent.
    #[getter]
    fn period(&mut self) -> PyResult<Option<f64>> {
        Ok(self.get()?.period().map(|p| p.as_secs_f64()))
    }

    /// This step's deadline (ns); None for an event-driven agent.
    #[getter]
    fn deadline_ns(&mut self) -> PyResult<Option<u64>> {
        Ok(self.get()?.deadline_ns())
    }

    /// The inputs with new samples that woke this step.
    #[getter]
    fn woken_by(&mut self) -> PyResult<Vec<String>> {
        Ok(self.get()?.woken_by().map(str::to_owned).collect())
    }

    /// Whether input `input` woke this step.
    fn has_new(&mut self, input: &str) -> PyResult<bool> {
        Ok(self.get()?.has_new(input))
    }

    /// Stops the agent after this step.
    fn request_stop(&mut self) -> PyResult<()> {
        self.get()?.request_stop();
        Ok(())
    }
}

/// An input port.
#[pyclass(module = "nerve._native")]
struct Input {
    input: SchemaInput,
}

#[pymethods]
impl Input {
    /// The next waiting sample, read in place; None when none waits.
    fn take(&self) -> PyResult<Option<Received>> {
        Ok(self
            .input
            .take()
            .map_err(to_py_err)?
            .map(|sample| Received { sample: Mutex::new(sample), exports: Mutex::new(0) }))
    }

    /// How many output ports feed it now.
    fn sources(&self) -> usize {
        self.input.sources()
    }
}

/// A received sample: its bytes are the sender's, in shared memory, while
/// this object (or a view of it) lives.
#[pyclass(module = "nerve._native")]
struct Received {
    // iceoryx2's samples may move between threads but not be shared: the
    // lock makes the object shareable, as Python objects are
    sample: Mutex<agent_sdk::dynamic::Received>,
    /// how many buffer views of it live (numpy arrays): each keeps this
    /// object, so the sample and its mapping, alive
    exports: Mutex<usize>,
}

impl Received {
    fn meta(&self) -> agent_sdk::Meta {
        lock(&self.sample).meta()
    }
}

fn lock<X>(m: &Mutex<X>) -> std::sync::MutexGuard<'_, X> {
    m.lock().unwrap_or_else(|p| p.into_inner())
}

#[pymethods]
impl Received {
    /// The sending agent.
    #[getter]
    fn sender(&self) -> String {
        self.meta().sender.as_str().to_owned()
    }

    /// Its number on the sending port.
    #[getter]
    fn seq(&self) -> u64 {
        self.meta().seq
    }

    /// When it was sent (CLOCK_MONOTONIC, ns).
    #[getter]
    fn stamp_ns(&self) -> u64 {
        self.meta().stamp_ns
    }

    fn __len__(&self) -> usize {
        lock(&self.sample).bytes().len()
    }

    /// How many buffer views (numpy arrays) of the sample live now.
    #[getter]
    fn exports(&self) -> usize {
        *lock(&self.exports)
    }

    unsafe fn __getbuffer__(slf: Bound<'_, Self>, view: *mut ffi::Py_buffer, flags: c_int) -> PyResult<()> {
        if flags & ffi::PyBUF_WRITABLE != 0 {
            return Err(PyBufferError::new_err("a received sample is read-only"));
        }
        let (ptr, len) = {
            let me = slf.borrow();
            let sample = lock(&me.sample);
            let bytes = sample.bytes();
            (bytes.as_ptr(), bytes.len())
        };
        // SAFETY: the bytes live as long as the sample, which this object
        // owns and never gives up; `view` keeps the object alive
        // (PyBuffer_FillInfo takes a reference to `slf`). In shared memory
        // the sample holds iceoryx2's reference to the subscriber's
        // mapping, so the bytes outlive the Input too.
        unsafe { fill_buffer(&slf, view, ptr.cast_mut(), len, true, flags) }?;
        *lock(&slf.borrow().exports) += 1;
        Ok(())
    }

    unsafe fn __releasebuffer__(&self, _view: *mut ffi::Py_buffer) {
        let mut n = lock(&self.exports);
        *n = n.saturating_sub(1);
    }
}

/// Fills `view` with `len` bytes at `ptr`, owned by `owner`.
///
/// # Safety
/// `view` is the buffer the interpreter asked for; the bytes stay valid
/// while `owner` lives.
unsafe fn fill_buffer<T>(
    owner: &Bound<'_, T>,
    view: *mut ffi::Py_buffer,
    ptr: *mut u8,
    len: usize,
    readonly: bool,
    flags: c_int,
) -> PyResult<()> {
    let len = ffi::Py_ssize_t::try_from(len).map_err(|_| PyBufferError::new_err("a sample too large to view"))?;
    // SAFETY: the caller's contract; PyBuffer_FillInfo takes a new reference to `owner`
    let rc = unsafe { ffi::PyBuffer_FillInfo(view, owner.as_ptr(), ptr.cast(), len, c_int::from(readonly), flags) };
    if rc == 0 { Ok(()) } else { Err(PyErr::fetch(owner.py())) }
}

/// An output port.
#[pyclass(module = "nerve._native")]
struct Output {
    output: SchemaOutput,
}

#[pymethods]
impl Output {
    /// A sample to write in place: zeroed, or (`zeroed=False`) holding what
    /// its slot last held.
    #[pyo3(signature = (zeroed = true))]
    fn loan(&self, zeroed: bool) -> PyResult<Loan> {
        let loan = self.output.loan(zeroed).map_err(to_py_err)?;
        Ok(Loan { state: Mutex::new(LoanState { loan: Some(loan), exports: 0 }) })
    }

    /// Sends a loaned sample and wakes the readers; the loan is spent.
    /// BufferError while a view of it lives (a numpy array of its bytes),
    /// as a `bytearray` refuses to resize: once sent, the bytes are the
    /// readers' (or, in a test, freed), and a view would write into them.
    fn send(&mut self, loan: &Bound<'_, Loan>) -> PyResult<()> {
        let taken = {
            let me = loan.borrow();
            let mut state = lock(&me.state);
            if state.exports > 0 {
                return Err(PyBufferError::new_err(format!(
                    "this message cannot be sent while {} view(s) of its memory live (numpy arrays from \
                     msg.array, an array field or a nested struct): delete them (del) or keep copies (.copy()) \
                     before sending",
                    state.exports
                )));
            }
            state.loan.take().ok_or_else(|| PyRuntimeError::new_err("this loan was sent already"))?
        };
        self.output.send(taken).map_err(to_py_err)
    }

    /// Sends a copy of `data` (bytes of exactly the layout's size).
    fn send_bytes(&mut self, data: &[u8]) -> PyResult<()> {
        self.output.send_bytes(data).map_err(to_py_err)
    }

    /// The port's iceoryx2 service name.
    #[getter]
    fn service(&self) -> String {
        self.output.service().to_owned()
    }
}

/// A loaned sample: its bytes are a slot of the port's shared memory until
/// it is sent.
#[pyclass(module = "nerve._native")]
struct Loan {
    /// as for [`Received`]
    state: Mutex<LoanState>,
}

struct LoanState {
    /// None once sent
    loan: Option<agent_sdk::dynamic::Loan>,
    /// how many buffer views of it live: while any does, it is not sent
    exports: usize,
}

#[pymethods]
impl Loan {
    /// How many buffer views (numpy arrays) of the sample live now.
    #[getter]
    fn exports(&self) -> usize {
        lock(&self.state).exports
    }

    /// Whether it was sent.
    #[getter]
    fn sent(&self) -> bool {
        lock(&self.state).loan.is_none()
    }

    unsafe fn __getbuffer__(slf: Bound<'_, Self>, view: *mut ffi::Py_buffer, flags: c_int) -> PyResult<()> {
        let me = slf.borrow();
        let mut state = lock(&me.state);
        let loan = state.loan.as_mut().ok_or_else(|| PyBufferError::new_err("this message was sent already"))?;
        let bytes = loan.bytes_mut();
        let (ptr, len) = (bytes.as_mut_ptr(), bytes.len());
        // SAFETY: the bytes are the loan's, which this object owns until
        // `Output.send` takes it, and `send` refuses while `exports` is
        // not zero: every view is released before the loan is sent or
        // dropped (`view` keeps this object alive: PyBuffer_FillInfo takes
        // a reference to `slf`). A shared-memory loan holds iceoryx2's
        // reference to the publisher's mapping, so the bytes outlive the
        // Output; a test's loan is a heap box owned here. The lock is held
        // while the view is filled, so no send runs between.
        unsafe { fill_buffer(&slf, view, ptr, len, false, flags) }?;
        state.exports += 1;
        Ok(())
    }

    unsafe fn __releasebuffer__(&self, _view: *mut ffi::Py_buffer) {
        let mut state = lock(&self.state);
        state.exports = state.exports.saturating_sub(1);
    }
}

/// The layout (JSON) of the built-in payload type `type_name`, or None.
#[pyfunction]
fn builtin_schema(type_name: &str) -> Option<String> {
    let mut found = shm_schemas::schema::built_in_named(type_name);
    if found.is_none() && type_name == "nerve::FixedName" {
        found = Some(<shm_schemas::FixedName as Described>::schema());
    }
    found.and_then(|s| serde_json::to_string(&s).ok())
}

/// The type names of the built-in payloads.
#[pyfunction]
fn builtin_types() -> Vec<&'static str> {
    shm_schemas::payloads::known_type_names()
}

/// The layout (JSON) of primitive `name` (`u8` ... `f64`, `bool`).
#[pyfunction]
fn primitive_schema(name: &str) -> PyResult<String> {
    macro_rules! prim {
        ($($t:ty),*) => {
            match name {
                $(stringify!($t) => <$t as Described>::schema(),)*
                _ => return Err(PyValueError::new_err(format!(
                    "{name:?} is not a primitive type (u8, u16, u32, u64, i8, i16, i32, i64, f32, f64, bool)"
                ))),
            }
        };
    }
    let s = prim!(u8, u16, u32, u64, i8, i16, i32, i64, f32, f64, bool);
    serde_json::to_string(&s).map_err(to_py_err)
}

/// The layout (JSON) of `[element; len]`.
#[pyfunction]
fn array_schema(element: &str, len: usize) -> PyResult<String> {
    let element = schema_from(element)?;
    let size = element.size.checked_mul(len).ok_or_else(|| PyValueError::new_err("an array too large"))?;
    let s = Schema {
        type_name: format!("[{}; {len}]", element.type_name),
        size,
        align: element.align,
        kind: shm_schemas::schema::Kind::Array { len, element: Box::new(element) },
    };
    serde_json::to_string(&valid(s)?).map_err(to_py_err)
}

/// The layout (JSON) of the `#[repr(C)]` struct `type_name` with `fields`
/// (name, layout JSON) in order: each field at the next offset its
/// alignment allows, the size rounded up to the largest alignment, as
/// Rust lays out `#[repr(C)]`.
#[pyfunction]
fn struct_schema(type_name: &str, fields: Vec<(String, String)>) -> PyResult<String> {
    let round = |at: usize, align: usize| at.div_ceil(align).checked_mul(align);
    let too_large = || PyValueError::new_err(format!("{type_name}: a layout too large"));
    let mut at = 0usize;
    let mut align = 1usize;
    let mut laid = Vec::with_capacity(fields.len());
    for (name, schema) in fields {
        let schema = schema_from(&schema)?;
        if schema.align == 0 || !schema.align.is_power_of_two() {
            return Err(PyValueError::new_err(format!(
                "field {name:?}: alignment {} is not a power of two",
                schema.align
            )));
        }
        let offset = round(at, schema.align).ok_or_else(too_large)?;
        at = offset.checked_add(schema.size).ok_or_else(too_large)?;
        align = align.max(schema.align);
        laid.push(shm_schemas::schema::Field { name, offset, schema });
    }
    let size = round(at, align).ok_or_else(too_large)?;
    let s =
        Schema { type_name: type_name.into(), size, align, kind: shm_schemas::schema::Kind::Struct { fields: laid } };
    serde_json::to_string(&valid(s)?).map_err(to_py_err)
}

/// The layout fingerprint of a layout (JSON): what the router compares.
#[pyfunction]
fn fingerprint(schema: &str) -> PyResult<u64> {
    Ok(schema_from(schema)?.fingerprint())
}

/// The kind (checked, kept for the process's life) and the task of an agent class.
fn kind_and_task(kind: String, period_s: Option<f64>) -> PyResult<(&'static str, Task)> {
    let task = match period_s {
        None => Task::EventDriven,
        Some(p) => Task::Periodic(period(p)?),
    };
    shm_schemas::AgentName::new(&kind).map_err(|e| PyValueError::new_err(format!("kind {kind:?}: {e}")))?;
    Ok((Box::leak(kind.into_boxed_str()), task))
}

/// Seconds from Python as a duration: finite, not negative, at most
/// [`MAX_DURATION`] (a day); ValueError otherwise, never a panic (which
/// would abort the interpreter).
fn seconds(s: f64) -> PyResult<Duration> {
    Duration::try_from_secs_f64(s).ok().filter(|d| *d <= MAX_DURATION).ok_or_else(|| {
        PyValueError::new_err(format!("{s} s: give a number of seconds from 0 to {} (one day)", MAX_DURATION.as_secs()))
    })
}

/// The shortest period nerve runs (as `--period` and `nerve rate` accept).
const MIN_PERIOD: Duration = Duration::from_micros(10);

/// A period from Python (an agent class's `period`, `set_period`): as
/// [`seconds`], and at least [`MIN_PERIOD`].
fn period(s: f64) -> PyResult<Duration> {
    seconds(s).ok().filter(|d| *d >= MIN_PERIOD).ok_or_else(|| {
        PyValueError::new_err(format!(
            "a period of {s} s: give a number of seconds from {} to {} (one day)",
            MIN_PERIOD.as_secs_f64(),
            MAX_DURATION.as_secs()
        ))
    })
}

/// Runs the agent made by `class()` under the SDK with command line `argv`
/// (without the program name): `kind` as `nerve ps` shows it, `period_s`
/// for a periodic agent, None for an event-driven one. Returns the exit
/// status. The interpreter's lock is released while the SDK runs; the task
/// thread takes it for each call of the agent.
#[pyfunction]
#[pyo3(signature = (class, kind, period_s, argv))]
fn run(py: Python<'_>, class: Py<PyAny>, kind: String, period_s: Option<f64>, argv: Vec<String>) -> PyResult<u8> {
    let (kind, task) = kind_and_task(kind, period_s)?;
    SPEC.set(Spec { kind, task, class })
        .map_err(|_| PyRuntimeError::new_err("nerve.run runs one agent per process, and it ran already"))?;
    let args = match <CommonArgs as clap::Parser>::try_parse_from(std::iter::once(kind.to_owned()).chain(argv)) {
        Ok(a) => a,
        Err(e) => {
            // --help and --version print and succeed; a bad argument prints and fails
            let _ = e.print();
            return Ok(if e.use_stderr() { 2 } else { 0 });
        }
    };
    if args.daemon && !args.describe {
        THREADS_AT_FORK.store(thread_count().unwrap_or(0), Ordering::Relaxed);
    }
    Ok(py.detach(|| agent_sdk::runtime::run_status::<PyAgent>(args)))
}

/// The module Python imports as `nerve._native`.
#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<Setup>()?;
    m.add_class::<Context>()?;
    m.add_class::<Input>()?;
    m.add_class::<Output>()?;
    m.add_class::<Received>()?;
    m.add_class::<Loan>()?;
    m.add_class::<ParamHandle>()?;
    m.add_class::<harness::Harness>()?;
    m.add_function(wrap_pyfunction!(builtin_schema, m)?)?;
    m.add_function(wrap_pyfunction!(builtin_types, m)?)?;
    m.add_function(wrap_pyfunction!(primitive_schema, m)?)?;
    m.add_function(wrap_pyfunction!(array_schema, m)?)?;
    m.add_function(wrap_pyfunction!(struct_schema, m)?)?;
    m.add_function(wrap_pyfunction!(fingerprint, m)?)?;
    m.add_function(wrap_pyfunction!(run, m)?)?;
    seq::register(m)?;
    call::register(m)?;
    Ok(())
}
