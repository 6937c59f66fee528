//! Reading a recording as a stream, in bounded memory, up to its last good
//! record: the one reader of `nerve replay`, `nerve export` and `nerve
//! snapshot`.
//!
//! The file is read front to back from a [`Read`] (a `BufReader` of the
//! file), one record at a time: what is held is the record being read (a
//! message's bytes, at most [`MAX_RECORD`]) and the file's schemas and
//! channels, never the file. Messages of channels the caller
//! [skips](RecordingReader::skip) are read past without being kept.
//!
//! A recording that ends early is read up to its last whole record: `kill
//! -9`, the OOM killer, a power loss or a full disk stop the writer before
//! it closes its last chunk, whose length is then still mcap's placeholder
//! (`!0`). Other readers (mcap's own `LinearReader`, `MessageStream`) refuse
//! such a chunk whole; this one reads the records in it one by one until
//! the file ends or a record does not parse, and says what was lost
//! ([`Cut`]). Only uncompressed chunks are read: nerve writes no others
//! (recording must cost the robot next to nothing).
//!
//! What this reader does not check: chunk CRCs (a message's bytes that
//! changed on disk are not noticed; the record structure around them is).

use crate::{MESSAGE_ENCODING, SCHEMA_ENCODING};
use mcap::records::op;
use shm_schemas::Schema;
use std::collections::{BTreeMap, BTreeSet};
use std::fmt;
use std::io::{BufReader, ErrorKind, Read};
use std::path::Path;
use std::sync::Arc;

/// The largest record read into memory (1 GiB): a longer one is taken as
/// damage. A message of nerve is at most a port's payload or an encoded
/// frame, megabytes.
pub const MAX_RECORD: u64 = 1 << 30;

/// Size of the buffer between the file and the reader.
const READ_BUFFER: usize = 256 * 1024;

/// A channel of the file, with its schema.
pub type Channel = Arc<mcap::Channel<'static>>;

/// Why a recording could not be read at all (a file cut short is not an
/// error: it is read up to its last good record, see [`Cut`]).
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ReadError {
    /// The file could not be opened.
    #[error("cannot read {file}: {source}")]
    Open {
        /// the file
        file: String,
        /// why
        #[source]
        source: std::io::Error,
    },
    /// Reading failed (not the end of the file: an I/O error).
    #[error("cannot read {file} at byte {at}: {source}; check the disk (dmesg) and try again")]
    Io {
        /// the file
        file: String,
        /// where
        at: u64,
        /// why
        #[source]
        source: std::io::Error,
    },
    /// The file does not start as an MCAP file.
    #[error("{file}: not a readable MCAP file (it does not start with MCAP's magic bytes)")]
    NotMcap {
        /// the file
        file: String,
    },
    /// The file's chunks are compressed.
    #[error(
        "{file}: its chunks are compressed ({compression}); nerve reads uncompressed recordings only: `mcap decompress` (the mcap CLI) makes one"
    )]
    Compressed {
        /// the file
        file: String,
        /// the compression named in the chunk at byte ...
        compression: String,
    },
}

/// Why a channel's nerve schema was refused.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum SchemaError {
    /// The channel is not a nerve port's (another encoding, or no nerve schema).
    #[error("{file}: channel {topic} is not a nerve port's ({what}); is it a file `nerve record` wrote?")]
    NotNerve {
        /// the file
        file: String,
        /// the channel's topic
        topic: String,
        /// what it is instead
        what: String,
    },
    /// The schema is not a nerve schema in JSON.
    #[error("{file}: the schema of channel {topic} does not read: {source}; the file is damaged or not nerve's")]
    Json {
        /// the file
        file: String,
        /// the channel's topic
        topic: String,
        /// why
        #[source]
        source: serde_json::Error,
    },
    /// The schema reads but describes a layout nerve refuses (an alignment
    /// of 0, fields past the end...): it never reaches shared memory.
    #[error(
        "{file}: the schema of channel {topic} is refused: {source}; the file is damaged or was not written by nerve"
    )]
    Invalid {
        /// the file
        file: String,
        /// the channel's topic
        topic: String,
        /// what is wrong with it
        #[source]
        source: Box<shm_schemas::schema::SchemaInvalid>,
    },
}

/// The nerve schema of a port's channel (encoding [`MESSAGE_ENCODING`],
/// schema [`SCHEMA_ENCODING`]), parsed and checked
/// ([`Schema::validate`]): a schema from a file is outside input.
pub fn nerve_schema(file: &str, ch: &mcap::Channel<'_>) -> Result<Schema, SchemaError> {
    let not_nerve = |what: String| SchemaError::NotNerve { file: file.into(), topic: ch.topic.clone(), what };
    if ch.message_encoding != MESSAGE_ENCODING {
        return Err(not_nerve(format!("encoded {:?}, not {MESSAGE_ENCODING:?}", ch.message_encoding)));
    }
    let Some(s) = ch.schema.as_ref().filter(|s| s.encoding == SCHEMA_ENCODING) else {
        return Err(not_nerve(format!("no {SCHEMA_ENCODING} schema")));
    };
    let schema: Schema = serde_json::from_slice(&s.data).map_err(|source| SchemaError::Json {
        file: file.into(),
        topic: ch.topic.clone(),
        source,
    })?;
    schema.validate().map_err(|e| SchemaError::Invalid {
        file: file.into(),
        topic: ch.topic.clone(),
        source: Box::new(e),
    })?;
    Ok(schema)
}

/// What the reader found next.
#[derive(Debug)]
pub enum Event<'a> {
    /// A channel, the first time the file names it (before its messages).
    Channel(Channel),
    /// A message of a channel that is not skipped.
    Message(Message<'a>),
}

/// A message, its bytes borrowed from the reader until the next call.
#[derive(Debug)]
pub struct Message<'a> {
    /// its channel
    pub channel: Channel,
    /// the sender's sequence number (low 32 bits)
    pub sequence: u32,
    /// when it was taken, CLOCK_REALTIME ns
    pub log_time: u64,
    /// its publish time (nerve: the sample's stamp)
    pub publish_time: u64,
    /// its bytes
    pub data: &'a [u8],
}

/// How a file ended.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum End {
    /// Whole: its data section ended as MCAP says.
    Complete,
    /// Cut short, or damaged: read up to the last good record.
    Cut(Cut),
}

/// A file read up to its last good record: what was read and what was lost.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Cut {
    /// the file
    pub file: String,
    /// the byte where the lost part starts (the unfinished chunk, or the bad record)
    pub at: u64,
    /// messages read (those of skipped channels too)
    pub messages: u64,
    /// the log time of the last message read
    pub last_log_time: Option<u64>,
    /// what happened
    pub kind: CutKind,
}

/// What cut a file short.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum CutKind {
    /// Its last chunk was never closed (the writer was killed, ran out of
    /// memory or disk, or the power went): its whole records were read.
    UnfinishedChunk,
    /// It ends after a whole chunk or record, without MCAP's end.
    NoEnd,
    /// It ends in the middle of a record.
    PartialRecord,
    /// A record does not parse (what is wrong).
    Damaged(String),
}

impl fmt::Display for Cut {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let (file, at) = (&self.file, grouped(self.at));
        match &self.kind {
            CutKind::UnfinishedChunk => write!(f, "{file} ends in an unfinished chunk at byte {at}")?,
            CutKind::NoEnd => write!(f, "{file} ends at byte {at} without MCAP's end")?,
            CutKind::PartialRecord => write!(f, "{file} ends in the middle of a record at byte {at}")?,
            CutKind::Damaged(what) => write!(f, "{file} is damaged at byte {at} ({what})")?,
        }
        write!(f, ": read {} messages", grouped(self.messages))?;
        if let Some(t) = self.last_log_time {
            write!(f, " up to {}", clock_text(t))?;
        }
        match &self.kind {
            CutKind::Damaged(_) => write!(f, "; the rest of the file is not read"),
            CutKind::NoEnd => write!(f, "; the writer stopped before closing the file (nothing whole is lost)"),
            _ => write!(
                f,
                "; the rest of the last chunk is lost (the writer was stopped: killed, out of memory or disk, or a power loss)"
            ),
        }
    }
}

/// `n` with thousands separated by commas.
pub fn grouped(n: u64) -> String {
    let digits = n.to_string();
    let mut out = String::with_capacity(digits.len() + digits.len() / 3);
    for (i, c) in digits.chars().enumerate() {
        if i > 0 && (digits.len() - i).is_multiple_of(3) {
            out.push(',');
        }
        out.push(c);
    }
    out
}

/// `YYYY-mm-dd HH:MM:SS.s UTC` of CLOCK_REALTIME nanoseconds.
pub fn clock_text(unix_ns: u64) -> String {
    let secs = unix_ns / 1_000_000_000;
    let (days, s) = (secs / 86_400, secs % 86_400);
    let (y, m, d) = crate::civil_from_days(days as i64);
    let tenth = unix_ns / 100_000_000 % 10;
    format!("{y:04}-{m:02}-{d:02} {:02}:{:02}:{:02}.{tenth} UTC", s / 3600, s / 60 % 60, s % 60)
}

/// Where the reader is in the file's structure.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Place {
    /// between top-level records
    Top,
    /// in a closed chunk: its records end at `records_end`, the chunk
    /// record at `record_end`
    Chunk { records_end: u64, record_end: u64 },
    /// in a chunk that was never closed (starting at `at`): records until
    /// the file ends
    Unfinished { at: u64 },
}

/// How a read of a given length went.
enum Got {
    /// all of it
    All,
    /// the file ended first
    Eof,
}

/// What became of a message record.
enum Step {
    /// read into the buffer, for the caller
    Kept { channel: Channel, sequence: u32, log_time: u64, publish_time: u64 },
    /// read past (a skipped channel)
    Skipped,
    /// the file ended in it, or it is damaged
    Ended,
}

/// A recording read front to back; see the module.
pub struct RecordingReader<R> {
    src: R,
    file: String,
    /// bytes consumed from the start
    pos: u64,
    place: Place,
    schemas: BTreeMap<u16, Arc<mcap::Schema<'static>>>,
    channels: BTreeMap<u16, Channel>,
    skipped: BTreeSet<u16>,
    skip_all: bool,
    buf: Vec<u8>,
    messages: u64,
    last_log_time: Option<u64>,
    end: Option<End>,
}

impl<R> fmt::Debug for RecordingReader<R> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("RecordingReader")
            .field("file", &self.file)
            .field("pos", &self.pos)
            .field("messages", &self.messages)
            .finish_non_exhaustive()
    }
}

impl RecordingReader<BufReader<std::fs::File>> {
    /// Opens `path` (through a buffer) and checks that it is MCAP.
    pub fn open(path: &Path) -> Result<Self, ReadError> {
        let file = path.display().to_string();
        let f = std::fs::File::open(path).map_err(|source| ReadError::Open { file: file.clone(), source })?;
        RecordingReader::new(BufReader::with_capacity(READ_BUFFER, f), &file)
    }
}

impl<R: Read> RecordingReader<R> {
    /// Reads from `src`, named `file` in messages; checks MCAP's magic.
    pub fn new(src: R, file: &str) -> Result<Self, ReadError> {
        let mut r = RecordingReader {
            src,
            file: file.to_string(),
            pos: 0,
            place: Place::Top,
            schemas: BTreeMap::new(),
            channels: BTreeMap::new(),
            skipped: BTreeSet::new(),
            skip_all: false,
            buf: Vec::new(),
            messages: 0,
            last_log_time: None,
            end: None,
        };
        match r.fill(8)? {
            Got::All if r.buf == mcap::MAGIC => Ok(r),
            _ => Err(ReadError::NotMcap { file: r.file }),
        }
    }

    /// Reads past the messages of channel `id` without keeping them.
    pub fn skip(&mut self, id: u16) {
        self.skipped.insert(id);
    }

    /// Reads past every message: only channels are returned (a first look
    /// at what a file holds).
    pub fn skip_messages(&mut self) {
        self.skip_all = true;
    }

    /// How the file ended, once [`Self::next_event`] returned `None`.
    pub fn end(&self) -> Option<&End> {
        self.end.as_ref()
    }

    /// The [`Cut`], when the file ended early.
    pub fn cut(&self) -> Option<&Cut> {
        match &self.end {
            Some(End::Cut(c)) => Some(c),
            _ => None,
        }
    }

    /// Messages read so far (those of skipped channels too).
    pub fn messages(&self) -> u64 {
        self.messages
    }

    /// The channels seen so far, by id.
    pub fn channels(&self) -> &BTreeMap<u16, Channel> {
        &self.channels
    }

    /// Reads exactly `n` bytes into `self.buf`, a MiB at a time (a length
    /// that a damaged file inflates costs memory only as far as the file goes).
    fn fill(&mut self, n: u64) -> Result<Got, ReadError> {
        const STEP: u64 = 1 << 20;
        self.buf.clear();
        let mut left = n;
        while left > 0 {
            let step = left.min(STEP);
            let got = (&mut self.src).take(step).read_to_end(&mut self.buf).map_err(|source| ReadError::Io {
                file: self.file.clone(),
                at: self.pos,
                source,
            })?;
            self.pos = self.pos.saturating_add(got as u64);
            if (got as u64) < step {
                return Ok(Got::Eof);
            }
            left -= step;
        }
        Ok(Got::All)
    }

    /// Reads past `n` bytes without keeping them.
    fn pass(&mut self, n: u64) -> Result<Got, ReadError> {
        let got = std::io::copy(&mut (&mut self.src).take(n), &mut std::io::sink()).map_err(|source| {
            let source = if source.kind() == ErrorKind::Interrupted { std::io::Error::other(source) } else { source };
            ReadError::Io { file: self.file.clone(), at: self.pos, source }
        })?;
        self.pos = self.pos.saturating_add(got);
        Ok(if got == n { Got::All } else { Got::Eof })
    }

    /// Ends the reading with `kind` at byte `at`.
    fn cut_at(&mut self, at: u64, kind: CutKind) {
        self.end = Some(End::Cut(Cut {
            file: self.file.clone(),
            at,
            messages: self.messages,
            last_log_time: self.last_log_time,
            kind,
        }));
    }

    /// The end of the file, or of what the place allows, while a record was
    /// expected or half read.
    fn eof(&mut self, record_at: u64, whole_records: bool) {
        match self.place {
            Place::Unfinished { at } => self.cut_at(at, CutKind::UnfinishedChunk),
            Place::Top if whole_records => self.cut_at(record_at, CutKind::NoEnd),
            _ => self.cut_at(record_at, CutKind::PartialRecord),
        }
    }

    /// The next channel or message; `None` at the end of the data (see
    /// [`Self::end`] for how it ended).
    pub fn next_event(&mut self) -> Result<Option<Event<'_>>, ReadError> {
        loop {
            if self.end.is_some() {
                return Ok(None);
            }
            if let Place::Chunk { records_end, record_end } = self.place
                && self.pos >= records_end
            {
                // past the chunk's records: its padding, if any
                let at = self.pos;
                if let Got::Eof = self.pass(record_end.saturating_sub(self.pos))? {
                    self.cut_at(at, CutKind::PartialRecord);
                    return Ok(None);
                }
                self.place = Place::Top;
                continue;
            }
            let at = self.pos;
            match self.fill(9)? {
                Got::All => {}
                Got::Eof => {
                    let whole = self.buf.is_empty();
                    self.eof(at, whole);
                    return Ok(None);
                }
            }
            let opcode = self.buf[0];
            let mut len_bytes = [0u8; 8];
            len_bytes.copy_from_slice(&self.buf[1..9]);
            let len = u64::from_le_bytes(len_bytes);
            let body_end = self.pos.checked_add(len);
            let in_chunk = !matches!(self.place, Place::Top);
            if let Place::Chunk { records_end, .. } = self.place
                && body_end.is_none_or(|e| e > records_end)
            {
                self.cut_at(at, CutKind::Damaged(format!("a record of {len} bytes runs past the end of its chunk")));
                return Ok(None);
            }
            if opcode == op::CHUNK && !in_chunk {
                if let Some(cut) = self.chunk_header(at, len)? {
                    self.cut_at(at, cut);
                    return Ok(None);
                }
                continue;
            }
            if len > MAX_RECORD {
                self.cut_at(at, CutKind::Damaged(format!("a record of {len} bytes, more than a recording holds")));
                return Ok(None);
            }
            match opcode {
                op::MESSAGE => match self.message(at, len)? {
                    Step::Kept { channel, sequence, log_time, publish_time } => {
                        let data = &self.buf;
                        return Ok(Some(Event::Message(Message { channel, sequence, log_time, publish_time, data })));
                    }
                    Step::Skipped => {}
                    Step::Ended => return Ok(None),
                },
                op::SCHEMA | op::CHANNEL => {
                    if let Got::Eof = self.fill(len)? {
                        self.eof(at, false);
                        return Ok(None);
                    }
                    match self.definition(opcode) {
                        Ok(Some(ch)) => return Ok(Some(Event::Channel(ch))),
                        Ok(None) => {}
                        Err(what) => {
                            self.cut_at(at, CutKind::Damaged(what));
                            return Ok(None);
                        }
                    }
                }
                op::HEADER if !in_chunk && at == 8 => {
                    if let Got::Eof = self.pass(len)? {
                        self.eof(at, false);
                        return Ok(None);
                    }
                }
                op::DATA_END | op::FOOTER if !in_chunk => {
                    self.end = Some(End::Complete);
                    return Ok(None);
                }
                0 | op::HEADER | op::FOOTER | op::DATA_END | op::CHUNK => {
                    // zeros (a power loss can leave them), or a record that
                    // has no place here
                    self.cut_at(at, CutKind::Damaged(format!("a record of type {opcode:#04x} where none can be")));
                    return Ok(None);
                }
                _ => {
                    // indexes, attachments, metadata: not needed to read the messages
                    if let Got::Eof = self.pass(len)? {
                        self.eof(at, false);
                        return Ok(None);
                    }
                }
            }
        }
    }

    /// Reads a chunk's header (the record's opcode and length are read);
    /// what cut the file, if it did.
    fn chunk_header(&mut self, at: u64, len: u64) -> Result<Option<CutKind>, ReadError> {
        // start, end, uncompressed size (8 each), uncompressed crc (4), compression's length (4)
        if let Got::Eof = self.fill(32)? {
            return Ok(Some(CutKind::PartialRecord));
        }
        let le32 = |b: &[u8]| b.iter().rev().fold(0u32, |a, &x| (a << 8) | u32::from(x));
        let le64 = |b: &[u8]| b.iter().rev().fold(0u64, |a, &x| (a << 8) | u64::from(x));
        let name_len = u64::from(le32(&self.buf[28..32]));
        if name_len > 64 {
            return Ok(Some(CutKind::Damaged(format!("a chunk whose compression's name is {name_len} bytes"))));
        }
        if let Got::Eof = self.fill(name_len + 8)? {
            return Ok(Some(CutKind::PartialRecord));
        }
        let split = self.buf.len().saturating_sub(8);
        let compression = String::from_utf8_lossy(&self.buf[..split]).into_owned();
        let compressed_size = le64(&self.buf[split..]);
        if !compression.is_empty() {
            return Err(ReadError::Compressed { file: self.file.clone(), compression });
        }
        let header_len = 40 + name_len;
        let records_end = self.pos.checked_add(compressed_size);
        let record_end = at.checked_add(9).and_then(|s| s.checked_add(len));
        self.place = match (len, records_end, record_end) {
            // the writer's placeholders, never replaced: the chunk was not closed
            (u64::MAX, ..) => Place::Unfinished { at },
            (_, Some(records_end), Some(record_end))
                if compressed_size != u64::MAX && header_len.saturating_add(compressed_size) <= len =>
            {
                Place::Chunk { records_end, record_end }
            }
            _ => {
                return Ok(Some(CutKind::Damaged(format!(
                    "a chunk of {len} bytes whose records are {compressed_size}"
                ))));
            }
        };
        Ok(None)
    }

    /// A message record (its opcode and length read).
    fn message(&mut self, at: u64, len: u64) -> Result<Step, ReadError> {
        const HEADER: u64 = 2 + 4 + 8 + 8;
        if len < HEADER {
            self.cut_at(at, CutKind::Damaged(format!("a message record of {len} bytes")));
            return Ok(Step::Ended);
        }
        if let Got::Eof = self.fill(HEADER)? {
            self.eof(at, false);
            return Ok(Step::Ended);
        }
        let b = &self.buf;
        let channel_id = u16::from_le_bytes([b[0], b[1]]);
        let sequence = u32::from_le_bytes([b[2], b[3], b[4], b[5]]);
        let mut t = [0u8; 8];
        t.copy_from_slice(&b[6..14]);
        let log_time = u64::from_le_bytes(t);
        t.copy_from_slice(&b[14..22]);
        let publish_time = u64::from_le_bytes(t);
        let Some(channel) = self.channels.get(&channel_id).cloned() else {
            self.cut_at(
                at,
                CutKind::Damaged(format!("a message of channel {channel_id}, which the file did not name")),
            );
            return Ok(Step::Ended);
        };
        let keep = !self.skip_all && !self.skipped.contains(&channel_id);
        let got = if keep { self.fill(len - HEADER)? } else { self.pass(len - HEADER)? };
        if let Got::Eof = got {
            self.eof(at, false);
            return Ok(Step::Ended);
        }
        self.messages += 1;
        self.last_log_time = Some(log_time);
        Ok(if keep { Step::Kept { channel, sequence, log_time, publish_time } } else { Step::Skipped })
    }

    /// A schema or channel record, in `self.buf`: a new channel, or nothing
    /// new (a schema, a channel named again); what is wrong with it.
    fn definition(&mut self, opcode: u8) -> Result<Option<Channel>, String> {
        match mcap::parse_record(opcode, &self.buf) {
            Ok(mcap::records::Record::Schema { header, data }) => {
                let schema = mcap::Schema {
                    id: header.id,
                    name: header.name,
                    encoding: header.encoding,
                    data: std::borrow::Cow::Owned(data.into_owned()),
                };
                self.schemas.entry(header.id).or_insert_with(|| Arc::new(schema));
                Ok(None)
            }
            Ok(mcap::records::Record::Channel(c)) => {
                if self.channels.contains_key(&c.id) {
                    return Ok(None);
                }
                let schema = match c.schema_id {
                    0 => None,
                    id => Some(
                        self.schemas
                            .get(&id)
                            .cloned()
                            .ok_or_else(|| format!("channel {} names schema {id}, which the file did not", c.topic))?,
                    ),
                };
                let ch = Arc::new(mcap::Channel {
                    id: c.id,
                    topic: c.topic,
                    schema,
                    message_encoding: c.message_encoding,
                    metadata: c.metadata,
                });
                self.channels.insert(ch.id, ch.clone());
                Ok(Some(ch))
            }
            Ok(_) => Ok(None),
            Err(e) => Err(format!(
                "a {} record that does not parse: {e}",
                if opcode == op::SCHEMA { "schema" } else { "channel" }
            )),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{PortChannel, RecordingWriter, Sample};
    use shm_schemas::Described;
    use shm_schemas::payloads::Tick;
    use std::io::Cursor;

    /// A recording of `n` ticks of 16 bytes, in chunks of `chunk` bytes;
    /// with `finish`, closed as the recorder closes it.
    fn recording(n: u64, finish: bool) -> Vec<u8> {
        let mut out = Vec::new();
        let mut w = RecordingWriter::with_chunk_size(Cursor::new(&mut out), 1024).expect("writer");
        let schema = Tick::schema();
        let ch = w
            .add_port(&PortChannel {
                robot: "r",
                agent: "t1",
                port: "tick",
                type_name: &schema.type_name,
                fingerprint: schema.fingerprint(),
                schema: &schema,
            })
            .expect("channel");
        for i in 0..n {
            let bytes = i.to_le_bytes().repeat(2);
            w.write_sample(ch, &Sample { seq: i, log_time_ns: 1_000 + i, stamp_ns: i, bytes: &bytes }).expect("sample");
        }
        if finish {
            w.finish().expect("finish");
        } else {
            // as a kill leaves it: what was written, nothing more
            std::mem::forget(w);
        }
        out
    }

    /// The sequences read from `bytes`, and how it ended.
    fn read_all(bytes: &[u8]) -> (Vec<u32>, End) {
        let mut r = RecordingReader::new(Cursor::new(bytes), "t.mcap").expect("mcap");
        let mut seqs = Vec::new();
        while let Some(e) = r.next_event().expect("read") {
            if let Event::Message(m) = e {
                assert_eq!(m.data, u64::from(m.sequence).to_le_bytes().repeat(2), "message {}", m.sequence);
                seqs.push(m.sequence);
            }
        }
        (seqs, r.end().cloned().expect("an end"))
    }

    #[test]
    fn a_whole_file_reads_whole() {
        let (seqs, end) = read_all(&recording(500, true));
        assert_eq!(seqs, (0..500).collect::<Vec<u32>>());
        assert_eq!(end, End::Complete);
    }

    #[test]
    fn a_file_cut_anywhere_reads_up_to_its_last_whole_message() {
        let whole = recording(120, false);
        let (all, end) = read_all(&whole);
        assert_eq!(all, (0..120).collect::<Vec<u32>>(), "a file never closed: every message written");
        assert!(matches!(end, End::Cut(Cut { kind: CutKind::UnfinishedChunk, .. })), "{end:?}");
        let mut last = 0;
        for len in 8..whole.len() {
            let (seqs, end) = read_all(&whole[..len]);
            assert_eq!(seqs, (0..seqs.len() as u32).collect::<Vec<_>>(), "cut at {len}: a prefix, in order");
            assert!(seqs.len() >= last, "cut at {len}: fewer messages than a shorter cut");
            // one byte more completes at most one message: each message is
            // read from the byte that ends it, only the one cut is lost
            assert!(seqs.len() <= last + 1, "cut at {len}: {} messages after {last}", seqs.len());
            last = seqs.len();
            let End::Cut(cut) = end else { panic!("cut at {len}: read as whole") };
            assert_eq!(cut.messages, seqs.len() as u64);
        }
        let e = RecordingReader::new(Cursor::new(&whole[..5]), "t.mcap").expect_err("no magic");
        assert!(e.to_string().contains("not a readable MCAP file"), "{e}");
    }

    #[test]
    fn a_cut_says_what_was_read_and_lost() {
        let whole = recording(100, false);
        let mut r = RecordingReader::new(Cursor::new(&whole[..whole.len() - 10]), "run.mcap").expect("mcap");
        r.skip_messages();
        let mut channels = 0;
        while let Some(e) = r.next_event().expect("read") {
            assert!(matches!(e, Event::Channel(_)), "messages are skipped");
            channels += 1;
        }
        assert_eq!(channels, 1);
        let cut = r.cut().expect("cut").to_string();
        assert!(cut.starts_with("run.mcap ends in an unfinished chunk at byte "), "{cut}");
        assert!(cut.contains("read 99 messages up to 1970-01-01 00:00:00.0 UTC"), "{cut}");
        assert!(cut.contains("the rest of the last chunk is lost"), "{cut}");
        assert_eq!(grouped(12_345_678), "12,345,678");
        assert_eq!(grouped(999), "999");
        assert_eq!(clock_text(1_764_000_000_550_000_000), "2025-11-24 16:00:00.5 UTC");
    }

    #[test]
    fn zeros_after_the_last_record_are_damage_not_messages() {
        let mut bytes = recording(50, false);
        bytes.extend(std::iter::repeat_n(0u8, 4096));
        let (seqs, end) = read_all(&bytes);
        assert_eq!(seqs.len(), 50);
        assert!(matches!(end, End::Cut(Cut { kind: CutKind::Damaged(_), .. })), "{end:?}");
    }

    #[test]
    fn bad_schemas_are_refused_before_use() {
        let schema = mcap::Schema {
            id: 1,
            name: "t".into(),
            encoding: SCHEMA_ENCODING.into(),
            data: std::borrow::Cow::Owned(serde_json::to_vec(&Tick::schema()).expect("json")),
        };
        let good = mcap::Channel {
            id: 1,
            topic: "t1/tick".into(),
            schema: Some(Arc::new(schema.clone())),
            message_encoding: MESSAGE_ENCODING.into(),
            metadata: BTreeMap::new(),
        };
        assert!(nerve_schema("f.mcap", &good).is_ok());
        let mut value = serde_json::to_value(Tick::schema()).expect("json");
        value["align"] = serde_json::json!(3);
        let bad_schema =
            mcap::Schema { data: std::borrow::Cow::Owned(serde_json::to_vec(&value).expect("json")), ..schema };
        let bad = mcap::Channel { schema: Some(Arc::new(bad_schema)), ..good };
        let e = nerve_schema("f.mcap", &bad).expect_err("align 3");
        assert!(e.to_string().contains("f.mcap") && e.to_string().contains("t1/tick"), "{e}");
        assert!(matches!(e, SchemaError::Invalid { .. }), "{e}");
    }
}
