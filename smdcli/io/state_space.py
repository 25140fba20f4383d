"""A scenario's linear part as a state-space model x' = A x + B u, y = C x + D u, for python-control or MATLAB.

States [displacements; velocities], inputs the force on each DOF (and the ground's acceleration under support
motion), outputs the displacements. Written as .npz (numpy) or .mat (scipy.io, MATLAB 5 format), atomically.

Must not import: commands, cli.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from smdcli.errors import UsageError
from smdcli.io.atomic import atomic_path
from smdcli.model import Model, mass_solve

FORMATS = (".npz", ".mat")


def state_space_arrays(model: Model) -> dict:
    """A, B, C, D, the initial state x0 and the names of states, inputs and outputs; a nonlinear scene gives its linear part."""
    n = model.n
    inputs = np.eye(n)
    input_names = [f"force.{d}" for d in model.dofs]
    if model.ground is not None:  # the effective force -M 1 a_g
        inputs = np.column_stack([inputs, -model.M.sum(axis=1)])
        input_names.append("ground_acceleration")
    B = np.vstack([np.zeros((n, inputs.shape[1])), mass_solve(model.M, inputs)])
    out = {"A": model.state_matrix, "B": B, "C": np.hstack([np.eye(n), np.zeros((n, n))]),
           "D": np.zeros((n, inputs.shape[1])),
           "state_names": np.array([f"displacement.{d}" for d in model.dofs] + [f"velocity.{d}" for d in model.dofs]),
           "input_names": np.array(input_names), "output_names": np.array([f"displacement.{d}" for d in model.dofs]),
           "x0": np.concatenate([model.x0, model.v0])}
    notes = []
    if not model.is_linear:
        notes.append(f"the linear part only: {', '.join(model.nonlinear_paths)} left out")
    if model.ground is not None:
        notes.append("states are relative to the ground")
    out["note"] = np.array("; ".join(notes) or "exact: the scene is linear")
    return out


def write_state_space(path: Path, model: Model) -> Path:
    """Write A, B, C, D and the names to FILE.npz or FILE.mat."""
    path = Path(path)
    if path.suffix.lower() not in FORMATS:
        raise UsageError(f"--state-space: expected a file ending in .npz or .mat, found {str(path)!r}")
    arrays = state_space_arrays(model)
    with atomic_path(path) as tmp:
        if path.suffix.lower() == ".npz":
            with open(tmp, "wb") as f:
                np.savez(f, **arrays)
        else:
            from scipy.io import savemat

            cells = {k: (np.array(list(v), dtype=object) if v.dtype.kind == "U" and v.ndim else v)
                     for k, v in arrays.items()}
            with open(tmp, "wb") as f:
                savemat(f, cells)
    return path
