"""The expressive descriptors' hand-written fast paths (issue 36's cost: a node with
``expressive`` within 1.5x of a default node's CPU) against the straightforward versions they
replace: the derivative fit against least squares solved anew, the Laban Efforts' running sums
against the window summed anew, curvature against ``geometry``, one FK pass against one per
frame; and the frames at a robot's own times, which make a new fit operator every frame,
without a matrix inverse per frame."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from sonibus.adapters.features import FeaturesConfig
from sonibus.adapters.features.compute import RobotFeatures
from sonibus.adapters.features.config import DEFAULT
from sonibus.adapters.features.kinematic import PointDerivatives, curvature, geometry
from sonibus.adapters.features.laban import LabanEfforts
from sonibus.adapters.features.table import describe
from sonibus.bus import load_model

from .conftest import T0


def jittered_times(n: int, rate_hz: float = 100.0, jitter: float = 0.1, drop: float = 0.2, seed: int = 0):
    """``n`` frame times at ``rate_hz``, each off its grid by up to ``jitter`` of a step, a
    fraction ``drop`` of them left out."""
    rng = np.random.default_rng(seed)
    t = T0 + (np.arange(n) + rng.uniform(-jitter, jitter, n)) / rate_hz
    return t[rng.random(n) >= drop]


def least_squares(times: np.ndarray, points: np.ndarray, t: float, window_s: float, degree: int = 5):
    """Position and derivatives at ``t − W/2`` of the power-basis polynomial fitted anew by
    ``np.linalg.lstsq`` to the frames of the window ``(t − W, t]``."""
    inside = (times > t - window_s * (1 + 1e-9)) & (times <= t)
    s = (times[inside] - t) / window_s
    coefficients = np.linalg.lstsq(np.vander(s, degree + 1, increasing=True), points[inside], rcond=None)[0]
    read = np.array([[math.perm(k, m) * (-0.5) ** (k - m) / window_s**m if k >= m else 0.0
                      for k in range(degree + 1)] for m in range(4)])
    return read @ coefficients


@pytest.mark.parametrize("rate_hz", [50.0, 100.0, 250.0])
def test_fit_equals_least_squares_solved_anew_at_jittered_times(rate_hz):
    times = jittered_times(int(3 * rate_hz), rate_hz)
    rng = np.random.default_rng(1)
    points = np.cumsum(rng.normal(0, 0.01, (len(times), 6)), axis=0)  # two 3-D points
    fit = PointDerivatives(2, window_s=0.4)
    checked = 0
    for k, t in enumerate(times):
        if fit.update(t, points[k].reshape(2, 3)):
            expected = least_squares(times[:k + 1], points[:k + 1], t, 0.4).reshape(4, 2, 3)
            got = (fit.position, fit.velocity, fit.acceleration, fit.jerk)
            for m in range(4):  # each derivative relative to its own size
                assert np.abs(got[m] - expected[m]).max() <= 1e-9 * np.abs(expected[m]).max()
            checked += 1
    assert checked > 0.5 * len(times)


def pepper_features() -> RobotFeatures:
    info = {"model": "pepper", "joints": [j.to_info() for j in load_model("pepper").joints]}
    return RobotFeatures(describe("pepper", info), FeaturesConfig(features=(*DEFAULT, "expressive")))


def test_frames_at_a_robots_own_times_invert_no_matrix_per_frame(monkeypatch):
    """A robot stamps frames with its own clock: no two windows have the same times, and the fit
    needs a new operator each frame. It is refined from the last one, not inverted anew (a pinv
    per fit and frame cost ~130 µs a frame on a node's worker thread)."""
    calls = []
    for name in ("inv", "pinv", "solve", "lstsq", "svd"):
        real = getattr(np.linalg, name)
        monkeypatch.setattr(np.linalg, name,
                            lambda *a, _real=real, _name=name, **k: calls.append(_name) or _real(*a, **k))
    features = pepper_features()
    model = load_model("pepper")
    middle = np.array([(j.min + j.max) / 2 for j in model.joints])
    times = jittered_times(400, jitter=0.03, drop=0.0)
    for k, t in enumerate(times):
        if k == 100:  # (the first second: a first inverse for each window length as the windows fill)
            calls.clear()
        values = middle + 0.2 * np.sin(2 * math.pi * 0.5 * (t - T0) + np.arange(len(middle)))
        out = features.step(float(t), k, {f"pepper/joints/{j}": float(v) for j, v in zip(model.joint_names, values,
                                                                                        strict=True)})
    assert any(key.endswith("laban_flow/Head") for key, _ in out.samples)
    assert any(key.endswith("laban_flow/L") for key, _ in out.samples)
    assert len(calls) <= 3, f"{len(calls)} matrix inversions in {len(times) - 100} frames"


def window_efforts(frames: list[tuple[float, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]],
                   alpha: np.ndarray, window_s: float, min_displacement: float, still: float) -> np.ndarray:
    """Per group (weight, time, flow, space, fluidity) of the last frame, every sum taken anew
    over the frames of the trailing window (trapezoid, each step's own Δt)."""
    t = frames[-1][0]
    inside = [f for f in frames if t - f[0] <= window_s * (1 + 1e-9)]
    ts = np.array([f[0] for f in inside])
    norms = {name: np.array([alpha @ np.linalg.norm(f[i], axis=1) for f in inside])
             for i, name in ((2, "v"), (3, "a"), (4, "j"))}
    weight = np.max([alpha @ np.einsum("ij,ij->i", f[2], f[2]) for f in inside], axis=0)
    dt = np.diff(ts)[:, None]
    span = dt.sum()
    mean = {name: (dt * (x[1:] + x[:-1]) / 2).sum(axis=0) / span for name, x in norms.items()}
    mass = alpha.sum(axis=1)
    path = sum(alpha @ np.linalg.norm(b[1] - a[1], axis=1) for a, b in itertools.pairwise(inside)) / mass
    displacement = alpha @ np.linalg.norm(inside[-1][1] - inside[0][1], axis=1) / mass
    space = np.where(displacement > min_displacement, path / np.where(displacement > 0, displacement, 1), np.nan)
    ok = (mean["v"] > still) & (mean["a"] > 0)
    fluidity = np.where(ok, mean["v"] / np.where(ok, mean["a"], 1), np.nan)
    return np.stack([weight, mean["a"], mean["j"], space, fluidity], axis=1)


@pytest.mark.parametrize("alpha", [np.eye(3), np.array([[1.0, 0.5, 0.0], [0.0, 2.0, 1.0]])],
                         ids=["each point its group", "weighted groups"])
def test_laban_running_sums_equal_the_window_summed_anew(alpha):
    rng = np.random.default_rng(2)
    times = jittered_times(600, jitter=0.3)
    laban = LabanEfforts(alpha, window_s=0.5, min_displacement=1e-3, still=0.05)
    frames: list = []
    position = np.zeros((3, 3))
    for k, t in enumerate(times):
        moving = (k // 100) % 2  # still spells (no Space, no fluidity) between moves
        v, a, j = (moving * rng.normal(0, 0.3, (3, 3)) for _ in range(3))
        position = position + moving * rng.normal(0, 0.01, (3, 3))
        frames.append((t, position.copy(), v, a, j))
        got = laban.update(t, position, v, a, j)
        if len(frames) < 3:
            continue
        expected = window_efforts(frames, alpha, 0.5, 1e-3, 0.05)
        got_rows = np.stack([got.weight, got.time, got.flow, got.space, got.fluidity], axis=1)
        assert np.array_equal(np.isnan(got_rows), np.isnan(expected)), k
        np.testing.assert_allclose(got_rows, expected, rtol=1e-9, atol=1e-12)


def test_curvature_equals_geometry():
    rng = np.random.default_rng(3)
    for scale in (1e-3, 0.04, 0.06, 1.0, 30.0):  # under and over the speed floor (0.05 m/s)
        v, a = rng.normal(0, scale, (50, 3)), rng.normal(0, 1, (50, 3))
        expected = geometry(v, a)[0]
        got = np.array([curvature(vi, ai) for vi, ai in zip(v.tolist(), a.tolist(), strict=True)])
        assert np.array_equal(np.isnan(got), np.isnan(expected))
        np.testing.assert_allclose(got, expected, rtol=1e-12)


def test_one_fk_pass_gives_every_frame_as_its_own_pass():
    arms = pepper_features().robot.arms
    rng = np.random.default_rng(4)
    n = arms.axes.shape[1]
    q = rng.uniform(-1.5, 1.5, (len(arms.sides), n))
    together = arms.points_at(q, (n, 2, 0, 3))
    for got, upto in zip(together, (n, 2, 0, 3), strict=True):
        np.testing.assert_allclose(got, arms.points(q, upto), rtol=0, atol=1e-15)


def test_the_efforts_wait_for_every_arm_and_chain_joint():
    """The hands and the chains share one fit: while a Head joint has never been seen (a robot's
    first frames), no Efforts go out, the arms' shape does; once it comes, hands and chains start
    together, 3/4 of a fit window (0.3 s) later."""
    features = pepper_features()
    model = load_model("pepper")
    middle = np.array([(j.min + j.max) / 2 for j in model.joints])
    first: dict[str, float] = {}
    for k in range(150):
        t = T0 + k / 100
        values = middle + 0.2 * np.sin(2 * math.pi * 0.5 * k / 100 + np.arange(len(middle)))
        frame = {f"pepper/joints/{j}": float(v) for j, v in zip(model.joint_names, values, strict=True)}
        if k < 50:
            frame["pepper/joints/HeadPitch"] = math.nan
        for key, _ in features.step(t, k, frame).samples:
            first.setdefault(key.split("/", 2)[2], t)
    assert first["symmetry/arms"] == T0
    assert first["laban_time/L"] == first["laban_time/Head"] == first["laban_time/Leg"]
    assert first["laban_time/L"] == pytest.approx(T0 + 0.5 + 0.3, abs=0.025)  # (Time: two fitted frames)
