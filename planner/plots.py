"""Plots of trajectories and feasible sets (matplotlib, no display needed).

The paper's Fig. 4 coordinates for the two-finger scene: finger depths x1 = y0 - finger1.y,
x2 = y0 - finger2.y (0 = fully raised) and the triangle's offset x3 = triangle.x; its C-space
(C_free's boundary and the goal edge) comes from `planner.cspace`, for a scene of those three
coordinates whose only other body is a floor (the palm); the goal drawn is the file's (its
interval of triangle.x; the goal edge cut to it). Any other scene is drawn one panel per body,
its coordinates against time with the task's goal intervals shaded.
"""

from __future__ import annotations

import math
import textwrap
from pathlib import Path

import numpy as np

PAPER_COORDINATES = ("finger1.y", "finger2.y", "triangle.x")

#: Colour of each outcome (models.task.Outcome labels) in the sweep and fan plots.
OUTCOME_COLOURS = {"goal": "tab:green", "unsafe": "tab:red", "none": "0.6"}
#: What the paper calls each outcome's set (its text: Z_F and Z_U; Fig. 5's caption calls Z_U Z_A).
OUTCOME_SETS = {"goal": "Z_F (grasp)", "unsafe": "Z_U (slipped out)", "none": "neither"}
#: The paper's Fig. 4 window along x3.
FIG4_WINDOW = 1.5
#: Colours of the four finger-face strata in Fig. 4.
STRATUM_COLOURS = ("tab:orange", "tab:purple", "tab:cyan", "tab:olive")
GOAL_EDGE_COLOUR = "tab:blue"
#: Line styles and markers cycled so that no curve hides another.
LINE_STYLES = ("-", "--", "-.", ":")
MARKERS = ("o", "s", "^", "D", "v", "P", "X")
#: Coordinates that are angles (rad); quaternions are shown as their yaw.
ANGLE_NAMES = ("theta", "yaw", "roll", "pitch")
QUATERNION_NAMES = ("qw", "qx", "qy", "qz")
#: Smallest y span of a body panel's position (m) and angle (rad) axes.
MIN_POSITION_SPAN = 0.05
MIN_ANGLE_SPAN = 0.2


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _wrap(text: str, width: int) -> str:
    return "\n".join(textwrap.wrap(text, width))


def _save(fig, path: Path, svg: bool = False) -> Path:
    """Save and close the figure. A folder that passed the commands' checks but takes no file
    (root under /proc, a full disk) is bad input: a ScenarioError naming the file."""
    import matplotlib.pyplot as plt

    from models.scenario import Problem, ScenarioError

    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(path, dpi=110, bbox_inches="tight")
        if svg and path.suffix == ".png":
            fig.savefig(path.with_suffix(".svg"), bbox_inches="tight")
    except OSError as exc:
        raise ScenarioError(path, [Problem("", f"cannot write the plot: {exc.strerror or exc}")]) from None
    finally:
        plt.close(fig)
    return path


# ----------------------------------------------------------------------------- paper coordinates


def has_paper_coordinates(coordinates) -> bool:
    return all(c in coordinates for c in PAPER_COORDINATES)


def paper_coordinates(coordinates, start, trajectory) -> np.ndarray:
    """(n, 3) array of (x1, x2, x3) from a trajectory in the scenario's coordinates."""
    i1, i2, i3 = (list(coordinates).index(c) for c in PAPER_COORDINATES)
    return np.column_stack([start[i1] - trajectory[:, i1], start[i2] - trajectory[:, i2], trajectory[:, i3]])


def clip_to_window(P: np.ndarray, space, window: float = FIG4_WINDOW) -> tuple[np.ndarray, bool]:
    """P (n, 3) with the points outside Fig. 4's axes (x1, x2 in [0, limit], x3 in
    [-window, window], a 2% margin) set to NaN, so a line breaks where it leaves them; and
    whether any point was outside."""
    margin = 0.02 * max(space.depth_limit)
    inside = (
        (P[:, 0] >= -margin)
        & (P[:, 0] <= space.depth_limit[0] + margin)
        & (P[:, 1] >= -margin)
        & (P[:, 1] <= space.depth_limit[1] + margin)
        & (np.abs(P[:, 2]) <= window)
    )
    Q = P.astype(float).copy()
    Q[~inside] = np.nan
    return Q, not inside.all()


def draw_cspace(ax, space, window: float = FIG4_WINDOW) -> list:
    """Draw C_free's boundary (edges, and the four finger-face strata as shaded facets) and
    the goal edge on a 3D axes in (x1, x2, x3); set the axes to the window. Returns legend
    handles (strata and goal edge)."""
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    x3 = np.linspace(-window, window, 601)
    f1, f2 = space.depth_bound(0, x3), space.depth_bound(1, x3)
    zeros = np.zeros_like(x3)
    for a, b in ((f1, zeros), (zeros, f2), (f1, f2)):  # the polyhedron's edges along x3
        ax.plot(a, b, x3, color="0.35", lw=0.7)
    for k in (0, -1):  # its square ends at the window
        ax.plot([0, f1[k], f1[k], 0, 0], [0, 0, f2[k], f2[k], 0], [x3[k]] * 5, color="0.35", lw=0.7)
    handles = []
    for colour, s in zip(STRATUM_COLOURS, space.strata):
        lo, hi = max(s.x3_low, -window), min(s.x3_high, window)
        if hi <= lo:
            continue
        z = np.linspace(lo, hi, 40)
        own = s.depth(z)
        other = space.depth_bound(1 - s.finger, z)
        grid = np.vstack([np.zeros_like(z), other])  # the other finger from raised to its bound
        X = np.vstack([own, own]) if s.finger == 0 else grid
        Y = grid if s.finger == 0 else np.vstack([own, own])
        ax.plot_surface(X, Y, np.vstack([z, z]), color=colour, alpha=0.28, shade=False, linewidth=0)
        handles.append(Patch(color=colour, alpha=0.5, label=f"C_free facet: {s.name}"))
    if space.goal_edge is not None:
        e = space.goal_edge
        ax.plot(e[:, 0], e[:, 1], e[:, 2], color=GOAL_EDGE_COLOUR, lw=4, solid_capstyle="round", zorder=10)
        ends = " .. ".join("(" + ", ".join(f"{v:.2f}" for v in p) + ")" for p in e)
        handles.append(Line2D([], [], color=GOAL_EDGE_COLOUR, lw=4, label=f"goal edge (both fingers on their faces): {ends}"))
    ax.set_xlim(0, space.depth_limit[0])
    ax.set_ylim(0, space.depth_limit[1])
    ax.set_zlim(-window, window)
    ax.set_xlabel("x1 (finger 1 depth)")
    ax.set_ylabel("x2 (finger 2 depth)")
    ax.set_zlabel("x3 (triangle offset)")
    ax.view_init(elev=22, azim=-128)
    return handles


def _draw_paper_run(ax, P: np.ndarray, space, colour: str, style: str, label: str | None = None) -> bool:
    """One trajectory in (x1, x2, x3) clipped to the axes, its end marked: a filled dot where
    it ended inside them, an open triangle where it left them. Returns whether it left."""
    Q, left = clip_to_window(P, space)
    ax.plot(Q[:, 0], Q[:, 1], Q[:, 2], color=colour, lw=1.1, ls=style, label=label)
    finite = np.flatnonzero(np.isfinite(Q[:, 0]))
    if len(finite):
        end = Q[finite[-1]]
        left_at_end = finite[-1] < len(Q) - 1
        ax.scatter(
            *end, color=colour, marker="^" if left_at_end else "o", s=26, facecolors="none" if left_at_end else colour, depthshade=False
        )
    return left


def _end_handles(start_colour: str = "k") -> list:
    from matplotlib.lines import Line2D

    return [
        Line2D([], [], color=start_colour, marker="*", ls="none", ms=11, label="start (0, 0, 0)"),
        Line2D([], [], color="0.3", marker="o", ls="none", label="end of a run"),
        Line2D([], [], color="0.3", marker="^", mfc="none", ls="none", label="where a run leaves the axes (clipped)"),
    ]


# ----------------------------------------------------------------------------- simulate / plan plots


def plot_rollouts(path: Path, scenario, runs: list[tuple[str, np.ndarray, np.ndarray]], title: str) -> Path:
    """Write a plot of rollouts [(label, times, trajectory)] of `scenario`: the paper's Fig. 4
    C-space when it is the two-finger scene, else one panel per body (`rollout_figure`)."""
    return _save(rollout_figure(scenario, runs, title), path)


def rollout_figure(scenario, runs, title: str):
    """The figure `plot_rollouts` writes (callers close it)."""
    if has_paper_coordinates(scenario.coordinates):
        try:
            from planner.cspace import two_finger_cspace

            space = two_finger_cspace(scenario)
        except ValueError:
            space = None
        if space is not None:
            return _paper_rollout_figure(scenario, space, runs, title)
    return body_figure(scenario, runs, title)


def _paper_rollout_figure(scenario, space, runs, title: str):
    plt = _pyplot()
    fig = plt.figure(figsize=(12, 5.2))
    ax3 = fig.add_subplot(1, 2, 1, projection="3d")
    ax2 = fig.add_subplot(1, 2, 2)
    interval = goal_intervals(scenario.spec.task.goal).get(PAPER_COORDINATES[2])  # the file's, not the paper's [-0.5, 0.5]
    handles = draw_cspace(ax3, _goal_edge_within(space, interval))
    for k, (label, _, X) in enumerate(runs):
        P = paper_coordinates(scenario.coordinates, scenario.start, X)
        colour = f"C{k}"
        _draw_paper_run(ax3, P, space, colour, LINE_STYLES[k % len(LINE_STYLES)], label)
        ax2.plot(P[:, 0] - P[:, 1], P[:, 2], color=colour, ls=LINE_STYLES[k % len(LINE_STYLES)], label=label)
    ax3.scatter([0], [0], [0], color="k", marker="*", s=80, depthshade=False)
    if interval is not None:
        ax2.axhspan(*interval, color="tab:green", alpha=0.08, label=f"goal: {PAPER_COORDINATES[2]} in [{interval[0]:g}, {interval[1]:g}]")
        _view_without_far_edges(ax2, [interval])
    ax2.set_xlabel("x1 - x2")
    ax2.set_ylabel("x3 (triangle offset)")
    ax2.legend(fontsize=7)
    fig.legend(handles=handles + _end_handles(), loc="lower center", ncol=2, fontsize=7, frameon=False)
    fig.suptitle(_wrap(title, 110))
    fig.tight_layout(rect=(0, 0.14, 1, 1))
    return fig


def _goal_edge_within(space, interval: tuple[float, float] | None):
    """`space` with its goal edge (a segment in (x1, x2, x3)) cut to the goal's interval of x3
    (none where they do not meet); as it is without an interval."""
    from dataclasses import replace

    edge = space.goal_edge
    if edge is None or interval is None:
        return space
    (a, b), (lo, hi) = edge[:, 2], interval
    if a == b:
        return space if lo <= a <= hi else replace(space, goal_edge=None)
    s0, s1 = sorted(((lo - a) / (b - a), (hi - a) / (b - a)))
    s0, s1 = max(s0, 0.0), min(s1, 1.0)
    if s1 < s0:
        return replace(space, goal_edge=None)
    return replace(space, goal_edge=np.array([edge[0] + s * (edge[1] - edge[0]) for s in (s0, s1)]))


def body_coordinates(coordinates) -> dict[str, dict[str, list]]:
    """Per body (file order): its position coordinates and its angles, as lists of
    (shown name, column index or quaternion column indices (qw, qx, qy, qz))."""
    bodies: dict[str, dict[str, list]] = {}
    for j, name in enumerate(coordinates):
        body, _, dof = name.partition(".")
        entry = bodies.setdefault(body, {"position": [], "angle": []})
        if dof in QUATERNION_NAMES:
            if dof == "qw":
                quat = tuple(list(coordinates).index(f"{body}.{q}") for q in QUATERNION_NAMES)
                entry["angle"].append((f"{body}.yaw (from the quaternion)", quat))
        elif dof in ANGLE_NAMES:
            entry["angle"].append((name, j))
        else:
            entry["position"].append((name, j))
    return bodies


def _column(trajectory: np.ndarray, index) -> np.ndarray:
    if isinstance(index, tuple):  # a quaternion's yaw
        w, x, y, z = (trajectory[:, i] for i in index)
        return np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return trajectory[:, index]


def goal_intervals(predicate) -> dict[str, tuple[float, float]]:
    """The coordinate intervals of a goal predicate's boxes (inside all/any; not `not`)."""
    out: dict[str, tuple[float, float]] = {}
    box = getattr(predicate, "box", None)
    if box is not None:
        out.update({name: (float(lo), float(hi)) for name, (lo, hi) in box.items()})
    for child in getattr(predicate, "all", ()) or ():
        out.update(goal_intervals(child))
    for child in getattr(predicate, "any", ()) or ():
        out.update(goal_intervals(child))
    return out


def body_figure(scenario, runs, title: str):
    """One panel per moving body: its positions (m, left axis) and angles (rad, right axis)
    against time, each curve its own colour, line style and markers; the task's goal
    intervals shaded in the colour of their coordinate. Panels carry the label "body:NAME"."""
    plt = _pyplot()
    bodies = body_coordinates(scenario.coordinates)
    goal = goal_intervals(scenario.spec.task.goal)
    fig, axes = plt.subplots(len(bodies), 1, figsize=(9, 2.9 * len(bodies) + 0.6), sharex=True, squeeze=False)
    style = 0
    for ax, (body, groups) in zip(axes[:, 0], bodies.items()):
        ax.set_label(f"body:{body}")
        twin = ax.twinx() if groups["angle"] else None
        lines = []
        for kind, target in (("position", ax), ("angle", twin)):
            for name, index in groups[kind]:
                colour = f"C{style % 10}"
                for r, (label, times, X) in enumerate(runs):
                    k = style + r
                    n = max(len(times) // 12, 1)
                    line = target.plot(
                        times,
                        _column(X, index),
                        color=colour,
                        ls=LINE_STYLES[k % len(LINE_STYLES)],
                        marker=MARKERS[k % len(MARKERS)],
                        markevery=(k * n // 5 % n, n),  # markers staggered between curves
                        ms=4,
                        lw=1.3,
                        label=f"{label}: {name}" if len(runs) > 1 else name,
                    )
                    lines += line
                interval = goal.get(name)
                if interval is not None:
                    target.axhspan(*interval, color=colour, alpha=0.13)
                    lines.append(_band_handle(colour, f"goal: {name} in [{interval[0]:g}, {interval[1]:g}]"))
                style += 1
        for kind, target in (("position", ax), ("angle", twin)):
            if target is not None:
                _view_without_far_edges(target, [goal[name] for name, _ in groups[kind] if name in goal])
        ax.set_ylabel(f"{body}: position (m)")
        _least_span(ax, MIN_POSITION_SPAN)
        if twin is not None:
            twin.set_ylabel("angle (rad)")
            _least_span(twin, MIN_ANGLE_SPAN)
        ax.set_title(body, fontsize=9, loc="left")
        ax.grid(alpha=0.3)
        ax.legend(handles=lines, fontsize=7, loc="upper left", bbox_to_anchor=(1.13 if twin else 1.01, 1.0), borderaxespad=0)
    axes[-1, 0].set_xlabel("t (s)")
    fig.suptitle(_wrap(title, 90))
    fig.tight_layout()
    return fig


#: A goal interval's edge this many times further from 0 than the curves and the interval's other
#: edges (at least 1) stands for "no bound" (a one-sided goal, [0.5, 1e6]): not drawn to scale.
FAR_EDGE = 1e3


def _view_without_far_edges(ax, intervals: list[tuple[float, float]]) -> None:
    """The y axis over the curves and the goal intervals' edges, but for far ones (FAR_EDGE):
    a one-sided goal's sentinel had set the axis, the curves drawn flat along its bottom."""
    data = [np.asarray(line.get_ydata(), float) for line in ax.get_lines()]
    data = np.concatenate(data)[np.isfinite(np.concatenate(data))] if data else np.zeros(0)
    edges = [e for interval in intervals for e in interval]
    scale = max([1.0, *np.abs(data).tolist()])
    near = [e for e in edges if abs(e) < FAR_EDGE * scale]
    scale = max([scale, *np.abs(near).tolist()])
    near = [e for e in edges if abs(e) < FAR_EDGE * scale]
    if len(near) == len(edges) or not (len(data) or near):
        return  # (every edge to scale: matplotlib's own limits)
    values = np.concatenate([data, near])
    lo, hi = float(values.min()), float(values.max())
    pad = 0.05 * (hi - lo) or 0.05 * max(abs(lo), 1.0)  # (matplotlib's default margin)
    ax.set_ylim(lo - pad, hi + pad)


def _least_span(ax, span: float) -> None:
    """Widen a y axis to at least `span` around its middle: a coordinate that barely moves
    (round-off) is drawn flat, not magnified into noise."""
    lo, hi = ax.get_ylim()
    if hi - lo < span:
        mid = 0.5 * (lo + hi)
        ax.set_ylim(mid - span / 2, mid + span / 2)


def _band_handle(colour: str, label: str):
    from matplotlib.patches import Patch

    return Patch(color=colour, alpha=0.25, label=label)


# ----------------------------------------------------------------------------- feasible sets


def plot_feasible_sets(path: Path, result) -> Path:
    """The sweep's map: each grid point coloured by outcome (Z_F green, Z_U red, none grey),
    one panel per model; refined boundaries as black ticks. Two axes: a map over them; one
    axis: a strip. An axis of one value (`--grid mu=0.5`) is a fixed parameter, named in the
    panels' titles, not an axis. Writes PNG (and SVG when path ends in .png)."""
    plt = _pyplot()
    models = [m.label for m in result.models]
    varying = [a for a in result.axes if len(a.values) > 1] or list(result.axes[:1])
    fixed = ", ".join(f"{a.name} = {a.values[0]:g}" for a in result.axes if a not in varying)
    fig, panels = plt.subplots(1, len(models), figsize=(4.2 * len(models), 3.9), squeeze=False, sharey=True)
    x_axis = varying[0]
    y_axis = varying[1] if len(varying) > 1 else None
    for panel, model in zip(panels[0], models):
        for outcome, colour in OUTCOME_COLOURS.items():
            pts = [p for p in result.points if p is not None and p.model == model and p.outcome == outcome]
            more = [p for p in result.refine_points if p.model == model and p.outcome == outcome]  # (an outcome only they found too)
            label = f"{outcome} ({len(pts)}" + (f"; {len(more)} refining, small dots)" if more else ")")
            for runs, size, marker in ((pts, 14, "s"), (more, 5, "o")):
                xs = [p.parameters[x_axis.name] for p in runs]
                ys = [p.parameters[y_axis.name] if y_axis else 0.0 for p in runs]
                panel.scatter(xs, ys, s=size, color=colour, label=label if runs is pts else None, marker=marker)
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
        low, high = min(x_axis.values), max(x_axis.values)
        if x_axis.log:
            panel.set_xscale("log")
            log_ticks(panel.xaxis, low, high)
            # the grid's range, run or not: a model an interrupted sweep never reached has no point
            # to scale a log axis by (matplotlib had raised)
            if high > low:
                panel.set_xlim(low * (high / low) ** -0.04, high * (high / low) ** 0.04)
        else:  # (at most 5 labelled ticks: 0.3200 0.3225 ... had run into each other)
            from matplotlib.ticker import MaxNLocator

            panel.xaxis.set_major_locator(MaxNLocator(nbins=5))
            if high > low:
                panel.set_xlim(low - 0.04 * _span(x_axis), high + 0.04 * _span(x_axis))
        panel.set_xlabel(x_axis.name)
        panel.set_title(_wrap(model + (f" ({fixed})" if fixed else ""), 38), fontsize=8)
        if any(p is not None and p.model == model for p in result.points):
            panel.legend(fontsize=7, loc="best")
        else:
            panel.text(0.5, 0.5, "no run done", transform=panel.transAxes, ha="center", va="center", fontsize=9, color="0.4")
        if y_axis is None:  # a strip: its height means nothing
            panel.set_yticks([])
    panels[0][0].set_ylabel(y_axis.name if y_axis else "")
    title = f"{Path(result.file).stem}: goal (Z_F) and unsafe (Z_U) sets" + ("" if result.complete else " (INCOMPLETE)")
    fig.suptitle(_wrap(title, max(40, int(30 * len(models)))))
    fig.tight_layout()
    return _save(fig, path, svg=True)


def log_ticks(axis, low: float, high: float) -> list[float]:
    """Readable ticks on a log axis spanning [low, high]: 1-2-5 steps per decade (fewer when it
    spans many decades, more within one) and the range's ends, labelled as plain numbers.
    Returns the ticks."""
    from matplotlib.ticker import FixedLocator, FuncFormatter, NullFormatter

    low, high = sorted((float(low), float(high)))
    decades = math.log10(high / low) if low > 0 else 0.0
    steps = (1, 2, 5) if decades <= 3 else (1,)
    if decades < 1:
        steps = (1, 1.5, 2, 3, 4, 5, 7)
    ticks = [
        m * 10.0**e
        for e in range(math.floor(math.log10(low)) - 1, math.ceil(math.log10(high)) + 1)
        for m in steps
        if low * (1 - 1e-9) <= m * 10.0**e <= high * (1 + 1e-9)
    ]
    for end in (low, high):  # the range's ends, unless a tick sits nearly there
        if low > 0 and all(abs(math.log10(end / t)) > 0.12 * max(decades, 1) for t in ticks):
            ticks.append(end)
    ticks.sort()
    axis.set_major_locator(FixedLocator(ticks))
    axis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    axis.set_minor_formatter(NullFormatter())
    return ticks


def _span(axis) -> float:
    if axis is None:
        return 1.0
    return (max(axis.values) - min(axis.values)) or 1.0


def plot_feasible_sets_3d(path: Path, panels: list[tuple[str, list[dict], list[dict]]], title: str) -> Path:
    """Fig. 5 in the paper's axes: per model a 3D panel over (finger speed 1, finger speed 2,
    mu). panels: [(model title, points, boundaries)] with points {v1, v2, mu, outcome} (every
    run, coloured as its set: Z_F green, Z_U red) and boundaries {v1, v2, mu, side} (refined
    edges of Z_F along finger speed 1, side "low" or "high"), drawn as the green surfaces
    through them, each boundary point as a black dot."""
    plt = _pyplot()
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    fig = plt.figure(figsize=(12, 11))
    for k, (label, points, boundaries) in enumerate(panels):
        ax = fig.add_subplot(2, (len(panels) + 1) // 2, k + 1, projection="3d")
        for outcome, colour in OUTCOME_COLOURS.items():
            mine = [p for p in points if p["outcome"] == outcome]
            if mine:
                ax.scatter(*(np.array([p[c] for p in mine]) for c in ("v1", "v2", "mu")), color=colour, s=5, alpha=0.45, depthshade=False)
        for side in ("low", "high"):
            mine = [b for b in boundaries if b["side"] == side]
            if len({b["v2"] for b in mine}) >= 2 and len({b["mu"] for b in mine}) >= 2:
                _boundary_surface(ax, mine)
            if mine:
                ax.scatter(*(np.array([b[c] for b in mine]) for c in ("v1", "v2", "mu")), color="k", s=8, depthshade=False)
        ax.set_xlabel("finger speed 1 (m/s)")
        ax.set_ylabel("finger speed 2 (m/s)")
        ax.set_zlabel("mu")
        ax.set_title(_wrap(label, 45), fontsize=9)
        ax.view_init(elev=24, azim=-120)
    handles = [
        Line2D([], [], color=OUTCOME_COLOURS["goal"], marker="o", ls="none", label=f"run in {OUTCOME_SETS['goal']}"),
        Line2D([], [], color=OUTCOME_COLOURS["unsafe"], marker="o", ls="none", label=f"run in {OUTCOME_SETS['unsafe']}"),
        Patch(color="tab:green", alpha=0.35, label="boundary of Z_F (refined; surface through the black dots)"),
    ]
    fig.legend(handles=handles, loc="lower center", ncol=3, fontsize=8, frameon=False)
    fig.suptitle(_wrap(title, 110))
    fig.tight_layout(rect=(0, 0.04, 1, 1))
    return _save(fig, path, svg=True)


def _boundary_surface(ax, boundaries: list[dict]) -> None:
    """The surface v1 = edge(v2, mu) through refined boundary points on a (v2, mu) grid."""
    v2s = sorted({b["v2"] for b in boundaries})
    mus = sorted({b["mu"] for b in boundaries})
    at = {(b["v2"], b["mu"]): b["v1"] for b in boundaries}
    V1 = np.array([[at.get((v2, mu), np.nan) for v2 in v2s] for mu in mus])
    V2, MU = np.meshgrid(v2s, mus)
    ax.plot_surface(np.ma.masked_invalid(V1), V2, MU, color="tab:green", alpha=0.3, shade=False, linewidth=0.5, edgecolor="darkgreen")


# ----------------------------------------------------------------------------- Fig. 4


def plot_fan(path: Path, panels: list[tuple[str, list[tuple[float, str, np.ndarray]]]], scenario, title: str) -> Path:
    """Fig. 4 as the paper draws it: per model a 3D panel of C-space (x1, x2, x3) with
    C_free's boundary and the goal edge (`draw_cspace`) and the trajectories of a fan of speed
    ratios, clipped to the axes, coloured by how each ended (solid: grasp; dotted: not), start
    and ends marked. panels: [(model title, [(ratio, outcome label, trajectory)])]."""
    from matplotlib.lines import Line2D

    from planner.cspace import two_finger_cspace

    plt = _pyplot()
    space = two_finger_cspace(scenario)
    fig = plt.figure(figsize=(12, 11.5))
    handles = []
    for k, (label, runs) in enumerate(panels):
        ax = fig.add_subplot(2, (len(panels) + 1) // 2, k + 1, projection="3d")
        handles = draw_cspace(ax, space)
        for _ratio, outcome, X in runs:
            P = paper_coordinates(scenario.coordinates, scenario.start, X)
            _draw_paper_run(ax, P, space, OUTCOME_COLOURS[outcome], "-" if outcome == "goal" else ":")
        ax.scatter([0], [0], [0], color="k", marker="*", s=90, depthshade=False)
        ax.set_title(_wrap(label, 45), fontsize=10)
    handles += [
        Line2D([], [], color=OUTCOME_COLOURS["goal"], label="run that grasps"),
        Line2D([], [], color=OUTCOME_COLOURS["unsafe"], ls=":", label="run whose triangle slips out"),
        *_end_handles(),
    ]
    fig.legend(handles=handles, loc="lower center", ncol=2, fontsize=8, frameon=False)
    fig.suptitle(_wrap(title, 110))
    fig.tight_layout(rect=(0, 0.1, 1, 1))
    return _save(fig, path, svg=True)


# ----------------------------------------------------------------------------- point labels

#: Offsets (points) tried in turn for a point's label, nearest first.
LABEL_OFFSETS = ((5, 4), (5, -11), (-8, 6), (-8, -13), (5, 14), (5, -21), (-8, 16), (-8, -23))


def label_points(ax, points, texts, fontsize: float = 6.5) -> list:
    """Label data points without overlap: each label takes the first offset (LABEL_OFFSETS)
    where it overlaps no label placed before; a label whose text is already shown where it
    would overlap (the same step of a coinciding curve) is left out, as is one with no free
    offset inside the axes. Call after the axes' limits are final. Returns the annotations placed."""
    fig = ax.figure
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    frame = ax.get_window_extent(renderer)
    placed: list = []
    boxes: list = []
    for (x, y), text in zip(points, texts):
        for dx, dy in LABEL_OFFSETS:
            note = ax.annotate(
                text, (x, y), xytext=(dx, dy), textcoords="offset points", fontsize=fontsize, color="0.2", ha="left" if dx >= 0 else "right"
            )
            box = note.get_window_extent(renderer)
            clash = [k for k, other in enumerate(boxes) if box.overlaps(other)]
            inside = frame.x0 <= box.x0 and box.x1 <= frame.x1 and frame.y0 <= box.y0 and box.y1 <= frame.y1
            if not clash and inside:
                placed.append(note)
                boxes.append(box)
                break
            note.remove()
            if any(placed[k].get_text() == text for k in clash):
                break  # this step is labelled right there already
    return placed
