//! `gyrobench sim serve`: run the simulated bench as a standalone process.

use std::io::Write as _;
use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::{Args, Subcommand};

use super::Outcome;
use crate::sim::serve::{Serve, start};

#[derive(Debug, Subcommand)]
pub enum SimCommand {
    /// Serve the simulated chamber, table and gyro on loopback TCP and ptys.
    /// Prints one line per endpoint, `<device> <protocol> <address>`, then
    /// serves until Ctrl-C or SIGTERM.
    Serve(ServeArgs),
}

#[derive(Debug, Args)]
pub struct ServeArgs {
    /// Serve configuration (twin, seed, speed, fixed ports); see
    /// fixtures/sim/serve.toml.
    #[arg(long)]
    config: Option<PathBuf>,
}

pub fn run(cmd: SimCommand) -> Result<Outcome> {
    match cmd {
        SimCommand::Serve(args) => {
            let serve = Serve::load(args.config.as_deref())
                .context("loading the sim serve configuration")?;
            let rt = tokio::runtime::Builder::new_multi_thread()
                .worker_threads(2)
                .enable_all()
                .build()
                .context("starting the async runtime")?;
            rt.block_on(async {
                let served = start(&serve)
                    .await
                    .context("opening the simulated devices")?;
                let mut out = std::io::stdout().lock();
                for e in &served.endpoints {
                    writeln!(out, "{e}")?;
                }
                out.flush()?;
                drop(out);
                eprintln!(
                    "serving the simulated bench (speed {}x); Ctrl-C or SIGTERM to stop",
                    serve.config.speed
                );
                wait_for_stop().await?;
                eprintln!("stopped");
                Ok(Outcome::Success)
            })
        }
    }
}

async fn wait_for_stop() -> Result<()> {
    let mut term = tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate())
        .context("installing the SIGTERM handler")?;
    tokio::select! {
        r = tokio::signal::ctrl_c() => r.context("waiting for Ctrl-C")?,
        _ = term.recv() => {}
    }
    Ok(())
}
