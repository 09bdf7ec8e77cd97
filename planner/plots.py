"""Plots of trajectories (matplotlib, no display needed).

The paper's Fig. 4 coordinates for the two-finger scene: finger depths x1 = y0 - finger1.y,
x2 = y0 - finger2.y (0 = fully raised) and the triangle's offset x3 = triangle.x.
"""

from __future__ import annotations

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
