//! The one rule for every output a command writes: never one of its
//! inputs, never a run's log, never anywhere inside a run directory.
//!
//! A run directory is a directory holding a run's log (`run.mcap`) or its
//! lock (`run.lock`); everything in it, at any depth, is that run's: a
//! file written over one of them forges the record (a coefficient set
//! where the log was, a CSV where the report was), and a new one is read
//! as the run's (a log named `run.part2.mcap` is indexed as its next
//! part). So an output that resolves (through `..` and links, its missing
//! directories included) to a place inside a run directory, or to an
//! existing run's log anywhere, is refused unless the user says `--force`.
//! A command's own place in a run directory (`replay`'s `RUN/replay/`,
//! `recover`'s `RUN/run-recovered.mcap`) is its to write.

use std::path::{Component, Path, PathBuf};

use super::SamePath;

/// Name of a run's (first) log in its run directory.
pub const RUN_LOG: &str = "run.mcap";

/// Name of the lock file a running run holds in its run directory.
pub const RUN_LOCK: &str = "run.lock";

/// Whether `dir` is a run directory: it holds a run's log or lock (as a
/// file or a link: either makes it a run's).
pub fn is_run_dir(dir: &Path) -> bool {
    [RUN_LOG, RUN_LOCK]
        .iter()
        .any(|name| std::fs::symlink_metadata(dir.join(name)).is_ok())
}

/// Why an output is refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum OutputRefused {
    /// The output is one of the command's inputs.
    #[error(transparent)]
    IsAnInput(#[from] SamePath),
    /// The output exists and is a run's log.
    #[error(
        "{output} is a run's log: writing it would replace the record of a run; choose another \
         output path, or give --force to write over it"
    )]
    RunLog {
        /// The output as given.
        output: String,
    },
    /// The output is a run directory, or inside one.
    #[error(
        "{output} is {place} {dir}: a run directory holds its run's files alone \
         (a file written there replaces one of them or is read as one of them); choose a path \
         outside it, or give --force to write there anyway"
    )]
    InRunDir {
        /// The output as given.
        output: String,
        /// "inside the run directory", or "the run directory" when the
        /// output is the directory itself.
        place: &'static str,
        /// The run directory, resolved.
        dir: String,
    },
}

/// What an output is checked against.
#[derive(Debug, Clone, Copy, Default)]
pub struct OutputRule<'a> {
    /// The files the command reads: the output may be none of them.
    pub inputs: &'a [&'a Path],
    /// `--force`: the user means to write into a run directory or over a
    /// run's log.
    pub force: bool,
    /// The command's own place, a file or directory that may lie in a run
    /// directory (`replay`'s default `RUN/replay`): an output there, or
    /// below it, is the command's to write.
    pub own: Option<&'a Path>,
}

/// Check `output` (a file, or a directory a command writes its files
/// into) against `rule`; see the module's documentation.
pub fn check_output(output: &Path, rule: OutputRule<'_>) -> Result<(), OutputRefused> {
    super::ensure_distinct(output, rule.inputs)?;
    if rule.force {
        return Ok(());
    }
    let real = real_path(output);
    if rule.own.is_some_and(|own| real.starts_with(real_path(own))) {
        return Ok(());
    }
    let shown = output.display().to_string();
    if let Some(dir) = real.ancestors().find(|a| is_run_dir(a)) {
        return Err(OutputRefused::InRunDir {
            output: shown,
            place: if dir == real {
                "the run directory"
            } else {
                "inside the run directory"
            },
            dir: dir.display().to_string(),
        });
    }
    if is_log(&real) {
        return Err(OutputRefused::RunLog { output: shown });
    }
    Ok(())
}

/// Whether `path` is a regular file that starts as an MCAP file does
/// (never opened when it is a FIFO or a device: that open could wait).
fn is_log(path: &Path) -> bool {
    use std::io::Read;
    let mut magic = [0u8; 8];
    crate::config::open_file(path)
        .ok()
        .is_some_and(|mut f| f.read_exact(&mut magic).is_ok() && magic == *mcap::MAGIC)
}

/// Where `p` really is: absolute, through links (the output's own, and
/// every existing directory's), its missing part joined as written with
/// `.` and `..` taken as the directories a create would make.
pub fn real_path(p: &Path) -> PathBuf {
    let p = super::resolve(p);
    let abs = std::path::absolute(&p).unwrap_or(p);
    let parts: Vec<Component<'_>> = abs.components().collect();
    for k in (1..=parts.len()).rev() {
        let Ok(mut out) = parts[..k].iter().collect::<PathBuf>().canonicalize() else {
            continue;
        };
        for c in &parts[k..] {
            match c {
                Component::ParentDir => {
                    out.pop();
                }
                Component::Normal(n) => out.push(n),
                _ => {}
            }
        }
        return out;
    }
    abs
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run_dir(root: &Path, name: &str) -> PathBuf {
        let d = root.join(name);
        std::fs::create_dir_all(&d).expect("run dir");
        std::fs::write(d.join(RUN_LOG), mcap::MAGIC).expect("log");
        d
    }

    fn refused(output: &Path, rule: OutputRule<'_>) -> Option<OutputRefused> {
        check_output(output, rule).err()
    }

    #[test]
    fn the_run_directory_is_the_one_the_run_locks() {
        // The controller's run directory and this rule name the same files.
        assert_eq!(crate::session::rundir::LOCK_FILE, RUN_LOCK);
    }

    #[test]
    fn anything_inside_a_run_directory_is_refused_however_it_is_spelled() {
        let tmp = tempfile::tempdir().expect("temp dir");
        let root = tmp.path();
        let run = run_dir(root, "run");
        std::fs::create_dir_all(root.join("other")).expect("other");
        std::os::unix::fs::symlink(&run, root.join("link")).expect("link");
        let locked = root.join("locked");
        std::fs::create_dir_all(&locked).expect("locked");
        std::fs::write(locked.join(RUN_LOCK), b"").expect("lock");
        let rule = OutputRule::default();
        for out in [
            run.join("run.part2.mcap"),
            run.join("report.json"),
            run.join("new").join("deeper").join("x.csv"),
            root.join("other").join("..").join("run").join("x.csv"),
            root.join("missing").join("..").join("run").join("x.csv"),
            root.join("link").join("x.csv"),
            locked.join("x.csv"),
            run.clone(),
        ] {
            match refused(&out, rule) {
                Some(e @ OutputRefused::InRunDir { .. }) => {
                    let msg = e.to_string();
                    assert!(
                        msg.contains("--force") && msg.contains("run directory"),
                        "{msg}"
                    );
                }
                other => panic!("{}: {other:?}", out.display()),
            }
        }
        // Outside: written; --force: written anywhere.
        assert_eq!(refused(&root.join("other").join("x.csv"), rule), None);
        assert_eq!(refused(&root.join("x.csv"), rule), None);
        let force = OutputRule {
            force: true,
            ..rule
        };
        assert_eq!(refused(&run.join("x.csv"), force), None);
    }

    #[test]
    fn a_run_log_anywhere_is_refused_and_an_input_always() {
        let tmp = tempfile::tempdir().expect("temp dir");
        let lone = tmp.path().join("lab-run.mcap");
        std::fs::write(&lone, mcap::MAGIC).expect("log");
        assert!(matches!(
            refused(&lone, OutputRule::default()),
            Some(OutputRefused::RunLog { .. })
        ));
        let csv = tmp.path().join("a.csv");
        std::fs::write(&csv, b"time_s\n").expect("csv");
        assert_eq!(refused(&csv, OutputRule::default()), None);
        let inputs = [csv.as_path()];
        let rule = OutputRule {
            inputs: &inputs,
            force: true,
            own: None,
        };
        assert!(matches!(
            refused(&csv, rule),
            Some(OutputRefused::IsAnInput(_))
        ));
    }

    #[test]
    fn a_commands_own_place_in_a_run_directory_is_its_to_write() {
        let tmp = tempfile::tempdir().expect("temp dir");
        let run = run_dir(tmp.path(), "run");
        let own = run.join("replay");
        let rule = OutputRule {
            own: Some(&own),
            ..OutputRule::default()
        };
        assert_eq!(refused(&own, rule), None);
        assert_eq!(refused(&own.join("report.json"), rule), None);
        assert!(refused(&run.join("elsewhere"), rule).is_some());
        assert!(
            refused(&run.join("replay2"), rule).is_some(),
            "a prefix of a name is not a place"
        );
    }
}
