//! Operating-system plumbing shared by writer and reader: the memory mapping
//! of a ring file, typed views of its header and slots, the copy of bytes
//! another process may be writing, clocks, and the "is the writer still
//! alive" check.
//!
//! # Reading memory another process writes
//!
//! Rust's memory model makes a plain read that races with a write undefined
//! behaviour, even if the value read is thrown away afterwards, and a
//! `&[u8]` or `&T` over such bytes lets the compiler assume they do not
//! change. So a reader never makes a reference to bytes a writer may store
//! to concurrently, except to atomics: the ring header's mutable fields are
//! reached one by one ([`Mapping::header_atomics`]), its fixed fields are
//! copied once with a volatile read ([`Mapping::header_copy`]), and payload
//! bytes are copied out with volatile loads ([`copy_volatile`]) before
//! anyone looks at them, as crossbeam's seqlock (`AtomicCell`) does. The
//! copy may be torn; the seqlock tells afterwards whether it is.

use nix::errno::Errno;
use nix::sys::mman::{MapFlags, ProtFlags, mmap, munmap};
use shm_schemas::ring::{RingHeader, SlotHeader};
use std::fs::File;
use std::num::NonZeroUsize;
use std::ptr::NonNull;
use std::sync::atomic::{AtomicU32, AtomicU64};

/// A `MAP_SHARED` mapping of a whole ring file, unmapped on drop.
///
/// All access to the shared bytes goes through the typed views below: the
/// headers are made of atomics (or of fields written once before the magic
/// was published), and payload bytes are only touched under the seqlock
/// protocol of `writer.rs` / `reader.rs`.
#[derive(Debug)]
pub(crate) struct Mapping {
    ptr: NonNull<u8>,
    len: usize,
}

// SAFETY: the mapping is plain memory shared with other processes; every
// concurrent access to it is through atomics or seqlock-validated reads, and
// the writer's mutable access is serialised by `&mut RingWriter`.
unsafe impl Send for Mapping {}
// SAFETY: see `Send`; `&Mapping` only gives out shared views.
unsafe impl Sync for Mapping {}

impl Mapping {
    /// Maps `len` bytes of `file` from offset 0, read-only or read-write.
    pub(crate) fn new(file: &File, len: usize, writable: bool) -> Result<Self, Errno> {
        let length = NonZeroUsize::new(len).ok_or(Errno::EINVAL)?;
        let prot = if writable { ProtFlags::PROT_READ | ProtFlags::PROT_WRITE } else { ProtFlags::PROT_READ };
        // SAFETY: a fresh mapping chosen by the kernel (addr None) aliases no
        // Rust object; its lifetime is tied to `Mapping` and ends in `drop`.
        let ptr = unsafe { mmap(None, length, prot, MapFlags::MAP_SHARED, file, 0) }?;
        Ok(Mapping { ptr: ptr.cast(), len })
    }

    pub(crate) fn len(&self) -> usize {
        self.len
    }

    pub(crate) fn base(&self) -> *mut u8 {
        self.ptr.as_ptr()
    }

    /// The mutable (atomic) fields of the ring header, each reached through
    /// a raw pointer, without a reference to the header's other fields.
    pub(crate) fn header_atomics(&self) -> HeaderAtomics<'_> {
        let h = self.ptr.as_ptr() as *const RingHeader;
        // SAFETY: the mapping is page-aligned and at least RING_HEADER_SIZE
        // long (checked before any mapping is made); `&(*h).field` borrows
        // only that field, not the whole header, and each is an atomic, which
        // other processes only store to atomically.
        unsafe {
            HeaderAtomics {
                magic: &(*h).magic,
                writer_pid: &(*h).writer_pid,
                last_seq: &(*h).last_seq,
                writer_generation: &(*h).writer_generation,
            }
        }
    }

    /// A copy of the ring header, read with one volatile read: the fixed
    /// fields (geometry, name) as they were when read. Read it after the
    /// magic number was seen (acquire), and check it before use: the file
    /// may be damaged or hostile.
    pub(crate) fn header_copy(&self) -> RingHeader {
        // SAFETY: in bounds and aligned as in `header_atomics`; RingHeader is
        // plain old data (integers, atomics, a byte array) valid for any bit
        // pattern, and a volatile read never assumes the bytes stay put.
        unsafe { std::ptr::read_volatile(self.ptr.as_ptr() as *const RingHeader) }
    }

    /// The ring header at offset 0. For the writer, whose ring it is;
    /// readers use [`Mapping::header_atomics`] and [`Mapping::header_copy`].
    pub(crate) fn header(&self) -> &RingHeader {
        // SAFETY: the mapping is page-aligned and at least RING_HEADER_SIZE
        // long (checked by every constructor's caller before use); the
        // mutable fields are atomics, so a shared reference is sound while
        // another process updates them.
        unsafe { &*(self.ptr.as_ptr() as *const RingHeader) }
    }
}

impl Drop for Mapping {
    fn drop(&mut self) {
        // SAFETY: ptr/len are exactly what mmap returned; no reference into
        // the mapping outlives `self` (all views borrow from it).
        if let Err(e) = unsafe { munmap(self.ptr.cast(), self.len) } {
            tracing::warn!("munmap of a ring failed: {e}");
        }
    }
}

/// The atomic fields of a mapped ring header (see [`Mapping::header_atomics`]).
#[derive(Debug, Clone, Copy)]
pub(crate) struct HeaderAtomics<'a> {
    pub(crate) magic: &'a AtomicU64,
    pub(crate) writer_pid: &'a AtomicU32,
    pub(crate) last_seq: &'a AtomicU64,
    pub(crate) writer_generation: &'a AtomicU64,
}

/// Copies `len` bytes from `src`, which another process may be writing at
/// this moment, to `dst`, with volatile loads (16-byte SSE2 loads on x86_64,
/// 8-byte loads elsewhere, single bytes at the unaligned ends): the compiler
/// neither assumes the source stays put nor reads it twice. The copy may be
/// torn; validate it with the seqlock before trusting it.
///
/// # Safety
/// `src` must be valid for reads and `dst` for writes of `len` bytes, and
/// they must not overlap.
pub(crate) unsafe fn copy_volatile(src: *const u8, dst: *mut u8, len: usize) {
    #[cfg(target_arch = "x86_64")]
    type Word = std::arch::x86_64::__m128i;
    #[cfg(not(target_arch = "x86_64"))]
    type Word = u64;
    const W: usize = std::mem::size_of::<Word>();
    let mut i = 0;
    // SAFETY: (the whole body) every offset read or written is below `len`,
    // as the caller guarantees to be valid; word loads are aligned (the head
    // loop stops at an aligned source address) and stores are unaligned.
    unsafe {
        let head = src.align_offset(W).min(len);
        while i < head {
            dst.add(i).write(std::ptr::read_volatile(src.add(i)));
            i += 1;
        }
        // four words per round, so the loads can overlap
        while i + 4 * W <= len {
            let s = src.add(i) as *const Word;
            let (a, b, c, d) = (
                std::ptr::read_volatile(s),
                std::ptr::read_volatile(s.add(1)),
                std::ptr::read_volatile(s.add(2)),
                std::ptr::read_volatile(s.add(3)),
            );
            let t = dst.add(i) as *mut Word;
            t.write_unaligned(a);
            t.add(1).write_unaligned(b);
            t.add(2).write_unaligned(c);
            t.add(3).write_unaligned(d);
            i += 4 * W;
        }
        while i + W <= len {
            (dst.add(i) as *mut Word).write_unaligned(std::ptr::read_volatile(src.add(i) as *const Word));
            i += W;
        }
        while i < len {
            dst.add(i).write(std::ptr::read_volatile(src.add(i)));
            i += 1;
        }
    }
}

/// Largest ring header a reader accepts (this layout writes
/// [`shm_schemas::ring::RING_HEADER_SIZE`]).
pub(crate) const MAX_HEADER_SIZE: u64 = 1 << 16;

/// The geometry of a ring, as read from (or written to) its header, checked
/// against the size of the mapping so that slot views stay in bounds.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Geometry {
    pub(crate) header_size: u64,
    pub(crate) slot_count: u32,
    pub(crate) slot_capacity: u64,
    pub(crate) slot_stride: u64,
}

impl Geometry {
    /// The geometry of a new ring; `None` on arithmetic overflow.
    pub(crate) fn new(slot_count: u32, slot_capacity: u64) -> Option<Self> {
        use shm_schemas::ring::{RING_HEADER_SIZE, SLOT_ALIGN, SLOT_HEADER_SIZE};
        let padded = slot_capacity.checked_add(SLOT_ALIGN - 1)? / SLOT_ALIGN * SLOT_ALIGN;
        let slot_stride = padded.checked_add(u64::from(SLOT_HEADER_SIZE))?;
        let g = Geometry { header_size: u64::from(RING_HEADER_SIZE), slot_count, slot_capacity, slot_stride };
        g.file_len()?;
        Some(g)
    }

    /// Total bytes of the file; `None` on overflow or beyond `isize::MAX`.
    pub(crate) fn file_len(&self) -> Option<u64> {
        let len = self.slot_stride.checked_mul(u64::from(self.slot_count))?.checked_add(self.header_size)?;
        (len <= isize::MAX as u64).then_some(len)
    }

    /// The geometry stored in a header, if it is self-consistent and fits in
    /// `mapped` bytes.
    pub(crate) fn from_header(h: &RingHeader, mapped: usize) -> Option<Self> {
        use crate::writer::{MAX_SLOT_CAPACITY, MAX_SLOTS};
        use shm_schemas::ring::{SLOT_ALIGN, SLOT_HEADER_SIZE};
        let g = Geometry {
            header_size: u64::from(h.header_size),
            slot_count: h.slot_count,
            slot_capacity: h.slot_capacity,
            slot_stride: h.slot_stride,
        };
        // Every size is bounded before it is used: the header may come from a
        // corrupt or hostile file, and readers size allocations and scans by
        // it (`stamps()` walks every slot).
        let ok = h.slot_header_size == SLOT_HEADER_SIZE
            && g.header_size >= std::mem::size_of::<RingHeader>() as u64
            && g.header_size <= MAX_HEADER_SIZE
            && g.header_size.is_multiple_of(SLOT_ALIGN)
            && g.slot_count >= 1
            && g.slot_count <= MAX_SLOTS
            && g.slot_capacity <= MAX_SLOT_CAPACITY
            && g.slot_stride <= MAX_SLOT_CAPACITY + SLOT_ALIGN + u64::from(SLOT_HEADER_SIZE)
            && g.slot_stride.is_multiple_of(SLOT_ALIGN)
            && g.slot_stride >= g.slot_capacity.checked_add(u64::from(SLOT_HEADER_SIZE))?
            && g.file_len()? <= mapped as u64;
        ok.then_some(g)
    }

    /// The slot of frame `seq`.
    pub(crate) fn slot_of(&self, seq: u64) -> u32 {
        (seq % u64::from(self.slot_count)) as u32
    }
}

/// The slot header of slot `i`.
///
/// # Safety
/// `geo` must have been validated against `map` (`Geometry::from_header` or
/// the writer's own sizing) and `i < geo.slot_count`.
pub(crate) unsafe fn slot_header<'a>(map: &'a Mapping, geo: &Geometry, i: u32) -> &'a SlotHeader {
    let off = geo.header_size + u64::from(i) * geo.slot_stride;
    // SAFETY: in bounds by the caller's contract; 64-byte aligned because the
    // mapping is page-aligned and header_size and slot_stride are multiples of
    // 64; all fields are atomics, so shared references are sound while other
    // processes store to them.
    unsafe { &*(map.base().add(off as usize) as *const SlotHeader) }
}

/// A pointer to the payload of slot `i` (`geo.slot_capacity` bytes).
///
/// # Safety
/// As for [`slot_header`].
pub(crate) unsafe fn slot_payload(map: &Mapping, geo: &Geometry, i: u32) -> *mut u8 {
    let off = geo.header_size + u64::from(i) * geo.slot_stride + u64::from(shm_schemas::ring::SLOT_HEADER_SIZE);
    // SAFETY: in bounds by the caller's contract.
    unsafe { map.base().add(off as usize) }
}

/// CLOCK_MONOTONIC now, in nanoseconds: the clock every nerve stamp uses.
pub fn monotonic_ns() -> u64 {
    clock_ns(nix::time::ClockId::CLOCK_MONOTONIC)
}

/// CLOCK_REALTIME now, in nanoseconds.
pub(crate) fn realtime_ns() -> u64 {
    clock_ns(nix::time::ClockId::CLOCK_REALTIME)
}

fn clock_ns(id: nix::time::ClockId) -> u64 {
    match nix::time::clock_gettime(id) {
        Ok(ts) => (ts.tv_sec() as u64).saturating_mul(1_000_000_000).saturating_add(ts.tv_nsec() as u64),
        // clock_gettime cannot fail for these clocks on Linux
        Err(_) => 0,
    }
}

/// Whether process `pid` exists and is not a zombie. Pid 0 (no writer) is
/// not alive. A pid reused by an unrelated process reads as alive: the
/// callers only use this to choose between "being written" and "will never
/// be complete", and err on the side of "being written".
pub(crate) fn pid_alive(pid: u32) -> bool {
    if pid == 0 || pid > i32::MAX as u32 {
        return false;
    }
    match nix::sys::signal::kill(nix::unistd::Pid::from_raw(pid as i32), None) {
        Ok(()) | Err(Errno::EPERM) => {}
        Err(_) => return false,
    }
    // A killed process that its parent has not reaped yet still answers
    // kill(0); /proc tells a zombie apart (state after the ")" of the name).
    match std::fs::read_to_string(format!("/proc/{pid}/stat")) {
        Ok(stat) => {
            let state = stat.rfind(')').and_then(|i| stat[i + 1..].split_whitespace().next());
            !matches!(state, Some("Z" | "X" | "x"))
        }
        Err(_) => true,
    }
}

/// This process's pid.
pub(crate) fn my_pid() -> u32 {
    std::process::id()
}

#[cfg(test)]
mod tests {
    use super::{Geometry, MAX_HEADER_SIZE};
    use crate::name::RingName;
    use crate::writer::{MAX_SLOT_CAPACITY, MAX_SLOTS};
    use shm_schemas::ring::{RING_HEADER_SIZE, RING_LAYOUT_VERSION, RingHeader, SLOT_HEADER_SIZE};
    use std::sync::atomic::{AtomicU32, AtomicU64};

    /// A header as a writer of `g` stores it.
    fn header(g: &Geometry) -> RingHeader {
        RingHeader {
            magic: AtomicU64::new(0),
            layout_version: RING_LAYOUT_VERSION,
            header_size: g.header_size as u32,
            slot_count: g.slot_count,
            slot_header_size: SLOT_HEADER_SIZE,
            slot_capacity: g.slot_capacity,
            slot_stride: g.slot_stride,
            name: RingName::parse("t").expect("name").to_fixed(),
            name_kind: 0,
            name_id: 0,
            created_realtime_ns: 0,
            created_monotonic_ns: 0,
            writer_pid: AtomicU32::new(0),
            reserved0: 0,
            last_seq: AtomicU64::new(0),
            writer_generation: AtomicU64::new(0),
            creation_id: 1,
            reserved: [0; 15],
        }
    }

    #[test]
    fn volatile_copies_are_exact_at_every_alignment_and_length() {
        let src: Vec<u8> = (0..300u32).map(|i| (i * 7 + 3) as u8).collect();
        for start in 0..20 {
            for len in [0, 1, 7, 15, 16, 17, 63, 64, 65, 129, 200, 280] {
                let mut dst = vec![0xAAu8; len + 2];
                // SAFETY: start + len <= 300 and dst has len + 2 bytes.
                unsafe { super::copy_volatile(src.as_ptr().add(start), dst.as_mut_ptr().add(1), len) };
                assert_eq!(&dst[1..=len], &src[start..start + len], "start {start}, len {len}");
                assert_eq!((dst[0], dst[len + 1]), (0xAA, 0xAA), "wrote outside: start {start}, len {len}");
            }
        }
    }

    /// A mapping "large enough" for any header: only the bounds can refuse.
    const HUGE: usize = isize::MAX as usize;

    #[test]
    fn header_sizes_are_bounded_before_use() {
        let ok = Geometry::new(4, 100).expect("geometry");
        assert!(Geometry::from_header(&header(&ok), HUGE).is_some());
        let max = Geometry::new(MAX_SLOTS, MAX_SLOT_CAPACITY).expect("largest geometry");
        assert!(Geometry::from_header(&header(&max), HUGE).is_some(), "the largest ring a writer makes is readable");

        // a hostile header declaring 2^32-1 slots in a sparse file
        let many = Geometry::new(u32::MAX, 1).expect("geometry");
        assert!(Geometry::from_header(&header(&many), HUGE).is_none(), "slot_count is capped at MAX_SLOTS");
        let one_more = Geometry::new(MAX_SLOTS + 1, 1).expect("geometry");
        assert!(Geometry::from_header(&header(&one_more), HUGE).is_none());

        // absurd slot capacity (and a stride to match)
        let big = Geometry::new(2, MAX_SLOT_CAPACITY + 1).expect("geometry");
        assert!(Geometry::from_header(&header(&big), HUGE).is_none(), "slot_capacity is capped");
        let big = Geometry::new(2, 1 << 50).expect("geometry");
        assert!(Geometry::from_header(&header(&big), HUGE).is_none());

        // a stride far beyond what the capacity needs
        let mut wide = header(&ok);
        wide.slot_stride = 1 << 50;
        assert!(Geometry::from_header(&wide, HUGE).is_none(), "slot_stride is capped");

        // a header size far beyond the layout's
        let mut tall = header(&ok);
        tall.header_size = (MAX_HEADER_SIZE + 64) as u32;
        assert!(Geometry::from_header(&tall, HUGE).is_none(), "header_size is capped");
        assert!(u64::from(RING_HEADER_SIZE) <= MAX_HEADER_SIZE);
    }
}
