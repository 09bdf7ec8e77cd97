"""The task's vocabulary: what a state is for the task (the paper's Z_F, Z_U or neither).

`Outcome` is the one definition of a run's or a state's class, used by rollouts (as its
integer value, inside compiled code), sweeps, plans, benchmarks and reports. Its `label`
is what files and the CLI print. `goal_distance` and `classify` are the one definition of a
configuration's distance to the goal set and of its class.
"""

from __future__ import annotations

from enum import IntEnum

import numpy as np


class Outcome(IntEnum):
    """A state's class for the task; a run's outcome is the first class other than NONE it met."""

    NONE = 0  # neither in the goal set nor in the unsafe set
    GOAL = 1  # in the goal set (Z_F)
    UNSAFE = 2  # in the unsafe set (Z_U); checked first: a state in both is unsafe

    @property
    def label(self) -> str:
        return self.name.lower()


#: What files and the command line call the outcomes.
OUTCOME_LABELS: tuple[str, ...] = tuple(o.label for o in Outcome)


def goal_distance(scenario, q, pair_psi=None) -> float:
    """How far configuration q is from the task's goal set (0 inside it): the summed interval
    and touch violations of the goal predicate (`models.predicates.predicate_distance`), m or
    rad. pair_psi: every contact pair's signed distance at q if the caller has them (else
    measured here, `models.rungs.pair_signed_distances`)."""
    from models.predicates import predicate_distance

    if pair_psi is None:
        pair_psi = _pair_distances(scenario, q)
    return float(predicate_distance(scenario, scenario.spec.task.goal, q, pair_psi))


def classify(scenario, q, pair_psi=None) -> Outcome:
    """The class of configuration q for the task, as a rollout classifies a state: UNSAFE if
    it is in the unsafe set (checked first), else GOAL if in the goal set, else NONE. q must
    be finite (a state that diverged has no class: that is a run's status). pair_psi: as in
    `goal_distance`."""
    from models.kinematics import kernel_array
    from models.predicates import evaluate
    from models.rungs import compiled

    c = compiled(scenario)
    if pair_psi is None:
        pair_psi = _pair_distances(scenario, q)
    q = kernel_array(q)
    if evaluate(c.unsafe, q, pair_psi):
        return Outcome.UNSAFE
    return Outcome.GOAL if evaluate(c.goal, q, pair_psi) else Outcome.NONE


def _pair_distances(scenario, q) -> np.ndarray:
    # models.rungs imports the compiled kernels, which may use this module's vocabulary:
    # imported when first needed, not at module load
    from models.rungs import pair_signed_distances

    return pair_signed_distances(scenario, q)
