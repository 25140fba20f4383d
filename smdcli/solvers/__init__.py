"""Solvers: a registry of names, options and capabilities (catalog.py, registry.py), one module per family.

`solve` and `get_solver` are loaded on first use, so that the scenario layer can read catalog.py (plain data)
without importing any solver.

Must not import (at import time): any solver module, so the scenario layer can read the catalog.
"""


def __getattr__(name: str):
    if name in ("solve", "get_solver"):
        from smdcli.solvers import registry

        return getattr(registry, name)
    raise AttributeError(name)
