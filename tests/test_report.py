"""The report file robot programs read (fixwizard.report/2): what it says at a glance, rounding that keeps the
guarantee, atomic writing, and loading with checks, also of fixwizard.report/1 files."""

import datetime as dt
import os
import re
from pathlib import Path

import numpy as np
import pytest
import yaml
from scipy.spatial.transform import Rotation

from conftest import piped
from fixwizard import report
from fixwizard.errors import InputError
from fixwizard.fixture import load_fixture
from fixwizard.geometry.se3 import make_transform, transform_points
from fixwizard.solver.estimates import Bounds
from fixwizard.solver.solve import solve
from fixwizard.synthetic import bounded_noise, touching_ball_centres
from fixwizard.yamlfile import parse_yaml
from report_edits import with_pose
from shapes import l_prism

V1_REPORT = Path(__file__).resolve().parent / "data" / "report_v1.yaml"
EXAMPLE_REPORT = Path(__file__).resolve().parents[1] / "examples" / "report.yaml"


@pytest.fixture(scope="module")
def plate(tmp_path_factory):
    """The L-plate as a mesh file (mm), loaded."""
    folder = tmp_path_factory.mktemp("plate")
    mesh = l_prism()
    mesh.apply_scale(1000.0)
    mesh.export(folder / "l plate (v2).stl")
    return load_fixture(folder / "l plate (v2).stl", "mm")


@pytest.fixture(scope="module")
def solved(plate):
    rng = np.random.default_rng(4)
    base_T_cad = make_transform(Rotation.from_euler("xyz", [3, -2, 50], degrees=True), [0.4, -0.2, 0.05])
    taps = transform_points(base_T_cad, touching_ball_centres(plate.mesh, 20, 0.0015, rng)) + bounded_noise(20, 0.0005,
                                                                                                          rng)
    solution = solve(plate, taps, 0.003, 0.0005, max_cells=1e6, max_samples=2000)
    assert solution.status == "unique"
    return plate, taps, solution


def written(solved, tmp_path, **options) -> Path:
    fixture, taps, solution = solved
    return report.write(tmp_path / "r.yaml", report.report_dict(solution, fixture, taps, 0.003, 0.0005, 0.0005 / 3,
                                                                 **options))


def test_a_report_cut_short_at_any_line_is_refused_never_read_with_fewer_taps(solved, tmp_path):
    """A copy that did not finish (a full disk, a pulled stick) ends at a line: whatever line, it is refused, and
    once the file says it is a report, the message says it may be cut short (it blamed a missing ball diameter, as if
    the report had been edited, for most lines)."""
    lines = written(solved, tmp_path).read_text().splitlines(keepends=True)
    cut = tmp_path / "cut.yaml"
    schema_line = next(number for number, line in enumerate(lines) if line.startswith("schema:"))
    for end in range(1, len(lines)):
        cut.write_text("".join(lines[:end]))
        with pytest.raises(InputError) as refused:
            report.load(cut)
        assert end <= schema_line or "cut short" in str(refused.value), (end, str(refused.value))
    cut.write_text("".join(lines))
    assert len(report.load(cut).data["inputs"]["points_m"]) == 20


def test_the_file_says_at_the_top_whether_it_is_simulated_its_status_frame_and_units(solved, tmp_path):
    text = written(solved, tmp_path, simulated=True).read_text()
    comments = [line for line in text.splitlines() if line.startswith("#")]
    assert "CAD frame" in comments[1] and "robot base frame" in comments[1]
    assert "metres" in comments[2] and "radians" in comments[2] and "degrees" in comments[2]
    assert "Use `pose`" in comments[3] and "`bounds.center`" in comments[4]
    assert comments[-1].endswith("THIS ONE IS NOT.")
    data = yaml.safe_load(text)
    assert list(data)[:4] == ["schema", "simulated", "status", "created"]
    assert data["schema"] == "fixwizard.report/2" and data["simulated"] is True
    assert data["frame"]["relative_to"] == "robot base frame" and data["units"]["length"] == "m"


def test_a_unique_report_from_a_real_cell_says_a_program_may_use_it(solved, tmp_path):
    assert written(solved, tmp_path).read_text().splitlines()[5].endswith("this one is.")


def test_round_trip_keeps_the_pose_to_within_its_rounding(solved, tmp_path):
    _, _, solution = solved
    loaded = report.load(written(solved, tmp_path))
    assert loaded.schema == "fixwizard.report/2" and not loaded.simulated
    assert loaded.base_T_cad[:3, 3] == pytest.approx(solution.base_T_cad[:3, 3], abs=1e-7)
    angle = Rotation.from_matrix(loaded.base_T_cad[:3, :3].T @ solution.base_T_cad[:3, :3]).magnitude()
    assert angle < 2e-6
    assert loaded.position_bound_m >= solution.bounds.position_m
    assert loaded.pose_guarantee.position_m >= loaded.position_bound_m
    assert [interval["level"] for interval in loaded.data["intervals"]] == [0.95, 0.99]
    assert set(loaded.data) >= {"created", "status", "modes", "warnings", "search", "inputs"}


def test_the_fixture_is_named_after_the_mesh_file_unless_named(solved, tmp_path):
    fixture = solved[0]
    loaded = report.load(written(solved, tmp_path))
    assert loaded.name == "l_plate_v2" and loaded.mesh == fixture.path.resolve() and loaded.mesh.is_absolute()
    assert loaded.mesh_sha256 == fixture.sha256 and loaded.mesh_units == "mm"
    assert report.load(written(solved, tmp_path, name="bracket-2")).name == "bracket-2"
    with pytest.raises(InputError, match="letters, digits"):
        written(solved, tmp_path, name="two words")
    with pytest.raises(InputError, match=r"in ASCII \(a-z, A-Z, 0-9\)"):  # 'ö' is a letter, but not one of those
        written(solved, tmp_path, name="Förderband")


def test_numbers_have_sensible_precision(solved, tmp_path):
    text = written(solved, tmp_path).read_text()
    data = yaml.safe_load(text)
    assert not re.search(r"\d\.\d{11,}", text)  # no 17-digit floats anywhere
    for values, decimals in ((data["pose"]["position_m"], 7), (data["pose"]["rotvec_rad"], 6),
                             (data["bounds"]["center"]["position_m"], 7), ([data["bounds"]["rotation_deg"]], 5),
                             ([value for point in data["inputs"]["points_m"] for value in point], 7)):
        assert all(round(value, decimals) == value for value in values)
    position, rotvec = data["pose"]["position_m"], data["pose"]["rotvec_rad"]
    assert data["pose"]["ur"] == "p[" + ", ".join([f"{v:.7f}" for v in position] + [f"{v:.6f}" for v in rotvec]) + "]"
    quaternion = Rotation.from_quat(data["pose"]["quaternion_xyzw"])
    assert (quaternion.inv() * Rotation.from_rotvec(rotvec)).magnitude() < 2e-7


def _pose_at(rng, centre: np.ndarray, position_m: float, rotation_rad: float) -> np.ndarray:
    """A pose whose CAD origin lies exactly ``position_m`` and whose rotation exactly ``rotation_rad`` from the
    centre's: the worst case a guarantee must hold for."""
    direction, axis = rng.normal(size=3), rng.normal(size=3)
    turn = Rotation.from_rotvec(axis / np.linalg.norm(axis) * rotation_rad)
    return make_transform(turn * Rotation.from_matrix(centre[:3, :3]),
                          centre[:3, 3] + position_m * direction / np.linalg.norm(direction))


def _within(figures: dict, centre: np.ndarray, pose: np.ndarray, vertices: np.ndarray) -> bool:
    """Whether ``pose`` lies within the written figures of ``centre`` (CAD origin, rotation, every vertex)."""
    angle = np.degrees(Rotation.from_matrix(centre[:3, :3].T @ pose[:3, :3]).magnitude())
    moved = np.linalg.norm(transform_points(pose, vertices) - transform_points(centre, vertices), axis=1).max()
    return bool(np.linalg.norm(pose[:3, 3] - centre[:3, 3]) <= figures["position_m"]
                and angle <= figures["rotation_deg"] and moved <= figures["max_point_displacement_m"])


def test_rounding_never_lets_a_pose_at_the_edge_of_the_bounds_escape_them(plate):
    """Random centres and poses exactly at the bounds (tight in every figure): the written bounds about the written
    centre, and the pose's guarantee about the written pose, still hold them, also read through the quaternion."""
    rng = np.random.default_rng(21)
    vertices = plate.mesh.vertices
    for _ in range(300):
        centre = make_transform(Rotation.random(random_state=rng), rng.uniform(-0.8, 0.8, 3))
        position_m, rotation_rad = rng.uniform(1e-7, 3e-3), rng.uniform(1e-7, 0.05)
        true = _pose_at(rng, centre, position_m, rotation_rad)
        point_m = np.linalg.norm(transform_points(true, vertices) - transform_points(centre, vertices), axis=1).max()
        bounds = report.bounds_dict(Bounds(centre, position_m, rotation_rad, point_m), plate)
        written_centre = make_transform(Rotation.from_rotvec(bounds["center"]["rotvec_rad"]),
                                        bounds["center"]["position_m"])
        assert _within(bounds, written_centre, true, vertices)
        estimate = _pose_at(rng, centre, rng.uniform(0, position_m), rng.uniform(0, rotation_rad))
        pose = report._pose_with_guarantee(estimate, bounds, plate)
        for rotation in (Rotation.from_rotvec(pose["rotvec_rad"]), Rotation.from_quat(pose["quaternion_xyzw"])):
            assert _within(pose["guaranteed"], make_transform(rotation, pose["position_m"]), true, vertices)


def test_an_inconsistent_report_has_no_pose_and_loads(plate, solved, tmp_path):
    _, taps, _ = solved
    off = taps.copy()
    off[3] += [0.0, 0.0, 0.05]
    solution = solve(plate, off, 0.003, 0.0005, max_cells=2e5, max_samples=500, diagnose_inconsistent=False)
    path = report.write(tmp_path / "off.yaml", report.report_dict(solution, plate, off, 0.003, 0.0005, 0.0005 / 3))
    loaded = report.load(path)
    assert loaded.status == "inconsistent" and loaded.base_T_cad is None and loaded.pose_guarantee is None
    assert loaded.data["pose"] is None and loaded.data["bounds"] is None
    assert path.read_text().splitlines()[5].endswith("THIS ONE IS NOT.")


def test_a_version_1_report_still_loads(tmp_path):
    loaded = report.load(V1_REPORT)
    assert loaded.schema == "fixwizard.report/1" and loaded.status == "unique"
    assert loaded.name == "demo_bracket" and loaded.mesh == Path("fixtures/demo_bracket.stl")
    assert loaded.mesh_units == "mm" and loaded.ball_diameter_m == 0.003 and loaded.sample_bound_m == 0.001
    assert loaded.pose_guarantee is None and not loaded.simulated
    assert loaded.created == dt.datetime(2026, 11, 24, 4, 28, 12, tzinfo=dt.UTC)
    assert loaded.position_bound_m == pytest.approx(0.004182796099050545)
    assert loaded.base_T_cad[:3, 3] == pytest.approx([0.4500388342801127, -0.12033487023360534, 0.01998762907265287])


def test_a_stream_piped_in_as_a_report_is_refused_after_its_first_megabyte(tmp_path):
    """``export <(ssh cell cat ...)`` gives a pipe, which has no size to check first: it was read and parsed whole."""
    reading, writing = os.pipe()
    feeder = piped(writing, b"x: [" + b"0.1, " * 1_000_000 + b"0]\n")
    try:
        with pytest.raises(InputError, match="holds more than 1 MB, more than any fixwizard report"):
            report.load(f"/proc/self/fd/{reading}")
    finally:
        os.close(reading)
        feeder.join(timeout=10)


V2_START = ("schema: fixwizard.report/2\nsimulated: false\nstatus: unique\ncreated: '2026-01-02T03:04:05+00:00'\n"
            "fixture: {name: b, mesh: /x.stl, mesh_sha256: abc, mesh_units: mm}\n"
            "inputs: {ball_diameter_m: 0.003, sample_bound_m: 0.001}\n")
V2_END = "search: {cells: 10, rotation_level: 1, position_level: 1, elapsed_s: 0.1, max_cells: 100000.0}\n"


@pytest.mark.parametrize("text, match", [
    ("just words", "not a fixwizard report"),
    ("schema: fixwizard.report/3\n", "a fixwizard report of a version this fixwizard does not read "
     r"\('fixwizard.report/3'; it reads fixwizard.report/2, fixwizard.report/1\): .*update fixwizard"),
    ("schema: fixwizard.report/1\nstatus: great\n", "status"),
    (V2_START + "pose: null\n", "needs 'pose'"),
    (V2_START.replace("simulated: false", "simulated: maybe"), "'simulated' must be true or false"),
    (V2_START.replace("created: '2026-01-02T03:04:05+00:00'", "created: yesterday"), "'created' must be"),
    (V2_START.replace("fixture: {name: b, mesh: /x.stl, mesh_sha256: abc, mesh_units: mm}\n", ""),
     "does not say which fixture"),
    (V2_START.replace("name: b,", "name: 'a b',"), "letters, digits"),
    (V2_START.replace("mesh_units: mm", "mesh_units: inch"), "mesh_units"),
    (V2_START.replace("sample_bound_m: 0.001", "sample_bound_m: -1"), "positive length"),
    (V2_START + "pose: {position_m: [0, 0, 0], rotvec_rad: [0, 0, 0], guaranteed: {position_m: 0.001, rotation_deg: 1,"
     " max_point_displacement_m: 0.002}}\nbounds: {center: {position_m: [0, 0, 0], rotvec_rad: [0, 0, .nan]},"
     " position_m: 0.001, rotation_deg: 1, max_point_displacement_m: 0.002}\n", "not finite"),
    (V2_START + "pose: {position_m: [0, 0, 0], rotvec_rad: [0, 0, 0], guaranteed: {position_m: 0.001, rotation_deg: 1,"
     " max_point_displacement_m: 0.002}}\nbounds: {center: {position_m: [0, 0, 0], rotvec_rad: [0, 0, 0]},"
     " position_m: -0.001, rotation_deg: 1, max_point_displacement_m: 0.002}\n", "not negative"),
    (V2_START.replace("sample_bound_m: 0.001", f"sample_bound_m: 1{'0' * 400}"), "positive length .* not inf"),
    (V2_START + "pose: {position_m: [0, 0, 0], rotvec_rad: [0, 0, 0], guaranteed: {position_m: 0.001, rotation_deg: 1,"
     " max_point_displacement_m: 0.002}}\nbounds: {center: {position_m: [0, 0, 0], rotvec_rad: [0, 0, 0]},"
     f" position_m: -1{'0' * 400}, rotation_deg: 1, max_point_displacement_m: 0.002}}\n", "finite numbers"),
    (V2_START + "pose: {position_m: [true, 0, 0], rotvec_rad: [0, 0, 0], guaranteed: {position_m: 0.001, "
     "rotation_deg: 1, max_point_displacement_m: 0.002}}\nbounds: {center: {position_m: [0, 0, 0], rotvec_rad: [0, 0,"
     " 0]}, position_m: 0.001, rotation_deg: 1, max_point_displacement_m: 0.002}\n", "three numbers each"),
    (V2_START + "pose: {position_m: [0, 0, 0], rotvec_rad: [0, 0, 0], guaranteed: {position_m: yes, rotation_deg: 1,"
     " max_point_displacement_m: 0.002}}\nbounds: {center: {position_m: [0, 0, 0], rotvec_rad: [0, 0, 0]},"
     " position_m: 0.001, rotation_deg: 1, max_point_displacement_m: 0.002}\n", "need position_m, rotation_deg"),
    (V2_START.replace("sample_bound_m: 0.001", "sample_bound_m: true"), "must be a length in metres"),
    ("{{{", "is not valid YAML: .* at line 1")])
def test_damaged_reports_are_refused_with_a_reason(tmp_path, text, match):
    """Each damage in a report that is otherwise whole (its last section, ``search``, is there)."""
    path = tmp_path / "bad.yaml"
    path.write_text(text + V2_END if text.startswith("schema: fixwizard.report/2") else text)
    with pytest.raises(InputError, match=match):
        report.load(path)


@pytest.mark.parametrize("edit, match", [
    (lambda pose: pose.update(ur="p[0.5, -0.1203435, 0.0199822, -0.005898, 0.005470, 0.560606]"),
     r"pose.ur is not p\[0.450059, .*the report was edited in one of them only"),
    (lambda pose: pose.update(quaternion_xyzw=[0.0, 0.0, 0.0, 1.0]),
     r"pose.quaternion_xyzw and rotvec_rad are rotations 32.1 deg apart: the report was edited in one of them only"),
    (lambda pose: pose.update(rotvec_rad=[0.0, 0.0, 7.0]), r"pose.rotvec_rad turns by more than pi rad"),
    (lambda pose: pose.update(rotvec_rad=[1e308, 0.0, 0.0]), r"pose.rotvec_rad turns by more than pi rad"),
])
def test_a_pose_whose_forms_disagree_is_refused(tmp_path, edit, match):
    """A robot program may read the pose's position and rotation vector, its quaternion or its UR literal: a report
    edited in one of them would give programs different poses (and a rotation vector of 1e308 rad none at all)."""
    data = yaml.safe_load(EXAMPLE_REPORT.read_text())
    edit(data["pose"])
    with pytest.raises(InputError, match=match):
        report.load(report.write(tmp_path / "edited.yaml", data))


def test_a_pose_moved_without_its_guarantee_is_refused(tmp_path):
    """The pose moved 3 mm (in every form) while ``pose.guaranteed`` stayed: the guarantee no longer holds about it.
    Moved together with the bounds' centre, the report is read."""
    data = yaml.safe_load(EXAMPLE_REPORT.read_text())
    moved = [0.4530593, -0.1203435, 0.0199822]
    centre = dict(data["bounds"]["center"])
    with_pose(data, moved)
    data["bounds"]["center"] = centre
    with pytest.raises(InputError, match=r"pose.guaranteed \(5.342 mm, 5.352 deg\) is less than the bounds \(4.815 "
                                         r"mm, 4.29 deg\) plus the pose's distance from bounds.center \(3.446 mm, "
                                         r"1.061 deg\), so it does not hold about the pose: the report was edited"):
        report.load(report.write(tmp_path / "moved.yaml", data))
    assert report.load(report.write(tmp_path / "moved.yaml", with_pose(data, moved))).base_T_cad[0, 3] == moved[0]


def test_a_key_given_twice_is_refused_naming_both_lines_never_read_as_the_last(tmp_path):
    """A hand edit that adds a line instead of changing one: PyYAML alone reads the last value, so this report would
    have been a real cell's unique pose; the merge keys of YAML (<<) may still be given again."""
    example = (Path(__file__).resolve().parents[1] / "examples" / "report.yaml").read_text()
    path = tmp_path / "edited.yaml"
    path.write_text(example.replace("simulated: true\n", "simulated: true\nsimulated: false\n"))
    with pytest.raises(InputError, match=r"the key 'simulated' is given twice \(keep one\): at line 8 and at line 9"):
        report.load(path)
    assert parse_yaml("base: &b {x: 1, y: 2}\nmoved:\n  <<: *b\n  x: 3\n")["moved"] == {"x": 3, "y": 2}


def test_writing_replaces_the_file_whole(solved, tmp_path):
    path = tmp_path / "r.yaml"
    path.write_text("old")
    written(solved, tmp_path)
    assert report.load(path).status == solved[2].status
    assert [entry.name for entry in tmp_path.iterdir()] == ["r.yaml"]


@pytest.mark.parametrize("rotvec_rad", [[np.pi, 0.0, 0.0], [0.0, -np.pi, 0.0], [0.0, 0.0, np.pi],
                                        [1.778264576, -1.231115296, -2.278537817]])
def test_a_report_of_a_fixture_turned_half_way_round_is_read_back(tmp_path, rotvec_rad):
    """A fixture mounted the other way round (180 deg about the base's z, or about any axis): the rotation vector,
    rounded to 1e-6 rad, may turn by a hair more than pi, and one of its opposite sign is the same rotation. Such a
    pose as fixwizard writes it was refused as edited ('pose.ur is not p[..., -3.14159], the pose of position_m and
    rotvec_rad'): its UR literal was compared with the rotation vector the matrix gives back, of the other sign."""
    data = yaml.safe_load(EXAMPLE_REPORT.read_text())
    written_pose = with_pose(data, [0.45, -0.12, 0.02], rotvec_rad)["pose"]
    loaded = report.load(report.write(tmp_path / "turned.yaml", data))
    turn = Rotation.from_rotvec(rotvec_rad)
    assert (Rotation.from_matrix(loaded.base_T_cad[:3, :3]).inv() * turn).magnitude() < 2e-6
    assert loaded.ur_pose_to_use() == [*written_pose["position_m"], *written_pose["rotvec_rad"]]
