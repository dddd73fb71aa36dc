//! `gyrobench calibrate RUN.mcap... -o COEFFS.toml`: fit the compensation
//! models on recorded runs, validate on held-out runs, write coefficients.

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::Args;

use super::Outcome;
use crate::calibrate::{calibrate, load};

#[derive(Debug, Args)]
pub struct CalibrateArgs {
    /// Run logs (.mcap) of one unit; two or more for held-out validation.
    #[arg(required = true)]
    runs: Vec<PathBuf>,
    /// Coefficients file to write (the format `run --coeffs` reads).
    #[arg(short, long)]
    out: PathBuf,
}

pub fn run(args: CalibrateArgs) -> Result<Outcome> {
    let runs = args
        .runs
        .iter()
        .map(|p| load(p).with_context(|| format!("reading {}", p.display())))
        .collect::<Result<Vec<_>>>()?;
    let cal = calibrate(&runs).context("fitting the compensation models")?;
    let toml_text = format!(
        "# Thermal compensation coefficients written by gyrobench calibrate.\n# `gyrobench run --coeffs` compensates with [model4].\n{}",
        toml::to_string_pretty(&cal.coeffs_file()).context("writing the coefficients as TOML")?
    );
    crate::fsutil::write_atomic(&args.out, toml_text.as_bytes())
        .with_context(|| format!("writing {}", args.out.display()))?;
    let json_path = args.out.with_extension("calibration.json");
    crate::fsutil::write_atomic(&json_path, serde_json::to_string_pretty(&cal)?.as_bytes())
        .with_context(|| format!("writing {}", json_path.display()))?;
    let html_path = args.out.with_extension("calibration.html");
    crate::fsutil::write_atomic(&html_path, cal.render_html().as_bytes())
        .with_context(|| format!("writing {}", html_path.display()))?;
    outf!("{}", cal.render_text())?;
    eprintln!(
        "coefficients in {}, details in {} and {}",
        args.out.display(),
        json_path.display(),
        html_path.display()
    );
    Ok(Outcome::Success)
}
