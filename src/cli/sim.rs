//! `gyrobench sim serve`: run the simulated bench as a standalone process.

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::{Args, Subcommand};

use super::{Outcome, Usage};
use gyrobench::sim::Fault;
use gyrobench::sim::serve::{Serve, can_play, schedule_faults, start};

#[derive(Debug, Subcommand)]
pub enum SimCommand {
    /// Serve the simulated chamber, table and gyro on loopback TCP and ptys.
    /// Prints one line per endpoint, `<device> <protocol> <address>`, then
    /// serves until Ctrl-C or SIGTERM.
    #[command(after_help = after_help!(
        "gyrobench sim serve --config fixtures/sim/serve.toml --inject chamber-alarm@600",
        "0 stopped by Ctrl-C or SIGTERM, 1 it could not start (a port taken, a bad configuration), \
         2 usage"
    ))]
    Serve(ServeArgs),
    /// Benchmark the gyro link: the simulated gyro streams frames into a pty
    /// in real time and the driver decodes them; prints frames, losses and rate.
    #[command(after_help = after_help!("gyrobench sim link-bench --seconds 10", plain))]
    LinkBench(LinkBenchArgs),
}

#[derive(Debug, Args)]
pub struct LinkBenchArgs {
    /// Frame rate of the simulated gyro, Hz.
    #[arg(long, default_value_t = 2000.0)]
    rate_hz: f64,
    /// Line speed set on the pty, baud.
    #[arg(long, default_value_t = 921_600)]
    baud: u32,
    /// Duration, s of wall time.
    #[arg(long, default_value_t = 600.0)]
    seconds: f64,
}

#[derive(Debug, Args)]
pub struct ServeArgs {
    /// Serve configuration (twin, seed, speed, fixed ports); see
    /// fixtures/sim/serve.toml.
    #[arg(long)]
    config: Option<PathBuf>,
    /// Play a device's fault, FAULT@SECONDS of the served device time, on
    /// the wire (the same faults as `run --inject`: chamber-alarm,
    /// chamber-silent, table-interlock, gyro-silent, gyro-corrupt,
    /// gyro-stuck, gyro-saturated, supply-overcurrent; unit-lost on a
    /// batch's fixture). Repeatable.
    #[arg(long, value_name = "FAULT@SECONDS")]
    inject: Vec<String>,
}

fn runtime() -> Result<tokio::runtime::Runtime> {
    tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .context("starting the async runtime")
}

pub fn run(cmd: SimCommand) -> Result<Outcome> {
    match cmd {
        SimCommand::LinkBench(args) => {
            let positive = |v: f64| v > 0.0 && v.is_finite();
            if !(positive(args.rate_hz) && positive(args.seconds)) {
                return Err(Usage("--rate-hz and --seconds must be positive".into()).into());
            }
            let r = runtime()?.block_on(gyrobench::sim::link_bench::run(
                args.rate_hz,
                args.baud,
                args.seconds,
            ))?;
            outf!("{}", render_link_bench(&args, &r))?;
            Ok(Outcome::Success)
        }
        SimCommand::Serve(args) => {
            let serve = Serve::load(args.config.as_deref())
                .context("loading the sim serve configuration")?;
            let faults = args
                .inject
                .iter()
                .map(|s| {
                    let (at, f) = Fault::parse_at(s).map_err(|e| Usage(format!("--inject {e}")))?;
                    can_play(&serve, f).map_err(|e| Usage(format!("--inject {s:?}: {e}")))?;
                    Ok((at, f))
                })
                .collect::<Result<Vec<_>>>()?;
            runtime()?.block_on(async {
                // Listening for the stop signals before the endpoints are
                // printed: a script that stops the server as soon as it
                // has read them must not kill it without its handler.
                let stop = stop_signals()?;
                let served = start(&serve).await.with_context(|| match &args.config {
                    Some(p) => format!("serving the simulated bench of {}", p.display()),
                    None => "serving the simulated bench".to_owned(),
                })?;
                // Through `out`: a reader that stops after the first lines
                // (`sim serve | head -1`) does not stop the server.
                let lines: String = served.endpoints.iter().map(|e| format!("{e}\n")).collect();
                super::out(&lines)?;
                schedule_faults(&served.bench, faults, |t, f, r| match r {
                    Ok(()) => errln!("fault {} played at {t:.1} s of device time", f.name()),
                    Err(e) => errln!("fault {} not played: {e}", f.name()),
                });
                errln!(
                    "serving the simulated bench (speed {}x); Ctrl-C or SIGTERM to stop",
                    serve.config.speed
                );
                wait_for_stop(stop).await;
                errln!("stopped");
                Ok(Outcome::Success)
            })
        }
    }
}

/// Ctrl-C and SIGTERM, listened for from now on.
fn stop_signals() -> Result<[tokio::signal::unix::Signal; 2]> {
    use tokio::signal::unix::{SignalKind, signal};
    Ok([
        signal(SignalKind::interrupt()).context("installing the Ctrl-C handler")?,
        signal(SignalKind::terminate()).context("installing the SIGTERM handler")?,
    ])
}

async fn wait_for_stop([mut int, mut term]: [tokio::signal::unix::Signal; 2]) {
    tokio::select! {
        _ = int.recv() => {}
        _ = term.recv() => {}
    }
}

/// The benchmark's figures as text.
pub fn render_link_bench(a: &LinkBenchArgs, r: &gyrobench::sim::link_bench::LinkBench) -> String {
    let s = &r.stats;
    format!(
        "gyro link over a pty at {baud} baud, {rate} Hz frames, {secs:.0} s\n\
         frames decoded    {frames}\n\
         decoded rate      {dec:.1} frames/s (expected {rate})\n\
         lost frames       {lost}\n\
         CRC errors        {crc}\n\
         resyncs           {resync}\n\
         duplicates        {dup}\n\
         bytes             {bytes} ({bps:.0} bit/s at 10 bits a byte)\n",
        baud = a.baud,
        rate = a.rate_hz,
        secs = r.elapsed_s,
        frames = r.frames,
        dec = r.frames as f64 / r.elapsed_s,
        lost = s.lost_frames,
        crc = s.crc_errors,
        resync = s.resyncs,
        dup = s.duplicates,
        bytes = s.bytes,
        bps = s.bytes as f64 * 10.0 / r.elapsed_s,
    )
}
