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
    for (key, device) in [
        ("espec", "chamber"),
        ("acl", "table"),
        ("gyro", "gyro"),
        ("supply", "supply"),
    ] {
        let port = ports.get(key).and_then(toml::Value::as_integer).expect(key);
        assert!(
            text.contains(&format!("spec = \"tcp://127.0.0.1:{port}\"")),
            "{device} at port {port}"
        );
    }
    // The served unit is off until a run switches its supply on: the
    // bench file names that supply.
    let src = gyrobench::config::Source::from_text("sim-serve.toml", &text);
    let cfg = gyrobench::bench::BenchConfig::from_source(&src)
        .unwrap_or_else(|e| panic!("the served bench: {e}"));
    assert!(cfg.devices.supply.is_some(), "{text}");
}

/// The batch's served bench reads each unit on the gyro line its serve
/// file gives that slot, at its speed, every unit where the serve file
/// mounts it.
#[test]
fn the_served_batch_bench_reads_each_unit_on_the_line_its_fixture_serves() {
    let bench =
        gyrobench::bench::BenchConfig::load(&Path::new(ROOT).join("fixtures/bench/sim-quad.toml"))
            .expect("fixtures/bench/sim-quad.toml");
    let serve =
        gyrobench::sim::serve::Serve::load(Some(&Path::new(ROOT).join("fixtures/sim/quad.toml")))
            .expect("fixtures/sim/quad.toml");
    assert_eq!(bench.time_scale, serve.config.speed);
    assert_eq!(bench.slots.len(), serve.units.len());
    for (slot, unit) in bench.slots.iter().zip(&serve.units) {
        assert_eq!(slot.name, unit.name);
        assert_eq!(
            bench.slot_gyro_spec(slot),
            format!("tcp://127.0.0.1:{}", unit.port),
            "slot {}",
            slot.name
        );
        assert_eq!(
            bench.slot_geometry(slot).mount,
            unit.twin.table.geometry.mount,
            "slot {}",
            slot.name
        );
    }
    let p = serve.config.ports;
    assert_eq!(
        bench.devices.chamber.spec,
        format!("tcp://127.0.0.1:{}", p.espec)
    );
    assert_eq!(
        bench.devices.table.spec,
        format!("tcp://127.0.0.1:{}", p.acl)
    );
}

/// Every `docs/NAME.md` the code or the documentation cites is a file of
/// the project (not a note kept elsewhere).
#[test]
fn every_document_cited_exists() {
    let mut stack = vec![
        Path::new(ROOT).join("src"),
        Path::new(ROOT).join("crates"),
        Path::new(ROOT).join("docs"),
    ];
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

/// The rows of ARCHITECTURE.md's module table, bottom layer first: the
/// module paths each row names (`runlog::reader`, `protocol::espec`, ...).
fn layer_rows() -> Vec<Vec<String>> {
    read("ARCHITECTURE.md")
        .lines()
        // The module table (the crates' table above it is not a layer).
        .skip_while(|l| !l.starts_with("| module |"))
        .filter_map(|l| l.strip_prefix("| `"))
        .map(|l| {
            let cell = l.split('|').next().unwrap_or_default();
            format!("`{cell}")
                .split('`')
                .skip(1)
                .step_by(2)
                .filter(|name| {
                    name.chars()
                        .all(|c| c.is_alphanumeric() || c == '_' || c == ':')
                })
                .map(str::to_owned)
                .collect()
        })
        .collect()
}

/// The row of the deepest module path that `path` (`a::b::c`) lies in.
fn row_of(rows: &[Vec<String>], path: &str) -> Option<usize> {
    let mut parts: Vec<&str> = path.split("::").collect();
    while !parts.is_empty() {
        let key = parts.join("::");
        if let Some(i) = rows.iter().position(|r| r.contains(&key)) {
            return Some(i);
        }
        parts.pop();
    }
    None
}

/// Every path named after `crate::` in `code`, `crate::a::{b, c::d}`
/// read as `a::b` and `a::c::d`.
fn crate_paths(code: &str) -> Vec<String> {
    fn group(prefix: &str, text: &str, out: &mut Vec<String>) -> usize {
        // `text` starts after `{`: items up to the matching `}`.
        let (mut depth, mut start) = (0, 0);
        for (i, c) in text.char_indices() {
            match c {
                '{' => depth += 1,
                '}' if depth > 0 => depth -= 1,
                ',' | '}' if depth == 0 => {
                    item(prefix, &text[start..i], out);
                    start = i + 1;
                    if c == '}' {
                        return i + 1;
                    }
                }
                _ => {}
            }
        }
        text.len()
    }
    fn item(prefix: &str, text: &str, out: &mut Vec<String>) {
        let text = text.trim();
        let path: String = text
            .chars()
            .take_while(|c| c.is_alphanumeric() || *c == '_' || *c == ':')
            .collect();
        let rest = &text[path.len()..];
        let full = format!("{prefix}{path}");
        if let Some(inner) = rest.strip_prefix('{') {
            group(&full, inner, out);
        } else if path == "self" {
            out.push(prefix.trim_end_matches("::").to_owned());
        } else if !path.is_empty() {
            out.push(full.trim_end_matches("::").to_owned());
        }
    }
    let mut out = Vec::new();
    let mut rest = code;
    while let Some(at) = rest.find("crate::") {
        let after = &rest[at + "crate::".len()..];
        let path: String = after
            .chars()
            .take_while(|c| c.is_alphanumeric() || *c == '_' || *c == ':')
            .collect();
        let tail = &after[path.len()..];
        if let Some(inner) = tail.strip_prefix('{') {
            let used = group(&path, inner, &mut out);
            rest = &inner[used..];
        } else {
            out.push(path.trim_end_matches("::").to_owned());
            rest = tail;
        }
    }
    out
}

fn rust_files(dir: &Path, out: &mut Vec<std::path::PathBuf>) {
    for e in std::fs::read_dir(dir).expect("src") {
        let p = e.expect("entry").path();
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
}

#[test]
fn every_import_follows_the_layers_architecture_md_states() {
    let rows = layer_rows();
    assert!(rows.len() > 40, "{rows:?}");
    let src = Path::new(ROOT).join("src");
    let mut files = Vec::new();
    rust_files(&src, &mut files);
    let mut against = Vec::new();
    let mut unplaced = Vec::new();
    for file in &files {
        let rel = file.strip_prefix(&src).expect("under src");
        let name = rel
            .to_string_lossy()
            .trim_end_matches(".rs")
            .replace('/', "::");
        let module = name.trim_end_matches("::mod");
        // The crate root and the binary see every layer; tests may too.
        if matches!(module, "lib" | "main") || module.ends_with("tests") {
            continue;
        }
        let text = std::fs::read_to_string(file).expect("source");
        let Some(me) = row_of(&rows, module) else {
            // A parent that only declares its children needs no row.
            if text.contains("fn ") {
                unplaced.push(rel.display().to_string());
            }
            continue;
        };
        let code = text
            .split("#[cfg(test)]\nmod tests")
            .next()
            .unwrap_or_default();
        let code: String = code
            .lines()
            .map(|l| l.split("//").next().unwrap_or_default())
            .collect::<Vec<_>>()
            .join("\n");
        for path in crate_paths(&code) {
            if let Some(theirs) = row_of(&rows, &path)
                && theirs > me
            {
                against.push(format!(
                    "src/{}: `crate::{path}` (row `{}`) is above `{}`",
                    rel.display(),
                    rows[theirs][0],
                    rows[me][0]
                ));
            }
        }
    }
    assert!(
        unplaced.is_empty(),
        "modules with no row in ARCHITECTURE.md: {unplaced:?}"
    );
    against.sort();
    against.dedup();
    assert!(
        against.is_empty(),
        "imports against the layering ARCHITECTURE.md states:\n{}",
        against.join("\n")
    );
}

#[test]
fn crate_paths_reads_plain_and_grouped_imports() {
    let code =
        "use crate::a::b;\nuse crate::{c::d, e::{self, f, g::h}, i};\nlet x = crate::j::k(1);";
    assert_eq!(
        crate_paths(code),
        ["a::b", "c::d", "e", "e::f", "e::g::h", "i", "j::k"]
    );
}
