//! The single writer of a ring: creation (or re-opening after a restart),
//! the writer lock, and the writer side of the per-slot seqlock.
//!
//! # Writer side of the seqlock
//!
//! To store frame `seq` in slot `seq % slots`:
//!
//! 1. `lock.store(2*seq - 1, Relaxed)` — odd: "being written";
//! 2. `fence(Release)` — every store below is ordered after the odd store
//!    for any reader that observes one of them and then issues an acquire
//!    fence (fence-to-fence synchronisation). So a reader that saw even a
//!    single byte of the new frame re-reads `lock` as odd or newer, and
//!    rejects what it read;
//! 3. payload bytes and slot header fields (relaxed);
//! 4. `lock.store(2*seq, Release)` — even: "complete"; a reader that loads
//!    this value and then fences (acquire) sees all of step 3;
//! 5. `RingHeader::last_seq.store(seq, Release)` — readers looking for "the
//!    latest" find frame `seq`, whose slot is already complete.
//!
//! This is the protocol of crossbeam's `SeqLock` with a single writer (so the
//! odd store need not be a read-modify-write), and with the sequence number
//! in the lock word so that a reader also knows *which* frame a slot holds.
//! As with every seqlock, the payload copy itself is not atomic; the reader
//! treats what it copied as speculative until it has re-checked the lock.
//!
//! If the writer dies between 1 and 4, the slot stays odd forever: readers
//! report [`crate::ReadError::Incomplete`] once they see that the writer is
//! gone, and a restarted writer rewrites that slot with the same sequence
//! number (the frame never existed for anyone).

use crate::error::{CreateError, WriteError};
use crate::name::RingName;
use crate::sys::{Geometry, Mapping, monotonic_ns, my_pid, realtime_ns, slot_header, slot_payload};
use crate::{FrameDesc, RingOptions};
use nix::errno::Errno;
use nix::fcntl::{Flock, FlockArg};
use shm_schemas::RobotName;
use shm_schemas::ring::{
    RING_HEADER_SIZE, RING_LAYOUT_VERSION, RING_MAGIC, RING_NAME_KIND_ID, RING_NAME_KIND_TEXT, RingHeader, RingNotice,
    SLOT_HEADER_SIZE,
};
use std::fs::{File, OpenOptions};
use std::os::unix::fs::{MetadataExt, OpenOptionsExt, PermissionsExt};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU32, AtomicU64, Ordering, fence};

/// Fewest slots of a ring: one for the writer to fill while readers read another.
pub const MIN_SLOTS: u32 = 2;
/// Most slots of a ring.
pub const MAX_SLOTS: u32 = 1 << 20;
/// Largest slot capacity of a ring, in bytes (1 GiB: a 8K RGB frame is 100 MB).
/// Readers refuse a ring whose header claims more.
pub const MAX_SLOT_CAPACITY: u64 = 1 << 30;

/// The one process that stores frames into a ring.
///
/// Holds an exclusive `flock` on the ring file for its whole life: a second
/// writer is refused, and the kernel releases the lock when this process
/// exits, however it exits. Dropping the writer records "no writer" in the
/// header; the ring and its frames stay for readers (use [`RingWriter::remove`]
/// to delete it).
#[derive(Debug)]
pub struct RingWriter {
    map: Mapping,
    geo: Geometry,
    name: RingName,
    path: PathBuf,
    next_seq: u64,
    /// The ring's `RingHeader::creation_id`, copied into every notice.
    creation_id: u64,
    // last field: dropped (unlocked, closed) after the mapping
    _lock: Flock<File>,
}

impl RingWriter {
    /// Creates ring `name` of `robot` in `/dev/shm` with `slots` slots of
    /// `slot_capacity` bytes each, or re-opens it if it exists with the same
    /// geometry (a restarted writer), continuing after its last frame.
    pub fn create(robot: &RobotName, name: &RingName, slots: u32, slot_capacity: usize) -> Result<Self, CreateError> {
        Self::create_with(&RingOptions::default(), robot, name, slots, slot_capacity)
    }

    /// [`RingWriter::create`] with options (base directory, permissions).
    pub fn create_with(
        opts: &RingOptions,
        robot: &RobotName,
        name: &RingName,
        slots: u32,
        slot_capacity: usize,
    ) -> Result<Self, CreateError> {
        let ring = name.to_string();
        if !(MIN_SLOTS..=MAX_SLOTS).contains(&slots) {
            return Err(CreateError::BadGeometry {
                ring,
                why: format!(
                    "{slots} slots asked for; a ring has {MIN_SLOTS} to {MAX_SLOTS} slots (at least 2, so that readers read one while the writer fills another)"
                ),
            });
        }
        if slot_capacity == 0 || slot_capacity as u64 > MAX_SLOT_CAPACITY {
            return Err(CreateError::BadGeometry {
                ring,
                why: format!(
                    "slot capacity of {slot_capacity} bytes asked for; a slot holds 1 to {MAX_SLOT_CAPACITY} bytes"
                ),
            });
        }
        let geo = Geometry::new(slots, slot_capacity as u64).ok_or_else(|| CreateError::BadGeometry {
            ring: ring.clone(),
            why: format!("{slots} slots of {slot_capacity} bytes exceed the address space"),
        })?;
        let path = name.path_in(&opts.base_dir, robot);
        let file = open_rw(&path, true, opts).map_err(|e| os("cannot create", &path, e))?;
        let file = take_lock(file, &path, &ring)?;
        Self::init_or_reopen(opts, file, path, *name, Some(geo), false)
    }

    /// Re-opens an existing ring of `robot` in `/dev/shm` with the geometry
    /// stored in it, continuing after its last frame.
    pub fn open_existing(robot: &RobotName, name: &RingName) -> Result<Self, CreateError> {
        Self::open_existing_with(&RingOptions::default(), robot, name)
    }

    /// [`RingWriter::open_existing`] with options.
    pub fn open_existing_with(opts: &RingOptions, robot: &RobotName, name: &RingName) -> Result<Self, CreateError> {
        let ring = name.to_string();
        let path = name.path_in(&opts.base_dir, robot);
        let file = match open_rw(&path, false, opts) {
            Ok(f) => f,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Err(CreateError::NotFound { ring, path }),
            Err(e) => return Err(os("cannot open", &path, e)),
        };
        let file = take_lock(file, &path, &ring)?;
        Self::init_or_reopen(opts, file, path, *name, None, false)
    }

    fn init_or_reopen(
        opts: &RingOptions,
        file: Flock<File>,
        path: PathBuf,
        name: RingName,
        want: Option<Geometry>,
        recreated: bool,
    ) -> Result<Self, CreateError> {
        let ring = name.to_string();
        let meta = file.metadata().map_err(|e| os("cannot stat", &path, e))?;
        let me = nix::unistd::geteuid().as_raw();
        if meta.uid() != me {
            return Err(CreateError::NotOwner { path, owner: meta.uid(), me });
        }
        if !meta.file_type().is_file() {
            return Err(not_a_ring(&path, "not a regular file"));
        }
        let mode = opts.mode();
        if meta.mode() & 0o777 != mode {
            file.set_permissions(std::fs::Permissions::from_mode(mode))
                .map_err(|e| os("cannot set permissions of", &path, e))?;
        }

        // An existing, complete ring: check it and continue it.
        if meta.len() >= u64::from(RING_HEADER_SIZE) {
            let len = usize::try_from(meta.len()).map_err(|_| not_a_ring(&path, "file too large"))?;
            let map = Mapping::new(&file, len, true).map_err(|e| os("cannot map", &path, e.into()))?;
            let h = map.header();
            let magic = h.magic.load(Ordering::Acquire);
            if magic == RING_MAGIC {
                if h.layout_version != RING_LAYOUT_VERSION {
                    let version = h.layout_version;
                    return match want {
                        // Left by another build of nerve: its header means
                        // something else (a version-1 ring has no creation
                        // id, so its notices would match no reader). We hold
                        // the writer lock, so nobody writes it: replace it.
                        Some(geo) if !recreated => {
                            tracing::warn!(
                                ring = %ring, path = %path.display(), found = version, expected = RING_LAYOUT_VERSION,
                                "ring has another layout version; recreating it, its frames are lost"
                            );
                            drop(map);
                            Self::recreate(opts, file, path, name, geo)
                        }
                        _ => Err(not_a_ring(&path, &format!("it has layout version {version}"))),
                    };
                }
                let found = Geometry::from_header(h, map.len())
                    .ok_or_else(|| not_a_ring(&path, "its header contradicts its size"))?;
                let mismatch =
                    want.filter(|w| (w.slot_count, w.slot_capacity) != (found.slot_count, found.slot_capacity));
                if let Some(w) = mismatch {
                    return Err(CreateError::GeometryMismatch {
                        ring,
                        path,
                        existing_slots: found.slot_count,
                        existing_capacity: found.slot_capacity,
                        slots: w.slot_count,
                        capacity: w.slot_capacity,
                    });
                }
                match plausible_state(&map, &found) {
                    Ok(()) => return Ok(Self::start(map, found, name, path, file)),
                    Err(why) if !recreated => {
                        // Continuing would overflow the sequence arithmetic
                        // or hand out numbers readers already saw. Replace
                        // the file (a new inode: readers that mapped the old
                        // one keep it until they notice it is stale).
                        tracing::warn!(
                            ring = %ring, path = %path.display(),
                            "ring state is implausible ({why}); recreating the ring with the same geometry, its frames are lost"
                        );
                        drop(map);
                        return Self::recreate(opts, file, path, name, found);
                    }
                    Err(why) => return Err(not_a_ring(&path, &format!("its state is implausible: {why}"))),
                }
            }
            if magic != 0 {
                return Err(not_a_ring(&path, "unknown magic number"));
            }
            // magic 0: a creator died before finishing; start over below
        }

        let Some(geo) = want else {
            return Err(not_a_ring(&path, "its creation never finished; create it again with RingWriter::create"));
        };
        let map = match create_file(&file, &path, &ring, &geo, &name, meta.len()) {
            Ok(map) => map,
            Err(e) => {
                // leave no empty file behind for a ring that never existed
                // (we still hold the lock, so no other writer is using it)
                if meta.len() == 0 {
                    let _ = std::fs::remove_file(&path);
                }
                return Err(e);
            }
        };
        tracing::info!(ring = %ring, path = %path.display(), slots = geo.slot_count, slot_capacity = geo.slot_capacity, "ring created");
        Ok(Self::start(map, geo, name, path, file))
    }

    /// Replaces the ring file by a new, empty one of geometry `geo` (a new
    /// inode and creation id: readers that mapped the old file keep it until
    /// they notice, and refuse notices of the other file). `file` is the old
    /// file, whose writer lock we hold until the new file is locked.
    fn recreate(
        opts: &RingOptions,
        file: Flock<File>,
        path: PathBuf,
        name: RingName,
        geo: Geometry,
    ) -> Result<Self, CreateError> {
        let ring = name.to_string();
        std::fs::remove_file(&path).map_err(|e| os("cannot remove the old ring", &path, e))?;
        drop(file);
        let file = open_rw(&path, true, opts).map_err(|e| os("cannot create", &path, e))?;
        let file = take_lock(file, &path, &ring)?;
        Self::init_or_reopen(opts, file, path, name, Some(geo), true)
    }

    /// Takes over a complete ring: finds the last complete frame and records
    /// this process as the writer.
    fn start(map: Mapping, geo: Geometry, name: RingName, path: PathBuf, lock: Flock<File>) -> Self {
        let h = map.header();
        // We hold the writer lock, so no slot changes under us. A frame is
        // complete if its lock word is even; the largest one is the last.
        let mut last = h.last_seq.load(Ordering::Relaxed);
        let mut incomplete = Vec::new();
        for i in 0..geo.slot_count {
            // SAFETY: geometry validated against the mapping, i in range.
            let s = unsafe { slot_header(&map, &geo, i) };
            let l = s.lock.load(Ordering::Relaxed);
            if l != 0 && l % 2 == 0 {
                last = last.max(l / 2);
            } else if l % 2 == 1 {
                incomplete.push(l.div_ceil(2));
            }
        }
        h.last_seq.store(last, Ordering::Release);
        h.writer_pid.store(my_pid(), Ordering::Relaxed);
        let generation = h.writer_generation.fetch_add(1, Ordering::Relaxed) + 1;
        if !incomplete.is_empty() {
            tracing::warn!(ring = %name, frames = ?incomplete, "the previous writer died while storing these frames; they are lost");
        }
        tracing::info!(ring = %name, path = %path.display(), next_seq = last + 1, generation, "ring writer ready");
        let creation_id = h.creation_id;
        RingWriter { map, geo, name, path, next_seq: last + 1, creation_id, _lock: lock }
    }

    /// Stores a copy of `data` as the next frame, overwriting the oldest.
    /// Returns the notice to publish.
    pub fn write(&mut self, desc: FrameDesc, data: &[u8]) -> Result<RingNotice, WriteError> {
        self.write_with(desc, data.len(), |buf| buf.copy_from_slice(data))
    }

    /// Stores the next frame of `len` bytes by letting `fill` write it in
    /// place, directly into shared memory (a camera can decode or render into
    /// it without a copy). Returns the notice to publish.
    ///
    /// `fill` gets exactly `len` bytes holding whatever the slot held before
    /// (an older frame): it must write every byte it means to publish.
    /// Readers see the frame only after `fill` returned. If `fill` panics,
    /// the frame is not stored; the slot reads as "being written" until the
    /// next write, or as incomplete once this writer is gone.
    pub fn write_with<F: FnOnce(&mut [u8])>(
        &mut self,
        desc: FrameDesc,
        len: usize,
        fill: F,
    ) -> Result<RingNotice, WriteError> {
        self.check(&desc, len)?;
        let seq = self.next_seq;
        let slot = self.geo.slot_of(seq);
        // SAFETY: the geometry was validated against the mapping; slot < slot_count.
        let h = unsafe { slot_header(&self.map, &self.geo, slot) };

        // 1-2: mark the slot odd, then fence so that no store below can be
        // seen by a reader without it also seeing the odd word (see module doc).
        h.lock.store(2 * seq - 1, Ordering::Relaxed);
        fence(Ordering::Release);

        // 3: the payload, in place. We are the only writer (flock + &mut
        // self); readers only read, and validate afterwards.
        // SAFETY: slot in range, len <= slot_capacity (checked), the mapping
        // is read-write, and no other reference to these bytes exists in
        // this process.
        let buf = unsafe { std::slice::from_raw_parts_mut(slot_payload(&self.map, &self.geo, slot), len) };
        fill(buf);
        let stamp_ns = desc.stamp_ns.unwrap_or_else(monotonic_ns);
        h.seq.store(seq, Ordering::Relaxed);
        h.stamp_ns.store(stamp_ns, Ordering::Relaxed);
        h.len.store(len as u64, Ordering::Relaxed);
        h.width.store(desc.width, Ordering::Relaxed);
        h.height.store(desc.height, Ordering::Relaxed);
        h.format.store(desc.format.code(), Ordering::Relaxed);

        // 4: complete. 5: announce as the latest.
        h.lock.store(2 * seq, Ordering::Release);
        self.map.header().last_seq.store(seq, Ordering::Release);
        self.next_seq = seq + 1;

        Ok(RingNotice {
            ring: self.name.to_fixed(),
            slot,
            ring_id: self.name.as_id().unwrap_or(0),
            seq,
            stamp_ns,
            size: len as u64,
            width: desc.width,
            height: desc.height,
            format: desc.format.code(),
            reserved: 0,
            creation_id: self.creation_id,
        })
    }

    fn check(&self, desc: &FrameDesc, len: usize) -> Result<(), WriteError> {
        let len = len as u64;
        if len > self.geo.slot_capacity {
            return Err(WriteError::TooLarge { ring: self.name.to_string(), len, capacity: self.geo.slot_capacity });
        }
        if let Some(bpp) = desc.format.bytes_per_pixel() {
            let needed = u64::from(desc.width).saturating_mul(u64::from(desc.height)).saturating_mul(bpp as u64);
            if len < needed {
                return Err(WriteError::ImageTooShort {
                    format: desc.format.as_str(),
                    width: desc.width,
                    height: desc.height,
                    needed,
                    len,
                });
            }
        }
        Ok(())
    }

    /// The sequence number the next frame will get.
    pub fn next_seq(&self) -> u64 {
        self.next_seq
    }

    /// The last complete frame, `None` while the ring is empty.
    pub fn last_seq(&self) -> Option<u64> {
        Some(self.next_seq - 1).filter(|s| *s > 0)
    }

    /// The ring's name.
    pub fn name(&self) -> &RingName {
        &self.name
    }

    /// The ring's file.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Number of slots (the frames kept).
    pub fn slot_count(&self) -> u32 {
        self.geo.slot_count
    }

    /// Largest frame, in bytes.
    pub fn slot_capacity(&self) -> usize {
        self.geo.slot_capacity as usize
    }

    /// The random number drawn when this ring file was created (see
    /// [`RingHeader::creation_id`]); every notice carries it.
    pub fn creation_id(&self) -> u64 {
        self.creation_id
    }

    /// Deletes the ring file. Readers that mapped it keep their mapping (and
    /// its frames) until they drop it; new readers no longer find it.
    pub fn remove(self) -> std::io::Result<()> {
        let path = self.path.clone();
        drop(self);
        std::fs::remove_file(path)
    }
}

impl Drop for RingWriter {
    fn drop(&mut self) {
        // "no writer": a slot still odd now is incomplete for good
        let _ = self.map.header().writer_pid.compare_exchange(my_pid(), 0, Ordering::Relaxed, Ordering::Relaxed);
        tracing::debug!(ring = %self.name, "ring writer closed");
    }
}

/// Largest sequence number a reopened ring may continue from: far beyond
/// any real ring (2^62 frames at 1 MHz is 146 000 years), and far enough
/// from 2^63 that `2 * seq` never overflows.
pub(crate) const MAX_SEQ: u64 = 1 << 62;

/// Whether the shared state of an existing ring (last_seq and the slot lock
/// words) is one a writer could have left, so that continuing it is safe.
///
/// A writer stores frames 1, 2, 3, ... in slot `seq % slots`; so a nonzero
/// lock word `2*seq` (complete) or `2*seq - 1` (being written when the
/// writer died) sits in slot `seq % slots`, the complete frames are the last
/// `slots` ones, a half-written frame is the one after them, and last_seq
/// is the newest complete frame or the one before it (a writer that died
/// between completing the slot and announcing it).
fn plausible_state(map: &Mapping, geo: &Geometry) -> Result<(), String> {
    let last_seq = map.header().last_seq.load(Ordering::Relaxed);
    if last_seq >= MAX_SEQ {
        return Err(format!("last_seq {last_seq} is at least 2^62"));
    }
    let mut newest = 0u64;
    let mut words = Vec::new();
    for i in 0..geo.slot_count {
        // SAFETY: geometry validated against the mapping, i in range.
        let l = unsafe { slot_header(map, geo, i) }.lock.load(Ordering::Relaxed);
        if l == 0 {
            continue;
        }
        let seq = l.div_ceil(2);
        if seq >= MAX_SEQ {
            return Err(format!("slot {i} has lock word {l} (frame {seq}, at least 2^62)"));
        }
        if geo.slot_of(seq) != i {
            return Err(format!("slot {i} has lock word {l}, but frame {seq} belongs in slot {}", geo.slot_of(seq)));
        }
        if l % 2 == 0 {
            newest = newest.max(seq);
        }
        words.push((i, l, seq));
    }
    let window = u64::from(geo.slot_count);
    for (i, l, seq) in words {
        let ok = if l % 2 == 0 { seq + window > newest } else { seq == newest + 1 };
        if !ok {
            return Err(format!("slot {i} has lock word {l} (frame {seq}) but the newest complete frame is {newest}"));
        }
    }
    if last_seq > newest || last_seq + 1 < newest {
        return Err(format!("last_seq {last_seq} does not match the newest complete frame {newest}"));
    }
    Ok(())
}

fn os(what: &'static str, path: &Path, source: std::io::Error) -> CreateError {
    CreateError::Os { what, path: path.to_owned(), source }
}

fn not_a_ring(path: &Path, why: &str) -> CreateError {
    CreateError::NotARing { path: path.to_owned(), expected: RING_LAYOUT_VERSION, why: why.to_owned() }
}

/// Opens the ring file for writing, never following a symbolic link (the
/// directory is world-writable /dev/shm).
fn open_rw(path: &Path, create: bool, opts: &RingOptions) -> std::io::Result<File> {
    OpenOptions::new()
        .read(true)
        .write(true)
        .create(create)
        .mode(opts.mode())
        .custom_flags(libc::O_NOFOLLOW | libc::O_CLOEXEC)
        .open(path)
}

fn take_lock(file: File, path: &Path, ring: &str) -> Result<Flock<File>, CreateError> {
    match Flock::lock(file, FlockArg::LockExclusiveNonblock) {
        Ok(lock) => Ok(lock),
        Err((file, Errno::EWOULDBLOCK)) => {
            // best effort: the pid the current writer recorded
            let pid = read_writer_pid(&file).unwrap_or(0);
            Err(CreateError::WriterExists { ring: ring.to_owned(), path: path.to_owned(), pid })
        }
        Err((_, e)) => Err(os("cannot lock", path, e.into())),
    }
}

fn read_writer_pid(file: &File) -> Option<u32> {
    use std::os::unix::fs::FileExt;
    let mut b = [0u8; 4];
    file.read_exact_at(&mut b, std::mem::offset_of!(RingHeader, writer_pid) as u64).ok()?;
    Some(u32::from_ne_bytes(b))
}

/// Sizes, reserves and initialises a new ring file; the magic is stored last.
fn create_file(
    file: &File,
    path: &Path,
    ring: &str,
    geo: &Geometry,
    name: &RingName,
    old_len: u64,
) -> Result<Mapping, CreateError> {
    let total =
        geo.file_len().ok_or_else(|| CreateError::BadGeometry { ring: ring.into(), why: "too large".into() })?;
    // Refuse up front rather than die of SIGBUS on first touch of a page
    // tmpfs cannot supply.
    let vfs = nix::sys::statvfs::fstatvfs(file).map_err(|e| os("cannot statvfs", path, e.into()))?;
    let available = (vfs.blocks_available() as u64).saturating_mul(vfs.fragment_size() as u64);
    let needed = total.saturating_sub(old_len);
    let dir = path.parent().unwrap_or(Path::new("/")).to_owned();
    if needed > available {
        return Err(CreateError::NoSpace { ring: ring.into(), dir, needed, available });
    }
    file.set_len(total).map_err(|e| os("cannot size", path, e))?;
    // Reserve the pages now (tmpfs allocates them), so that a concurrent
    // consumer of /dev/shm cannot make our later writes fault.
    match nix::fcntl::posix_fallocate(file, 0, total as libc::off_t) {
        Ok(()) => {}
        Err(Errno::ENOSPC) => {
            let _ = file.set_len(0);
            return Err(CreateError::NoSpace { ring: ring.into(), dir, needed, available });
        }
        Err(e @ (Errno::EOPNOTSUPP | Errno::EINVAL | Errno::ENOSYS)) => {
            tracing::debug!(path = %path.display(), "posix_fallocate not supported here ({e}); pages are allocated on first write");
        }
        Err(e) => return Err(os("cannot reserve space for", path, e.into())),
    }
    let map = Mapping::new(file, total as usize, true).map_err(|e| os("cannot map", path, e.into()))?;
    let kind = if name.as_id().is_some() { RING_NAME_KIND_ID } else { RING_NAME_KIND_TEXT };
    let header = RingHeader {
        magic: AtomicU64::new(0),
        layout_version: RING_LAYOUT_VERSION,
        header_size: RING_HEADER_SIZE,
        slot_count: geo.slot_count,
        slot_header_size: SLOT_HEADER_SIZE,
        slot_capacity: geo.slot_capacity,
        slot_stride: geo.slot_stride,
        name: name.to_fixed(),
        name_kind: kind,
        name_id: name.as_id().unwrap_or(0),
        created_realtime_ns: realtime_ns(),
        created_monotonic_ns: monotonic_ns(),
        writer_pid: AtomicU32::new(0),
        reserved0: 0,
        last_seq: AtomicU64::new(0),
        writer_generation: AtomicU64::new(0),
        creation_id: new_creation_id(),
        reserved: [0; 15],
    };
    // SAFETY: the mapping is at least RING_HEADER_SIZE long and page-aligned;
    // with magic 0 no reader trusts (or keeps) this mapping, and we hold the
    // writer lock, so nothing else accesses these bytes now.
    unsafe {
        std::ptr::write_bytes(map.base(), 0, RING_HEADER_SIZE as usize);
        std::ptr::write(map.base() as *mut RingHeader, header);
    }
    for i in 0..geo.slot_count {
        // SAFETY: geometry computed for exactly this mapping; i in range.
        let s = unsafe { slot_header(&map, geo, i) };
        s.lock.store(0, Ordering::Relaxed);
        s.seq.store(0, Ordering::Relaxed);
    }
    // publish: a reader that sees the magic (acquire) sees all of the above
    map.header().magic.store(RING_MAGIC, Ordering::Release);
    Ok(map)
}

/// A fresh [`RingHeader::creation_id`]: 64 random bits from the kernel,
/// never 0 (a default notice, or a ring of an older layout, has 0). Should
/// the kernel refuse (it does not, once booted), the clocks, the pid and a
/// counter still tell two rings of one name apart.
fn new_creation_id() -> u64 {
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    let mut b = [0u8; 8];
    // SAFETY: b is valid for writes of its 8 bytes; getrandom writes at most that many.
    let n = unsafe { libc::getrandom(b.as_mut_ptr().cast(), b.len(), 0) };
    let id = if n == 8 {
        u64::from_ne_bytes(b)
    } else {
        let count = COUNTER.fetch_add(1, Ordering::Relaxed);
        realtime_ns() ^ monotonic_ns().rotate_left(21) ^ (u64::from(my_pid()) << 40) ^ count.rotate_left(11)
    };
    id.max(1)
}
