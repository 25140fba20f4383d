"""The assembled system M x'' + C x' + K x + f_nl(x, x') = B u(t).

Springs and dampers are two-terminal elements: each stamps a 2x2 block
[[a, -a], [-a, a]] into K or C (one diagonal entry for an element to
ground). Nonlinear parts (cubic springs, quadratic dampers) act through an
incidence matrix D, one row per element: relative motion d = D x, and the
element forces return to the DOFs as D^T g(d).

Must not import: solvers, sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from smdcli.errors import ScenarioError
from smdcli.model.damping import added_damping, check_damping
from smdcli.model.elements import GROUND, Element, Incidence, elements_of, incidence, incidence_row
from smdcli.shapes import Signal, build_signal
from smdcli.model.ground import MAX_JUMPS, GroundMotion, ground_motion, state_jumps
from smdcli.model.checks import check_finite, check_forces, check_matrices_finite
from smdcli.model.mass import mass_solve, reciprocal_masses
from smdcli.model.modes import RIGID_BODY, Modes, modal_eigenvalues, regime, signed
from smdcli.model.nonsmooth import NonsmoothElement, check_initial_state, initial_stiffness, nonsmooth_elements
from smdcli.model.sparse import (assembled, check_dense_size, cheapest, dense_file_matrices, gershgorin_omega,
                                 is_sparse_scene, lowest_modes, rows_times, symmetric)
from smdcli.scenario import Scenario

# A linear model whose decaying eigenvalues spread wider than this is stiff.
STIFF_RATIO = 1e3
# From this many DOFs the undamped modes of a diagonal M come from the standard symmetric problem (divide and
# conquer), and the damped eigenvalues of a non-classical model from its undamped modal coordinates (T^-1 A T with
# T = diag(Phi, Phi), Phi^T M Phi = I), where LAPACK's QR iteration needs 20 % less time on chains.
MODAL_FORM_DOFS = 64
# The DOF index of a signal that is the ground's acceleration: its column of B is -M 1, on every DOF.
GROUND_DOF = -1


@dataclass(frozen=True)
class Model:
    """Matrices, DOF names, nonlinear elements and force signals of one scenario."""

    dofs: tuple[str, ...]
    M: np.ndarray  # M, C and K: CSR matrices where is_sparse (a scene of more than SPARSE_DOFS masses)
    C: np.ndarray
    K: np.ndarray
    x0: np.ndarray
    v0: np.ndarray
    signals: tuple[Signal, ...] = ()
    force_dofs: tuple[int, ...] = ()  # DOF index each signal acts on
    force_paths: tuple[str, ...] = ()
    force_types: tuple[str, ...] = ()  # each force's `type` as the scenario names it (sine, table, ...)
    cubic: Incidence | None = None  # force k3 d^3
    quadratic: Incidence | None = None  # force c |d'| d'
    source: str = "<model>"
    element_form: bool = True
    ground: GroundMotion | None = None  # support motion: x is measured from the moving ground
    jumps: tuple[tuple[float, np.ndarray, np.ndarray], ...] = ()  # (t, dx, dv): the state jumps there
    elements: tuple[Element, ...] = ()  # the springs and dampers (none in a [system] scene)
    added_damping: np.ndarray | None = None  # [damping]'s part of C
    nonsmooth: tuple[NonsmoothElement, ...] = ()  # hysteretic springs, friction contacts, stops (their laws)
    # B given whole where an input acts on several DOFs (a sensitivity system's), and what each input adds to the
    # absolute accelerations: fields, not cached values, so that every dataclasses.replace of the model keeps them
    inputs: np.ndarray | None = None
    ground_inputs: np.ndarray | None = None

    def with_matrices(self, **changes) -> Model:
        """This model with other matrices (M, C, K, x0, v0...), its ground jumps made from the new M and C."""
        model = dataclasses.replace(self, **changes)
        if model.ground is not None and ("M" in changes or "C" in changes):
            model = dataclasses.replace(model, jumps=state_jumps(model.ground, model.M, model.C))
        return model

    # ------------------------------------------------------------ structure
    @property
    def is_sparse(self) -> bool:
        """M, C and K are CSR matrices (assembled so above SPARSE_DOFS masses)."""
        return not isinstance(self.M, np.ndarray)

    def dense(self) -> Model:
        """This model with dense M, C and K, for the methods that take dense matrices (itself where they are)."""
        if not self.is_sparse:
            return self
        return dataclasses.replace(self, M=self.M.toarray(), C=self.C.toarray(), K=self.K.toarray(),
                                   added_damping=None if self.added_damping is None else self.added_damping.toarray())

    @property
    def n(self) -> int:
        """Number of degrees of freedom."""
        return len(self.dofs)

    @property
    def is_linear(self) -> bool:
        """True when there is no cubic spring, quadratic damper or nonsmooth element."""
        return self.cubic is None and self.quadratic is None and not self.nonsmooth

    @property
    def is_piecewise_linear(self) -> bool:
        """Linear between events: nonsmooth elements of piecewise-linear laws only (elastoplastic, bilinear,
        Coulomb friction, stops), no cubic spring or quadratic damper. Solved exactly, event to event."""
        return bool(self.nonsmooth) and self.cubic is None and self.quadratic is None and \
            all(e.law.piecewise_linear for e in self.nonsmooth)

    @cached_property
    def initial_K(self) -> np.ndarray:
        """K with the hysteretic springs at their elastic stiffness: the scene at rest (modes, [damping])."""
        return initial_stiffness(self.K, self.nonsmooth)

    @property
    def is_forced(self) -> bool:
        """True when any force acts."""
        return bool(self.signals)

    @property
    def nonlinear_paths(self) -> tuple[str, ...]:
        """Field paths of the nonlinear elements, nonsmooth ones included."""
        smooth = sum((inc.paths for inc in (self.cubic, self.quadratic) if inc is not None), ())
        return smooth + tuple(e.path for e in self.nonsmooth)

    @cached_property
    def Minv(self) -> np.ndarray:
        """Inverse mass matrix, by a solve rather than inv() (a sparse scene's diagonal M: its reciprocals, CSR)."""
        if self.is_sparse:
            from scipy.sparse import diags

            return diags(1.0 / self.M.diagonal()).tocsr()
        return mass_solve(self.M, np.eye(self.n))

    @cached_property
    def sparse(self) -> tuple:
        """(C, K, M^-1) as they multiply a grid of states cheapest: CSR where at most a tenth of the entries are
        nonzero (a chain's banded matrices: O(n) a state instead of O(n^2)), else the dense arrays."""
        return cheapest(self.C), cheapest(self.K), cheapest(self.Minv)

    @cached_property
    def B(self) -> np.ndarray:
        """Input matrix: column j puts force j on its DOF; the ground's acceleration is the effective force -M 1 a_g."""
        if self.inputs is not None:
            return self.inputs
        B = np.zeros((self.n, len(self.signals)))
        for j, dof in enumerate(self.force_dofs):
            if dof == GROUND_DOF:
                B[:, j] = -self.M.sum(axis=1)
            else:
                B[dof, j] = 1.0
        return B

    @cached_property
    def state_matrix(self) -> np.ndarray:
        """A = [[0, I], [-M^-1 K, -M^-1 C]] of the linear part."""
        return _state_matrix(self.M, self.C, self.K)

    @cached_property
    def input_matrix(self) -> np.ndarray:
        """[0; M^-1 B]: how the force signals enter the state equation."""
        return np.vstack([np.zeros((self.n, len(self.signals))), mass_solve(self.M, self.B)])

    # --------------------------------------------------------------- forces
    def forces(self, t) -> np.ndarray:
        """Signal values at t: (len(t), n_signals) for an array, (n_signals,) for a scalar."""
        t_arr = np.asarray(t, dtype=float)
        out = np.zeros(t_arr.shape + (len(self.signals),))
        for j, s in enumerate(self.signals):
            out[..., j] = s.value(t_arr)
        return out

    def applied_force(self, t: np.ndarray) -> np.ndarray:
        """External force per DOF on the grid: (N, n)."""
        forces = self.forces(t)
        out = np.zeros(forces.shape[:-1] + (self.n,))
        for j, column in enumerate(self.B.T):  # a force acts on one DOF (the ground's on all): no dense product
            dofs = np.flatnonzero(column)
            out[..., dofs] += forces[..., j, None] * column[dofs]
        return out

    def breakpoints(self, t0: float, t1: float) -> np.ndarray:
        """Sorted distinct times in (t0, t1) where some force jumps or kinks."""
        parts = [s.breakpoints(t0, t1) for s in self.signals]
        if not parts:
            return np.empty(0)
        times = np.unique(np.concatenate(parts))
        # Merge breakpoints closer than rounding: they are one edge.
        if len(times) > 1:
            keep = np.concatenate([[True], np.diff(times) > 1e-12 * max(1.0, abs(t1))])
            times = times[keep]
        return times

    # ------------------------------------------------------------ nonlinear
    def nonlinear_force(self, x: np.ndarray, v: np.ndarray) -> np.ndarray:
        """f_nl(x, v) on the DOFs; x and v may carry a leading time axis."""
        f = np.zeros(np.shape(x))
        if self.cubic is not None:
            d = x @ self.cubic.D.T
            f = f + (self.cubic.coef * d**3) @ self.cubic.D
        if self.quadratic is not None:
            dv = v @ self.quadratic.D.T
            f = f + (self.quadratic.coef * np.abs(dv) * dv) @ self.quadratic.D
        return f

    def tangent(self, x: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Tangent stiffness and damping K + df_nl/dx, C + df_nl/dv at (x, v)."""
        Kt, Ct = self.K, self.C
        if self.cubic is not None:
            d = self.cubic.D @ x
            Kt = _plus_weighted(Kt, self.cubic.D, 3 * self.cubic.coef * d**2)
        if self.quadratic is not None:
            dv = self.quadratic.D @ v
            Ct = _plus_weighted(Ct, self.quadratic.D, 2 * self.quadratic.coef * np.abs(dv))
        return Kt, Ct

    def rhs(self, t: float, y: np.ndarray, u: np.ndarray) -> np.ndarray:
        """State derivative [v; a] for state y = [x; v] and force values u."""
        n = self.n
        dy = self.state_matrix @ y
        if len(u):
            dy += self.input_matrix @ u
        if not self.is_linear:
            dy[n:] -= self.Minv @ self.nonlinear_force(y[:n], y[n:])
        return dy

    def jacobian(self, t: float, y: np.ndarray) -> np.ndarray:
        """Analytic Jacobian of rhs with respect to the state, nonlinear terms included."""
        if self.is_linear:
            return self.state_matrix
        n = self.n
        Kt, Ct = self.tangent(y[:n], y[n:])
        J = np.zeros((2 * n, 2 * n))
        J[:n, n:] = np.eye(n)
        J[n:, :n] = -self.Minv @ Kt
        J[n:, n:] = -self.Minv @ Ct
        return J

    def acceleration(self, x: np.ndarray, v: np.ndarray, force: np.ndarray) -> np.ndarray:
        """a = M^-1 (F - C v - K x - f_nl) on a grid of states, (N, n) each."""
        C, K, Minv = self.sparse
        rest = force - rows_times(v, C.T) - rows_times(x, K.T)
        if not self.is_linear:
            rest = rest - self.nonlinear_force(x, v)
        inverse = reciprocal_masses(self.M)  # a diagonal M's: a product by each 1 / m, not by M^-1
        return rest * inverse if inverse is not None else rows_times(rest, Minv.T)

    # ----------------------------------------------------------------- modes
    @cached_property
    def modes(self) -> Modes:
        """Natural frequencies, damping ratios and regimes of the linear part (hysteretic springs elastic)."""
        K = self.initial_K
        n = self.n
        if self.is_sparse:
            return lowest_modes(self)
        if n == 1:
            m, c, k = self.M[0, 0], self.C[0, 0], K[0, 0]
            wn = math.sqrt(k / m)
            zeta = c / (2 * math.sqrt(k * m)) if k > 0 else math.inf
            eig = np.roots([m, c, k]).astype(complex)
            return Modes(eig, np.array([wn]), np.array([zeta]), (regime(zeta, wn),), np.array([[1 / math.sqrt(m)]]))
        from scipy.linalg import eigh

        masses = np.diag(self.M)
        if n >= MODAL_FORM_DOFS and np.count_nonzero(self.M) == np.count_nonzero(masses):
            # Diagonal M: the standard problem of M^-1/2 K M^-1/2 by divide and conquer, half the generalized time;
            # a chain's is tridiagonal: MRRR (O(n^2), not O(n^3))
            root = 1.0 / np.sqrt(masses)
            scaled = K * root[:, None] * root[None, :]
            if not np.triu(scaled, 2).any():
                from scipy.linalg import eigh_tridiagonal

                squared, shapes = eigh_tridiagonal(np.diag(scaled).copy(), np.diag(scaled, 1).copy(),
                                                   lapack_driver="stemr")
            else:
                squared, shapes = eigh(scaled, driver="evd")
            shapes = shapes * root[:, None]
        else:
            squared, shapes = eigh(K, self.M)
        classical = self.proportional_damping and squared.min() > 0
        if classical:  # C = Phi^-T diag(c) Phi^-1: each mode a 1-DOF oscillator (symmetric solver, 5-10x faster)
            wn = np.sqrt(squared)
            c = (shapes * (self.sparse[0] @ shapes)).sum(axis=0)  # the diagonal of Phi^T C Phi
            zeta = c / (2 * wn)
            eig = modal_eigenvalues(c, squared)
        elif n >= MODAL_FORM_DOFS:  # the same eigenvalues from [[0, I], [-Omega^2, -Phi^T C Phi]]: 20 % faster
            modal = np.zeros((2 * n, 2 * n))
            modal[:n, n:] = np.eye(n)
            modal[n:, :n] = -np.diag(squared)
            modal[n:, n:] = -(shapes.T @ self.C @ shapes)
            eig = np.linalg.eigvals(modal)
        else:
            eig = np.linalg.eigvals(self.state_matrix if K is self.K else _state_matrix(self.M, self.C, K))
        eig = eig[np.lexsort((eig.real, eig.imag))]  # one order whatever LAPACK returns
        if not classical:
            wn, zeta = _pair_modes(eig)
        order = np.argsort(wn, kind="stable")
        wn, zeta = wn[order], zeta[order]
        shapes = signed(shapes)
        # A rigid-body mode's frequency is a rounding of zero: sqrt(eps) of the largest, from its squared value
        rigid = wn <= RIGID_BODY * wn.max()
        return Modes(eig, wn, zeta, tuple(regime(z, 0.0 if r else w) for z, w, r in zip(zeta, wn, rigid)), shapes)

    @cached_property
    def proportional_damping(self) -> bool:
        """C M^-1 K = K M^-1 C (Caughey's condition) with M and K symmetric: the undamped modes decouple the damped
        system too (a sensitivity system's block-triangular M and K have no such modes)."""
        K = self.initial_K
        if not (symmetric(self.M) and symmetric(K)):
            return False
        C, _, Minv = self.sparse
        CK = C @ (Minv @ cheapest(K))  # dense or CSR alike
        scale = np.abs(self.C).max(initial=0.0) * np.abs(self.Minv).max(initial=0.0) * np.abs(K).max(initial=0.0)
        return bool(abs(CK - CK.T).max() <= 1e-12 * self.n * scale)

    @cached_property
    def stiffness_ratio(self) -> float:
        """max |Re lambda| / min |Re lambda| over the decaying eigenvalues of the linear part (1 if none decay)."""
        re = np.abs(self.modes.eigenvalues.real)
        scale = np.abs(self.modes.eigenvalues).max(initial=0.0)
        re = re[re > 1e-12 * max(scale, 1.0)]
        return float(re.max() / re.min()) if len(re) else 1.0

    @cached_property
    def omega_max(self) -> float:
        """Highest undamped natural frequency, rad/s: what bounds an explicit step (a sparse scene's, whose modes are
        the lowest few: Gershgorin's bound on it)."""
        if self.is_sparse:
            return gershgorin_omega(self)
        return float(self.modes.natural_frequencies.max())

    @property
    def is_stiff(self) -> bool:
        """Stiff in the classical sense: decay rates spread over STIFF_RATIO (1000) or more."""
        return self.stiffness_ratio >= STIFF_RATIO * (1 - 1e-9)


def _plus_weighted(A, D: np.ndarray, w: np.ndarray):
    """A + D^T diag(w) D: dense, or CSR for a sparse scene's A (its few incidence rows made sparse)."""
    if isinstance(A, np.ndarray):
        return A + D.T @ (w[:, None] * D)
    from scipy.sparse import csr_matrix, diags

    rows = csr_matrix(D)
    return A + rows.T @ diags(w) @ rows


def _state_matrix(M: np.ndarray, C: np.ndarray, K: np.ndarray) -> np.ndarray:
    """[[0, I], [-M^-1 K, -M^-1 C]]."""
    n = len(M)
    A = np.zeros((2 * n, 2 * n))
    A[:n, n:] = np.eye(n)
    A[n:, :n] = -mass_solve(M, K)  # not Minv @ K: a division where M is diagonal, O(n^2)
    A[n:, n:] = -mass_solve(M, C)
    return A


def _pair_modes(eig: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Group state eigenvalues into n modes; from each pair, wn = sqrt(l1 l2) and zeta = -(l1 + l2) / (2 wn)."""
    scale = max(np.abs(eig).max(initial=0.0), 1.0)
    is_complex = np.abs(eig.imag) > 1e-9 * scale
    upper = eig[is_complex & (eig.imag > 0)]
    pairs = [(lam, np.conj(lam)) for lam in upper]
    real = np.sort(eig[~is_complex].real)  # most negative first
    # Real eigenvalues come from overdamped (or critically damped) modes; pair them outside in.
    while len(real) >= 2:
        pairs.append((real[0], real[-1]))
        real = real[1:-1]
    if len(real):  # a lone real root: a rigid-body mode with a damper
        pairs.append((real[0], 0.0))
    wn = np.array([math.sqrt(max((a * b).real, 0.0)) for a, b in pairs])
    zeta = np.array([(-(a + b).real / (2 * w)) if w > 0 else math.inf for (a, b), w in zip(pairs, wn)])
    zeta = np.where(np.abs(zeta) < 1e-12, 0.0, zeta)
    return wn, zeta


def build(scenario: Scenario) -> Model:
    """Assemble the Model of a validated scenario."""
    dofs = scenario.dof_names
    index = {name: i for i, name in enumerate(dofs)}
    n = len(dofs)
    cubic = quadratic = None
    check_dense_size(scenario)
    if scenario.system is not None:
        sys = scenario.system
        if is_sparse_scene(scenario):  # matrices from files, kept sparse
            M, C, K = sys.M, sys.C, sys.K
        else:
            M, C, K = dense_file_matrices(scenario) if sys.from_files else sys.dense()
        x0, v0 = np.array(sys.x0, dtype=float), np.array(sys.v0, dtype=float)
    else:
        masses = np.array([m.m for m in scenario.masses], dtype=float)
        x0 = np.array([m.x0 for m in scenario.masses], dtype=float)
        v0 = np.array([m.v0 for m in scenario.masses], dtype=float)
        stamps = {"spring": ([], [], []), "damper": ([], [], [])}  # (rows, columns, values): summed where they meet
        cubic_rows, quad_rows = [], []
        for element in scenario.springs + scenario.dampers:
            if element.kind == "damper" and element.law == "quadratic":
                quad_rows.append((incidence_row(element.connects, index, n), element.coef, element.path))
                continue
            # its one or two nodes, +1 and -1 (the ground has none): a 2x2 stamp, not a row of n per element
            ends = [(index[node], sign) for node, sign in zip(element.connects, (1.0, -1.0)) if node != GROUND]
            # a hysteretic spring stamps only the stiffness it always has (a bilinear spring's b k); its law the rest
            coef = float(element.coef if element.nonsmooth is None else element.nonsmooth.linear_stiffness)
            rows, columns, values = stamps[element.kind]
            for i, si in ends:  # coef * si * sj: +-coef (an overflow, inf, is named by check_finite below)
                for j, sj in ends:
                    rows.append(i), columns.append(j), values.append(coef if si == sj else -coef)
            if element.law == "cubic":
                cubic_rows.append((incidence_row(element.connects, index, n), element.k3, element.path))
        sparse = is_sparse_scene(scenario)
        M, K, C = (assembled(masses_or_stamp, n, sparse) for masses_or_stamp in
                   ((range(n), range(n), masses), stamps["spring"], stamps["damper"]))
        cubic, quadratic = incidence(cubic_rows), incidence(quad_rows)
    nonsmooth = nonsmooth_elements(scenario, dofs)
    check_initial_state(scenario, nonsmooth, x0)
    check_finite(scenario, dofs, K=K, C=C)
    check_matrices_finite(M, C, initial_stiffness(K, nonsmooth), scenario, dofs)  # before [damping]'s modes
    with np.errstate(all="ignore"):
        try:  # of the scene at rest: hysteretic springs at their elastic stiffness, as structural codes take it
            extra = added_damping(scenario, M, initial_stiffness(K, nonsmooth)) if scenario.damping is not None else None
        except (np.linalg.LinAlgError, ValueError) as exc:  # LAPACK's eigensolver gave up on these matrices
            raise ScenarioError(scenario.path, f"damping.{scenario.damping.given}", "the undamped modes it is "
                                f"defined by cannot be computed ({str(exc).split('.')[0]}); check M and K") from None
        C = C if extra is None else C + extra
    check_finite(scenario, dofs, C=C)
    check_matrices_finite(M, C, K, scenario, dofs)
    signals = tuple(build_signal(f) for f in scenario.forces)
    force_dofs = tuple(index[f.on] for f in scenario.forces)
    shapes = scenario.forces
    ground = jumps = None
    if scenario.ground_motion is not None:
        ground = ground_motion(scenario.ground_motion, scenario.time.start, scenario.time.end, scenario.path)
        if len(ground.jumps) > MAX_JUMPS:  # jumps of displacement and of velocity together
            raise ScenarioError(scenario.path, "ground_motion", f"the ground's displacement or velocity jumps "
                                f"{len(ground.jumps)} times in the run (limit {MAX_JUMPS}); each is a restart")
        jumps = state_jumps(ground, M, C)
        if ground.acceleration is not None:
            signals += (ground.acceleration,)
            force_dofs += (GROUND_DOF,)
            shapes += (scenario.ground_motion.shape,)
    model = Model(
        dofs=dofs, M=M, C=C, K=K, x0=x0, v0=v0, signals=signals, force_dofs=force_dofs,
        force_paths=tuple(f.path for f in shapes),
        force_types=tuple(f.type for f in shapes),
        cubic=cubic, quadratic=quadratic, source=scenario.path,
        element_form=scenario.system is None, ground=ground, jumps=jumps or (),
        elements=elements_of(scenario, dofs), added_damping=extra, nonsmooth=nonsmooth)
    check_forces(model, scenario)
    check_damping(model.C, scenario)
    return model
