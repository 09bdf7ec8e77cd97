"""Plots of trajectories (matplotlib, no display needed).

The paper's Fig. 4 coordinates for the two-finger scene: finger depths x1 = y0 - finger1.y,
x2 = y0 - finger2.y (0 = fully raised) and the triangle's offset x3 = triangle.x.
"""

from __future__ import annotations

import textwrap
from pathlib import Path

import numpy as np

PAPER_COORDINATES = ("finger1.y", "finger2.y", "triangle.x")


def has_paper_coordinates(coordinates) -> bool:
    return all(c in coordinates for c in PAPER_COORDINATES)


def paper_coordinates(coordinates, start, trajectory) -> np.ndarray:
    """(n, 3) array of (x1, x2, x3) from a trajectory in the scenario's coordinates."""
    i1, i2, i3 = (list(coordinates).index(c) for c in PAPER_COORDINATES)
    return np.column_stack([start[i1] - trajectory[:, i1], start[i2] - trajectory[:, i2], trajectory[:, i3]])


def plot_rollouts(path: Path, coordinates, start, runs: list[tuple[str, np.ndarray, np.ndarray]], title: str) -> Path:
    """Write a plot of rollouts [(label, times, trajectory)]: Fig. 4 axes when the scene has them."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    if has_paper_coordinates(coordinates):
        fig = plt.figure(figsize=(11, 4.5))
        ax3 = fig.add_subplot(1, 2, 1, projection="3d")
        ax2 = fig.add_subplot(1, 2, 2)
        for label, _, X in runs:
            P = paper_coordinates(coordinates, start, X)
            ax3.plot(P[:, 0], P[:, 1], P[:, 2], label=label)
            ax2.plot(P[:, 0] - P[:, 1], P[:, 2], label=label)
        # the goal edge of the paper (point fingers): from (1, 2, -0.5) to (2, 1, 0.5)
        ax3.plot([1, 2], [2, 1], [-0.5, 0.5], color="tab:blue", lw=3, alpha=0.4)
        ax3.set_xlabel("x1 (finger 1 depth)")
        ax3.set_ylabel("x2 (finger 2 depth)")
        ax3.set_zlabel("x3 (triangle offset)")
        ax2.axhspan(-0.5, 0.5, color="tab:green", alpha=0.08)
        ax2.set_xlabel("x1 - x2")
        ax2.set_ylabel("x3")
        ax2.legend(fontsize=7)
    else:
        fig, ax = plt.subplots(figsize=(8, 4.5))
        for label, times, X in runs:
            for j, name in enumerate(coordinates):
                ax.plot(times, X[:, j], label=f"{label}: {name}" if len(runs) > 1 else name)
        ax.set_xlabel("t (s)")
        ax.set_ylabel("coordinate")
        ax.legend(fontsize=7)
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


#: Colour of each outcome (models.task.Outcome labels) in the sweep and fan plots.
OUTCOME_COLOURS = {"goal": "tab:green", "unsafe": "tab:red", "none": "0.6"}


def plot_feasible_sets(path: Path, result) -> Path:
    """The Fig. 5 analogue: each grid point coloured by outcome (Z_F green, Z_U red, none
    grey), one panel per model; refined boundaries as black ticks. Two axes: a map over them;
    one axis: a strip. Writes PNG (and SVG when path ends in .svg)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    models = [m.label for m in result.models]
    axes = result.axes
    fig, panels = plt.subplots(1, len(models), figsize=(4.2 * len(models), 3.8), squeeze=False, sharey=True)
    x_axis = axes[0]
    y_axis = axes[1] if len(axes) > 1 else None
    for panel, model in zip(panels[0], models):
        for outcome, colour in OUTCOME_COLOURS.items():
            pts = [p for p in result.points if p is not None and p.model == model and p.outcome == outcome]
            xs = [p.parameters[x_axis.name] for p in pts]
            ys = [p.parameters[y_axis.name] if y_axis else 0.0 for p in pts]
            panel.scatter(xs, ys, s=14, color=colour, label=f"{outcome} ({len(pts)})", marker="s")
        for b in result.boundaries:
            if b["model"] != model:
                continue
            if b["axis"] == x_axis.name:
                y = b["at"][y_axis.name] if y_axis else 0.0
                panel.plot([b["boundary"]] * 2, [y - 0.02 * _span(y_axis), y + 0.02 * _span(y_axis)], color="k", lw=1.5)
            elif y_axis is not None and b["axis"] == y_axis.name:
                x = b["at"][x_axis.name]
                panel.plot(
                    [x / 1.02, x * 1.02] if x_axis.log else [x - 0.01 * _span(x_axis), x + 0.01 * _span(x_axis)],
                    [b["boundary"]] * 2,
                    color="k",
                    lw=1.5,
                )
        if x_axis.log:
            from matplotlib.ticker import NullFormatter, ScalarFormatter

            panel.set_xscale("log")
            panel.xaxis.set_major_formatter(ScalarFormatter())
            panel.xaxis.set_minor_formatter(NullFormatter())
        panel.set_xlabel(x_axis.name)
        panel.set_title("\n".join(textwrap.wrap(model, 38)), fontsize=8)
        panel.legend(fontsize=7, loc="best")
    panels[0][0].set_ylabel(y_axis.name if y_axis else "")
    fig.suptitle(f"{Path(result.file).stem}: goal (Z_F) and unsafe (Z_U) sets" + ("" if result.complete else " (INCOMPLETE)"))
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    if path.suffix == ".png":
        fig.savefig(path.with_suffix(".svg"))
    plt.close(fig)
    return path


def _span(axis) -> float:
    if axis is None:
        return 1.0
    return (max(axis.values) - min(axis.values)) or 1.0


def plot_fan(path: Path, panels: list[tuple[str, list[tuple[float, str, np.ndarray]]]], coordinates, start, title: str) -> Path:
    """The Fig. 4 analogue: per model a panel of trajectories in (x1, x2, x3) for a fan of
    speed ratios, each coloured by how it ended. panels: [(model label, [(ratio, outcome label,
    trajectory)])]."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig = plt.figure(figsize=(4.6 * len(panels), 4.6))
    for k, (label, runs) in enumerate(panels):
        ax = fig.add_subplot(1, len(panels), k + 1, projection="3d")
        for _ratio, outcome, X in runs:
            P = paper_coordinates(coordinates, start, X)
            inside = np.abs(P[:, 2]) <= 1.5  # the paper's window; a triangle thrown out leaves it
            P = P[: (np.argmin(inside) if not inside.all() else len(P))]
            ax.plot(P[:, 0], P[:, 1], P[:, 2], color=OUTCOME_COLOURS[outcome], lw=1.0, ls="-" if outcome == "goal" else ":")
        ax.plot([1, 2], [2, 1], [-0.5, 0.5], color="tab:blue", lw=3, alpha=0.4)
        ax.set_xlabel("x1")
        ax.set_ylabel("x2")
        ax.set_zlabel("x3")
        ax.set_zlim(-1.5, 1.5)
        ax.set_title("\n".join(textwrap.wrap(label, 38)), fontsize=8)
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    if path.suffix == ".png":
        fig.savefig(path.with_suffix(".svg"))
    plt.close(fig)
    return path
