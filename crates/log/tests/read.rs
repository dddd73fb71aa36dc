//! The log crate alone reads a log gyrobench wrote (the first format's,
//! kept in the repository's fixtures): no bench controller in the build.

#![expect(
    clippy::expect_used,
    reason = "a test that cannot read its fixture fails"
)]

use std::path::{Path, PathBuf};

use gyrobench_log::schema::{RUN_META, Rate1Hz, topics};
use gyrobench_log::{Item, Stop, read};

fn fixture() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/logs/format1/whole/run.mcap")
}

/// The seconds of a log, decoded with the crate's own message types, and
/// whether its run metadata was there.
fn seconds(path: &Path) -> (Vec<Rate1Hz>, bool, gyrobench_log::ReadSummary) {
    let (mut out, mut meta) = (Vec::new(), false);
    let summary = read(
        path,
        gyrobench_log::refusing(|item| {
            match item {
                Item::Meta { name, entries } if name == RUN_META => {
                    meta = entries.contains_key("procedure_toml");
                }
                Item::Message { topic, data, .. } if topic == topics::RATE_1HZ => {
                    out.push(serde_json::from_slice(data).map_err(|e| e.to_string())?);
                }
                _ => {}
            }
            Ok::<(), String>(())
        }),
    )
    .expect("the log reads");
    (out, meta, summary)
}

#[test]
fn a_whole_log_reads_to_its_end_with_its_metadata_and_every_second() {
    let (s, meta, summary) = seconds(&fixture());
    assert!(summary.complete && summary.bytes_lost == 0, "{summary:?}");
    assert!(meta, "the run metadata holds its procedure");
    assert!(s.len() > 100, "{} seconds", s.len());
    assert!(s.windows(2).all(|w| w[1].t_s > w[0].t_s), "in time order");
}

#[test]
fn a_log_cut_short_reads_to_its_last_whole_chunk_and_says_what_was_lost() {
    // Cut as a killed run leaves its file: its summary and footer lost
    // (every chunk whole), or cut inside a chunk (that chunk's seconds
    // lost). Either way what is read is what was written, up to the cut.
    let bytes = std::fs::read(fixture()).expect("fixture");
    let (whole, _, _) = seconds(&fixture());
    let mut lost_seconds = false;
    for keep in [bytes.len() - 2000, bytes.len() / 2] {
        let cut = std::env::temp_dir().join(format!(
            "gyrobench-log-cut-{}-{keep}.mcap",
            std::process::id()
        ));
        std::fs::write(&cut, &bytes[..keep]).expect("a cut copy");
        let (part, meta, summary) = seconds(&cut);
        std::fs::remove_file(&cut).expect("cleanup");
        assert!(
            !summary.complete && summary.bytes_lost > 0,
            "{keep}: {summary:?}"
        );
        assert!(meta, "{keep}: the metadata comes first");
        assert!(
            part.len() <= whole.len(),
            "{keep}: {} of {}",
            part.len(),
            whole.len()
        );
        assert_eq!(
            part[..],
            whole[..part.len()],
            "{keep}: what was read is what was written"
        );
        lost_seconds |= part.len() < whole.len();
    }
    assert!(
        lost_seconds,
        "a cut inside a chunk loses that chunk's seconds"
    );
}

#[test]
fn a_sink_stops_the_read_when_it_has_enough_or_refuses_the_log() {
    use std::ops::ControlFlow;
    let path = fixture();
    // Enough after ten seconds: the rest unread, nothing said lost.
    let mut seen = 0;
    let summary = read(&path, |item| {
        if let Item::Message { topic, .. } = item
            && topic == topics::RATE_1HZ
        {
            seen += 1;
            if seen == 10 {
                return ControlFlow::Break(Stop::Enough);
            }
        }
        ControlFlow::Continue(())
    })
    .expect("the log reads");
    assert_eq!(seen, 10);
    assert!(
        !summary.complete && summary.stopped.is_none() && summary.bytes_lost == 0,
        "{summary:?}"
    );
    // Refused at the run record: said as the read's stop.
    let summary = read(&path, |item| match item {
        Item::Meta { name, .. } if name == RUN_META => {
            ControlFlow::Break(Stop::Refused("not this bench's".into()))
        }
        _ => ControlFlow::Continue(()),
    })
    .expect("the log reads");
    assert_eq!(summary.stopped.as_deref(), Some("not this bench's"));
    assert!(!summary.complete && summary.messages == 0, "{summary:?}");
}
