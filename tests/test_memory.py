"""Making and closing environments does not leak: a sweep or a test suite builds hundreds."""

from __future__ import annotations

import gc
import sys

import gymnasium as gym
import pytest

import foosball_gym  # noqa: F401


def rss_kb() -> int:
    with open("/proc/self/status") as status:
        for line in status:
            if line.startswith("VmRSS:"):
                return int(line.split()[1])
    raise RuntimeError("no VmRSS in /proc/self/status")


def growth_kb(cycles: int) -> int:
    def cycle() -> None:
        env = gym.make("Foosball-FullGame-v0")
        env.reset(seed=0)
        env.close()
        del env
        gc.collect()

    for _ in range(10):  # caches and allocator pools fill first
        cycle()
    start = rss_kb()
    for _ in range(cycles):
        cycle()
    return rss_kb() - start


pytestmark = pytest.mark.skipif(sys.platform != "linux", reason="reads /proc/self/status")


def test_thirty_full_games_made_and_closed_do_not_grow_memory():
    # Bullet's URDF_MERGE_FIXED_LINKS leaked 108 kB a load: 3.2 MB here.
    grown = growth_kb(30)
    assert grown < 1_500, f"{grown} kB"


@pytest.mark.slow
def test_six_hundred_full_games_grow_memory_by_less_than_5_mb():
    grown = growth_kb(600)
    assert grown < 5_000, f"{grown} kB"
