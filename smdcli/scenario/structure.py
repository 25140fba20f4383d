"""The structure's tables: [time], [[mass]], [[spring]], [[damper]] and [system].

Must not import: model, solvers, or any layer above."""

from __future__ import annotations

import difflib
import math

import numpy as np

from smdcli.errors import ScenarioError
from smdcli.scenario.reader import _MASS_KEYS, _SYSTEM_KEYS, _TIME_KEYS, _kind, _Table
from smdcli.scenario.spec import (DEFAULT_POINTS, GROUND, BuildingSpec, DampingSpec, ElementSpec, MassSpec,
                                  MatrixSystem, TimeSpec)


def _read_time(table: _Table | None, file: str) -> TimeSpec:
    if table is None:
        raise ScenarioError(file, "time", "required table is missing (expected [time] with end = ...)")
    start = table.number("start", 0.0)
    end = table.number("end")
    if end <= start:
        raise table.fail("end", f"expected a time after start = {start:g}, found {end:g}")
    if table.has("step") and table.has("points"):
        raise table.fail("points", "give either step or points, not both")
    step = table.number("step", None, positive=True)
    points = table.integer("points", None, minimum=2)
    if step is not None and step > end - start:
        raise table.fail("step", f"expected a step no longer than end - start = {end - start:g}, found {step:g}")
    if step is None and points is None:
        points = DEFAULT_POINTS
    table.finish(_TIME_KEYS)
    return TimeSpec(start=start, end=end, step=step, points=points)


def _read_masses(top: _Table, file: str) -> tuple[MassSpec, ...]:
    raw = top.tables("mass")
    if not raw:
        raise ScenarioError(file, "mass", "no masses: give [[mass]] tables or a [system] table")
    masses, seen = [], {}
    for i, item in enumerate(raw):
        t = _Table(file, f"mass[{i}]", item, _MASS_KEYS)
        name = t.string("name")
        if not name.strip():
            raise t.fail("name", "expected a non-empty name")
        if name == GROUND:
            raise t.fail("name", f"{GROUND!r} is reserved for the fixed wall")
        if name in seen:
            raise t.fail("name", f"duplicate name {name!r} (also mass[{seen[name]}])")
        seen[name] = i
        m = t.number("m", positive=True)
        x0 = t.number("x0", 0.0)
        v0 = t.number("v0", 0.0)
        t.finish(_MASS_KEYS)
        masses.append(MassSpec(name=name, m=m, x0=x0, v0=v0))
    return tuple(masses)


def _read_elements(top: _Table, file: str, kind: str, dofs: tuple[str, ...]) -> tuple[ElementSpec, ...]:
    from smdcli.elements import SPRING_LAWS

    coef_key, laws = ("k", ("linear", "cubic", *SPRING_LAWS)) if kind == "spring" else ("c", ("linear", "quadratic"))
    hysteretic_keys = tuple(dict.fromkeys(k for law in SPRING_LAWS.values() for k in law.keys if k != "k"))
    known = frozenset(dofs)
    elements = []
    for i, item in enumerate(top.tables(kind)):
        keys = ("connects", coef_key, "law") + (("k3",) + hysteretic_keys if kind == "spring" else ())
        t = _Table(file, f"{kind}[{i}]", item, keys)
        connects = _read_connects(t, dofs, known)
        law = t.string("law", "linear", choices=laws)
        if law in SPRING_LAWS:  # a hysteretic spring: its law reads and checks its own keys
            cls = SPRING_LAWS[law]
            _refuse_other_keys(t, law, ("connects", "law") + cls.keys)
            t.units.update(cls.units)
            model = cls.read(t)
            t.finish(("connects", "law") + cls.keys)
            elements.append(ElementSpec(kind=kind, index=i, connects=connects, coef=model.elastic_stiffness, law=law,
                                        nonsmooth=model))
            continue
        coef = t.number(coef_key, minimum=0.0, unit="N s^2/m^2" if law == "quadratic" else None)
        k3 = 0.0
        allowed = ("connects", coef_key, "law")
        if kind == "spring":
            allowed += ("k3",)
            if law == "cubic":
                k3 = t.number("k3")
            elif t.has("k3"):
                raise t.fail("k3", 'only a cubic spring has k3; set law = "cubic"')
            _refuse_other_keys(t, law, allowed)
        t.finish(allowed)
        elements.append(ElementSpec(kind=kind, index=i, connects=connects, coef=coef, law=law, k3=k3))
    return tuple(elements)


def read_law(file: str, kind: str, index: int, item: dict):
    """The law of [[kind]] entry `index` read from its table `item` (the TOML entry, numbers in SI or as unit strings)
    with the checks the scenario's reading makes of it: ScenarioError where it is no law (a yield force of 0, a
    restitution past 1)."""
    from smdcli.elements import SPRING_LAWS, TABLES

    cls = SPRING_LAWS[item["law"]] if kind == "spring" else TABLES[kind]
    t = _Table(file, f"{kind}[{index}]", item)
    t.units.update(cls.units)
    return cls.read(t)


def _refuse_other_keys(t: _Table, law: str, allowed: tuple[str, ...]) -> None:
    """A key of another spring law (fy on a linear spring, say) named with the law that takes it."""
    from smdcli.elements import SPRING_LAWS

    for key in t.data:
        if key not in allowed:
            owners = [name for name, cls in SPRING_LAWS.items() if key in cls.keys] + (["cubic"] if key == "k3" else [])
            raise t.fail(key, f"a {law} spring has no {key}" + (f"; it belongs to law = {owners[0]!r}" if owners
                                                                else ""))


def read_law_elements(top: _Table, file: str, table: str, dofs: tuple[str, ...]) -> tuple[ElementSpec, ...]:
    """[[friction]] or [[stop]]: each entry one law, which reads and checks its own keys."""
    from smdcli.elements import TABLES

    cls = TABLES[table]
    known = frozenset(dofs)
    elements = []
    for i, item in enumerate(top.tables(table)):
        t = _Table(file, f"{table}[{i}]", item, ("connects",) + cls.keys)
        connects = _read_connects(t, dofs, known)
        t.units.update(cls.units)
        model = cls.read(t)
        if table == "friction" and model.belt_velocity and GROUND not in connects:
            raise t.fail("belt_velocity", f"a belt is the ground moving under a mass; this contact connects "
                                          f"{connects[0]!r} and {connects[1]!r}, neither of them the ground")
        t.finish(("connects",) + cls.keys)
        elements.append(ElementSpec(kind=table, index=i, connects=connects, coef=0.0, law=getattr(model, "law_name", table),
                                    nonsmooth=model))
    return tuple(elements)


def _read_connects(t: _Table, dofs: tuple[str, ...], known: frozenset[str]) -> tuple[str, str]:
    """An element's two nodes; known: the DOF names as a set (20,000 ends looked up in a 10,000-name tuple: 2 s)."""
    if not t.has("connects"):
        raise t.fail("connects", 'required field is missing (expected ["ground", "m1"] or ["m1", "m2"])')
    value = t.raw("connects")
    if not isinstance(value, list) or len(value) != 2 or not all(isinstance(v, str) for v in value):
        raise t.fail("connects", f"expected two node names, found {_kind(value)}")
    for node in value:
        if node != GROUND and node not in known:
            hint = difflib.get_close_matches(node, dofs + (GROUND,), n=1)
            extra = f" (did you mean {hint[0]!r}?)" if hint else f"; nodes are {', '.join(dofs + (GROUND,))}"
            raise t.fail("connects", f"unknown node {node!r}{extra}")
    if value[0] == value[1]:
        what = "ground to ground" if value[0] == GROUND else f"{value[0]!r} to itself"
        raise t.fail("connects", f"an element from {what} does nothing; connect two different nodes")
    return (value[0], value[1])


def _read_matrix(t: _Table, key: str, n: int) -> tuple[tuple[float, ...], ...]:
    if not t.has(key):
        raise t.fail(key, f"required field is missing (expected a {n}x{n} matrix)")
    value = t.raw(key)
    if not isinstance(value, list) or len(value) != n or not all(isinstance(r, list) for r in value):
        raise t.fail(key, f"expected a {n}x{n} matrix (one row per DOF), found {_kind(value)}")
    rows = []
    for i, row in enumerate(value):
        if len(row) != n:
            raise t.fail(f"{key}[{i}]", f"expected {n} numbers (a square matrix), found {len(row)}")
        rows.append(tuple(t._check_number(f"{key}[{i}][{j}]", v, None, False, t._unit(key, None)) for j, v in enumerate(row)))
    matrix = tuple(rows)
    for i in range(n):
        for j in range(i + 1, n):
            a, b = matrix[i][j], matrix[j][i]
            if abs(a - b) > 1e-12 * max(abs(a), abs(b), 1.0):
                raise t.fail(key, f"expected a symmetric matrix, found {key}[{i}][{j}] = {a:g} but {key}[{j}][{i}] = {b:g}")
    _check_definite(t, key, matrix, strict=(key == "M"))
    return matrix


def _check_definite(t: _Table, key: str, matrix, strict: bool) -> None:
    # Sylvester-free check without numpy: Cholesky (semi-definite with a small slack).
    n = len(matrix)
    scale = max((abs(v) for row in matrix for v in row), default=0.0) or 1.0
    tol = 1e-12 * scale * n
    L = [[0.0] * n for _ in range(n)]
    for i in range(n):
        for j in range(i + 1):
            s = matrix[i][j] - sum(L[i][k] * L[j][k] for k in range(j))
            if i == j:
                if s <= (tol if strict else -tol):
                    need = "positive definite" if strict else "positive semi-definite"
                    raise t.fail(key, f"expected a symmetric {need} matrix; pivot {i} is {s:.3g}")
                L[i][i] = math.sqrt(max(s, 0.0))
            else:
                L[i][j] = s / L[j][j] if L[j][j] > 0 else 0.0


def _read_system(t: _Table) -> MatrixSystem:
    if any(t.has(key) and isinstance(t.data[key], str) for key in ("M", "C", "K")):
        return _read_file_system(t)
    if not t.has("dofs"):
        raise t.fail("dofs", 'required field is missing (expected names, e.g. ["x1", "x2"])')
    dofs = _read_dofs(t)
    n = len(dofs)
    M = _read_matrix(t, "M", n)
    C = _read_matrix(t, "C", n) if t.has("C") else tuple(tuple(0.0 for _ in range(n)) for _ in range(n))
    K = _read_matrix(t, "K", n)
    x0 = t.numbers("x0", (0.0,) * n, length=n)
    v0 = t.numbers("v0", (0.0,) * n, length=n)
    t.finish(_SYSTEM_KEYS)
    return MatrixSystem(dofs=tuple(dofs), M=M, C=C, K=K, x0=x0, v0=v0)


def _read_dofs(t: _Table) -> tuple[str, ...]:
    dofs = t.raw("dofs")
    if not isinstance(dofs, list) or not dofs or not all(isinstance(d, str) and d.strip() for d in dofs):
        raise t.fail("dofs", f"expected a non-empty array of names, found {_kind(dofs)}")
    if len(set(dofs)) != len(dofs):
        raise t.fail("dofs", "duplicate DOF names")
    if GROUND in dofs:
        raise t.fail("dofs", f"{GROUND!r} is reserved for the fixed wall")
    return tuple(dofs)


def _read_file_system(t: _Table) -> MatrixSystem:
    """[system] with M, C or K naming files, kept sparse (a matrix written inline beside them joins them as CSR);
    dofs default to x1..xn."""
    from scipy.sparse import csr_matrix

    from smdcli.scenario.matrix_files import check_file_matrix, matrix_file_path, read_matrix_file

    for key in ("M", "K"):
        if not t.has(key):
            raise t.fail(key, "required field is missing (expected a .mtx, .npz or .mat file, or a matrix)")
    dofs = _read_dofs(t) if t.has("dofs") else None
    n = None if dofs is None else len(dofs)
    matrices, files = {}, []
    named = [key for key in ("M", "C", "K") if t.has(key) and isinstance(t.data[key], str)]
    sized_by = "one row per name in dofs" if dofs is not None else f"as {named[0]} is"
    for key in named:
        matrices[key], sha256 = read_matrix_file(t, key)
        check_file_matrix(t, key, matrices[key], n, strict=(key == "M"), sized_by=sized_by)
        n = matrices[key].shape[0]
        files.append((key, str(matrix_file_path(t, key)), sha256))
    for key in ("M", "C", "K"):
        if key not in matrices:
            # an array, not the tuple of rows: csr_matrix reads a tuple as (data, indices) or a shape
            matrices[key] = csr_matrix(np.array(_read_matrix(t, key, n)) if t.has(key) else (n, n), dtype=float)
    if dofs is None:
        dofs = tuple(f"x{i + 1}" for i in range(n))
    x0 = t.numbers("x0", (0.0,) * n, length=n)
    v0 = t.numbers("v0", (0.0,) * n, length=n)
    t.finish(_SYSTEM_KEYS)
    return MatrixSystem(dofs=dofs, M=matrices["M"], C=matrices["C"], K=matrices["K"], x0=x0, v0=v0,
                        files=tuple(files))


DAMPING_KEYS = ("alpha", "beta", "zeta", "omega", "modal")


def _check_ratio(t: _Table, key: str, ratio: float, which: str) -> None:
    """A damping ratio of at most 1: above it every such mode is overdamped, and a ratio written as a percentage
    (modal = 5 for 5 %) is the usual cause."""
    if ratio > 1.0:
        hint = f"; did you mean {ratio / 100:g} ({ratio:g} %)?" if ratio <= 100 else ""
        raise t.fail(key, f"expected a damping ratio from 0 to 1 (a fraction of critical; above 1 every such mode is "
                          f"overdamped), found {which}{ratio:g}{hint}")


def _read_damping(t: _Table, n: int) -> DampingSpec:
    """[damping]: alpha and/or beta, or zeta with omega = [w1, w2] (rad/s), or modal (one ratio or one per mode)."""
    given = [key for key in DAMPING_KEYS if t.has(key)]
    ways = {"alpha": "coefficients", "beta": "coefficients", "zeta": "two frequencies", "omega": "two frequencies",
            "modal": "modal"}
    if len({ways[key] for key in given}) > 1:
        raise t.fail(given[-1], "expected one way of giving damping: alpha and beta, zeta with omega, or modal; "
                                f"found {', '.join(given)}")
    if not given:
        raise t.fail(None, "expected alpha and beta, zeta with omega, or modal; found an empty table")
    if "modal" in given:
        raw = t.raw("modal")
        if isinstance(raw, list):
            ratios = t.numbers("modal", length=n, minimum=0.0)
        else:
            ratios = (t.number("modal", minimum=0.0),)
        for i, ratio in enumerate(ratios):
            _check_ratio(t, "modal", ratio, f"modal[{i}] = " if isinstance(raw, list) else "")
        t.finish(DAMPING_KEYS)
        return DampingSpec(modal=tuple(ratios), given="modal")
    if "zeta" in given or "omega" in given:
        for key in ("zeta", "omega"):
            if not t.has(key):
                raise t.fail(key, "required with " + ("omega" if key == "zeta" else "zeta") + " (Rayleigh damping "
                                  "through a damping ratio at two frequencies)")
        zeta = t.number("zeta", minimum=0.0)
        _check_ratio(t, "zeta", zeta, "")
        w1, w2 = t.numbers("omega", length=2)
        if not (w1 > 0 and w2 > 0 and w1 != w2):
            raise t.fail("omega", f"expected two distinct positive frequencies in rad/s, found [{w1!r}, {w2!r}]")
        # zeta = alpha / (2 w) + beta w / 2 at w1 and at w2, computed so that no intermediate overflows
        t.finish(DAMPING_KEYS)
        mean = 0.5 * w1 + 0.5 * w2
        alpha, beta = zeta * min(w1, w2) * (max(w1, w2) / mean), zeta / mean
        if not (math.isfinite(alpha) and math.isfinite(beta)):
            raise t.fail("zeta", f"Rayleigh coefficients alpha = {alpha:.3g} 1/s and beta = {beta:.3g} s overflow "
                                 f"double precision for zeta = {zeta:g} at omega = [{w1:g}, {w2:g}] rad/s")
        return DampingSpec(alpha=alpha, beta=beta, given="zeta")
    alpha = t.number("alpha", 0.0, unit="1/s")  # C = alpha M + beta K
    beta = t.number("beta", 0.0, unit="s")
    t.finish(DAMPING_KEYS)
    return DampingSpec(alpha=alpha, beta=beta, given="alpha" if t.has("alpha") else "beta")


BUILDING_KEYS = ("storey_heights", "masses")


def _read_building(t: _Table, dofs: tuple[str, ...]) -> BuildingSpec:
    """[building]: storey_heights (m, one per mass of the chain), masses (the chain ground up; default every mass)."""
    if not t.has("storey_heights"):
        raise t.missing("storey_heights", "one storey height in m per mass of the chain, from the ground up")
    heights = t.numbers("storey_heights")
    if t.has("masses"):
        names = t.raw("masses")
        if not (isinstance(names, list) and names and all(isinstance(n, str) for n in names)):
            raise t.fail("masses", f"expected a list of mass names, the chain from the ground up, found {names!r}")
        for name in names:
            if name not in dofs:
                hint = difflib.get_close_matches(name, dofs, n=1)
                raise t.fail("masses", f"unknown mass {name!r}" + (f" (did you mean {hint[0]!r}?)" if hint else
                                                                   f"; masses are {', '.join(dofs)}"))
        if len(set(names)) != len(names):
            raise t.fail("masses", "expected each mass once")
        chain = tuple(names)
    else:
        chain = tuple(dofs)
    if len(heights) != len(chain):
        raise t.fail("storey_heights", f"expected {len(chain)} heights, one per mass of the chain "
                                       f"({', '.join(chain)}), found {len(heights)}")
    for i, h in enumerate(heights):
        if not h > 0:
            raise t.fail(f"storey_heights[{i}]", f"expected a positive height in m, found {h:g}")
    t.finish(BUILDING_KEYS)
    return BuildingSpec(tuple(float(h) for h in heights), chain)
