"""Model layer: Scenario -> Model, the assembled M x'' + C x' + K x + f_nl(x, x') = B u(t).

Modules: system (assembly, modes, stiffness, the nonlinear element tables), forcing (force signals: values,
discontinuities, exosystems for exact integration). Must not import: solvers, sweep, io, plots, commands, cli.
"""

from smdcli.model.grid import time_grid
from smdcli.model.system import GROUND_DOF, Incidence, Model, Modes, build, mass_solve, regime

__all__ = ["GROUND_DOF", "Incidence", "Model", "Modes", "build", "mass_solve", "regime", "time_grid"]
