//! The import map's own tests: conversions, layouts, and every refusal with its place.

use super::*;

fn map(text: &str) -> Result<ImportMap, ConfigError> {
    from_source(Source::from_text("m.toml", text))
}

const TEMPS: &str = "[temperatures]\nt1 = \"a\"\nt2 = \"b\"\ntcase = \"c\"\nchamber = \"d\"\n";

fn with(rate: &str, rest: &str) -> String {
    format!(
        "[time]\ncolumn = \"t\"\nform = \"seconds\"\n\n[rate]\ncolumn = \"r\"\n{rate}\n\n{TEMPS}\n{rest}"
    )
}

const FIXED: &str = "[orientation]\nfixed = { azimuth_deg = 90.0, elevation_deg = 0.0, roll_deg = 0.0 }\n[step]\nboundaries = [{ from_s = 0.0, label = \"a\" }, { from_s = 2.0, label = \"b\" }]\n";

#[test]
fn every_rate_unit_is_converted_to_deg_per_hour() {
    let w = 7.292_115e-5_f64;
    for (unit, cell, want) in [
        ("unit = \"deg/h\"", "15.041", 15.041),
        ("unit = \"deg/s\"", "0.5", 1800.0),
        ("unit = \"rad/s\"", &format!("{w}"), w.to_degrees() * 3600.0),
        // 0.15 arcsec in 10 ms is 15 arcsec/s, 15 deg/h.
        ("unit = \"arcsec/sample\"\nsample_s = 0.01", "0.15", 15.0),
        (
            "unit = \"counts\"\nscale_arcsec = 0.05\nsample_s = 0.01",
            "3",
            15.0,
        ),
    ] {
        let m = map(&with(unit, FIXED)).unwrap_or_else(|e| panic!("{unit}: {e}"));
        let text = format!("t,r,a,b,c,d\n0.25,{cell},20,20,20,20\n");
        let got = m.parse(text.as_bytes(), "f.csv").expect("parses");
        assert!(
            (got.rows[0].rate_dph - want).abs() < 1e-9 * want.abs().max(1.0),
            "{unit}: {}",
            got.rows[0].rate_dph
        );
    }
}

#[test]
fn kelvin_dates_steps_and_poses_come_out_as_interchange_rows() {
    let text = "[file]\ndelimiter = \";\"\n[time]\ncolumn = 1\nform = \"datetime\"\n[rate]\ncolumn = \"r\"\nunit = \"deg/h\"\n[temperatures]\nunit = \"K\"\nt1 = \"a\"\nt2 = \"b\"\ntcase = \"c\"\nchamber = \"d\"\n[step]\ncolumn = \"s\"\n[orientation.by_step]\nup = { azimuth_deg = 0.0, elevation_deg = 90.0, roll_deg = 0.0 }\nnorth = { azimuth_deg = 0.0, elevation_deg = 0.0, roll_deg = 0.0 }\n";
    let m = map(text).expect("map");
    let csv = "when;r;a;b;c;d;s\n2026-03-02T08:00:00.5+07:00;12;293.15;294.15;295.15;296.15;up\n2026-03-02T01:00:01.5Z;9;293.15;293.15;293.15;293.15;north\n";
    let got = m.parse(csv.as_bytes(), "f.csv").expect("parses");
    assert_eq!(
        got.power_on_utc.as_deref(),
        Some("2026-03-02T01:00:00.500+00:00")
    );
    let r = &got.rows;
    assert_eq!(r.len(), 2);
    assert_eq!((r[0].time_s, r[1].time_s), (0.0, 1.0));
    assert!((r[0].t1_c - 20.0).abs() < 1e-9 && (r[0].chamber_c - 23.0).abs() < 1e-9);
    assert_eq!((r[0].elevation_deg, r[1].elevation_deg), (90.0, 0.0));
    assert_eq!(r[1].step, "north");
    // A step the map gives no pose is refused with its line.
    let bad = format!("{csv}2026-03-02T08:00:02.5+07:00;9;293.15;293.15;293.15;293.15;east\n");
    let e = m
        .parse(bad.as_bytes(), "f.csv")
        .expect_err("no pose")
        .to_string();
    assert!(e.starts_with("f.csv:4: step \"east\" has no pose"), "{e}");
}

#[test]
fn samples_finer_than_a_second_are_averaged_per_second_and_step() {
    let m = map(&with(
        "unit = \"counts\"\nscale_arcsec = 0.01\nsample_s = 0.01",
        FIXED,
    ))
    .expect("map");
    let mut csv = String::from("t,r,a,b,c,d\n");
    for k in 0..400 {
        // Alternating 10 and 20 counts: 15 counts of 0.01 arcsec per 10 ms.
        csv.push_str(&format!(
            "{},{},20,20,20,{}\n",
            k as f64 * 0.01,
            10 + 10 * (k % 2),
            k / 100
        ));
    }
    let got = m.parse(csv.as_bytes(), "f.csv").expect("parses");
    assert_eq!(got.samples, 400);
    let times: Vec<f64> = got.rows.iter().map(|r| r.time_s).collect();
    assert_eq!(times, [0.5, 1.5, 2.5, 3.5]);
    for (i, r) in got.rows.iter().enumerate() {
        assert!((r.rate_dph - 15.0).abs() < 1e-9, "{r:?}");
        assert_eq!(r.chamber_c, i as f64);
        assert_eq!(r.step, if i < 2 { "a" } else { "b" });
    }
}

#[test]
fn a_bad_map_or_cell_is_named_with_its_place() {
    for (text, want) in [
        (
            with("unit = \"counts\"\nsample_s = 0.01", FIXED),
            "m.toml:7:8: `rate.unit` is `counts`: give `scale_arcsec`",
        ),
        (
            with("unit = \"deg/s\"\nsample_s = 0.01", FIXED),
            "`rate.sample_s` is only for a rate per sample",
        ),
        (
            with(
                "unit = \"deg/s\"",
                "[step]\ncolumn = \"s\"\n[orientation]\n",
            ),
            "`orientation` needs exactly one of",
        ),
        (
            with(
                "unit = \"deg/s\"",
                "[orientation]\nfixed = { azimuth_deg = 0.0, elevation_deg = 95.0, roll_deg = 0.0 }\n[step]\ncolumn = \"s\"\n",
            ),
            "`orientation.fixed.elevation_deg`",
        ),
        (
            with("unit = \"deg/s\"\nearth_rate_included = false", FIXED),
            "`rate.earth_rate_included` must be true",
        ),
        (
            with(
                "unit = \"deg/s\"",
                "[orientation]\nfixed = { azimuth_deg = 0.0, elevation_deg = 0.0, roll_deg = 0.0 }\n[step]\nboundaries = [{ from_s = 5.0, label = \"a\" }, { from_s = 2.0, label = \"b\" }]\n",
            ),
            "`step.boundaries.1.from_s` must be after",
        ),
    ] {
        let e = map(&text).expect_err(want).to_string();
        assert!(e.contains(want), "{e}");
    }
    let m = map(&with("unit = \"deg/s\"", FIXED)).expect("map");
    for (csv, want) in [
        (
            "t,r,a,b,c\n",
            "m.toml:13:11: `temperatures.chamber` names column \"d\", which f.csv's header does not have (its columns: t, r, a, b, c)",
        ),
        (
            "t,r,a,b,c,d\n0,1,20,20,20,20\n1,x,20,20,20,20\n",
            "f.csv:3: column \"r\" (rate): \"x\" is not a number",
        ),
        (
            "t,r,a,b,c,d\n0,1,20,20,20,20\n0,1,20,20,20,20\n",
            "f.csv:3: field time_s: 0 does not follow 0",
        ),
        (
            "t,r,a,b,c,d\n0,1,20,20,20,900\n",
            "f.csv:2: field chamber_c: 900 is outside",
        ),
        ("t,r,a,b,c,d\n", "f.csv:2: no samples"),
    ] {
        let e = m
            .parse(csv.as_bytes(), "f.csv")
            .expect_err(want)
            .to_string();
        assert!(e.starts_with(want), "{e}");
    }
}

/// One column given two roles is refused at the second role's line,
/// naming the column and both roles, whether named or numbered.
#[test]
fn one_column_in_two_roles_is_refused_naming_both() {
    let twice = with("unit = \"deg/s\"", FIXED).replace("t2 = \"b\"", "t2 = \"a\"");
    let m = map(&twice).expect("the map alone cannot tell");
    let e = m
        .parse("t,r,a,b,c,d\n0,1,20,20,20,20\n".as_bytes(), "f.csv")
        .expect_err("two roles")
        .to_string();
    assert!(
        e.starts_with("m.toml:11:6: `temperatures.t2` names column \"a\" of f.csv, which `temperatures.t1` already reads"),
        "{e}"
    );
    // By number: column 2 is "r", the rate's.
    let numbered = with("unit = \"deg/s\"", FIXED).replace("chamber = \"d\"", "chamber = 2");
    let m = map(&numbered).expect("map");
    let e = m
        .parse("t,r,a,b,c,d\n0,1,20,20,20,20\n".as_bytes(), "f.csv")
        .expect_err("two roles")
        .to_string();
    assert!(
        e.contains(
            "`temperatures.chamber` names column \"r\" of f.csv, which `rate.column` already reads"
        ),
        "{e}"
    );
}

/// A time scale that crowds the samples into one second is refused with
/// the map's line: out of range at once, or by the data it makes.
#[test]
fn a_scale_that_collapses_the_samples_is_refused_with_its_line() {
    let scaled = |k: &str| {
        with("unit = \"deg/s\"", FIXED).replace(
            "form = \"seconds\"\n",
            &format!("form = \"seconds\"\nscale_s = {k}\n"),
        )
    };
    let e = map(&scaled("1e-300")).expect_err("absurd").to_string();
    assert!(
        e.starts_with("m.toml:4:11: `time.scale_s` is 1e-300 s per unit of the time column"),
        "{e}"
    );
    // Microseconds read from a column of 1 kHz sample numbers: 12,000
    // samples within 12 ms.
    let m = map(&scaled("1e-6")).expect("in range");
    let mut csv = String::from("t,r,a,b,c,d\n");
    for k in 0..12_000 {
        csv.push_str(&format!("{k},1,20,20,20,20\n"));
    }
    let e = m
        .parse(csv.as_bytes(), "f.csv")
        .expect_err("collapsed")
        .to_string();
    assert!(
        e.starts_with(
            "f.csv:10002: more than 10000 samples fall within one second (0 to 1 s since power-on)"
        ),
        "{e}"
    );
    assert!(
        e.contains("column \"t\" read as 1e-6 s per unit (`time.scale_s`, m.toml:4:11)"),
        "{e}"
    );
    // The right scale (1 ms) reads the same file as 12 one-second means.
    let got = map(&scaled("0.001"))
        .expect("map")
        .parse(csv.as_bytes(), "f.csv")
        .expect("reads");
    assert_eq!((got.samples, got.rows.len()), (12_000, 12));
}

/// A power-on far from the data is said with both times and the data's
/// first, never as a number that is not finite.
#[test]
fn a_power_on_far_from_the_data_is_named_with_the_first_time() {
    let dated = |power_on: &str| {
        format!(
            "[time]\ncolumn = \"t\"\nform = \"datetime\"\n{power_on}\n[rate]\ncolumn = \"r\"\nunit = \"deg/h\"\n\n{TEMPS}\n{FIXED}"
        )
    };
    let csv =
        "t,r,a,b,c,d\n2026-03-02T08:00:00Z,1,20,20,20,20\n2026-03-02T08:00:01Z,1,20,20,20,20\n";
    for (power_on, want) in [
        (
            "power_on = \"1700-01-01T00:00:00Z\"",
            "f.csv:2: column \"t\" (time): 2026-03-02T08:00:00+00:00 is more than 290 years after the power-on 1700-01-01T00:00:00+00:00 (`time.power_on`, m.toml:4:12); the data's first time is 2026-03-02T08:00:00+00:00",
        ),
        (
            "power_on = \"2025-03-02T08:00:00Z\"",
            "is 365 days after the power-on 2025-03-02T08:00:00+00:00",
        ),
        (
            "power_on = \"2026-03-05T08:00:00Z\"",
            "is 3 days before the power-on 2026-03-05T08:00:00+00:00",
        ),
    ] {
        let e = map(&dated(power_on))
            .expect("map")
            .parse(csv.as_bytes(), "f.csv")
            .expect_err(power_on)
            .to_string();
        assert!(e.contains(want), "{e}");
        assert!(!e.contains("NaN") && !e.contains("finite"), "{e}");
    }
    // No power-on given: the first row stands for it.
    let late = format!("{csv}2026-09-30T08:00:00Z,1,20,20,20,20\n");
    let e = map(&dated(""))
        .expect("map")
        .parse(late.as_bytes(), "f.csv")
        .expect_err("a year apart")
        .to_string();
    assert!(
        e.starts_with("f.csv:4: column \"t\" (time): 2026-09-30T08:00:00+00:00 is 212 days after the data's first time 2026-03-02T08:00:00+00:00, which stands for the power-on"),
        "{e}"
    );
}

proptest::proptest! {
    /// Arbitrary text under a good map: rows or an error, never a panic.
    #[test]
    fn arbitrary_input_never_panics(bytes in proptest::collection::vec(proptest::num::u8::ANY, 0..2000)) {
        if let Ok(m) = map(&with("unit = \"counts\"\nscale_arcsec = 0.01\nsample_s = 0.01", FIXED)) {
            let _ = m.parse(bytes.as_slice(), "fuzz.csv");
            let mut text = b"t,r,a,b,c,d\n".to_vec();
            text.extend_from_slice(&bytes);
            let _ = m.parse(text.as_slice(), "fuzz.csv");
        }
    }
}
