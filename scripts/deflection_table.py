"""Measure the table of keeper deflections that the scripted keeper aims with.

    python scripts/deflection_table.py [--processes 2]

Runs ``foosball_gym.sim.probes.deflection`` over a grid of ball speeds, incoming angles and
ball-minus-figurine offsets and writes the directions the ball left in to
``foosball_gym/policies/deflection_table.npz`` (about 62,000 probes, 40 s on 2 cores). Run it
again whenever the physics revision changes; ``tests/test_deflection.py`` checks the shipped
table against fresh probes.
"""

from __future__ import annotations

import argparse
from multiprocessing import Pool

import numpy as np

from foosball_gym import table
from foosball_gym.policies.deflection import ANGLES, OFFSETS, SPEEDS, TABLE_PATH
from foosball_gym.sim import probes

_sim = None


def _row(job: tuple[float, float]) -> list[float]:
    global _sim
    if _sim is None:
        from foosball_gym.sim import TableSim

        _sim = TableSim(["home_keeper"])
    speed, angle = job
    out = []
    for offset in OFFSETS:
        found = probes.deflection(_sim, float(speed), float(angle), float(offset))
        out.append(np.nan if found["out_deg"] is None else found["out_deg"])
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--processes", type=int, default=2)
    args = parser.parse_args()
    jobs = [(s, a) for s in SPEEDS for a in ANGLES]
    with Pool(args.processes) as pool:
        rows = pool.map(_row, jobs)
    out = np.array(rows, dtype=np.float32).reshape(len(SPEEDS), len(ANGLES), len(OFFSETS))
    np.savez_compressed(TABLE_PATH, out_deg=out, physics_revision=table.PHYSICS_REVISION)
    print(f"wrote {TABLE_PATH}: {out.size} probes, {np.isnan(out).mean():.1%} without a clean exit")


if __name__ == "__main__":
    main()
