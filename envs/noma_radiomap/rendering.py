"""Drawing (docs/ARCHITECTURE.md): the radio maps (paper Fig. 4, :meth:`RadioMap.plot`) and the env's rendering,
the SINR map with the robots (:class:`Renderer`).

matplotlib is imported here only, and this module only when a map is plotted or an env renders for the first time.
"""

from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

    from noma_radiomap.env import NomaRadioMapEnv
    from noma_radiomap.radiomap import RadioMap

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


def plot_radio_map(
    radio_map: "RadioMap",
    ax: "Axes | None" = None,
    kind: str = "sinr",
    show_obstacles: bool = True,
    show_transmitters: bool = True,
    show_outage: bool = True,
    colorbar: bool = True,
    legend: bool = True,
    **imshow_kwargs: Any,
) -> "Axes":
    """
    :meth:`noma_radiomap.RadioMap.plot`: draw a map of ``radio_map`` as a heat map (see there for the parameters).
    """
    import matplotlib.pyplot as plt
    from matplotlib.patches import Rectangle
    from matplotlib.patheffects import withStroke

    outlined = [withStroke(linewidth=2.2, foreground="black")]  # readable on any map colour and on white

    if kind not in ("sinr", "power"):
        raise ValueError(f"kind: expected 'sinr' or 'power', got {kind!r}")
    if ax is None:
        _, ax = plt.subplots(figsize=(8, 5.4))
    room = radio_map.scenario.room
    values = radio_map.sinr_map_db if kind == "sinr" else radio_map.power_map_dbm
    label = "SINR (dB)" if kind == "sinr" else "received power (dBm)"
    imshow_kwargs.setdefault("cmap", "viridis")
    image = ax.imshow(values.T, origin="lower", extent=(0.0, room.width, 0.0, room.depth), **imshow_kwargs)
    walls = Rectangle((0.0, 0.0), room.width, room.depth, fill=False, ec="black", lw=1.2, zorder=3)
    ax.add_patch(walls)
    if colorbar:
        # An inset keeps the bar exactly as tall as the map, whatever the figure's layout.
        ax.figure.colorbar(image, cax=ax.inset_axes((1.03, 0.0, 0.03, 1.0)), label=label)
    outage = radio_map.outage_map() if show_outage and kind == "sinr" else None
    if outage is not None and outage.any():
        # Padded by one cell so the region closes at the walls; clipped to the room.
        padded = np.pad(outage.T.astype(float), 1, mode="edge")
        x = (np.arange(radio_map.nx + 2) - 0.5) * radio_map.resolution
        y = (np.arange(radio_map.ny + 2) - 0.5) * radio_map.resolution
        with plt.rc_context({"hatch.color": "red", "hatch.linewidth": 0.6}):
            fill = ax.contourf(x, y, padded, levels=[0.5, 1.5], colors="none", hatches=["////"])
        lines = ax.contour(x, y, padded, levels=[0.5], colors="red", linewidths=0.8)
        for artist in (fill, lines):
            artist.set_clip_path(walls)
        with plt.rc_context({"hatch.color": "red", "hatch.linewidth": 0.6}):
            ax.add_patch(Rectangle((0, 0), 0, 0, fc="none", ec="red", hatch="////", label="outage (one robot, full AP power)"))
    if show_obstacles:
        body = radio_map.scenario.robot.body_height
        labelled: set[bool] = set()
        for x0, y0, x1, y1, z0, _ in radio_map.boxes:
            if x0 <= 0 and y0 <= 0 and x1 >= room.width and y1 >= room.depth:
                continue  # a floor slab over the whole room
            blocks_motion = bool(z0 < body)
            text = "obstacle (blocks robots and radio)" if blocks_motion else "hanging obstacle (blocks radio only)"
            ax.add_patch(
                Rectangle(
                    (x0, y0),
                    x1 - x0,
                    y1 - y0,
                    fill=False,
                    lw=0.8,
                    ec="white",
                    ls="-" if blocks_motion else "--",
                    path_effects=outlined,
                    label=None if blocks_motion in labelled else text,
                )
            )
            labelled.add(blocks_motion)
    limits = [[0.0, room.width], [0.0, room.depth]]
    if show_transmitters:
        x, y, z = radio_map.scenario.ap.position
        ax.plot(x, y, marker="*", ms=14, color="red", mec="black", ls="none", label=f"AP (z = {z:g} m)")
        reach = 0.2 * max(room.width, room.depth)
        for k, interferer in enumerate(radio_map.scenario.interferers):
            x, y, z = interferer.position
            edge = np.array([np.clip(x, 0, room.width), np.clip(y, 0, room.depth)])
            distance = float(np.hypot(x - edge[0], y - edge[1]))
            far = distance > reach
            marker = edge if far else np.array([x, y])
            ax.plot(
                *marker,
                marker="X",
                ms=11,
                color="orange",
                mec="black",
                ls="none",
                clip_on=False,
                zorder=4,
                label="interferer (name, antenna height)" if k == 0 else None,
            )
            text = f"{interferer.name} (z = {z:g} m)"
            if far:
                ux, uy = (np.array([x, y]) - edge) / distance
                arrow = ax.annotate(
                    "",
                    marker,
                    xytext=(-28 * ux, -28 * uy),
                    textcoords="offset points",
                    arrowprops={"arrowstyle": "->", "color": "orange", "lw": 2, "shrinkB": 7},
                    annotation_clip=False,
                    zorder=4,
                )
                arrow.arrow_patch.set_path_effects(outlined)
                text = f"{interferer.name} ({distance:.0f} m outside, z = {z:g} m)"
            else:
                limits[0] = [min(limits[0][0], x), max(limits[0][1], x)]
                limits[1] = [min(limits[1][0], y), max(limits[1][1], y)]
            # Offset towards the room's centre, so the label stays inside the axes.
            dx = -1 if marker[0] > room.width / 2 else 1
            dy = -1 if marker[1] > room.depth / 2 else 1
            ax.annotate(
                text,
                marker,
                textcoords="offset points",
                xytext=(6 * dx, 6 * dy),
                ha="right" if dx < 0 else "left",
                va="top" if dy < 0 else "bottom",
                color="orange",
                fontsize=8,
                fontweight="bold",
                path_effects=outlined,
                annotation_clip=False,
            )
    extended = limits != [[0.0, room.width], [0.0, room.depth]]
    margin = 0.03 * max(room.width, room.depth) if extended else 0.0
    ax.set_xlim(limits[0][0] - margin * (limits[0][0] < 0), limits[0][1] + margin * (limits[0][1] > room.width))
    ax.set_ylim(limits[1][0] - margin * (limits[1][0] < 0), limits[1][1] + margin * (limits[1][1] > room.depth))
    if extended:
        ax.set_facecolor("0.85")
        ax.add_patch(Rectangle((0, 0), 0, 0, fc="0.85", ec="black", label="outside the room"))
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title(f"{radio_map.scenario.name}: {'SINR map' if kind == 'sinr' else 'power distribution map'}")
    if legend:
        legend_below(ax)
    return ax


def plot_radio_maps(radio_map: "RadioMap", path: str | None = None, dpi: int = 120) -> "Figure":
    """:meth:`noma_radiomap.RadioMap.plot_maps`: the paper's Fig. 4, power and SINR maps side by side."""
    import matplotlib.pyplot as plt

    figure, axes = plt.subplots(1, 2, figsize=(15, 5.6), layout="constrained")
    plot_radio_map(radio_map, axes[0], kind="power", legend=False)
    plot_radio_map(radio_map, axes[1], kind="sinr", legend=False)
    handles, labels = axes[1].get_legend_handles_labels()
    figure.legend(handles, labels, loc="outside lower center", ncol=min(len(labels), 4), fontsize=9, frameon=False)
    if path is not None:
        figure.savefig(path, dpi=dpi)
    return figure
