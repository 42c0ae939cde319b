#!/usr/bin/python3
"""Keeps the latest status of each robot in a file: subscribes /ROBOT/sgm/status (std_msgs/String,
JSON) for every ROBOT named and writes each message to DIR/ROBOT.json (atomically, by rename),
until killed. With TRIGGER_FILE and TRIGGER_ID in the environment, it creates TRIGGER_FILE the
first time a robot reports robot TRIGGER_ID as Matched or KeyframesRequested (an exchange with
it under way). The ROS side of tests/ros_fleet.sh; run with Debian's Python.
Usage: ros_status.py DIR ROBOT [ROBOT ...]"""
import json
import os
import sys

import rospy
from std_msgs.msg import String


def main():
    directory, robots = sys.argv[1], sys.argv[2:]
    rospy.init_node("sgm_fleet_status", anonymous=True)

    def keep(robot):
        def callback(message):
            path = os.path.join(directory, robot + ".json")
            with open(path + ".tmp", "w") as f:
                f.write(message.data)
            os.replace(path + ".tmp", path)
            trigger, victim = os.environ.get("TRIGGER_FILE"), os.environ.get("TRIGGER_ID")
            if trigger and victim and not os.path.exists(trigger):
                neighbours = json.loads(message.data).get("neighbours", [])
                if any(str(n["robot"]) == victim and n["state"] in ("Matched", "KeyframesRequested")
                       for n in neighbours):
                    open(trigger, "w").close()
        return callback

    subscribers = [rospy.Subscriber(f"/{r}/sgm/status", String, keep(r), queue_size=1) for r in robots]
    rospy.spin()
    del subscribers


main()
