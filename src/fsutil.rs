//! Files that are never half-written, never written through a planted
//! link, never written over the file they were made from, and never put
//! in a run directory by another command ([`check_output`], in `guard`).
//!
//! Output goes to a new file with a random name in the target's directory,
//! created exclusively (`O_EXCL`, by the `tempfile` crate), synced, then
//! renamed over the target: readers see the old file or the whole new one,
//! and a symlink planted under a predictable temporary name is never
//! followed. A temporary left by a crash is removed when its handle drops.

use std::fs::File;
use std::io::Write;
use std::path::{Path, PathBuf};

mod guard;
pub use guard::{
    OutputRefused, OutputRule, RUN_LOCK, RUN_LOG, check_output, is_run_dir, real_path,
};

/// A file being written beside `target`; [`Pending::commit`] puts it in
/// place, dropping it removes it.
///
/// [`Pending::new`] replaces whatever is at `target` (a file gyrobench
/// owns, in its own run directory: a link planted there is replaced, never
/// followed). [`Pending::output`] is for a path the user named (`-o`): a
/// link is written where it points (the link stays), a FIFO or a device
/// (`-o /dev/stdout`) directly, as neither can be renamed over.
#[derive(Debug)]
pub struct Pending {
    file: Option<File>,
    temp: Option<tempfile::TempPath>,
    target: PathBuf,
}

/// Where an output named `path` really goes: through links.
fn resolve(path: &Path) -> PathBuf {
    let is_link = std::fs::symlink_metadata(path).is_ok_and(|m| m.file_type().is_symlink());
    if !is_link {
        return path.to_owned();
    }
    std::fs::canonicalize(path).unwrap_or_else(|_| {
        // A dangling link: the file it names, created there.
        match std::fs::read_link(path) {
            Ok(t) if t.is_absolute() => t,
            Ok(t) => path.parent().map_or(t.clone(), |d| d.join(t)),
            Err(_) => path.to_owned(),
        }
    })
}

impl Pending {
    /// An output the user named: through links; a FIFO or a device is
    /// written directly.
    pub fn output(target: &Path) -> std::io::Result<Self> {
        let target = &resolve(target);
        if let Ok(m) = std::fs::metadata(target)
            && !m.is_file()
            && !m.is_dir()
        {
            let file = std::fs::OpenOptions::new().write(true).open(target)?;
            return Ok(Self {
                file: Some(file),
                temp: None,
                target: target.to_owned(),
            });
        }
        Self::new(target)
    }

    /// An exclusively created temporary beside `target`, to replace it.
    pub fn new(target: &Path) -> std::io::Result<Self> {
        let dir = match target.parent() {
            Some(d) if !d.as_os_str().is_empty() => d,
            _ => Path::new("."),
        };
        let name = target.file_name().ok_or_else(|| {
            std::io::Error::new(std::io::ErrorKind::InvalidInput, "path has no file name")
        })?;
        let mut prefix = std::ffi::OsString::from(".");
        prefix.push(name);
        prefix.push(".");
        // The mode a plain create gives (0666 less the umask), not the
        // temporary's private 0600: the result is an ordinary output file.
        // A missing directory said plainly: tempfile's own error names its
        // random temporary, which only confuses.
        std::fs::metadata(dir)?;
        let named = tempfile::Builder::new()
            .prefix(&prefix)
            .suffix(".partial")
            .permissions(std::os::unix::fs::PermissionsExt::from_mode(0o666))
            .tempfile_in(dir)?;
        let (file, temp) = named.into_parts();
        Ok(Self {
            file: Some(file),
            temp: Some(temp),
            target: target.to_owned(),
        })
    }

    /// The temporary's path (for messages).
    pub fn path(&self) -> &Path {
        self.temp.as_deref().unwrap_or(&self.target)
    }

    /// Take the open file to write through (once).
    pub fn take_file(&mut self) -> std::io::Result<File> {
        self.file
            .take()
            .ok_or_else(|| std::io::Error::other("the temporary file was taken already"))
    }

    /// Sync the written file and rename it over the target.
    pub fn commit(self) -> std::io::Result<()> {
        let Some(temp) = self.temp else {
            return Ok(());
        };
        File::open(&temp)?.sync_all()?;
        temp.persist(&self.target)
            .map_err(|e| std::io::Error::new(e.error.kind(), e.error))
    }
}

/// Write `bytes` to `path` through a [`Pending`] file that replaces it
/// (gyrobench's own files).
pub fn write_atomic(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    write_pending(Pending::new(path)?, bytes)
}

/// Write `bytes` to an output the user named ([`Pending::output`]).
pub fn write_output(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    write_pending(Pending::output(path)?, bytes)
}

fn write_pending(mut p: Pending, bytes: &[u8]) -> std::io::Result<()> {
    let mut f = p.take_file()?;
    f.write_all(bytes)?;
    if p.temp.is_some() {
        f.sync_all()?;
    }
    drop(f);
    p.commit()
}

/// An output that would destroy an input.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error(
    "the output {output} is the input {input}: writing it would destroy the input; choose another output path"
)]
pub struct SamePath {
    /// The output as given.
    pub output: String,
    /// The input it names.
    pub input: String,
}

/// Refuse an `output` that is one of `inputs` (the same path, through
/// `..` or a symlink, or the same file by another hard link).
pub fn ensure_distinct(output: &Path, inputs: &[&Path]) -> Result<(), SamePath> {
    use std::os::unix::fs::MetadataExt;
    let out_id = std::fs::metadata(output).ok().map(|m| (m.dev(), m.ino()));
    let out_canon = canonical(output);
    for input in inputs {
        let same_file =
            out_id.is_some() && std::fs::metadata(input).ok().map(|m| (m.dev(), m.ino())) == out_id;
        if same_file || (out_canon.is_some() && canonical(input) == out_canon) {
            return Err(SamePath {
                output: output.display().to_string(),
                input: input.display().to_string(),
            });
        }
    }
    Ok(())
}

/// The path with its directory resolved, even when the file itself does
/// not exist yet.
fn canonical(p: &Path) -> Option<PathBuf> {
    if let Ok(c) = p.canonicalize() {
        return Some(c);
    }
    let name = p.file_name()?;
    let dir = match p.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    Some(dir.canonicalize().ok()?.join(name))
}

/// The SHA-256 of a file, in hex.
pub fn sha256_file(path: &Path) -> std::io::Result<String> {
    use sha2::Digest;
    use std::io::Read;
    let mut f = std::fs::File::open(path)?;
    let mut h = sha2::Sha256::new();
    let mut buf = vec![0u8; 1 << 16];
    loop {
        let n = f.read(&mut buf)?;
        if n == 0 {
            break;
        }
        h.update(&buf[..n]);
    }
    Ok(hex(&h.finalize()))
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// The SHA-256 of a text, in hex.
pub fn sha256_text(text: &str) -> String {
    sha256_bytes(text.as_bytes())
}

/// The SHA-256 of bytes, in hex.
pub fn sha256_bytes(bytes: &[u8]) -> String {
    use sha2::Digest;
    hex(&sha2::Sha256::digest(bytes))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn temp_dir(tag: &str) -> PathBuf {
        let dir =
            std::env::temp_dir().join(format!("gyrobench-fsutil-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).expect("temp dir");
        dir
    }

    #[test]
    fn writes_whole_file_and_leaves_no_temporary() {
        let dir = temp_dir("whole");
        let p = dir.join("out.csv");
        write_atomic(&p, b"a,b\n1,2\n").expect("write");
        assert_eq!(std::fs::read(&p).expect("read back"), b"a,b\n1,2\n");
        let mode = std::os::unix::fs::PermissionsExt::mode(
            &std::fs::metadata(&p).expect("meta").permissions(),
        );
        assert_eq!(mode & 0o044, 0o044, "readable like any output, {mode:o}");
        let names: Vec<_> = std::fs::read_dir(&dir).expect("list").collect();
        assert_eq!(names.len(), 1, "temporary left behind");
        std::fs::remove_dir_all(&dir).expect("cleanup");
    }

    #[test]
    fn a_planted_symlink_at_the_old_temporary_name_is_not_followed() {
        let dir = temp_dir("symlink");
        let victim = dir.join("victim.txt");
        std::fs::write(&victim, b"keep me").expect("victim");
        let pid = std::process::id();
        for name in [
            format!(".report.json.tmp{pid}"),
            "report.json.partial".to_owned(),
        ] {
            std::os::unix::fs::symlink(&victim, dir.join(name)).expect("plant");
        }
        write_atomic(&dir.join("report.json"), b"{}").expect("write");
        assert_eq!(std::fs::read(&victim).expect("victim"), b"keep me");
        assert_eq!(std::fs::read(dir.join("report.json")).expect("out"), b"{}");
        std::fs::remove_dir_all(&dir).expect("cleanup");
    }

    #[test]
    fn an_output_link_is_written_through_and_a_fifo_directly() {
        let dir = temp_dir("through");
        let real = dir.join("real.csv");
        std::fs::write(&real, b"old").expect("real");
        let link = dir.join("link.csv");
        std::os::unix::fs::symlink(&real, &link).expect("link");
        write_output(&link, b"new").expect("through the link");
        assert_eq!(std::fs::read(&real).expect("real"), b"new");
        assert!(
            std::fs::symlink_metadata(&link)
                .expect("link")
                .file_type()
                .is_symlink(),
            "the link stays a link"
        );
        let null = Path::new("/dev/null");
        write_output(null, b"gone").expect("a device is written directly");
        assert!(
            !std::fs::metadata(null).expect("dev").is_file(),
            "/dev/null untouched"
        );
        std::fs::remove_dir_all(&dir).expect("cleanup");
    }

    #[test]
    fn a_dropped_pending_file_leaves_nothing() {
        let dir = temp_dir("drop");
        let mut p = Pending::new(&dir.join("x.mcap")).expect("pending");
        p.take_file()
            .expect("file")
            .write_all(b"half")
            .expect("write");
        drop(p);
        assert_eq!(std::fs::read_dir(&dir).expect("list").count(), 0);
        std::fs::remove_dir_all(&dir).expect("cleanup");
    }

    #[test]
    fn an_output_naming_an_input_is_refused_however_it_is_spelled() {
        let dir = temp_dir("same");
        let a = dir.join("a.mcap");
        std::fs::write(&a, b"log").expect("a");
        std::fs::create_dir_all(dir.join("sub")).expect("sub");
        let dotted = dir.join("sub").join("..").join("a.mcap");
        let link = dir.join("b.mcap");
        std::fs::hard_link(&a, &link).expect("hard link");
        let sym = dir.join("c.mcap");
        std::os::unix::fs::symlink(&a, &sym).expect("symlink");
        for out in [&a, &dotted, &link, &sym] {
            assert!(ensure_distinct(out, &[&a]).is_err(), "{}", out.display());
        }
        assert!(ensure_distinct(&dir.join("new.mcap"), &[&a]).is_ok());
        std::fs::remove_dir_all(&dir).expect("cleanup");
    }
}
