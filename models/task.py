"""The task's vocabulary: what a state is for the task (the paper's Z_F, Z_U or neither).

`Outcome` is the one definition of a run's or a state's class, used by rollouts (as its
integer value, inside compiled code), sweeps, plans, benchmarks and reports. Its `label`
is what files and the CLI print.
"""

from __future__ import annotations

from enum import IntEnum


class Outcome(IntEnum):
    """A state's class for the task; a run's outcome is the first class other than NONE it met."""

    NONE = 0  # neither in the goal set nor in the unsafe set
    GOAL = 1  # in the goal set (Z_F)
    UNSAFE = 2  # in the unsafe set (Z_U); checked first: a state in both is unsafe

    @property
    def label(self) -> str:
        return self.name.lower()

    @property
    def message(self) -> str:
        return _MESSAGES[self]

    @classmethod
    def from_label(cls, label: str) -> Outcome:
        """The outcome a label names ('goal', 'unsafe', 'none'); ValueError otherwise."""
        try:
            return cls[label.upper()]
        except KeyError:
            raise ValueError(f"unknown outcome {label!r}; outcomes: {', '.join(o.label for o in cls)}") from None


_MESSAGES = {
    Outcome.NONE: "neither the goal nor the unsafe set was reached",
    Outcome.GOAL: "the goal set was reached",
    Outcome.UNSAFE: "the unsafe set was entered",
}
