//! What the three transports of the `images` scenario share, so that they
//! differ only in how a frame travels:
//!
//! * the frame: an RGB image whose first cache line is a header (sequence
//!   number, batch, readers, flags, stamp) and of which one 64-byte line per
//!   4 KiB page carries a pattern derived from the sequence number. The
//!   writer writes exactly these lines (what a camera's rendering costs is
//!   the same for every transport, so it is kept small and equal); every
//!   reader checks exactly these lines ([`check`]): every page of the frame
//!   is touched, 1/64 of its bytes read, and a frame that is not the one
//!   announced is counted as bad;
//! * the writer's batch loop ([`run_batch`]), paced at a fixed rate or closed
//!   loop, over a [`FramePub`] per transport;
//! * the readers' [`Recorder`]: per frame, when the reader woke and when the
//!   frame was read, written to `<dir>/reader-<i>-<batch>.txt` when the
//!   batch's end frame arrives;
//! * [`Acks`]: the closed-loop ("max") mode's acknowledgements, a counter in
//!   a shared file and a futex, identical for all transports;
//! * the text files between the processes and their parsers.

use crate::shared_page::{SharedPage, futex_wait, futex_wake};
use agent_sdk::clock::{now_ns, sleep_until_ns};
use anyhow::{Context as _, Result, anyhow, bail};
use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU32, Ordering};
use std::time::Duration;

/// A cache line.
pub const LINE: usize = 64;
/// One checked line per this many bytes.
pub const PAGE: usize = 4096;
/// The batch's last frame: readers write their records and do not count it.
pub const FLAG_END: u32 = 1;
/// Closed-loop mode: readers acknowledge the frame.
pub const FLAG_ACK: u32 = 2;

/// An image size (RGB8).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Res {
    /// one letter for names of agents, rings and services
    pub key: char,
    /// pixels
    pub width: u32,
    /// pixels
    pub height: u32,
}

/// The resolutions of issue #4.
pub const RESOLUTIONS: [Res; 3] = [
    Res { key: 'q', width: 320, height: 240 },
    Res { key: 'v', width: 640, height: 480 },
    Res { key: 'h', width: 1920, height: 1080 },
];

impl Res {
    /// Bytes of one RGB frame.
    pub fn bytes(&self) -> usize {
        self.width as usize * self.height as usize * 3
    }

    /// `640x480`.
    pub fn label(&self) -> String {
        format!("{}x{}", self.width, self.height)
    }

    /// One of [`RESOLUTIONS`] from `640x480`.
    pub fn parse(s: &str) -> Result<Res> {
        RESOLUTIONS
            .iter()
            .copied()
            .find(|r| r.label() == s.trim())
            .ok_or_else(|| anyhow!("no resolution {s:?}; use 320x240, 640x480 or 1920x1080"))
    }
}

/// How the writer paces a batch.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Mode {
    /// one frame per period (absolute deadlines); missed deadlines are skipped
    Paced,
    /// closed loop: the next frame as soon as every reader has read the last
    Max,
}

impl Mode {
    /// `paced` or `max`.
    pub fn as_str(self) -> &'static str {
        match self {
            Mode::Paced => "paced",
            Mode::Max => "max",
        }
    }

    fn parse(s: &str) -> Result<Mode> {
        match s {
            "paced" => Ok(Mode::Paced),
            "max" => Ok(Mode::Max),
            _ => bail!("no mode {s:?}"),
        }
    }
}

/// The header line of a frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct FrameHead {
    /// the writer's frame number (from 1)
    pub seq: u64,
    /// the batch
    pub batch: u64,
    /// readers of the batch
    pub n: u32,
    /// [`FLAG_END`], [`FLAG_ACK`]
    pub flags: u32,
    /// the send stamp, where the transport has no header of its own (socket)
    pub stamp_ns: u64,
}

fn pattern(seq: u64, line: usize, word: usize) -> u64 {
    (seq ^ ((line as u64) << 20) ^ ((word as u64) << 56)).wrapping_mul(0x9E37_79B9_7F4A_7C15)
}

/// Checked lines of a frame of `len` bytes: the header line, then one line per page.
pub fn lines(len: usize) -> usize {
    if len < LINE { 0 } else { 1 + (len - LINE) / PAGE }
}

/// Writes the header line and the pattern lines of frame `h` into `len` bytes at `p`.
///
/// # Safety
/// `p` must be valid for writes of `len` bytes (any alignment).
pub unsafe fn fill_raw(p: *mut u8, len: usize, h: &FrameHead) {
    if len < LINE {
        return;
    }
    let w = |off: usize, v: u64| {
        // SAFETY: every offset written is below `len - 7` (LINE-sized lines inside `len`).
        unsafe { p.add(off).cast::<u64>().write_unaligned(v) };
    };
    w(0, h.seq);
    w(8, h.batch);
    w(16, u64::from(h.n) | (u64::from(h.flags) << 32));
    w(24, h.stamp_ns);
    for j in 4..8 {
        w(j * 8, pattern(h.seq, 0, j));
    }
    for k in 1..lines(len) {
        for j in 0..8 {
            w(k * PAGE + j * 8, pattern(h.seq, k, j));
        }
    }
}

/// [`fill_raw`] on a slice.
pub fn fill(buf: &mut [u8], h: &FrameHead) {
    // SAFETY: the slice is valid for writes of its length.
    unsafe { fill_raw(buf.as_mut_ptr(), buf.len(), h) }
}

/// Overwrites the stamp of a filled frame (the socket writer stamps after filling).
pub fn set_stamp(buf: &mut [u8], stamp_ns: u64) {
    if let Some(b) = buf.get_mut(24..32) {
        b.copy_from_slice(&stamp_ns.to_ne_bytes());
    }
}

fn word(bytes: &[u8], off: usize) -> u64 {
    match bytes.get(off..off + 8) {
        // SAFETY: the range is in bounds (checked by `get`); any bytes are a valid u64.
        Some(b) => unsafe { b.as_ptr().cast::<u64>().read_unaligned() },
        None => 0,
    }
}

/// Reads the header line and checks every pattern line of a frame: returns
/// the header and the number of lines that do not match its sequence number.
/// This is all the reading a reader does (the same for every transport).
pub fn check(bytes: &[u8]) -> (FrameHead, u32) {
    let seq = word(bytes, 0);
    let nf = word(bytes, 16);
    let h = FrameHead { seq, batch: word(bytes, 8), n: nf as u32, flags: (nf >> 32) as u32, stamp_ns: word(bytes, 24) };
    let mut bad = 0u32;
    if bytes.len() < LINE {
        return (h, 1);
    }
    if (4..8).any(|j| word(bytes, j * 8) != pattern(seq, 0, j)) {
        bad += 1;
    }
    for k in 1..lines(bytes.len()) {
        let mut ok = true;
        for j in 0..8 {
            ok &= word(bytes, k * PAGE + j * 8) == pattern(seq, k, j);
        }
        bad += u32::from(!ok);
    }
    (h, bad)
}

/// What the orchestrator asks a writer to do.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BatchReq {
    /// unique batch number (from 1)
    pub batch: u64,
    /// readers
    pub n: usize,
    /// pacing
    pub mode: Mode,
    /// frames per second when paced
    pub rate: f64,
    /// length of the batch
    pub seconds: f64,
}

impl BatchReq {
    /// One line: `batch n mode rate seconds`.
    pub fn to_line(self) -> String {
        format!("{} {} {} {} {}", self.batch, self.n, self.mode.as_str(), self.rate, self.seconds)
    }

    /// Parses [`BatchReq::to_line`].
    pub fn parse(s: &str) -> Result<BatchReq> {
        let f: Vec<&str> = s.split_whitespace().collect();
        let [batch, n, mode, rate, seconds] = f[..] else { bail!("bad batch request {s:?}") };
        let r = BatchReq {
            batch: batch.parse().with_context(|| format!("batch in {s:?}"))?,
            n: n.parse().with_context(|| format!("readers in {s:?}"))?,
            mode: Mode::parse(mode)?,
            rate: rate.parse().with_context(|| format!("rate in {s:?}"))?,
            seconds: seconds.parse().with_context(|| format!("seconds in {s:?}"))?,
        };
        if !(r.rate > 0.0 && r.seconds > 0.0 && r.n > 0) {
            bail!("bad batch request {s:?}");
        }
        Ok(r)
    }
}

/// One frame as the writer saw it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct WriterRec {
    /// frame number
    pub seq: u64,
    /// the stamp readers measure from (CLOCK_MONOTONIC ns)
    pub stamp: u64,
    /// the writer's publishing time for this frame, ns (see [`FramePub`])
    pub publish: u64,
}

/// A batch as the writer saw it.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct WriterBatch {
    /// frames, in order (the end frame excluded)
    pub recs: Vec<WriterRec>,
    /// paced: deadlines skipped because the previous frame took longer than a period
    pub skipped: u64,
    /// closed loop: frames not acknowledged by every reader within 1 s
    pub stalls: u64,
}

impl WriterBatch {
    /// Text form: `skipped stalls` then `seq stamp publish` per line.
    pub fn to_text(&self) -> String {
        let mut s = format!("{} {}\n", self.skipped, self.stalls);
        for r in &self.recs {
            s += &format!("{} {} {}\n", r.seq, r.stamp, r.publish);
        }
        s
    }

    /// Parses [`WriterBatch::to_text`].
    pub fn parse(s: &str) -> Result<WriterBatch> {
        let mut lines = s.lines();
        let first = lines.next().ok_or_else(|| anyhow!("empty writer file"))?;
        let [skipped, stalls] = nums::<2>(first)?;
        let recs = lines
            .filter(|l| !l.trim().is_empty())
            .map(|l| nums::<3>(l).map(|[seq, stamp, publish]| WriterRec { seq, stamp, publish }))
            .collect::<Result<_>>()?;
        Ok(WriterBatch { recs, skipped, stalls })
    }
}

/// One frame as a reader saw it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ReaderRec {
    /// frame number
    pub seq: u64,
    /// wake-up (or the end of the previous frame read in the same wake-up), ns
    pub begin: u64,
    /// read and checked, ns
    pub done: u64,
    /// read intact (the frame announced, every line as written)
    pub ok: bool,
}

/// Parses a reader file: `seq begin done ok` per line.
pub fn parse_reader(s: &str) -> Result<Vec<ReaderRec>> {
    s.lines()
        .filter(|l| !l.trim().is_empty())
        .map(|l| nums::<4>(l).map(|[seq, begin, done, ok]| ReaderRec { seq, begin, done, ok: ok == 1 }))
        .collect()
}

fn nums<const N: usize>(l: &str) -> Result<[u64; N]> {
    let mut out = [0u64; N];
    let mut it = l.split_whitespace();
    for o in &mut out {
        let f = it.next().ok_or_else(|| anyhow!("short line {l:?}"))?;
        *o = f.parse().with_context(|| format!("bad number {f:?} in {l:?}"))?;
    }
    if it.next().is_some() {
        bail!("long line {l:?}");
    }
    Ok(out)
}

/// Writes `text` to `path` atomically (temporary file, then rename).
pub fn write_atomic(path: &Path, text: &str) -> std::io::Result<()> {
    let tmp = path.with_extension("tmp");
    {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(text.as_bytes())?;
    }
    std::fs::rename(&tmp, path)
}

/// The acknowledgement counter of the closed-loop mode: one `u32` in a
/// shared file mapping, counted up by readers, waited on by the writer with
/// a futex (the same for all transports).
#[derive(Debug)]
pub struct Acks {
    page: SharedPage,
}

impl Acks {
    /// Creates the file (64 zero bytes).
    pub fn create_file(path: &Path) -> Result<()> {
        std::fs::write(path, [0u8; 64]).with_context(|| format!("cannot create {}", path.display()))
    }

    /// Maps the file.
    pub fn open(path: &Path) -> Result<Acks> {
        Ok(Acks { page: SharedPage::map(path, 64)? })
    }

    fn word(&self) -> &AtomicU32 {
        self.page.word(0)
    }

    /// Writer: no acknowledgement yet (before publishing a frame).
    pub fn reset(&self) {
        self.word().store(0, Ordering::SeqCst);
    }

    /// Reader: one more reader has read the frame; the `n`-th wakes the writer.
    pub fn ack(&self, n: u32) {
        if self.word().fetch_add(1, Ordering::SeqCst) + 1 >= n {
            futex_wake(self.word(), i32::MAX);
        }
    }

    /// Writer: blocks until `n` readers acknowledged, at most `timeout`; false on timeout.
    pub fn wait(&self, n: usize, timeout: Duration) -> bool {
        let end = now_ns() + timeout.as_nanos() as u64;
        loop {
            let v = self.word().load(Ordering::SeqCst);
            if v as usize >= n {
                return true;
            }
            let now = now_ns();
            if now >= end {
                return false;
            }
            futex_wait(self.word(), v, Duration::from_nanos(end - now));
        }
    }
}

/// How a transport publishes one frame to its first `n` readers.
pub trait FramePub {
    /// Publishes frame `h` (filled with [`fill_raw`] in the transport's own
    /// memory) to readers `0..n`; returns the stamp readers measure from and
    /// the publishing time: everything the transport adds to filling the
    /// frame (loaning the memory, sealing, announcing or copying, waking).
    fn publish(&mut self, n: usize, h: &FrameHead) -> Result<(u64, u64)>;
}

/// Runs one batch: frames for `req.seconds` (paced or closed loop), then the
/// end frame. `seq` is the writer's running frame number.
pub fn run_batch(p: &mut dyn FramePub, req: &BatchReq, acks: &Acks, seq: &mut u64) -> Result<WriterBatch> {
    let period = (1e9 / req.rate).max(1.0) as u64;
    let t0 = now_ns() + 1_000_000;
    let end = t0 + (req.seconds * 1e9) as u64;
    let mut out = WriterBatch::default();
    let mut k = 0u64;
    let head = |seq: u64, flags: u32| FrameHead { seq, batch: req.batch, n: req.n as u32, flags, stamp_ns: 0 };
    loop {
        match req.mode {
            Mode::Paced => {
                let d = t0 + k * period;
                if d >= end {
                    break;
                }
                sleep_until_ns(d);
            }
            Mode::Max => {
                if now_ns() >= end {
                    break;
                }
                acks.reset();
            }
        }
        *seq += 1;
        let flags = if req.mode == Mode::Max { FLAG_ACK } else { 0 };
        let (stamp, publish) = p.publish(req.n, &head(*seq, flags)).with_context(|| format!("frame {seq}"))?;
        out.recs.push(WriterRec { seq: *seq, stamp, publish });
        if req.mode == Mode::Max && !acks.wait(req.n, Duration::from_secs(1)) {
            out.stalls += 1;
        }
        // the next deadline still ahead (a slow transport skips the ones it missed)
        let next = (now_ns().saturating_sub(t0) / period + 1).max(k + 1);
        out.skipped += next - (k + 1);
        k = next;
    }
    // let the readers finish the last frame, then end the batch
    std::thread::sleep(Duration::from_millis(20));
    *seq += 1;
    p.publish(req.n, &head(*seq, FLAG_END)).context("end frame")?;
    Ok(out)
}

/// A reader's records of the current batch, written when its end frame comes.
#[derive(Debug)]
pub struct Recorder {
    dir: PathBuf,
    index: usize,
    recs: Vec<(u64, ReaderRec)>,
    acks: Acks,
}

impl Recorder {
    /// Records for reader `index`, files in `dir`, acknowledgements in `acks`.
    pub fn new(dir: PathBuf, index: usize, acks: &Path) -> Result<Recorder> {
        Ok(Recorder { dir, index, recs: Vec::with_capacity(4096), acks: Acks::open(acks)? })
    }

    /// A frame read (`bad` lines did not match); `begin` is the wake-up.
    pub fn frame(&mut self, h: &FrameHead, bad: u32, begin: u64, done: u64) -> Result<()> {
        if h.flags & FLAG_END != 0 {
            return self.flush(h.batch);
        }
        self.recs.push((h.batch, ReaderRec { seq: h.seq, begin, done, ok: bad == 0 }));
        if h.flags & FLAG_ACK != 0 {
            self.acks.ack(h.n);
        }
        Ok(())
    }

    /// A frame announced but not read intact (the ring slot was overwritten).
    pub fn failed(&mut self, seq: u64, begin: u64, done: u64) {
        let batch = self.recs.last().map(|r| r.0).unwrap_or(0);
        self.recs.push((batch, ReaderRec { seq, begin, done, ok: false }));
    }

    fn flush(&mut self, batch: u64) -> Result<()> {
        let mut s = String::with_capacity(self.recs.len() * 48);
        for (b, r) in &self.recs {
            if *b == batch {
                s += &format!("{} {} {} {}\n", r.seq, r.begin, r.done, u8::from(r.ok));
            }
        }
        self.recs.clear();
        let path = reader_file(&self.dir, self.index, batch);
        write_atomic(&path, &s).with_context(|| format!("cannot write {}", path.display()))
    }
}

/// Where reader `index` writes its records of `batch`.
pub fn reader_file(dir: &Path, index: usize, batch: u64) -> PathBuf {
    dir.join(format!("reader-{index}-{batch}.txt"))
}

/// Where the ring writer agent writes its records of `batch`.
pub fn writer_file(dir: &Path, batch: u64) -> PathBuf {
    dir.join(format!("writer-{batch}.txt"))
}

/// Where the ring writer agent finds its next batch request.
pub fn request_file(dir: &Path) -> PathBuf {
    dir.join("request.txt")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fill_then_check() {
        for len in [64usize, 100, 4096 + 64, Res::parse("320x240").expect("res").bytes()] {
            let mut buf = vec![0u8; len];
            let h = FrameHead { seq: 77, batch: 3, n: 8, flags: FLAG_ACK, stamp_ns: 5 };
            fill(&mut buf, &h);
            let (got, bad) = check(&buf);
            assert_eq!((got, bad), (h, 0), "len {len}");
            if len > PAGE {
                buf[PAGE + 9] ^= 1;
                assert_eq!(check(&buf).1, 1);
            }
        }
        assert_eq!(lines(230_400), 57);
        assert_eq!(lines(6_220_800), 1519);
        let (_, bad) = check(&[0u8; 10]);
        assert_eq!(bad, 1);
    }

    #[test]
    fn text_forms_round_trip() {
        let r = BatchReq { batch: 4, n: 8, mode: Mode::Max, rate: 200.0, seconds: 0.5 };
        assert_eq!(BatchReq::parse(&r.to_line()).expect("parse"), r);
        assert!(BatchReq::parse("1 0 paced 200 1").is_err());
        assert!(BatchReq::parse("1 2 fast 200 1").is_err());
        let w = WriterBatch {
            recs: vec![WriterRec { seq: 1, stamp: 10, publish: 2 }, WriterRec { seq: 2, stamp: 20, publish: 3 }],
            skipped: 1,
            stalls: 0,
        };
        assert_eq!(WriterBatch::parse(&w.to_text()).expect("parse"), w);
        let r = parse_reader("1 10 12 1\n2 20 25 0\n").expect("parse");
        assert_eq!(r[1], ReaderRec { seq: 2, begin: 20, done: 25, ok: false });
        assert!(parse_reader("1 2 3\n").is_err());
    }
}
