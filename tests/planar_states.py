"""States in contact along rollouts of a scenario, for the tests that hold a specialised
path of the contact step to the general one (test_planar_lcp, test_warm_steps)."""

from __future__ import annotations

import numpy as np


def slots(pair, first_slot):
    """Each contact's slot: its pair's first slot plus its rank among the pair's contacts."""
    out = np.empty(len(pair), np.int64)
    for i, p in enumerate(pair):
        out[i] = first_slot[p] + int(np.sum(pair[:i] == p))
    return out


def sampled_states(sc, rung, h, seed, tries=2000):
    """(state, u, t) along rollouts of the scenario's policy command with noise (fixed seed): to
    the first contact in 20 ms rollouts, then states a random 1-29 steps apart, starting over
    where a rollout fails or the task's horizon passes. The caller says whether each state had a
    contact by sending True or False into the generator (`send`) before the next one."""
    speeds = sc.spec.task.policy.speeds if sc.spec.task.policy is not None else {}  # (no policy: noise about rest)
    policy = np.array([speeds.get(a, 0.0) for a in sc.actuated])
    rng = np.random.default_rng(seed)
    state, t, touching = rung.initial_state(sc), 0.0, False
    for _ in range(tries):
        u = policy + rng.uniform(-0.3, 0.3, size=policy.shape)
        steps = int(rng.integers(1, 30)) if touching else max(1, int(round(0.02 / h)))
        out = rung.rollout(sc, state, u[None, :], [steps * h], h, stop_at_outcome=False, t0=t)
        if not out.ok or t > sc.spec.task.horizon:  # (start over)
            state, t, touching = rung.initial_state(sc), 0.0, False
            continue
        state, t = out.state, t + steps * h
        touching = yield state, u, t
