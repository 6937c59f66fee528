//! Reading the simulator's ground-truth CSV (`nerve_sim::TRUTH_HEADER`).
//!
//! Columns are found by name in the header, so a simulator that adds columns
//! does not break the reader. The file may be read while the simulator still
//! writes it: an incomplete last line is skipped, and [`TruthTail`] reads only
//! what was appended since its last call.

use crate::DemoError;
use std::io::{Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};

/// One simulation step of the ground truth.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct TruthRow {
    /// Simulated time, s.
    pub t: f64,
    /// x, m.
    pub x: f64,
    /// y, m.
    pub y: f64,
    /// Heading, rad, (-π, π].
    pub theta: f64,
    /// Forward speed, m/s.
    pub v: f64,
    /// Turn rate, rad/s.
    pub omega: f64,
    /// Collisions so far.
    pub collisions: u64,
    /// Touching something now.
    pub in_contact: bool,
}

/// Where each needed column is.
#[derive(Debug, Clone, Copy)]
struct Columns {
    t: usize,
    x: usize,
    y: usize,
    theta: usize,
    v: usize,
    omega: usize,
    collisions: usize,
    in_contact: Option<usize>,
}

impl Columns {
    fn from_header(line: &str) -> Result<Self, String> {
        let names: Vec<&str> = line.trim().split(',').map(str::trim).collect();
        let find = |n: &str| {
            names.iter().position(|c| *c == n).ok_or_else(|| {
                format!("the header has no column {n:?} (header: {}); is this a nerve-sim truth log?", line.trim())
            })
        };
        Ok(Columns {
            t: find("t")?,
            x: find("x")?,
            y: find("y")?,
            theta: find("theta")?,
            v: find("v")?,
            omega: find("omega")?,
            collisions: find("collisions")?,
            in_contact: names.iter().position(|c| *c == "in_contact"),
        })
    }

    fn parse(&self, line: &str) -> Option<TruthRow> {
        let f: Vec<&str> = line.trim().split(',').collect();
        let num = |i: usize| f.get(i).and_then(|s| s.trim().parse::<f64>().ok()).filter(|x| x.is_finite());
        Some(TruthRow {
            t: num(self.t)?,
            x: num(self.x)?,
            y: num(self.y)?,
            theta: num(self.theta)?,
            v: num(self.v)?,
            omega: num(self.omega)?,
            collisions: f.get(self.collisions)?.trim().parse().ok()?,
            in_contact: match self.in_contact {
                Some(i) => f.get(i)?.trim() == "1",
                None => false,
            },
        })
    }
}

/// Parses complete CSV text. Lines that do not parse are errors except the
/// last one, which may be cut short by a writer.
pub fn parse_truth(text: &str, origin: &Path) -> Result<Vec<TruthRow>, DemoError> {
    let mut lines = text.lines();
    let header = lines.next().ok_or_else(|| DemoError::Format {
        path: origin.to_path_buf(),
        problem: "empty file; the simulator wrote no ground truth".into(),
    })?;
    let cols =
        Columns::from_header(header).map_err(|problem| DemoError::Format { path: origin.to_path_buf(), problem })?;
    let body: Vec<&str> = lines.filter(|l| !l.trim().is_empty()).collect();
    let mut rows = Vec::with_capacity(body.len());
    for (i, l) in body.iter().enumerate() {
        match cols.parse(l) {
            Some(r) => rows.push(r),
            None if i + 1 == body.len() => {}
            None => {
                return Err(DemoError::Format {
                    path: origin.to_path_buf(),
                    problem: format!("line {} is not a truth row: {l:?}", i + 2),
                });
            }
        }
    }
    Ok(rows)
}

/// Reads a whole truth CSV.
pub fn read_truth(path: &Path) -> Result<Vec<TruthRow>, DemoError> {
    let text = std::fs::read_to_string(path).map_err(|source| DemoError::Io {
        what: "cannot read the ground-truth log",
        path: path.to_path_buf(),
        source,
    })?;
    parse_truth(&text, path)
}

/// Follows a truth CSV that is being written: each [`TruthTail::poll`]
/// returns the complete rows appended since the last call.
#[derive(Debug)]
pub struct TruthTail {
    path: PathBuf,
    offset: u64,
    partial: String,
    cols: Option<Columns>,
}

impl TruthTail {
    /// A tail of `path` (the file need not exist yet).
    pub fn new(path: &Path) -> Self {
        TruthTail { path: path.to_path_buf(), offset: 0, partial: String::new(), cols: None }
    }

    /// New complete rows; none while the file does not exist. A file that
    /// shrank (a new run) is read again from its start.
    pub fn poll(&mut self) -> Vec<TruthRow> {
        let Ok(mut f) = std::fs::File::open(&self.path) else { return vec![] };
        let len = f.metadata().map(|m| m.len()).unwrap_or(0);
        if len < self.offset {
            self.offset = 0;
            self.partial.clear();
            self.cols = None;
        }
        if f.seek(SeekFrom::Start(self.offset)).is_err() {
            return vec![];
        }
        let mut buf = Vec::new();
        let Ok(n) = f.read_to_end(&mut buf) else { return vec![] };
        self.offset += n as u64;
        self.partial.push_str(&String::from_utf8_lossy(&buf));
        let Some(end) = self.partial.rfind('\n') else { return vec![] };
        let complete: String = self.partial.drain(..=end).collect();
        let mut rows = Vec::new();
        for line in complete.lines().filter(|l| !l.trim().is_empty()) {
            match &self.cols {
                None => match Columns::from_header(line) {
                    Ok(c) => self.cols = Some(c),
                    Err(e) => tracing::warn!(file = %self.path.display(), "{e}"),
                },
                Some(c) => rows.extend(c.parse(line)),
            }
        }
        rows
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const HEAD: &str = "t,x,y,theta,v,omega,wheel_left,wheel_right,enc_left,enc_right,collisions,in_contact,pan,tilt";

    #[test]
    fn parses_and_tolerates_a_cut_last_line() {
        let text = format!(
            "{HEAD}\n0.010,1.0,2.0,0.1,0.2,0.0,0,0,0,0,0,0,0,0\n0.020,1.1,2.0,0.1,0.2,0.0,0,0,0,0,1,1,0,0\n0.03,1."
        );
        let rows = parse_truth(&text, Path::new("t.csv")).expect("parses");
        assert_eq!(rows.len(), 2);
        assert_eq!(rows[1].collisions, 1);
        assert!(rows[1].in_contact);
        let bad = format!("{HEAD}\nx,y\n0.02,1,1,0,0,0,0,0,0,0,0,0,0,0\n");
        assert!(parse_truth(&bad, Path::new("t.csv")).is_err());
        assert!(parse_truth("a,b\n", Path::new("t.csv")).is_err());
    }

    #[test]
    fn tail_reads_appended_rows_only() {
        let dir = std::env::temp_dir().join(format!("nerve-demo-tail-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("dir");
        let p = dir.join("truth.csv");
        let mut tail = TruthTail::new(&p);
        assert!(tail.poll().is_empty());
        std::fs::write(&p, format!("{HEAD}\n0.01,1,1,0,0,0,0,0,0,0,0,0,0,0\n0.02,1,")).expect("write");
        assert_eq!(tail.poll().len(), 1);
        let mut s = std::fs::read_to_string(&p).expect("read");
        s.push_str("1,0,0,0,0,0,0,0,0,0,0,0\n");
        std::fs::write(&p, s).expect("write");
        let rows = tail.poll();
        assert_eq!(rows.len(), 1);
        assert!((rows[0].t - 0.02).abs() < 1e-9);
        let _ = std::fs::remove_dir_all(&dir);
    }
}
