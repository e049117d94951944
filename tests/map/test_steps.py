"""Each step of a map against its closed form; the one-euro filter against the
algorithm of its paper, written out here as the paper gives it; and a property:
whatever a source sends (NaN, infinities, huge values), no map gives a value
outside its range, or a NaN."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sonibus.adapters.map.chain import Chain
from sonibus.adapters.map.config import parse_map
from sonibus.adapters.map.curves import Exp, Log, Points, S
from sonibus.adapters.map.steps import Calibration, Deadband, OneEuro, OnePole, RateLimit, Threshold


def run(table: dict, values: list[float], dt: float = 0.01, span=(0.0, 1.0)) -> list[float | None]:
    chain = Chain(parse_map("m", {"source": "pepper/joints/HeadYaw", **table}))
    out = []
    for i, v in enumerate(values):
        result = chain.compute(i * dt) if chain.feed("x", v, span, i * dt) else None
        out.append(None if result is None else result.value)
    return out


@pytest.mark.parametrize("curve, closed", [
    ("linear", lambda x: 200 + 1800 * x),
    ("exp", lambda x: 200 * 10 ** x),                                # r = 2000/200
    ("log", lambda x: 200 + 1800 * math.log(1 + 9 * x) / math.log(10)),
    ("s", lambda x: 200 + 1800 * (3 * x * x - 2 * x ** 3)),
])
def test_each_curve_is_its_closed_form_over_the_destination_range(curve, closed):
    xs = [i / 20 for i in range(21)]
    chain = Chain(parse_map("m", {"source": "pepper/joints/HeadYaw", "to": [200, 2000], "curve": curve}))
    for x in xs:
        chain.feed("x", -1.0 + 2.0 * x, (-1.0, 1.0), 0.0)
        assert chain.compute(0.0).value == pytest.approx(closed(x), rel=1e-12), (curve, x)


def test_exp_and_log_with_a_base_and_points_between_their_breakpoints():
    assert Exp(4.0)(0.5) == pytest.approx((4 ** 0.5 - 1) / 3)
    assert Log(4.0)(Exp(4.0)(0.3)) == pytest.approx(0.3)
    assert S()(0.5) == 0.5
    points = Points(((0.0, 0.0), (0.2, 0.8), (1.0, 1.0)))
    assert [points(x) for x in (0.0, 0.1, 0.2, 0.6, 1.0)] == pytest.approx([0.0, 0.4, 0.8, 0.9, 1.0])
    assert run({"curve": "points", "points": [[0.25, 0.5], [0.75, 1.0]]}, [0.0, 0.5, 1.0]) == [0.5, 0.75, 1.0]


def test_invert_clip_from_and_a_downward_range():
    assert run({"invert": True, "to": [0, 10]}, [0.2]) == [pytest.approx(8.0)]
    assert run({"to": [2000, 200]}, [0.25]) == [pytest.approx(1550.0)]
    assert run({"to": [0, 10], "clip": [2, 6]}, [0.1, 0.5, 0.9]) == [2.0, 5.0, 6.0]
    assert run({"from": [10, 20], "to": [0, 1]}, [15.0, 25.0, -3.0], span=None) == [0.5, 1.0, 0.0]


def test_one_pole_reaches_63_percent_of_a_step_in_its_time_constant_whatever_the_rate():
    for dt in (0.001, 0.01, 0.02):
        pole = OnePole(0.080)
        pole(0.0, 0.0)
        steps = round(0.080 / dt)
        for i in range(1, steps + 1):
            y = pole(i * dt, 1.0)
        assert y == pytest.approx(1 - math.exp(-1), rel=1e-9)


def test_rate_limit_deadband_and_threshold_with_hysteresis():
    limit = RateLimit(10.0)  # 10 per second: 0.1 per 10 ms
    assert [round(limit(i * 0.01, 1.0), 9) for i in range(4)] == [1.0, 1.0, 1.0, 1.0]
    limit = RateLimit(10.0)
    assert [round(limit(i * 0.01, 0.0 if i == 0 else 1.0), 9) for i in range(4)] == [0.0, 0.1, 0.2, 0.3]
    band = Deadband(0.5)
    assert [band(v) for v in (0.0, 0.3, 0.6, 0.8, 1.2)] == [0.0, None, 0.6, None, 1.2]
    trigger = Threshold(on=0.8, off=0.6)
    assert [trigger(v) for v in (0.79, 0.8, 0.99, 0.61, 0.8, 0.6, 0.7, 0.81)] == \
        [None, "on", None, None, None, "off", None, "on"]


def test_calibration_learns_the_real_range_then_freezes_it():
    calibration = Calibration(1.0)
    assert calibration.range is None
    froze = [calibration(t / 10, v) for t, v in enumerate([0.3, 0.5, 0.2, 0.4, 0.45, 0.3, 0.3, 0.3, 0.3, 0.3])]
    assert calibration.range == (0.2, 0.5) and not any(froze)
    assert calibration(1.0, 0.9) is True and calibration.range == (0.2, 0.5)  # frozen: 0.9 is not learned
    assert run({"calibrate_s": 1.0}, [0.3, 0.5, 0.2, 0.35], span=None, dt=0.1) == [None, 1.0, 0.0, pytest.approx(0.5)]


class PaperLowPass:
    """LowPassFilter of Casiez et al. 2012 (the 1€ filter's paper), Algorithm 1."""

    def __init__(self) -> None:
        self.first, self.hatxprev = True, 0.0

    def filter(self, x: float, alpha: float) -> float:
        if self.first:
            self.first, self.hatxprev = False, x
        hatx = alpha * x + (1 - alpha) * self.hatxprev
        self.hatxprev = hatx
        return hatx


class PaperOneEuro:
    """OneEuroFilter of the same Algorithm 1, with the rate of each sample (1 / its interval)."""

    def __init__(self, mincutoff: float, beta: float, dcutoff: float) -> None:
        self.mincutoff, self.beta, self.dcutoff = mincutoff, beta, dcutoff
        self.first = True
        self.xfilt, self.dxfilt = PaperLowPass(), PaperLowPass()

    @staticmethod
    def alpha(rate: float, cutoff: float) -> float:
        tau, te = 1.0 / (2 * math.pi * cutoff), 1.0 / rate
        return 1.0 / (1.0 + tau / te)

    def filter(self, x: float, rate: float) -> float:
        if self.first:
            self.first, dx = False, 0.0
        else:
            dx = (x - self.xfilt.hatxprev) * rate
        edx = self.dxfilt.filter(dx, self.alpha(rate, self.dcutoff))
        cutoff = self.mincutoff + self.beta * abs(edx)
        return self.xfilt.filter(x, self.alpha(rate, cutoff))


@pytest.mark.parametrize("mincutoff, beta, dcutoff", [(1.0, 0.0, 1.0), (0.5, 0.05, 1.0), (2.0, 1.0, 3.0)])
def test_the_one_euro_filter_is_the_papers_algorithm(mincutoff, beta, dcutoff):
    ours, paper = OneEuro(mincutoff, beta, dcutoff), PaperOneEuro(mincutoff, beta, dcutoff)
    t = 0.0
    for i in range(500):
        dt = 0.005 + 0.01 * ((i * 7919) % 13) / 13  # uneven intervals: the filter works with each one's
        t += dt
        x = math.sin(i / 20) + 0.05 * math.sin(i * 2.7) + (1.0 if 200 <= i < 300 else 0.0)
        expected = paper.filter(x, 1.0 / dt)
        assert ours(t, x) == pytest.approx(expected, rel=1e-12, abs=1e-12), i


def test_the_one_euro_filter_is_the_papers_algorithm_in_a_map():
    chain = Chain(parse_map("m", {"source": "pepper/joints/HeadYaw", "to": [0, 1],
                                  "one_euro": {"min_cutoff": 1.5, "beta": 0.2}}))
    paper = PaperOneEuro(1.5, 0.2, 1.0)
    for i in range(200):
        x = 0.5 + 0.4 * math.sin(i / 10)
        chain.feed("x", x, (0.0, 1.0), i * 0.01)
        expected = paper.filter(x, 100.0)
        assert chain.compute(i * 0.01).value == pytest.approx(expected, rel=1e-9)


WILD = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.floats(-1e6, 1e6),
                 st.sampled_from([math.nan, math.inf, -math.inf, 1e308, -1e308, 5e-324, 0.0]))
TABLES = st.fixed_dictionaries({
    "to": st.sampled_from([[200, 2000], [2000, 200], [-1, 1], [0, 1e6], [-1e6, 1e6], [1e-6, 2e-6]]),
    "curve": st.sampled_from(["linear", "exp", "log", "s"]),
}, optional={
    "invert": st.booleans(),
    "smooth_ms": st.sampled_from([1.0, 80.0, 5000.0]),
    "rate_limit": st.sampled_from([0.5, 1e6]),
    "deadband": st.sampled_from([0.0, 0.1]),
    "calibrate_s": st.sampled_from([0.05, 1.0]),
})


@settings(max_examples=100, deadline=None, derandomize=True, database=None)  # (the same inputs every run)
@given(table=TABLES, values=st.lists(WILD, min_size=100, max_size=100),
       span=st.sampled_from([(0.0, 1.0), (-1e6, 1e6), (1e-300, 2e-300), (5.0, -5.0)]))
def test_no_value_a_source_sends_gives_an_output_outside_its_range_or_not_finite(table, values, span):
    """100 examples × 100 values: 10,000 source values per run, NaN, ±inf and huge ones among them."""
    chain = Chain(parse_map("m", {"source": "pepper/joints/HeadYaw", **table}))
    low, high = min(table["to"]), max(table["to"])
    for i, value in enumerate(values):
        if chain.feed("x", value, span, i * 0.01):
            out = chain.compute(i * 0.01)
            if out is not None and out.value is not None:
                assert math.isfinite(out.value) and low <= out.value <= high, (value, out)
    n = len(values)  # and whatever came before, the map still maps (no NaN kept in a filter's state)
    for i in range(n, n + 20):
        assert chain.feed("x", 0.2 if i % 2 else 0.8, span, i * 0.01) or not table.get("calibrate_s")
    out = chain.compute((n + 20) * 0.01)
    assert out is not None and (out.value is None or low <= out.value <= high), out


@settings(max_examples=50, deadline=None, derandomize=True, database=None)
@given(a=st.lists(WILD, min_size=50, max_size=50), b=st.lists(WILD, min_size=50, max_size=50),
       expr=st.sampled_from(["max(a, b)", "a * b", "hypot(a, b)", "a / b", "exp(a * 1000)", "log(a) * b",
                             "a ** b", "sqrt(a - b)"]))
def test_no_expression_of_wild_sources_gives_an_output_outside_its_range(a, b, expr):
    chain = Chain(parse_map("m", {"sources": {"a": "pepper/joints/HeadYaw", "b": "nao/joints/HeadYaw"},
                                  "expr": expr, "to": [-3, 3]}))
    for i, (x, y) in enumerate(zip(a, b, strict=True)):
        chain.feed("a", x, (-1.0, 1.0), i * 0.01)
        chain.feed("b", y, (-1.0, 1.0), i * 0.01)
        out = chain.compute(i * 0.01)
        if out is not None:
            assert math.isfinite(out.value) and -3 <= out.value <= 3, (x, y, out)


def test_a_calibrated_span_of_the_whole_float_range_does_not_stop_the_map():
    """Found by the property above: a span of ±1e308 overflowed to inf/inf = NaN, which stayed in the
    one-pole's state and dropped every output after it."""
    out = run({"calibrate_s": 0.05, "smooth_ms": 1.0, "to": [200, 2000]},
              [7.976931348623158e307, -1e308, 7.976931348623158e307] + [0.0] * 20, span=None)
    assert out[1] == 200.0 and out[-1] is not None and 200.0 <= out[-1] <= 2000.0, out
    assert all(v is not None for v in out[1:]), out
