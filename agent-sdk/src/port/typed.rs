//! Typed ports: [`Output<T>`] and [`Input<T>`], thin views of the byte
//! port (`port::bytes`) that read and write a Rust payload type `T` in
//! place.
//!
//! An [`Output<T>`] is a [`SchemaOutput`] whose samples are
//! `size_of::<T>()` bytes aligned for `T`: [`Output::send`] loans a slot
//! and writes the value into it, once, in shared memory; an [`Input<T>`] is
//! a [`SchemaInput`] whose samples it hands out as `&T`, in place. Nothing
//! is copied or allocated on the way beyond what the byte port does, and
//! the service is the one a port declared by the type's [`Schema`] makes:
//! a Rust agent and a Python agent (or `nerve echo`, the recorder, a
//! replay) read each other's samples.
//!
//! A view is only made over a byte port of `T`'s own size and alignment
//! ([`Output::over`], [`Input::over`]): reading the bytes as `T` otherwise
//! would read past the sample or misaligned.
//!
//! [`Schema`]: shm_schemas::Schema

use super::bytes::{Binding, InputInner, Meta, SchemaInput, SchemaOutput};
use super::error::PortError;
use super::service::{Carried, SUBSCRIBER_BUFFER};
use shm_schemas::Payload;
use std::marker::PhantomData;
use std::mem::{MaybeUninit, align_of, size_of};
use std::sync::Arc;

/// Refuses a byte port that does not carry `T`: another type name, or
/// another size or alignment (the typed view would read it wrongly).
fn check_carries<T: Payload>(service: &str, carried: &Carried) -> Result<(), PortError> {
    if carried.size() != size_of::<T>() || carried.align() != align_of::<T>() {
        return Err(PortError::TypeLayout {
            service: service.into(),
            type_name: T::stable_type_name().into(),
            size: size_of::<T>(),
            align: align_of::<T>(),
            port_size: carried.size(),
            port_align: carried.align(),
        });
    }
    if carried.type_name != T::stable_type_name() {
        return Err(PortError::IncompatibleType { service: service.into(), type_name: T::stable_type_name().into() });
    }
    Ok(())
}

/// `bytes` read in place as a `T`, if they are a whole, aligned `T`.
fn view<T: Payload>(bytes: &[u8]) -> Option<&T> {
    if bytes.len() != size_of::<T>() || !(bytes.as_ptr() as usize).is_multiple_of(align_of::<T>()) {
        return None;
    }
    // SAFETY: the bytes are `size_of::<T>()` long and aligned for `T`
    // (checked above); they are a sample of a port of `T`'s type name and
    // layout (checked when the view was made, and by the service's
    // fingerprint), written by a peer as a `T`; a payload type is plain
    // data (`#[derive(Payload)]` requires every field to accept any bits).
    Some(unsafe { &*bytes.as_ptr().cast::<T>() })
}

/// An output port of payload type `T`.
///
/// What it is bound to is the SDK's choice, never the agent's: an iceoryx2
/// service in a running agent, nothing while the agent is described
/// (`--describe`), an in-memory list in a test ([`crate::testing`]).
pub struct Output<T: Payload> {
    port: SchemaOutput,
    _type: PhantomData<fn(T)>,
}

impl<T: Payload> std::fmt::Debug for Output<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Output").field("service", &self.port.service()).field("type", &T::stable_type_name()).finish()
    }
}

impl<T: Payload> Output<T> {
    /// Output `port` (service `service`) of agent `sender`, bound to `binding`.
    pub(crate) fn bind(binding: &Binding, port: &str, service: &str, sender: &str) -> Result<Self, PortError> {
        let carried = Carried::of_type::<T>(service)?;
        Self::over(SchemaOutput::bind(binding, port, service, sender, T::schema(), carried, true)?)
    }

    /// An output of `T` in shared memory: service `service`, sent as `sender`.
    #[cfg(test)]
    pub(crate) fn create(
        node: &iceoryx2::prelude::Node<crate::world::Ipc>,
        service: &str,
        sender: &str,
    ) -> Result<Self, PortError> {
        let carried = Carried::of_type::<T>(service)?;
        Self::over(SchemaOutput::shm(node, service, sender, T::schema(), carried)?)
    }

    /// The typed view of byte output `port`; refused unless the port carries
    /// `T` (its type name, size and alignment).
    pub fn over(port: SchemaOutput) -> Result<Self, PortError> {
        check_carries::<T>(port.service(), port.carried())?;
        Ok(Output { port, _type: PhantomData })
    }

    /// The iceoryx2 service name of this port.
    pub fn service(&self) -> &str {
        self.port.service()
    }

    /// What this output counted of its keep-all readers (issue 46,
    /// [`crate::port::keep_all`]): readers, waits, samples lost.
    pub fn keep_all_counts(&self) -> crate::port::keep_all::KeepAllCounts {
        self.port.keep_all_figures().map(|f| f.counts()).unwrap_or_default()
    }

    /// Loans a slot and hands it to `write` as a `T` not yet written, then
    /// sends it.
    ///
    /// # Safety
    /// `write` must leave the `T` initialised (see [`Output::send_uninit`]).
    unsafe fn send_in_place(&self, write: impl FnOnce(&mut MaybeUninit<T>)) -> Result<(), PortError> {
        let mut loan = self.port.loan(false)?;
        // stamped as it starts to be written, as a sample loaned from a typed iceoryx2 port always was
        let header = self.port.next_header();
        let bytes = loan.bytes_mut();
        debug_assert!(bytes.len() == size_of::<T>() && (bytes.as_ptr() as usize).is_multiple_of(align_of::<T>()));
        // SAFETY: a loan of this port is `size_of::<T>()` bytes aligned for
        // `T` (the port carries `T`'s layout, checked in `over`; iceoryx2
        // aligns the payload as the service's type details say), and it is
        // the only reference to them until sent
        write(unsafe { &mut *bytes.as_mut_ptr().cast::<MaybeUninit<T>>() });
        self.port.publish_as(loan, header).map(|_| ())
    }

    /// Sends `value` (written once, in place, into shared memory) and wakes the readers.
    pub fn send(&self, value: T) -> Result<(), PortError> {
        // SAFETY: the value is written whole
        unsafe {
            self.send_in_place(|slot| {
                slot.write(value);
            })
        }
    }

    /// Sends a value built in place by `fill`, for payloads too large to build on the stack.
    pub fn send_with(&self, fill: impl FnOnce(&mut T)) -> Result<(), PortError>
    where
        T: Default,
    {
        // SAFETY: a default value is written whole before `fill` changes it
        unsafe { self.send_in_place(|slot| fill(slot.write(T::default()))) }
    }

    /// Sends a payload written in place by `fill`, without writing a default
    /// value first: a large frame costs one write into shared memory, not two.
    ///
    /// # Safety
    /// `fill` must leave the payload initialised: every field a reader will
    /// look at written, and only bit patterns valid for `T` in the rest (for
    /// plain numeric and byte-array payloads any bytes are valid).
    pub unsafe fn send_uninit(&self, fill: impl FnOnce(&mut MaybeUninit<T>)) -> Result<(), PortError> {
        // SAFETY: the caller guarantees that `fill` initialises the payload
        unsafe { self.send_in_place(fill) }
    }
}

/// An input port of payload type `T`, fed by any number of output ports.
pub struct Input<T: Payload> {
    port: SchemaInput,
    _type: PhantomData<fn() -> T>,
}

impl<T: Payload> std::fmt::Debug for Input<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Input").field("name", &self.inner().name()).field("type", &T::stable_type_name()).finish()
    }
}

impl<T: Payload> Input<T> {
    /// Input `name` of `T`, and its shared side for the message checker.
    pub(crate) fn new(name: &str) -> Result<(Self, Arc<InputInner>), PortError> {
        let carried = Carried::of_type::<T>(name)?;
        let (port, inner) = SchemaInput::with(name, T::schema(), carried, false);
        Ok((Self::over(port)?, inner))
    }

    /// The typed view of byte input `port`; refused unless the port carries
    /// `T` (its type name, size and alignment).
    pub fn over(port: SchemaInput) -> Result<Self, PortError> {
        check_carries::<T>(port.inner().name(), port.inner().carried())?;
        Ok(Input { port, _type: PhantomData })
    }

    pub(crate) fn inner(&self) -> &InputInner {
        self.port.inner()
    }

    /// Hands `bytes` to `f` as a `T`; a sample that is not a whole `T` (a
    /// peer that wrote another length) is logged and passed over.
    fn typed<R>(&self, h: &shm_schemas::SampleHeader, bytes: &[u8], f: impl FnOnce(&Meta, &T) -> R) -> Option<R> {
        match view::<T>(bytes) {
            Some(v) => Some(f(&Meta::of(h), v)),
            None => {
                tracing::warn!(input = %self.inner().name(), len = bytes.len(), "a sample that is not a whole {}", T::stable_type_name());
                None
            }
        }
    }

    /// Takes the next sample from any source (round robin between sources).
    pub fn recv(&self) -> Option<(Meta, T)> {
        self.inner().next_with(|h, b| self.typed(h, b, |m, v| (*m, *v))).flatten()
    }

    /// Hands every waiting sample, in place (zero copy), to `f`; returns how
    /// many. At most a port's buffer ([`SUBSCRIBER_BUFFER`]) per source:
    /// what arrives meanwhile is left for the next step (whose wake-up is
    /// already pending). Unbounded, a step that sends what it drains along
    /// an allowed loop back to itself never returned, and held the input,
    /// so that even `nerve ps` could not read its statistics.
    pub fn drain(&self, f: impl FnMut(&Meta, &T)) -> usize {
        self.drain_up_to(SUBSCRIBER_BUFFER, f)
    }

    /// Like [`Input::drain`], but takes at most `max` samples from each
    /// source: a sender that refills the port faster than `f` works cannot
    /// keep the caller in the loop for ever. What is left stays queued (and
    /// the oldest of it is overwritten, and counted, if the sender goes on).
    pub fn drain_up_to(&self, max: usize, mut f: impl FnMut(&Meta, &T)) -> usize {
        let done: Result<usize, std::convert::Infallible> = self.try_drain_up_to(max, |m, v| {
            f(m, v);
            Ok(())
        });
        match done {
            Ok(n) => n,
        }
    }

    /// Like [`Input::drain`], but `f` may fail: the first error ends the
    /// drain and is returned, so that a step can use `?` on what it does with
    /// each sample:
    ///
    /// ```ignore
    /// self.input.try_drain(|_, tick| self.out.send(*tick))?;
    /// ```
    ///
    /// The sample `f` failed on is consumed; those after it stay queued for
    /// the next step.
    pub fn try_drain<E>(&self, f: impl FnMut(&Meta, &T) -> Result<(), E>) -> Result<usize, E> {
        self.try_drain_up_to(SUBSCRIBER_BUFFER, f)
    }

    /// [`Input::try_drain`] with at most `max` samples from each source (see
    /// [`Input::drain_up_to`]).
    pub fn try_drain_up_to<E>(&self, max: usize, mut f: impl FnMut(&Meta, &T) -> Result<(), E>) -> Result<usize, E> {
        self.inner().visit_up_to(max, |h, b| self.typed(h, b, &mut f).unwrap_or(Ok(())))
    }

    /// Drains every waiting sample and returns the newest (by stamp).
    pub fn latest(&self) -> Option<(Meta, T)> {
        let mut best: Option<(Meta, T)> = None;
        self.drain(|m, v| {
            if best.as_ref().is_none_or(|(b, _)| m.stamp_ns >= b.stamp_ns) {
                best = Some((*m, *v));
            }
        });
        best
    }

    /// How many sources feed this input now.
    pub fn sources(&self) -> usize {
        self.port.sources()
    }
}

#[cfg(test)]
mod tests {
    use super::{Input, Output};
    use crate::port::PortError;
    use crate::port::bytes::{DynInput, gap};
    use crate::port::service::{MAX_SOURCES, port_event, port_service};
    use crate::world::World;
    use crate::world::test_support::Cleanup;
    use shm_schemas::payloads::{Scalar, Tick};

    /// `Pose` as an old build defined it: the same name and size as the
    /// new one, the fields in another order (iceoryx2 alone cannot tell).
    mod old {
        #[derive(Debug, Clone, Copy, Default, serde::Serialize, shm_schemas::Payload)]
        #[payload(name = "test::Pose")]
        #[repr(C)]
        pub struct Pose {
            pub x: f64,
            pub y: f64,
        }
    }
    mod new {
        #[derive(Debug, Clone, Copy, Default, serde::Serialize, shm_schemas::Payload)]
        #[payload(name = "test::Pose")]
        #[repr(C)]
        pub struct Pose {
            pub y: f64,
            pub x: f64,
        }
    }

    #[test]
    fn a_port_carries_its_attributes_and_another_layout_of_its_type_is_refused() {
        use iceoryx2::service::port_factory::PortFactory as _;
        use shm_schemas::Payload as _;
        let world = World::new(&format!("layout{}", std::process::id())).expect("world");
        let _cleanup = Cleanup(world.clone());
        let node = world.node("test").expect("node");
        let robot = world.robot().clone();
        let service = robot.port_service("arm", "pose");
        let out = port_service::<old::Pose>(&node, &service).expect("created");
        let _ev = port_event(&node, &service).expect("event");
        let attrs: Vec<String> = out.attributes().iter().map(|a| format!("{}={}", a.key(), a.value())).collect();
        let fp = old::Pose::layout_fingerprint();
        assert_ne!(fp, new::Pose::layout_fingerprint());
        for want in [
            "nerve.type=test::Pose".to_string(),
            format!("nerve.fingerprint={fp:#018x}"),
            "nerve.agent=arm".into(),
            "nerve.port=pose".into(),
        ] {
            assert!(attrs.contains(&want), "{want} in {attrs:?}");
        }
        assert_eq!(crate::port::service::service_fingerprint(&out), Some(fp));
        // an input of the new build refuses the old port, saying both layouts
        let (_input, inner) = Input::<new::Pose>::new("in").expect("input");
        match inner.connect(&node, &robot, "arm", "pose") {
            Err(e @ PortError::LayoutMismatch { .. }) => {
                let text = e.to_string();
                assert!(text.contains(&format!("{fp:#018x}")) && text.contains("rebuild the older one"), "{text}");
            }
            other => panic!("another layout of test::Pose: {:?}", other.err()),
        }
        // and so does a second publisher of the new build
        match port_service::<new::Pose>(&node, &service) {
            Err(PortError::LayoutMismatch { theirs, ours, .. }) => {
                assert_eq!((theirs, ours), (fp, new::Pose::layout_fingerprint()))
            }
            other => panic!("a publisher of another layout: {:?}", other.err()),
        }
        // the same build reads it
        let (_input, inner) = Input::<old::Pose>::new("in").expect("input");
        assert!(inner.connect(&node, &robot, "arm", "pose").expect("same layout"));
    }

    #[test]
    fn a_port_error_says_which_operation_failed_and_keeps_iceoryx2s_cause() {
        let world = World::new(&format!("perr{}", std::process::id())).expect("world");
        let _cleanup = Cleanup(world.clone());
        let node = world.node("test").expect("node");
        let service = format!("nerve/{}/a/out", world.robot());
        let _ticks = port_service::<Tick>(&node, &service).expect("created");
        match port_service::<Scalar>(&node, &service) {
            Err(PortError::IncompatibleType { service: s, type_name }) => {
                assert_eq!(s, service);
                assert_eq!(type_name, "nerve::Scalar");
            }
            other => panic!("another type on the same port: {:?}", other.err()),
        }
        // an operation's failure keeps iceoryx2's error as its source
        let e = PortError::Loan { service: service.clone(), source: iceoryx2::port::LoanError::OutOfMemory };
        let source = std::error::Error::source(&e).expect("a source");
        assert!(source.downcast_ref::<iceoryx2::port::LoanError>().is_some(), "{source:?}");
        assert!(e.to_string().contains("cannot loan a sample") && e.to_string().contains(&service), "{e}");
    }

    /// A Connect can come from anyone who opens the agent's control service
    /// (review R10): a source that does not exist is refused and leaves no
    /// file, and an input takes at most MAX_SOURCES sources.
    #[test]
    fn an_input_opens_existing_sources_only_and_at_most_max_sources() {
        let world = World::new(&format!("fanin{}", std::process::id())).expect("world");
        let _cleanup = Cleanup(world.clone());
        let node = world.node("test").expect("node");
        let robot = world.robot().clone();
        let (input, inner) = Input::<Tick>::new("in").expect("input");
        let files = |w: &World| {
            let mut f = w.shm_files();
            f.extend(w.iox2_files());
            f.sort();
            f
        };
        let before = files(&world);
        match inner.connect(&node, &robot, "ghost", "out") {
            Err(PortError::NoSuchPort { service }) => assert_eq!(service, robot.port_service("ghost", "out")),
            other => panic!("a source nobody has: {:?}", other.err()),
        }
        assert_eq!(files(&world), before, "refusing a source created files");
        assert_eq!(input.sources(), 0);

        let sources: Vec<_> = (0..=MAX_SOURCES)
            .map(|i| {
                let service = robot.port_service(&format!("a{i}"), "out");
                (port_service::<Tick>(&node, &service).expect("service"), port_event(&node, &service).expect("event"))
            })
            .collect();
        for i in 0..MAX_SOURCES {
            assert!(inner.connect(&node, &robot, &format!("a{i}"), "out").expect("an existing source"));
        }
        assert!(!inner.connect(&node, &robot, "a0", "out").expect("again"), "already read: nothing changes");
        match inner.connect(&node, &robot, &format!("a{MAX_SOURCES}"), "out") {
            Err(e @ PortError::TooManySources { .. }) => {
                assert!(e.to_string().contains(&format!("{MAX_SOURCES} sources")), "{e}")
            }
            other => panic!("source {} of one input: {:?}", MAX_SOURCES + 1, other.err()),
        }
        assert_eq!(input.sources(), MAX_SOURCES);
        drop(sources);
    }

    #[test]
    fn gaps_are_counted_without_overflow() {
        assert_eq!(gap(0, 5), 0, "the first sample starts the count");
        assert_eq!(gap(5, 6), 0);
        assert_eq!(gap(5, 9), 3);
        assert_eq!(gap(9, 2), 0, "a restarted sender counts again from its own start");
        assert_eq!(gap(u64::MAX, 1), 0, "a hostile u64::MAX does not overflow (review R9)");
        assert_eq!(gap(1, u64::MAX), u64::MAX - 2);
        assert_eq!(gap(u64::MAX - 1, u64::MAX), 0);
    }

    /// A typed view is made only over a byte port of the type's own size,
    /// alignment and name: a schema that says another layout (a
    /// hand-written `Described`, a Python class of that name) is refused
    /// on both sides, before a sample is ever read as the type.
    #[test]
    fn a_typed_view_over_a_port_of_another_size_alignment_or_type_is_refused() {
        use crate::port::bytes::{Binding, SchemaInput, SchemaOutput};
        use shm_schemas::Described as _;
        let renamed = |mut schema: shm_schemas::Schema| {
            schema.type_name = "nerve::Tick".into();
            schema
        };
        // 16 bytes as Tick, aligned to 1; 24 bytes aligned to 8
        for (schema, size, align) in [(renamed(<[u8; 16]>::schema()), 16, 1), (renamed(<[u64; 3]>::schema()), 24, 8)] {
            let out = SchemaOutput::declare(&Binding::Nothing, "tick", "nerve/r/a/tick", "a", schema.clone())
                .expect("a valid schema");
            match Output::<Tick>::over(out) {
                Err(e @ PortError::TypeLayout { .. }) => {
                    let text = e.to_string();
                    assert!(text.contains(&format!("{size} bytes aligned to {align}")), "{text}");
                    assert!(text.contains("16 bytes aligned to 8"), "the type's own layout: {text}");
                }
                other => panic!("a view of {size} bytes aligned to {align} as Tick: {other:?}"),
            }
            let (input, _) = SchemaInput::new("in", schema).expect("input");
            assert!(matches!(Input::<Tick>::over(input), Err(PortError::TypeLayout { .. })));
        }
        // the same layout under another name is another type
        let out = SchemaOutput::declare(&Binding::Nothing, "v", "nerve/r/a/v", "a", Scalar::schema()).expect("scalar");
        assert!(matches!(Output::<Tick>::over(out), Err(PortError::IncompatibleType { .. })));
        // and the type's own schema makes a view
        let out = SchemaOutput::declare(&Binding::Nothing, "t", "nerve/r/a/t", "a", Tick::schema()).expect("tick");
        assert!(Output::<Tick>::over(out).is_ok());
    }

    /// Wire compatibility: a typed port of this stack is the very service
    /// a port made with the type itself (`publish_subscribe::<T>()`) is, so
    /// a program built before this stack (or a tool publishing with
    /// iceoryx2 directly) and an agent of it read each other; and typed
    /// and byte ports of one layout read each other in place.
    #[test]
    fn typed_ports_read_and_are_read_by_iceoryx2_typed_ports_and_byte_ports() {
        use crate::port::bytes::{RawPort, SchemaInput, SchemaOutput};
        use crate::port::service::existing_port_service;
        use shm_schemas::Described as _;
        let world = World::new(&format!("view{}", std::process::id())).expect("world");
        let _cleanup = Cleanup(world.clone());
        let node = world.node("test").expect("node");
        let robot = world.robot().clone();

        // a typed output, read by iceoryx2 as the type, by bytes and by a tool
        let service = robot.port_service("a", "tick");
        let out = Output::<Tick>::create(&node, &service, "a").expect("typed output");
        let ps = existing_port_service::<Tick>(&node, &service).expect("iceoryx2 opens it as Tick");
        let typed_sub = ps.subscriber_builder().create().expect("typed subscriber");
        let raw = RawPort::open(&node, &service).expect("raw");
        let (bytes_in, bytes_inner) = SchemaInput::new("in", Tick::schema()).expect("input");
        assert!(bytes_inner.connect(&node, &robot, "a", "tick").expect("bytes open it"));
        out.send(Tick { seq: 7, stamp_ns: 70 }).expect("send");
        out.send_with(|t| t.seq = 8).expect("send_with");
        // SAFETY: both fields are written
        unsafe {
            out.send_uninit(|t| {
                t.write(Tick { seq: 9, stamp_ns: 90 });
            })
        }
        .expect("send_uninit");
        let sample = typed_sub.receive().expect("receive").expect("a sample");
        assert_eq!((*sample.payload(), sample.user_header().seq), (Tick { seq: 7, stamp_ns: 70 }, 1));
        assert_eq!(sample.user_header().sender.as_str(), "a");
        let mut seen = Vec::new();
        raw.receive(|h, b| {
            seen.push((h.seq, b.to_vec()));
            true
        })
        .expect("raw receive");
        assert_eq!(seen.len(), 3);
        assert_eq!(seen[1].1, [8u64.to_ne_bytes(), 0u64.to_ne_bytes()].concat(), "send_with starts from the default");
        let mut got = Vec::new();
        assert_eq!(bytes_in.drain(|m, b| got.push((m.seq, b.len()))), 3);
        assert_eq!(got, [(1, 16), (2, 16), (3, 16)]);

        // an iceoryx2 typed publisher of the type, read by a typed input of this stack
        let service = robot.port_service("old", "tick");
        let publisher = crate::port::service::port_service::<Tick>(&node, &service)
            .expect("typed service")
            .publisher_builder()
            .create()
            .expect("publisher");
        let _ev = crate::port::service::port_event(&node, &service).expect("event");
        let (input, inner) = Input::<Tick>::new("in").expect("input");
        assert!(inner.connect(&node, &robot, "old", "tick").expect("a typed input opens it"));
        for seq in 1..=3 {
            let sample = publisher.loan_uninit().expect("loan");
            let mut sample = sample.write_payload(Tick { seq, stamp_ns: 100 - seq });
            *sample.user_header_mut() =
                shm_schemas::SampleHeader { sender: shm_schemas::FixedName::new("old"), seq, stamp_ns: 100 - seq };
            sample.send().expect("send");
        }
        assert_eq!(input.recv().map(|(m, t)| (m.seq, t.seq)), Some((1, 1)));
        let newest = input.latest().expect("the newest by stamp");
        assert_eq!((newest.0.seq, newest.1), (2, Tick { seq: 2, stamp_ns: 98 }));
        assert_eq!(inner.stats(crate::clock::now_ns())[0].received, 3);

        // a byte output, read in place by a typed input
        let service = robot.port_service("py", "tick");
        let mut by_layout = SchemaOutput::create(&node, &service, Tick::schema(), "py").expect("byte output");
        let (input, inner) = Input::<Tick>::new("in2").expect("input");
        assert!(inner.connect(&node, &robot, "py", "tick").expect("a typed input opens it"));
        by_layout.send_bytes(&[5u64.to_ne_bytes(), 50u64.to_ne_bytes()].concat()).expect("send");
        let mut seen = Vec::new();
        assert_eq!(input.drain(|m, t| seen.push((m.sender.as_str().to_owned(), *t))), 1);
        assert_eq!(seen, [("py".to_owned(), Tick { seq: 5, stamp_ns: 50 })]);
    }

    /// In a test, a typed port's samples are bytes like any other: the
    /// harness reads a typed output as bytes and feeds a typed input bytes.
    #[test]
    fn a_harness_carries_typed_samples_as_bytes_and_back() {
        use crate::testing::Harness;
        use crate::{Agent, AgentError, Context, Setup, Task};
        struct Echo {
            input: Input<Tick>,
            out: Output<Tick>,
        }
        impl Agent for Echo {
            const KIND: &'static str = "echo";
            fn task() -> Task {
                Task::EventDriven
            }
            fn new(setup: &mut Setup) -> Result<Self, AgentError> {
                Ok(Echo { input: setup.input("in")?, out: setup.output("out")? })
            }
            fn step(&mut self, _ctx: &mut Context) -> Result<(), AgentError> {
                self.input.try_drain(|_, t| self.out.send(Tick { seq: t.seq + 1, stamp_ns: t.stamp_ns }))?;
                Ok(())
            }
        }
        let mut h = Harness::<Echo>::new().expect("start");
        h.send_bytes_from("in", "py", &[41u64.to_ne_bytes(), 3u64.to_ne_bytes()].concat()).expect("bytes in");
        h.send("in", Tick { seq: 1, stamp_ns: 4 }).expect("a value in");
        h.step().expect("step");
        let out = h.output_bytes("out").expect("bytes out");
        assert_eq!(out.len(), 2);
        assert_eq!(out[0].1, [42u64.to_ne_bytes(), 3u64.to_ne_bytes()].concat());
        assert_eq!((out[1].0.seq, out[1].0.sender.as_str()), (2, "echo"));
        assert!(h.send_bytes_from("in", "py", &[0; 15]).is_err(), "15 bytes are no Tick");
        assert!(h.send("in", Scalar { value: 1.0, stamp_ns: 0 }).is_err(), "a Scalar is no Tick");
    }
}
