"""A ROS 2 robot on Cyclone DDS, in a process of its own, configured by ``CYCLONEDDS_URI``
as rmw_cyclonedds configures one (the test sets it): it publishes a JointState every 20 ms
on ``rt/joint_states`` (reliable, as ROS 2's default profile) and prints every
JointTrajectory it takes on ``rt/joint_trajectory_controller/joint_trajectory`` as a JSON line.
With ``silent``, it publishes nothing (its writer matched, no data).

    python cyclone_robot.py DOMAIN [silent]
"""

import json
import sys
import time

from cyclonedds.core import Policy, Qos
from cyclonedds.domain import DomainParticipant
from cyclonedds.pub import DataWriter
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from cyclonedds.util import duration

from sonibus.adapters.ros2.dds_link import Header, JointState, JointTrajectory, Time


def main() -> None:
    participant = DomainParticipant(int(sys.argv[1]))
    qos = Qos(Policy.Reliability.Reliable(duration(milliseconds=100)), Policy.Durability.Volatile,
              Policy.History.KeepLast(10))
    writer = DataWriter(participant, Topic(participant, "rt/joint_states", JointState), qos)
    reader = DataReader(participant, Topic(participant, "rt/joint_trajectory_controller/joint_trajectory",
                                           JointTrajectory), qos)
    print(json.dumps({"ready": True}), flush=True)
    silent = sys.argv[2:] == ["silent"]
    while True:
        now = time.time()
        if not silent:
            writer.write(JointState(Header(Time(int(now), int(now % 1 * 1e9)), ""), ["shoulder", "elbow", "lift"],
                                    [0.3, -0.4, 0.1], [], []))
        for sample in reader.take(N=10):
            if isinstance(sample, JointTrajectory):
                print(json.dumps({"names": list(sample.joint_names),
                                  "positions": [list(p.positions) for p in sample.points]}), flush=True)
        time.sleep(0.02)


if __name__ == "__main__":
    main()
