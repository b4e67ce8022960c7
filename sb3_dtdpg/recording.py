"""An animation of one mission: the robots' paths over the SINR map, the power split and the outage steps.

``sb3-dtdpg enjoy MODEL --record mission.gif`` uses it. It draws off-screen (matplotlib's Agg canvas, no
display needed) and writes with matplotlib's own writers: ``.gif`` with ``PillowWriter`` (pillow comes with
matplotlib), ``.mp4`` with ``FFMpegWriter`` (needs an ``ffmpeg`` program on the ``PATH``). The file is written
whole or not at all (:func:`sb3_dtdpg.common.files.atomic_write`): an error or Ctrl-C while it is written keeps the
file that was there.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from sb3_dtdpg.common.files import atomic_write

__all__ = [
    "GIF_MAX_FPS",
    "MissionTrace",
    "animation_writer",
    "frame_steps",
    "record_mission",
    "run_mission",
    "save_animation",
]

#: The most frames per second a ``.gif`` plays: its frame times are whole hundredths of a second, and browsers and
#: most viewers play a frame of 1/100 s (or 0) for 1/10 s, so 2/100 s per frame is the shortest that plays as written.
GIF_MAX_FPS = 50

_ROBOT_COLORS = ("magenta", "cyan", "white", "lime", "pink", "deepskyblue")


@dataclass
class MissionTrace:
    """
    What one mission did, step by step (``T`` steps, ``U`` robots).

    :param positions: robot positions, shape (T + 1, U, 2), metres
    :param power_w: allocated transmit power per step, shape (T, U), watts
    :param outage: whether each robot was in outage at each step, shape (T, U)
    :param destinations: shape (U, 2)
    :param info: the last step's ``info`` (``is_success``, ``mqi``, ...)
    """

    positions: np.ndarray
    power_w: np.ndarray
    outage: np.ndarray
    destinations: np.ndarray
    info: dict[str, Any]


def run_mission(model: Any, env: Any, seed: int, deterministic: bool = True) -> MissionTrace:
    """
    :param model: anything with SB3's ``predict``
    :param env: a (wrapped) NomaRadioMap env
    :param seed: the reset seed (the mission and its fading)
    :param deterministic: passed to ``predict``
    :return: the mission's trace
    """
    obs, _ = env.reset(seed=seed)
    base = env.unwrapped
    positions = [np.array(base.positions, dtype=np.float64)]
    power, outage, done, info = [], [], False, {}
    while not done:
        action, _ = model.predict(obs, deterministic=deterministic)
        obs, _, terminated, truncated, info = env.step(action)
        positions.append(np.array(base.positions, dtype=np.float64))
        power.append(np.asarray(info["power_w"], dtype=np.float64))
        outage.append(np.asarray(info["outage"], dtype=bool))
        done = terminated or truncated
    return MissionTrace(np.stack(positions), np.stack(power), np.stack(outage), np.array(base.destinations), info)


def animation_writer(path: str | Path, fps: int = 10) -> Any:
    """
    The matplotlib writer of a recording, checked before a mission runs (``.mp4`` needs ffmpeg).

    :param path: ``.gif`` or ``.mp4``
    :param fps: frames per second: positive, for a ``.gif`` at most :data:`GIF_MAX_FPS` (a ``.gif`` of 30 fps
        holds each frame 3/100 s: 33.3 fps)
    :return: a ``PillowWriter`` (``.gif``) or ``FFMpegWriter`` (``.mp4``)
    :raises ValueError: another suffix, ``.mp4`` without ffmpeg, or an ``fps`` the file cannot play
    """
    from matplotlib import animation

    path = Path(path)
    if not fps > 0:
        raise ValueError(f"{path}: fps must be positive, got {fps!r}")
    if path.suffix.lower() == ".gif":
        if fps > GIF_MAX_FPS:
            raise ValueError(
                f"{path}: fps must be at most {GIF_MAX_FPS} for a .gif, got {fps!r} (a .gif's frame times are whole "
                "hundredths of a second, and viewers play frames shorter than 2/100 s at 10 fps); record a .mp4 for "
                "more frames per second"
            )
        return animation.PillowWriter(fps=fps)
    if path.suffix.lower() == ".mp4":
        if not animation.FFMpegWriter.isAvailable():
            raise ValueError(f"{path}: writing .mp4 needs the ffmpeg program on the PATH; record a .gif instead")
        return animation.FFMpegWriter(fps=fps)
    raise ValueError(f"{path}: the recording must be a .gif or .mp4 file, got suffix {path.suffix!r}")


def frame_steps(steps: int, max_frames: int) -> list[int]:
    """
    :param steps: the mission's steps (frame ``t`` shows the robots after ``t`` steps, ``0..steps``)
    :param max_frames: at most this many frames (>= 1)
    :return: the steps to draw, evenly spread, first and last included; one frame is the last step (the whole paths)
    :raises ValueError: ``max_frames`` below 1
    """
    if max_frames < 1:
        raise ValueError(f"max_frames must be >= 1, got {max_frames!r}")
    count = min(steps + 1, max_frames)
    if count == 1:
        return [steps]
    return sorted(set(np.linspace(0, steps, num=count).round().astype(int).tolist()))


def save_animation(env: Any, trace: MissionTrace, path: str | Path, fps: int = 10, max_frames: int = 120) -> int:
    """
    Write the mission as an animation.

    :param env: the env the trace comes from (its radio map is the background)
    :param trace: see :func:`run_mission`
    :param path: ``.gif`` or ``.mp4``, replaced only once the whole animation is written: on an error or
        ``KeyboardInterrupt`` the file that was there is kept and no temporary file is left
    :param fps: frames per second (:func:`animation_writer`)
    :param max_frames: at most this many frames (long missions show every k-th step; the last is always shown;
        one frame: the last step alone, :func:`frame_steps`)
    :return: the number of frames written
    :raises ValueError: another suffix, ``.mp4`` without ffmpeg, an ``fps`` the file cannot play, or ``max_frames``
        below 1
    """
    from matplotlib import animation
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    path = Path(path)
    writer = animation_writer(path, fps)
    base = env.unwrapped
    steps, n_robots = trace.power_w.shape
    frames = frame_steps(steps, max_frames)

    figure = Figure(figsize=(10.0, 5.2), dpi=72, layout="constrained")
    FigureCanvasAgg(figure)
    ax_map, ax_power = figure.subplots(1, 2, width_ratios=(1.6, 1.0))
    base.radio_map.plot(ax_map, kind="sinr", colorbar=True, legend=False)
    colors = [_ROBOT_COLORS[u % len(_ROBOT_COLORS)] for u in range(n_robots)]
    for u, color in enumerate(colors):
        x, y = trace.destinations[u]
        ax_map.plot([x], [y], "P", color=color, mec="black", ms=11)
        ax_map.plot(*trace.positions[0, u], "s", color=color, mec="black", ms=7)
    trails = [ax_map.plot([], [], "-", color=c, lw=1.5)[0] for c in colors]
    robots = [ax_map.plot([], [], "o", color=c, mec="black", ms=9, label=f"robot {u}")[0] for u, c in enumerate(colors)]
    outages = ax_map.scatter([], [], marker="x", color="red", s=18, label="outage", zorder=5)
    starts = ax_map.plot([], [], "s", color="gray", mec="black", ms=7, label="start")[0]
    goals = ax_map.plot([], [], "P", color="gray", mec="black", ms=10, label="destination")[0]
    ax_map.legend(
        handles=[*robots, starts, goals, outages], loc="upper center", bbox_to_anchor=(0.5, -0.13), ncol=4, fontsize=7
    )
    title = ax_map.set_title("")

    time = np.arange(1, steps + 1)
    share = trace.power_w / np.maximum(trace.power_w.sum(axis=1, keepdims=True), 1e-12)
    ax_power.stackplot(
        time, share.T, colors=colors, edgecolor="black", linewidth=0.2, labels=[f"robot {u}" for u in range(n_robots)]
    )
    for u, color in enumerate(colors):  # a strip per robot above the shares: red where it was in outage
        low = 1.02 + 0.04 * u
        ax_power.fill_between(time, low, low + 0.03, color=color, step="mid", lw=0)
        ax_power.fill_between(time, low, low + 0.03, where=trace.outage[:, u], color="red", step="mid", lw=0)
    ax_power.plot([], [], "s", color="red", label="outage (strips above: one per robot)")
    ax_power.set(xlim=(0, max(steps, 1)), ylim=(0, 1.04 + 0.04 * n_robots), xlabel="step", ylabel="share of the AP's power")
    ax_power.legend(loc="upper center", bbox_to_anchor=(0.5, -0.13), ncol=2, fontsize=7)
    cursor = ax_power.axvline(0, color="black", lw=1)
    outage_points = [(t, u) for t in range(steps) for u in range(n_robots) if trace.outage[t, u]]

    def draw(t: int) -> None:
        for u in range(n_robots):
            trails[u].set_data(trace.positions[: t + 1, u, 0], trace.positions[: t + 1, u, 1])
            robots[u].set_data([trace.positions[t, u, 0]], [trace.positions[t, u, 1]])
        shown = [trace.positions[s + 1, u] for s, u in outage_points if s < t]
        outages.set_offsets(np.array(shown).reshape(-1, 2))
        cursor.set_xdata([t, t])
        outage_steps = int(trace.outage[:t].sum())
        title.set_text(
            f"{base.scenario.name}, {base.multiple_access.upper()}: step {t}/{steps}, outage steps {outage_steps}"
            + (f", MQI {float(trace.info['mqi']):.1f}" if t == steps and "mqi" in trace.info else "")
        )

    movie = animation.FuncAnimation(figure, draw, frames=frames, blit=False)

    def write(tmp: str) -> None:
        # the writers pick the format from the suffix, and atomic_write's file ends in .tmp: the movie goes to a file
        # of the suffix beside it, which then takes its place
        movie_file = f"{tmp}{path.suffix}"
        try:
            movie.save(movie_file, writer=writer)
            os.replace(movie_file, tmp)
        except BaseException:
            Path(movie_file).unlink(missing_ok=True)
            raise

    atomic_write(path, write)
    return len(frames)


def record_mission(model: Any, env: Any, path: str | Path, seed: int, fps: int = 10, max_frames: int = 120) -> MissionTrace:
    """
    Run one mission with ``model`` and write its animation to ``path`` (:func:`run_mission`, :func:`save_animation`).

    :return: the mission's trace
    """
    trace = run_mission(model, env, seed)
    save_animation(env, trace, path, fps=fps, max_frames=max_frames)
    return trace
