//! Property tests of the control protocol's decoding (`control::decode`:
//! router <-> agent, cli <-> router, on iceoryx2 and on the tool socket) and
//! of schemas read from JSON (an MCAP file's channels) and from postcard (a
//! registration), under generated input (issue 40, "every decoder of
//! outside bytes").
//!
//! * Arbitrary bytes, and arbitrary bytes behind a valid version word: an
//!   error or a message, never a panic; the heap the decoding holds at its
//!   peak stays within a bound of the input's length plus serde's cap on a
//!   sequence's pre-allocation (1 MiB); what decodes encodes and decodes
//!   again to the same bytes.
//! * Valid messages round-trip; every strict prefix of one is refused; a
//!   changed byte is refused or decodes to a message that re-encodes
//!   stably; bytes appended are ignored (postcard reads what it needs:
//!   the value is the same).
//! * Schemas: arbitrary JSON text, and JSON of generated schemas, parse or
//!   fail without a panic; what parses and passes `Schema::validate` decodes
//!   arbitrary sample bytes without a panic and without more values than
//!   bytes per field.
//!
//! A schema nested tens of thousands deep in a postcard message overflowed
//! the stack of the decoding thread (postcard has no depth limit) until the
//! schema's deserialisation bounded its depth
//! (`deep_schema_in_a_registration_is_refused` below).
//!
//! The default case count is proptest's (256, or `PROPTEST_CASES`); the long
//! run is in `docs/robustness.md`.

use proptest::prelude::*;
use serde::Serialize;
use serde::de::DeserializeOwned;
use shm_schemas::Schema;
use shm_schemas::control::agent_to_router::{AgentToRouter, PortSpec, Registration, TaskKind};
use shm_schemas::control::cli_to_router::{CliRequest, RouterReply, RouterRequest};
use shm_schemas::control::describe::Description;
use shm_schemas::control::router_to_agent::{AgentCommand, AgentReply};
use shm_schemas::control::{PROTOCOL_VERSION, decode, encode};
use shm_schemas::schema::{Field, Kind, Primitive};
use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

/// Tracks the live heap of the calling thread and its peak, so that a test
/// can bound what a decoder holds at once.
struct Metered;

thread_local! {
    static LIVE: Cell<usize> = const { Cell::new(0) };
    static PEAK: Cell<usize> = const { Cell::new(0) };
}

fn grew(n: usize) {
    let _ = LIVE.try_with(|l| {
        l.set(l.get().saturating_add(n));
        let _ = PEAK.try_with(|p| p.set(p.get().max(l.get())));
    });
}

fn shrank(n: usize) {
    let _ = LIVE.try_with(|l| l.set(l.get().saturating_sub(n)));
}

// SAFETY: every call is forwarded unchanged to the system allocator; the
// counters are thread-local `Cell`s without destructors, which never
// allocate.
unsafe impl GlobalAlloc for Metered {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        grew(layout.size());
        // SAFETY: the caller's contract is the system allocator's.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        shrank(layout.size());
        // SAFETY: `ptr` came from `System.alloc` with this layout.
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        grew(new_size);
        shrank(layout.size());
        // SAFETY: `ptr` came from `System.alloc` with this layout.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static METERED: Metered = Metered;

/// `f()`, and the most heap it held at once beyond what was live before.
fn peak_of<R>(f: impl FnOnce() -> R) -> (R, usize) {
    let base = LIVE.with(Cell::get);
    PEAK.with(|p| p.set(base));
    let r = f();
    (r, PEAK.with(Cell::get) - base)
}

/// The most heap a decoding of `len` bytes may hold: serde pre-allocates a
/// sequence for at most 1 MiB whatever length it claims, and each input
/// byte can make a bounded number of heap bytes (a string's or a vector's
/// element, a boxed schema).
fn heap_bound(len: usize) -> usize {
    (2 << 20) + 256 * len
}

/// Decodes arbitrary `bytes` as `T`: no panic, bounded heap, and a message
/// that decodes re-encodes to bytes that decode to the same encoding.
fn check_arbitrary<T: DeserializeOwned + Serialize>(bytes: &[u8]) -> Result<(), TestCaseError> {
    let (got, peak) = peak_of(|| decode::<T>(bytes));
    prop_assert!(peak <= heap_bound(bytes.len()), "{} bytes held {} bytes of heap", bytes.len(), peak);
    if let Ok(v) = got {
        let once = encode(&v);
        let again: T = decode(&once).map_err(|e| TestCaseError::fail(format!("re-decoding failed: {e}")))?;
        prop_assert_eq!(encode(&again), once);
    }
    Ok(())
}

fn version_word() -> Vec<u8> {
    postcard::to_stdvec(&PROTOCOL_VERSION).expect("a u16 encodes")
}

fn name() -> impl Strategy<Value = String> {
    "[a-z][a-z0-9_-]{0,12}"
}

fn primitive() -> impl Strategy<Value = Primitive> {
    prop_oneof![
        Just(Primitive::U8),
        Just(Primitive::U16),
        Just(Primitive::U32),
        Just(Primitive::U64),
        Just(Primitive::I8),
        Just(Primitive::I16),
        Just(Primitive::I32),
        Just(Primitive::I64),
        Just(Primitive::F32),
        Just(Primitive::F64),
        Just(Primitive::Bool),
    ]
}

/// Schemas of any shape (sizes and offsets need not be consistent: a
/// schema from outside is whatever its sender says), a few levels deep.
fn schema() -> impl Strategy<Value = Schema> {
    let size = prop_oneof![0usize..64, any::<usize>()];
    let leaf = (
        name(),
        size.clone(),
        0usize..16,
        prop_oneof![
            primitive().prop_map(|primitive| Kind::Primitive { primitive }),
            prop_oneof![0usize..64, any::<usize>()].prop_map(|capacity| Kind::String { capacity }),
        ],
    )
        .prop_map(|(type_name, size, align, kind)| Schema { type_name, size, align, kind });
    leaf.prop_recursive(4, 32, 6, move |inner| {
        (
            name(),
            prop_oneof![0usize..256, any::<usize>()],
            0usize..16,
            prop_oneof![
                (prop_oneof![0usize..8, any::<usize>()], inner.clone())
                    .prop_map(|(len, e)| Kind::Array { len, element: Box::new(e) }),
                proptest::collection::vec((name(), prop_oneof![0usize..64, any::<usize>()], inner), 0..6).prop_map(
                    |fs| Kind::Struct {
                        fields: fs.into_iter().map(|(name, offset, schema)| Field { name, offset, schema }).collect()
                    }
                ),
            ],
        )
            .prop_map(|(type_name, size, align, kind)| Schema { type_name, size, align, kind })
    })
}

fn port_spec() -> impl Strategy<Value = PortSpec> {
    (name(), name(), any::<u64>()).prop_map(|(name, type_name, fingerprint)| PortSpec { name, type_name, fingerprint })
}

fn registration() -> impl Strategy<Value = Registration> {
    (
        (name(), any::<u32>(), name(), ".{0,32}"),
        prop_oneof![Just(TaskKind::Periodic), Just(TaskKind::EventDriven)],
        proptest::option::of(any::<u64>()),
        proptest::collection::vec(port_spec(), 0..4),
        proptest::collection::vec(port_spec(), 0..4),
        proptest::option::of(".{0,32}"),
        any::<bool>(),
        proptest::collection::vec(schema(), 0..3),
    )
        .prop_map(
            |((name, pid, kind, executable), task, period_ns, inputs, outputs, log_file, suspended, schemas)| {
                Registration {
                    name,
                    pid,
                    kind,
                    executable,
                    task,
                    period_ns,
                    inputs,
                    outputs,
                    log_file,
                    suspended,
                    schemas,
                    services: Vec::new(),
                    clients: Vec::new(),
                }
            },
        )
}

fn agent_command() -> impl Strategy<Value = AgentCommand> {
    prop_oneof![
        (name(), name(), name(), name()).prop_map(|(input, from_agent, from_port, type_name)| AgentCommand::Connect {
            input,
            from_agent,
            from_port,
            type_name
        }),
        (name(), name(), name()).prop_map(|(input, from_agent, from_port)| AgentCommand::Disconnect {
            input,
            from_agent,
            from_port
        }),
        any::<u64>().prop_map(|period_ns| AgentCommand::SetPeriod { period_ns }),
        Just(AgentCommand::Suspend),
        Just(AgentCommand::Resume),
        name().prop_map(|key| AgentCommand::ParamGet { key }),
        (name(), ".{0,40}").prop_map(|(key, value)| AgentCommand::ParamSet { key, value }),
        Just(AgentCommand::ParamList),
        Just(AgentCommand::Stop),
        Just(AgentCommand::Stats),
    ]
}

fn router_request() -> impl Strategy<Value = RouterRequest> {
    prop_oneof![
        registration().prop_map(|r| RouterRequest::Agent(AgentToRouter::Register(r))),
        (name(), any::<u32>()).prop_map(|(name, pid)| RouterRequest::Agent(AgentToRouter::Unregister { name, pid })),
        Just(RouterRequest::Cli(CliRequest::Ps)),
        any::<u64>().prop_map(|after| RouterRequest::Cli(CliRequest::Events { after })),
        (name(), any::<u64>()).prop_map(|(name, period_ns)| RouterRequest::Cli(CliRequest::Rate { name, period_ns })),
        (name(), name(), ".{0,40}").prop_map(|(name, key, value)| RouterRequest::Cli(CliRequest::ParamSet {
            name,
            key,
            value
        })),
        (name(), "[a-z]{1,8}/[a-z]{1,8}", any::<u32>(), name(), any::<u64>()).prop_filter_map(
            "a valid port reference",
            |(from, to, pid, type_name, fingerprint)| {
                Some(RouterRequest::Cli(CliRequest::Attach {
                    from: format!("{from}/out").parse().ok()?,
                    pid,
                    type_name,
                    fingerprint,
                    to: to.parse().ok()?,
                }))
            }
        ),
    ]
}

/// A valid encoding, then: every strict prefix refused, one byte changed
/// never a panic (and stable if taken), bytes appended the same value.
fn check_mutations<T: DeserializeOwned + Serialize>(
    bytes: &[u8],
    cut: prop::sample::Index,
    at: prop::sample::Index,
    flip: u8,
    tail: &[u8],
) -> Result<(), TestCaseError> {
    let n = cut.index(bytes.len());
    prop_assert!(decode::<T>(&bytes[..n]).is_err(), "a message cut at {} of {} bytes was taken", n, bytes.len());
    let mut changed = bytes.to_vec();
    changed[at.index(bytes.len())] ^= flip;
    check_arbitrary::<T>(&changed)?;
    let mut longer = bytes.to_vec();
    longer.extend_from_slice(tail);
    let v: T = decode(&longer).map_err(|e| TestCaseError::fail(format!("bytes appended: {e}")))?;
    prop_assert_eq!(encode(&v), bytes.to_vec());
    Ok(())
}

proptest! {
    // no regression files in the source tree: a failure prints its input
    #![proptest_config(ProptestConfig { failure_persistence: None, ..ProptestConfig::default() })]

    /// Arbitrary bytes as every message type of the protocol.
    #[test]
    fn proptest_control_arbitrary_bytes(
        versioned in any::<bool>(),
        body in proptest::collection::vec(any::<u8>(), 0..512),
    ) {
        let mut bytes = if versioned { version_word() } else { Vec::new() };
        bytes.extend_from_slice(&body);
        check_arbitrary::<RouterRequest>(&bytes)?;
        check_arbitrary::<RouterReply>(&bytes)?;
        check_arbitrary::<AgentCommand>(&bytes)?;
        check_arbitrary::<AgentReply>(&bytes)?;
        check_arbitrary::<AgentToRouter>(&bytes)?;
        check_arbitrary::<Description>(&bytes)?;
    }

    /// Arbitrary bytes behind a valid version and the tags of a
    /// registration, so that the decoder walks into ports and schemas.
    #[test]
    fn proptest_control_arbitrary_registrations(body in proptest::collection::vec(any::<u8>(), 0..1024)) {
        let mut bytes = version_word();
        bytes.extend_from_slice(&[0, 0]); // RouterRequest::Agent, AgentToRouter::Register
        bytes.extend_from_slice(&body);
        check_arbitrary::<RouterRequest>(&bytes)?;
    }

    /// decode(encode(x)) == x, and the mutations of a valid message.
    #[test]
    fn proptest_control_round_trip_and_mutations(
        reg in registration(),
        cmd in agent_command(),
        req in router_request(),
        cut in any::<prop::sample::Index>(),
        at in any::<prop::sample::Index>(),
        flip in 1u8..=255,
        tail in proptest::collection::vec(any::<u8>(), 1..32),
    ) {
        let bytes = encode(&AgentToRouter::Register(reg.clone()));
        match decode::<AgentToRouter>(&bytes) {
            Ok(AgentToRouter::Register(back)) => prop_assert_eq!(back, reg),
            other => prop_assert!(false, "a registration came back as {:?}", other),
        }
        check_mutations::<AgentToRouter>(&bytes, cut, at, flip, &tail)?;

        let bytes = encode(&cmd);
        let back: AgentCommand = decode(&bytes).map_err(|e| TestCaseError::fail(e.to_string()))?;
        prop_assert_eq!(encode(&back), bytes.clone());
        check_mutations::<AgentCommand>(&bytes, cut, at, flip, &tail)?;

        let bytes = encode(&req);
        let back: RouterRequest = decode(&bytes).map_err(|e| TestCaseError::fail(e.to_string()))?;
        prop_assert_eq!(encode(&back), bytes.clone());
        check_mutations::<RouterRequest>(&bytes, cut, at, flip, &tail)?;
    }

    /// A schema's JSON (as an MCAP channel carries it): generated schemas
    /// round-trip, arbitrary text parses or fails, and a schema that parses
    /// and validates reads arbitrary sample bytes without a panic.
    #[test]
    fn proptest_schema_json(
        s in schema(),
        text in ".{0,256}",
        sample in proptest::collection::vec(any::<u8>(), 0..512),
    ) {
        let json = serde_json::to_vec(&s).map_err(|e| TestCaseError::fail(e.to_string()))?;
        let back: Schema = serde_json::from_slice(&json).map_err(|e| TestCaseError::fail(e.to_string()))?;
        prop_assert_eq!(&back, &s);
        let _ = serde_json::from_str::<Schema>(&text);
        // validated or not: `Schema::decode` never trusts a schema's figures
        let _ = s.validate();
        let _ = s.decode(&sample);
        s.visit_fields(|_, _, _| {});
        let post = postcard::to_stdvec(&s).map_err(|e| TestCaseError::fail(e.to_string()))?;
        let back: Schema = postcard::from_bytes(&post).map_err(|e| TestCaseError::fail(e.to_string()))?;
        prop_assert_eq!(back, s);
    }

    /// A schema's JSON with one character changed or cut: an error or a
    /// schema, never a panic; a schema that validates reads any bytes.
    #[test]
    fn proptest_schema_json_mutated(
        s in schema(),
        at in any::<prop::sample::Index>(),
        with in any::<char>(),
        cut in any::<prop::sample::Index>(),
        sample in proptest::collection::vec(any::<u8>(), 0..512),
    ) {
        let json = serde_json::to_string(&s).map_err(|e| TestCaseError::fail(e.to_string()))?;
        let mut chars: Vec<char> = json.chars().collect();
        let i = at.index(chars.len());
        chars[i] = with;
        let changed: String = chars.iter().collect();
        for text in [changed.as_str(), &json[..json.char_indices().nth(cut.index(chars.len())).map_or(0, |(b, _)| b)]] {
            let (parsed, peak) = peak_of(|| serde_json::from_str::<Schema>(text));
            prop_assert!(peak <= heap_bound(text.len()));
            if let Ok(p) = parsed
                && p.validate().is_ok()
            {
                let _ = p.decode(&sample);
            }
        }
    }
}

/// A registration whose one schema is an array of an array of ... 50,000
/// deep (250 KB, within the tool socket's 1 MiB and the router's growing
/// service): postcard recurses once per level and overflows an 8 MiB stack,
/// which aborts the router. It must be refused with an error instead.
#[test]
fn deep_schema_in_a_registration_is_refused() {
    let mut bytes = version_word();
    bytes.extend_from_slice(&[0, 0]); // RouterRequest::Agent, AgentToRouter::Register
    // name "a", pid 1, kind "k", executable "e", periodic, no period, no
    // inputs, no outputs, no log file, not suspended, one schema
    bytes.extend_from_slice(&[1, b'a', 1, 1, b'k', 1, b'e', 0, 0, 0, 0, 0, 0, 1]);
    for _ in 0..50_000 {
        // type name "", size 0, align 0, Kind::Array, len 0, element:
        bytes.extend_from_slice(&[0, 0, 0, 1, 0]);
    }
    bytes.extend_from_slice(&[0, 0, 0, 0, 0]); // a u8 primitive
    let refused = std::thread::Builder::new()
        .stack_size(8 << 20)
        .spawn(move || decode::<RouterRequest>(&bytes).is_err())
        .expect("a thread")
        .join()
        .expect("no panic");
    assert!(refused, "a schema nested 50,000 deep was taken");
}
