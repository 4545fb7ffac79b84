"""The table of keeper deflections the scripted keeper aims with: it is the simulator's, and
it is read the right way round."""

from __future__ import annotations

import math

import numpy as np
import pytest

from foosball_gym.policies import deflection
from foosball_gym.sim import TableSim, probes
from foosball_gym.table import PHYSICS_REVISION


@pytest.fixture(scope="module")
def sim():
    sim = TableSim(["home_keeper"])
    yield sim
    sim.close()


def test_the_shipped_table_was_measured_on_the_current_physics():
    # Otherwise: python scripts/deflection_table.py
    assert deflection.table_revision() == PHYSICS_REVISION


@pytest.mark.parametrize(("i", "j"), [(0, 4), (5, 12), (10, 24)])
def test_the_shipped_table_is_what_the_simulator_measures_now(sim, i, j):
    table = deflection._table()[0]
    speed, angle = float(deflection.SPEEDS[i]), float(deflection.ANGLES[j])
    for k in range(60, 101, 8):  # offsets -5 mm to +5 mm: the flat and both edges
        found = probes.deflection(sim, speed, angle, float(deflection.OFFSETS[k]))
        assert found["out_deg"] == pytest.approx(float(table[i, j, k]), abs=0.5), k


def test_the_flat_face_returns_a_head_on_ball_straight_and_steepens_an_angled_one(sim):
    straight = probes.deflection(sim, 5.0, 0.0, 0.0)
    assert straight["out_deg"] == pytest.approx(0.0, abs=0.5)
    # Restitution 0.5, less what the ball's own turning (still the way it came) brakes.
    assert 0.2 * 5.0 < straight["out_speed"] < 0.5 * 5.0
    angled = probes.deflection(sim, 5.0, 15.0, 0.002)
    # Half the normal speed comes back, the sideways speed mostly stays: a steeper angle.
    assert 20.0 < angled["out_deg"] < 45.0


# Angles the table measured: between them the direction is good to a few degrees only (the
# contact moves across facets of the figurine's hull).
@pytest.mark.parametrize("angle_deg", [-25.0, -7.5, 0.0, 12.5, 30.0])
@pytest.mark.parametrize("want_deg", [-4.0, 0.0, 3.0])
def test_the_offset_found_sends_the_ball_where_it_was_asked(sim, angle_deg, want_deg):
    offset = deflection.deflection_offset(5.0, math.radians(angle_deg), math.radians(want_deg))
    assert offset is not None and abs(offset) < 0.015
    found = probes.deflection(sim, 5.0, angle_deg, offset)
    assert found["out_deg"] == pytest.approx(want_deg, abs=2.0), offset


def test_a_direction_out_of_the_feet_reach_has_no_offset():
    assert deflection.deflection_offset(5.0, math.radians(10.0), math.radians(89.0)) is None


def test_the_axes_match_the_table():
    table = deflection._table()[0]
    assert table.shape == (len(deflection.SPEEDS), len(deflection.ANGLES), len(deflection.OFFSETS))
    assert np.isnan(table).mean() < 0.1


def test_the_keeper_deflects_only_where_it_sees_the_simulators_own_state():
    # A deflection needs the ball's path to a millimetre: through a camera and a filter the
    # scripted keeper volleys instead (10 % against 49.5 % of incoming balls, measured).
    import gymnasium as gym

    from foosball_gym.registration import scripted_policy

    kwargs = {"ball_start": "incoming"}
    exact = gym.make("Foosball-Score-v0", **kwargs)
    estimated = gym.make("Foosball-Score-v0", estimated_state=True, **kwargs)
    try:
        assert exact.unwrapped.scripted_policy().deflect
        assert not estimated.unwrapped.scripted_policy().deflect
    finally:
        exact.close()
        estimated.close()
    assert scripted_policy("Foosball-Score-v0", kwargs).deflect
    assert not scripted_policy("Foosball-Score-v0", {**kwargs, "estimated_state": True}).deflect
    assert not scripted_policy("Foosball-Score-v0", kwargs, on_table=True).deflect
