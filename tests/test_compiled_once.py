"""Nothing is compiled at run time once numba's cache holds the kernels: a process's first
rollout and first propagation load compiled code, they do not compile it (`models.rollout.bind`:
a typed List made by numba.typed.List in Python compiled the List's methods, about 1 s in
every process)."""

from __future__ import annotations

import json
import subprocess
import sys

from tests.conftest import ROOT

#: A process's first rollout and first planner propagation on box_push_3d, with numba's
#: compile events recorded (a function loaded from the cache raises none): prints their
#: dispatchers as JSON, and the two runs' steps.
FIRST_CALLS = """
import json, sys
import numpy as np
from numba.core import event

compiled = []

class Compiles(event.Listener):
    def on_start(self, ev):
        compiled.append(str(ev.data["dispatcher"]))

    def on_end(self, ev):
        pass

event.register("numba:compile", Compiles())
from models.rungs import rung_for
from models.scenario import load_scenario

box = load_scenario("scenarios/box_push_3d.toml")
rung = rung_for(box, "dynamic-rigid")
start = rung.initial_state(box)
out = rung.rollout(box, start, np.array([[0.2, 0.0]]), [0.05], 1e-3)
nq = len(start.q)
sizes = (nq, len(start.nu), len(start.q_ref), len(start.delta_n))
x = np.concatenate([start.q, start.nu, start.q_ref, start.delta_n, start.delta_t.ravel(), [0.0]])
y = np.empty_like(x)
propagate = rung.propagator(box, 1e-3, sizes, np.full(nq, -10.0), np.full(nq, 10.0), np.zeros(0, np.int64), np.zeros(0))
status = propagate(x, np.array([0.2, 0.0]), 0.05, y)
print(json.dumps({"compiled": compiled, "steps": out.steps, "status": int(status), "same": bool(np.allclose(y[:nq], out.state.q))}))
"""


def _first_calls() -> dict:
    done = subprocess.run([sys.executable, "-c", FIRST_CALLS], capture_output=True, text=True, cwd=ROOT, timeout=1800)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout.strip().splitlines()[-1])


def test_a_process_s_first_rollout_and_propagation_compile_nothing_from_a_warm_cache():
    _first_calls()  # fills numba's cache where this run is the first to need these kernels
    again = _first_calls()
    assert again["compiled"] == []
    # and they ran: 50 steps each, the propagation ending where the rollout did
    assert again["steps"] == 50 and again["status"] == 0 and again["same"]
