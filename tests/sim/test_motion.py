"""The simulator itself: its joint model without a bus, then what it streams
over real Zenoh sessions (rates, frames, joint tables, speeds, behaviors,
idling, ownership)."""

from __future__ import annotations

import itertools
import time
from typing import Any

import pytest

from sonibus.adapters.sim import SimConfig, SimRobot
from sonibus.adapters.sim.behaviors import LIBRARY
from sonibus.adapters.sim.motion import STIFF, Body
from sonibus.bus import Bus, OwnershipError, decode, load_model, robot_info, send_command

from ..conftest import wait_for
from ..pacing import drift_frames

# Joint tables of ../shared/reference/robots.json, written out here so that the
# simulator's own copy of the data is checked, not trusted.
PEPPER_17 = ["HeadPitch", "HeadYaw", "HipPitch", "HipRoll", "KneePitch", "LElbowRoll", "LElbowYaw", "LHand",
             "LShoulderPitch", "LShoulderRoll", "LWristYaw", "RElbowRoll", "RElbowYaw", "RHand", "RShoulderPitch",
             "RShoulderRoll", "RWristYaw"]  # "body_joint_names_17"
NAO_26 = ["HeadYaw", "HeadPitch", "LShoulderPitch", "LShoulderRoll", "LElbowYaw", "LElbowRoll", "LWristYaw", "LHand",
          "LHipYawPitch", "LHipRoll", "LHipPitch", "LKneePitch", "LAnklePitch", "LAnkleRoll", "RHipYawPitch",
          "RHipRoll", "RHipPitch", "RKneePitch", "RAnklePitch", "RAnkleRoll", "RShoulderPitch", "RShoulderRoll",
          "RElbowYaw", "RElbowRoll", "RWristYaw", "RHand"]  # "body_joint_order_getBodyNames_Body"
JOINTS = {"pepper": PEPPER_17, "nao": NAO_26}

VELOCITY_SLACK = 1.01   # 1 % on top of max velocity ...
EPSILON = 1e-9          # ... and float noise


# -- helpers --------------------------------------------------------------------

class Samples:
    """Every joint sample of ``keyexpr``, decoded: ``(key, message)`` in arrival order."""

    def __init__(self, bus: Bus, keyexpr: str) -> None:
        self.subscriber, self.queue = bus.subscribe(keyexpr, maxlen=1_000_000)
        self.items: list[tuple[str, dict[str, Any]]] = []
        self.latest: dict[str, dict[str, Any]] = {}

    def poll(self) -> list[tuple[str, dict[str, Any]]]:
        while (item := self.queue.get(timeout=0)) is not None:
            key, payload = item
            message = decode(payload)
            self.items.append((key, message))
            self.latest[key] = message
        return self.items

    def span(self) -> float:
        """Seconds of robot time covered so far."""
        items = self.poll()
        return items[-1][1]["t"] - items[0][1]["t"] if items else 0.0

    def collect(self, seconds: float, timeout: float = 10.0) -> list[tuple[str, dict[str, Any]]]:
        """Wait until ``seconds`` of robot time have been received."""
        wait_for(lambda: self.span() >= seconds, timeout, f"{seconds} s of samples")
        return self.items

    def series(self) -> dict[str, list[dict[str, Any]]]:
        """Samples per joint name, by ``seq``."""
        out: dict[str, list[dict[str, Any]]] = {}
        for key, message in self.poll():
            out.setdefault(key.rsplit("/", 1)[1], []).append(message)
        return {joint: sorted(ms, key=lambda m: m["seq"]) for joint, ms in out.items()}

    def keys(self) -> set[str]:
        return {key for key, _ in self.poll()}


def check_limits_and_speed(model_name: str, series: dict[str, list[dict[str, Any]]], fraction: float = 1.0) -> None:
    """Every sample within [min, max]; between consecutive frames no joint faster
    than ``fraction`` of its max velocity (measured with the samples' ``t``)."""
    model = load_model(model_name)
    for joint, samples in series.items():
        spec = model.joint(joint)
        for m in samples:
            assert spec.min <= m["v"] <= spec.max, f"{model_name} {joint} = {m['v']} outside [{spec.min}, {spec.max}]"
        for a, b in itertools.pairwise(samples):
            dt = b["t"] - a["t"]
            assert dt > 0, f"{joint}: t does not increase from seq {a['seq']} to {b['seq']}"
            speed = abs(b["v"] - a["v"])
            allowed = fraction * spec.max_velocity * dt * VELOCITY_SLACK + EPSILON
            assert speed <= allowed, (f"{model_name} {joint} moved {speed:.5f} in {dt:.4f} s between seq {a['seq']} "
                                      f"and {b['seq']}: {speed / dt:.3f} > {fraction} x {spec.max_velocity}")


# -- the joint model, no bus ------------------------------------------------------

@pytest.mark.parametrize(("model_name", "joint", "target"), [
    ("pepper", "HeadYaw", 1.5), ("pepper", "HipPitch", -0.9), ("pepper", "RHand", 0.02), ("nao", "LKneePitch", 2.0),
])
def test_move_at_half_speed_takes_delta_over_half_max_velocity(model_name, joint, target):
    model = load_model(model_name)
    body = Body(model, model.posture("StandInit"))
    start = body.pose()[joint]
    expected = abs(target - start) / (0.5 * model.joint(joint).max_velocity)
    body.set_targets({joint: target}, 0.5)
    dt, steps = 0.01, 0
    while body.moving():
        body.step(dt)
        steps += 1
        assert steps < 100_000
    assert body.pose()[joint] == target
    assert expected - EPSILON <= steps * dt < expected + dt + EPSILON, (steps * dt, expected)


@pytest.mark.parametrize("fraction", [0.25, 1.0, 3.0])
@pytest.mark.parametrize("dt", [0.001, 0.02, 0.1])
def test_a_step_never_exceeds_max_velocity(fraction, dt):
    model = load_model("pepper")
    body = Body(model, model.posture("StandInit"))
    body.set_targets({j.name: j.max if i % 2 else j.min for i, j in enumerate(model.joints)}, fraction)
    for _ in range(int(2.0 / dt)):
        before = list(body.positions)
        body.step(dt)
        for spec, a, b in zip(model.joints, before, body.positions, strict=True):
            allowed = min(fraction, 1.0) * spec.max_velocity * dt + EPSILON
            assert abs(b - a) <= allowed, f"{spec.name} moved {abs(b - a)} in {dt} s (allowed {allowed})"


def test_targets_are_clamped_to_the_limits():
    model = load_model("pepper")
    body = Body(model)
    body.set_targets({"HeadYaw": 10.0, "HeadPitch": -10.0, "LHand": 2.0, "RHand": -1.0}, 1.0)
    for _ in range(200):
        body.step(0.02)
        for spec, v in zip(model.joints, body.positions, strict=True):
            assert spec.min <= v <= spec.max, f"{spec.name} = {v}"
    pose = body.pose()
    assert pose["HeadYaw"] == model.joint("HeadYaw").max
    assert pose["HeadPitch"] == model.joint("HeadPitch").min
    assert pose["LHand"] == model.joint("LHand").max
    assert pose["RHand"] == model.joint("RHand").min
    assert not body.moving()


def test_a_start_pose_is_clamped_to_the_limits():
    model = load_model("pepper")
    body = Body(model, {"HeadYaw": 5.0, "KneePitch": -3.0})
    assert body.pose()["HeadYaw"] == model.joint("HeadYaw").max
    assert body.pose()["KneePitch"] == model.joint("KneePitch").min


def test_stiffness_below_threshold_holds():
    model = load_model("pepper")
    body = Body(model, model.posture("StandInit"))
    start = body.pose()
    body.set_stiffness(["HeadYaw"], STIFF - 0.01)
    body.set_targets({"HeadYaw": 1.0, "HeadPitch": 0.3}, 1.0)
    for _ in range(100):
        body.step(0.02)
    assert body.pose()["HeadYaw"] == start["HeadYaw"]
    assert body.pose()["HeadPitch"] == 0.3  # a stiff joint of the same command moves
    assert not body.moving(), "a limp joint must not count as moving (a posture would never be reached)"
    body.set_stiffness(["HeadYaw"], STIFF)
    body.set_targets({"HeadYaw": 1.0}, 1.0)
    body.step(0.02)
    assert body.pose()["HeadYaw"] != start["HeadYaw"], f"stiffness {STIFF} must drive the joint"


def test_halt_holds_where_the_joints_are():
    model = load_model("pepper")
    body = Body(model, model.posture("StandInit"))
    body.set_targets({"HeadYaw": 2.0}, 0.1)
    body.step(0.1)
    body.halt()
    held = body.pose()
    for _ in range(10):
        body.step(0.02)
    assert body.pose() == held
    assert not body.moving()


@pytest.mark.parametrize("dt", [0.0, -0.05, -1.0])
def test_a_step_never_moves_a_joint_away_from_its_target_or_out_of_its_limits(dt):
    # The frame loop's dt is a difference of wall-clock times (time.time()); an
    # NTP step backwards makes it negative.
    model = load_model("pepper")
    body = Body(model, model.posture("StandInit"))
    body.set_targets({"HeadYaw": 2.0, "HipPitch": 1.0}, 1.0)
    body.step(0.05)
    before = body.pose()
    body.step(dt)
    after = body.pose()
    for joint, target in (("HeadYaw", 2.0), ("HipPitch", 1.0)):
        spec = model.joint(joint)
        assert spec.min <= after[joint] <= spec.max, f"{joint} = {after[joint]} after step({dt})"
        assert abs(target - after[joint]) <= abs(target - before[joint]), (
            f"step({dt}) moved {joint} away from its target: {before[joint]} -> {after[joint]}")


# -- over the bus -----------------------------------------------------------------

@pytest.mark.parametrize("rate_hz", [50, 100])
def test_published_rate_matches_rate_hz(net, rate_hz):
    net.sim("pepper", rate_hz=rate_hz, idle=False)
    head = Samples(net.bus("listener"), "pepper/joints/HeadYaw")
    items = head.collect(1.1)
    stamps = [(m["seq"], m["t"]) for _, m in items]
    assert len(stamps) >= 10 and [s for s, _ in stamps] == sorted({s for s, _ in stamps})
    # seq advances rate_hz a second of t (a busy machine skips frames: gaps in seq; the achieved
    # rate is bench/pacing.py's figure)
    drift = drift_frames(stamps, rate_hz)
    assert abs(drift) <= 1.0, f"seq drifts from t by {drift:.1f} frames in 1 s at rate_hz={rate_hz}"


def test_frames_share_t_and_seq_and_time_advances(net):
    net.sim("pepper", rate_hz=100, idle=False)
    samples = Samples(net.bus("listener"), "pepper/joints/*")
    items = samples.collect(0.5)
    now = time.time()
    frames: dict[int, dict[str, float]] = {}
    for key, m in items:
        assert abs(m["t"] - now) < 5.0, f"t = {m['t']} is not UNIX time (now {now})"
        frames.setdefault(m["seq"], {})[key] = m["t"]
    for seq, ts in frames.items():
        assert len(set(ts.values())) == 1, f"frame {seq}: joints carry different t: {set(ts.values())}"
    # streams drop under congestion (by design), so not every frame need be complete
    complete = {seq: ts for seq, ts in frames.items() if len(ts) == len(PEPPER_17)}
    assert len(complete) >= 20
    ordered = sorted(complete.items())
    for (s0, ts0), (s1, ts1) in itertools.pairwise(ordered):
        assert next(iter(ts1.values())) > next(iter(ts0.values())), f"t does not increase from seq {s0} to {s1}"
    for joint, series in samples.series().items():
        arrival = [m["seq"] for key, m in items if key.endswith("/" + joint)]
        assert arrival == sorted(set(arrival)), f"{joint}: seq repeated or out of order"
        assert len(series) == len(arrival)


def test_pacing_is_drift_free(net):
    rate_hz = 100
    net.sim("pepper", rate_hz=rate_hz, idle=False)
    head = Samples(net.bus("listener"), "pepper/joints/HeadYaw")
    items = head.collect(2.5)
    # Each frame is stamped when its thread wakes, a little late (very late on a busy machine:
    # then it skips frames, bench/pacing.py counts them); a loop that sleeps one period after
    # its work instead falls behind frame after frame.
    drift = drift_frames([(m["seq"], m["t"]) for _, m in items], rate_hz)
    assert abs(drift) <= 1.0, f"seq drifts from the clock by {drift:.2f} frames over 2.5 s"


@pytest.mark.parametrize("robot", ["pepper", "nao"])
def test_joint_table(net, robot):
    net.sim(robot, rate_hz=50, idle=False)
    listener = net.bus("listener")
    samples = Samples(listener, f"{robot}/joints/*")
    samples.collect(0.3)
    assert sorted(samples.keys()) == sorted(f"{robot}/joints/{j}" for j in JOINTS[robot])
    assert len(JOINTS[robot]) == {"pepper": 17, "nao": 26}[robot]
    info = robot_info(listener, robot)
    assert sorted(j["name"] for j in info["joints"]) == sorted(JOINTS[robot])


@pytest.mark.parametrize(("joint", "target"), [("HeadYaw", 2.0), ("HipPitch", 1.0)])
def test_joints_set_at_half_speed_takes_as_long_as_on_the_robot(net, joint, target):
    net.sim("pepper", rate_hz=100, idle=False)
    listener = net.bus("listener")
    samples = Samples(listener, f"pepper/joints/{joint}")
    start = samples.collect(0.05)[-1][1]["v"]
    expected = abs(target - start) / (0.5 * load_model("pepper").joint(joint).max_velocity)
    send_command(listener, "pepper", "joints/set", {"names": [joint], "angles": [target], "speed": 0.5})
    wait_for(lambda: samples.poll() and samples.latest[f"pepper/joints/{joint}"]["v"] == target,
             expected + 2.0, f"{joint} at {target}")
    series = samples.series()[joint]
    moving = [i for i, m in enumerate(series) if m["v"] != start]
    first_move, arrival = moving[0], next(i for i, m in enumerate(series) if m["v"] == target)
    measured = series[arrival]["t"] - series[first_move - 1]["t"]
    # never faster than the robot; slower only by frames a busy machine stalls (not the 2x of a speed taken twice)
    assert expected - EPSILON <= measured < 1.5 * expected, f"{measured:.3f} s, a robot takes {expected:.3f} s"
    check_limits_and_speed("pepper", {joint: series}, fraction=0.5)


def test_the_library_has_enough_behaviors():
    assert len(LIBRARY) >= 6
    for name, behavior in LIBRARY.items():
        assert name == behavior.name and name.startswith("animations/")
        assert 1.0 <= behavior.duration <= 4.0, f"{name} lasts {behavior.duration} s"


@pytest.mark.parametrize("name", sorted(LIBRARY))
def test_behavior_stays_within_limits_and_speeds(net, name):
    robots = ("pepper", "nao")
    for robot in robots:
        net.sim(robot, rate_hz=50, idle=False)
    listener = net.bus("listener")
    events = Samples(listener, "*/events/behavior")
    streams = {robot: Samples(listener, f"{robot}/joints/*") for robot in robots}
    for stream in streams.values():
        stream.collect(0.05)
    for robot in robots:
        send_command(listener, robot, "behavior/run", {"name": name})

    def stopped() -> bool:
        done = {key.split("/")[0] for key, m in events.poll() if m["name"] == name and m["state"] == "stopped"}
        return done == set(robots)

    wait_for(stopped, LIBRARY[name].duration + 5.0, f"'{name}' to stop on both robots")
    end = max(m["t"] for _, m in events.poll()) + 0.5
    for robot, stream in streams.items():
        # half a second of robot time after the end: a behavior returns to where it started
        wait_for(lambda s=stream: s.poll()[-1][1]["t"] >= end, 5.0, f"{robot} samples until {end}")
        start = {joint: ms[0]["v"] for joint, ms in stream.series().items()}
        final = {key.rsplit("/", 1)[1]: m["v"] for key, m in stream.latest.items()}
        assert final == start, f"{robot} did not return to where {name} started"
        series = stream.series()
        assert set(series) == set(JOINTS[robot])
        check_limits_and_speed(robot, series)
        travel = max(max(m["v"] for m in ms) - min(m["v"] for m in ms) for ms in series.values())
        assert travel > 0.1, f"{name} hardly moved {robot} ({travel:.3f})"


@pytest.mark.parametrize("idle", [True, False])
def test_idle_moves_and_not_idle_is_flat(net, idle):
    net.sim("pepper", rate_hz=50, idle=idle)
    samples = Samples(net.bus("listener"), "pepper/joints/*")
    samples.collect(1.0)
    series = samples.series()
    changing = {joint for joint, ms in series.items() if len({m["v"] for m in ms}) > 1}
    if idle:
        assert {"HeadYaw", "HeadPitch"} <= changing, f"idle stream is flat except {changing}"
        check_limits_and_speed("pepper", series)
    else:
        assert not changing, f"idle=False but {sorted(changing)} change"


def test_a_second_owner_refuses_to_start(net):
    net.sim("pepper", rate_hz=50, idle=False)
    listener = net.bus("listener")
    head = Samples(listener, "pepper/joints/HeadYaw")
    head.collect(0.05)
    second = SimRobot(SimConfig(robot="pepper", rate_hz=50), name="sim-pepper-backup")
    with pytest.raises(OwnershipError) as caught:
        net.start(second)
    message = str(caught.value)
    assert "'sim-pepper'" in message and "pepper" in message, message
    assert second.state == "stopped"
    # the first owner is untouched: it still streams, answers and is the only one
    seen = head.poll()[-1][1]["seq"]
    wait_for(lambda: head.poll()[-1][1]["seq"] >= seen + 10, 5.0, "the first owner to keep streaming")
    replies = listener.query("pepper/info", timeout=2.0)
    assert [r["owner"]["node"] for r in replies] == ["sim-pepper"]
    assert send_command(listener, "pepper", "behavior/list")["behaviors"]


def test_two_robots_on_one_bus_keep_their_keys_apart(net):
    shared = net.bus("robots")
    net.sim("pepper", bus=shared, rate_hz=50, idle=False)
    net.sim("nao", bus=shared, rate_hz=50, idle=False)
    listener = net.bus("listener")
    nao, pepper = Samples(listener, "nao/joints/*"), Samples(listener, "pepper/joints/*")
    nao.collect(0.3)
    pepper.collect(0.3)
    assert nao.keys() == {f"nao/joints/{j}" for j in NAO_26}
    assert pepper.keys() == {f"pepper/joints/{j}" for j in PEPPER_17}
    # a command to one moves that one only
    pepper_before = dict(pepper.latest)
    send_command(listener, "nao", "joints/set", {"names": ["HeadYaw"], "angles": [1.0], "speed": 1.0})
    wait_for(lambda: nao.poll() and nao.latest["nao/joints/HeadYaw"]["v"] == 1.0, 5.0, "nao's head to turn")
    pepper.collect(pepper.span() + 0.1)
    assert {k: m["v"] for k, m in pepper.latest.items()} == {k: m["v"] for k, m in pepper_before.items()}


def test_a_stop_holds_an_idling_robot_still_until_the_next_move():
    """The operator's STOP left examples/web.toml's robot breathing and looking around (idle
    motion), and an autoplaying demo started its next behavior: a stop means still."""
    from sonibus.adapters.sim.engine import SimEngine
    events: list[tuple[str, dict]] = []
    engine = SimEngine(load_model("pepper"), lambda kind, fields: events.append((kind, fields)), idle=True,
                       autoplay_s=0.05)
    now = 1000.0
    for _ in range(100):                                   # 2 s of idle motion (and autoplay)
        now += 0.02
        engine.advance(now, 0.02)
    engine.stop()
    for _ in range(25):                                    # let the halt settle
        now += 0.02
        engine.advance(now, 0.02)
    held = engine.advance(now + 0.02, 0.02)
    started = len([e for e in events if e[0] == "behavior" and e[1]["state"] == "started"])
    for step in range(2, 200):                             # 4 s more: nothing moves, nothing starts
        assert engine.advance(now + 0.02 * step, 0.02) == held
    assert len([e for e in events if e[0] == "behavior" and e[1]["state"] == "started"]) == started
    engine.joints_set(["HeadYaw"], [0.5], 0.5)             # the next move: idle motion again after it
    moved = [engine.advance(now + 4 + 0.02 * step, 0.02) for step in range(100)]
    assert moved[-1] != held


def test_offline_play_is_what_the_engine_plays(monkeypatch):
    """adapters/sim/offline.py (Hey_1's golden values in tests/features, the docs' plots) gives,
    frame for frame, the positions the engine gives on the same clock."""
    import types

    import sonibus.adapters.sim.engine as engine_module
    from sonibus.adapters.sim.engine import SimEngine
    from sonibus.adapters.sim.offline import play

    clock = [0.0]
    monkeypatch.setattr(engine_module, "time", types.SimpleNamespace(time=lambda: clock[0],
                                                                     monotonic=lambda: clock[0]))
    model = load_model("pepper")
    engine = SimEngine(model, lambda kind, fields: None)
    for k, (t, positions) in enumerate(play(model, "animations/Stand/Gestures/Hey_1", 50.0, 4.0)):
        clock[0] = t
        if k == 25:
            engine.behavior_run("animations/Stand/Gestures/Hey_1")
        assert engine.advance(t, 0.02) == positions, t
