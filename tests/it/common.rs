//! Helpers and procedures several whole-system tests share.

use std::path::Path;

/// A path as the `&str` a command line takes.
pub fn s(p: &Path) -> &str {
    p.to_str().expect("utf-8 path")
}

/// A JSON file, parsed.
pub fn json(p: &Path) -> serde_json::Value {
    let text = std::fs::read_to_string(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
    serde_json::from_str(&text).expect("JSON")
}

/// A short procedure with every metric, a repeat (steps sharing keys) and
/// a temperature ramp, so compensation has something to fit.
pub const MINI: &str = r#"
[procedure]
name = "mini"
description = "every metric in an hour of device time"
dut_type = "RL-16"
spec = "test"

[[setup]]
action = "chamber"
set_c = 20.0
ramp_c_per_min = 1.0

[[main]]
action = "record"
label = "warm"
duration_s = 1800.0

[[main]]
action = "repeat"
positions = [
  { label = "up", table = { outer_deg = 90.0, inner_deg = 0.0 } },
  { label = "east", table = { outer_deg = 0.0, inner_deg = 0.0 } },
]

[[main.steps]]
action = "record"
label = "{label}"
duration_s = 120.0

[[main.steps]]
action = "measure"
name = "bias_dph:{label}"
metric = "mean_bias"
records = ["{label}"]
low = -5.0
high = 5.0
unit = "deg/h"

[[main]]
action = "move"
table = { outer_deg = 90.0, inner_deg = 0.0 }

[[main]]
action = "chamber"
set_c = 30.0
ramp_c_per_min = 1.0

[[main]]
action = "record"
label = "ramp"
duration_s = 1200.0

[[main]]
action = "measure"
name = "self_heating_dph"
metric = "self_heating"
records = ["warm"]
high = 1.0
unit = "deg/h"

[[main]]
action = "measure"
name = "stability"
metric = "bias_stability"
records = ["up"]
averaging_s = 10.0
high = 0.2
unit = "deg/h"

[[main]]
action = "measure"
name = "raw"
metric = "drift_pp"
records = ["warm", "ramp"]
averaging_s = 600.0
high = 1.0
unit = "deg/h"

[[main]]
action = "measure"
name = "compensated"
metric = "compensated_drift_pp"
records = ["warm", "ramp"]
averaging_s = 600.0
high = 0.1
unit = "deg/h"

[[cleanup]]
action = "chamber"
set_c = 20.0
ramp_c_per_min = 2.0
"#;

/// A run of a few minutes of device time: a chamber step, two short
/// records, a measure each and a cleanup move.
pub const TINY: &str = r#"
[procedure]
name = "tiny"
description = "two 60 s records"
dut_type = "RL-16"
spec = "test"

[[setup]]
action = "chamber"
set_c = 20.0
ramp_c_per_min = 1.0

[[main]]
action = "repeat"
positions = [
  { label = "up", table = { outer_deg = 90.0, inner_deg = 0.0 } },
  { label = "east", table = { outer_deg = 0.0, inner_deg = 0.0 } },
]

[[main.steps]]
action = "record"
label = "{label}"
duration_s = 60.0

[[main.steps]]
action = "measure"
name = "bias_dph:{label}"
metric = "mean_bias"
records = ["{label}"]
low = -5.0
high = 5.0
unit = "deg/h"

[[cleanup]]
action = "move"
table = { outer_deg = 90.0, inner_deg = 0.0 }
"#;

/// Write `text` to `dir/name` and return the path.
pub fn write(dir: &Path, name: &str, text: &str) -> std::path::PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
    p
}

/// stderr of a finished command, as text.
pub fn stderr(o: &std::process::Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}
