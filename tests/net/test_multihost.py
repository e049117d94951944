"""Issue 7: sonibus across machines — LANs, subnets joined by a router, cut links,
killed robots, namespaces, user/password with access control, and mutual TLS.

Every machine is a network namespace (``netns.py``); every node is a real
``sonibus run show.toml --host NAME`` (or ``--only NODE``) process inside one,
and what a sound machine gets is read by liblo's ``oscdump`` running there. One
installation file describes all machines of a test, as in a real show.
"""

from __future__ import annotations

import json
import re
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from ..conftest import wait_for
from .netns import Host, Message, NsProcess, OscDump, Topology

pytestmark = pytest.mark.external

RATE = 25                       # frames/s of the simulated robots: light on a 2-core CI machine
BURST_RATE = 50                 # frames/s in the stale-burst test: a frame of jitter is small beside the limit
PEPPER_JOINTS = 17
WINDOW = 0.2                    # s: the window a stale burst is counted in
# Samples younger than the sink's max_age_ms (100 ms) are rightly sent after a cut, so a
# 200 ms window may hold up to 1.5 windows' worth; twice a window is the line (a stale
# backlog, with max_age_ms = 0, measured 2215).
MAX_IN_WINDOW = int(PEPPER_JOINTS * BURST_RATE * WINDOW * 2)


def sim(rate: int = RATE) -> str:
    return f"""
adapter = "sim"
rate_hz = {rate}
idle = false
"""


SIM = sim()

SINK = """
adapter = "osc"
targets = ["127.0.0.1:9000"]
events = true
max_age_ms = 100
"""


def show(tmp_path: Path, text: str, name: str = "show.toml") -> str:
    """Write an installation file (each line stripped of its indentation); its path."""
    path = tmp_path / name
    path.write_text("\n".join(line.strip() for line in text.strip().splitlines()) + "\n", encoding="utf-8")
    return str(path)


def until(topology: Topology, predicate: Callable[[], Any], timeout: float, what: str) -> Any:
    """``predicate()`` once truthy; else fail, with what every process said."""
    return wait_for(predicate, timeout, what, topology.report)


def started(topology: Topology, process: NsProcess, marker: str = "sonibus: running", timeout: float = 20.0) -> None:
    """Wait for ``marker`` on the process's stdout (``sonibus run`` prints it once its nodes run)."""
    until(topology, lambda: any(marker in line for line in list(process.lines)) or not process.running,
          timeout, f"'{marker}' from {process.describe()}")
    if not process.running:
        pytest.fail(f"{process.describe()}\n{topology.report()}")


def run_show(topology: Topology, path: str, *hosts: Host) -> list[NsProcess]:
    """``sonibus run FILE --host NAME`` on each of ``hosts``, once each has started."""
    runs = [host.sonibus("run", path, "--host", host.name) for host in hosts]
    for process in runs:
        started(topology, process)
    return runs


def joint(dump: OscDump, robot: str = "pepper", name: str = "HeadYaw", since: float = 0.0) -> list[Message]:
    return [m for m in dump.messages(f"/{robot}/joints/{name}") if m.read >= since]


def joints(dump: OscDump, robot: str = "pepper", since: float = 0.0) -> list[Message]:
    return [m for m in dump.messages(f"/{robot}/joints/") if m.read >= since]


def connection(dump: OscDump, state: str, robot: str = "pepper", since: float = 0.0) -> list[Message]:
    """``/<robot>/events/connection "<state>"`` messages read at or after ``since``."""
    return [m for m in dump.events(robot) if f'"{state}"' in m.args and m.read >= since]


def streaming(topology: Topology, dump: OscDump, robot: str = "pepper", since: float = 0.0, count: int = 10,
              timeout: float = 20.0) -> list[Message]:
    """Wait for ``count`` HeadYaw samples of ``robot`` read at or after ``since``."""
    def enough() -> list[Message] | None:
        found = joint(dump, robot, since=since)
        return found if len(found) >= count else None
    return until(topology, enough, timeout, f"{count} /{robot}/joints/HeadYaw samples at oscdump")


def reaches(topology: Topology, dump: OscDump, angle: float, since: float, timeout: float = 5.0) -> Message:
    """The first HeadYaw sample read after ``since`` within 0.02 rad of ``angle``."""
    def near() -> Message | None:
        return next((m for m in joint(dump, since=since) if abs(m.value - angle) < 0.02), None)
    return until(topology, near, timeout, f"HeadYaw at oscdump to approach {angle}")


def sent(done: subprocess.CompletedProcess[str], status: int = 0) -> Any:
    """The JSON a ``sonibus send`` printed, after checking its exit status."""
    assert done.returncode == status, f"sonibus send: exit {done.returncode}: {done.stdout} {done.stderr}"
    return json.loads(done.stdout) if status == 0 else None


def robots_listed(done: subprocess.CompletedProcess[str]) -> int:
    """How many robots ``sonibus nodes`` listed (its ``N robot(s)`` line)."""
    assert done.returncode == 0, f"sonibus nodes: exit {done.returncode}: {done.stderr}"
    found = re.search(r"^(\d+) robot\(s\)", done.stdout, re.MULTILINE)
    assert found, f"no 'N robot(s)' line in: {done.stdout}"
    return int(found[1])


def most_in_window(messages: list[Message], window: float = WINDOW) -> int:
    """The most messages oscdump received within any ``window`` seconds (its own stamps)."""
    stamps = sorted(m.received for m in messages)
    most, start = 0, 0
    for end, stamp in enumerate(stamps):
        while stamp - stamps[start] > window:
            start += 1
        most = max(most, end - start + 1)
    return most


def tcp_connects(host: Host, address: str, port: int, timeout: float = 1.5) -> bool:
    """Whether a TCP connection from ``host`` to ``address:port`` is accepted."""
    code = f"import socket; socket.create_connection(('{address}', {port}), timeout={timeout}).close()"
    return host.call(sys.executable, "-c", code, timeout=timeout + 10).returncode == 0


# -- 1. one LAN ------------------------------------------------------------------------


def test_robot_and_sound_hosts_on_one_lan(topology, tmp_path):
    robot, sound = topology.lan("robot", "sound")
    path = show(tmp_path, f"""
        [bus]
        mode = "peer"
        multicast = true

        [nodes.robot]
        robot = "pepper"
        {SIM}
        [nodes.sound]
        subscribe = ["pepper/joints/*", "pepper/events/*"]
        {SINK}
        """)
    dump = sound.oscdump()
    runs = [robot.sonibus("run", path, "--only", "robot", "--listen", robot.endpoint()),
            sound.sonibus("run", path, "--only", "sound")]
    for process in runs:
        started(topology, process)
    streaming(topology, dump)
    until(topology, lambda: len({m.address for m in joints(dump)}) == PEPPER_JOINTS, 5.0, "every Pepper joint")

    start = time.time()
    reply = sent(sound.cli("send", "pepper", "joints/set", "names=HeadYaw", "angles=0.5", "speed=1.0"))
    assert isinstance(reply, dict)
    reaches(topology, dump, 0.5, start)


# -- 2. two subnets, a router ----------------------------------------------------------


def test_two_subnets_joined_only_by_a_zenoh_router(topology, tmp_path):
    nets = topology.subnets(["robot"], ["sound"])
    (robot,), (sound,) = nets.groups
    router = nets.router
    gate_a, gate_b = router.addresses

    # No IP crosses the router: a listener on subnet B is out of reach from subnet A
    # (though A has a route to B through the router).
    listener = sound.run(sys.executable, "-c", "import socket, time; s = socket.socket(); "
                         "s.bind(('0.0.0.0', 7000)); s.listen(); print('listening', flush=True); time.sleep(120)")
    started(topology, listener, "listening")
    assert tcp_connects(sound, sound.address, 7000), "the listener on subnet B does not answer on B"
    assert not tcp_connects(robot, sound.address, 7000), "subnet A reached subnet B: the router forwards IP"

    zenoh_router = router.sonibus("router", "--listen", f"tcp/{gate_a}:7447", "--listen", f"tcp/{gate_b}:7447",
                                  "--no-multicast")
    started(topology, zenoh_router, "listening on")
    assert tcp_connects(robot, gate_a, 7447), "the router's address on subnet A does not answer"

    path = show(tmp_path, f"""
        [bus]
        mode = "client"
        multicast = false

        [bus.hosts.robot]
        connect = ["tcp/{gate_a}:7447"]

        [bus.hosts.sound]
        connect = ["tcp/{gate_b}:7447"]

        [nodes.robot]
        host = "robot"
        robot = "pepper"
        {SIM}
        [nodes.sound]
        host = "sound"
        subscribe = ["pepper/joints/*", "pepper/events/*"]
        {SINK}
        """)
    dump = sound.oscdump()
    run_show(topology, path, robot, sound)
    streaming(topology, dump)

    start = time.time()
    sent(sound.cli("send", "pepper", "joints/set", "names=HeadYaw", "angles=-0.4", "speed=1.0",
                   "--mode", "client", "--no-multicast", "--connect", f"tcp/{gate_b}:7447"))
    reaches(topology, dump, -0.4, start)


# -- 3-5. cut links and killed robots --------------------------------------------------


def point_to_point(tmp_path: Path, robot: Host, extra: str = "", rate: int = RATE, nodes: str = "") -> str:
    """The robot host listens on its address, the sound host connects to it; no multicast;
    ``nodes``: more node tables."""
    return show(tmp_path, f"""
        [bus]
        mode = "peer"
        multicast = false
        {extra}
        [bus.hosts.robot]
        listen = ["{robot.endpoint()}"]

        [bus.hosts.sound]
        connect = ["{robot.endpoint()}"]

        [nodes.robot]
        host = "robot"
        robot = "pepper"
        {sim(rate)}
        [nodes.sound]
        host = "sound"
        subscribe = ["pepper/joints/*", "pepper/events/*"]
        {SINK}
        {nodes}
        """)


def start_pair(topology: Topology, path: str, robot: Host, sound: Host) -> tuple[OscDump, NsProcess, NsProcess]:
    dump = sound.oscdump()
    robot_run, sound_run = run_show(topology, path, robot, sound)
    streaming(topology, dump, count=RATE)  # a second of data
    return dump, robot_run, sound_run


def test_short_cut_within_the_lease_brings_no_stale_burst(topology, tmp_path, figure):
    robot, sound = topology.lan("robot", "sound")
    dump, _, _ = start_pair(topology, point_to_point(tmp_path, robot, "lease_ms = 10000", BURST_RATE), robot, sound)
    time.sleep(1.0)  # a second of steady streaming to compare with
    steady = most_in_window(joints(dump, since=time.time() - 1.0))
    figure("steady samples per 200 ms", steady)

    cut = topology.cut(sound)
    time.sleep(5.0)  # the deliberate outage, shorter than the 10 s lease
    during = joints(dump, since=cut + 0.5)
    restored = topology.restore(sound)
    assert not during, f"{len(during)} samples reached oscdump while the link was down"

    resumed = streaming(topology, dump, since=restored, count=RATE, timeout=10.0)[0]
    time.sleep(1.0)  # one more second of streaming after it resumed
    after = joints(dump, since=restored)
    first = [m for m in after if m.received < restored + WINDOW]
    burst = most_in_window(after)
    figure("samples in the first 200 ms after restore", len(first))
    figure("most samples in any 200 ms after restore", burst)
    figure("streaming resumed after restore", resumed.read - restored, "s")
    assert len(first) <= MAX_IN_WINDOW, f"{len(first)} samples in the first 200 ms after the link came back"
    assert burst <= MAX_IN_WINDOW, f"a burst of {burst} samples in 200 ms after the link came back " \
                                   f"(steady: {steady}, at most {MAX_IN_WINDOW})"
    assert not connection(dump, "lost"), "a 5 s cut within a 10 s lease was reported as a lost robot"


# "sound owns a robot too": both processes open a control session (bus/control.py); a close that
# held one of Zenoh's 2 link-reading threads for 10 s made "lost" take 11.5 s in 3 of 6 runs
# (ZENOH_RUNTIME in bus/session.py)
@pytest.mark.parametrize("sound_owns_a_robot", [False, True], ids=["sink only", "sound owns a robot too"])
def test_cut_longer_than_the_lease_is_lost_then_connected_again(topology, tmp_path, figure, sound_owns_a_robot):
    robot, sound = topology.lan("robot", "sound")
    nao = f"""
        [nodes.nao]
        host = "sound"
        robot = "nao"
        {SIM}
        """ if sound_owns_a_robot else ""
    dump, _, _ = start_pair(topology, point_to_point(tmp_path, robot, nodes=nao), robot, sound)
    until(topology, lambda: connection(dump, "connected"), 5.0, '"connected" at start')

    cut = topology.cut(robot)
    lost = until(topology, lambda: connection(dump, "lost", since=cut), 6.0, '"lost" after the cut')[0]
    figure("lost detected after the cut (read by the test)", lost.read - cut, "s")
    figure("lost detected after the cut (oscdump's stamp)", lost.received - cut, "s")
    # (spans by oscdump's own stamps: how late this busy test process reads its output is not the product's)
    assert lost.received - cut <= 2.5, f'"lost" took {lost.received - cut:.2f} s (lease 1.5 s)'

    restored = topology.restore(robot)
    again = until(topology, lambda: connection(dump, "connected", since=restored), 6.0,
                  '"connected" after the link came back')[0]
    data = streaming(topology, dump, since=restored, count=1, timeout=6.0)[0]
    figure('"connected" after restore', again.read - restored, "s")
    figure("joint data after restore", data.read - restored, "s")
    assert again.received - restored <= 2.0, \
        f'"connected" took {again.received - restored:.2f} s after the link came back'
    assert data.received - restored <= 2.0, f"joint data took {data.received - restored:.2f} s after the link came back"


def test_killed_robot_is_lost_at_once_and_found_again(topology, tmp_path, figure):
    robot, sound = topology.lan("robot", "sound")
    path = point_to_point(tmp_path, robot)
    dump, robot_run, sound_run = start_pair(topology, path, robot, sound)
    until(topology, lambda: connection(dump, "connected"), 5.0, '"connected" at start')

    killed = time.time()
    robot_run.kill()  # SIGKILL to its process group: no goodbye on the bus
    lost = until(topology, lambda: connection(dump, "lost", since=killed), 5.0, '"lost" after SIGKILL')[0]
    figure("lost after SIGKILL", lost.read - killed, "s")
    assert lost.received - killed <= 1.0, f'"lost" took {lost.received - killed:.2f} s after the robot was killed'

    restarted = time.time()
    started(topology, robot.sonibus("run", path, "--host", "robot"))
    again = until(topology, lambda: connection(dump, "connected", since=restarted), 10.0,
                  '"connected" after the robot restarted')[0]
    data = streaming(topology, dump, since=restarted, count=RATE, timeout=10.0)[0]
    figure('"connected" after restart', again.read - restarted, "s")
    figure("joint data after restart", data.read - restarted, "s")
    assert sound_run.running, "the sink process ended"


# -- 6. many robots, and installations kept apart ----------------------------------------


def test_two_robots_on_two_hosts_reach_one_sink(topology, tmp_path):
    hosta, hostb, sound = topology.lan("hosta", "hostb", "sound")
    path = show(tmp_path, f"""
        [bus]
        multicast = true

        [nodes.pepper]
        host = "hosta"
        robot = "pepper"
        {SIM}
        [nodes.nao]
        host = "hostb"
        robot = "nao"
        {SIM}
        [nodes.sound]
        host = "sound"
        subscribe = "*/joints/HeadYaw"
        {SINK}
        """)
    dump = sound.oscdump()
    run_show(topology, path, hosta, hostb, sound)
    streaming(topology, dump, "pepper")
    streaming(topology, dump, "nao")
    assert {m.address for m in dump.messages() if "/joints/" in m.address} == \
        {"/pepper/joints/HeadYaw", "/nao/joints/HeadYaw"}


def test_namespaces_keep_two_installations_on_one_lan_apart(topology, tmp_path):
    museum, lab, msound, lsound = topology.lan("museum", "lab", "msound", "lsound")

    def installation(name: str, robot: str, robot_host: str, sound_host: str) -> str:
        return show(tmp_path, f"""
            [bus]
            multicast = true
            namespace = "{name}"

            [nodes.robot]
            host = "{robot_host}"
            robot = "{robot}"
            {SIM}
            [nodes.sound]
            host = "{sound_host}"
            subscribe = "*/joints/*"
            {SINK}
            """, f"{name}.toml")

    museum_toml = installation("museum", "pepper", "museum", "msound")
    lab_toml = installation("lab", "pepper2", "lab", "lsound")
    museum_dump, lab_dump = msound.oscdump(), lsound.oscdump()
    runs = [museum.sonibus("run", museum_toml, "--host", "museum"),
            msound.sonibus("run", museum_toml, "--host", "msound"),
            lab.sonibus("run", lab_toml, "--host", "lab"),
            lsound.sonibus("run", lab_toml, "--host", "lsound")]
    for process in runs:
        started(topology, process)
    streaming(topology, museum_dump, "pepper")
    streaming(topology, lab_dump, "pepper2")
    time.sleep(1.0)  # both installations stream side by side for a while
    assert not museum_dump.messages("/pepper2/"), "the museum's sink got the lab's robot"
    assert not lab_dump.messages("/pepper/"), "the lab's sink got the museum's robot"


# -- 7. users, passwords and access control -------------------------------------------

DATA_MESSAGES = ["put", "delete", "declare_subscriber", "query", "reply", "declare_queryable",
                 "liveliness_token", "declare_liveliness_subscriber", "liveliness_query"]


def credentials(user: str, password: str) -> list[str]:
    """Bus options of a CLI process that logs in as ``user``."""
    return ["--zenoh", f"transport/auth/usrpwd/user={json.dumps(user)}",
            "--zenoh", f"transport/auth/usrpwd/password={json.dumps(password)}"]


def test_access_control_lets_control_command_and_sound_only_listen(topology, tmp_path):
    robot, control, sound, stranger = topology.lan("robot", "control", "sound", "stranger")
    users = tmp_path / "users.txt"
    users.write_text("control:ctrl-secret\nsound:sound-secret\nrobot:robot-secret\n", encoding="utf-8")
    endpoint = robot.endpoint()
    path = show(tmp_path, f"""
        [bus]
        mode = "peer"
        multicast = false
        connect = ["{endpoint}"]

        [bus.hosts.robot]
        connect = []
        listen = ["{endpoint}"]
        user = "robot"
        password = "robot-secret"
        users_file = "{users}"

        [bus.hosts.robot.access_control]
        enabled = true
        default_permission = "deny"

        [[bus.hosts.robot.access_control.rules]]
        id = "data"
        permission = "allow"
        flows = ["egress", "ingress"]
        messages = {json.dumps(DATA_MESSAGES)}
        key_exprs = ["*/frame", "*/joints/**", "*/derived/**", "*/events/**", "*/info", "*/info/**", "sonibus/**"]

        [[bus.hosts.robot.access_control.rules]]
        id = "commands"
        permission = "allow"
        flows = ["egress", "ingress"]
        messages = ["query", "reply", "declare_queryable"]
        key_exprs = ["*/cmd/**"]

        [[bus.hosts.robot.access_control.subjects]]
        id = "control"
        usernames = ["control"]

        [[bus.hosts.robot.access_control.subjects]]
        id = "sound"
        usernames = ["sound"]

        [[bus.hosts.robot.access_control.policies]]
        rules = ["data"]
        subjects = ["control", "sound"]

        [[bus.hosts.robot.access_control.policies]]
        rules = ["commands"]
        subjects = ["control"]

        [bus.hosts.control]
        user = "control"
        password = "ctrl-secret"

        [bus.hosts.sound]
        user = "sound"
        password = "sound-secret"

        [nodes.robot]
        host = "robot"
        robot = "pepper"
        {SIM}
        [nodes.sound]
        host = "sound"
        subscribe = ["pepper/joints/HeadYaw", "pepper/events/*"]
        {SINK}
        """)
    dump = sound.oscdump()
    run_show(topology, path, robot, sound)
    streaming(topology, dump)  # the sound user gets data
    bus = ["--no-multicast", "--connect", endpoint]

    sent(control.cli("send", "pepper", "stop", *bus, *credentials("control", "ctrl-secret")))

    before = joint(dump)[-1].value
    tried = time.time()
    refused = sound.cli("send", "pepper", "joints/set", "names=HeadYaw", "angles=1.0", "speed=1.0",
                        *bus, *credentials("sound", "sound-secret"))
    assert refused.returncode in (3, 4), f"the sound user's command: exit {refused.returncode}: {refused.stdout}"
    time.sleep(1.5)  # the head would be at 1.0 within ~0.5 s had the command gone through
    seen = joint(dump, since=tried)
    assert seen, "no HeadYaw samples while checking that the robot stayed still"
    assert all(abs(m.value - before) < 0.02 for m in seen), \
        f"HeadYaw moved from {before} after a refused command: {[m.value for m in seen][-5:]}"

    moved = time.time()
    sent(control.cli("send", "pepper", "joints/set", "names=HeadYaw", "angles=0.5", "speed=1.0",
                     *bus, *credentials("control", "ctrl-secret")))
    reaches(topology, dump, 0.5, moved)

    assert robots_listed(control.cli("nodes", "--timeout", "2", *bus, *credentials("control", "ctrl-secret"))) == 1
    assert robots_listed(stranger.cli("nodes", "--timeout", "2", *bus, *credentials("sound", "wrong"))) == 0


# -- 8. mutual TLS ---------------------------------------------------------------------


def openssl(*args: str, cwd: Path) -> None:
    done = subprocess.run(["openssl", *args], cwd=cwd, capture_output=True, text=True, timeout=30)
    if done.returncode != 0:
        pytest.fail(f"openssl {' '.join(args)}: {done.stderr}")


def make_ca(folder: Path, name: str) -> None:
    openssl("req", "-x509", "-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:P-256", "-nodes", "-days", "2",
            "-keyout", f"{name}.key", "-out", f"{name}.crt", "-subj", f"/CN={name}",
            "-addext", "basicConstraints=critical,CA:TRUE", "-addext", "keyUsage=critical,keyCertSign,cRLSign",
            cwd=folder)


def make_cert(folder: Path, ca: str, name: str, address: str) -> None:
    """A certificate for host ``name`` (CN and DNS name; ``address`` as IP SAN), signed by ``ca``."""
    (folder / f"{name}.ext").write_text(
        f"subjectAltName = DNS:{name}, IP:{address}\nbasicConstraints = CA:FALSE\n"
        "keyUsage = critical, digitalSignature\nextendedKeyUsage = serverAuth, clientAuth\n", encoding="utf-8")
    openssl("req", "-new", "-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:P-256", "-nodes",
            "-keyout", f"{name}.key", "-out", f"{name}.csr", "-subj", f"/CN={name}", cwd=folder)
    openssl("x509", "-req", "-in", f"{name}.csr", "-CA", f"{ca}.crt", "-CAkey", f"{ca}.key", "-CAcreateserial",
            "-days", "2", "-extfile", f"{name}.ext", "-out", f"{name}.crt", cwd=folder)


def test_mutual_tls_keeps_a_foreign_certificate_out(topology, tmp_path):
    robot, sound, intruder = topology.lan("robot", "sound", "intruder")
    pki = tmp_path / "pki"
    pki.mkdir()
    make_ca(pki, "ca")
    make_ca(pki, "foreign")
    for host in (robot, sound):
        make_cert(pki, "ca", host.name, host.address)
    make_cert(pki, "foreign", intruder.name, intruder.address)

    def tls(name: str) -> str:
        return (f'tls = {{ root_ca = "{pki}/ca.crt", cert = "{pki}/{name}.crt", key = "{pki}/{name}.key", '
                f'mutual = true }}')

    endpoint = robot.endpoint(proto="tls")
    path = show(tmp_path, f"""
        [bus]
        mode = "peer"
        multicast = false
        connect = ["{endpoint}"]

        [bus.hosts.robot]
        connect = []
        listen = ["{endpoint}"]
        {tls("robot")}

        [bus.hosts.sound]
        {tls("sound")}

        [bus.hosts.intruder]
        {tls("intruder")}

        [nodes.robot]
        host = "robot"
        robot = "pepper"
        {SIM}
        [nodes.sound]
        host = "sound"
        subscribe = "pepper/joints/*"
        {SINK}
        [nodes.eavesdrop]
        host = "intruder"
        subscribe = "pepper/joints/*"
        {SINK}
        """)
    dumps = {host.name: host.oscdump() for host in (sound, intruder)}
    robot_run = robot.sonibus("run", path, "--host", "robot")
    started(topology, robot_run)
    sound_run, intruder_run = sound.sonibus("run", path, "--host", "sound"), \
        intruder.sonibus("run", path, "--host", "intruder")
    started(topology, sound_run)
    streaming(topology, dumps["sound"], count=2 * RATE)

    def raw_tls(name: str) -> list[str]:
        options = {"root_ca_certificate": f"{pki}/ca.crt", "connect_certificate": f"{pki}/{name}.crt",
                   "connect_private_key": f"{pki}/{name}.key", "enable_mtls": True}
        return [item for key, value in options.items()
                for item in ("--zenoh", f"transport/link/tls/{key}={json.dumps(value)}")]

    bus = ["--no-multicast", "--connect", endpoint]
    assert robots_listed(sound.cli("nodes", "--timeout", "2", *bus, *raw_tls("sound"))) == 1
    assert robots_listed(intruder.cli("nodes", "--timeout", "2", *bus, *raw_tls("intruder"))) == 0
    assert not dumps["intruder"].messages("/pepper/"), \
        f"the intruder's sink got data: {intruder_run.describe()}"
