//! The two engines behind one small interface: statements with `$1`-style
//! parameters (SQLite takes them as numbered parameters, PostgreSQL as its
//! own) and rows of plain values, so every query of the store is written
//! once. Schema migrations, versioned in `src/results/migrations/`, are
//! applied here on open.

use super::StoreError;

/// A value going in or coming out.
#[derive(Debug, Clone, PartialEq)]
pub enum Value {
    /// NULL.
    Null,
    /// An integer.
    Int(i64),
    /// A float.
    Real(f64),
    /// Text.
    Text(String),
}

impl From<i64> for Value {
    fn from(v: i64) -> Self {
        Self::Int(v)
    }
}

impl From<f64> for Value {
    fn from(v: f64) -> Self {
        if v.is_finite() {
            Self::Real(v)
        } else {
            Self::Null
        }
    }
}

impl From<&str> for Value {
    fn from(v: &str) -> Self {
        Self::Text(v.to_owned())
    }
}

impl From<String> for Value {
    fn from(v: String) -> Self {
        Self::Text(v)
    }
}

impl From<bool> for Value {
    fn from(v: bool) -> Self {
        Self::Int(i64::from(v))
    }
}

impl<T: Into<Value>> From<Option<T>> for Value {
    fn from(v: Option<T>) -> Self {
        v.map_or(Self::Null, Into::into)
    }
}

impl Value {
    /// As text (empty for NULL).
    pub fn text(&self) -> String {
        match self {
            Self::Null => String::new(),
            Self::Int(v) => v.to_string(),
            Self::Real(v) => v.to_string(),
            Self::Text(s) => s.clone(),
        }
    }

    /// As an optional float.
    pub fn real(&self) -> Option<f64> {
        match self {
            Self::Int(v) => Some(*v as f64),
            Self::Real(v) => Some(*v),
            _ => None,
        }
    }

    /// As an optional integer.
    pub fn int(&self) -> Option<i64> {
        match self {
            Self::Int(v) => Some(*v),
            Self::Real(v) => Some(*v as i64),
            _ => None,
        }
    }
}

/// A row of a query, read by the names of its select list's columns (a
/// column's `AS` alias, else its own name without the table's): a query
/// and the code that reads it agree on names, never on positions.
#[derive(Debug, Clone, PartialEq)]
pub struct Row {
    names: std::sync::Arc<[String]>,
    values: Vec<Value>,
}

impl Row {
    /// A row of `values` under the column `names` (shared by a query's rows).
    pub fn new(names: std::sync::Arc<[String]>, values: Vec<Value>) -> Self {
        Self { names, values }
    }

    /// The value of column `name`; NULL when the row has no such column
    /// (case-insensitive, as SQL names are).
    pub fn get(&self, name: &str) -> &Value {
        self.names
            .iter()
            .position(|n| n.eq_ignore_ascii_case(name))
            .and_then(|i| self.values.get(i))
            .unwrap_or(&Value::Null)
    }

    /// Column `name` as text (empty for NULL).
    pub fn text(&self, name: &str) -> String {
        self.get(name).text()
    }

    /// Column `name` as text, none for NULL or empty.
    pub fn opt_text(&self, name: &str) -> Option<String> {
        Some(self.text(name)).filter(|s| !s.is_empty())
    }

    /// Column `name` as an integer (none for NULL).
    pub fn int(&self, name: &str) -> Option<i64> {
        self.get(name).int()
    }

    /// Column `name` as a float (none for NULL).
    pub fn real(&self, name: &str) -> Option<f64> {
        self.get(name).real()
    }
}

/// Which engine.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Engine {
    /// An embedded SQLite file.
    Sqlite,
    /// A PostgreSQL server.
    Postgres,
}

/// What an engine does for the store.
pub trait Sql: Send {
    /// Run a statement; rows affected.
    fn execute(&mut self, sql: &str, params: &[Value]) -> Result<u64, StoreError>;
    /// Run a query; its rows.
    fn query(&mut self, sql: &str, params: &[Value]) -> Result<Vec<Row>, StoreError>;
    /// Run statements without parameters (a migration, BEGIN, COMMIT).
    fn batch(&mut self, sql: &str) -> Result<(), StoreError>;
    /// Which engine this is.
    fn engine(&self) -> Engine;
}

/// The migrations of each engine, in order: (version, name, SQL).
pub fn migrations(engine: Engine) -> &'static [(i64, &'static str, &'static str)] {
    match engine {
        Engine::Sqlite => &[
            (1, "init", include_str!("migrations/sqlite/0001_init.sql")),
            (
                2,
                "indexes",
                include_str!("migrations/sqlite/0002_indexes.sql"),
            ),
            (
                3,
                "unit record",
                include_str!("migrations/sqlite/0003_unit_record.sql"),
            ),
            (
                4,
                "set identity",
                include_str!("migrations/sqlite/0004_set_identity.sql"),
            ),
            (
                5,
                "judged",
                include_str!("migrations/sqlite/0005_judged.sql"),
            ),
            (
                6,
                "signatures",
                include_str!("migrations/sqlite/0006_signatures.sql"),
            ),
            (
                7,
                "bench kind",
                include_str!("migrations/sqlite/0007_bench_kind.sql"),
            ),
        ],
        Engine::Postgres => &[
            (1, "init", include_str!("migrations/postgres/0001_init.sql")),
            (
                2,
                "indexes",
                include_str!("migrations/postgres/0002_indexes.sql"),
            ),
            (
                3,
                "unit record",
                include_str!("migrations/postgres/0003_unit_record.sql"),
            ),
            (
                4,
                "set identity",
                include_str!("migrations/postgres/0004_set_identity.sql"),
            ),
            (
                5,
                "judged",
                include_str!("migrations/postgres/0005_judged.sql"),
            ),
            (
                6,
                "signatures",
                include_str!("migrations/postgres/0006_signatures.sql"),
            ),
            (
                7,
                "bench kind",
                include_str!("migrations/postgres/0007_bench_kind.sql"),
            ),
        ],
    }
}

/// The schema version this build writes and reads.
pub fn latest_version(engine: Engine) -> i64 {
    migrations(engine).last().map_or(0, |m| m.0)
}

/// Bring the schema up to this build's version in one transaction (others
/// that open the store meanwhile wait: an exclusive transaction in SQLite,
/// an advisory lock in PostgreSQL). A store whose schema is newer than
/// this build is refused.
pub fn migrate(sql: &mut dyn Sql, store: &str) -> Result<i64, StoreError> {
    let engine = sql.engine();
    sql.batch(match engine {
        Engine::Sqlite => "BEGIN IMMEDIATE",
        Engine::Postgres => "BEGIN; SELECT pg_advisory_xact_lock(7411846281553)",
    })?;
    let result = (|| {
        sql.batch("CREATE TABLE IF NOT EXISTS gyrobench_schema (version BIGINT NOT NULL)")?;
        let rows = sql.query("SELECT version FROM gyrobench_schema", &[])?;
        let have = rows.first().and_then(|r| r.int("version")).unwrap_or(0);
        let latest = latest_version(engine);
        if have > latest {
            return Err(StoreError::Newer {
                store: store.to_owned(),
                have,
                supported: latest,
            });
        }
        for (version, _, text) in migrations(engine) {
            if *version > have {
                sql.batch(text)?;
            }
        }
        if rows.is_empty() {
            sql.execute(
                "INSERT INTO gyrobench_schema (version) VALUES ($1)",
                &[Value::Int(latest)],
            )?;
        } else if have < latest {
            sql.execute(
                "UPDATE gyrobench_schema SET version = $1",
                &[Value::Int(latest)],
            )?;
        }
        Ok(latest)
    })();
    end(sql, result)
}

/// Commit when `result` is Ok, roll back otherwise.
fn end<T>(sql: &mut dyn Sql, result: Result<T, StoreError>) -> Result<T, StoreError> {
    match result {
        Ok(v) => {
            sql.batch("COMMIT")?;
            Ok(v)
        }
        Err(e) => {
            let _rolled_back = sql.batch("ROLLBACK");
            Err(e)
        }
    }
}

/// Run `f` in a transaction: committed when it returns Ok, rolled back
/// otherwise.
pub fn transaction<T>(
    sql: &mut dyn Sql,
    f: impl FnOnce(&mut dyn Sql) -> Result<T, StoreError>,
) -> Result<T, StoreError> {
    sql.batch("BEGIN")?;
    let result = f(sql);
    end(sql, result)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_row_is_read_by_its_columns_names_whatever_their_order() {
        let names: std::sync::Arc<[String]> = ["id", "Value", "note"]
            .into_iter()
            .map(str::to_owned)
            .collect();
        let row = Row::new(
            names,
            vec![Value::from("r1"), Value::from(2.5), Value::Null],
        );
        assert_eq!(row.text("id"), "r1");
        assert_eq!(row.real("value"), Some(2.5), "names are case-insensitive");
        assert_eq!(row.opt_text("note"), None, "NULL");
        assert_eq!(row.get("missing"), &Value::Null);
        assert_eq!(row.int("id"), None);
    }
}
