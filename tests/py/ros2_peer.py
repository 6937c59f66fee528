"""A ROS 2 node as rmw_zenoh would be one, with no ROS: for tests/tests/ros2.rs.

Built on PyPI eclipse-zenoh (the session, liveliness, puts with an
attachment) and rosbags (ROS 2 Jazzy's message definitions, their RIHS01
hashes, CDR). Its one argument is a JSON object:

  connect     the router's endpoint, e.g. "tcp/127.0.0.1:7447"
  domain      ROS_DOMAIN_ID
  node        the robot's ROS node name to find
  twist       [linear.x, angular.z] to publish on /cmd_vel
  publish_s   for how long (10 Hz)
  settle_s    how long to wait after, for the robot to stop
  range       (optional) a topic of sensor_msgs/Range: the sonar ring, one
              message per direction, the latest of each frame is reported
  vector3     (optional) a topic of geometry_msgs/Vector3 (a mapping of the
              agent's configuration): the latest is reported
  tf_static   (optional) [[parent, child, x, y, z], ...] the robot's static
              transforms, which this peer, joining after the robot sent them,
              must still get on /tf_static (transient local)
  odom_in     (optional) {"topic", "x", "y", "v", "sec", "bad_y"}: a topic the
              robot subscribes to as nav_msgs/Odometry (into a user's type,
              field by field); published at 10 Hz with the Twists, then once
              with position.y = bad_y, which the robot must refuse

It finds the node and its topics in the liveliness tokens (`@ros2_lv/...`),
subscribes to /odom, /tf, /scan and /camera/image_raw by the keys the tokens give, decodes
them with rosbags, publishes the Twist with the attachment rmw_zenoh puts
on every message (and a publisher token of its own), then a malformed
message and a sideways Twist that the robot must refuse, and prints one
JSON object.
Every wait is bounded; any failure prints {"error": ...} and exits 1.
"""

import json
import os
import struct
import sys
import threading
import time

import zenoh
from rosbags.typesys import Stores, get_typestore

A = json.loads(sys.argv[1])
TS = get_typestore(Stores.ROS2_JAZZY)


def fail(msg):
    # os._exit: an open zenoh session (its threads, an advanced subscriber's
    # pending queries) can keep sys.exit from ending the interpreter
    print(json.dumps({"error": msg}), flush=True)
    sys.stderr.flush()
    os._exit(1)


def dds(ros_type):
    pkg, kind, name = ros_type.split("/")
    return f"{pkg}::{kind}::dds_::{name}_"


conf = zenoh.Config()
for k, v in [("mode", "peer"), ("connect/endpoints", [A["connect"]]), ("listen/endpoints", []),
             ("scouting/multicast/enabled", False), ("connect/timeout_ms", 3000),
             ("connect/exit_on_failure", False)]:
    conf.insert_json5(k, json.dumps(v))
session = zenoh.open(conf)
dom = A["domain"]

# 1. the graph, as rmw_zenoh's graph cache reads it
want = {("NN", None), ("MP", "/odom"), ("MP", "/tf"), ("MP", "/scan"), ("MP", "/camera/image_raw"), ("MS", "/cmd_vel")}
if A.get("tf_static"):
    want.add(("MP", "/tf_static"))
if A.get("range"):
    want.add(("MP", A["range"]))
if A.get("vector3"):
    want.add(("MP", A["vector3"]))
if A.get("odom_in"):
    want.add(("MS", A["odom_in"]["topic"]))
found = {}
deadline = time.monotonic() + 15
while time.monotonic() < deadline:
    for reply in session.liveliness().get(f"@ros2_lv/{dom}/**", timeout=2.0):
        if reply.ok is None:
            continue
        parts = str(reply.ok.key_expr).split("/")
        if len(parts) < 9 or parts[8] != A["node"]:
            continue
        kind = parts[5]
        topic = parts[9].replace("%", "/") if len(parts) > 9 else None
        found[(kind, topic)] = parts
    if want <= set(found):
        break
    time.sleep(0.2)
if not want <= set(found):
    fail(f"tokens of node {A['node']} not all found: want {sorted(map(str, want))}, found {sorted(map(str, found))}")

tokens = {}
for (kind, topic), parts in found.items():
    if kind == "NN":
        if parts[3] != parts[4] or parts[6] != "%" or parts[7] != "%":
            fail(f"node token {'/'.join(parts)}: node id twice, enclave and namespace %")
        continue
    ros_type, hash_ = parts[10], parts[11]
    tokens[topic] = {"kind": kind, "type": ros_type, "hash": hash_, "qos": parts[12], "zid": parts[2]}

expect = {"/odom": "nav_msgs/msg/Odometry", "/tf": "tf2_msgs/msg/TFMessage", "/scan": "sensor_msgs/msg/LaserScan",
          "/camera/image_raw": "sensor_msgs/msg/Image", "/cmd_vel": "geometry_msgs/msg/Twist"}
for topic, ros_type in expect.items():
    t = tokens[topic]
    if t["type"] != dds(ros_type):
        fail(f"{topic}: token type {t['type']}, expected {dds(ros_type)}")
    if t["hash"] != TS.hash_rihs01(ros_type):
        fail(f"{topic}: token hash {t['hash']}, rosbags says {TS.hash_rihs01(ros_type)}")


def key(topic):
    t = tokens[topic]
    return f"{dom}/{topic.lstrip('/')}/{t['type']}/{t['hash']}"


# 2. /odom, /tf, /scan and /camera/image_raw, decoded by rosbags
lock = threading.Lock()
odoms, tfs, scans, images, atts = [], [], [], [], []


def on_odom(sample):
    m = TS.deserialize_cdr(bytes(sample.payload.to_bytes()), "nav_msgs/msg/Odometry")
    a = sample.attachment.to_bytes() if sample.attachment is not None else b""
    with lock:
        p, o = m.pose.pose.position, m.pose.pose.orientation
        odoms.append({"x": p.x, "y": p.y, "z": p.z, "qz": o.z, "qw": o.w, "v": m.twist.twist.linear.x,
                      "omega": m.twist.twist.angular.z, "frame": m.header.frame_id, "child": m.child_frame_id,
                      "sec": m.header.stamp.sec, "t": time.time()})
        atts.append(a)


def on_tf(sample):
    m = TS.deserialize_cdr(bytes(sample.payload.to_bytes()), "tf2_msgs/msg/TFMessage")
    with lock:
        tfs.append([(t.header.frame_id, t.child_frame_id, t.transform.translation.x) for t in m.transforms])


def on_scan(sample):
    m = TS.deserialize_cdr(bytes(sample.payload.to_bytes()), "sensor_msgs/msg/LaserScan")
    with lock:
        # JSON has no infinity: a ray without echo is null
        scans.append({"frame": m.header.frame_id, "angle_increment": float(m.angle_increment),
                      "ranges": [float(r) if r != float("inf") else None for r in m.ranges]})


def on_image(sample):
    m = TS.deserialize_cdr(bytes(sample.payload.to_bytes()), "sensor_msgs/msg/Image")
    px = bytes(m.data)
    # pixels of a strong red (the test pattern's disc)
    red = sum(1 for i in range(0, len(px) - 2, 3) if px[i] > 180 and px[i + 1] < 70 and px[i + 2] < 70) \
        if m.encoding == "rgb8" else 0
    with lock:
        images.append({"frame": m.header.frame_id, "width": int(m.width), "height": int(m.height),
                       "encoding": m.encoding, "step": int(m.step), "bigendian": int(m.is_bigendian),
                       "bytes": len(px), "red": red})


ranges = {}


def on_range(sample):
    m = TS.deserialize_cdr(bytes(sample.payload.to_bytes()), "sensor_msgs/msg/Range")
    with lock:
        ranges[m.header.frame_id] = {"range": float(m.range) if m.range != float("inf") else None,
                                     "type": int(m.radiation_type), "fov": float(m.field_of_view),
                                     "min": float(m.min_range), "max": float(m.max_range)}


subs = [session.declare_subscriber(key("/odom"), on_odom), session.declare_subscriber(key("/tf"), on_tf),
        session.declare_subscriber(key("/scan"), on_scan),
        session.declare_subscriber(key("/camera/image_raw"), on_image)]


def wait_for(cond, secs, what):
    end = time.monotonic() + secs
    while time.monotonic() < end:
        with lock:
            if cond():
                return
        time.sleep(0.05)
    fail(f"timed out waiting for {what}")


# /tf_static, transient local: sent once when the robot joined the router,
# before this peer existed; a late-joining subscription gets it from the
# publisher's cache, as rmw_zenoh's does (zenoh-ext's advanced subscriber
# with history and late-publisher detection)
statics = []
if A.get("tf_static"):
    import zenoh.ext

    def on_static(sample):
        m = TS.deserialize_cdr(bytes(sample.payload.to_bytes()), "tf2_msgs/msg/TFMessage")
        a = sample.attachment.to_bytes() if sample.attachment is not None else b""
        with lock:
            statics.append({"transforms": [[t.header.frame_id, t.child_frame_id, t.transform.translation.x,
                                            t.transform.translation.y, t.transform.translation.z,
                                            t.transform.rotation.z, t.transform.rotation.w]
                                           for t in m.transforms],
                            "attachment": len(a), "seq": struct.unpack("<q", a[:8])[0] if len(a) == 33 else None})

    subs.append(zenoh.ext.declare_advanced_subscriber(
        session, key("/tf_static"), on_static,
        history=zenoh.ext.HistoryConfig(detect_late_publishers=True, max_samples=1)))
    wait_for(lambda: len(statics) >= 1, 10, "the static transforms on /tf_static (transient local)")

if A.get("range"):
    subs.append(session.declare_subscriber(key(A["range"]), on_range))
vectors = []


def on_vector3(sample):
    m = TS.deserialize_cdr(bytes(sample.payload.to_bytes()), "geometry_msgs/msg/Vector3")
    with lock:
        vectors.append([m.x, m.y, m.z])


if A.get("vector3"):
    t = tokens[A["vector3"]]
    if t["type"] != dds("geometry_msgs/msg/Vector3") or t["hash"] != TS.hash_rihs01("geometry_msgs/msg/Vector3"):
        fail(f"{A['vector3']}: token type {t['type']} hash {t['hash']}")
    subs.append(session.declare_subscriber(key(A["vector3"]), on_vector3))
wait_for(lambda: len(odoms) >= 5 and len(tfs) >= 1 and len(scans) >= 1 and len(images) >= 1, 15,
         "5 /odom, 1 /tf, 1 /scan and 1 /camera/image_raw messages")
with lock:
    first = dict(odoms[-1])

# 3. a Twist on /cmd_vel with the attachment, as a ROS publisher would
Twist, Vector3 = TS.types["geometry_msgs/msg/Twist"], TS.types["geometry_msgs/msg/Vector3"]
cmd = Twist(linear=Vector3(x=A["twist"][0], y=0.0, z=0.0), angular=Vector3(x=0.0, y=0.0, z=A["twist"][1]))
cdr = bytes(TS.serialize_cdr(cmd, "geometry_msgs/msg/Twist"))
gid = bytes(range(16))
me = session.zid()
token = session.liveliness().declare_token(
    f"@ros2_lv/{dom}/{me}/0/1/MP/%/%/teleop/%cmd_vel/{dds('geometry_msgs/msg/Twist')}/"
    f"{TS.hash_rihs01('geometry_msgs/msg/Twist')}/::,10:,:,:,,")
pub = session.declare_publisher(key("/cmd_vel"))


def odom_cdr(o, y):
    # nav_msgs/Odometry as a ROS node would send it, built by rosbags
    import numpy as np
    T = TS.types
    Time, Header = T["builtin_interfaces/msg/Time"], T["std_msgs/msg/Header"]
    Point, Quat = T["geometry_msgs/msg/Point"], T["geometry_msgs/msg/Quaternion"]
    Pose, PoseC = T["geometry_msgs/msg/Pose"], T["geometry_msgs/msg/PoseWithCovariance"]
    TwistC = T["geometry_msgs/msg/TwistWithCovariance"]
    m = T["nav_msgs/msg/Odometry"](
        header=Header(stamp=Time(sec=o["sec"], nanosec=0), frame_id="map"), child_frame_id="base_link",
        pose=PoseC(pose=Pose(position=Point(x=o["x"], y=y, z=0.0), orientation=Quat(x=0.0, y=0.0, z=0.0, w=1.0)),
                   covariance=np.zeros(36)),
        twist=TwistC(twist=Twist(linear=Vector3(x=o["v"], y=0.0, z=0.0), angular=Vector3(x=0.0, y=0.0, z=0.0)),
                     covariance=np.zeros(36)))
    return bytes(TS.serialize_cdr(m, "nav_msgs/msg/Odometry"))


odom_pub, odom_token, odom_seq = None, None, 0
if A.get("odom_in"):
    o = A["odom_in"]
    t = tokens[o["topic"]]
    if t["type"] != dds("nav_msgs/msg/Odometry") or t["hash"] != TS.hash_rihs01("nav_msgs/msg/Odometry"):
        fail(f"{o['topic']}: subscription token type {t['type']} hash {t['hash']}")
    odom_token = session.liveliness().declare_token(
        f"@ros2_lv/{dom}/{me}/0/2/MP/%/%/teleop/{o['topic'].lstrip('/').replace('/', '%')}/"
        f"{t['type']}/{t['hash']}/::,10:,:,:,,")
    odom_pub = session.declare_publisher(key(o["topic"]))
    odom_good = odom_cdr(o, o["y"])
seq = 0
end = time.monotonic() + A["publish_s"]
while time.monotonic() < end:
    seq += 1
    att = struct.pack("<qqB", seq, time.time_ns(), 16) + gid
    pub.put(cdr, attachment=att)
    if odom_pub is not None:
        odom_seq += 1
        odom_pub.put(odom_good, attachment=struct.pack("<qqB", odom_seq, time.time_ns(), 16) + bytes(range(1, 17)))
    time.sleep(0.1)
if odom_pub is not None:
    # a value the user's f32 cannot hold: refused and counted, not wrapped
    odom_seq += 1
    odom_pub.put(odom_cdr(A["odom_in"], A["odom_in"]["bad_y"]),
                 attachment=struct.pack("<qqB", odom_seq, time.time_ns(), 16) + bytes(range(1, 17)))
# two messages the robot must refuse: bytes that are not a Twist, and a
# Twist asking for sideways motion
seq += 1
pub.put(b"\x00\x01\x00\x00\x07", attachment=struct.pack("<qqB", seq, time.time_ns(), 16) + gid)
side = Twist(linear=Vector3(x=0.0, y=0.5, z=0.0), angular=Vector3(x=0.0, y=0.0, z=0.0))
seq += 1
pub.put(bytes(TS.serialize_cdr(side, "geometry_msgs/msg/Twist")),
        attachment=struct.pack("<qqB", seq, time.time_ns(), 16) + gid)
time.sleep(A["settle_s"])
with lock:
    n0, s0 = len(odoms), len(scans)
with lock:
    ranges.clear()
wait_for(lambda: len(odoms) >= n0 + 3 and len(scans) >= s0 + 2 and (not A.get("range") or len(ranges) == 12), 10,
         "3 more /odom and 2 more /scan messages after the robot stopped")
with lock:
    last = dict(odoms[-1])
    # the attachments: 33 bytes, sequence numbers rising, one GID
    parsed = [struct.unpack("<qqB", a[:17]) + (a[17:],) for a in atts if len(a) == 33]
    bad = len(atts) - len(parsed)
    seqs = [p[0] for p in parsed]
    gids = {p[3] for p in parsed}
    now_ns = time.time_ns()
    stamps_ok = all(abs(now_ns - p[1]) < 600e9 and p[2] == 16 for p in parsed)
    tf_last = tfs[-1]
    scan_last = scans[-1]
    image_last = images[-1]
    image_count = len(images)
    statics_got = list(statics)
    ranges_got = dict(ranges)
    vector3_last = vectors[-1] if vectors else None

for s in subs:
    s.undeclare()
pub.undeclare()
token.undeclare()
if odom_pub is not None:
    odom_pub.undeclare()
    odom_token.undeclare()
session.close()
print(json.dumps({
    "tokens": tokens,
    "first": first,
    "last": last,
    "odom_count": len(odoms),
    "tf_last": tf_last,
    "scan_last": scan_last,
    "image_last": image_last,
    "image_count": image_count,
    "bad_attachments": bad,
    "seq_rising": len(seqs) > 0 and all(b > a for a, b in zip(seqs, seqs[1:])),
    "gids": len(gids),
    "stamps_ok": stamps_ok,
    "sent": seq,
    "tf_static": statics_got,
    "ranges": ranges_got,
    "vector3_last": vector3_last,
    "odom_in_sent": odom_seq,
}))
