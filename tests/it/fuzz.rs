//! Hostile input never crashes or hangs gyrobench: property-based fuzzing
//! of everything that reads a file from outside. Logs (a current and a
//! first-format one) are mutated (bytes, record lengths, chunk sizes,
//! truncation) and read, replayed, recovered and exported; the procedure,
//! bench, twin, site and sim serve loaders get spliced text and extreme
//! numbers, and what they accept is used (a twin simulated, a layout
//! decoded, a procedure estimated). Each case must end in a value or an
//! error, never a panic or an abort.
//!
//! The budget is proptest's: `PROPTEST_CASES` (default 64 per property
//! here; CI runs more in release). Inputs that once crashed are kept in
//! `fixtures/bad/` with the error they must give (`bad_input.rs`).

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use gyrobench::bench::BenchConfig;
use gyrobench::config::Source;
use gyrobench::procedure::Procedure;
use gyrobench::protocol::frame::Decoder;
use gyrobench::runlog::exchange::{export, site_from_source};
use gyrobench::runlog::recover::recover;
use gyrobench::runlog::replay::{record_rates, replay};
use gyrobench::sim::serve::Serve;
use gyrobench::twin::{Twin, TwinConfig};
use proptest::prelude::*;

use crate::cli::{gyrobench, temp_dir};
use crate::common::{TINY, s, write};

fn cases() -> ProptestConfig {
    let n = std::env::var("PROPTEST_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(64);
    ProptestConfig::with_cases(n)
}

fn manifest(p: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(p)
}

/// A small log of the current format, made once per test process.
fn current_log() -> &'static [u8] {
    static LOG: OnceLock<Vec<u8>> = OnceLock::new();
    LOG.get_or_init(|| {
        let dir = temp_dir("fuzz-log");
        let p = write(&dir, "tiny.toml", TINY);
        let out = dir.join("run");
        let _ = std::fs::remove_dir_all(&out);
        let r = gyrobench(&["run", s(&p), "--out", s(&out)]);
        assert_eq!(r.status.code(), Some(0), "the log to mutate");
        std::fs::read(out.join("run.mcap")).expect("log")
    })
}

fn format1_log() -> &'static [u8] {
    static LOG: OnceLock<Vec<u8>> = OnceLock::new();
    LOG.get_or_init(|| {
        std::fs::read(manifest("fixtures/logs/format1/whole/run.mcap")).expect("fixture")
    })
}

/// Offsets of the top-level records (opcode byte) of an MCAP file.
fn records(bytes: &[u8]) -> Vec<(usize, u8)> {
    let mut out = Vec::new();
    let mut at = 8;
    while at + 9 <= bytes.len() {
        let len = u64::from_le_bytes(bytes[at + 1..at + 9].try_into().expect("8 bytes"));
        out.push((at, bytes[at]));
        match (at as u64).checked_add(9 + len) {
            Some(end) if end <= bytes.len() as u64 => at = end as usize,
            _ => break,
        }
    }
    out
}

const EXTREME_LENGTHS: [u64; 6] = [u64::MAX, u64::MAX - 8, 1 << 63, 1 << 40, u32::MAX as u64, 0];

#[derive(Debug, Clone)]
enum Mutation {
    /// Set bytes at (relative position, value).
    Bytes(Vec<(f64, u8)>),
    /// Overwrite the length of the k-th record.
    Length(usize, u64),
    /// Overwrite a chunk's uncompressed size (k-th chunk).
    ChunkSize(usize, u64),
    /// Keep the first fraction of the file.
    Truncate(f64),
}

fn mutation() -> impl Strategy<Value = Mutation> {
    prop_oneof![
        prop::collection::vec((0.0f64..1.0, any::<u8>()), 1..16).prop_map(Mutation::Bytes),
        (
            any::<usize>(),
            prop::sample::select(EXTREME_LENGTHS.to_vec())
        )
            .prop_map(|(k, v)| Mutation::Length(k, v)),
        (
            any::<usize>(),
            prop::sample::select(EXTREME_LENGTHS.to_vec())
        )
            .prop_map(|(k, v)| Mutation::ChunkSize(k, v)),
        (0.0f64..1.0).prop_map(Mutation::Truncate),
    ]
}

fn mutate(log: &[u8], m: &Mutation) -> Vec<u8> {
    let mut b = log.to_vec();
    let recs = records(log);
    match m {
        Mutation::Bytes(v) => {
            for (at, val) in v {
                let i = ((*at * b.len() as f64) as usize).min(b.len() - 1);
                b[i] = *val;
            }
        }
        Mutation::Length(k, v) => {
            let (at, _) = recs[k % recs.len()];
            b[at + 1..at + 9].copy_from_slice(&v.to_le_bytes());
        }
        Mutation::ChunkSize(k, v) => {
            let chunks: Vec<usize> = recs
                .iter()
                .filter(|(_, op)| *op == 0x06)
                .map(|(at, _)| *at)
                .collect();
            if let Some(at) = chunks.get(k % chunks.len().max(1)) {
                let field = at + 9 + 16;
                b[field..field + 8].copy_from_slice(&v.to_le_bytes());
            }
        }
        Mutation::Truncate(f) => b.truncate((f * b.len() as f64) as usize),
    }
    b
}

/// Every reader of logs on `bytes`: each returns, none panics.
fn read_everything(dir: &Path, bytes: &[u8]) {
    let log = dir.join("fuzzed.mcap");
    std::fs::write(&log, bytes).expect("write the case");
    let _ = gyrobench::runlog::read(&log, |_| std::ops::ControlFlow::Continue(()));
    let _ = replay(&log, None);
    let _ = record_rates(&log, None);
    let out = dir.join("recovered.mcap");
    let _ = std::fs::remove_file(&out);
    if recover(&log, &out).is_ok() {
        // What recover writes must read back whole.
        let r = gyrobench::runlog::read(&out, |_| std::ops::ControlFlow::Continue(()))
            .expect("a recovered log reads");
        assert!(r.complete, "a recovered log is complete");
        let _ = replay(&out, None);
    }
    let csv = dir.join("fuzzed.csv");
    let _ = std::fs::remove_file(&csv);
    let _ = export(&log, &csv);
    let _ = gyrobench::diagnose::data::load(&log);
}

fn case_dir(tag: &str) -> PathBuf {
    let d = temp_dir(&format!("fuzz-{tag}"));
    std::fs::create_dir_all(&d).expect("dir");
    d
}

proptest! {
    #![proptest_config(cases())]

    #[test]
    fn mutated_logs_are_read_replayed_recovered_and_exported_without_a_panic(
        m in mutation(),
        first_format in any::<bool>(),
    ) {
        let log = if first_format { format1_log() } else { current_log() };
        let dir = case_dir("log");
        read_everything(&dir, &mutate(log, &m));
    }
}

/// Numbers a hostile file might hold.
const EXTREMES: [&str; 14] = [
    "1e308",
    "-1e308",
    "nan",
    "inf",
    "-inf",
    "0",
    "-0.0",
    "1e-300",
    "9223372036854775807",
    "-9223372036854775808",
    "-1",
    "1e12",
    "4294967296",
    "65536",
];

/// Replace the k-th number literal of `text` with `with`.
fn replace_number(text: &str, k: usize, with: &str) -> String {
    let bytes = text.as_bytes();
    let mut spans = Vec::new();
    let mut i = 0;
    while i < bytes.len() {
        let starts = bytes[i].is_ascii_digit()
            && (i == 0 || !(bytes[i - 1].is_ascii_alphanumeric() || bytes[i - 1] == b'_'));
        if starts {
            let j = i + bytes[i..]
                .iter()
                .take_while(|c| c.is_ascii_digit() || matches!(c, b'.' | b'e' | b'E' | b'-' | b'+'))
                .count();
            let j = if j < bytes.len() && bytes[j].is_ascii_alphabetic() {
                i + 1
            } else {
                j
            };
            spans.push((i, j));
            i = j.max(i + 1);
        } else {
            i += 1;
        }
    }
    match spans.get(k % spans.len().max(1)) {
        Some(&(a, b)) => format!("{}{with}{}", &text[..a], &text[b..]),
        None => text.to_owned(),
    }
}

#[derive(Debug, Clone)]
enum TextMutation {
    Splice(usize, String),
    Number(usize, &'static str),
}

fn text_mutation() -> impl Strategy<Value = TextMutation> {
    prop_oneof![
        (any::<usize>(), "\\PC{0,40}").prop_map(|(at, t)| TextMutation::Splice(at, t)),
        (any::<usize>(), prop::sample::select(EXTREMES.to_vec()))
            .prop_map(|(k, v)| TextMutation::Number(k, v)),
    ]
}

fn apply(text: &str, m: &TextMutation) -> String {
    match m {
        TextMutation::Splice(at, t) => {
            let mut s = text.to_owned();
            let mut i = at % (s.len() + 1);
            while !s.is_char_boundary(i) {
                i -= 1;
            }
            s.insert_str(i, t);
            s
        }
        TextMutation::Number(k, v) => replace_number(text, *k, v),
    }
}

fn text_of(p: &str) -> String {
    std::fs::read_to_string(manifest(p)).expect("fixture")
}

proptest! {
    #![proptest_config(cases())]

    #[test]
    fn mutated_procedures_load_or_are_refused_with_a_line(
        m in text_mutation(),
        which in prop::sample::select(vec!["procedures/acceptance.toml", "procedures/smoke.toml"]),
    ) {
        let text = apply(&text_of(which), &m);
        match Procedure::from_source(&Source::from_text("fuzz.toml", &text), &BenchConfig::embedded().procedure_limits()) {
            Ok(p) => {
                let _ = gyrobench::procedure::estimate::estimate(&p, &BenchConfig::embedded().procedure_limits());
            }
            Err(e) => prop_assert!(e.line().is_some(), "{e}"),
        }
    }

    #[test]
    fn mutated_benches_load_and_their_layouts_decode(
        m in text_mutation(),
        which in prop::sample::select(vec![
            "fixtures/bench/embedded.toml",
            "fixtures/bench/lab-espec-serial.toml",
            "fixtures/bench/lab-watlow-tcp.toml",
        ]),
        bytes in prop::collection::vec(any::<u8>(), 0..256),
    ) {
        let text = apply(&text_of(which), &m);
        match BenchConfig::from_source(&Source::from_text("fuzz.toml", &text)) {
            Ok(b) => {
                let mut d = Decoder::new(b.frame_layout());
                d.push(&bytes);
                while d.next_event().is_some() {}
                let _ = Procedure::from_source(
                    &Source::from_text("smoke.toml", &text_of("procedures/smoke.toml")),
                    &b.procedure_limits(),
                );
            }
            Err(e) => prop_assert!(e.line().is_some(), "{e}"),
        }
    }

    #[test]
    fn mutated_twins_load_and_what_loads_simulates(m in text_mutation()) {
        let text = apply(&text_of("fixtures/twin/rl16.toml"), &m);
        match TwinConfig::from_source(&Source::from_text("fuzz.toml", &text)) {
            Ok(cfg) => {
                let mut t = Twin::new(cfg, 1);
                t.run_until(5.0, |_, _| {});
            }
            Err(e) => prop_assert!(e.line().is_some(), "{e}"),
        }
    }

    #[test]
    fn mutated_site_and_serve_files_load_or_are_refused(m in text_mutation()) {
        let site = "[site]\nlatitude_deg = 50.45\nlongitude_deg = 30.52\nheight_m = 180.0\nmagnetic_field_ned_ut = [19.5, 2.7, 46.5]\n";
        if let Err(e) = site_from_source(&Source::from_text("site.toml", &apply(site, &m))) {
            prop_assert!(e.line().is_some(), "{e}");
        }
        let serve = apply(&text_of("fixtures/sim/serve.toml"), &m);
        let base = manifest("fixtures/sim");
        match Serve::from_source(&Source::from_text("serve.toml", &serve), &base) {
            Ok(sv) => {
                let mut d = Decoder::new(sv.layout.clone());
                d.push(&[0xA5, 0x5A, 1, 2, 3]);
                while d.next_event().is_some() {}
            }
            Err(e) => prop_assert!(e.line().is_some(), "{e}"),
        }
    }
}
