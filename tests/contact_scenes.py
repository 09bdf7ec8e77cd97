"""Small scenes for the contact tests: two free bodies of chosen shapes over a tilted floor."""

from __future__ import annotations

from pathlib import Path

from models.kinematics import compile_scene
from models.scenario import load_scenario

SHAPES_2D = {
    "disc": '{ type = "disc", radius = 0.3 }',
    "box": '{ type = "box", size = [0.8, 0.4] }',
    "triangle": '{ type = "polygon", vertices = [[-1.0, 0.0], [1.0, 0.0], [0.0, 1.0]] }',
    "capsule": '{ type = "capsule", radius = 0.15, length = 0.6 }',
    "hexagon": '{ type = "polygon", vertices = [[0.5, 0.0], [0.25, 0.43], [-0.25, 0.43], [-0.5, 0.0], [-0.25, -0.43], [0.25, -0.43]] }',
}

TEMPLATE_2D = """
version = 1
[scenario]
name = "pair"
[scene]
dimension = 2
gravity = [0.0, 0.0]
[contact]
mu = 0.5
K = 1e6
C = 1e3
[[bodies]]
name = "floor"
role = "obstacle"
shape = {{ type = "halfplane", normal = [0.3, 1.0], offset = -20.0 }}
[[bodies]]
name = "a"
role = "object"
mass = 1.0
inertia = 1.0
shape = {a}
pose = {{ x = -5.0, y = 0.0 }}
dofs = ["x", "y", "theta"]
[[bodies]]
name = "b"
role = "object"
mass = 1.0
inertia = 1.0
shape = {b}
pose = {{ x = 5.0, y = 0.0 }}
dofs = ["x", "y", "theta"]
[task]
horizon = 1.0
goal = {{ box = {{ "a.x" = [0.0, 1.0] }} }}
[ladder]
time_limit = 1.0
[[ladder.rungs]]
model = "dynamic-rigid"
h = 1e-3
"""


def pair_scene(tmp: Path, a: str, b: str):
    path = tmp / f"{a}_{b}.toml"
    path.write_text(TEMPLATE_2D.format(a=SHAPES_2D[a], b=SHAPES_2D[b]))
    scenario = load_scenario(path)
    return scenario, compile_scene(scenario)
