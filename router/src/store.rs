//! The persisted connection list: `<state>/connections.json`, written
//! atomically (temporary file, fsync, rename, fsync of the directory) so that
//! a router killed at any moment leaves either the old or the new list.
//!
//! The router writes through a [`Writer`] thread: the two fsyncs take tens of
//! milliseconds on a busy disk, and a router blocked in them made the next
//! `nerve connect` (or a decision maker's rewiring) wait. The thread writes
//! the newest list it has been given, skipping lists overtaken meanwhile,
//! and is flushed when the router stops.

use serde::{Deserialize, Serialize};
use std::io::Write;
use std::path::{Path, PathBuf};

/// One connection: output port → input port, with the checked payload type.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Connection {
    /// `agent/port` of the output
    pub from: String,
    /// `agent/port` of the input
    pub to: String,
    /// payload type name
    #[serde(rename = "type")]
    pub type_name: String,
}

#[derive(Debug, Serialize, Deserialize)]
struct File {
    version: u32,
    connections: Vec<Connection>,
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

    /// Loads the list; a missing file is an empty list, a corrupt one an error.
    pub fn load(&self) -> Result<Vec<Connection>, String> {
        match std::fs::read(&self.path) {
            Ok(bytes) => serde_json::from_slice::<File>(&bytes).map(|f| f.connections).map_err(|e| {
                format!(
                    "{}: {e}; fix or remove the file (it holds the connection list) and start the router again",
                    self.path.display()
                )
            }),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(Vec::new()),
            Err(e) => Err(format!("cannot read {}: {e}", self.path.display())),
        }
    }

    /// Saves the list atomically.
    pub fn save(&self, connections: &[Connection]) -> std::io::Result<()> {
        let dir = self.path.parent().unwrap_or(Path::new("."));
        std::fs::create_dir_all(dir)?;
        // a fresh temporary name, created exclusively, never through a
        // symlink, readable by its owner only (review R1, R11d, R24)
        let tmp = self.path.with_extension(format!("json.{}.tmp", std::process::id()));
        let body = serde_json::to_vec_pretty(&File { version: 1, connections: connections.to_vec() })
            .map_err(std::io::Error::other)?;
        {
            use std::os::unix::fs::OpenOptionsExt;
            let _ = std::fs::remove_file(&tmp);
            let mut f = std::fs::OpenOptions::new()
                .write(true)
                .create_new(true)
                .mode(0o600)
                .custom_flags(libc::O_NOFOLLOW)
                .open(&tmp)?;
            f.write_all(&body)?;
            f.sync_all()?;
        }
        std::fs::rename(&tmp, &self.path)?;
        std::fs::File::open(dir)?.sync_all()?;
        Ok(())
    }
}

/// Saves connection lists on a thread of its own, newest first.
#[derive(Debug)]
pub struct Writer {
    tx: Option<std::sync::mpsc::Sender<Vec<Connection>>>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Writer {
    /// Starts the thread that saves into `store`.
    pub fn start(store: Store) -> std::io::Result<Self> {
        let (tx, rx) = std::sync::mpsc::channel::<Vec<Connection>>();
        let thread = std::thread::Builder::new().name("persist".into()).spawn(move || {
            while let Ok(mut list) = rx.recv() {
                // a newer list makes the older ones pointless
                while let Ok(newer) = rx.try_recv() {
                    list = newer;
                }
                if let Err(e) = store.save(&list) {
                    tracing::error!("cannot save the connection list to {}: {e}", store.path().display());
                }
            }
        })?;
        Ok(Writer { tx: Some(tx), thread: Some(thread) })
    }

    /// Queues `list` to be saved.
    pub fn save(&self, list: Vec<Connection>) {
        if let Some(tx) = &self.tx {
            let _ = tx.send(list);
        }
    }

    /// Waits until every queued list is saved.
    pub fn flush(&mut self) {
        self.tx.take();
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
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
        let dir = std::env::temp_dir().join(format!("nerve-store-test-{}", std::process::id()));
        let store = Store::new(&dir);
        assert_eq!(store.load(), Ok(vec![]));
        let c = vec![Connection { from: "t1/tick".into(), to: "r1/in".into(), type_name: "nerve::Tick".into() }];
        store.save(&c).expect("saves");
        assert_eq!(store.load(), Ok(c));
        std::fs::write(store.path(), b"{ not json").expect("writes");
        assert!(store.load().expect_err("corrupt").contains("fix or remove"));
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_planted_symlink_is_never_written_through() {
        use std::os::unix::fs::MetadataExt;
        let dir = std::env::temp_dir().join(format!("nerve-store-link-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
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
        let dir = std::env::temp_dir().join(format!("nerve-store-writer-{}", std::process::id()));
        let store = Store::new(&dir);
        let mut w = Writer::start(store.clone()).expect("thread");
        for i in 0..20 {
            w.save(vec![Connection { from: format!("a{i}/out"), to: "b/in".into(), type_name: "nerve::Tick".into() }]);
        }
        w.flush();
        let got = store.load().expect("load");
        assert_eq!(got.len(), 1);
        assert_eq!(got[0].from, "a19/out");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
