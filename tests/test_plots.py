"""The plots' structure: Fig. 4's C-space geometry against the scene's own distances, one
panel per body with the goal drawn, readable log ticks, labels that do not overlap."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from models import geometry as geo
from models.scenario import load_scenario
from planner import plots
from planner.cspace import two_finger_cspace, upper_envelope

SCENARIOS = Path(__file__).resolve().parent.parent / "scenarios"
TRIANGLE = SCENARIOS / "two_finger_triangle.toml"


def _q(scenario, x1, x2, x3):
    """The scenario's q at paper coordinates (x1, x2, x3)."""
    q = np.array(scenario.start, float)
    c = list(scenario.coordinates)
    q[c.index("finger1.y")] -= x1
    q[c.index("finger2.y")] -= x2
    q[c.index("triangle.x")] = x3
    return q


def _distance(scenario, q, finger):
    place = scenario.placements(q)
    return geo.signed_distance(scenario.geometries[finger], place[finger], scenario.geometries["triangle"], place["triangle"])


def _scene_with_radius(tmp_path, r):
    """The paper's scene with finger discs of radius r, started 2 above the palm."""
    text = TRIANGLE.read_text()
    text = text.replace("radius = 0.05", f"radius = {r}").replace("y = 2.05", f"y = {2 + r}")
    text = text.replace("lower = 0.05, upper = 2.05", f"lower = {r}, upper = {2 + r}")
    path = tmp_path / "scene.toml"
    path.write_text(text)
    return load_scenario(path)


def test_goal_edge_touches_both_faces():
    scenario = load_scenario(TRIANGLE)
    edge = two_finger_cspace(scenario).goal_edge
    assert edge is not None and edge.shape == (2, 3)
    for s in np.linspace(0, 1, 5):  # endpoints and points between
        x1, x2, x3 = (1 - s) * edge[0] + s * edge[1]
        q = _q(scenario, x1, x2, x3)
        assert abs(_distance(scenario, q, "finger1")) < 1e-9
        assert abs(_distance(scenario, q, "finger2")) < 1e-9
    # our discs: the edge ends where a contact point reaches the peak, |x3| = 0.5 - r / sqrt 2
    assert edge[:, 2] == pytest.approx([-(0.5 - 0.05 / np.sqrt(2)), 0.5 - 0.05 / np.sqrt(2)])


def test_goal_edge_follows_the_disc_radius(tmp_path):
    # point-like fingers give the paper's edge (1, 2, -0.5) .. (2, 1, 0.5); larger discs move it
    small = two_finger_cspace(_scene_with_radius(tmp_path, 1e-4)).goal_edge
    assert small == pytest.approx(np.array([[1, 2, -0.5], [2, 1, 0.5]]), abs=1e-3)
    big_scene = _scene_with_radius(tmp_path, 0.2)
    big = two_finger_cspace(big_scene).goal_edge
    assert big[0, 0] == pytest.approx(2 - 1.5 + 0.2 - 0.2 * np.sqrt(2) + big[0, 2] + 1.0, abs=1e-9)
    for x1, x2, x3 in big:
        q = _q(big_scene, x1, x2, x3)
        assert abs(_distance(big_scene, q, "finger1")) < 1e-9 and abs(_distance(big_scene, q, "finger2")) < 1e-9


def test_free_boundary_is_contact_or_limit():
    scenario = load_scenario(TRIANGLE)
    space = two_finger_cspace(scenario)
    assert len(space.strata) == 4
    for x3 in np.linspace(-1.5, 1.5, 61):
        for finger, name in ((0, "finger1"), (1, "finger2")):
            depth = float(space.depth_bound(finger, x3))
            q = _q(scenario, depth if finger == 0 else 0.0, depth if finger == 1 else 0.0, x3)
            d = _distance(scenario, q, name)
            # on the boundary: touching the triangle, or at the drive's limit and clear of it
            assert d > -1e-9
            assert abs(d) < 1e-9 or depth == pytest.approx(space.depth_limit[finger])
    for s in space.strata:  # every facet is a finger-face contact
        for x3 in np.linspace(s.x3_low, s.x3_high, 7):
            depth = float(s.depth(x3))
            q = _q(scenario, depth if s.finger == 0 else 0.0, depth if s.finger == 1 else 0.0, x3)
            assert abs(_distance(scenario, q, f"finger{s.finger + 1}")) < 1e-9


def test_envelope_of_a_square():
    square = np.array([[-1.0, 0.0], [1.0, 0.0], [1.0, 1.0], [-1.0, 1.0]])
    top = upper_envelope(square, 0.5, np.array([0.0, 1.2, 1.5, 2.0]))
    assert top == pytest.approx([1.5, 1.0 + np.sqrt(0.25 - 0.04), 1.0, -np.inf])


def test_cspace_refuses_other_scenes():
    with pytest.raises(ValueError, match="not a two-finger scene"):
        two_finger_cspace(load_scenario(SCENARIOS / "four_finger_grasp.toml"))


def _still_runs(scenario, n=50):
    times = np.linspace(0, 1, n)
    X = np.tile(scenario.start, (n, 1))
    X[:, 0] += 0.1 * times
    return [("test", times, X)]


@pytest.mark.parametrize("name", ["box_push_3d.toml", "box_rotate_3d.toml", "four_finger_grasp.toml"])
def test_one_panel_per_body_with_the_goal(name):
    scenario = load_scenario(SCENARIOS / name)
    fig = plots.rollout_figure(scenario, _still_runs(scenario), "t")
    try:
        panels = [ax for ax in fig.axes if ax.get_label().startswith("body:")]
        moving = list(dict.fromkeys(c.split(".")[0] for c in scenario.coordinates))
        assert [ax.get_label() for ax in panels] == [f"body:{b}" for b in moving]
        goal = plots.goal_intervals(scenario.spec.task.goal)
        assert goal
        legend_text = " ".join(t.get_text() for ax in panels for t in ax.get_legend().get_texts())
        for coordinate in goal:
            assert f"goal: {coordinate} in" in legend_text
        # every curve has its own (line style, marker) within a panel
        for ax in fig.axes:
            styles = [(line.get_linestyle(), line.get_marker()) for line in ax.get_lines()]
            assert len(styles) == len(set(styles))
    finally:
        import matplotlib.pyplot as plt

        plt.close(fig)


def test_quaternion_yaw():
    yaw = 0.7
    q = geo.rpy_quaternion(0.0, 0.0, yaw)
    assert plots._column(np.array([q]), (0, 1, 2, 3))[0] == pytest.approx(yaw)
    bodies = plots.body_coordinates(("box.x", "box.qw", "box.qx", "box.qy", "box.qz", "pusher.x"))
    assert bodies["box"]["angle"] == [("box.yaw (from the quaternion)", (1, 2, 3, 4))]
    assert bodies["pusher"] == {"position": [("pusher.x", 5)], "angle": []}


def test_log_ticks_are_readable():
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots()
    ax.set_xscale("log")
    ticks = plots.log_ticks(ax.xaxis, 0.25, 4)
    assert len(ticks) >= 4 and min(ticks) >= 0.25 and max(ticks) <= 4
    assert [ax.xaxis.get_major_formatter()(t, 0) for t in (0.5, 1, 2)] == ["0.5", "1", "2"]
    plt.close(fig)


def test_point_labels_do_not_overlap():
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(4, 3))
    x = np.geomspace(1e-3, 1e-1, 4)
    points = [(xi, 1e-3 * (1 + 0.01 * k)) for k in range(4) for xi in x]  # four coinciding curves
    texts = [f"h={h:g}" for _ in range(4) for h in (1e-2, 1e-3, 1e-4, 1e-5)]
    ax.loglog(*zip(*points), "o")
    placed = plots.label_points(ax, points, texts)
    renderer = fig.canvas.get_renderer()
    boxes = [n.get_window_extent(renderer) for n in placed]
    assert sorted({n.get_text() for n in placed}) == sorted(set(texts))  # each step labelled
    assert not any(a.overlaps(b) for i, a in enumerate(boxes) for b in boxes[i + 1 :])
    plt.close(fig)


def test_paper_figures_write(tmp_path):
    scenario = load_scenario(TRIANGLE)
    runs = _still_runs(scenario, 20)
    X = runs[0][2].copy()
    X[:, 0] = np.linspace(0, 3, 20)  # the triangle leaves the axes: clipped
    out = plots.plot_fan(tmp_path / "fig4.png", [("(a)", [(1.0, "goal", runs[0][2]), (2.0, "unsafe", X)])], scenario, "t")
    assert out.exists() and out.with_suffix(".svg").exists()
    space = two_finger_cspace(scenario)
    P, left = plots.clip_to_window(plots.paper_coordinates(scenario.coordinates, scenario.start, X), space)
    assert left and np.isnan(P[-1]).all() and np.isfinite(P[0]).all()
    points = [{"v1": v1, "v2": v2, "mu": mu, "outcome": "goal"} for v1 in (0.5, 1) for v2 in (0.5, 1) for mu in (0.3, 0.5)]
    bounds = [{"v1": 0.5 * v2, "v2": v2, "mu": mu, "side": "low"} for v2 in (0.5, 1) for mu in (0.3, 0.5)]
    out = plots.plot_feasible_sets_3d(tmp_path / "fig5.png", [("(a)", points, bounds)], "t")
    assert out.exists()


def test_a_one_sided_goal_does_not_set_the_axis(tmp_path):
    """A goal interval with an edge standing for "no bound" ([0.55, 1e6]: scenario values are
    within +-1e6) had set the panel's y axis to 1e6, the curves flat along its bottom; the axis
    now spans the curves and the goal's near edge, and a goal to scale still sets it."""
    import shutil

    import matplotlib.pyplot as plt

    shutil.copytree(SCENARIOS / "meshes", tmp_path / "meshes")
    text = (SCENARIOS / "box_push_3d.toml").read_text()
    old = 'goal = { box = { "box.x" = [0.55, 0.75], "box.y" = [-0.1, 0.1] } }'
    assert old in text
    for interval, top in (("[0.55, 1e6]", (0.55, 0.7)), ("[0.55, 0.75]", (0.75, 0.9)), ("[-1e6, 1e6]", (0.1, 0.2))):
        path = tmp_path / "one_sided.toml"
        path.write_text(text.replace(old, f'goal = {{ box = {{ "box.x" = {interval}, "box.y" = [-0.1, 0.1] }} }}'))
        scenario = load_scenario(path)
        fig = plots.rollout_figure(scenario, _still_runs(scenario), "t")
        try:
            box = next(ax for ax in fig.axes if ax.get_label() == "body:box")
            data = np.concatenate([line.get_ydata() for line in box.get_lines()])
            lo, hi = box.get_ylim()
            assert lo <= data.min() and hi >= data.max(), interval
            assert top[0] <= hi <= top[1], (interval, hi)
        finally:
            plt.close(fig)


def test_the_paper_figure_draws_the_files_goal_not_the_papers(tmp_path):
    """The Fig. 4 plot of a two-finger scene had shaded triangle.x in [-0.5, 0.5], the paper's
    goal box, whatever the file's goal said, and drawn the whole form-closure edge as the goal:
    both are the file's goal now (its interval of triangle.x; the edge cut to it)."""
    import matplotlib.pyplot as plt

    text = TRIANGLE.read_text()
    old = '{ box = { "triangle.x" = [-0.5, 0.5] } }'
    assert old in text
    shipped = load_scenario(TRIANGLE)
    whole = two_finger_cspace(shipped).goal_edge
    for interval, edge_x3 in (("[0.1, 0.4]", (0.1, 0.4)), ("[-0.5, 0.5]", tuple(whole[:, 2])), ("[0.6, 0.9]", None)):
        path = tmp_path / "goal.toml"
        path.write_text(text.replace(old, f'{{ box = {{ "triangle.x" = {interval} }} }}'))
        scenario = load_scenario(path)
        fig = plots.rollout_figure(scenario, _still_runs(scenario), "t")
        try:
            flat = next(ax for ax in fig.axes if ax.name != "3d")
            lo, hi = (float(v) for v in interval.strip("[]").split(","))
            spans = [p for p in flat.patches if p.get_label().startswith("goal: triangle.x in")]
            assert [p.get_label() for p in spans] == [f"goal: triangle.x in [{lo:g}, {hi:g}]"]
            extent = spans[0].get_transform().transform(spans[0].get_path().vertices)  # (display units)
            back = flat.transData.inverted().transform(extent)[:, 1]
            assert (back.min(), back.max()) == pytest.approx((lo, hi))
            space = plots._goal_edge_within(two_finger_cspace(scenario), (lo, hi))
            if edge_x3 is None:
                assert space.goal_edge is None
            else:
                assert tuple(space.goal_edge[:, 2]) == pytest.approx(edge_x3)
                # the cut edge lies on the whole edge: both fingers still on their faces
                for point in space.goal_edge:
                    q = _q(scenario, *point)
                    assert _distance(scenario, q, "finger1") == pytest.approx(0.0, abs=1e-9)
                    assert _distance(scenario, q, "finger2") == pytest.approx(0.0, abs=1e-9)
        finally:
            plt.close(fig)


def test_a_two_finger_scene_with_other_bodies_or_coordinates_is_drawn_per_body(tmp_path):
    """A wall beside the triangle, or the triangle free in y, bounds or changes C-space in ways
    the paper's figure does not know: such a scene had been drawn with the paper's facets alone."""
    import matplotlib.pyplot as plt

    text = TRIANGLE.read_text()
    wall = text + '\n[[bodies]]\nname = "wall"\nrole = "obstacle"\nshape = { type = "halfplane", normal = [1.0, 0.0], offset = -1.3 }\n'
    assert 'dofs = ["x"]' in text
    free_y = text.replace('dofs = ["x"]', 'dofs = ["x", "y"]', 1)
    for name, variant, said in (("wall", wall, "other bodies wall"), ("free_y", free_y, "other coordinates triangle.y")):
        path = tmp_path / f"{name}.toml"
        path.write_text(variant)
        scenario = load_scenario(path)
        with pytest.raises(ValueError, match=f"not a two-finger scene: {said}"):
            two_finger_cspace(scenario)
        fig = plots.rollout_figure(scenario, _still_runs(scenario), "t")
        try:
            assert any(ax.get_label() == "body:triangle" for ax in fig.axes)
        finally:
            plt.close(fig)
    assert two_finger_cspace(load_scenario(TRIANGLE)).goal_edge is not None  # the palm, a floor, is the scene's own
