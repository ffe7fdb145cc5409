"""``fixwizard export REPORT --format urscript|ros2|json``: the report's pose for robot programs.

- ``urscript``: a global ``fixture_<name> = p[x, y, z, rx, ry, rz]`` (m, rad; the CAD frame in the base frame;
  numbers as fixwizard's own UR programs write them, without exponents) with comment lines saying what it is, to
  load in a program (a Script node in BeforeStart);
- ``ros2``: a ``geometry_msgs/msg/TransformStamped`` (YAML) from the UR base frame (``base``, as the UR ROS 2
  driver names the controller's base; not ``base_link``, which is turned by 180 deg about z) to the fixture, and
  the ``tf2_ros static_transform_publisher`` arguments that publish it; the fixture's frame is
  ``--child-frame-id``, by default its name (``default_child_frame_id``: ``cell2-bracket`` gives ``cell2_bracket``,
  ``1-a.b`` gives ``fixture_1_a_b``, as a ROS name starts with a letter);
- ``json``: the whole report as JSON, for anything else.

The pose is the one to use (``Report.pose_to_use``). URScript and ROS 2 are for robots: only a ``unique`` report
is exported in them, and a simulated one only with ``--allow-simulated`` (marked SIMULATED). JSON carries the
status and ``simulated`` itself and exports any report. ``-o`` never writes over the report or its mesh.
"""

import argparse
import json
import re
import sys
import time

import yaml
from scipy.spatial.transform import Rotation

from fixwizard import report
from fixwizard.atomic import check_output, write_text_atomic
from fixwizard.cli import ROS_BASE_FRAME_ID as BASE_FRAME_ID
from fixwizard.errors import InputError, one_line
from fixwizard.robot.ur_script import pose_literal

SUFFIXES = {"urscript": ".script", "ros2": ".yaml", "json": ".json"}  # of a file of each format, as suggested


def _identifier(name: str) -> str:
    """A URScript or ROS name part from a fixture name: letters, digits and ``_``."""
    return re.sub(r"[^A-Za-z0-9_]", "_", name)


def default_child_frame_id(name: str) -> str:
    """The fixture's ROS frame when none is given: ``_identifier`` of its name, with ``fixture_`` before it when
    that would start with a digit (so ``1-a.b`` gives ``fixture_1_a_b``, the URScript variable's name)."""
    identifier = _identifier(name)
    return identifier if re.match(r"[A-Za-z_]", identifier) else f"fixture_{identifier}"


def _usable(loaded: report.Report, allow_simulated: bool, format_name: str) -> report.Guarantee:
    """The guarantee of the pose to use; InputError when a robot must not use this report."""
    pose = loaded.pose_to_use()
    if loaded.status != "unique" or pose is None:
        raise InputError(f"the report {loaded.path} is {loaded.status}, so a robot must not use its pose: calibrate "
                         f"the fixture again (--format json exports any report, with its status)")
    if loaded.simulated and not allow_simulated:
        raise InputError(f"the report {loaded.path} comes from the simulated cell, not from a real fixture: export "
                         f"it to {format_name} only for a test, with --allow-simulated")
    return pose[1]


def _comment_lines(loaded: report.Report, guarantee: report.Guarantee, prefix: str) -> list[str]:
    lines = [f"fixwizard export of {loaded.path} ({loaded.schema}), created {loaded.created.isoformat()}",
             (f"fixture '{loaded.name}' (mesh {loaded.mesh.name}, {loaded.mesh_units}): its CAD frame in the robot "
              "base frame"),
             (f"guaranteed: the true pose lies within {report.round_up(guarantee.position_m * 1e3, 2):.2f} mm (CAD "
              f"origin), {report.round_up(guarantee.rotation_deg, 2):.2f} deg and "
              f"{report.round_up(guarantee.max_point_displacement_m * 1e3, 2):.2f} mm (any fixture point) of this "
              "one")]
    if loaded.simulated:
        lines.insert(0, "SIMULATED: from the simulated cell, not a real fixture's pose; for tests only")
    return [f"{prefix} {one_line(line)}" for line in lines]  # a path's line break would start a line of code


def _ur_values(loaded: report.Report) -> list[float]:
    values = loaded.ur_pose_to_use()
    assert values is not None  # _usable refused a report without a pose
    return values


def urscript_text(loaded: report.Report, allow_simulated: bool = False) -> str:
    """A URScript file defining ``fixture_<name>`` as the pose to use."""
    guarantee = _usable(loaded, allow_simulated, "URScript")
    literal = pose_literal(_ur_values(loaded))
    variable = f"fixture_{_identifier(loaded.name)}"
    lines = _comment_lines(loaded, guarantee, "#")
    lines += ["# p[x, y, z, rx, ry, rz]: metres and a rotation vector in radians. A point taught in the CAD frame:",
              f"#   pose_trans({variable}, p[0.01, 0.02, 0.0, 0.0, 0.0, 0.0])",
              f"{variable} = {literal}"]
    return "\n".join(lines) + "\n"


def ros2_document(loaded: report.Report, frame_id: str = BASE_FRAME_ID, child_frame_id: str | None = None,
                  allow_simulated: bool = False) -> dict:
    """The ``TransformStamped`` from ``frame_id`` to the fixture (``child_frame_id``, by default
    ``default_child_frame_id`` of its name) and the ``static_transform_publisher`` arguments; frame ids given are
    checked by the command line (``cli._ros_frame_id``)."""
    _usable(loaded, allow_simulated, "ROS 2")
    child = default_child_frame_id(loaded.name) if child_frame_id is None else child_frame_id
    values = _ur_values(loaded)
    quaternion = Rotation.from_rotvec(values[3:]).as_quat()
    quaternion = [float(value) for value in (quaternion if quaternion[3] >= 0 else -quaternion)]
    translation = dict(zip("xyz", values[:3], strict=True))
    rotation = dict(zip("xyzw", quaternion, strict=True))
    arguments = [*(item for axis in "xyz" for item in (f"--{axis}", repr(translation[axis]))),
                 *(item for axis in "xyzw" for item in (f"--q{axis}", repr(rotation[axis]))),
                 "--frame-id", frame_id, "--child-frame-id", child]
    return {"transform_stamped": {"header": {"stamp": {"sec": 0, "nanosec": 0}, "frame_id": frame_id},
                                  "child_frame_id": child,
                                  "transform": {"translation": translation, "rotation": rotation}},
            "static_transform_publisher": {"arguments": arguments,
                                           "command": "ros2 run tf2_ros static_transform_publisher "
                                                      + " ".join(arguments)}}


def ros2_text(loaded: report.Report, frame_id: str = BASE_FRAME_ID, child_frame_id: str | None = None,
              allow_simulated: bool = False) -> str:
    document = ros2_document(loaded, frame_id, child_frame_id, allow_simulated)
    guarantee = _usable(loaded, allow_simulated, "ROS 2")
    lines = _comment_lines(loaded, guarantee, "#")
    lines.append(f"# frame '{frame_id}': the UR controller's base frame (the UR ROS 2 driver's 'base', not "
                 "'base_link'); metres, quaternion x y z w")
    return "\n".join(lines) + "\n" + yaml.safe_dump(document, sort_keys=False, width=200)


def json_text(loaded: report.Report) -> str:
    """The whole report as JSON (times as ISO 8601 text); InputError for a number JSON cannot hold (a hand-edited
    report's inf or nan)."""
    try:
        return json.dumps(loaded.data, indent=2, default=str, allow_nan=False) + "\n"
    except ValueError as error:
        raise InputError(f"{loaded.path} holds a number that is not finite ({error}), which JSON cannot hold: "
                         "solve again for a fresh report") from error


def export_text(loaded: report.Report, format_name: str, frame_id: str = BASE_FRAME_ID,
                child_frame_id: str | None = None, allow_simulated: bool = False) -> str:
    if format_name == "urscript":
        return urscript_text(loaded, allow_simulated)
    if format_name == "ros2":
        return ros2_text(loaded, frame_id, child_frame_id, allow_simulated)
    return json_text(loaded)


def export_command(args: argparse.Namespace) -> int:
    """``fixwizard export``: the text to ``-o`` (``-`` or none: standard output)."""
    loaded = report.load(args.report)
    output = None if args.output in (None, "", "-") else args.output
    if output:  # the mesh as ``verify.fixture_of`` finds it
        check_output(output, [("report", args.report), ("report's mesh", loaded.mesh)],
                     "give another output path with -o", f"{loaded.name}{SUFFIXES[args.format]}")
    frame_id = BASE_FRAME_ID if args.frame_id is None else args.frame_id
    text = export_text(loaded, args.format, frame_id, args.child_frame_id, args.allow_simulated)
    ahead_s = loaded.created.timestamp() - time.time()
    if ahead_s > report.FUTURE_TOLERANCE_S:
        print(f"fixwizard: note: the report {args.report} is dated {ahead_s / 3600:.1f} h in the future: check the "
              "clocks of the PCs (serve refuses it until then)", file=sys.stderr)
    if output:
        write_text_atomic(output, text)
        print(f"{args.format} of '{loaded.name}' written to {output}", file=sys.stderr)
    else:
        sys.stdout.write(text)
    return 0

