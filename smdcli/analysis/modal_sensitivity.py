"""Sensitivities of a classically damped linear scene in its modal coordinates: the scene's modes and each
parameter's stepped side by side, exactly, at O(n) a step for each mode and one matrix product over the run for
their coupling, where the stacked system's dense exponential takes (2 (P + 1) n)^2 a step.

The undamped mode shapes Phi (Phi^T M Phi = I) decouple the scene: q_k'' + d_k q_k' + w_k^2 q_k = (Phi^T B u)_k.
A parameter's block x_i = Phi r_i (its scale times dx/dp_i; model_derivative.augmented_model) obeys the same
oscillators, driven by the scene's modes through the parameter's model derivatives dM_i, dC_i, dK_i:

    r_i'' + D r_i' + W r_i = alpha_i q + beta_i q' + Phi^T (B_i - dM_i M^-1 B) u
    alpha_i = -(Phi^T dK_i Phi - Phi^T dM_i Phi W),  beta_i = -(Phi^T dC_i Phi - Phi^T dM_i Phi D)

(the scene's q'' replaced by its own equation). Over an output step h the pair steps exactly:
q+ = E q + G_q w, r+ = E r + F q + G_r w, where E holds each mode's 2 x 2 propagator and
F_kj = alpha_kj F1_kj + beta_kj F2_kj, Fc_kj = int_0^h e^(L_k (h - s)) e2 e_c^T e^(L_j s) ds: e^(L_j s) as its
Taylor series makes every Fc one product of two thin matrices (phi functions of each mode against powers of each
mode), over a step short enough for the series and squared back to h where the modes are stiff. Where the series
spans the whole step and a parameter moves alpha and beta by a matrix of small rank r (an element's stiffness or
damper: Phi^T e e^T Phi, rank one; a mass: two), F itself is a product of thin factors of 2 r T columns (T the
series' terms), and F q costs O(n r T) a step instead of O(n^2). The forces'
generator states w (w' = S w, reseeded from their closed forms at each output point) drive q through each mode's
own augmented exponential, and r through it and through q: q's response from rest to w is Y e^(S s) w -
e^(L s) Y w, Y the particular solution (L_k Y_k - Y_k S = -e2 b_k g, a small Sylvester equation per mode). The
steps run in each mode's eigenvectors, where E is diagonal: a cumulative sum a block of steps at a time.

It serves a uniform grid holding every force discontinuity, modes away from critical damping (their eigenvectors
well conditioned) and forces away from resonance with a mode (Y well conditioned); elsewhere the caller takes the
dense stacked system.

Must not import: sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import math

import numpy as np

from smdcli.analysis.stacked_blocks import block_accelerations, stacked_blocks
from smdcli.model import Model
from smdcli.solvers.base import stated_rounding
from smdcli.solvers.exact.accurate_expm import NEEDED_NORM
from smdcli.model.modes import modal_eigenvalues
from smdcli.solvers.exact.modal import modal_coefficients, mode_matrices, mode_propagators
from smdcli.solvers.exact.sampled import BLOCK

STACKED_DOFS = 64  # (P + 1) n from which this path costs less than the dense stacked system (30 masses: 60)
LARGEST_GENERATOR = 8  # a force's generator size this path takes (a Fourier series' many harmonics: the dense one)
MODAL_METHOD = ("exact, in modal coordinates: the scene's undamped modes and each parameter's, driven by the scene's "
                "through the model's derivatives (-dM x'' - dC x' - dK x + B du/dp), stepped exactly output step by "
                "output step (each mode's exponential, the modes' coupling summed as its series); the "
                "model's derivatives taken on the assembled model (one difference where it is affine in the parameter, "
                "else a five-point stencil)")
SERIES_RADIUS = 2.0  # |lambda| h up to which the modes' coupling is summed as its series
SERIES_TERMS = 25  # its terms: 2^25 / 26! below 1e-19
_INVERSE_FACTORIALS = np.array([1.0 / math.factorial(k) for k in range(3 * SERIES_TERMS + 1)])
CONDITION = 1e4  # the largest condition of a mode's eigenvectors or of Y's equation this path accepts


def modal_sensitivities(base: Model, stacked: Model, scales: np.ndarray,
                        grid: np.ndarray) -> tuple[np.ndarray, float] | None:
    """Each quantity's scene and derivatives, as sensitivity._split's (quantities, P + 1, N, n) array, and the
    stated accuracy; None where this path does not serve the scene (the caller solves the stacked system)."""
    setup = _setup(base, stacked, grid)
    if setup is None:
        return None
    shapes, squared, damping, h, exos = setup
    n, P, N = base.n, len(scales), len(grid)
    lam, vector_condition = _eigen(squared, damping)
    gains, S, ends = _generators(exos)
    m = S.shape[0]
    Y, forcing_condition = _particular(lam, squared, damping, S, ends, shapes.T @ stacked.inputs[:n] @ gains)
    if max(vector_condition, forcing_condition) > CONDITION:
        return None
    dM, dC, dK, columns, x0, v0 = stacked_blocks(stacked, n, P)
    mass_form = shapes.T @ base.dense().M
    participation = shapes.T @ columns  # (P + 1, n, F): the forces' reach on each block's modes
    pairs = []  # each parameter's alpha and beta, each as factors (left, right) or (the matrix, None)
    rows = np.empty((P + 1, n, m))  # each block's modes' forcing by w: the direct one, then r's through q's Y
    direct = participation.copy()  # each block's modes' forcing by the forces
    rows[0] = direct[0] @ gains
    for i in range(P):
        Gm, Gc, Gk = (_projected_factors(shapes, d[i]) for d in (dM, dC, dK))
        pair = _thin_pair(Gm, Gc, Gk, squared, damping) or (
            (-(_product(Gk) - _product(Gm) * squared), None), (-(_product(Gc) - _product(Gm) * damping), None))
        pairs.append(pair)
        direct[i + 1] -= _times(Gm, participation[0])  # Phi^T dM M^-1 B = Phi^T dM Phi Phi^T B
        rows[i + 1] = direct[i + 1] @ gains + _times(pair[0], Y[:, 0]) + _times(pair[1], Y[:, 1])
    A = np.repeat(mode_matrices(squared, damping, 2 + m)[None], P + 1, axis=0)
    A[:, :, 1, 2:] = rows
    A[:, :, 2:, 2:] = S
    flows = mode_propagators(A.reshape(-1, 2 + m, 2 + m), h).reshape(P + 1, n, 2 + m, 2 + m)
    couple = _Coupling(squared, damping, h, pairs)  # X (rows, 2n) -> X F_i^T (rows, P, 2n)
    G_q = flows[0, :, :2, 2:]  # (n, 2, m)
    G_r = flows[1:, :, :2, 2:] - couple(Y.reshape(2 * n, m).T).transpose(1, 2, 0).reshape(P, n, 2, m)
    w = np.concatenate([np.zeros((N, 0))] + [signal.exo_states(grid) for signal, _ in exos], axis=1)  # just after
    q, chain = _eigen_steps(lam, h, (w[:-1] @ G_q.reshape(2 * n, m).T).reshape(N - 1, n, 2),
                            np.stack([mass_form @ base.x0, mass_form @ base.v0], axis=1))
    flat = q.reshape(N, 2 * n)
    forced = (couple(flat[:-1]).reshape(N - 1, P * 2 * n)
              + w[:-1] @ G_r.transpose(3, 0, 1, 2).reshape(m, P * 2 * n)).reshape(N - 1, P, n, 2)
    r, _ = _eigen_steps(lam, h, forced, np.stack([x0 @ mass_form.T, v0 @ mass_form.T], axis=2))
    u = w @ gains.T  # (N, F) the forces at each time
    values = np.empty((3, P + 1, N, n))
    by = np.concatenate([[1.0], scales])
    for block in range(P + 1):
        state = q if block == 0 else r[:, block - 1]
        to_dofs = shapes.T / by[block]
        np.matmul(state[:, :, 0], to_dofs, out=values[0, block])
        np.matmul(state[:, :, 1], to_dofs, out=values[1, block])
    block_accelerations(base, values, u, columns, dM, dC, dK, scales)
    growth = max(float((np.sqrt(squared) + damping).max()) * h, 1.0)
    accurate = growth > NEEDED_NORM  # the stiff modes' propagators came in double-double
    stated = stated_rounding(2 * chain + N + n, 1.0 if accurate else growth) * max(vector_condition, forcing_condition)
    return values, stated


def _eigen_steps(lam: np.ndarray, h: float, forced: np.ndarray, start: np.ndarray) -> tuple:
    """The modes' states (N, ..., n, 2) [q, q'] from y_(k+1) = E y_k + forced_k (E = V diag(e^(lam h)) V^-1, each
    mode's exact step, V = [[1, 1], [lam+, lam-]]; forced (N - 1, ..., n, 2), start (..., n, 2)), in the modes'
    eigenvectors: c = V^-1 y steps as c_(k+1) = e^(lam h) c_k + V^-1 forced_k, each component on its own, and
    y = V c (q = c+ + c-, q' = lam+ c+ + lam- c-). An underdamped mode's c- is its c+'s conjugate: only c+ is
    stepped. And the longest chain of dependent operations (the rounding's count)."""
    under = lam[:, 0].imag != 0
    modes, which = np.nonzero(~np.stack([np.zeros_like(under), under], axis=1))  # (k, +) each; (k, -) overdamped
    gap = (lam[:, 1] - lam[:, 0])[modes]
    first = np.where(which == 0, lam[modes, 1], -lam[modes, 0]) / gap  # row `which` of V^-1: (first, second)
    second = np.where(which == 0, -1.0, 1.0) / gap
    every = len(modes) == len(lam)  # every mode underdamped: its c+ alone, no gather
    lead, steps = start.shape[:-2], len(forced)
    exponents = np.broadcast_to(lam[modes, which] * h, (*lead, len(modes))).reshape(-1)
    J = _block(exponents, steps)
    c = np.empty((1 + -(-steps // J) * J, len(exponents)), dtype=complex)  # the start, then whole blocks of steps
    into = c[1:steps + 1].reshape(steps, *lead, len(modes))
    if every:  # V^-1 y written in place: forced's two columns times V^-1's row, no complex copies between
        np.multiply(forced[..., 0], first, out=into)
        into += forced[..., 1] * second
        c[0] = (start[..., 0] * first + start[..., 1] * second).reshape(-1)
    else:
        into[...] = forced[..., modes, 0] * first + forced[..., modes, 1] * second
        c[0] = (start[..., modes, 0] * first + start[..., modes, 1] * second).reshape(-1)
    c[steps + 1:] = 0.0
    chain = _diagonal_steps(exponents, c, J)
    c = c[:steps + 1].reshape(steps + 1, *lead, len(modes))
    out = np.empty((steps + 1, *start.shape))
    if every:  # y = 2 Re(c+ (1, lam+)), from c's real and imaginary parts
        np.multiply(c.real, 2.0, out=out[..., 0])
        np.multiply(c.real, 2.0 * lam[:, 0].real, out=out[..., 1])
        out[..., 1] -= c.imag * (2.0 * lam[:, 0].imag)
        return out, chain
    full = np.empty(out.shape, dtype=complex)
    full[..., modes, which] = c
    full[..., under, 1] = full[..., under, 0].conj()
    out[..., 0] = (full[..., 0] + full[..., 1]).real
    out[..., 1] = (full[..., 0] * lam[:, 0] + full[..., 1] * lam[:, 1]).real
    return out, chain


def _block(exponents: np.ndarray, steps: int) -> int:
    """Steps a block of _diagonal_steps takes: at most BLOCK and the run, and so few that |mu|^-J, the growth of its
    sums, stays within e."""
    decay = float(np.max(-exponents.real, initial=0.0))
    return int(max(1, min(BLOCK, steps, 1.0 / decay if decay > 0 else BLOCK)))


def _diagonal_steps(exponents: np.ndarray, c: np.ndarray, J: int) -> int:
    """c_(k+1) = mu c_k + forced_k (mu = e^(exponent)), component by component (complex), in place: c (1 + whole
    blocks of J steps, S) holds c_0, then forced_0, forced_1, ... (zeros past the run), and leaves c_0, c_1, ....
    Within a block c_(b, j) = mu^j (mu c_b + sum_(l <= j) mu^-l forced_(b, l)): the sums row by row (numpy's
    cumsum over this axis takes twice as long), the blocks' starts one after another. The longest chain of
    dependent operations."""
    blocks = c[1:].reshape(-1, J, c.shape[1])
    grow = np.exp(np.arange(J)[:, None] * exponents[None, :])  # mu^0 .. mu^(J - 1)
    blocks *= 1.0 / grow
    for j in range(1, J):
        blocks[:, j] += blocks[:, j - 1]
    mu = np.exp(exponents)
    starts = np.empty((len(blocks), c.shape[1]), dtype=complex)
    starts[0] = c[0]
    for b in range(len(blocks) - 1):
        starts[b + 1] = grow[-1] * (mu * starts[b] + blocks[b, -1])
    starts *= mu
    blocks += starts[:, None, :]
    blocks *= grow
    return J + len(blocks)


def _projected_factors(shapes: np.ndarray, matrix: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
    """Phi^T matrix Phi as (left (n, r), right (r, n)), through the r rows and the columns where the matrix has
    entries (an element's derivative: two, or none); (Phi^T matrix Phi, None) where it has entries in many."""
    rows, cols = np.flatnonzero(matrix.any(axis=1)), np.flatnonzero(matrix.any(axis=0))
    if len(rows) > len(matrix) // 4 or len(cols) > len(matrix) // 4:
        return shapes.T @ matrix @ shapes, None
    return shapes[rows].T, matrix[np.ix_(rows, cols)] @ shapes[cols]


def _product(factors: tuple[np.ndarray, np.ndarray | None]) -> np.ndarray:
    """The matrix _projected_factors' factors stand for."""
    left, right = factors
    return left if right is None else left @ right


def _times(factors: tuple[np.ndarray, np.ndarray | None], X: np.ndarray) -> np.ndarray:
    """The factors' matrix times X, through the thin factors where there are two."""
    left, right = factors
    return left @ X if right is None else left @ (right @ X)


def _thin_pair(Gm: tuple, Gc: tuple, Gk: tuple, squared: np.ndarray, damping: np.ndarray) -> tuple | None:
    """alpha = -(Gk - Gm W) and beta = -(Gc - Gm D) as thin factors ((left, right), (left, right)), each left
    (n, r) and right (r, n), where every projection came in factors; else None."""
    if any(right is None for _, right in (Gm, Gc, Gk)):
        return None
    (Lm, Rm), (Lc, Rc), (Lk, Rk) = Gm, Gc, Gk
    return ((np.hstack([Lk, Lm]), np.vstack([-Rk, Rm * squared])),
            (np.hstack([Lc, Lm]), np.vstack([-Rc, Rm * damping])))


class _Coupling:
    """X (rows, 2n) -> X F_i^T for every parameter (rows, P, 2n), F_i = alpha_i Fc_0 + beta_i Fc_1 entry by entry
    (_coupling_flows' pair flows; pairs: each parameter's alpha and beta as modal_sensitivities holds them). Where
    the series sums Fc over the whole step, Fc_c = phis rows_c, a product of thin matrices (T = SERIES_TERMS), and a
    parameter's alpha and beta come in thin factors of rank r (an element's stiffness, damper or mass: one or two),
    F_i is U V^T of 2 r T columns: X V U^T costs 8 n r T a row, not the dense F_i's 8 n^2 (a 1000-mass chain's
    three parameters: most of the run, 1.25 of its 2.5 s)."""

    def __init__(self, squared: np.ndarray, damping: np.ndarray, h: float, pairs: list):
        n = self.n = len(squared)
        factors = _series_factors(squared, damping, h) if _halvings(squared, damping, h) == 0 else None
        self.parts = []  # per parameter: ("thin", U (2n, R), V (2n, R)) or ("dense", F_i (2n, 2n))
        flows = None
        for pair in pairs:
            thin = all(right is not None for _, right in pair)
            if factors is not None and thin and sum(left.shape[1] for left, _ in pair) * SERIES_TERMS < n // 2:
                phis, powers = factors  # (n, 2, T), (2, T, n, 2)
                U = np.concatenate([(left[:, None, :, None] * phis[:, :, None, :]).reshape(2 * n, -1)
                                    for left, _ in pair], axis=1)
                V = np.concatenate([(right.T[:, None, :, None] * powers[c].transpose(1, 2, 0)[:, :, None, :]
                                     ).reshape(2 * n, -1) for c, (_, right) in enumerate(pair)], axis=1)
                self.parts.append(("thin", U, V))
                continue
            if flows is None:  # (2, n, 2, n, 2): [c, k, row, j, column]
                flows = _coupling_flows(squared, damping, h, factors)
            alpha, beta = (_product(factors_of) for factors_of in pair)
            F = alpha[:, None, :, None] * flows[0] + beta[:, None, :, None] * flows[1]
            self.parts.append(("dense", F.reshape(2 * n, 2 * n)))

    def __call__(self, X: np.ndarray) -> np.ndarray:
        out = np.empty((len(X), len(self.parts), 2 * self.n))
        for i, part in enumerate(self.parts):
            if part[0] == "thin":
                np.matmul(X @ part[2], part[1].T, out=out[:, i])
            else:
                np.matmul(X, part[1].T, out=out[:, i])
        return out


def may_serve(base: Model) -> bool:
    """Whether this path may take the scene (_setup decides, with its parameters and grid): linear, classically
    damped with no rigid-body mode, every force with a small generator."""
    return (base.is_linear and not base.jumps
            and all(s.exo() is not None and s.exo().S.shape[0] <= LARGEST_GENERATOR for s in base.signals)
            and base.proportional_damping and float(base.modes.natural_frequencies.min()) > 0)


def _setup(base: Model, stacked: Model, grid: np.ndarray):
    """(Phi, squared frequencies, damping, the step, [(signal, exo)]) where this path serves, else None."""
    N = len(grid)
    if stacked.n < STACKED_DOFS or N < 3 or stacked.jumps or not may_serve(base):
        return None
    exos = [(signal, signal.exo()) for signal in stacked.signals]  # the scene's and its derivatives' generators
    if any(exo is None or exo.S.shape[0] > LARGEST_GENERATOR for _, exo in exos):
        return None
    h = (grid[-1] - grid[0]) / (N - 1)
    if np.abs(np.diff(grid) - h).max() > 1e-9 * h:
        return None
    edges = stacked.breakpoints(float(grid[0]), float(grid[-1]))
    nearest = grid[0] + np.rint((edges - grid[0]) / h) * h
    if len(edges) and np.abs(nearest - edges).max() > 8 * np.spacing(float(np.abs(grid).max())) + 1e-9 * h:
        return None  # a force's edge between output points: the step would hold it
    shapes, squared, damping = modal_coefficients(base)
    return shapes, squared, damping, h, exos


def _generators(exos) -> tuple[np.ndarray, np.ndarray, list[int]]:
    """The gains (F, m) from the generator states to the forces, their block-diagonal S (m, m) and each signal's
    slice end."""
    sizes = [exo.S.shape[0] for _, exo in exos]
    ends = list(np.cumsum(sizes))
    m = ends[-1] if ends else 0
    gains, S = np.zeros((len(exos), m)), np.zeros((m, m))
    for j, ((_, exo), end, size) in enumerate(zip(exos, ends, sizes)):
        gains[j, end - size:end] = exo.g
        S[end - size:end, end - size:end] = exo.S
    return gains, S, ends


def _eigen(squared: np.ndarray, damping: np.ndarray) -> tuple[np.ndarray, float]:
    """Each mode's eigenvalues (n, 2), lam+- = -d / 2 +- sqrt(d^2 / 4 - w^2), and its eigenvectors' worst condition:
    V = [[1, 1], [lam+, lam-]] degenerates at critical damping."""
    lam = modal_eigenvalues(damping, squared).reshape(2, -1).T
    # in the mode's own scale (w q, q'), V's condition: 1 / sqrt(1 - zeta^2) underdamped, about 2 overdamped
    with np.errstate(divide="ignore"):
        condition = float((2 * np.abs(lam).max(axis=1) / np.abs(lam[:, 1] - lam[:, 0])).max())
    return lam, condition


def _series_pair_flows(squared: np.ndarray, damping: np.ndarray, h: float, factors=None) -> np.ndarray:
    """_coupling_flows' Fc_kj where every mode's |lambda| h is at most SERIES_RADIUS: e^(L_j s) as its
    Taylor series, int_0^h e^(L_k (h - s)) s^m / m! ds = h^(m + 1) phi_(m+1)(L_k h), so that
    Fc_kj = h sum_m [phi_(m+1)(L_k h) e2] [e_c^T (L_j h)^m]: one product of (2 n, SERIES_TERMS) by (SERIES_TERMS,
    2 n) per c, in real arithmetic, with no eigenvectors (critically damped modes alike). Both factors are read off
    the powers of each mode's L h: (L_k h)^i e2 their second columns, e_c^T (L_j h)^m their rows (factors:
    _series_factors' at h, where the caller has them)."""
    n = len(squared)
    phis, rows = _series_factors(squared, damping, h) if factors is None else factors
    pairs = np.empty((2, 2 * n, 2 * n))
    for c in range(2):
        pairs[c] = phis.reshape(2 * n, SERIES_TERMS) @ rows[c].reshape(SERIES_TERMS, 2 * n)
    return pairs.reshape(2, n, 2, n, 2)


def _series_factors(squared: np.ndarray, damping: np.ndarray, h: float) -> tuple[np.ndarray, np.ndarray]:
    """_series_pair_flows' two thin factors: h phi_(m+1)(L_k h) e2 (n, 2, T: k, row; m) and e_c^T (L_j h)^m
    (2, T, n, 2: c; m; j, column), Fc = their product over m."""
    n, terms = len(squared), SERIES_TERMS
    powers = _mode_powers(mode_matrices(squared, damping) * h, 2 * terms)  # (2 terms, n, 2, 2)
    index = np.arange(2 * terms)[:, None] + np.arange(terms)[None, :] + 1
    inverse_factorials = _INVERSE_FACTORIALS[index]  # 1 / (i + m + 1)!
    phis = h * (powers[:, :, :, 1].reshape(2 * terms, 2 * n).T @ inverse_factorials)  # (2 n: k, row; m)
    return phis.reshape(n, 2, terms), np.moveaxis(powers[:terms], 2, 0)


def _mode_powers(M: np.ndarray, count: int) -> np.ndarray:
    """M^0 .. M^(count - 1) of each mode's 2 x 2 matrix M (n, 2, 2), by doubling: (count, n, 2, 2)."""
    out = np.empty((count, *M.shape))
    out[0] = np.eye(2)
    done = 1
    while done < count:
        more = min(done, count - done)
        _times_2x2(out[:more], _times_2x2(out[done - 1], M, np.empty(M.shape)), out[done:done + more])
        done += more
    return out


def _times_2x2(A: np.ndarray, B: np.ndarray, out: np.ndarray) -> np.ndarray:
    """A @ B for stacks of 2 x 2 matrices, entry by entry (numpy's matmul pays a call's work per 2 x 2)."""
    a00, a01, a10, a11 = A[..., 0, 0], A[..., 0, 1], A[..., 1, 0], A[..., 1, 1]
    b00, b01, b10, b11 = B[..., 0, 0], B[..., 0, 1], B[..., 1, 0], B[..., 1, 1]
    out[..., 0, 0] = a00 * b00 + a01 * b10
    out[..., 0, 1] = a00 * b01 + a01 * b11
    out[..., 1, 0] = a10 * b00 + a11 * b10
    out[..., 1, 1] = a10 * b01 + a11 * b11
    return out


def _coupling_flows(squared: np.ndarray, damping: np.ndarray, h: float, factors=None) -> np.ndarray:
    """Fc_kj = int_0^h e^(L_k (h - s)) e2 e_c^T e^(L_j s) ds for every pair of modes, as (c, k, row, j, column):
    by the series over a step of h / 2^s that brings every |lambda| h within SERIES_RADIUS, then squared s times as
    the exponential of [[L_j, 0], [e2 e_c^T, L_k]] squares (its lower-left block: F E_j + E_k F). factors: the
    series' factors at h where no halving is needed and the caller has them."""
    halvings = _halvings(squared, damping, h)
    step = h / 2 ** halvings
    pairs = _series_pair_flows(squared, damping, step, factors if halvings == 0 else None)
    if halvings:
        E = mode_propagators(mode_matrices(squared, damping), step)
        for _ in range(halvings):
            pairs = (np.einsum("ckrjb,jbl->ckrjl", pairs, E, optimize=True)
                     + np.einsum("kra,ckajl->ckrjl", E, pairs, optimize=True))
            E = E @ E
    return pairs


def _halvings(squared: np.ndarray, damping: np.ndarray, h: float) -> int:
    """Halvings of h that bring every mode's |lambda| h within SERIES_RADIUS."""
    radius = float(np.sqrt(np.maximum(squared, damping ** 2)).max(initial=0.0)) * h  # |lambda| <= max(w, d)
    return max(0, math.ceil(math.log2(radius / SERIES_RADIUS))) if radius > SERIES_RADIUS else 0


def _particular(lam: np.ndarray, squared: np.ndarray, damping: np.ndarray, S: np.ndarray, ends: list[int],
                forcing: np.ndarray) -> tuple[np.ndarray, float]:
    """Y (n, 2, m): each mode's particular response to the generator states (L_k Y_k - Y_k S = -e2 forcing_k, one
    small Sylvester equation per mode and signal), and how near resonance it is: the largest of |lambda| / |lambda -
    mu| over the modes' eigenvalues lambda and the generators' mu (Y's condition, in the mode's own scale)."""
    n, m = len(squared), S.shape[0]
    Y = np.zeros((n, 2, m))
    worst = 1.0
    L = mode_matrices(squared, damping)
    start = 0
    for end in ends:
        s = end - start
        block = S[start:end, start:end]
        # vec (column by column) of L Y - Y S: (I_s kron L - S^T kron I_2) vec Y
        operator = np.kron(np.eye(s), L) - np.kron(block.T, np.eye(2))[None]
        rhs = np.zeros((n, 2, s))
        rhs[:, 1] = -forcing[:, start:end]
        solved = np.linalg.solve(operator, rhs.transpose(0, 2, 1).reshape(n, 2 * s, 1))
        Y[:, :, start:end] = solved.reshape(n, s, 2).transpose(0, 2, 1)
        mu = np.linalg.eigvals(block)[None, None, :]
        with np.errstate(divide="ignore", invalid="ignore"):
            near = np.maximum(np.abs(lam[:, :, None]), np.abs(mu)) / np.abs(lam[:, :, None] - mu)
        worst = max(worst, float(np.nan_to_num(near, nan=np.inf).max()))
        start = end
    return Y, worst
