"""TOML file or text -> validated Scenario: load, parse, parse_document, and the checks across tables.

Must not import: model, solvers, or any layer above."""

from __future__ import annotations

import math
import re
import tomllib
from pathlib import Path

from smdcli.errors import ScenarioError
from smdcli.scenario.plain_toml import loads_plain
from smdcli.scenario.forces import _ANY_FORCE_KEYS, GROUND_KEYS, _read_force, _read_ground_motion
from smdcli.scenario.options import (EXPECT_KEYS, FIT_KEYS, IDA_KEYS, OPTIMIZE_KEYS, SWEEP_KEYS, _read_expect,
                                     _read_fit, _read_ida, _read_optimize, _read_solver, _read_sweep)
from smdcli.scenario.reader import (_SYSTEM_KEYS, _TIME_KEYS, _TOP_KEYS, MAX_SCENARIO_BYTES, _NotRegular, _Table,
                                    read_regular_file)
from smdcli.scenario.spec import MAX_SAMPLES, Scenario, SolverSpec, TimeSpec
from smdcli.shapes.registry import SHAPES
from smdcli.scenario.structure import (BUILDING_KEYS, DAMPING_KEYS, _read_building, _read_damping, _read_elements,
                                      _read_masses, _read_system, _read_time, read_law_elements)


def load(path: str | Path) -> Scenario:
    """Read and validate a scenario file; raises ScenarioError on any bad input."""
    path = Path(path)
    file = str(path)
    if path.is_dir():
        raise ScenarioError(file, None, "is a directory, expected a scenario .toml file")
    try:
        data = read_regular_file(path, MAX_SCENARIO_BYTES)
    except FileNotFoundError:
        raise ScenarioError(file, None, "no such file") from None
    except _NotRegular as exc:
        raise ScenarioError(file, None, f"{exc}, expected a scenario .toml file") from None
    except OSError as exc:
        raise ScenarioError(file, None, f"cannot be read: {exc.strerror}") from None
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data[: exc.start].count(b"\n") + 1
        raise ScenarioError(file, None, "is not UTF-8 text", line=line) from None
    return parse(text, file)


def parse(text: str, file: str = "<scenario>") -> Scenario:
    """Validate scenario text; `file` names it in messages and anchors relative paths."""
    if not text.strip():
        raise ScenarioError(file, None, "is empty; a scenario needs at least [time] and one [[mass]] or [system]")
    text = text.removeprefix("\ufeff")  # a byte-order mark, as Windows editors save UTF-8
    _refuse_many_samples_early(text, file)
    try:
        doc = loads_plain(text)  # a large scene's plain tables, three times faster; else None, and tomllib reads it
        if doc is None:
            doc = tomllib.loads(text)
    except RecursionError:
        raise ScenarioError(file, None, "invalid TOML: arrays or tables nested too deeply") from None
    except tomllib.TOMLDecodeError as exc:  # before ValueError, its base class: the parser's own words and line
        message = str(exc)
        match = re.search(r"\(at line (\d+), column (\d+)\)", message)
        line = int(match.group(1)) if match else None
        message = re.sub(r"\s*\(at line \d+, column \d+\)", "", message)
        column = f" (column {match.group(2)})" if match else ""
        if "(at end of document)" in message:  # where the file ran out: its last line
            line = text.count("\n") + (0 if text.endswith("\n") else 1)
            message, column = message.replace("(at end of document)", "").strip(), " (at the end of the file)"
        raise ScenarioError(file, None, f"invalid TOML: {message}{column}", line=line) from None
    except ValueError as exc:  # Python refuses integer literals of more than 4300 digits
        raise ScenarioError(file, None, f"invalid TOML: a number literal too long ({str(exc).split(':')[0]})") from None
    return parse_document(doc, text, file, decoded_from_text=True)


def parse_document(doc: dict, text: str, file: str = "<scenario>", decoded_from_text: bool = False) -> Scenario:
    """Validate an already-decoded TOML document (a sweep member is one, edited; decoded_from_text: doc is text's
    whole decoding, unedited)."""
    if not (decoded_from_text and _MAY_DECODE_TO_CONTROL.search(text) is None):
        _refuse_control_characters(file, doc, "")
    top = _Table(file, "", doc, _TOP_KEYS)
    title = top.string("title", "")
    description = top.string("description", "")
    time = _read_time(_Table(file, "time", top.raw("time"), _TIME_KEYS) if top.has("time") else None, file)

    if top.has("system"):
        for element in ("mass", "spring", "damper", "friction", "stop"):
            if top.has(element):
                raise ScenarioError(file, element, "cannot be combined with [system]; use one form or the other")
        system = _read_system(_Table(file, "system", top.raw("system"), _SYSTEM_KEYS))
        masses, springs, dampers, frictions, stops = (), (), (), (), ()
        dofs = system.dofs
    else:
        system = None
        masses = _read_masses(top, file)
        dofs = tuple(m.name for m in masses)
        springs = _read_elements(top, file, "spring", dofs)
        dampers = _read_elements(top, file, "damper", dofs)
        frictions = read_law_elements(top, file, "friction", dofs)
        stops = read_law_elements(top, file, "stop", dofs)

    forces = tuple(
        _read_force(_Table(file, f"force[{i}]", raw, _ANY_FORCE_KEYS), i, dofs) for i, raw in enumerate(top.tables("force"))
    )
    solver = _read_solver(_Table(file, "solver", top.raw("solver"))) if top.has("solver") else SolverSpec()
    sweep = _read_sweep(_Table(file, "sweep", top.raw("sweep"), SWEEP_KEYS)) if top.has("sweep") else ()
    damping = _read_damping(_Table(file, "damping", top.raw("damping"), DAMPING_KEYS), len(dofs)) \
        if top.has("damping") else None
    ground_motion = _read_ground_motion(_Table(file, "ground_motion", top.raw("ground_motion"), GROUND_KEYS)) \
        if top.has("ground_motion") else None
    expect = tuple(_read_expect(_Table(file, f"expect[{i}]", raw, EXPECT_KEYS), i, dofs, file)
                   for i, raw in enumerate(top.tables("expect")))
    fit = _read_fit(_Table(file, "fit", top.raw("fit"), FIT_KEYS)) if top.has("fit") else ()
    optimize = _read_optimize(_Table(file, "optimize", top.raw("optimize"), OPTIMIZE_KEYS)) \
        if top.has("optimize") else ()
    if top.has("building") and system is not None:
        raise ScenarioError(file, "building", "needs the element form (springs and dampers joining the floors, whose "
                                              "tensions are the storey shears); [system] has no elements")
    ida = _read_ida(_Table(file, "ida", top.raw("ida"), IDA_KEYS)) if top.has("ida") else ()
    building = _read_building(_Table(file, "building", top.raw("building"), BUILDING_KEYS), dofs) \
        if top.has("building") else None
    top.finish(_TOP_KEYS)

    n_points = _check_samples(file, time, len(dofs))
    step = (time.end - time.start) / max(n_points - 1, 1)
    for force in forces + ((ground_motion.shape,) if ground_motion else ()):
        problem = SHAPES[force.type].resolution_problem(force, time.start, time.end, step)
        if problem is not None:
            raise ScenarioError(file, f"{force.path}.{problem[0]}", problem[1])
    return Scenario(
        path=file, text=text, time=time, masses=masses, springs=springs, dampers=dampers,
        system=system, forces=forces, solver=solver, title=title, description=description,
        sweep=sweep, damping=damping, ground_motion=ground_motion, expect=expect, frictions=frictions, stops=stops,
        fit=fit,
        optimize=optimize,
        building=building,
        ida=ida,
    )


def _check_samples(file: str, time: TimeSpec, dofs: int) -> float:
    """The output grid's number of points, refused where points x DOFs is more than MAX_SAMPLES (x, v and a of
    every point are held, written and read)."""
    if not math.isfinite(time.end - time.start):
        raise ScenarioError(file, "time.end", f"expected a time span that is a finite number, found {time.end:g} - {time.start:g}")
    # In floating point: a huge span over a small step is refused before it becomes an integer.
    n_points = time.points if time.points is not None else (time.end - time.start) / time.step * (1 + 1e-12) + 1
    if not n_points * max(dofs, 1) <= MAX_SAMPLES:
        key = "time.points" if time.points is not None else "time.step"
        raise ScenarioError(
            file, key,
            f"output grid of {n_points:.3g} points x {dofs} DOF is too large "
            f"(limit {MAX_SAMPLES:.0e} samples); use a larger step or fewer points",
        )
    spacing = time.step if time.step is not None else (time.end - time.start) / (time.points - 1)
    resolvable = 4 * math.ulp(max(abs(time.start), abs(time.end)))  # distinct times, each step kept to a quarter
    if not spacing > resolvable:
        key = "time.step" if time.step is not None else "time.points"
        raise ScenarioError(file, key, f"expected samples at least {resolvable:.3g} s apart (what times near "
                                       f"{max(abs(time.start), abs(time.end)):g} s can tell apart), found "
                                       f"{spacing:.3g} s between them")
    return n_points


_TIME_TABLE = re.compile(r"^[ \t]*\[[ \t]*time[ \t]*\][^\n]*\n(?P<body>(?:(?![ \t]*\[)[^\n]*\n?)*)", flags=re.M)
_MASS_HEADER = re.compile(r"^[ \t]*\[\[[ \t]*mass[ \t]*\]\]", flags=re.M)


def _refuse_many_samples_early(text: str, file: str) -> None:
    """A scene whose output grid is too large, refused before the TOML parser reads it (tomllib takes 2 s on 60,000
    masses): its [[mass]] headers counted in the text and its [time] table read alone, as the full parse would
    (a header in a multi-line string would count too; none is that long). Where [time] is not a table of its own,
    or does not read alone, the full parse judges."""
    masses = len(_MASS_HEADER.findall(text))
    found = _TIME_TABLE.search(text) if masses > 1000 else None
    if found is None:
        return
    try:
        table = tomllib.loads(found["body"])
        time = _read_time(_Table(file, "time", table, _TIME_KEYS), file)
    except (tomllib.TOMLDecodeError, ScenarioError, ValueError):
        return
    _check_samples(file, time, masses)


def _refuse_control_characters(file: str, node, path: str) -> None:
    """Any text in the document (names, labels, expressions, file names) must print as itself: a terminal
    escape or a NUL in a scenario is refused, whatever table it is in; `description` may hold line breaks."""
    if isinstance(node, dict):
        for key, value in node.items():
            if isinstance(value, _TEXT_HOLDERS):  # a number holds no text: no path built for it
                _refuse_control_characters(file, value, f"{path}.{key}" if path else key)
    elif isinstance(node, list):
        for i, value in enumerate(node):
            if isinstance(value, _TEXT_HOLDERS):
                _refuse_control_characters(file, value, f"{path}[{i}]")
    elif isinstance(node, str):
        control = _control_character(node, multiline=path == "description")
        if control is not None:
            raise ScenarioError(file, path, f"expected printable text, found the control character {control!r}")


_TEXT_HOLDERS = (dict, list, str)
# What in a TOML text can decode to a control character: an escape, a multi-line string (line breaks), DEL or C1
# (TOML refuses every other control character but the tab in its strings). A text with none of them holds none: its
# walk (0.06 s on 30,000 tables) is skipped.
_MAY_DECODE_TO_CONTROL = re.compile('\\\\|"""|\'\'\'|[\x7f-\x9f]')
_CONTROL = re.compile("[\x00-\x08\x0a-\x1f\x7f-\x9f]")  # C0 but the tab, DEL, C1
_CONTROL_MULTILINE = re.compile("[\x00-\x08\x0b\x0c\x0e-\x1f\x7f-\x9f]")  # line breaks allowed too


def _control_character(text: str, multiline: bool) -> str | None:
    """The first control character of `text` (terminal escapes, NUL...), or None."""
    found = (_CONTROL_MULTILINE if multiline else _CONTROL).search(text)
    return None if found is None else found.group()
