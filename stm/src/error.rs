//! Error types. Each message names the ring and the file, says what went
//! wrong, and what to do about it.

use std::path::PathBuf;

/// Why a writer could not create or open a ring.
#[derive(Debug, thiserror::Error)]
pub enum CreateError {
    /// Another process holds the writer lock.
    #[error(
        "ring {ring} already has a writer (pid {pid}); a ring has exactly one writer at a time. Stop that process, or write to another ring name (file {path})"
    )]
    WriterExists {
        /// the ring
        ring: String,
        /// its file
        path: PathBuf,
        /// the pid recorded by the current writer (0 if unknown)
        pid: u32,
    },
    /// The ring exists with another geometry.
    #[error(
        "ring {ring} exists with {existing_slots} slots of {existing_capacity} bytes, but {slots} slots of {capacity} bytes were asked for; use the existing geometry, or remove {path} once no agent uses the ring"
    )]
    GeometryMismatch {
        /// the ring
        ring: String,
        /// its file
        path: PathBuf,
        /// slots in the file
        existing_slots: u32,
        /// slot capacity in the file
        existing_capacity: u64,
        /// slots asked for
        slots: u32,
        /// capacity asked for
        capacity: u64,
    },
    /// Geometry out of range.
    #[error("invalid geometry for ring {ring}: {why}")]
    BadGeometry {
        /// the ring
        ring: String,
        /// what is wrong, and the allowed range
        why: String,
    },
    /// The target file system has too little free space.
    #[error(
        "not enough free space for ring {ring}: it needs {needed} bytes but {dir} has {available} bytes free; a full /dev/shm kills the writer with SIGBUS, so nerve refuses up front. Free shared memory (`nerve mem list`, remove stale rings) or make the ring smaller"
    )]
    NoSpace {
        /// the ring
        ring: String,
        /// the directory
        dir: PathBuf,
        /// bytes needed
        needed: u64,
        /// bytes free
        available: u64,
    },
    /// The file exists but is not a ring of this layout.
    #[error("{path} is not a nerve ring of layout version {expected} ({why}); remove it if it is stale")]
    NotARing {
        /// the file
        path: PathBuf,
        /// the layout version this build writes
        expected: u32,
        /// what did not match
        why: String,
    },
    /// The file belongs to another user.
    #[error(
        "{path} belongs to uid {owner}, not to this process (uid {me}); refusing to write into another user's shared memory. If the file is stale, remove it (as its owner, or root); if someone else holds this ring's name, find out who (`ls -l {path}`) or run the robot under another name"
    )]
    NotOwner {
        /// the file
        path: PathBuf,
        /// the file's owner
        owner: u32,
        /// our effective uid
        me: u32,
    },
    /// `open_existing` found no ring.
    #[error("ring {ring} does not exist (no file {path}); create it with RingWriter::create")]
    NotFound {
        /// the ring
        ring: String,
        /// its file
        path: PathBuf,
    },
    /// A system call failed.
    #[error("{what} {path}: {source}")]
    Os {
        /// what was being done
        what: &'static str,
        /// the file
        path: PathBuf,
        /// the error
        #[source]
        source: std::io::Error,
    },
}

/// Why a reader could not open a ring.
#[derive(Debug, thiserror::Error)]
pub enum OpenError {
    /// No such ring.
    #[error("ring {ring} does not exist (no file {path}); is its writer running, and under the same robot name?")]
    NotFound {
        /// the ring
        ring: String,
        /// its file
        path: PathBuf,
    },
    /// Not allowed to read the file.
    #[error(
        "permission denied reading {path}: rings are read by agents of the writer's own user only; run the reader as the writer's user"
    )]
    PermissionDenied {
        /// the file
        path: PathBuf,
    },
    /// The file belongs to another user, or others may write it: its frames
    /// cannot be trusted.
    #[error(
        "refusing to read ring file {path}: it belongs to uid {owner} with mode {mode:04o}, but a ring must belong to this user (uid {me}) and be writable by nobody else, or another user could feed it fake frames. If the file is stale, remove it (as its owner, or root); if someone else holds this ring's name, find out who (`ls -l {path}`) or run the robot under another name"
    )]
    Untrusted {
        /// the file
        path: PathBuf,
        /// the file's owner
        owner: u32,
        /// the file's permission bits
        mode: u32,
        /// our effective uid
        me: u32,
    },
    /// The writer is still initialising the ring.
    #[error("ring file {path} is still being created by its writer; retry in a moment")]
    NotReady {
        /// the file
        path: PathBuf,
    },
    /// The file is not a ring this build can read.
    #[error("{path} is not a nerve ring of layout version {expected} ({why})")]
    NotARing {
        /// the file
        path: PathBuf,
        /// the layout version this build reads
        expected: u32,
        /// what did not match
        why: String,
    },
    /// A system call failed.
    #[error("{what} {path}: {source}")]
    Os {
        /// what was being done
        what: &'static str,
        /// the file
        path: PathBuf,
        /// the error
        #[source]
        source: std::io::Error,
    },
}

/// Why a frame was not stored.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum WriteError {
    /// The frame is larger than a slot.
    #[error(
        "frame of {len} bytes does not fit ring {ring}, whose slots hold {capacity} bytes; create the ring with a larger slot capacity"
    )]
    TooLarge {
        /// the ring
        ring: String,
        /// bytes of the frame
        len: u64,
        /// bytes of a slot
        capacity: u64,
    },
    /// An image frame shorter than its width x height x bytes per pixel.
    #[error("{format} image of {width}x{height} needs {needed} bytes but the frame has {len}")]
    ImageTooShort {
        /// the pixel format
        format: &'static str,
        /// width in pixels
        width: u32,
        /// height in pixels
        height: u32,
        /// bytes needed
        needed: u64,
        /// bytes given
        len: u64,
    },
}

/// Why a frame could not be read. None of these is returned with data: a
/// reader never sees a torn or half-written frame.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ReadError {
    /// Sequence numbers start at 1.
    #[error("frame 0 does not exist; sequence numbers start at 1")]
    ZeroSeq,
    /// The ring has no complete frame yet.
    #[error("ring {ring} holds no frame yet")]
    Empty {
        /// the ring
        ring: String,
    },
    /// The frame has not been stored yet.
    #[error("frame {seq} of ring {ring} has not been stored yet (last stored: {last})")]
    NotYet {
        /// the ring
        ring: String,
        /// the frame asked for
        seq: u64,
        /// the last complete frame
        last: u64,
    },
    /// The frame was overwritten by a newer one, before or while it was read.
    #[error(
        "frame {seq} of ring {ring} was overwritten{when} (its slot now holds frame {now}); the ring keeps its last {slots} frames, so read sooner or give the ring more slots",
        when = if *during_read { " while it was being read" } else { "" }
    )]
    Overwritten {
        /// the ring
        ring: String,
        /// the frame asked for
        seq: u64,
        /// the frame its slot holds (or is being filled with) now
        now: u64,
        /// slots of the ring
        slots: u32,
        /// true if the overwrite happened during this read (a torn read, detected)
        during_read: bool,
    },
    /// The writer is storing this frame right now.
    #[error("frame {seq} of ring {ring} is being stored right now; retry")]
    InProgress {
        /// the ring
        ring: String,
        /// the frame asked for
        seq: u64,
    },
    /// The writer died while storing this frame; it will never be complete.
    #[error(
        "frame {seq} of ring {ring} is incomplete: its writer (pid {writer_pid}) stopped while storing it; the frame is lost, earlier frames are intact"
    )]
    Incomplete {
        /// the ring
        ring: String,
        /// the frame asked for
        seq: u64,
        /// the pid of the writer that left it (0 if it closed the ring)
        writer_pid: u32,
    },
    /// The notice names a frame of another file of this ring: the ring was
    /// replaced (another geometry, or created again) after the notice was
    /// sent, or before this reader mapped it. The frame is gone; its
    /// sequence number means another frame in the ring's current file.
    #[error(
        "frame {seq} of ring {ring} was announced for the ring's file with creation id {notice_creation_id:016x}, but the ring's file is now another one (creation id {creation_id:016x}): the ring was replaced since, and the frame is gone; wait for the next notice"
    )]
    OtherRing {
        /// the ring
        ring: String,
        /// the frame the notice named
        seq: u64,
        /// the creation id the notice carries
        notice_creation_id: u64,
        /// the creation id of the file the reader maps
        creation_id: u64,
    },
    /// The slot header contradicts itself (a misbehaving writer).
    #[error("slot {slot} of ring {ring} is corrupt: {why}")]
    Corrupt {
        /// the ring
        ring: String,
        /// the slot
        slot: u32,
        /// what is inconsistent
        why: String,
    },
}
