//! Input files read as files: regular files only, opened without blocking,
//! never read past a limit.
//!
//! A path a user gives may name a FIFO (opening one for reading waits for
//! a writer, which may never come), a device (`/dev/zero` never ends; a
//! serial port's open raises its control lines), a directory or a socket.
//! Every gyrobench input is a file: anything else is refused by name
//! before it is opened for reading. The type is checked again on the open
//! file (opened `O_NONBLOCK`, so a FIFO swapped in meanwhile is refused,
//! not waited on). The size `metadata` gives is not trusted (a file may
//! grow while it is read, `/proc` files say 0): a whole read stops one byte
//! past its limit, and a file of text rows is read through
//! [`LinesOfAtMost`], which stops at the first line longer than its limit.

use std::fs::File;
use std::io::Read;
use std::path::{Path, PathBuf};

/// Why an input file is not read.
#[derive(Debug, thiserror::Error)]
pub enum InputError {
    /// It could not be opened or read.
    #[error("cannot read {path}: {cause}; check the path")]
    Io {
        /// The file.
        path: PathBuf,
        /// What the system said (in the message too: the CLI's error
        /// chain leaves out a source its message already says).
        #[source]
        cause: std::io::Error,
    },
    /// It is a FIFO, a device, a directory or a socket.
    #[error(
        "{path} is {kind}, not a regular file; gyrobench reads its inputs from files only: \
         give the path of a file (save a stream or a device's output to a file first)"
    )]
    NotAFile {
        /// The file.
        path: PathBuf,
        /// What it is ("a FIFO (named pipe)", "a character device", ...).
        kind: &'static str,
    },
    /// Longer than the limit of a whole read.
    #[error("{path} is larger than {limit} bytes, the most gyrobench reads of such a file")]
    TooLarge {
        /// The file.
        path: PathBuf,
        /// The limit, bytes.
        limit: u64,
    },
}

/// What a file type is, in words, when it is not a regular file.
fn kind_of(t: std::fs::FileType) -> &'static str {
    if t.is_dir() {
        return "a directory";
    }
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        if t.is_fifo() {
            return "a FIFO (named pipe)";
        } else if t.is_char_device() {
            return "a character device";
        } else if t.is_block_device() {
            return "a block device";
        } else if t.is_socket() {
            return "a socket";
        }
    }
    "not a file"
}

/// Open `path` for reading if it is a regular file (through links), and
/// only then: anything else is [`InputError::NotAFile`], refused before
/// it is opened where the path says so, and again on the open file.
pub fn open_file(path: &Path) -> Result<File, InputError> {
    let not_a_file = |t: std::fs::FileType| InputError::NotAFile {
        path: path.to_owned(),
        kind: kind_of(t),
    };
    let io = |cause| InputError::Io {
        path: path.to_owned(),
        cause,
    };
    if let Ok(m) = std::fs::metadata(path)
        && !m.is_file()
    {
        return Err(not_a_file(m.file_type()));
    }
    // Without blocking: a FIFO put in the file's place after the check
    // above opens at once, and is refused below. On a regular file the
    // flag changes nothing.
    let mut options = std::fs::OpenOptions::new();
    options.read(true);
    #[cfg(unix)]
    std::os::unix::fs::OpenOptionsExt::custom_flags(&mut options, libc::O_NONBLOCK);
    let file = options.open(path).map_err(io)?;
    let t = file.metadata().map_err(io)?.file_type();
    if !t.is_file() {
        return Err(not_a_file(t));
    }
    Ok(file)
}

/// The whole of the regular file at `path`, if it holds at most `limit`
/// bytes: the read stops at `limit + 1` bytes, whatever the file's size
/// said.
pub fn read_at_most(path: &Path, limit: u64) -> Result<Vec<u8>, InputError> {
    let file = open_file(path)?;
    let mut bytes = Vec::new();
    file.take(limit.saturating_add(1))
        .read_to_end(&mut bytes)
        .map_err(|cause| InputError::Io {
            path: path.to_owned(),
            cause,
        })?;
    if bytes.len() as u64 > limit {
        return Err(InputError::TooLarge {
            path: path.to_owned(),
            limit,
        });
    }
    Ok(bytes)
}

/// A line of a text file longer than a reader takes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error(
    "line {line} is longer than {max} bytes; a row of a text file is far shorter: is it the right \
     file?"
)]
pub struct LineTooLong {
    /// The line, counted from 1.
    pub line: u64,
    /// The most a line may hold, bytes.
    pub max: usize,
}

/// A reader of text rows that fails (an `InvalidData` error holding a
/// [`LineTooLong`]) once a line, the bytes from one `\n` to the next,
/// grows past `max`: what reads through it never has to hold more than
/// that of one line, however long the file or stream.
#[derive(Debug)]
pub struct LinesOfAtMost<R> {
    inner: R,
    max: usize,
    /// Bytes of the current line read so far.
    run: usize,
    /// Lines ended so far.
    ended: u64,
    overlong: Option<LineTooLong>,
}

impl<R> LinesOfAtMost<R> {
    /// Read `inner`, lines of at most `max` bytes.
    pub fn new(inner: R, max: usize) -> Self {
        Self {
            inner,
            max,
            run: 0,
            ended: 0,
            overlong: None,
        }
    }

    /// The line that stopped the read, if one did.
    pub fn overlong(&self) -> Option<LineTooLong> {
        self.overlong
    }
}

impl<R: Read> Read for LinesOfAtMost<R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let too_long = |e: LineTooLong| std::io::Error::new(std::io::ErrorKind::InvalidData, e);
        if let Some(e) = self.overlong {
            return Err(too_long(e));
        }
        let n = self.inner.read(buf)?;
        // The chunk's lines: the first continues the line before it, the
        // last goes on in the next chunk.
        let mut newlines = 0;
        for (i, seg) in buf[..n].split(|&b| b == b'\n').enumerate() {
            let len = if i == 0 {
                self.run + seg.len()
            } else {
                seg.len()
            };
            if len > self.max {
                let e = LineTooLong {
                    line: self.ended + 1 + i as u64,
                    max: self.max,
                };
                self.overlong = Some(e);
                return Err(too_long(e));
            }
            newlines = i;
            self.run = len;
        }
        self.ended += newlines as u64;
        Ok(n)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[cfg(unix)]
    #[test]
    fn a_device_a_fifo_and_a_directory_are_refused_by_name_at_once() {
        let dir = tempfile::tempdir().expect("temp dir");
        let fifo = dir.path().join("procedures.toml");
        let made = std::process::Command::new("mkfifo")
            .arg(&fifo)
            .status()
            .expect("mkfifo runs");
        assert!(made.success());
        // Without O_NONBLOCK and the check, the open itself waits for a
        // writer that never comes; this test would hang, not fail.
        for (path, kind) in [
            (Path::new("/dev/zero"), "a character device"),
            (fifo.as_path(), "a FIFO (named pipe)"),
            (dir.path(), "a directory"),
        ] {
            let e = read_at_most(path, 1 << 20).expect_err("not a file");
            assert!(
                matches!(&e, InputError::NotAFile { kind: k, .. } if *k == kind),
                "{}: {e}",
                path.display()
            );
            assert!(e.to_string().contains(&path.display().to_string()), "{e}");
        }
    }

    #[test]
    fn a_whole_read_stops_one_byte_past_its_limit() {
        let dir = tempfile::tempdir().expect("temp dir");
        let p = dir.path().join("a.toml");
        std::fs::write(&p, b"0123456789").expect("write");
        assert_eq!(read_at_most(&p, 10).expect("at the limit"), b"0123456789");
        assert!(matches!(
            read_at_most(&p, 9),
            Err(InputError::TooLarge { limit: 9, .. })
        ));
    }

    #[test]
    fn a_line_longer_than_the_limit_stops_the_read_wherever_the_chunks_split() {
        let text = b"ab\nabcdef\nabc\n";
        for chunk in 1..=text.len() {
            // Lines of at most 6 bytes pass whole, in chunks of any size.
            let mut r = LinesOfAtMost::new(Chunked(text, chunk), 6);
            let mut all = Vec::new();
            r.read_to_end(&mut all).expect("short lines");
            assert_eq!(all, text);
            // At most 5: line 2 is refused, and named.
            let mut r = LinesOfAtMost::new(Chunked(text, chunk), 5);
            let e = r.read_to_end(&mut Vec::new()).expect_err("line 2");
            assert_eq!(e.kind(), std::io::ErrorKind::InvalidData);
            assert_eq!(r.overlong(), Some(LineTooLong { line: 2, max: 5 }));
        }
        // An endless stream without a newline ends at the limit.
        let mut r = LinesOfAtMost::new(std::io::repeat(0), 1 << 16);
        assert!(r.read_to_end(&mut Vec::new()).is_err());
        assert_eq!(r.overlong().map(|e| e.line), Some(1));
    }

    /// A reader that gives at most `.1` bytes at a time.
    struct Chunked<'a>(&'a [u8], usize);

    impl Read for Chunked<'_> {
        fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
            let n = self.0.len().min(self.1).min(buf.len());
            buf[..n].copy_from_slice(&self.0[..n]);
            self.0 = &self.0[n..];
            Ok(n)
        }
    }
}
