//! The station's HTTP routes: the page, its assets, the API and the run
//! files, each behind the gate (`gate`: the token on the head, bodies
//! bounded in time and size).

use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;

use axum::Router;
use axum::extract::{Path as UrlPath, Query, State};
use axum::http::header;
use axum::response::sse::{Event, KeepAlive, Sse};
use axum::response::{Html, IntoResponse, Response};
use axum::routing::{get, post};
use serde::{Deserialize, Serialize};

use super::state::{self, RunView};
use super::{Refused, Start, Station, gate};

/// A prompt's answer.
#[derive(Debug, Deserialize)]
struct Answer {
    id: u64,
}

/// A unit's history request.
#[derive(Debug, Deserialize)]
struct HistoryQuery {
    serial: String,
}

const PAGE: &str = include_str!("page.html");
const UPLOT_JS: &str = include_str!("assets/uPlot.iife.min.js");
const UPLOT_CSS: &str = include_str!("assets/uPlot.min.css");

/// The station's routes.
pub fn router(station: Arc<Station>) -> Router {
    Router::new()
        .route("/", get(|| async { Html(PAGE) }))
        .route(
            "/assets/uPlot.iife.min.js",
            get(|| async { ([(header::CONTENT_TYPE, "text/javascript")], UPLOT_JS) }),
        )
        .route(
            "/assets/uPlot.min.css",
            get(|| async { ([(header::CONTENT_TYPE, "text/css")], UPLOT_CSS) }),
        )
        .route("/api/procedures", get(procedures))
        .route("/api/state", get(snapshot))
        .route("/api/events", get(events))
        .route("/api/history", get(history))
        .route("/api/report", get(stored_report))
        .route("/api/start", post(start))
        .route("/api/abort", post(abort))
        .route("/api/answer", post(answer))
        .route("/api/resume", post(resume))
        .route("/runs/{number}/{file}", get(run_file))
        .layer(axum::middleware::from_fn_with_state(
            station.clone(),
            gate::gate,
        ))
        .with_state(station)
}

type St = State<Arc<Station>>;

async fn procedures(State(s): St) -> Response {
    let offers = tokio::task::spawn_blocking(move || s.offers())
        .await
        .unwrap_or_default();
    axum::Json(offers).into_response()
}

/// Everything a page needs, from the run's start.
#[derive(Debug, Serialize)]
struct Snapshot {
    version: u64,
    run: Option<RunView>,
    /// Samples from `from` on.
    from: usize,
    samples: Vec<state::Sample>,
    /// When the newest sample arrived at the station, Unix ms.
    sample_unix_ms: i64,
    /// The live Foxglove stream's URL, if there is one.
    live_url: Option<String>,
    /// The bench as named to the operator (`embedded` or its file).
    bench: String,
    /// True when the bench is simulated (the embedded twin, or every
    /// device `sim://`): no hardware moves.
    simulated: bool,
    /// The bench's slots, in order (empty: one unit).
    slots: Vec<String>,
}

fn snapshot_of(station: &Station, from: usize) -> Snapshot {
    let b = station.shared.lock();
    let from = from.min(b.samples.len());
    Snapshot {
        version: b.version,
        run: b.run.clone(),
        from,
        samples: b.samples[from..].to_vec(),
        sample_unix_ms: b.sample_unix_ms,
        live_url: b.live_url.clone(),
        bench: station.cfg.bench_label.clone(),
        simulated: station.cfg.bench.is_embedded(),
        slots: station
            .cfg
            .bench
            .slots
            .iter()
            .map(|s| s.name.clone())
            .collect(),
    }
}

async fn snapshot(State(s): St) -> Response {
    axum::Json(snapshot_of(&s, 0)).into_response()
}

/// Server-sent events: the whole run first, then what changed, at most
/// four times a second and at least once a second.
async fn events(State(s): St) -> Response {
    struct Cursor {
        station: Arc<Station>,
        sent_samples: usize,
        run: u64,
        first: bool,
    }
    let cursor = Cursor {
        station: s,
        sent_samples: 0,
        run: 0,
        first: true,
    };
    let stream = futures_util::stream::unfold(cursor, |mut c| async move {
        if c.station
            .stopping
            .load(std::sync::atomic::Ordering::Relaxed)
        {
            return None;
        }
        if !c.first {
            let shared = c.station.shared.clone();
            let _woken =
                tokio::time::timeout(Duration::from_secs(1), shared.changed.notified()).await;
            tokio::time::sleep(Duration::from_millis(250)).await;
        }
        c.first = false;
        let number = c.station.shared.lock().run.as_ref().map_or(0, |r| r.number);
        if number != c.run {
            c.run = number;
            c.sent_samples = 0;
        }
        let snap = snapshot_of(&c.station, c.sent_samples);
        c.sent_samples = snap.from + snap.samples.len();
        let event = Event::default()
            .event("state")
            .json_data(&snap)
            .unwrap_or_else(|_| Event::default().event("state").data("{}"));
        Some((Ok::<_, std::convert::Infallible>(event), c))
    });
    Sse::new(stream)
        .keep_alive(KeepAlive::default())
        .into_response()
}

async fn history(State(s): St, Query(q): Query<HistoryQuery>) -> Response {
    let store = s.cfg.store.clone();
    let serial = q.serial;
    let found = tokio::task::spawn_blocking(move || -> Result<serde_json::Value, String> {
        let Some(mut st) = crate::results::Store::open(&store).map_err(|e| e.to_string())? else {
            return Ok(serde_json::json!({ "runs": [], "note": "no results store (--db none)" }));
        };
        let h = st.unit(&serial).map_err(|e| e.to_string())?;
        serde_json::to_value(&h).map_err(|e| e.to_string())
    })
    .await;
    match found {
        Ok(Ok(v)) => axum::Json(v).into_response(),
        Ok(Err(e)) => Refused::NotFound(e).into_response(),
        Err(e) => Refused::Bad(e.to_string()).into_response(),
    }
}

/// A stored run's report request.
#[derive(Debug, Deserialize)]
struct ReportQuery {
    run: String,
    /// The unit, for a batch's run (its report is `report-SERIAL.html`).
    unit: Option<String>,
}

/// The report page of a run the results store knows (a unit history's
/// row), from its log's directory, when that directory is one of this
/// station's run directories: the store names the file, the station's
/// runs directory bounds what it serves.
async fn stored_report(State(s): St, Query(q): Query<ReportQuery>) -> Response {
    let store = s.cfg.store.clone();
    let runs = s.cfg.runs.clone();
    let found = tokio::task::spawn_blocking(move || -> Result<Vec<u8>, Refused> {
        let not_found = |why: String| Refused::NotFound(why);
        let mut st = crate::results::Store::open(&store)
            .map_err(|e| not_found(e.to_string()))?
            .ok_or_else(|| not_found("no results store (--db none)".into()))?;
        let detail = st.show(&q.run).map_err(|e| not_found(e.to_string()))?;
        let log = detail
            .fields
            .iter()
            .find(|(k, _)| k == "log_path")
            .map(|(_, v)| PathBuf::from(v))
            .unwrap_or_default();
        let page = q
            .unit
            .as_deref()
            .map(|u| log.with_file_name(format!("{}.html", crate::unit::report_name(u))))
            .filter(|p| p.is_file())
            .unwrap_or_else(|| log.with_file_name("report.html"));
        let inside = match (
            log.parent().map(std::fs::canonicalize),
            std::fs::canonicalize(&runs),
        ) {
            (Some(Ok(dir)), Ok(runs)) => dir.starts_with(runs),
            _ => false,
        };
        let regular = std::fs::symlink_metadata(&page).is_ok_and(|m| m.file_type().is_file());
        if !(inside && regular) {
            return Err(not_found(format!(
                "run {} has no report in this station's runs directory",
                q.run
            )));
        }
        std::fs::read(&page).map_err(|e| not_found(e.to_string()))
    })
    .await;
    match found {
        Ok(Ok(bytes)) => {
            ([(header::CONTENT_TYPE, "text/html; charset=utf-8")], bytes).into_response()
        }
        Ok(Err(e)) => e.into_response(),
        Err(e) => Refused::Bad(e.to_string()).into_response(),
    }
}

async fn start(State(s): St, axum::Json(req): axum::Json<Start>) -> Response {
    match tokio::task::spawn_blocking(move || s.start(&req)).await {
        Ok(Ok(n)) => axum::Json(serde_json::json!({ "run": n })).into_response(),
        Ok(Err(e)) => e.into_response(),
        Err(e) => Refused::Bad(e.to_string()).into_response(),
    }
}

async fn abort(State(s): St) -> Response {
    match s.abort() {
        Ok(()) => axum::Json(serde_json::json!({ "aborting": true })).into_response(),
        Err(e) => e.into_response(),
    }
}

async fn answer(State(s): St, axum::Json(a): axum::Json<Answer>) -> Response {
    if s.shared.answer(a.id) {
        axum::Json(serde_json::json!({ "answered": a.id })).into_response()
    } else {
        Refused::Bad(format!("prompt {} is not waiting", a.id)).into_response()
    }
}

/// Which run to resume.
#[derive(Debug, Deserialize)]
struct ResumeRequest {
    run: u64,
}

async fn resume(State(s): St, axum::Json(r): axum::Json<ResumeRequest>) -> Response {
    match tokio::task::spawn_blocking(move || s.resume(r.run)).await {
        Ok(Ok(n)) => axum::Json(serde_json::json!({ "run": n })).into_response(),
        Ok(Err(e)) => e.into_response(),
        Err(e) => Refused::Bad(e.to_string()).into_response(),
    }
}

async fn run_file(State(s): St, UrlPath((number, file)): UrlPath<(u64, String)>) -> Response {
    // A batch's unit's report: `report-SERIAL.html` with the serial as its
    // run wrote it into a file name.
    let unit_report = |ext: &str| {
        file.strip_prefix("report-")
            .and_then(|f| f.strip_suffix(ext))
            .is_some_and(|serial| !serial.is_empty() && crate::unit::file_safe(serial) == serial)
    };
    let (name, kind) = match file.as_str() {
        "report.html" => ("report.html", "text/html; charset=utf-8"),
        "report.json" => ("report.json", "application/json"),
        "run.mcap" => ("run.mcap", "application/octet-stream"),
        _ if unit_report(".html") => (file.as_str(), "text/html; charset=utf-8"),
        _ if unit_report(".json") => (file.as_str(), "application/json"),
        _ => return Refused::NotFound(format!("no {file} in a run")).into_response(),
    };
    let path = match s.run_file(number, name) {
        Ok(p) => p,
        Err(e) => return e.into_response(),
    };
    match tokio::task::spawn_blocking(move || std::fs::read(&path))
        .await
        .unwrap_or_else(|e| Err(std::io::Error::other(e)))
    {
        Ok(bytes) => {
            let mut headers = vec![(header::CONTENT_TYPE, kind.to_owned())];
            if name == "run.mcap" {
                headers.push((
                    header::CONTENT_DISPOSITION,
                    format!("attachment; filename=\"run-{number}.mcap\""),
                ));
            }
            let mut r = bytes.into_response();
            for (k, v) in headers {
                if let Ok(v) = v.parse() {
                    r.headers_mut().insert(k, v);
                }
            }
            r
        }
        Err(e) => Refused::NotFound(format!("{name} of run {number}: {e}")).into_response(),
    }
}
