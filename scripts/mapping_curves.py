"""Draw docs/img/mapping-curves.svg: each curve of the map node, from the curves
themselves (adapters/map/curves.py), as docs/mapping.md shows them.

    .venv/bin/python scripts/mapping_curves.py          # writes docs/img/mapping-curves.svg
"""

from __future__ import annotations

import argparse
from pathlib import Path

from sonibus.adapters.map.curves import Exp, Linear, Log, Points, S

OUT = Path(__file__).resolve().parent.parent / "docs" / "img" / "mapping-curves.svg"
SIZE, PAD, GAP, STEPS = 120, 24, 16, 60
PANELS = (
    ("linear", "f(x) = x", Linear()),
    ("exp (r = 10)", "(r^x − 1) / (r − 1)", Exp(10.0)),
    ("log (r = 10)", "log(1 + (r − 1)x) / log r", Log(10.0)),
    ("s", "3x² − 2x³", S()),
    ("points", "lines between [x, y] points", Points(((0.0, 0.0), (0.3, 0.7), (0.6, 0.5), (1.0, 1.0)))),
)


def svg() -> str:
    """The picture, as text (the same bytes every time)."""
    width = len(PANELS) * (SIZE + GAP) - GAP + 2 * PAD
    height = SIZE + 3 * PAD + 10
    parts = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" '
             f'viewBox="0 0 {width} {height}" font-family="sans-serif" font-size="11">',
             f'<rect width="{width}" height="{height}" fill="white"/>']
    for i, (name, formula, curve) in enumerate(PANELS):
        left, top = PAD + i * (SIZE + GAP), PAD
        points = " ".join(f"{left + SIZE * k / STEPS:.1f},{top + SIZE * (1 - curve(k / STEPS)):.1f}"
                          for k in range(STEPS + 1))
        parts += [f'<rect x="{left}" y="{top}" width="{SIZE}" height="{SIZE}" fill="none" stroke="#bbb"/>',
                  f'<polyline points="{points}" fill="none" stroke="#c0392b" stroke-width="2"/>',
                  f'<text x="{left}" y="{top - 6}" font-weight="bold">{name}</text>',
                  f'<text x="{left}" y="{top + SIZE + 14}" fill="#555" font-size="9">{formula}</text>']
    parts.append(f'<text x="{PAD}" y="{height - 6}" fill="#555">x: the source as a fraction of its range (0..1, '
                 'left to right); f(x): the fraction of the destination range (0..1, bottom to top)</text>')
    return "\n".join([*parts, "</svg>", ""])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=OUT)
    args = parser.parse_args()
    args.out.write_text(svg(), encoding="utf-8")
    print(args.out)


if __name__ == "__main__":
    main()
