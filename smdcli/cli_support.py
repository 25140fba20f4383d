"""What every smd command shares at the terminal: one-line failures, strict JSON, interrupts, carrying out work.

Must not import: scipy, matplotlib, h5py at module level (`smd --help` stays fast); imports no command module.
"""

from __future__ import annotations

import typer

from smdcli import interrupts, strict_json


def _fail(message: str) -> None:
    """One line on stderr."""
    typer.echo(f"smd: {message}", err=True)


def _interrupted(exc: KeyboardInterrupt) -> typer.Exit:
    """Say what stopped the run; the exit code a shell expects (130 for SIGINT, 143 for SIGTERM)."""
    import signal

    global _announced
    signum = interrupts.received() or (signal.SIGTERM if isinstance(exc, interrupts.Terminated) else signal.SIGINT)
    if not _announced:
        notes = "".join(f"; {note}" for note in getattr(exc, "__notes__", ()))
        _fail(f"{'terminated' if signum == signal.SIGTERM else 'interrupted'}; no partial file was left under a "
              f"final name{notes}")
        _announced = True
    return typer.Exit(interrupts.exit_code(signum))


_announced = False  # the interrupt has been reported


def _print_json(data) -> None:
    """Strict JSON on stdout: no NaN or Infinity (see strict_json)."""
    typer.echo(strict_json.dumps(data))


def _message(exc: Exception, doing: str = "write") -> str:
    """The one line that says what went wrong."""
    from smdcli.errors import SmdError

    if isinstance(exc, SmdError):
        return str(exc)
    where = f"{exc.filename}: " if getattr(exc, "filename", None) else ""
    return f"{where}cannot {doing}: {exc.strerror or exc}"


def _report(exc: Exception, doing: str = "write") -> int:
    """One line for an error smd reports (its exit code) or a file that could not be written or read (2)."""
    from smdcli.errors import SmdError

    _fail(_message(exc, doing))
    return exc.exit_code if isinstance(exc, SmdError) else 2


def _report_json(exc: Exception, about: dict, as_json: bool, doing: str = "write", status: str | None = None) -> int:
    """_report, and with --json the same facts as a JSON object on stdout, so that a script always gets JSON."""
    code = _report(exc, doing)
    if as_json:
        _print_json({**about, "success": False, "status": status or strict_json.status(code), "exit_code": code,
                     "message": _message(exc, doing)})
    return code


def _carried_out(work, about: dict, as_json: bool, quiet: bool, summarize, describe):
    """Run a command's work: a failure is its one line and exit code (JSON too with --json), an interrupt smd's
    own line; else summarize(run) printed as JSON, or describe(run, that summary) as text. Returns the run."""
    from smdcli.errors import SmdError

    try:
        run = work()
    except (SmdError, OSError) as exc:
        raise typer.Exit(_report_json(exc, about, as_json))
    except KeyboardInterrupt as exc:
        raise _interrupted(exc)
    data = summarize(run)
    if as_json:
        _print_json(data)
    elif not quiet:
        typer.echo(describe(run, data))
    return run




# --help in plain words: typer 0.29 shows each option's Python type (`--json <bool>`, `<list[Path]>`) and a
# required argument as `{scenario}`; smd shows what to type instead: nothing after a flag, NUMBER, TEXT, PATH.
_WORDS = {"float": "NUMBER", "int": "INTEGER", "str": "TEXT", "path": "PATH", "Path": "PATH", "file": "PATH",
          "directory": "PATH"}


def _plain_type(self, ctx) -> str | None:
    """The value an option or argument takes, in --help: a word, `...` where it repeats; nothing for a flag."""
    if getattr(self, "is_flag", False) or getattr(self, "count", False):
        return None
    if self.metavar is not None:
        return self.metavar
    shown = typer.core._TyperParameter.display_type(self, ctx).strip("<>")
    repeated = shown.startswith("list[")
    shown = shown.removeprefix("list[").removesuffix("]")
    word = "|".join(_WORDS.get(part, part) for part in shown.split("|"))
    return word + ("..." if repeated or self.nargs != 1 else "")


def _usage_name(self) -> str:
    """An argument in the usage line: SCENARIO, SCENARIO... (optional ones in brackets)."""
    name = self.display_name_raw.upper() + ("..." if self.nargs != 1 else "")
    return name if self.required else f"[{name}]"


def plain_help() -> None:
    """Make every command's --help show values in plain words (see _WORDS)."""
    typer.core.TyperOption.display_type_rich = _plain_type
    typer.core.TyperArgument.display_type_rich = _plain_type
    typer.core.TyperArgument._usage_display_name = _usage_name


def plain_coercion() -> None:
    """Coerce smd's plain parameters (str, int, float, bool, Path and lists of them) without pydantic: typer 0.29
    builds a pydantic TypeAdapter for every parameter it reads, and importing pydantic for that is 0.14 s of every
    smd call (a fifth of a 1-DOF simulate). Paths still go through typer's own checks (coerce_cli_path); ranged
    numbers, choices, files and parsers are left to typer, as is everything where this typer lacks the hook."""
    try:
        from dataclasses import dataclass
        from pathlib import Path

        from typer import core
        from typer._click.exceptions import BadParameter
        from typer._coercion import RuntimeParam
        from typer._param_types import coerce_cli_path
    except ImportError:
        return
    parameter = getattr(core, "_TyperParameter", None)
    typers_own = getattr(parameter, "get_runtime_param", None)
    if typers_own is None:
        return
    kinds = (str, int, float, bool, Path)
    truth = {"true": True, "1": True, "yes": True, "y": True, "on": True,
             "false": False, "0": False, "no": False, "n": False, "off": False, "": False}

    def coerce(kind, value, info, param, ctx):
        if kind is str:
            return value.decode(errors="replace") if isinstance(value, bytes) else str(value)
        if kind is bool:
            if isinstance(value, bool):
                return value
            word = str(value).strip().lower()
            if word in truth:
                return truth[word]
            raise BadParameter(f"{value!r} is not a valid boolean.", ctx=ctx, param=param)
        if kind in (int, float):
            try:
                return kind(value)
            except (TypeError, ValueError):
                noun = "an integer" if kind is int else "a number"
                raise BadParameter(f"{value!r} is not {noun}.", ctx=ctx, param=param) from None
        return coerce_cli_path(value if isinstance(value, Path) else Path(value), info, path_type=Path, param=param,
                               ctx=ctx)

    @dataclass(frozen=True)
    class Plain(RuntimeParam):
        def _coerce_value(self, value, param, ctx):
            if isinstance(value, (list, tuple)):
                (item,) = self.annotation.__args__
                return [coerce(item, v, self.parameter_info, param, ctx) for v in value]
            return coerce(self.annotation, value, self.parameter_info, param, ctx)

    def plain(descriptor) -> bool:
        info, annotation = descriptor.parameter_info, descriptor.annotation
        if getattr(annotation, "__origin__", None) is list and len(annotation.__args__) == 1:
            annotation = annotation.__args__[0]
        return (annotation in kinds and info.parser is None and info.min is None and info.max is None
                and descriptor.file_annotation is None and (annotation is not Path or info.path_type in (None, Path)))

    def get_runtime_param(self):
        if self._runtime_param is None and plain(self.type_descriptor):
            self._runtime_param = Plain(self.type_descriptor.parameter_info, self.type_descriptor.annotation)
        return typers_own(self)

    parameter.get_runtime_param = get_runtime_param
