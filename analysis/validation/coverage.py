"""Coverage of the critical-slope interval on the pendulum model of the verdicts (``rimless trials coverage --truth pendulum``).

Each synthetic series is a wheel drawn at random, walked on slopes straddling its own critical slope, turned into
trial-like objects (impact times with timing noise, a measured slope with its stated 95 % interval), and fed to
the same verdicts and estimates as real trials (`rimless.analysis.inference.sustained.trial_verdicts`,
`rimless.analysis.inference.critical_slope.estimate_critical_slope`). The report is how often the reported
95 % interval contains the true critical slope, and the median error.

The series come from a fast model of the verdict process, not from simulated Vicon files (importing would take
seconds per trial): a rigid rimless wheel (mass at the hub, eight massless legs of length L, angle alpha
between them) whose stance obeys theta'' = k sin(theta + phi), k = M g L / I_foot, with the impact map
w' = beta^2 (w + 4 k sin(phi) sin(alpha/2)) - d on the squared post-impact speed w (rad^2/s^2): beta is the
rigid wheel's angular-momentum ratio and d >= 0 a speed-independent loss per step (guide friction the
verdict's pendulum does not know of). Step periods are the stance quadrature; the true critical slope is the
slope where the fixed point of this map just passes over the top (bisection). What this leaves out, and the
benchmark therefore does not measure: the importer's errors (hub fit, impact detection) beyond the stated
timing noise and slope uncertainty, and the compliance of a real (ER) wheel.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from types import SimpleNamespace
from typing import Any

import numpy as np

__all__ = [
    "RigidFrictionWheel",
    "SeriesOutcome",
    "CoverageResult",
    "synthetic_series",
    "run_coverage",
    "wilson_interval",
]

ALPHA = math.pi / 4
G = 9.81
_GL_NODES, _GL_WEIGHTS = np.polynomial.legendre.leggauss(64)
Z95 = 1.959963984540054


@dataclass(frozen=True)
class RigidFrictionWheel:
    """The truth model of one synthetic series (SI units; ``loss_rad2_s2`` is d of the impact map)."""

    mass_kg: float = 2.0
    inertia_hub_kg_m2: float = 0.2
    leg_m: float = 0.237
    loss_rad2_s2: float = 0.0

    @property
    def inertia_foot(self) -> float:
        return self.inertia_hub_kg_m2 + self.mass_kg * self.leg_m**2

    @property
    def k(self) -> float:
        return self.mass_kg * G * self.leg_m / self.inertia_foot

    @property
    def beta(self) -> float:
        ml2 = self.mass_kg * self.leg_m**2
        return (self.inertia_hub_kg_m2 + ml2 * math.cos(ALPHA)) / self.inertia_foot

    def top_margin(self, w: float, phi: float) -> float:
        """Squared speed over the top (rad^2/s^2) of a stance starting with squared speed w at -alpha/2."""
        return w + 2 * self.k * (math.cos(phi - ALPHA / 2) - 1.0)

    def next_w(self, w: float, phi: float) -> float:
        return self.beta**2 * (w + 4 * self.k * math.sin(phi) * math.sin(ALPHA / 2)) - self.loss_rad2_s2

    def critical_slope_deg(self) -> float:
        """The slope (deg) above which the fixed point of the map passes over the top, by bisection."""
        b2 = self.beta**2

        def margin(phi: float) -> float:
            w_star = (b2 * 4 * self.k * math.sin(phi) * math.sin(ALPHA / 2) - self.loss_rad2_s2) / (1 - b2)
            return self.top_margin(w_star, phi)

        lo, hi = 1e-9, ALPHA / 2 - 1e-9
        for _ in range(100):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if margin(mid) < 0 else (lo, mid)
        return math.degrees(0.5 * (lo + hi))

    def period_s(self, w: float, phi: float) -> float:
        """Stance time (s) from -alpha/2 to alpha/2 starting with squared speed w: Gauss-Legendre on 64 nodes
        over each side of the top (theta = -phi), where the integrand peaks."""
        k = self.k
        nodes, weights = _GL_NODES, _GL_WEIGHTS
        c0 = math.cos(phi - ALPHA / 2)

        def part(a: float, b: float) -> float:
            th = 0.5 * (b - a) * nodes + 0.5 * (a + b)
            return float(0.5 * (b - a) * np.sum(weights / np.sqrt(w + 2 * k * (c0 - np.cos(th + phi)))))

        return part(-ALPHA / 2, -phi) + part(-phi, ALPHA / 2)

    def walk(self, slope_deg: float, release_rad_s: float, ramp_steps: int) -> tuple[np.ndarray, bool]:
        """Step periods (s) from the release, and whether the wheel stalled on the ramp."""
        phi = math.radians(slope_deg)
        w = release_rad_s**2
        periods: list[float] = []
        for _ in range(ramp_steps):
            if w <= 0 or self.top_margin(w, phi) <= 1e-6:
                return np.array(periods), True
            periods.append(self.period_s(w, phi))
            w = self.next_w(w, phi)
        return np.array(periods), False

    def wheel_params(self) -> Any:
        """`rimless.sim.model.params.WheelParams` of this rigid wheel (tiny legs: M = m_H + 8 m)."""
        from rimless.sim.model.params import WheelParams

        m = 1e-4
        return WheelParams(
            hub_mass_kg=self.mass_kg - 8 * m,
            leg_mass_kg=m,
            inertia_kg_m2=self.inertia_hub_kg_m2 - 8 * m * self.leg_m**2,
            leg_length_m=self.leg_m,
        )


@dataclass
class _Trial:
    time_s: np.ndarray
    impact_time_s: np.ndarray
    step_period_s: np.ndarray
    meta: SimpleNamespace
    series: dict = field(default_factory=dict)


def synthetic_series(
    rng: np.random.Generator, *, ramp_steps: int = 11, timing_noise_s: float = 1e-3, rate_hz: float = 100.0
) -> tuple[RigidFrictionWheel, float, list[_Trial]]:
    """One series: a random wheel (hub inertia, friction loss), six slopes straddling its critical slope at
    random offsets (two releases each), each trial's slope measured with a random uncertainty (0.03-0.12 deg,
    1 sigma) that its ``meta.slope_ci_rad`` states. Returns (wheel, true critical slope deg, trials)."""
    while True:
        wheel = RigidFrictionWheel(
            inertia_hub_kg_m2=float(rng.uniform(0.06, 0.3)), loss_rad2_s2=float(rng.uniform(0.0, 0.25))
        )
        crit = wheel.critical_slope_deg()
        if 0.5 < crit < 4.0:
            break
    spacing = float(rng.uniform(0.1, 0.25))
    offsets = (np.arange(6) - float(rng.uniform(1.5, 3.5))) * spacing
    trials = []
    for j, off in enumerate(offsets):
        slope = crit + float(off)
        if slope <= 0.05:
            continue
        for release in (float(rng.uniform(1.6, 2.2)), float(rng.uniform(2.4, 3.2))):
            periods, stalled = wheel.walk(slope, release, ramp_steps)
            imp_true = np.cumsum(periods)  # the release step ends at the first impact seen
            imp = (
                imp_true[:-1] + rng.normal(0.0, timing_noise_s, max(imp_true.size - 1, 0))
                if imp_true.size
                else imp_true
            )
            imp = np.sort(imp)
            sigma = float(rng.uniform(0.03, 0.12))
            measured = slope + float(rng.normal(0.0, sigma))
            half = math.radians(Z95 * sigma)
            end = float(imp_true[-1]) + (1.5 if stalled else 0.2) if imp_true.size else 1.0
            meta = SimpleNamespace(
                slope_deg=measured,
                source_file=f"series_{j}_{release:.2f}",
                rate_hz=rate_hz,
                outcome="stalled" if stalled else "walked",
                slope_source="estimated",
                slope_ci_rad=(math.radians(measured) - half, math.radians(measured) + half),
                true_slope_deg=slope,
            )
            trials.append(_Trial(np.arange(0.0, end, 1.0 / rate_hz), imp, np.diff(imp), meta))
    return wheel, crit, trials


@dataclass
class SeriesOutcome:
    truth_deg: float
    estimate_deg: float
    ci_deg: tuple[float, float] | None
    method: str | None
    covered: bool
    per_method: dict[str, bool]


@dataclass
class CoverageResult:
    outcomes: list[SeriesOutcome]
    seed: int

    def summary(self) -> dict[str, Any]:
        est = [o for o in self.outcomes if o.ci_deg is not None]
        n = len(est)
        cov = sum(o.covered for o in est)
        err = np.array([o.estimate_deg - o.truth_deg for o in est])
        cis = [o.ci_deg for o in est if o.ci_deg is not None]  # all of est (the test narrows the type)
        widths = np.array([hi - lo for lo, hi in cis]) if est else np.zeros(0)
        methods: dict[str, dict[str, int]] = {}
        for o in est:
            for m, ok in o.per_method.items():
                d = methods.setdefault(m, {"series": 0, "covered": 0, "chosen": 0})
                d["series"] += 1
                d["covered"] += int(ok)
            methods.setdefault(o.method or "", {"series": 0, "covered": 0, "chosen": 0})["chosen"] += 1
        lo, hi = wilson_interval(cov, n)
        return {
            "series": len(self.outcomes),
            "estimated": n,
            "covered": cov,
            "coverage": cov / n if n else math.nan,
            "coverage_ci95": [lo, hi],
            "median_abs_error_deg": float(np.median(np.abs(err))) if n else math.nan,
            "median_error_deg": float(np.median(err)) if n else math.nan,
            "median_ci_width_deg": float(np.median(widths)) if n else math.nan,
            "per_method": methods,
            "seed": self.seed,
            "goal": [0.90, 0.98],
        }


def wilson_interval(k: int, n: int) -> tuple[float, float]:
    """95 % Wilson interval of a binomial proportion k/n."""
    if n == 0:
        return math.nan, math.nan
    p, z2 = k / n, Z95**2
    c = (p + z2 / (2 * n)) / (1 + z2 / n)
    h = Z95 * math.sqrt(p * (1 - p) / n + z2 / (4 * n * n)) / (1 + z2 / n)
    return max(c - h, 0.0), min(c + h, 1.0)


def run_coverage(
    n_series: int = 60, seed: int = 0, *, n_boot: int = 200, progress: Callable[[int], None] | None = None
) -> CoverageResult:
    """Generate ``n_series`` series and estimate each one's critical slope; ``progress(i)`` after each."""
    from rimless.analysis.inference.critical_slope import estimate_critical_slope
    from rimless.analysis.inference.sustained import trial_verdicts

    rng = np.random.default_rng(seed)
    outcomes = []
    for i in range(n_series):
        wheel, crit, trials = synthetic_series(rng)
        verdicts = trial_verdicts(trials, wheel.wheel_params())
        res = estimate_critical_slope(
            verdicts, [t.meta.source_file for t in trials], n_boot=n_boot, seed=int(rng.integers(2**31))
        )
        c = res.chosen
        per = {}
        for e in res.estimates:
            per[e.method] = bool(e.ci_deg[0] <= crit <= e.ci_deg[1])
            ci = getattr(e, "ci_bootstrap_deg", None)  # the bootstrap check, reported beside
            per[f"{e.method} (bootstrap check)"] = bool(ci and ci[0] <= crit <= ci[1])
        outcomes.append(
            SeriesOutcome(
                crit,
                c.value_deg if c else math.nan,
                c.ci_deg if c else None,
                c.method if c else None,
                bool(c and c.ci_deg[0] <= crit <= c.ci_deg[1]),
                per,
            )
        )
        if progress:
            progress(i + 1)
    return CoverageResult(outcomes, seed)
