"""What the solver is doing, in plain words, for every wait on it: the levels of the search, the phases of a solve
after it, and the fixtures identify has decided."""

from fixwizard.solver.search import SearchProgress
from fixwizard.workflow.solver_process import Progress
from fixwizard.workflow.stage_words import stage_words


def search_words(search: SearchProgress) -> str:
    level = search.rotation_level + search.position_level
    if search.final:
        return f"narrowing done after pass {level}, {search.survivors:,} groups of possible poses left"
    return f"narrowing the poses, pass {level}: {search.survivors:,} groups of possible poses left"


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
