"""A solve's phases after its search in plain words, for every display of them (the CLI's progress lines, the
wizard's solve and sampling screens)."""

from fixwizard.solver.solve import SolveStage


def stage_words(stage: SolveStage) -> str:
    """A phase after the search: 'computing the guaranteed bounds, round 3' and the like."""
    group = f" of pose group {stage.mode} of {stage.modes}" if stage.modes > 1 else ""
    if stage.name == "bounds":
        return f"computing the guaranteed bounds{group}" + (f", round {stage.round}" if stage.round else "")
    return {"modes": "grouping the possible poses",
            "samples": f"weighing the possible poses{group}",
            "masses": "weighing the pose groups against each other",
            "intervals": "computing the 95 % and 99 % intervals",
            "diagnosis": "no pose fits all taps: looking for the tap that does not fit"}[stage.name]
