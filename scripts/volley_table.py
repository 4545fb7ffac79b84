"""Measure the table of keeper volleys that the scripted keeper aims with.

    python scripts/volley_table.py [--processes 1]

Runs ``foosball_gym.sim.probes.volley`` over a grid of ball speeds, incoming angles,
ball-minus-figurine offsets and launch phases and writes the directions the ball left in to
``foosball_gym/policies/volley_table.npz`` (about 8,800 probes, about a minute on one core).
Run it again whenever the physics revision changes; ``tests/test_volley.py`` checks the
shipped table against fresh probes.
"""

from __future__ import annotations

import argparse
from multiprocessing import Pool

import numpy as np

from foosball_gym import table
from foosball_gym.policies.volley import ANGLES, OFFSETS, PHASES, SPEEDS, TABLE_PATH
from foosball_gym.sim import probes

_sim = None


def _row(job: tuple[float, float]) -> list[list[float]]:
    global _sim
    if _sim is None:
        from foosball_gym.sim import TableSim

        _sim = TableSim(["home_keeper"])
    speed, angle = job
    out = []
    for offset in OFFSETS:
        found = [
            probes.volley(_sim, float(speed), float(angle), float(offset), phase)
            for phase in PHASES
        ]
        out.append([np.nan if f["out_deg"] is None else f["out_deg"] for f in found])
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--processes", type=int, default=1)
    args = parser.parse_args()
    if args.processes < 1:
        parser.error(f"--processes must be 1 or more, got {args.processes}")
    jobs = [(s, a) for s in SPEEDS for a in ANGLES]
    if args.processes == 1:
        rows = [_row(job) for job in jobs]
    else:
        with Pool(args.processes) as pool:
            rows = pool.map(_row, jobs)
    shape = (len(SPEEDS), len(ANGLES), len(OFFSETS), len(PHASES))
    out = np.array(rows, dtype=np.float32).reshape(shape)
    np.savez_compressed(TABLE_PATH, out_deg=out, physics_revision=table.PHYSICS_REVISION)
    print(f"wrote {TABLE_PATH}: {out.size} probes, {np.isnan(out).mean():.1%} without a clean exit")


if __name__ == "__main__":
    main()
