//! The documentation is true: what it says of the shipped files holds.

use std::path::Path;

const ROOT: &str = env!("CARGO_MANIFEST_DIR");

/// Every dotted key path of a TOML table (`devices.gyro.spec`, ...),
/// inline tables included; arrays are values.
fn keys(table: &toml::Table, prefix: &str, out: &mut Vec<String>) {
    for (k, v) in table {
        let path = if prefix.is_empty() {
            k.clone()
        } else {
            format!("{prefix}.{k}")
        };
        match v {
            toml::Value::Table(t) => keys(t, &path, out),
            _ => out.push(path),
        }
    }
}

fn read(rel: &str) -> String {
    let p = Path::new(ROOT).join(rel);
    std::fs::read_to_string(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

#[test]
fn every_key_of_the_shipped_bench_files_is_in_docs_bench_md() {
    let doc = read("docs/bench.md");
    let dir = Path::new(ROOT).join("fixtures/bench");
    let mut files: Vec<_> = std::fs::read_dir(&dir)
        .expect("fixtures/bench")
        .map(|e| e.expect("entry").path())
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    files.sort();
    assert!(files.len() >= 4, "{files:?}");
    for f in files {
        let table: toml::Table = std::fs::read_to_string(&f)
            .expect("bench file")
            .parse()
            .unwrap_or_else(|e| panic!("{}: {e}", f.display()));
        let mut all = Vec::new();
        keys(&table, "", &mut all);
        for k in all {
            // Documented by its own name (`spec`) in its table's section.
            let leaf = k.rsplit('.').next().unwrap_or(&k);
            assert!(
                doc.contains(&format!("`{leaf}`")),
                "{}: `{k}` is not in docs/bench.md",
                f.display()
            );
        }
    }
    // time_scale: its own section, its default and what it must equal.
    let section = doc
        .split("### ")
        .find(|s| s.starts_with("`time_scale`"))
        .expect("a time_scale section in docs/bench.md");
    assert!(
        section.contains("default 1") && section.contains("`speed`"),
        "{section}"
    );
}

#[test]
fn the_served_bench_file_runs_at_the_speed_of_the_serve_configuration() {
    let bench: toml::Table = read("fixtures/bench/sim-serve.toml").parse().expect("TOML");
    let serve: toml::Table = read("fixtures/sim/serve.toml").parse().expect("TOML");
    assert_eq!(
        bench.get("time_scale").and_then(toml::Value::as_float),
        serve.get("speed").and_then(toml::Value::as_float),
        "time_scale of fixtures/bench/sim-serve.toml must be the speed of fixtures/sim/serve.toml"
    );
    // And its devices are the ports that configuration serves.
    let text = read("fixtures/bench/sim-serve.toml");
    let ports = serve
        .get("ports")
        .and_then(toml::Value::as_table)
        .expect("[ports]");
    for (key, device) in [("espec", "chamber"), ("acl", "table"), ("gyro", "gyro")] {
        let port = ports.get(key).and_then(toml::Value::as_integer).expect(key);
        assert!(
            text.contains(&format!("spec = \"tcp://127.0.0.1:{port}\"")),
            "{device} at port {port}"
        );
    }
}

/// Every `docs/NAME.md` the code or the documentation cites is a file of
/// the project (not a note kept elsewhere).
#[test]
fn every_document_cited_exists() {
    let mut stack = vec![Path::new(ROOT).join("src"), Path::new(ROOT).join("docs")];
    let mut files = vec![
        Path::new(ROOT).join("README.md"),
        Path::new(ROOT).join("ARCHITECTURE.md"),
    ];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).expect("dir") {
            let p = e.expect("entry").path();
            if p.is_dir() {
                stack.push(p);
            } else if p.extension().is_some_and(|x| x == "rs" || x == "md") {
                files.push(p);
            }
        }
    }
    let mut cited = 0;
    for f in files {
        let text = std::fs::read_to_string(&f).expect("text");
        for (i, _) in text.match_indices("docs/") {
            let name: String = text[i + 5..]
                .chars()
                .take_while(|c| c.is_ascii_alphanumeric() || *c == '_' || *c == '-')
                .collect();
            if text[i + 5 + name.len()..].starts_with(".md") {
                cited += 1;
                let doc = Path::new(ROOT).join("docs").join(format!("{name}.md"));
                assert!(
                    doc.is_file(),
                    "{} cites docs/{name}.md, which does not exist",
                    f.display()
                );
            }
        }
    }
    assert!(cited > 20, "{cited} citations found");
}
