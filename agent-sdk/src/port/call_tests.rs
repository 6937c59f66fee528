//! Calls answered and read in place, over real iceoryx2 in one process:
//! the server writes its answer into the response's shared memory
//! (`serve_in_place`, `serve_uninit`), the client writes its request there
//! (`call_with`) and reads the answer where the server wrote it
//! (`take_with`), fixed answers and sequences alike; the by-value forms
//! (`serve`, `take`) still work beside them, and the errors are the same.

use super::{CallError, CallId, CallOptions, Client, Server};
use crate::port::bytes::Binding;
use crate::port::{SeqClient, SeqServer};
use crate::world::World;
use crate::world::test_support::Cleanup;
use shm_schemas::payloads::{Scalar, Tick};
use std::sync::Arc;
use std::time::Duration;

/// Whether `at` lies in a shared-memory mapping of this process (an
/// iceoryx2 data segment under `/dev/shm`), not on the stack or the heap.
fn in_shared_memory<T>(at: *const T) -> bool {
    let at = at as usize;
    let maps = std::fs::read_to_string("/proc/self/maps").expect("/proc/self/maps");
    maps.lines().any(|line| {
        let mut fields = line.split_whitespace();
        let range = fields.next().unwrap_or("");
        let path = fields.nth(4).unwrap_or("");
        let Some((lo, hi)) = range.split_once('-') else { return false };
        let (Ok(lo), Ok(hi)) = (usize::from_str_radix(lo, 16), usize::from_str_radix(hi, 16)) else { return false };
        (lo..hi).contains(&at) && path.starts_with("/dev/shm/")
    })
}

/// Repeats `f` until it gives something, at most 500 times 2 ms apart.
fn within_a_second<R>(what: &str, mut f: impl FnMut() -> Option<R>) -> R {
    for _ in 0..500 {
        if let Some(r) = f() {
            return r;
        }
        std::thread::sleep(Duration::from_millis(2));
    }
    panic!("{what}: nothing within 1 s");
}

/// Serves until one request was answered, with `serve`.
fn served(mut serve: impl FnMut() -> Result<usize, CallError>) {
    let n = within_a_second("a request", || Some(serve().expect("served")).filter(|n| *n > 0));
    assert_eq!(n, 1);
}

/// The fixed call's in-place forms, each against the by-value form of the
/// other side, and the errors `take_with` gives: a timeout, not wired.
#[test]
fn a_call_is_answered_and_read_in_place_in_shared_memory() {
    let world = World::new(&format!("callinplace{}", std::process::id())).expect("world");
    let _cleanup = Cleanup(world.clone());
    let node = Arc::new(world.node("test").expect("node"));
    let robot = world.robot().clone();
    let service = robot.port_service("doubler", "double");
    let (server, _) = Server::<Tick, Scalar>::bind(&Binding::Shm(node.clone()), "double", &service, 1).expect("server");
    let options = CallOptions { timeout: Duration::from_millis(200), max_in_flight: 4 };
    let (client, side) = Client::<Tick, Scalar>::bind(&Binding::Shm(node.clone()), "doubler", options).expect("client");
    let e = client.call_with(|t| t.seq = 1).expect_err("not wired yet");
    assert!(matches!(e, CallError::NotWired { .. }), "{e}");
    assert!(side.connect(&node, &robot, "doubler", "double").expect("wired"));
    let on_the_stack = Scalar::default();
    assert!(!in_shared_memory(&on_the_stack) && !in_shared_memory(Box::new(0u64).as_ref()), "the check can fail");

    // the request written in place; answered in place; read in place
    let mut request_in_shm = false;
    let id = client
        .call_with(|t| {
            request_in_shm = in_shared_memory(t);
            *t = Tick { seq: 21, stamp_ns: 5 };
        })
        .expect("call");
    assert!(request_in_shm, "call_with wrote the request elsewhere than in shared memory");
    let mut answer_in_shm = false;
    served(|| {
        server.serve_in_place(|t, answer| {
            answer_in_shm = in_shared_memory(t) && in_shared_memory(answer);
            assert_eq!(*answer, Scalar::default(), "a default answer to start from");
            answer.value = 2.0 * t.seq as f64;
            answer.stamp_ns = t.stamp_ns;
        })
    });
    assert!(answer_in_shm, "serve_in_place gave a request or an answer outside shared memory");
    let (got, value, read_in_shm) = within_a_second("the answer", || {
        client.take_with(|got, answer| {
            let answer = answer.expect("answered");
            (got, *answer, in_shared_memory(answer))
        })
    });
    assert_eq!((got, value), (id, Scalar { value: 42.0, stamp_ns: 5 }));
    assert!(read_in_shm, "take_with read a copy, not the answer in shared memory");

    // in place against by value, both ways
    let id = client.call(&Tick { seq: 4, stamp_ns: 6 }).expect("call");
    // SAFETY: both fields of the answer are written
    served(|| unsafe {
        server.serve_uninit(|t, slot| {
            slot.write(Scalar { value: -(t.seq as f64), stamp_ns: t.stamp_ns });
        })
    });
    let (got, answer) = within_a_second("the answer", || client.take());
    assert_eq!((got, answer.expect("answered")), (id, Scalar { value: -4.0, stamp_ns: 6 }));
    let id = client.call_with(|t| t.seq = 8).expect("call");
    served(|| server.serve(|t| Scalar { value: t.seq as f64, stamp_ns: 1 }));
    let got = within_a_second("the answer", || client.take_with(|got, answer| (got, answer.map(|a| a.value))));
    assert_eq!((got.0, got.1.expect("answered")), (id, 8.0));
    assert_eq!(server.answered(), 3);

    // no answer within the timeout: take_with hands out the same error as take
    let id = client.call_with(|t| t.seq = 9).expect("call");
    std::thread::sleep(options.timeout + Duration::from_millis(20));
    let (got, e) = within_a_second("the timeout", || client.take_with(|got, answer| (got, answer.copied())));
    match e {
        Err(e @ CallError::TimedOut { .. }) => assert!(e.maybe_carried_out(), "{e}"),
        other => panic!("a call past its timeout: {other:?}"),
    }
    assert_eq!(got, id);
    assert!(client.take_with(|_, _| ()).is_none(), "nothing else finished");
}

/// A sequence answer read in place: the header and the elements where the
/// server wrote them, of the length it chose; one past the maximum is the
/// same refusal as `take` gives.
#[test]
fn a_sequence_answer_is_read_in_place() {
    let world = World::new(&format!("callseqinplace{}", std::process::id())).expect("world");
    let _cleanup = Cleanup(world.clone());
    let node = Arc::new(world.node("test").expect("node"));
    let robot = world.robot().clone();
    let service = robot.port_service("planner", "plan");
    let (server, _) =
        SeqServer::<Tick, Tick, Scalar>::bind(&Binding::Shm(node.clone()), "plan", &service, 300).expect("server");
    let options = CallOptions { timeout: Duration::from_secs(5), max_in_flight: 4 };
    let (client, side) =
        SeqClient::<Tick, Tick, Scalar>::bind(&Binding::Shm(node.clone()), "planner", options).expect("client");
    assert!(side.connect(&node, &robot, "planner", "plan").expect("wired"));
    let answer = |t: &Tick| {
        (Scalar { value: t.seq as f64, stamp_ns: 3 }, (0..t.seq).map(|i| Tick { seq: i, stamp_ns: 7 }).collect())
    };
    for (n, ok) in [(300u64, true), (301, false), (0, true)] {
        let id = client.call_with(|t| t.seq = n).expect("call");
        let served = within_a_second("a request", || match server.serve(answer) {
            Ok(0) => None,
            other => Some(other),
        });
        assert_eq!(served.is_ok(), ok, "{served:?}");
        let (got, result) = within_a_second("the answer", || {
            client.take_with(|got: CallId, answer| {
                (
                    got,
                    answer.map(|(header, items)| {
                        assert!(in_shared_memory(header) && (items.is_empty() || in_shared_memory(items.as_ptr())));
                        (*header, items.len(), items.last().copied())
                    }),
                )
            })
        });
        assert_eq!(got, id);
        match (ok, result) {
            (true, Ok((header, len, last))) => {
                assert_eq!((header.value, len as u64), (n as f64, n));
                assert_eq!(last, n.checked_sub(1).map(|i| Tick { seq: i, stamp_ns: 7 }));
            }
            (false, Err(CallError::RefusedTooLong { len, max, .. })) => assert_eq!((len, max), (301, 300)),
            (_, other) => panic!("an answer of {n}: {other:?}"),
        }
    }
}
