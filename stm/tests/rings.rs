//! Ring tests with real processes and real shared memory.
//!
//! Child processes are this test binary re-executed with `NERVE_STM_CHILD`
//! set: it then runs only `child_process_entry`, which plays the role named
//! in the variable (reader, crashing writer, ...) and reports on stdout with
//! lines starting with `STM_`. Every test uses its own robot name (and
//! sometimes its own directory); a guard removes its files and kills its
//! children even when the test fails. No assertion depends on timing; waits
//! are bounded by generous timeouts only to turn a hang into a failure.

use nerve_stm::{
    CreateError, FrameDesc, FrameSelector, OpenError, PixelFormat, ReadError, RingName, RingNameError, RingOptions,
    RingReader, RingWriter, WriteError, dump_png, list_rings_with, monotonic_ns,
};
use shm_schemas::RobotName;
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::mpsc;
use std::time::{Duration, Instant};

// ---------------------------------------------------------------- helpers

static COUNTER: AtomicU32 = AtomicU32::new(0);

/// A robot name no other test (or test run) uses.
fn unique_robot() -> RobotName {
    let n = COUNTER.fetch_add(1, Ordering::Relaxed);
    RobotName::new(&format!("stm-{}-{n}", std::process::id())).expect("valid robot name")
}

/// Removes every file of a robot in a directory on drop (and the directory
/// itself if the test made it).
struct ShmGuard {
    dir: PathBuf,
    prefix: String,
    remove_dir: bool,
}

impl ShmGuard {
    fn dev_shm(robot: &RobotName) -> Self {
        ShmGuard { dir: PathBuf::from("/dev/shm"), prefix: robot.shm_prefix(), remove_dir: false }
    }

    /// A fresh private directory (under /dev/shm, so that space checks see tmpfs).
    fn own_dir(robot: &RobotName) -> Self {
        let dir = PathBuf::from(format!("/dev/shm/nerve-stm-test-{}", robot.as_str()));
        std::fs::create_dir_all(&dir).expect("create test dir");
        ShmGuard { dir, prefix: robot.shm_prefix(), remove_dir: true }
    }

    fn opts(&self) -> RingOptions {
        RingOptions { base_dir: self.dir.clone(), group_readable: false }
    }
}

impl Drop for ShmGuard {
    fn drop(&mut self) {
        if let Ok(entries) = std::fs::read_dir(&self.dir) {
            for e in entries.flatten() {
                if e.file_name().to_string_lossy().starts_with(&self.prefix) {
                    let _ = std::fs::remove_file(e.path());
                }
            }
        }
        if self.remove_dir {
            let _ = std::fs::remove_dir_all(&self.dir);
        }
    }
}

/// A child process, killed and reaped on drop, whose `STM_` stdout lines
/// arrive on a channel.
struct ChildGuard {
    child: Child,
    lines: mpsc::Receiver<String>,
}

impl ChildGuard {
    fn spawn(role: &str, robot: &RobotName, dir: &Path, extra: &[(&str, String)]) -> Self {
        let exe = std::env::current_exe().expect("test binary path");
        let mut cmd = Command::new(exe);
        cmd.args(["--exact", "child_process_entry", "--nocapture", "--test-threads=1"])
            .env("NERVE_STM_CHILD", role)
            .env("NERVE_STM_ROBOT", robot.as_str())
            .env("NERVE_STM_DIR", dir)
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit());
        for (k, v) in extra {
            cmd.env(k, v);
        }
        let mut child = cmd.spawn().expect("spawn child");
        let stdout = child.stdout.take().expect("piped stdout");
        let (tx, lines) = mpsc::channel();
        std::thread::spawn(move || {
            for line in BufReader::new(stdout).lines().map_while(Result::ok) {
                // libtest may print "test child_process_entry ... " first
                let Some(at) = line.find("STM_") else { continue };
                if tx.send(line[at..].to_owned()).is_err() {
                    break;
                }
            }
        });
        ChildGuard { child, lines }
    }

    /// The next `STM_` line, within a generous bound.
    fn expect_line(&self, starts_with: &str) -> String {
        let deadline = Instant::now() + Duration::from_secs(120);
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.lines.recv_timeout(left) {
                Ok(l) if l.starts_with(starts_with) => return l,
                Ok(_) => continue,
                Err(e) => panic!("child never printed {starts_with}: {e}"),
            }
        }
    }

    fn wait_success(&mut self) {
        let deadline = Instant::now() + Duration::from_secs(120);
        loop {
            if let Some(st) = self.child.try_wait().expect("try_wait") {
                assert!(st.success(), "child failed: {st}");
                return;
            }
            assert!(Instant::now() < deadline, "child did not finish within 120 s");
            std::thread::sleep(Duration::from_millis(10));
        }
    }

    fn kill(&mut self) {
        let _ = self.child.kill(); // SIGKILL
        let _ = self.child.wait();
    }
}

impl Drop for ChildGuard {
    fn drop(&mut self) {
        self.kill();
    }
}

/// Parses `key=value` from an `STM_` line.
fn field(line: &str, key: &str) -> u64 {
    line.split_whitespace()
        .find_map(|kv| kv.strip_prefix(key).and_then(|v| v.strip_prefix('=')))
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("no {key} in {line:?}"))
}

fn name(s: &str) -> RingName {
    RingName::parse(s).expect("valid ring name")
}

// ------------------------------------------------------- frame content

const CAP: usize = 64 * 1024;

/// Length of frame `seq` in a ring of capacity `cap`: varies from frame to frame.
fn frame_len(seq: u64, cap: usize) -> usize {
    let lo = 64.min(cap);
    lo + (seq.wrapping_mul(7919) as usize) % (cap - lo + 1)
}

fn fnv(bytes: &[u8]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for &b in bytes {
        h = (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3);
    }
    h
}

/// Frame `seq`: its number, a checksum of the rest, pseudo-random bytes.
fn fill_frame(seq: u64, buf: &mut [u8]) {
    let mut x = seq.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
    for chunk in buf[16..].chunks_mut(8) {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        let b = x.to_le_bytes();
        chunk.copy_from_slice(&b[..chunk.len()]);
    }
    let sum = fnv(&buf[16..]);
    buf[..8].copy_from_slice(&seq.to_le_bytes());
    buf[8..16].copy_from_slice(&sum.to_le_bytes());
}

/// Whether `bytes` are exactly frame `seq` (speculative data allowed).
fn frame_ok(seq: u64, bytes: &[u8], cap: usize) -> bool {
    bytes.len() == frame_len(seq, cap)
        && bytes.len() >= 16
        && bytes[..8] == seq.to_le_bytes()
        && bytes[8..16] == fnv(&bytes[16..]).to_le_bytes()
}

fn write_frame(w: &mut RingWriter, seq: u64) {
    let cap = w.slot_capacity();
    assert_eq!(w.next_seq(), seq);
    let n = w.write_with(FrameDesc::raw(), frame_len(seq, cap), |buf| fill_frame(seq, buf)).expect("write");
    assert_eq!(n.seq, seq);
}

// -------------------------------------------------------- child roles

/// Not a test by itself: the entry point of child processes (does nothing
/// when run by the test harness normally).
#[test]
fn child_process_entry() {
    let Ok(role) = std::env::var("NERVE_STM_CHILD") else { return };
    let robot = RobotName::new(&std::env::var("NERVE_STM_ROBOT").expect("robot")).expect("robot name");
    let opts =
        RingOptions { base_dir: PathBuf::from(std::env::var("NERVE_STM_DIR").expect("dir")), group_readable: false };
    let ring = name(&std::env::var("NERVE_STM_RING").unwrap_or_else(|_| "cam".into()));
    let num = |k: &str| std::env::var(k).ok().and_then(|v| v.parse::<u64>().ok()).unwrap_or(0);
    match role.as_str() {
        "reader" => child_reader(&opts, &robot, &ring, num("NERVE_STM_TARGET")),
        "crash_writer" => {
            let mut w = RingWriter::create_with(&opts, &robot, &ring, 8, 4096).expect("create");
            for seq in 1..=5 {
                write_frame(&mut w, seq);
            }
            let _ = w.write_with(FrameDesc::raw(), frame_len(6, 4096), |buf| {
                let half = buf.len() / 2;
                buf[..half].fill(0xEE); // half a frame...
                println!("STM_READY pid={}", std::process::id());
                std::thread::sleep(Duration::from_secs(600)); // ...then SIGKILL
            });
            unreachable!("killed while writing");
        }
        "writer" => {
            let mut w = RingWriter::create_with(&opts, &robot, &ring, 8, 4096).expect("create");
            let first = w.next_seq();
            println!("STM_START next={first}");
            for seq in first..first + num("NERVE_STM_COUNT") {
                write_frame(&mut w, seq);
            }
            println!("STM_DONE last={}", w.last_seq().unwrap_or(0));
        }
        other => panic!("unknown child role {other}"),
    }
}

/// Reads frames every way there is until `target` intact ones were seen;
/// counts torn frames (Ok but wrong content), which must stay zero.
fn child_reader(opts: &RingOptions, robot: &RobotName, ring: &RingName, target: u64) {
    let deadline = Instant::now() + Duration::from_secs(120);
    let r = loop {
        match RingReader::open_with(opts, robot, ring) {
            Ok(r) if r.last_seq().is_some() => break r,
            _ => {
                assert!(Instant::now() < deadline, "ring never appeared");
                std::thread::sleep(Duration::from_millis(5));
            }
        }
    };
    println!("STM_OPENED");
    let cap = r.slot_capacity();
    let (mut good, mut torn, mut overwritten, mut in_progress, mut copies) = (0u64, 0u64, 0u64, 0u64, 0u64);
    let mut torn_detected = 0u64; // overwritten while being read, and caught
    let mut buf = Vec::new();
    let mut i = 0u64;
    while good < target {
        assert!(Instant::now() < deadline, "only {good} good frames within 120 s");
        i += 1;
        let res = match i % 3 {
            // in place, latest
            0 => r.latest_with(|m, bytes| frame_ok(m.seq, bytes, cap)),
            // copy, a random recent frame
            1 => {
                let (lo, hi) = r.seq_range().expect("not empty");
                let seq = lo + (i * 2_654_435_761) % (hi - lo + 1);
                r.read_into(seq, &mut buf).map(|m| {
                    copies += 1;
                    m.seq == seq && frame_ok(seq, &buf, cap)
                })
            }
            // in place, a chosen frame
            _ => {
                let (_, hi) = r.seq_range().expect("not empty");
                r.read_with(hi, |m, bytes| m.seq == hi && frame_ok(hi, bytes, cap))
            }
        };
        match res {
            Ok(true) => good += 1,
            Ok(false) => torn += 1,
            Err(ReadError::Overwritten { during_read, .. }) => {
                overwritten += 1;
                torn_detected += u64::from(during_read);
            }
            Err(ReadError::InProgress { .. }) => in_progress += 1,
            Err(e) => panic!("unexpected read error: {e}"),
        }
    }
    println!(
        "STM_RESULT good={good} torn={torn} overwritten={overwritten} torn_detected={torn_detected} in_progress={in_progress} copies={copies}"
    );
}

// ------------------------------------------------------------- tests

#[test]
fn many_reader_processes_never_see_torn_frames() {
    const GOOD: u64 = 3000;
    let robot = unique_robot();
    let guard = ShmGuard::dev_shm(&robot);
    // few slots, so that the writer laps readers often
    let mut w = RingWriter::create_with(&guard.opts(), &robot, &name("cam"), 4, CAP).expect("create");
    write_frame(&mut w, 1);
    let mut readers: Vec<ChildGuard> = (0..4)
        .map(|_| ChildGuard::spawn("reader", &robot, &guard.dir, &[("NERVE_STM_TARGET", GOOD.to_string())]))
        .collect();
    let deadline = Instant::now() + Duration::from_secs(180);
    let mut seq = 2;
    let mut running = readers.len();
    while running > 0 {
        assert!(Instant::now() < deadline, "readers did not finish within 180 s");
        write_frame(&mut w, seq);
        seq += 1;
        if seq % 64 == 0 {
            running = readers.iter_mut().map(|c| matches!(c.child.try_wait(), Ok(None)) as usize).sum();
        }
    }
    for c in &mut readers {
        let line = c.expect_line("STM_RESULT");
        c.wait_success();
        eprintln!("{line} (writer stored {} frames)", seq - 1);
        assert_eq!(field(&line, "torn"), 0, "a reader got a torn frame: {line}");
        assert!(field(&line, "good") >= GOOD, "{line}");
    }
}

#[test]
fn overwrite_during_read_is_detected() {
    let robot = unique_robot();
    let guard = ShmGuard::dev_shm(&robot);
    let mut w = RingWriter::create_with(&guard.opts(), &robot, &name("ovr"), 2, 1024).expect("create");
    write_frame(&mut w, 1);
    let r = RingReader::open_with(&guard.opts(), &robot, &name("ovr")).expect("open");
    // while the reader looks at frame 2 in place, the writer stores frames 3 and 4
    write_frame(&mut w, 2);
    let res = r.read_with(2, |_, bytes| {
        write_frame(&mut w, 3);
        write_frame(&mut w, 4); // same slot as frame 2
        bytes.to_vec()
    });
    match res {
        Err(ReadError::Overwritten { seq: 2, now: 4, during_read: true, .. }) => {}
        other => panic!("expected a detected overwrite, got {other:?}"),
    }
    // afterwards frame 2 is plainly gone, frame 4 fine, frame 5 not yet there
    assert!(matches!(r.read(2), Err(ReadError::Overwritten { during_read: false, .. })));
    assert!(frame_ok(4, &r.read(4).expect("frame 4").data, 1024));
    assert!(matches!(r.read(5), Err(ReadError::NotYet { seq: 5, last: 4, .. })));
    assert!(matches!(r.read(0), Err(ReadError::ZeroSeq)));
}

#[test]
fn writer_killed_mid_write_leaves_slot_incomplete() {
    let robot = unique_robot();
    let guard = ShmGuard::dev_shm(&robot);
    let ring = name("crash");
    let mut child = ChildGuard::spawn("crash_writer", &robot, &guard.dir, &[("NERVE_STM_RING", ring.to_string())]);
    let ready = child.expect_line("STM_READY");
    let pid = field(&ready, "pid") as u32;

    let r = RingReader::open_with(&guard.opts(), &robot, &ring).expect("open");
    assert_eq!(r.writer_pid(), Some(pid));
    assert_eq!(r.last_seq(), Some(5));
    // the writer is alive and inside write_with: frame 6 is "being written"
    assert!(matches!(r.read(6), Err(ReadError::InProgress { seq: 6, .. })), "{:?}", r.read(6));
    // and a second writer is refused, naming the first
    match RingWriter::create_with(&guard.opts(), &robot, &ring, 8, 4096) {
        Err(e @ CreateError::WriterExists { .. }) => {
            assert!(e.to_string().contains(&format!("pid {pid}")), "{e}");
        }
        other => panic!("second writer not refused: {other:?}"),
    }

    child.kill(); // SIGKILL mid-write, then reaped
    match r.read(6) {
        Err(ReadError::Incomplete { seq: 6, writer_pid, .. }) => assert_eq!(writer_pid, pid),
        other => panic!("expected Incomplete, got {other:?}"),
    }
    assert!(!r.writer_alive());
    for seq in 1..=5 {
        let f = r.read(seq).expect("earlier frames intact");
        assert!(frame_ok(seq, &f.data, 4096), "frame {seq} damaged");
    }
    assert_eq!(r.latest().expect("latest").meta.seq, 5);
    assert_eq!(r.last_k(10).iter().map(|f| f.meta.seq).collect::<Vec<_>>(), vec![1, 2, 3, 4, 5]);

    // the kernel released the dead writer's lock: a new writer takes over
    // and rewrites frame 6
    let mut w = RingWriter::create_with(&guard.opts(), &robot, &ring, 8, 4096).expect("restart after crash");
    assert_eq!(w.next_seq(), 6);
    write_frame(&mut w, 6);
    assert!(frame_ok(6, &r.read(6).expect("frame 6 rewritten").data, 4096));
    assert_eq!(r.writer_generation(), 2);
}

#[test]
fn readers_survive_writer_restart() {
    let robot = unique_robot();
    let guard = ShmGuard::dev_shm(&robot);
    let count = [("NERVE_STM_COUNT", "10".to_string())];
    let mut first = ChildGuard::spawn("writer", &robot, &guard.dir, &count);
    assert_eq!(field(&first.expect_line("STM_DONE"), "last"), 10);
    first.wait_success();

    let r = RingReader::open_with(&guard.opts(), &robot, &name("cam")).expect("open");
    assert_eq!(r.last_seq(), Some(10));
    assert_eq!(r.writer_pid(), None, "a writer that exits cleanly says so");

    let mut second = ChildGuard::spawn("writer", &robot, &guard.dir, &count);
    assert_eq!(field(&second.expect_line("STM_START"), "next"), 11);
    assert_eq!(field(&second.expect_line("STM_DONE"), "last"), 20);
    second.wait_success();

    // the same mapping sees the continued sequence
    assert!(!r.is_stale());
    assert_eq!(r.last_seq(), Some(20));
    assert_eq!(r.writer_generation(), 2);
    let frames = r.last_k(8);
    assert_eq!(frames.iter().map(|f| f.meta.seq).collect::<Vec<_>>(), (13..=20).collect::<Vec<_>>());
    assert!(frames.iter().all(|f| frame_ok(f.meta.seq, &f.data, 4096)));
    assert!(matches!(r.read(12), Err(ReadError::Overwritten { seq: 12, now: 20, .. })));
}

#[test]
fn second_writer_is_refused() {
    let robot = unique_robot();
    let guard = ShmGuard::dev_shm(&robot);
    let _w = RingWriter::create_with(&guard.opts(), &robot, &name("one"), 4, 64).expect("create");
    // flock conflicts between two opens even within one process
    let e = RingWriter::create_with(&guard.opts(), &robot, &name("one"), 4, 64).expect_err("second writer");
    assert!(matches!(e, CreateError::WriterExists { .. }), "{e}");
    let msg = e.to_string();
    assert!(msg.contains("already has a writer") && msg.contains(&format!("pid {}", std::process::id())), "{msg}");
    let e = RingWriter::open_existing_with(&guard.opts(), &robot, &name("one")).expect_err("second writer");
    assert!(matches!(e, CreateError::WriterExists { .. }), "{e}");
}

#[test]
fn oversize_frame_is_refused() {
    let robot = unique_robot();
    let guard = ShmGuard::dev_shm(&robot);
    let mut w = RingWriter::create_with(&guard.opts(), &robot, &name("big"), 4, 1000).expect("create");
    let e = w.write(FrameDesc::raw(), &[0u8; 1001]).expect_err("too large");
    assert!(matches!(e, WriteError::TooLarge { len: 1001, capacity: 1000, .. }));
    let msg = e.to_string();
    assert!(msg.contains("1001") && msg.contains("1000"), "{msg}");
    let e = w.write_with(FrameDesc::raw(), 5000, |_| panic!("must not be called")).expect_err("too large");
    assert!(matches!(e, WriteError::TooLarge { .. }));
    // an image shorter than its size says is refused too
    let e = w.write(FrameDesc::image(20, 20, PixelFormat::Rgb8), &[0u8; 100]).expect_err("short");
    assert!(matches!(e, WriteError::ImageTooShort { needed: 1200, len: 100, .. }));
    // nothing was stored
    assert_eq!(w.next_seq(), 1);
    w.write(FrameDesc::raw(), &[7u8; 1000]).expect("exactly full fits");
}

#[test]
fn bad_ring_names_are_refused() {
    for (bad, what) in [("", "empty"), ("camera7", "at most 6"), ("Cam", "a-z"), ("a-b", "a-z"), ("id-x", "id-<N>")] {
        let e = RingName::parse(bad).expect_err(bad);
        assert!(e.to_string().contains(what), "{bad:?}: {e}");
    }
    assert!(matches!(RingName::parse("x.y"), Err(RingNameError::BadChar { ch: '.', .. })));
    // every allowed form round-trips through a real ring
    let robot = unique_robot();
    let guard = ShmGuard::dev_shm(&robot);
    for n in [RingName::id(u64::MAX), name("a_1"), name("zzzzzz")] {
        let mut w = RingWriter::create_with(&guard.opts(), &robot, &n, 2, 16).expect("create");
        let notice = w.write(FrameDesc::raw(), b"hello").expect("write");
        assert_eq!(RingName::from_notice(&notice), Ok(n));
        assert_eq!(notice.ring_id, n.as_id().unwrap_or(0));
        let r = RingReader::open_with(&guard.opts(), &robot, &n).expect("open by name");
        assert_eq!(r.name(), &n);
        assert_eq!(r.read(notice.seq).expect("read").data, b"hello");
        assert!(w.path().file_name().is_some_and(|f| f.to_string_lossy().starts_with(&robot.shm_prefix())));
    }
}

#[test]
fn geometry_is_checked() {
    let robot = unique_robot();
    let guard = ShmGuard::dev_shm(&robot);
    let ring = name("geo");
    drop(RingWriter::create_with(&guard.opts(), &robot, &ring, 4, 100).expect("create"));
    let e = RingWriter::create_with(&guard.opts(), &robot, &ring, 8, 100).expect_err("mismatch");
    assert!(matches!(e, CreateError::GeometryMismatch { existing_slots: 4, slots: 8, .. }), "{e}");
    let w = RingWriter::open_existing_with(&guard.opts(), &robot, &ring).expect("open existing");
    assert_eq!((w.slot_count(), w.slot_capacity()), (4, 100));
    assert!(matches!(
        RingWriter::open_existing_with(&guard.opts(), &robot, &name("nope")),
        Err(CreateError::NotFound { .. })
    ));
    assert!(matches!(
        RingWriter::create_with(&guard.opts(), &robot, &name("one"), 1, 100),
        Err(CreateError::BadGeometry { .. })
    ));
    // slots larger than any reader accepts are refused up front
    let e =
        RingWriter::create_with(&guard.opts(), &robot, &name("big"), 2, (nerve_stm::MAX_SLOT_CAPACITY + 1) as usize)
            .expect_err("slot too large");
    assert!(matches!(e, CreateError::BadGeometry { .. }) && e.to_string().contains("1 to 1073741824 bytes"), "{e}");
    // far more than the file system holds: refused up front, no file left
    let cap = nerve_stm::MAX_SLOT_CAPACITY as usize;
    let e = RingWriter::create_with(&guard.opts(), &robot, &name("huge"), 1024, cap).expect_err("no space");
    assert!(matches!(e, CreateError::NoSpace { .. }), "{e}");
    assert!(e.to_string().contains("SIGBUS"), "{e}");
    match RingReader::open_with(&guard.opts(), &robot, &name("huge")) {
        Err(OpenError::NotReady { .. }) | Err(OpenError::NotFound { .. }) => {}
        other => panic!("a refused ring must not be readable: {other:?}"),
    }
    assert!(matches!(RingReader::open_with(&guard.opts(), &robot, &name("nope")), Err(OpenError::NotFound { .. })));
}

#[test]
fn permissions_owner_only_unless_asked() {
    use std::os::unix::fs::PermissionsExt;
    let robot = unique_robot();
    let guard = ShmGuard::own_dir(&robot);
    let w = RingWriter::create_with(&guard.opts(), &robot, &name("priv"), 2, 16).expect("create");
    assert_eq!(std::fs::metadata(w.path()).expect("stat").permissions().mode() & 0o777, 0o600);
    let opts = RingOptions { group_readable: true, ..guard.opts() };
    let w = RingWriter::create_with(&opts, &robot, &name("grp"), 2, 16).expect("create");
    assert_eq!(std::fs::metadata(w.path()).expect("stat").permissions().mode() & 0o777, 0o640);
}

#[test]
fn nearest_latest_and_last_k() {
    let robot = unique_robot();
    let guard = ShmGuard::dev_shm(&robot);
    let mut w = RingWriter::create_with(&guard.opts(), &robot, &name("t"), 4, 8).expect("create");
    let r = RingReader::open_with(&guard.opts(), &robot, &name("t")).expect("open");
    assert!(matches!(r.latest(), Err(ReadError::Empty { .. })));
    assert!(matches!(r.nearest_seq(0), Err(ReadError::Empty { .. })));
    assert!(r.last_k(3).is_empty());
    for seq in 1..=6u64 {
        w.write(FrameDesc::raw().stamped(seq * 1000), &seq.to_le_bytes()).expect("write");
    }
    // slots hold 3..=6, stamped 3000..=6000
    assert_eq!(r.nearest_seq(0), Ok(3));
    assert_eq!(r.nearest_seq(4400), Ok(4));
    assert_eq!(r.nearest_seq(4600), Ok(5));
    assert_eq!(r.nearest_seq(4500), Ok(5), "a tie goes to the newer frame");
    assert_eq!(r.nearest_seq(u64::MAX), Ok(6));
    let mut buf = Vec::new();
    let m = r.nearest_into(5100, &mut buf).expect("nearest");
    assert_eq!((m.seq, m.stamp_ns, buf.as_slice()), (5, 5000, &5u64.to_le_bytes()[..]));
    assert_eq!(r.latest().expect("latest").meta.seq, 6);
    assert_eq!(r.latest_with(|m, b| (m.seq, b.to_vec())), Ok((6, 6u64.to_le_bytes().to_vec())));
    assert_eq!(r.last_k(2).iter().map(|f| f.meta.seq).collect::<Vec<_>>(), vec![5, 6]);
    assert_eq!(r.last_k(100).len(), 4);
    assert_eq!(r.seq_range(), Some((3, 6)));
    // default stamps are the monotonic time of storing
    let before = monotonic_ns();
    let n = w.write(FrameDesc::raw(), b"now").expect("write");
    assert!(n.stamp_ns >= before && n.stamp_ns <= monotonic_ns());
}

#[test]
fn list_rings_reports_geometry_and_rate() {
    let robot = unique_robot();
    let guard = ShmGuard::own_dir(&robot);
    let mut a = RingWriter::create_with(&guard.opts(), &robot, &name("cam"), 4, 100).expect("create");
    let _b = RingWriter::create_with(&guard.opts(), &robot, &RingName::id(9), 2, 50).expect("create");
    // another robot's ring in the same directory is not listed
    let other = unique_robot();
    let _guard_other = ShmGuard { dir: guard.dir.clone(), prefix: other.shm_prefix(), remove_dir: false };
    let _c = RingWriter::create_with(&guard.opts(), &other, &name("cam"), 2, 8).expect("create");
    // 10 Hz by stamps
    for seq in 1..=6u64 {
        a.write(FrameDesc::raw().stamped(seq * 100_000_000), b"x").expect("write");
    }
    let list = list_rings_with(&guard.opts(), &robot).expect("list");
    let infos: Vec<_> = list.iter().map(|l| l.info.as_ref().expect("readable")).collect();
    assert_eq!(infos.len(), 2);
    let cam = infos.iter().find(|i| i.name == name("cam")).expect("cam listed");
    assert_eq!((cam.slots, cam.slot_capacity, cam.last_seq), (4, 100, 6));
    let rate = cam.rate_hz.expect("rate");
    assert!((rate - 10.0).abs() < 1e-6, "{rate}");
    assert_eq!(cam.writer_pid, Some(std::process::id()));
    assert!(cam.writer_alive);
    let id9 = infos.iter().find(|i| i.name == RingName::id(9)).expect("id-9 listed");
    assert_eq!((id9.slots, id9.last_seq, id9.rate_hz), (2, 0, None));
}

#[test]
fn dump_png_writes_viewable_images() {
    let robot = unique_robot();
    let guard = ShmGuard::own_dir(&robot);
    let (wd, ht) = (32u32, 24u32);
    let mut w =
        RingWriter::create_with(&guard.opts(), &robot, &name("img"), 4, (wd * ht * 3) as usize).expect("create");
    let rgb: Vec<u8> = (0..wd * ht).flat_map(|i| [(i % wd * 8) as u8, (i / wd * 10) as u8, 200]).collect();
    let n_rgb = w.write(FrameDesc::image(wd, ht, PixelFormat::Rgb8), &rgb).expect("rgb");
    let n_gray = w
        .write_with(FrameDesc::image(wd, ht, PixelFormat::Gray8), (wd * ht) as usize, |b| {
            b.iter_mut().enumerate().for_each(|(i, p)| *p = i as u8)
        })
        .expect("gray");
    // HSI: pure red everywhere
    let hsi: Vec<u8> = (0..wd * ht).flat_map(|_| [0u8, 255, 85]).collect();
    let n_hsi = w.write(FrameDesc::image(wd, ht, PixelFormat::Hsi8), &hsi).expect("hsi");
    let n_raw = w.write(FrameDesc::raw(), b"not an image").expect("raw");
    let r = RingReader::open_with(&guard.opts(), &robot, &name("img")).expect("open");

    let decode = |path: &Path| {
        let dec = png::Decoder::new(std::fs::File::open(path).expect("png file"));
        let mut reader = dec.read_info().expect("png header");
        let mut buf = vec![0; reader.output_buffer_size()];
        let info = reader.next_frame(&mut buf).expect("png data");
        buf.truncate(info.buffer_size());
        (info.width, info.height, info.color_type, buf)
    };
    let p = guard.dir.join("rgb.png");
    dump_png(&r, FrameSelector::Seq(n_rgb.seq), &p).expect("dump rgb");
    assert_eq!(decode(&p), (wd, ht, png::ColorType::Rgb, rgb));

    let p = guard.dir.join("gray.png");
    let m = dump_png(&r, FrameSelector::Nearest(n_gray.stamp_ns), &p).expect("dump gray");
    assert_eq!(m.seq, n_gray.seq);
    let (gw, gh, gc, gbuf) = decode(&p);
    assert_eq!((gw, gh, gc, gbuf[5]), (wd, ht, png::ColorType::Grayscale, 5));

    let p = guard.dir.join("hsi.png");
    dump_png(&r, FrameSelector::Seq(n_hsi.seq), &p).expect("dump hsi");
    let (hw, hh, hc, hbuf) = decode(&p);
    assert_eq!((hw, hh, hc, &hbuf[..3]), (wd, ht, png::ColorType::Rgb, &[255u8, 0, 0][..]));

    let p = guard.dir.join("raw.png");
    assert!(matches!(dump_png(&r, FrameSelector::Latest, &p), Err(nerve_stm::DumpError::NotAnImage { .. })));
    assert_eq!(r.last_seq(), Some(n_raw.seq));
    assert!(!p.exists());
}

/// Writes `value` at byte `offset` of `path` (tampering with a ring file).
fn poke(path: &Path, offset: usize, value: &[u8]) {
    use std::os::unix::fs::FileExt;
    let f = std::fs::OpenOptions::new().write(true).open(path).expect("open ring file for tampering");
    f.write_all_at(value, offset as u64).expect("tamper");
}

#[test]
fn foreign_or_writable_ring_files_are_refused() {
    use std::os::unix::fs::PermissionsExt;
    let robot = unique_robot();
    let guard = ShmGuard::own_dir(&robot);
    let ring = name("cam");
    let mut w = RingWriter::create_with(&guard.opts(), &robot, &ring, 2, 16).expect("create");
    w.write(FrameDesc::raw(), b"frame").expect("write");
    let path = w.path().to_owned();
    drop(w);
    assert!(RingReader::open_with(&guard.opts(), &robot, &ring).is_ok(), "our own 0600 ring reads");

    // world-writable: anyone could feed fake frames
    std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o666)).expect("chmod");
    let e = RingReader::open_with(&guard.opts(), &robot, &ring).expect_err("a world-writable ring is refused");
    assert!(matches!(e, OpenError::Untrusted { mode: 0o666, .. }), "{e}");
    let msg = e.to_string();
    assert!(msg.contains(&path.display().to_string()) && msg.contains("0666") && msg.contains("remove it"), "{msg}");
    // group-writable too
    std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o620)).expect("chmod");
    assert!(matches!(RingReader::open_path(&path), Err(OpenError::Untrusted { .. })));
    // `nerve mem list` lists it with the reason instead of reading it
    let listed = list_rings_with(&guard.opts(), &robot).expect("list");
    assert!(matches!(listed[0].info, Err(OpenError::Untrusted { .. })), "{:?}", listed[0].info);

    // another user's file (needs root to make one)
    std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o644)).expect("chmod");
    if nix::unistd::geteuid().is_root() {
        std::os::unix::fs::chown(&path, Some(65534), Some(65534)).expect("chown to nobody");
        let e = RingReader::open_path(&path).expect_err("a foreign ring is refused");
        assert!(matches!(e, OpenError::Untrusted { owner: 65534, me: 0, .. }), "{e}");
        assert!(e.to_string().contains("uid 65534"), "{e}");
        // and its writer says what to do
        let e = RingWriter::create_with(&guard.opts(), &robot, &ring, 2, 16).expect_err("not ours");
        assert!(matches!(e, CreateError::NotOwner { owner: 65534, .. }) && e.to_string().contains("remove it"), "{e}");
    }
}

#[test]
fn hostile_ring_headers_are_refused_before_mapping_or_allocating() {
    use shm_schemas::ring::RingHeader;
    use std::mem::offset_of;
    let robot = unique_robot();
    let guard = ShmGuard::own_dir(&robot);
    let ring = name("cam");
    let w = RingWriter::create_with(&guard.opts(), &robot, &ring, 2, 64).expect("create");
    let path = w.path().to_owned();
    drop(w);
    let stride: u64 = 128; // 64 bytes of payload + 64 of slot header

    // 2^32-1 slots declared, in a sparse file as large as they say
    poke(&path, offset_of!(RingHeader, slot_count), &u32::MAX.to_ne_bytes());
    let f = std::fs::OpenOptions::new().write(true).open(&path).expect("open");
    f.set_len(4096 + stride * u64::from(u32::MAX)).expect("sparse file");
    let e = RingReader::open_path(&path).expect_err("2^32-1 slots are refused");
    assert!(matches!(e, OpenError::NotARing { .. }), "{e}");
    let listed = list_rings_with(&guard.opts(), &robot).expect("list");
    assert!(matches!(listed[0].info, Err(OpenError::NotARing { .. })), "{:?}", listed[0].info);

    // one slot more than MAX_SLOTS, in a file of that size (fits tmpfs: sparse)
    let slots = nerve_stm::MAX_SLOTS + 1;
    poke(&path, offset_of!(RingHeader, slot_count), &slots.to_ne_bytes());
    f.set_len(4096 + stride * u64::from(slots)).expect("sparse file");
    let e = RingReader::open_path(&path).expect_err("more than MAX_SLOTS slots are refused");
    assert!(matches!(e, OpenError::NotARing { .. }), "{e}");

    // an absurd slot capacity and stride, in a file of that size
    let cap = nerve_stm::MAX_SLOT_CAPACITY * 2;
    poke(&path, offset_of!(RingHeader, slot_count), &2u32.to_ne_bytes());
    poke(&path, offset_of!(RingHeader, slot_capacity), &cap.to_ne_bytes());
    poke(&path, offset_of!(RingHeader, slot_stride), &(cap + 64).to_ne_bytes());
    f.set_len(4096 + 2 * (cap + 64)).expect("sparse file");
    let e = RingReader::open_path(&path).expect_err("an absurd slot capacity is refused");
    assert!(matches!(e, OpenError::NotARing { .. }), "{e}");
}

#[test]
fn implausible_ring_state_is_recreated_on_reopen() {
    use shm_schemas::ring::{RingHeader, SlotHeader};
    use std::mem::offset_of;
    use std::os::unix::fs::MetadataExt;
    let robot = unique_robot();
    let guard = ShmGuard::own_dir(&robot);
    let ring = name("cam");
    let stride = 64 + 64; // a slot of 8 bytes padded to 64, plus its header
    let lock_of = |slot: usize| 4096 + slot * stride + offset_of!(SlotHeader, lock);
    let fresh = || {
        let mut w = RingWriter::create_with(&guard.opts(), &robot, &ring, 4, 8).expect("create");
        for seq in 1..=3u64 {
            w.write(FrameDesc::raw(), &seq.to_le_bytes()).expect("write");
        }
        let (path, ino) = (w.path().to_owned(), std::fs::metadata(w.path()).expect("stat").ino());
        drop(w);
        (path, ino)
    };

    // a plausible ring continues where it stopped
    let (path, ino) = fresh();
    let w = RingWriter::create_with(&guard.opts(), &robot, &ring, 4, 8).expect("reopen");
    assert_eq!((w.next_seq(), std::fs::metadata(&path).expect("stat").ino()), (4, ino));
    drop(w);

    let cases: [(&str, usize, u64); 4] = [
        ("last_seq at 2^63 (2*seq overflows)", offset_of!(RingHeader, last_seq), 1 << 63),
        ("last_seq at 2^62", offset_of!(RingHeader, last_seq), 1 << 62),
        ("a lock word near u64::MAX", lock_of(1), u64::MAX - 1),
        ("frame 6 in slot 1 of 4", lock_of(1), 12),
    ];
    for (what, offset, value) in cases {
        let (path, ino) = fresh();
        poke(&path, offset, &value.to_ne_bytes());
        let reader_of_old = RingReader::open_path(&path).expect("open the tampered ring");
        let mut w = RingWriter::create_with(&guard.opts(), &robot, &ring, 4, 8)
            .unwrap_or_else(|e| panic!("{what}: an implausible ring is recreated, not refused: {e}"));
        assert_eq!(w.next_seq(), 1, "{what}: the recreated ring starts over");
        assert_ne!(std::fs::metadata(&path).expect("stat").ino(), ino, "{what}: a new file");
        assert!(reader_of_old.is_stale(), "{what}: old readers notice the replacement");
        let n = w.write(FrameDesc::raw(), b"fresh").expect("write");
        let r = RingReader::open_path(&path).expect("open the new ring");
        assert_eq!(r.read(n.seq).expect("read").data, b"fresh", "{what}");
        drop(w);
        // open_existing recreates it too (with the geometry in the file)
        poke(&path, offset, &value.to_ne_bytes());
        let w = RingWriter::open_existing_with(&guard.opts(), &robot, &ring).expect("open existing");
        assert_eq!((w.next_seq(), w.slot_count(), w.slot_capacity()), (1, 4, 8), "{what}");
        drop(w);
        std::fs::remove_file(&path).expect("remove");
    }
}

#[test]
fn dump_png_refuses_absurd_frame_sizes_from_the_ring() {
    use shm_schemas::ring::SlotHeader;
    use std::mem::offset_of;
    let robot = unique_robot();
    let guard = ShmGuard::own_dir(&robot);
    let mut w = RingWriter::create_with(&guard.opts(), &robot, &name("img"), 2, 32 * 24 * 3).expect("create");
    let n = w.write(FrameDesc::image(32, 24, PixelFormat::Rgb8), &[7u8; 32 * 24 * 3]).expect("write");
    // a misbehaving writer's slot header: 0xFFFF_FFFF x 0xFFFF_FFFF rgb8
    let slot = 4096 + n.slot as usize * (32 * 24 * 3 + 64);
    poke(w.path(), slot + offset_of!(SlotHeader, width), &u32::MAX.to_ne_bytes());
    poke(w.path(), slot + offset_of!(SlotHeader, height), &u32::MAX.to_ne_bytes());
    let r = RingReader::open_with(&guard.opts(), &robot, &name("img")).expect("open");
    let p = guard.dir.join("absurd.png");
    let e = dump_png(&r, FrameSelector::Seq(n.seq), &p).expect_err("absurd sizes are refused");
    assert!(matches!(e, nerve_stm::DumpError::BadSize { width: u32::MAX, height: u32::MAX, .. }), "{e}");
    assert!(!p.exists());
}

/// Review R18: a ring replaced by one of another geometry starts over at
/// frame 1. Its notices carry the new file's creation id, so a reader of
/// the old file refuses them (and maps the ring again), and a notice of the
/// old file is refused by a reader of the new one: frame N of one file is
/// never handed out as frame N of the other.
#[test]
fn notices_name_the_ring_file_and_a_replaced_ring_refuses_old_ones() {
    let robot = unique_robot();
    let guard = ShmGuard::own_dir(&robot);
    let ring = name("cam");
    let mut w = RingWriter::create_with(&guard.opts(), &robot, &ring, 4, 64).expect("create");
    let old: Vec<_> = (1..=3u8).map(|k| w.write(FrameDesc::raw(), &[k; 64]).expect("write")).collect();
    assert!(old.iter().all(|n| n.creation_id == w.creation_id() && n.creation_id != 0));
    let r_old = RingReader::open_with(&guard.opts(), &robot, &ring).expect("open");
    assert_eq!(r_old.creation_id(), w.creation_id());
    r_old.check_notice(&old[0]).expect("a notice of the mapped file");

    // another geometry: the file is replaced, the sequence starts over
    w.remove().expect("remove");
    let mut w = RingWriter::create_with(&guard.opts(), &robot, &ring, 8, 128).expect("recreate");
    let new1 = w.write(FrameDesc::raw(), &[101; 128]).expect("write");
    assert_eq!(new1.seq, 1);
    assert_ne!(new1.creation_id, old[0].creation_id, "every ring file draws its own creation id");
    let e = r_old.check_notice(&new1).expect_err("a notice of the new file, checked against the old mapping");
    assert!(matches!(e, ReadError::OtherRing { seq: 1, .. }), "{e}");
    assert!(r_old.is_stale());
    // the old mapping still holds frame 1, the old one: that is what must not be returned
    assert_eq!(r_old.read(1).expect("old frame 1").data, [1; 64]);

    let r_new = RingReader::open_with(&guard.opts(), &robot, &ring).expect("open again");
    r_new.check_notice(&new1).expect("the new notice in the new file");
    assert_eq!(r_new.read(new1.seq).expect("new frame 1").data, [101; 128]);
    let e = r_new.check_notice(&old[0]).expect_err("a notice of the old file");
    assert!(e.to_string().contains("replaced") && e.to_string().contains("cam"), "{e}");
    assert!(r_new.check_notice(&nerve_stm::RingNotice::default()).is_err(), "creation ids are never 0");

    // a writer restart keeps the file, so the creation id and old notices stay good
    drop(w);
    let w = RingWriter::create_with(&guard.opts(), &robot, &ring, 8, 128).expect("reopen");
    assert_eq!(w.creation_id(), new1.creation_id);
    r_new.check_notice(&new1).expect("same file after a writer restart");
}

/// A ring file of an older layout (version 1 has no creation id) is
/// recreated by its writer, never continued, and refused by readers.
#[test]
fn a_ring_of_an_older_layout_is_recreated_by_its_writer() {
    use shm_schemas::ring::RingHeader;
    use std::mem::offset_of;
    use std::os::unix::fs::MetadataExt;
    let robot = unique_robot();
    let guard = ShmGuard::own_dir(&robot);
    let ring = name("old");
    let mut w = RingWriter::create_with(&guard.opts(), &robot, &ring, 4, 8).expect("create");
    w.write(FrameDesc::raw(), b"12345678").expect("write");
    let path = w.path().to_owned();
    let ino = std::fs::metadata(&path).expect("stat").ino();
    drop(w);
    poke(&path, offset_of!(RingHeader, layout_version), &1u32.to_ne_bytes());
    poke(&path, offset_of!(RingHeader, creation_id), &0u64.to_ne_bytes());
    let e = RingReader::open_path(&path).expect_err("an old layout");
    assert!(matches!(e, OpenError::NotARing { .. }) && e.to_string().contains("layout version 1"), "{e}");
    // without a geometry to create it with, the writer cannot replace it
    let e = RingWriter::open_existing_with(&guard.opts(), &robot, &ring).expect_err("no geometry");
    assert!(e.to_string().contains("layout version 1"), "{e}");
    let w = RingWriter::create_with(&guard.opts(), &robot, &ring, 4, 8).expect("recreated");
    assert_eq!(w.next_seq(), 1, "a recreated ring starts over");
    assert_ne!(w.creation_id(), 0);
    assert_ne!(std::fs::metadata(&path).expect("stat").ino(), ino, "a new file");
    RingReader::open_path(&path).expect("readable again");
}
