"""Draw the rig diagram ``docs/figures/rig.svg``: the SAS rig of Iskandarani & Karimi (2011, seed 001,
section 6 and eqs. 13-17) as the model sees it, written as SVG by this code (no drawing program).

Two views of one shaft. Left, along the shaft: the road wheel turned to θ1 by the road motor, the
arm at θ2, their difference θ = θ2 − θ1 (the angle the spring and the damper see), the torsion
spring k at the hub and the arm's inertia J. Right, across the shaft: the road wheel, the torsion
spring and the MR damper between the road-wheel side and the arm, the damper's coil with its current
i and the torque T it gives, and the two encoders. Beneath: the model's equation with the names the
manual uses, and the seed's k and J (the defaults of the ``model`` section).

Beside it, ``rig.json``: the symbols the figure names and the values it prints, which
``tests/test_figures.py`` compares with a fresh drawing.

    .venv/bin/python tools/rig_figure.py            # docs/figures/rig.svg and rig.json
    .venv/bin/python tools/rig_figure.py --quick    # draw into a temporary folder and check the SVG parses
"""

from __future__ import annotations

import argparse
import json
import math
import tempfile
import xml.etree.ElementTree as ElementTree
from pathlib import Path

from sashil.models.hysteresis import BoucWenParams

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "docs" / "figures"
WIDTH, HEIGHT = 960, 520
#: the angles the front view is drawn at [deg] (a picture, not a state of the rig)
THETA1_DEG, THETA2_DEG = 18.0, 48.0
INK, ROAD, ARM, DAMPER, SPRING = "#222", "#1f77b4", "#d62728", "#7b4fa0", "#2a9d3a"
#: the symbols the figure names, with what each is (rig.json; the glossary's words)
SYMBOLS = {
    "θ1": "road wheel angle (the road side, turned by the road motor)",
    "θ2": "arm angle (the body side)",
    "θ": "relative angle θ = θ2 − θ1, which the spring and the damper see",
    "k": "torsion spring stiffness",
    "T": "MR damper torque",
    "i": "coil current of the MR damper",
    "J": "the arm's inertia about the shaft",
}


def _text(x: float, y: float, body: str, size: int = 14, color: str = INK, anchor: str = "start", **extra: str) -> str:
    attrs = "".join(f' {key.replace("_", "-")}="{value}"' for key, value in extra.items())
    return (
        f'<text x="{x:.1f}" y="{y:.1f}" font-size="{size}" fill="{color}" text-anchor="{anchor}"{attrs}>{body}</text>'
    )


def _line(x1: float, y1: float, x2: float, y2: float, color: str = INK, width: float = 1.5, dash: str = "") -> str:
    dashed = f' stroke-dasharray="{dash}"' if dash else ""
    return f'<line x1="{x1:.1f}" y1="{y1:.1f}" x2="{x2:.1f}" y2="{y2:.1f}" stroke="{color}" stroke-width="{width}"{dashed}/>'


def _polar(cx: float, cy: float, radius: float, deg: float) -> tuple[float, float]:
    """A point at ``radius`` and ``deg`` (counter-clockwise from the right, SVG's y pointing down)."""
    return cx + radius * math.cos(math.radians(deg)), cy - radius * math.sin(math.radians(deg))


def _arc_arrow(cx: float, cy: float, radius: float, start: float, end: float, color: str) -> str:
    """An arc from ``start`` to ``end`` degrees (counter-clockwise) with an arrowhead at its end."""
    x0, y0 = _polar(cx, cy, radius, start)
    x1, y1 = _polar(cx, cy, radius, end)
    large = 1 if end - start > 180 else 0
    return (
        f'<path d="M {x0:.1f} {y0:.1f} A {radius:.1f} {radius:.1f} 0 {large} 0 {x1:.1f} {y1:.1f}" '
        f'fill="none" stroke="{color}" stroke-width="1.6" marker-end="url(#head-{color[1:]})"/>'
    )


def _markers() -> str:
    heads = "".join(
        f'<marker id="head-{color[1:]}" viewBox="0 0 10 10" refX="9" refY="5" markerWidth="7" markerHeight="7" '
        f'orient="auto-start-reverse"><path d="M 0 0 L 10 5 L 0 10 z" fill="{color}"/></marker>'
        for color in (INK, ROAD, ARM, DAMPER, SPRING)
    )
    return f"<defs>{heads}</defs>"


def _spiral(cx: float, cy: float, r0: float, r1: float, turns: float) -> str:
    """The torsion spring seen along the shaft: an Archimedean spiral from ``r0`` to ``r1``."""
    steps = int(turns * 48)
    points = []
    for k in range(steps + 1):
        a = 2 * math.pi * turns * k / steps
        r = r0 + (r1 - r0) * k / steps
        points.append(f"{cx + r * math.cos(a):.1f},{cy - r * math.sin(a):.1f}")
    return f'<polyline points="{" ".join(points)}" fill="none" stroke="{SPRING}" stroke-width="1.8"/>'


def front_view(cx: float = 235.0, cy: float = 265.0) -> list[str]:
    """Along the shaft: the road wheel at θ1, the arm at θ2, θ between them, the spring at the hub."""
    wheel_r, arm_len = 120.0, 205.0
    parts = [
        _text(cx - 200, 52, "along the shaft", 15, INK, font_weight="bold"),
        _line(cx - 150, cy, cx + 235, cy, "#888", 1.0, "6 4"),
        _text(cx + 238, cy + 4, "0", 12, "#666"),
        f'<circle cx="{cx}" cy="{cy}" r="{wheel_r}" fill="#e8f0f8" stroke="{ROAD}" stroke-width="2.5"/>',
    ]
    mark = _polar(cx, cy, wheel_r, THETA1_DEG)
    parts.append(_line(cx, cy, *mark, ROAD, 2.5))
    parts.append(f'<circle cx="{mark[0]:.1f}" cy="{mark[1]:.1f}" r="5" fill="{ROAD}"/>')
    parts.append(_arc_arrow(cx, cy, wheel_r + 22, 0.0, THETA1_DEG, ROAD))
    parts.append(_text(*_polar(cx, cy, wheel_r + 34, THETA1_DEG / 2), "θ1", 17, ROAD))
    parts.append(_text(cx - 118, cy + 150, "road wheel θ1 (the road motor turns it)", 14, ROAD))
    tip = _polar(cx, cy, arm_len, THETA2_DEG)
    parts.append(_line(cx, cy, *tip, ARM, 7.0))
    parts.append(f'<circle cx="{tip[0]:.1f}" cy="{tip[1]:.1f}" r="15" fill="{ARM}" fill-opacity="0.85"/>')
    parts.append(_text(tip[0], tip[1] + 5, "J", 14, "#fff", "middle", font_weight="bold"))
    parts.append(_text(tip[0] + 20, tip[1] - 4, "arm θ2, inertia J", 14, ARM))
    parts.append(_arc_arrow(cx, cy, arm_len - 40, 0.0, THETA2_DEG, ARM))
    parts.append(_text(*_polar(cx, cy, arm_len - 22, 30.0), "θ2", 17, ARM))
    parts.append(_arc_arrow(cx, cy, 78.0, THETA1_DEG, THETA2_DEG, DAMPER))
    middle = _polar(cx, cy, 78.0, (THETA1_DEG + THETA2_DEG) / 2)
    parts.append(_line(*middle, cx - 20, cy - 72, DAMPER, 0.8))
    parts.append(_text(cx - 104, cy - 76, "θ = θ2 − θ1", 15, DAMPER))
    parts.append(_spiral(cx, cy, 9.0, 38.0, 3.0))
    parts.append(f'<circle cx="{cx}" cy="{cy}" r="7" fill="{INK}"/>')
    parts.append(_text(cx - 82, cy + 56, "spring k at the hub", 13, SPRING))
    return parts


def _coil(x: float, y: float, width: float, height: float) -> list[str]:
    """The coil's winding in the damper housing: a hatched block."""
    parts = [
        f'<rect x="{x:.1f}" y="{y:.1f}" width="{width:.1f}" height="{height:.1f}" fill="#f3e9fa" stroke="{DAMPER}"/>'
    ]
    for k in range(1, 6):
        xk = x + k * width / 6
        parts.append(_line(xk, y, xk - 6, y + height, DAMPER, 1.0))
    return parts


def section_view(y: float = 265.0) -> list[str]:
    """Across the shaft: road wheel, spring, MR damper and arm on one shaft; coil current i, torque T;
    the encoders of θ1 and θ2."""
    x0 = 500.0
    parts = [
        _text(x0, 52, "across the shaft", 15, INK, font_weight="bold"),
        # the road-wheel side: the wheel, edge on, and its sleeve out to the damper's housing
        f'<rect x="{x0 + 20}" y="{y - 120}" width="16" height="240" fill="#e8f0f8" stroke="{ROAD}" stroke-width="2"/>',
        _line(x0 + 36, y - 14, x0 + 190, y - 14, ROAD, 2.5),
        _line(x0 + 36, y + 14, x0 + 190, y + 14, ROAD, 2.5),
        _text(x0 + 6, y + 142, "road wheel θ1", 14, ROAD),
        # the arm's side: the inner shaft through it all to the arm
        _line(x0 - 10, y, x0 + 400, y, ARM, 3.0),
        f'<rect x="{x0 + 330}" y="{y - 160}" width="14" height="170" fill="{ARM}" fill-opacity="0.85"/>',
        f'<circle cx="{x0 + 337}" cy="{y - 165}" r="15" fill="{ARM}"/>',
        _text(x0 + 337, y - 160, "J", 14, "#fff", "middle", font_weight="bold"),
        _text(x0 + 300, y - 190, "arm θ2", 14, ARM),
    ]
    # the torsion spring between the sleeve and the inner shaft: a helix seen from the side
    for k in range(6):
        xk = x0 + 52 + 14 * k
        parts.append(
            f'<path d="M {xk:.1f} {y - 26:.1f} C {xk + 12:.1f} {y - 26:.1f} {xk + 2:.1f} {y + 26:.1f} '
            f'{xk + 14:.1f} {y + 26:.1f}" fill="none" stroke="{SPRING}" stroke-width="1.8"/>'
        )
    parts.append(_text(x0 + 44, y - 42, "torsion spring k", 14, SPRING))
    parts.append(_text(x0 + 44, y + 48, "torque k·θ", 13, SPRING))
    # the MR damper: its housing on the road-wheel side, its rotor on the arm's shaft, fluid between
    hx, hw = x0 + 190, 110.0
    parts += [
        f'<rect x="{hx}" y="{y - 70}" width="{hw}" height="140" rx="6" fill="#faf5fd" stroke="{DAMPER}" stroke-width="2.2"/>',
        f'<rect x="{hx + 10}" y="{y - 50}" width="{hw - 20}" height="100" fill="#fde9c8" stroke="#c98a1b"/>',
        f'<rect x="{hx + 49}" y="{y - 44}" width="12" height="88" fill="{ARM}" fill-opacity="0.85"/>',
        *_coil(hx + 10, y - 66, hw - 20, 14),
        *_coil(hx + 10, y + 52, hw - 20, 14),
        _text(hx + hw / 2, y - 80, "MR damper", 14, DAMPER, "middle", font_weight="bold"),
        _text(hx + hw / 2, y + 100, "MR fluid between housing and rotor", 12, "#9a6a12", "middle"),
    ]
    # the coil current i: a lead into the winding
    parts.append(
        f'<path d="M {hx - 40:.1f} {y - 132:.1f} L {hx + 14:.1f} {y - 68:.1f}" stroke="{DAMPER}" '
        f'stroke-width="1.6" marker-end="url(#head-{DAMPER[1:]})"/>'
    )
    parts.append(_text(hx - 150, y - 136, "coil current i", 14, DAMPER))
    # the damper torque T about the shaft, on the arm
    parts.append(
        f'<path d="M {hx + hw + 6:.1f} {y + 40:.1f} A 26 40 0 0 0 {hx + hw + 6:.1f} {y - 40:.1f}" fill="none" '
        f'stroke="{DAMPER}" stroke-width="1.8" marker-end="url(#head-{DAMPER[1:]})"/>'
    )
    parts.append(_text(hx + hw + 22, y + 58, "torque T(i, θ, θ̇)", 14, DAMPER))
    # the encoders
    for x, label, color in ((x0 - 36, "encoder θ1", ROAD), (x0 + 400, "encoder θ2", ARM)):
        parts.append(
            f'<rect x="{x}" y="{y - 12}" width="26" height="24" fill="#fff" stroke="{color}" stroke-width="1.6"/>'
        )
        parts.append(_text(x + 13, y + 34, label, 12, color, "middle"))
    return parts


def numbers(params: BoucWenParams | None = None) -> dict:
    """What the figure prints beside the symbols: the seed's k and J (the ``model`` section's defaults)."""
    params = params or BoucWenParams()
    return {
        "source": "Iskandarani & Karimi 2011 (seed 001), section 6, eqs. 13-17",
        "symbols": SYMBOLS,
        "k_nm_per_rad": f"{params.k:g}",
        "J_kg_m2": f"{params.J:g}",
        "natural_frequency_hz": f"{math.sqrt(params.k / params.J) / (2 * math.pi):.2f}",
    }


def svg(params: BoucWenParams | None = None) -> str:
    """The whole diagram as SVG text (the same text for the same parameters)."""
    shown = numbers(params)
    lines = [
        f'<svg xmlns="http://www.w3.org/2000/svg" width="{WIDTH}" height="{HEIGHT}" viewBox="0 0 {WIDTH} {HEIGHT}" '
        'font-family="DejaVu Sans, Helvetica, Arial, sans-serif">',
        "<title>The SAS rig: road wheel θ1, arm θ2, θ = θ2 − θ1, torsion spring k, MR damper (coil current i, "
        "torque T), inertia J</title>",
        _markers(),
        f'<rect width="{WIDTH}" height="{HEIGHT}" fill="#ffffff"/>',
        _text(20, 26, "The SAS rig (Iskandarani &amp; Karimi 2011): one shaft, road side and arm side", 16),
        *front_view(),
        *section_view(),
        _text(20, HEIGHT - 38, "J·θ̈2 = −k·θ − T,   T = α(i)·z + c(i)·θ̇,   θ = θ2 − θ1", 16, INK, font_style="italic"),
        _text(
            20,
            HEIGHT - 14,
            f"seed's values: k = {shown['k_nm_per_rad']} N·m/rad, J = {shown['J_kg_m2']} "
            f"(√(k/J) ≈ {shown['natural_frequency_hz']} Hz); a schematic, not to scale",
            13,
            "#444",
        ),
        "</svg>",
    ]
    return "\n".join(lines) + "\n"


def write(out: Path) -> tuple[Path, Path]:
    """rig.svg and rig.json into ``out``."""
    out.mkdir(parents=True, exist_ok=True)
    figure, data = out / "rig.svg", out / "rig.json"
    figure.write_text(svg(), encoding="utf-8")
    data.write_text(
        json.dumps({"command": "tools/figures.py --figure rig", **numbers()}, indent=2, ensure_ascii=False) + "\n",
        encoding="utf-8",
    )
    return figure, data


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="draw into a temporary folder and check the SVG parses")
    args = parser.parse_args()
    if args.quick:
        with tempfile.TemporaryDirectory(prefix="rig_figure-") as tmp:
            figure, _ = write(Path(tmp))
            ElementTree.parse(figure)
            print(f"rig.svg: {figure.stat().st_size / 1e3:.1f} kB, parses")
        return
    for path in write(OUT):
        print(f"{path.relative_to(ROOT)}  {path.stat().st_size / 1e3:.1f} kB")


if __name__ == "__main__":
    main()
