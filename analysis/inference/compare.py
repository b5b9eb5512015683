"""Compare Vicon trials with the simulated wheel: CoM height over time and step period per step.

What is fitted (one number per trial): the wheel is modelled as released at the rigid-touchdown state
theta = -alpha/2 with angular velocity ``release_theta_dot`` one step before the first measured impact (a
hand release, or any earlier step, ends in such a touchdown). That speed is found by a bracketed 1-D root
find (grid scan, then Brent) so that the simulated step from the first to the second impact lasts exactly
the measured first step period. The walk is then simulated on the trial's slope (given or estimated) for
as many steps as were measured; ``theta_dot_plus_rad_s`` is the simulated post-impact theta' at the first
measured impact (model.md section 6 section point).

Release (`rimless.analysis.inference.release`): a compliant wheel released into its gait reaches the first
measured impact with its post-impact angle 0.05-0.10 rad below where the rigid touchdown puts it, which the
speed alone cannot hold (the first periods then miss by milliseconds). So, with three or more measured periods,
that angle's offset (``first_angle_offset_rad``, within +-0.1 rad) is fitted with the release speed by least
squares on all the measured step frequencies (on the compiled step map), and kept only when the test against
the rigid release (offset 0, the speed alone) supports it (p < `FIRST_ANGLE_P`, ``first_angle_offset_p``; the
periods' noise at least the importer's, `PERIOD_NOISE_FLOOR_S`); otherwise the rigid release, whose speed matches
the first period. The test is reported whole (`first_angle_test`, `FirstAngleTest`; keys ``first_angle_offset_tested``,
``_kept``, ``_test``, ``_statistic``, ``_level``, ``_fitted_deg`` and ``first_angle_choice_period_change_ms``, what
the other choice would move a simulated period, and ``_noise_ms`` / ``_noise_source``, the period noise it took).
On a truth released as the rigid release (true offset 0) it kept the offset in 17.5 % of 120 walks at the nominal
1 % while the importer's first period carried a bias of about 0.9 ms; with the first impact at its own touchdown
(`rimless.analysis.kinematics.steps`) in 1 of 82 (docs/trials.md, "The first period's bias, found and removed").
``Simulator.fit_first_angle`` False keeps the rigid release. With an offset the first period is no longer matched
by construction.

Alignment: time zero is the first measured impact (and the simulated first impact). The importer places
impacts from the CoM-height minima, which in the compliant wheel lag the touchdown by a few ms; so the
simulated curve is then shifted in time by at most ``MAX_SHIFT_S`` (the lag minimising the CoM-height RMS,
reported as ``time_shift_s``). Heights: when the trial's CoM height is measured from the line through its
impacts (no leg length given at import), it is offset by the constant that best matches the simulation
(``height_offset_m``, reported); when it is measured from the slope plane it is compared as it is.

Metrics: the first measured period is matched by construction (it fixes the release speed), so the period
error metrics use steps 2..N only (``mean_abs_period_error_s``). The CoM-height RMS is also given relative to
the measured peak-to-peak CoM amplitude (``rms_com_relative``) with the correlation between measured and
simulated curves (``com_correlation``): a flat simulated line cannot score well on both.

Status: ``ok`` only when the comparison passes the plausibility checks (`PLAUSIBILITY`: the CoM curve's, and the
step periods after the first against their noise, `period_misfit`); otherwise
``suspect`` with the reasons in the warnings; ``failed`` when nothing could be compared (no steps, slope
outside the model's range, a period the model cannot produce, a stalled walk), returned with a message,
never raised.

One concept: the comparison of one trial with the simulated wheel (its release, the first angle's test, whose
weighted form on the importer's per-impact sds is `_weighted_first_angle_test`, the alignment and the metrics).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from rimless.analysis.io.trial import ALPHA_RAD

__all__ = [
    "TrialComparison",
    "SlopeGroup",
    "Simulator",
    "compare_trial",
    "step_period_trends",
    "fit_release_speed",
    "fit_first_angle_offset",
    "first_angle_test",
    "FirstAngleTest",
    "period_misfit",
    "PeriodMisfit",
]

MAX_SHIFT_S = 0.05
RELEASE_GRID_RAD_S = (0.3, 8.0, 78)  # scan of the release speed: lo, hi, points
#: a comparison is "suspect" unless: correlation >= min_correlation, RMS / amplitude <= max_relative_rms,
#: the measured CoM swings by >= min_amplitude_m, and the time shift is inside the search
#: the step periods after the first fail when they miss the measured ones both beyond the periods' noise (the
#: chi-square of `period_misfit` below ``period_p``) and by more than ``max_relative_period_rms`` of the measured
#: period (rms): a miss the noise cannot explain and large enough to matter
PLAUSIBILITY = {
    "min_correlation": 0.8,
    "max_relative_rms": 0.35,
    "min_amplitude_m": 1e-3,
    "period_p": 1e-3,
    "max_relative_period_rms": 0.1,
}
#: the first impact's angle offset is kept when its test on the periods gives p below this (a wheel released at the
#: rigid touchdown, the bundled example generator's, noise free, gave p = 0.02: the importer's bias on the first
#: impacts; ER truths released into their gait, p below 1e-6)
FIRST_ANGLE_P = 0.01
#: the importer's noise on a measured period (s) the test of the offset takes at least: 0.22 ms an impact
#: (measured on Tracker exports of the simulator's ER wheel, session 16; tests/analysis/inference/
#: test_calibrate_release.py), times sqrt(2) for the two impacts of a period
PERIOD_NOISE_FLOOR_S = 0.3e-3


@dataclass
class Simulator:
    """The simulator pieces a comparison needs (built once, reused for every trial)."""

    model: str = "er"
    params: Any = None  # WheelParams; Table 1 when None (the slope is replaced per trial)
    rtol: float = 1e-8
    record_dt_s: float = 2e-3
    integrator: Any = None
    #: fit the first measured impact's post-impact angle offset (`fit_first_angle_offset`); False: the rigid release
    fit_first_angle: bool = True

    def __post_init__(self) -> None:
        from rimless.sim.model.params import WheelParams
        from rimless.sim.step.backend import make_integrator

        if self.params is None:
            self.params = WheelParams()
        if self.integrator is None:
            self.integrator = make_integrator("auto", rtol=self.rtol)

    def on_slope(self, slope_deg: float) -> Any:
        """Parameters with the slope replaced (raises `ParameterError` outside 0 <= phi < alpha/2)."""
        return self.params.replace(slope_rad=math.radians(slope_deg))

    def walk(
        self, slope_deg: float, release_theta_dot_rad_s: float, n_steps: int, *, record: bool, offset_rad: float = 0.0
    ) -> Any:
        """`simulate_steps` from the rigid-touchdown release (theta = -alpha/2, theta' given), the post-impact
        angle at the first impact moved by ``offset_rad`` (`rimless.analysis.inference.release.walk_from_release`)."""
        from rimless.analysis.inference.release import walk_from_release

        return walk_from_release(
            self.on_slope(slope_deg),
            self.model,
            release_theta_dot_rad_s,
            n_steps,
            self.integrator,
            self.record_dt_s if record else 1.0,
            offset_rad,
        )


@dataclass
class TrialComparison:
    """Measured vs simulated for one trial (SI inside; `metrics` gives the edge units)."""

    name: str
    file: str
    slope_deg: float
    slope_source: str
    model: str
    status: str  # "ok", "suspect" (failed a plausibility check, see warnings) or "failed"
    message: str | None = None
    warnings: list[str] = field(default_factory=list)
    release_theta_dot_rad_s: float = float("nan")
    #: the first measured impact's post-impact angle, offset from where the rigid release puts it (rad; 0: not
    #: fitted or not kept, `fit_first_angle_offset`)
    first_angle_offset_rad: float = 0.0
    first_angle_offset_p: float = float("nan")  # its F test's p-value on the periods (NaN: not tested)
    theta_dot_plus_rad_s: float = float("nan")
    time_shift_s: float = float("nan")
    height_offset_m: float = float("nan")
    measured_period_s: np.ndarray = field(default_factory=lambda: np.zeros(0))
    sim_period_s: np.ndarray = field(default_factory=lambda: np.zeros(0))  # NaN where the simulation stopped
    #: simulated clutched time (the ``slsp_clutched`` phase, s) of the step of each measured period; NaN where the
    #: simulation stopped, 0 for the VE model
    sim_clutched_s: np.ndarray = field(default_factory=lambda: np.zeros(0))
    measured_step: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))  # step number of each period,
    # 1 = the first measured period; a period lost in a gap keeps its number (empty: 1..n)
    time_s: np.ndarray = field(default_factory=lambda: np.zeros(0))  # measured, from the first impact
    measured_com_m: np.ndarray = field(default_factory=lambda: np.zeros(0))  # after the height offset
    sim_com_m: np.ndarray = field(default_factory=lambda: np.zeros(0))  # simulated at time_s (NaN outside)
    sim_time_s: np.ndarray = field(default_factory=lambda: np.zeros(0))  # dense simulated curve, aligned
    sim_curve_m: np.ndarray = field(default_factory=lambda: np.zeros(0))
    measured_impact_time_s: np.ndarray = field(default_factory=lambda: np.zeros(0))  # from the first impact
    rms_com_error_m: float = float("nan")
    com_amplitude_m: float = float("nan")  # measured peak-to-peak (1st-99th percentile) in the RMS window
    com_correlation: float = float("nan")  # Pearson r, measured vs simulated, in the RMS window
    #: the simulated wheel's parameters, one {name, symbol, value, sd, unit, source, basis} each (`Wheel.input`:
    #: Table 1's or the wheel file's); None when the comparison was assembled without a wheel
    parameters: list[dict[str, Any]] | None = None
    #: the test in full (`first_angle_test`): the offset fitted whether kept or not, the statistic, and how much
    #: the choice moves the simulated periods; None when not run (``Simulator.fit_first_angle`` False)
    first_angle: FirstAngleTest | None = None

    def __repr__(self) -> str:
        return (
            f"TrialComparison({self.name}: {self.status}, {self.model} at {self.slope_deg:.3f} deg, "
            f"{self.n_steps} step(s), RMS CoM {self.rms_com_error_m * 1e3:.2f} mm; .to_dict())"
        )

    def _first_angle_row(self) -> dict[str, Any]:
        return _first_angle_keys(self.first_angle)

    def to_dict(self) -> dict[str, Any]:
        """`metrics()` (the trial's row of metrics.csv and of `rimless trials report --json`) and ``parameters``:
        the simulated wheel's parameters with their values and sources (the JSON of `rimless.analysis.compare`)."""
        return self.metrics() | {"parameters": self.parameters}

    @property
    def rms_com_relative(self) -> float:
        """RMS CoM error / measured CoM amplitude (a flat line scores about 0.3-0.4)."""
        a = self.com_amplitude_m
        return self.rms_com_error_m / a if a > 0 else float("nan")

    @property
    def n_steps(self) -> int:
        return int(self.measured_period_s.size)

    @property
    def period_error_s(self) -> np.ndarray:
        """Simulated minus measured period per measured step, s."""
        if self.sim_period_s.size != self.measured_period_s.size:  # nothing simulated (failed)
            return np.full(self.measured_period_s.size, np.nan)
        return self.sim_period_s - self.measured_period_s

    @property
    def mean_abs_period_error_s(self) -> float:
        """Mean |simulated - measured| over steps 2..N (step 1 fixes the release: its error is 0 by construction
        with the rigid release, small with a fitted first-angle offset), s."""
        e = self.period_error_s[1:]
        e = e[np.isfinite(e)]
        return float(np.mean(np.abs(e))) if e.size else float("nan")

    def metrics(self) -> dict[str, Any]:
        """One flat row: the metrics table / metrics.csv (edge units in the names)."""
        return {
            "trial": self.name,
            "file": self.file,
            "status": self.status,
            "slope_deg": self.slope_deg,
            "slope_source": self.slope_source,
            "model": self.model,
            "steps": self.n_steps,
            "rms_com_error_mm": self.rms_com_error_m * 1e3,
            "mean_abs_period_error_ms": self.mean_abs_period_error_s * 1e3,
            "rms_com_relative": self.rms_com_relative,
            "com_correlation": self.com_correlation,
            "theta_dot_plus_rad_s": self.theta_dot_plus_rad_s,
            "release_theta_dot_rad_s": self.release_theta_dot_rad_s,
            "first_angle_offset_deg": math.degrees(self.first_angle_offset_rad),
            "first_angle_offset_p": self.first_angle_offset_p,
            **self._first_angle_row(),
            "time_shift_ms": self.time_shift_s * 1e3,
            "height_offset_mm": self.height_offset_m * 1e3,
            "message": "; ".join(([self.message] if self.message else []) + self.warnings),
            **_period_misfit_keys(self.period_fit()),
        }

    def period_fit(self) -> PeriodMisfit | None:
        """`period_misfit` of this comparison's periods after the first (the plausibility check's figures); None
        when nothing was simulated or there is no period after the first."""
        return period_misfit(self.measured_period_s, self.sim_period_s, self.measured_step)


def _first_angle_keys(t: FirstAngleTest | None) -> dict[str, Any]:
    """The first-angle test's row keys (edge units): tested, kept, the statistic, the offset fitted either way and
    how far the choice moves a simulated period."""
    tested = t is not None and math.isfinite(t.p)
    return {
        "first_angle_offset_tested": tested,
        "first_angle_offset_kept": bool(t is not None and t.kept),
        "first_angle_offset_test": t.test if tested and t is not None else None,
        "first_angle_offset_statistic": t.statistic if tested and t is not None else None,
        "first_angle_offset_level": t.level if t is not None else FIRST_ANGLE_P,
        "first_angle_offset_fitted_deg": math.degrees(t.fitted_offset_rad) if tested and t is not None else None,
        "first_angle_choice_period_change_ms": (
            t.period_change_s * 1e3 if tested and t is not None and math.isfinite(t.period_change_s) else None
        ),
        "first_angle_offset_noise_ms": t.noise_s * 1e3 if tested and t is not None else None,
        "first_angle_offset_noise_source": t.noise_source if tested and t is not None else None,
        "first_angle_offset_weighted": bool(tested and t is not None and t.weighted),
    }


def _period_misfit_keys(pm: PeriodMisfit | None) -> dict[str, Any]:
    """The periods' misfit row keys (`period_misfit`, edge units): the chi-square of periods 2..N against their
    noise, its degrees of freedom and p, the rms miss relative to the median period, the impact noise taken and
    where it came from; None each when not computed."""
    return {
        "period_misfit_chi2": pm.chi2 if pm is not None else None,
        "period_misfit_dof": pm.dof if pm is not None else None,
        "period_misfit_p": pm.p if pm is not None else None,
        "period_misfit_relative_rms": pm.relative_rms if pm is not None else None,
        "period_misfit_impact_sd_ms": pm.impact_sd_s * 1e3 if pm is not None else None,
        "period_misfit_noise_source": pm.noise_source if pm is not None else None,
    }


def fit_release_speed(sim: Simulator, slope_deg: float, first_period_s: float) -> tuple[float | None, str | None]:
    """Release theta' (rad/s) whose simulated second step lasts ``first_period_s``; (None, why) if none does.

    The scan of `RELEASE_GRID_RAD_S` runs on the compiled step map (`_map_periods`, no trajectory, some 10x
    cheaper) where it applies; the bracket it finds is checked on the walk itself and the root is found on
    the walk, so the result is the walk's (a scan that disagrees, or finds no bracket, is redone on walks)."""

    def period2(w: float) -> float:
        g = sim.walk(slope_deg, w, 2, record=False)
        if len(g.steps) >= 2:
            return g.steps[1].period_s
        if g.failure is not None and g.failure.reason.value == "stall":
            return math.inf  # too slow: never gets there
        return math.nan

    def solve(i: int, a: float, b: float, vals: np.ndarray) -> tuple[float | None, str | None]:
        """The root in [grid[i], grid[i + 1]]; from a stall at grid[i], first the stall's edge by bisection:
        the walk's second period is longest just above it (finite: the first step then creeps over the top),
        so a measured period longer than that one is refused with it, and the root is searched from the edge
        (where the period is continuous) rather than across the jump to the stall."""
        if not math.isinf(a):
            return _root_in(period2, grid, i, b, first_period_s, vals)
        w_stall, w_walk, t_walk = float(grid[i]), float(grid[i + 1]), b + first_period_s
        while w_walk - w_stall > 1e-9:  # rad/s: the period there has converged to 1e-4 s
            mid = 0.5 * (w_stall + w_walk)
            t = period2(mid)
            if math.isnan(t):  # another failure between: keep the grid's bracket
                return _root_in(period2, grid, i, b, first_period_s, vals)
            if math.isinf(t):
                w_stall = mid
            else:
                w_walk, t_walk = mid, t
        if t_walk < first_period_s:
            return None, (
                f"the measured first period {first_period_s:.3f} s is longer than any the model gives after a "
                f"release one step earlier (at most {t_walk:.3f} s, just above the stall at a release of "
                f"{w_walk:.4f} rad/s)"
            )
        edge = np.array([w_walk, float(grid[i + 1])])
        return _root_in(period2, edge, 0, b, first_period_s, np.array([t_walk - first_period_s, b]))

    lo, hi, n = RELEASE_GRID_RAD_S
    grid = np.linspace(lo, hi, int(n))
    fast = _map_periods(sim, slope_deg, grid)
    if fast is not None:
        i = _first_bracket(fast - first_period_s)
        if i is not None:
            a, b = period2(float(grid[i])) - first_period_s, period2(float(grid[i + 1])) - first_period_s
            if a > 0 and b <= 0:  # the walk agrees: the same bracket as a scan on walks finds first
                return solve(i, a, b, fast - first_period_s)
    vals = np.array([period2(w) for w in grid]) - first_period_s
    i = _first_bracket(vals)
    if i is not None:
        return solve(i, vals[i], vals[i + 1], vals)
    fin = vals[np.isfinite(vals)]
    if fin.size == 0:
        return None, "the simulated wheel does not complete two steps from any release speed in the scanned range"
    if np.all(fin > 0):
        return None, (
            f"the measured first period {first_period_s:.3f} s is longer than any the model gives "
            f"(at most {first_period_s + float(np.max(fin)):.3f} s)"
        )
    return None, (
        f"the measured first period {first_period_s:.3f} s is shorter than any the model gives for a release "
        f"up to {hi:g} rad/s (at least {first_period_s + float(np.min(fin)):.3f} s)"
    )


@dataclass(frozen=True)
class FirstAngleTest:
    """The test of the first measured impact's angle offset against the rigid release (`first_angle_test`).

    ``offset_rad`` and ``release_theta_dot_rad_s``: what the comparison simulates (offset 0 and the rigid release's
    speed unless ``kept``); ``fitted_offset_rad``: the offset the two-parameter fit found, kept or not (NaN: not
    tested); ``statistic`` the test's F (``test`` "F(1, n-2)", the periods' noise from the fit's residuals) or chi^2
    (``test`` "chi2(1)", the noise at the importer's floor `PERIOD_NOISE_FLOOR_S`), ``p`` its p-value (NaN: not
    tested), ``level`` `FIRST_ANGLE_P`; ``period_change_s``: the largest change of a simulated period after the
    first had the other model been simulated (the dropped offset's, or the rigid release's when kept), s: what the
    choice moves."""

    offset_rad: float
    release_theta_dot_rad_s: float
    fitted_offset_rad: float = math.nan
    statistic: float = math.nan
    test: str = ""
    p: float = math.nan
    level: float = FIRST_ANGLE_P
    kept: bool = False
    period_change_s: float = math.nan  # over the steps both reach; NaN: none
    #: the rigid release's speed fitted on all the periods (the test's null model), and the speed fitted with the
    #: offset (kept or not), rad/s; NaN: not tested
    rigid_fit_theta_dot_rad_s: float = math.nan
    fitted_theta_dot_rad_s: float = math.nan
    #: the sd of a measured period the test took (s; NaN: not tested) and where it came from: the offset fit's
    #: residuals (F test) or the importer's floor `PERIOD_NOISE_FLOOR_S` (chi-square test)
    noise_s: float = math.nan
    noise_source: str = ""
    #: True when the test weighed the periods by the importer's per-impact sds (``impact_sd_s``: generalised least
    #: squares; ``noise_s`` then their rms period sd and the statistic in units of them)
    weighted: bool = False


def period_covariance(impact_sd_s: np.ndarray) -> np.ndarray:
    """(n, n) covariance of the n consecutive periods between n + 1 impacts of independent time errors with sds
    ``impact_sd_s`` (s), s^2: var P_i = sd_(i-1)^2 + sd_i^2, cov(P_i, P_(i+1)) = -sd_i^2 (periods are differences)."""
    v = np.asarray(impact_sd_s, float) ** 2
    n = v.size - 1
    c = np.diag(v[:-1] + v[1:])
    if n > 1:
        i = np.arange(n - 1)
        c[i, i + 1] = c[i + 1, i] = -v[1:-1]
    return c


def _usable_sd(impact_sd_s: np.ndarray | None, n_periods: int) -> np.ndarray | None:
    """The per-impact sds (s) when there is one per impact of the n periods, all finite and positive; else None."""
    if impact_sd_s is None:
        return None
    sd = np.asarray(impact_sd_s, float)
    if sd.size != n_periods + 1 or not np.all(np.isfinite(sd)) or not np.all(sd > 0):
        return None
    return sd


def fit_first_angle_offset(
    sim: Simulator, slope_deg: float, periods_s: np.ndarray, w0: float
) -> tuple[float, float, float]:
    """(offset rad, release theta' rad/s, p-value): `first_angle_test`'s ``offset_rad``, ``release_theta_dot_rad_s``
    and ``p``."""
    t = first_angle_test(sim, slope_deg, periods_s, w0)
    return t.offset_rad, t.release_theta_dot_rad_s, t.p


def first_angle_test(
    sim: Simulator, slope_deg: float, periods_s: np.ndarray, w0: float, impact_sd_s: np.ndarray | None = None
) -> FirstAngleTest:
    """The first measured impact's post-impact angle offset and the release speed fitted on all the measured
    periods (`rimless.analysis.inference.release.fit_first_angle`, on the compiled step map, from offset 0 and
    -0.06 rad), kept only when it lowers the periods' sum of squares significantly below the rigid release's
    (offset 0, the speed fitted alone, from ``w0``): the test of one extra parameter on the n periods, with their
    noise the larger of the fit's residual variance (F test, n - 2 degrees of freedom) and the importer's floor
    `PERIOD_NOISE_FLOOR_S` (chi-square test: the impacts the importer places from the CoM minima carry a bias of a
    few tenths of a ms that a noise-free recording does not average out), p < `FIRST_ANGLE_P`. Else offset 0 and
    ``w0``; not tested (p NaN) with fewer than three periods (two unknowns) or when no fit walks.

    ``impact_sd_s`` (s; the importer's ``impact_sd_s`` of the n + 1 impacts bounding the n consecutive periods):
    the test weighs the periods by them instead (`_weighted_first_angle_test`: generalised least squares with the
    periods' covariance, `period_covariance`; the first impact, placed from its own touchdown, carries more than the
    later ones). Ignored (the test above) unless there is one finite sd per impact."""
    sd = _usable_sd(impact_sd_s, np.asarray(periods_s).size)
    if sd is not None:
        got_w = _weighted_first_angle_test(sim, slope_deg, np.asarray(periods_s, float), w0, sd)
        if got_w is not None:
            return got_w
    from scipy.optimize import least_squares
    from scipy.stats import chi2, f

    from rimless.analysis.inference.release import fit_first_angle, map_frequencies

    periods = np.asarray(periods_s, float)
    if periods.size < 3 or not np.all(np.isfinite(periods)):
        return FirstAngleTest(0.0, w0, level=FIRST_ANGLE_P)
    p = sim.on_slope(slope_deg)
    f_meas = 1.0 / periods

    def freq_res(offset: float, w: float) -> np.ndarray:
        return map_frequencies(p, sim.model, w, periods.size, offset, sim.rtol) - f_meas

    def sim_periods(offset: float, w: float) -> np.ndarray:  # s; 1 s past the measured one for a step not reached
        f_sim = freq_res(offset, w) + f_meas
        return np.where(f_sim > 0, 1.0 / np.where(f_sim > 0, f_sim, 1.0), periods + 1.0)

    def rss_s2(offset: float, w: float) -> float:  # the periods' sum of squares, s^2
        e = sim_periods(offset, w) - periods
        return float(e @ e)

    got = fit_first_angle(freq_res, f_meas, w0, (0.0, -0.06))
    if got is None:
        return FirstAngleTest(0.0, w0, level=FIRST_ANGLE_P)
    rigid = least_squares(lambda q: freq_res(0.0, float(q[0])), [w0], bounds=([0.05], [20.0]), diff_step=[1e-5])
    rss0 = min(rss_s2(0.0, float(rigid.x[0])), rss_s2(0.0, w0))
    rss1, dof = rss_s2(got[0], got[1]), periods.size - 2
    var = rss1 / dof
    if var >= PERIOD_NOISE_FLOOR_S**2:
        stat, test = (rss0 - rss1) / var, f"F(1, {dof})"
        p_value = float(f.sf(stat, 1, dof))
        noise, source = math.sqrt(var), f"the offset fit's residuals ({dof} degrees of freedom)"
    else:
        stat, test = (rss0 - rss1) / PERIOD_NOISE_FLOOR_S**2, "chi2(1)"
        p_value = float(chi2.sf(stat, 1))
        noise, source = PERIOD_NOISE_FLOOR_S, "the importer's floor (PERIOD_NOISE_FLOOR_S)"
    f1, f0 = freq_res(got[0], got[1]) + f_meas, freq_res(0.0, w0) + f_meas
    return _first_angle_verdict(
        (got[0], got[1]), w0, float(rigid.x[0]), (rss0, rss1), (float(stat), test, p_value), (noise, source), (f1, f0)
    )


def _weighted_first_angle_test(
    sim: Simulator, slope_deg: float, periods: np.ndarray, w0: float, impact_sd_s: np.ndarray
) -> FirstAngleTest | None:
    """`first_angle_test` on the periods weighed by the impacts' sds: both models (the offset with the speed, from
    offset 0 and -0.06 rad; the speed alone, from ``w0``) fitted by least squares on the whitened period residuals
    (``L^-1 (simulated - measured)``, ``L L^T`` = `period_covariance`), their costs chi-squares in the stated sds.
    The drop of the cost is chi2(1) when the offset fit's cost per degree of freedom is at most 1 (the sds explain
    the residuals), else F(1, n - 2) with the residuals' own scale. None when no fit walks or too few periods."""
    from scipy.optimize import least_squares
    from scipy.stats import chi2, f

    from rimless.analysis.inference.release import FIRST_ANGLE_RANGE_RAD, RELEASE_SPEED_BOUNDS_RAD_S, map_frequencies

    n = periods.size
    if n < 3 or not np.all(np.isfinite(periods)):
        return None
    p = sim.on_slope(slope_deg)
    chol = np.linalg.cholesky(period_covariance(impact_sd_s))

    def freqs(offset: float, w: float) -> np.ndarray:
        return map_frequencies(p, sim.model, w, n, offset, sim.rtol)

    def whitened(offset: float, w: float) -> np.ndarray:  # a step not reached: 1 s past the measured period
        fs = freqs(offset, w)
        sim_p = np.where(fs > 0, 1.0 / np.where(fs > 0, fs, 1.0), periods + 1.0)
        return np.linalg.solve(chol, sim_p - periods)

    def cost(offset: float, w: float) -> float:
        r = whitened(offset, w)
        return float(r @ r)

    lo, hi = -FIRST_ANGLE_RANGE_RAD, FIRST_ANGLE_RANGE_RAD
    w_lo, w_hi = RELEASE_SPEED_BOUNDS_RAD_S
    best: tuple[float, float, float] | None = None
    for a0 in (0.0, -0.06):
        if not np.all(freqs(a0, w0) > 0):
            continue  # the start does not walk
        r = least_squares(
            lambda q: whitened(float(q[0]), float(q[1])), [a0, w0], bounds=([lo, w_lo], [hi, w_hi]), method="trf",
            diff_step=[1e-5, 1e-5], x_scale=[0.01, 0.01 * w0], xtol=1e-8, ftol=1e-10, max_nfev=40,
        )  # fmt: skip
        c = cost(float(r.x[0]), float(r.x[1]))
        if best is None or c < best[2]:
            best = (float(r.x[0]), float(r.x[1]), c)
    if best is None:
        return None
    rigid = least_squares(lambda q: whitened(0.0, float(q[0])), [w0], bounds=([0.05], [20.0]), diff_step=[1e-5])
    rss0 = min(cost(0.0, float(rigid.x[0])), cost(0.0, w0))
    rss1, dof = best[2], n - 2
    scale = rss1 / dof
    period_sd = float(np.sqrt(np.mean(np.diag(period_covariance(impact_sd_s)))))
    if scale > 1.0:
        stat, test = (rss0 - rss1) / scale, f"F(1, {dof})"
        p_value = float(f.sf(stat, 1, dof))
        noise = period_sd * math.sqrt(scale)
        source = f"the importer's per-impact sds, scaled by the offset fit's residuals ({dof} degrees of freedom)"
    else:
        stat, test = rss0 - rss1, "chi2(1)"
        p_value = float(chi2.sf(stat, 1))
        noise, source = period_sd, "the importer's per-impact sds (impact_sd_ms)"
    return _first_angle_verdict(
        (best[0], best[1]), w0, float(rigid.x[0]), (rss0, rss1), (float(stat), test, p_value), (noise, source),
        (freqs(best[0], best[1]), freqs(0.0, w0)), weighted=True,
    )  # fmt: skip


def _first_angle_verdict(
    fitted: tuple[float, float],
    w0: float,
    rigid_w: float,
    costs: tuple[float, float],
    tested: tuple[float, str, float],
    noise: tuple[float, str],
    freqs: tuple[np.ndarray, np.ndarray],
    *,
    weighted: bool = False,
) -> FirstAngleTest:
    """The test's result: the offset and speed ``fitted`` (rad, rad/s) kept when the fit's cost is below the rigid
    release's (``costs``: rigid, offset), p (``tested``: statistic, test, p) < `FIRST_ANGLE_P` and the offset not
    zero; else offset 0 and ``w0``. ``freqs``: the step frequencies simulated with the offset and with the rigid
    release (Hz; <= 0 a step not reached), for ``period_change_s``."""
    rss0, rss1 = costs
    stat, test, p_value = tested
    kept = bool(rss1 < rss0 and p_value < FIRST_ANGLE_P and abs(fitted[0]) >= 1e-6)
    f1, f0 = freqs
    both = (f1 > 0) & (f0 > 0)  # the steps both models reach
    change = np.abs(1.0 / np.where(both, f1, 1.0) - 1.0 / np.where(both, f0, 1.0))[1:][both[1:]]
    return FirstAngleTest(
        fitted[0] if kept else 0.0,
        fitted[1] if kept else w0,
        fitted_offset_rad=fitted[0],
        statistic=stat,
        test=test,
        p=p_value,
        level=FIRST_ANGLE_P,
        kept=kept,
        period_change_s=float(np.max(change)) if change.size else math.nan,
        rigid_fit_theta_dot_rad_s=rigid_w,
        fitted_theta_dot_rad_s=fitted[1],
        noise_s=noise[0],
        noise_source=noise[1],
        weighted=weighted,
    )


def _first_bracket(vals: np.ndarray) -> int | None:
    """The first i with vals[i] > 0 >= vals[i + 1] (the period falls through the measured one), or None."""
    for i in range(vals.size - 1):
        a, b = vals[i], vals[i + 1]
        if a > 0 and b <= 0 and not (math.isnan(a) or math.isnan(b)):
            return i
    return None


def _root_in(
    period2: Any, grid: np.ndarray, i: int, b: float, first_period_s: float, vals: np.ndarray
) -> tuple[float | None, str | None]:
    """Brent's root of period2(w) - first_period_s in [grid[i], grid[i + 1]] (b: the value at grid[i + 1])."""
    from scipy.optimize import brentq

    if b == 0:
        return float(grid[i + 1]), None

    def f(w: float) -> float:
        v = period2(w) - first_period_s
        return 1e3 if math.isinf(v) else (v if not math.isnan(v) else 1e3)

    w = brentq(f, grid[i], grid[i + 1], xtol=1e-7)
    if abs(f(w)) < 1e-4:
        return float(w), None
    fin = vals[np.isfinite(vals)]
    return None, (
        f"the measured first period {first_period_s:.3f} s is longer than any the model gives after a "
        f"release one step earlier (at most {first_period_s + float(np.max(fin)):.3f} s)"
    )


def _map_periods(sim: Simulator, slope_deg: float, grid: np.ndarray) -> np.ndarray | None:
    """The second step's period (s) after each release of ``grid`` on the compiled step map
    (`rimless.sim.fast.fast_step`, the simulator's tolerances): inf after a stall, NaN after another failure;
    None where the map does not apply (guide friction, a non-compiled integrator)."""
    from rimless.sim.model.failures import StepFailure

    integ = sim.integrator
    if type(integ).__name__ != "FastIntegrator" or sim.params.guide_friction_n != 0.0:
        return None
    from rimless.sim.fast import fast_step

    p = sim.on_slope(slope_deg)
    out = np.empty(grid.size)
    for j, w in enumerate(grid):
        try:
            r = fast_step(p, sim.model, np.array([-ALPHA_RAD / 2, float(w)]), rtol=integ.rtol, atol=integ.atol)
            out[j] = fast_step(p, sim.model, r.z_next, rtol=integ.rtol, atol=integ.atol).period_s
        except StepFailure as err:
            out[j] = math.inf if err.reason.value == "stall" else math.nan
    return out


def _consecutive_impact_sd(trial: Any) -> np.ndarray | None:
    """The trial's per-impact sds (s) when its periods run between consecutive impacts with none lost; else None."""
    sd = getattr(trial, "impact_sd_s", None)
    ks = np.asarray(getattr(trial, "impact_step", np.zeros(0)), np.int64)
    n = np.asarray(trial.step_period_s).size
    if sd is None or ks.size != n + 1 or not np.all(np.diff(ks) == 1):
        return None
    return np.asarray(sd, float)


def clean_curve(t: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A simulated curve sorted by time with repeated times dropped (the first kept), for interpolation."""
    order = np.argsort(t, kind="stable")
    t, y = t[order], y[order]
    keep = np.concatenate([[True], np.diff(t) > 0]) if t.size else np.zeros(0, bool)
    return t[keep], y[keep]


def compare_trial(trial: Any, sim: Simulator | None = None, *, name: str | None = None) -> TrialComparison:
    """Fit the release speed to the first measured step (and the first impact's angle offset to all of them, see
    the module doc), simulate, and align."""
    sim = sim or Simulator()
    m = trial.meta
    res = TrialComparison(
        name=name or Path(m.source_file).name,
        file=m.source_file,
        slope_deg=float(m.slope_deg),
        slope_source=m.slope_source,
        model=sim.model,
        status="failed",
    )
    periods = np.asarray(trial.step_period_s, float)
    res.measured_period_s = periods
    if periods.size == 0:
        res.message = f"no steps detected ({m.step_refused or 'fewer than two impacts'}): nothing to compare"
        return res
    try:
        sim.on_slope(res.slope_deg)
    except Exception as err:  # ParameterError: slope outside 0 <= phi < alpha/2  # noqa: BLE001
        res.message = f"slope {res.slope_deg:.3f} deg cannot be simulated: {err}"
        return res
    w0, why = fit_release_speed(sim, res.slope_deg, float(periods[0]))
    if w0 is None:
        res.message = f"no initial condition matches: {why}"
        return res
    if sim.fit_first_angle:
        res.first_angle = first_angle_test(sim, res.slope_deg, periods, w0, _consecutive_impact_sd(trial))
        res.first_angle_offset_rad, w0 = res.first_angle.offset_rad, res.first_angle.release_theta_dot_rad_s
        res.first_angle_offset_p = res.first_angle.p
    res.release_theta_dot_rad_s = w0
    # Measured period i is simulated step 1 + (its step count - the first period's): a period lost in a gap
    # keeps the count, so the periods after a gap meet the simulated steps they belong to.
    ends = np.asarray(getattr(trial, "period_step", np.zeros(0)), np.int64)
    offset = ends - ends[0] if ends.size == periods.size else np.arange(periods.size)
    n_sim = int(offset[-1]) + 1
    gait = sim.walk(res.slope_deg, w0, n_sim + 2, record=True, offset_rad=res.first_angle_offset_rad)
    steps = gait.steps
    res.theta_dot_plus_rad_s = float(steps[0].y_plus[7])
    sim_p = np.full(periods.size, np.nan)
    sim_c = np.full(periods.size, np.nan)
    for i, d in enumerate(offset):
        if 1 + d < len(steps):
            sim_p[i] = steps[1 + d].period_s
            sim_c[i] = float(steps[1 + d].phase_durations_s.get("slsp_clutched", 0.0))
    res.sim_period_s = sim_p
    res.sim_clutched_s = sim_c
    res.measured_step = offset + 1
    if len(steps) < n_sim + 1:
        reason = gait.failure.reason.value if gait.failure is not None else "stopped"
        res.warnings.append(f"simulation ended ({reason}) after {max(len(steps) - 1, 0)} of {n_sim} measured steps")

    t0_sim = steps[1].t_start_s if len(steps) > 1 else steps[0].t_start_s + steps[0].period_s
    st, sy = clean_curve(
        np.asarray(gait.table["t_s"], float) - t0_sim, np.asarray(gait.table["com_height_normal_m"], float)
    )
    imp = trial.impact_time_s
    t = trial.time_s - imp[0]
    y = np.asarray(trial.series["com_height"], float)
    valid = ~np.asarray(trial.series["gap"], bool) & ~np.asarray(trial.series["interpolated"], bool) & np.isfinite(y)
    t_last = imp[-1] - imp[0]
    win = valid & (t >= 0) & (t <= t_last) & (t <= st[-1])
    from_plane = m.com_height_reference.startswith("slope plane")
    if win.sum() < 5:
        res.message = "fewer than 5 valid samples between the first and last impact"
        return res

    def fit(shift: float) -> tuple[float, float]:
        s = np.interp(t[win] - shift, st, sy)
        off = 0.0 if from_plane else float(np.mean(s - y[win]))
        return float(np.sqrt(np.mean((y[win] + off - s) ** 2))), off

    shifts = np.round(np.arange(-MAX_SHIFT_S, MAX_SHIFT_S + 1e-12, 5e-4), 9)
    rms = np.array([fit(s)[0] for s in shifts])
    best = float(shifts[int(np.argmin(rms))])
    if abs(best) >= MAX_SHIFT_S - 1e-9:
        res.warnings.append(
            f"best time shift at the limit ({best * 1e3:+.0f} ms): timing mismatch larger than the search"
        )
    res.time_shift_s = best
    res.rms_com_error_m, res.height_offset_m = fit(best)
    res.time_s = t
    res.measured_com_m = np.where(valid, y + res.height_offset_m, np.nan)
    inside = (t - best >= st[0]) & (t - best <= st[-1])
    res.sim_com_m = np.where(inside, np.interp(t - best, st, sy), np.nan)
    res.sim_time_s, res.sim_curve_m = st + best, sy
    res.measured_impact_time_s = imp - imp[0]
    ym = y[win] + res.height_offset_m
    ys = np.interp(t[win] - best, st, sy)
    lo_q, hi_q = np.percentile(ym, [1, 99])
    res.com_amplitude_m = float(hi_q - lo_q)
    if np.std(ys) > 0 and np.std(ym) > 0:
        res.com_correlation = float(np.corrcoef(ym, ys)[0, 1])
    res.status = "ok"
    _plausibility(res)
    return res


@dataclass(frozen=True)
class PeriodMisfit:
    """The simulated periods after the first against the measured ones (`period_misfit`): ``chi2`` on ``dof``
    periods, its tail ``p``, the impact-time noise ``impact_sd_s`` it assumed and where that came from
    (``noise_source``), and the residuals' rms relative to the median measured period."""

    chi2: float
    dof: int
    p: float
    impact_sd_s: float
    noise_source: str
    relative_rms: float


def period_misfit(
    measured_s: np.ndarray, simulated_s: np.ndarray, step: np.ndarray | None = None
) -> PeriodMisfit | None:
    """Chi-square of the period residuals (simulated - measured) of steps 2..N against the periods' noise; None
    with no residual.

    A measured period is the difference of two impact times, so its noise is ``e[k+1] - e[k]`` with ``e`` the
    impacts' independent errors of sd ``s``: variance ``2 s^2``, ``-s^2`` between periods sharing an impact
    (consecutive ``step`` numbers). ``s`` from the recording: the measured periods' second differences (smooth
    along a walk; their noise part ``e[k+3] - 3 e[k+2] + 3 e[k+1] - e[k]`` has variance ``20 s^2``), robustly
    (1.4826 MAD), with four periods or more; never below the importer's floor (`PERIOD_NOISE_FLOOR_S` a period,
    i.e. that / sqrt(2) an impact), which alone is used with fewer."""
    from scipy.stats import chi2

    meas = np.asarray(measured_s, float)
    sim = np.asarray(simulated_s, float)
    k = np.arange(1, meas.size + 1) if step is None or len(step) != meas.size else np.asarray(step, np.int64)
    floor = PERIOD_NOISE_FLOOR_S / math.sqrt(2.0)
    sd, source = floor, f"the importer's floor ({PERIOD_NOISE_FLOOR_S * 1e3:g} ms a period)"
    runs = np.split(np.arange(meas.size), np.flatnonzero(np.diff(k) != 1) + 1)
    d2 = np.concatenate([np.diff(meas[r], 2) for r in runs if r.size >= 3] + [np.zeros(0)])
    d2 = d2[np.isfinite(d2)]
    if meas.size >= 4 and d2.size >= 2:
        est = 1.4826 * float(np.median(np.abs(d2))) / math.sqrt(20.0)
        if est > floor:
            sd, source = est, f"the measured periods' second differences ({d2.size})"
    if sim.size != meas.size or meas.size == 0:
        return None
    use = np.isfinite(sim) & np.isfinite(meas)
    use[0] = False  # the first period fixes the release
    idx = np.flatnonzero(use)
    if idx.size == 0:
        return None
    r = sim[idx] - meas[idx]
    adjacent = np.abs(k[idx][:, None] - k[idx][None, :]) == 1
    cov = sd**2 * (2.0 * np.eye(idx.size) - adjacent)
    stat = float(r @ np.linalg.solve(cov, r))
    rel = float(np.sqrt(np.mean(r**2)) / np.median(meas[np.isfinite(meas)]))
    return PeriodMisfit(stat, int(idx.size), float(chi2.sf(stat, idx.size)), sd, source, rel)


def _plausibility(res: TrialComparison) -> None:
    """Mark a compared trial ``suspect`` (with the reasons in ``warnings``) when a check fails."""
    lim = PLAUSIBILITY
    why = []
    if not res.com_amplitude_m >= lim["min_amplitude_m"]:
        why.append(f"measured CoM height swings by only {res.com_amplitude_m * 1e3:.2f} mm (no steps visible?)")
    if not res.com_correlation >= lim["min_correlation"]:
        why.append(
            f"measured and simulated CoM heights correlate poorly (r = {res.com_correlation:.2f} < "
            f"{lim['min_correlation']})"
        )
    if not res.rms_com_relative <= lim["max_relative_rms"]:
        why.append(
            f"RMS CoM error is {res.rms_com_relative:.0%} of the measured amplitude (> {lim['max_relative_rms']:.0%})"
        )
    pm = res.period_fit()
    if pm is not None and pm.p < lim["period_p"] and pm.relative_rms > lim["max_relative_period_rms"]:
        why.append(
            f"the simulated step periods after the first miss the measured ones by {pm.relative_rms:.0%} of a period "
            f"(rms; > {lim['max_relative_period_rms']:.0%}), beyond their noise (chi2 {pm.chi2:.3g} on {pm.dof}, "
            f"p = {pm.p:.2g} < {lim['period_p']:g}; impact noise {pm.impact_sd_s * 1e3:.2f} ms from {pm.noise_source})"
        )
    if any(w.startswith("best time shift at the limit") or w.startswith("simulation ended") for w in res.warnings):
        why.append("the simulation does not follow the whole trial (see above)")
    if why:
        res.status = "suspect"
        res.message = "suspect: " + "; ".join(why)


@dataclass
class SlopeGroup:
    """Step period against step number for the trials of one slope bin, with the simulation."""

    slope_deg: float  # bin centre
    trials: list[str]
    step_number: np.ndarray  # 1..N
    mean_period_s: np.ndarray
    std_period_s: np.ndarray  # sample std (ddof=1); NaN with one trial
    count: np.ndarray
    sim_period_s: np.ndarray  # mean over the bin's trials of each one simulated at its own slope and release
    release_theta_dot_rad_s: float
    message: str | None = None
    #: the lowest and highest slope of the bin's trials, deg (NaN: not set)
    slope_range_deg: tuple[float, float] = (math.nan, math.nan)
    #: how the bin is named in figures and tables (`slope_label`); "" names it by ``slope_deg``
    label: str = ""

    @property
    def slope_label(self) -> str:
        """The bin's name, deg: ``label`` when set (e.g. the range of its trials' slopes), else ``slope_deg``."""
        return self.label or f"{self.slope_deg:g}"

    def rows(self) -> list[dict[str, Any]]:
        """Flat rows (edge units) for tables and JSON."""
        return [
            {
                "slope_deg": self.slope_deg,
                "slope_bin_label_deg": self.slope_label,
                "slope_min_deg": self.slope_range_deg[0],
                "slope_max_deg": self.slope_range_deg[1],
                "step": int(k),
                "trials": int(c),
                "mean_period_ms": mu * 1e3,
                "std_period_ms": sd * 1e3,
                "sim_period_ms": sp * 1e3,
            }
            for k, c, mu, sd, sp in zip(
                self.step_number, self.count, self.mean_period_s, self.std_period_s, self.sim_period_s
            )
        ]


def step_period_trends(
    comparisons: Sequence[TrialComparison], sim: Simulator | None = None, *, slope_bin_deg: float = 0.5
) -> list[SlopeGroup]:
    """Group trials with steps by slope (rounded to ``slope_bin_deg``): mean +- std period per step, and the model."""
    sim = sim or Simulator()
    bins: dict[float, list[TrialComparison]] = {}
    for c in comparisons:
        if c.n_steps and math.isfinite(c.slope_deg):
            key = round(round(c.slope_deg / slope_bin_deg) * slope_bin_deg, 6)
            bins.setdefault(key, []).append(c)
    groups = []
    for key in sorted(bins):
        cs = bins[key]
        numbers = [c.measured_step if c.measured_step.size == c.n_steps else np.arange(1, c.n_steps + 1) for c in cs]
        n = max(int(k[-1]) for k in numbers)
        mat = np.full((len(cs), n), np.nan)
        for i, c in enumerate(cs):
            mat[i, numbers[i] - 1] = c.measured_period_s
        count = np.isfinite(mat).sum(axis=0)
        mean = np.nanmean(mat, axis=0)
        std = np.array([np.std(col[np.isfinite(col)], ddof=1) if k > 1 else np.nan for col, k in zip(mat.T, count)])
        simmat = np.full((len(cs), n), np.nan)
        msgs = []
        for i, c in enumerate(cs):  # each trial simulated at its own slope from its own fitted release
            if c.sim_period_s.size:
                simmat[i, numbers[i] - 1] = c.sim_period_s
            elif math.isfinite(c.release_theta_dot_rad_s):
                try:
                    g = sim.walk(c.slope_deg, c.release_theta_dot_rad_s, c.n_steps + 1, record=False)
                    got = [s.period_s for s in g.steps[1 : 1 + c.n_steps]]
                    simmat[i, : len(got)] = got
                except Exception as err:  # noqa: BLE001 - a slope the model cannot take
                    msgs.append(f"{c.name}: simulation failed: {err}")
        ws = [c.release_theta_dot_rad_s for c in cs if math.isfinite(c.release_theta_dot_rad_s)]
        w = float(np.mean(ws)) if ws else float("nan")
        have = np.isfinite(simmat).any(axis=0)
        simp = np.full(n, np.nan)
        simp[have] = np.nanmean(simmat[:, have], axis=0)
        msg = "; ".join(msgs) or (None if ws else "no trial in this group has a fitted release speed: no simulation")
        slopes = [c.slope_deg for c in cs]
        group = SlopeGroup(key, [c.name for c in cs], np.arange(1, n + 1), mean, std, count, simp, w, msg)
        group.slope_range_deg = (min(slopes), max(slopes))
        groups.append(group)
    return groups
