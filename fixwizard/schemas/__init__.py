"""JSON Schemas (draft 2020-12) of the files fixwizard writes: the report, the tool-tip calibration and one line of
a session journal or of a tip calibration's journal. They document the layouts for other programs; fixwizard's own
loaders check what they need without them."""

import json
from pathlib import Path

FOLDER = Path(__file__).resolve().parent
FILES = {"fixwizard.report/2": "report-2.schema.json", "fixwizard.tip/1": "tip-1.schema.json",
         "fixwizard.session/1": "session-1.schema.json",
         "fixwizard.tip-calibration-journal/1": "tip-calibration-journal-1.schema.json"}


def schema_path(schema_id: str) -> Path:
    """The JSON Schema file of a document's ``schema`` value, e.g. ``fixwizard.report/2``."""
    return FOLDER / FILES[schema_id]


def load_schema(schema_id: str) -> dict:
    """The JSON Schema of a document's ``schema`` value as a dict."""
    return json.loads(schema_path(schema_id).read_text(encoding="utf-8"))
