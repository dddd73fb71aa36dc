//! The pages as a person gets them: loaded and printed by a real headless
//! Chromium (Debian's `chromium`, which `.ci/run` installs). Without one
//! the test says so and passes, except under CI, where it must run.

use std::path::{Path, PathBuf};
use std::process::Command;

use crate::cli::{gyrobench, temp_dir};
use crate::common::{MINI, s};

/// The browser: `$GYROBENCH_CHROMIUM`, else `chromium` on the PATH.
fn chromium() -> Option<PathBuf> {
    if let Some(p) = std::env::var_os("GYROBENCH_CHROMIUM") {
        return Some(PathBuf::from(p));
    }
    let found = std::env::var_os("PATH").and_then(|paths| {
        std::env::split_paths(&paths)
            .flat_map(|d| ["chromium", "chromium-browser"].map(|n| d.join(n)))
            .find(|p| p.is_file())
    });
    if found.is_none() {
        assert!(
            std::env::var_os("CI").is_none(),
            "CI must check the pages in Chromium: install chromium (apt-get install chromium)"
        );
        eprintln!("no chromium on the PATH: the pages were not checked in a browser");
    }
    found
}

fn headless(browser: &Path, args: &[&str], page: &Path) -> std::process::Output {
    Command::new(browser)
        .args([
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--no-first-run",
            "--hide-scrollbars",
        ])
        .args(args)
        .arg(format!("file://{}", page.display()))
        .output()
        .expect("chromium runs")
}

/// Width and height of each page of a PDF, in points.
fn media_boxes(pdf: &[u8]) -> Vec<(f64, f64)> {
    let text = String::from_utf8_lossy(pdf);
    text.split("/MediaBox [")
        .skip(1)
        .filter_map(|b| {
            let n: Vec<f64> = b
                .split(']')
                .next()?
                .split_whitespace()
                .filter_map(|v| v.parse().ok())
                .collect();
            (n.len() == 4).then(|| (n[2] - n[0], n[3] - n[1]))
        })
        .collect()
}

#[test]
fn report_html_loads_in_chromium_with_every_chart_and_prints_on_a4() {
    let _busy = crate::common::busy_turn();
    let Some(browser) = chromium() else {
        return;
    };
    let dir = temp_dir("pages");
    let proc_ = dir.join("mini.toml");
    std::fs::write(&proc_, MINI).expect("procedure");
    let run = dir.join("run");
    let out = gyrobench(&["run", s(&proc_), "--out", s(&run), "--db", "none"]);
    assert!(
        matches!(out.status.code(), Some(0 | 3)),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let page = run.join("report.html");

    // The DOM the browser built: every chart is an SVG figure, none fell
    // back to a note, and the verdict is the first thing on the page.
    let dom = headless(&browser, &["--dump-dom"], &page);
    let dom = String::from_utf8_lossy(&dom.stdout);
    let expected = std::fs::read_to_string(&page)
        .expect("report.html")
        .matches("<figure>")
        .count();
    assert!(expected >= 3, "{expected} charts in report.html");
    assert_eq!(dom.matches("<figure><svg").count(), expected, "{dom}");
    assert!(!dom.contains("not drawn"), "a chart failed to draw");
    // The embedded bench powers the unit throughout: nothing was switched
    // on, so there is no turn-on section.
    assert!(
        !dom.contains("Turn-ons"),
        "a turn-on section without turn-ons"
    );
    let body = dom.split("<body>").nth(1).expect("a body");
    assert!(
        body.trim_start().starts_with("<div class=\"verdict\""),
        "{}",
        &body[..body.len().min(200)]
    );

    // Printed: A4 portrait pages (the print style sheet's @page).
    let pdf = dir.join("report.pdf");
    let printed = headless(
        &browser,
        &[
            "--no-pdf-header-footer",
            &format!("--print-to-pdf={}", pdf.display()),
        ],
        &page,
    );
    assert!(
        pdf.is_file(),
        "{}",
        String::from_utf8_lossy(&printed.stderr)
    );
    let boxes = media_boxes(&std::fs::read(&pdf).expect("pdf"));
    assert!(!boxes.is_empty(), "no pages in the PDF");
    for (w, h) in &boxes {
        assert!(
            (w - 595.3).abs() < 2.0 && (h - 841.9).abs() < 2.0,
            "page of {w} x {h} pt, not A4 portrait"
        );
    }
    // Every printed page names the unit and the run, and which page of how
    // many it is (poppler's pdftotext reads the text as printed).
    let report = crate::common::json(&run.join("report.json"));
    let run_id = report["run_id"].as_str().expect("run id");
    match Command::new("pdftotext")
        .args(["-layout", s(&pdf), "-"])
        .output()
    {
        Ok(text) if text.status.success() => {
            let text = String::from_utf8_lossy(&text.stdout);
            let pages: Vec<&str> = text
                .split('\u{c}')
                .filter(|p| !p.trim().is_empty())
                .collect();
            assert_eq!(pages.len(), boxes.len(), "{text}");
            assert!(
                pages.len() >= 2,
                "a report of one page cannot show the margins repeat"
            );
            for (i, page) in pages.iter().enumerate() {
                for want in [
                    "RL-16 SIMULATED".to_owned(),
                    format!("run {}", &run_id[..12]),
                    format!("page {} of {}", i + 1, pages.len()),
                    format!("run id {run_id}"),
                ] {
                    assert!(
                        page.contains(&want),
                        "page {} lacks {want:?}:\n{page}",
                        i + 1
                    );
                }
            }
        }
        _ => assert!(
            std::env::var_os("CI").is_none(),
            "CI must read the printed pages: install poppler-utils (pdftotext)"
        ),
    }
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

/// A turn-on run's report, as Chromium builds it: a "Turn-ons" section
/// with the bias of each turn-on against the repeatability's band, every
/// warm-up curve overlaid, and the supply current with each turn-on's
/// peak, each an SVG figure.
#[test]
fn a_turn_on_report_draws_the_bias_per_turn_on_the_warm_ups_and_the_current() {
    let _busy = crate::common::busy_turn();
    let Some(browser) = chromium() else {
        return;
    };
    let dir = temp_dir("pages-turn-on");
    let procedure = crate::power::with_cycles(&dir, 3);
    let run = dir.join("run");
    // Three turn-ons judge the repeatability with a wide U: any verdict
    // (pass, fail, conditional) draws the page.
    let out = gyrobench(&["run", s(&procedure), "--out", s(&run), "--db", "none"]);
    assert!(
        matches!(out.status.code(), Some(0 | 3 | 4)),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let dom = headless(&browser, &["--dump-dom"], &run.join("report.html"));
    let dom = String::from_utf8_lossy(&dom.stdout);
    let section = dom
        .split("<h2>Turn-ons</h2>")
        .nth(1)
        .and_then(|s| s.split("<h2>").next())
        .expect("a Turn-ons section");
    assert_eq!(section.matches("<figure><svg").count(), 3, "{section}");
    for want in [
        "bias_repeatability_dph: ",
        "over 3 turn-ons",
        "bias_c1",
        "bias_c3",
        "Warm-up from each turn-on (100 s moving means)",
        "warmup_c1",
        "warmup_c2",
        "warmup_c3",
        "Supply current",
        "highest reading of each turn-on",
    ] {
        assert!(section.contains(want), "the section lacks {want:?}");
    }
    std::fs::remove_dir_all(&dir).expect("cleanup");
}
