//! The embedded engine: a SQLite file (rusqlite, SQLite compiled in).

use std::path::Path;
use std::time::Duration;

use rusqlite::types::{Value as SqliteValue, ValueRef};

use super::StoreError;
use super::sql::{Engine, Row, Sql, Value};

/// A SQLite store.
pub struct Sqlite {
    conn: rusqlite::Connection,
    name: String,
}

impl std::fmt::Debug for Sqlite {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Sqlite").field("name", &self.name).finish()
    }
}

fn err(store: &str) -> impl Fn(rusqlite::Error) -> StoreError + '_ {
    move |e| StoreError::Engine {
        store: store.to_owned(),
        message: e.to_string(),
    }
}

impl Sqlite {
    /// Open (or create) the file at `path`, creating its directory.
    pub fn open(path: &Path) -> Result<Self, StoreError> {
        let name = path.display().to_string();
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).map_err(|e| StoreError::Engine {
                store: name.clone(),
                message: format!("cannot create its directory: {e}"),
            })?;
        }
        let conn = rusqlite::Connection::open(path).map_err(err(&name))?;
        // Several runs on one machine write the same file: wait for a
        // writer rather than fail; WAL lets readers go on meanwhile.
        conn.busy_timeout(Duration::from_secs(30))
            .map_err(err(&name))?;
        // NORMAL in WAL mode: a power cut may lose the last commits, never
        // corrupt the file; the logs are the record and `results sync`
        // writes them again.
        conn.execute_batch(
            "PRAGMA journal_mode = WAL; PRAGMA synchronous = NORMAL; PRAGMA foreign_keys = ON;",
        )
        .map_err(err(&name))?;
        Ok(Self { conn, name })
    }
}

fn to_sqlite(v: &Value) -> SqliteValue {
    match v {
        Value::Null => SqliteValue::Null,
        Value::Int(i) => SqliteValue::Integer(*i),
        Value::Real(r) => SqliteValue::Real(*r),
        Value::Text(s) => SqliteValue::Text(s.clone()),
    }
}

fn from_sqlite(v: ValueRef<'_>) -> Value {
    match v {
        ValueRef::Null => Value::Null,
        ValueRef::Integer(i) => Value::Int(i),
        ValueRef::Real(r) => Value::Real(r),
        ValueRef::Text(t) | ValueRef::Blob(t) => {
            Value::Text(String::from_utf8_lossy(t).into_owned())
        }
    }
}

/// Bind `$1`, `$2`, ... by name: SQLite numbers named parameters in the
/// order they first appear, which is not their number when a statement
/// uses `$2` before `$1`.
fn bind(st: &mut rusqlite::Statement<'_>, params: &[Value]) -> rusqlite::Result<()> {
    st.clear_bindings();
    for (i, v) in params.iter().enumerate() {
        if let Some(idx) = st.parameter_index(&format!("${}", i + 1))? {
            st.raw_bind_parameter(idx, to_sqlite(v))?;
        }
    }
    Ok(())
}

impl Sql for Sqlite {
    fn execute(&mut self, sql: &str, params: &[Value]) -> Result<u64, StoreError> {
        let mut st = self.conn.prepare_cached(sql).map_err(err(&self.name))?;
        bind(&mut st, params).map_err(err(&self.name))?;
        let n = st.raw_execute().map_err(err(&self.name))?;
        Ok(n as u64)
    }

    fn query(&mut self, sql: &str, params: &[Value]) -> Result<Vec<Row>, StoreError> {
        let mut st = self.conn.prepare_cached(sql).map_err(err(&self.name))?;
        let names: std::sync::Arc<[String]> = st.column_names().map(str::to_owned).collect();
        let cols = names.len();
        bind(&mut st, params).map_err(err(&self.name))?;
        let mut rows = st.raw_query();
        let mut out = Vec::new();
        while let Some(r) = rows.next().map_err(err(&self.name))? {
            let mut row = Vec::with_capacity(cols);
            for i in 0..cols {
                row.push(from_sqlite(r.get_ref(i).map_err(err(&self.name))?));
            }
            out.push(Row::new(names.clone(), row));
        }
        Ok(out)
    }

    fn batch(&mut self, sql: &str) -> Result<(), StoreError> {
        self.conn.execute_batch(sql).map_err(err(&self.name))
    }

    fn engine(&self) -> Engine {
        Engine::Sqlite
    }
}
