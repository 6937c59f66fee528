//! Readers of a ring: map it once, read frames in place or by copy, never
//! block the writer, never return a torn frame.
//!
//! # Reader side of the seqlock
//!
//! To read frame `seq` from slot `seq % slots`:
//!
//! 1. `l1 = lock.load(Relaxed); fence(Acquire)` — if `l1 != 2*seq` the slot
//!    does not hold a complete frame `seq`: it holds an older one (not yet
//!    written), a newer one (overwritten), or frame `seq` half-written
//!    (being written now, or left so by a dead writer). The acquire fence
//!    pairs with the writer's release store of `2*seq`, so everything the
//!    writer stored for frame `seq` is visible below;
//! 2. read the slot header fields and the payload (speculatively: the writer
//!    may start overwriting at any moment);
//! 3. `fence(Acquire); l2 = lock.load(Relaxed)` — the acquire fence pairs with
//!    the writer's release fence after its odd store: if step 2 observed any
//!    byte of a newer frame, `l2` is that newer odd (or even) value. So
//!    `l2 == l1` proves that step 2 read frame `seq` untouched.
//!
//! Loads are `Relaxed` followed by an acquire fence rather than `Acquire`
//! loads because the reader's mapping is read-only, and the standard library
//! guarantees only small relaxed atomic loads on read-only memory.
//!
//! Step 2 never makes a `&[u8]` or a reference to non-atomic header fields
//! over the shared bytes: that would be a data race in Rust's memory model
//! (the compiler may assume the bytes do not change). Slot headers are
//! atomics; the payload is copied out with volatile loads
//! ([`crate::sys::copy_volatile`]) into the caller's buffer or, for the
//! in-place reads (`read_with`, `latest_with`, `nearest_with`), into a
//! buffer of the calling thread that is reused from read to read. The
//! closure sees that private copy; the seqlock still decides whether the
//! copy is frame `seq` intact.
//!
//! Readers keep no state in shared memory: the cost of a read is the same for
//! one reader or fifty, and a reader that dies leaves nothing behind.

use crate::RingOptions;
use crate::error::{OpenError, ReadError};
use crate::name::RingName;
use crate::sys::{Geometry, Mapping, copy_volatile, pid_alive, slot_header, slot_payload};
use crate::writer::{MAX_SLOT_CAPACITY, MAX_SLOTS};
use serde::Serialize;
use shm_schemas::RobotName;
use shm_schemas::ring::{PixelFormat, RING_HEADER_SIZE, RING_LAYOUT_VERSION, RING_MAGIC, RingNotice};
use std::cell::Cell;
use std::fs::{File, OpenOptions};
use std::os::unix::fs::{MetadataExt, OpenOptionsExt};
use std::path::{Path, PathBuf};
use std::sync::atomic::{Ordering, fence};

thread_local! {
    /// The private copy the in-place reads hand to their closure, kept from
    /// read to read (it grows to the largest frame this thread has read).
    /// Taken out while a closure runs, so a nested read gets a fresh one.
    static SCRATCH: Cell<Vec<u8>> = const { Cell::new(Vec::new()) };
}

/// How often a read of "the latest" or "the nearest" frame is retried when
/// the writer overwrote the chosen frame meanwhile (only a ring with very few
/// slots and a very fast writer gets there).
const RETRIES: usize = 4;

/// What a reader learns about a stored frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct FrameMeta {
    /// Sequence number, from 1.
    pub seq: u64,
    /// The slot that holds it.
    pub slot: u32,
    /// CLOCK_MONOTONIC nanoseconds stamped on the frame.
    pub stamp_ns: u64,
    /// Payload bytes.
    pub len: usize,
    /// Image width in pixels (0 for raw data).
    pub width: u32,
    /// Image height in pixels (0 for raw data).
    pub height: u32,
    /// The stored [`PixelFormat`] code; see [`FrameMeta::format`].
    pub format_code: u32,
}

impl FrameMeta {
    /// The pixel format, `None` if this build does not know the code.
    pub fn format(&self) -> Option<PixelFormat> {
        PixelFormat::from_code(self.format_code)
    }
}

/// A copied frame.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Frame {
    /// Its description.
    pub meta: FrameMeta,
    /// Its bytes.
    pub data: Vec<u8>,
}

/// Refuses a ring file that another user owns or that group or others may
/// write: whoever can write it can feed readers fake frames (a fake target
/// for the tracker) or truncate it under them.
pub(crate) fn check_trusted(meta: &std::fs::Metadata, euid: u32, path: &Path) -> Result<(), OpenError> {
    let mode = meta.mode() & 0o7777;
    if meta.uid() != euid || mode & 0o022 != 0 {
        return Err(OpenError::Untrusted { path: path.to_owned(), owner: meta.uid(), mode, me: euid });
    }
    Ok(())
}

/// A read-only view of a ring, mapped once. `Send + Sync`: one reader may
/// serve several threads.
#[derive(Debug)]
pub struct RingReader {
    map: Mapping,
    geo: Geometry,
    name: RingName,
    path: PathBuf,
    dev_ino: (u64, u64),
    creation_id: u64,
}

impl RingReader {
    /// Opens ring `name` of `robot` in `/dev/shm`.
    pub fn open(robot: &RobotName, name: &RingName) -> Result<Self, OpenError> {
        Self::open_with(&RingOptions::default(), robot, name)
    }

    /// [`RingReader::open`] with options (base directory).
    pub fn open_with(opts: &RingOptions, robot: &RobotName, name: &RingName) -> Result<Self, OpenError> {
        let path = name.path_in(&opts.base_dir, robot);
        match Self::open_path(&path) {
            Err(OpenError::NotFound { path, .. }) => Err(OpenError::NotFound { ring: name.to_string(), path }),
            other => other,
        }
    }

    /// Opens the ring stored in file `path`.
    pub fn open_path(path: &Path) -> Result<Self, OpenError> {
        let file =
            OpenOptions::new().read(true).custom_flags(libc::O_NOFOLLOW | libc::O_CLOEXEC).open(path).map_err(|e| {
                match e.kind() {
                    std::io::ErrorKind::NotFound => OpenError::NotFound {
                        ring: path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default(),
                        path: path.to_owned(),
                    },
                    std::io::ErrorKind::PermissionDenied => OpenError::PermissionDenied { path: path.to_owned() },
                    _ => OpenError::Os { what: "cannot open", path: path.to_owned(), source: e },
                }
            })?;
        Self::from_file(&file, path)
    }

    fn from_file(file: &File, path: &Path) -> Result<Self, OpenError> {
        let not_a_ring =
            |why: &str| OpenError::NotARing { path: path.to_owned(), expected: RING_LAYOUT_VERSION, why: why.into() };
        let meta =
            file.metadata().map_err(|e| OpenError::Os { what: "cannot stat", path: path.to_owned(), source: e })?;
        if !meta.file_type().is_file() {
            return Err(not_a_ring("not a regular file"));
        }
        check_trusted(&meta, nix::unistd::geteuid().as_raw(), path)?;
        if meta.len() < u64::from(RING_HEADER_SIZE) {
            return Err(OpenError::NotReady { path: path.to_owned() });
        }
        // A writer reserves every page of its ring up front, so a ring is
        // never larger than its file system: a larger file is a sparse one
        // that no writer made, and mapping it would only serve to fault in
        // pages that tmpfs cannot supply.
        if let Ok(vfs) = nix::sys::statvfs::fstatvfs(file) {
            let fs_bytes = vfs.blocks().saturating_mul(vfs.fragment_size());
            if fs_bytes > 0 && meta.len() > fs_bytes {
                return Err(not_a_ring(&format!(
                    "the file has {} bytes, more than its whole file system ({fs_bytes} bytes): a sparse file no ring writer made",
                    meta.len()
                )));
            }
        }
        let len = usize::try_from(meta.len()).map_err(|_| not_a_ring("file too large"))?;
        let map = Mapping::new(file, len, false).map_err(|e| OpenError::Os {
            what: "cannot map",
            path: path.to_owned(),
            source: e.into(),
        })?;
        let magic = map.header_atomics().magic.load(Ordering::Relaxed);
        // pairs with the creator's release store of the magic: the other
        // header fields, copied below, are complete
        fence(Ordering::Acquire);
        if magic == 0 {
            return Err(OpenError::NotReady { path: path.to_owned() });
        }
        if magic != RING_MAGIC {
            return Err(not_a_ring("unknown magic number"));
        }
        // the fixed fields, read once: never a reference into the mapping
        let h = map.header_copy();
        if h.layout_version != RING_LAYOUT_VERSION {
            return Err(not_a_ring(&format!("it has layout version {}", h.layout_version)));
        }
        let geo = Geometry::from_header(&h, map.len()).ok_or_else(|| {
            not_a_ring(&format!(
                "its header ({} slots of {} bytes, stride {}, header {} bytes) contradicts its size of {} bytes or exceeds the limits ({MAX_SLOTS} slots of {MAX_SLOT_CAPACITY} bytes)",
                h.slot_count, h.slot_capacity, h.slot_stride, h.header_size, map.len()
            ))
        })?;
        let name = RingName::parse(h.name.as_str()).map_err(|e| not_a_ring(&format!("bad name in header: {e}")))?;
        tracing::debug!(ring = %name, path = %path.display(), slots = geo.slot_count, "ring opened for reading");
        Ok(RingReader {
            map,
            geo,
            name,
            path: path.to_owned(),
            dev_ino: (meta.dev(), meta.ino()),
            creation_id: h.creation_id,
        })
    }

    /// The ring's name.
    pub fn name(&self) -> &RingName {
        &self.name
    }

    /// The ring's file.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Number of slots (frames kept).
    pub fn slot_count(&self) -> u32 {
        self.geo.slot_count
    }

    /// Largest frame, in bytes.
    pub fn slot_capacity(&self) -> usize {
        self.geo.slot_capacity as usize
    }

    /// The last complete frame's sequence number, `None` while empty.
    pub fn last_seq(&self) -> Option<u64> {
        let last = self.map.header_atomics().last_seq.load(Ordering::Relaxed);
        fence(Ordering::Acquire);
        Some(last).filter(|s| *s > 0)
    }

    /// The oldest and newest frame the ring may still hold, `None` while
    /// empty. The oldest may be overwritten at any moment.
    pub fn seq_range(&self) -> Option<(u64, u64)> {
        let last = self.last_seq()?;
        let oldest = last.saturating_sub(u64::from(self.geo.slot_count) - 1).max(1);
        Some((oldest, last))
    }

    /// The pid of the current writer, `None` if it closed the ring.
    pub fn writer_pid(&self) -> Option<u32> {
        Some(self.map.header_atomics().writer_pid.load(Ordering::Relaxed)).filter(|p| *p != 0)
    }

    /// Whether the recorded writer process is alive.
    pub fn writer_alive(&self) -> bool {
        self.writer_pid().is_some_and(pid_alive)
    }

    /// How many times a writer opened this ring; changes when the writer restarts.
    pub fn writer_generation(&self) -> u64 {
        self.map.header_atomics().writer_generation.load(Ordering::Relaxed)
    }

    /// The random number drawn when this ring file was created; a notice
    /// names a frame of this file only if it carries the same number.
    pub fn creation_id(&self) -> u64 {
        self.creation_id
    }

    /// Whether `notice` names a frame of the ring file this reader maps.
    /// Sequence numbers start at 1 again in a replaced ring (another
    /// geometry), so frame `seq` of another file is another frame: reading
    /// it here would hand out an unrelated frame as if it were the one
    /// announced. `Err(OtherRing)` then: open the ring again and check once
    /// more ([`RingReader::is_stale`] says whether the file changed).
    pub fn check_notice(&self, notice: &RingNotice) -> Result<(), ReadError> {
        if notice.creation_id == self.creation_id {
            Ok(())
        } else {
            Err(ReadError::OtherRing {
                ring: self.name.to_string(),
                seq: notice.seq,
                notice_creation_id: notice.creation_id,
                creation_id: self.creation_id,
            })
        }
    }

    /// Whether the ring file was removed or replaced since this reader
    /// opened it (then open it again to see new frames).
    pub fn is_stale(&self) -> bool {
        match std::fs::symlink_metadata(&self.path) {
            Ok(m) => (m.dev(), m.ino()) != self.dev_ino,
            Err(_) => true,
        }
    }

    /// Reads frame `seq` without an allocation: `f` gets its description
    /// and a copy of its bytes in a buffer of the calling thread, reused
    /// from read to read (see the module doc for why not the shared bytes
    /// themselves).
    ///
    /// **The copy is speculative while `f` runs**: the writer may have been
    /// overwriting the slot while it was copied (it is never blocked by
    /// readers). Only after `read_with` returned `Ok` is it known that `f`
    /// saw frame `seq` intact; on `Err(Overwritten { during_read: true, .. })`
    /// whatever `f` computed must be discarded. So `f` should compute (a
    /// checksum, a detection) and not act, and it must not panic on odd
    /// content. The copy does not change while `f` runs.
    pub fn read_with<R>(&self, seq: u64, f: impl FnOnce(&FrameMeta, &[u8]) -> R) -> Result<R, ReadError> {
        SCRATCH.with(|scratch| {
            let mut buf = scratch.take();
            let r = self.with_frame(seq, |meta, ptr| {
                copy_frame(ptr, meta.len, &mut buf);
                f(meta, &buf)
            });
            scratch.set(buf);
            r
        })
    }

    /// Copies frame `seq` into `buf` (replacing its content) and returns its
    /// description. On error `buf` is left empty.
    pub fn read_into(&self, seq: u64, buf: &mut Vec<u8>) -> Result<FrameMeta, ReadError> {
        buf.clear();
        let r = self.with_frame(seq, |meta, ptr| {
            copy_frame(ptr, meta.len, buf);
            *meta
        });
        if r.is_err() {
            buf.clear();
        }
        r
    }

    /// Copies frame `seq`.
    pub fn read(&self, seq: u64) -> Result<Frame, ReadError> {
        let mut data = Vec::new();
        let meta = self.read_into(seq, &mut data)?;
        Ok(Frame { meta, data })
    }

    /// The description of frame `seq` (validated like a read).
    pub fn meta(&self, seq: u64) -> Result<FrameMeta, ReadError> {
        self.with_frame(seq, |meta, _| *meta)
    }

    /// Reads the latest frame without an allocation (see
    /// [`RingReader::read_with`] for what `f` gets and may do). `f` is called again if the frame was overwritten
    /// while it ran (a newer one is then the latest).
    pub fn latest_with<R>(&self, mut f: impl FnMut(&FrameMeta, &[u8]) -> R) -> Result<R, ReadError> {
        self.retry(|| self.last_seq().ok_or_else(|| self.empty()), |seq| self.read_with(seq, &mut f))
    }

    /// Copies the latest frame into `buf`.
    pub fn latest_into(&self, buf: &mut Vec<u8>) -> Result<FrameMeta, ReadError> {
        self.retry(|| self.last_seq().ok_or_else(|| self.empty()), |seq| self.read_into(seq, buf))
    }

    /// Copies the latest frame.
    pub fn latest(&self) -> Result<Frame, ReadError> {
        let mut data = Vec::new();
        let meta = self.latest_into(&mut data)?;
        Ok(Frame { meta, data })
    }

    /// The sequence number of the complete frame whose stamp is nearest to
    /// `stamp_ns` (CLOCK_MONOTONIC); on a tie, the newer one.
    pub fn nearest_seq(&self, stamp_ns: u64) -> Result<u64, ReadError> {
        let mut best: Option<(u64, u64)> = None; // (distance, seq)
        for (seq, stamp) in self.stamps() {
            let d = stamp.abs_diff(stamp_ns);
            if best.is_none_or(|(bd, bs)| d < bd || (d == bd && seq > bs)) {
                best = Some((d, seq));
            }
        }
        best.map(|(_, seq)| seq).ok_or_else(|| self.empty())
    }

    /// Copies the frame stamped nearest to `stamp_ns` into `buf`.
    pub fn nearest_into(&self, stamp_ns: u64, buf: &mut Vec<u8>) -> Result<FrameMeta, ReadError> {
        self.retry(|| self.nearest_seq(stamp_ns), |seq| self.read_into(seq, buf))
    }

    /// Reads the frame stamped nearest to `stamp_ns` without an allocation
    /// (as [`RingReader::read_with`]).
    pub fn nearest_with<R>(&self, stamp_ns: u64, mut f: impl FnMut(&FrameMeta, &[u8]) -> R) -> Result<R, ReadError> {
        self.retry(|| self.nearest_seq(stamp_ns), |seq| self.read_with(seq, &mut f))
    }

    /// Copies the last `k` complete frames (at most the slot count), oldest
    /// first. Frames overwritten or incomplete by the time they are reached
    /// are left out, so fewer than `k` may come back.
    pub fn last_k(&self, k: usize) -> Vec<Frame> {
        let Some(last) = self.last_seq() else { return Vec::new() };
        let k = (k as u64).min(u64::from(self.geo.slot_count)).min(last);
        let mut out = Vec::with_capacity(k as usize);
        for seq in last + 1 - k..=last {
            if let Ok(f) = self.read(seq) {
                out.push(f);
            }
        }
        out
    }

    /// `(seq, stamp_ns)` of every complete frame in the ring, in slot order.
    /// Frames changing while looked at are skipped.
    pub fn stamps(&self) -> Vec<(u64, u64)> {
        // grows as frames are found: an empty ring of many slots costs nothing
        let mut v = Vec::with_capacity(self.geo.slot_count.min(1024) as usize);
        for i in 0..self.geo.slot_count {
            // SAFETY: geometry validated against the mapping; i in range.
            let h = unsafe { slot_header(&self.map, &self.geo, i) };
            let l1 = h.lock.load(Ordering::Relaxed);
            fence(Ordering::Acquire);
            if l1 == 0 || l1 % 2 == 1 {
                continue;
            }
            let seq = h.seq.load(Ordering::Relaxed);
            let stamp = h.stamp_ns.load(Ordering::Relaxed);
            fence(Ordering::Acquire);
            if h.lock.load(Ordering::Relaxed) == l1 && seq.checked_mul(2) == Some(l1) {
                v.push((seq, stamp));
            }
        }
        v
    }

    fn empty(&self) -> ReadError {
        ReadError::Empty { ring: self.name.to_string() }
    }

    /// Picks a frame with `pick` and reads it with `read`, again if it was
    /// overwritten in between (the pick is then stale).
    fn retry<T>(
        &self,
        mut pick: impl FnMut() -> Result<u64, ReadError>,
        mut read: impl FnMut(u64) -> Result<T, ReadError>,
    ) -> Result<T, ReadError> {
        let mut attempt = 0;
        loop {
            let seq = pick()?;
            match read(seq) {
                Err(ReadError::Overwritten { .. }) if attempt + 1 < RETRIES => attempt += 1,
                other => return other,
            }
        }
    }

    /// The seqlock read (see the module doc). `f` gets the description and a
    /// pointer to `meta.len` in-bounds bytes, which it may only read through
    /// [`copy_frame`]; its result is returned only if the slot did not change
    /// while it ran.
    fn with_frame<R>(&self, seq: u64, f: impl FnOnce(&FrameMeta, *const u8) -> R) -> Result<R, ReadError> {
        if seq == 0 {
            return Err(ReadError::ZeroSeq);
        }
        let Some(want) = seq.checked_mul(2) else {
            return Err(self.not_yet(seq));
        };
        let slot = self.geo.slot_of(seq);
        // SAFETY: geometry validated against the mapping; slot < slot_count.
        let h = unsafe { slot_header(&self.map, &self.geo, slot) };

        // 1: the lock word must say "frame seq, complete"
        let mut retried = false;
        let l1 = loop {
            let l = h.lock.load(Ordering::Relaxed);
            fence(Ordering::Acquire);
            if l == want {
                break l;
            }
            match self.classify(seq, l) {
                // the writer completed seq between our loads of the slot and
                // of last_seq: look again once
                ReadError::NotYet { last, .. } if last >= seq && !retried => retried = true,
                e => return Err(e),
            }
        };

        // 2: speculative reads
        let meta = FrameMeta {
            seq: h.seq.load(Ordering::Relaxed),
            slot,
            stamp_ns: h.stamp_ns.load(Ordering::Relaxed),
            len: h.len.load(Ordering::Relaxed).min(self.geo.slot_capacity) as usize,
            width: h.width.load(Ordering::Relaxed),
            height: h.height.load(Ordering::Relaxed),
            format_code: h.format.load(Ordering::Relaxed),
        };
        let stored_len = h.len.load(Ordering::Relaxed);
        let consistent = meta.seq == seq && stored_len <= self.geo.slot_capacity;
        // SAFETY: as above; the payload follows the slot header.
        let ptr = unsafe { slot_payload(&self.map, &self.geo, slot) } as *const u8;
        let r = consistent.then(|| f(&meta, ptr));

        // 3: validate
        fence(Ordering::Acquire);
        let l2 = h.lock.load(Ordering::Relaxed);
        if l2 != l1 {
            return Err(ReadError::Overwritten {
                ring: self.name.to_string(),
                seq,
                now: l2.div_ceil(2),
                slots: self.geo.slot_count,
                during_read: true,
            });
        }
        r.ok_or_else(|| ReadError::Corrupt {
            ring: self.name.to_string(),
            slot,
            why: format!(
                "lock word says frame {seq} but the header says frame {} of {stored_len} bytes (capacity {})",
                meta.seq, self.geo.slot_capacity
            ),
        })
    }

    /// Why slot lock word `l` does not hold frame `seq` complete.
    fn classify(&self, seq: u64, l: u64) -> ReadError {
        let want = 2 * seq;
        if l > want {
            ReadError::Overwritten {
                ring: self.name.to_string(),
                seq,
                now: l.div_ceil(2),
                slots: self.geo.slot_count,
                during_read: false,
            }
        } else if l == want - 1 {
            let pid = self.map.header_atomics().writer_pid.load(Ordering::Relaxed);
            if pid_alive(pid) {
                ReadError::InProgress { ring: self.name.to_string(), seq }
            } else {
                ReadError::Incomplete { ring: self.name.to_string(), seq, writer_pid: pid }
            }
        } else {
            self.not_yet(seq)
        }
    }

    fn not_yet(&self, seq: u64) -> ReadError {
        match self.last_seq() {
            None => self.empty(),
            Some(last) => ReadError::NotYet { ring: self.name.to_string(), seq, last },
        }
    }
}

/// Replaces `buf`'s content with a volatile copy of the `len` shared bytes at
/// `src` (a slot's payload, as [`RingReader::with_frame`] hands it out).
fn copy_frame(src: *const u8, len: usize, buf: &mut Vec<u8>) {
    buf.clear();
    buf.reserve(len);
    // SAFETY: with_frame guarantees src points at len <= slot_capacity bytes
    // inside the mapping, alive while the reader is borrowed; buf has
    // capacity for len bytes, a fresh allocation that cannot overlap the
    // mapping, and u8 needs no initialisation beyond the copy.
    unsafe {
        copy_volatile(src, buf.as_mut_ptr(), len);
        buf.set_len(len);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{FrameDesc, RingOptions, RingWriter};

    #[test]
    fn in_place_reads_see_a_private_copy_the_writer_cannot_change() {
        let robot = RobotName::new(&format!("stmu-{}", std::process::id())).expect("robot name");
        let dir = PathBuf::from(format!("/dev/shm/nerve-stm-unit-{}", robot.as_str()));
        std::fs::create_dir_all(&dir).expect("test dir");
        let opts = RingOptions { base_dir: dir.clone(), group_readable: false };
        let name = RingName::parse("copy").expect("ring name");
        let mut w = RingWriter::create_with(&opts, &robot, &name, 2, 64).expect("create");
        let r = RingReader::open_with(&opts, &robot, &name).expect("open");
        w.write(FrameDesc::raw(), &[1; 64]).expect("frame 1");
        w.write(FrameDesc::raw(), &[2; 64]).expect("frame 2");

        // while `f` looks at frame 2, the writer overwrites its slot: `f`'s
        // bytes stay what was copied, and the read reports the overwrite
        let res = r.read_with(2, |_, bytes| {
            let before = bytes[0];
            w.write(FrameDesc::raw(), &[3; 64]).expect("frame 3");
            w.write(FrameDesc::raw(), &[4; 64]).expect("frame 4"); // frame 2's slot
            (before, bytes[0])
        });
        assert!(matches!(res, Err(ReadError::Overwritten { seq: 2, during_read: true, .. })), "{res:?}");
        let seen = std::cell::RefCell::new(Vec::new());
        let res = r.read_with(4, |_, bytes| {
            seen.borrow_mut().push(bytes[0]);
            w.write(FrameDesc::raw(), &[5; 64]).expect("frame 5");
            w.write(FrameDesc::raw(), &[6; 64]).expect("frame 6"); // frame 4's slot
            seen.borrow_mut().push(bytes[0]);
            // a nested read gets its own copy, not this one
            let nested = r.read_with(6, |_, b| b[0]).expect("frame 6");
            seen.borrow_mut().push(nested);
            seen.borrow_mut().push(bytes[0]);
        });
        assert!(matches!(res, Err(ReadError::Overwritten { seq: 4, during_read: true, .. })), "{res:?}");
        assert_eq!(*seen.borrow(), [4, 4, 6, 4], "the bytes changed under the closure");
        // and a copy by read_into is exact
        let mut buf = Vec::new();
        assert_eq!(r.read_into(6, &mut buf).expect("frame 6").len, 64);
        assert_eq!(buf, [6; 64]);
        drop((r, w));
        std::fs::remove_dir_all(&dir).expect("remove test dir");
    }
}
