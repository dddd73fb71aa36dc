"""The official Python mcap reader opens a run's log and agrees with its report.

Usage: check_mcap.py RUN_DIR
Checks: the file opens and has a summary; every channel has a schema;
message counts match the summary statistics; the gyro frames logged match
the frame count the run reports; the run metadata is there; every step
starts and ends on /steps; the procedure and the report travel in the log
as attachments; the result record lists the report's measurements.
"""
import json
import os
import sys

from mcap.reader import make_reader

passed = 0
failed = 0


def check(name, ok, detail=""):
    global passed, failed
    print(("ok   " if ok else "FAIL ") + name + (f": {detail}" if detail else ""))
    if ok:
        passed += 1
    else:
        failed += 1


def main():
    run_dir = sys.argv[1]
    report = json.load(open(f"{run_dir}/report.json"))
    with open(f"{run_dir}/run.mcap", "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        check("the file has a summary", summary is not None)
        channels = summary.channels
        check("every channel has a schema", all(c.schema_id != 0 and c.schema_id in summary.schemas for c in channels.values()),
              str({c.topic: c.schema_id for c in channels.values()}))
        check("schemas are jsonschema", all(s.encoding == "jsonschema" for s in summary.schemas.values()))
        topics = {c.topic for c in channels.values()}
        for t in ["/gyro/frames", "/gyro/rate_1hz", "/chamber/state", "/table/state", "/events", "/gyro/link", "/steps"]:
            check(f"channel {t}", t in topics)
        counts = {}
        frames = 0
        steps = []
        for schema, channel, message in reader.iter_messages():
            counts[channel.topic] = counts.get(channel.topic, 0) + 1
            if channel.topic == "/gyro/frames":
                frames += len(json.loads(message.data)["counts"])
            if channel.topic == "/steps":
                steps.append(json.loads(message.data))
        starts = [s["index"] for s in steps if s["phase"] == "start"]
        ends = [s["index"] for s in steps if s["phase"] == "end"]
        check("every step starts once, in run order, and ends", starts == sorted(set(starts)) and starts == ends and len(starts) > 0,
              f"{len(starts)} starts, {len(ends)} ends")
        stats = summary.statistics
        check("message count matches the statistics", sum(counts.values()) == stats.message_count,
              f"{sum(counts.values())} vs {stats.message_count}")
        check("frames logged match the frames the run reports", frames == report["frames"],
              f"{frames} vs {report['frames']}")
        meta = {m.name: m.metadata for m in reader.iter_metadata()}
        run = meta.get("run", {})
        check("run metadata holds the procedure, bench, twin and start time",
              all(k in run for k in ["procedure_toml", "bench_toml", "twin_toml", "start_time_utc", "dut_serial", "software_version"]),
              str(sorted(run)))
        attachments = {a.name: a.data for a in reader.iter_attachments()}
        check("the procedure is attached as run", attachments.get("procedure.toml", b"").decode() == run.get("procedure_toml"))
        on_disk = open(f"{run_dir}/report.json", "rb").read()
        check("report.json is attached, as written", attachments.get("report.json") == on_disk)
        result = meta.get("result", {})
        listed = json.loads(result.get("measurements", "[]"))
        check("the result record lists every measurement with the report's values",
              [(m["name"], m["value"], m["outcome"]) for m in listed]
              == [(m["name"], m["value"], m["outcome"]) for m in report["measurements"]],
              f"{len(listed)} listed")
    per_frame = os.path.getsize(f"{run_dir}/run.mcap") / max(report["frames"], 1)
    check("at most 12 bytes a frame on disk", per_frame <= 12.0, f"{per_frame:.2f}")
    print(f"{passed} passed, {failed} failed")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
