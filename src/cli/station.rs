//! `gyrobench station [--bench FILE] [--procedures DIR] [--listen ADDR]`:
//! the operator's page, served until Ctrl-C.

use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::Arc;

use anyhow::{Context, Result};
use clap::Args;

use super::{Outcome, Usage};
use crate::runlog::live::{Live, LiveError};
use crate::station::listener::{Admission, Guarded};
use crate::station::{Config, Station, new_token, router};

#[derive(Debug, Args)]
#[command(after_help = after_help!(
    "gyrobench station --procedures procedures",
    "0 stopped with Ctrl-C, SIGTERM, SIGHUP or SIGQUIT (a run going on is aborted first: the bench goes to its safe state), \
     1 error (the address cannot be taken, a bench file that does not load), 2 usage (bad arguments)"
))]
pub struct StationArgs {
    /// Bench file (default: the embedded simulated bench, on virtual time)
    #[arg(long)]
    pub bench: Option<PathBuf>,
    /// The procedures the page offers (every `*.toml` in it)
    #[arg(long, default_value = "procedures")]
    pub procedures: PathBuf,
    /// Where run directories go
    #[arg(long, default_value = "runs")]
    pub runs: PathBuf,
    /// Address to serve on; anything but loopback is said loudly (the
    /// token in the URL is then all that keeps others out)
    #[arg(long, default_value = "127.0.0.1:8700")]
    pub listen: SocketAddr,
    /// Simulated bench speed: `max` or a factor over real time
    #[arg(long, default_value = "max")]
    pub speed: String,
    /// The results store (as `run --db`)
    #[arg(long = "db", value_name = "STORE")]
    pub db: Option<String>,
    /// The access token (default: a fresh random one)
    #[arg(long)]
    pub token: Option<String>,
    /// Where every run's channels are published live for Foxglove or
    /// Lichtblick (a Foxglove WebSocket server; loopback only, port 0
    /// picks a free one)
    #[arg(long, value_name = "ADDR", default_value = "127.0.0.1:8765")]
    pub live: SocketAddr,
    /// No live Foxglove stream
    #[arg(long, conflicts_with = "live")]
    pub no_live: bool,
}

pub fn run(args: StationArgs) -> Result<Outcome> {
    let pacing = super::run::pacing(&args.speed)?;
    if !args.no_live && !args.live.ip().is_loopback() {
        return Err(Usage(LiveError::NotLoopback(args.live).to_string()).into());
    }
    let bench = super::check::load_bench(args.bench.as_ref())?;
    if !args.procedures.is_dir() {
        return Err(Usage(format!(
            "{} is not a directory of procedures; give one with --procedures",
            args.procedures.display()
        ))
        .into());
    }
    let token = match args.token {
        Some(t) if t.len() < 16 || !t.chars().all(|c| c.is_ascii_alphanumeric()) => {
            return Err(Usage("a station token is at least 16 letters or digits".into()).into());
        }
        Some(t) => t,
        None => new_token(),
    };
    let store = crate::results::Location::resolve(
        args.db.as_deref(),
        bench.results.as_ref().and_then(|r| r.db.as_deref()),
    );
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .context("starting the async runtime")?;
    let live = if args.no_live {
        None
    } else {
        let live = rt
            .block_on(Live::start(args.live))
            .map_err(|e| anyhow::anyhow!("{e}, or run the station without it: --no-live"))?;
        Some(Arc::new(live))
    };
    let banner = live.as_ref().map(|l| l.banner());
    let station = Station::new(Config {
        bench_label: args
            .bench
            .as_ref()
            .map_or("embedded".into(), |p| p.display().to_string()),
        bench,
        procedures: args.procedures,
        runs: args.runs,
        store,
        speed: args.speed,
        pacing,
        token: token.clone(),
        db: args.db,
        live,
    });
    rt.block_on(serve(args.listen, station, token, banner))?;
    // A handler's blocking work (a store query, say) is not waited for
    // past this: the station has stopped.
    rt.shutdown_timeout(STOP_GRACE);
    Ok(Outcome::Success)
}

/// How long the stop waits for connections still open after closing
/// them all (a response being written, a client slow to read it).
const STOP_GRACE: std::time::Duration = std::time::Duration::from_secs(2);

/// Serve the station on `listen` until a stop signal; then a run going on
/// is aborted (its cleanup runs), every connection is closed, whatever it
/// waits for (a half-sent request, an idle browser, a flood of them), and
/// this returns.
async fn serve(
    listen: SocketAddr,
    station: Arc<Station>,
    token: String,
    banner: Option<String>,
) -> Result<()> {
    let listener = tokio::net::TcpListener::bind(listen)
        .await
        .with_context(|| format!("serving the station on {listen}"))?;
    let addr = listener.local_addr().context("the station's address")?;
    if !addr.ip().is_loopback() {
        errln!(
            "warning: the station listens on {addr}, beyond this computer: anyone with the URL below (its token) can run the bench"
        );
    }
    // The handlers are in place before the URL is printed: whoever reads
    // it may send SIGTERM at once, and the station must stop cleanly.
    let stop =
        stop_signal().context("installing the Ctrl-C, SIGTERM, SIGHUP and SIGQUIT handlers")?;
    outln!("station http://{addr}/?token={token}")?;
    errln!("open the URL above in a browser; Ctrl-C stops the station");
    if let Some(b) = &banner {
        errln!("{b}");
    }
    let app = router(station.clone()).into_make_service_with_connect_info::<Admission>();
    let listener = Guarded::new(listener);
    let closer = listener.closer();
    let stopped = Arc::new(tokio::sync::Notify::new());
    let server = {
        let stopped = stopped.clone();
        axum::serve(listener, app).with_graceful_shutdown(async move {
            stop.await;
            errln!("stopping: a run going on is aborted and its cleanup runs first");
            station.shut_down().await;
            closer.close_all();
            stopped.notify_one();
        })
    };
    tokio::select! {
        served = server.into_future() => served.context("serving the station"),
        () = async {
            stopped.notified().await;
            tokio::time::sleep(STOP_GRACE).await;
        } => Ok(()),
    }
}

/// Ctrl-C, SIGTERM, SIGHUP (the terminal or SSH session that started the
/// station closed) or SIGQUIT (Ctrl-\): every handler installed when this
/// returns, so a signal that comes before the future is first polled is
/// not lost, and none of them kills the station outright: a run going on
/// is aborted, its cleanup runs and its report is written first.
fn stop_signal() -> std::io::Result<impl std::future::Future<Output = ()>> {
    use tokio::signal::unix::{SignalKind, signal};
    let mut term = signal(SignalKind::terminate())?;
    let mut int = signal(SignalKind::interrupt())?;
    let mut hup = signal(SignalKind::hangup())?;
    let mut quit = signal(SignalKind::quit())?;
    Ok(async move {
        tokio::select! {
            _ = int.recv() => {}
            _ = term.recv() => {}
            _ = hup.recv() => {}
            _ = quit.recv() => {}
        }
    })
}
