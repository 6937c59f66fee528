//! The agents' log files, read without loading them whole: the last lines
//! of a log (`nerve logs --lines`), a [`Tail`] following one (`nerve logs
//! --follow`, `nerve launch --foreground`).
//!
//! Logs can be large (they are rotated at 8 MiB, see
//! `agent_sdk::daemon::open_log`), so nothing here reads a whole file into
//! memory: [`last_lines`] reads blocks backwards from the end until it has
//! N lines, and a [`Tail`] reads at most [`TAIL_READ_MAX`] bytes per poll.
//! A tail notices a rotated log (another file under the name) and starts
//! again at its beginning.

use std::io::{Read, Seek, SeekFrom};
use std::os::unix::fs::MetadataExt;
use std::path::PathBuf;

/// The most a [`Tail`] reads in one poll; the rest comes at the next.
pub const TAIL_READ_MAX: u64 = 1 << 20;

/// Block size for reading a log backwards.
const BACK_BLOCK: u64 = 64 << 10;

/// Follows a growing file from an offset, line by line.
#[derive(Debug)]
pub struct Tail {
    path: PathBuf,
    offset: u64,
    /// (device, inode) of the file the offset is in; another file under the
    /// name (a rotated log) starts again at 0.
    file_id: Option<(u64, u64)>,
    partial: Vec<u8>,
}

impl Tail {
    /// Starts at `offset` (0: the beginning; `u64::MAX`: the current end).
    pub fn new(path: PathBuf, offset: u64) -> Self {
        let meta = std::fs::metadata(&path).ok();
        let offset = if offset == u64::MAX { meta.as_ref().map(|m| m.len()).unwrap_or(0) } else { offset };
        let file_id = meta.map(|m| (m.dev(), m.ino()));
        Tail { path, offset, file_id, partial: Vec::new() }
    }

    /// Starts at the current end of the file: only lines written from now
    /// on (a file that does not exist yet is read from its beginning).
    pub fn from_end(path: PathBuf) -> Self {
        Tail::new(path, u64::MAX)
    }

    /// The complete lines added since the last call (at most
    /// [`TAIL_READ_MAX`] bytes of them; invalid UTF-8 is replaced).
    pub fn poll(&mut self) -> Vec<String> {
        let Ok(f) = std::fs::File::open(&self.path) else { return vec![] };
        let Ok(meta) = f.metadata() else { return vec![] };
        let id = Some((meta.dev(), meta.ino()));
        if id != self.file_id || meta.len() < self.offset {
            // rotated, replaced or truncated: start again
            self.file_id = id;
            self.offset = 0;
            self.partial.clear();
        }
        if meta.len() == self.offset {
            return vec![];
        }
        let mut f = f;
        if f.seek(SeekFrom::Start(self.offset)).is_err() {
            return vec![];
        }
        let mut buf = Vec::new();
        let n = f.take(TAIL_READ_MAX).read_to_end(&mut buf).unwrap_or(0);
        self.offset += n as u64;
        self.partial.extend_from_slice(&buf[..n.min(buf.len())]);
        let Some(last_nl) = self.partial.iter().rposition(|&b| b == b'\n') else { return vec![] };
        let rest = self.partial.split_off(last_nl + 1);
        let done = std::mem::replace(&mut self.partial, rest);
        done[..last_nl].split(|&b| b == b'\n').map(|l| String::from_utf8_lossy(l).into_owned()).collect()
    }
}

/// One [`Tail`] per path, each from the file's current end: taken before a
/// launch starts its agents, they show this run's lines and none of the
/// earlier runs'.
pub fn tails_from_now(paths: impl IntoIterator<Item = PathBuf>) -> Vec<Tail> {
    paths.into_iter().map(Tail::from_end).collect()
}

/// `lines` without the frames of Rust backtraces (from a `stack backtrace:`
/// line to the `note:` that ends it, or to the first line that is not a
/// frame), each replaced by one line that says where it went: shown a few
/// lines of a log, a person wants the panic's message, which a backtrace
/// would push out.
pub fn without_backtraces(lines: &[String]) -> Vec<String> {
    let mut out = Vec::new();
    let mut in_trace = false;
    for l in lines {
        let t = l.trim_start();
        if t == "stack backtrace:" {
            in_trace = true;
            out.push("(a backtrace, in the log)".to_owned());
            continue;
        }
        if in_trace {
            let frame = t.starts_with("at ") || t.split_once(':').is_some_and(|(n, _)| n.parse::<u32>().is_ok());
            if frame {
                continue;
            }
            in_trace = false;
            if t.starts_with("note: Some details are omitted") {
                continue;
            }
        }
        out.push(l.clone());
    }
    out
}

/// The last `n` lines of `f` (the bytes from the start of the n-th line from
/// the end to the end) and the offset of the end. Reads blocks of
/// [`BACK_BLOCK`] backwards from the end until it has seen `n` line breaks,
/// so the memory used is about the size of those lines, not of the file.
pub fn last_lines<F: Read + Seek>(f: &mut F, n: usize) -> std::io::Result<(Vec<u8>, u64)> {
    let end = f.seek(SeekFrom::End(0))?;
    if n == 0 {
        return Ok((Vec::new(), end));
    }
    let mut pos = end;
    let mut found = 0usize;
    let mut out: Vec<u8> = Vec::new();
    while pos > 0 {
        let len = BACK_BLOCK.min(pos);
        pos -= len;
        f.seek(SeekFrom::Start(pos))?;
        // `len` is at most BACK_BLOCK, so it fits a usize
        let mut block = vec![0u8; len as usize];
        f.read_exact(&mut block)?;
        for i in (0..block.len()).rev() {
            // the line break that ends the file ends the last line, it
            // does not start one
            if block[i] == b'\n' && pos + i as u64 + 1 != end {
                found += 1;
                if found == n {
                    block.drain(..=i);
                    block.extend_from_slice(&out);
                    return Ok((block, end));
                }
            }
        }
        block.extend_from_slice(&out);
        out = block;
    }
    Ok((out, end))
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use std::io::{Cursor, Write};

    /// A reader that counts the bytes read through it.
    struct Counting<R> {
        inner: R,
        read: u64,
    }

    impl<R: Read> Read for Counting<R> {
        fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
            let n = self.inner.read(buf)?;
            self.read += n as u64;
            Ok(n)
        }
    }

    impl<R: Seek> Seek for Counting<R> {
        fn seek(&mut self, pos: SeekFrom) -> std::io::Result<u64> {
            self.inner.seek(pos)
        }
    }

    #[test]
    fn backtraces_are_left_out_of_a_logs_lines_and_the_message_kept() {
        let log: Vec<String> = [
            "thread 'task' (7) panicked at src/a.rs:1:2:",
            "boom",
            "stack backtrace:",
            "   0: __rustc::rust_begin_unwind",
            "             at /rustc/x/library/std/src/panicking.rs:689:5",
            "  12: start_thread",
            "note: Some details are omitted, run with `RUST_BACKTRACE=full` for a verbose backtrace.",
            "after",
        ]
        .map(String::from)
        .to_vec();
        assert_eq!(
            without_backtraces(&log),
            ["thread 'task' (7) panicked at src/a.rs:1:2:", "boom", "(a backtrace, in the log)", "after"]
        );
        // a trace without its note ends at the first line that is no frame
        let cut: Vec<String> = ["stack backtrace:", "   0: f", "next"].map(String::from).to_vec();
        assert_eq!(without_backtraces(&cut), ["(a backtrace, in the log)", "next"]);
        let plain: Vec<String> = ["12:00:01 INFO started", "x: y"].map(String::from).to_vec();
        assert_eq!(without_backtraces(&plain), plain);
    }

    #[test]
    fn last_lines_reads_only_the_tail_of_a_large_log() {
        let mut text = Vec::new();
        for i in 0..200_000 {
            writeln!(text, "line {i} of a long log").unwrap();
        }
        assert!(text.len() > 4 << 20);
        let mut f = Counting { inner: Cursor::new(text.clone()), read: 0 };
        let (tail, end) = last_lines(&mut f, 3).unwrap();
        assert_eq!(tail, b"line 199997 of a long log\nline 199998 of a long log\nline 199999 of a long log\n");
        assert_eq!(end, text.len() as u64);
        assert!(f.read <= BACK_BLOCK, "read {} bytes for 3 lines", f.read);

        // more lines than one block holds, a last line without a line
        // break, fewer lines than asked, none asked
        let (tail, _) = last_lines(&mut Cursor::new(text.clone()), 5000).unwrap();
        assert_eq!(tail, text[text.len() - tail.len()..]);
        assert_eq!(tail.iter().filter(|&&b| b == b'\n').count(), 5000);
        assert!(tail.starts_with(b"line 195000 "));
        assert_eq!(last_lines(&mut Cursor::new(b"a\nb\nc".to_vec()), 2).unwrap().0, b"b\nc");
        assert_eq!(last_lines(&mut Cursor::new(b"a\nb\n".to_vec()), 9).unwrap().0, b"a\nb\n");
        assert_eq!(last_lines(&mut Cursor::new(b"a\nb\n".to_vec()), 0).unwrap().0, b"");
        assert_eq!(last_lines(&mut Cursor::new(Vec::new()), 4).unwrap(), (Vec::new(), 0));
    }

    #[test]
    fn a_launch_follows_logs_from_their_end_and_across_rotation() {
        let dir = std::env::temp_dir().join(format!("nerve-logs-tail-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let (old, fresh) = (dir.join("old.log"), dir.join("fresh.log"));
        std::fs::write(&old, "an earlier run\nits last line\n").unwrap();
        let mut tails = tails_from_now([old.clone(), fresh.clone()]);
        assert!(tails.iter_mut().all(|t| t.poll().is_empty()), "an earlier run's lines were replayed");

        let append = |p: &PathBuf, s: &[u8]| {
            std::fs::OpenOptions::new().create(true).append(true).open(p).unwrap().write_all(s).unwrap()
        };
        append(&old, b"this run\npart");
        append(&fresh, b"a new agent\n");
        assert_eq!(tails[0].poll(), ["this run"]);
        assert_eq!(tails[1].poll(), ["a new agent"]);
        append(&old, b"ial \xff line\n");
        assert_eq!(tails[0].poll(), ["partial \u{fffd} line"]);

        // rotated: the log is renamed and a new one, longer than the
        // offset, appears before the next poll
        std::fs::rename(&old, dir.join("old.log.1")).unwrap();
        std::fs::write(&old, "after rotation, a line longer than the earlier offset\n").unwrap();
        assert_eq!(tails[0].poll(), ["after rotation, a line longer than the earlier offset"]);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
