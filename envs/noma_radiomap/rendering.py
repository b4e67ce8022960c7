"""Rendering of :class:`~noma_radiomap.env.NomaRadioMapEnv` (docs/ARCHITECTURE.md): the SINR map with the robots.

matplotlib is imported here only, and this module only when an env renders for the first time.
"""

from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from matplotlib.axes import Axes

    from noma_radiomap.env import NomaRadioMapEnv

#: Robot colours: distinct from the map's colour scale and from the AP (red) and interferer (orange) markers.
_ROBOT_COLORS = ("magenta", "cyan", "white", "lime", "pink", "deepskyblue")
#: Figure size (inches): the map with its legend below.
_FIGSIZE = (8.0, 6.0)
#: Backends that cannot open a window: ``"human"`` rendering draws off-screen on them (no display).
_NON_INTERACTIVE = {"agg", "cairo", "pdf", "pgf", "ps", "svg", "template"}


def legend_below(ax: "Axes", extra: Any = (), ncol: int = 3) -> None:
    """
    A legend of the axes' labelled artists (plus ``extra`` handles) below the axes, off the data.

    :param ax: the axes
    :param extra: more legend handles (artists with labels)
    :param ncol: legend columns
    """
    handles, labels = ax.get_legend_handles_labels()
    for handle in extra:
        handles.append(handle)
        labels.append(handle.get_label())
    # A fixed offset in font sizes below the axes clears the tick labels and the x label at any axes size.
    ax.legend(handles, labels, loc="upper center", bbox_to_anchor=(0.5, 0.0), borderaxespad=4.0, ncol=ncol, fontsize=8)


def _marker_keys() -> list[Any]:
    """Legend keys (grey) for what every robot has in its own colour: position, destination, trail."""
    from matplotlib.lines import Line2D

    return [
        Line2D([], [], ls="none", marker="o", color="0.6", mec="black", ms=8, label="robot position"),
        Line2D([], [], ls="none", marker="P", color="0.6", mec="black", ms=10, label="destination"),
        Line2D([], [], ls="-", color="0.6", lw=1.5, label="path since reset"),
    ]


class Renderer:
    """
    Draws the env's SINR map (:meth:`noma_radiomap.RadioMap.plot`: heat map, obstacles, AP, interferers)
    once, then per frame the robots, their destinations and their trajectories since the last reset.

    ``rgb_array`` frames come from an off-screen Agg canvas; ``human`` opens a pyplot window and updates it
    (without a display, e.g. under the Agg backend, it only draws, so it is safe anywhere).

    :param env: the env to draw
    :param human: open a window (``render_mode="human"``) instead of drawing off-screen
    """

    def __init__(self, env: "NomaRadioMapEnv", human: bool = False, dpi: int = 80) -> None:
        self.env = env
        self.human = human
        if human:
            import matplotlib.pyplot as plt

            self.figure = plt.figure(figsize=_FIGSIZE, dpi=dpi, layout="constrained")
            self._interactive = plt.get_backend().lower() not in _NON_INTERACTIVE
            if self._interactive:
                plt.ion()
                plt.show(block=False)
        else:
            from matplotlib.backends.backend_agg import FigureCanvasAgg
            from matplotlib.figure import Figure

            self.figure = Figure(figsize=_FIGSIZE, dpi=dpi, layout="constrained")
            FigureCanvasAgg(self.figure)
            self._interactive = False
        ax = self.figure.add_subplot()
        env.radio_map.plot(ax, kind="sinr", colorbar=True, legend=False)
        colors = [_ROBOT_COLORS[u % len(_ROBOT_COLORS)] for u in range(env.n_robots)]
        self._trails = [ax.plot([], [], "-", color=c, lw=1.5)[0] for c in colors]
        self._robots = [ax.plot([], [], "o", color=c, mec="black", ms=8, label=f"robot {u}")[0] for u, c in enumerate(colors)]
        self._goals = [ax.plot([], [], "P", color=c, mec="black", ms=10)[0] for c in colors]
        legend_below(ax, _marker_keys(), ncol=3)
        self._title = ax.set_title(self._title_text())
        # Lay out once, then freeze: frames keep the same geometry (no jitter in videos) and draw faster.
        self.figure.canvas.draw()
        self.figure.set_layout_engine("none")

    def _title_text(self) -> str:
        env = self.env
        return (
            f"{env.scenario.name} ({env.multiple_access.upper()}, {env.channel}): step {env.step_count}, "
            f"arrived {int(env.arrived.sum())}/{env.n_robots}"
        )

    def render(self) -> np.ndarray | None:
        """
        Draw the current state.

        :return: an RGB frame (height, width, 3) uint8 for ``rgb_array``; None for ``human``
        """
        env = self.env
        trajectory = env.trajectory
        for u in range(env.n_robots):
            self._trails[u].set_data(trajectory[:, u, 0], trajectory[:, u, 1])
            self._robots[u].set_data([env.positions[u, 0]], [env.positions[u, 1]])
            self._goals[u].set_data([env.destinations[u, 0]], [env.destinations[u, 1]])
        self._title.set_text(self._title_text())
        if self.human:
            self.figure.canvas.draw_idle()
            if self._interactive:
                self.figure.canvas.flush_events()
                import matplotlib.pyplot as plt

                plt.pause(1.0 / env.metadata["render_fps"])
            return None
        self.figure.canvas.draw()
        return np.asarray(self.figure.canvas.buffer_rgba())[..., :3].copy()

    def close(self) -> None:
        """Release the figure (and close the window in ``human`` mode)."""
        if self.human:
            import matplotlib.pyplot as plt

            plt.close(self.figure)
        self.figure = None

    def __getstate__(self) -> dict[str, Any]:
        raise TypeError("Renderer holds a matplotlib figure and is not picklable; the env drops it when pickled")
