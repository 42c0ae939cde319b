#!/usr/bin/python3
"""Feeds one robot's sensor topics from a ROS 1 bag through rospy publishers, at RATE times
the recorded pace (the rospy side of the ROS interop tests; run with Debian's Python).
Waits for a subscriber on every topic first (/tf_static is latched, so later subscribers get
it too); ground truth is not published.
Usage: ros_feed.py BAG RATE"""
import sys
import time

import rosbag
import roslib.message
import rospy


def main():
    path, rate = sys.argv[1], float(sys.argv[2])
    rospy.init_node("sgm_feed", anonymous=True, disable_signals=True)
    bag = rosbag.Bag(path)
    publishers = {}
    for topic, info in bag.get_type_and_topic_info().topics.items():
        if not topic.endswith("/ground_truth"):
            cls = roslib.message.get_message_class(info.msg_type)
            # /tf_static is latched, as tf2's static broadcaster latches it: both robots' nodes
            # subscribe to it, and unlatched, the one mount message went only to whichever node
            # had connected when the wait below ended (CI at 5a08bc87: alpha got no camera mount).
            latch = topic.endswith("tf_static")
            publishers[topic] = (rospy.Publisher(topic, cls, queue_size=100, latch=latch), cls)
    deadline = time.monotonic() + 60
    while any(p.get_num_connections() == 0 for p, _ in publishers.values()):
        if time.monotonic() > deadline:
            sys.exit(f"{path}: no subscriber on " + ", ".join(t for t, (p, _) in publishers.items()
                                                              if p.get_num_connections() == 0))
        time.sleep(0.05)
    start, first, sent = time.monotonic(), None, 0
    for topic, (_, data, _, _, _), t in bag.read_messages(topics=list(publishers), raw=True):
        publisher, cls = publishers[topic]
        first = t if first is None else first
        time.sleep(max(0.0, start + (t - first).to_sec() / rate - time.monotonic()))
        publisher.publish(cls().deserialize(data))
        sent += 1
    # rospy writes each connection's queue from its own thread and drops what is still queued
    # when the process exits: wait until every queue is written (a loaded machine or a veth can
    # take seconds), then a second for the last bytes to be read.
    def queued():
        return sum(len(getattr(c, "_queue", None) or ()) for p, _ in publishers.values() for c in p.impl.connections)

    deadline = time.monotonic() + 60
    while queued() and time.monotonic() < deadline:
        time.sleep(0.05)
    if queued():
        print(f"{path}: {queued()} messages still queued after 60 s; they are lost", file=sys.stderr)
    time.sleep(1)
    print(f"{path}: {sent} messages published")


main()
