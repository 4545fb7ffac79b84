"""Videos: several episodes in one .mp4 or .gif from ``foosball eval``, and clips while training.

Frames are kept tiny (64 x 36) through the envs' ``render_width`` and ``render_height``:
rendering is most of a video's cost.
"""

from __future__ import annotations

import csv
import functools
import json
from importlib.util import find_spec
from pathlib import Path

import pytest

from foosball_gym.cli import main
from foosball_gym.evaluation import EPISODE_PAUSE_S, evaluate

needs_cv2 = pytest.mark.skipif(find_spec("cv2") is None, reason="writing .mp4 needs OpenCV")
needs_pillow = pytest.mark.skipif(find_spec("PIL") is None, reason="writing .gif needs Pillow")
needs_train = pytest.mark.skipif(
    any(find_spec(m) is None for m in ("stable_baselines3", "torch", "cv2")),
    reason='needs the train extra: pip install -e ".[train]"',
)

ENV_ID = "Foosball-Block-v0"
SMALL = ["--env-kwarg", "render_width=64", "--env-kwarg", "render_height=36"]
# Block renders at its control rate.
FPS = 60


def eval_video(tmp_path: Path, video: Path, episodes: int, *extra: str) -> dict:
    """Run ``foosball eval`` of the scripted keeper recording ``video``; its JSON result."""
    result = tmp_path / f"{video.stem}.json"
    argv = ["eval", "--policy", "scripted", ENV_ID, "--episodes", str(episodes), *SMALL]
    argv += ["--video", str(video), "--json", str(result), *extra]
    assert main(argv) == 0
    return json.loads(result.read_text())


def mp4_frames(path: Path) -> list:
    import cv2

    cap = cv2.VideoCapture(str(path))
    frames = []
    while True:
        ok, frame = cap.read()
        if not ok:
            break
        frames.append(frame)
    cap.release()
    return frames


def gif_frames(path: Path) -> tuple[int, float, tuple[int, int]]:
    """A GIF's frame count, the seconds it plays and its size."""
    from PIL import Image

    with Image.open(path) as gif:
        seconds = 0.0
        for i in range(gif.n_frames):
            gif.seek(i)
            seconds += gif.info["duration"] / 1000
            gif.convert("RGB")  # every frame decodes
        return gif.n_frames, seconds, gif.size


@needs_cv2
def test_an_mp4_holds_every_frame_of_each_recorded_episode_one_after_the_other(tmp_path, capsys):
    one, three = tmp_path / "one.mp4", tmp_path / "three.mp4"
    first = eval_video(tmp_path, one, 1)
    result = eval_video(tmp_path, three, 3, "--video-episodes", "3")
    frames = mp4_frames(three)
    assert frames[0].shape == (36, 64, 3)
    # Each episode: its first frame, one a step, then its last frame held for the pause.
    pause = round(EPISODE_PAUSE_S * FPS)
    steps = round(result["mean_length"] * result["episodes"])
    assert len(frames) == steps + 3 * (1 + pause)
    assert len(mp4_frames(one)) == round(first["mean_length"]) + 1 + pause < len(frames)


@needs_pillow
def test_a_gif_holds_the_recorded_episodes_and_plays_them_in_real_time(tmp_path, capsys):
    one, two = tmp_path / "one.gif", tmp_path / "two.gif"
    eval_video(tmp_path, one, 2)
    result = eval_video(tmp_path, two, 2, "--video-episodes", "2")
    frames, seconds, size = gif_frames(two)
    assert size == (64, 36)
    assert frames > gif_frames(one)[0]
    # A third of the frames are kept (every 3rd, and each episode's last), each shown for as
    # long as the three it stands for.
    steps = result["mean_length"] * result["episodes"]
    played = (steps + 2) / FPS + 2 * EPISODE_PAUSE_S
    assert seconds == pytest.approx(played, abs=2 * 2 / FPS)


@needs_pillow
def test_a_gif_takes_a_frame_stride_but_refuses_one_too_fast_for_a_gif(tmp_path, capsys):
    default, finer = tmp_path / "default.gif", tmp_path / "finer.gif"
    eval_video(tmp_path, default, 1)
    eval_video(tmp_path, finer, 1, "--video-stride", "2")
    (few, seconds, _), (more, finer_seconds, _) = gif_frames(default), gif_frames(finer)
    assert more > few and finer_seconds == pytest.approx(seconds, abs=2 / FPS)
    with pytest.raises(ValueError, match=r"at most 50 frames a second .* stride of 2 or more"):
        evaluate(lambda obs: [0.0], ENV_ID, episodes=1, video=tmp_path / "v.gif", video_stride=1)
    assert not (tmp_path / "v.gif").exists()


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--video", "{tmp}/clip.avi"], "clip.avi: a video's suffix must be one of .mp4, .gif"),
        (["--video", "{tmp}/clip"], "suffix must be one of .mp4, .gif, and it has none"),
        (
            ["--video", "{tmp}/clip.mp4", "--video-episodes", "4"],
            "--video-episodes 4 is more than --episodes 3",
        ),
        (["--video-episodes", "2"], "--video-episodes 2 needs --video FILE"),
    ],
)
def test_a_bad_video_request_exits_with_status_2_before_any_episode_runs(
    tmp_path, extra, message, monkeypatch, capsys
):
    import foosball_gym.cli.evaluate as command

    @functools.wraps(command.evaluate)  # the parser reads its defaults off the signature
    def refuse(*args, **kwargs):
        raise AssertionError("an episode ran although the video request was bad")

    monkeypatch.setattr(command, "evaluate", refuse)
    argv = ["eval", "--policy", "scripted", ENV_ID, "--episodes", "3"]
    with pytest.raises(SystemExit) as exit_info:
        main([*argv, *(e.format(tmp=tmp_path) for e in extra)])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err, err
    assert list(tmp_path.iterdir()) == []


def train_tiny(out: Path, *extra: str) -> Path:
    argv = ["train", ENV_ID, "--timesteps", "512", "--n-envs", "1", "--n-steps", "128"]
    argv += ["--batch-size", "64", "--eval-freq", "256", "--eval-episodes", "2"]
    argv += ["--checkpoint-freq", "512", "--no-progress", *SMALL, "--out", str(out), *extra]
    assert main(argv) == 0
    return out


@pytest.fixture(scope="module")
def runs(tmp_path_factory) -> tuple[Path, Path]:
    """The same tiny run trained without clips and with one every 256 steps."""
    root = tmp_path_factory.mktemp("runs")
    return train_tiny(root / "plain"), train_tiny(root / "filmed", "--video-every", "256")


@needs_train
def test_train_writes_a_clip_of_the_policy_every_video_every_steps(runs):
    filmed = runs[1]
    clips = sorted(p.name for p in (filmed / "videos").iterdir())
    assert clips == ["step_000000256.mp4", "step_000000512.mp4"]
    for clip in clips:
        frames = mp4_frames(filmed / "videos" / clip)
        # Three Block episodes at every 2nd frame: more than any one episode gives.
        assert frames[0].shape == (36, 64, 3) and len(frames) > 90 // 2 + 1
    assert json.loads((filmed / "config.json").read_text())["video_every"] == 256


@needs_train
def test_recording_clips_does_not_change_what_a_seeded_run_learns(runs):
    from foosball_gym.training.run_dir.storage import read_model_zip

    plain, filmed = (read_model_zip(run / "model.zip")[1]["policy"] for run in runs)
    assert plain.keys() == filmed.keys()
    assert all((plain[k] == filmed[k]).all() for k in plain)

    def curve(run: Path) -> list[dict[str, str]]:
        with (run / "eval.csv").open() as f:
            rows = list(csv.DictReader(f))
        return [{k: v for k, v in row.items() if k != "wall_seconds"} for row in rows]

    assert curve(runs[0]) == curve(runs[1])


@needs_train
def test_a_self_play_run_writes_clips_of_one_match(tmp_path, capsys):
    from foosball_gym.training.sb3.videos import clip_episodes

    env_id = "Foosball-KeeperVsKeeper-v0"
    argv = ["train", env_id, "--timesteps", "256", "--n-envs", "1", "--n-steps", "128"]
    argv += ["--batch-size", "64", "--eval-freq", "256", "--eval-episodes", "1"]
    argv += ["--checkpoint-freq", "256", "--video-every", "256", "--no-progress", *SMALL]
    assert main([*argv, "--out", str(tmp_path / "run")]) == 0
    assert clip_episodes(env_id) == 1  # a match is 1800 steps: one is clip enough
    frames = mp4_frames(tmp_path / "run" / "videos" / "step_000000256.mp4")
    assert frames[0].shape == (36, 64, 3) and len(frames) > 90


@pytest.mark.parametrize("every", [0, -5, 2.5, True])
def test_video_every_takes_a_positive_whole_number_of_steps_or_none(every):
    from foosball_gym.training.config import TrainConfig

    with pytest.raises(ValueError, match="video_every must be a whole number of steps"):
        TrainConfig(ENV_ID, video_every=every).check()
