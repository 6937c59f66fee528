//! The persisted connection list: `<state>/connections.json`, written
//! atomically (temporary file, fsync, rename, fsync of the directory) so that
//! a router killed at any moment leaves either the old or the new list.
//!
//! The router writes through a [`Writer`] thread: the fsyncs take tens of
//! milliseconds on a busy disk, and a router blocked in them made the next
//! `nerve connect` (or a decision maker's rewiring) wait. The thread writes
//! the newest body it has been given for each file, skipping bodies
//! overtaken meanwhile, and is flushed when the router stops. It writes the
//! supervision list ([`crate::supervision`]) the same way.
//!
//! A rewire is answered once its list is on disk, which for the connection
//! list means in its journal (`connections.json.journal`, [`crate::journal`]):
//! one synced append instead of the two syncs of an atomic rewrite. The file
//! itself is rewritten right after, and [`Store::load`] takes the journal's
//! list when a router stopped before that.
//!
//! A file that cannot be read (corrupt, truncated, a hand edit gone wrong, a
//! version this router does not know) does not keep the router from
//! starting: it is moved aside as `connections.json.corrupt-<time>` with a
//! loud message, and the last good copy (`connections.json.bak`, refreshed
//! at every successful load) is used instead.

use crate::journal;
use serde::{Deserialize, Serialize};
use shm_schemas::PortRef;
use std::io::Write;
use std::path::{Path, PathBuf};

/// One connection: output port → input port, with the checked payload type.
/// The ports are written `agent/port` in the file, as they always were.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Connection {
    /// the output
    #[serde(with = "port_text")]
    pub from: PortRef,
    /// the input
    #[serde(with = "port_text")]
    pub to: PortRef,
    /// payload type name
    #[serde(rename = "type")]
    pub type_name: String,
    /// it may close a loop of event-driven agents ([`shm_schemas::cycles`])
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub allow_cycle: bool,
}

/// Version of the file's layout.
pub const FILE_VERSION: u32 = 1;

/// A port as the file writes it: `agent/port`.
mod port_text {
    use serde::{Deserialize as _, Deserializer, Serializer};
    use shm_schemas::PortRef;

    pub fn serialize<S: Serializer>(p: &PortRef, s: S) -> Result<S::Ok, S::Error> {
        s.collect_str(p)
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<PortRef, D::Error> {
        let text = String::deserialize(d)?;
        text.parse().map_err(|e| serde::de::Error::custom(format!("{text:?} does not name a port AGENT/PORT ({e})")))
    }
}

#[derive(Debug, Serialize, Deserialize)]
struct File {
    version: u32,
    connections: Vec<Connection>,
}

fn parse(bytes: &[u8]) -> Result<Vec<Connection>, String> {
    let f: File = serde_json::from_slice(bytes).map_err(|e| e.to_string())?;
    if f.version != FILE_VERSION {
        return Err(format!(
            "version {} (this router reads version {FILE_VERSION}); it was written by another nerve",
            f.version
        ));
    }
    let mut list: Vec<Connection> = Vec::new();
    for c in f.connections {
        if !list.contains(&c) {
            list.push(c);
        }
    }
    Ok(list)
}

/// Where the connection list lives.
#[derive(Debug, Clone)]
pub struct Store {
    path: PathBuf,
}

impl Store {
    /// The store in `state_dir`.
    pub fn new(state_dir: &Path) -> Self {
        Store { path: state_dir.join("connections.json") }
    }

    /// The file's path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The last good copy.
    pub fn backup_path(&self) -> PathBuf {
        self.path.with_extension("json.bak")
    }

    /// Loads the list: the file's, or its journal's when a router stopped
    /// between answering a rewire and rewriting the file (the journal is
    /// then written into the file and emptied, so that nothing is appended
    /// after a record a crash may have torn). A missing file is an empty
    /// list. A file that cannot be used is moved aside and the last good
    /// copy loaded instead, each said loudly; only a file that cannot even
    /// be read is an error.
    pub fn load(&self) -> Result<Vec<Connection>, String> {
        // the journal first: emptied only once the file is written, it is
        // then never older than the file read after it
        let journal = journal::path_for(&self.path);
        let contents = journal::read(&journal);
        let from_file = self.load_file()?;
        let contents = match contents {
            Ok(c) => c,
            Err(e) => {
                tracing::warn!(file = %journal.display(), "cannot read the connection list's journal: {e}; using {}", self.path.display());
                return Ok(from_file);
            }
        };
        let list = match contents.last.as_deref().map(|body| (body, parse(body))) {
            None => from_file,
            Some((body, Ok(list))) => {
                if list != from_file {
                    tracing::info!(
                        file = %journal.display(),
                        "the router stopped before it rewrote {}: its journal holds the newer list ({} connection(s) against {})",
                        self.path.display(),
                        list.len(),
                        from_file.len()
                    );
                    if let Err(e) = write_atomic(&self.path, body) {
                        tracing::warn!(file = %self.path.display(), "cannot rewrite the connection list: {e}; its journal keeps it");
                        // the next record must follow a whole one to be read
                        if contents.whole < contents.bytes
                            && let Err(e) = journal::cut_to_whole(&journal, contents.whole)
                        {
                            tracing::warn!(file = %journal.display(), "cannot cut the journal's torn tail: {e}");
                        }
                        return Ok(list);
                    }
                }
                list
            }
            Some((_, Err(why))) => {
                tracing::warn!(file = %journal.display(), "the journal's last record cannot be used ({why}); using {}", self.path.display());
                from_file
            }
        };
        if contents.bytes > 0
            && let Err(e) = journal::clear(&journal)
        {
            tracing::warn!(file = %journal.display(), "cannot empty the connection list's journal: {e}");
        }
        Ok(list)
    }

    /// The file's list (see [`Store::load`]).
    fn load_file(&self) -> Result<Vec<Connection>, String> {
        let bytes = match std::fs::read(&self.path) {
            Ok(b) => b,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Vec::new()),
            Err(e) => return Err(format!("cannot read {}: {e}", self.path.display())),
        };
        match parse(&bytes) {
            Ok(list) => {
                // the last good copy, for the day this file is damaged
                if let Err(e) = write_private(&self.backup_path(), &bytes) {
                    tracing::warn!(
                        "cannot keep a copy of the connection list in {}: {e}",
                        self.backup_path().display()
                    );
                }
                Ok(list)
            }
            Err(why) => {
                let secs =
                    std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_secs());
                let aside = self.path.with_extension(format!("json.corrupt-{secs}"));
                let moved = std::fs::rename(&self.path, &aside).is_ok();
                let backup = std::fs::read(self.backup_path()).ok().and_then(|b| parse(&b).ok());
                tracing::error!(
                    file = %self.path.display(),
                    "THE CONNECTION LIST CANNOT BE USED: {why}; {}; {}",
                    if moved { format!("moved aside to {}", aside.display()) } else { "left in place".into() },
                    match &backup {
                        Some(l) => format!("starting from the last good copy {} ({} connection(s))", self.backup_path().display(), l.len()),
                        None => "no good copy exists: starting with no connections (relaunch to restore them)".into(),
                    }
                );
                Ok(backup.unwrap_or_default())
            }
        }
    }

    /// The file's bytes for `connections`.
    pub fn encode(connections: &[Connection]) -> Vec<u8> {
        serde_json::to_vec_pretty(&File { version: FILE_VERSION, connections: connections.to_vec() })
            .unwrap_or_default()
    }

    /// Saves the list atomically, here and now (the router saves through
    /// its [`Writer`]); the journal is emptied, as it is no newer.
    pub fn save(&self, connections: &[Connection]) -> std::io::Result<()> {
        write_atomic(&self.path, &Self::encode(connections))?;
        journal::clear(&journal::path_for(&self.path))
    }
}

/// Writes `path` atomically and durably: [`write_private`], then a sync of
/// its directory so that the rename survives a power cut.
pub fn write_atomic(path: &Path, body: &[u8]) -> std::io::Result<()> {
    let dir = path.parent().unwrap_or(Path::new("."));
    std::fs::create_dir_all(dir)?;
    write_private(path, body)?;
    std::fs::File::open(dir)?.sync_all()
}

/// Writes `path` atomically: a fresh temporary name beside it, created
/// exclusively, never through a symlink, readable by its owner only, synced,
/// then renamed over `path` (review R1, R11d, R24).
pub(crate) fn write_private(path: &Path, body: &[u8]) -> std::io::Result<()> {
    use std::os::unix::fs::OpenOptionsExt;
    let tmp = path.with_extension(format!(
        "{}.{}.tmp",
        path.extension().and_then(|e| e.to_str()).unwrap_or(""),
        std::process::id()
    ));
    let _ = std::fs::remove_file(&tmp);
    {
        let mut f = std::fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .mode(0o600)
            .custom_flags(libc::O_NOFOLLOW)
            .open(&tmp)?;
        f.write_all(body)?;
        f.sync_all()?;
    }
    std::fs::rename(&tmp, path)
}

/// What the writer thread does to one file.
#[derive(Debug)]
enum Job {
    /// Write this body atomically.
    Write(Vec<u8>),
    /// Append this body to the file's journal, then write it atomically
    /// once nothing else waits ([`crate::journal`]).
    Journaled(Vec<u8>),
    /// Remove the file.
    Remove,
}

/// A queued save, to learn when it is on disk ([`Writer::outcome`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub struct Saved(u64);

/// How far the writer thread got: every save up to `done` was attempted;
/// those that failed are in `failed` (the newest [`MAX_FAILED`]).
#[derive(Debug, Default)]
struct Progress {
    done: std::sync::atomic::AtomicU64,
    failed: std::sync::Mutex<std::collections::VecDeque<(u64, String)>>,
}

/// How many failed saves are remembered for their callers.
const MAX_FAILED: usize = 256;

/// Saves files on a thread of its own, the newest body of each file only.
/// Each save is numbered, so that a caller can answer only once its change
/// is on disk (review R11a: `nerve connect` was acknowledged before the
/// save, and a failed save was only logged).
#[derive(Debug)]
pub struct Writer {
    tx: Option<std::sync::mpsc::Sender<Queued>>,
    thread: Option<std::thread::JoinHandle<()>>,
    queued: std::sync::atomic::AtomicU64,
    progress: std::sync::Arc<Progress>,
}

impl Writer {
    /// Starts the thread.
    pub fn start() -> std::io::Result<Self> {
        let (tx, rx) = std::sync::mpsc::channel::<Queued>();
        let progress = std::sync::Arc::new(Progress::default());
        let shared = progress.clone();
        let thread = std::thread::Builder::new().name("persist".into()).spawn(move || persist(&rx, &shared))?;
        Ok(Writer { tx: Some(tx), thread: Some(thread), queued: 0.into(), progress })
    }

    /// Queues the connection list `list` to be saved into `store`.
    pub fn save(&self, store: &Store, list: &[Connection]) -> Saved {
        self.journaled(store.path(), Store::encode(list))
    }

    /// Queues `body` to be written atomically to `path`.
    pub fn write(&self, path: &Path, body: Vec<u8>) -> Saved {
        self.send(path, Job::Write(body))
    }

    /// Queues `body` for `path` through its journal: the save is done once
    /// the journal has it, and the file is rewritten right after.
    pub fn journaled(&self, path: &Path, body: Vec<u8>) -> Saved {
        self.send(path, Job::Journaled(body))
    }

    /// Queues the removal of `path`.
    pub fn remove(&self, path: &Path) -> Saved {
        self.send(path, Job::Remove)
    }

    fn send(&self, path: &Path, job: Job) -> Saved {
        let seq = self.queued.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
        if let Some(tx) = &self.tx
            && tx.send((path.to_owned(), job, seq)).is_err()
        {
            let mut failed = self.progress.failed.lock().unwrap_or_else(|p| p.into_inner());
            failed.push_back((seq, "the persisting thread is gone".into()));
            self.progress.done.fetch_max(seq, std::sync::atomic::Ordering::Release);
        }
        Saved(seq)
    }

    /// What became of save `saved`: `None` while it is queued, then whether
    /// it reached the disk (and if not, why).
    pub fn outcome(&self, saved: Saved) -> Option<Result<(), String>> {
        if self.progress.done.load(std::sync::atomic::Ordering::Acquire) < saved.0 {
            return None;
        }
        let failed = self.progress.failed.lock().unwrap_or_else(|p| p.into_inner());
        Some(match failed.iter().find(|(s, _)| *s == saved.0) {
            Some((_, why)) => Err(why.clone()),
            None => Ok(()),
        })
    }

    /// Waits until every queued file is saved.
    pub fn flush(&mut self) {
        self.tx.take();
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

type Queued = (PathBuf, Job, u64);

/// The writer thread: saves what comes until the channel closes, then
/// brings every journaled file up to date.
fn persist(rx: &std::sync::mpsc::Receiver<Queued>, progress: &Progress) {
    // files whose journal holds a newer body than they do, oldest first
    let mut behind: Vec<(PathBuf, Vec<u8>)> = Vec::new();
    let mut next: Option<Queued> = None;
    while let Some((path, job, seq)) = next.take().or_else(|| rx.recv().ok()) {
        // a newer body of a file makes the older ones pointless (their
        // callers learn the newer one's outcome); the order of files is kept
        let mut batch: Vec<(PathBuf, Job, Vec<u64>)> = vec![(path, job, vec![seq])];
        let mut last = seq;
        while let Ok((path, job, seq)) = rx.try_recv() {
            last = seq;
            match batch.iter_mut().find(|(p, _, _)| *p == path) {
                Some(slot) => {
                    slot.1 = job;
                    slot.2.push(seq);
                }
                None => batch.push((path, job, vec![seq])),
            }
        }
        for (path, job, seqs) in batch {
            let done = match job {
                Job::Write(body) => write_atomic(&path, &body),
                Job::Journaled(body) => match journal::append(&journal::path_for(&path), &body) {
                    Ok(()) => {
                        behind.retain(|(p, _)| *p != path);
                        behind.push((path.clone(), body));
                        Ok(())
                    }
                    Err(e) => write_past_journal(&path, &body, &e).inspect(|()| behind.retain(|(p, _)| *p != path)),
                },
                Job::Remove => match std::fs::remove_file(&path) {
                    Err(e) if e.kind() != std::io::ErrorKind::NotFound => Err(e),
                    _ => Ok(()),
                },
            };
            if let Err(e) = done {
                tracing::error!(file = %path.display(), "cannot save: {e}");
                let mut failed = progress.failed.lock().unwrap_or_else(|p| p.into_inner());
                for s in seqs {
                    if failed.len() == MAX_FAILED {
                        failed.pop_front();
                    }
                    failed.push_back((s, format!("cannot save {}: {e}", path.display())));
                }
            }
        }
        progress.done.store(last, std::sync::atomic::Ordering::Release);
        // the files themselves, while no save waits
        while !behind.is_empty() {
            match rx.try_recv() {
                Ok(q) => {
                    next = Some(q);
                    break;
                }
                // closed: flushing, every file is brought up to date
                Err(std::sync::mpsc::TryRecvError::Disconnected | std::sync::mpsc::TryRecvError::Empty) => {}
            }
            let (path, body) = behind.remove(0);
            catch_up(&path, &body);
        }
    }
    for (path, body) in behind {
        catch_up(&path, &body);
    }
}

/// Writes a journaled file whose journal has its newest body, then empties
/// the journal.
fn catch_up(path: &Path, body: &[u8]) {
    let journal = journal::path_for(path);
    match write_atomic(path, body) {
        Ok(()) => {
            if let Err(e) = journal::clear(&journal) {
                tracing::warn!(file = %journal.display(), "cannot empty the journal: {e}");
            }
        }
        Err(e) => tracing::error!(
            file = %path.display(),
            "cannot rewrite the file: {e}; its journal {} keeps the newest body, read at the next start",
            journal.display()
        ),
    }
}

/// The journal of `path` could not take `body` (`why`): the file is
/// written atomically instead, as it was before journals, once the journal
/// is gone (an older record left there would win over the file at the next
/// start).
fn write_past_journal(path: &Path, body: &[u8], why: &std::io::Error) -> std::io::Result<()> {
    let journal = journal::path_for(path);
    tracing::warn!(file = %journal.display(), "cannot append to the journal: {why}; writing {} itself", path.display());
    match std::fs::remove_file(&journal) {
        Err(e) if e.kind() != std::io::ErrorKind::NotFound => {
            return Err(std::io::Error::new(
                e.kind(),
                format!("its journal {} can be neither written ({why}) nor removed ({e})", journal.display()),
            ));
        }
        _ => {}
    }
    write_atomic(path, body)
}

impl Drop for Writer {
    fn drop(&mut self) {
        self.flush();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn save_and_load() {
        let dir = fresh_dir("test");
        let store = Store::new(&dir);
        assert_eq!(store.load(), Ok(vec![]));
        let c = vec![Connection {
            from: port("t1/tick"),
            to: port("r1/in"),
            type_name: "nerve::Tick".into(),
            allow_cycle: false,
        }];
        store.save(&c).expect("saves");
        assert_eq!(store.load(), Ok(c));
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_list_in_the_journal_only_is_loaded_and_written_into_the_file() {
        let dir = fresh_dir("journal");
        let store = Store::new(&dir);
        store.save(&[conn("a/out")]).expect("saves");
        // a router killed after it answered a rewire, before it rewrote the file
        let journal = journal::path_for(store.path());
        journal::append(&journal, &Store::encode(&[conn("a/out"), conn("x/out")])).expect("append");
        assert_eq!(store.load(), Ok(vec![conn("a/out"), conn("x/out")]), "the journal's newer list");
        assert_eq!(
            std::fs::read(store.path()).ok(),
            Some(Store::encode(&[conn("a/out"), conn("x/out")])),
            "and it is in the file now"
        );
        assert_eq!(journal::read(&journal).expect("read"), journal::Contents::default(), "the journal emptied");
        // a torn record, nothing whole: the file's list
        std::fs::write(&journal, b"NRJ1\x05\0\0").expect("torn");
        assert_eq!(store.load(), Ok(vec![conn("a/out"), conn("x/out")]));
        assert_eq!(journal::read(&journal).expect("read").bytes, 0, "a torn journal is emptied too");
        // a record that is no connection list is not believed
        journal::append(&journal, b"{ not json").expect("append");
        assert_eq!(store.load(), Ok(vec![conn("a/out"), conn("x/out")]));
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// A test's folder `nerve-store-TAG-PID`, empty.
    fn fresh_dir(tag: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("nerve-store-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        dir
    }

    #[test]
    fn a_file_of_an_earlier_router_loads_and_is_written_the_same_way() {
        let dir = fresh_dir("format");
        std::fs::create_dir_all(&dir).expect("dir");
        let body = br#"{"version": 1, "connections": [
            {"from": "t1/tick", "to": "r1/in", "type": "nerve::Tick"},
            {"from": "a/out", "to": "b/in", "type": "T", "allow_cycle": true}]}"#;
        std::fs::write(dir.join("connections.json"), body).expect("write");
        let list = Store::new(&dir).load().expect("load");
        assert_eq!(list.len(), 2);
        assert_eq!((list[0].from.agent.as_str(), list[0].from.port.as_str()), ("t1", "tick"));
        assert_eq!((list[0].to.agent.as_str(), list[0].to.port.as_str()), ("r1", "in"));
        assert!(!list[0].allow_cycle && list[1].allow_cycle);
        let text = String::from_utf8(Store::encode(&list)).expect("utf-8");
        for field in [r#""from": "t1/tick""#, r#""to": "r1/in""#, r#""type": "nerve::Tick""#, r#""allow_cycle": true"#]
        {
            assert!(text.contains(field), "{field} in {text}");
        }
        assert_eq!(parse(text.as_bytes()), Ok(list));
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// `from` → `b/in`, of type `T`.
    fn conn(from: &str) -> Connection {
        Connection { from: port(from), to: port("b/in"), type_name: "T".into(), allow_cycle: false }
    }

    fn port(text: &str) -> PortRef {
        text.parse().expect("a port")
    }

    /// What became of `saved`, once the writer has done it (10 s at most).
    fn wait_outcome(w: &Writer, saved: Saved) -> Result<(), String> {
        let t0 = std::time::Instant::now();
        loop {
            if let Some(r) = w.outcome(saved) {
                return r;
            }
            assert!(t0.elapsed() < std::time::Duration::from_secs(10), "save {saved:?} never done");
            std::thread::sleep(std::time::Duration::from_millis(1));
        }
    }

    #[test]
    fn a_journaled_save_is_done_once_in_the_journal_and_the_file_follows() {
        let dir = fresh_dir("follows");
        let store = Store::new(&dir);
        let mut w = Writer::start().expect("thread");
        let c = Connection { from: port("a/out"), to: port("b/in"), type_name: "T".into(), allow_cycle: false };
        let saved = w.save(&store, std::slice::from_ref(&c));
        assert_eq!(wait_outcome(&w, saved), Ok(()));
        // on disk: in the journal, in the file, or both by now
        let journal = journal::path_for(store.path());
        let in_journal = journal::read(&journal).expect("read").last == Some(Store::encode(std::slice::from_ref(&c)));
        let in_file = std::fs::read(store.path()).ok() == Some(Store::encode(std::slice::from_ref(&c)));
        assert!(in_journal || in_file, "reported saved, but on disk nowhere");
        w.flush();
        assert_eq!(std::fs::read(store.path()).ok(), Some(Store::encode(std::slice::from_ref(&c))), "the file follows");
        assert_eq!(journal::read(&journal).expect("read").bytes, 0, "and the journal is emptied");
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_corrupt_list_is_moved_aside_and_the_last_good_copy_used() {
        let dir = fresh_dir("corrupt");
        let store = Store::new(&dir);
        let c = vec![Connection {
            from: port("t1/tick"),
            to: port("r1/in"),
            type_name: "nerve::Tick".into(),
            allow_cycle: false,
        }];
        store.save(&c).expect("saves");
        assert_eq!(store.load(), Ok(c.clone()), "a good load keeps a copy");
        for bad in [
            &b"{ not json"[..],
            b"",
            br#"{"version": 99, "connections": []}"#,
            br#"{"version": 1, "connections": [{"from": "a", "to": "b/c", "type": "x"}]}"#,
        ] {
            std::fs::write(store.path(), bad).expect("damage");
            assert_eq!(store.load(), Ok(c.clone()), "recovered from the copy after {:?}", String::from_utf8_lossy(bad));
            let aside = std::fs::read_dir(&dir)
                .expect("dir")
                .filter_map(|e| e.ok())
                .filter(|e| e.file_name().to_string_lossy().contains(".corrupt-"))
                .count();
            assert!(aside >= 1, "the damaged file was not kept aside");
        }
        // no copy at all: an empty list, and the router starts
        let _ = std::fs::remove_file(store.backup_path());
        std::fs::write(store.path(), b"garbage").expect("damage");
        assert_eq!(store.load(), Ok(vec![]));
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_planted_symlink_is_never_written_through() {
        use std::os::unix::fs::MetadataExt;
        let dir = fresh_dir("link");
        std::fs::create_dir_all(&dir).expect("dir");
        let store = Store::new(&dir);
        let victim = dir.join("victim");
        std::fs::write(&victim, "keep").expect("victim");
        // the old fixed temporary name, and this process's own one
        for name in ["connections.json.tmp".to_string(), format!("connections.json.{}.tmp", std::process::id())] {
            let _ = std::fs::remove_file(dir.join(&name));
            std::os::unix::fs::symlink(&victim, dir.join(&name)).expect("symlink");
        }
        store.save(&[]).expect("saves");
        assert_eq!(
            std::fs::read_to_string(&victim).ok().as_deref(),
            Some("keep"),
            "wrote through a symlink (review R1)"
        );
        let mode = std::fs::metadata(store.path()).map(|m| m.mode() & 0o777).expect("saved");
        assert_eq!(mode, 0o600, "the connection list is private (review R24)");
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn writer_saves_the_newest_list_and_flushes() {
        let dir = fresh_dir("writer");
        let store = Store::new(&dir);
        let mut w = Writer::start().expect("thread");
        for i in 0..20 {
            w.save(
                &store,
                &[Connection {
                    from: port(&format!("a{i}/out")),
                    to: port("b/in"),
                    type_name: "nerve::Tick".into(),
                    allow_cycle: false,
                }],
            );
        }
        w.flush();
        let got = store.load().expect("load");
        assert_eq!(got.len(), 1);
        assert_eq!(got[0].from.to_string(), "a19/out");
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn each_save_reports_when_it_is_on_disk_and_whether_it_failed() {
        let dir = fresh_dir("outcome");
        let store = Store::new(&dir);
        let w = Writer::start().expect("thread");
        let c = Connection { from: port("a/out"), to: port("b/in"), type_name: "T".into(), allow_cycle: false };
        let wait = |saved| wait_outcome(&w, saved);
        let ok = w.save(&store, std::slice::from_ref(&c));
        assert_eq!(wait(ok), Ok(()));
        // once reported, it is on disk
        assert_eq!(Store::new(&dir).load().expect("load"), vec![c.clone()]);
        // a save that cannot happen (the journal is a folder now, which
        // cannot be removed either) is reported, not only logged
        let journal = journal::path_for(store.path());
        let _ = std::fs::remove_file(&journal);
        std::fs::create_dir(&journal).expect("a folder in its place");
        let bad = w.save(&store, &[]);
        let err = wait(bad).expect_err("the save failed");
        assert!(err.contains("connections.json"), "{err}");
        assert!(bad > ok);
        let _ = std::fs::remove_dir_all(&dir);
    }
}
