//! A file's journal: `<file>.journal` beside it, where the newest body of
//! the file is appended and synced before the file itself is rewritten.
//!
//! Why: a `connect` is answered once the connection list is on disk (review
//! R11a). Writing the list atomically (temporary file, fsync, rename, fsync
//! of the folder) costs two journal commits of the file system, 0.6-1.7 ms
//! on this project's VMs, and the reply waited for them. An append to a file
//! that exists, then `fdatasync`, costs one (0.2-0.3 ms), so the writer
//! thread ([`crate::store::Writer`]) appends the body here, reports the save
//! done, and brings the file itself up to date after, when nothing else
//! waits; once the file is on disk the journal is emptied.
//!
//! So the journal's last record is never older than the file: a body is
//! appended before the file gets it, and the journal is emptied only after
//! the file is synced. A router killed between the two finds the newer list
//! here at its next start ([`crate::store::Store::load`]), which writes it
//! into the file and empties the journal before anything is appended again
//! (so that no record ever follows a torn one).
//!
//! A record is `NRJ1`, the body's length and its CRC-32 (both little
//! endian), then the body. Reading stops at the first record that is short
//! or does not match its CRC: the tail a power cut tore.

use std::ffi::OsString;
use std::io::{Read, Write};
use std::os::unix::fs::OpenOptionsExt;
use std::path::{Path, PathBuf};

const MAGIC: [u8; 4] = *b"NRJ1";
const HEADER: usize = 12;

/// The journal of `file`: `<file>.journal`.
pub fn path_for(file: &Path) -> PathBuf {
    let mut p = OsString::from(file.as_os_str());
    p.push(".journal");
    PathBuf::from(p)
}

/// Appends `body` as a record and syncs it; the folder is synced too when
/// the journal was created, so that the file's name is durable as well.
/// Never writes through a symlink; the journal is readable by its owner only.
pub fn append(journal: &Path, body: &[u8]) -> std::io::Result<()> {
    let len = u32::try_from(body.len())
        .map_err(|_| std::io::Error::new(std::io::ErrorKind::InvalidInput, "a record of 4 GiB or more"))?;
    let created = std::fs::symlink_metadata(journal).is_err();
    let mut f = std::fs::OpenOptions::new()
        .append(true)
        .create(true)
        .mode(0o600)
        .custom_flags(libc::O_NOFOLLOW)
        .open(journal)?;
    let mut record = Vec::with_capacity(HEADER + body.len());
    record.extend_from_slice(&MAGIC);
    record.extend_from_slice(&len.to_le_bytes());
    record.extend_from_slice(&crc32fast::hash(body).to_le_bytes());
    record.extend_from_slice(body);
    f.write_all(&record)?;
    f.sync_data()?;
    if created {
        std::fs::File::open(journal.parent().unwrap_or(Path::new(".")))?.sync_all()?;
    }
    Ok(())
}

/// What a journal holds.
#[derive(Debug, Default, PartialEq, Eq)]
pub struct Contents {
    /// the body of its last whole record
    pub last: Option<Vec<u8>>,
    /// its length in bytes (0 when it is missing)
    pub bytes: u64,
    /// the length of its whole records: less than `bytes` after a torn tail
    pub whole: u64,
}

/// Reads the journal; a missing one holds nothing.
pub fn read(journal: &Path) -> std::io::Result<Contents> {
    let mut buf = Vec::new();
    match std::fs::OpenOptions::new().read(true).custom_flags(libc::O_NOFOLLOW).open(journal) {
        Ok(mut f) => f.read_to_end(&mut buf)?,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Contents::default()),
        Err(e) => return Err(e),
    };
    let mut last = None;
    let mut rest = buf.as_slice();
    let mut whole = 0u64;
    while let Some((head, tail)) = rest.split_first_chunk::<HEADER>() {
        let word = |i: usize| u32::from_le_bytes([head[i], head[i + 1], head[i + 2], head[i + 3]]);
        if head[..4] != MAGIC {
            break;
        }
        let Some((body, after)) = usize::try_from(word(4)).ok().and_then(|n| tail.split_at_checked(n)) else {
            break;
        };
        if crc32fast::hash(body) != word(8) {
            break;
        }
        last = Some(body.to_vec());
        whole = whole.saturating_add((HEADER + body.len()) as u64);
        rest = after;
    }
    Ok(Contents { last, bytes: buf.len() as u64, whole })
}

/// Empties the journal (its file stays, so that the next append needs no
/// sync of the folder). Not synced: should the emptying be lost, the
/// records that come back are no newer than the file.
pub fn clear(journal: &Path) -> std::io::Result<()> {
    cut(journal, 0, false)
}

/// Cuts the journal to its first `len` bytes (a torn tail off, so that the
/// next record follows a whole one), and syncs that.
pub fn cut_to_whole(journal: &Path, len: u64) -> std::io::Result<()> {
    cut(journal, len, true)
}

/// Cuts the journal to `len` bytes, synced if `sync`; a missing one is left so.
fn cut(journal: &Path, len: u64, sync: bool) -> std::io::Result<()> {
    match std::fs::OpenOptions::new().write(true).custom_flags(libc::O_NOFOLLOW).open(journal) {
        Ok(f) => {
            f.set_len(len)?;
            if sync { f.sync_data() } else { Ok(()) }
        }
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(()),
        Err(e) => Err(e),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dir(tag: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("nerve-journal-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).expect("dir");
        d
    }

    #[test]
    fn the_last_whole_record_is_read_and_a_torn_tail_ignored() {
        let d = dir("torn");
        let j = path_for(&d.join("list.json"));
        assert_eq!(j.file_name().and_then(|n| n.to_str()), Some("list.json.journal"));
        assert_eq!(read(&j).expect("missing"), Contents::default());
        append(&j, b"first").expect("append");
        append(&j, b"second, longer").expect("append");
        let whole = read(&j).expect("read");
        assert_eq!(whole.last.as_deref(), Some(&b"second, longer"[..]));
        assert_eq!(whole.whole, whole.bytes);
        // every cut through the last record leaves the one before it
        let bytes = std::fs::read(&j).expect("bytes");
        let first_len = HEADER + 5;
        for cut in first_len..bytes.len() {
            std::fs::write(&j, &bytes[..cut]).expect("cut");
            let c = read(&j).expect("read");
            assert_eq!(c.last.as_deref(), Some(&b"first"[..]), "cut at {cut}");
            assert_eq!(c.whole, first_len as u64, "cut at {cut}");
        }
        // cut to its whole records, the journal takes a record that is read back
        cut_to_whole(&j, first_len as u64).expect("cut to whole");
        append(&j, b"third").expect("append");
        assert_eq!(read(&j).expect("read").last.as_deref(), Some(&b"third"[..]));
        // a flipped bit in the body: that record is not believed
        let mut flipped = bytes.clone();
        if let Some(b) = flipped.last_mut() {
            *b ^= 1;
        }
        std::fs::write(&j, &flipped).expect("flip");
        assert_eq!(read(&j).expect("read").last.as_deref(), Some(&b"first"[..]));
        // a length beyond the file
        let mut long = bytes[..first_len].to_vec();
        long.extend_from_slice(&MAGIC);
        long.extend_from_slice(&u32::MAX.to_le_bytes());
        long.extend_from_slice(&[0; 4]);
        std::fs::write(&j, &long).expect("long");
        assert_eq!(read(&j).expect("read").last.as_deref(), Some(&b"first"[..]));
        let _ = std::fs::remove_dir_all(&d);
    }

    #[test]
    fn cleared_it_holds_nothing_and_takes_records_again() {
        let d = dir("clear");
        let j = path_for(&d.join("list.json"));
        clear(&j).expect("clearing a missing journal is nothing");
        append(&j, b"one").expect("append");
        clear(&j).expect("clear");
        assert_eq!(read(&j).expect("read"), Contents { last: None, bytes: 0, whole: 0 });
        append(&j, b"two").expect("append");
        assert_eq!(read(&j).expect("read").last.as_deref(), Some(&b"two"[..]));
        let _ = std::fs::remove_dir_all(&d);
    }

    #[test]
    fn it_is_private_and_never_written_through_a_symlink() {
        use std::os::unix::fs::MetadataExt;
        let d = dir("link");
        let victim = d.join("victim");
        std::fs::write(&victim, "keep").expect("victim");
        let j = path_for(&d.join("list.json"));
        std::os::unix::fs::symlink(&victim, &j).expect("symlink");
        assert!(append(&j, b"x").is_err(), "appended through a symlink");
        assert!(clear(&j).is_err(), "cleared through a symlink");
        assert_eq!(std::fs::read_to_string(&victim).expect("victim"), "keep");
        std::fs::remove_file(&j).expect("rm");
        append(&j, b"x").expect("append");
        assert_eq!(std::fs::metadata(&j).map(|m| m.mode() & 0o777).expect("meta"), 0o600);
        let _ = std::fs::remove_dir_all(&d);
    }
}
