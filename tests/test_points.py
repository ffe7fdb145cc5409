"""The POINTS file as spreadsheets and editors write it: byte-order marks, headers, typos in any row, and
YAML built to blow up. Every tap counts or the file is refused naming the row; messages stay short."""

import os
import re
import time

import numpy as np
import pytest

from conftest import piped
from fixwizard.errors import QUOTE_LIMIT, InputError
from fixwizard.points import load_points, write_points
from fixwizard.report import load as load_report

TAPS = np.random.default_rng(18).uniform(-0.5, 0.5, (20, 3))
MESSAGE_LIMIT = 600  # characters: the path, a quoted value of at most QUOTE_LIMIT and the words around it


def csv_text(rows: list[str]) -> str:
    return "\r\n".join(rows) + "\r\n"


def tap_rows(taps: np.ndarray = TAPS) -> list[str]:
    return [",".join(f"{value:.6f}" for value in tap) for tap in taps]


@pytest.mark.parametrize("header", [[], ["x,y,z"], ["X (m); Y (m)", ], ["ball x,ball y,ball z"]])
def test_excel_csv_utf8_with_a_byte_order_mark_keeps_every_tap(tmp_path, header):
    path = tmp_path / "taps.csv"
    path.write_bytes(b"\xef\xbb\xbf" + csv_text(header + tap_rows()).encode())
    np.testing.assert_allclose(load_points(path), TAPS, atol=1e-6)


@pytest.mark.parametrize("row", [1, 10, 20])
@pytest.mark.parametrize("typo", ["0.1,0.2,0.3x", "0.1,,0.3", "0.1 0.2 0.3", "O.1,0.2,0.3", "-,0.2,0.3"])
def test_a_typo_in_any_row_is_refused_naming_its_line(tmp_path, row, typo):
    rows = tap_rows()
    rows[row - 1] = typo
    path = tmp_path / "taps.csv"
    path.write_text(csv_text(["x,y,z", *rows]))
    with pytest.raises(InputError, match=f"tap {row} \\(line {row + 1} of {path}\\)") as caught:
        load_points(path)
    assert "numbers" in str(caught.value)
    path.write_text(csv_text(rows))  # no header: the first row is a tap like any other
    with pytest.raises(InputError, match=f"tap {row} \\(line {row} of {path}\\)"):
        load_points(path)


def test_a_first_row_with_any_number_is_a_tap_not_a_header(tmp_path):
    path = tmp_path / "taps.csv"
    path.write_text(csv_text(["x,y,0.3", *tap_rows()]))
    with pytest.raises(InputError, match="tap 1 \\(line 1 of .*\\) is not three numbers: \\['x', 'y', '0.3'\\]"):
        load_points(path)


def test_blank_lines_do_not_shift_the_line_named(tmp_path):
    path = tmp_path / "taps.csv"
    path.write_text("x,y,z\n\n0.1,0.2,0.3\n\n0.1,0.2\n")
    with pytest.raises(InputError, match="tap 2 \\(line 5 of .*\\) has 2 numbers"):
        load_points(path)


@pytest.mark.parametrize("line_end", ["\r", "\n", "\r\n"])
def test_every_line_end_keeps_every_tap_and_names_the_right_line(tmp_path, line_end):
    """Excel for Mac before 2016 saves CSV with CR alone at each line end: refused in the csv module's words ("new-line
    character seen in unquoted field - do you need to open the file in universal-newline mode?")."""
    path = tmp_path / "taps.csv"
    path.write_text(line_end.join(["x,y,z", *tap_rows()]) + line_end, newline="")
    np.testing.assert_allclose(load_points(path), TAPS, atol=1e-6)
    rows = tap_rows()
    rows[4] = "0.1,0.2"
    path.write_text(line_end.join(["x,y,z", *rows]) + line_end, newline="")
    with pytest.raises(InputError, match="tap 5 \\(line 6 of .*\\) has 2 numbers"):
        load_points(path)


BOMB = "\n".join(["a: &a [1, 2, 3, 4, 5, 6, 7, 8, 9]"] + [
    f"{chr(98 + level)}: &{chr(98 + level)} [{', '.join(['*' + chr(97 + level)] * 9)}]" for level in range(8)])


@pytest.mark.parametrize("tail", ["points_m: [*i, *i]", "frame: *i\npoints_m: []", "points_m: *i"])
def test_an_alias_expanding_yaml_gives_a_short_message_quickly(tmp_path, tail):
    path = tmp_path / "taps.yaml"
    path.write_text(f"{BOMB}\n{tail}\n")
    started = time.perf_counter()
    with pytest.raises(InputError) as caught:
        load_points(path)
    assert time.perf_counter() - started < 2.0
    assert len(str(caught.value)) < MESSAGE_LIMIT


def test_a_foreign_report_with_an_alias_bomb_as_schema_gives_a_short_message(tmp_path):
    path = tmp_path / "report.yaml"
    path.write_text(f"{BOMB}\nschema: *i\n")
    with pytest.raises(InputError, match="not a fixwizard report") as caught:
        load_report(path)
    assert len(str(caught.value)) < MESSAGE_LIMIT


@pytest.mark.parametrize("sign", ["", "-"])
@pytest.mark.parametrize("zeros", [400, 5000])  # Python refuses to convert a text of over 4300 digits to an int
def test_an_integer_beyond_any_float_is_a_coordinate_that_is_not_finite(tmp_path, sign, zeros):
    path = tmp_path / "taps.yaml"
    path.write_text(f"frame: base\npoints_m:\n- [{sign}1{'0' * zeros}, 0, 0]\n- [0, 0, 0]\n- [0, 0.01, 0]\n")
    with pytest.raises(InputError, match="tap 1 in .* has a coordinate that is not a finite number") as caught:
        load_points(path)
    assert len(str(caught.value)) < MESSAGE_LIMIT


def test_a_huge_row_is_quoted_in_part(tmp_path):
    path = tmp_path / "taps.csv"
    path.write_text(csv_text(["1," + "9" * 100_000 + "x,3", *tap_rows()]))
    with pytest.raises(InputError) as caught:
        load_points(path)
    assert len(str(caught.value)) < MESSAGE_LIMIT and str(caught.value).count("9") <= QUOTE_LIMIT


def test_a_cell_longer_than_the_csv_reader_takes_is_refused_naming_its_line(tmp_path):
    path = tmp_path / "taps.csv"
    path.write_text(csv_text([*tap_rows()[:2], "0." + "1" * 200_000 + ",0.2,0.3"]))
    with pytest.raises(InputError, match=r"line 3 of .*taps.csv") as caught:
        load_points(path)
    assert len(str(caught.value)) < MESSAGE_LIMIT


def test_random_garbage_is_a_short_message_or_taps(tmp_path):
    rng = np.random.default_rng(7)
    alphabet = list("0123456789.,-e \n\t;:[]{}&*!#'\"xyzm") + ["\ufeff", "nan", "inf", "points_m:", "frame: base"]
    for trial in range(300):
        text = "".join(rng.choice(alphabet, size=int(rng.integers(0, 200))))
        for suffix in (".csv", ".yaml"):
            path = tmp_path / f"t{trial}{suffix}"
            path.write_text(text)
            try:
                taps = load_points(path)
            except InputError as error:
                assert len(str(error)) < MESSAGE_LIMIT
            else:
                assert taps.ndim == 2 and taps.shape[1] == 3 and np.all(np.isfinite(taps))


@pytest.mark.parametrize("suffix", [".stl", ".PLY", ".obj"])
def test_a_mesh_given_as_the_points_file_says_the_arguments_may_be_swapped(tmp_path, suffix):
    path = tmp_path / f"fixture{suffix}"
    path.write_bytes(b"solid x\x00\xff")
    with pytest.raises(InputError, match="is a mesh, not a points file .* wrong order"):
        load_points(path)


def test_a_folder_as_points_file_is_called_a_folder(tmp_path):
    with pytest.raises(InputError, match="is a folder, not a points file"):
        load_points(tmp_path)


@pytest.mark.parametrize("separator, name", [(";", "';'"), ("\t", "tabs"), (" ", "spaces"), ("; ", "';'")])
@pytest.mark.parametrize("header", [False, True])
def test_other_separators_than_commas_are_named_with_the_one_fixwizard_reads(tmp_path, separator, name, header):
    """Spaces and tabs were 'not three numbers' without the fix. Nothing is guessed: the file is refused."""
    rows = [row.replace(",", separator) for row in tap_rows()]
    path = tmp_path / "taps.csv"
    path.write_text(csv_text(([separator.join("xyz")] if header else []) + rows))
    line = 1 + header
    with pytest.raises(InputError, match=re.escape(f"tap 1 (line {line} of {path}) separates the numbers with {name} "
                                                   f"({rows[0]!r}): fixwizard reads CSV with commas between x, y and "
                                                   "z, one tap per line, and '.' as the decimal point")):
        load_points(path)


@pytest.mark.parametrize("line, comment", [(2, "# taps of 6 Dec"), (5, "# 3 mm ball, 0.5 mm"),
                                           (1, "#0.1,0.2,0.3")])
def test_a_comment_line_among_the_taps_is_named_as_a_comment_to_delete(tmp_path, line, comment):
    """A first row of names is a header; a '#' line after it, or a first row with numbers in it (a tap commented
    out), is a comment that fixwizard's CSV does not have (it was 'not three numbers')."""
    lines = ["x,y,z", *tap_rows()] if line > 1 else tap_rows()
    lines.insert(line - 1, comment)
    path = tmp_path / "taps.csv"
    path.write_text(csv_text(lines))
    with pytest.raises(InputError, match=re.escape(f"(line {line} of {path}) is a comment ({comment!r}): a points "
                                                   "CSV has no comments; delete the line")):
        load_points(path)


def test_a_yaml_points_file_of_several_documents_says_so(tmp_path):
    """PyYAML's words were 'but found another document'."""
    path = tmp_path / "taps.yaml"
    one = "frame: base\npoints_m: [[0.1, 0.2, 0.3], [0.2, 0.3, 0.4], [0.3, 0.1, 0.2]]\n"
    path.write_text(f"---\n{one}---\n{one}")
    with pytest.raises(InputError, match=re.escape(f"{path} is not valid YAML: it holds more than one document (the "
                                                   "second starts at line 4; '---' separates them), and a fixwizard "
                                                   "file is one: keep the one meant")):
        load_points(path)


@pytest.mark.parametrize("header", ["x_m,y_m,z_m\n", ""])
def test_csv_in_a_file_not_named_csv_is_said_to_need_the_name(tmp_path, header):
    """CSV saved as taps.txt (or piped in as /dev/stdin) is read as YAML: the message only asked for YAML."""
    path = tmp_path / "taps.txt"
    path.write_text(header + "0.1,0.2,0.3\n0.2,0.3,0.4\n0.3,0.1,0.2\n")
    with pytest.raises(InputError, match="it looks like CSV, which fixwizard reads from a file named .csv"):
        load_points(path)


def test_a_yaml_points_file_indented_with_tabs_says_to_use_spaces(tmp_path):
    """An editor set to indent with tabs: PyYAML's words were only "found character '\\t' that cannot start any
    token"."""
    path = tmp_path / "taps.yaml"
    path.write_text("frame: base\npoints_m:\n\t- [0.1, 0.2, 0.3]\n\t- [0.2, 0.3, 0.4]\n\t- [0.3, 0.1, 0.2]\n")
    with pytest.raises(InputError, match=re.escape(f"{path} is not valid YAML: found character '\\t' that cannot start "
                                                   "any token at line 3, column 1: YAML takes spaces there, not tabs; "
                                                   "replace the tabs with spaces")):
        load_points(path)


@pytest.mark.parametrize("name", ["taps.yaml", "report.yaml"])
def test_lists_nested_too_deeply_to_read_are_refused_in_a_short_message(tmp_path, name):
    path = tmp_path / name
    path.write_text("points_m: " + "[" * 100_000)
    read = load_points if name == "taps.yaml" else load_report
    with pytest.raises(InputError, match="nested too deeply to read") as caught:
        read(path)
    assert len(str(caught.value)) < MESSAGE_LIMIT


@pytest.mark.parametrize("suffix", [".csv", ".yaml"])
def test_a_point_cloud_is_refused_by_its_size_before_it_is_read(tmp_path, suffix):
    cloud = np.random.default_rng(3).uniform(-0.5, 0.5, (60_000, 3))
    path = tmp_path / f"scan{suffix}"
    path.write_text(csv_text(tap_rows(cloud)) if suffix == ".csv"
                    else "points_m:\n" + "".join(f"- [{row}]\n" for row in tap_rows(cloud)))
    started = time.perf_counter()
    with pytest.raises(InputError, match=r"holds \d+\.\d MB: a points file holds the taps .* not a point cloud"):
        load_points(path)
    assert time.perf_counter() - started < 0.5


def test_a_point_cloud_piped_in_is_refused_after_its_first_megabyte(tmp_path):
    """A pipe (``solve MESH /dev/stdin``) has no size to look at: the whole stream was read, then parsed for
    minutes."""
    reading, writing = os.pipe()
    cloud = ("points_m:\n" + "- [0.1, 0.2, 0.3]\n" * 200_000).encode()  # 3.6 MB
    feeder = piped(writing, cloud)
    try:
        started = time.perf_counter()
        with pytest.raises(InputError, match=r"holds more than 1 MB: a points file holds the taps .* point cloud"):
            load_points(f"/proc/self/fd/{reading}")
        assert time.perf_counter() - started < 0.5
    finally:
        os.close(reading)
        feeder.join(timeout=10)


def test_true_or_false_is_no_coordinate(tmp_path):
    path = tmp_path / "taps.yaml"
    path.write_text("frame: base\npoints_m:\n- [0.1, 0.2, 0.3]\n- [0.4, true, 0.2]\n")
    with pytest.raises(InputError, match="tap 2 in .* is not three numbers: \\[0.4, True, 0.2\\]"):
        load_points(path)


@pytest.mark.parametrize("name", ["taps.csv", "taps.CSV", "taps.yaml", "taps.txt"])
def test_points_written_are_read_back_exactly_whatever_the_suffix(tmp_path, name):
    """import-poses -o taps.csv wrote YAML into taps.csv, which no reader of POINTS took ('not three numbers')."""
    path = write_points(tmp_path / name, TAPS, source=["a.pose"])
    assert np.array_equal(load_points(path), TAPS)
