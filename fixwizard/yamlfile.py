"""Reading fixwizard's own YAML documents: parse, check the schema, and say what is wrong."""

from pathlib import Path

import yaml

from fixwizard.errors import InputError


def load_document(path: Path, schema: str, what: str, error: type[InputError] = InputError, hint: str = "") -> dict:
    """The YAML mapping in ``path`` if its ``schema`` key matches; ``error`` names the ``what`` otherwise."""
    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, yaml.YAMLError) as problem:
        raise error(f"cannot read the {what} {path}: {problem}") from problem
    found = data.get("schema") if isinstance(data, dict) else None
    if found != schema:
        raise error(f"{path} is not a {what}: expected 'schema: {schema}', found {found!r}.{hint}")
    return data
