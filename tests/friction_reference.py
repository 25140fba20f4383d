"""An independent event-driven solution of masses with linear springs and dampers and Coulomb friction contacts
(static breakaway >= kinetic force), written here with scipy's solve_ivp and its own event location, not smd's
modes or decisions: the reference the friction tests compare every method with.

A stuck contact's force is the constraint force that keeps its relative velocity zero (the KKT system of the stuck
set); it breaks away when that force reaches its static force, and then slips the way the force pushed. A slipping
contact whose relative velocity reaches zero sticks if the stuck set including it holds every stuck force within
its static force, else it slips on the way its acceleration takes it. A jump of the force re-decides the stuck set.
"""

from __future__ import annotations

import itertools

import numpy as np
from scipy.integrate import solve_ivp


class FrictionReference:
    """M x'' + C x' + K x + sum_e T_e r_e = f(t); T_e the tension of contact e (r_e . v its relative velocity)."""

    def __init__(self, M, C, K, contacts, force, breaks=()):
        self.M, self.C, self.K = (np.asarray(a, dtype=float) for a in (M, C, K))
        self.rows = np.array([r for r, _, _ in contacts], dtype=float).reshape(len(contacts), len(self.M))
        self.kinetic = np.array([fk for _, fk, _ in contacts], dtype=float)
        self.static = np.array([fs for _, _, fs in contacts], dtype=float)
        self.force, self.breaks = force, sorted(breaks)

    def solve_mode(self, t, y, signs):
        """(acceleration, tensions) with signs[e] = 0 for a stuck contact, +-1 for one slipping that way."""
        n = len(self.M)
        x, v = y[:n], y[n:]
        rhs = self.force(min(t, self.until)) - self.K @ x - self.C @ v
        tensions = np.where(signs != 0, signs * self.kinetic, 0.0)
        rhs = rhs - self.rows.T @ tensions
        stuck = np.flatnonzero(signs == 0)
        G = self.rows[stuck]
        kkt = np.block([[self.M, G.T], [G, np.zeros((len(stuck), len(stuck)))]])
        solution = np.linalg.solve(kkt, np.concatenate([rhs, np.zeros(len(stuck))]))
        tensions[stuck] = solution[n:]
        return solution[:n], tensions

    def decide(self, t, y, signs, zero):
        """The modes at (t, y): contacts in `zero` (at zero relative speed) stick or slip, the others kept."""
        for size in range(len(zero), -1, -1):
            for stuck in itertools.combinations(zero, size):
                sliding = [e for e in zero if e not in stuck]
                for directions in itertools.product((1.0, -1.0), repeat=len(sliding)):
                    trial = signs.copy()
                    trial[list(stuck)] = 0.0
                    trial[sliding] = directions
                    a, tensions = self.solve_mode(t, y, trial)
                    if np.any(np.abs(tensions[list(stuck)]) > self.static[list(stuck)] * (1 + 1e-12)):
                        continue
                    if all(d * (self.rows[e] @ a) > 0 for e, d in zip(sliding, directions)):
                        return trial
        raise AssertionError(f"no consistent mode at t = {t}")

    def run(self, grid, x0, v0):
        """x on the grid."""
        n = len(self.M)
        y = np.concatenate([x0, v0]).astype(float)
        t, t_end = float(grid[0]), float(grid[-1])
        spacing = (t_end - t) / max(len(grid) - 1, 1)
        self.until = np.inf
        rates = self.rows @ y[n:]
        signs = np.sign(rates)
        signs = self.decide(t, y, signs, [e for e in range(len(signs)) if signs[e] == 0])
        out = np.full((len(grid), n), np.nan)
        cuts = [b for b in self.breaks if t < b < t_end] + [t_end]
        while t < t_end:
            t_stop = next(c for c in cuts if c > t)
            self.until = float(np.nextafter(t_stop, -np.inf))  # the force's left limit at the segment's end
            events = []
            for e in range(len(signs)):
                if signs[e] == 0:
                    def breaks_away(tt, yy, e=e):
                        return abs(self.solve_mode(tt, yy, signs)[1][e]) - self.static[e]
                    breaks_away.terminal, breaks_away.direction = True, 1
                    events.append((e, "slip", breaks_away))
                else:
                    def stops(tt, yy, e=e):
                        return self.rows[e] @ yy[n:]
                    stops.terminal, stops.direction = True, -signs[e]
                    events.append((e, "stick", stops))

            def rhs(tt, yy):
                return np.concatenate([yy[n:], self.solve_mode(tt, yy, signs)[0]])

            # steps no longer than the output's: while stuck nothing moves, and a step would span the force's periods
            sol = solve_ivp(rhs, (t, t_stop), y, method="DOP853", rtol=1e-12, atol=1e-15, dense_output=True,
                            events=[f for _, _, f in events], max_step=spacing)
            hit = [(float(te[0]), i) for i, te in enumerate(sol.t_events) if len(te)]
            t_new = min(hit)[0] if hit else t_stop
            inside = (grid >= t) & (grid <= t_new)
            if inside.any():
                out[inside] = sol.sol(grid[inside]).T[:, :n]
            y = sol.sol(t_new)
            if hit:
                e, kind, _ = events[min(hit)[1]]
                if kind == "slip":
                    signs = signs.copy()
                    signs[e] = np.sign(self.solve_mode(t_new, y, signs)[1][e])
                else:
                    signs = self.decide(t_new, y, signs, [e])
            else:  # a force's jump: a stuck contact it takes past its breakaway slips
                self.until = np.inf
                tensions = self.solve_mode(_after(t_new), y, signs)[1]
                past = (signs == 0) & (np.abs(tensions) > self.static)
                if past.any():
                    e = int(np.flatnonzero(past)[0])
                    signs = signs.copy()
                    signs[e] = np.sign(tensions[e])
            t = t_new
        return out


def _after(t: float) -> float:
    """The next float after t: a force's right limit at its jump."""
    return float(np.nextafter(t, np.inf))
