"""A Model as the flat arrays compiled kernels read: one compiled function serves every scenario.

The linear part is stored as sparse rows (CSR) of [-M^-1 K, -M^-1 C] and of M^-1, so a chain of n masses
costs O(n) per right-hand side; nonlinear elements are a table (law, nodes, coefficient), so a new element
law is one more row kind; forces are a table of kinds and parameters, with tabulated data, Fourier terms
and expression programs packed into shared arrays.

Must not import: solvers, sweep, io, plots, commands, cli. Imports no numba: this is plain numpy.
"""

from __future__ import annotations

import weakref
from typing import NamedTuple

import numpy as np

from smdcli.model import Model

# Element laws: the row kinds of the nonlinear element table.
CUBIC_SPRING, QUADRATIC_DAMPER = 0, 1
FORCE_PARAMETERS = 4
LAW_PARAMETERS = 6
GUARD_D, GUARD_RATE, GUARD_TENSION, GUARD_INTERNAL = range(4)
INTERIOR = 4  # interior points of each step where an integrator looks at the guards too: a touch within a step is seen


class ModelArrays(NamedTuple):
    """What a kernel needs of a model; every field an array (or the DOF count)."""

    n: int
    a_ptr: np.ndarray  # CSR of the n x 2n rows [-M^-1 K, -M^-1 C]
    a_idx: np.ndarray
    a_val: np.ndarray
    mi_ptr: np.ndarray  # CSR of M^-1, applied to the applied force less the nonlinear element forces
    mi_idx: np.ndarray
    mi_val: np.ndarray
    el_law: np.ndarray  # (E,) int: CUBIC_SPRING or QUADRATIC_DAMPER
    el_a: np.ndarray  # (E,) int: first node, -1 for ground (the element pulls it with -g)
    el_b: np.ndarray  # (E,) int: second node, -1 for ground
    el_coef: np.ndarray  # (E,) k3 or the quadratic damping coefficient
    f_kind: np.ndarray  # (F,) int force row kind (each shape's, smdcli.shapes)
    f_dof: np.ndarray  # (F,) int DOF the force acts on; -1: the ground's acceleration, -a_g on every DOF's acceleration
    f_par: np.ndarray  # (F, FORCE_PARAMETERS) float parameters, by kind
    f_ptr: np.ndarray  # (F + 1,) int: each force's slice of f_data
    f_data: np.ndarray  # tables (times then values), Fourier terms (harmonics then coefficients), constants
    f_cptr: np.ndarray  # (F + 1,) int: each expression's slice of f_code
    f_code: np.ndarray  # postfix opcodes of expression forces
    # A nonsmooth scene in one mode (smdcli.solvers.events.scene): empty for smooth models. The state is then
    # [x, v, q, energy]: q the laws' internal variables, energy the ACCUMULATED powers' integrals; a_* and mi_*
    # hold the mode's P M^-1 [-Kt, -Ct] and P M^-1 (P projects out the held rows' accelerations).
    ns_q: int  # internal variables (0 for smooth models)
    ns_acc: int  # accumulated energy terms (0 for smooth models)
    f_const: np.ndarray  # (n,) the mode's constant forces g
    ground_row: np.ndarray  # (n,) P 1: how the ground's acceleration reaches each DOF
    mass_row: np.ndarray  # (n,) M 1: the ground's effective force per unit acceleration, for the input power
    c_dense: np.ndarray  # (n, n) the dampers' C, for their power
    ns_R: np.ndarray  # (E, n) element rows: d = R x
    ns_belt: np.ndarray  # (E,) belt speeds: d' = R v + belt
    ns_held: np.ndarray  # (E,) int: 1 where the element is held (its tension the constraint's force)
    ns_stiff: np.ndarray  # (E,) the mode's piece: tension = stiff d + damp d' + const (+ the smooth law)
    ns_damp: np.ndarray
    ns_const: np.ndarray
    ns_law: np.ndarray  # (E,) int: the smooth part's kernel code (its law's SMOOTH_*), 0 (SMOOTH_NONE) if none
    ns_par: np.ndarray  # (E, LAW_PARAMETERS) its parameters
    ns_term: np.ndarray  # (E,) int: the energy term it dissipates into (ACCUMULATED index), -1 if none
    ns_pd: np.ndarray  # (E,) dissipated power = pd d'^2 + pc d' + px d d' (+ the smooth law's)
    ns_pc: np.ndarray
    ns_px: np.ndarray
    h_lin: np.ndarray  # (E, 2n) held tensions = h_lin [x, v] + h_f F - h_g a_g
    h_f: np.ndarray  # (E, n)
    h_g: np.ndarray  # (E,)
    gd_el: np.ndarray  # (G,) int: the element each guard watches
    gd_qty: np.ndarray  # (G,) int: GUARD_D, GUARD_RATE, GUARD_TENSION or GUARD_INTERNAL
    gd_level: np.ndarray  # (G,)
    gd_dir: np.ndarray  # (G,) +1 or -1: the direction that ends the mode
    gd_kink: np.ndarray  # (G,) int: 1 where it is a smooth law's kink (a restart, nothing else happens)


def csr(matrix) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Row pointers, column indices and values of a matrix's nonzero entries (dense, or scipy sparse), each row's
    columns in order."""
    if not isinstance(matrix, np.ndarray):
        matrix = matrix.tocsr(copy=True)
        matrix.eliminate_zeros()
        matrix.sort_indices()
        return matrix.indptr.astype(np.int64), matrix.indices.astype(np.int64), matrix.data.astype(float)
    rows, cols = np.nonzero(matrix)
    ptr = np.zeros(matrix.shape[0] + 1, dtype=np.int64)
    np.add.at(ptr, rows + 1, 1)
    return np.cumsum(ptr), cols.astype(np.int64), matrix[rows, cols].astype(float)


def _elements(model: Model) -> tuple[np.ndarray, ...]:
    """The nonlinear element table from the model's incidence rows (+1 on the first node, -1 on the second)."""
    laws, first, second, coefs = [], [], [], []
    for law, incidence in ((CUBIC_SPRING, model.cubic), (QUADRATIC_DAMPER, model.quadratic)):
        if incidence is None:
            continue
        for row, coef in zip(incidence.D, incidence.coef):
            plus, minus = np.flatnonzero(row > 0), np.flatnonzero(row < 0)
            laws.append(law)
            first.append(int(plus[0]) if len(plus) else -1)
            second.append(int(minus[0]) if len(minus) else -1)
            coefs.append(float(coef))
    ints = lambda values: np.array(values, dtype=np.int64)  # noqa: E731
    return ints(laws), ints(first), ints(second), np.array(coefs, dtype=float)


_BUILT: dict[int, tuple[weakref.ref, ModelArrays]] = {}


def model_arrays(model: Model) -> ModelArrays:
    """The arrays of a model, for the compiled kernels: built once per model (a Model is frozen and no kernel writes
    to them), so that solving one model again and again, as a sweep's pieces or a benchmark do, does not rebuild
    its sparse rows each time."""
    key = id(model)
    held = _BUILT.get(key)
    if held is not None and held[0]() is model:
        return held[1]
    arrays = _build(model)
    _BUILT[key] = (weakref.ref(model, lambda _, key=key: _BUILT.pop(key, None)), arrays)
    return arrays


def _build(model: Model) -> ModelArrays:
    a_ptr, a_idx, a_val = _linear_rows(model)
    mi_ptr, mi_idx, mi_val = csr(model.Minv)
    rows = [s.kernel_row() for s in model.signals]
    par = np.zeros((len(rows), FORCE_PARAMETERS))
    for j, (_, values, _, _) in enumerate(rows):
        par[j, :len(values)] = values
    sizes = [len(data) for _, _, data, _ in rows]
    code_sizes = [len(codes) for _, _, _, codes in rows]
    return ModelArrays(
        model.n, a_ptr, a_idx, a_val, mi_ptr, mi_idx, mi_val, *_elements(model),
        f_kind=np.array([kind for kind, _, _, _ in rows], dtype=np.int64),
        f_dof=np.array(model.force_dofs, dtype=np.int64).reshape(len(rows)),
        f_par=par,
        f_ptr=np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64),
        f_data=np.concatenate([np.zeros(0), *(np.asarray(data, dtype=float) for _, _, data, _ in rows)]),
        f_cptr=np.concatenate([[0], np.cumsum(code_sizes)]).astype(np.int64),
        f_code=np.array([c for _, _, _, codes in rows for c in codes], dtype=np.int64),
        **_smooth_scene(model.n),
    )


def _linear_rows(model: Model) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """CSR of [-M^-1 K, -M^-1 C]: a sparse scene's from its CSR matrices, never its dense 2n x 2n state matrix
    (3.2 GB at 10,000 masses)."""
    if not model.is_sparse:
        return csr(model.state_matrix[model.n:])
    from scipy.sparse import hstack

    inverse = model.Minv
    return csr(hstack([-(inverse @ model.K), -(inverse @ model.C)], format="csr"))


def _smooth_scene(n: int) -> dict:
    """The nonsmooth fields of a model without nonsmooth elements: all empty."""
    none, ints = np.zeros(0), np.zeros(0, dtype=np.int64)
    return dict(ns_q=0, ns_acc=0, f_const=none, ground_row=none, mass_row=none, c_dense=np.zeros((0, 0)),
                ns_R=np.zeros((0, n)), ns_belt=none, ns_held=ints, ns_stiff=none, ns_damp=none, ns_const=none,
                ns_law=ints, ns_par=np.zeros((0, LAW_PARAMETERS)), ns_term=ints, ns_pd=none, ns_pc=none, ns_px=none,
                h_lin=np.zeros((0, 2 * n)), h_f=np.zeros((0, n)), h_g=none, gd_el=ints, gd_qty=ints, gd_level=none,
                gd_dir=ints, gd_kink=ints)
