"""Reads an MCAP file chassisd wrote with an independent reader (PyPI mcap) and checks it
against the recording it came from and what `chassisd replay --stamped` printed for it.

usage: check_export.py FILE.mcap RECORDING_DIR REPLAY_STAMPED_LINES [ZONES.geojson]

With ZONES, the first /zones message must carry that GeoJSON (compared as JSON).

Prints one JSON object: the channels (topic, schema, count) and what was compared. Exits 1
with the reason on the first check that fails.
"""

import base64
import json
import sys
import tomllib
from collections import defaultdict
from pathlib import Path

import jsonschema
from mcap.reader import make_reader

WELL_KNOWN = {
    "/gnss/fix": "foxglove.LocationFix",
    "/fused/fix": "foxglove.LocationFix",
    "/fused/pose": "foxglove.PoseInFrame",
    "/tf": "foxglove.FrameTransforms",
    "/zones": "foxglove.GeoJSON",
    "/events": "foxglove.Log",
    "/plan": "foxglove.PosesInFrame",
    "/status/base_status": "chassisd.BaseStatus",
    "/status/battery": "sensor_msgs/msg/BatteryState",
    "/status/diagnostics": "diagnostic_msgs/msg/DiagnosticArray",
}


def fail(why):
    print(f"check_export: {why}", file=sys.stderr)
    sys.exit(1)


def stamp_ns(line):
    """`(1700000000.123456) ...` -> ns."""
    sec, frac = line[1 : line.index(")")].split(".")
    return int(sec) * 1_000_000_000 + int(frac.ljust(6, "0")[:6]) * 1000


def recording_inputs(folder):
    """Per source: [(t_ns, kind, bytes-or-frame)], read from the files themselves."""
    meta = tomllib.loads((folder / "meta.toml").read_text())
    inputs = defaultdict(list)
    for s in meta["source"]:
        name, kind = s["name"], s["kind"]
        for line in (folder / s["file"]).read_text().splitlines():
            if not line.startswith("("):
                continue
            t = stamp_ns(line)
            rest = line[line.index(")") + 2 :].split(" ", 1)[1]
            if rest.startswith("!link-"):
                inputs[name + "/link"].append((t, rest[len("!link-") :]))
            elif kind == "serial":
                inputs[name].append((t, bytes.fromhex(rest)))
            elif kind == "can":
                frame = rest.split(" ")[0]
                inputs[name].append((t, (frame.upper(), rest.endswith(" T"))))
            else:
                topic, payload = rest.split("#", 1)
                inputs[name].append((t, bytes.fromhex(payload)))
        if s.get("events"):
            for line in (folder / s["events"]).read_text().splitlines():
                if line.startswith("("):
                    state = line.split("!link-")[1].strip()
                    inputs[name + "/link"].append((stamp_ns(line), state))
    return meta, inputs


def main():
    path, folder, replayed = Path(sys.argv[1]), Path(sys.argv[2]), Path(sys.argv[3])
    with path.open("rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        messages = defaultdict(list)
        validators = {}
        order_checked = 0
        for schema, channel, message in reader.iter_messages(log_time_order=False):
            if channel.message_encoding != "json" or schema.encoding != "jsonschema":
                fail(f"{channel.topic}: encodings {channel.message_encoding}/{schema.encoding}")
            want = WELL_KNOWN.get(channel.topic)
            if want and schema.name != want:
                fail(f"{channel.topic}: schema {schema.name}, not {want}")
            if schema.id not in validators:
                validators[schema.id] = jsonschema.Draft7Validator(json.loads(schema.data))
            body = json.loads(message.data)
            errors = list(validators[schema.id].iter_errors(body))
            if errors:
                fail(f"{channel.topic} message {message.sequence}: {errors[0].message}")
            got = messages[channel.topic]
            if got and message.log_time < got[-1][0]:
                fail(f"{channel.topic}: message {message.sequence} goes back in time")
            if got and message.sequence != got[-1][2] + 1:
                fail(f"{channel.topic}: sequence {message.sequence} after {got[-1][2]}")
            got.append((message.log_time, body, message.sequence))
            order_checked += 1

    # The summary's statistics against what was read.
    stats = summary.statistics
    counts = {summary.channels[c].topic: n for c, n in stats.channel_message_counts.items()}
    read = {topic: len(m) for topic, m in messages.items()}
    if counts != read:
        fail(f"statistics' channel counts {counts} differ from the messages read {read}")
    if stats.message_count != order_checked:
        fail(f"statistics say {stats.message_count} messages, {order_checked} were read")
    times = [t for m in messages.values() for t, _, _ in m]
    if (stats.message_start_time, stats.message_end_time) != (min(times), max(times)):
        fail("statistics' start and end are not the messages' first and last times")
    if stats.channel_count != len(summary.channels) or stats.schema_count != len(summary.schemas):
        fail("statistics' channel or schema count is wrong")

    # The raw frames against the recording's files.
    compared = {}
    if (folder / "meta.toml").exists():
        meta, inputs = recording_inputs(folder)
        for source, records in inputs.items():
            got = messages.get(f"/raw/{source}", [])
            if len(got) != len(records):
                fail(f"/raw/{source}: {len(got)} messages, the recording has {len(records)}")
            for (t, want), (logged, body, _) in zip(records, got):
                if logged != t or body["timestamp"] != {"sec": t // 10**9, "nsec": t % 10**9}:
                    fail(f"/raw/{source}: a message at {logged}, its record at {t}")
                if source.endswith("/link"):
                    same = body["state"] == want
                elif "data" in body and "interface" not in body:
                    same = base64.b64decode(body["data"]) == want
                elif "interface" in body:
                    same = (body["candump"], body["direction"] == "tx") == want
                else:
                    same = base64.b64decode(body["payload"]) == want
                if not same:
                    fail(f"/raw/{source} at {t}: {body} is not the recorded {want!r}")
            compared[source] = len(records)
        # Every /raw/ channel is one of the recording's sources.
        extra = [t for t in messages if t.startswith("/raw/") and not t.endswith("/nmea")
                 and t[len("/raw/"):] not in inputs]
        if extra:
            fail(f"channels without a source in the recording: {extra}")

    # Each status line's fix against the last receiver fix before it.
    fixes = messages.get("/gnss/fix", [])
    statuses = [json.loads(l) for l in replayed.read_text().splitlines()]
    matched = 0
    k = 0
    for status in statuses:
        t = round(status["stamp"] * 1e6) * 1000
        while k < len(fixes) and fixes[k][0] <= t:
            k += 1
        rtk = status["rtk"]
        if k == 0:
            if rtk["latitude"] != 0 or rtk["longitude"] != 0:
                fail(f"status at {t} has a position before any /gnss/fix")
            continue
        fix = fixes[k - 1][1]
        if (fix["latitude"], fix["longitude"]) != (rtk["latitude"], rtk["longitude"]):
            fail(f"status at {t}: rtk {rtk} is not the last /gnss/fix {fix}")
        matched += 1
    base = messages.get("/status/base_status", [])
    if len(base) != len(statuses):
        fail(f"{len(base)} base_status messages, replay printed {len(statuses)} lines")
    for (logged, body, _), status in zip(base, statuses):
        stamp = status.pop("stamp")
        if body != status or abs(logged / 1e9 - stamp) > 1e-6:
            fail(f"base_status at {logged} differs from replay's line at {stamp}")

    zones_compared = False
    if len(sys.argv) > 4:
        want = json.loads(Path(sys.argv[4]).read_text())
        got = messages.get("/zones", [])
        if not got or json.loads(got[0][1]["geojson"]) != want:
            fail(f"/zones does not carry {sys.argv[4]}")
        zones_compared = True

    print(json.dumps({
        "channels": {t: len(m) for t, m in sorted(messages.items())},
        "raw_sources_compared": compared,
        "statuses_with_a_fix_compared": matched,
        "chunks": stats.chunk_count,
        "zones_compared": zones_compared,
    }))


main()
