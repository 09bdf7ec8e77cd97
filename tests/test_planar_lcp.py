"""The planar contact LCP's builder (`_planar_lcp`) against the general one (`contact_lcp`).

A planar step whose active contacts all have friction rows and whose drives have no force
limit builds its LCP with `_planar_lcp`, on two flat buffers (docs/measurements.md: the
squeeze's contact steps about 8% faster). Its contract is to be the same LCP bit for bit: the
same M, q, Y = A^-1 B, combinations C, friction contacts and force-limited drives, from the same
operations in the same order. Everything after the build (scaling, the warm start's guess,
Lemke, the impulses' velocity update) is shared. Checked here at states of every planar rung
that solves an LCP, on the planar scenarios with contact, with random commands (fixed seeds).
"""

from __future__ import annotations

import numpy as np
import pytest

from models.contact import ContactSet, contact_buffers, contact_frames, place_scripted, scripted_bias
from models.contact_pgs import body_blocks
from models.rollout import _start_system
from models.rungs import compiled, own_poses, rung_for
from models.scenario import load_scenario
from models.stepper import SceneTables, _active_contacts, _free_velocity, _planar_case, _planar_lcp, contact_lcp
from planner.bench import SCENARIOS
from tests.planar_states import sampled_states, slots

RUNGS = ("quasistatic-rigid", "quasistatic-compliant", "dynamic-rigid", "dynamic-compliant")
SCENES = ("two_finger_triangle", "four_finger_grasp", "incline_block", "bouncing_disc")
STATES = 40  # compared per scene and rung (states with an active contact, sampled along rollouts)
#: the scenes whose contacts have friction (mu > 0), which `_planar_lcp` builds; bouncing_disc's
#: are frictionless, which the general builder serves
WITH_FRICTION = ("two_finger_triangle", "four_finger_grasp", "incline_block")
#: at least this many active contacts at one of the states compared
MOST_CONTACTS = {"two_finger_triangle": 2, "four_finger_grasp": 2, "incline_block": 2, "bouncing_disc": 1}


def _both_builds(sc, rung, state, u, h, t):
    """(general, planar, covered, contacts) at the state: both builders' outputs from the same
    inputs, built as the step builds them (A's blocks, the free velocity, the active contacts)."""
    c = compiled(sc)
    S = own_poses(c.scene)
    place_scripted(S.bf, S.base_pos, S.base_quat, t)
    frames = contact_frames(S, state.q, state.nu, h)
    nc = len(frames.pair)
    _, first_slot = contact_buffers(S.pi, S.nv)
    bias = np.zeros((nc, 3))
    scripted_bias(S.bf, S.pi, nc, frames.pair, frames.n, frames.t, frames.o, frames.pa, frames.pb, bias)
    model, D = rung.model, c.drives
    system = _start_system(S, D, model, h, state.q)
    dofs, count, inv, ok = body_blocks(S.bi, system.A, system.Ainv)
    assert ok
    tables = SceneTables(S.bi, S.bf, S.pi, S.pf, False)
    u = np.asarray(u, dtype=float)
    nu_free, _, drive_a = _free_velocity(model, D, tables, system, h, state.q, state.nu, state.q_ref, u, dofs, count, inv)
    W_n = np.ascontiguousarray(frames.W_n)
    contacts = ContactSet(
        frames.pair, frames.psi, slots(frames.pair, first_slot), W_n, np.ascontiguousarray(frames.W_t), np.zeros_like(W_n), bias
    )
    active = _active_contacts(W_n, nc)
    if len(active) == 0:
        return None, None, False, 0
    args = (h, dofs, count, inv, nu_free, active, S.pi, S.pf, contacts, state.delta_n, state.delta_t)
    general = contact_lcp(model, False, *args, D, drive_a)
    covered = _planar_case(False, D.max_force, active, contacts.pair, S.pf, contacts.W_t)
    planar = _planar_lcp(model, *args) if covered else None
    return general, planar, covered, len(active)


# (bouncing_disc's elastic impacts on the dynamic-compliant rung last a few ms: a state in
# contact is rarely sampled; its other rungs check that frictionless contacts take the general path)
CASES = [(name, rung) for name in SCENES for rung in RUNGS if (name, rung) != ("bouncing_disc", "dynamic-compliant")]


@pytest.mark.parametrize("name, rung_name", CASES)
def test_planar_build_is_the_general_one_bit_for_bit(name, rung_name):
    sc = load_scenario(SCENARIOS / f"{name}.toml")
    rung = rung_for(sc, rung_name)
    h = sc.rung_settings(rung_name).h
    states = sampled_states(sc, rung, h, sum(map(ord, name + rung_name)))
    compared, most, touching = 0, 0, None
    while compared < STATES:
        try:
            state, u, t = states.send(touching)
        except StopIteration:
            break
        general, planar, covered, n_active = _both_builds(sc, rung, state, u, h, t)
        touching = n_active > 0
        if not touching:
            continue
        assert covered == (name in WITH_FRICTION)
        names = ("M", "q", "Y", "gen", "cf", "fric", "nf", "lim")
        for what, a, b in zip(names, general, planar if covered else general):
            a, b = np.asarray(a), np.asarray(b)
            assert a.shape == b.shape and a.dtype == b.dtype, (what, a.shape, b.shape)
            assert np.array_equal(a, b), f"{what} differs at t = {t}: max |diff| {np.max(np.abs(a - b))}"
        compared += 1
        most = max(most, n_active)
    assert compared == STATES, f"only {compared} states with contact"
    assert most >= MOST_CONTACTS[name]  # steps with several contacts (their Delassus coupling)
