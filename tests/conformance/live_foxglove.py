"""A third-party Foxglove WebSocket client against gyrobench's live stream.

Speaks the Foxglove WebSocket protocol v1 with the `websockets` package (no
gyrobench code). The protocol's subprotocol name was `foxglove.websocket.v1`;
the official SDK's server now negotiates the same protocol as
`foxglove.sdk.v1`, so the client offers both, as Foxglove does. It takes the server's advertised channels, subscribes to all of them,
and receives messages while a run goes on. Then checks, against the run's
own MCAP read with the `mcap` package, that

- every channel the log has is advertised, with the log's schema name,
  schema encoding, JSON Schema and message encoding;
- every message received decodes as JSON, validates against its channel's
  JSON Schema (the `jsonschema` package), and is a message of the log:
  same topic, same log time, same bytes;
- the run's gyro frames, 1 Hz rate, chamber, table, event and step topics
  all arrived live.

    live_foxglove.py run GYROBENCH WORKDIR       # gyrobench run --live
    live_foxglove.py batch GYROBENCH WORKDIR     # a batch of two units (quad.toml)
    live_foxglove.py station BASE_URL TOKEN      # a station's runs

In batch mode the second unit's topics (`/slots/B/...`) must arrive live
too, each advertised with its single-unit topic's schema.

Exit 0 when all holds, else 1 with what did not.
"""

import asyncio
import json
import re
import struct
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

import jsonschema
import websockets
from mcap.reader import make_reader

# The same wire protocol under its current and its former name.
SUBPROTOCOLS = ["foxglove.sdk.v1", "foxglove.websocket.v1"]
LIVE_TOPICS = [
    "/gyro/frames",
    "/gyro/rate_1hz",
    "/chamber/state",
    "/table/state",
    "/events",
    "/steps",
]


class Collected:
    def __init__(self):
        self.channels = {}  # id -> advertised channel
        self.server_info = None
        self.messages = []  # (topic, log_time, bytes)


async def listen(url, got, done):
    """Subscribe to every advertised channel; collect until `done` is set
    or the server closes the connection."""
    async with websockets.connect(url, subprotocols=SUBPROTOCOLS, max_size=None) as ws:
        if ws.subprotocol not in SUBPROTOCOLS:
            raise AssertionError(f"server chose subprotocol {ws.subprotocol!r}")
        subs = {}
        while not done.is_set():
            try:
                raw = await asyncio.wait_for(ws.recv(), timeout=0.2)
            except asyncio.TimeoutError:
                continue
            except websockets.ConnectionClosed:
                return
            if isinstance(raw, str):
                msg = json.loads(raw)
                if msg["op"] == "serverInfo":
                    got.server_info = msg
                elif msg["op"] == "advertise":
                    new = []
                    for ch in msg["channels"]:
                        got.channels[ch["id"]] = ch
                        sub = len(subs) + 1
                        subs[sub] = ch
                        new.append({"id": sub, "channelId": ch["id"]})
                    await ws.send(json.dumps({"op": "subscribe", "subscriptions": new}))
                continue
            if raw[0] != 0x01:  # only message data is expected
                continue
            sub, log_time = struct.unpack_from("<IQ", raw, 1)
            got.messages.append((subs[sub]["topic"], log_time, bytes(raw[13:])))


BATCH_TOPICS = ["/slots/B/gyro/frames", "/slots/B/gyro/rate_1hz", "/slots/B/table/state"]


def check(got, log_path, live_topics=LIVE_TOPICS):
    problems = []
    if got.server_info is None:
        problems.append("no serverInfo")
    with open(log_path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        logged = {}
        for schema, channel, message in reader.iter_messages():
            logged[(channel.topic, message.log_time, bytes(message.data))] = True
    log_channels = {
        c.topic: (c, summary.schemas[c.schema_id]) for c in summary.channels.values()
    }
    advertised = {c["topic"]: c for c in got.channels.values()}
    validators = {}
    for topic, (channel, schema) in log_channels.items():
        a = advertised.get(topic)
        if a is None:
            problems.append(f"{topic} is in the log but was not advertised")
            continue
        want = {
            "encoding": channel.message_encoding,
            "schemaName": schema.name,
            "schemaEncoding": schema.encoding,
            "schema": schema.data.decode(),
        }
        for k, v in want.items():
            if a.get(k) != v:
                problems.append(f"{topic}: advertised {k} {a.get(k)!r}, the log has {v!r}")
        js = json.loads(a["schema"])
        validators[topic] = jsonschema.validators.validator_for(js)(js)
    counts = {}
    for topic, log_time, data in got.messages:
        counts[topic] = counts.get(topic, 0) + 1
        try:
            value = json.loads(data)
        except ValueError as e:
            problems.append(f"{topic} at {log_time}: not JSON ({e})")
            continue
        v = validators.get(topic)
        if v is not None:
            errors = list(v.iter_errors(value))
            if errors:
                problems.append(f"{topic} at {log_time}: {errors[0].message}")
        if (topic, log_time, data) not in logged:
            problems.append(f"{topic} at {log_time}: received live but not in the log")
    for topic in live_topics:
        if counts.get(topic, 0) == 0:
            problems.append(f"no {topic} message arrived live")
    print(
        f"{len(got.channels)} channels advertised; received live: "
        + ", ".join(f"{t} {n}" for t, n in sorted(counts.items()))
        + f"; {len(logged)} messages in the log"
    )
    return problems[:20]


async def run_mode(gyrobench, workdir, batch=False):
    root = Path(__file__).parents[2]
    out = Path(workdir) / ("live-batch" if batch else "live-run")
    units = ["--dut", "LIVE-0001"]
    if batch:
        units = ["--bench", str(root / "fixtures/bench/quad.toml"),
                 "--dut", "A=LIVE-0011", "--dut", "B=LIVE-0012"]
    proc = await asyncio.create_subprocess_exec(
        gyrobench, "run", str(root / "procedures/smoke.toml"),
        "--live", "127.0.0.1:0", "--speed", "60", "--out", str(out), "--db", "none",
        *units,
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
    )
    url = None
    seen = []
    while url is None:
        line = await asyncio.wait_for(proc.stderr.readline(), timeout=60)
        if not line:
            raise AssertionError("gyrobench ended before saying its live URL:\n" + "".join(seen))
        seen.append(line.decode())
        m = re.match(r"live: (ws://\S+)", line.decode())
        if m:
            url = m.group(1)
    got = Collected()
    done = asyncio.Event()
    listener = asyncio.create_task(listen(url, got, done))
    rest = asyncio.create_task(proc.stderr.read())
    code = await asyncio.wait_for(proc.wait(), timeout=120)
    done.set()
    await listener
    if code != 0:
        raise AssertionError(f"gyrobench run --live exited {code}: {(await rest).decode()}")
    return check(got, out / "run.mcap", LIVE_TOPICS + (BATCH_TOPICS if batch else []))


def api(base, token, method, path, body=None):
    req = urllib.request.Request(
        base + path,
        method=method,
        data=None if body is None else json.dumps(body).encode(),
        headers={"X-Gyrobench-Token": token, "Content-Type": "application/json"},
    )
    with urllib.request.urlopen(req, timeout=10) as r:
        return json.loads(r.read() or b"null")


async def station_mode(base, token):
    state = api(base, token, "GET", "/api/state")
    url = state.get("live_url")
    if not url:
        raise AssertionError(f"the station says no live URL: {state}")
    got = Collected()
    done = asyncio.Event()
    listener = asyncio.create_task(listen(url, got, done))
    await asyncio.sleep(0.5)  # advertised and subscribed before the start
    number = api(base, token, "POST", "/api/start",
                 {"procedure": "smoke.toml", "serial": "LIVE-0002", "operator": "fox"})["run"]
    deadline = time.monotonic() + 120
    while True:
        run = (await asyncio.to_thread(api, base, token, "GET", "/api/state"))["run"]
        if run and run["number"] == number and run["phase"] == "finished":
            break
        if run and run.get("prompt"):
            await asyncio.to_thread(api, base, token, "POST", "/api/answer", {"id": run["prompt"]["id"]})
        if time.monotonic() > deadline:
            raise AssertionError(f"the station's run did not finish within 120 s: {run}")
        await asyncio.sleep(0.2)
    await asyncio.sleep(0.5)  # the last messages in flight
    done.set()
    await listener
    if run["outcome"] != "pass":
        raise AssertionError(f"the station's run ended {run['outcome']}: {run.get('error')}")
    return check(got, Path(run["dir"]) / "run.mcap")


def main():
    if len(sys.argv) == 4 and sys.argv[1] in ("run", "batch"):
        problems = asyncio.run(run_mode(sys.argv[2], sys.argv[3], sys.argv[1] == "batch"))
    elif len(sys.argv) == 4 and sys.argv[1] == "station":
        problems = asyncio.run(station_mode(sys.argv[2], sys.argv[3]))
    else:
        sys.exit(__doc__)
    for p in problems:
        print("FAIL:", p)
    sys.exit(1 if problems else 0)


if __name__ == "__main__":
    main()
