//! The in-memory binding of ports, beside the shared-memory one: what a
//! test's ports ([`crate::testing::Harness`], [`crate::testing::Wiring`])
//! are bound to instead of iceoryx2 services.
//!
//! A sample in memory is a [`SampleBuf`]: the payload's bytes in a buffer
//! of its own, aligned as the payload type is, so that a typed port reads
//! it in place as it reads a slot of shared memory. The [`Bus`] holds the
//! test's clock, which stamps the samples, and what every output sent
//! ([`Collected`]); an input's samples wait in a [`Queue`], which numbers
//! and overwrites them as an iceoryx2 subscription does.
//!
//! This module knows nothing of the ports themselves (`bytes`, `typed`):
//! they use it, never the other way round.

use super::error::PortError;
use super::service::{SUBSCRIBER_BUFFER, lock};
use shm_schemas::{FixedName, SampleHeader};
use std::alloc::Layout;
use std::collections::VecDeque;
use std::ptr::NonNull;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};

/// A payload's bytes in memory of their own, zeroed when made, aligned as
/// the payload's layout says.
pub(crate) struct SampleBuf {
    ptr: NonNull<u8>,
    layout: Layout,
}

// SAFETY: a SampleBuf owns its allocation alone (no alias is kept); it is
// plain bytes, so moving it to or sharing it with another thread is as
// safe as a Box<[u8]>.
unsafe impl Send for SampleBuf {}
// SAFETY: as above: `&SampleBuf` only reads the bytes.
unsafe impl Sync for SampleBuf {}

impl SampleBuf {
    /// `size` zero bytes aligned to `align` (a power of two: the layout of a
    /// port's payload, checked before any port is made).
    pub(crate) fn zeroed(service: &str, size: usize, align: usize) -> Result<Self, PortError> {
        let layout = Layout::from_size_align(size, align).map_err(|e| PortError::Ipc {
            service: service.into(),
            detail: format!("a {size}-byte sample aligned to {align}: {e}"),
        })?;
        Ok(Self::with_layout(layout))
    }

    /// Zero bytes of `layout`.
    fn with_layout(layout: Layout) -> Self {
        if layout.size() == 0 {
            // no allocation for a zero-sized payload: a dangling, aligned pointer
            let ptr =
                NonNull::new(std::ptr::without_provenance_mut::<u8>(layout.align())).unwrap_or(NonNull::dangling());
            return SampleBuf { ptr, layout };
        }
        // SAFETY: the layout's size is not zero (checked above)
        let raw = unsafe { std::alloc::alloc_zeroed(layout) };
        let Some(ptr) = NonNull::new(raw) else { std::alloc::handle_alloc_error(layout) };
        SampleBuf { ptr, layout }
    }

    /// A copy of `bytes`, aligned to `align`.
    pub(crate) fn copy_of(service: &str, bytes: &[u8], align: usize) -> Result<Self, PortError> {
        let mut buf = Self::zeroed(service, bytes.len(), align)?;
        buf.bytes_mut().copy_from_slice(bytes);
        Ok(buf)
    }

    /// The bytes.
    pub(crate) fn bytes(&self) -> &[u8] {
        // SAFETY: `ptr` is valid for `layout.size()` bytes, initialised
        // (zeroed when made) and owned by `self` (dangling only for 0 bytes)
        unsafe { std::slice::from_raw_parts(self.ptr.as_ptr(), self.layout.size()) }
    }

    /// The bytes, to write.
    pub(crate) fn bytes_mut(&mut self) -> &mut [u8] {
        // SAFETY: as in `bytes`, and `&mut self` is the only access
        unsafe { std::slice::from_raw_parts_mut(self.ptr.as_ptr(), self.layout.size()) }
    }

    /// The alignment the bytes start at.
    pub(crate) fn align(&self) -> usize {
        self.layout.align()
    }
}

impl Clone for SampleBuf {
    fn clone(&self) -> Self {
        let mut copy = SampleBuf::with_layout(self.layout);
        copy.bytes_mut().copy_from_slice(self.bytes());
        copy
    }
}

impl Drop for SampleBuf {
    fn drop(&mut self) {
        if self.layout.size() != 0 {
            // SAFETY: allocated in `zeroed` with this very layout
            unsafe { std::alloc::dealloc(self.ptr.as_ptr(), self.layout) };
        }
    }
}

impl std::fmt::Debug for SampleBuf {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SampleBuf").field("len", &self.layout.size()).field("align", &self.layout.align()).finish()
    }
}

/// The samples one output sent in a test, in order, with their headers.
#[derive(Debug)]
pub(crate) struct Collected {
    samples: Mutex<Vec<(SampleHeader, SampleBuf)>>,
    /// the harness's clock, which stamps them
    clock: Arc<AtomicU64>,
}

impl Collected {
    /// Takes every sample sent since the last call.
    pub(crate) fn take(&self) -> Vec<(SampleHeader, SampleBuf)> {
        std::mem::take(&mut *lock(&self.samples))
    }

    /// Keeps `sample`, sent by `sender` as its `seq`th, stamped by the test's clock.
    pub(crate) fn push(&self, sender: FixedName, seq: u64, sample: SampleBuf) {
        let header = SampleHeader { sender, seq, stamp_ns: self.clock.load(Ordering::Acquire) };
        lock(&self.samples).push((header, sample));
    }
}

/// One output of a test's agent, as the harness sees it.
struct Collector {
    port: String,
    type_name: String,
    /// the layout fingerprint of a typed port (`None`: declared by layout)
    fingerprint: Option<u64>,
    samples: Arc<Collected>,
}

/// The in-memory side of a test's ports: the clock that stamps samples and
/// the outputs' collected samples, by port.
#[derive(Debug)]
pub(crate) struct Bus {
    clock: Arc<AtomicU64>,
    outputs: Mutex<Vec<Collector>>,
}

impl std::fmt::Debug for Collector {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Collector").field("port", &self.port).field("type", &self.type_name).finish()
    }
}

impl Bus {
    /// A bus whose clock reads `now_ns`, with no output yet.
    pub(crate) fn new(now_ns: u64) -> Self {
        Bus { clock: Arc::new(AtomicU64::new(now_ns)), outputs: Mutex::new(Vec::new()) }
    }

    /// Sets the test's clock.
    pub(crate) fn set_now(&self, now_ns: u64) {
        self.clock.store(now_ns, Ordering::Release);
    }

    /// The test's clock.
    pub(crate) fn now_ns(&self) -> u64 {
        self.clock.load(Ordering::Acquire)
    }

    /// A new output `port` carrying `type_name`: where its samples go.
    pub(crate) fn add_output(&self, port: &str, type_name: &str, fingerprint: Option<u64>) -> Arc<Collected> {
        let samples = Arc::new(Collected { samples: Mutex::new(Vec::new()), clock: self.clock.clone() });
        lock(&self.outputs).push(Collector {
            port: port.into(),
            type_name: type_name.into(),
            fingerprint,
            samples: samples.clone(),
        });
        samples
    }

    /// Every output's port name, type name and fingerprint (`None`: declared by layout).
    pub(crate) fn outputs(&self) -> Vec<(String, String, Option<u64>)> {
        lock(&self.outputs).iter().map(|c| (c.port.clone(), c.type_name.clone(), c.fingerprint)).collect()
    }

    /// Output `port`'s type name and collected samples; `Err` lists the outputs there are.
    pub(crate) fn output(&self, port: &str) -> Result<(String, Arc<Collected>), Vec<String>> {
        let outputs = lock(&self.outputs);
        match outputs.iter().find(|c| c.port == port) {
            Some(c) => Ok((c.type_name.clone(), c.samples.clone())),
            None => Err(outputs.iter().map(|c| c.port.clone()).collect()),
        }
    }
}

/// The samples a test queued on one source of an input: at most
/// [`SUBSCRIBER_BUFFER`] (the oldest is overwritten past it, as iceoryx2
/// does), and how many were queued in all (the sender's sequence number).
#[derive(Debug, Default)]
pub(crate) struct Queue {
    samples: VecDeque<(SampleHeader, SampleBuf)>,
    sent: u64,
}

impl Queue {
    /// Queues `sample` from `sender`, stamped `stamp_ns`, numbered as a
    /// sender numbers its samples, so that an overwritten one shows as a
    /// gap and is counted as dropped.
    pub(crate) fn push(&mut self, sender: &str, sample: SampleBuf, stamp_ns: u64) {
        self.sent = self.sent.saturating_add(1);
        if self.samples.len() >= SUBSCRIBER_BUFFER {
            self.samples.pop_front();
        }
        self.samples.push_back((SampleHeader { sender: FixedName::new(sender), seq: self.sent, stamp_ns }, sample));
    }

    /// The oldest waiting sample.
    pub(crate) fn pop(&mut self) -> Option<(SampleHeader, SampleBuf)> {
        self.samples.pop_front()
    }

    /// Whether none waits.
    pub(crate) fn is_empty(&self) -> bool {
        self.samples.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::SampleBuf;

    #[test]
    fn a_sample_buffer_is_zeroed_aligned_and_copied_whole() {
        for align in [1, 2, 8, 64, 4096] {
            let mut b = SampleBuf::zeroed("t", 24, align).expect("buffer");
            assert_eq!(b.bytes().as_ptr() as usize % align, 0, "aligned to {align}");
            assert!(b.bytes().iter().all(|x| *x == 0));
            b.bytes_mut()[23] = 7;
            let c = b.clone();
            assert_eq!((c.bytes()[23], c.align()), (7, align));
        }
        let empty = SampleBuf::zeroed("t", 0, 8).expect("empty");
        assert!(empty.bytes().is_empty());
        assert!(SampleBuf::zeroed("t", 8, 3).is_err(), "an alignment that is not a power of two");
    }
}
