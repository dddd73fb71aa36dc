//! The README's commands, run as a new user would from a fresh clone: the
//! first of "The two commands" and every line of "More commands", in
//! order, in a working directory holding copies of `procedures/` and
//! `fixtures/` (so nothing lands in the repository), each exit code
//! checked: 0, or the `(exit N` the line's comment gives. A line whose
//! comment says `needs hardware` is skipped; one that `serves until
//! Ctrl-C` is started, seen serving, and stopped with SIGTERM. The
//! diagnosis self-checks, which depend on no other line, run in a test and
//! a working directory of their own, beside the rest.

use std::io::BufRead;
use std::path::Path;
use std::process::Stdio;

use crate::cli::{command, temp_dir};
use crate::common::stderr;

const ROOT: &str = env!("CARGO_MANIFEST_DIR");

/// What a README line is expected to do.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Expect {
    /// Run to its end with this exit code.
    Exit(i32),
    /// Serve until stopped (`# serves until Ctrl-C`).
    Serves,
    /// Not runnable here (`# needs hardware`).
    NeedsHardware,
}

/// One `cargo run --release -- ARGS` line of the README.
#[derive(Debug, Clone)]
struct Line {
    /// 1-based line number in README.md.
    number: usize,
    /// The line as written.
    text: String,
    /// ARGS.
    args: Vec<String>,
    /// `> FILE`: stdout goes there.
    stdout_to: Option<String>,
    expect: Expect,
}

const PREFIX: &str = "cargo run --release -- ";

/// The expectation a line's comment states.
fn expectation(comment: &str) -> Expect {
    if comment.contains("needs hardware") {
        return Expect::NeedsHardware;
    }
    if comment.contains("serves until Ctrl-C") {
        return Expect::Serves;
    }
    match comment.split_once("(exit ") {
        Some((_, rest)) => {
            let digits: String = rest.chars().take_while(char::is_ascii_digit).collect();
            Expect::Exit(digits.parse().expect("a number after `(exit `"))
        }
        None => Expect::Exit(0),
    }
}

fn parse_line(number: usize, text: &str) -> Line {
    let (command, comment) = match text.find(" #") {
        Some(i) => (&text[..i], &text[i + 2..]),
        None => (text, ""),
    };
    let command = command
        .strip_prefix(PREFIX)
        .unwrap_or_else(|| panic!("README.md:{number}: not a `{PREFIX}` line: {text}"));
    let mut words: Vec<&str> = command.split_whitespace().collect();
    if words.last() == Some(&"&") {
        words.pop();
    }
    let mut stdout_to = None;
    if let Some(i) = words.iter().position(|w| *w == ">") {
        assert_eq!(
            i + 2,
            words.len(),
            "README.md:{number}: `> FILE` ends the line"
        );
        stdout_to = Some(words[i + 1].to_owned());
        words.truncate(i);
    }
    for w in &words {
        assert!(
            !w.contains(['<', '>', '"', '\'', '$', '|', ';', '*']),
            "README.md:{number}: `{w}` is a placeholder or shell syntax, not a runnable argument: {text}"
        );
    }
    Line {
        number,
        text: text.to_owned(),
        args: words.iter().map(|w| (*w).to_owned()).collect(),
        stdout_to,
        expect: expectation(comment),
    }
}

/// The `cargo run` lines of the `sh` blocks of each `## ` section.
fn sections(readme: &str) -> Vec<(String, Vec<Line>)> {
    let mut out: Vec<(String, Vec<Line>)> = Vec::new();
    let mut in_sh = false;
    for (i, l) in readme.lines().enumerate() {
        if let Some(title) = l.strip_prefix("## ") {
            out.push((title.trim().to_owned(), Vec::new()));
        } else if l.starts_with("```") {
            in_sh = !in_sh && l.trim() == "```sh";
        } else if in_sh
            && l.starts_with(PREFIX)
            && let Some((_, lines)) = out.last_mut()
        {
            lines.push(parse_line(i + 1, l));
        }
    }
    out
}

/// The lines the test runs: the first of "The two commands", then all of
/// "More commands".
fn readme_lines() -> Vec<Line> {
    let readme = std::fs::read_to_string(Path::new(ROOT).join("README.md")).expect("README.md");
    let all = sections(&readme);
    let section = |title: &str| {
        all.iter()
            .find(|(t, _)| t == title)
            .map(|(_, l)| l.clone())
            .unwrap_or_else(|| panic!("README.md has no `## {title}` with commands"))
    };
    let mut lines: Vec<Line> = section("The two commands").into_iter().take(1).collect();
    lines.extend(section("More commands"));
    lines
}

fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).expect("mkdir");
    for e in std::fs::read_dir(from).expect("read_dir") {
        let e = e.expect("entry");
        let (src, dst) = (e.path(), to.join(e.file_name()));
        // A link to a folder (`fixtures/twin`, the twin crate's own) is
        // copied as the folder: the copy has no crates beside it.
        if std::fs::metadata(&src).expect("type").is_dir() {
            copy_dir(&src, &dst);
        } else {
            std::fs::copy(&src, &dst).expect("copy");
        }
    }
}

/// Start a serving line, see it print its first endpoint, stop it with
/// SIGTERM: it must end with exit 0.
fn serve_and_stop(line: &Line, work: &Path) {
    let err_file = work.join(format!("serve-{}.stderr", line.number));
    let mut child = command()
        .current_dir(work)
        .args(&line.args)
        .stdout(Stdio::piped())
        .stderr(std::fs::File::create(&err_file).expect("stderr file"))
        .spawn()
        .expect("gyrobench starts");
    let mut first = String::new();
    // Kept open while it serves, as a terminal would be.
    let mut endpoints = std::io::BufReader::new(child.stdout.take().expect("stdout"));
    endpoints.read_line(&mut first).expect("stdout");
    let err = || std::fs::read_to_string(&err_file).unwrap_or_default();
    // `sim serve` prints its endpoints, `station` its URL.
    if !first.starts_with("chamber espec-ascii tcp://127.0.0.1:")
        && !first.starts_with("station http://127.0.0.1:")
    {
        let _killed = child.kill();
        let _reaped = child.wait();
        panic!(
            "README.md:{}: `{}` does not serve: {first:?} {}",
            line.number,
            line.text,
            err()
        );
    }
    let kill = std::process::Command::new("kill")
        .args(["-TERM", &child.id().to_string()])
        .status()
        .expect("kill runs");
    assert!(kill.success());
    let status = child.wait().expect("it ends");
    drop(endpoints);
    assert_eq!(
        status.code(),
        Some(0),
        "README.md:{}: `{}` stopped by SIGTERM: {}",
        line.number,
        line.text,
        err()
    );
}

/// Whether `status` is the exit code `want` as a shell reports it
/// (128 + N for a process killed by signal N).
fn exited(status: std::process::ExitStatus, want: i32) -> bool {
    use std::os::unix::process::ExitStatusExt;
    status.code() == Some(want) || status.signal().is_some_and(|s| 128 + s == want)
}

/// Whether a line is one of the diagnosis self-checks: each reads nothing
/// another line writes and writes only its own `--out`, so they run in a
/// test of their own beside the rest (a third of the README's time).
fn is_selfcheck(line: &Line) -> bool {
    line.args
        .starts_with(&["diagnose".to_owned(), "selfcheck".to_owned()])
}

/// Run `lines` in order in a fresh working directory named `tag` holding
/// copies of `procedures/` and `fixtures/`; the directory.
fn run_in_order(tag: &str, lines: &[&Line]) -> std::path::PathBuf {
    let work = temp_dir(tag);
    let _fresh = std::fs::remove_dir_all(&work);
    for dir in ["procedures", "fixtures"] {
        copy_dir(&Path::new(ROOT).join(dir), &work.join(dir));
    }
    for line in lines {
        // A line paced against the wall clock (`--speed`, the 2 kHz link
        // benchmark, a server) takes its turn alone; the rest (selfchecks,
        // runs at full speed) keep the cores busy beside other busy tests,
        // not beside a paced one. Each line takes its turn afresh.
        let paced = line.expect == Expect::Serves
            || line
                .args
                .iter()
                .any(|a| a == "--speed" || a == "link-bench");
        let (_wall, _busy) = if paced {
            (Some(crate::common::wall_clock_turn()), None)
        } else {
            (None, Some(crate::common::busy_turn()))
        };
        let started = std::time::Instant::now();
        match line.expect {
            Expect::NeedsHardware => continue,
            Expect::Serves => serve_and_stop(line, &work),
            Expect::Exit(want) => {
                // The README's store is its own: `--coeffs latest` and
                // `results verify` see the README's runs alone.
                let out = command()
                    .current_dir(&work)
                    .env("GYROBENCH_DB", work.join("results.sqlite"))
                    .args(&line.args)
                    .stdin(Stdio::null())
                    .output()
                    .expect("gyrobench runs");
                assert!(
                    exited(out.status, want),
                    "README.md:{}: `{}` ended with {} (want exit {want}): {}",
                    line.number,
                    line.text,
                    out.status,
                    stderr(&out)
                );
                if let Some(file) = &line.stdout_to {
                    std::fs::write(work.join(file), &out.stdout).expect("redirect");
                }
            }
        }
        eprintln!(
            "README.md:{} {:.1} s: {}",
            line.number,
            started.elapsed().as_secs_f64(),
            line.args.join(" ")
        );
    }
    work
}

#[test]
fn the_readme_commands_run_top_to_bottom_from_a_fresh_clone() {
    let lines = readme_lines();
    assert!(lines.len() >= 20, "{lines:#?}");
    assert_eq!(lines[0].args, ["run", "procedures/acceptance.toml"]);
    assert!(lines.iter().any(|l| l.expect == Expect::Serves));
    let rest: Vec<&Line> = lines.iter().filter(|l| !is_selfcheck(l)).collect();
    let work = run_in_order("readme", &rest);
    // What the commands wrote stayed in the working directory.
    for made in [
        "runs/smoke/run.mcap",
        "unit.toml",
        "my-twin.toml",
        "lab-run.mcap",
    ] {
        assert!(work.join(made).exists(), "{made}");
    }
    std::fs::remove_dir_all(&work).expect("cleanup");
}

#[test]
fn the_readme_selfchecks_run_in_order_from_a_fresh_clone() {
    let lines = readme_lines();
    let checks: Vec<&Line> = lines.iter().filter(|l| is_selfcheck(l)).collect();
    assert!(checks.len() >= 3, "{lines:#?}");
    let work = run_in_order("readme-selfchecks", &checks);
    for line in &checks {
        let out = line
            .args
            .windows(2)
            .find(|w| w[0] == "--out")
            .map(|w| w[1].clone())
            .unwrap_or_else(|| panic!("README.md:{}: a selfcheck names its --out", line.number));
        assert!(work.join(&out).is_dir(), "README.md:{}: {out}", line.number);
    }
    std::fs::remove_dir_all(&work).expect("cleanup");
}

#[test]
fn readme_lines_are_parsed_with_their_redirects_and_markers() {
    let l = parse_line(
        7,
        "cargo run --release -- twin default-config > my-twin.toml  # start from the default",
    );
    assert_eq!(l.args, ["twin", "default-config"]);
    assert_eq!(l.stdout_to.as_deref(), Some("my-twin.toml"));
    assert_eq!(l.expect, Expect::Exit(0));
    let l = parse_line(
        8,
        "cargo run --release -- run p.toml --inject process-kill@300   # killed (exit 137, SIGKILL)",
    );
    assert_eq!(l.expect, Expect::Exit(137));
    let l = parse_line(
        9,
        "cargo run --release -- sim serve --config f.toml &   # serves until Ctrl-C",
    );
    assert_eq!((l.args.len(), l.expect), (4, Expect::Serves));
    let l = parse_line(
        10,
        "cargo run --release -- run p.toml --bench my-lab.toml   # needs hardware",
    );
    assert_eq!(l.expect, Expect::NeedsHardware);
    // Every README line outside the sections the test runs parses too, and
    // each that cannot run here says why.
    let readme = std::fs::read_to_string(Path::new(ROOT).join("README.md")).expect("README.md");
    let bench = sections(&readme)
        .into_iter()
        .find(|(t, _)| t == "Running on a bench")
        .expect("Running on a bench");
    assert!(
        bench.1.iter().any(
            |l| l.args.contains(&"my-lab.toml".to_owned()) && l.expect == Expect::NeedsHardware
        )
    );
}
