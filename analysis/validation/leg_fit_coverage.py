"""Coverage of the leg-test fit's intervals, measured by simulation (``rimless trials leg-fit-coverage``).

Each simulated leg test is a leg drawn at random (k, c and the guide friction F_c uniform over `K_RANGE`,
`C_RANGE`, `F_RANGE`: damping ratios 0.2-0.6 about the paper's leg), released `releases` times at
compressions spread over `COMPRESSIONS_MM`, recorded by the truth model `rimless.analysis.validation.leg_truth`
(numerical integration with stiction; position noise, a random-walk drift of the count, floor quantisation,
read jitter, late and descheduled reads, an unknown release delay and sensor zero), written as leg-test logs and
fitted by `rimless.analysis.inference.leg_fit.fit_leg` exactly as a robot's logs are. The leg's moving mass is
drawn too (`MASS_RANGE`) and the fit is told it as a user knows it: a weighed value off by `MASS_REL_SD` (relative,
1 sigma) with that uncertainty, carried into its intervals; never the truth. The report, per
parameter: how often the 95 % interval holds the truth (with the binomial 95 % interval of that share), the
median and RMS relative error, the median relative 95 % half width, and the spread of (estimate - truth) / se
(1 for honest standard errors); and how many tests reach the precision goal (k and c to 2 %, F_c to 10 %, as
95 % half widths). A fit that fails (`RunFailure`: a leg that stuck in its first half cycle in every release) is
counted, never dropped silently.

One concept: the coverage study of the leg-test fit.
"""

from __future__ import annotations

import math
import tempfile
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from rimless.analysis.inference.leg_fit import GOALS, Z95, fit_leg, goal_check, read_leg_log
from rimless.analysis.validation.leg_truth import LegTruth, write_log
from rimless.errors import ParameterError, RunFailure

__all__ = ["K_RANGE", "C_RANGE", "F_RANGE", "COMPRESSIONS_MM", "LegCoverageResult", "run_leg_fit_coverage"]

K_RANGE = (2000.0, 3500.0)  # N/m (the paper's leg: 2700)
C_RANGE = (4.0, 10.0)  # N s/m (8; with m = 0.0378 kg the damping ratio spans about 0.2-0.6)
F_RANGE = (0.1, 0.5)  # N
MASS_RANGE = (0.030, 0.046)  # kg: the leg's moving mass (Table 1's leg: 0.0378), never handed to the fit
MASS_REL_SD = 0.005  # the fit is told a weighed mass: the truth times (1 + this x N(0, 1)), with this sd (relative)
COMPRESSIONS_MM = (1.5, 2.5)  # the releases' compressions, spread evenly (one release: the middle)
_KEYS = (("k_n_per_m", "k"), ("c_n_s_per_m", "c"), ("guide_friction_n", "friction"))


@dataclass
class LegCoverageResult:
    """The fits of `tests` simulated leg tests (see the module doc)."""

    tests: int
    releases: int
    seed: int
    noise_counts: float
    drift_counts_per_sqrt_s: float
    mass_rel_sd: float = MASS_REL_SD
    rows: list[dict[str, Any]] = field(default_factory=list)

    def summary(self) -> dict[str, Any]:
        """The JSON of ``rimless trials leg-fit-coverage --json``."""
        fitted = [r for r in self.rows if "failure" not in r]
        per: dict[str, Any] = {}
        for key, _ in _KEYS:
            if not fitted:
                per[key] = {"covered": 0, "fitted": 0}
                continue
            v = np.array([r[key] for r in fitted])
            t = np.array([r["truth"][key] for r in fitted])
            se = np.array([r[key + "_se"] for r in fitted])
            cov = np.abs(v - t) <= Z95 * se
            rel = (v - t) / t
            k = int(cov.sum())
            lo, hi = _wilson(k, len(fitted))
            per[key] = {
                "covered": k,
                "fitted": len(fitted),
                "coverage": k / len(fitted),
                "coverage_ci95": [lo, hi],
                "median_abs_rel_error": float(np.median(np.abs(rel))),
                "rms_rel_error": float(np.sqrt(np.mean(rel**2))),
                "median_rel_half_width": float(np.median(Z95 * se / np.abs(v))),
                "z_sd": float(np.std((v - t) / se)),
                "z_mean": float(np.mean((v - t) / se)),
                "within_goal_error": int(np.sum(np.abs(rel) <= GOALS[key])),
            }
        return {
            "tests": self.tests,
            "fitted": len(fitted),
            "failures": len(self.rows) - len(fitted),
            "failure_messages": [r["failure"] for r in self.rows if "failure" in r],
            "releases": self.releases,
            "seed": self.seed,
            "truth_model": {
                "k_n_per_m": list(K_RANGE),
                "c_n_s_per_m": list(C_RANGE),
                "guide_friction_n": list(F_RANGE),
                "compressions_mm": self._compressions(),
                "moving_mass_kg": list(MASS_RANGE),
                "stated_moving_mass": f"the truth times (1 + {self.mass_rel_sd:g} N(0, 1)), sd {self.mass_rel_sd:g} "
                "of the stated value (the leg as its user weighed it; the fit never sees the truth)",
                "noise_counts": self.noise_counts,
                "drift_counts_per_sqrt_s": self.drift_counts_per_sqrt_s,
            },
            "per_parameter": per,
            "goal": {"rel_half_width": GOALS, "tests_meeting_goal": sum(1 for r in fitted if r["goal"]["met"])},
        }

    def _compressions(self) -> list[float]:
        if self.releases == 1:
            return [0.5 * (COMPRESSIONS_MM[0] + COMPRESSIONS_MM[1])]
        return [float(x) for x in np.linspace(COMPRESSIONS_MM[0], COMPRESSIONS_MM[1], self.releases)]


def run_leg_fit_coverage(
    tests: int = 100,
    *,
    releases: int = 3,
    seed: int = 0,
    noise_counts: float = 0.3,
    drift_counts_per_sqrt_s: float = 0.5,
    mass_rel_sd: float = MASS_REL_SD,
    progress: Callable[[int], None] | None = None,
) -> LegCoverageResult:
    """Simulate and fit `tests` leg tests of `releases` releases each (same `seed`, same figures); `progress(i)`
    after each. About a second a test of three releases."""
    if tests < 1:
        raise ParameterError(f"--tests must be >= 1, got {tests}")
    if releases < 1:
        raise ParameterError(f"--releases must be >= 1, got {releases}")
    for name, v in (
        ("--noise-counts", noise_counts),
        ("--drift-counts-per-sqrt-s", drift_counts_per_sqrt_s),
        ("--mass-sd-rel", mass_rel_sd),
    ):
        if not (math.isfinite(v) and v >= 0):
            raise ParameterError(f"{name} must be >= 0, got {v!r}")
    res = LegCoverageResult(tests, releases, seed, noise_counts, drift_counts_per_sqrt_s, mass_rel_sd)
    rng = np.random.default_rng(seed)
    comp = res._compressions()
    with tempfile.TemporaryDirectory(prefix="rimless-leg-coverage-") as tmp:
        for i in range(tests):
            k, c, f = rng.uniform(*K_RANGE), rng.uniform(*C_RANGE), rng.uniform(*F_RANGE)
            mass = rng.uniform(*MASS_RANGE)
            stated = mass * (1.0 + mass_rel_sd * rng.standard_normal())
            truth = LegTruth(
                k_n_per_m=k,
                c_n_s_per_m=c,
                friction_n=f,
                mass_kg=mass,
                noise_counts=noise_counts,
                drift_counts_per_s=drift_counts_per_sqrt_s,
            )
            row: dict[str, Any] = {
                "truth": {"k_n_per_m": k, "c_n_s_per_m": c, "guide_friction_n": f, "moving_mass_kg": mass},
                "stated_moving_mass_kg": stated,
                "stated_moving_mass_sd_kg": mass_rel_sd * stated,
            }
            logs = []
            for j, mm in enumerate(comp):
                p = Path(tmp) / f"release{j}.jsonl"
                write_log(p, truth, compression_m=mm * 1e-3, seed=int(rng.integers(2**31)))
                logs.append(read_leg_log(p))
            try:
                fit = fit_leg(logs, moving_mass_kg=stated, moving_mass_sd_kg=mass_rel_sd * stated)
            except RunFailure as err:
                row["failure"] = str(err).replace(str(Path(tmp)) + "/", "")
            else:
                for key, attr in _KEYS:
                    est = getattr(fit, attr)
                    row[key], row[key + "_se"] = est.value, est.se
                row["goal"] = goal_check(
                    {key: row[key] for key, _ in _KEYS}, {key: Z95 * row[key + "_se"] for key, _ in _KEYS}, releases
                )
            res.rows.append(row)
            if progress is not None:
                progress(i + 1)
    return res


def _wilson(k: int, n: int) -> tuple[float, float]:
    """Wilson's 95 % interval of a binomial share k / n."""
    if n == 0:
        return (math.nan, math.nan)
    p, z2 = k / n, Z95 * Z95
    mid = (p + z2 / (2 * n)) / (1 + z2 / n)
    half = Z95 * math.sqrt(p * (1 - p) / n + z2 / (4 * n * n)) / (1 + z2 / n)
    return (max(mid - half, 0.0), min(mid + half, 1.0))
