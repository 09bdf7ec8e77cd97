"""The model family: the one registry of rungs, lowest fidelity first.

Each entry says what a rung is (its name, the paper's equation, its physics settings) and
the time step it takes when a scenario's ladder does not give one. This module is plain
data, with no compiled code, so that the scenario format (`models.schema`) can take the
rung names from it; `models.rungs.RUNGS` builds the rung objects from the same entries.
Adding a rung is one entry here (and its physics in the stepper).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class RungDefinition:
    """One rung of the family. physics: None for the geometric rung (a validity check, no
    dynamics), else the `models.stepper.Model` fields (kinematic, eps, compliant, theta,
    friction_directions). default_step: h (s) when a scenario's ladder does not list the
    rung (None for geometric)."""

    name: str
    description: str
    physics: tuple[bool, float, bool, float, int] | None
    default_step: float | None

    @property
    def friction_directions(self) -> int | None:
        """The rung's default number of friction directions (None: geometric)."""
        return None if self.physics is None else self.physics[4]


FAMILY: tuple[RungDefinition, ...] = (
    RungDefinition("geometric", "eq. (9): non-penetration only", None, None),
    RungDefinition("kinematic", "eq. (8): commanded speeds, min-norm passive speeds", (True, 0.0, False, 1.0, 2), 1e-2),
    RungDefinition("quasistatic-rigid", "eq. (7)", (False, 0.0, False, 1.0, 4), 1e-3),
    RungDefinition("quasistatic-compliant", "eq. (6)", (False, 0.0, True, 1.0, 4), 1e-3),
    RungDefinition("dynamic-rigid", "eq. (5)", (False, 1.0, False, 1.0, 4), 1e-4),
    RungDefinition("dynamic-compliant", "eq. (3)", (False, 1.0, True, 1.0, 4), 1e-4),
)
#: Rung names, lowest fidelity first. The ladder in a file must respect this order.
RUNG_NAMES: tuple[str, ...] = tuple(r.name for r in FAMILY)
#: The rungs that run physics (every rung but the geometric one).
PROPAGATING_RUNGS: tuple[str, ...] = tuple(r.name for r in FAMILY if r.physics is not None)


def definition(name: str) -> RungDefinition:
    """The family's entry for a rung name; KeyError for an unknown name."""
    for rung in FAMILY:
        if rung.name == name:
            return rung
    raise KeyError(name)


def control_steps(durations, h: float) -> list[int]:
    """The steps a run takes for each control's duration at step h: round(duration / h), as
    the rollout kernel counts them (`models.rollout.rollout_kernel`), so a control shorter than
    h / 2 takes none."""
    return [round(float(d) / h) for d in np.atleast_1d(durations)]
