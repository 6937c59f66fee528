//! The persisted connection list: `<state>/connections.json`, written
//! atomically (temporary file, fsync, rename, fsync of the directory) so that
//! a router killed at any moment leaves either the old or the new list.

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
        let tmp = self.path.with_extension("json.tmp");
        let body = serde_json::to_vec_pretty(&File { version: 1, connections: connections.to_vec() })
            .map_err(std::io::Error::other)?;
        {
            let mut f = std::fs::File::create(&tmp)?;
            f.write_all(&body)?;
            f.sync_all()?;
        }
        std::fs::rename(&tmp, &self.path)?;
        std::fs::File::open(dir)?.sync_all()?;
        Ok(())
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
}
