"""What a fit of a table's physics found, and the forms it is written in: a table for people,
JSON under the physical quantities' names, and a training settings file whose ``env_kwargs``
make the environments play on the fitted table. Nothing here needs the simulator."""

from __future__ import annotations

import math
import shlex
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from foosball_gym import table
from foosball_gym.camera import CameraNoise
from foosball_gym.real_table.sysid.latency import CameraLatency
from foosball_gym.real_table.sysid.logs import PHYSICS_OPTIONS, PlayLog

if TYPE_CHECKING:
    from foosball_gym.real_table.sysid.ball_fit import BallFit
    from foosball_gym.real_table.sysid.drive_fit import DriveFit

#: The physical quantities fitted, in the order they are shown, each with the simulator's
#: default and its unit.
QUANTITIES = {
    "rolling_resistance": (table.ROLLING_RESISTANCE, "g"),
    "ball_restitution": (table.BALL_TABLE_RESTITUTION, ""),
    "ball_friction": (table.BALL_MATERIAL.dynamic_friction, ""),
    "drive_gain": (1.0, "x"),
    "drive_latency_s": (0.0, "s"),
    "camera_latency_s": (CameraNoise().latency_s, "s"),
}
#: A value whose uncertainty is more than this share of the value is not shown by the logs:
#: it is reported, but not written into the environments' options.
UNDETERMINED_SHARE = 0.5
#: Each residual's name, what it measures and its unit.
RESIDUALS = {
    "ball_track_mm": ("ball on the cloth, replay vs camera (RMS)", "mm"),
    "wall_bounce_speed_mm_s": ("speed off the walls, replay vs camera (RMS)", "mm/s"),
    "drive_position_mm": ("drives a step on, law vs drive (RMS)", "mm"),
}


@dataclass
class SysidResult:
    """A fit of a table's physics.

    Attributes:
        values: each quantity of :data:`QUANTITIES` the logs showed, fitted.
        std: their standard uncertainties.
        not_determined: the quantities the logs did not show, each with why.
        residuals: each residual of :data:`RESIDUALS` the fit has, as (before, after): under
            the simulator's defaults and under the fitted values.
        data: how much of the logs the fit used.
        logs: the logs' paths.
        env_id: the environment the logs were played in (None where they do not say).
        task_options: the logs' environment options other than physics.
        ball: the ball's fit, for plotting its replays.
    """

    values: dict[str, float]
    std: dict[str, float]
    not_determined: dict[str, str]
    residuals: dict[str, tuple[float, float]]
    data: dict[str, float]
    logs: list[str]
    env_id: str | None
    task_options: dict[str, Any]
    ball: BallFit | None = field(default=None, repr=False)

    @classmethod
    def from_fits(
        cls,
        logs: list[PlayLog],
        ball: BallFit,
        drives: DriveFit | None,
        camera: CameraLatency | None,
        stretches: int,
    ) -> SysidResult:
        """Gather what the parts of a fit found."""
        fitted = dict(ball.values)
        std = dict(ball.std)
        not_determined: dict[str, str] = {}
        residuals = {"ball_track_mm": (ball.rms_before_mm, ball.rms_after_mm)}
        if ball.bounces:
            residuals["wall_bounce_speed_mm_s"] = (
                ball.bounce_rms_before_mm_s,
                ball.bounce_rms_after_mm_s,
            )
        if len(ball.bounces) < 2:
            not_determined["ball_restitution"] = (
                f"{len(ball.bounces)} wall bounce(s) seen whole, and 2 are needed; serve balls "
                "that run into the side walls clear of the rods"
            )
        if drives is None:
            why = "the drives hardly moved: play a policy that moves them"
            not_determined["drive_gain"] = not_determined["drive_latency_s"] = why
        else:
            fitted.update(drive_gain=drives.gain, drive_latency_s=drives.latency_s)
            std.update(drive_gain=drives.gain_std, drive_latency_s=drives.latency_std)
            residuals["drive_position_mm"] = (drives.rms_before_mm, drives.rms_after_mm)
        if camera is None:
            not_determined["camera_latency_s"] = "no loop used a new camera frame"
        elif not camera.from_exposure:
            not_determined["camera_latency_s"] = (
                "the camera stamped its frames on arrival, so its latency before that is not in "
                f"the logs (the loop used them {1e3 * camera.mean_s:.1f} ms after arrival)"
            )
        else:
            fitted["camera_latency_s"], std["camera_latency_s"] = camera.mean_s, camera.std_s
        for name in list(fitted):
            if name in not_determined:
                del fitted[name], std[name]
            elif name != "drive_latency_s" and not std[name] <= UNDETERMINED_SHARE * abs(
                fitted[name]
            ):
                not_determined[name] = (
                    f"fitted {fitted[name]:.4g} +- {std[name]:.2g}: the logs hardly show it"
                )
                del fitted[name], std[name]
        data = {
            "logs": len(logs),
            "loops": sum(log.loops for log in logs),
            "ball_stretches": stretches,
            "ball_stretches_fitted": len(ball.kept),
            "ball_seconds_fitted": round(ball.seconds, 2),
            "wall_bounces": len(ball.bounces),
            "drive_steps": drives.steps if drives is not None else 0,
            "camera_frames": camera.frames if camera is not None else 0,
        }
        physics = set(PHYSICS_OPTIONS)
        return cls(
            values={k: fitted[k] for k in QUANTITIES if k in fitted},
            std={k: std[k] for k in QUANTITIES if k in std},
            not_determined={k: not_determined[k] for k in QUANTITIES if k in not_determined},
            residuals=residuals,
            data=data,
            logs=[log.path for log in logs],
            env_id=logs[0].env_id,
            task_options={k: v for k, v in logs[0].env_kwargs.items() if k not in physics},
            ball=ball,
        )

    # ------------------------------------------------------------------ for people

    def summary(self) -> str:
        """One line: how much of the logs the fit used."""
        d = self.data
        return (
            f"{d['logs']} log(s), {d['loops']} loops: the ball on {d['ball_stretches_fitted']} "
            f"stretches clear of the rods ({d['ball_seconds_fitted']:.1f} s) and "
            f"{d['wall_bounces']} wall bounces, {d['drive_steps']} drive steps, "
            f"{d['camera_frames']} camera frames"
        )

    def table(self) -> str:
        """Each quantity fitted with its uncertainty and the simulator's default."""
        rows = [f"{'quantity':20s} {'fitted':>10s} {'+-':>9s} {'default':>9s}"]
        for name, (default, _) in QUANTITIES.items():
            if name in self.values:
                rows.append(
                    f"{name:20s} {self.values[name]:10.4g} {self.std[name]:9.2g} {default:9.4g}"
                )
            elif name in self.not_determined:
                rows.append(f"{name:20s} {'not fitted':>10s}: {self.not_determined[name]}")
        return "\n".join(rows)

    def residual_table(self) -> str:
        """Each residual before (the simulator's defaults) and after the fit."""
        rows = [f"{'residual':46s} {'before':>9s} {'after':>9s}"]
        for name, (before, after) in self.residuals.items():
            text, unit = RESIDUALS[name]
            rows.append(f"{text:46s} {before:9.3g} {after:9.3g} {unit}")
        return "\n".join(rows)

    def env_kwarg_flags(self) -> str:
        """The fitted options as ``foosball play``'s and ``foosball eval``'s ``--env-kwarg``."""
        return " ".join(
            f"--env-kwarg {shlex.quote(f'{key}={_spelled(value)}')}"
            for key, value in self.env_kwargs().items()
        )

    # ------------------------------------------------------------------ for programs

    def to_json(self) -> dict[str, Any]:
        """Each fitted value under its quantity's name, as a number, and the rest beside."""

        def number(value: float) -> float | None:
            return value if math.isfinite(value) else None

        return {
            **self.values,
            "uncertainty": {k: number(v) for k, v in self.std.items()},
            "default": {k: default for k, (default, _) in QUANTITIES.items()},
            "not_determined": self.not_determined,
            "residual": {
                k: {"before": number(b), "after": number(a), "unit": RESIDUALS[k][1]}
                for k, (b, a) in self.residuals.items()
            },
            "env_kwargs": self.env_kwargs(),
            "data": self.data,
            "logs": self.logs,
            "env_id": self.env_id,
        }

    def env_kwargs(self) -> dict[str, Any]:
        """The fitted values as the environments take them: a range of one value where an
        environment takes a range. The drives' latency has no option, and the camera's only
        goes in with ``estimated_state``."""
        out: dict[str, Any] = {}
        values = {k: _rounded(v) for k, v in self.values.items()}
        if "rolling_resistance" in values:
            out["rolling_resistance"] = values["rolling_resistance"]
        for name in ("ball_friction", "ball_restitution", "drive_gain"):
            if name in values:
                out[f"{name}_range"] = [values[name], values[name]]
        if "camera_latency_s" in values and self.task_options.get("estimated_state"):
            noise = dict(self.task_options.get("camera_noise") or {})
            out["camera_noise"] = {**noise, "latency_s": values["camera_latency_s"]}
        return out

    def config(self, env_id: str | None = None) -> dict[str, Any]:
        """A training settings file (``foosball train --config``) for ``env_id`` (the logs'
        environment by default) on the fitted table: the shipped settings of the environment
        where there are some, its ``env_kwargs`` the logs' task options and the fitted
        physics.

        Raises:
            ValueError: no environment is named, here or in the logs; or it is not registered.
        """
        from foosball_gym.registration import check_env_id

        env_id = env_id or self.env_id
        if env_id is None:
            raise ValueError("the logs do not name their environment: give one (--env ENV_ID)")
        check_env_id(env_id)
        settings = _shipped(env_id)
        task = self.task_options if env_id == self.env_id else {}
        base = {
            k: v for k, v in (settings.get("env_kwargs") or {}).items() if k not in PHYSICS_OPTIONS
        }
        return {
            "env_id": env_id,
            "env_kwargs": {**base, **task, **self.env_kwargs()},
            **{k: v for k, v in settings.items() if k not in ("env_id", "env_kwargs")},
        }

    def config_text(self, env_id: str | None = None) -> str:
        """:meth:`config` as a YAML file, with what was fitted in its comments."""
        import yaml

        settings = self.config(env_id)
        lines = [
            "# Training settings for a table fitted by foosball sysid from:",
            *(f"#   {path}" for path in self.logs),
            "#",
        ]
        for name, value in self.values.items():
            lines.append(f"#   {name} = {value:.4g} +- {self.std[name]:.2g}")
        for name, why in self.not_determined.items():
            lines.append(f"#   {name}: not fitted ({why})")
        if "drive_latency_s" in self.values:
            lines.append("#   (the drives' latency is no environment option)")
        lines += [
            "#",
            f"#   foosball train --config FILE --out runs/NAME   (a {settings['env_id']} run on "
            "the fitted table)",
        ]
        return "\n".join(lines) + "\n" + yaml.safe_dump(settings, sort_keys=False)


def _rounded(value: float) -> float:
    return float(f"{value:.4g}")


def _spelled(value: Any) -> str:
    if isinstance(value, list):
        return "(" + ",".join(_spelled(v) for v in value) + ")"
    if isinstance(value, dict):
        return "{" + ",".join(f"'{k}':{_spelled(v)}" for k, v in value.items()) + "}"
    return repr(value)


def _shipped(env_id: str) -> dict[str, Any]:
    """The shipped training settings of ``env_id`` (empty where none ship)."""
    from foosball_gym.training.config_file import ConfigFileError, config_path

    try:
        path = config_path(f"builtin:{env_id}")
    except ConfigFileError:
        return {}
    import yaml

    data = yaml.safe_load(Path(path).read_text())
    return data if isinstance(data, dict) else {}
