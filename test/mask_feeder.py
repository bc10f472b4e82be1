"""Feeds the fixture bag's exact masks (+ camera_info, extrinsics) to an estimator, with faults.

``python mask_feeder.py BAG`` publishes frame by frame in /mocap and waits (bounded) for
``/mocap/estimator/done`` of each frame; faults by frame index (the first person frame is 3):
  4: cam1 mask with a data length that disagrees with height*step
  5: cam2 mask in the wrong encoding (rgb8)
  6, 7: cam3 silent (a view that stops publishing)
  8: after the frame, cam0 re-sends frame 7's stamp (out of order)
Prints ``sent <k>`` and ``done <k>`` lines.
"""
import sys
import time

import numpy as np
import rclpy
from rclpy.node import Node
from sensor_msgs.msg import Image
from std_msgs.msg import Header

import msg_adapters as ma
from rosnode import mask_publishers, masks_by_stamp


def main() -> None:
    bag = sys.argv[1]
    frames, latched = masks_by_stamp(bag)
    rclpy.init()
    node = Node("feeder", namespace="/mocap")
    pubs = mask_publishers(node, frames, latched)
    done: set[int] = set()
    node.create_subscription(Header, "/mocap/estimator/done", lambda h: done.add(ma.stamp_to_ns(h)), 10)
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline and any(p.get_subscription_count() == 0 for p in pubs.values()):
        rclpy.spin_once(node, timeout_sec=0.05)
    time.sleep(1.0)
    stamps = sorted(frames)
    for k, s in enumerate(stamps):
        for topic, msg in sorted(frames[s].items()):
            if k in (6, 7) and topic.startswith("/mocap/cam3/"):
                continue
            if k == 4 and topic == "/mocap/cam1/mask":
                msg = Image(header=msg.header, height=msg.height, width=msg.width, encoding="mono8",
                            step=msg.step, data=bytes(msg.step * msg.height - 7))
            if k == 5 and topic == "/mocap/cam2/mask":
                arr = np.repeat(ma.image_to_array(msg)[..., None], 3, axis=2)
                msg = ma.array_to_image(arr, "rgb8", stamp_ns=s, frame_id=msg.header.frame_id)
            pubs[topic].publish(msg)
        if k == 8:
            pubs["/mocap/cam0/mask"].publish(frames[stamps[7]]["/mocap/cam0/mask"])
        print(f"sent {k}", flush=True)
        end = time.monotonic() + 10
        while s not in done and time.monotonic() < end:
            rclpy.spin_once(node, timeout_sec=0.05)
        print(f"{'done' if s in done else 'timeout'} {k}", flush=True)
    node.destroy_node()
    rclpy.try_shutdown()


if __name__ == "__main__":
    main()
