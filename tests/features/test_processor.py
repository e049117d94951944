"""The ``features`` processor on a real bus: derived values with their frame's
``t`` and ``seq``, motion events from a simulated behavior, ``<robot>/info/derived``,
an unknown model, and bad input."""

from __future__ import annotations

import logging
import math
import threading
import time

import pytest
import zenoh

from sonibus import schemas
from sonibus.adapters.features import Features, FeaturesConfig
from sonibus.bus import ConfigError, decode, encode, framing, keys, load_model, robot_info, send_command
from sonibus.bus.info import InfoRequests

from ..conftest import queued_keys, wait_for
from ..wakes import left_after_stop, named, wakes
from .conftest import T0, model_info

HEY = "animations/Stand/Gestures/Hey_1"
PEPPER = load_model("pepper")


def start(net, **options) -> Features:
    """A features node; frames here carry made-up times (T0), so none is too old to compute."""
    return net.start(Features(FeaturesConfig(**{"max_age_ms": 0, **options}), name="features"))


class _Both:
    def __init__(self, *subscribers) -> None:
        self.subscribers = subscribers

    def undeclare(self) -> None:
        for subscriber in self.subscribers:
            subscriber.undeclare()


def collect(bus, pattern: str) -> tuple[object, list[tuple[str, dict]]]:
    """Every message on ``pattern`` as (key, decoded message), gathered as it comes; derived
    values come in derived frames (``<robot>/derived``): each of those on ``pattern`` as the
    sample its own key would carry."""
    got: list[tuple[str, dict]] = []
    lock = threading.Lock()
    wanted = zenoh.KeyExpr(keys.expr(pattern))

    def take(sample) -> None:
        key, message = str(sample.key_expr), decode(sample.payload.to_bytes())
        with lock:
            if keys.is_derived_frame(key):
                got.extend((f"{key}/{name}", part) for name, part in framing.derived_samples(message)
                           if wanted.intersects(zenoh.KeyExpr(f"{key}/{name}")))
            else:
                got.append((key, message))

    robot = pattern.split("/")[0]
    own = bus.session.declare_subscriber(wanted, take)
    if "derived" not in pattern or wanted.includes(zenoh.KeyExpr(keys.derived_frame(robot))):
        return own, got  # (pepper/derived/** takes pepper/derived too)
    return _Both(own, bus.session.declare_subscriber(keys.derived_frame(robot), take)), got


def test_derived_values_carry_their_frames_t_and_seq(net):
    watch = net.bus("watch")
    joints_sub, joints = collect(watch, "pepper/joints/HeadYaw")
    derived_sub, derived = collect(watch, "pepper/derived/**")
    net.sim("pepper", rate_hz=50)
    start(net, robots="pepper")
    wait_for(lambda: robot_info(watch, "pepper", timeout=0.5), what="pepper/info")
    send_command(watch, "pepper", "behavior/run", {"name": HEY})
    expected = {*(f"pepper/derived/velocity/{j}" for j in PEPPER.joint_names),
                *(f"pepper/derived/{f}/{s}" for f in ("hand", "hand_speed") for s in "LR"),
                *(f"pepper/derived/qom/{c}" for c in ("Head", "LArm", "Leg", "RArm", "Body"))}
    wait_for(lambda: {k for k, _ in list(derived)} == expected
             and any(k.endswith("qom/RArm") and m["v"] > 1.0 for k, m in list(derived)),
             what="every derived key, and the right arm moving")
    joints_sub.undeclare()
    derived_sub.undeclare()
    frames = {m["seq"]: m["t"] for _, m in joints}
    checked = 0
    for key, message in derived:
        schemas.validate("derived_sample", message)
        if message["seq"] in frames:
            assert message["t"] == frames[message["seq"]], key
            checked += 1
        size = 3 if "/hand/" in key else 1
        assert (len(message["v"]) if isinstance(message["v"], list) else 1) == size, key
    assert checked >= 0.9 * len(derived)
    hand = [m["v"] for k, m in derived if k == "pepper/derived/hand/R"]
    assert all(-0.6 < x < 0.6 for v in hand for x in v)


def test_every_derived_value_of_a_frame_goes_in_one_message_or_on_its_own_key(net):
    """By default one derived frame per robot and frame (issue 35: a sink paid per message for
    ~26 a frame), none on the per-value keys; ``per_key = true`` puts each on its own key, as before."""
    watch = net.bus("watch")
    got: list[tuple[str, dict]] = []
    subscriber = watch.session.declare_subscriber("pepper/derived/**", lambda s: got.append(
        (str(s.key_expr), decode(s.payload.to_bytes()))))
    net.sim("pepper", rate_hz=50)
    features = start(net, robots="pepper")
    wait_for(lambda: len(got) >= 5, what="derived frames")
    assert {key for key, _ in list(got)} == {"pepper/derived"}
    for _, message in list(got):
        schemas.validate("derived_frame", message)
    seqs = [m["seq"] for _, m in list(got)]
    assert len(seqs) == len(set(seqs))  # one message a frame
    assert "qom/Body" in got[-1][1]["names"] and "hand/R" in got[-1][1]["names"]  # (the first has no velocities)
    features.stop()
    got.clear()
    net.start(Features(FeaturesConfig(max_age_ms=0, robots="pepper", per_key=True), name="features2"))
    wait_for(lambda: len(got) >= 60, what="derived samples on their own keys")
    keys = [key for key, _ in list(got)]
    # (a frame of the first node still on its way when it stopped may come after the clear: what counts is
    # everything from the second node's first sample on, which one link delivers in order behind it)
    first = next(i for i, key in enumerate(keys) if key != "pepper/derived")
    assert "pepper/derived" not in keys[first:], keys
    assert "pepper/derived/qom/Body" in keys[first:]
    subscriber.undeclare()


def test_a_behavior_gives_one_onset_and_one_offset_for_the_arm_that_moves(net):
    watch = net.bus("watch")
    subscriber, events = collect(watch, "pepper/events/*")
    net.sim("pepper", rate_hz=50)
    features = start(net, robots="pepper")
    wait_for(lambda: features.stats["frames"] > 10, what="frames processed")
    send_command(watch, "pepper", "behavior/run", {"name": HEY})

    def motion(chain: str) -> list[dict]:
        return [m for k, m in list(events) if k == "pepper/events/motion" and m["chain"] == chain]

    wait_for(lambda: [m["state"] for m in motion("RArm")] == ["onset", "offset"], timeout=8,
             what="the right arm's onset and offset")
    stopped = wait_for(lambda: [m for k, m in list(events) if k == "pepper/events/behavior"
                                and m["state"] == "stopped"], what="the behavior's end")
    subscriber.undeclare()
    started = next(m for k, m in events if k == "pepper/events/behavior" and m["state"] == "started")
    onset, offset = motion("RArm")
    assert started["t"] - 0.05 <= onset["t"] <= started["t"] + 0.4
    assert stopped[0]["t"] - 0.6 <= offset["t"] <= stopped[0]["t"] + 0.5
    assert motion("LArm") == [] and motion("Leg") == []
    for _, message in events:
        schemas.validate("event", message)


def test_info_derived_is_served_and_merged_into_the_robots_info(net):
    net.sim("pepper", rate_hz=50)
    start(net, robots="pepper")
    watch = net.bus("watch")
    reply = wait_for(lambda: watch.query(keys.derived_info("pepper"), timeout=0.5), what="pepper/info/derived")[0]
    schemas.validate("derived_info", reply)
    assert "unavailable" not in reply
    entries = {d["name"]: d for d in reply["derived"]}
    assert entries["velocity/RHand"]["unit"] == "1/s" and entries["velocity/HeadYaw"]["unit"] == "rad/s"
    assert entries["hand/R"]["box"]["min"][2] < -0.2 < 0.4 < entries["hand/R"]["box"]["max"][2]
    assert entries["qom/Body"]["max"] == pytest.approx(sum(j.max_velocity for j in PEPPER.joints if j.unit == "rad"))
    assert reply["events"]["motion"]["chains"] == ["Head", "LArm", "Leg", "RArm"]

    answers: list[tuple[str, dict]] = []
    requests = InfoRequests(watch, lambda robot, info: answers.append((robot, info)), lambda robot, text: None)
    ghost = watch.serve(keys.derived_info("ghost"), lambda q: q.reply(keys.derived_info("ghost"), encode(reply)))
    requests.ask("ghost")        # derived values but no owner: no answer at all
    requests.ask("pepper")
    wait_for(lambda: answers, what="pepper's merged info")
    ghost.undeclare()
    (robot, info), = answers
    schemas.validate("robot_info", info)
    assert robot == "pepper" and info["model"] == "pepper"
    assert {d["name"] for d in info["derived"]} == set(entries)


def pump(fake, values, until, what: str, timeout: float = 5.0) -> int:
    """Publish frames (one per poll, 10 ms apart in ``t``) until ``until()``; returns the last seq."""
    def step():
        seq = fake.seq + 1
        fake.frame(T0 + seq * 0.01, values(seq))
        return until()
    wait_for(step, timeout=timeout, what=what)
    return fake.seq


def test_an_unknown_model_gets_velocity_and_qom_and_is_told_why_not_hands(net, owner, caplog):
    caplog.set_level(logging.INFO, logger="sonibus.adapters.features")
    joints = [{"name": "Neck", "unit": "rad", "min": -1.0, "max": 1.0, "max_velocity": 2.0, "chain": "Head"},
              {"name": "Elbow", "unit": "rad", "min": -2.0, "max": 2.0, "max_velocity": 4.0, "chain": "Arm"},
              {"name": "Grip", "unit": "fraction", "min": 0.0, "max": 1.0, "max_velocity": 1.0, "chain": "Arm"}]
    fake = owner("bot", {"robot": "bot", "model": "robbie", "rate_hz": 100.0, "joints": joints})
    features = start(net, robots="bot")
    watch = net.bus("watch")
    subscriber, derived = collect(watch, "bot/derived/**")
    expected = {"bot/derived/velocity/Neck", "bot/derived/velocity/Elbow", "bot/derived/velocity/Grip",
                "bot/derived/qom/Head", "bot/derived/qom/Arm", "bot/derived/qom/Body"}
    pump(fake, lambda k: {"Neck": 0.0, "Elbow": 0.5 * math.sin(k * 0.05), "Grip": 0.5},
         lambda: {k for k, _ in list(derived)} == expected and features.stats["frames"] >= 20, "velocity and QoM")
    subscriber.undeclare()
    assert {k for k, _ in derived} == expected  # no hands
    assert max(m["v"] for k, m in derived if k == "bot/derived/qom/Arm") > 0.05
    reply = watch.query(keys.derived_info("bot"))[0]
    schemas.validate("derived_info", reply)
    reason = "no kinematics for model 'robbie'"
    assert reply["unavailable"] == {"hand": reason, "hand_speed": reason}
    warnings = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    assert warnings == [f"features: bot: hand positions unavailable: {reason}"]


@pytest.mark.parametrize("per_joint_keys", [False, True], ids=["frames", "joint-keys"])
def test_nan_missing_joints_and_garbage_are_counted_not_fatal(net, owner, caplog, per_joint_keys):
    caplog.set_level(logging.WARNING, logger="sonibus.adapters.features")
    fake = owner("pepper", model_info("pepper"))
    features = start(net, robots="pepper", per_joint_keys=per_joint_keys)
    watch = net.bus("watch")
    subscriber, derived = collect(watch, "pepper/derived/velocity/HeadYaw")
    pose = PEPPER.posture("StandInit")
    pump(fake, lambda k: pose, lambda: features.stats["frames"] >= 5, "the first frames")

    def broken(k: int) -> dict:
        if k % 3 == 0:
            return {**pose, "HeadYaw": math.nan}
        if k % 3 == 1:
            return {j: v for j, v in pose.items() if j != "RHand"}
        fake.put("pepper/joints/HeadPitch" if per_joint_keys else "pepper/frame", b"\xc1 not msgpack")
        return pose

    # (a frame holding NaN is refused whole by the gate: counted bad, as garbage is)
    pump(fake, broken, lambda: features.stats["missing"] >= 5 and features.stats["bad"] >= 10, "bad input counted")
    before = len(derived)
    pump(fake, lambda k: {**pose, "HeadYaw": 0.001 * k}, lambda: len(derived) > before + 5, "values after bad input")
    subscriber.undeclare()
    assert features.state == "running"
    assert all(math.isfinite(m["v"]) for _, m in derived)
    warned = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    assert len([w for w in warned if "lacks" in w]) == 1, warned   # at most one every 10 s
    assert len([w for w in warned if "refused" in w]) == 1, warned


@pytest.mark.parametrize("per_joint_keys", [False, True], ids=["frames", "joint-keys"])
def test_frames_are_taken_or_with_per_joint_keys_the_joint_keys(net, owner, per_joint_keys):
    """A robot owner puts both; a script may put only one: the processor takes what its option says."""
    fake = owner("pepper", model_info("pepper"))
    features = start(net, robots="pepper", per_joint_keys=per_joint_keys)
    subscriber, derived = collect(net.bus("watch"), "pepper/derived/velocity/HeadYaw")
    pose = PEPPER.posture("StandInit")
    last = pump(fake, lambda k: pose, lambda: derived, "HeadYaw's velocity")
    wait_for(lambda: any(m["seq"] == last for _, m in list(derived)), what="the last frame pumped, processed")
    frames = features.stats["frames"]
    unheard = fake.frame(T0 + (last + 1) * 0.01, pose, whole=per_joint_keys, joints=not per_joint_keys)
    heard = fake.frame(T0 + (last + 2) * 0.01, pose, whole=not per_joint_keys, joints=per_joint_keys)
    wait_for(lambda: any(m["seq"] == heard for _, m in list(derived)), what="the frame after the unheard one")
    subscriber.undeclare()
    assert features.stats["frames"] == frames + 1
    assert unheard not in {m["seq"] for _, m in derived}


def test_frames_too_old_to_matter_are_skipped_not_computed_late(net, owner):
    """After a backlog (a flood, a stalled machine) what is left is old: sinks would drop what
    it gives as stale, so it is skipped and counted, and the next fresh frame is computed."""
    fake = owner("pepper", model_info("pepper"))
    features = start(net, robots="pepper", max_age_ms=100)
    subscriber, derived = collect(net.bus("watch"), "pepper/derived/velocity/HeadYaw")
    pose = PEPPER.posture("StandInit")
    last = pump(fake, lambda k: pose, lambda: features.stats["stale"] >= 20 and features.stats["frames"] == 0,
                "old frames skipped")  # pump stamps them T0 + ..., years old
    fresh = []
    for k in (1, 2):  # one after the other: two frames 10 ms apart in t put at once are a burst, the newest goes
        fresh.append(fake.frame(time.time(), pose, seq=last + k))
        wait_for(lambda n=k: features.stats["frames"] == n, what=f"fresh frame {k} computed")
    wait_for(lambda: any(m["seq"] == fresh[1] for _, m in list(derived)), what="the fresh frames computed")
    subscriber.undeclare()
    assert features.stats["frames"] == 2 and {m["seq"] for _, m in derived} <= set(fresh)


@pytest.mark.parametrize(("options", "fragment"), [
    ({"robots": "pepper/joints"}, "not a robot name"),
    ({"features": ("velocity", "speed")}, "'speed' is unknown"),
    ({"features": ()}, "is empty"),
    ({"onset": 0.2, "offset": 0.3}, "below onset"),
    ({"cutoff_hz": 0.0}, "key 'cutoff_hz'"),
    ({"weights": {"HeadYaw": -1.0}}, "HeadYaw = -1.0"),
])
def test_bad_options_are_config_errors(options, fragment):
    with pytest.raises(ConfigError, match=fragment):
        FeaturesConfig(**options)


def test_expressive_descriptors_go_on_the_bus_like_any_derived_value(net):
    """The sim plays Hey_1: the node with ``expressive`` publishes each hand's descriptors, the
    arms' shape and the head's joint-space ones as ``<robot>/derived/...`` samples a sink takes as
    they are, and the right arm's offset event carries its segment."""
    from sonibus.adapters.features.expressive import BOTH, HANDS, JOINT_SPACE, SEGMENT_FEATURES

    watch = net.bus("watch")
    subscriber, derived = collect(watch, "pepper/derived/**")
    events_subscriber, events = collect(watch, "pepper/events/motion")
    net.sim("pepper", rate_hz=50)
    start(net, robots="pepper", features=("motion", "expressive"))
    wait_for(lambda: robot_info(watch, "pepper", timeout=0.5), what="pepper/info")
    send_command(watch, "pepper", "behavior/run", {"name": HEY})
    wanted = ({f"pepper/derived/{f}/R" for f in HANDS} | {f"pepper/derived/{f}/arms" for f in BOTH}
              | {f"pepper/derived/{f}/Head" for f in JOINT_SPACE})
    wait_for(lambda: wanted <= {k for k, _ in list(derived)}
             and any(k.endswith("laban_weight/R") and m["v"] > 0.01 for k, m in list(derived)),
             what="the right hand's, the arms' and the head's expressive values, moving")
    wait_for(lambda: any(m["chain"] == "RArm" and m["state"] == "offset" for _, m in list(events)),
             timeout=15.0, what="the right arm's offset (Hey_1 lasts 3.1 s)")
    wait_for(lambda: {"pepper/derived/segment_sparc/RArm"} <= {k for k, _ in list(derived)},
             what="the segment's values as derived values")
    subscriber.undeclare()
    events_subscriber.undeclare()
    for _, message in list(derived):
        schemas.validate("derived_sample", message)
    assert {k.split("/")[2] for k, _ in derived} <= {*HANDS, *BOTH, *SEGMENT_FEATURES.values()}
    offset = next(m for _, m in list(events) if m["chain"] == "RArm" and m["state"] == "offset")
    schemas.validate("event", offset)
    assert set(offset["segment"]) >= {"duration_s", "path", "peak_speed", "directness", "sparc", "ldlj"}
    as_values = {k.split("/")[2]: m["v"] for k, m in list(derived) if k.endswith("/RArm") and m["seq"] == offset["seq"]}
    assert as_values == {SEGMENT_FEATURES[v]: value for v, value in offset["segment"].items()}


def test_frames_are_worked_out_where_they_arrive_not_through_the_queue(net, owner):
    """A robot's whole frames are worked out on the subscription's callback thread (a thread
    hand-off a frame less: the worker's wake-up cost about what a frame's features do; issue 35)."""
    fake = owner("pepper", model_info("pepper"))
    features = start(net, robots="pepper")
    subscriber, derived = collect(net.bus("watch"), "pepper/derived/qom/Body")
    pose = PEPPER.posture("StandInit")
    last = pump(fake, lambda seq: pose, lambda: derived, "the body's QoM")
    queued = queued_keys(features._queue)
    for seq in range(last + 1, last + 11):  # (a tick's spacing, in t too: not paced)
        fake.frame(T0 + seq * 0.01, pose)
        time.sleep(0.01)
    wait_for(lambda: any(m["seq"] == last + 10 for _, m in list(derived)), what="the tenth frame's features")
    subscriber.undeclare()
    assert queued.count("pepper/frame") <= 1, queued  # (one may meet the worker holding the state)


def test_an_idle_worker_sleeps_while_frames_are_worked_out_where_they_arrive(net):
    """With a robot streaming, its frames worked out where they arrive, the worker has nothing to
    do: it sleeps until a message comes (before: a 0.2 s timeout, 5 wake-ups a second; issue 35);
    stopped, it ends at once."""
    node = net.start(Features(FeaturesConfig(robots="pepper"), name="idlefeat"))
    net.sim("pepper", rate_hz=50)
    wait_for(lambda: node.stats["frames"] >= 10, what="pepper's frames worked out")
    counted = wakes(named("idlefeat:"), 2.0)
    assert counted["idlefeat:features"] <= 2, counted  # (a count: the GIL's waits count too; before: 10)
    assert not left_after_stop(node, "idlefeat:")  # (woken by the stop: not left to its join's 2 s)
