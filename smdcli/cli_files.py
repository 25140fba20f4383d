"""Commands that read result files: diff (compare two) and export (CSV).

Must not import: scipy, matplotlib, h5py at module level (the commands import what they need inside).
"""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

from smdcli.cli_support import _print_json, _report_json


def diff_files(
    a: Path = typer.Argument(..., help="First smd .h5 file."),
    b: Path = typer.Argument(..., help="Second smd .h5 file."),
    rtol: Optional[float] = typer.Option(None, "--rtol", help="Relative tolerance per sample (default 1e-9)."),
    atol: Optional[float] = typer.Option(None, "--atol", help="Absolute tolerance per sample (default 0)."),
    tolerance: Optional[str] = typer.Option(None, "--tolerance", help="'stated': each data set within the accuracy "
                                            "the two runs state (for another machine or method); not with --rtol/--atol."),
    datasets: Optional[str] = typer.Option(None, "--datasets", help="Comma list of data sets to compare (default: all)."),
    allow_failed: bool = typer.Option(False, "--allow-failed", help="Compare files whose run failed."),
    as_json: bool = typer.Option(False, "--json", help="Print the report as JSON."),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="Print nothing; the exit code says it."),
):
    """Compare two result files: exit 0 when every data set agrees within tolerance, 1 when not, 2 if unreadable."""
    from smdcli.commands.diff import as_dict, diff, format_report
    from smdcli.errors import SmdError

    given = {name: value for name, value in (("rtol", rtol), ("atol", atol)) if value is not None}
    if tolerance is not None and tolerance != "stated":
        raise typer.BadParameter(f"expected 'stated', found {tolerance!r}", param_hint="--tolerance")
    if tolerance and given:
        raise typer.BadParameter("give either --tolerance stated or --rtol/--atol, not both", param_hint="--tolerance")
    try:
        report = diff(a, b, names=datasets.split(",") if datasets else None, allow_failed=allow_failed,
                      stated=tolerance == "stated", **given)
    except (SmdError, OSError) as exc:
        raise typer.Exit(_report_json(exc, {"a": str(a), "b": str(b)}, as_json, doing="read",
                                      status="unusable"))
    if as_json:
        _print_json(as_dict(report))
    elif not quiet:
        typer.echo(format_report(report))
    raise typer.Exit(1 if report.differs else 0)




def export(
    result: Path = typer.Argument(..., help="An smd result file (.h5): simulate, or sweep."),
    out: Optional[Path] = typer.Option(None, "-o", "--out", help="The CSV file (default: RESULT with .csv)."),
    datasets: Optional[str] = typer.Option(None, "--datasets", help="Comma list of data sets (default: every time "
                                           "series; 'energy' for all its terms)."),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="Print errors only."),
):
    """One CSV table of a result: a header row time,displacement.m1,..., a '# units:' line above it, values as
    %.17g (they read back bit for bit); a sweep file gives one row per member: parameters and metrics."""
    from smdcli.commands.export import export_csv
    from smdcli.errors import SmdError

    try:
        path, rows, columns, note = export_csv(result, out, datasets.split(",") if datasets else None)
    except (SmdError, OSError) as exc:
        raise typer.Exit(_report_json(exc, {"result": str(result)}, False, doing="export"))
    if not quiet:
        typer.echo(f"wrote {path}: {rows} rows x {columns} columns" + (f" ({note})" if note else ""))
