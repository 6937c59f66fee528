//! Short-term memory rings: the shared-memory layout, and the notice that
//! announces a stored frame (the thesis' "a link and a signal").
//!
//! A ring is one file in `/dev/shm` named `nerve_<uid>_<robot>_stm_<name>`. Its
//! layout, all little-endian native `#[repr(C)]`:
//!
//! ```text
//! offset 0                 RingHeader (256 bytes), then zeros up to
//! offset header_size       (4096, one page)
//! slot i at                header_size + i * slot_stride:
//!     SlotHeader           (64 bytes, one cache line)
//!     payload              slot_capacity bytes, padded to a multiple of 64
//! ```
//!
//! Frame number `seq` (counted from 1) lives in slot `seq % slot_count`.
//! Each slot is guarded by a seqlock word ([`SlotHeader::lock`]) that encodes
//! the frame it holds: `2*seq - 1` (odd) while frame `seq` is being written,
//! `2*seq` (even) once it is complete, `0` if the slot was never written. The
//! protocol (writer and reader side, memory orderings) is implemented by the
//! `nerve-stm` crate and described in `docs/short-term-memory.md`.
//!
//! The fields that change while the ring is in use are atomics (same size
//! and alignment as the plain integers, guaranteed by the standard library),
//! so that a process may read them while another writes them. The others are
//! written once, before [`RingHeader::magic`] is published.
//!
//! [`RingNotice`] is the small payload sent on an iceoryx2 port after each
//! stored frame: it names the ring and the slot; the reader maps the ring once
//! and reads the frame in place.

use crate::fixed::FixedName;
use crate::payloads::Payload;
use serde::Serialize;
use std::sync::atomic::{AtomicU32, AtomicU64};

/// `RingHeader::magic` of a ready ring: the bytes `NERVESTM`.
pub const RING_MAGIC: u64 = u64::from_le_bytes(*b"NERVESTM");

/// Version of this layout; a ring of another version is refused by name
/// by readers, and replaced by a writer that creates the ring again.
///
/// Version 2 added [`RingHeader::creation_id`] (and [`RingNotice::creation_id`]):
/// a version-1 file has zero there, which would match no notice.
pub const RING_LAYOUT_VERSION: u32 = 2;

/// Bytes before the first slot: the header, padded to one page.
pub const RING_HEADER_SIZE: u32 = 4096;

/// Bytes of a [`SlotHeader`]; the payload follows it.
pub const SLOT_HEADER_SIZE: u32 = 64;

/// Payloads are padded to a multiple of this (a cache line) so that every
/// slot header and payload starts on a cache line.
pub const SLOT_ALIGN: u64 = 64;

/// `RingHeader::name_kind` of a ring named by a number (`id-42`).
pub const RING_NAME_KIND_ID: u32 = 0;
/// `RingHeader::name_kind` of a ring named by up to six characters (`cam`).
pub const RING_NAME_KIND_TEXT: u32 = 1;

/// The header at offset 0 of a ring file.
///
/// Written once by the creating writer, except the atomics, which a writer
/// updates while readers read them.
#[derive(Debug)]
#[repr(C)]
pub struct RingHeader {
    /// [`RING_MAGIC`] once the header is complete; stored last (release),
    /// so a reader that sees it (acquire) sees every other field.
    pub magic: AtomicU64,
    /// [`RING_LAYOUT_VERSION`].
    pub layout_version: u32,
    /// Offset of slot 0 ([`RING_HEADER_SIZE`]).
    pub header_size: u32,
    /// Number of slots.
    pub slot_count: u32,
    /// Bytes of each slot header ([`SLOT_HEADER_SIZE`]).
    pub slot_header_size: u32,
    /// Largest payload a slot holds, in bytes.
    pub slot_capacity: u64,
    /// Distance between two slots: header + capacity rounded up to [`SLOT_ALIGN`].
    pub slot_stride: u64,
    /// The ring's name as text: `cam`, or `id-42` for a numbered ring.
    pub name: FixedName,
    /// [`RING_NAME_KIND_ID`] or [`RING_NAME_KIND_TEXT`].
    pub name_kind: u32,
    /// The number of a numbered ring; 0 for a named one.
    pub name_id: u64,
    /// CLOCK_REALTIME nanoseconds when the ring was created (for people).
    pub created_realtime_ns: u64,
    /// CLOCK_MONOTONIC nanoseconds when the ring was created.
    pub created_monotonic_ns: u64,
    /// Pid of the process that holds the writer lock; 0 once it closed the
    /// ring cleanly. A crashed writer leaves its pid here.
    pub writer_pid: AtomicU32,
    /// Zero.
    pub reserved0: u32,
    /// Sequence number of the last completed frame; 0 while the ring is empty.
    pub last_seq: AtomicU64,
    /// How many times a writer opened the ring (1 for the creator). A reader
    /// sees a writer restart as a change of this number.
    pub writer_generation: AtomicU64,
    /// A random, nonzero number drawn when this file was created, never
    /// changed afterwards: it tells this ring apart from an earlier or later
    /// ring of the same name (a ring replaced for another geometry starts
    /// its sequence numbers at 1 again). Every [`RingNotice`] carries it, so
    /// that a reader never resolves a notice in another ring's file.
    pub creation_id: u64,
    /// Zero; room for later fields within the same layout version.
    pub reserved: [u64; 15],
}

/// The header of one slot, followed by the payload.
///
/// Every field is written by the writer between the odd and the even store of
/// [`SlotHeader::lock`]; a reader trusts them only if `lock` reads the same
/// even value before and after it read them.
#[derive(Debug)]
#[repr(C)]
pub struct SlotHeader {
    /// The seqlock word: `2*seq - 1` while frame `seq` is written, `2*seq`
    /// once complete, 0 if never written.
    pub lock: AtomicU64,
    /// Sequence number of the frame stored (same as `lock / 2` when even).
    pub seq: AtomicU64,
    /// CLOCK_MONOTONIC nanoseconds when the frame was stored (or the stamp
    /// the writer gave it).
    pub stamp_ns: AtomicU64,
    /// Payload bytes used, at most `RingHeader::slot_capacity`.
    pub len: AtomicU64,
    /// Image width in pixels; 0 for [`PixelFormat::Raw`] data.
    pub width: AtomicU32,
    /// Image height in pixels; 0 for [`PixelFormat::Raw`] data.
    pub height: AtomicU32,
    /// A [`PixelFormat`] code.
    pub format: AtomicU32,
    /// Zero.
    pub reserved0: AtomicU32,
    /// Zero.
    pub reserved: [AtomicU64; 2],
}

/// How the bytes of a frame are to be understood. Stored as its `u32` code;
/// an unknown code (from a newer writer) reads as `None` from
/// [`PixelFormat::from_code`], never as undefined behaviour.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize)]
#[repr(u32)]
pub enum PixelFormat {
    /// Opaque bytes (not an image).
    Raw = 0,
    /// 3 bytes per pixel, red, green, blue; rows top to bottom, no padding.
    Rgb8 = 1,
    /// 1 byte per pixel, grey level; also binary masks (0 or 255).
    Gray8 = 2,
    /// 3 bytes per pixel: hue (0..=255 for 0°..360°), saturation
    /// (0..=255 for 0..1), intensity (0..=255 for 0..1); rows top to bottom.
    Hsi8 = 3,
}

impl PixelFormat {
    /// The format of a stored code, `None` if this build does not know it.
    pub fn from_code(code: u32) -> Option<Self> {
        match code {
            0 => Some(PixelFormat::Raw),
            1 => Some(PixelFormat::Rgb8),
            2 => Some(PixelFormat::Gray8),
            3 => Some(PixelFormat::Hsi8),
            _ => None,
        }
    }

    /// The stored code.
    pub fn code(self) -> u32 {
        self as u32
    }

    /// Bytes per pixel, `None` for [`PixelFormat::Raw`].
    pub fn bytes_per_pixel(self) -> Option<usize> {
        match self {
            PixelFormat::Raw => None,
            PixelFormat::Gray8 => Some(1),
            PixelFormat::Rgb8 | PixelFormat::Hsi8 => Some(3),
        }
    }

    /// A short lowercase name (`rgb8`), for tools.
    pub fn as_str(self) -> &'static str {
        match self {
            PixelFormat::Raw => "raw",
            PixelFormat::Rgb8 => "rgb8",
            PixelFormat::Gray8 => "gray8",
            PixelFormat::Hsi8 => "hsi8",
        }
    }
}

impl std::fmt::Display for PixelFormat {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

/// "A link and a signal": sent on a port after a frame was stored in a ring.
///
/// The receiver opens (once) the ring named here and reads frame `seq` in
/// place. The frame may have been overwritten by the time the notice is read;
/// the ring reader reports that instead of returning torn data.
#[derive(Debug, Clone, Copy, Default, Payload, Serialize)]
#[repr(C)]
#[payload(name = "nerve::RingNotice")]
pub struct RingNotice {
    /// The ring's name as text: `cam`, or `id-42` for a numbered ring.
    pub ring: FixedName,
    /// The slot that holds the frame (`seq % slot_count`).
    pub slot: u32,
    /// The number of a numbered ring; 0 for a named one.
    pub ring_id: u64,
    /// Sequence number of the frame in its ring, from 1.
    pub seq: u64,
    /// CLOCK_MONOTONIC nanoseconds stamped on the frame.
    pub stamp_ns: u64,
    /// Payload bytes.
    pub size: u64,
    /// Image width in pixels (0 for raw data).
    pub width: u32,
    /// Image height in pixels (0 for raw data).
    pub height: u32,
    /// A [`PixelFormat`] code.
    pub format: u32,
    /// Zero.
    pub reserved: u32,
    /// The [`RingHeader::creation_id`] of the ring file that holds the
    /// frame: `seq` means this frame only in that file. A reader whose
    /// mapping has another creation id maps the ring again, and refuses the
    /// notice if the ring's file is still another one (the ring was
    /// replaced since: the frame is gone).
    pub creation_id: u64,
}

impl RingNotice {
    /// A notice from a sample's bytes (a tool that reads ports untyped,
    /// such as the recorder); `None` unless `bytes` is exactly one notice.
    pub fn from_bytes(bytes: &[u8]) -> Option<RingNotice> {
        if bytes.len() != std::mem::size_of::<RingNotice>() {
            return None;
        }
        // SAFETY: the length is checked; every field is an integer or an
        // integer array (FixedName: u32 and bytes, read back clamped), so any
        // bit pattern is a valid RingNotice; read_unaligned needs no alignment.
        Some(unsafe { std::ptr::read_unaligned(bytes.as_ptr().cast::<RingNotice>()) })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::mem::{align_of, offset_of, size_of};

    #[test]
    fn layout_is_stable() {
        assert_eq!(size_of::<RingHeader>(), 256);
        assert_eq!(align_of::<RingHeader>(), 8);
        assert_eq!(offset_of!(RingHeader, slot_capacity), 24);
        assert_eq!(offset_of!(RingHeader, name), 40);
        assert_eq!(offset_of!(RingHeader, writer_pid), 104);
        assert_eq!(offset_of!(RingHeader, last_seq), 112);
        assert_eq!(offset_of!(RingHeader, writer_generation), 120);
        assert_eq!(offset_of!(RingHeader, creation_id), 128);
        assert!(size_of::<RingHeader>() <= RING_HEADER_SIZE as usize);

        assert_eq!(size_of::<SlotHeader>(), SLOT_HEADER_SIZE as usize);
        assert_eq!(align_of::<SlotHeader>(), 8);
        assert_eq!(offset_of!(SlotHeader, len), 24);
        assert_eq!(offset_of!(SlotHeader, format), 40);

        assert_eq!(size_of::<RingNotice>(), 96);
        assert_eq!(align_of::<RingNotice>(), 8);
        assert_eq!(offset_of!(RingNotice, ring_id), 40);
        assert_eq!(offset_of!(RingNotice, seq), 48);
        assert_eq!(offset_of!(RingNotice, creation_id), 88);
        assert_eq!(<RingNotice as Payload>::stable_type_name(), "nerve::RingNotice");
    }

    #[test]
    fn a_notice_comes_back_from_its_bytes() {
        let n = RingNotice { ring: FixedName::new("cam"), seq: 42, width: 640, creation_id: 7, ..Default::default() };
        // SAFETY: a live, initialized value, viewed as its bytes for the test
        let bytes =
            unsafe { std::slice::from_raw_parts((&n as *const RingNotice).cast::<u8>(), size_of::<RingNotice>()) };
        let back = RingNotice::from_bytes(bytes).expect("a whole notice");
        assert_eq!((back.ring.as_str(), back.seq, back.width, back.creation_id), ("cam", 42, 640, 7));
        assert!(RingNotice::from_bytes(&bytes[1..]).is_none(), "a short slice is no notice");
        let mut garbage = vec![0xffu8; size_of::<RingNotice>()];
        garbage[0] = 200;
        assert_eq!(RingNotice::from_bytes(&garbage).map(|n| n.ring.as_str().len()), Some(1), "any bytes read safely");
    }

    #[test]
    fn pixel_format_codes_round_trip() {
        for f in [PixelFormat::Raw, PixelFormat::Rgb8, PixelFormat::Gray8, PixelFormat::Hsi8] {
            assert_eq!(PixelFormat::from_code(f.code()), Some(f));
        }
        assert_eq!(PixelFormat::from_code(99), None);
        assert_eq!(&RING_MAGIC.to_le_bytes(), b"NERVESTM");
    }
}
