"""The one event-location engine: which guard of rimless.sim.model.guards ends a continuous phase, and when.

Used step by step by every Python integration loop (the reference integrator rimless.sim.integrate.reference
and the firmware in the loop rimless.sim.in_the_loop.loop); the compiled path (rimless.sim.fast.rk) is its
numba twin with the same codes, directions and dip constants. The rules, written once:

- sign change on a step: guard i fires on the step (t_old, t] when it crosses 0 in its direction
  (`crossed`: solve_ivp's semantics, a value of exactly 0 at the step's start counts as on either side;
  `strict=True`: only a start value strictly on the non-firing side counts);
- root on the dense output: the crossing time is found by Brent's method on the step's interpolant
  (`locate`, to 4 eps in t by default); the earliest root of the step wins, ties to the first guard;
- dip search between samples: a normal-force guard (`FORCE_GUARDS`) may dip below zero and recover
  between two step ends without a sign change there. Around every discrete minimum of the force over the
  last three step ends whose parabola comes below DIP_MARGIN times the middle value, and at the phase's
  first and last step, the force is sampled at DIP_SAMPLES interior points of a dense output of the span,
  the lowest sample refined by a bounded minimisation, and the first downward zero located (`first_dip`).
  Where that dense output comes from is the caller's choice (`dense_on`): a re-integration of the span
  or the interpolants of the steps already taken.

Times in s, states y = [q, q', extras...] (the guards read y[:10]), guard values in the guard's units.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from rimless.sim.model.guards import DIRECTION, FORCE_GUARDS

EPS4 = 4 * float(np.finfo(float).eps)  # Brent's tolerance on the event time (solve_ivp's)
DIP_MARGIN = 0.5  # skip a force minimum the steps resolve well: its parabola stays above this times its value
DIP_SAMPLES = 8  # dense-output samples of a normal force when looking for a dip between two solver steps

Dense = Callable[[float], np.ndarray]  # t -> y(t) on one step or span


class NonFiniteGuard(ArithmeticError):
    """A guard value is not finite at a step's end (the state is too large or the dynamics singular)."""


def crossed(g_old: np.ndarray, g_new: np.ndarray, directions: np.ndarray, *, strict: bool = False) -> np.ndarray:
    """Indices of the guards that cross 0 in their direction between the values g_old and g_new."""
    g_old, g_new = np.asarray(g_old), np.asarray(g_new)
    if strict:
        up = (g_old < 0) & (g_new >= 0)
        down = (g_old > 0) & (g_new <= 0)
    else:
        up = (g_old <= 0) & (g_new >= 0)
        down = (g_old >= 0) & (g_new <= 0)
    mask = up & (directions > 0) | down & (directions < 0) | (up | down) & (directions == 0)
    return np.nonzero(mask)[0]


def locate(g_at: Callable[[float], float], ta: float, tb: float, *, xtol: float = EPS4, rtol: float = EPS4) -> float:
    """The root of g_at on [ta, tb] (a sign change there), by Brent's method."""
    from scipy.optimize import brentq

    return float(brentq(g_at, ta, tb, xtol=xtol, rtol=rtol))


def parabola_min(ts: Sequence[float], gs: Sequence[float]) -> float:
    """Minimum of the parabola through three (t, g) points whose middle g is below both neighbours
    (-inf when the parabola opens downwards)."""
    d1 = (gs[1] - gs[0]) / (ts[1] - ts[0])
    d2 = (gs[2] - gs[1]) / (ts[2] - ts[1])
    a = (d2 - d1) / (ts[2] - ts[0])
    if not a > 0.0:
        return -np.inf
    t_min = 0.5 * (ts[0] + ts[1]) - d1 / (2.0 * a)
    return gs[1] + d1 * (t_min - ts[1]) + a * (t_min - ts[0]) * (t_min - ts[1])


def first_dip(g_at: Callable[[float], float], ta: float, tb: float) -> float | None:
    """The first zero crossing (downwards) of g on [ta, tb] when g(ta) > 0 dips to <= 0 inside, else None.
    g is sampled at DIP_SAMPLES interior points; the lowest sample is refined by a bounded minimisation."""
    from scipy.optimize import minimize_scalar

    ts = np.linspace(ta, tb, DIP_SAMPLES + 2)
    gs = np.array([g_at(t) for t in ts])
    neg = np.nonzero(gs <= 0.0)[0]
    if neg.size:
        t_low = ts[neg[0]]
    else:
        i = int(np.argmin(gs))
        lo, hi = ts[max(i - 1, 0)], ts[min(i + 1, len(ts) - 1)]
        res = minimize_scalar(g_at, bounds=(lo, hi), method="bounded", options={"xatol": 1e-9 * (tb - ta)})
        if not (res.fun <= 0.0):
            return None
        t_low = float(res.x)
    if g_at(t_low) == 0.0:
        return t_low
    return locate(g_at, ta, t_low)


class Piecewise:
    """A dense output over consecutive steps from their per-step interpolants [(t_old, t, sol), ...]."""

    def __init__(self, pieces: Sequence[tuple[float, float, Dense]]) -> None:
        self.pieces = list(pieces)

    def __call__(self, t: float) -> np.ndarray:
        for _t_old, t_new, sol in self.pieces:
            if t <= t_new:
                return sol(t)
        return self.pieces[-1][2](t)


class EventLocator:
    """Locates the guards `codes` along one continuous phase, one solver step at a time.

    value(code, y) evaluates a guard; `dense_on(ta, ya, tb)` gives a dense output over [ta, tb] starting from
    the step end (ta, ya) for the force-dip search (None: the span could not be integrated); `strict` and
    the Brent tolerances as in `crossed` and `locate`; check_finite: raise NonFiniteGuard on a non-finite
    guard value at a step's end.
    """

    def __init__(
        self,
        codes: Sequence[int],
        value: Callable[[int, np.ndarray], float],
        t0: float,
        y0: np.ndarray,
        *,
        dense_on: Callable[[float, np.ndarray, float], Dense | None] | None = None,
        strict: bool = False,
        xtol: float = EPS4,
        rtol: float = EPS4,
        check_finite: bool = True,
    ) -> None:
        self.codes = tuple(codes)
        self.value = value
        self.directions = np.array([DIRECTION[c] for c in self.codes], dtype=float)
        self.force = [i for i, c in enumerate(self.codes) if c in FORCE_GUARDS] if dense_on is not None else []
        self.dense_on = dense_on
        self.strict, self.xtol, self.rtol, self.check_finite = strict, xtol, rtol, check_finite
        self.g = self.values(y0)
        self.hist: list[tuple[float, np.ndarray, np.ndarray]] = [(t0, np.array(y0, dtype=float), self.g.copy())]

    def values(self, y: np.ndarray) -> np.ndarray:
        g = np.array([self.value(c, y) for c in self.codes])
        if self.check_finite and not np.all(np.isfinite(g)):
            raise NonFiniteGuard("non-finite guard value")
        return g

    def step(
        self, t_old: float, t: float, y: np.ndarray, dense: Callable[[], Dense], *, last_step: bool = False
    ) -> tuple[float, int, np.ndarray] | None:
        """The earliest event on the step (t_old, t] ending at y, as (time, index into codes, state), or None.
        dense() gives the step's interpolant (called only when a guard changes sign)."""
        g_new = self.values(y)
        best: tuple[float, int, np.ndarray] | None = None
        active = crossed(self.g, g_new, self.directions, strict=self.strict)
        if active.size:
            sol = dense()
            for e in active:
                code = self.codes[e]
                root = locate(lambda s: self.value(code, sol(s)), t_old, t, xtol=self.xtol, rtol=self.rtol)  # noqa: B023
                if best is None or root < best[0]:
                    best = (root, int(e), sol(root))
        self.hist.append((t, np.array(y, dtype=float), g_new.copy()))
        del self.hist[:-3]
        dip = self._force_dip(active, last_step, best is not None)
        if dip is not None and (best is None or dip[0] < best[0]):
            best = dip
        self.g = g_new
        return best

    def _force_dip(
        self, active: np.ndarray, last_step: bool, other_fired: bool
    ) -> tuple[float, int, np.ndarray] | None:
        """The earliest time at which a normal-force guard dips through zero between step ends where it is
        positive, as (t, index, state), or None. Checked around every discrete minimum of the force over the
        step ends (and at the phase's first and last step)."""
        best = None
        hist = self.hist
        for e in self.force:
            if e in active:
                continue
            gs = [h[2][e] for h in hist]
            if min(gs) <= 0.0:
                continue
            if len(gs) == 3 and gs[0] > gs[1] < gs[2]:
                if parabola_min([h[0] for h in hist], gs) > DIP_MARGIN * gs[1]:
                    continue  # resolved by the steps: the force stays well above zero between them
                span = (hist[0], hist[2])
            elif len(gs) == 2 and gs[0] < gs[1]:
                span = (hist[0], hist[1])
            elif (last_step or other_fired) and gs[-2] > gs[-1]:
                span = (hist[-2], hist[-1])
            else:
                continue
            (ta, ya, _), (tb, _, _) = span
            assert self.dense_on is not None
            sol = self.dense_on(ta, ya, tb)
            if sol is None:
                continue
            code = self.codes[e]
            found = first_dip(lambda tt: self.value(code, sol(tt)), ta, tb)  # noqa: B023
            if found is not None and (best is None or found < best[0]):
                best = (found, e, sol(found))
        return best
