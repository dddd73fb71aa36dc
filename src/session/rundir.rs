//! The run directory: created new (never reused, never truncated) and
//! locked for the run's life.
//!
//! The lock is `run.lock` in the directory, held with an exclusive
//! advisory lock (`flock`, through `std::fs::File::try_lock`) that the
//! kernel releases when the process ends however it ends. The file names
//! the holder (pid, host, start); a clean end empties it. A lock file that
//! still names a holder but is free was left by a process that was killed:
//! it is reported and taken over, never silently.

use std::fs::File;
use std::io::{Read, Seek, Write};
use std::path::{Path, PathBuf};

/// Name of the lock file in a run directory.
pub const LOCK_FILE: &str = "run.lock";

/// Why a run directory cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum RunDirError {
    /// The directory holds a run already.
    #[error(
        "{path} holds a run already ({what}); choose another directory with --out, \
         resume it with `gyrobench run --resume {path}`, or give --force to move it aside"
    )]
    Exists {
        /// The directory.
        path: String,
        /// What is in it.
        what: String,
    },
    /// `--force` on a directory that holds something other than a run.
    #[error(
        "{path} is not a run directory (it holds {what} but no run.mcap); --force only moves \
         an old run aside: choose an empty or new directory with --out"
    )]
    NotARun {
        /// The directory.
        path: String,
        /// What is in it.
        what: String,
    },
    /// Another process runs in it.
    #[error(
        "{path} is in use by another run ({holder}); wait for it to end or choose another directory"
    )]
    Locked {
        /// The directory.
        path: String,
        /// Who holds the lock.
        holder: String,
    },
    /// The lock is free but names a process that still runs.
    #[error(
        "{path}/{LOCK_FILE} names {holder}, which is still running but does not hold the lock; \
         if it is not a gyrobench run, delete {path}/{LOCK_FILE} and try again"
    )]
    Suspicious {
        /// The directory.
        path: String,
        /// Who the file names.
        holder: String,
    },
    /// A file system error.
    #[error("{what} {path}: {cause}")]
    Io {
        /// What was being done.
        what: &'static str,
        /// The path.
        path: String,
        /// Cause.
        #[source]
        cause: std::io::Error,
    },
}

fn io(what: &'static str, path: &Path) -> impl FnOnce(std::io::Error) -> RunDirError {
    let path = path.display().to_string();
    move |cause| RunDirError::Io { what, path, cause }
}

/// An exclusive lock on a run directory, held until dropped.
#[derive(Debug)]
pub struct DirLock {
    file: File,
    path: PathBuf,
    /// The holder before us, when it was killed without releasing.
    pub stale: Option<String>,
}

impl DirLock {
    /// Lock `dir` for this process.
    pub fn acquire(dir: &Path, started_utc: &str) -> Result<Self, RunDirError> {
        let path = dir.join(LOCK_FILE);
        let shown = dir.display().to_string();
        // A holder that unlinks the file between our open and our lock
        // leaves us a lock on a dead inode: check and try again.
        for _ in 0..3 {
            use std::os::unix::fs::OpenOptionsExt;
            if std::fs::symlink_metadata(&path).is_ok_and(|m| !m.file_type().is_file()) {
                return Err(RunDirError::Io {
                    what: "locking",
                    path: path.display().to_string(),
                    cause: std::io::Error::other(
                        "it is not a plain file (a link, a directory): refusing to follow it; remove it",
                    ),
                });
            }
            // Never through a link planted between the check and the open.
            let mut file = std::fs::OpenOptions::new()
                .read(true)
                .write(true)
                .create(true)
                .truncate(false)
                .custom_flags(libc::O_NOFOLLOW)
                .open(&path)
                .map_err(io("opening the lock", &path))?;
            match file.try_lock() {
                Ok(()) => {}
                Err(std::fs::TryLockError::WouldBlock) => {
                    return Err(RunDirError::Locked {
                        path: shown,
                        holder: holder_text(&read_all(&mut file)),
                    });
                }
                Err(std::fs::TryLockError::Error(e)) => {
                    return Err(io("locking", &path)(e));
                }
            }
            if !same_file(&file, &path) {
                continue;
            }
            let before = read_all(&mut file);
            let stale = if before.trim().is_empty() {
                None
            } else {
                let holder = holder_text(&before);
                if holder_alive(&before) {
                    return Err(RunDirError::Suspicious {
                        path: shown,
                        holder,
                    });
                }
                Some(holder)
            };
            let me = format!(
                "pid={}\nhost={}\nstarted={started_utc}\n",
                std::process::id(),
                hostname()
            );
            file.set_len(0).map_err(io("writing the lock", &path))?;
            file.rewind().map_err(io("writing the lock", &path))?;
            file.write_all(me.as_bytes())
                .and_then(|()| file.sync_all())
                .map_err(io("writing the lock", &path))?;
            return Ok(Self { file, path, stale });
        }
        Err(RunDirError::Locked {
            path: shown,
            holder: "a process that keeps replacing the lock file".into(),
        })
    }
}

impl Drop for DirLock {
    fn drop(&mut self) {
        // Empty means "released cleanly"; the kernel drops the flock when
        // the file closes.
        let _ignored = self.file.set_len(0);
        let _ignored = std::fs::remove_file(&self.path);
    }
}

fn read_all(f: &mut File) -> String {
    let mut s = String::new();
    let _ignored = f.rewind().and_then(|()| f.read_to_string(&mut s));
    s
}

fn field<'a>(text: &'a str, key: &str) -> Option<&'a str> {
    text.lines()
        .find_map(|l| l.strip_prefix(key)?.strip_prefix('='))
}

fn holder_text(text: &str) -> String {
    match (
        field(text, "pid"),
        field(text, "host"),
        field(text, "started"),
    ) {
        (Some(pid), host, started) => format!(
            "pid {pid}{}{}",
            host.map_or(String::new(), |h| format!(" on {h}")),
            started.map_or(String::new(), |s| format!(", started {s}"))
        ),
        _ if text.trim().is_empty() => "a run that is starting".into(),
        _ => "an unknown process".into(),
    }
}

/// The process the lock file names runs on this host still. A zombie (a
/// process that ended, not yet reaped by its parent) runs no more: it
/// holds no lock and does nothing.
fn holder_alive(text: &str) -> bool {
    let on_this_host = field(text, "host").is_none_or(|h| h == hostname());
    let pid = field(text, "pid").and_then(|p| p.trim().parse::<u32>().ok());
    on_this_host && pid.is_some_and(|p| p != std::process::id() && process_runs(p))
}

/// Whether process `pid` exists and is not a zombie (`/proc/PID/stat`:
/// the state after the command name's closing parenthesis).
fn process_runs(pid: u32) -> bool {
    let Ok(stat) = std::fs::read_to_string(format!("/proc/{pid}/stat")) else {
        return false;
    };
    let state = stat
        .rsplit_once(')')
        .and_then(|(_, rest)| rest.split_whitespace().next());
    !matches!(state, Some("Z" | "X"))
}

/// This machine's host name (empty when it cannot be read).
pub fn hostname() -> String {
    std::fs::read_to_string("/proc/sys/kernel/hostname")
        .map(|h| h.trim().to_owned())
        .unwrap_or_default()
}

fn same_file(f: &File, path: &Path) -> bool {
    use std::os::unix::fs::MetadataExt;
    match (f.metadata(), std::fs::metadata(path)) {
        (Ok(a), Ok(b)) => a.dev() == b.dev() && a.ino() == b.ino(),
        _ => false,
    }
}

/// A run directory in use by this process.
#[derive(Debug)]
pub struct RunDir {
    /// The directory.
    pub path: PathBuf,
    /// Its lock.
    pub lock: DirLock,
    /// Where an earlier run in the same place was moved (`--force`).
    pub moved_aside: Option<PathBuf>,
}

/// What a directory holds besides a lock file, if anything.
/// `dir` holds a run's log (a directory gyrobench wrote).
pub fn is_run_dir(dir: &Path) -> bool {
    dir.join("run.mcap").exists() || dir.join(LOCK_FILE).exists()
}

fn run_contents(dir: &Path) -> Option<String> {
    let entries = std::fs::read_dir(dir).ok()?;
    let names: Vec<String> = entries
        .filter_map(Result::ok)
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n != LOCK_FILE)
        .collect();
    (!names.is_empty()).then(|| {
        let mut shown: Vec<&str> = names.iter().map(String::as_str).take(4).collect();
        shown.sort_unstable();
        let more = names.len().saturating_sub(shown.len());
        format!(
            "{}{}",
            shown.join(", "),
            if more > 0 {
                format!(" and {more} more")
            } else {
                String::new()
            }
        )
    })
}

impl RunDir {
    /// A new run directory at `path`: refused when it holds anything
    /// (unless `force`, which moves the old one aside, never truncates it).
    pub fn create_at(path: &Path, started_utc: &str, force: bool) -> Result<Self, RunDirError> {
        let mut moved_aside = None;
        if let Some(what) = run_contents(path) {
            if !force {
                return Err(RunDirError::Exists {
                    path: path.display().to_string(),
                    what,
                });
            }
            // Never move aside a directory that is not a run (a home, a
            // source tree given as `--out .`).
            if !is_run_dir(path) {
                return Err(RunDirError::NotARun {
                    path: path.display().to_string(),
                    what,
                });
            }
            // Never move a directory a live run is writing.
            drop(DirLock::acquire(path, started_utc)?);
            let aside = unique_sibling(path, "replaced")?;
            std::fs::rename(path, &aside).map_err(io("moving aside", path))?;
            moved_aside = Some(aside);
        }
        if let Some(parent) = path.parent().filter(|p| !p.as_os_str().is_empty()) {
            std::fs::create_dir_all(parent).map_err(io("creating", parent))?;
        }
        match std::fs::create_dir(path) {
            Ok(()) => {}
            // An empty directory is the operator's choice of place.
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists && path.is_dir() => {}
            Err(e) => return Err(io("creating the run directory", path)(e)),
        }
        let lock = DirLock::acquire(path, started_utc)?;
        // Another run may have started here between our checks.
        if let Some(what) = run_contents(path) {
            return Err(RunDirError::Exists {
                path: path.display().to_string(),
                what,
            });
        }
        Ok(Self {
            path: path.to_owned(),
            lock,
            moved_aside,
        })
    }

    /// A new directory `base/name-stamp` (`-2`, `-3`, ... when another run
    /// took that name, even in the same second).
    pub fn create_unique(
        base: &Path,
        name: &str,
        stamp: &str,
        started_utc: &str,
    ) -> Result<Self, RunDirError> {
        std::fs::create_dir_all(base).map_err(io("creating", base))?;
        for n in 1..10_000 {
            let leaf = if n == 1 {
                format!("{name}-{stamp}")
            } else {
                format!("{name}-{stamp}-{n}")
            };
            let path = base.join(leaf);
            match std::fs::create_dir(&path) {
                Ok(()) => {
                    let lock = DirLock::acquire(&path, started_utc)?;
                    return Ok(Self {
                        path,
                        lock,
                        moved_aside: None,
                    });
                }
                Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {}
                Err(e) => return Err(io("creating the run directory", &path)(e)),
            }
        }
        Err(RunDirError::Exists {
            path: base.join(format!("{name}-{stamp}")).display().to_string(),
            what: "ten thousand runs of that name in the same second".into(),
        })
    }

    /// An existing run directory, locked (to resume the run in it).
    pub fn open_existing(path: &Path, started_utc: &str) -> Result<Self, RunDirError> {
        if !path.is_dir() {
            return Err(io("opening the run directory", path)(std::io::Error::new(
                std::io::ErrorKind::NotFound,
                "no such directory",
            )));
        }
        Ok(Self {
            path: path.to_owned(),
            lock: DirLock::acquire(path, started_utc)?,
            moved_aside: None,
        })
    }
}

/// `path.tag-N` that does not exist yet.
fn unique_sibling(path: &Path, tag: &str) -> Result<PathBuf, RunDirError> {
    let name = path
        .file_name()
        .map_or_else(|| "run".into(), |n| n.to_string_lossy().into_owned());
    for n in 1..10_000 {
        let cand = path.with_file_name(format!("{name}.{tag}-{n}"));
        if !cand.exists() {
            return Ok(cand);
        }
    }
    Err(io("moving aside", path)(std::io::Error::other(
        "too many earlier runs moved aside",
    )))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn temp(tag: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("gyrobench-rundir-{tag}-{}", std::process::id()));
        let _ignored = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).expect("temp");
        d
    }

    #[test]
    fn a_directory_holding_a_run_is_refused_and_force_moves_it_aside() {
        let base = temp("exists");
        let dir = base.join("r");
        std::fs::create_dir_all(&dir).expect("dir");
        std::fs::write(dir.join("run.mcap"), b"old log").expect("old");
        let err = RunDir::create_at(&dir, "t", false).expect_err("must refuse");
        assert!(err.to_string().contains("holds a run already"), "{err}");
        assert_eq!(
            std::fs::read(dir.join("run.mcap")).expect("kept"),
            b"old log"
        );
        let d = RunDir::create_at(&dir, "t", true).expect("force");
        let aside = d.moved_aside.clone().expect("moved");
        assert_eq!(
            std::fs::read(aside.join("run.mcap")).expect("kept"),
            b"old log"
        );
        assert!(!dir.join("run.mcap").exists());
        drop(d);
        std::fs::remove_dir_all(&base).expect("cleanup");
    }

    #[test]
    fn unique_names_in_the_same_second_and_a_lock_that_excludes() {
        let base = temp("unique");
        let a = RunDir::create_unique(&base, "smoke", "20260101T000000Z", "t").expect("a");
        let b = RunDir::create_unique(&base, "smoke", "20260101T000000Z", "t").expect("b");
        assert_ne!(a.path, b.path);
        assert!(b.path.ends_with("smoke-20260101T000000Z-2"));
        // The same process cannot take a held lock a second time either
        // (flock is per open file).
        let err = RunDir::open_existing(&a.path, "t").expect_err("locked");
        assert!(err.to_string().contains("in use by another run"), "{err}");
        assert!(
            err.to_string()
                .contains(&format!("pid {}", std::process::id())),
            "{err}"
        );
        drop(a);
        drop(b);
        std::fs::remove_dir_all(&base).expect("cleanup");
    }

    #[test]
    fn a_stale_lock_is_reported_and_taken_over() {
        let base = temp("stale");
        // A pid that cannot exist (above pid_max).
        std::fs::write(
            base.join(LOCK_FILE),
            format!("pid=4999999\nhost={}\nstarted=yesterday\n", hostname()),
        )
        .expect("stale lock");
        let d = RunDir::open_existing(&base, "t").expect("taken over");
        let stale = d.lock.stale.clone().expect("reported");
        assert!(
            stale.contains("pid 4999999") && stale.contains("yesterday"),
            "{stale}"
        );
        drop(d);
        assert!(!base.join(LOCK_FILE).exists(), "released on drop");
        std::fs::remove_dir_all(&base).expect("cleanup");
    }

    #[test]
    fn a_lock_naming_a_live_process_that_does_not_hold_it_is_refused() {
        let base = temp("alive");
        // pid 1 runs on every Linux machine.
        std::fs::write(
            base.join(LOCK_FILE),
            format!("pid=1\nhost={}\n", hostname()),
        )
        .expect("lock");
        let err = RunDir::open_existing(&base, "t").expect_err("refused");
        assert!(err.to_string().contains("still running"), "{err}");
        std::fs::remove_dir_all(&base).expect("cleanup");
    }

    #[test]
    fn a_lock_naming_a_zombie_is_taken_over() {
        let base = temp("zombie");
        // A child that ends at once and is not reaped: a zombie.
        let mut child = std::process::Command::new("true").spawn().expect("a child");
        let pid = child.id();
        let state = || {
            std::fs::read_to_string(format!("/proc/{pid}/stat"))
                .ok()
                .and_then(|s| {
                    s.rsplit_once(')')
                        .map(|(_, r)| r.trim_start().chars().next())
                })
                .flatten()
        };
        while state() != Some('Z') {
            std::thread::yield_now();
        }
        std::fs::write(
            base.join(LOCK_FILE),
            format!("pid={pid}\nhost={}\n", hostname()),
        )
        .expect("lock");
        let d = RunDir::open_existing(&base, "t").expect("a zombie holds nothing");
        assert!(
            d.lock
                .stale
                .as_deref()
                .is_some_and(|s| s.contains(&format!("pid {pid}")))
        );
        drop(d);
        child.wait().expect("reaped");
        std::fs::remove_dir_all(&base).expect("cleanup");
    }
}
