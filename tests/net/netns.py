"""Machines and networks for multi-host tests, out of Linux network namespaces.

Every host is a namespace with ``lo`` and one ``eth0``; a LAN is a Linux bridge
living in a "switch" namespace of its own, with one veth pair per host (``eth0``
in the host, port ``pN`` on the bridge). Two subnets are two LANs joined by a
router namespace that has one interface on each and does *not* forward IP
(``net.ipv4.ip_forward=0``), so only a Zenoh router can join them. Addresses
come from 10.213.0.0/16, used nowhere else: LAN k is 10.213.k.0/24, hosts get
.1, .2, ... in the order named, the router .254.

Everything runs in real processes started with ``ip netns exec NS ...``; the
test process stays in the root namespace. ``Topology.close`` kills every process
it started (process group SIGKILL) and whatever else lives in its namespaces,
and deletes the namespaces — also when the test failed. Namespaces left by a
crashed run (their owner pid is gone) are deleted by ``remove_stale``.

    topology.lan("robot", "sound")        -> [Host robot 10.213.1.1, Host sound 10.213.1.2]
    topology.subnets(["robot"], ["sound"]) -> Subnets(groups=[[robot], [sound]], router=...)
    topology.cut(host) / restore(host)     -> the host's switch port down / up
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import signal
import subprocess
import threading
import time
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest

from ..conftest import SONIBUS, Process, require_tool, wait_for
from ..osc.pd import PROBE

NET = "10.213"
OWNERS = Path("/run/sonibus-netns")       # one file per namespace: the pid of the run that made it
NAME = re.compile(r"^sb\d+-[a-z0-9-]+$")  # sb<pid % 1000><n>-<host>
NTP_EPOCH = 2208988800                    # seconds from 1900-01-01 (OSC timetags) to 1970-01-01


def root_reason() -> str | None:
    """Why namespaces cannot be made here, or None."""
    if os.geteuid() != 0:
        return f"network namespaces need root: running as uid {os.geteuid()} (CI runs the suite as root)"
    return None


def require_root() -> None:
    """Fail (in CI, which runs as root: a missing capability is a failure there) or skip a test
    that needs network namespaces where they cannot be made."""
    reason = root_reason()
    if reason is None:
        return
    if os.environ.get("CI"):
        pytest.fail(reason)
    pytest.skip(reason)


def ip(*args: str, check: bool = True, timeout: float = 10.0) -> subprocess.CompletedProcess[str]:
    """``ip ARGS``; a failure fails the test with ip's message."""
    done = subprocess.run(["ip", *args], capture_output=True, text=True, timeout=timeout)
    if check and done.returncode != 0:
        pytest.fail(f"ip {' '.join(args)}: {done.stderr.strip() or done.stdout.strip()}")
    return done


def namespaces() -> list[str]:
    out = subprocess.run(["ip", "netns", "list"], capture_output=True, text=True).stdout
    return [line.split()[0] for line in out.splitlines() if line.strip()]


def kill_inside(ns: str) -> None:
    """SIGKILL every process living in namespace ``ns``."""
    pids = subprocess.run(["ip", "netns", "pids", ns], capture_output=True, text=True).stdout.split()
    for pid in pids:
        with contextlib.suppress(ProcessLookupError, ValueError):
            os.kill(int(pid), signal.SIGKILL)


def delete_namespace(ns: str) -> None:
    kill_inside(ns)
    subprocess.run(["ip", "netns", "del", ns], capture_output=True, text=True)
    (OWNERS / ns).unlink(missing_ok=True)


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def remove_stale() -> list[str]:
    """Delete namespaces of ours whose run is gone (a crashed or killed pytest); their names."""
    removed = []
    for ns in namespaces():
        if not NAME.match(ns):
            continue
        try:
            owner = int((OWNERS / ns).read_text().strip())
        except (OSError, ValueError):
            owner = 0
        if owner and _alive(owner):
            continue  # another run, alive: leave it alone
        delete_namespace(ns)
        removed.append(ns)
    return removed


# -- processes -----------------------------------------------------------------------


@dataclass(frozen=True)
class Message:
    """One line of ``oscdump``: when oscdump got it (its own clock, epoch seconds),
    when this process read it (``time.time()``), the address and the arguments."""

    received: float
    read: float
    address: str
    args: str

    @property
    def value(self) -> float:
        """The first argument as a number (``f 0.500000`` → 0.5)."""
        return float(self.args.split()[1])

    @property
    def text(self) -> str:
        """The first argument as a string (``s "lost"`` → ``lost``)."""
        return self.args.split(None, 1)[1].strip('"')


class NsProcess(Process):
    """A ``Process`` inside a namespace: stdout lines in ``lines`` (each read time in
    ``stamps``, ``time.time()``) and stderr lines in ``errors``, both read as they come,
    so a chatty process never blocks on a full pipe."""

    def __init__(self, args: list[str], collect: bool = True, **kwargs: Any) -> None:
        self.stamps: list[float] = []
        self.errors: list[str] = []
        super().__init__(args, collect=collect, **kwargs)
        self._threads = [threading.Thread(target=self._collect_errors, daemon=True)]
        self._threads[0].start()

    def _collect(self) -> None:
        for line in self.popen.stdout:
            self.stamps.append(time.time())
            self.lines.append(line.rstrip("\n"))

    def _collect_errors(self) -> None:
        for line in self.popen.stderr:
            self.errors.append(line.rstrip("\n"))

    @property
    def running(self) -> bool:
        return self.popen.poll() is None

    def stop(self, sig: int = signal.SIGINT, timeout: float = 5.0) -> tuple[int, str, str]:
        if self.popen.poll() is None:
            self.popen.send_signal(sig)
        try:
            self.popen.wait(timeout)
        except subprocess.TimeoutExpired:
            self.kill()
            pytest.fail(f"{self.popen.args} did not end within {timeout} s of signal {sig}")
        for thread in self._threads:
            thread.join(1.0)
        return self.popen.returncode, "\n".join(self.lines), "\n".join(self.errors)

    def kill(self) -> None:
        if self.popen.poll() is None:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(self.popen.pid, signal.SIGKILL)
        with contextlib.suppress(subprocess.TimeoutExpired):
            self.popen.wait(5.0)

    def describe(self) -> str:
        """The command, whether it runs, and what it said: for failure messages."""
        state = "running" if self.running else f"exited {self.popen.returncode}"
        tail = (self.lines[-5:] + self.errors[-10:])
        return f"{' '.join(self.popen.args[4:])} ({state}): " + " | ".join(tail)


_OSC_LINE = re.compile(r"^([0-9a-f]{8})\.([0-9a-f]{8}) (\S+) ?(.*)$")


class OscDump(NsProcess):
    """``oscdump -L PORT`` in a namespace, its lines parsed into ``Message``s."""

    def messages(self, prefix: str = "/") -> list[Message]:
        """Messages whose address starts with ``prefix`` (the readiness probes left out)."""
        out = []
        for line, read in zip(list(self.lines), list(self.stamps), strict=False):
            match = _OSC_LINE.match(line)
            if match is None or match[3] == PROBE or not match[3].startswith(prefix):
                continue
            received = int(match[1], 16) - NTP_EPOCH + int(match[2], 16) / 2**32
            out.append(Message(received, read, match[3], match[4]))
        return out

    def since(self, when: float, prefix: str = "/") -> list[Message]:
        """Messages read at or after ``when`` (``time.time()``)."""
        return [m for m in self.messages(prefix) if m.read >= when]

    def events(self, robot: str, kind: str = "connection") -> list[Message]:
        return self.messages(f"/{robot}/events/{kind}")

    def last(self, address: str) -> Message | None:
        found = self.messages(address)
        return found[-1] if found else None


# -- machines --------------------------------------------------------------------------


@dataclass(eq=False)
class Host:
    """One machine: a namespace with ``lo`` and ``eth0`` (address ``address``)."""

    topology: Topology
    name: str
    ns: str
    addresses: list[str] = field(default_factory=list)
    switch: str = ""  # the switch namespace of eth0's LAN
    port: str = ""    # eth0's peer on that switch's bridge

    @property
    def address(self) -> str:
        return self.addresses[0]

    def endpoint(self, port: int = 7447, proto: str = "tcp") -> str:
        return f"{proto}/{self.address}:{port}"

    def command(self, *args: str) -> list[str]:
        return ["ip", "netns", "exec", self.ns, *args]

    def run(self, *args: str, collect: bool = True, cls: type[NsProcess] = NsProcess) -> NsProcess:
        """Start ``args`` inside this host; ended (process group SIGKILL) when the topology closes."""
        return self.topology.track(cls(self.command(*args), collect=collect))

    def sonibus(self, *args: str) -> NsProcess:
        """A long-running ``sonibus ARGS`` in this host (``run``, ``router``)."""
        return self.run(SONIBUS, *args)

    def call(self, *args: str, timeout: float = 30.0) -> subprocess.CompletedProcess[str]:
        """Run ``args`` in this host to completion."""
        try:
            return subprocess.run(self.command(*args), capture_output=True, text=True, timeout=timeout)
        except subprocess.TimeoutExpired as exc:
            pytest.fail(f"{' '.join(args)} on {self.name} did not end within {timeout} s: {exc.stderr}")

    def cli(self, *args: str, timeout: float = 30.0) -> subprocess.CompletedProcess[str]:
        """``sonibus ARGS`` in this host to completion (``send``, ``nodes``)."""
        return self.call(SONIBUS, *args, timeout=timeout)

    def oscdump(self, port: int = 9000, timeout: float = 10.0) -> OscDump:
        """``oscdump -L PORT`` in this host, returned once it prints what it receives
        (a probe sent with ``oscsend`` from inside this host reached it)."""
        require_tool("oscdump", "liblo-tools")
        require_tool("oscsend", "liblo-tools")
        dump = self.run("oscdump", "-L", str(port), cls=OscDump)
        deadline = time.monotonic() + timeout
        while not any(PROBE in line for line in list(dump.lines)):
            if not dump.running or time.monotonic() > deadline:
                pytest.fail(f"oscdump on {self.name} port {port} did not start: {dump.describe()}")
            self.call("oscsend", "127.0.0.1", str(port), PROBE, timeout=5.0)
            time.sleep(0.05)
        return dump

    def sent_packets(self, interface: str = "eth0") -> int:
        """Packets this host has sent out of ``interface`` so far (the kernel's counter)."""
        done = ip("-n", self.ns, "-s", "-j", "link", "show", interface)
        return int(json.loads(done.stdout)[0]["stats64"]["tx"]["packets"])

    def without_ipv6(self) -> None:
        """No IPv6 on this host: the kernel then sends nothing by itself (router solicitations,
        multicast listener reports), so what leaves ``eth0`` is what its processes sent."""
        for setting in ("net.ipv6.conf.all.disable_ipv6=1", "net.ipv6.conf.default.disable_ipv6=1",
                        "net.ipv6.conf.eth0.disable_ipv6=1"):
            self.topology._sysctl(self.ns, setting)

    def __repr__(self) -> str:
        return f"<Host {self.name} {self.ns} {' '.join(self.addresses)}>"


@dataclass
class Subnets:
    """Two (or more) LANs joined by ``router``, which does not forward IP."""

    groups: list[list[Host]]
    router: Host


class Topology:
    """The namespaces, links and processes of one test; ``close`` removes them all."""

    _count = 0

    def __init__(self) -> None:
        for tool in ("ip", "sysctl"):
            require_tool(tool, "iproute2" if tool == "ip" else "procps")
        Topology._count += 1
        self.prefix = self._free_prefix()
        self.namespaces: list[str] = []
        self.processes: list[NsProcess] = []
        self.hosts: dict[str, Host] = {}
        self._lans = 0

    def _free_prefix(self) -> str:
        taken = set(namespaces())
        while True:
            prefix = f"sb{os.getpid() % 1000}{Topology._count}"
            if not any(ns.startswith(prefix + "-") for ns in taken):
                return prefix
            Topology._count += 1

    # -- building -------------------------------------------------------------------

    def namespace(self, role: str) -> str:
        ns = f"{self.prefix}-{role}"
        ip("netns", "add", ns)
        self.namespaces.append(ns)
        OWNERS.mkdir(parents=True, exist_ok=True)
        (OWNERS / ns).write_text(str(os.getpid()))
        ip("-n", ns, "link", "set", "lo", "up")
        return ns

    def _switch(self) -> tuple[str, int]:
        """A new switch namespace with bridge ``br0``; its LAN number."""
        self._lans += 1
        lan = self._lans
        ns = self.namespace(f"sw{lan}")
        ip("-n", ns, "link", "add", "br0", "type", "bridge", "mcast_snooping", "0")
        ip("-n", ns, "link", "set", "br0", "up")
        return ns, lan

    def _plug(self, ns: str, ifname: str, switch: str, port: str, address: str) -> None:
        """A veth from ``ns`` (``ifname``, with ``address``/24) to the bridge of ``switch``."""
        ip("link", "add", ifname, "netns", ns, "type", "veth", "peer", "name", port, "netns", switch)
        ip("-n", switch, "link", "set", port, "master", "br0")
        ip("-n", switch, "link", "set", port, "up")
        ip("-n", ns, "addr", "add", f"{address}/24", "dev", ifname)
        ip("-n", ns, "link", "set", ifname, "up")

    def _host(self, name: str, switch: str, lan: int, index: int) -> Host:
        if name in self.hosts:
            pytest.fail(f"host name '{name}' used twice in one topology")
        if not re.fullmatch(r"[a-z][a-z0-9]{0,9}", name):
            pytest.fail(f"host name '{name}': lowercase letters and digits, at most 10")
        ns = self.namespace(name)
        port = f"p{index}"
        self._plug(ns, "eth0", switch, port, f"{NET}.{lan}.{index}")
        # Zenoh's multicast scouting (224.0.0.224:7446) goes out of eth0.
        ip("-n", ns, "route", "add", "224.0.0.0/4", "dev", "eth0")
        host = Host(self, name, ns, [f"{NET}.{lan}.{index}"], switch, port)
        self.hosts[name] = host
        return host

    def lan(self, *names: str) -> list[Host]:
        """Hosts ``names`` on one new LAN (10.213.k.1, .2, ... in this order)."""
        switch, lan = self._switch()
        hosts = [self._host(name, switch, lan, index) for index, name in enumerate(names, 1)]
        self._wait_carrier(hosts)
        return hosts

    def subnets(self, *groups: Sequence[str], router: str = "router") -> Subnets:
        """One LAN per group of host names, and a router namespace with an interface
        (``ethK``, address 10.213.k.254) on each and IP forwarding off. Every host has a
        default route through the router, so what does not cross is not for want of a route."""
        if len(groups) < 2:
            pytest.fail("subnets() needs two groups of hosts or more")
        router_ns = self.namespace(router)
        self._sysctl(router_ns, "net.ipv4.ip_forward=0")
        router_host = Host(self, router, router_ns)
        out: list[list[Host]] = []
        for k, names in enumerate(groups):
            switch, lan = self._switch()
            gateway = f"{NET}.{lan}.254"
            self._plug(router_ns, f"eth{k}", switch, "p254", gateway)
            router_host.addresses.append(gateway)
            hosts = [self._host(name, switch, lan, index) for index, name in enumerate(names, 1)]
            for host in hosts:
                ip("-n", host.ns, "route", "add", "default", "via", gateway)
            out.append(hosts)
        self.hosts[router] = router_host
        forward = router_host.call("sysctl", "-n", "net.ipv4.ip_forward").stdout.strip()
        if forward != "0":
            pytest.fail(f"router {router_ns}: net.ipv4.ip_forward is {forward!r}, wanted 0")
        self._wait_carrier([h for group in out for h in group])
        return Subnets(out, router_host)

    def _sysctl(self, ns: str, setting: str) -> None:
        done = subprocess.run(["ip", "netns", "exec", ns, "sysctl", "-w", setting], capture_output=True, text=True)
        if done.returncode != 0:
            pytest.fail(f"sysctl -w {setting} in {ns}: {done.stderr.strip()}")

    def _wait_carrier(self, hosts: Iterable[Host]) -> None:
        for host in hosts:
            wait_for(lambda h=host: "LOWER_UP" in ip("-n", h.ns, "link", "show", "eth0").stdout, 5.0,
                     f"{host.name}'s eth0 to come up")

    # -- links ------------------------------------------------------------------------

    def cut(self, host: Host) -> float:
        """Take ``host``'s link down at the switch (its address and routes stay);
        the time (``time.time()``) just before the command."""
        when = time.time()
        ip("-n", host.switch, "link", "set", host.port, "down")
        return when

    def restore(self, host: Host) -> float:
        """Bring ``host``'s link back; the time (``time.time()``) just after it is up."""
        ip("-n", host.switch, "link", "set", host.port, "up")
        return time.time()

    # -- processes and the end ---------------------------------------------------------

    def track(self, process: NsProcess) -> NsProcess:
        self.processes.append(process)
        return process

    def report(self) -> str:
        """Every process and what it said last: for failure messages."""
        return "\n".join(p.describe() for p in self.processes)

    def close(self) -> None:
        for process in self.processes:
            process.kill()
        for ns in reversed(self.namespaces):
            delete_namespace(ns)
        self.namespaces.clear()
