"""Reading fixwizard's own YAML documents: parse, check the schema, and say what is wrong."""

import contextlib
import math
import sys
from pathlib import Path
from typing import Any

import yaml

from fixwizard.errors import InputError, file_problem, other_version, quoted


def yaml_problem(error: yaml.YAMLError) -> str:
    """A YAML syntax error in one line: what and where (line, column)."""
    if isinstance(error, yaml.composer.ComposerError) and error.problem == "but found another document":
        line = error.problem_mark.line + 1 if error.problem_mark is not None else "?"
        return (f"it holds more than one document (the second starts at line {line}; '---' separates them), and a "
                "fixwizard file is one: keep the one meant and delete the others")
    if isinstance(error, yaml.MarkedYAMLError) and error.problem_mark is not None:
        mark = error.problem_mark
        where = f"{error.problem} at line {mark.line + 1}, column {mark.column + 1}"
        if error.problem is not None and "'\\t'" in error.problem:  # an editor that indents with tabs
            return f"{where}: YAML takes spaces there, not tabs; replace the tabs with spaces"
        return where
    return str(error).splitlines()[0]


# fixwizard's documents take under 100 kB (a report of 1000 taps and a few candidate poses; 1 MB holds 1500 of them);
# PyYAML's own parser reads 60-200 kB/s (libyaml's, tried first, about ten times that), so a larger file (a point cloud
# saved as .yaml among the reports) would hold up its reader, serve's calls included, for minutes (13.6 MB: 3.6 min
# with PyYAML's): refused before it is read, as POINTS are.
MAX_DOCUMENT_BYTES = 1_000_000


class _Checks(yaml.constructor.SafeConstructor):
    """``yaml.safe_load``'s constructor, except that an integer too large for a float reads as +-inf (also one of over
    4300 digits, which Python refuses to convert): where a number is read, it is then refused as not finite, with
    that place's message (``float()`` of it would raise); and a key
    given twice in one mapping is an error (PyYAML keeps the last one silently: a report with ``status`` twice
    would be read as whichever came last)."""

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict:
        first_at: dict[tuple[str, str], yaml.Mark] = {}
        for key_node, _ in node.value:
            if not isinstance(key_node, yaml.ScalarNode) or key_node.tag == "tag:yaml.org,2002:merge":
                continue  # keys merged in with << may be given again: that is what merging is for
            key = (key_node.tag, key_node.value)
            if key in first_at:
                raise yaml.constructor.ConstructorError(
                    None, None, f"the key {quoted(key_node.value)} is given twice (keep one): at line "
                    f"{first_at[key].line + 1} and", key_node.start_mark)
            first_at[key] = key_node.start_mark
        return super().construct_mapping(node, deep)


def _int_or_infinity(loader: yaml.SafeLoader, node: yaml.ScalarNode) -> int | float:
    try:
        value: int = loader.construct_yaml_int(node)
    except ValueError:  # a decimal of over 4300 digits, which Python will not convert: far beyond any float
        return -math.inf if str(node.value).lstrip().startswith("-") else math.inf
    return value if abs(value) <= sys.float_info.max else (math.inf if value > 0 else -math.inf)


_Checks.add_constructor("tag:yaml.org,2002:int", _int_or_infinity)


class _Loader(_Checks, yaml.SafeLoader):
    """``_Checks`` on PyYAML's own parser: what a document that does not parse gets its message from."""


# The same checks on libyaml's parser (where PyYAML has it): about ten times faster, which is what a folder of a
# year's reports needs (PyYAML's own parser took 25-70 ms per report, so serve took 72 s to start on 1000 of them,
# and every call waited as long after they were all touched); libyaml refuses nesting deeper than 1000 levels.
_FastLoader: type | None = type("_FastLoader", (_Checks, yaml.CSafeLoader), {}) if yaml.__with_libyaml__ else None


def parse_yaml(text: str) -> Any:
    """The YAML document in ``text``, as ``yaml.safe_load`` (raises ``yaml.YAMLError``) reads it but for integers
    beyond any float (+-inf), and a ``yaml.YAMLError`` for lists or mappings nested too deeply to read. Read with
    libyaml where it can; a document it does not take is read again by PyYAML's parser, whose errors say where."""
    if _FastLoader is not None:
        with contextlib.suppress(Exception):  # any refusal is said as PyYAML's parser says it
            return yaml.load(text, Loader=_FastLoader)  # safe constructors only: no arbitrary objects
    try:
        return yaml.load(text, Loader=_Loader)  # a SafeLoader subclass: no arbitrary objects
    except RecursionError:
        raise yaml.YAMLError("lists or mappings nested too deeply to read (no fixwizard file nests so)") from None


def parse_yaml_start(text: str, tries: int = 8) -> Any:
    """The document of a start of ``text`` that parses, cut back before the line where each error's part began
    (``tries`` times at most): what a file cut short or damaged part-way still says before the damage; None when
    nothing does."""
    for _ in range(tries):
        try:
            return parse_yaml(text)
        except yaml.MarkedYAMLError as error:
            lines = text.splitlines(keepends=True)
            marks = [mark.line for mark in (error.context_mark, error.problem_mark) if mark is not None]
            cut = min([*marks, len(lines) - 1])  # where the broken part began, or at least one line less
            if not marks or cut <= 0:
                return None
            text = "".join(lines[:cut])
        except yaml.YAMLError:
            return None
    return None


def load_document(path: Path, schema: str | tuple[str, ...], what: str, error: type[InputError] = InputError,
                  hint: str = "") -> dict:
    """The YAML mapping in ``path`` if its ``schema`` key matches (one of several, the first the current one);
    ``error`` names the ``what`` otherwise, also for a file over ``MAX_DOCUMENT_BYTES``, refused before it is read."""
    try:
        size = path.stat().st_size
        with path.open("rb") as stream:  # a pipe has no size to look at: read no more than any document holds
            text = stream.read(MAX_DOCUMENT_BYTES + 1) if size <= MAX_DOCUMENT_BYTES else b""
        if size > MAX_DOCUMENT_BYTES or len(text) > MAX_DOCUMENT_BYTES:
            held = f"{size / 1e6:.1f} MB" if size > MAX_DOCUMENT_BYTES else f"more than {MAX_DOCUMENT_BYTES / 1e6:g} MB"
            raise error(f"{path} holds {held}, more than any {what} (at most {MAX_DOCUMENT_BYTES / 1e6:g} MB): it is "
                        f"no {what}; give the file fixwizard wrote")
        data = parse_yaml(text.decode("utf-8-sig"))
    except OSError as problem:
        raise error(f"cannot read the {what}: {file_problem(problem, path, 'read')}") from problem
    except UnicodeDecodeError as problem:
        raise error(f"cannot read the {what} {path}: it is not UTF-8 text ({problem.reason})") from problem
    except yaml.YAMLError as problem:
        raise error(f"the {what} {path} is not valid YAML: {yaml_problem(problem)}") from problem
    found = data.get("schema") if isinstance(data, dict) else None
    accepted = (schema,) if isinstance(schema, str) else schema
    if found not in accepted:
        newer = other_version(path, what, found, accepted)
        if newer is not None:
            raise error(newer)
        raise error(f"{path} is not a {what}: expected 'schema: {accepted[0]}', found {quoted(found)}.{hint}")
    return data
