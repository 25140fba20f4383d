"""Which class reads and runs each element law: by the [[spring]] law name, or by the table.

Must not import: scenario, model, solvers, sweep, io, plots, commands, cli.
"""

from __future__ import annotations

from smdcli.elements.base import Law
from smdcli.elements.bouc_wen import BoucWen
from smdcli.elements.clough import Clough
from smdcli.elements.elastoplastic import Bilinear, Elastoplastic
from smdcli.elements.friction import Friction
from smdcli.elements.iwan import Iwan
from smdcli.elements.stop import Stop

# [[spring]] laws beyond linear and cubic, by name.
SPRING_LAWS: dict[str, type[Law]] = {cls.name: cls for cls in (Elastoplastic, Bilinear, Clough, BoucWen, Iwan)}
# Tables whose every entry is one law.
TABLES: dict[str, type[Law]] = {"friction": Friction, "stop": Stop}


def law_for(table: str, law: str | None = None) -> type[Law]:
    """The class of a table's law (a [[spring]]'s by its law name)."""
    return SPRING_LAWS[law] if table == "spring" else TABLES[table]
