"""Measurements of the simulated table's contacts, each reduced to a few plain numbers.

Every probe takes a :class:`foosball_gym.sim.TableSim` built by the caller with the home
keeper in play (``TableSim(["home_keeper"])``; other rods must not be in play), drives it
through its public control-step API only (``reset``, ``command``, ``step``, ``ball_xy``,
``ball_state``, ``joint_states``, ``physics_hz``, ``control_dt``), and never imports pybullet,
so the same file measures an older simulator as well as the current one.

The ball is seen only at the end of each control step (1/60 s): depths of penetration are
what those samples show, not the deepest point a contact reached between them.

Conventions: world frame of ``foosball_gym.table`` (home goal at x = -0.60, side walls at
y = +-0.34), metres, seconds, m/s; angles in degrees, measured as each probe says.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from foosball_gym import table
from foosball_gym.policies.scripted import KICK_ANGLE, WIND_UP_ANGLE

if TYPE_CHECKING:  # only for the hints: importing the simulator would import pybullet
    from foosball_gym.sim.table_sim import TableSim

R = table.BALL_RADIUS
# Where the ball's centre is when it touches a side wall.
WALL_Y = table.BALL_LIMIT_Y
KEEPER = table.rod("home_keeper")
# What of a figurine the ball meets, from the rod's axis: the front face (towards +x at spin 0)
# at the height of the ball's centre and the half width along y. The slim leg where the table
# models one (its section from 0.017 m up); an older table's figurine is one box.
if hasattr(table, "FIGURINE_LEG_SECTIONS"):
    _LEG_FRONT = table.FIGURINE_LEG_SECTIONS[-1][2]
    _LEG_HALF_WIDTH = table.FIGURINE_LEG_HALF_WIDTH
else:
    _LEG_FRONT = table.FIGURINE_SIZE[0] / 2
    _LEG_HALF_WIDTH = table.FIGURINE_SIZE[1] / 2
# How far before the keeper's line a deflection probe's ball is served (m): about the distance
# of the task's serves, so that it meets the foot turning as theirs do.
DEFLECTION_RUN = 0.55
# Beyond this spin (rad) the foot's sole is above a ball on the table.
_FOOT_CLEARS_BALL = math.acos((table.ROD_HEIGHT - 2 * R) / table.FIGURINE_FOOT_BELOW_AXIS)


def _control_dt(sim: TableSim) -> float:
    return getattr(sim, "control_dt", 1.0 / table.CONTROL_HZ)


def _base_dt(sim: TableSim) -> float:
    return 1.0 / getattr(sim, "physics_hz", table.PHYSICS_HZ)


def wall_rebound(sim: TableSim, speed: float, angle_deg: float, phase: float) -> float:
    """Coefficient of restitution of the ball's normal speed at the side wall y = +0.34.

    The ball is launched at ``speed`` towards the wall at ``angle_deg`` from the wall's
    normal, along +x as well as +y. It starts where, at that speed, it would touch the wall
    (centre at y = 0.34 - R) exactly ``n + phase`` base physics steps (``1 / sim.physics_hz``)
    after the reset: n = 8, or fewer where 8 steps of travel, and two control steps after the
    bounce, do not fit on the table (fast balls). A sweep over ``phase`` in [0, 1] thus puts
    the moment of contact everywhere within a fixed-rate physics step. The keeper is slid to
    +0.12 and stands still at x = -0.522, far from the path; the ball starts at x = 0.2, or
    further towards -x where the path after the bounce needs the room.

    Incoming: the normal speed on the last control-step sample before the ball touches the
    wall (or the launch), carried to the wall at the deceleration seen between that sample and
    the first one: v_in = sqrt(v_a^2 - 2 a d_a), d_a the sample's distance from the wall.
    Outgoing: the normal speed on the first sample at which the ball moves away with its
    centre 2 mm or more off the wall, carried back to the wall at the deceleration seen
    between that sample and the next: v_out = sqrt(v_b^2 + 2 a' d_b). The carrying matters for
    a ball that slides after its launch or its bounce (friction ~1 m/s^2: 2 % of the ratio at
    1.5 m/s); it is negligible for a rolling one.

    Returns:
        v_out / v_in; NaN if the ball never came back within 1 s.
    """
    a = math.radians(angle_deg)
    vn, vt = speed * math.cos(a), speed * math.sin(a)
    if vn <= 0:
        raise ValueError(f"the ball must move towards the wall, got angle {angle_deg} deg")
    if not 0.0 <= phase <= 1.0:
        raise ValueError(f"phase is a fraction of a physics step in [0, 1], got {phase}")
    dt, cdt = _base_dt(sim), _control_dt(sim)
    # After the bounce the ball runs on for up to two control steps (and 2 mm off the wall at
    # half its normal speed) before both samples are read; the end wall must not be in the way.
    after = vt * (2 * cdt + 0.004 / vn)
    n = 8
    while n > 0:
        before = (n + phase) * dt
        start_y = WALL_Y - vn * before
        hit_x = min(0.2 + vt * before, 0.5 - after)
        if start_y >= -0.25 and hit_x - vt * before >= -0.45:
            break
        n -= 1
    else:
        raise ValueError(f"a ball at {speed} m/s, {angle_deg} deg does not fit on the table")
    sim.reset(
        slide=[0.12],
        spin=[0.0],
        ball_position=(hit_x - vt * before, start_y),
        ball_velocity=(vt, vn),
    )
    # (y, vy) samples: before the contact, launch first; after it, from leaving 2 mm off.
    approach = [(start_y, vn)]
    away: list[tuple[float, float]] = []
    for _ in range(round(1.0 / cdt)):
        sim.command("position", [0.12, 0.0])
        sim.step()
        _, y, _, vy = sim.ball_xy()
        if away or (vy < 0 and y <= WALL_Y - 0.002):
            away.append((y, -vy))
            if len(away) == 2:
                break
        elif vy > 0 and y < WALL_Y - 1e-5:
            approach.append((y, vy))
    if len(away) < 2:
        return math.nan
    (_, v0), (ya, va) = approach[0], approach[-1]
    decel = (v0 - va) / ((len(approach) - 1) * cdt) if len(approach) > 1 else 0.0
    v_in = math.sqrt(max(va * va - 2 * decel * (WALL_Y - ya), 0.0))
    (yb, vb), (_, vc) = away
    decel = (vb - vc) / cdt
    v_out = math.sqrt(max(vb * vb + 2 * decel * (WALL_Y - yb), 0.0))
    return v_out / v_in


def _figurine_overlap(x: float, y: float, z: float, slide: float, spin: float) -> float:
    """How deep (m) the ball overlaps the front face of the home keeper's leg, from +x.

    The face is the leg's flat front at the ball centre's height, turned about the rod axis by
    ``spin``: at height z it lies at x = rod + (h - z) tan(spin) + front / cos(spin), h the
    axis height. 0 where the ball is not in front of the leg (|y - figurine| beyond the leg's
    half width) or the foot is lifted clear of the ball.
    """
    if abs(y - slide) > _LEG_HALF_WIDTH or abs(spin) > _FOOT_CLEARS_BALL:
        return 0.0
    face = KEEPER.x + (table.ROD_HEIGHT - z) * math.tan(spin) + _LEG_FRONT / math.cos(spin)
    return max(face + R - x, 0.0)


def _post_overlap(x: float, y: float) -> float:
    """How deep (m) the ball overlaps the home end wall beside the goal mouth.

    The wall's material at the ball's height is x <= -0.60 with |y| >= GOAL_HALF_WIDTH; its
    corner at the mouth's edge is sharp. Overlap = R minus the distance from the ball's centre
    to that region, or R plus the depth when the centre is inside it.
    """
    out_x = x + table.FIELD_HALF_LENGTH  # > 0: in front of the wall's face
    out_y = table.GOAL_HALF_WIDTH - abs(y)  # > 0: over the mouth
    if out_x <= 0 and out_y <= 0:
        return R + min(-out_x, -out_y)
    return max(R - math.hypot(max(out_x, 0.0), max(out_y, 0.0)), 0.0)


def tunnelling(sim: TableSim, speed: float, target: str) -> dict:
    """Whether a fast ball gets through something solid, and how deep it was seen inside.

    Targets (the ball launched as ``reset`` launches it, the keeper's drives given their
    targets every control step):

    - ``"figurine"``: along -x from x = 0.2 at y = 0, +0.008 and -0.008 at the keeper's
      figurine, held at slide 0, spin 0. Passed: the ball's centre was seen at
      x < keeper.x - 0.005 while within 0.012 of the figurine's y, or a goal at the home end.
      Overlap: with the leg's front face at the ball's height, turned with the rod's actual
      spin (the drive's 1.41 N m may give way to a hard shot).
    - ``"wall"``: along +y from (0.2, 0) at the side wall, head-on, keeper slid to +0.12.
      Passed: |y| > 0.34 (the centre beyond the wall's face). Overlap: |y| + R - 0.34.
    - ``"post"``: along -x from x = 0.2 at y = +-(GOAL_HALF_WIDTH + R / 2), so the ball meets
      the end wall's corner at the goal mouth's edge off centre, the keeper slid to the other
      side. Passed: the centre was seen at x < -0.60 - R with |y| > GOAL_HALF_WIDTH (inside
      the wall's material), or a goal at the home end (the ball started outside the mouth, and
      the corner deflects it outwards). Overlap: with the wall region, its corner included.

    Each run ends once the ball moves away from its target 5 cm clear of it (so the numbers
    are about the first impact, at the given speed), at a goal, or after 40 control steps.

    Returns:
        ``passed`` (any run), ``max_overlap`` (m, over every run's control-step samples),
        ``out_of_table`` (any run's ball jumped higher than the table's limit), and for the
        figurine ``stopped`` (every run's ball was seen moving back towards +x).
    """
    if target == "figurine":
        runs = [((0.2, y0), (-speed, 0.0), 0.0) for y0 in (0.0, 0.008, -0.008)]
    elif target == "wall":
        runs = [((0.2, 0.0), (0.0, speed), 0.12)]
    elif target == "post":
        y0 = table.GOAL_HALF_WIDTH + R / 2
        runs = [((0.2, s * y0), (-speed, 0.0), -s * KEEPER.slide_limit) for s in (1, -1)]
    else:
        raise ValueError(f"unknown target {target!r}; allowed: figurine, wall, post")
    passed = out = False
    stopped = True
    overlap = 0.0
    for position, velocity, slide in runs:
        sim.reset(slide=[slide], spin=[0.0], ball_position=position, ball_velocity=velocity)
        came_back = False
        for _ in range(40):
            sim.command("position", [slide, 0.0])
            goal, left = sim.step()
            out |= left
            ball = sim.ball_state()
            (x, y, z), vx = ball.position, ball.velocity[0]
            if target == "figurine":
                (slide_now, spin_now), _ = sim.joint_states()
                overlap = max(overlap, _figurine_overlap(x, y, z, slide_now, spin_now))
                passed |= x < KEEPER.x - 0.005 and abs(y - slide_now) < 0.012
                came_back |= vx > 0
                clear = vx > 0 and x > KEEPER.x + _LEG_FRONT + R + 0.05
            elif target == "wall":
                overlap = max(overlap, abs(y) + R - table.FIELD_HALF_WIDTH)
                passed |= abs(y) > table.FIELD_HALF_WIDTH
                clear = ball.velocity[1] < 0 and y < WALL_Y - 0.05
            else:
                overlap = max(overlap, _post_overlap(x, y))
                passed |= x < -table.FIELD_HALF_LENGTH - R and abs(y) > table.GOAL_HALF_WIDTH
                clear = vx > 0 and x > -table.FIELD_HALF_LENGTH + R + 0.05
            if goal != table.NO_GOAL:
                # Only a goal at the home end is the ball getting through; a rebound may
                # run the length of the table into the other one.
                passed |= goal == table.AWAY_SCORED
                break
            if clear:
                break
        stopped &= came_back
    result = {"passed": bool(passed), "max_overlap": float(overlap), "out_of_table": bool(out)}
    if target == "figurine":
        result["stopped"] = bool(stopped)
    return result


def unfold(y: float, walls: list[int], factor: float = 1.0) -> float:
    """A ball's y with its side-wall bounces undone, as if the walls were not there.

    By default the walls are mirrors: the unfolded coordinate moves exactly as far as the ball
    does, so a step in it is a step of the real crossing point, however many bounces came
    before. With ``factor`` < 1 each bounce is taken to keep that share of the sideways speed,
    and the unfolded coordinate moves ``1 / factor**k`` times as far as the ball after k
    bounces. With W = 0.34 - R and one bounce off +W: W + (W - y) / factor.

    Args:
        y: where the ball is now.
        walls: the side (+1 or -1) of each wall it bounced off, in order.
    """
    if not walls:
        return y
    # The sides alternate, so the first one sets the direction the unfolded y moves in.
    first = walls[0]
    u = first * WALL_Y
    for k in range(1, len(walls)):
        u += first * 2 * WALL_Y / factor**k
    return u + first * abs(walls[-1] * WALL_Y - y) / factor ** len(walls)


def _bounced(prev: tuple, now: tuple, cdt: float) -> int:
    """The side (+1/-1) of a side-wall bounce between two (x, y, vx, vy) samples, else 0."""
    (_, _, _, vy0), (_, y1, _, vy1) = prev, now
    if vy0 * vy1 >= 0 or min(abs(vy0), abs(vy1)) < 0.02:
        return 0
    near = (abs(vy0) + abs(vy1)) * cdt + 0.005
    side = 1 if vy0 > 0 else -1
    return side if side * y1 > WALL_Y - near else 0


def corner_kick(sim: TableSim, offset: float) -> dict:
    """Where a scripted kick struck off the foot's centre sends the ball.

    The ball lies still at (-0.497, 0); the keeper's figurine stands at y = -offset (ball y
    minus figurine y = +offset, in m), spin 0. The keeper winds up (spin target WIND_UP_ANGLE,
    25 control steps) and kicks (KICK_ANGLE, 6 steps), its slide target fixed. It keeps
    KICK_ANGLE while the ball runs on until its centre reaches x = +0.522 (the away keeper's
    line; no away rod is in play), for at most 240 more steps.

    Returns:
        ``angle_deg`` and ``speed``: direction (from +x, positive towards +y) and speed of the
        ball's velocity at the end of the 6 kick steps. ``crossing_y``: the ball's y where its
        centre crosses x = 0.522, on the straight line through the nearest sample on the near
        side of any wall bounce (None if it never got there). ``unfolded_y``: that crossing
        with the side-wall bounces before it undone, each taken to halve the sideways speed
        (see :func:`unfold`), a quantity that should move monotonically with ``offset``.
        ``bounces``: how many side-wall bounces came before the crossing.
    """
    slide = -offset
    sim.reset(slide=[slide], spin=[0.0], ball_position=(-0.497, 0.0), ball_velocity=(0.0, 0.0))
    for spin, steps in ((WIND_UP_ANGLE, 25), (KICK_ANGLE, 6)):
        for _ in range(steps):
            sim.command("position", [slide, spin])
            sim.step()
    x, y, vx, vy = now = sim.ball_xy()
    result = {
        "angle_deg": math.degrees(math.atan2(vy, vx)),
        "speed": math.hypot(vx, vy),
        "crossing_y": None,
        "unfolded_y": None,
        "bounces": 0,
    }
    line, cdt = -KEEPER.x, _control_dt(sim)
    walls: list[int] = []
    for _ in range(240):
        sim.command("position", [slide, KICK_ANGLE])
        sim.step()
        prev, now = now, sim.ball_xy()
        if now[0] >= line:
            break
        side = _bounced(prev, now, cdt)
        if side:
            walls.append(side)
    else:
        return result
    x, y, vx, vy = now
    # Back along the last velocity is right unless a bounce came after the crossing, which
    # puts that line beyond the wall; then forward from the sample before is.
    crossing = y - vy * (x - line) / vx if vx > 0 else math.inf
    if abs(crossing) > WALL_Y:
        px, py, pvx, pvy = prev
        crossing = py + pvy * (line - px) / pvx if pvx > 0 else py
    else:
        side = _bounced(prev, now, cdt)
        if side:
            walls.append(side)
    result.update(crossing_y=crossing, unfolded_y=unfold(crossing, walls), bounces=len(walls))
    return result


def rolling_distance(sim: TableSim, speed: float = 1.0) -> float:
    """How far a ball rolling at ``speed`` on a flat table would roll before it stops.

    The ball is launched at ``speed`` along +x at y = 0.25 from x = -0.56, the keeper slid to
    -0.12 (its figurine at y = -0.12, far from the path; its rod passes above the ball). A
    simulator that launches the ball without spin lets it slide first, slowing at the table's
    friction (~1 m/s^2) until it rolls at about 5/7 of the launch speed; that part is left
    out: rolling starts at the end of the first control step whose deceleration is below half
    the largest seen before it (from the first step's end if there is none, a ball launched
    rolling). From there to the first sample 1.0 m further on, or to the last before the end
    wall if the table is too short for that (about 0.85 m after a slide from 1 m/s), the mean
    deceleration is a = (v0^2 - v1^2) / (2 d), d the distance between the two samples.

    Returns:
        ``speed**2 / (2 a)`` in m; exact for a constant deceleration (rolling resistance), an
        underestimate where linear damping (proportional to the speed) matters. Inf if the
        ball did not slow down.
    """
    sim.reset(slide=[-0.12], spin=[0.0], ball_position=(-0.56, 0.25), ball_velocity=(speed, 0.0))
    cdt = _control_dt(sim)
    limit = table.FIELD_HALF_LENGTH - R - 0.002
    samples = [(-0.56, speed)]  # (x, vx) at the end of each control step, launch first
    start = None
    hardest = 0.0
    for _ in range(round(60.0 / cdt)):
        sim.command("position", [-0.12, 0.0])
        sim.step()
        x, _, vx, _ = sim.ball_xy()
        if x > limit or vx <= 0:
            break
        decel = (samples[-1][1] - vx) / cdt
        samples.append((x, vx))
        if start is None and decel < 0.5 * hardest:
            start = len(samples) - 1
        hardest = max(hardest, decel)
        if start is not None and x - samples[start][0] >= 1.0:
            break
    x0, v0 = samples[1 if start is None else start]
    x1, v1 = samples[-1]
    if x1 <= x0:
        raise RuntimeError(f"no rolling seen: the ball went from x = {x0} to {x1}")
    decel = (v0 * v0 - v1 * v1) / (2 * (x1 - x0))
    return math.inf if decel <= 0 else speed * speed / (2 * decel)


def volley(
    sim: TableSim, speed: float, angle_deg: float, offset: float = 0.0, phase: float = 0.0
) -> dict:
    """The direction a volley of the scripted keeper sends an incoming ball.

    The ball is launched from x = 0 at ``speed`` and ``angle_deg`` from -x (positive: moving
    towards +y), aimed to cross the keeper's line x = -0.522 at y = 0; the keeper holds its
    figurine at y = -``offset`` (``offset``: the ball's crossing y minus the figurine's, so the
    ball meets the flat face near 0 and a rounded end beyond about +-0.009 m), and it starts
    wound up (spin WIND_UP_ANGLE). On the first control step at whose start the ball's time to
    arrive, (x - keeper.x - 0.03) / |vx|, is 0.035 s or less, it swings (spin target
    KICK_ANGLE) and keeps that target.

    ``phase`` in [0, 1) moves the ball's start back along its path by ``phase`` control
    steps of travel (``phase * speed * control_dt``): a sweep over it makes the swing meet
    the ball at every point of a control step, as the swing of a keeper that decides once a
    step does.

    Returns:
        ``in_deg``: the ball's direction from -x (positive towards +y) on the sample before the
        swing. ``out_deg`` and ``out_speed``: its direction from +x (positive towards +y) and
        speed about 0.1 s (a whole number of control steps) after the first sample at which it
        had left the foot (vx > 0, x > keeper.x + 0.04), or on the last sample before a side
        wall if it got there sooner. All None if there was no clean volley: a goal, the ball
        off the table, or no ball leaving the foot within 1.5 s.
    """
    a = math.radians(angle_deg)
    vx, vy = -speed * math.cos(a), speed * math.sin(a)
    if vx >= 0:
        raise ValueError(f"the ball must come towards the keeper, got angle {angle_deg} deg")
    if not 0.0 <= phase < 1.0:
        raise ValueError(f"phase is a fraction of a control step in [0, 1), got {phase}")
    cdt = _control_dt(sim)
    back = phase * speed * cdt
    x0 = back * math.cos(a)
    y0 = -vy * KEEPER.x / vx - back * math.sin(a)
    slide = -offset  # the figurine's y is the slide
    sim.reset(slide=[slide], spin=[WIND_UP_ANGLE], ball_position=(x0, y0), ball_velocity=(vx, vy))
    none = {"in_deg": None, "out_deg": None, "out_speed": None}
    after = max(1, round(0.1 / cdt))
    swing = False
    in_deg = None
    left_at = None
    last_clean = None
    for k in range(round(1.5 / cdt)):
        x, y, bvx, bvy = sim.ball_xy()
        if not swing and bvx < 0 and (x - KEEPER.x - 0.03) / -bvx <= 0.035:
            swing = True
            in_deg = math.degrees(math.atan2(bvy, -bvx))
        sim.command("position", [slide, KICK_ANGLE if swing else WIND_UP_ANGLE])
        goal, out = sim.step()
        if goal != table.NO_GOAL or out:
            return none
        x, y, bvx, bvy = now = sim.ball_xy()
        if left_at is None:
            if swing and bvx > 0 and x > KEEPER.x + 0.04:
                left_at, last_clean = k, now
            continue
        assert last_clean is not None  # set with left_at
        if _bounced(last_clean, now, cdt) or abs(y) >= WALL_Y - 0.002:
            break
        last_clean = now
        if k - left_at >= after:
            break
    if last_clean is None or in_deg is None:
        return none
    _, _, bvx, bvy = last_clean
    return {
        "in_deg": in_deg,
        "out_deg": math.degrees(math.atan2(bvy, bvx)),
        "out_speed": math.hypot(bvx, bvy),
    }


def swinging_foot(sim: TableSim, ball_speed: float) -> dict:
    """A foot swung as hard as its drive can meets a ball: is it kicked, or passed through?

    The keeper is driven forwards at the drive's top speed (velocity control, 100 pi rad/s)
    from its feet raised behind the rod, while the ball rolls at ``ball_speed`` along -x at
    the figurine (or rests in front of it, x = keeper.x + 0.025, at 0). The drive's torque
    gets the foot's tip to about 7 m/s by the ball. Physics that resolves the contact sends
    the ball back forwards; a foot that jumped through it in one step leaves it on its way, or
    behind the rod. Reported, not required.

    Returns:
        ``returned``: the ball was last seen moving along +x, in front of the rod; ``kicked``:
        faster than it came; ``speed_after``: its speed then (m/s); ``behind``: it ended
        behind the rod.
    """
    start_x = KEEPER.x + 0.025 if ball_speed == 0 else KEEPER.x + 0.025 + ball_speed * 0.03
    sim.reset(
        slide=[0.0],
        spin=[WIND_UP_ANGLE],
        ball_position=(start_x, 0.0),
        ball_velocity=(-ball_speed, 0.0),
    )
    sim.command("velocity", [0.0, 100 * math.pi])
    for _ in range(6):
        goal, out = sim.step()
        if goal != table.NO_GOAL or out:
            break
    x, _, vx, vy = sim.ball_xy()
    sim.command("position", [0.0, 0.0])
    return {
        "returned": vx > 0 and x > KEEPER.x,
        "kicked": vx > ball_speed and x > KEEPER.x,
        "speed_after": math.hypot(vx, vy),
        "behind": x < KEEPER.x,
    }


def deflection(sim: TableSim, speed: float, angle_deg: float, offset: float) -> dict:
    """Where a still keeper sends a ball that rolls into it: the deflection a keeper aims.

    The ball is launched at ``speed`` and ``angle_deg`` from -x (positive: moving towards +y)
    so that it crosses the keeper's line x = -0.522 at y = 0, from DEFLECTION_RUN m before
    that line (less where a steep ball would meet a side wall first), as a served ball comes
    from half the table away, turning on its way as such a ball does. The keeper holds its
    figurine still and upright (spin 0) at y = -``offset``: ``offset`` is the ball's crossing
    y minus the figurine's, so the ball meets the flat face near 0 and a rounded end beyond
    about +-0.009 m.

    Returns:
        ``out_deg``: the ball's direction from +x (positive towards +y) and ``out_speed`` its
        speed three control steps after the first sample at which it had left the foot
        (vx > 0, x > keeper.x + 0.04). Both None if it did not leave within 2 s, scored or
        left the table.
    """
    a = math.radians(angle_deg)
    vx, vy = -speed * math.cos(a), speed * math.sin(a)
    if vx >= 0:
        raise ValueError(f"the ball must come towards the keeper, got angle {angle_deg} deg")
    run = DEFLECTION_RUN
    if vy != 0.0:
        run = min(run, (WALL_Y - 0.04) * -vx / abs(vy))
    sim.reset(
        slide=[-offset],
        spin=[0.0],
        ball_position=(KEEPER.x + run, vy / vx * run),
        ball_velocity=(vx, vy),
    )
    none = {"out_deg": None, "out_speed": None}
    left_at = None
    for k in range(round(2.0 / _control_dt(sim))):
        sim.command("position", [-offset, 0.0])
        goal, out = sim.step()
        if goal != table.NO_GOAL or out:
            return none
        x, _, bvx, bvy = sim.ball_xy()
        if left_at is None and bvx > 0 and x > KEEPER.x + 0.04:
            left_at = k
        if left_at is not None and k - left_at >= 2:
            return {
                "out_deg": math.degrees(math.atan2(bvy, bvx)),
                "out_speed": math.hypot(bvx, bvy),
            }
    return none
