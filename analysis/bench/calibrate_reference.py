"""The previous calibration algorithm, frozen as the reference of `rimless.analysis.bench.calibrate`.

`rimless.analysis.inference.calibrate.calibrate` replaced these inner loops with faster ones and keeps one
algorithm; this module keeps the one it replaced, with the same estimator and stopping rules (least squares on
step periods and CoM height, one release speed and time shift per trial, the block sigmas, the Gauss-Newton stop,
the restart from Table 1 on a ridge), so that the benchmark can run both side by side in one run:

- every column of `rimless.sim.step.gait.simulate_steps` recorded (not only the CoM height and its rate), and the
  simulated CoM curve interpolated by a cubic spline per step, built again at every evaluation (no cache);
- each release of the coarse profile found by a grid search and a full least squares (no warm start), the
  first-period release by a 40-step bisection, each trial's time shift on a full 0.5 ms grid;
- the least squares started at the coarse profile's best point (no parabolic refinement);
- the BLAS on as many threads as it likes.

It is kept only to be compared: the analysis never calls it. Its result is a `CalibrationResult` without the
held parameters' refits, the loss-separation check, the leg-test priors, the multistart and the adequacy figures
of the method (`calibrate_reference` takes none of them).

One concept: the frozen reference calibration (its data, objective, stages and estimates are the method's as of
dd983a2, with the reference inner loops).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from rimless.analysis.inference.calibrate import (
    CUSP_GUARD_S,
    FIT_FIELDS,
    GN_STOP_COST,
    GN_STOP_STATUS,
    MAX_NFEV,
    MAX_ROUNDS,
    MAX_SHIFT_MS,
    NOT_IDENTIFIABLE_REL_SE,
    PROFILE_FACTORS,
    RIDGE_CORRELATION,
    CalibrationResult,
    NoTrialCalibrated,
    ParamEstimate,
)
from rimless.analysis.inference.identifiability import least_squares_report, sandwich_se
from rimless.analysis.io.trial import ALPHA_RAD
from rimless.errors import ParameterError

#: Per trial: (RMS step-frequency residual Hz, RMS CoM residual m, RMS period error s, steps reached).
_RmsRow = tuple[float, float, float, int]
_REL_STEP = 1e-5

__all__ = ["calibrate_reference"]


@dataclass
class _TrialData:
    name: str
    slope_deg: float
    periods_s: np.ndarray  # consecutive periods from the first measured impact
    t_s: np.ndarray  # valid frame times from the first impact, within [0, last impact]
    com_m: np.ndarray
    from_plane: bool
    shift_s: float = 0.0
    release_rad_s: float = math.nan


def _trial_data(trial: Any, name: str) -> _TrialData | str:
    from rimless.analysis.inference.sustained import consecutive_periods

    chains = consecutive_periods(trial)
    if not chains or chains[0].size < 2:
        return f"{name}: fewer than two consecutive step periods"
    slope = float(trial.meta.slope_deg)
    if not 0.0 <= slope < math.degrees(ALPHA_RAD / 2):
        return f"{name}: its slope {slope:.3f} deg cannot be simulated (0 <= slope < 22.5 deg)"
    periods = chains[0]
    imp = np.asarray(trial.impact_time_s, float)
    t = np.asarray(trial.time_s, float) - imp[0]
    y = np.asarray(trial.series["com_height"], float)
    valid = np.isfinite(y)
    for key in ("gap", "interpolated"):
        try:
            valid &= ~np.asarray(trial.series[key], bool)
        except (KeyError, TypeError):
            pass
    t_last = float(np.sum(periods))
    win = valid & (t >= 0) & (t <= t_last)
    # leave out the samples next to an impact: the CoM height has a cusp there, and a sample whose side of the
    # simulated cusp flips with a parameter makes the cost non-smooth (the periods carry that timing)
    impacts_rel = np.concatenate([[0.0], np.cumsum(periods)])
    near = np.min(np.abs(t[:, None] - impacts_rel[None, :]), axis=1) < CUSP_GUARD_S
    win &= ~near
    ref = str(getattr(trial.meta, "com_height_reference", ""))
    return _TrialData(name, float(trial.meta.slope_deg), periods, t[win], y[win], ref.startswith("slope plane"))


@dataclass
class _Sim:
    model: str
    rtol: float
    record_dt_s: float
    calls: int = 0
    cache: dict = field(default_factory=dict)

    def frequencies(self, params: Any, slope_deg: float, w: float, n: int) -> np.ndarray:
        """Step frequencies (1/s) of the n steps after the release step, on the compiled step map; 0 for steps
        not reached (the wheel stalled or the step failed)."""
        from rimless.sim.fast import fast_step
        from rimless.sim.model.failures import StepFailure
        from rimless.sim.step.fast_map import friction_step

        self.calls += 1
        p = params.replace(slope_rad=math.radians(slope_deg))
        z = np.array([-ALPHA_RAD / 2, w])
        out = np.zeros(n)
        step = fast_step if p.guide_friction_n == 0.0 else friction_step  # guide friction: phase by phase
        try:
            for k in range(n + 1):
                r = step(p, self.model, z, rtol=self.rtol)
                if k:
                    out[k - 1] = 1.0 / r.period_s
                z = r.z_next
        except StepFailure:
            pass
        return out

    def walk(self, params: Any, slope_deg: float, w: float, n: int, record: bool) -> Any:
        """`simulate_steps` (every column recorded) from the rigid-touchdown release; the last walks are cached (a
        change of the time shift alone then costs no simulation)."""
        from rimless.sim.step.backend import make_integrator
        from rimless.sim.step.gait import simulate_steps

        key = (params.as_vector(), params.mass_model, params.guide_friction_n, slope_deg, w, n, record)
        if key in self.cache:
            return self.cache[key]
        self.calls += 1
        p = params.replace(slope_rad=math.radians(slope_deg))
        z0 = np.array([-ALPHA_RAD / 2, w])
        g = simulate_steps(
            p, self.model, z0, n, make_integrator("auto", rtol=self.rtol), record_dt=self.record_dt_s if record else 1.0
        )
        if len(self.cache) > 256:
            self.cache.pop(next(iter(self.cache)))
        self.cache[key] = g
        return g


def _residuals(
    sim: _Sim, params: Any, d: _TrialData, w: float, shift_s: float, with_com: bool = True
) -> tuple[np.ndarray, np.ndarray]:
    """(step-frequency residuals 1/T_sim - 1/T_meas in Hz, CoM residuals in m), unscaled.

    Frequencies, not periods: a step the simulation does not reach (it stalled) has frequency 0, the limit of
    a period that grows without bound, so the cost stays continuous across the stall boundary."""
    n = d.periods_s.size
    g = sim.walk(params, d.slope_deg, w, n + 2, with_com)
    if with_com and g.failure is None and len(g.steps) > 1 and d.t_s.size:
        covered = g.steps[-1].t_start_s + g.steps[-1].period_s - g.steps[1].t_start_s
        if covered < d.t_s[-1] + 0.06:  # the simulated walk is faster: simulate enough steps to cover the window
            extra = int(math.ceil((d.t_s[-1] + 0.06 - covered) / max(g.steps[-1].period_s, 1e-3))) + 1
            g = sim.walk(params, d.slope_deg, w, n + 2 + min(extra, 3 * n + 4), with_com)
    got = np.array([s.period_s for s in g.steps[1 : 1 + n]])
    f_sim = np.zeros(n)  # a step the simulation did not reach (stalled) has frequency 0: continuous at the stall
    f_sim[: got.size] = 1.0 / got
    rp = f_sim - 1.0 / d.periods_s
    if not with_com or d.t_s.size == 0:
        return rp, np.zeros(0)
    if len(g.steps) < 2:
        return rp, np.full(d.t_s.size, float(np.mean(d.com_m)) if d.from_plane else 0.0)
    t0 = g.steps[1].t_start_s
    tt = d.t_s - shift_s
    s = _smooth_curve(g, t0, tt)
    off = 0.0 if d.from_plane else float(np.mean(s - d.com_m))
    return rp, s - (d.com_m + off)


def _curve_parts(g: Any, t0: float) -> tuple[np.ndarray, np.ndarray, list[tuple[float, float, Any]]]:
    """The simulated CoM curve of walk ``g`` (times from t0): the clean samples and one cubic spline per step
    (built at every call: no cache)."""
    from scipy.interpolate import CubicSpline

    from rimless.analysis.inference.compare import clean_curve

    t_all = np.asarray(g.table["t_s"], float) - t0
    y_all = np.asarray(g.table["com_height_normal_m"], float)
    step = np.asarray(g.table["step"])
    st, sy = clean_curve(t_all, y_all)
    splines = []
    for k in np.unique(step):
        ts, ys = clean_curve(t_all[step == k], y_all[step == k])
        if ts.size >= 4:
            splines.append((float(ts[0]), float(ts[-1]), CubicSpline(ts, ys)))
    return st, sy, splines


def _smooth_curve(g: Any, t0: float, tt: np.ndarray) -> np.ndarray:
    """The simulated CoM height at times tt (s from t0): a cubic spline through each step\'s samples (the
    impact cusp stays a cusp); held at the end values outside the simulated walk (a stall)."""
    st, sy, splines = _curve_parts(g, t0)
    out = np.interp(tt, st, sy)
    for lo, hi, sp in splines:
        m = (tt >= lo) & (tt <= hi)
        if m.any():
            out[m] = sp(tt[m])
    return out


@dataclass
class _Globals:
    """The global parameters being fitted: WheelParams fields, their Table 1 (start) values and scales.

    The optimiser sees them relative to the start, in units of ``scale`` (|start value|, or 1 at zero)."""

    base: Any
    fields: list[str]
    x0: np.ndarray
    scale: np.ndarray

    @classmethod
    def of(cls, base: Any, fit: Sequence[str]) -> _Globals:
        fields = [FIT_FIELDS[n][0] for n in fit]
        x0 = np.array([float(getattr(base, f)) for f in fields])
        return cls(base, fields, x0, np.where(x0 != 0, np.abs(x0), 1.0))

    @property
    def n(self) -> int:
        return len(self.fields)

    def params(self, xg: np.ndarray) -> Any:
        """The wheel with these global values, or None when they are not a valid wheel."""
        try:
            return self.base.replace(**{f: float(v) for f, v in zip(self.fields, xg)})
        except ParameterError:
            return None

    def at(self, ug: np.ndarray) -> Any:
        """`params` at the relative values ``ug`` (0 = the start)."""
        return self.params(self.x0 + ug * self.scale)


class _ReleaseFit:
    """Stage 1: per trial, the release speed from the step periods alone, on the compiled step map."""

    def __init__(self, sim: _Sim, tick: Callable[[], None]) -> None:
        self.sim, self.tick = sim, tick

    def freq_res(self, p: Any, d: _TrialData, w: float) -> np.ndarray:
        """Step-frequency residuals (Hz) from the compiled map alone."""
        f = self.sim.frequencies(p, d.slope_deg, w, d.periods_s.size)
        self.tick()
        return f - 1.0 / d.periods_s

    def fit(self, p: Any, d: _TrialData, w0: float | None, coarse: bool = False) -> tuple[float, float]:
        """(release rad/s, cost) from the periods: a grid (first time) or the previous value, then least squares
        to 1e-10 relative (``coarse`` too)."""
        from scipy.optimize import least_squares

        if w0 is None or not math.isfinite(w0):
            w0 = self.first_period_release(p, d)
        r = least_squares(
            lambda q: self.freq_res(p, d, float(q[0])),
            [w0],
            bounds=([0.05], [20.0]),
            method="trf",
            diff_step=[1e-5],
            xtol=1e-10,
            ftol=1e-12,
            max_nfev=30,
        )
        return float(r.x[0]), float(2 * r.cost)

    def fit_warm(self, p: Any, d: _TrialData, w0: float) -> tuple[float, float]:
        """`fit` from the grid of `first_period_release` (the reference ignores the warm start ``w0``)."""
        return self.fit(p, d, None, coarse=True)

    def first_period_release(self, p: Any, d: _TrialData) -> float:
        """The release whose first simulated step after the release step lasts the first measured period
        (grid + bisection on the compiled map, on the walking branch); the grid's best when none does."""
        sim = self.sim
        grid = np.linspace(0.4, 6.0, 29)
        f1 = np.array([sim.frequencies(p, d.slope_deg, w, 1)[0] for w in grid])
        self.tick()
        target = 1.0 / d.periods_s[0]
        diff = f1 - target
        for i in range(grid.size - 1):
            if f1[i] > 0 and diff[i] <= 0 < diff[i + 1]:
                a, b = grid[i], grid[i + 1]
                for _ in range(40):
                    m = 0.5 * (a + b)
                    a, b = (m, b) if sim.frequencies(p, d.slope_deg, m, 1)[0] - target <= 0 else (a, m)
                return 0.5 * (a + b)
        costs = [float(np.sum(self.freq_res(p, d, w) ** 2)) for w in grid]
        return float(grid[int(np.argmin(costs))])


def _start(releases: _ReleaseFit, glob: _Globals, data: list[_TrialData]) -> tuple[dict[str, float], np.ndarray]:
    """Stage 1: the releases at Table 1 (returned by trial name), then the coarse profile of each global
    (`PROFILE_FACTORS`) on the periods alone, whose best point (relative globals, returned) is where the least
    squares begin: every trial's ``release_rad_s`` is set at it. Each release is found from the grid."""
    p0 = glob.at(np.zeros(glob.n))
    table1 = {}
    for d in data:
        d.release_rad_s = table1[d.name] = releases.fit(p0, d, None)[0]
    best = sum(releases.fit(p0, d, d.release_rad_s)[1] for d in data)
    ug_best = np.zeros(glob.n)

    def try_start(ug: np.ndarray) -> float:
        """The periods' cost at relative globals ug (inf for an invalid wheel); the best start kept."""
        nonlocal best, ug_best
        p = glob.at(ug)
        if p is None:
            return math.inf
        fits = [releases.fit_warm(p, d, math.nan) for d in data]
        cost = sum(c for _, c in fits)
        if cost < best:
            best, ug_best = cost, ug
            for d, (w, _) in zip(data, fits):
                d.release_rad_s = w
        return cost

    for j in range(glob.n):
        for factor in sorted(PROFILE_FACTORS, key=lambda f: abs(math.log(f))):  # outwards from Table 1
            ug = ug_best.copy()
            ug[j] = factor - 1.0
            try_start(ug)
    if ug_best.any():  # releases at the chosen start, to full precision
        pb = glob.at(ug_best)
        for d in data:
            d.release_rad_s = releases.fit(pb, d, None)[0]
    return table1, ug_best


class _Objective:
    """Stage 2: the scaled residuals of every trial (periods and CoM height) as a function of one vector
    u = (globals relative to the start, release speeds rad/s, time shifts ms), and its Jacobian."""

    def __init__(self, sim: _Sim, glob: _Globals, data: list[_TrialData], tick: Callable[[], None]) -> None:
        self.sim, self.glob, self.data, self.tick = sim, glob, data, tick
        self.sig = {"t": 0.02, "h": 0.5e-3}  # step frequency (Hz), CoM height (m)
        self.last_jac: tuple[np.ndarray, np.ndarray] | None = None  # (u, J) of the latest `jac_kept` call
        self.n_g, self.n_t = glob.n, len(data)
        sizes = [d.periods_s.size + d.t_s.size for d in data]
        self.offs = np.concatenate([[0], np.cumsum(sizes)])

    def trial_res(self, p: Any, i: int, w: float, shift: float) -> np.ndarray:
        d = self.data[i]
        if p is None:
            return np.full(d.periods_s.size + d.t_s.size, 1e3)
        rp, rh = _residuals(self.sim, p, d, w, shift)
        self.tick()
        return np.concatenate([rp / self.sig["t"], rh / self.sig["h"]])

    def unpack(self, u: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(globals, release speeds rad/s, time shifts s); u holds globals relative to Table 1, shifts in ms."""
        n_g, n_t = self.n_g, self.n_t
        return self.glob.x0 + u[:n_g] * self.glob.scale, u[n_g : n_g + n_t], u[n_g + n_t :] * 1e-3

    def fun(self, u: np.ndarray) -> np.ndarray:
        xg, ws, sh = self.unpack(u)
        p = self.glob.params(xg)
        return np.concatenate([self.trial_res(p, i, ws[i], sh[i]) for i in range(self.n_t)])

    def cost(self, u: np.ndarray) -> float:
        return float(np.sum(self.fun(u) ** 2))

    def jac(self, u: np.ndarray, central: bool = False) -> np.ndarray:
        """Forward differences: a global column needs every trial, a trial's release and shift only that trial
        (the shift costs no simulation: the walk is cached and only the interpolation moves)."""
        glob, n_g, n_t, offs, res = self.glob, self.n_g, self.n_t, self.offs, self.trial_res
        xg, ws, sh = self.unpack(u)
        p = glob.params(xg)
        r0 = [res(p, i, ws[i], sh[i]) for i in range(n_t)]
        J = np.zeros((offs[-1], n_g + 2 * n_t))
        for j in range(n_g):
            h = 1e-3
            xg2 = xg.copy()
            xg2[j] += h * glob.scale[j]
            p2 = glob.params(xg2)
            xg3 = xg.copy()
            xg3[j] -= h * glob.scale[j]
            p3 = glob.params(xg3) if central else None
            for i in range(n_t):
                if p3 is not None:
                    J[offs[i] : offs[i + 1], j] = (res(p2, i, ws[i], sh[i]) - res(p3, i, ws[i], sh[i])) / (2 * h)
                else:
                    J[offs[i] : offs[i + 1], j] = (res(p2, i, ws[i], sh[i]) - r0[i]) / h
        for i in range(n_t):
            h = _REL_STEP
            J[offs[i] : offs[i + 1], n_g + i] = (res(p, i, ws[i] + h, sh[i]) - r0[i]) / h
            hs = 0.2  # ms
            J[offs[i] : offs[i + 1], n_g + n_t + i] = (res(p, i, ws[i], sh[i] + hs * 1e-3) - r0[i]) / hs
        return J

    def jac_kept(self, u: np.ndarray) -> np.ndarray:
        """`jac(u)` (with whatever rows a prior added), kept for `near_minimum`."""
        J = self.jac(u)
        self.last_jac = (np.array(u, dtype=float), J)
        return J

    def stop_near_minimum(self, intermediate_result: Any) -> None:
        """scipy's least_squares callback (by this parameter name it gets the iterate with its residuals)."""
        if self.near_minimum(intermediate_result.x, intermediate_result.fun):
            raise StopIteration

    def near_minimum(self, u: np.ndarray, f: np.ndarray) -> bool:
        """Whether the Gauss-Newton step from `u` (the latest Jacobian, taken there) would lower the cost
        0.5 |f|^2 by less than `GN_STOP_COST`: the minimum is then within about 0.1 of a standard error in every
        direction (the residuals are scaled to unit variance), and further steps only chase it."""
        if self.last_jac is None or not np.array_equal(self.last_jac[0], u):
            return False
        J = self.last_jac[1]
        dx = np.linalg.lstsq(J, -f, rcond=None)[0]
        return bool(0.5 * float(np.sum((J @ dx) ** 2)) < GN_STOP_COST)

    def best_shifts(self, ug: np.ndarray, ws: np.ndarray) -> np.ndarray:
        """Per trial the shift (ms) that minimises the CoM residual (no new simulation): a 0.5 ms grid over
        +-`MAX_SHIFT_MS`."""
        p = self.glob.at(ug)
        out = []
        for i, d in enumerate(self.data):

            def cost(g: float) -> float:
                return float(np.sum(_residuals(self.sim, p, d, ws[i], g * 1e-3)[1] ** 2))  # noqa: B023

            grid = np.arange(-MAX_SHIFT_MS, MAX_SHIFT_MS + 1e-9, 0.5)
            out.append(float(grid[int(np.argmin([cost(g) for g in grid]))]))
        return np.array(out)

    def start(self, ug: np.ndarray, ws: np.ndarray) -> np.ndarray:
        """u at these globals and releases, with each trial's best time shift."""
        return np.concatenate([ug, ws, self.best_shifts(ug, ws)])

    def rms_rows(self, u: np.ndarray) -> list[_RmsRow]:
        xg, ws, sh = self.unpack(u)
        return _rms_rows(self.sim, self.data, self.glob.params(xg), ws, sh)

    def set_sigmas(self, u: np.ndarray) -> None:
        """Each block's sigma = its RMS residual at u (reduced chi^2 of 1 per block)."""
        _set_sigmas(self.sig, self.rms_rows(u))

    def bounds(self, ws_start: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Globals free; releases within [0.8, 1.25] x their start (the walking branch) and [0.05, 20] rad/s;
        shifts within +-`MAX_SHIFT_MS`."""
        n_g, n_t = self.n_g, self.n_t
        lo = np.concatenate([np.full(n_g, -np.inf), np.full(n_t, 0.05), np.full(n_t, -MAX_SHIFT_MS)])
        hi = np.concatenate([np.full(n_g, np.inf), np.full(n_t, 20.0), np.full(n_t, MAX_SHIFT_MS)])
        for j, f in enumerate(self.glob.fields):
            if f == "guide_friction_n":  # a friction force is >= 0
                lo[j] = -self.glob.x0[j] / self.glob.scale[j]
        lo[n_g : n_g + n_t] = np.maximum(lo[n_g : n_g + n_t], 0.8 * ws_start)
        hi[n_g : n_g + n_t] = np.minimum(hi[n_g : n_g + n_t], 1.25 * ws_start)
        return lo, hi

    def solve(self, u: np.ndarray, lo: np.ndarray, hi: np.ndarray, max_rounds: int = MAX_ROUNDS) -> Any:
        """Trust-region least squares from u, restarted from where it stopped while it stops on its budget
        (`MAX_NFEV` evaluations a round, at most ``max_rounds`` rounds). The scipy result of the last round
        with ``rounds`` and the total ``nfev_total``; ``status == 0`` means the budget ran out (not converged),
        `GN_STOP_STATUS` that the Gauss-Newton step would gain less than `GN_STOP_COST` (converged)."""
        from scipy.optimize import least_squares

        total = 0
        for k in range(max_rounds):  # noqa: B007
            # ftol 1e-6: a step that lowers the cost by less than 1e-6 of itself (about 0.002 in chi-square units
            # for the ~2000 residuals of a series, far below the 1 unit of a one-sigma change) ends the fit; the
            # finite-difference Jacobian of walks integrated at rtol 1e-7 cannot resolve 1e-10 (the bundled
            # critical series ran out of its budget at 1e-10 with c within 4e-5 N s/m of where 1e-6 stops)
            r = least_squares(
                self.fun,
                np.clip(u, lo, hi),
                jac=self.jac_kept,
                bounds=(lo, hi),
                method="trf",
                xtol=1e-6,
                ftol=1e-6,
                max_nfev=MAX_NFEV,
                callback=self.stop_near_minimum,
            )
            total += int(r.nfev)
            u = r.x
            if r.status == -2:  # stopped by near_minimum: converged to a tenth of a standard error
                r.status = GN_STOP_STATUS
                r.message = (
                    f"the Gauss-Newton step would lower chi-square by less than {2 * GN_STOP_COST:g} "
                    "(within about 0.1 standard error of the minimum)"
                )
            if r.status != 0:
                break
        r.rounds, r.nfev_total = k + 1, total
        return r

    def inflate_com_sigma(self, u: np.ndarray) -> None:
        """CoM samples 10 ms apart are not independent when the model misses a systematic shape (their residuals
        are correlated): count them by their effective number, (1 - rho) / (1 + rho) of the samples, rho the
        lag-1 autocorrelation of the residuals, by inflating the block's sigma."""
        xg, ws, sh = self.unpack(u)
        rhos = []
        for i, d in enumerate(self.data):
            rh = _residuals(self.sim, self.glob.params(xg), d, float(ws[i]), float(sh[i]))[1]
            if rh.size > 10 and np.std(rh) > 0:
                rhos.append(float(np.corrcoef(rh[:-1], rh[1:])[0, 1]))
        rho = float(np.clip(np.mean(rhos), 0.0, 0.95)) if rhos else 0.0
        self.sig["h"] *= math.sqrt((1 + rho) / (1 - rho))


def _estimates(
    glob: _Globals,
    fit: Sequence[str],
    xg: np.ndarray,
    se: np.ndarray,
    ok: list[bool],
    notes: list[str],
    se_sand: np.ndarray | None = None,
    converged: bool = True,
) -> list[ParamEstimate]:
    """One `ParamEstimate` per fitted name. Its standard error is the larger of the model-based one and the
    trial-clustered sandwich (``se_sand``); it is identifiable when the fit converged, the cost is not flat
    along it and that relative standard error is at most `NOT_IDENTIFIABLE_REL_SE` (a 95 % interval no wider
    than about +-100 %)."""
    estimates = []
    for j, n in enumerate(fit):
        f, unit = FIT_FIELDS[n]
        s_sand = float(se_sand[j]) if se_sand is not None else math.nan
        s_use = max(float(se[j]), s_sand) if math.isfinite(s_sand) else float(se[j])
        rel = s_use / abs(xg[j]) if xg[j] != 0 else math.inf
        ident = ok[j] and rel <= NOT_IDENTIFIABLE_REL_SE and converged
        note = notes[j]
        if ok[j] and rel > NOT_IDENTIFIABLE_REL_SE:
            note = f"relative uncertainty {rel:.0%} > {NOT_IDENTIFIABLE_REL_SE:.0%}: the data hardly constrain it"
        elif ok[j] and not converged:
            note = "the fit did not converge (optimiser stopped on its budget): the value is where it stopped"
        estimates.append(
            ParamEstimate(
                n, f, unit, float(getattr(glob.base, f)), float(xg[j]), s_use, ident, note, float(se[j]), s_sand
            )
        )
    return estimates


def _residual_rows(
    data: list[_TrialData],
    rows_t1: Sequence[_RmsRow],
    rows_cal: Sequence[_RmsRow],
    ws_t1: np.ndarray,
    ws: np.ndarray,
    sh: np.ndarray,
) -> list[dict[str, Any]]:
    """Per trial, Table 1 against calibrated: RMS period and CoM errors, steps reached, releases and shift."""
    residuals = []
    for d, a, b, w_t1, w, s_ in zip(data, rows_t1, rows_cal, ws_t1, ws, sh):
        residuals.append(
            {
                "trial": d.name,
                "slope_deg": d.slope_deg,
                "n_period": d.periods_s.size,
                "n_com": d.t_s.size,
                "table1_release_theta_dot_rad_s": float(w_t1),
                "calibrated_release_theta_dot_rad_s": float(w),
                "time_shift_ms": float(s_) * 1e3,
                "table1_rms_period_ms": a[2] * 1e3,
                "calibrated_rms_period_ms": b[2] * 1e3,
                "table1_steps_reached": a[3],
                "calibrated_steps_reached": b[3],
                "table1_rms_com_mm": a[1] * 1e3,
                "calibrated_rms_com_mm": b[1] * 1e3,
            }
        )
    return residuals


def _usable(trials: Sequence[Any], names: Sequence[str]) -> tuple[list[_TrialData], dict[str, str]]:
    """The trials that can be fitted, and why the others cannot (by name)."""
    failed: dict[str, str] = {}
    data: list[_TrialData] = []
    for tr, nm in zip(trials, names):
        d = _trial_data(tr, nm)
        if isinstance(d, str):
            failed[nm] = d
        else:
            data.append(d)
    return data, failed


def calibrate_reference(
    trials: Sequence[Any],
    names: Sequence[str],
    fit: Sequence[str] = ("c",),
    *,
    params: Any = None,
    model: str = "er",
    rtol: float = 1e-7,
    record_dt_s: float = 8e-3,
    max_rounds: int = MAX_ROUNDS,
    multi_start: bool = True,
) -> CalibrationResult:
    """Fit ``fit`` (names of `FIT_FIELDS`) and one release speed and time shift per trial with the reference
    inner loops (the module doc). Stages: the releases and the coarse profile (`_start`), then the least squares
    on periods and CoM height from the profile's best point, with the sigmas there; with two or more globals on
    a ridge (correlation above `RIDGE_CORRELATION`) or without convergence, also from Table 1, the lower cost
    kept. Uncertainties as the method's: the larger of the Jacobian's and the trial-clustered sandwich."""
    from rimless.sim.model.params import WheelParams

    data, failed = _usable(trials, names)
    if not data:
        raise NoTrialCalibrated("no trial could be calibrated: " + "; ".join(failed.values()))
    sim = _Sim(model, rtol, record_dt_s)
    glob = _Globals.of(params or WheelParams(), fit)
    table1_releases, ug_start = _start(_ReleaseFit(sim, lambda: None), glob, data)
    obj = _Objective(sim, glob, data, lambda: None)
    ws_t1 = np.array([table1_releases[d.name] for d in data])
    u_t1 = obj.start(np.zeros(glob.n), ws_t1)
    rows_t1 = obj.rms_rows(u_t1)
    ws_start = np.array([d.release_rad_s for d in data])
    u = obj.start(ug_start, ws_start)
    obj.set_sigmas(u)
    cost_t1 = obj.cost(u_t1)
    lo, hi = obj.bounds(ws_start)
    best = obj.solve(u, lo, hi, max_rounds)
    starts = 1
    if multi_start and glob.n >= 2 and ug_start.any() and (best.status == 0 or _on_ridge(best.jac, glob.n)):
        starts = 2
        r = obj.solve(obj.start(np.zeros(glob.n), ws_t1), lo, hi, max_rounds)
        if r.cost < best.cost:
            best = r
    u = best.x
    converged = bool(best.status > 0)
    optimizer = {
        "status": int(best.status),
        "message": str(best.message),
        "nfev": int(best.nfev_total),
        "rounds": int(best.rounds),
        "starts": starts,
        "converged": converged,
    }
    obj.set_sigmas(u)
    obj.inflate_com_sigma(u)
    J = obj.jac(u, central=True)
    cost_cal = obj.cost(u)
    scale_all = np.concatenate([glob.scale, np.ones(2 * obj.n_t)])
    se, corr, ok, notes = least_squares_report(J, glob.n, scale_all)
    se_sand = sandwich_se(J, obj.fun(u), obj.offs, glob.n, scale_all)
    xg, ws, sh = obj.unpack(u)
    estimates = _estimates(glob, fit, xg, se, ok, notes, se_sand, converged)
    residuals = _residual_rows(data, rows_t1, obj.rms_rows(u), ws_t1, ws, sh)
    cal_params = glob.params(np.array([e.value if e.identifiable else e.table1 for e in estimates]))
    return CalibrationResult(
        estimates,
        corr,
        {d.name: float(w) for d, w in zip(data, ws)},
        residuals,
        obj.sig["t"],
        obj.sig["h"],
        cal_params,
        failed,
        sim.calls,
        cost_t1,
        cost_cal,
        model,
        converged,
        optimizer,
    )


def _on_ridge(J: np.ndarray, n_global: int) -> bool:
    """Whether two globals are correlated beyond `RIDGE_CORRELATION` at the optimiser's last Jacobian."""
    _, corr, _, _ = least_squares_report(np.asarray(J), n_global, np.ones(J.shape[1]))
    off = np.abs(corr[~np.eye(n_global, dtype=bool)])
    return bool(np.any(~np.isfinite(off)) or np.any(off > RIDGE_CORRELATION))


def _rms_rows(sim: _Sim, data: list[_TrialData], p: Any, ws: np.ndarray, shifts: np.ndarray) -> list[_RmsRow]:
    """Per trial: (RMS step-frequency residual Hz, RMS CoM residual m, RMS period error s over the steps
    the simulation reached, steps reached)."""
    out: list[_RmsRow] = []
    for d, w, sh in zip(data, ws, shifts):
        rp, rh = _residuals(sim, p, d, float(w), float(sh))
        f_sim = rp + 1.0 / d.periods_s
        ok = f_sim > 0
        dt = 1.0 / f_sim[ok] - d.periods_s[ok]
        out.append(
            (
                float(np.sqrt(np.mean(rp**2))),
                float(np.sqrt(np.mean(rh**2))) if rh.size else math.nan,
                float(np.sqrt(np.mean(dt**2))) if dt.size else math.nan,
                int(ok.sum()),
            )
        )
    return out


def _set_sigmas(sig: dict[str, float], rows: Sequence[_RmsRow]) -> None:
    tp = [r[0] for r in rows if math.isfinite(r[0])]
    th = [r[1] for r in rows if math.isfinite(r[1])]
    if tp:
        sig["t"] = max(float(np.sqrt(np.mean(np.square(tp)))), 1e-4)
    if th:
        sig["h"] = max(float(np.sqrt(np.mean(np.square(th)))), 5e-5)
