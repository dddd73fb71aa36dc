//! The log crate alone writes a log that it reads back whole, keeps the
//! first write failure, and recovers what a failed run left on the disk:
//! no bench controller in the build.

#![expect(
    clippy::expect_used,
    reason = "a test that cannot write its temporary files fails"
)]

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use gyrobench_log::schema::{
    PROCEDURE_ATTACHMENT, REPORT_ATTACHMENT, RESULT_META, RUN_META, Rate1Hz, slot_topic, topics,
};
use gyrobench_log::{Item, LogWriter, Opening, read, recover::recover, refusing};

/// A path of its own under the temporary directory (removed first).
fn temp(name: &str) -> PathBuf {
    let p = std::env::temp_dir().join(format!(
        "gyrobench-log-write-{}-{name}.mcap",
        std::process::id()
    ));
    let _ = std::fs::remove_file(&p);
    p
}

fn second(t_s: f64) -> Rate1Hz {
    Rate1Hz {
        t_s,
        rate_dph: 9.1 + t_s * 1e-3,
        reference_dph: 9.0,
        bias_dph: 0.1 + t_s * 1e-3,
        t1_c: 20.0,
        t2_c: 20.5,
        tcase_c: 21.0,
        chamber_c: 19.0,
        frames: 2000,
        record: Some("bias".into()),
    }
}

fn entries(pairs: &[(&str, &str)]) -> BTreeMap<String, String> {
    pairs
        .iter()
        .map(|(k, v)| ((*k).to_owned(), (*v).to_owned()))
        .collect()
}

fn opening(slots: &[&str]) -> Opening<'static> {
    Opening {
        library: "gyrobench-log test".into(),
        run: entries(&[("dut_serial", "RL16-0007"), ("format", "3")]),
        procedure_toml: "[procedure]\nname = \"written\"\n",
        slots: slots.iter().map(|s| (*s).to_owned()).collect(),
        start_ns: 1_700_000_000_000_000_000,
    }
}

/// Everything a log holds, as read back: metadata records, attachments
/// (name, bytes), and the 1 Hz messages per topic.
#[derive(Debug, Default)]
struct Held {
    meta: BTreeMap<String, BTreeMap<String, String>>,
    attachments: BTreeMap<String, Vec<u8>>,
    seconds: BTreeMap<String, Vec<Rate1Hz>>,
    log_times: Vec<u64>,
}

fn held(path: &Path) -> (Held, gyrobench_log::ReadSummary) {
    let mut h = Held::default();
    let summary = read(
        path,
        refusing(|item| {
            match item {
                Item::Meta { name, entries } => {
                    h.meta.insert(name.to_owned(), entries.clone());
                }
                Item::Attachment { name, data, .. } => {
                    h.attachments.insert(name.to_owned(), data.to_vec());
                }
                Item::Message {
                    topic,
                    data,
                    log_time_ns,
                    ..
                } => {
                    let s: Rate1Hz = serde_json::from_slice(data).map_err(|e| e.to_string())?;
                    h.seconds.entry(topic.to_owned()).or_default().push(s);
                    h.log_times.push(log_time_ns);
                }
            }
            Ok::<(), String>(())
        }),
    )
    .expect("the log reads");
    (h, summary)
}

#[test]
fn a_log_written_message_by_message_reads_back_whole_with_its_records() {
    let path = temp("whole");
    let o = opening(&["b"]);
    let mut w = LogWriter::create(&path, &o).expect("created");
    let b = slot_topic("b", topics::RATE_1HZ);
    for t in [1.0, 2.0, 3.0] {
        w.write(topics::RATE_1HZ, t, &second(t)).expect("written");
    }
    w.write(&b, 1.0, &second(1.0)).expect("the slot's topic");
    let wrong = w.write("/no/such/topic", 4.0, &second(4.0));
    assert_eq!(
        wrong
            .expect_err("a topic the log has no channel for")
            .kind(),
        std::io::ErrorKind::InvalidInput
    );
    w.unit_result(
        "b",
        entries(&[("outcome", "pass")]),
        "report-b.json".into(),
        "{\"b\": 1}",
        3.0,
    )
    .expect("the slot's result");
    let written = w
        .finish(entries(&[("outcome", "fail")]), Some("{}"), 3.0)
        .expect("finished");
    assert_eq!(
        written.messages,
        BTreeMap::from([(topics::RATE_1HZ.to_owned(), 3), (b.clone(), 1)])
    );
    assert!(
        LogWriter::create(&path, &o).is_err(),
        "a log is never overwritten"
    );

    let (h, summary) = held(&path);
    std::fs::remove_file(&path).expect("cleanup");
    assert!(summary.complete && summary.bytes_lost == 0, "{summary:?}");
    assert_eq!(h.meta[RUN_META], o.run);
    assert_eq!(h.meta[RESULT_META], entries(&[("outcome", "fail")]));
    assert_eq!(
        h.meta[&format!("{RESULT_META}/b")],
        entries(&[("outcome", "pass")])
    );
    assert_eq!(
        h.attachments[PROCEDURE_ATTACHMENT],
        o.procedure_toml.as_bytes()
    );
    assert_eq!(h.attachments[REPORT_ATTACHMENT], b"{}");
    assert_eq!(h.attachments["report-b.json"], b"{\"b\": 1}");
    assert_eq!(
        h.seconds[topics::RATE_1HZ],
        [second(1.0), second(2.0), second(3.0)]
    );
    assert_eq!(h.seconds[&b], [second(1.0)]);
    assert_eq!(h.log_times[0], o.start_ns + 1_000_000_000);
}

#[test]
fn the_first_failure_sticks_and_nothing_after_it_is_written() {
    let path = temp("failed");
    let mut w = LogWriter::create(&path, &opening(&[])).expect("created");
    w.fail_from(150.0, "writing it: No space left on device".into());
    for t in (0..=120).step_by(30) {
        w.write(topics::RATE_1HZ, f64::from(t), &second(f64::from(t)))
            .expect("before the disk is full");
    }
    for t in [150.0, 151.0] {
        let e = w
            .write(topics::RATE_1HZ, t, &second(t))
            .expect_err("the disk is full");
        assert_eq!(e.to_string(), "writing it: No space left on device");
    }
    assert_eq!(w.failure(), Some("writing it: No space left on device"));
    let e = w
        .finish(entries(&[("outcome", "pass")]), Some("{}"), 151.0)
        .expect_err("a log whose disk filled does not end");
    assert_eq!(e.to_string(), "writing it: No space left on device");

    let (h, _) = held(&path);
    std::fs::remove_file(&path).expect("cleanup");
    assert!(!h.meta.contains_key(RESULT_META), "{:?}", h.meta.keys());
    assert!(!h.attachments.contains_key(REPORT_ATTACHMENT));
    let kept: Vec<f64> = h.seconds[topics::RATE_1HZ].iter().map(|s| s.t_s).collect();
    assert_eq!(kept, [0.0, 30.0, 60.0, 90.0, 120.0]);
}

#[test]
fn a_log_cut_short_is_recovered_to_its_last_whole_chunk() {
    // A chunk is closed every minute of device time: ten minutes of
    // seconds are ten chunks and more, most of them whole after a cut.
    let path = temp("cut");
    let mut w = LogWriter::create(&path, &opening(&[])).expect("created");
    for t in 0..600 {
        w.write(topics::RATE_1HZ, f64::from(t), &second(f64::from(t)))
            .expect("written");
    }
    w.finish(entries(&[("outcome", "pass")]), None, 600.0)
        .expect("finished");
    let (whole, _) = held(&path);
    let bytes = std::fs::read(&path).expect("the log");
    std::fs::write(&path, &bytes[..bytes.len() / 2]).expect("cut");

    let out = temp("recovered");
    let file = std::fs::File::create(&out).expect("the output");
    let r = recover(&path, file, &out, "gyrobench-log test (recovered)").expect("recovered");
    let (back, summary) = held(&out);
    for p in [&path, &out] {
        std::fs::remove_file(p).expect("cleanup");
    }
    assert!(summary.complete, "the recovered log ends: {summary:?}");
    assert!(!r.was_complete && r.bytes_lost > 0, "{r:?}");
    let kept = &back.seconds[topics::RATE_1HZ];
    assert!(
        kept.len() > 100 && kept.len() < 600,
        "{} seconds of 600",
        kept.len()
    );
    assert_eq!(r.messages, kept.len() as u64);
    assert_eq!(
        kept[..],
        whole.seconds[topics::RATE_1HZ][..kept.len()],
        "what is recovered is what was written"
    );
    assert_eq!(back.meta[RUN_META], whole.meta[RUN_META]);
    assert_eq!(
        back.attachments[PROCEDURE_ATTACHMENT],
        whole.attachments[PROCEDURE_ATTACHMENT]
    );
}
