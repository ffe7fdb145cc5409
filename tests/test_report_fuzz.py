"""A report edited by hand, damaged or written by something else, field by field: every value of every field
replaced by what a person or a tool might put there (nothing, text, a negative, zero, NaN, infinity, a huge
number, a list, a mapping, a boolean), every field removed, and an unknown field added. ``report.load`` either
reads it or says what is wrong (an InputError, never another exception); a report it reads gives finite poses and
non-negative finite bounds; ``fixwizard export`` answers 0 or 1, never a traceback; ``serve`` serves a finite pose
or refuses with a fault."""

import copy
import datetime as dt
import math
import random
import xmlrpc.client
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
import yaml

from fixwizard import report
from fixwizard.cli import main
from fixwizard.errors import InputError
from fixwizard.serve import FixtureService

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "report.yaml"
BAD_VALUES = (None, "", "abc", -1.0, 0, 1e308, float("nan"), float("inf"), -float("inf"), [], {}, True, 10**40,
              [1.0, 2.0], [[0.0, 0.0, 0.0]])


def example() -> dict:
    """The example report as from a real cell, dated now (so that serve's age limit does not refuse all)."""
    data = yaml.safe_load(EXAMPLE.read_text())
    data["simulated"] = False
    data["created"] = dt.datetime.now(dt.UTC).isoformat(timespec="seconds")
    data["fixture"]["mesh"] = str((EXAMPLE.parents[1] / data["fixture"]["mesh"]).resolve())
    return data


def leaves(node: object, path: tuple = ()) -> Iterator[tuple]:
    """Every path (keys and list indices) to a field, the containers' own paths first."""
    if path:
        yield path
    if isinstance(node, dict):
        for key, value in node.items():
            yield from leaves(value, (*path, key))
    elif isinstance(node, list):
        for index, value in enumerate(node):
            yield from leaves(value, (*path, index))


def changed(data: dict, path: tuple, value: object, remove: bool = False) -> dict:
    edited = copy.deepcopy(data)
    parent = edited
    for key in path[:-1]:
        parent = parent[key]
    if remove:
        del parent[path[-1]]
    else:
        parent[path[-1]] = value
    return edited


def edits(rng: random.Random, values_per_field: int) -> Iterator[tuple[str, dict]]:
    """Each field removed, and set to ``values_per_field`` of ``BAD_VALUES`` drawn at random; a field added."""
    data = example()
    for path in leaves(data):
        where = ".".join(map(str, path))
        yield f"{where} removed", changed(data, path, None, remove=True)
        for value in rng.sample(BAD_VALUES, values_per_field):
            yield f"{where} = {value!r}", changed(data, path, value)
    yield "an unknown field", {**data, "comment_by_hand": "moved it 2 mm"}


def check_loaded(found: report.Report, edit: str) -> None:
    """A report that loads gives finite poses and finite, non-negative bounds."""
    use = found.pose_to_use()
    if use is None:
        return
    base_T_cad, guarantee = use
    assert np.all(np.isfinite(base_T_cad)), edit
    np.testing.assert_allclose(base_T_cad[:3, :3] @ base_T_cad[:3, :3].T, np.eye(3), atol=1e-6, err_msg=edit)
    figures = (guarantee.position_m, guarantee.rotation_deg, guarantee.max_point_displacement_m)
    assert all(math.isfinite(value) and value >= 0.0 for value in figures), edit
    assert all(math.isfinite(value) for value in found.ur_pose_to_use()), edit


@pytest.mark.slow
def test_every_field_edited_is_read_or_refused_in_words_never_used_wrong(tmp_path, capsys):
    path = tmp_path / "cell" / "bracket.yaml"
    path.parent.mkdir()
    service = FixtureService(path.parent, max_age_s=86400.0)
    outcomes = {"read": 0, "refused": 0}
    seed = random.randrange(1 << 30)
    rng = random.Random(seed)
    for edit, data in edits(rng, values_per_field=3):
        edit = f"seed {seed}: {edit}"
        try:
            text = yaml.safe_dump(data, sort_keys=False)
        except (OverflowError, ValueError):
            continue
        path.write_text(text)
        try:
            found = report.load(path)
        except InputError as error:
            assert str(error) and "Traceback" not in str(error), edit
            outcomes["refused"] += 1
            if rng.random() > 0.1:  # export and serve read it as load does; some are tried all the same
                continue
        else:
            check_loaded(found, edit)
            outcomes["read"] += 1
        assert main(["export", str(path), "--format", "json"]) in (0, 1), edit
        capsys.readouterr()
        name = data.get("fixture", {}).get("name") if isinstance(data.get("fixture"), dict) else None
        try:
            pose = service.get_pose(name if isinstance(name, str) else "bracket")
        except xmlrpc.client.Fault as fault:
            assert fault.faultString.startswith("fixwizard: "), (edit, fault.faultString)
        else:
            values = [pose[key] for key in ("x", "y", "z", "rx", "ry", "rz")]
            assert all(isinstance(value, float) and math.isfinite(value) for value in values), edit
    print(f"\n{sum(outcomes.values())} edited reports (seed {seed}): {outcomes}")
    assert outcomes["read"] and outcomes["refused"]
