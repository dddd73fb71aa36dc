//! The results store: every run of every unit, with its measurements, its
//! logs and the coefficient sets calibrate made, in a database a lab can
//! query (`docs/results.md`).
//!
//! One interface, two engines ([`sql::Sql`]): an embedded SQLite file by
//! default (rusqlite, SQLite compiled in: nothing to install), PostgreSQL
//! for a lab with several benches (the `postgres` client). Both are
//! synchronous, as the command line and the run's own thread are; the
//! same SQL serves both. The log is the record of truth: the store is an
//! index of it, written by the run itself (at its start and its end), and
//! rebuilt from the logs at any time (`results sync`). A store that cannot
//! be reached never stops a run: the run is queued and written later.

pub mod facts;
pub mod junit;
pub mod page;
pub mod pg;
pub mod query;
pub mod record;
pub mod sets;
pub mod sign;
pub mod sql;
pub mod sqlite;
pub mod verify;

use std::path::{Path, PathBuf};

use sql::Sql;

/// Where a stored run part stands (the vocabulary crate's).
pub use gyrobench_model::outcome::RunState;

/// What went wrong with the store.
#[derive(Debug, thiserror::Error)]
pub enum StoreError {
    /// The engine refused or failed (a corrupt file, a wrong password, a
    /// server that went away).
    #[error("results store {store}: {message}")]
    Engine {
        /// The store (a file, a URL without its password).
        store: String,
        /// The engine's words.
        message: String,
    },
    /// The store's schema is newer than this build reads.
    #[error(
        "results store {store}: its schema is version {have}, newer than this gyrobench reads ({supported}); use a newer gyrobench"
    )]
    Newer {
        /// The store.
        store: String,
        /// Its schema version.
        have: i64,
        /// The newest this build knows.
        supported: i64,
    },
    /// What was asked for is not there.
    #[error("results store {store}: {what}")]
    NotFound {
        /// The store.
        store: String,
        /// What is missing.
        what: String,
    },
    /// A request the store's rules refuse (a signature out of turn).
    #[error("{why}")]
    Refused {
        /// Why, naming the run.
        why: String,
    },
    /// A log or run directory could not be indexed.
    #[error("{path}: {message}")]
    Log {
        /// The file.
        path: String,
        /// Why.
        message: String,
    },
}

/// Where the results go.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Location {
    /// A SQLite file.
    Sqlite(PathBuf),
    /// A PostgreSQL server (`postgres://...`).
    Postgres(String),
    /// Nowhere (`none`).
    Off,
}

/// The environment variable that names the store.
pub const ENV: &str = "GYROBENCH_DB";

impl Location {
    /// The store named by `spec`: `none`, a `postgres://` or
    /// `postgresql://` URL, or a SQLite file path.
    pub fn parse(spec: &str) -> Self {
        let s = spec.trim();
        if s.eq_ignore_ascii_case("none") || s.eq_ignore_ascii_case("off") {
            Self::Off
        } else if s.starts_with("postgres://") || s.starts_with("postgresql://") {
            Self::Postgres(s.to_owned())
        } else {
            Self::Sqlite(PathBuf::from(s))
        }
    }

    /// The store to use: `--db`, else `$GYROBENCH_DB`, else the bench
    /// file's `[results] db`, else the default SQLite file
    /// ([`default_sqlite`]).
    pub fn resolve(cli: Option<&str>, bench: Option<&str>) -> Self {
        if let Some(s) = cli {
            return Self::parse(s);
        }
        if let Ok(s) = std::env::var(ENV)
            && !s.trim().is_empty()
        {
            return Self::parse(&s);
        }
        if let Some(s) = bench {
            return Self::parse(s);
        }
        Self::Sqlite(default_sqlite())
    }

    /// The store in words, without a password.
    pub fn describe(&self) -> String {
        match self {
            Self::Sqlite(p) => p.display().to_string(),
            Self::Postgres(url) => pg::redact(url),
            Self::Off => "none".into(),
        }
    }
}

/// Where gyrobench keeps its own files on this machine:
/// `$XDG_DATA_HOME/gyrobench`, else `$HOME/.local/share/gyrobench`, else
/// `.gyrobench` here.
pub fn data_dir() -> PathBuf {
    let from = |k: &str| {
        std::env::var_os(k)
            .filter(|v| !v.is_empty())
            .map(PathBuf::from)
    };
    from("XDG_DATA_HOME")
        .or_else(|| from("HOME").map(|h| h.join(".local/share")))
        .map_or_else(|| PathBuf::from(".gyrobench"), |d| d.join("gyrobench"))
}

/// The default store: `results.sqlite` in [`data_dir`].
pub fn default_sqlite() -> PathBuf {
    data_dir().join("results.sqlite")
}

/// An open store.
pub struct Store {
    sql: Box<dyn Sql>,
    name: String,
}

impl std::fmt::Debug for Store {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Store").field("name", &self.name).finish()
    }
}

impl Store {
    /// Open the store at `loc`, creating it and bringing its schema up to
    /// date; None for [`Location::Off`].
    pub fn open(loc: &Location) -> Result<Option<Self>, StoreError> {
        let name = loc.describe();
        let mut sql: Box<dyn Sql> = match loc {
            Location::Off => return Ok(None),
            Location::Sqlite(p) => Box::new(sqlite::Sqlite::open(p)?),
            Location::Postgres(url) => Box::new(pg::Postgres::connect(url)?),
        };
        sql::migrate(sql.as_mut(), &name)?;
        Ok(Some(Self { sql, name }))
    }

    /// The store in words (no password).
    pub fn name(&self) -> &str {
        &self.name
    }

    fn sql(&mut self) -> &mut dyn Sql {
        self.sql.as_mut()
    }
}

/// Runs waiting for a store that could not be reached: one file per run
/// part and store in `data_dir()/pending`, naming the store (as
/// [`Location::describe`] words it, without a password) and the log.
/// Written when a run cannot record itself; indexed (and removed) the next
/// time a command opens that store, and no other.
pub mod pending {
    use super::*;

    /// The queue's directory.
    pub fn dir() -> PathBuf {
        data_dir().join("pending")
    }

    /// A queue entry: which store, which log.
    #[derive(Debug, Clone, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
    pub struct Entry {
        /// The store it waits for.
        pub store: String,
        /// The log to index there.
        pub log: PathBuf,
    }

    /// Queue the log at `log` (part `key` of a run) for the store named
    /// `store`.
    pub fn push(store: &str, key: &str, log: &Path) -> std::io::Result<PathBuf> {
        let d = dir();
        std::fs::create_dir_all(&d)?;
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
        // One entry per part and store: the same part queued for two
        // stores waits for each.
        let store_tag = &crate::fsutil::sha256_text(store)[..12];
        let path = d.join(format!("{name}.{store_tag}.json"));
        let entry = Entry {
            store: store.to_owned(),
            log: std::path::absolute(log)?,
        };
        let text = serde_json::to_string(&entry).map_err(std::io::Error::other)?;
        crate::fsutil::write_atomic(&path, text.as_bytes())?;
        Ok(path)
    }

    /// The queued logs waiting for the store named `store`, with their
    /// queue entries. An entry of an earlier gyrobench (a bare log path,
    /// naming no store) is left for `results sync`: which store it was
    /// meant for is not known.
    pub fn list(store: &str) -> Vec<(PathBuf, PathBuf)> {
        let Ok(entries) = std::fs::read_dir(dir()) else {
            return Vec::new();
        };
        let mut out: Vec<(PathBuf, PathBuf)> = entries
            .filter_map(Result::ok)
            .filter(|e| !e.file_name().to_string_lossy().starts_with('.'))
            .filter_map(|e| {
                let text = std::fs::read_to_string(e.path()).ok()?;
                let entry: Entry = serde_json::from_str(&text).ok()?;
                (entry.store == store).then(|| (e.path(), entry.log))
            })
            .collect();
        out.sort();
        out
    }
}

impl Store {
    /// Index the runs waiting in the queue; each one indexed (or whose
    /// log is gone) leaves it. Returns how many were indexed.
    pub fn flush_pending(&mut self) -> usize {
        let mut done = 0;
        for (entry, log) in pending::list(&self.name) {
            match self.index_log(&log) {
                Ok(_) => {
                    done += 1;
                    let _removed = std::fs::remove_file(&entry);
                }
                Err(StoreError::Log { .. }) if !log.exists() => {
                    let _removed = std::fs::remove_file(&entry);
                }
                Err(_) => {}
            }
        }
        done
    }
}

#[cfg(test)]
mod run_state_tests {
    use super::RunState;

    #[test]
    fn a_run_state_is_the_stores_word_in_json_and_back() {
        for s in RunState::ALL {
            let json = serde_json::to_string(&s).expect("JSON");
            assert_eq!(json, format!("\"{}\"", s.as_str()));
            assert_eq!(RunState::parse(s.as_str()), Some(s));
        }
        assert_eq!(RunState::parse("passed"), None);
        assert!(RunState::Pass.judged() && !RunState::Reference.judged());
    }
}
