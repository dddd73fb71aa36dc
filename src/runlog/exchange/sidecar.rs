//! The export's sidecar: `RUN.export.toml`, written by `export` beside
//! `RUN.csv` and read by `import RUN.csv` when it lies there. It carries
//! what the interchange CSV cannot and an import needs to judge the rows
//! as the run was judged: the run's procedure (its text), its unit (serial
//! and type), its site and table geometry, the coefficient set it
//! compensated with, and where it came from (`docs/analysis.md`, "The
//! export's sidecar").

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::SiteTable;
use crate::coeffs::{CoefficientSet, CoeffsUsed};
use crate::config::{Checker, ConfigError, Source};
use crate::geometry::Site;
use crate::runlog::meta::RunMeta;

/// The sidecar's format number (`[export] format`).
pub const FORMAT: u32 = 1;

/// The heading comment of a sidecar.
const HEADER: &str = "# Written by gyrobench export beside its CSV: what the CSV cannot carry.\n\
# `gyrobench import CSV` reads it when it lies beside the CSV, and judges the\n\
# rows with this procedure, unit, site and coefficients, as the run was judged\n\
# (docs/analysis.md, \"The export's sidecar\"). Delete it to import the CSV alone.\n";

/// `RUN.export.toml`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Sidecar {
    /// Where it came from.
    pub export: Provenance,
    /// The unit the run was of.
    pub unit: Unit,
    /// Where the run stood.
    pub site: Site,
    /// The table it was made on, when the log knew its angles.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub table: Option<SiteTable>,
    /// The procedure it was judged by.
    pub procedure: Carried,
    /// The coefficient set it compensated with (absent: model 4 fitted on
    /// its own records).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub coefficients: Option<Coefficients>,
}

/// `[export]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Provenance {
    /// [`FORMAT`].
    pub format: u32,
    /// The CSV it was written with (its file name).
    pub csv: String,
    /// The log exported.
    pub log: String,
    /// The run's id.
    pub run_id: String,
    /// When the run started (UTC, RFC 3339); the import is dated by it.
    pub started_utc: String,
    /// The gyrobench that exported it.
    pub software: String,
}

/// `[unit]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Unit {
    /// Serial number.
    pub serial: String,
    /// Type (the procedure's `dut_type`).
    #[serde(rename = "type")]
    pub dut_type: String,
}

/// `[procedure]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Carried {
    /// The procedure file the run was given.
    pub path: String,
    /// Its text, as the run logged it.
    pub text: String,
}

/// `[coefficients]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Coefficients {
    /// The set's text, as the run logged it.
    pub text: String,
    /// How the run named it.
    pub used: CoeffsUsed,
}

/// The sidecar of the CSV at `csv`: `RUN.export.toml` beside `RUN.csv`.
pub fn path_for(csv: &Path) -> PathBuf {
    csv.with_extension("export.toml")
}

/// What a log lacks for a sidecar.
#[derive(Debug, thiserror::Error)]
pub enum SidecarError {
    /// No procedure in its run metadata.
    #[error("the log's run metadata has no procedure")]
    NoProcedure,
    /// Its site does not read.
    #[error("the log's site does not read ({0})")]
    Site(#[source] serde_json::Error),
}

impl Sidecar {
    /// The sidecar of a run from its `run` metadata; `geometry` is the
    /// table's when the log knows its angles. Errors say what the log
    /// lacks.
    pub fn of_run(
        meta: &RunMeta,
        geometry: Option<crate::geometry::TableGeometry>,
        csv: &Path,
        log: &Path,
    ) -> Result<Self, SidecarError> {
        if meta.procedure_toml.trim().is_empty() {
            return Err(SidecarError::NoProcedure);
        }
        let site: Site = serde_json::from_str(&meta.site_json).map_err(SidecarError::Site)?;
        let (serial, dut_type) = meta.unit().map_or_else(
            || (meta.dut_serial.clone(), meta.dut_type.clone()),
            |u| (u.serial.clone(), u.dut_type.clone()),
        );
        let coefficients = meta.coeffs_toml.as_ref().map(|text| Coefficients {
            text: text.clone(),
            used: meta
                .unit()
                .map_or_else(CoeffsUsed::fitted, |u| u.coefficients.clone()),
        });
        Ok(Self {
            export: Provenance {
                format: FORMAT,
                csv: csv
                    .file_name()
                    .map_or_else(String::new, |n| n.to_string_lossy().into_owned()),
                log: log.display().to_string(),
                run_id: meta.run_id.clone(),
                started_utc: meta.start_time_utc.clone(),
                software: format!(
                    "gyrobench {} ({})",
                    crate::version::VERSION,
                    crate::version::REVISION
                ),
            },
            unit: Unit { serial, dut_type },
            site,
            table: geometry.map(|geometry| SiteTable { geometry }),
            procedure: Carried {
                path: meta.procedure_path.clone(),
                text: meta.procedure_toml.clone(),
            },
            coefficients,
        })
    }

    /// The sidecar's text.
    pub fn to_toml(&self) -> Result<String, toml::ser::Error> {
        Ok(format!("{HEADER}\n{}", toml::to_string_pretty(self)?))
    }

    /// Read and check the sidecar at `path`.
    pub fn load(path: &Path) -> Result<Self, ConfigError> {
        Self::from_source(&Source::read(path)?)
    }

    /// Parse and check a sidecar's text: its format, the site and geometry
    /// as a site file's, the unit's serial, the coefficient set (the
    /// procedure is checked against the bench the import makes).
    pub fn from_source(src: &Source) -> Result<Self, ConfigError> {
        let s: Self = src.parse()?;
        let c = Checker::new(src);
        c.ensure(
            s.export.format == FORMAT,
            "export.format",
            &format!(
                "is {}: this gyrobench reads sidecars of format {FORMAT}; export the log again with it",
                s.export.format
            ),
        )?;
        s.site.validate(&c, "site")?;
        if let Some(t) = &s.table {
            t.geometry.validate(&c, "table.geometry")?;
        }
        if let Err(e) = crate::unit::check_serial(&s.unit.serial) {
            return Err(src.invalid("unit.serial", e.to_string()));
        }
        c.ensure(
            !s.unit.dut_type.trim().is_empty(),
            "unit.type",
            "is empty; give the unit's type",
        )?;
        if let Some(k) = &s.coefficients {
            CoefficientSet::from_source(&Source::from_text(
                &format!("coefficients.text in {}", src.path.display()),
                &k.text,
            ))?;
        }
        Ok(s)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_sidecar_reads_back_what_was_written_and_names_a_bad_key() {
        let meta = RunMeta {
            run_id: "abc".into(),
            procedure_toml: "[procedure]\nname = \"x\"\n".into(),
            procedure_path: "procedures/x.toml".into(),
            site_json: serde_json::to_string(&crate::bench::BenchConfig::embedded().site)
                .expect("site"),
            dut_serial: "RL16-0042".into(),
            dut_type: "RL-16".into(),
            start_time_utc: "2026-12-03T10:15:00+00:00".into(),
            ..RunMeta::default()
        };
        let s = Sidecar::of_run(
            &meta,
            Some(crate::bench::BenchConfig::embedded().table.geometry),
            Path::new("out/run.csv"),
            Path::new("runs/x/run.mcap"),
        )
        .expect("sidecar");
        let text = s.to_toml().expect("toml");
        assert!(text.starts_with("# Written by gyrobench export"), "{text}");
        let back =
            Sidecar::from_source(&Source::from_text("run.export.toml", &text)).expect("reads");
        assert_eq!(back, s);
        assert_eq!(back.export.csv, "run.csv");
        assert_eq!(
            path_for(Path::new("a/run.csv")),
            Path::new("a/run.export.toml")
        );
        let bad = text.replace("serial = \"RL16-0042\"", "serial = \" RL16-0042\"");
        let e = Sidecar::from_source(&Source::from_text("run.export.toml", &bad))
            .expect_err("padded serial")
            .to_string();
        assert!(
            e.starts_with("run.export.toml:") && e.contains("`unit.serial`"),
            "{e}"
        );
    }
}
