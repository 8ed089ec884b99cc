#!/usr/bin/env python3
"""Hostile DDS peers for the ROS 2 node's tests (tests/suite/ros2_node.rs). Run inside the
test's own network namespace: everything goes to 127.0.0.1 and the loopback multicast group.

    hostile.py participants N --seconds S   N Cyclone DDS participants on the domain, each with
                                            a reader and a writer, held S seconds
    hostile.py garbage N                    N malformed RTPS datagrams to the domain's ports:
                                            random bytes, an RTPS header with random
                                            submessages, and DATA_FRAGs to the participant
                                            discovery reader announcing a sample of up to 4 GiB

ROS_DOMAIN_ID (or --domain) selects the domain. Prints one JSON line with what it did.
"""

import argparse
import json
import os
import random
import socket
import struct
import sys
import time

# RTPS's port mapping (DDSI-RTPS 9.6.1.1): base, domain gain, participant gain, offsets.
PB, DG, PG, D0, D1, D2, D3 = 7400, 250, 2, 0, 10, 1, 11
MULTICAST = "239.255.0.1"
# The built-in participant discovery (SPDP) writer and reader entity ids.
SPDP_WRITER, SPDP_READER = 0x000100C2, 0x000100C7
DATA_FRAG = 0x16


def ports(domain):
    """Every port a participant of `domain` may listen on (participant ids 0 to 9)."""
    found = [(MULTICAST, PB + DG * domain + D0), (MULTICAST, PB + DG * domain + D2)]
    for pid in range(10):
        found.append(("127.0.0.1", PB + DG * domain + D1 + PG * pid))
        found.append(("127.0.0.1", PB + DG * domain + D3 + PG * pid))
    return found


def rtps_header(rng):
    return b"RTPS" + bytes([2, 3]) + b"\x01\x0f" + rng.randbytes(12)


def huge_fragment(rng):
    """A DATA_FRAG to the discovery reader announcing a sample of up to 4 GiB, of which it
    carries one fragment."""
    size = rng.choice([0xFFFFFFFF, 0xF0000000, 1 << 30, 200 << 20])
    fragment = b"\x00\x03\x00\x00" + rng.randbytes(1020)
    body = struct.pack("<HHII", 0, 28, SPDP_READER, SPDP_WRITER)
    body += struct.pack("<iI", 0, rng.randrange(1, 1 << 20))  # sequence number
    body += struct.pack("<IHHI", rng.randrange(1, 64), 1, len(fragment), size)
    body += fragment  # the first fragment: PL_CDR_LE encapsulation, then bytes
    return rtps_header(rng) + struct.pack("<BBH", DATA_FRAG, 0x01, len(body)) + body


def random_submessages(rng):
    out = rtps_header(rng)
    for _ in range(rng.randrange(1, 6)):
        body = rng.randbytes(rng.randrange(0, 200))
        length = rng.choice([len(body), rng.randrange(0, 65536)])
        out += struct.pack("<BBH", rng.randrange(256), rng.randrange(256), length) + body
    return out


def garbage(args):
    rng = random.Random(7)
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_IF, socket.inet_aton("127.0.0.1"))
    targets = ports(args.domain)
    kinds = {"random": 0, "submessages": 0, "huge_fragment": 0}
    for n in range(args.count):
        kind = ("random", "submessages", "huge_fragment")[n % 3]
        packet = {"random": lambda: rng.randbytes(rng.randrange(1, 1500)),
                  "submessages": lambda: random_submessages(rng),
                  "huge_fragment": lambda: huge_fragment(rng)}[kind]()
        for target in targets:
            try:
                sock.sendto(packet, target)
            except OSError:
                pass
        kinds[kind] += 1
        if n % 200 == 199:
            time.sleep(0.01)  # a bounded flood: the kernel's buffers, not the test, set the pace
    print(json.dumps({"sent": kinds, "ports": len(targets)}), flush=True)


def participants(args):
    from cyclonedds.domain import DomainParticipant
    from cyclonedds.idl import IdlStruct
    from cyclonedds.idl.types import float64
    from cyclonedds.pub import DataWriter
    from cyclonedds.sub import DataReader
    from cyclonedds.topic import Topic
    from dataclasses import dataclass

    @dataclass
    class Vector3(IdlStruct, typename="geometry_msgs::msg::dds_::Vector3_"):
        x: float64
        y: float64
        z: float64

    held = []
    for _ in range(args.count):
        dp = DomainParticipant(args.domain)
        topic = Topic(dp, "rt/hostile_vector", Vector3)
        held.append((dp, DataReader(dp, topic), DataWriter(dp, topic)))
    print(json.dumps({"participants": len(held)}), flush=True)
    time.sleep(args.seconds)


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--domain", type=int, default=int(os.environ.get("ROS_DOMAIN_ID", "0")))
    sub = p.add_subparsers(dest="command", required=True)
    a = sub.add_parser("participants")
    a.add_argument("count", type=int)
    a.add_argument("--seconds", type=float, default=10.0)
    g = sub.add_parser("garbage")
    g.add_argument("count", type=int)
    args = p.parse_args()
    {"participants": participants, "garbage": garbage}[args.command](args)


if __name__ == "__main__":
    sys.exit(main())
