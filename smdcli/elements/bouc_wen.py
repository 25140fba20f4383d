"""The Bouc-Wen hysteretic spring (OpenSees' BoucWen without degradation):

    [[spring]]
    connects = ["ground", "m1"]
    law = "bouc_wen"
    k = 4000.0       # N/m, initial stiffness
    alpha = 0.1      # post-yield stiffness ratio, 0 <= alpha < 1
    beta = 5000.0    # 1/m^n
    gamma = 5000.0   # 1/m^n
    n = 1.0          # sharpness, >= 1
    A = 1.0          # default 1
    z0 = 0.0         # m, default 0

T = alpha k d + (1 - alpha) k z with dz/dt = A d' - beta |d'| |z|^(n-1) z - gamma d' |z|^n. Smooth, with the
hysteretic variable z as an internal state: integrators take it (the ODE family and the Newmark family, the
latter by a trapezoidal update of z inside each step's Newton iteration: smdcli.kernels.return_mapping.z_step). The energy (1 - alpha) k z z' is
stored, the rest of (1 - alpha) k z d' dissipated: hysteretic.

Must not import: scenario, model, solvers, sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

from smdcli.elements.base import KINK, NEWMARK_SMOOTH_Z, RATE, Guard, KernelPiece, Law, Piece, State

SMOOTH_BOUC_WEN = 1  # its smooth tension's kernel code (smdcli.kernels.rhs)

SMOOTH = "smooth"


@dataclass(frozen=True)
class BoucWen(Law):
    """Bouc-Wen: initial stiffness k [N/m], post-yield ratio alpha, shape A, beta, gamma [1/m^n], n; z0 [m]."""

    k: float
    alpha: float
    beta: float
    gamma: float
    n: float = 1.0
    A: float = 1.0
    z0: float = 0.0

    table: ClassVar[str] = "spring"
    name: ClassVar[str] = "bouc_wen"
    keys: ClassVar[tuple[str, ...]] = ("k", "alpha", "A", "beta", "gamma", "n", "z0")
    piecewise_linear: ClassVar[bool] = False
    stiff: ClassVar[bool] = True  # pinned at its saturation, z is stiff
    units: ClassVar[dict[str, str]] = {"k": "N/m", "alpha": "1", "A": "1", "n": "1", "z0": "m"}  # beta, gamma: unit_of
    # alpha k d + (1 - alpha) k z; z' = A d' - beta |d'| |z|^(n-1) z - gamma d' |z|^n, z(0) = z0: all but n
    affine_keys: ClassVar[tuple[str, ...]] = ("k", "alpha", "A", "beta", "gamma", "z0")
    ode_states: ClassVar[tuple[str, ...]] = ("z",)
    internal_names: ClassVar[tuple[str, ...]] = ("z",)

    @classmethod
    def read(cls, t) -> "BoucWen":
        """From a [[spring]] table."""
        k = t.number("k", positive=True)
        alpha = t.number("alpha")
        if not 0.0 <= alpha < 1.0:
            raise t.fail("alpha", f"expected a post-yield stiffness ratio 0 <= alpha < 1, found {alpha:g}")
        n = t.number("n", 1.0)
        if n < 1.0:
            raise t.fail("n", f"expected n >= 1 (the sharpness of the yield), found {n:g}")
        beta, gamma = (t.number(key, unit=f"1/m^{n:g}") for key in ("beta", "gamma"))  # z is a displacement
        A = t.number("A", 1.0, positive=True)
        if beta - gamma < 0 and beta + gamma < 0:
            raise t.fail("beta", f"expected beta + gamma > 0 or beta - gamma >= 0 (z grows without bound on loading "
                                 f"and on unloading otherwise), found beta = {beta:g}, gamma = {gamma:g}")
        return cls(k=k, alpha=alpha, beta=beta, gamma=gamma, n=n, A=A, z0=t.number("z0", 0.0))

    @property
    def dissipation_never_decreases(self) -> bool:
        """With (1 - alpha) k z^2 / 2 stored, the power booked as hysteretic is (1 - alpha) k |d'| |z|^(n+1)
        (beta + gamma sign(d' z)): never negative only where beta >= |gamma|. Elsewhere (the Noel-Schoukens benchmark:
        beta = 800, gamma = -1100) the law itself gives some back on loading; the balance still closes."""
        return self.beta >= abs(self.gamma)

    def unit_of(self, key: str) -> str:
        if key in ("beta", "gamma"):
            return "1/m" if self.n == 1 else f"1/m^{self.n:g}"
        return self.units.get(key, "")

    def warning(self) -> str | None:
        """With beta + gamma <= 0 (the Noel-Schoukens benchmark's identified law, for one) z is not bounded: loading
        on, it grows the faster the larger it is. The run stays bounded while the deformation stays below where
        that growth takes over: (A / |beta + gamma|)^(1/n) / A, where the growth term equals A."""
        c = self.beta + self.gamma
        if c > 0:
            return None
        if c == 0:
            return ("beta + gamma = 0: z grows in proportion to the deformation on loading (no yield: a linear "
                    "spring of stiffness k beyond the linear part)")
        scale = (self.A / -c) ** (1 / self.n) / self.A
        return (f"beta + gamma = {c:g} < 0: z is not bounded; on loading it grows the faster the larger it is, "
                f"taking over beyond a deformation of about {scale:.3g} m (z then {'e-folds' if self.n == 1 else 'doubles'} "
                f"within about that much more): bounded only while the motion stays well below it")

    @property
    def linear_stiffness(self) -> float:
        return self.alpha * self.k

    def start(self, d: float, rate: float) -> State:
        return State(SMOOTH, {"z": self.z0})

    def piece(self, state: State) -> Piece:
        # dz/dt has kinks where d' and z change sign (|d'|, |z|^n): an integrator restarts there, as at an event
        kinks = (Guard(RATE, 0.0, +1, KINK), Guard(RATE, 0.0, -1, KINK),
                 Guard("internal:z", 0.0, +1, KINK), Guard("internal:z", 0.0, -1, KINK))
        return Piece(nonlinear=lambda d, rate, internal: (1 - self.alpha) * self.k * internal["z"], guards=kinks)

    def force_derivatives(self, state: State, d: float, rate: float) -> dict[str, float]:
        z = state.internal["z"]  # alpha k d + (1 - alpha) k z; the shape (A, beta, gamma, n) and z0 act through z
        return {"k": self.alpha * d + (1 - self.alpha) * z, "alpha": self.k * (d - z), "A": 0.0, "beta": 0.0,
                "gamma": 0.0, "n": 0.0, "z0": 0.0}

    def event(self, state: State, kind: str, d: float, rate: float, tension: float) -> State:
        return state  # a kink: nothing changes but the integrator's start

    def z_rate(self, z: float, rate: float) -> float:
        """dz/dt at z and d'."""
        size = abs(z)
        return self.A * rate - self.beta * abs(rate) * size ** (self.n - 1) * z - self.gamma * rate * size ** self.n

    def ode(self, state: State, d: float, rate: float) -> tuple[float, ...]:
        return (self.z_rate(state.internal["z"], rate),)

    def smooth_jacobian(self, state: State, d: float, rate: float):
        # T = (1 - alpha) k z (alpha k d is stamped into K); z' = A d' - beta |d'| |z|^(n-1) z - gamma d' |z|^n
        z = state.internal["z"]
        size = abs(z)
        power = size ** (self.n - 1) if size > 0 or self.n > 1 else 1.0  # |z|^(n-1), 1 at z = 0 for n = 1
        d_rate = self.A - self.beta * math.copysign(1.0, rate) * power * z - self.gamma * size ** self.n
        d_z = -self.n * power * (self.beta * abs(rate) + self.gamma * rate * math.copysign(1.0, z))
        return (0.0, 0.0, (1 - self.alpha) * self.k), ((0.0, d_rate, d_z),)

    def internal_values(self, state: State, d: float) -> tuple[float, ...]:
        return (state.internal["z"],)

    def dissipation(self, state: State, d: float, rate: float, tension: float) -> tuple[str, float]:
        z = state.internal["z"]
        return "hysteretic", (1 - self.alpha) * self.k * z * (rate - self.z_rate(z, rate))

    def kernel_piece(self, state: State) -> KernelPiece:
        return KernelPiece(SMOOTH_BOUC_WEN, ((1 - self.alpha) * self.k, self.A, self.beta, self.gamma, self.n),
                           "hysteretic")

    def newmark_rows(self, d: float) -> list[tuple[int, tuple[float, ...], float]]:
        """Its z, stepped by the trapezoidal rule from z0."""
        return [(NEWMARK_SMOOTH_Z, ((1 - self.alpha) * self.k, self.A, self.beta, self.gamma, self.n), self.z0)]

    def stored(self, state: State, d: float) -> tuple[str, float]:
        z = state.internal["z"]
        return "strain", 0.5 * (1 - self.alpha) * self.k * z * z
