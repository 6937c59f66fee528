//! The C API called as a C program calls it, in one process with the SDK's
//! test harness: a relay declared and stepped through the extern
//! functions, and every misuse (NULL, an unknown port, a wrong layout, a
//! context kept past its step) answered with a status and a message.

use super::*;
use agent_sdk::testing::Harness;
use shm_schemas::payloads::Tick;
use std::sync::Mutex;
use std::sync::atomic::{AtomicPtr, AtomicU32, Ordering};

/// What the callbacks found wrong (a panic must not unwind into C).
static WRONG: Mutex<Vec<String>> = Mutex::new(Vec::new());
static IN: AtomicU32 = AtomicU32::new(0);
static OUT: AtomicU32 = AtomicU32::new(0);
static GAIN: AtomicU32 = AtomicU32::new(0);
/// The context of the last step, kept past it on purpose.
static KEPT: AtomicPtr<nerve_ctx> = AtomicPtr::new(std::ptr::null_mut());

fn expect(what: &str, got: nerve_status, want: nerve_status) {
    let msg = last_error_string();
    if got != want {
        WRONG.lock().expect("lock").push(format!("{what}: {got:?}, not {want:?} ({msg})"));
    } else if want != nerve_status::NERVE_OK && msg.is_empty() {
        WRONG.lock().expect("lock").push(format!("{what}: {got:?} without a message"));
    }
}

fn last_error_string() -> String {
    // SAFETY: nerve_last_error gives a NUL-terminated string valid until the next call
    unsafe { CStr::from_ptr(nerve_last_error()) }.to_string_lossy().into_owned()
}

const TICK: &CStr = c"nerve::Tick";
const SIZE: usize = std::mem::size_of::<Tick>();
const ALIGN: usize = std::mem::align_of::<Tick>();

unsafe extern "C" fn new(setup: *mut nerve_setup, _user: *mut c_void) -> c_int {
    use nerve_status::*;
    let mut port = 0;
    // SAFETY: for every call, the pointers are this call's setup, C strings and a local
    unsafe {
        let null = std::ptr::null_mut();
        expect(
            "null setup",
            nerve_setup_input(null, c"in".as_ptr(), TICK.as_ptr(), SIZE, ALIGN, 0, &mut port),
            NERVE_NULL_POINTER,
        );
        expect(
            "null name",
            nerve_setup_input(setup, std::ptr::null(), TICK.as_ptr(), SIZE, ALIGN, 0, &mut port),
            NERVE_NULL_POINTER,
        );
        expect(
            "null out",
            nerve_setup_input(setup, c"in".as_ptr(), TICK.as_ptr(), SIZE, ALIGN, 0, std::ptr::null_mut()),
            NERVE_NULL_POINTER,
        );
        expect(
            "unknown type",
            nerve_setup_input(setup, c"in".as_ptr(), c"nerve::Nope".as_ptr(), SIZE, ALIGN, 0, &mut port),
            NERVE_UNKNOWN_TYPE,
        );
        expect(
            "short struct",
            nerve_setup_input(setup, c"in".as_ptr(), TICK.as_ptr(), 8, ALIGN, 0, &mut port),
            NERVE_LAYOUT_MISMATCH,
        );
        expect(
            "wrong fingerprint",
            nerve_setup_input(setup, c"in".as_ptr(), TICK.as_ptr(), SIZE, ALIGN, 1, &mut port),
            NERVE_LAYOUT_MISMATCH,
        );
        let fp = <Tick as shm_schemas::Payload>::layout_fingerprint();
        expect("input", nerve_setup_input(setup, c"in".as_ptr(), TICK.as_ptr(), SIZE, ALIGN, fp, &mut port), NERVE_OK);
        IN.store(port, Ordering::Relaxed);
        expect(
            "output",
            nerve_setup_output(setup, c"out".as_ptr(), TICK.as_ptr(), SIZE, ALIGN, 0, &mut port),
            NERVE_OK,
        );
        OUT.store(port, Ordering::Relaxed);
        let mut gain = 0;
        expect(
            "default out of bounds",
            nerve_setup_param_f64(setup, c"gain".as_ptr(), 20.0, 0.0, 10.0, &mut gain),
            NERVE_INVALID_ARGUMENT,
        );
        expect(
            "min above max",
            nerve_setup_param_f64(setup, c"gain".as_ptr(), 2.0, 10.0, 0.0, &mut gain),
            NERVE_INVALID_ARGUMENT,
        );
        expect("param", nerve_setup_param_f64(setup, c"gain".as_ptr(), 2.0, 0.0, 10.0, &mut gain), NERVE_OK);
        GAIN.store(gain, Ordering::Relaxed);
    }
    0
}

unsafe extern "C" fn step(ctx: *mut nerve_ctx, _user: *mut c_void) -> c_int {
    use nerve_status::*;
    KEPT.store(ctx, Ordering::Relaxed);
    let (input, output) = (IN.load(Ordering::Relaxed), OUT.load(Ordering::Relaxed));
    let (mut data, mut len) = (std::ptr::null::<c_void>(), 0usize);
    let mut loan = std::ptr::null_mut::<c_void>();
    // SAFETY: for every call, `ctx` is this step's; the out-pointers are locals
    unsafe {
        expect("null ctx", nerve_take(std::ptr::null_mut(), input, &mut data, &mut len), NERVE_NULL_POINTER);
        expect("null data", nerve_take(ctx, input, std::ptr::null_mut(), &mut len), NERVE_NULL_POINTER);
        expect("unknown port", nerve_take(ctx, 999, &mut data, &mut len), NERVE_UNKNOWN_PORT);
        expect("an output taken", nerve_take(ctx, output, &mut data, &mut len), NERVE_UNKNOWN_PORT);
        expect("an input loaned", nerve_loan(ctx, input, &mut loan), NERVE_UNKNOWN_PORT);
        expect("send without loan", nerve_send(ctx, output), NERVE_NO_LOAN);
        let got = nerve_latest(ctx, input, &mut data, &mut len);
        if got == NERVE_NO_SAMPLE {
            if !data.is_null() || len != 0 {
                WRONG.lock().expect("lock").push("no sample, but data or len set".into());
            }
            return 0;
        }
        expect("latest", got, NERVE_OK);
        if len != SIZE {
            WRONG.lock().expect("lock").push(format!("a tick of {len} bytes"));
            return 0;
        }
        let tick = data.cast::<Tick>().read();
        let mut gain = 0.0;
        expect("unknown param", nerve_param_f64(ctx, 77, &mut gain), NERVE_UNKNOWN_PORT);
        expect("gain", nerve_param_f64(ctx, GAIN.load(Ordering::Relaxed), &mut gain), NERVE_OK);
        expect("loan", nerve_loan(ctx, output, &mut loan), NERVE_OK);
        expect("second loan", nerve_loan(ctx, output, &mut data.cast_mut()), NERVE_LOAN_PENDING);
        loan.cast::<Tick>().write(Tick { seq: tick.seq * gain as u64, stamp_ns: tick.stamp_ns });
        expect("send", nerve_send(ctx, output), NERVE_OK);
    }
    0
}

#[test]
fn a_relay_through_the_c_api_relays_and_every_misuse_is_a_status() {
    SPEC.set(Spec {
        kind: "crelay",
        task: Task::EventDriven,
        new: Some(new),
        start: None,
        step: Some(step),
        stop: None,
        user: 0,
    })
    .expect("first spec");
    let mut h = Harness::<CAgent>::builder().param("gain", "10").start().expect("the harness makes the C agent");
    let refused = h.set_param("gain", "11").expect_err("a gain above its bound is refused");
    assert!(refused.contains("[0, 10]"), "{refused}");
    h.send("in", Tick { seq: 1, stamp_ns: 10 }).expect("send");
    h.send("in", Tick { seq: 2, stamp_ns: 20 }).expect("send");
    h.step().expect("step");
    let out: Vec<Tick> = h.output("out").expect("output");
    assert_eq!(out.iter().map(|t| (t.seq, t.stamp_ns)).collect::<Vec<_>>(), vec![(20, 20)], "the newest, relayed");
    h.step().expect("a step with nothing waiting");
    assert!(h.output::<Tick>("out").expect("output").is_empty());

    // the context of a step that returned is refused, not read
    let kept = KEPT.load(Ordering::Relaxed);
    assert!(!kept.is_null(), "the step ran");
    let (mut data, mut len) = (std::ptr::null::<c_void>(), 0usize);
    // SAFETY: `kept` is the agent's context, alive while the harness is
    let got = unsafe { nerve_take(kept, IN.load(Ordering::Relaxed), &mut data, &mut len) };
    assert_eq!(got, nerve_status::NERVE_STALE);
    assert!(last_error_string().contains("after the callback"), "{}", last_error_string());

    let wrong = WRONG.lock().expect("lock").clone();
    assert!(wrong.is_empty(), "{wrong:#?}");
}

#[test]
fn nerve_run_refuses_a_null_agent_and_a_bad_kind() {
    // SAFETY: a NULL agent is one of the documented cases
    let code = unsafe { nerve_run(0, std::ptr::null(), std::ptr::null(), std::ptr::null_mut()) };
    assert_eq!(code, 2);
    assert!(last_error_string().contains("`agent` is NULL"), "{}", last_error_string());
    let vt = nerve_agent_vtable {
        kind: c"no spaces".as_ptr(),
        period_ns: 0,
        init: Some(new),
        start: None,
        step: Some(step),
        stop: None,
    };
    // SAFETY: a valid vtable with a kind nerve refuses
    let code = unsafe { nerve_run(0, std::ptr::null(), &vt, std::ptr::null_mut()) };
    assert_eq!(code, 2);
    assert!(last_error_string().contains("kind"), "{}", last_error_string());
}
