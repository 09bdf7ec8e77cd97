"""Object paths carry upward: the geometric rung's path of a pushed object, turned into a
pushing reference that the first physics rung tracks (`planner.tracking`).

The geometric rung plans where the object goes (its position and its turn about the vertical)
and moves the robot on its own, so its robot path is no pushing plan. Here the robot's path is
made from the object's: the pusher rides at the object's boundary behind its direction of
travel, off the object's centre line by the offset that turns it at the path's rate, after an
approach around the object to the first push point. The object moves along its path at a
fraction of the pusher's speed limit. Tracking then corrects the pushes per control period
against the object's path (the pose error counts only the passive bodies) and repairs locally
where it is lost.

The offset for a turn is the quasistatic pushing rule of a sticking point push on a body with
a circular limit surface of radius c (Lynch and Mason, "Stable pushing", 1996): a push at
offset o from the centre line turns the body at o / (c^2 + o^2) rad per metre travelled, at
most 1 / (2 c), at o = c. For c the reference takes the mean distance from the centre of a
disc of the body's footprint area under uniform pressure (2/3 of its radius): a gain more
than a measurement, since a box on a plane rests on its four corners (c = their distance,
0.14 m for box_rotate_3d's box, against 0.075 m) and turns as that predicts when pushed open
loop along the reference; tracked, the smaller c reaches the goal far more often (the
geometric path turns faster than a push can, and the larger offsets of the smaller c catch
up). Measured: docs/measurements.md, "Object paths".

A pusher behind a face pushes the object along the face's normal unless its push lies within
the friction cone of the pair: a box pushed at 35 degrees to its faces with mu = 0.2 (a cone of
11 degrees) goes along the face's normal, off the path. Where the goal leaves the object's turn
free, so that its faces keep their directions, a stretch of the path outside the cone becomes
legs along the face normals first (`pushable_path`).

A scene is a pushing scene when it has one object whose x and y are coordinates and one robot
whose x and y are both actuated; elsewhere `push_reference` returns None and the ladder plans
as before.
"""

from __future__ import annotations

import numpy as np

from models.rungs import GeometricChecker, compiled
from models.scenario import Scenario
from planner.ompl_adapter import goal_coordinates, sampling_limits
from planner.tracking import Reference

#: The object's speed along its path, as a fraction of the pusher's smaller speed limit: slow
#: enough that the pusher can correct sideways within its limit (box_rotate_3d, 10 seeds:
#: 0.1, 0.2 and 0.3 of 0.5 m/s reached the goal by tracking in 7, 7 and 8; docs/measurements.md).
PUSH_SPEED = 0.3
#: The pusher's speed on its approach to the first push point, as a fraction of its speed limit.
APPROACH_SPEED = 0.8
#: Clearance from the object's bounding circle on the approach around it, m.
APPROACH_CLEARANCE = 0.02
#: An approach whose bearing from the object's centre turns by more than this goes around the
#: object on a circle, rad; a smaller one goes straight.
AROUND = 0.5
#: Where the push point moves by more than this many times the object's advance in a control
#: period (a corner of the path), the pusher leaves the object and goes to it as on its approach.
REPOSITION = 2.0
#: The largest push offset, as a fraction of the object's half-width across the push.
OFFSET_REACH = 0.8
#: A stretch of the object's path is pushed as it is while its heading is within this share of
#: the pusher's friction cone (atan mu of the pair) of a face's normal; further from every one,
#: a pusher behind it would press a face outside its cone, slide along it, and the object would
#: go along the face's normal instead of the path. Such a stretch becomes legs along the face
#: normals (`pushable_path`). Measured: docs/measurements.md, "Pushing a box past a post".
CONE_SHARE = 0.8
#: The legs keep the object this far (m) from what it may not touch or pass through: each leg is
#: checked also moved this far to either side (tracking lets the object drift TRACK_TOLERANCE).
LEG_CLEARANCE = 0.03
#: Where the legs are checked along them, m.
LEG_STEP = 0.01
#: A stretch that neither two legs nor three (the middle one at a level scanned in LEG_STEP
#: steps) replace is halved, at most this many times; else it stays as it is.
LEG_SPLITS = 3
#: The robot's offset (m, along x and y) while the legs are checked: out of every body's reach.
FAR = 1e3


class _Footprint:
    """What pushing needs of a body's shape, from the compiled scene: its support distance along
    a direction of its own plane, and its limit-surface radius."""

    def __init__(self, scenario: Scenario, name: str):
        scene = compiled(scenario).scene
        i = [b.name for b in scenario.spec.bodies].index(name)
        start, count = int(scene.vstart[i]), int(scene.vcount[i])
        self.points = np.asarray(scene.verts[start : start + count], float).reshape(count, -1)[:, :2]
        self.radius = float(scene.radius[i])
        self.limit_radius = 2.0 / 3.0 * np.sqrt(self._hull() / np.pi)

    def _hull(self) -> float:
        """Footprint area (the convex hull of the vertices in the plane, swept by the radius);
        keeps the hull's outward face normals as angles in the body frame (`normals`, none for
        a point or a segment)."""
        from scipy.spatial import ConvexHull, QhullError

        p, r = self.points, self.radius
        try:
            hull = ConvexHull(p)
            area, perimeter = float(hull.volume), float(hull.area)  # in the plane: area, perimeter
            self.normals = np.arctan2(hull.equations[:, 1], hull.equations[:, 0])
        except (QhullError, ValueError):  # a point or a segment (fewer than 3 points, or collinear)
            area, perimeter = 0.0, 2.0 * float(np.ptp(p, axis=0).max(initial=0.0)) if len(p) else 0.0
            self.normals = np.zeros(0)
        return area + perimeter * r + np.pi * r * r

    def support(self, direction: np.ndarray) -> float:
        """How far the body reaches from its centre along `direction` (unit, body frame)."""
        return float(np.max(self.points @ direction, initial=0.0)) + self.radius


def _turn_coordinate(scenario: Scenario, body: str) -> str | None:
    """The body's coordinate of turn about the vertical (yaw in space, theta in the plane), or None."""
    return next((f"{body}.{c}" for c in ("yaw", "theta") if f"{body}.{c}" in scenario.coordinates), None)


def _yaw(scenario: Scenario, q: np.ndarray, body: str) -> float | None:
    """The body's turn about the vertical at q: its yaw or theta coordinate, or the yaw of its
    orientation quaternion; None when it has none."""
    names = scenario.coordinates
    turn = _turn_coordinate(scenario, body)
    if turn is not None:
        return float(q[names.index(turn)])
    if f"{body}.qw" in names:
        w, x, y, z = (float(q[names.index(f"{body}.{c}")]) for c in ("qw", "qx", "qy", "qz"))
        return float(np.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z)))
    return None


def pushing_pair(scenario: Scenario) -> tuple[str, str] | None:
    """(object, robot) of a pushing scene (see the module docstring), else None."""
    names, actuated = scenario.coordinates, set(scenario.actuated)
    objects = [b.name for b in scenario.spec.bodies if b.role == "object" and f"{b.name}.x" in names and f"{b.name}.y" in names]
    robots = [b.name for b in scenario.spec.bodies if b.role == "robot"]
    if len(objects) != 1 or len(robots) != 1 or not {f"{robots[0]}.x", f"{robots[0]}.y"} <= actuated:
        return None
    return objects[0], robots[0]


def free_turn(scenario: Scenario) -> tuple[str, ...]:
    """The pushed object's turn coordinate (yaw, theta) when the goal leaves it free, which the
    reference does not plan (it pushes straight) and tracking does not measure; else ()."""
    pair = pushing_pair(scenario)
    if pair is None:
        return ()
    turn = _turn_coordinate(scenario, pair[0])
    return () if turn is None or turn in goal_coordinates(scenario) else (turn,)


def push_reference(scenario: Scenario, path, q0: np.ndarray, period: float) -> Reference | None:
    """The pushing reference along the geometric rung's path (configurations `path`) from the
    rung's start configuration q0, per control period; None when the scene is no pushing scene
    or the path does not move the object."""
    pair = pushing_pair(scenario)
    if pair is None:
        return None
    obj, robot = pair
    names = scenario.coordinates
    ox, oy = names.index(f"{obj}.x"), names.index(f"{obj}.y")
    rx, ry = names.index(f"{robot}.x"), names.index(f"{robot}.y")
    turn = _turn_coordinate(scenario, obj)
    turn = None if turn is None else names.index(turn)
    shape, pusher = _Footprint(scenario, obj), _Footprint(scenario, robot)
    c = shape.limit_radius
    path = np.asarray(path, float)
    xy = path[:, [ox, oy]]
    # a turn the goal does not ask for is one the geometric path takes at random: pushed straight
    free = turn is None or names[turn] in free_turn(scenario)
    if free:  # (the object keeps its start's turn: its faces' normals are fixed)
        legs = pushable_path(scenario, xy, q0)
        if legs is not None:
            xy, path = legs, np.repeat(path[-1:], len(legs), axis=0)
    yaw = np.full(len(path), _yaw(scenario, q0, obj) or 0.0) if free else path[:, turn]
    # arc length: the object's travel, or its turn times c where it turns more than it moves
    arc = np.concatenate([[0.0], np.cumsum(np.maximum(np.hypot(*np.diff(xy, axis=0).T), c * np.abs(np.diff(yaw))))])
    if arc[-1] <= 1e-9:
        return None
    speeds = np.array([scenario.drive(n).max_speed for n in (f"{robot}.x", f"{robot}.y")])
    # evenly along the path, and through its vertices (a corner is where the push turns)
    s = np.unique(np.concatenate([np.linspace(0.0, arc[-1], int(np.ceil(arc[-1] / (PUSH_SPEED * speeds.min() * period))) + 1), arc]))
    n = len(s)
    xy = np.column_stack([np.interp(s, arc, xy[:, 0]), np.interp(s, arc, xy[:, 1])])
    yaw = np.interp(s, arc, yaw)
    # where the pusher is at each pose: leading into the push that follows it (measured: box_push_3d,
    # seeds 1-20, 0.56 s median against 1.15 s behind the push that brought the object there),
    # and at a corner (the two far apart) first behind the push into it, then round to the next
    ahead = _push_points(shape, pusher.radius, xy, yaw, c, lead=True)
    behind = _push_points(shape, pusher.radius, xy, yaw, c, lead=False)
    drives = [list(scenario.actuated).index(f"{robot}.{c}") for c in ("x", "y")]
    reference = _Builder(q0, (ox, oy), turn, (rx, ry), drives, len(scenario.actuated), period)
    approach = APPROACH_SPEED * speeds.min()
    for p in _approach(q0[[rx, ry]], ahead[0], xy[0], shape, pusher.radius):
        reference.move(p, xy[0], yaw[0], approach)
    advance = PUSH_SPEED * speeds.min() * period
    for k in range(1, n):
        if np.hypot(*(ahead[k] - behind[k])) > REPOSITION * advance:  # a corner: round the object
            reference.move(behind[k], xy[k], yaw[k], np.inf)
            for p in _approach(reference.at, ahead[k], xy[k], shape, pusher.radius):
                reference.move(p, xy[k], yaw[k], approach)
        else:
            reference.move(ahead[k], xy[k], yaw[k], np.inf)
    return reference.done()


def _push_points(shape: _Footprint, r: float, xy: np.ndarray, yaw: np.ndarray, c: float, lead: bool) -> np.ndarray:
    """Where the pusher's centre is at each of the object's poses: at the object's boundary
    behind the push from that pose to the next (`lead`; else the push that brought it there),
    off the centre line by the offset that turns it at that push's rate (the module docstring)."""
    points, heading = [], np.array([1.0, 0.0])
    for k in range(len(xy)):
        j = min(k, len(xy) - 2) if lead else max(k - 1, 0)
        step = xy[j + 1] - xy[j]
        length = float(np.hypot(*step))
        if length > 1e-9:
            heading = step / length
        rate = (yaw[j + 1] - yaw[j]) / max(length, 1e-9)
        cos, sin = np.cos(yaw[k]), np.sin(yaw[k])
        local = np.array([cos * heading[0] + sin * heading[1], -sin * heading[0] + cos * heading[1]])  # in the body frame
        across = np.array([-local[1], local[0]])
        width = OFFSET_REACH * min(shape.support(across), shape.support(-across))
        bend = min(abs(rate), (1.0 - 1e-9) / (2.0 * c))
        offset = (1.0 - np.sqrt(1.0 - 4.0 * bend * bend * c * c)) / (2.0 * bend) if bend > 1e-9 else 0.0
        # a push at +offset (to the left of the travel) turns the object clockwise
        offset = -np.sign(rate) * min(offset, width)
        side = np.array([-heading[1], heading[0]])
        points.append(xy[k] - (shape.support(-local) + r) * heading + offset * side)
    return np.array(points)


def _approach(start: np.ndarray, first: np.ndarray, centre: np.ndarray, shape: _Footprint, r: float) -> list[np.ndarray]:
    """Waypoints from the pusher's start to the first push point: straight when the bearing
    from the object's centre changes little (AROUND), else around the object on a circle clear
    of it first."""
    bearing = lambda p: float(np.arctan2(p[1] - centre[1], p[0] - centre[0]))  # noqa: E731
    a0 = bearing(start)
    turn = (bearing(first) - a0 + np.pi) % (2.0 * np.pi) - np.pi
    points = []
    if abs(turn) > AROUND:
        clear = float(np.max(np.hypot(*shape.points.T), initial=0.0)) + shape.radius + r + APPROACH_CLEARANCE
        reach = max(clear, float(np.hypot(*(start - centre))))
        for t in np.linspace(0.0, 1.0, int(np.ceil(abs(turn) / 0.2)) + 1)[1:]:
            points.append(centre + reach * np.array([np.cos(a0 + t * turn), np.sin(a0 + t * turn)]))
    points.append(first)
    return points


class _Builder:
    """The reference, one control period at a time: configurations at the period boundaries
    (the object where the path has it, the pusher where it is commanded) and the pusher's
    commanded speeds between them."""

    def __init__(self, q0: np.ndarray, obj, turn: int | None, robot, drives: list[int], na: int, period: float):
        self.q = [np.array(q0, float)]
        self.controls: list[np.ndarray] = []
        self.obj, self.turn, self.robot, self.drives, self.na, self.period = list(obj), turn, list(robot), drives, na, period
        self.at = self.q[0][self.robot].copy()

    def move(self, point: np.ndarray, xy: np.ndarray, yaw: float, speed: float) -> None:
        """The pusher to `point` at most at `speed` (in whole periods, at least one), the
        object at (xy, yaw) at the end."""
        periods = max(1, int(np.ceil(np.hypot(*(point - self.at)) / (speed * self.period) - 1e-9))) if np.isfinite(speed) else 1
        for k in range(1, periods + 1):
            q = self.q[-1].copy()
            q[self.robot] = self.at + (point - self.at) * (k / periods)
            q[self.obj] = xy
            if self.turn is not None:
                q[self.turn] = yaw
            self.q.append(q)
            u = np.zeros(self.na)
            u[self.drives] = (point - self.at) / (periods * self.period)
            self.controls.append(u)
        self.at = np.array(point, float)

    def done(self) -> Reference:
        return Reference(np.arange(len(self.q)) * self.period, np.array(self.q), np.array(self.controls))


def _rectangle_frame(shape: _Footprint) -> float | None:
    """The angle (body frame) of one of the footprint's face normals when every face normal is
    one of the four axes of that frame (a rectangle: its legs run along them), else None."""
    angles = shape.normals
    if not len(angles):  # a point or a segment: no faces
        return None
    quarter = np.mod(angles - angles[0] + np.pi / 4, np.pi / 2) - np.pi / 4
    return float(angles[0]) if np.all(np.abs(quarter) < 1e-6) else None


def pushable_path(scenario: Scenario, xy: np.ndarray, q0: np.ndarray) -> np.ndarray | None:
    """The pushed object's path (its positions `xy` along the geometric path, from q0) as
    pushes along its faces' normals: each straight stretch whose heading is further than
    CONE_SHARE of the friction cone from every face normal becomes two legs (an L), else three
    (a Z, the middle leg at the nearest level that is clear), else is halved (LEG_SPLITS), each
    leg clear of what the object may not touch by LEG_CLEARANCE; corners are skipped where one
    stretch, an L or a Z reaches further along the path. For a rectangular footprint whose turn
    the goal leaves free (it keeps its start's turn); None where the path stays as it is (no
    such footprint, no pusher-object pair, or the object cannot be checked alone)."""
    pair = pushing_pair(scenario)
    if pair is None:
        return None
    obj, robot = pair
    shape = _Footprint(scenario, obj)
    frame = _rectangle_frame(shape)
    mu = next((p.mu for p in scenario.pairs if {p.body_a, p.body_b} == {obj, robot}), None)
    if frame is None or mu is None:
        return None
    names = scenario.coordinates
    ox, oy = names.index(f"{obj}.x"), names.index(f"{obj}.y")
    rx, ry = names.index(f"{robot}.x"), names.index(f"{robot}.y")
    # the object alone: the geometric rung's validity, with the robot out of reach
    low, high = sampling_limits(scenario, q0)
    far = np.array(q0, float)
    far[[rx, ry]] += FAR
    low[[rx, ry]], high[[rx, ry]] = -np.inf, np.inf
    check = GeometricChecker(scenario, low, high)
    if not check(far):
        return None
    yaw = (_yaw(scenario, q0, obj) or 0.0) + frame
    axes = np.array([[np.cos(yaw), -np.sin(yaw)], [np.sin(yaw), np.cos(yaw)]])  # columns: the legs' two directions
    cone = CONE_SHARE * float(np.arctan(mu))

    def clear(a, b) -> bool:
        d = b - a
        length = float(np.hypot(*d))
        side = np.array([-d[1], d[0]]) / length if length > 1e-12 else np.zeros(2)
        q = far.copy()
        for s in np.linspace(0.0, 1.0, max(2, int(np.ceil(length / LEG_STEP)) + 1)):
            for off in (0.0, LEG_CLEARANCE, -LEG_CLEARANCE):
                q[[ox, oy]] = a + s * d + off * side
                if not check(q):
                    return False
        return True

    def pushable(a, b) -> bool:
        d = axes.T @ (b - a)
        angle = float(np.arctan2(abs(d[1]), abs(d[0])))
        return min(angle, np.pi / 2 - angle) <= cone

    def straight(a, b):
        return [b] if pushable(a, b) and clear(a, b) else None

    def two(a, b):
        d = axes.T @ (b - a)
        for first in (0, 1):
            corner = a + axes[:, first] * d[first]
            if clear(a, corner) and clear(corner, b):
                return [corner, b]
        return None

    local = xy @ axes  # the path in the legs' frame
    reach = float(np.max(np.hypot(*shape.points.T), initial=0.0))
    lo, hi = local.min(axis=0) - reach, local.max(axis=0) + reach

    def three(a, b):
        A, B = axes.T @ a, axes.T @ b
        best = None
        for k in (1, 0):  # the middle leg along axis 1 - k, at a level on axis k
            levels = np.arange(lo[k], hi[k] + LEG_STEP / 2, LEG_STEP)
            for level in sorted(levels, key=lambda v: abs(v - A[k]) + abs(v - B[k])):
                length = abs(level - A[k]) + abs(level - B[k]) + abs(B[1 - k] - A[1 - k])
                if best is not None and length >= best[0]:
                    break
                c1, c2 = A.copy(), B.copy()
                c1[k] = c2[k] = level
                p1, p2 = axes @ c1, axes @ c2
                if clear(a, p1) and clear(p1, p2) and clear(p2, b):
                    best = (length, [p1, p2, b])
                    break
        return None if best is None else best[1]

    def split(a, b, depth: int):
        if pushable(a, b):
            return [b]
        found = two(a, b) or three(a, b)
        if found is not None or depth == 0:
            return found or [b]
        m = (a + b) / 2.0
        return split(a, m, depth - 1) + split(m, b, depth - 1)

    # the path's corners (the geometric rung's path is subdivided per control period)
    keep = [0]
    for k in range(1, len(xy) - 1):
        u, v = xy[k] - xy[keep[-1]], xy[k + 1] - xy[k]
        if abs(u[0] * v[1] - u[1] * v[0]) > 1e-9 * max(float(np.hypot(*u) * np.hypot(*v)), 1e-12) or u @ v < 0.0:
            keep.append(k)
    points = [xy[k] for k in keep] + [xy[-1]]
    out, i = [points[0]], 0
    while i < len(points) - 1:
        for j in range(len(points) - 1, i, -1):
            a, b = points[i], points[j]
            legs = (straight(a, b) or two(a, b) or three(a, b)) if j > i + 1 else split(a, b, LEG_SPLITS)
            if legs is not None:
                out += legs
                i = j
                break
    return np.array(out)
