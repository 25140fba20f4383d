"""[[expect]]: acceptance checks written in the scenario, evaluated after `smd simulate`, and their JUnit report.

rms_displacement and settling_time are measured as `smd sweep` measures them (one code); peak_displacement is the
summary's, located between samples and at events;
natural_frequency is the undamped mode's, rad/s; energy_residual the balance's max_relative_residual; golden
compares every trajectory both files hold, sample by sample, within atol + rtol |golden|.

Must not import: cli.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from smdcli.result import Result
from smdcli.scenario.spec import EXPECT_UNITS as UNITS, ExpectSpec

GOLDEN_DATASETS = ("displacement", "velocity", "acceleration", "force")


@dataclass(frozen=True)
class Check:
    """A check's verdict: what was measured against what was asked."""

    spec: ExpectSpec
    value: float
    passed: bool
    detail: str

    @property
    def name(self) -> str:
        """expect[0] peak_displacement m1: the check as a test case is named."""
        s = self.spec
        what = f" {s.dof}" if s.dof else f" mode {s.mode}" if s.quantity == "natural_frequency" else ""
        return f"{s.path} {s.quantity}{what}"

    def line(self) -> str:
        """PASS or FAIL, the check, the measured value and the bounds."""
        return check_line(self.as_dict())

    def as_dict(self) -> dict:
        """Plain data for JSON."""
        s = self.spec
        return {"name": self.name, "quantity": s.quantity, "dof": s.dof, "mode": s.mode if s.quantity == "natural_frequency" else None, "value": self.value,
                "units": UNITS[s.quantity], "min": s.min, "max": s.max, "passed": self.passed, "detail": self.detail}


def check_line(check: dict) -> str:
    """A check's verdict as one line (from Check.as_dict, so the summary of a --json record reads the same)."""
    unit = "" if check["units"] == "1" else " " + check["units"]
    return f"{'PASS' if check['passed'] else 'FAIL'} {check['name']} = {check['value']:.6g}{unit} ({check['detail']})"


def evaluate(checks: tuple[ExpectSpec, ...], model, result: Result) -> tuple[Check, ...]:
    """Every check of the scenario against a successful run."""
    return tuple(_evaluate(spec, model, result) for spec in checks)


def _evaluate(spec: ExpectSpec, model, result: Result) -> Check:
    if spec.quantity == "golden":
        return _golden(spec, result)
    if spec.quantity == "natural_frequency":
        value = float(model.modes.natural_frequencies[spec.mode - 1])
    elif spec.quantity == "energy_residual":
        value = float(result.energy.max_relative_residual)
    elif spec.quantity == "peak_displacement":  # located between samples and at events, as the summary's
        from smdcli.solvers.peaks import result_peaks

        value = float(result_peaks(result)[result.dofs.index(spec.dof)])
    else:
        from smdcli.sweep.members import measures

        j = result.dofs.index(spec.dof)
        x = result.displacement[:, j][None, None, :]
        value = float(measures(result.time, x, np.zeros_like(x), len(result.time))[spec.quantity][0, 0])
    passed = math.isfinite(value) and (spec.min is None or value >= spec.min) and (spec.max is None or value <= spec.max)
    bounds = " and ".join(part for part in (f"min {spec.min:g}" if spec.min is not None else "",
                                            f"max {spec.max:g}" if spec.max is not None else "") if part)
    if spec.quantity == "settling_time" and not math.isfinite(value):
        bounds += "; not settled within 2 % by the end of the run"
    return Check(spec, value, passed, bounds)


def _golden(spec: ExpectSpec, result: Result) -> Check:
    """The run against a stored result: the largest |difference| over the golden's peak, and the sample test."""
    import h5py

    worst, failing, compared = 0.0, [], []
    with h5py.File(spec.file, "r") as f:
        for name in ("time",) + GOLDEN_DATASETS:
            if name not in f:
                continue
            golden, mine = f[name][()], getattr(result, name)
            if golden.shape != mine.shape:
                return Check(spec, math.inf, False, f"{name} is {golden.shape} in {spec.file}, {mine.shape} here")
            difference = np.abs(mine - golden)
            peak = float(np.max(np.abs(golden), initial=0.0))
            worst = max(worst, float(difference.max(initial=0.0)) / peak if peak > 0 else float(difference.max(initial=0.0)))
            compared.append(name)
            if not (difference <= spec.atol + spec.rtol * np.abs(golden)).all():
                failing.append(name)
    detail = (f"largest difference over the golden's peak, {', '.join(compared)} against {spec.file} within "
              f"atol {spec.atol:g} + rtol {spec.rtol:g}" + (f"; differs in {', '.join(failing)}" if failing else ""))
    return Check(spec, worst, not failing and bool(compared), detail)


def write_junit(path: Path, suites: list[tuple[str, float, tuple[Check, ...], str | None]]) -> None:
    """A JUnit XML report: a test suite per scenario, a test case per check; an error case where the run failed."""
    import xml.etree.ElementTree as ET

    from smdcli.io.atomic import atomic_path

    root = ET.Element("testsuites", name="smd simulate")
    for scenario, seconds, checks, error in suites:
        failures = sum(not c.passed for c in checks)
        suite = ET.SubElement(root, "testsuite", name=scenario, tests=str(max(len(checks), 1 if error else 0)),
                              failures=str(failures), errors=str(1 if error else 0), time=f"{seconds:.3f}")
        if error:
            case = ET.SubElement(suite, "testcase", classname=scenario, name="simulate")
            ET.SubElement(case, "error", message=error).text = error
        for check in checks:
            case = ET.SubElement(suite, "testcase", classname=scenario, name=check.name)
            ET.SubElement(case, "system-out").text = check.line()
            if not check.passed:
                ET.SubElement(case, "failure", message=check.line(), type="expect").text = \
                    f"measured {check.value!r} {UNITS[check.spec.quantity]}; {check.detail}"
    root.set("tests", str(sum(int(s.get("tests")) for s in root)))
    root.set("failures", str(sum(int(s.get("failures")) for s in root)))
    root.set("errors", str(sum(int(s.get("errors")) for s in root)))
    ET.indent(root)
    with atomic_path(Path(path)) as tmp:
        ET.ElementTree(root).write(tmp, encoding="utf-8", xml_declaration=True)
