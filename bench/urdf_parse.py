"""What reading a URDF costs beside the XML parser alone (issue 33: a looped URDF made the
node's start run for ever, and the checks were quadratic: 10,000 joints took 6.8 s, 300,000
ran past 60 s). One chain of N joints (ten movable, the rest fixed), parsed by
``urdf.parse`` (XML, joints, the loop and tree checks) and by ``ElementTree.fromstring``
alone (the baseline), interleaved in rounds; a URDF closing a loop at the chain's far end
is refused in about the same time. Linear means the ratio stays flat as N grows.

    .venv/bin/python bench/urdf_parse.py [--sizes 1000 10000 100000 300000] [--rounds 5]
"""

from __future__ import annotations

import argparse
import statistics
import time
import xml.etree.ElementTree as ET

from common import write

from sonibus.adapters.ros2.urdf import UrdfError, parse


def chain(count: int, loop: bool = False) -> str:
    lines = ['<robot name="long">', *(f'<link name="l{i}"/>' for i in range(count + 1))]
    lines += [f'<joint name="j{i}" type="{"revolute" if i < 10 else "fixed"}"><parent link="l{i}"/>'
              f'<child link="l{i + 1}"/><limit lower="-1" upper="1" velocity="1" effort="1"/></joint>'
              for i in range(count)]
    if loop:
        lines.append(f'<joint name="back" type="fixed"><parent link="l{count}"/><child link="l0"/></joint>')
    return "\n".join([*lines, "</robot>"])


def refused(text: str) -> None:
    try:
        parse(text, "loop.urdf")
    except UrdfError:
        return
    raise AssertionError("a looped URDF was taken")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[1000, 10_000, 100_000, 300_000])
    parser.add_argument("--rounds", type=int, default=5)
    args = parser.parse_args()
    result: dict = {"sizes": {}, "summary": []}
    for size in args.sizes:
        texts = {"xml": chain(size), "urdf": chain(size), "loop": chain(size, loop=True)}
        work = {"xml": ET.fromstring, "urdf": parse, "loop": refused}
        times: dict[str, list[float]] = {k: [] for k in work}
        for _ in range(args.rounds if size < 300_000 else max(1, args.rounds // 3)):
            for kind, run in work.items():
                t0 = time.perf_counter()
                run(texts[kind])
                times[kind].append(time.perf_counter() - t0)
        med = {k: statistics.median(v) for k, v in times.items()}
        result["sizes"][size] = {**{f"{k}_s": v for k, v in med.items()}, **{f"{k}_max_s": max(v)
                                                                             for k, v in times.items()}}
        print(f"{size:>7} joints: xml {med['xml']:.3f} s, urdf.parse {med['urdf']:.3f} s "
              f"({med['urdf'] / med['xml']:.1f}×), looped refused {med['loop']:.3f} s")
        result["summary"].append({"scenario": f"URDF of {size:,} joints read (median; a loop refused: "
                                              f"{med['loop']:.2f} s)",
                                  "sonibus": f"{med['urdf']:.3f} s", "baseline": f"{med['xml']:.3f} s (XML alone)",
                                  "ratio": f"{med['urdf'] / med['xml']:.1f}×", "goal": "linear: ratio flat",
                                  "met": ""})
    write("urdf_parse", result)


if __name__ == "__main__":
    main()
