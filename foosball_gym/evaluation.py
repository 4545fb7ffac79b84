"""Seeded evaluation of a policy: success rate with a confidence interval, goals, rewards.

Needs neither PyTorch nor Stable-Baselines3: a policy is any callable from an observation to
an action, so the scripted baselines are evaluated on the base install. Recording an .mp4
video needs OpenCV, from the ``train`` or the ``hardware`` extra; a .gif needs Pillow, which
the ``train`` extra brings with matplotlib.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

import gymnasium as gym
import numpy as np

from foosball_gym.progress import Progress
from foosball_gym.registration import check_env_id

if TYPE_CHECKING:
    from foosball_gym.envs.base import FoosballEnv
    from foosball_gym.replay import EnvRecorder

Policy = Callable[[np.ndarray], Any]

# Where an option played came from, as the summary says it.
FROM_MODEL = "the model's training config"
FROM_COMMAND_LINE = "the command line"
GIVEN = "given"
RESIDUAL = "the model's training config: it corrects the scripted baseline's actions"

VIDEO_SUFFIXES = (".mp4", ".gif")
# GIF delays are whole hundredths of a second and browsers play a delay under 2 of them as
# 10, so a GIF faster than 50 frames a second would play slower, not faster.
GIF_MAX_FPS = 50
# About 20 frames a second keeps a GIF small enough for a README and the ball's path smooth.
GIF_FPS = 20
# 64 colours hold the table's few flat colours and their shading; more only add size.
GIF_COLOURS = 64
# How long a video holds each recorded episode's last frame, so that its end can be seen
# before the next one starts (or a GIF starts over).
EPISODE_PAUSE_S = 0.5


def wilson_interval(successes: int, n: int, z: float = 1.96) -> tuple[float, float]:
    """95 % Wilson score interval of a success rate (sensible at 0 % and 100 % too)."""
    if n == 0:
        return 0.0, 1.0
    p = successes / n
    denom = 1 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    return max(0.0, centre - half), min(1.0, centre + half)


@dataclass
class EvalResult:
    env_id: str
    env_kwargs: dict[str, Any]
    policy: str
    opponent: str | None
    episodes: int
    seed: int
    successes: int
    success_rate: float
    ci_low: float
    ci_high: float
    goals_for: int
    goals_against: int
    mean_reward: float
    std_reward: float
    mean_length: float
    # Balls put in play (a match serves again after each goal and dead ball) and how many of
    # them left the table.
    serves: int = 0
    off_table: int = 0
    # Where each of env_kwargs came from (see evaluate's option_sources), and the scale of a
    # residual policy's correction to the scripted baseline (None: it plays whole actions).
    option_sources: dict[str, str] = field(default_factory=dict)
    residual: Any = None

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    def option_lines(self) -> list[str]:
        """The options played, one a line, each with where it came from; the options left out
        are the environment's defaults, which the last line says."""
        played = [
            (f"{name}={self.env_kwargs[name]!r}", self.option_sources.get(name, GIVEN))
            for name in sorted(self.env_kwargs)
        ]
        if self.residual is not None:
            played.append((f"residual={self.residual!r}", RESIDUAL))
        width = max((len(text) for text, _ in played), default=0)
        lines = [f"{text:<{width}}  ({source})" for text, source in played]
        others = "every other option" if played else "every option"
        return [*lines, f"{others}: {self.env_id}'s default"]

    def table(self) -> str:
        """The result as a small text table."""
        options = self.option_lines()
        rows = [
            ("environment", self.env_id),
            ("options", options[0]),
            *(("", line) for line in options[1:]),
            ("policy", self.policy),
            *([("opponent", self.opponent)] if self.opponent else []),
            ("episodes", f"{self.episodes} (seeds {self.seed}..{self.seed + self.episodes - 1})"),
            (
                "success rate",
                f"{100 * self.success_rate:.1f} % "
                f"(95 % CI {100 * self.ci_low:.1f} - {100 * self.ci_high:.1f} %)",
            ),
            ("goals for / against", f"{self.goals_for} / {self.goals_against}"),
            ("mean reward", f"{self.mean_reward:.1f} ± {self.std_reward:.1f}"),
            ("mean episode length", f"{self.mean_length:.1f} steps"),
        ]
        if self.serves > self.episodes or self.off_table:
            share = 100 * self.off_table / max(self.serves, 1)
            rows.append(("serves", str(self.serves)))
            rows.append(("off the table", f"{self.off_table} ({share:.1f} % of serves)"))
        width = max(len(k) for k, _ in rows)
        return "\n".join(f"{k:<{width}}  {v}" for k, v in rows)


def evaluate(
    policy: Policy,
    env_id: str,
    env_kwargs: dict[str, Any] | None = None,
    episodes: int = 100,
    seed: int = 0,
    opponent: Policy | str | None = None,
    policy_name: str = "policy",
    opponent_name: str | None = None,
    video: str | Path | None = None,
    video_episodes: int = 1,
    video_stride: int | None = None,
    replay: str | Path | None = None,
    option_sources: Mapping[str, str] | None = None,
    progress: bool = False,
) -> EvalResult:
    """Run ``episodes`` episodes seeded ``seed, seed + 1, ...`` and summarise them.

    Args:
        policy: a callable from one observation to one action; one with a ``reset()`` method
            (a recurrent policy) has it called before each episode, as has ``opponent``. A
            residual (:class:`~foosball_gym.training.loading.LoadedPolicy`) plays over the
            scripted baseline of this environment's state, which on estimated state may not
            be the one it was trained over.
        env_id: the environment.
        env_kwargs: its options, as keyword arguments of ``gymnasium.make``.
        opponent: for two-player envs, the away side's policy (None: the env's default;
            ``"scripted:N"``: rung N of the game's scripted ladder).
        video: write the first ``video_episodes`` episodes, rendered, one after the other
            into this file: .mp4 or .gif, by its suffix. Frames are 640 x 360 unless
            ``env_kwargs`` give ``render_width`` and ``render_height``.
        video_episodes: how many episodes ``video`` holds, 1 to ``episodes``.
        video_stride: keep every this many frames (None: all of them for .mp4, about
            20 a second for .gif, every 3rd at 60 Hz); the video still plays in real time.
        replay: write every episode, frame by frame, into this self-contained HTML page
            (see :mod:`foosball_gym.replay`): the table from above with a time slider, and
            the estimate the policy saw beside the true ball where it observes through the
            simulated camera (``estimated_state``).
        option_sources: where each of ``env_kwargs`` came from (:func:`option_sources`), for
            the summary (:meth:`EvalResult.table`) to say; an option it leaves out is
            ``"given"``.
        progress: show the episodes played on standard error, a bar on a terminal and a
            line now and then elsewhere (:class:`~foosball_gym.progress.Progress`).

    Raises:
        ValueError: ``episodes`` is below 1, ``env_id`` is not registered, an option has a
            bad value (TypeError where the environment has no such option), a policy that
            says the size of the observations it takes (``observation_size``) takes others,
            or a video option is out of range (see :func:`video_format`). All of these are
            raised before the first episode runs.
        ImportError: the video needs OpenCV or Pillow, and it is not installed.
    """
    if episodes < 1:
        raise ValueError(f"episodes must be at least 1, got {episodes}")
    if video is not None:
        video_format(video)
        if not 1 <= video_episodes <= episodes:
            raise ValueError(
                f"video_episodes must lie between 1 and episodes ({episodes}), got {video_episodes}"
            )
        if video_stride is not None and video_stride < 1:
            raise ValueError(f"video_stride must be at least 1, got {video_stride}")
    if replay is not None:
        from foosball_gym.replay.page import check_page_path

        check_page_path(replay)
    check_env_id(env_id)
    kwargs = dict(env_kwargs or {})
    # A residual policy plays over the scripted baseline of this environment's state.
    with_baseline_for = getattr(policy, "with_baseline_for", None)
    if callable(with_baseline_for):
        policy = with_baseline_for(env_id, kwargs)
    # A loaded opponent trained with slide_around_ball slides over the rods' travel here.
    whole_action = getattr(opponent, "whole_action", None)
    if callable(whole_action):
        opponent = whole_action()
    if video is not None:
        kwargs["render_mode"] = "rgb_array"
        kwargs.setdefault("render_width", 640)
        kwargs.setdefault("render_height", 360)
    env = gym.make(env_id, **kwargs)
    # In render_mode="rgb_array", render() gives an (H, W, 3) array.
    render = cast("Callable[[], np.ndarray]", env.render)
    writer: _VideoWriter | None = None
    try:
        _check_fits(policy, policy_name, env_id, env)
        if opponent is not None and not isinstance(opponent, str):
            _check_fits(opponent, opponent_name or "opponent", env_id, env)
        if video is not None:
            writer = open_video(video, env.metadata["render_fps"], video_stride)
    except Exception:
        env.close()
        raise
    if opponent is not None:
        try:
            cast("FoosballEnv", env.unwrapped).set_opponent(opponent)
        except Exception:
            env.close()
            raise
    frames = None if replay is None else _replay_recorder(env, policy_name, opponent_name)
    rewards, lengths = [], []
    successes = goals_for = goals_against = serves = off_table = 0
    count = Progress(episodes, "eval", "episodes", enabled=progress)
    try:
        for i in range(episodes):
            start_episode(policy, None if isinstance(opponent, str) else opponent)
            obs, info = env.reset(seed=seed + i)
            if frames is not None:
                frames.start(f"episode {i + 1}, seed {seed + i}", obs)
            recorder = writer if i < video_episodes else None
            if recorder is not None:
                recorder.add(render)
            total, steps, done = 0.0, 0, False
            serves += 1
            while not done:
                obs, reward, terminated, truncated, info = env.step(policy(obs))
                total += float(reward)
                steps += 1
                done = terminated or truncated
                off_table += bool(info.get("out_of_table"))
                ended = info["goal"] or info.get("out_of_table") or info.get("stagnated")
                serves += bool(ended) and not done
                if frames is not None:
                    frames.step(obs, info)
                if recorder is not None:
                    recorder.add(render)
            if recorder is not None:
                recorder.end_episode(render)
                if i + 1 == video_episodes:
                    recorder.close()
                    writer = None
            if frames is not None:
                frames.end(info)
            rewards.append(total)
            lengths.append(steps)
            successes += bool(info["is_success"])
            if "goals_for" in info:
                goals_for += info["goals_for"]
                goals_against += info["goals_against"]
            else:
                goals_for += info["goal"] == 1
                goals_against += info["goal"] == -1
            count.set_note(f"success {100 * successes / (i + 1):.1f} %")
            count.update()
    finally:
        count.close()
        if writer is not None:
            writer.close()
        env.close()
    if frames is not None:
        from foosball_gym.replay import write_html

        frames.recording.notes.append(f"seeds {seed}..{seed + episodes - 1}")
        write_html(frames.recording, cast("str | Path", replay))
    low, high = wilson_interval(successes, episodes)
    given = dict(env_kwargs or {})
    return EvalResult(
        env_id=env_id,
        env_kwargs=given,
        policy=policy_name,
        opponent=opponent_name,
        episodes=episodes,
        seed=seed,
        successes=successes,
        success_rate=successes / episodes,
        ci_low=low,
        ci_high=high,
        goals_for=int(goals_for),
        goals_against=int(goals_against),
        mean_reward=float(np.mean(rewards)),
        std_reward=float(np.std(rewards)),
        mean_length=float(np.mean(lengths)),
        serves=serves,
        off_table=off_table,
        option_sources={k: (option_sources or {}).get(k, GIVEN) for k in given},
        residual=_residual(policy),
    )


def option_sources(trained: Mapping[str, Any], given: Mapping[str, Any]) -> dict[str, str]:
    """Where each option of ``{**trained, **given}`` comes from: the model's training
    configuration (``trained``, the options a loaded model keeps) or the command line
    (``given``, which wins where both set one)."""
    sources = dict.fromkeys(trained, FROM_MODEL)
    for name in given:
        over = f", over the model's {trained[name]!r}" if name in trained else ""
        sources[name] = FROM_COMMAND_LINE + over
    return sources


def _residual(policy: Any) -> Any:
    """The scale of a residual policy's correction (a loaded one playing over its baseline),
    as a list where it is one a rod; None for any other policy."""
    if getattr(policy, "baseline", None) is None:
        return None
    scale = getattr(policy, "trained_residual", None)
    return list(scale) if isinstance(scale, tuple) else scale


def _replay_recorder(env: gym.Env, policy_name: str, opponent_name: str | None) -> EnvRecorder:
    from foosball_gym.replay import EnvRecorder

    title = f"{policy_name} on {env.unwrapped.spec.id if env.unwrapped.spec else 'the table'}"
    return EnvRecorder(env, title=title + (f" against {opponent_name}" if opponent_name else ""))


def start_episode(*policies: Policy | None) -> None:
    """Tell the policies an episode starts: those that carry a state from step to step
    (a recurrent one) have a ``reset()`` that forgets it."""
    for policy in policies:
        reset = getattr(policy, "reset", None)
        if callable(reset):
            reset()


def _check_fits(policy: Policy, name: str, env_id: str, env: gym.Env) -> None:
    expected = getattr(policy, "observation_size", None)
    shape = env.observation_space.shape
    assert shape is not None  # the environments observe a Box
    size = int(np.prod(shape))
    if expected is not None and expected != size:
        trained = getattr(policy, "env_id", None)
        of = f" of {trained}" if trained else ""
        raise ValueError(
            f"{name} expects observations of size {expected}{of}, but {env_id} gives {size}: "
            f"give a model trained on {env_id}"
        )


def video_format(path: str | Path) -> str:
    """The kind of video ``path`` names by its suffix: ``".mp4"`` or ``".gif"``.

    Raises:
        ValueError: any other suffix, or none.
    """
    suffix = Path(path).suffix.lower()
    if suffix not in VIDEO_SUFFIXES:
        has = f"not {suffix}" if suffix else "and it has none"
        raise ValueError(
            f"{path}: a video's suffix must be one of {', '.join(VIDEO_SUFFIXES)}, {has}"
        )
    return suffix


def open_video(path: str | Path, fps: float, stride: int | None = None) -> _VideoWriter:
    """A writer of episodes rendered at ``fps`` frames a second to ``path`` (.mp4 or .gif).

    Args:
        stride: keep every this many frames (None: every frame for .mp4, about
            :data:`GIF_FPS` a second for .gif); the video still plays in real time.

    Raises:
        ValueError: an unsupported suffix, or a .gif whose stride leaves more than
            :data:`GIF_MAX_FPS` frames a second.
        ImportError: OpenCV (.mp4) or Pillow (.gif) is not installed.
    """
    if video_format(path) == ".gif":
        if stride is None:
            stride = max(1, round(fps / GIF_FPS), math.ceil(fps / GIF_MAX_FPS))
        if fps / stride > GIF_MAX_FPS:
            raise ValueError(
                f"a GIF plays at most {GIF_MAX_FPS} frames a second and the environment renders "
                f"{fps:g}: give a frame stride of {math.ceil(fps / GIF_MAX_FPS)} or more, "
                f"not {stride}"
            )
        return _GifWriter(path, fps, stride)
    return _Mp4Writer(path, fps, stride or 1)


class _VideoWriter:
    """Episodes' frames, every ``stride``-th kept, to a video that plays in real time.

    Frames come as the env's ``render``, called only for the frames kept: rendering is most
    of a video's cost. Each episode starts with its first frame and ends with its last one,
    whatever the stride, so that the video shows how every episode ended.
    """

    def __init__(self, path: str | Path, fps: float, stride: int) -> None:
        self.path = str(path)
        self.stride = stride
        self.fps = fps / stride
        self._count = 0
        self._skipped = False

    def add(self, render: Callable[[], np.ndarray]) -> None:
        """The env's next frame, ``render()``, called where the stride keeps it."""
        self._skipped = self._count % self.stride != 0
        if not self._skipped:
            self._write(render())
        self._count += 1

    def end_episode(self, render: Callable[[], np.ndarray]) -> None:
        """Show the episode's last frame, ``render()``, held for :data:`EPISODE_PAUSE_S`."""
        if self._skipped:
            self._write(render())
            self._skipped = False
        self._hold(EPISODE_PAUSE_S)
        self._count = 0

    def _write(self, frame: np.ndarray) -> None:
        raise NotImplementedError

    def _hold(self, seconds: float) -> None:
        raise NotImplementedError

    def close(self) -> None:
        raise NotImplementedError


class _Mp4Writer(_VideoWriter):
    """Frames to an .mp4 file with OpenCV."""

    def __init__(self, path: str | Path, fps: float, stride: int) -> None:
        try:
            import cv2
        except ImportError as err:
            raise ImportError(
                "recording an .mp4 video needs OpenCV, which the train and hardware extras "
                'install: pip install -e ".[train]"'
            ) from err
        super().__init__(path, fps, stride)
        self._cv2 = cv2
        self._writer: cv2.VideoWriter | None = None
        self._last: np.ndarray | None = None

    def _write(self, frame: np.ndarray) -> None:
        if self._writer is None:
            h, w = frame.shape[:2]
            fourcc = self._cv2.VideoWriter.fourcc(*"mp4v")
            self._writer = self._cv2.VideoWriter(self.path, fourcc, self.fps, (w, h))
            if not self._writer.isOpened():
                raise OSError(f"cannot write a video to {self.path}")
        self._last = self._cv2.cvtColor(frame, self._cv2.COLOR_RGB2BGR)
        self._writer.write(self._last)

    def _hold(self, seconds: float) -> None:
        if self._writer is None or self._last is None:
            return
        for _ in range(round(seconds * self.fps)):
            self._writer.write(self._last)

    def close(self) -> None:
        if self._writer is not None:
            self._writer.release()
            self._writer = None


class _GifWriter(_VideoWriter):
    """Frames to a looping .gif file with Pillow, kept in memory until :meth:`close`.

    Every frame takes the first frame's palette, without dithering: the camera stands still,
    so a frame differs from the one before only where something moved, and Pillow stores
    only that rectangle. Frames are one byte a pixel while they wait (230 kB at 640 x 360).
    """

    def __init__(self, path: str | Path, fps: float, stride: int) -> None:
        try:
            from PIL import Image
        except ImportError as err:
            raise ImportError(
                "recording a .gif needs Pillow, which the train extra installs with "
                'matplotlib: pip install -e ".[train]"'
            ) from err
        super().__init__(path, fps, stride)
        self._image = Image
        self._frames: list[Any] = []
        self._seconds: list[float] = []

    def _write(self, frame: np.ndarray) -> None:
        Image = self._image
        image = Image.fromarray(np.ascontiguousarray(frame[..., :3]))
        if self._frames:
            image = image.quantize(palette=self._frames[0], dither=Image.Dither.NONE)
        else:
            image = image.quantize(GIF_COLOURS, dither=Image.Dither.NONE)
        self._frames.append(image)
        self._seconds.append(1 / self.fps)

    def _hold(self, seconds: float) -> None:
        if self._seconds:
            self._seconds[-1] += seconds

    def _durations_ms(self) -> list[int]:
        # GIF delays are whole hundredths: each frame ends at its time rounded to one, so
        # that rounding errors do not add up and the GIF plays in real time.
        ends = np.round(np.cumsum(self._seconds) * 100).astype(int)
        return [10 * int(d) for d in np.diff(ends, prepend=0)]

    def close(self) -> None:
        if not self._frames:
            return
        frames, self._frames = self._frames, []
        frames[0].save(
            self.path,
            format="GIF",
            save_all=True,
            append_images=frames[1:],
            duration=self._durations_ms(),
            loop=0,
        )
