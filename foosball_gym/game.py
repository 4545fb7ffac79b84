"""A match on the simulated table: serves, goals, the opponent and the state of play.

Both faces of the simulation use it: the Gymnasium environment (:mod:`foosball_gym.envs`),
which adds actions, observations and rewards, and the simulated real table
(:mod:`foosball_gym.real_table.virtual`), whose learner's rods are moved by simulated CAN drives
instead. The game only calls the :class:`~foosball_gym.sim.TableSim` it is given.
"""

from __future__ import annotations

import copy
import pickle
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from foosball_gym import table
from foosball_gym.policies.ladder import is_scripted, parse_scripted
from foosball_gym.policy_io.observations import mirrored_builder
from foosball_gym.policy_io.task import Joint, TaskInterface, action_joints, check_action
from foosball_gym.tasks.base import Start, Task, clear_of_ball

if TYPE_CHECKING:
    from foosball_gym.sim import TableSim

Policy = Callable[[np.ndarray], Any]

# A ball slower than this (m/s) counts as lying still for the stagnation and dead-ball rules.
STILL_SPEED = 0.05
# Serves drawn in a running game until one leaves every figurine clear of the ball.
SERVE_TRIES = 20


@dataclass(frozen=True)
class Outcome:
    """What one control step brought: ``goal`` is +1 (home scored), -1 (away scored) or 0."""

    goal: int
    out_of_table: bool
    stagnated: bool

    @property
    def ended(self) -> bool:
        """Whether the ball is dead: a goal, off the table, or lying still too long (or out of
        every figurine's reach)."""
        return self.goal != 0 or self.out_of_table or self.stagnated


class Game:
    """A task played on a simulated table.

    Args:
        task: what is played.
        interface: the learner's observation builder and action mapping for the task.
        sim: the simulated table, holding exactly ``task.layout.rods``.
        opponent: the away side's policy, a callable from the mirrored observation to an
            action (tasks with an opponent only; ``None``: the scripted team; ``"scripted:N"``:
            rung N of the task's scripted ladder).
        stagnation_steps: a ball still for this many steps is dead (0: never). So is one still
            out of every figurine's reach for the task's ``dead_ball_steps``.

    Attributes:
        positions, velocities: joint values of the rods in play, all slides then all spins,
            in ``task.layout.rods`` order, as of the last serve or step.
        ball: the ball's x, y, vx, vy then.
        goals_for, goals_against: goals since the last serve.
        own_offsets: None, or per entry of the learner's action, how far its reading of that
            joint is off (a miscalibrated table): the joint is driven that much short of the
            target the action asks for.
    """

    def __init__(
        self,
        task: Task,
        interface: TaskInterface,
        sim: TableSim,
        *,
        opponent: Policy | str | None = None,
        stagnation_steps: int = 0,
    ) -> None:
        layout = task.layout
        if tuple(r.name for r in sim.rods) != layout.rods:
            raise ValueError(f"the simulator holds {sim.rods}, the task plays {layout.rods}")
        if opponent is not None and not layout.opponent:
            raise ValueError(f"{type(task).__name__} has no opponent to set")
        self.task, self.interface, self.sim = task, interface, sim
        self.stagnation_steps = int(stagnation_steps)
        self.dead_ball_steps = int(task.dead_ball_steps)
        self.rods = [table.rod(name) for name in layout.rods]
        n = len(self.rods)
        self._index = {
            (name, kind): i + (n if kind == "spin" else 0)
            for i, name in enumerate(layout.rods)
            for kind in ("slide", "spin")
        }
        self._own = [self._index[j] for j in interface.action_joints]
        self._own_scale = list(interface.action_scales)
        self._opp_builder = mirrored_builder(interface.builder) if layout.opponent else None
        opp_joints, opp_scales, _ = action_joints(layout.opponent, layout.joints)
        self._opp_joints = opp_joints
        self._opp = [self._index[j] for j in opp_joints]
        self._opp_scale = list(opp_scales)
        self._opponent: Policy | None = None
        if layout.opponent:
            self.set_opponent(opponent)
        self.targets = [0.0] * (2 * n)
        self.own_offsets: Sequence[float] | None = None
        self.positions: list[float] = [0.0] * (2 * n)
        self.velocities: list[float] = [0.0] * (2 * n)
        self.ball = (0.0, 0.0, 0.0, 0.0)
        self.goals_for = self.goals_against = 0
        self._still_steps = self._dead_steps = 0

    # ------------------------------------------------------------------ serving

    def start(self, start: Start) -> None:
        """Put the rods and the ball where ``start`` says (a figurine that would overlap the
        ball is slid beside it) and the score at 0-0."""
        pose = self.start_pose(start)
        self.sim.reset(pose[: len(self.rods)], start.spin, start.ball_position, start.ball_velocity)
        self.targets[:] = pose
        self._begin()

    def serve(self, rng: np.random.Generator) -> None:
        """A new ball, as the task starts its episodes, with the rods left where they are and
        the score at 0-0: a serve in a running game."""
        n = len(self.rods)
        for _ in range(SERVE_TRIES):
            start = self.task.sample_start(rng)
            if all(
                clear_of_ball(rod, s, start.ball_position) == s
                for rod, s in zip(self.rods, self.positions[:n])
            ):
                break
        self.sim.place_ball(start.ball_position, start.ball_velocity)
        self._begin()

    def start_pose(self, start: Start) -> list[float]:
        """The joint values (slides, then spins, in the layout's rod order) that ``start``
        puts the rods at, as :meth:`start` places them."""
        slide = [
            clear_of_ball(rod, s, start.ball_position) for rod, s in zip(self.rods, start.slide)
        ]
        return [float(v) for v in (*slide, *start.spin)]

    def start_targets(self, start: Start) -> dict[Joint, float]:
        """:meth:`start_pose` by joint."""
        pose = self.start_pose(start)
        return {joint: pose[i] for joint, i in self._index.items()}

    def serve_start(self, start: Start) -> None:
        """The ball of ``start``, wherever the rods are, and the score at 0-0: a serve
        after the rods were brought to ``start``'s places (see :meth:`start_pose`)."""
        self.sim.place_ball(start.ball_position, start.ball_velocity)
        self._begin()

    def put_ball(
        self, position: tuple[float, float], velocity: tuple[float, float], rolling: bool = False
    ) -> None:
        """A new ball where the caller says (a calibration serve: see
        :mod:`foosball_gym.real_table.sysid.excitation`), rolling without slipping or (``rolling``
        False) sliding without spin; the rods stay where they are and the score is 0-0."""
        self.sim.place_ball(position, velocity, rolling=rolling)
        self._begin()

    def _begin(self) -> None:
        self.goals_for = self.goals_against = 0
        self._still_steps = self._dead_steps = 0
        self.read_state()

    # ------------------------------------------------------------------ the opponent

    @property
    def opponent(self) -> Policy | None:
        return self._opponent

    def set_opponent(self, policy: Policy | str | None) -> None:
        """Set the away side's policy; ``None`` or ``"scripted"`` is the task's scripted team,
        ``"scripted:N"`` rung N of its scripted ladder."""
        if self._opp_builder is None:
            raise ValueError(f"{type(self.task).__name__} has no opponent to set")
        self._opponent = resolve_opponent(self.task, self.interface.builder.names, policy)

    def scripted_opponent(self, level: int | None = None) -> Policy:
        """A scripted team for the away side, acting on its mirrored observation: the task's
        scripted baseline, or rung ``level`` of its ladder."""
        if self._opp_builder is None:
            raise ValueError(f"{type(self.task).__name__} has no opponent")
        # The mirrored observation is laid out as the home side's, so a team built on the
        # home side's names plays the away rods of the same roles.
        return self.task.scripted_level(level, list(self.interface.builder.names))

    def opponent_observation(self) -> np.ndarray:
        """What the opponent sees now: the mirrored observation."""
        if self._opp_builder is None:
            raise ValueError(f"{type(self.task).__name__} has no opponent")
        return self._opp_builder.build(self.positions, self.velocities, self.ball)

    def _opponent_action(self) -> list[float]:
        assert self._opponent is not None
        action = self._opponent(self.opponent_observation())
        return check_action(action, len(self._opp), "opponent action")

    def opponent_targets(self) -> dict[Joint, float]:
        """The away rods' joint targets (m, rad) the opponent chooses in the current state."""
        if self._opponent is None:
            raise ValueError(f"{type(self.task).__name__} has no opponent")
        action = self._opponent_action()
        return {j: a * s for j, s, a in zip(self._opp_joints, self._opp_scale, action)}

    # ------------------------------------------------------------------ playing

    def command(
        self, action: Sequence[float], opponent_action: Sequence[float] | None = None
    ) -> None:
        """Drive the learner's joints with a checked action in [-1, 1] and the opponent's with
        its policy's choice.

        Args:
            action: the learner's action.
            opponent_action: a checked action for the away rods, in the away side's own frame,
                played instead of asking the opponent policy (where both sides learn).
        """
        targets = self.targets
        for i, s, a in zip(self._own, self._own_scale, action):
            targets[i] = a * s
        if self.own_offsets is not None:
            for i, offset in zip(self._own, self.own_offsets):
                targets[i] -= offset
        if opponent_action is not None and self._opponent is None:
            raise ValueError(f"{type(self.task).__name__} has no opponent to command")
        if self._opponent is not None:
            away = self._opponent_action() if opponent_action is None else opponent_action
            for i, s, a in zip(self._opp, self._opp_scale, away):
                targets[i] = a * s
        self.sim.command("position", targets)

    def advance(self) -> Outcome:
        """One control step of physics with the rods' targets as last commanded."""
        goal, out = self.sim.step()
        self.read_state()
        if goal == table.HOME_SCORED:
            self.goals_for += 1
        elif goal == table.AWAY_SCORED:
            self.goals_against += 1
        return Outcome(goal, out, self._stagnated())

    def _stagnated(self) -> bool:
        if not (self.stagnation_steps or self.dead_ball_steps):
            return False
        x, y, vx, vy = self.ball
        if vx * vx + vy * vy >= STILL_SPEED**2:
            self._still_steps = self._dead_steps = 0
            return False
        self._still_steps += 1
        if self.dead_ball_steps and not any(table.within_reach(r, x, y) for r in self.rods):
            self._dead_steps += 1
        else:
            self._dead_steps = 0
        return bool(
            (self.stagnation_steps and self._still_steps >= self.stagnation_steps)
            or (self.dead_ball_steps and self._dead_steps >= self.dead_ball_steps)
        )

    @property
    def success(self) -> bool:
        """Whether the task is met by the goals since the last serve."""
        return self.task.success(self.goals_for, self.goals_against)

    def own_readings(self) -> list[float]:
        """Where the joints the learner's action drives are, as the table reads them (each off
        by its calibration offset, if any), in action order."""
        offsets = self.own_offsets or [0.0] * len(self._own)
        return [self.positions[i] + o for i, o in zip(self._own, offsets)]

    def read_state(self) -> None:
        """Re-read the rods and the ball from the simulator."""
        self.positions, self.velocities = self.sim.joint_states()
        self.ball = self.sim.ball_xy()

    # ------------------------------------------------------------------ copies

    def __getstate__(self) -> dict[str, Any]:
        """A pickled game carries its opponent: as it is where pickle takes it, by value
        (cloudpickle) where pickle cannot (a lambda, a local function), else a TypeError
        names it. The simulator copies itself (see ``TableSim.__getstate__``)."""
        state = self.__dict__.copy()
        state["_opponent"] = portable(self._opponent)
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        state["_opponent"] = unpacked(state["_opponent"])
        self.__dict__.update(state)

    def __deepcopy__(self, memo: dict[int, Any]) -> Game:
        # As deepcopy would copy it without __getstate__: a function opponent stays itself.
        copied = Game.__new__(Game)
        memo[id(self)] = copied
        copied.__dict__.update(copy.deepcopy(self.__dict__, memo))
        return copied


def resolve_opponent(task: Task, names: Sequence[str], policy: Policy | str | None) -> Policy:
    """The away side's policy that ``policy`` names in ``task``, on the mirrored observation
    (laid out as the home side's, whose entries are ``names``): itself where it is a callable,
    the task's scripted team where it is None or ``"scripted"``, rung N of its ladder where it
    is ``"scripted:N"``.

    Raises:
        ValueError: the task has no opponent, no such rung, or ``policy`` is none of these.
    """
    if not task.layout.opponent:
        raise ValueError(f"{type(task).__name__} has no opponent to set")
    if isinstance(policy, str) and is_scripted(policy):
        # The mirrored observation is laid out as the home side's, so a team built on the
        # home side's names plays the away rods of the same roles.
        return task.scripted_level(parse_scripted(policy), list(names))
    if policy is not None and not callable(policy):
        raise ValueError(
            "an opponent must be a callable obs -> action, 'scripted' or 'scripted:N', "
            f"got {policy!r}"
        )
    return task.scripted_level(None, list(names)) if policy is None else policy


@dataclass(frozen=True)
class _ByValue:
    """An opponent pickled by cloudpickle (pickle reads it back, cloudpickle installed)."""

    data: bytes


# The opponents being pickled here: one that holds its own game meets itself again there, and
# is left to the pickler at work.
_TRYING: set[int] = set()


def portable(policy: Policy | None) -> Policy | _ByValue | None:
    """``policy`` as pickle can take it: itself, or its bytes from cloudpickle (which
    :func:`unpacked` reads back); a TypeError names one that neither can take."""
    if policy is None or id(policy) in _TRYING:
        return policy
    _TRYING.add(id(policy))
    try:
        return _pickled(policy)
    finally:
        _TRYING.discard(id(policy))


def unpacked(value: Any) -> Any:
    """What :func:`portable` was given."""
    return pickle.loads(value.data) if isinstance(value, _ByValue) else value


def _pickled(policy: Policy) -> Policy | _ByValue:
    try:
        pickle.dumps(policy)
        return policy
    except Exception:
        pass
    import cloudpickle  # only for what pickle cannot take

    try:
        return _ByValue(cloudpickle.dumps(policy))
    except Exception as err:
        raise TypeError(
            f"cannot copy the game: its opponent {policy!r} cannot be pickled ({err}); set an "
            "opponent that pickles (a module-level function or an instance of a module-level "
            "class), or set_opponent(None) for the scripted team, before copying"
        ) from err
