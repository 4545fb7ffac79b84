"""A plain-text report of the simulated table's contacts, from the probes in
``foosball_gym.sim.probes``: wall rebounds, tunnelling, corner kicks, rolling, volleys,
a foot swung at the drive's top speed.

    python benchmarks/physics_report.py [--quick] [--contact-travel M] [--physics-hz HZ]
                                        [--json FILE]

``--contact-travel`` and ``--physics-hz`` reach ``TableSim`` only when given, so this file and
``foosball_gym/sim/probes.py``, copied into an older checkout whose ``TableSim`` lacks them,
measure that checkout too.
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import time
from collections.abc import Callable

from foosball_gym import table
from foosball_gym.sim import probes

try:
    from foosball_gym.sim import TableSim
except ImportError:  # a checkout from before the sim package
    from foosball_gym.simulator import TableSim

FULL = {
    "speeds": (1.5, 3.0, 5.0, 10.0, 15.0, 20.0),
    "angles": (0.0, 30.0, 60.0),
    "phases": 8,
    "tunnel_speeds": (10.0, 15.0, 20.0),
    "offsets_mm": tuple(0.5 * i for i in range(61)),
    "volley_angles": (-20.0, -10.0, 0.0, 10.0, 20.0),
}
QUICK = {
    "speeds": (1.5, 5.0, 20.0),
    "angles": (0.0, 60.0),
    "phases": 4,
    "tunnel_speeds": (10.0, 20.0),
    "offsets_mm": tuple(2.5 * i for i in range(13)),
    "volley_angles": (-20.0, 0.0, 20.0),
}
# Offsets (mm) the aiming keeper uses (foosball_gym/policies/aiming.py).
AIMABLE_MM = 26.0
TARGETS = ("figurine", "wall", "post")
VOLLEY_SPEED = 4.0


class _Counted:
    """A table that counts the control steps taken through it; everything else passes on."""

    def __init__(self, sim: TableSim) -> None:
        self._sim = sim
        self.control_steps = 0

    def step(self) -> tuple[int, bool]:
        self.control_steps += 1
        return self._sim.step()

    def __getattr__(self, name: str) -> object:
        return getattr(self._sim, name)


def _section(sim_kwargs: dict, work: Callable[[_Counted], object]) -> tuple[object, dict]:
    """Run ``work`` on a fresh keeper-only table; returns its result and the stepping cost."""
    sim = TableSim(["home_keeper"], **sim_kwargs)
    try:
        counted = _Counted(sim)
        before = getattr(sim, "physics_steps", None)
        start = time.perf_counter()
        result = work(counted)
        seconds = time.perf_counter() - start
        after = getattr(sim, "physics_steps", None)
    finally:
        sim.close()
    per_step = None
    if before is not None and after is not None and counted.control_steps:
        per_step = (after - before) / counted.control_steps
    cost = {
        "control_steps": counted.control_steps,
        "physics_per_control_step": per_step,
        "seconds": seconds,
    }
    return result, cost


def _rebounds(sim, grid: dict) -> list[dict]:
    cells = []
    phases = [k / grid["phases"] for k in range(grid["phases"])]
    for speed in grid["speeds"]:
        for angle in grid["angles"]:
            ratios = [probes.wall_rebound(sim, speed, angle, p) for p in phases]
            finite = [r for r in ratios if math.isfinite(r)]
            cells.append(
                {
                    "speed": speed,
                    "angle_deg": angle,
                    "ratios": ratios,
                    "min": min(finite, default=math.nan),
                    "median": statistics.median(finite) if finite else math.nan,
                    "max": max(finite, default=math.nan),
                    "lost": len(ratios) - len(finite),
                }
            )
    return cells


def _tunnelling(sim, grid: dict) -> list[dict]:
    return [
        {"speed": speed, "target": target, **probes.tunnelling(sim, speed, target)}
        for speed in grid["tunnel_speeds"]
        for target in TARGETS
    ]


def _corner_kicks(sim, grid: dict) -> dict:
    kicks = [{"offset_mm": mm, **probes.corner_kick(sim, mm / 1000)} for mm in grid["offsets_mm"]]
    unfolded = [k["unfolded_y"] for k in kicks]
    known = [u for u in unfolded if u is not None]
    trend = math.copysign(1.0, known[-1] - known[0]) if len(known) > 1 else 0.0

    def against(values: list) -> float | None:
        # Steps between neighbouring offsets that both reached the line.
        steps = [(b - a) * 1000 for a, b in zip(values, values[1:]) if None not in (a, b)]
        return max((max(-trend * s, 0.0) for s in steps), default=None)

    # The range the aiming keeper uses: past it kicks are weak (under 3 m/s at times) and
    # bounce twice, and unfolding their bounces with a fixed restitution is too crude.
    aimable = [k["unfolded_y"] for k in kicks if k["offset_mm"] <= AIMABLE_MM]
    steps = [(b - a) * 1000 for a, b in zip(unfolded, unfolded[1:]) if None not in (a, b)]
    return {
        "kicks": kicks,
        "trend": trend,
        "largest_step_against_trend_mm": against(unfolded),
        "largest_step_against_trend_aimable_mm": against(aimable),
        "largest_abs_step_mm": max((abs(s) for s in steps), default=None),
        "missed_line": len(unfolded) - len(known),
    }


def _volleys(sim, grid: dict) -> list[dict]:
    return [
        {"angle_deg": angle, **probes.volley(sim, VOLLEY_SPEED, angle)}
        for angle in grid["volley_angles"]
    ]


def measure(grid: dict, sim_kwargs: dict) -> dict:
    """Every section of the report, as numbers (what ``--json`` writes)."""
    start = time.perf_counter()
    sections = {
        "wall_rebound": lambda sim: _rebounds(sim, grid),
        "tunnelling": lambda sim: _tunnelling(sim, grid),
        "corner_kick": lambda sim: _corner_kicks(sim, grid),
        "rolling_distance": lambda sim: probes.rolling_distance(sim, 1.0),
        "volley": lambda sim: _volleys(sim, grid),
        "swinging_foot": lambda sim: [
            {"ball_speed": v, **probes.swinging_foot(sim, v)} for v in (0.0, 10.0, 20.0)
        ],
    }
    report: dict = {"sim_kwargs": sim_kwargs, "cost": {}}
    for name, work in sections.items():
        report[name], report["cost"][name] = _section(sim_kwargs, work)
    probe = TableSim(["home_keeper"], **sim_kwargs)
    report["simulator"] = {
        "physics_hz": getattr(probe, "physics_hz", None),
        "control_hz": getattr(probe, "control_hz", None),
        "contact_travel": getattr(probe, "contact_travel", None),
        "physics_revision": getattr(table, "PHYSICS_REVISION", None),
    }
    probe.close()
    report["wall_seconds"] = time.perf_counter() - start
    return report


def _yes(value: bool | None) -> str:
    """yes / NO, or a dash where an older probe did not say."""
    return "-" if value is None else "yes" if value else "NO"


def _f(value: float | None, fmt: str) -> str:
    """``value`` formatted, or a dash as wide as the format asks for None."""
    if value is None:
        width = fmt.split(".")[0]
        return format("-", f">{width}") if width else "-"
    return format(value, fmt)


def render(report: dict) -> str:
    """The report as plain text."""
    lines = []
    sim = report["simulator"]
    lines.append(
        f"Simulator: physics_hz {sim['physics_hz']}, control_hz {sim['control_hz']}, "
        f"contact_travel {sim['contact_travel']}, physics revision {sim['physics_revision']}; "
        f"TableSim arguments {report['sim_kwargs'] or 'default'}"
    )

    cells = report["wall_rebound"]
    angles = sorted({c["angle_deg"] for c in cells})
    phases = len(cells[0]["ratios"])
    lines += [
        "",
        "(a) Side-wall rebound: normal speed out / in, both carried to the wall (0.5 is the",
        f"    materials' restitution); min / median / max over {phases} moments of contact "
        "spread over a base physics step",
        f"{'speed m/s':>10s}" + "".join(f"{f'{a:g} deg':>24s}" for a in angles),
    ]
    for speed in sorted({c["speed"] for c in cells}):
        row = f"{speed:10.1f}"
        for a in angles:
            (c,) = [c for c in cells if c["speed"] == speed and c["angle_deg"] == a]
            text = f"{c['min']:.3f} {c['median']:.3f} {c['max']:.3f}"
            if c["lost"]:
                text += f" ({c['lost']} lost)"
            row += f"{text:>24s}"
        lines.append(row)

    lines += [
        "",
        "(b) Tunnelling: does a fast ball get through? Deepest overlap seen at a control step",
        f"{'speed m/s':>10s} {'target':>9s} {'passed':>7s} {'overlap mm':>11s} {'jumped out':>11s}"
        f" {'stopped':>8s}",
    ]
    for t in report["tunnelling"]:
        stopped = {True: "yes", False: "no"}.get(t.get("stopped"), "")
        lines.append(
            f"{t['speed']:10.1f} {t['target']:>9s} {'YES' if t['passed'] else 'no':>7s} "
            f"{t['max_overlap'] * 1000:11.2f} {'yes' if t['out_of_table'] else 'no':>11s}"
            f" {stopped:>8s}"
        )

    corner = report["corner_kick"]
    lines += [
        "",
        "(c) Corner kick: scripted kick of a still ball, struck offset from the foot's centre;",
        "    crossing of the away keeper's line x = 0.522, and with wall bounces unfolded",
        f"{'offset mm':>10s} {'angle deg':>10s} {'speed m/s':>10s} {'crossing mm':>12s}"
        f" {'unfolded mm':>12s} {'bounces':>8s}",
    ]
    for k in corner["kicks"]:
        crossing = None if k["crossing_y"] is None else k["crossing_y"] * 1000
        unfolded = None if k["unfolded_y"] is None else k["unfolded_y"] * 1000
        lines.append(
            f"{k['offset_mm']:10.1f} {k['angle_deg']:10.2f} {k['speed']:10.3f} "
            f"{_f(crossing, '12.1f')} {_f(unfolded, '12.1f')} {k['bounces']:8d}"
        )
    lines.append(
        f"    unfolded crossing against the trend: largest step "
        f"{_f(corner['largest_step_against_trend_aimable_mm'], '.1f')} mm up to {AIMABLE_MM:g} mm "
        f"of offset, {_f(corner['largest_step_against_trend_mm'], '.1f')} mm over all; "
        f"largest step either way "
        f"{_f(corner['largest_abs_step_mm'], '.1f')} mm; offsets that never reached the line: "
        f"{corner['missed_line']}"
    )

    lines += [
        "",
        f"(d) Rolling distance of a ball rolling at 1 m/s on a flat table: "
        f"{report['rolling_distance']:.2f} m",
        "",
        f"(e) Volley by the scripted keeper of a ball at {VOLLEY_SPEED:g} m/s "
        f"(in: from -x, out: from +x; positive towards +y)",
        f"{'in deg':>10s} {'out deg':>10s} {'out m/s':>10s}",
    ]
    for v in report["volley"]:
        if v["in_deg"] is None:
            lines.append(f"{v['angle_deg']:10.1f} {'no clean volley':>21s}")
        else:
            lines.append(f"{v['in_deg']:10.1f} {v['out_deg']:10.1f} {v['out_speed']:10.2f}")

    if "swinging_foot" in report:
        lines += [
            "",
            "(f) A foot driven forwards from its wind-up at the drive's top speed (its tip at",
            "    about 7 m/s by the ball) meets a ball at rest or coming at it: reported, not",
            "    required",
            f"{'ball m/s':>10s} {'returned':>9s} {'kicked':>7s} {'m/s after':>10s}"
            f" {'behind rod':>11s}",
        ]
        for f in report["swinging_foot"]:
            returned = f.get("returned")
            lines.append(
                f"{f['ball_speed']:10.1f} {_yes(returned):>9s} {_yes(f['kicked']):>7s} "
                f"{f['speed_after']:10.2f} {'yes' if f['behind'] else 'no':>11s}"
            )

    lines += [
        "",
        "(g) Cost",
        f"{'section':>18s} {'control steps':>14s} {'physics/control':>16s} {'seconds':>8s}",
    ]
    for name, c in report["cost"].items():
        lines.append(
            f"{name:>18s} {c['control_steps']:14d} "
            f"{_f(c['physics_per_control_step'], '16.1f')} {c['seconds']:8.1f}"
        )
    lines.append(f"Wall time of the report: {report['wall_seconds']:.1f} s")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="a reduced grid (a few seconds)")
    parser.add_argument("--contact-travel", type=float, help="TableSim(contact_travel=...)")
    parser.add_argument("--physics-hz", type=int, help="TableSim(physics_hz=...)")
    parser.add_argument("--json", metavar="FILE", help="also write the numbers to FILE")
    args = parser.parse_args()
    sim_kwargs = {}
    if args.contact_travel is not None:
        sim_kwargs["contact_travel"] = args.contact_travel
    if args.physics_hz is not None:
        sim_kwargs["physics_hz"] = args.physics_hz
    report = measure(QUICK if args.quick else FULL, sim_kwargs)
    print(render(report))
    if args.json:
        with open(args.json, "w") as f:
            # NaN and inf are not JSON: they are written as null.
            json.dump(_jsonable(report), f, indent=1)


def _jsonable(value):
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    return value


if __name__ == "__main__":
    main()
