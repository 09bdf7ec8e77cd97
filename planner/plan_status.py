"""How a planning search, and a rung of the ladder, ended: `PlanStatus`; and the label of a rung's
entry in plan.json or the service's events (`rung_label`), which the service's client reads
without importing the planner."""

from __future__ import annotations

from enum import Enum


class PlanStatus(Enum):
    """How a search ended (after OMPL's ``ompl::base::PlannerStatus``) and how a rung of the
    ladder ended. Each member's value is its message; `label` is the word plan.json and
    report.json write in a rung's ``ended`` (the five ways a rung fails, TIMEOUT,
    BUDGET_EXHAUSTED, FAILED, PAST_HORIZON and ABORTED, all write ``failed``; ``cause`` beside it
    gives the member's name, and the rung's ``reason`` starts with the member's message).

    The adapter (`planner.ompl_adapter`) returns EXACT, TIMEOUT, BUDGET_EXHAUSTED, STOPPED or
    ABORTED for a search, from what ended it; the ladder adds the rest.
    """

    EXACT = "a search found a plan into the goal set"
    REPLANNED = "the previous plan did not hold; a search guided by it found a plan into the goal set"
    REPLAYED = "the previous plan holds under this rung"
    TRACKED = "the previous plan, tracked in closed loop (controls corrected per control period), reaches the goal under this rung"
    REPAIRED = (
        "the previous plan, tracked, did not reach the goal as it was; a search rooted at the tracked states found a plan into the goal set"
    )
    SKIPPED = "the rung computes along the plan what the rung below computed: the plan holds as it is"
    OMITTED = (
        "the rung takes more steps per control period than the rung above it, so it is no cheaper to plan with: "
        "left out, the plan below goes up past it"
    )
    APPROXIMATE = "no path into the goal set within the budget; the closest one seeds the next rung"
    TIMEOUT = "no exact plan before the time limit ran out"
    BUDGET_EXHAUSTED = "no exact plan within the iteration budget"
    FAILED = "the plan found does not hold when replayed"
    PAST_HORIZON = "the plan reaches the goal later than the task's horizon allows"
    STOPPED = "the search was stopped before it ended (interrupted)"
    ABORTED = "the planner ended the search by itself, with no plan (OMPL refused the start or the goal)"

    @property
    def message(self) -> str:
        return self.value

    @property
    def label(self) -> str:
        return _LABELS[self]

    @property
    def holds(self) -> bool:
        """The rung accepted a plan that reaches the goal under it."""
        return self in (
            PlanStatus.EXACT,
            PlanStatus.REPLANNED,
            PlanStatus.REPLAYED,
            PlanStatus.TRACKED,
            PlanStatus.REPAIRED,
            PlanStatus.SKIPPED,
        )


_LABELS = {
    PlanStatus.EXACT: "planned",
    PlanStatus.REPLANNED: "replanned",
    PlanStatus.REPLAYED: "replayed",
    PlanStatus.TRACKED: "tracked",
    PlanStatus.REPAIRED: "repaired",
    PlanStatus.SKIPPED: "skipped",
    PlanStatus.OMITTED: "omitted",
    PlanStatus.APPROXIMATE: "approximate",
    PlanStatus.TIMEOUT: "failed",
    PlanStatus.BUDGET_EXHAUSTED: "failed",
    PlanStatus.FAILED: "failed",
    PlanStatus.PAST_HORIZON: "failed",
    PlanStatus.STOPPED: "stopped",
    PlanStatus.ABORTED: "failed",
}


def rung_label(entry: dict) -> str:
    """The label of a rung's entry in plan.json or of a rung_ended event (`planner.ladder.rung_json`
    writes `RungReport.label`); one written before labels were: its rung's name."""
    return entry.get("label", entry.get("rung"))
