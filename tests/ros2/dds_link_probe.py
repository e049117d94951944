"""The ``ros2`` adapter's DDS link, configured as docs/ros2.md says (``interface = "lo"``), in a
process of its own (inside a test's network namespace): prints ``{"open": true}``, its first JointState's joint
names as a JSON line, then sends a trajectory (``shoulder`` to 0.5) every 0.2 s while a
controller is matched, printing ``{"sent": n}``.

    python dds_link_probe.py DOMAIN URDF
"""

import json
import sys
import time

from sonibus.adapters.ros2 import cdr
from sonibus.adapters.ros2.config import Ros2Config
from sonibus.adapters.ros2.dds_link import DdsLink


def main() -> None:
    link = DdsLink(Ros2Config(middleware="dds", domain_id=int(sys.argv[1]), interface="lo", urdf=sys.argv[2]))
    print(json.dumps({"open": True}), flush=True)
    try:
        received = None
        while received is None:
            received = link.take(0.2)
        print(json.dumps({"names": list(received.state.names)}), flush=True)
        sent = 0
        while True:
            if not link.matched():
                link.send(cdr.joint_trajectory(cdr.Stamp(0, 0), ["shoulder"], [cdr.Point([0.5], 1.0, [0.0])]))
                sent += 1
                print(json.dumps({"sent": sent}), flush=True)
            time.sleep(0.2)
    finally:
        link.close()


if __name__ == "__main__":
    main()
