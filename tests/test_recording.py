"""``sb3-dtdpg enjoy --record`` and :mod:`sb3_dtdpg.recording`: a recording is written whole or not at all, at a
frame rate its file plays."""

import os

import gymnasium as gym
import pytest
from matplotlib import animation
from PIL import Image

from sb3_dtdpg import DTDPG
from sb3_dtdpg.cli import main
from sb3_dtdpg.recording import GIF_MAX_FPS, animation_writer, run_mission, save_animation


@pytest.fixture(autouse=True)
def _agg_backend(monkeypatch):
    monkeypatch.setenv("MPLBACKEND", "Agg")


def small_env():
    return gym.make("NomaRadioMap-v0", scenario="small")


@pytest.fixture(scope="module")
def saved_dtdpg(tmp_path_factory):
    """A random-init DT-DPG on `small`, saved as it is."""
    path = tmp_path_factory.mktemp("model") / "dtdpg.zip"
    DTDPG("MlpPolicy", small_env(), seed=0).save(path)
    return path


@pytest.fixture(scope="module")
def mission():
    env = small_env()
    return env, run_mission(DTDPG("MlpPolicy", env, seed=0), env, seed=0)


def run_cli(argv, capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(argv)
    return exit_info.value.code, capsys.readouterr()


def failing_at_frame(monkeypatch, frame, error):
    """Make the GIF writer raise ``error`` when it grabs frame ``frame`` (0-based)."""
    grab_frame, grabbed = animation.PillowWriter.grab_frame, []

    def grab(self, **kwargs):
        if len(grabbed) == frame:
            raise error
        grabbed.append(frame)
        grab_frame(self, **kwargs)

    monkeypatch.setattr(animation.PillowWriter, "grab_frame", grab)


@pytest.mark.parametrize("before", ["a recording", "no file"])
def test_an_interrupted_recording_keeps_the_file_that_was_there(saved_dtdpg, tmp_path, capsys, monkeypatch, before):
    # was: matplotlib's writer wrote the frames grabbed so far (its finish() runs in a finally) over the old file
    gif = tmp_path / "out.gif"
    record = ["enjoy", str(saved_dtdpg), "--record", str(gif), "--max-frames", "6"]
    if before == "a recording":
        assert main(record) == 0
        with Image.open(gif) as image:
            assert image.n_frames == 6
    content = gif.read_bytes() if gif.exists() else None
    capsys.readouterr()
    failing_at_frame(monkeypatch, 3, KeyboardInterrupt())
    assert main(record) == 130
    assert "interrupted: enjoy stopped before its end" in capsys.readouterr().err
    assert (gif.read_bytes() if gif.exists() else None) == content
    assert sorted(p.name for p in tmp_path.iterdir()) == (["out.gif"] if content else [])  # no temporary file left


def test_a_recording_that_fails_leaves_no_file_and_a_finished_one_no_temporary_file(mission, tmp_path, monkeypatch):
    env, trace = mission
    gif = tmp_path / "sub" / "mission.gif"
    assert save_animation(env, trace, gif, max_frames=3) == 3
    assert [p.name for p in gif.parent.iterdir()] == ["mission.gif"]
    umask = os.umask(0o022)
    os.umask(umask)
    assert gif.stat().st_mode & 0o777 == 0o666 & ~umask  # as open() makes a file, not a private temporary one
    content = gif.read_bytes()
    failing_at_frame(monkeypatch, 1, OSError("disk full"))
    with pytest.raises(OSError, match="disk full"):
        save_animation(env, trace, gif, max_frames=3)
    assert gif.read_bytes() == content and [p.name for p in gif.parent.iterdir()] == ["mission.gif"]


def test_the_fps_a_gif_cannot_play_is_refused_and_an_mp4_takes_it(tmp_path, monkeypatch):
    # was: a .gif at fps above 100 got frame times of 0 ms (int(1000 / fps)); above 50, of 1/100 s, which browsers
    # and most viewers play at 10 fps
    assert isinstance(animation_writer(tmp_path / "m.gif", GIF_MAX_FPS), animation.PillowWriter)
    for fps in (GIF_MAX_FPS + 1, 150, 1000):
        with pytest.raises(ValueError, match=f"fps must be at most 50 for a .gif, got {fps} "):
            animation_writer(tmp_path / "m.gif", fps)
    for suffix in (".gif", ".mp4"):
        with pytest.raises(ValueError, match="fps must be positive, got 0"):
            animation_writer(tmp_path / f"m{suffix}", 0)
    monkeypatch.setattr(animation.FFMpegWriter, "isAvailable", classmethod(lambda cls: True))
    assert animation_writer(tmp_path / "m.mp4", 240).fps == 240  # ffmpeg takes any frame rate
    assert not list(tmp_path.iterdir())


def test_a_gif_at_its_highest_fps_holds_each_frame_two_hundredths_of_a_second(mission, tmp_path):
    env, trace = mission
    gif = tmp_path / "fast.gif"
    save_animation(env, trace, gif, fps=GIF_MAX_FPS, max_frames=3)
    with Image.open(gif) as image:
        assert image.n_frames == 3 and image.info["duration"] == 20


def test_enjoy_refuses_a_gif_fps_above_50_before_the_mission(saved_dtdpg, tmp_path, capsys):
    gif = tmp_path / "out.gif"
    code, printed = run_cli(["enjoy", str(saved_dtdpg), "--record", str(gif), "--fps", "150"], capsys)
    assert code == 2 and printed.out == "" and "Traceback" not in printed.err
    errors = [line for line in printed.err.splitlines() if ": error: " in line]
    assert len(errors) == 1 and errors[0].startswith("sb3-dtdpg enjoy: error: --record ")
    assert "fps must be at most 50 for a .gif, got 150" in errors[0]
    assert not gif.exists()
