//! An append-only row store that keeps its tail in memory and the rest in
//! an anonymous temporary file, so a run's 1 Hz records hold a constant
//! amount of memory however long the run is.
//!
//! Rows are fixed-size little-endian encodings ([`Row`]), so what is read
//! back is bit for bit what was filed: the live run, replay and the reports
//! made from either agree as they did with the rows in memory.
//!
//! A [`Spill`] is a view: the rows it holds, as ranges of a shared arena.
//! Cloning it is cheap (the ranges are copied, the arena is shared), and a
//! clone that files more rows appends them to the arena's end without
//! touching what another view sees, as a resumed run does with the records
//! of the part before it.
//!
//! When the temporary file cannot be made or written (no space), rows stay
//! in memory: nothing is lost, the store only stops being constant, and
//! [`Spill::write_fault`] says why. Rows the file cannot give back are
//! missing from what is read, and each such read is counted
//! ([`Spill::read_faults`]): a figure computed while the count rose is not
//! judged, a chart drawn while it rose says so.

use std::fs::File;
use std::io::{Read, Seek, SeekFrom, Write};
use std::ops::Range;
use std::sync::{Arc, Mutex, PoisonError};

/// Rows kept in memory before they are written to the file.
const TAIL_ROWS: usize = 4096;

/// A fixed-size row.
pub trait Row: Copy {
    /// Its size in bytes.
    const SIZE: usize;
    /// Write it to `out` (`SIZE` bytes).
    fn encode(&self, out: &mut Vec<u8>);
    /// Read it back from `b` (`SIZE` bytes).
    fn decode(b: &[u8]) -> Self;
}

/// The rows every view of one store appends to.
#[derive(Debug)]
struct Arena<T> {
    /// Rows written to `file` (the first `flushed` rows).
    flushed: u64,
    /// Rows after them.
    tail: Vec<T>,
    /// The file (none until the tail first fills, or when it cannot be
    /// made or written: then the tail keeps every later row).
    file: Option<File>,
    /// Set once the file could not be made or written: rows stay in memory.
    in_memory: bool,
    /// Why the file could not be made or written, once it could not.
    write_fault: Option<String>,
    /// Reads the file could not answer, and the last one's reason.
    read_faults: (u64, Option<String>),
}

impl<T: Row> Arena<T> {
    fn new() -> Self {
        Self {
            flushed: 0,
            tail: Vec::new(),
            file: None,
            in_memory: false,
            write_fault: None,
            read_faults: (0, None),
        }
    }

    fn len(&self) -> u64 {
        self.flushed + self.tail.len() as u64
    }

    fn push(&mut self, row: T) -> u64 {
        let at = self.len();
        self.tail.push(row);
        if self.tail.len() >= TAIL_ROWS && !self.in_memory {
            self.flush();
        }
        at
    }

    /// Write the tail to the file; on failure keep it (and every later
    /// row) in memory.
    fn flush(&mut self) {
        let mut bytes = Vec::with_capacity(self.tail.len() * T::SIZE);
        for r in &self.tail {
            r.encode(&mut bytes);
        }
        if self.file.is_none() {
            match tempfile::tempfile() {
                Ok(f) => self.file = Some(f),
                Err(e) => {
                    self.in_memory = true;
                    self.write_fault = Some(format!(
                        "the record store's temporary file could not be made ({e}); its rows stay in memory"
                    ));
                    return;
                }
            }
        }
        let at = self.flushed * T::SIZE as u64;
        let written = self.file.as_mut().map(|f| {
            f.seek(SeekFrom::Start(at))
                .and_then(|_| f.write_all(&bytes))
        });
        match written {
            Some(Ok(())) => {
                self.flushed += self.tail.len() as u64;
                self.tail.clear();
            }
            // The rows already written stay readable; these and every
            // later one stay here.
            Some(Err(e)) => {
                self.in_memory = true;
                self.write_fault = Some(format!(
                    "the record store's temporary file could not be written ({e}); its rows stay in memory"
                ));
            }
            None => self.in_memory = true,
        }
    }

    /// Rows `r` of the arena (at most a tail's worth), appended to `out`.
    fn read(&mut self, r: Range<u64>, out: &mut Vec<T>) {
        let on_file = r.start..r.end.min(self.flushed);
        if !on_file.is_empty() {
            let mut bytes = vec![0; (on_file.end - on_file.start) as usize * T::SIZE];
            let read = match self.file.as_mut() {
                Some(file) => file
                    .seek(SeekFrom::Start(on_file.start * T::SIZE as u64))
                    .and_then(|_| file.read_exact(&mut bytes)),
                None => Err(std::io::Error::other("the file is gone")),
            };
            match read {
                Ok(()) => out.extend(bytes.chunks_exact(T::SIZE).map(T::decode)),
                Err(e) => {
                    self.read_faults.0 += 1;
                    self.read_faults.1 = Some(format!(
                        "the record store's temporary file could not be read back ({e})"
                    ));
                }
            }
        }
        let in_tail = r.start.max(self.flushed)..r.end;
        if !in_tail.is_empty() {
            let from = (in_tail.start - self.flushed) as usize;
            let to = (in_tail.end - self.flushed) as usize;
            out.extend_from_slice(self.tail.get(from..to).unwrap_or_default());
        }
    }
}

/// A view of the rows filed in a store, in the order they were filed.
#[derive(Debug)]
pub struct Spill<T> {
    arena: Arc<Mutex<Arena<T>>>,
    /// The arena's rows this view holds, in order.
    ranges: Vec<Range<u64>>,
    /// Their number.
    len: u64,
}

impl<T> Clone for Spill<T> {
    fn clone(&self) -> Self {
        Self {
            arena: Arc::clone(&self.arena),
            ranges: self.ranges.clone(),
            len: self.len,
        }
    }
}

impl<T: Row> Default for Spill<T> {
    fn default() -> Self {
        Self {
            arena: Arc::new(Mutex::new(Arena::new())),
            ranges: Vec::new(),
            len: 0,
        }
    }
}

impl<T: Row> Spill<T> {
    fn arena(&self) -> std::sync::MutexGuard<'_, Arena<T>> {
        self.arena.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// Rows in the view.
    pub fn len(&self) -> u64 {
        self.len
    }

    /// Whether the view holds no row.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// File a row; returns its index in the view.
    pub fn push(&mut self, row: T) -> u64 {
        let at = self.arena().push(row);
        match self.ranges.last_mut() {
            Some(r) if r.end == at => r.end += 1,
            _ => self.ranges.push(at..at + 1),
        }
        self.len += 1;
        self.len - 1
    }

    /// The view's rows `r` (indices in the view; clipped to its length).
    pub fn get(&self, r: Range<u64>) -> Vec<T> {
        let mut out = Vec::new();
        self.for_each(r, |row| out.push(row));
        out
    }

    /// Hand the view's rows `r` to `f` in order (clipped to its length),
    /// a tail's worth at a time: the store is not locked while `f` runs,
    /// so `f` may read the store too.
    pub fn for_each(&self, r: Range<u64>, mut f: impl FnMut(T)) {
        let r = r.start.min(self.len)..r.end.min(self.len);
        let mut chunk = Vec::new();
        let mut at = 0;
        for range in &self.ranges {
            let n = range.end - range.start;
            let mut from = r.start.max(at);
            let to = r.end.min(at + n);
            while from < to {
                let upto = to.min(from + TAIL_ROWS as u64);
                chunk.clear();
                self.arena()
                    .read(range.start + from - at..range.start + upto - at, &mut chunk);
                chunk.iter().copied().for_each(&mut f);
                from = upto;
            }
            at += n;
            if at >= r.end {
                break;
            }
        }
    }

    /// Every row of the view.
    pub fn all(&self) -> Vec<T> {
        self.get(0..self.len)
    }

    /// Reads the file could not answer so far (in every view of the
    /// store), and the last one's reason.
    pub fn read_faults(&self) -> (u64, Option<String>) {
        self.arena().read_faults.clone()
    }

    /// Lose the file, as a disk that fails would (tests of what a failed
    /// read does).
    #[cfg(test)]
    pub(crate) fn lose_file(&self) {
        self.arena().file = None;
    }

    /// Why the store keeps its rows in memory (its file could not be made
    /// or written), once it does.
    pub fn write_fault(&self) -> Option<String> {
        self.arena().write_fault.clone()
    }
}

/// Read `N` bytes at `at` of a row.
pub fn bytes_at<const N: usize>(b: &[u8], at: usize) -> [u8; N] {
    let mut out = [0; N];
    if let Some(s) = b.get(at..at + N) {
        out.copy_from_slice(s);
    }
    out
}

/// An `f64` at byte `at` of a row.
pub fn f64_at(b: &[u8], at: usize) -> f64 {
    f64::from_le_bytes(bytes_at(b, at))
}

#[cfg(test)]
mod tests {
    use super::*;

    impl Row for u64 {
        const SIZE: usize = 8;
        fn encode(&self, out: &mut Vec<u8>) {
            out.extend_from_slice(&self.to_le_bytes());
        }
        fn decode(b: &[u8]) -> Self {
            u64::from_le_bytes(bytes_at(b, 0))
        }
    }

    #[test]
    fn rows_read_back_across_the_file_and_the_tail() {
        let mut s = Spill::<u64>::default();
        let n = TAIL_ROWS as u64 * 2 + 17;
        for i in 0..n {
            assert_eq!(s.push(i * 3), i);
        }
        assert_eq!(s.arena().flushed, TAIL_ROWS as u64 * 2, "two tails written");
        assert!(s.arena().file.is_some());
        assert_eq!(s.all(), (0..n).map(|i| i * 3).collect::<Vec<_>>());
        let edge = TAIL_ROWS as u64 * 2;
        assert_eq!(
            s.get(edge - 2..edge + 2),
            [edge - 2, edge - 1, edge, edge + 1].map(|i| i * 3)
        );
        assert_eq!(s.get(n - 1..n + 10), [(n - 1) * 3], "clipped to the view");
        assert!(s.get(n..n + 1).is_empty());
        assert_eq!(s.read_faults(), (0, None));
        assert!(s.write_fault().is_none());
    }

    #[test]
    fn a_clone_that_files_more_leaves_the_other_view_as_it_was() {
        let mut a = Spill::<u64>::default();
        for i in 0..10 {
            a.push(i);
        }
        let mut b = a.clone();
        for i in 100..105 {
            b.push(i);
        }
        a.push(10);
        b.push(105);
        assert_eq!(a.all(), (0..11).collect::<Vec<_>>());
        let mut want: Vec<u64> = (0..10).collect();
        want.extend(100..106);
        assert_eq!(b.all(), want);
        assert_eq!(b.get(9..11), [9, 100]);
        assert_eq!(
            b.ranges,
            [0..15, 16..17],
            "b's rows: its own after the shared, then past a's"
        );
    }

    #[test]
    fn what_reads_each_row_may_read_the_store_too() {
        let mut s = Spill::<u64>::default();
        for i in 0..(TAIL_ROWS as u64 + 10) {
            s.push(i);
        }
        let mut firsts = 0;
        s.for_each(0..s.len(), |_| firsts += s.get(0..1)[0]);
        assert_eq!(firsts, 0);
        let mut n = 0;
        s.for_each(TAIL_ROWS as u64 - 1..TAIL_ROWS as u64 + 1, |row| {
            n += 1;
            assert_eq!(s.get(row..row + 1), [row]);
        });
        assert_eq!(n, 2);
    }
}
