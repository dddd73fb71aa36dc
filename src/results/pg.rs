//! The engine for a lab's shared store: a PostgreSQL server (the
//! synchronous `postgres` client of rust-postgres).

use std::error::Error;
use std::time::Duration;

use bytes::BytesMut;
use postgres::types::{IsNull, ToSql, Type, to_sql_checked};

use super::StoreError;
use super::sql::{Engine, Row, Sql, Value};

/// A PostgreSQL store.
pub struct Postgres {
    client: postgres::Client,
    name: String,
}

impl std::fmt::Debug for Postgres {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Postgres")
            .field("name", &self.name)
            .finish()
    }
}

/// How long to wait for the server to answer a connection, s.
pub const CONNECT_TIMEOUT: Duration = Duration::from_secs(10);

fn err(store: &str) -> impl Fn(postgres::Error) -> StoreError + '_ {
    move |e| StoreError::Engine {
        store: store.to_owned(),
        // The server's own words when it sent any (a wrong password, a
        // missing database), the connection's otherwise.
        message: match e.as_db_error() {
            Some(db) => db.message().to_owned(),
            None => e
                .source()
                .map_or_else(|| e.to_string(), |s| format!("{e}: {s}")),
        },
    }
}

/// The URL without its password, to name the store in messages.
pub fn redact(url: &str) -> String {
    match url.split_once("://") {
        Some((scheme, rest)) => match rest.rsplit_once('@') {
            Some((cred, host)) => {
                let user = cred.split(':').next().unwrap_or("");
                format!("{scheme}://{user}@{host}")
            }
            None => url.to_owned(),
        },
        None => url.to_owned(),
    }
}

impl Postgres {
    /// Connect to the server at `url` (`postgres://user:pass@host:port/db`).
    pub fn connect(url: &str) -> Result<Self, StoreError> {
        let name = redact(url);
        let mut config: postgres::Config = url.parse().map_err(|e: postgres::Error| {
            StoreError::Engine {
                store: name.clone(),
                message: format!("not a PostgreSQL URL ({e}); expected postgres://USER:PASSWORD@HOST:PORT/DATABASE"),
            }
        })?;
        config.connect_timeout(CONNECT_TIMEOUT);
        let client = config.connect(postgres::NoTls).map_err(err(&name))?;
        Ok(Self { client, name })
    }
}

impl ToSql for Value {
    fn to_sql(
        &self,
        ty: &Type,
        out: &mut BytesMut,
    ) -> Result<IsNull, Box<dyn Error + Sync + Send>> {
        match (self, ty) {
            (Self::Null, _) => Ok(IsNull::Yes),
            (Self::Int(v), t) if *t == Type::INT4 => i32::try_from(*v)?.to_sql(ty, out),
            (Self::Int(v), t) if *t == Type::FLOAT8 => (*v as f64).to_sql(ty, out),
            (Self::Int(v), t) if *t == Type::TEXT || *t == Type::VARCHAR => {
                v.to_string().to_sql(ty, out)
            }
            (Self::Int(v), _) => v.to_sql(ty, out),
            (Self::Real(v), t) if *t == Type::FLOAT4 => (*v as f32).to_sql(ty, out),
            (Self::Real(v), _) => v.to_sql(ty, out),
            (Self::Text(s), _) => s.as_str().to_sql(ty, out),
        }
    }

    fn accepts(_: &Type) -> bool {
        true
    }

    to_sql_checked!();
}

fn get(row: &postgres::Row, i: usize) -> Result<Value, postgres::Error> {
    let ty = row.columns()[i].type_().clone();
    Ok(if ty == Type::INT8 {
        row.try_get::<_, Option<i64>>(i)?
            .map_or(Value::Null, Value::Int)
    } else if ty == Type::INT4 {
        row.try_get::<_, Option<i32>>(i)?
            .map_or(Value::Null, |v| Value::Int(i64::from(v)))
    } else if ty == Type::FLOAT8 {
        row.try_get::<_, Option<f64>>(i)?
            .map_or(Value::Null, Value::Real)
    } else if ty == Type::NUMERIC {
        // Aggregates of BIGINT (SUM) come back as NUMERIC: read as text.
        row.try_get::<_, Option<String>>(i)
            .ok()
            .flatten()
            .and_then(|s| s.parse().ok())
            .map_or(Value::Null, Value::Real)
    } else if ty == Type::BOOL {
        row.try_get::<_, Option<bool>>(i)?
            .map_or(Value::Null, |b| Value::Int(i64::from(b)))
    } else {
        row.try_get::<_, Option<String>>(i)?
            .map_or(Value::Null, Value::Text)
    })
}

impl Sql for Postgres {
    fn execute(&mut self, sql: &str, params: &[Value]) -> Result<u64, StoreError> {
        let refs: Vec<&(dyn ToSql + Sync)> = params.iter().map(|p| p as _).collect();
        self.client.execute(sql, &refs).map_err(err(&self.name))
    }

    fn query(&mut self, sql: &str, params: &[Value]) -> Result<Vec<Row>, StoreError> {
        let refs: Vec<&(dyn ToSql + Sync)> = params.iter().map(|p| p as _).collect();
        let rows = self.client.query(sql, &refs).map_err(err(&self.name))?;
        let names: std::sync::Arc<[String]> = rows.first().map_or_else(
            || std::sync::Arc::from(Vec::new()),
            |r| r.columns().iter().map(|c| c.name().to_owned()).collect(),
        );
        rows.iter()
            .map(|r| {
                (0..r.len())
                    .map(|i| get(r, i))
                    .collect::<Result<Vec<Value>, _>>()
                    .map(|values| Row::new(names.clone(), values))
                    .map_err(err(&self.name))
            })
            .collect()
    }

    fn batch(&mut self, sql: &str) -> Result<(), StoreError> {
        self.client.batch_execute(sql).map_err(err(&self.name))
    }

    fn engine(&self) -> Engine {
        Engine::Postgres
    }
}
