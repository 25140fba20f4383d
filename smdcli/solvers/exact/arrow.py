"""The flow of a sensitivity system by its arrow structure, never the stacked exponential.

The stacked sensitivity system (analysis/model_derivative.augmented_model) holds the scene and P copies of it, each
copy driven by the scene's state and by nothing else. Ordered [w; s_1; ...; s_P] (w the scene's x, v and every force
generator's state, q entries; s_i block i's x and v, 2n), its augmented matrix is an arrow:

    Z = [[A_w, 0], [B_i, A]]    (A = A_w's leading 2n x 2n block: the scene's own [x; v] matrix)

and so is every polynomial in it, its exponential among them: [[E_w, 0], [F_i, E]], E again E_w's leading block.
A product of two arrows costs one of the scene's (q^3) and 2 P of a block against it (2n q^2 each), where the
stacked system's costs ((P + 1) q)^3: the exponential (Higham's Pade 13 after scaling, as accurate_expm.expm_stack),
the powers a block of output steps takes and the rows read at each of them cost 3/8 of the stacked system's at
P = 1, 5/27 at P = 2: a row of copy i is read over J steps on its own columns and the scene's alone.

It serves where double scaling and squaring is accurate (||Z h||_1 up to NEEDED_NORM); a stiff scene's stacked
system takes the dense path, balanced and in double-double (accurate_expm.propagator).

Must not import: sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import math

import numpy as np

from smdcli.solvers.exact.accurate_expm import NEEDED_NORM, PADE_13, THETA_13, flush_negligible
from smdcli.solvers.exact.dense_flow import DENSE_ENTRY_S, DENSE_FLOP_S
from smdcli.solvers.base import stated_rounding
from smdcli.solvers.exact.sampled import BLOCK, recurrence, table_states
from smdcli.text import plural

_CALL_S = 6e-6  # a numpy call on small arrays


class Arrow:
    """[[X, 0], [Y_i, X_lead]]: the scene's block X (q, q), each copy's coupling Y (P, 2n, q), and the copies'
    diagonal X's leading 2n x 2n block (not stored)."""

    __slots__ = ("X", "Y")

    def __init__(self, X: np.ndarray, Y: np.ndarray):
        self.X, self.Y = X, Y

    def __matmul__(self, other: Arrow) -> Arrow:
        lead = self.Y.shape[1]
        return Arrow(self.X @ other.X, self.Y @ other.X + np.matmul(self.X[:lead, :lead], other.Y))

    def combined(self, terms: list[tuple[float, Arrow]]) -> Arrow:
        """self plus sum c_k T_k."""
        X, Y = self.X.copy(), self.Y.copy()
        for c, term in terms:
            X += c * term.X
            Y += c * term.Y
        return Arrow(X, Y)

    def times(self, w: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The arrow applied to a state: (X w, Y_i w + X_lead s_i), s (P, 2n)."""
        lead = self.Y.shape[1]
        return self.X @ w, self.Y @ w + s @ self.X[:lead, :lead].T

    def dense(self) -> np.ndarray:
        """The arrow as one matrix."""
        q, (P, lead, _) = len(self.X), self.Y.shape
        out = np.zeros((q + P * lead, q + P * lead))
        out[:q, :q] = self.X
        out[q:, :q] = self.Y.reshape(P * lead, q)
        for i in range(P):
            out[q + i * lead:q + (i + 1) * lead, q + i * lead:q + (i + 1) * lead] = self.X[:lead, :lead]
        return out

    def flushed(self) -> Arrow:
        """Negligible entries zeroed, in place (flush_negligible)."""
        flush_negligible(self.X)
        flush_negligible(self.Y)
        return self


def arrow_form(Aaug: np.ndarray, n: int, copies: int) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """(order, A_w, B) where the stacked system's augmented matrix (z = [x_0 .. x_P; v_0 .. v_P; generators], n DOFs
    a block) is the arrow of the module's docstring: order puts z as [w; s_1; ...; s_P], A_w (q, q) and B (P, 2n, q);
    None where it is not (a copy reaching another, or not the scene's own matrix)."""
    total = (copies + 1) * n
    m = Aaug.shape[0] - 2 * total
    scene = np.r_[0:n, total:total + n, 2 * total:2 * total + m]
    own = [np.r_[(i + 1) * n:(i + 2) * n, total + (i + 1) * n:total + (i + 2) * n] for i in range(copies)]
    order = np.concatenate([scene, *own])
    Z = Aaug[np.ix_(order, order)]
    q, lead = len(scene), 2 * n
    A_w = Z[:q, :q]
    if Z[:q, q:].any():
        return None
    B = np.empty((copies, lead, q))
    for i in range(copies):
        rows = slice(q + i * lead, q + (i + 1) * lead)
        block = Z[rows, q:].reshape(lead, copies, lead)
        if not np.array_equal(block[:, i], A_w[:lead, :lead]) or np.delete(block, i, axis=1).any():
            return None
        B[i] = Z[rows, :q]
    return order, np.ascontiguousarray(A_w), B


def arrow_expm(A_w: np.ndarray, B: np.ndarray, t: float) -> tuple[Arrow, float] | None:
    """exp(Z t) of the arrow Z = [[A_w, 0], [B_i, A_w's lead]] and ||Z t||_1; None where that norm is past
    NEEDED_NORM (double scaling and squaring would lose digits: the stacked system's balanced or double-double
    exponential takes it). Higham's Pade 13 after scaling by 2^-s, then s squarings."""
    lead = B.shape[1]
    columns = np.abs(A_w).sum(axis=0) + np.abs(B).sum(axis=(0, 1))
    columns[:lead] = np.maximum(columns[:lead], np.abs(A_w[:lead, :lead]).sum(axis=0))
    norm = float(columns.max(initial=0.0)) * abs(t)
    if norm > NEEDED_NORM:
        return None
    squarings = max(0, math.ceil(math.log2(norm / THETA_13))) if norm > 0 else 0
    scale = math.ldexp(t, -squarings)
    A = Arrow(A_w * scale, B * scale)
    b = PADE_13
    A2 = A @ A
    A4 = A2 @ A2
    A6 = A4 @ A2
    zero = Arrow(np.zeros_like(A_w), np.zeros_like(B))
    eye = Arrow(np.eye(len(A_w)), np.zeros_like(B))
    U = A @ (A6 @ zero.combined([(b[13], A6), (b[11], A4), (b[9], A2)])).combined(
        [(b[7], A6), (b[5], A4), (b[3], A2), (b[1], eye)])
    V = (A6 @ zero.combined([(b[12], A6), (b[10], A4), (b[8], A2)])).combined(
        [(b[6], A6), (b[4], A4), (b[2], A2), (b[0], eye)])
    # (V - U) E = V + U, block by block: the scene's block first, then each copy's against it
    below, above = V.combined([(-1.0, U)]), V.combined([(1.0, U)])
    X = np.linalg.solve(below.X, above.X)
    rest = (above.Y - below.Y @ X).transpose(1, 0, 2).reshape(lead, -1)
    Y = np.linalg.solve(below.X[:lead, :lead], rest).reshape(lead, len(B), -1).transpose(1, 0, 2)
    E = Arrow(X, np.ascontiguousarray(Y)).flushed()
    for _ in range(squarings):
        E = (E @ E).flushed()
    return E, norm


class ArrowFlow:
    """The arrow system's flow over a uniform grid's step h, for linear.propagate: the state in the arrow's order
    (linear.augmented's z taken at `order`), stepped by powers of the step's arrow (the 2^k-th powers up to J kept),
    and its rows read over J steps by doubling. growth: ||Z h||_1."""

    def __init__(self, order: np.ndarray, A_w: np.ndarray, B: np.ndarray, step: Arrow, growth: float, J: int):
        self.order, self.A_w, self.B, self.growth, self.J = order, A_w, B, growth, J
        self.q, self.copies, self.lead = len(A_w), len(B), B.shape[1]
        self.doubled = [step]  # step^(2^k)
        while 2 ** len(self.doubled) <= J:
            self.doubled.append((self.doubled[-1] @ self.doubled[-1]).flushed())
        self._over: dict[float, Arrow] = {}
        self.generators = slice(self.lead, self.q)  # the force generators' states in the arrow's order
        self._whole = self.doubled[-1].dense() if 2 ** (len(self.doubled) - 1) == J else None  # a block's J steps

    @classmethod
    def of(cls, Aaug: np.ndarray, n: int, copies: int, h: float, N: int, rows: int) -> ArrowFlow | None:
        """The flow where the stacked system is an arrow of `copies` copies of an n-DOF scene and its step's
        exponential is accurate in double; else None. rows: the rows read at every step (J's choice)."""
        form = arrow_form(Aaug, n, copies)
        if form is None:
            return None
        order, A_w, B = form
        found = arrow_expm(A_w, B, h)
        if found is None:
            return None
        step, growth = found
        return cls(order, A_w, B, step, growth, _steps_per_block(len(A_w), 2 * n, copies, N, rows))

    def step(self, z: np.ndarray, count: int) -> np.ndarray:
        """z (in the arrow's order) after count steps of h (1 <= count <= J): a whole block's by the J-th power as one
        matrix (one product, where the arrow's own three cost their calls), a part by the kept 2^k-th powers."""
        if count == self.J and self._whole is not None:
            return self._whole @ z
        w, s = z[:self.q], z[self.q:].reshape(self.copies, self.lead)
        k = 0
        while count:
            if count & 1:
                w, s = self.doubled[k].times(w, s)
            count >>= 1
            k += 1
        return np.concatenate([w, s.reshape(-1)])

    def advance(self, z: np.ndarray, dt: float) -> np.ndarray:
        """z (in the arrow's order) after dt (a force's breakpoint between output points: no longer than h, so that
        its exponential is accurate in double as h's is)."""
        if dt not in self._over:
            self._over[dt] = arrow_expm(self.A_w, self.B, dt)[0]
        w, s = self._over[dt].times(z[:self.q], z[self.q:].reshape(self.copies, self.lead))
        return np.concatenate([w, s.reshape(-1)])

    def tables(self, rows: np.ndarray) -> np.ndarray:
        """rows (r, size, in the arrow's order) times the step's powers 1 .. J, (J, r, size), each row reaching the
        scene's entries and at most one copy's (linear._arrow_flow's check): the first power, then powers k + 1 ..
        2k from powers 1 .. k and the kept k-th power, a row on the scene alone by T_w <- T_w E_w, one reaching copy
        i by (T_w, T_i) <- (T_w E_w + T_i F_i, T_i E). Each T flushed of negligible entries (the rows, where the caller
        flushed them, and the arrow have none): no product meets a subnormal number."""
        J, q, lead = self.J, self.q, self.lead
        out = np.zeros((J, len(rows), rows.shape[1]))
        reach = rows[:, q:].reshape(len(rows), self.copies, lead).any(axis=2)  # (r, P)
        groups = [(np.flatnonzero(~reach.any(axis=1)), None)]
        groups += [(np.flatnonzero(reach[:, i]), i) for i in range(self.copies)]
        for picked, i in groups:
            if not len(picked):
                continue
            into = _as_slice(picked)
            T_w = np.empty((J, len(picked), q))
            T_w[0] = rows[into, :q]
            if i is not None:
                own = slice(q + i * lead, q + (i + 1) * lead)
                T_i = np.empty((J, len(picked), lead))
                T_i[0] = rows[into, own]
            done = 0
            while done < J:  # the first power from the rows themselves, then by doubling (J and done powers of 2)
                if done == 0:
                    to, of, count, power = slice(0, 1), slice(0, 1), 1, self.doubled[0]
                else:
                    count = min(done, J - done)
                    to, of, power = slice(done, done + count), slice(0, count), self.doubled[done.bit_length() - 1]
                # each stack of rows as one matrix: one product, not one per power
                rows_w, into_w = T_w[of].reshape(-1, q), T_w[to].reshape(-1, q)
                if i is None:
                    np.matmul(rows_w, power.X, out=into_w)
                else:
                    rows_i, into_i = T_i[of].reshape(-1, lead), T_i[to].reshape(-1, lead)
                    np.matmul(rows_w, power.X, out=into_w)
                    into_w += rows_i @ power.Y[i]
                    np.matmul(rows_i, power.X[:lead, :lead], out=into_i)
                    flush_negligible(into_i)
                flush_negligible(into_w)
                done += count
            out[:, into, :q] = T_w
            if i is not None:
                out[:, into, own] = T_i
        return out


def _as_slice(indices: np.ndarray) -> slice | np.ndarray:
    """indices as a slice where they run unbroken (a view, not a copy, when indexed), else as they are."""
    if indices[-1] - indices[0] == len(indices) - 1:
        return slice(int(indices[0]), int(indices[-1]) + 1)
    return indices


def _steps_per_block(q: int, lead: int, copies: int, N: int, rows: int) -> int:
    """Output steps a block takes (a power of two, at most BLOCK and the run): the fewest seconds for the J rows'
    tables (each step of the recurrence a product of the rows by the arrow's columns that reach them) and the N / J
    blocks' starts (a few products with the state each)."""
    table, start = _table_and_start(q, lead, copies, rows)
    best = math.sqrt(max(N - 1, 1) * start / table)
    J = 2 ** max(0, round(math.log2(max(best, 1.0))))
    return int(max(1, min(BLOCK, J, 2 ** int(math.log2(max(N - 1, 1))))))


def _table_and_start(q: int, lead: int, copies: int, rows: int) -> tuple[float, float]:
    """Seconds of one power of the rows' tables (its products at the speed this machine's BLAS reaches on such thin
    ones, 2.4 times the dense path's flop time, and their calls), and of one block's start (a product by the J-th
    power as one matrix): fitted to the 10- to 63-mass chains' sensitivities, where the J they give was the fastest."""
    size = q + copies * lead
    table = _CALL_S * 8 * (1 + copies) + 2.4 * 2 * rows * (q * q + 2 * lead * q) * DENSE_FLOP_S
    start = _CALL_S * 2 + size * size * DENSE_ENTRY_S
    return table, start


def arrow_cost(q: int, lead: int, copies: int, N: int, rows: int) -> float:
    """Estimated seconds of the arrow's flow over N output steps reading `rows` rows (linear.dense_cost's
    counterpart): the exponential and the kept powers, the tables, the blocks' starts and the reads."""
    J = _steps_per_block(q, lead, copies, N, rows)
    table, start = _table_and_start(q, lead, copies, rows)
    product = 2 * (q ** 3 + 2 * copies * lead * q * q) * DENSE_FLOP_S
    return (16 + math.log2(J)) * product + J * table + N / J * start + 2 * N * rows * (q + lead) * DENSE_FLOP_S


def arrow_sampled_states(model, knots, Aaug: np.ndarray, blocks, copies: int) -> tuple[np.ndarray, float, str] | None:
    """sampled.sampled_states of a sensitivity system of `copies` copies (the stacked [x; v] (N, 2 (P + 1) n) at the
    output points, in the stacked order, the stated accuracy and a description) by its arrow: the scene's recurrence
    over every knot, then every copy's at once, driven by the scene's states through F_i (E, F_i and the generators'
    columns the step's arrow's blocks): (1 + 2P) (2n)^2 a step where the stacked recurrence takes (2 (P + 1) n)^2.
    None where the system is not an arrow or its step's exponential not accurate in double."""
    total = model.n
    n = total // (copies + 1)
    form = arrow_form(Aaug, n, copies)
    found = None if form is None else arrow_expm(form[1], form[2], knots.step)
    if found is None:
        return None
    (order, A_w, _), (step, norm) = form, found
    lead, q = 2 * n, len(A_w)
    steps = len(knots.times) - 1
    w = table_states(blocks, knots.read_at[:-1], 2 * total)  # the generators, in the scene's order as in the stack
    z = np.zeros(len(Aaug))
    z[:total], z[total:2 * total] = model.x0, model.v0
    z = z[order]
    E = step.X[None, :lead, :lead]
    scene, scene_chain = recurrence(E, (w @ step.X[:lead, lead:].T)[:, None], z[None, :lead], np.arange(steps + 1),
                                    flush=True)
    coupling = step.Y.transpose(2, 0, 1).reshape(q, copies * lead)  # [F_i, the generators' columns] of every copy
    forced = flush_negligible(scene[:-1, 0] @ coupling[:lead] + w @ coupling[lead:]).reshape(steps, copies, lead)
    copied, copy_chain = recurrence(E, forced, z[q:].reshape(copies, lead), knots.rows, flush=True)
    states = np.empty((len(knots.rows), 2 * total))
    states[:, order[:lead]] = scene[knots.rows, 0]
    states[:, order[q:]] = copied.reshape(len(knots.rows), copies * lead)
    stated = stated_rounding(steps + scene_chain + copy_chain, norm)
    message = (f"ok: {plural(steps, 'step')} between the tables' samples and the output points, each exact for the "
               f"tables' first-order hold, by the stacked system's arrow (the scene's state of size {lead} and "
               f"{plural(copies, 'copy', 'copies')})")
    return states, stated, message
