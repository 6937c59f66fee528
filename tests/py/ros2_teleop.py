"""ROS 2 teleop against an exploring robot, as rmw_zenoh would do it, with no
ROS: for tests/tests/ros2_teleop.rs.

Built on PyPI eclipse-zenoh and rosbags (Jazzy's definitions, RIHS01 hashes,
CDR), like tests/py/ros2_peer.py. Its one argument is a JSON object:

  connect     the router's endpoint, e.g. "tcp/127.0.0.1:7447"
  domain      ROS_DOMAIN_ID
  node        the robot's ROS node name to find
  twist       [linear.x, angular.z] to publish on /cmd_vel
  moving      the speed (m/s, /odom's twist) that says exploration drives
  publish_s   how long to publish the Twist (10 Hz)
  after_s     how long to listen after the last Twist

It finds /odom and /cmd_vel in the robot's liveliness tokens, waits until
/odom shows the robot exploring on its own (moving), publishes the Twist
with rmw_zenoh's attachment for publish_s, listens after_s more, and prints
one JSON object: every /odom message decoded by rosbags as
{"t", "phase", "x", "y", "yaw", "v", "omega"} with phase "before",
"during" or "after". Every wait is bounded; a failure prints
{"error": ...} and exits 1.
"""

import json
import math
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
    # os._exit: an open zenoh session's threads can keep sys.exit waiting
    print(json.dumps({"error": msg}), flush=True)
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

# the robot's /odom publisher and /cmd_vel subscription, from the graph
want = {("MP", "/odom"), ("MS", "/cmd_vel")}
found = {}
deadline = time.monotonic() + 20
while time.monotonic() < deadline and not want <= set(found):
    for reply in session.liveliness().get(f"@ros2_lv/{dom}/**", timeout=2.0):
        if reply.ok is None:
            continue
        parts = str(reply.ok.key_expr).split("/")
        if len(parts) > 11 and parts[8] == A["node"]:
            found[(parts[5], parts[9].replace("%", "/"))] = parts
    time.sleep(0.2)
if not want <= set(found):
    fail(f"tokens of node {A['node']}: want {sorted(want)}, found {sorted(found)}")


def key(kind, topic):
    p = found[(kind, topic)]
    return f"{dom}/{topic.lstrip('/')}/{p[10]}/{p[11]}"


lock = threading.Lock()
phase = ["before"]
odoms = []


def on_odom(sample):
    m = TS.deserialize_cdr(bytes(sample.payload.to_bytes()), "nav_msgs/msg/Odometry")
    p, o = m.pose.pose.position, m.pose.pose.orientation
    with lock:
        odoms.append({"t": time.monotonic(), "phase": phase[0], "x": p.x, "y": p.y,
                      "yaw": 2.0 * math.atan2(o.z, o.w), "v": m.twist.twist.linear.x,
                      "omega": m.twist.twist.angular.z})


sub = session.declare_subscriber(key("MP", "/odom"), on_odom)

# exploration first: the robot drives on its own before any command comes
deadline = time.monotonic() + 30
while time.monotonic() < deadline:
    with lock:
        if len(odoms) >= 5 and abs(odoms[-1]["v"]) >= A["moving"]:
            break
    time.sleep(0.05)
else:
    fail(f"the robot never explored on its own (no /odom with v >= {A['moving']}): last {odoms[-3:]}")

Twist, Vector3 = TS.types["geometry_msgs/msg/Twist"], TS.types["geometry_msgs/msg/Vector3"]
cmd = Twist(linear=Vector3(x=A["twist"][0], y=0.0, z=0.0), angular=Vector3(x=0.0, y=0.0, z=A["twist"][1]))
cdr = bytes(TS.serialize_cdr(cmd, "geometry_msgs/msg/Twist"))
gid = bytes(range(16, 32))
token = session.liveliness().declare_token(
    f"@ros2_lv/{dom}/{session.zid()}/0/1/MP/%/%/teleop/%cmd_vel/{dds('geometry_msgs/msg/Twist')}/"
    f"{TS.hash_rihs01('geometry_msgs/msg/Twist')}/::,10:,:,:,,")
pub = session.declare_publisher(key("MS", "/cmd_vel"))
with lock:
    phase[0] = "during"
seq = 0
end = time.monotonic() + A["publish_s"]
while time.monotonic() < end:
    seq += 1
    pub.put(cdr, attachment=struct.pack("<qqB", seq, time.time_ns(), 16) + gid)
    time.sleep(0.1)
with lock:
    phase[0] = "after"
time.sleep(A["after_s"])
with lock:
    got = list(odoms)
sub.undeclare()
pub.undeclare()
token.undeclare()
session.close()
print(json.dumps({"sent": seq, "odom": got}), flush=True)
os._exit(0)
