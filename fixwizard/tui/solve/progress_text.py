"""What the solver is doing, in plain words, for every wait on it: the levels of the search, the phases of a solve
after it, and the fixtures identify has decided."""

from fixwizard.solver.search import SearchProgress
from fixwizard.solver.solve import SolveStage
from fixwizard.workflow.solver_process import Progress


def search_words(search: SearchProgress) -> str:
    level = search.rotation_level + search.position_level
    if search.final:
        return f"narrowing done after pass {level}, {search.survivors:,} groups of possible poses left"
    return f"narrowing the poses, pass {level}: {search.survivors:,} groups of possible poses left"


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


def progress_words(progress: Progress) -> str:
    """One solver progress event in plain words."""
    if progress.search is not None:
        return search_words(progress.search)
    if progress.stage is not None:
        return stage_words(progress.stage)
    step = progress.identify
    if step is None:
        return "working"
    verdict = {"inconsistent": "ruled out", "unique": "fits", "ambiguous": "fits"}.get(step.status, "not decided yet")
    return f"{step.mesh.name}: {verdict} ({step.elapsed_s:.0f} s)"
