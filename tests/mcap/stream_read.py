"""Reads an MCAP file front to back with a streaming reader (PyPI mcap's StreamReader), as
one reads a file whose writer was killed: every record up to where the file ends. Prints one
JSON object: the messages read per topic, the last log time, and how the file ended.

usage: stream_read.py FILE.mcap
"""

import base64
import json
import sys
from collections import Counter

from mcap.records import Channel, Footer, Message
from mcap.stream_reader import StreamReader


def main():
    channels = {}
    counts = Counter()
    serial = {}
    last = 0
    ended = "footer"
    try:
        with open(sys.argv[1], "rb") as f:
            saw_footer = False
            for record in StreamReader(f, skip_magic=False).records:
                if isinstance(record, Channel):
                    channels[record.id] = record.topic
                elif isinstance(record, Message):
                    topic = channels[record.channel_id]
                    body = json.loads(record.data)
                    counts[topic] += 1
                    last = max(last, record.log_time)
                    if "data" in body and topic.count("/") == 2:
                        serial.setdefault(topic, bytearray()).extend(base64.b64decode(body["data"]))
                elif isinstance(record, Footer):
                    saw_footer = True
            if not saw_footer:
                ended = "no footer"
    except Exception as e:  # the cut: a record begun and not finished
        ended = f"cut: {type(e).__name__}"
    print(json.dumps({
        "messages": dict(counts),
        "last_log_time": last,
        "ended": ended,
        "serial_bytes": {t: b.hex() for t, b in serial.items()},
    }))


main()
