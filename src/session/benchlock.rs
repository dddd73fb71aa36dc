//! One bench, one run: every device a run drives is locked for the run's
//! life, so a second run on the same chamber, table, supply or gyro link
//! (another `run`, a second station, another user on the bench PC) is
//! refused before it sends anything, naming the run that holds it.
//!
//! A device is known by where it is, not by the bench file that names it:
//! a TCP instrument by its address (loopback names one host), a serial
//! port or pty by its real path (through `/dev/serial/by-id` links). Each
//! has a lock file in one directory every gyrobench on the machine shares
//! (`/run/lock/gyrobench`, the system's directory for such locks; else one
//! under the temporary directory; `GYROBENCH_LOCK_DIR` chooses another),
//! held with an exclusive `flock` that the kernel releases however the
//! process ends. The file says who holds it. Serial ports are besides
//! opened exclusively (`TIOCEXCL` and `flock`, by the serialport crate),
//! which also keeps out programs that are not gyrobench.

use std::fs::File;
use std::io::{Read, Seek, Write};
use std::path::{Path, PathBuf};

use crate::bench::BenchConfig;
use crate::transport::DeviceSpec;

/// The environment variable that names the lock directory.
pub const LOCK_DIR_ENV: &str = "GYROBENCH_LOCK_DIR";

/// Why a bench cannot be taken.
#[derive(Debug, thiserror::Error)]
pub enum BenchLockError {
    /// Another run holds one of its devices.
    #[error(
        "the {device} ({spec}) is in use by another run: {holder}; wait for that run to end \
         (or stop it from where it was started) before starting another on this bench"
    )]
    InUse {
        /// The device's role in this bench file (`chamber`, `gyro/B`).
        device: String,
        /// Its spec in this bench file.
        spec: String,
        /// Who holds it, in words.
        holder: String,
    },
    /// The lock directory or a lock file could not be used.
    #[error(
        "cannot lock the {device} at {path}: {cause}; make the directory writable for every user \
         who runs the bench, or point {LOCK_DIR_ENV} at one that is"
    )]
    Io {
        /// The device's role.
        device: String,
        /// The lock file or directory.
        path: String,
        /// Why.
        #[source]
        cause: std::io::Error,
    },
}

/// Who takes a bench: said in its lock files for a run that finds them
/// taken.
#[derive(Debug, Clone)]
pub struct Holder {
    /// The procedure's name.
    pub procedure: String,
    /// The unit(s) under test.
    pub units: String,
    /// The bench file as given.
    pub bench: String,
    /// When the run started (RFC 3339).
    pub started_utc: String,
}

/// The locks of every device of one bench, held until dropped.
#[derive(Debug)]
pub struct BenchLock {
    files: Vec<(File, PathBuf)>,
    text: String,
}

/// The key a device is locked under (none: the embedded simulator, which
/// belongs to its run alone).
pub fn device_key(spec: &str) -> Option<String> {
    match spec.parse::<DeviceSpec>().ok()? {
        DeviceSpec::Sim { .. } => None,
        DeviceSpec::Serial { path, .. } | DeviceSpec::Pty { path } => {
            let real = std::fs::canonicalize(&path).unwrap_or_else(|_| PathBuf::from(&path));
            Some(format!("serial:{}", real.display()))
        }
        DeviceSpec::Tcp { addr } => Some(format!("tcp:{}", tcp_key(&addr))),
    }
}

/// `host:port` as one name per endpoint: the first address the host
/// resolves to (every loopback address is `loopback`); the text as given,
/// lower case, when it does not resolve now.
fn tcp_key(addr: &str) -> String {
    use std::net::ToSocketAddrs;
    match addr.to_socket_addrs().ok().and_then(|mut a| a.next()) {
        Some(sa) if sa.ip().is_loopback() => format!("loopback:{}", sa.port()),
        Some(sa) => sa.to_string(),
        None => addr.to_ascii_lowercase(),
    }
}

/// The lock file's name for `key`: the key with every character that is
/// not a letter, digit, `.` or `-` as `_`.
fn file_name(key: &str) -> String {
    let name: String = key
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '.' || c == '-' {
                c
            } else {
                '_'
            }
        })
        .collect();
    format!("{name}.lock")
}

/// Where the lock files are.
pub fn lock_dir() -> PathBuf {
    if let Some(d) = std::env::var_os(LOCK_DIR_ENV).filter(|d| !d.is_empty()) {
        return PathBuf::from(d);
    }
    let system = Path::new("/run/lock");
    if system.is_dir() {
        return system.join("gyrobench");
    }
    std::env::temp_dir().join("gyrobench-locks")
}

/// Every device of `cfg` a run opens: its role and spec (a batch's empty
/// slots are not opened, so `cfg` holds the filled ones only).
fn devices(cfg: &BenchConfig) -> Vec<(String, String)> {
    let d = &cfg.devices;
    let mut all = vec![
        ("chamber".to_owned(), d.chamber.spec.clone()),
        ("table".to_owned(), d.table.spec.clone()),
    ];
    if let Some(s) = &d.supply {
        all.push(("supply".to_owned(), s.spec.clone()));
    }
    if cfg.slots.is_empty() {
        all.push(("gyro".to_owned(), d.gyro.spec.clone()));
    }
    for slot in &cfg.slots {
        all.push((
            format!("gyro/{}", slot.name),
            cfg.slot_gyro_spec(slot).to_owned(),
        ));
    }
    all
}

impl BenchLock {
    /// Lock every device of `cfg` for `holder`, or say which one another
    /// run holds (nothing is kept locked then). The embedded bench locks
    /// nothing.
    pub fn acquire(cfg: &BenchConfig, holder: &Holder) -> Result<Self, BenchLockError> {
        Self::acquire_in(&lock_dir(), cfg, holder)
    }

    /// [`BenchLock::acquire`] with the lock files in `dir`.
    pub fn acquire_in(
        dir: &Path,
        cfg: &BenchConfig,
        holder: &Holder,
    ) -> Result<Self, BenchLockError> {
        let mut keys: Vec<(String, String, String)> = devices(cfg)
            .into_iter()
            .filter_map(|(role, spec)| Some((device_key(&spec)?, role, spec)))
            .collect();
        // One file per device, whatever roles share it.
        keys.sort();
        keys.dedup_by(|a, b| a.0 == b.0);
        let text = format!(
            "pid={}\nhost={}\nstarted={}\nprocedure={}\nunits={}\nbench={}\n",
            std::process::id(),
            super::rundir::hostname(),
            holder.started_utc,
            one_line(&holder.procedure),
            one_line(&holder.units),
            one_line(&holder.bench),
        );
        let mut lock = Self {
            files: Vec::new(),
            text,
        };
        if keys.is_empty() {
            return Ok(lock);
        }
        make_dir(dir).map_err(|cause| BenchLockError::Io {
            device: keys[0].1.clone(),
            path: dir.display().to_string(),
            cause,
        })?;
        for (key, role, spec) in keys {
            let path = dir.join(file_name(&key));
            let io = |cause| BenchLockError::Io {
                device: role.clone(),
                path: path.display().to_string(),
                cause,
            };
            let mut file = open_lock(&path).map_err(io)?;
            match file.try_lock() {
                Ok(()) => {}
                Err(std::fs::TryLockError::WouldBlock) => {
                    return Err(BenchLockError::InUse {
                        device: role,
                        spec,
                        holder: holder_words(&read_holder(&mut file)),
                    });
                }
                Err(std::fs::TryLockError::Error(e)) => return Err(io(e)),
            }
            write_holder(&mut file, &lock.text).map_err(io)?;
            lock.files.push((file, path));
        }
        Ok(lock)
    }

    /// The run's directory, once it has one: said to a run refused later.
    pub fn set_run_dir(&mut self, dir: &Path) {
        self.text
            .push_str(&format!("run={}\n", one_line(&dir.display().to_string())));
        for (file, _) in &mut self.files {
            let _ignored = write_holder(file, &self.text);
        }
    }

    /// How many devices are locked.
    pub fn devices(&self) -> usize {
        self.files.len()
    }
}

impl Drop for BenchLock {
    fn drop(&mut self) {
        // Emptied, not removed: another process may be about to lock the
        // same file, and a removed file would let two runs lock two
        // files of one name. The kernel drops the flock on close.
        for (file, _) in &mut self.files {
            let _ignored = file.set_len(0);
        }
    }
}

fn one_line(s: &str) -> String {
    s.chars()
        .map(|c| if c.is_control() { ' ' } else { c })
        .collect()
}

/// The lock directory, made writable by every user of the bench PC
/// (sticky, like `/tmp`: each removes only its own files).
fn make_dir(dir: &Path) -> std::io::Result<()> {
    use std::os::unix::fs::PermissionsExt;
    if dir.is_dir() {
        return Ok(());
    }
    std::fs::create_dir_all(dir)?;
    std::fs::set_permissions(dir, std::fs::Permissions::from_mode(0o1777))
}

/// A lock file, opened for reading and writing (created, writable by
/// every user, never through a link).
fn open_lock(path: &Path) -> std::io::Result<File> {
    use std::os::unix::fs::{OpenOptionsExt, PermissionsExt};
    let file = std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .create(true)
        .truncate(false)
        .mode(0o666)
        .custom_flags(libc::O_NOFOLLOW)
        .open(path)?;
    // The umask may have taken the others' write bit; a lock file another
    // user cannot open would lock the bench to one account. Only its
    // owner can change it.
    if let Ok(m) = file.metadata()
        && m.permissions().mode() & 0o666 != 0o666
    {
        let _ignored = file.set_permissions(std::fs::Permissions::from_mode(0o666));
    }
    Ok(file)
}

fn write_holder(file: &mut File, text: &str) -> std::io::Result<()> {
    file.set_len(0)?;
    file.rewind()?;
    file.write_all(text.as_bytes())?;
    file.flush()
}

/// What a lock file says (at most 4 KiB of it).
fn read_holder(file: &mut File) -> String {
    let mut s = String::new();
    let _ignored = file
        .rewind()
        .and_then(|()| file.take(4096).read_to_string(&mut s));
    s
}

fn holder_words(text: &str) -> String {
    let field = |key: &str| {
        text.lines()
            .find_map(|l| l.strip_prefix(key)?.strip_prefix('='))
            .map(str::trim)
            .filter(|v| !v.is_empty())
    };
    let Some(pid) = field("pid") else {
        return "a run that is starting".into();
    };
    let mut words = match field("procedure") {
        Some(p) => p.to_owned(),
        None => "a run".to_owned(),
    };
    if let Some(u) = field("units") {
        words.push_str(&format!(" on {u}"));
    }
    if let Some(r) = field("run") {
        words.push_str(&format!(" in {r}"));
    }
    words.push_str(&format!(" (pid {pid}"));
    if let Some(h) = field("host") {
        words.push_str(&format!(" on {h}"));
    }
    if let Some(s) = field("started") {
        words.push_str(&format!(", started {s}"));
    }
    if let Some(b) = field("bench") {
        words.push_str(&format!(", bench file {b}"));
    }
    words.push(')');
    words
}

#[cfg(test)]
mod tests {
    use super::*;

    fn served() -> BenchConfig {
        let text = include_str!("../../fixtures/bench/sim-serve.toml");
        BenchConfig::from_source(&crate::config::Source::from_text("b.toml", text))
            .expect("the fixture loads")
    }

    fn holder(procedure: &str) -> Holder {
        Holder {
            procedure: procedure.into(),
            units: "RL16-0001".into(),
            bench: "b.toml".into(),
            started_utc: "2026-12-06T00:00:00+00:00".into(),
        }
    }

    #[test]
    fn a_device_is_known_by_where_it_is() {
        assert_eq!(
            device_key("tcp://127.0.0.1:5001"),
            device_key("tcp://localhost:5001")
        );
        assert_ne!(
            device_key("tcp://127.0.0.1:5001"),
            device_key("tcp://127.0.0.1:5002")
        );
        assert_eq!(device_key("sim://chamber"), None);
        assert_eq!(
            device_key("serial:///dev/ttyUSB7?baud=9600").as_deref(),
            Some("serial:/dev/ttyUSB7")
        );
        assert_eq!(file_name("tcp:loopback:5001"), "tcp_loopback_5001.lock");
    }

    #[test]
    fn a_second_run_is_refused_naming_the_first_until_it_ends() {
        let dir = tempfile::tempdir().expect("temp");
        let cfg = served();
        let mut first = BenchLock::acquire_in(dir.path(), &cfg, &holder("acceptance"))
            .expect("the first run takes the bench");
        assert_eq!(first.devices(), 4, "chamber, table, gyro and supply");
        first.set_run_dir(Path::new("runs/a"));
        let e = BenchLock::acquire_in(dir.path(), &cfg, &holder("smoke"))
            .expect_err("the bench is taken");
        let text = e.to_string();
        assert!(
            text.contains("in use by another run: acceptance on RL16-0001 in runs/a (pid")
                && text.contains("bench file b.toml"),
            "{text}"
        );
        // Another bench file naming one of the same devices is refused too.
        let mut other = cfg.clone();
        other.devices.chamber.spec = "tcp://127.0.0.1:6001".into();
        other.devices.table.spec = "tcp://127.0.0.1:6003".into();
        other.devices.gyro.spec = "tcp://localhost:5004".into();
        let e = BenchLock::acquire_in(dir.path(), &other, &holder("smoke"))
            .expect_err("the gyro link is taken");
        assert!(
            e.to_string().starts_with("the gyro (tcp://localhost:5004)"),
            "{e}"
        );
        drop(first);
        BenchLock::acquire_in(dir.path(), &cfg, &holder("smoke"))
            .expect("free once the first run ended");
    }

    #[test]
    fn the_embedded_bench_locks_nothing() {
        let dir = tempfile::tempdir().expect("temp");
        let cfg = BenchConfig::embedded();
        let a = BenchLock::acquire_in(dir.path(), &cfg, &holder("a")).expect("a");
        let b = BenchLock::acquire_in(dir.path(), &cfg, &holder("b")).expect("b");
        assert_eq!((a.devices(), b.devices()), (0, 0));
    }
}
