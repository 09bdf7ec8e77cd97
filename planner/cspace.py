"""The paper's Fig. 4 C-space of a two-finger scene, computed from the scenario's geometry.

Paper coordinates: x1 = y1_0 - finger1.y and x2 = y2_0 - finger2.y (finger depths, 0 at
the start, positive downwards) and x3 = the object's horizontal coordinate (triangle.x).
Each finger is a disc that moves only vertically; the object is a convex (possibly rounded)
polygon that only translates horizontally. C_free is then, at each x3, the rectangle
0 <= x_i <= depth_bound(i, x3): a finger goes down until it meets its lower limit or the
object's rounded top. Its boundary's facets are the finger limits and the finger-face
strata (a finger disc touching one of the object's upper faces); the goal edge is the
codimension-two stratum where each finger touches the upper face it starts above.

Everything here is plain geometry (numpy): no rollout, no plotting.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: The scene's names (scenarios/two_finger_triangle.toml): fingers, then the object.
FINGERS = ("finger1", "finger2")
OBJECT = "triangle"


@dataclass(frozen=True)
class FaceStratum:
    """Finger `finger` (0 or 1) touching the object's upper face `face`: x_finger = offset +
    slope * x3 for x3 in [x3_low, x3_high] (the range where the contact point lies on the face
    and the depth is within the finger's limits). name: e.g. "finger 1 on left face"."""

    finger: int
    face: str
    offset: float
    slope: float
    x3_low: float
    x3_high: float

    @property
    def name(self) -> str:
        return f"finger {self.finger + 1} on {self.face}"

    def depth(self, x3):
        return self.offset + self.slope * np.asarray(x3, float)


@dataclass(frozen=True)
class TwoFingerCSpace:
    """The C-space of the two-finger scene in paper coordinates (see the module docstring).

    finger_x: the fingers' (fixed) world x, m; finger_y0: their start heights (disc centres),
    m; depth_limit: the deepest depth each finger's drive allows (y0 - lower limit), m;
    core: the object's core polygon (k, 2) at x3 = 0, counter-clockwise, m; radius: the
    object's rounding plus the finger's radius, m; strata: the four finger-face strata;
    goal_edge: (2, 3) endpoints (x1, x2, x3) of the goal edge, or None when the two strata
    do not meet."""

    finger_x: tuple[float, float]
    finger_y0: tuple[float, float]
    depth_limit: tuple[float, float]
    core: np.ndarray
    radius: float
    strata: tuple[FaceStratum, ...]
    goal_edge: np.ndarray | None

    def depth_bound(self, finger: int, x3) -> np.ndarray:
        """The deepest free depth of `finger` at object offset(s) x3: its limit or where it
        meets the object's rounded top, whichever is shallower."""
        u = self.finger_x[finger] - np.asarray(x3, float)
        top = upper_envelope(self.core, self.radius, u)
        return np.minimum(self.depth_limit[finger], self.finger_y0[finger] - top)


def upper_envelope(core: np.ndarray, radius: float, u) -> np.ndarray:
    """Height of the top of the convex polygon `core` (k, 2, counter-clockwise) grown by
    `radius`, at horizontal position(s) u (same frame); -inf where nothing lies above u."""
    u = np.asarray(u, float)
    top = np.full(u.shape, -np.inf)
    for vx, vy in core:  # the arcs around the vertices
        inside = np.abs(u - vx) <= radius
        top = np.where(inside, np.maximum(top, vy + np.sqrt(np.clip(radius**2 - (u - vx) ** 2, 0, None))), top)
    for a, b, n in _edges(core):  # the edges pushed out along their normals
        dx, dy = b - a
        if abs(dx) < 1e-12:
            continue
        t = (u - a[0] - radius * n[0]) / dx
        on = (t >= 0) & (t <= 1)
        top = np.where(on, np.maximum(top, a[1] + t * dy + radius * n[1]), top)
    return top


def _edges(core: np.ndarray):
    """(a, b, outward unit normal) of each edge of a counter-clockwise polygon."""
    for k in range(len(core)):
        a, b = core[k], core[(k + 1) % len(core)]
        d = b - a
        length = float(np.hypot(*d))
        if length > 0:
            yield a, b, np.array([d[1], -d[0]]) / length


def _face_names(core: np.ndarray) -> list[tuple[np.ndarray, np.ndarray, np.ndarray, str]]:
    """The upper faces (outward normal pointing up), named by the side they face."""
    upper = [(a, b, n) for a, b, n in _edges(core) if n[1] > 1e-9 and abs(b[0] - a[0]) > 1e-12]
    if len(upper) == 2:
        names = ["left face" if n[0] < 0 else "right face" for _, _, n in upper]
        if len(set(names)) == 2:
            return [(a, b, n, name) for (a, b, n), name in zip(upper, names)]
    return [(a, b, n, f"upper face {k + 1}") for k, (a, b, n) in enumerate(upper)]


def _stratum(finger: int, xf: float, y0: float, limit: float, a, b, n, name: str, radius: float) -> FaceStratum | None:
    """Finger at x = xf touching face a -> b (normal n) of the object shifted by x3: its
    centre is p + radius n for p on the face, so its depth is linear in x3."""
    dx, dy = b - a
    slope = dy / dx
    # contact point on the face at x3: p.x = xf - radius n.x - x3, t = (p.x - a.x) / dx
    base = xf - radius * n[0] - a[0]
    offset = y0 - a[1] - radius * n[1] - slope * base
    ends = sorted((base, base - dx))  # x3 at t = 0 and t = 1
    lo, hi = ends
    # keep the depths within [0, limit]
    for bound in (0.0, limit):
        if abs(slope) > 1e-12:
            x3 = (bound - offset) / slope
            if (slope > 0) == (bound == 0.0):
                lo = max(lo, x3)
            else:
                hi = min(hi, x3)
        elif not 0.0 <= offset <= limit:
            return None
    if hi < lo:
        return None
    return FaceStratum(finger, name, float(offset), float(slope), float(lo), float(hi))


def two_finger_cspace(scenario) -> TwoFingerCSpace:
    """The C-space of a scenario with two vertical disc fingers (FINGERS) and a polygon
    object (OBJECT) moving along x. ValueError (saying what is missing) for any other scene."""
    names = set(scenario.coordinates)
    needed = [f"{f}.y" for f in FINGERS] + [f"{OBJECT}.x"]
    missing = [c for c in needed if c not in names]
    if missing:
        raise ValueError(f"not a two-finger scene: no coordinate {', '.join(missing)}")
    others = [c for c in scenario.coordinates if c not in needed]  # (the C-space has these three axes only)
    if others:
        raise ValueError(f"not a two-finger scene: other coordinates {', '.join(others)}")
    place = scenario.placements(scenario.start)
    # a body besides the fingers, the object and a floor under them (the palm) bounds C_free too,
    # which this C-space does not know: a wall had been left out of the plot's facets
    extra = [
        b.name for b in scenario.spec.bodies if b.name not in (*FINGERS, OBJECT) and not _floor(scenario.geometries[b.name], place[b.name])
    ]
    if extra:
        raise ValueError(f"not a two-finger scene: other bodies {', '.join(extra)}")
    obj = scenario.geometries[OBJECT]
    if obj.kind != "rounded" or len(obj.core) < 3:
        raise ValueError(f"{OBJECT} is not a polygon")
    x30 = float(scenario.start[scenario.coordinates.index(f"{OBJECT}.x")])
    core = (place[OBJECT].rotation @ obj.core.T).T + place[OBJECT].translation - np.array([x30, 0.0])
    finger_x, finger_y0, limits, radius = [], [], [], None
    for f in FINGERS:
        g = scenario.geometries[f]
        if g.kind != "rounded" or len(g.core) != 1:
            raise ValueError(f"{f} is not a disc")
        centre = place[f].rotation @ g.core[0] + place[f].translation
        finger_x.append(float(centre[0]))
        finger_y0.append(float(centre[1]))
        lower = scenario.drive(f"{f}.y").lower if f"{f}.y" in scenario.actuated else None
        # no drive limit: the finger stops on the object's lowest level (the palm under it)
        floor = lower if lower is not None else float(core[:, 1].min()) + g.radius
        limits.append(float(centre[1] - floor))
        r = obj.radius + g.radius
        if radius is not None and abs(r - radius) > 1e-12:
            raise ValueError("the two fingers have different radii")
        radius = r
    faces = _face_names(core)
    strata = []
    for i in range(2):
        for a, b, n, name in faces:
            s = _stratum(i, finger_x[i], finger_y0[i], limits[i], a, b, n, name, radius)
            if s is not None:
                strata.append(s)
    space = TwoFingerCSpace(tuple(finger_x), tuple(finger_y0), tuple(limits), core, float(radius), tuple(strata), None)
    return TwoFingerCSpace(**{**space.__dict__, "goal_edge": _goal_edge(space, x30)})


def _floor(geometry, placement) -> bool:
    """A half-plane whose normal points up: the palm under the fingers and the object."""
    if geometry.kind != "halfspace":
        return False
    normal = placement.rotation @ np.asarray(geometry.normal, float)
    return bool(np.allclose(normal, [0.0, 1.0], atol=1e-9))


def _goal_edge(space: TwoFingerCSpace, x30: float) -> np.ndarray | None:
    """Where each finger touches the upper face it starts above (the form-closure edge)."""
    chosen = []
    for i in range(2):
        under = [s for s in space.strata if s.finger == i and s.x3_low <= x30 <= s.x3_high]
        if not under:
            # the finger does not start above a face: the face its stratum range is nearest to
            under = sorted((s for s in space.strata if s.finger == i), key=lambda s: min(abs(s.x3_low - x30), abs(s.x3_high - x30)))
        if not under:
            return None
        chosen.append(under[0])
    s1, s2 = chosen
    if s1.face == s2.face:
        return None
    lo, hi = max(s1.x3_low, s2.x3_low), min(s1.x3_high, s2.x3_high)
    if hi <= lo:
        return None
    x3 = np.array([lo, hi])
    return np.column_stack([s1.depth(x3), s2.depth(x3), x3])
