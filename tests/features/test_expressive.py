"""Expressive descriptors (issue 36) on closed-form cases of
/work/shared/reference/expressive.md, at 50 and 100 Hz and with frames dropped."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from monalysa.quality.smoothness import log_dimensionless_jerk
from monalysa.quality.smoothness import sparc as monalysa_sparc

from sonibus import schemas
from sonibus.adapters.features.kinematic import PointDerivatives, geometry
from sonibus.adapters.features.laban import LabanEfforts
from sonibus.adapters.features.segments import directness, fluidity, ldlj, sparc

R, OMEGA = 0.2, math.pi
RTOL = {50: 2e-3, 100: 5e-4}
BASE: dict[int, tuple] = {}  # the 100 Hz circle, computed once for the property test


def circle(t: float) -> np.ndarray:
    return np.array([[R * math.cos(OMEGA * t), R * math.sin(OMEGA * t), 0.0]])


def run_circle(times: np.ndarray):
    d, laban = PointDerivatives(1, window_s=0.4), LabanEfforts(np.ones(1), window_s=0.5)
    out = []
    for t in times:
        p = circle(t)
        if d.update(t, p):
            out.append((t, d.velocity.copy(), d.acceleration.copy(), d.jerk.copy(),
                        laban.update(d.time, d.position, d.velocity, d.acceleration, d.jerk)))
    return out


@pytest.mark.parametrize("fs", [50, 100])
def test_uniform_circle(fs):
    _t, v, a, j, efforts = run_circle(np.arange(0, 2, 1 / fs))[-1]
    rtol = RTOL[fs]
    assert np.linalg.norm(v) == pytest.approx(R * OMEGA, rel=rtol)
    assert np.linalg.norm(a) == pytest.approx(R * OMEGA**2, rel=rtol)
    assert np.linalg.norm(j) == pytest.approx(R * OMEGA**3, rel=rtol)  # vector, not speed jerk (0)
    kappa, a_t, a_n = geometry(v, a)
    assert kappa[0] == pytest.approx(1 / R, rel=rtol)
    assert abs(a_t[0]) < rtol * R * OMEGA**2
    assert a_n[0] == pytest.approx(R * OMEGA**2, rel=rtol)
    assert efforts.weight == pytest.approx((R * OMEGA) ** 2, rel=2 * rtol)
    assert efforts.time == pytest.approx(R * OMEGA**2, rel=rtol)
    assert efforts.flow == pytest.approx(R * OMEGA**3, rel=rtol)
    phi = OMEGA * 0.5
    assert efforts.space == pytest.approx(phi / (2 * math.sin(phi / 2)), rel=rtol)  # 1.110721


def test_dropped_frames_change_no_windowed_value():
    """20 % of frames dropped (and 50 vs 100 Hz): the same values within the 50 Hz tolerance."""
    full = np.arange(0, 2, 1 / 100)
    rng = np.random.default_rng(7)
    kept = full[(rng.random(len(full)) > 0.2) | (full > 1.99)]
    a, b = run_circle(full)[-1][4], run_circle(kept)[-1][4]
    for name in ("weight", "time", "flow", "space"):
        assert getattr(b, name) == pytest.approx(getattr(a, name), rel=RTOL[50]), name


def minimum_jerk(fs: float):
    t = np.arange(0, 1 + 0.5 / fs, 1 / fs)
    tau = t / 1.0
    s = 0.3 * (10 * tau**3 - 15 * tau**4 + 6 * tau**5)
    speed = 0.3 * (30 * tau**2 - 60 * tau**3 + 30 * tau**4)
    acc = np.abs(0.3 * (60 * tau - 180 * tau**2 + 120 * tau**3))
    points = np.c_[s, np.zeros_like(s), np.zeros_like(s)]
    return t, points, speed, acc


@pytest.mark.parametrize(("fs", "sampled"), [(50, -5.2804), (100, -5.3016)])
def test_minimum_jerk_reach(fs, sampled):
    t, points, speed, acc = minimum_jerk(fs)
    assert directness(points) == pytest.approx(1.0, abs=1e-12)
    assert speed.max() == pytest.approx(0.5625, rel=1e-3)
    assert fluidity(t, speed, acc) == pytest.approx(1 / 3.75, rel=RTOL[fs])
    assert ldlj(speed, fs) == pytest.approx(sampled, abs=5e-4)
    assert sparc(speed, fs) == pytest.approx(-1.4058, abs=5e-3)


@pytest.mark.parametrize("fs", [50, 100])
def test_sparc_and_ldlj_equal_monalysa(fs):
    for speed in (minimum_jerk(fs)[2], np.exp(-5 * np.arange(-1, 1, 1 / fs) ** 2)):
        assert sparc(speed, fs) == pytest.approx(monalysa_sparc(speed, fs)[0], abs=1e-6)
        assert ldlj(speed, fs) == pytest.approx(log_dimensionless_jerk(speed, fs), abs=1e-6)


# slow: windows of 0.2c and 0.5c s on the 100 Hz grid (Space's path spans the frames inside its window,
# up to a frame less than T: 0.5 % on a 0.33 s window)
@settings(max_examples=10, deadline=None)
@given(shift=st.floats(-2, 2), angle=st.floats(0, 2 * math.pi), scale=st.floats(0.2, 5),
       slow=st.sampled_from([0.5, 0.8, 1.0, 1.5, 2.0]))
def test_invariance(shift, angle, scale, slow):
    """Translation and rotation change nothing; space × s scales speed, Time, Flow by s and
    Weight by s², κ by 1/s; time × c divides Time by c², Flow by c³, keeps Space."""
    c, s_ = math.cos(angle), math.sin(angle)
    rot = np.array([[c, -s_, 0], [s_, c, 0], [0, 0, 1]])
    fs = 100
    base = BASE[0] if BASE else BASE.setdefault(0, run_circle(np.arange(0, 2, 1 / fs))[-1])
    d, laban = PointDerivatives(1, window_s=0.4 * slow), LabanEfforts(np.ones(1), window_s=0.5 * slow)
    for t in np.arange(0, 2 * slow, 1 / fs):
        p = scale * circle(t / slow) @ rot.T + shift
        if d.update(t, p):
            e = laban.update(d.time, d.position, d.velocity, d.acceleration, d.jerk)
    e0 = base[4]
    tol = 5e-3
    assert e.space == pytest.approx(e0.space, rel=tol)
    assert e.weight == pytest.approx(e0.weight * scale**2 / slow**2, rel=tol)
    assert e.time == pytest.approx(e0.time * scale / slow**2, rel=tol)
    assert e.flow == pytest.approx(e0.flow * scale / slow**3, rel=tol)
    kappa = geometry(d.velocity, d.acceleration)[0][0]
    assert kappa == pytest.approx(geometry(base[1], base[2])[0][0] / scale, rel=tol)


def reach_efforts(times: np.ndarray):
    d, laban = PointDerivatives(1, window_s=0.4), LabanEfforts(np.ones(1), window_s=1.2)
    for t in times:
        tau = min(max(t - 0.5, 0.0), 1.0)
        p = np.array([[0.3 * (10 * tau**3 - 15 * tau**4 + 6 * tau**5), 0.0, 0.0]])
        if d.update(t, p):
            e = laban.update(d.time, d.position, d.velocity, d.acceleration, d.jerk)
    return e


def test_time_is_time_weighted_when_frames_are_dropped_unevenly():
    """Frames dropped only in the reach's first half: Time over a 1.2 s window holding the 1 s
    reach (read 0.2 s late, the fit's middle) is its mean |a| × 1/1.2 = 0.9375 m/s² still; a mean
    per frame would weigh the second half more."""
    full = np.arange(0, 1.7 + 1e-9, 1 / 100)
    uneven = full[~((full > 0.5) & (full < 1.0) & (np.arange(len(full)) % 5 < 2))]
    assert reach_efforts(full).time == pytest.approx(1.125 / 1.2, rel=5e-3)
    assert reach_efforts(uneven).time == pytest.approx(1.125 / 1.2, rel=5e-3)


@pytest.mark.parametrize("fs", [50, 100])
def test_shoulder_sweep_through_the_real_forward_kinematics(fs):
    """Only RShoulderPitch turns, at 1 rad/s: the right hand runs on a circle of 0.310452 m about
    the pitch axis, so the node's curvature is 1/r and its Laban Weight (ωr)²; a still left arm
    has no curvature (under the speed floor)."""
    from sonibus.adapters.features import FeaturesConfig
    from sonibus.adapters.features.catalog import derived
    from sonibus.adapters.features.compute import RobotFeatures
    from sonibus.adapters.features.table import describe
    from sonibus.bus import load_model

    model = load_model("pepper")
    info = {"model": "pepper", "joints": [j.to_info() for j in model.joints]}
    config = FeaturesConfig(features=("expressive",))
    robot = describe("pepper", info)
    features = RobotFeatures(robot, config)
    pose = {f"pepper/joints/{j}": 0.0 for j in model.joint_names}
    pose.update({"pepper/joints/RShoulderRoll": -0.3, "pepper/joints/RElbowYaw": 1.2,
                 "pepper/joints/RElbowRoll": 0.8, "pepper/joints/RWristYaw": 0.4})
    last = {}
    for k in range(int(1.0 * fs)):
        t = k / fs
        for key, msg in features.step(t, k + 1, {**pose, "pepper/joints/RShoulderPitch": -0.5 + t}).samples:
            last[key] = msg["v"]
    r = 0.310452
    assert last["pepper/derived/curvature/R"] == pytest.approx(1 / r, rel=RTOL[fs])
    assert last["pepper/derived/laban_weight/R"] == pytest.approx(r**2, rel=2 * RTOL[fs])
    assert last["pepper/derived/laban_time/R"] == pytest.approx(r, rel=RTOL[fs])  # |a| = ω²r
    assert "pepper/derived/curvature/L" not in last and last["pepper/derived/laban_weight/L"] < 1e-20
    reply = derived(robot, config, {"host": "h", "node": "features"})
    schemas.validate("derived_info", reply)
    listed = {e["key"] for e in reply["derived"]}
    assert set(last) <= listed  # every value published is described on <robot>/info/derived


# docs/features.md, "Noise floor": the largest value (the change, for the arms' shape) a still robot
# with 1 mrad of noise on every joint gives; measured maxima at 50 and 100 Hz, Pepper and NAO, in the docs
FLOOR = {"laban_weight/L": 1e-3, "laban_time/L": 0.2, "laban_flow/L": 5.0, "kinetic_energy/L": 5e-4,
         "laban_weight/Head": 5e-3, "laban_time/Head": 1.0, "laban_flow/Head": 20.0, "kinetic_energy/Head": 2e-3}
SHAPE_FLOOR = {"hand_distance": 5e-3, "points_density": 2e-3, "symmetry": 0.01}


@pytest.mark.parametrize(("model", "fs"), [("pepper", 50), ("pepper", 100), ("nao", 100)])
def test_a_still_robot_with_1_mrad_of_noise_stays_under_the_floor(model, fs):
    """Every descriptor a still robot publishes stays under its floor (hands: L and R; joint
    space: every chain with no kinematics); no Space, curvature nor fluidity at all."""
    from sonibus.adapters.features import FeaturesConfig
    from sonibus.adapters.features.compute import RobotFeatures
    from sonibus.adapters.features.table import describe
    from sonibus.bus import load_model

    robot_model = load_model(model)
    info = {"model": model, "joints": [j.to_info() for j in robot_model.joints]}
    features = RobotFeatures(describe(model, info), FeaturesConfig(features=("expressive",)))
    rng = np.random.default_rng(1)
    seen: dict[str, list[float]] = {}
    for k in range(2 * fs):
        pose = {f"{model}/joints/{j}": 0.3 + 1e-3 * rng.standard_normal() for j in robot_model.joint_names}
        for key, msg in features.step(k / fs, k + 1, pose).samples:
            seen.setdefault(key.split("/", 2)[2], []).append(msg["v"])
    legs = ("Leg",) if model == "pepper" else ("LLeg", "RLeg")
    floors = {f"{feature}/{name}": floor for feature_name, floor in FLOOR.items()
              for feature, kind in [feature_name.split("/")]
              for name in (("L", "R") if kind == "L" else ("Head", *legs))}
    assert set(seen) == set(floors) | {f"{f}/arms" for f in SHAPE_FLOOR}
    for name, floor in floors.items():
        assert max(seen[name]) < floor, name
    for feature, floor in SHAPE_FLOOR.items():
        assert np.ptp(seen[f"{feature}/arms"]) < floor, feature
