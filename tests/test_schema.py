"""`smd schema`: a JSON Schema of the scenario format that accepts every bundled scenario and refuses the
structural mistakes the reader refuses (an unknown key, a value of the wrong type, a required key missing)."""

from __future__ import annotations

import copy
import json
import tomllib

import jsonschema
import pytest
from conftest import SCENARIOS

from smdcli import scenario
from smdcli.errors import ScenarioError

BUNDLED = sorted(SCENARIOS.glob("*.toml"))


@pytest.fixture(scope="module")
def validator(tmp_path_factory):
    """The schema as `smd schema` prints it, checked as a schema."""
    from smdcli.cli import run as smd
    from typer.testing import CliRunner

    with CliRunner().isolation() as streams:
        assert smd(["schema"]) == 0
        text = streams[0].getvalue().decode()
    schema = json.loads(text)
    jsonschema.Draft202012Validator.check_schema(schema)
    return jsonschema.Draft202012Validator(schema)


@pytest.mark.parametrize("path", BUNDLED, ids=lambda p: p.stem)
def test_every_bundled_scenario_validates(validator, path):
    errors = [e.message for e in validator.iter_errors(tomllib.loads(path.read_text()))]
    assert not errors, errors


def _reader_refuses(doc: dict, path) -> bool:
    import tomli_w

    try:
        scenario.parse(tomli_w.dumps(doc), str(path))
    except ScenarioError:
        return True
    return False


def _mutations(doc: dict):
    """(what, mutated document) for each structural mistake in each table of a scenario."""
    for key, value in doc.items():
        tables = value if isinstance(value, list) and value and isinstance(value[0], dict) else \
            [value] if isinstance(value, dict) else []
        for i, table in enumerate(tables):
            where = f"{key}[{i}]" if isinstance(value, list) else key
            unknown = copy.deepcopy(doc)
            (unknown[key][i] if isinstance(value, list) else unknown[key])["bogus_key"] = 1.0
            yield f"{where}: an unknown key", unknown
            for field, entry in table.items():
                if isinstance(entry, (int, float)) and not isinstance(entry, bool):
                    wrong = copy.deepcopy(doc)
                    (wrong[key][i] if isinstance(value, list) else wrong[key])[field] = "a word"
                    yield f"{where}.{field}: a string for a number", wrong
    missing = copy.deepcopy(doc)
    missing.pop("time")
    yield "no [time]", missing
    yield "an unknown table", {**copy.deepcopy(doc), "bogus_table": {"x": 1.0}}


@pytest.mark.parametrize("path", BUNDLED, ids=lambda p: p.stem)
def test_the_schema_refuses_the_structural_mistakes_the_reader_refuses(validator, path):
    doc = tomllib.loads(path.read_text())
    disagreements = []
    for what, mutated in _mutations(doc):
        if not _reader_refuses(mutated, path):
            continue  # a mutation the reader takes (a string where it also reads a number spec): not structural
        if validator.is_valid(mutated):
            disagreements.append(what)
    assert not disagreements, disagreements
