#!/usr/bin/env python3
"""An independent ROS 2 peer for the ROS 2 interop tests of tests/suite (issue 52).

    peer.py listen   --topic /odom --type nav_msgs/msg/Odometry --seconds S
                     [--reliable|--best-effort] [--transient-local] [--depth N] [--count N]
    peer.py publish  --topic /cmd_vel --type geometry_msgs/msg/Twist --json '{"linear":{"x":0.3}}'
                     --rate HZ --seconds S [--count N] [--reliable|--best-effort]
                     [--transient-local] [--wait-match S] [--stamp-now] [--pad-frame-id N]
    peer.py navigate --x X --y Y [--yaw RAD] [--frame map] [--cancel-after S] [--seconds S]
                     [--mapping cyclone]

It is the side of those tests that is not ours: the Eclipse Cyclone DDS Python binding (PyPI
cyclonedds, whose wheel bundles the C library) speaking ROS 2's DDS conventions as a ROS 2
node on rmw_cyclonedds would: topics `rt/<name>`, services `rq/<name>Request` and
`rr/<name>Reply`, type names `pkg::msg::dds_::Type_`, XCDR1 (plain CDR) data representation,
rcl's default QoS. The message classes are built at run time from the type definitions of
PyPI rosbags (ROS2_JAZZY store, plus nav2_msgs' NavigateToPose as Jazzy and Kilted define it),
so any standard type works. Every sample received is decoded by cyclonedds, serialised again
by rosbags and compared byte for byte with what came over the wire (`bytes_match_rosbags`;
up to 3 zero bytes of trailing padding are no difference).

Output: one JSON object per line on stdout, per event, flushed. Non-finite floats are written
as the strings "NaN", "Infinity", "-Infinity". Exit 0 on success; 2 on a usage error; 3 when
nothing matched or answered in time, with the reason on stderr. ROS_DOMAIN_ID (or --domain)
selects the domain. Run it inside a network namespace of its own (see tests/suite): DDS
discovery multicasts.
"""

import argparse
import json
import math
import os
import sys
import time
import types
import uuid
from dataclasses import dataclass

import numpy as np
from cyclonedds._clayer import ddspy_take
from cyclonedds.core import InstanceState, Policy, Qos, ReadCondition, SampleState, ViewState, WaitSet
from cyclonedds.domain import DomainParticipant
from cyclonedds.idl import IdlStruct
from cyclonedds.idl import types as idl
from cyclonedds.pub import DataWriter
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from cyclonedds.util import duration
from rosbags.interfaces import Nodetype
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

BASE, NAME, ARRAY, SEQ = Nodetype.BASE, Nodetype.NAME, Nodetype.ARRAY, Nodetype.SEQUENCE
ANY = SampleState.Any | ViewState.Any | InstanceState.Any
_NUMBERS = ["int8", "uint8", "int16", "uint16", "int32", "uint32", "int64", "uint64", "float32", "float64"]
NUMPY = {"bool": np.bool_, "byte": np.uint8, "char": np.uint8, **{t: getattr(np, t) for t in _NUMBERS}}
CYCLONE = {"bool": bool, "byte": idl.uint8, "char": idl.uint8, "string": str,
           **{t: getattr(idl, t) for t in _NUMBERS}}

# --- Types: rosbags' definitions, with nav2_msgs/action/NavigateToPose (Jazzy, Kilted) added --
TS = get_typestore(Stores.ROS2_JAZZY)
ACTION = "nav2_msgs/action/NavigateToPose"
_NAV2 = {
    "Goal": "geometry_msgs/PoseStamped pose\nstring behavior_tree\n",
    "Result": "uint16 NONE=0\nuint16 error_code\nstring error_msg\n",
    "Feedback": "geometry_msgs/PoseStamped current_pose\nbuiltin_interfaces/Duration navigation_time\n"
                "builtin_interfaces/Duration estimated_time_remaining\nint16 number_of_recoveries\n"
                "float32 distance_remaining\n",
}
_defs = {}
for _part, _text in _NAV2.items():
    _defs.update(get_types_from_msg(_text, f"{ACTION}_{_part}"))
# The types rosidl derives from an action (rosidl_parser definition.Action) and CancelGoal.srv.
_UUID, _TIME = (NAME, "unique_identifier_msgs/msg/UUID"), (NAME, "builtin_interfaces/msg/Time")
_defs.update({
    f"{ACTION}_SendGoal_Request": ([], [("goal_id", _UUID), ("goal", (NAME, f"{ACTION}_Goal"))]),
    f"{ACTION}_SendGoal_Response": ([], [("accepted", (BASE, ("bool", 0))), ("stamp", _TIME)]),
    f"{ACTION}_GetResult_Request": ([], [("goal_id", _UUID)]),
    f"{ACTION}_GetResult_Response": ([], [("status", (BASE, ("int8", 0))),
                                          ("result", (NAME, f"{ACTION}_Result"))]),
    f"{ACTION}_FeedbackMessage": ([], [("goal_id", _UUID), ("feedback", (NAME, f"{ACTION}_Feedback"))]),
    "action_msgs/srv/CancelGoal_Request": ([], [("goal_info", (NAME, "action_msgs/msg/GoalInfo"))]),
    "action_msgs/srv/CancelGoal_Response": (
        [(c, "int8", v) for v, c in enumerate(["ERROR_NONE", "ERROR_REJECTED", "ERROR_UNKNOWN_GOAL_ID",
                                                "ERROR_GOAL_TERMINATED"])],
        [("return_code", (BASE, ("int8", 0))),
         ("goals_canceling", (SEQ, ((NAME, "action_msgs/msg/GoalInfo"), 0)))]),
})
TS.register(_defs)


def usage(why):
    print(f"peer.py: {why}", file=sys.stderr, flush=True)
    sys.exit(2)


def fields(name):
    if name not in TS.fielddefs:
        usage(f"unknown type {name} (rosbags ROS2_JAZZY names, e.g. nav_msgs/msg/Odometry)")
    return TS.fielddefs[name][1]


_classes = {}


def cy_class(name, service_header=False):
    """The cyclonedds IdlStruct of a rosbags type, named as ROS 2 names it on DDS. With
    service_header, the 16 bytes rmw_cyclonedds puts in front of a request or reply (serdata.hpp:
    `struct cdds_request_header_t { uint64_t guid; int64_t seq; }`) come first."""
    key = (name, service_header)
    if key not in _classes:
        ann = {"cdds_guid": idl.uint64, "cdds_seq": idl.int64} if service_header else {}
        ann.update({n: cy_field(t) for n, t in fields(name)})
        pkg, kind, typ = name.split("/")
        cls = types.new_class(typ, (IdlStruct,), {"typename": f"{pkg}::{kind}::dds_::{typ}_"},
                              lambda ns: ns.update(__annotations__=ann))
        _classes[key] = dataclass(cls)
    return _classes[key]


def cy_field(ft):
    kind, d = ft
    if kind == BASE:
        if d[0] not in CYCLONE:
            usage(f"base type {d[0]} is not supported")
        return idl.bounded_str[d[1]] if d[0] == "string" and d[1] else CYCLONE[d[0]]
    if kind == NAME:
        return cy_class(d)
    if kind == ARRAY:
        return idl.array[cy_field(d[0]), d[1]]
    return idl.sequence[cy_field(d[0]), d[1]] if d[1] else idl.sequence[cy_field(d[0])]


def numeric(ft):
    return ft[0] == BASE and ft[1][0] != "string"


def from_json(ft, v=None):
    """A rosbags value of field type ft from JSON; what is missing is zero, empty or false."""
    kind, d = ft
    if kind == NAME:
        v = {} if v is None else v
        fs = fields(d)
        if not isinstance(v, dict) or set(v) - {n for n, _ in fs}:
            raise ValueError(f"{d} has fields {[n for n, _ in fs]}, got {v!r}")
        return TS.types[d](**{n: from_json(t, v.get(n)) for n, t in fs})
    if kind == BASE:
        if d[0] == "string":
            return "" if v is None else str(v)
        return NUMPY[d[0]](v or 0).item()
    v = ([] if kind == SEQ else [None] * d[1]) if v is None else list(v)
    if kind == ARRAY and len(v) != d[1]:
        raise ValueError(f"an array of {d[1]} expected, got {len(v)}")
    if numeric(d[0]):
        return np.array([x or 0 for x in v], dtype=NUMPY[d[0][1][0]])
    return [from_json(d[0], x) for x in v]


def to_cy(ft, v):
    kind, d = ft
    if kind == NAME:
        return cy_class(d)(**{n: to_cy(t, getattr(v, n)) for n, t in fields(d)})
    if kind == BASE:
        return v
    return v.tolist() if numeric(d[0]) else [to_cy(d[0], x) for x in v]


def to_rb(ft, v):
    kind, d = ft
    if kind == NAME:
        return TS.types[d](**{n: to_rb(t, getattr(v, n)) for n, t in fields(d)})
    if kind == BASE:
        return v
    if numeric(d[0]):
        return np.array(list(v), dtype=NUMPY[d[0][1][0]])
    return [to_rb(d[0], x) for x in v]


def to_json(v):
    if hasattr(v, "__msgtype__"):
        return {n: to_json(getattr(v, n)) for n, _ in fields(v.__msgtype__)}
    if isinstance(v, np.ndarray):
        return [to_json(x) for x in v.tolist()]
    if isinstance(v, (list, tuple)):
        return [to_json(x) for x in v]
    if isinstance(v, float) and not math.isfinite(v):
        return "NaN" if math.isnan(v) else ("Infinity" if v > 0 else "-Infinity")
    return v


def same_bytes(raw, ours, skip=0):
    """Whether serialized data (after its 4-byte encapsulation header and skip more bytes) is
    ours. Up to 3 zero bytes of padding after the data are no difference, declared in the
    options (XCDR1: low 2 bits, as Cyclone writes) or not (as rustdds writes)."""
    a, b = raw[4 + skip:], ours[4:len(ours) - (ours[3] & 3)]
    return raw[:2] == ours[:2] and a[:len(b)] == b and len(a) - len(b) < 4 and not any(a[len(b):])


def decode(name, raw, service_header=False):
    """(cyclonedds object, rosbags message, the check for the event: bytes_match_rosbags, and
    the bytes received when they do not match)."""
    obj = cy_class(name, service_header).deserialize(raw)
    msg = to_rb((NAME, name), obj)
    same = same_bytes(raw, bytes(TS.serialize_cdr(msg, name)), 16 if service_header else 0)
    return obj, msg, {"bytes_match_rosbags": same, **({} if same else {"cdr_hex": raw.hex()})}


def emit(**event):
    print(json.dumps(event), flush=True)


def fail(why):
    print(f"peer.py: {why}", file=sys.stderr, flush=True)
    sys.exit(3)


# --- DDS -------------------------------------------------------------------------------------
def qos(reliable=True, transient=False, depth=10):
    return Qos(Policy.Reliability.Reliable(duration(seconds=1)) if reliable else Policy.Reliability.BestEffort,
               Policy.Durability.TransientLocal if transient else Policy.Durability.Volatile,
               Policy.History.KeepLast(depth), Policy.DataRepresentation(use_cdrv0_representation=True))


class Peer:
    def __init__(self, domain):
        self.dp = DomainParticipant(domain)
        self.ws = WaitSet(self.dp)
        self._keep = []

    def reader(self, topic, name, q, service_header=False):
        r = DataReader(self.dp, Topic(self.dp, topic, cy_class(name, service_header)), qos=q)
        cond = ReadCondition(r, ANY)
        self.ws.attach(cond)
        self._keep.append(cond)
        return r

    def writer(self, topic, name, q, service_header=False):
        return DataWriter(self.dp, Topic(self.dp, topic, cy_class(name, service_header)), qos=q)

    def wait(self, deadline, step=0.05):
        self.ws.wait(duration(seconds=max(0.0, min(step, deadline - time.monotonic()))))


def take(reader):
    return [bytes(raw) for raw, info in ddspy_take(reader._ref, ANY, 64) if info.valid_data]


def ros_topic(name):
    return "rt" + (name if name.startswith("/") else "/" + name)


# --- listen ----------------------------------------------------------------------------------
def listen(a):
    peer = Peer(a.domain)
    r = peer.reader(ros_topic(a.topic), a.type, qos(not a.best_effort, a.transient_local, a.depth))
    deadline, n = time.monotonic() + a.seconds, 0
    while time.monotonic() < deadline and (a.count is None or n < a.count):
        peer.wait(deadline)
        for raw in take(r):
            t_rx = time.monotonic()
            try:
                _, msg, check = decode(a.type, raw)
            except Exception as e:  # a sample cyclonedds or rosbags cannot take is an event too
                emit(topic=a.topic, t_rx=t_rx, error=f"{type(e).__name__}: {e}", cdr_hex=raw.hex(),
                     bytes_match_rosbags=False)
                continue
            n += 1
            emit(topic=a.topic, t_rx=t_rx, msg=to_json(msg), **{**check, "cdr_hex": raw.hex()})
            if a.count is not None and n >= a.count:
                break
    if a.count is not None and n < a.count:
        fail(f"{n} of {a.count} samples on {a.topic} in {a.seconds} s")


# --- publish ---------------------------------------------------------------------------------
def publish(a):
    try:
        msg = from_json((NAME, a.type), json.loads(a.json))
    except (ValueError, TypeError) as e:
        usage(f"--json does not fit {a.type}: {e}")
    if a.pad_frame_id and hasattr(msg, "header"):
        msg.header.frame_id = "x" * a.pad_frame_id  # a sample too big for any reasonable use
    peer = Peer(a.domain)
    w = peer.writer(ros_topic(a.topic), a.type, qos(not a.best_effort, a.transient_local, a.depth))
    until = time.monotonic() + a.wait_match
    while not w.get_matched_subscriptions() and time.monotonic() < until:
        time.sleep(0.02)
    matched = len(w.get_matched_subscriptions())
    emit(matched=matched)
    if matched == 0 and a.wait_match > 0:
        fail(f"no reader of {a.topic} ({a.type}) matched in {a.wait_match} s")
    start, count = time.monotonic(), 0
    while time.monotonic() - start < a.seconds and (a.count is None or count < a.count):
        if a.stamp_now and hasattr(msg, "header"):
            now = time.time()
            msg.header.stamp.sec, msg.header.stamp.nanosec = int(now), int(now % 1 * 1e9)
        w.write(to_cy((NAME, a.type), msg))
        count += 1
        time.sleep(max(0.0, start + count / a.rate - time.monotonic()))
    if not a.best_effort:
        try:
            w.wait_for_acks(duration(seconds=1))
        except Exception:
            pass
    emit(published=count)


# --- navigate: a NavigateToPose action client as rcl_action on rmw_cyclonedds frames it ----------
class ServiceClient:
    """rq/<name>Request and rr/<name>Reply with rmw_cyclonedds' 16-byte header: the request
    writer's instance handle as guid, and a sequence number; a reply is ours when both match."""
    seq = 0

    def __init__(self, peer, service, srv_type):
        q = qos(True, False, 10)  # rmw_qos_profile_services_default
        self.req_type, self.rep_type = srv_type + "_Request", srv_type + "_Response"
        self.w = peer.writer(f"rq/{service}Request", self.req_type, q, service_header=True)
        self.r = peer.reader(f"rr/{service}Reply", self.rep_type, q, service_header=True)
        self.guid = self.w.instance_handle & 0xFFFF_FFFF_FFFF_FFFF  # the C API's uint64

    def ready(self):
        return bool(self.w.get_matched_subscriptions()) and bool(self.r.get_matched_publications())

    def call(self, request):
        ServiceClient.seq += 1  # rmw_send_request: process-wide ++next_request_id
        cls = cy_class(self.req_type, service_header=True)
        self.w.write(cls(cdds_guid=self.guid, cdds_seq=ServiceClient.seq,
                         **{n: to_cy(t, getattr(request, n)) for n, t in fields(self.req_type)}))
        return ServiceClient.seq

    def replies(self):
        """(seq, rosbags reply, check) for each reply to one of our requests."""
        for raw in take(self.r):
            obj, msg, check = decode(self.rep_type, raw, service_header=True)
            if obj.cdds_guid == self.guid:
                yield obj.cdds_seq, msg, check


def navigate(a):
    if a.mapping != "cyclone":
        usage("only --mapping cyclone (rmw_cyclonedds' framing) is implemented")
    peer, base = Peer(a.domain), a.action.strip("/")
    send_goal = ServiceClient(peer, f"{base}/_action/send_goal", f"{ACTION}_SendGoal")
    get_result = ServiceClient(peer, f"{base}/_action/get_result", f"{ACTION}_GetResult")
    cancel = ServiceClient(peer, f"{base}/_action/cancel_goal", "action_msgs/srv/CancelGoal")
    # rcl_action_client_get_default_options: feedback rmw_qos_profile_default; status
    # rcl_action_qos_profile_status_default (reliable, transient local, depth 1).
    fb_r = peer.reader(f"rt/{base}/_action/feedback", f"{ACTION}_FeedbackMessage", qos(True, False, 10))
    st_r = peer.reader(f"rt/{base}/_action/status", "action_msgs/msg/GoalStatusArray", qos(True, True, 1))
    deadline = time.monotonic() + a.seconds
    clients = (send_goal, get_result, cancel)
    while not (all(c.ready() for c in clients) and fb_r.get_matched_publications()
               and st_r.get_matched_publications()):
        if time.monotonic() >= deadline:
            fail(f"no NavigateToPose server on /{base} in {a.seconds} s")
        time.sleep(0.02)
    time.sleep(0.2)  # let the server's reply writers match our readers too (volatile replies)
    emit(server="available")

    goal_id = uuid.uuid4().bytes
    now = time.time()
    goal = from_json((NAME, f"{ACTION}_SendGoal_Request"), {
        "goal_id": {"uuid": list(goal_id)},
        "goal": {"pose": {"header": {"stamp": {"sec": int(now), "nanosec": int(now % 1 * 1e9)},
                                     "frame_id": a.frame},
                          "pose": {"position": {"x": a.x, "y": a.y},
                                   "orientation": {"z": math.sin(a.yaw / 2), "w": math.cos(a.yaw / 2)}}},
                 "behavior_tree": ""}})
    goal_seq, result_seq, cancel_seq = send_goal.call(goal), None, None
    accepted_at, status = None, None
    while time.monotonic() < deadline:
        peer.wait(deadline)
        for seq, rep, check in send_goal.replies():
            if seq != goal_seq:
                continue
            emit(goal="accepted" if rep.accepted else "rejected", goal_id=goal_id.hex(),
                 stamp=to_json(rep.stamp), **check)
            if not rep.accepted:
                return
            accepted_at = time.monotonic()
            result_seq = get_result.call(from_json((NAME, f"{ACTION}_GetResult_Request"),
                                                   {"goal_id": {"uuid": list(goal_id)}}))
        for raw in take(fb_r):
            _, fb, check = decode(f"{ACTION}_FeedbackMessage", raw)
            if bytes(fb.goal_id.uuid) == goal_id:
                emit(feedback=to_json(fb.feedback), **check)
        for raw in take(st_r):
            _, arr, check = decode("action_msgs/msg/GoalStatusArray", raw)
            mine = [s.status for s in arr.status_list if bytes(s.goal_info.goal_id.uuid) == goal_id]
            if mine and mine[0] != status:
                status = mine[0]
                emit(status=status, **check)
        if (a.cancel_after is not None and accepted_at is not None and cancel_seq is None
                and time.monotonic() - accepted_at >= a.cancel_after):
            cancel_seq = cancel.call(from_json((NAME, "action_msgs/srv/CancelGoal_Request"),
                                               {"goal_info": {"goal_id": {"uuid": list(goal_id)}}}))
        for seq, rep, check in cancel.replies():
            if seq == cancel_seq:
                emit(cancel=to_json(rep), **check)
        for seq, rep, check in get_result.replies():
            if seq == result_seq:
                emit(result={"status": rep.status, "error_code": rep.result.error_code,
                             "error_msg": rep.result.error_msg}, **check)
                return
    fail("no " + ("result" if accepted_at else "answer to the goal") + f" in {a.seconds} s")


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--domain", type=int, default=int(os.environ.get("ROS_DOMAIN_ID", "0")))
    sub = p.add_subparsers(dest="cmd", required=True)
    for name in ("listen", "publish"):
        s = sub.add_parser(name)
        s.add_argument("--topic", required=True)
        s.add_argument("--type", required=True, help="e.g. geometry_msgs/msg/Twist")
        s.add_argument("--seconds", type=float, default=5.0)
        rel = s.add_mutually_exclusive_group()
        rel.add_argument("--reliable", action="store_true", help="(the default)")
        rel.add_argument("--best-effort", action="store_true")
        s.add_argument("--transient-local", action="store_true")
        s.add_argument("--depth", type=int, default=10)
        s.add_argument("--count", type=int)
    pub = sub.choices["publish"]
    pub.add_argument("--json", default="{}")
    pub.add_argument("--rate", type=float, default=10.0)
    pub.add_argument("--wait-match", type=float, default=5.0, help="0: publish without waiting")
    pub.add_argument("--stamp-now", action="store_true", help="header.stamp = wall clock at each write")
    pub.add_argument("--pad-frame-id", type=int, default=0, help="header.frame_id of N bytes")
    nav = sub.add_parser("navigate")
    nav.add_argument("--action", default="/navigate_to_pose")
    nav.add_argument("--x", type=float, required=True)
    nav.add_argument("--y", type=float, required=True)
    nav.add_argument("--yaw", type=float, default=0.0)
    nav.add_argument("--frame", default="map")
    nav.add_argument("--cancel-after", type=float)
    nav.add_argument("--seconds", type=float, default=30.0)
    nav.add_argument("--mapping", default="cyclone", choices=["cyclone", "enhanced"])
    a = p.parse_args()
    {"listen": listen, "publish": publish, "navigate": navigate}[a.cmd](a)


if __name__ == "__main__":
    main()
