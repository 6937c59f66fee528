"""Reads a ROS 2 bag that `nerve export --ros2` wrote with PyPI rosbags (an
independent rosbag2 reader, no ROS) and prints what it found as JSON; used by
tests/tests/ros2.rs.

Two of rosbags' readers: `rosbags.rosbag2.Reader` (the rosbag2 MCAP file:
its topics, types, counts, QoS and the ros2msg definitions in its schemas)
and `rosbags.highlevel.AnyReader` (which builds its types from those
definitions and deserializes every message). Its one argument is the file.
"""

import json
import math
import sys
from pathlib import Path

from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import Reader
from rosbags.typesys import Stores, get_typestore

path = Path(sys.argv[1])
out = {"topics": {}, "messages": {}}

with Reader(path) as reader:
    out["message_count"] = reader.message_count
    out["duration"] = reader.duration
    for conn in reader.connections:
        qos = conn.ext.offered_qos_profiles
        out["topics"][conn.topic] = {
            "type": conn.msgtype,
            "count": conn.msgcount,
            "serialization": conn.ext.serialization_format,
            "definition_format": conn.msgdef.format.name,
            "qos": [{"reliability": q.reliability.name, "durability": q.durability.name, "depth": q.depth}
                    for q in qos],
        }

# the message definitions in the file, not rosbags' own: AnyReader with an
# empty type store registers the types from the bag's schemas
store = get_typestore(Stores.EMPTY)
with AnyReader([path], default_typestore=store) as reader:
    for conn, stamp, raw in reader.messages():
        m = reader.deserialize(raw, conn.msgtype)
        if conn.msgtype == "nav_msgs/msg/Odometry":
            p, o = m.pose.pose.position, m.pose.pose.orientation
            v = {"x": p.x, "y": p.y, "yaw": 2 * math.atan2(o.z, o.w), "v": m.twist.twist.linear.x,
                 "omega": m.twist.twist.angular.z, "frame": m.header.frame_id, "child": m.child_frame_id}
        elif conn.msgtype == "sensor_msgs/msg/LaserScan":
            v = {"frame": m.header.frame_id, "angle_increment": float(m.angle_increment),
                 "ranges": [float(r) if math.isfinite(r) else None for r in m.ranges]}
        elif conn.msgtype == "geometry_msgs/msg/Twist":
            v = {"v": m.linear.x, "omega": m.angular.z}
        elif conn.msgtype == "sensor_msgs/msg/Image":
            px = bytes(m.data)
            v = {"frame": m.header.frame_id, "width": int(m.width), "height": int(m.height),
                 "encoding": m.encoding, "step": int(m.step), "bytes": len(px)}
            if conn.topic not in out["messages"] and m.encoding == "rgb8":
                # the first frame's strong red pixels (a test pattern's disc)
                v["red"] = sum(1 for r, g, b in zip(px[0::3], px[1::3], px[2::3]) if r > 180 and g < 70 and b < 70)
        else:
            v = {}
        v["stamp_ns"] = m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec if hasattr(m, "header") else None
        v["log_time"] = stamp
        out["messages"].setdefault(conn.topic, []).append(v)

print(json.dumps(out))
