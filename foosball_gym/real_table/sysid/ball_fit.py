"""The ball's physics, fitted by replaying the logged stretches in the simulator.

Two steps, each with what shows its parameters best
(:mod:`~foosball_gym.real_table.sysid.segments`):

1. **Rolling resistance and friction**, from the stretches the ball spends on the cloth alone,
   between wall bounces: each is replayed on the bare simulated table from a starting state
   (position, velocity and the spin, which the camera cannot see), and the two parameters are
   those under which the replays best match the camera, every stretch's start fitted with
   them. On the cloth the replays change smoothly with everything fitted. (A stretch that
   begins at a bounce is left to step 2: its spin is the bounce's doing, and its frames
   hardly show it.)
2. **Restitution**, from the wall bounces between two such stretches: the simulator carries the
   ball on from the first stretch's fitted start through the bounce, and each bounce's
   restitution is the one under which the ball leaves the wall as fast as the camera saw it
   (the slope of its track away from the wall over the next frames). A bounce happens at one
   of the simulator's discrete steps, so a position after it jumps as anything before it
   changes; its speed away from the wall does not.

Every start is fitted under the table's default physics first: how far those replays are from
the camera is the residual before the fit, as the fitted physics' is after it; the bounces'
residual is the speed off the walls under the default restitution and the fitted one.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import OptimizeResult, brentq, least_squares

from foosball_gym import table
from foosball_gym.progress import Progress
from foosball_gym.real_table.sysid.segments import BallSegment
from foosball_gym.sim.replay import BallReplay

#: The ball's parameters fitted, with the table's defaults and the bounds the environments
#: allow.
BALL_PARAMETERS = ("rolling_resistance", "ball_restitution", "ball_friction")
BALL_DEFAULTS = {
    "rolling_resistance": table.ROLLING_RESISTANCE,
    "ball_restitution": table.BALL_TABLE_RESTITUTION,
    "ball_friction": table.BALL_MATERIAL.dynamic_friction,
}
BALL_BOUNDS = {
    "rolling_resistance": (0.0, 0.5),
    "ball_restitution": (0.0, 1.0),
    "ball_friction": (0.0, 10.0),
}
# A stretch whose replay stays further from the camera (RMS) than this many times the median
# stretch, and more than _OUTLIER_M, is one the bare table cannot reproduce (the ball in the
# air after a kick, a hand on a real table): it is left out and the fit done again.
_OUTLIER_FACTOR = 4.0
_OUTLIER_M = 5e-4
# Finite-difference steps, each parameter's own (absolute, for values below 1): large enough
# that the replays' own jitter (about 0.06 mm) does not swamp them.
_ROLLING_STEPS = np.array([1e-3, 0.01])  # rolling resistance, friction
_STATE_STEPS = np.array([2e-3, 2e-3, 5e-3, 5e-3, 0.01, 0.01])
_STATE = 6  # x, y, vx, vy, and the velocity (ux, uy) the ball's spin would roll it at
# A start under given physics settles within a few Gauss-Newton steps (from a start fitted
# under physics near by, within two or three); the physics within a few steps more.
_START_ITERATIONS = 20
_WARM_ITERATIONS = 6
_OUTER_ITERATIONS = 8
# A step this small a share of the value ends the fit, whatever the uncertainty.
_SETTLED = 0.005
# The most one step changes rolling resistance and friction.
_ROLLING_REACH = np.array([0.02, 0.1])
# A stretch whose first frames (over this long, s) show a deceleration beyond this (m/s^2) is
# taken to start sliding: rolling slows a ball by a tenth of that or less.
_EARLY_S = 0.25
_SLIDING_PULL = 0.3
# A bounce's speed away from the wall is the slope of the track over at most this long after it
# (s), from at least _SLOPE_FRAMES frames.
_SLOPE_S = 0.25
_SLOPE_FRAMES = 5
# A bounce's restitution further than this many standard deviations (from the spread of the
# others) from their median, and further than _BOUNCE_TOLERANCE, is left out.
_BOUNCE_OUTLIER = 4.0
_BOUNCE_TOLERANCE = 0.05
# A bounce whose speed into the wall is below this (m/s) says little about the restitution.
_MIN_NORMAL_SPEED = 0.15


@dataclass
class BallFit:
    """What the ball's fit found.

    Attributes:
        values, std: each fitted parameter and its standard uncertainty (inf where the logs do
            not show it; the value is then the default).
        rms_before_mm, rms_after_mm: the replays' distance from the camera's measurements
            (RMS over every frame of the stretches, mm) under the default physics and under the
            fitted one, each stretch from its start fitted under that physics.
        bounce_rms_before_mm_s, bounce_rms_after_mm_s: the RMS difference between the speed the
            replays and the camera had the ball leave the walls at (mm/s), under the default
            restitution and the fitted one (NaN without a bounce).
        problem: the replays of every stretch found; ``kept`` those fitted (not those after a
            bounce, whose start the bounce makes, nor those left out as outliers).
        bounces: the wall bounces the restitution was fitted to, and what each gave:
            ``(stretch after it, restitution)``.
        starts_before, starts_after: each stretch's fitted start under the two physics.
    """

    values: dict[str, float]
    std: dict[str, float]
    rms_before_mm: float
    rms_after_mm: float
    bounce_rms_before_mm_s: float
    bounce_rms_after_mm_s: float
    problem: BallProblem = field(repr=False)
    kept: list[int] = field(repr=False)
    bounces: list[tuple[int, float]] = field(repr=False)
    starts_before: np.ndarray = field(repr=False)
    starts_after: np.ndarray = field(repr=False)

    @property
    def segments(self) -> list[BallSegment]:
        """The stretches fitted (those left out as outliers not among them)."""
        return [self.problem.segments[i] for i in self.kept]

    @property
    def dropped(self) -> int:
        """The stretches left out as outliers."""
        return sum(s.wall is None for s in self.problem.segments) - len(self.kept)

    @property
    def frames(self) -> int:
        return sum(len(s.times) for s in self.segments)

    @property
    def seconds(self) -> float:
        return sum(s.duration for s in self.segments)

    def physics(self, fitted: bool = True) -> np.ndarray:
        """The physics (rolling resistance, restitution, friction) fitted, or the default."""
        values = self.values if fitted else BALL_DEFAULTS
        return np.array([values[name] for name in BALL_PARAMETERS])


class BallProblem:
    """Replays of the stretches under given physics and starts."""

    def __init__(self, segments: list[BallSegment], replay: BallReplay) -> None:
        self.segments = segments
        self.replay = replay
        sizes = [2 * len(s.times) for s in segments]
        self.rows = np.concatenate([[0], np.cumsum(sizes)]).astype(int)

    def track(
        self, physics: np.ndarray, segment: int, start: np.ndarray, times: np.ndarray | None = None
    ) -> np.ndarray:
        """Where the replay of ``segment`` from ``start`` puts the ball at its frames' times
        (or at ``times`` after its start)."""
        rr, e, f = (float(v) for v in physics)
        seg = self.segments[segment]
        return self.replay.track(
            start,
            seg.times if times is None else times,
            rolling_resistance=rr,
            restitution=e,
            friction=f,
        )

    def residuals(
        self, physics: np.ndarray, starts: np.ndarray, which: list[int] | None = None
    ) -> np.ndarray:
        """Replay minus camera, x and y of every frame of the stretches ``which`` (all)."""
        which = list(range(len(self.segments))) if which is None else which
        return np.concatenate(
            [
                (self.track(physics, i, starts[k]) - self.segments[i].xy).ravel()
                for k, i in enumerate(which)
            ]
        )

    def clusters(self, which: list[int]) -> np.ndarray:
        return np.concatenate([np.full(2 * len(self.segments[i].times), i) for i in which])

    def rms(self, residuals: np.ndarray, which: list[int]) -> np.ndarray:
        """Each stretch's RMS residual, from residuals laid out as :meth:`residuals` does."""
        out, row = [], 0
        for i in which:
            size = 2 * len(self.segments[i].times)
            out.append(float(np.sqrt(np.mean(residuals[row : row + size] ** 2))))
            row += size
        return np.array(out)


def fit_ball(
    segments: list[BallSegment], replay: BallReplay, count: Progress | None = None
) -> BallFit:
    """Fit the ball's parameters to the stretches (see the module's docstring).

    Args:
        segments: the stretches of the ball's track.
        replay: the simulator that replays them.
        count: counts each stretch's start fitted, out of the most the fit may take (it
            ends short where the physics settles early).

    Raises:
        ValueError: no stretch to fit.
    """
    if not segments:
        raise ValueError("no stretch of the ball's track to fit")
    defaults = np.array([BALL_DEFAULTS[name] for name in BALL_PARAMETERS])
    problem = BallProblem(segments, replay)
    # A stretch after a bounce starts with the spin the bounce left, which its frames hardly
    # show: it is left to the restitution, which replays the ball through the bounce instead.
    kept = [i for i, s in enumerate(segments) if s.wall is None]
    if not kept:
        raise ValueError("no stretch of the ball's track to fit")
    if count is not None:
        count.set_total(count.done + (_OUTER_ITERATIONS + 2) * len(kept))
    guess = np.zeros((len(segments), _STATE))
    guess[kept] = [first_guess(problem, defaults, i) for i in kept]
    starts_before = fit_starts(problem, defaults, guess, kept, count)
    # 1. Rolling resistance and friction, every start with them.
    physics, starts, rolling_std = _fit_rolling(
        problem, defaults, starts_before.copy(), kept, count
    )
    rms = problem.rms(problem.residuals(physics, starts[kept], kept), kept)
    bad = (rms > _OUTLIER_FACTOR * np.median(rms)) & (rms > _OUTLIER_M)
    if bad.any() and (~bad).sum() >= 2:
        kept = [i for i, out in zip(kept, bad) if not out]
        if count is not None:
            count.set_total(count.done + (_OUTER_ITERATIONS + 1) * len(kept))
        physics, starts, rolling_std = _fit_rolling(problem, physics, starts, kept, count)
    # 2. Restitution, from the bounces out of the stretches kept.
    found = [b for b in _bounces(problem, physics, starts, kept) if b.restitution is not None]
    physics[1], restitution_std, bounces = _combine(found)
    before = problem.residuals(defaults, starts_before[kept], kept)
    after = problem.residuals(physics, starts[kept], kept)
    return BallFit(
        values=dict(zip(BALL_PARAMETERS, (float(v) for v in physics))),
        std={
            "rolling_resistance": float(rolling_std[0]),
            "ball_restitution": restitution_std,
            "ball_friction": float(rolling_std[1]),
        },
        rms_before_mm=1e3 * float(np.sqrt(np.mean(before**2))),
        rms_after_mm=1e3 * float(np.sqrt(np.mean(after**2))),
        bounce_rms_before_mm_s=1e3 * _gap_rms(bounces, defaults[1]),
        bounce_rms_after_mm_s=1e3 * _gap_rms(bounces, physics[1]),
        problem=problem,
        kept=kept,
        bounces=[(b.after, float(b.restitution or 0.0)) for b in bounces],
        starts_before=starts_before,
        starts_after=starts,
    )


def windows(problem: BallProblem, kept: list[int]) -> list[list[int]]:
    """The stretches replayed as one: each kept stretch, with the one after its bounce where
    there is one."""
    after = {s.follows: i for i, s in enumerate(problem.segments) if s.follows is not None}
    return [[i, after[i]] if i in after else [i] for i in kept]


def window_track(
    problem: BallProblem, physics: np.ndarray, start: np.ndarray, window: list[int]
) -> tuple[np.ndarray, np.ndarray]:
    """The replay of a window from its first stretch's start, at every frame of the window:
    (times after the first stretch's start, positions)."""
    first = problem.segments[window[0]]
    times = np.concatenate(
        [problem.segments[i].times + problem.segments[i].t0 - first.t0 for i in window]
    )
    return times, problem.track(physics, window[0], start, times)


def first_guess(problem: BallProblem, physics: np.ndarray, segment: int) -> np.ndarray:
    """A stretch's start: its position and velocity from its first frames, and of a few spins,
    the one whose replay comes closest to the whole stretch.

    A sliding ball decelerates by friction against its slip, several times faster than a
    rolling one: where the first frames show that, the candidates slip against the
    deceleration by a range of speeds; rolling is always one.
    """
    seg = problem.segments[segment]
    n = min(5, len(seg.times))
    vx, x0 = np.polyfit(seg.times[:n], seg.xy[:n, 0], 1)
    vy, y0 = np.polyfit(seg.times[:n], seg.xy[:n, 1], 1)
    spins = [(vx, vy), (0.0, 0.0)]
    early = int(np.searchsorted(seg.times, _EARLY_S, side="right"))
    if early >= 6:
        ax = 2 * np.polyfit(seg.times[:early], seg.xy[:early, 0], 2)[0]
        ay = 2 * np.polyfit(seg.times[:early], seg.xy[:early, 1], 2)[0]
        pull = math.hypot(ax, ay)
        if pull > _SLIDING_PULL:
            speed = math.hypot(vx, vy)
            for share in (0.25, 0.5, 1.0, 1.5, 2.0, 3.0):
                slip = share * speed
                spins.append((vx + slip * ax / pull, vy + slip * ay / pull))
    starts = [np.array([x0, y0, vx, vy, ux, uy]) for ux, uy in spins]
    costs = [
        float(np.sum((problem.track(physics, segment, start) - seg.xy) ** 2)) for start in starts
    ]
    return starts[int(np.argmin(costs))]


def fit_start(
    problem: BallProblem,
    physics: np.ndarray,
    segment: int,
    start: np.ndarray,
    iterations: int = _START_ITERATIONS,
) -> OptimizeResult:
    """One stretch's start under fixed physics, from ``start``: scipy's result, whose ``jac``
    is the replay's Jacobian in the start there."""
    seg = problem.segments[segment]

    def fun(x: np.ndarray) -> np.ndarray:
        return (problem.track(physics, segment, x) - seg.xy).ravel()

    return least_squares(
        fun,
        np.asarray(start, dtype=float),
        diff_step=_STATE_STEPS,
        ftol=1e-3,
        max_nfev=iterations,
    )


def fit_starts(
    problem: BallProblem,
    physics: np.ndarray,
    starts: np.ndarray,
    which: list[int],
    count: Progress | None = None,
) -> np.ndarray:
    """The starts of the stretches ``which`` under fixed physics (``starts`` indexed by
    stretch; those not in ``which`` are kept), each counted into ``count``."""
    out = np.array(starts, dtype=float)
    for i in which:
        out[i] = fit_start(problem, physics, i, out[i]).x
        if count is not None:
            count.update()
    return out


def _fit_rolling(
    problem: BallProblem,
    physics: np.ndarray,
    starts: np.ndarray,
    which: list[int],
    count: Progress | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rolling resistance and friction, the starts of the stretches ``which`` fitted with them:
    (physics, starts, the two parameters' uncertainties: the data's, and the last step's).

    Gauss-Newton on the two parameters alone (variable projection): at each step every
    stretch's start is fitted under the physics so far, and the step is taken on what the
    physics changes in the replays that a change of the start cannot take up. A start is a
    small fit of its own, which a joint fit of all would make share one trust region with
    every other.
    """
    physics = np.array(physics, dtype=float)
    starts = np.array(starts, dtype=float)
    low = np.array([BALL_BOUNDS["rolling_resistance"][0], BALL_BOUNDS["ball_friction"][0]])
    high = np.array([BALL_BOUNDS["rolling_resistance"][1], BALL_BOUNDS["ball_friction"][1]])
    covariance = np.full((2, 2), np.inf)
    last = np.zeros(2)
    for step_number in range(1, _OUTER_ITERATIONS + 1):
        if count is not None:
            count.set_note(f"step {step_number} of at most {_OUTER_ITERATIONS}")
        bread, scores = np.zeros((2, 2)), []
        for i in which:
            start = _better(problem, physics, i, starts[i])
            result = fit_start(problem, physics, i, start, _WARM_ITERATIONS)
            starts[i] = result.x
            reduced = _reduced_jacobian(problem, physics, i, result)
            scores.append(reduced.T @ result.fun)
            bread += reduced.T @ reduced
            if count is not None:
                count.update()
        step = -np.linalg.lstsq(bread, np.sum(scores, axis=0), rcond=1e-12)[0]
        covariance = _sandwich(bread, np.array(scores))
        # A step back over the last one overshot: half as far. Never further than the
        # parameters' scale at once, nor past their bounds.
        step = np.where(step * last < 0, 0.5 * step, step)
        step = np.clip(step, -_ROLLING_REACH, _ROLLING_REACH)
        new = np.clip(physics[[0, 2]] + step, low, high)
        last = new - physics[[0, 2]]
        physics[[0, 2]] = new
        # Settled: the step is within the uncertainty, or a small share of the value.
        settled = np.maximum(np.sqrt(np.diag(covariance)), _SETTLED * np.abs(new))
        if np.all(np.abs(last) <= settled):
            if count is not None:
                count.set_note(f"settled in {step_number} of at most {_OUTER_ITERATIONS} steps")
            break
    for i in which:
        starts[i] = fit_start(problem, physics, i, starts[i], _WARM_ITERATIONS).x
        if count is not None:
            count.update()
    # The last step is as far as the fit may still be from where it would settle: it counts
    # into the uncertainty with the data's own.
    return physics, starts, np.sqrt(np.diag(covariance) + last**2)


def _better(problem: BallProblem, physics: np.ndarray, segment: int, start: np.ndarray):
    """Of a stretch's start so far and a fresh guess under ``physics``, the one whose replay
    comes closer: a start fitted under other physics can be stuck where the fresh one is not."""
    seg = problem.segments[segment]
    fresh = first_guess(problem, physics, segment)
    costs = [
        float(np.sum((problem.track(physics, segment, x) - seg.xy) ** 2)) for x in (start, fresh)
    ]
    return start if costs[0] <= costs[1] else fresh


def _reduced_jacobian(
    problem: BallProblem, physics: np.ndarray, segment: int, result: OptimizeResult
) -> np.ndarray:
    """How the replay of ``segment`` changes with rolling resistance and friction, less what
    its start, fitted in ``result``, can take up: (residuals, 2)."""
    base = problem.track(physics, segment, result.x).ravel()
    columns = []
    for k, h in zip((0, 2), _ROLLING_STEPS):
        moved = physics.copy()
        moved[k] += h
        columns.append((problem.track(moved, segment, result.x).ravel() - base) / h)
    along = np.stack(columns, 1)
    start_jac = np.asarray(result.jac)
    taken = start_jac @ np.linalg.lstsq(start_jac, along, rcond=1e-10)[0]
    return along - taken


def _sandwich(bread: np.ndarray, scores: np.ndarray) -> np.ndarray:
    """The covariance of the parameters, stretches taken as independent and the frames within
    one not."""
    n = len(scores)
    inverse = np.linalg.pinv(bread)
    meat = scores.T @ scores * n / max(n - 1, 1)
    return inverse @ meat @ inverse


class Bounce:
    """A wall bounce between two stretches: how fast the ball left the wall, as the camera saw
    it and as the simulator has it for a restitution, carried on from the first stretch's start.

    Args:
        problem: the stretches' replays.
        physics: rolling resistance, (any) restitution and friction.
        start: the fitted start of stretch ``before``.
        before, after: the stretches either side of the bounce.
    """

    def __init__(
        self, problem: BallProblem, physics: np.ndarray, start: np.ndarray, before: int, after: int
    ) -> None:
        self.problem, self.physics, self.start = problem, physics, start
        self.before, self.after = before, after
        first, seg = problem.segments[before], problem.segments[after]
        self.axis = 0 if seg.wall == "end" else 1
        frames = int(np.searchsorted(seg.times, _SLOPE_S, side="right"))
        self.times = seg.times[:frames]
        self.offset = seg.t0 - first.t0
        self.into = abs(float(start[2 + self.axis]))
        self.seen = (
            float(np.polyfit(self.times, seg.xy[:frames, self.axis], 1)[0])
            if frames >= _SLOPE_FRAMES
            else math.nan
        )
        self.restitution = self._solve() if self.into >= _MIN_NORMAL_SPEED else None

    def slope(self, restitution: float) -> float:
        """The replay's speed away from the wall over the frames after the bounce (m/s)."""
        physics = np.array([self.physics[0], restitution, self.physics[2]])
        track = self.problem.track(physics, self.before, self.start, self.times + self.offset)
        return float(np.polyfit(self.times, track[:, self.axis], 1)[0])

    def gap(self, restitution: float) -> float:
        """How much faster (m/s) the replay leaves the wall than the camera saw."""
        return abs(self.slope(restitution)) - abs(self.seen)

    def _solve(self) -> float | None:
        """The restitution that leaves the wall as fast as the camera saw; None where the
        camera saw too little, or none does."""
        if not math.isfinite(self.seen):
            return None
        low, high = 0.02, BALL_BOUNDS["ball_restitution"][1]
        g_low, g_high = self.gap(low), self.gap(high)
        if not g_low <= 0 <= g_high or np.sign(self.slope(high)) != np.sign(self.seen):
            return None
        if g_low == 0 or g_high == 0:
            return low if g_low == 0 else high
        return float(brentq(self.gap, low, high, xtol=1e-4))


def _bounces(
    problem: BallProblem, physics: np.ndarray, starts: np.ndarray, kept: list[int]
) -> list[Bounce]:
    """Every bounce out of a kept stretch into another; ``starts`` indexed by stretch."""
    return [
        Bounce(problem, physics, starts[seg.follows], seg.follows, i)
        for i, seg in enumerate(problem.segments)
        if seg.follows is not None and seg.follows in kept
    ]


def _combine(bounces: list[Bounce]) -> tuple[float, float, list[Bounce]]:
    """The restitution of all bounces, each weighed by its speed into the wall squared (the
    faster, the more precisely it shows), its uncertainty (infinite with fewer than two), and
    the bounces it is of; the default with none."""
    if not bounces:
        return BALL_DEFAULTS["ball_restitution"], math.inf, []
    e = np.array([b.restitution for b in bounces], dtype=float)
    # A bounce far from the others is one the replay got wrong (the ball's spin into the wall
    # misjudged, a rod's reach grazed): left out.
    middle = float(np.median(e))
    spread = 1.4826 * float(np.median(np.abs(e - middle)))
    near = np.abs(e - middle) <= max(_BOUNCE_OUTLIER * spread, _BOUNCE_TOLERANCE)
    used = [b for b, keep in zip(bounces, near) if keep]
    e = e[near]
    w = np.array([b.into**2 for b in used])
    mean = float(np.sum(w * e) / np.sum(w))
    n = len(e)
    if n < 2:
        return mean, math.inf, used
    std = np.sqrt(np.sum(w**2 * (e - mean) ** 2) * n / (n - 1)) / np.sum(w)
    return mean, float(std), used


def _gap_rms(bounces: list[Bounce], restitution: float) -> float:
    """The RMS difference (m/s) between the replays' speeds off the walls and the camera's."""
    if not bounces:
        return math.nan
    return float(np.sqrt(np.mean([b.gap(restitution) ** 2 for b in bounces])))
