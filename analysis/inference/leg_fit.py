"""Fit a leg's stiffness k, damping c and Coulomb guide friction F_c to the free motion recorded by
`rimless robot leg-test` (the wheel held up, the leg hanging free, released at rest by its clutch).

The model: m x'' + c x' + k (x - x_eq) + F_c sign(x') = 0 with stiction, x the compression in sensor counts.
Gravity only shifts the equilibrium x_eq (by m g / k), which is fitted anyway, since the sensor's zero is
arbitrary. Its free response from rest is piecewise: each half cycle is the damped oscillation about the
shifted centre x_eq + a sign(x_start - x_eq), a = F_c / k, and ends at rest after pi / omega_d; the leg sticks
when it comes to rest within the friction band |x - x_eq| <= a (`free_response`, closed form, underdamped).

Unknowns: omega_n, zeta and the friction displacement a (shared by every log, a in metres: `a * counts_per_m`
counts in each log), and per log the locked position x_lock, x_eq, the instant t_r the clutch let go (its
release delay is unknown) and a linear drift of the count (the flow sensor integrates its errors). Least
squares on the displacement over the released segment (from `PRE_RELEASE_S` before the release command to
`SETTLED_S` after the motion ends), without the reads the process was descheduled in (`read_us` above
`SLOW_READ_US`: their instant is uncertain) and, after a first fit, without samples beyond `OUTLIER_SIGMAS`
robust sigmas (at most `OUTLIER_MAX_SHARE` of them; both counted in the report). Several releases of one leg at
different compressions fit together: each sees about two half cycles of a leg damped like the paper's (zeta
0.4), and their different amplitudes separate the friction (a loss per half cycle that does not scale with
amplitude) from the damping.

Then k = m omega_n^2, c = 2 m zeta omega_n, F_c = k a, m the leg's moving mass (an input:
`DEFAULT_MOVING_MASS_KG`, the leg mass of Table 1, which the wheel model puts entirely at the foot). k and c
come from the frequency and the decay, so they do not depend on the sensor's counts per metre; F_c does
(through a), and scales with it.

Uncertainties: the largest of three covariances, propagated to k, c and F_c (with the moving mass's own
uncertainty, when given): the Jacobian's with the residual variance, inflated for correlated residuals by their
long-run variance ratio (Bartlett weights over `LONG_RUN_LAGS` lags); a sandwich over blocks of
`SANDWICH_BLOCK` consecutive samples; and a noise model's sandwich A J' S J A, S white with each sample's own
variance (a read's timing error grows with the speed) plus the count's random-walk drift, whose rate is
measured where the leg is still (held before the release, stuck after the motion: `_count_drift`). The drift is
what the first two miss: a slow wander of the count, too small to see in the residuals of one release, moves the
fitted friction and decay.

The segmentation is chosen by the data: the half cycles each log makes before it sticks follow from the friction
band, and a motion that nearly sticks makes a last half cycle of a fraction of a count, so each log is also
fitted stuck one half cycle earlier (`max_half_cycles`); every segmentation within `SEGMENTATION_CHI2` of the
best (in units of the residual variance, inflated for correlated residuals) is plausible, and the intervals
span the intervals of every plausible one. Friction is claimed only when the frictionless model (a = 0) is
worse by more than the BIC's log(n) (and `SEGMENTATION_CHI2`); else its interval spans the frictionless fit
too and the summary gives an upper bound. A log with fewer than `MIN_SAMPLES_PER_HALF_CYCLE` reads in a half
cycle of the fitted motion, or an interval of k or c reaching zero, is refused (`RunFailure`), never a number.

The intervals' coverage is measured by simulation against an independent truth model (`rimless trials
leg-fit-coverage`, `leg_fit_coverage`); docs/trials.md gives the figures.

One concept: the leg-test fit (log, model, fit, uncertainty, figure).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from rimless.errors import InputFileError, ParameterError, RunFailure

__all__ = [
    "FORMAT",
    "DEFAULT_MOVING_MASS_KG",
    "LegLog",
    "LegFitResult",
    "read_leg_log",
    "free_response",
    "fit_leg",
    "run_leg_fit",
    "fake_truth",
    "plot_leg_fit",
    "Z95",
    "GOALS",
    "goal_check",
]

FORMAT = "rimless-leg-test/1"  # the first line of a leg-test log (firmware/service/leg_test.py writes it)
DEFAULT_MOVING_MASS_KG = 0.0378  # Table 1's leg mass, all of it moving with the foot in the wheel model
PRE_RELEASE_S = 0.02  # the fit starts this long before the release command (the leg still held)
SETTLED_S = 0.05  # and ends this long after the motion has ended (or at the log's end)
MOVE_COUNTS = 3.0  # a departure of this many counts from the held position is motion
MIN_FREE_SAMPLES = 20
SLOW_READ_US = 500.0  # a read that took longer (and SLOW_READ_FACTOR x the median) is left out
SLOW_READ_FACTOR = 3.0
SANDWICH_BLOCK = 30  # samples per block of the sandwich covariance
DRIFT_BLOCK_S = 0.04  # block of the count-drift estimate (s): its second differences of block means
HELD_SETTLE_S = 0.02  # the held part the drift is measured on starts this long after the engage
LONG_RUN_LAGS = 30  # lags of the residuals' long-run variance
OUTLIER_MAX_SHARE = 0.01  # at most this share of the samples are left out as outliers
DRIFT_MAX_COUNTS_PER_S = 100.0  # bound of the fitted count drift (a sensor drifting more is broken)
OUTLIER_SIGMAS = 8.0  # after a first fit, samples beyond this many robust sigmas (MAD) are left out, once
Z95 = 1.959963984540054
MAX_NFEV = 400
N_SHARED, N_PER_LOG = 3, 4  # omega_n, zeta, a; per log x_lock, x_eq, t_r, drift
A_STARTS = (0.0, 0.3, 1.0)  # starts of the friction displacement, times `_a_guess_um`
NO_FRICTION_UM = 1e-9  # the frictionless model: a bounded to this (um)
SEGMENTATION_CHI2 = 3.84  # a segmentation this close to the best (delta chi2) is plausible: chi2(1) at 95 %
MIN_SAMPLES_PER_HALF_CYCLE = 12  # fewer reads in a half cycle of the leg do not resolve it (refused)
ZETA_MAX = 0.95  # the model is the underdamped response; a fit at this bound is not an oscillation
ONE_RELEASE_NOTE = (
    "one release: friction and damping are told apart only by the few half cycles of one motion; its intervals "
    "span every segmentation the data allow; releases at several compressions reach the precision goal reliably "
    "(one release reached it in about a third of simulated tests)"
)
GOALS = {"k_n_per_m": 0.02, "c_n_s_per_m": 0.02, "guide_friction_n": 0.10}  # precision goal: 95 % half width/value


def goal_check(values: dict[str, float], half_widths: dict[str, float], releases: int) -> dict[str, Any]:
    """Whether a fit of `releases` logs reaches `GOALS` (95 % half width over the value, per parameter), and
    about how many releases like these would (a half width falls as 1 / sqrt(releases)). A value whose interval
    reaches zero has no relative precision: its entry has `rel_half_width` None, `met` None and `upper_95`."""
    out: dict[str, Any] = {"releases": releases, "per_parameter": {}}
    need: int | None = releases
    for key, goal in GOALS.items():
        if values[key] - half_widths[key] <= 0:  # consistent with zero: no relative precision, an upper bound
            out["per_parameter"][key] = {
                "rel_half_width": None,
                "goal": goal,
                "met": None,
                "releases_needed": None,
                "upper_95": max(values[key] + half_widths[key], 0.0),
                "consistent_with_zero": True,
            }
            continue
        rel = half_widths[key] / abs(values[key])
        ok = rel <= goal
        n = releases if ok else (math.ceil(releases * (rel / goal) ** 2) if math.isfinite(rel) else None)
        out["per_parameter"][key] = {"rel_half_width": rel, "goal": goal, "met": ok, "releases_needed": n}
        need = None if need is None or n is None else max(need, n)
    out["met"] = all(p["met"] for p in out["per_parameter"].values() if p["met"] is not None)
    out["releases_needed"] = need
    return out


@dataclass
class LegLog:
    """One leg-test log: sample times (s, from the run's start), cumulative counts, the clutch events."""

    path: Path
    leg: int
    counts_per_m: float
    t_s: np.ndarray
    counts: np.ndarray
    release_t_s: float
    engage_t_s: float | None
    header: dict[str, Any]
    outcome: str = "ok"
    read_us: np.ndarray = field(default_factory=lambda: np.zeros(0))  # each read's duration (NaN: not logged)

    @property
    def truth(self) -> dict[str, Any] | None:
        """The simulated leg's parameters, for a log of `leg-test --fake`."""
        return self.header.get("fake_leg")


def _num(value: Any, where: str, name: str, *, positive: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise InputFileError(f"{where}: field {name!r} must be a finite number, got {value!r}")
    if positive and value <= 0:
        raise InputFileError(f"{where}: field {name!r} must be > 0, got {value!r}")
    return float(value)


def read_leg_log(path: Path | str, counts_per_m: float | None = None) -> LegLog:
    """Read and check a leg-test log; `InputFileError` names the file, the line and the field of the first
    problem. `counts_per_m` overrides the header's scale (a calibration made after the test)."""
    p = Path(path)
    if not p.is_file():
        raise InputFileError(f"{p}: no such file")
    try:
        text = p.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as err:
        raise InputFileError(f"{p}: cannot read ({err})") from None
    lines = text.splitlines()
    if not lines or not lines[0].strip():
        raise InputFileError(f'{p}: empty, expected a leg-test log (first line {{"format": "{FORMAT}", ...}})')
    t: list[float] = []
    c: list[float] = []
    read_us: list[float] = []
    header: dict[str, Any] = {}
    release = engage = None
    outcome = None
    for n, line in enumerate(lines, 1):
        where = f"{p}:{n}"
        if not line.strip():
            continue
        try:
            obj = json.loads(line)
        except json.JSONDecodeError as err:
            torn = n == len(lines) and not text.endswith("\n")
            raise InputFileError(
                f"{where}: not JSON ({err.msg}, column {err.colno})"
                + ("; the last line is torn (the test did not finish writing)" if torn else "")
            ) from None
        if not isinstance(obj, dict):
            raise InputFileError(f"{where}: expected a JSON object, got {type(obj).__name__}")
        if n == 1:
            if obj.get("format") != FORMAT:
                raise InputFileError(
                    f"{where}: field 'format' must be {FORMAT!r}, got {obj.get('format')!r} "
                    "(not a log of `rimless robot leg-test`)"
                )
            header = obj
            for name in ("leg", "counts_per_m"):
                if name not in obj:
                    raise InputFileError(f"{where}: field {name!r} is missing")
            if isinstance(obj["leg"], bool) or not isinstance(obj["leg"], int) or obj["leg"] < 0:
                raise InputFileError(
                    f"{where}: field 'leg' must be a clutch index (an integer >= 0), got {obj['leg']!r}"
                )
            _num(obj["counts_per_m"], where, "counts_per_m", positive=True)
            continue
        if "event" in obj:
            ev = obj["event"]
            if ev in ("engage", "release", "fault"):
                ts = _num(obj.get("t_s"), where, "t_s")
                if ev == "release":
                    release = ts
                elif ev == "engage":
                    engage = ts
            if ev == "end":
                outcome = str(obj.get("outcome", "ok"))
            continue
        if "t_s" not in obj or "counts" not in obj:
            missing = "t_s" if "t_s" not in obj else "counts"
            raise InputFileError(f"{where}: field {missing!r} is missing (a sample has t_s and counts)")
        ts = _num(obj["t_s"], where, "t_s")
        cv = obj["counts"]
        if isinstance(cv, bool) or not isinstance(cv, int):
            raise InputFileError(f"{where}: field 'counts' must be an integer (sensor counts), got {cv!r}")
        if t and ts <= t[-1]:
            raise InputFileError(f"{where}: field 't_s' {ts!r} does not increase (previous sample at {t[-1]!r})")
        ru = obj.get("read_us", math.nan)
        if ru is not None and not math.isnan(ru if isinstance(ru, float) else 0.0):
            ru = _num(ru, where, "read_us")
        t.append(ts)
        c.append(float(cv))
        read_us.append(math.nan if ru is None else float(ru))
    if release is None:
        why = f" (the test ended with {outcome!r})" if outcome not in (None, "ok") else ""
        raise InputFileError(f"{p}: no 'release' event: the clutch never let the leg go{why}, nothing to fit")
    tt = np.asarray(t)
    n_free = int(np.sum(tt >= release))
    if n_free < MIN_FREE_SAMPLES:
        raise InputFileError(f"{p}: {n_free} samples after the release (at least {MIN_FREE_SAMPLES} needed)")
    cpm = float(counts_per_m) if counts_per_m is not None else float(header["counts_per_m"])
    return LegLog(
        p,
        int(header["leg"]),
        cpm,
        tt,
        np.asarray(c),
        float(release),
        engage,
        header,
        outcome or "ok",
        np.asarray(read_us),
    )


def free_response(
    t: np.ndarray,
    omega_n: float,
    zeta: float,
    a: float,
    x_eq: float,
    x_lock: float,
    t_r: float,
    max_half_cycles: int | None = None,
) -> np.ndarray:
    """The displacement at times `t` (s) of a spring-damper-Coulomb oscillator held at `x_lock` until `t_r`,
    then released at rest: half cycles about x_eq +/- a, sticking within |x - x_eq| <= a (or, given
    `max_half_cycles`, at the end of that half cycle at the latest: a stick event the data choose). Displacements
    in any one unit (counts here); omega_n in rad/s; 0 <= zeta < 1."""
    t = np.asarray(t, float)
    in_order = t.size < 2 or bool(np.all(t[1:] >= t[:-1]))
    order = None if in_order else np.argsort(t, kind="stable")
    ts_sorted = t if order is None else t[order]
    x = np.full(t.shape, float(x_lock))
    wd = omega_n * math.sqrt(max(1.0 - zeta * zeta, 1e-12))
    half = math.pi / wd
    sigma = zeta * omega_n
    r = math.exp(-sigma * half)
    ratio = sigma / wd
    xs, ts = float(x_lock), float(t_r)
    scale = max(abs(x_lock - x_eq), 1e-12)
    t_last = float(ts_sorted[-1]) if t.size else -math.inf
    for n_half in range(10000):
        d = xs - x_eq
        if max_half_cycles is not None and n_half >= max_half_cycles:
            break
        if abs(d) <= a or abs(d) < 1e-9 * scale or ts > t_last:  # stuck, or no sample left to see the motion
            break
        e = x_eq + math.copysign(a, d)
        # the samples of this half cycle, ts <= t < ts + half: a slice of the time-ordered samples
        lo, hi = np.searchsorted(ts_sorted, (ts, ts + half), side="left")
        tau = ts_sorted[lo:hi] - ts
        x[lo:hi] = e + (xs - e) * np.exp(-sigma * tau) * (np.cos(wd * tau) + ratio * np.sin(wd * tau))
        xs = e - (xs - e) * r
        ts += half
    x[np.searchsorted(ts_sorted, ts, side="left") :] = xs
    if order is not None:
        out = np.empty_like(x)
        out[order] = x
        return out
    return x


@dataclass
class _Segment:
    log: LegLog
    t: np.ndarray  # s from the release command
    y: np.ndarray  # counts
    x_lock0: float
    x_eq0: float
    t_r0: float
    slow_reads: int = 0  # reads left out: the process was descheduled in them (their instant is uncertain)
    still: list[tuple[np.ndarray, np.ndarray]] = field(default_factory=list)  # (t, counts) where the leg is still
    outliers: int = 0  # samples left out by the outlier test after the first fit


def _segment(log: LegLog) -> _Segment:
    t = log.t_s - log.release_t_s
    held = (t >= -PRE_RELEASE_S) & (t < 0)
    x_lock = float(np.median(log.counts[held])) if held.any() else float(log.counts[np.searchsorted(t, 0.0)])
    after = t >= 0
    moved = after & (np.abs(log.counts - x_lock) > MOVE_COUNTS)
    if not moved.any():
        raise RunFailure(
            f"{log.path}: the leg did not move after the release (held position kept within "
            f"{MOVE_COUNTS:g} counts): the clutch did not let go, or the leg is jammed"
        )
    t_move = float(t[np.argmax(moved)])
    tail = log.counts[after][-max(5, int(after.sum()) // 5) :]
    x_end = float(np.median(tail))
    moving = after & (np.abs(log.counts - x_end) > MOVE_COUNTS)
    t_last = float(t[moving][-1]) if moving.any() else t_move
    keep = (t >= -PRE_RELEASE_S) & (t <= t_last + SETTLED_S)
    slow = np.zeros_like(keep)
    ru = log.read_us
    if ru.size == t.size and np.isfinite(ru).any():
        limit = max(SLOW_READ_US, SLOW_READ_FACTOR * float(np.nanmedian(ru)))
        slow = np.isfinite(ru) & (ru > limit)
    seg = _Segment(log, t[keep & ~slow], log.counts[keep & ~slow], x_lock, x_end, max(t_move - 1e-3, 0.0))
    seg.slow_reads = int(np.sum(keep & slow))
    held_from = (log.engage_t_s - log.release_t_s + HELD_SETTLE_S) if log.engage_t_s is not None else -PRE_RELEASE_S
    for part in ((t >= held_from) & (t < 0), t >= t_last + SETTLED_S):  # held by the clutch; stuck after the motion
        seg.still.append((t[part & ~slow], log.counts[part & ~slow]))
    return seg


@dataclass
class Estimate:
    """A fitted quantity with its standard error and 95 % interval (its unit in `unit`)."""

    value: float
    se: float
    unit: str

    @property
    def ci95(self) -> tuple[float, float]:
        return (self.value - Z95 * self.se, self.value + Z95 * self.se)


@dataclass
class LegFitResult:
    """The fit of one leg (from one or more logs)."""

    leg: int
    files: list[str]
    moving_mass_kg: float
    moving_mass_sd_kg: float
    k: Estimate
    c: Estimate
    friction: Estimate
    natural_frequency_hz: Estimate
    damping_ratio: Estimate
    friction_displacement_m: Estimate
    per_log: list[dict[str, Any]]
    residual_rms_counts: float
    autocorrelation: float
    converged: bool
    optimizer: dict[str, Any]
    segments: list[_Segment] = field(default_factory=list, repr=False)
    params: np.ndarray = field(default_factory=lambda: np.zeros(0), repr=False)
    truth: list[dict[str, Any] | None] = field(default_factory=list)
    count_drift_counts_per_sqrt_s: float = 0.0  # the count's random-walk rate measured where the leg is still
    count_drift_differences: int = 0  # the block-mean second differences it rests on
    standard_errors: dict[str, float] = field(default_factory=dict)  # each of the three, before the mass's
    segmentation: dict[str, Any] = field(default_factory=dict)  # the half cycles chosen, the candidates
    friction_test: dict[str, Any] = field(default_factory=dict)  # friction against the frictionless model
    stick_caps: list[int | None] = field(default_factory=list)  # each log's stick event at the latest (None: band)

    @property
    def friction_resolved(self) -> bool:
        """Whether the data support friction over the frictionless model and its interval excludes zero."""
        return bool(self.friction_test.get("resolved", True)) and self.friction.ci95[0] > 0

    def checks(self) -> dict[str, Any]:
        """The checks a fit must pass to be used as a prior (`rimless trials calibrate --prior`): each with
        `passed` and what it found; `passed` overall."""
        sph = min(p.get("samples_per_half_cycle", math.inf) for p in self.per_log)
        out: dict[str, Any] = {
            "converged": {"passed": self.converged, "found": self.optimizer.get("message", "")},
            "resolution": {
                "passed": sph >= MIN_SAMPLES_PER_HALF_CYCLE,
                "found": f"{sph:.1f} samples per half cycle (at least {MIN_SAMPLES_PER_HALF_CYCLE})",
            },
            "intervals_positive": {
                "passed": self.k.ci95[0] > 0 and self.c.ci95[0] > 0,
                "found": f"k from {self.k.ci95[0]:.4g} N/m, c from {self.c.ci95[0]:.4g} N s/m",
            },
        }
        out["passed"] = all(v["passed"] for v in out.values())
        return out

    def parameters(self) -> list[dict[str, Any]]:
        """The JSON list ``parameters``: what the fit held, as the other commands list a wheel's parameters (name,
        symbol, value, sd, unit, source, basis, carried_as): the moving mass (k and c scale with it) and each log's
        sensor scale (the friction scales with it)."""
        m, sm = self.moving_mass_kg, self.moving_mass_sd_kg
        table1 = m == DEFAULT_MOVING_MASS_KG
        rows: list[dict[str, Any]] = [
            {
                "name": "leg_mass_kg",
                "symbol": "m",
                "value": m,
                "sd": sm,
                "unit": "kg",
                "source": "table1" if table1 else "given",
                "basis": ("Table 1's leg mass, all of it moving with the foot" if table1 else "--moving-mass-kg")
                + ("" if sm > 0 else "; held exact: its uncertainty is not in the intervals (--moving-mass-sd-kg)"),
                "carried_as": "normal" if sm > 0 else "exact",
            }
        ]
        for log in {id(s.log): s.log for s in self.segments}.values():
            header = log.header.get("counts_per_m")
            rows.append(
                {
                    "name": "counts_per_m",
                    "symbol": "counts/m",
                    "value": log.counts_per_m,
                    "sd": 0.0,
                    "unit": "1/m",
                    "source": "log" if header == log.counts_per_m else "given",
                    "basis": f"{log.path.name}: the sensor's scale "
                    + ("(its header)" if header == log.counts_per_m else "(--counts-per-m)")
                    + "; only the friction depends on it",
                    "carried_as": "exact",
                }
            )
        return rows

    def to_dict(self) -> dict[str, Any]:
        """The JSON object of ``rimless trials leg-fit --json``: `summary()`, with ``fake_truth`` (the simulated
        leg's parameters) for logs of ``leg-test --fake``."""
        out = self.summary()
        truth = fake_truth(self)
        if truth is not None:
            out["fake_truth"] = truth
        return out

    def summary(self) -> dict[str, Any]:
        """The JSON of `rimless trials leg-fit --json` without ``fake_truth`` (`to_dict`) (`k_n_per_m`, `c_n_s_per_m`, `guide_friction_n`, each
        with `_ci`, the 95 % interval)."""
        out: dict[str, Any] = {"leg": self.leg, "files": self.files}
        for key, est in (
            ("k_n_per_m", self.k),
            ("c_n_s_per_m", self.c),
            ("guide_friction_n", self.friction),
            ("natural_frequency_hz", self.natural_frequency_hz),
            ("damping_ratio", self.damping_ratio),
            ("friction_displacement_m", self.friction_displacement_m),
        ):
            out[key] = est.value
            out[key + "_se"] = est.se
            out[key + "_ci"] = list(est.ci95)
        out.update(
            {
                "moving_mass_kg": self.moving_mass_kg,
                "moving_mass_sd_kg": self.moving_mass_sd_kg,
                "scale_dependence": "k and c come from the natural frequency and the decay and do not depend on the "
                "sensor's counts per metre; guide_friction_n does (it scales with the counts per "
                "metre of each log); k and c scale with the moving mass",
                "intervals": "95 %: the largest of three covariances: least squares (inflated for correlated residuals), "
                "a block sandwich, and a noise model (each sample's own variance plus the count's random-walk "
                "drift measured where the leg is still)"
                + ", spanning every plausible segmentation (and the frictionless model when friction is not "
                "resolved)"
                + (
                    ", with the moving mass's uncertainty"
                    if self.moving_mass_sd_kg > 0
                    else ", without the moving mass's uncertainty (give --moving-mass-sd-kg)"
                ),
                "residual_rms_counts": self.residual_rms_counts,
                "residual_lag1_autocorrelation": self.autocorrelation,
                "count_drift_counts_per_sqrt_s": self.count_drift_counts_per_sqrt_s,
                "count_drift_differences": self.count_drift_differences,
                "standard_errors": self.standard_errors,
                "per_log": self.per_log,
                "converged": self.converged,
                "optimizer": self.optimizer,
            }
        )
        out["parameters"] = self.parameters()
        out["goal"] = goal_check({k: out[k] for k in GOALS}, {k: Z95 * out[k + "_se"] for k in GOALS}, len(self.files))
        out["friction_resolved"] = self.friction_resolved
        if not self.friction_resolved:  # an upper bound, never a relative precision of about zero
            out["guide_friction_n_upper_95"] = max(self.friction.ci95[1], 0.0)
        out["friction_test"] = self.friction_test
        out["segmentation"] = self.segmentation
        out["checks"] = self.checks()
        if len(self.files) == 1:
            out["one_release"] = ONE_RELEASE_NOTE
        return out


def fit_leg(
    logs: list[LegLog], *, moving_mass_kg: float = DEFAULT_MOVING_MASS_KG, moving_mass_sd_kg: float = 0.0
) -> LegFitResult:
    """Fit one leg's k, c and F_c to the released segments of `logs` (one leg; see the module doc).

    Raises `ParameterError` for a bad mass or logs of different legs, `RunFailure` when the motion is no
    oscillation the model can fit (no release motion, overdamped, stuck in the first half cycle).

    The BLAS runs on one thread meanwhile: the least squares take the SVD of a tall Jacobian (~1500 x 15) every
    iteration, which a multi-threaded OpenBLAS ran some 100x slower on a busy 2-core machine (0.46 s a call)."""
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # pragma: no cover - a dependency of the pc install
        return _fit_leg(logs, moving_mass_kg, moving_mass_sd_kg)
    with threadpool_limits(limits=1, user_api="blas"):
        return _fit_leg(logs, moving_mass_kg, moving_mass_sd_kg)


def _fit_leg(logs: list[LegLog], moving_mass_kg: float, moving_mass_sd_kg: float) -> LegFitResult:
    from scipy.optimize import least_squares

    if not logs:
        raise ParameterError("no log to fit")
    if not (math.isfinite(moving_mass_kg) and moving_mass_kg > 0):
        raise ParameterError(f"--moving-mass-kg must be > 0, got {moving_mass_kg!r}")
    if not (math.isfinite(moving_mass_sd_kg) and moving_mass_sd_kg >= 0):
        raise ParameterError(f"--moving-mass-sd-kg must be >= 0, got {moving_mass_sd_kg!r}")
    legs = {lg.leg for lg in logs}
    if len(legs) > 1:
        other = next(lg for lg in logs if lg.leg != logs[0].leg)
        raise ParameterError(
            f"{other.path}: leg {other.leg}, but {logs[0].path} is leg {logs[0].leg}: fit one leg at a time"
        )
    segs = [_segment(lg) for lg in logs]
    n_l = len(segs)
    cpms = np.array([s.log.counts_per_m for s in segs])

    # u = [omega_n (rad/s), zeta, a (um), then per log: x_lock (counts), x_eq (counts), t_r (ms), drift (counts/s)]
    def unpack(u: np.ndarray) -> tuple[float, float, float, np.ndarray]:
        return float(u[0]), float(u[1]), float(u[2]), u[N_SHARED:].reshape(n_l, N_PER_LOG)

    caps: list[int | None] = [None] * n_l  # each log's stick event at the latest (None: where the band says)

    def one(u: np.ndarray, i: int) -> np.ndarray:
        w, z, a_um, per = unpack(u)
        s, (xl, xe, tr, dr) = segs[i], per[i]
        return free_response(s.t, w, z, a_um * 1e-6 * cpms[i], xe, xl, tr * 1e-3, caps[i]) + dr * s.t - s.y

    def resid(u: np.ndarray) -> np.ndarray:
        return np.concatenate([one(u, i) for i in range(n_l)])

    offs = np.concatenate([[0], np.cumsum([s.t.size for s in segs])])
    typical = np.concatenate([[1.0, 1e-3, 0.1], np.tile([0.1, 0.1, 1e-3, 0.1], n_l)])

    def jac(u: np.ndarray) -> np.ndarray:
        """Forward differences: a shared parameter moves every log, a log's own parameters only its rows."""
        r0 = [one(u, i) for i in range(n_l)]
        J = np.zeros((int(offs[-1]), u.size))
        for j in range(u.size):
            h = 1e-6 * max(abs(u[j]), typical[j])
            u2 = u.copy()
            u2[j] += h
            rows = range(n_l) if j < N_SHARED else [(j - N_SHARED) // N_PER_LOG]
            for i in rows:
                J[offs[i] : offs[i + 1], j] = (one(u2, i) - r0[i]) / h
        return J

    u0 = _start(segs, cpms, one)
    lo = np.concatenate(
        [[2 * math.pi * 1.0, 0.0, 0.0], np.tile([-np.inf, -np.inf, -PRE_RELEASE_S * 1e3, -DRIFT_MAX_COUNTS_PER_S], n_l)]
    )
    hi = np.concatenate(
        [[2 * math.pi * 2000.0, ZETA_MAX, np.inf], np.tile([np.inf, np.inf, np.inf, DRIFT_MAX_COUNTS_PER_S], n_l)]
    )

    def solve(u_start: np.ndarray, hi_a: float = np.inf) -> Any:
        h = hi.copy()
        h[2] = hi_a
        return least_squares(
            resid,
            np.clip(u_start, lo, h),
            jac=jac,
            bounds=(lo, h),
            method="trf",
            x_scale="jac",
            xtol=1e-10,
            ftol=1e-12,
            max_nfev=MAX_NFEV,
        )

    def segmentation(u: np.ndarray) -> tuple[int, ...]:
        w, z, a_um, per = unpack(u)
        return tuple(_half_cycles(w, z, a_um * 1e-6 * cpms[i], per[i][1], per[i][0], caps[i]) for i in range(n_l))

    runs = []
    for a_start in A_STARTS:  # a few starts in the friction (the cost is not convex in it)
        u = u0.copy()
        u[2] = a_start * _a_guess_um(segs, cpms)
        runs.append(solve(u))
    no_friction = solve(u0, NO_FRICTION_UM)  # the simpler, nested model
    best = min(runs, key=lambda res: res.cost)
    r = resid(best.x)
    sig = 1.4826 * float(np.median(np.abs(r - np.median(r))))
    bad = np.abs(r) > OUTLIER_SIGMAS * max(sig, 1.0)
    # a read whose count or instant is wrong (a glitch): leave it out once, and fit again; more than
    # OUTLIER_MAX_SHARE of them is a misfit of the model or of the start, not glitches
    if bad.any() and bad.mean() <= OUTLIER_MAX_SHARE:
        for i, sg in enumerate(segs):
            drop = bad[offs[i] : offs[i + 1]]
            sg.outliers = int(drop.sum())
            sg.t, sg.y = sg.t[~drop], sg.y[~drop]
        offs = np.concatenate([[0], np.cumsum([sg.t.size for sg in segs])])
        nfev = sum(int(res.nfev) for res in runs)
        best = solve(best.x)
        no_friction = solve(no_friction.x, NO_FRICTION_UM)
        best.nfev += nfev
    # the segmentation (half cycles before each log's stick event): the band's, and each log stuck one half
    # cycle earlier (the last half cycle of a motion that nearly sticks is a few counts: the data choose)
    free_seg = segmentation(best.x)
    by_seg: dict[tuple[int, ...], tuple[Any, list[int | None]]] = {free_seg: (best, [None] * n_l)}
    for i in range(n_l):
        if free_seg[i] < 2:
            continue
        caps[:] = [None] * n_l
        caps[i] = free_seg[i] - 1
        res = solve(best.x)
        key = segmentation(res.x)
        if key not in by_seg or res.cost < by_seg[key][0].cost:
            by_seg[key] = (res, list(caps))
    free_seg = min(by_seg, key=lambda key: by_seg[key][0].cost)
    best, best_caps = by_seg[free_seg]
    caps[:] = best_caps
    u = best.x
    w, z, a_um, per = unpack(u)
    if z >= ZETA_MAX * 0.999:
        raise RunFailure(
            f"{segs[0].log.path}: the leg does not oscillate (damping ratio at the model's bound "
            f"{ZETA_MAX}): k, c and friction cannot be told apart from this motion"
        )
    _check_resolution(segs, w, z)
    r = resid(u)
    caps[:] = [None] * n_l
    n, p = r.size, u.size
    s2 = float(r @ r) / max(n - p, 1)
    rho = _lag1(r, [s.t.size for s in segs])
    infl = _long_run_inflation(r, [s.t.size for s in segs])
    q, n_drift = _count_drift(segs)
    m, sm = moving_mass_kg, moving_mass_sd_kg
    s2_eff = s2 * infl

    def chi2(res: Any) -> float:
        """The cost over the best's, in units of the residual variance (inflated for correlated residuals)."""
        return 2.0 * (float(res.cost) - float(best.cost)) / max(s2_eff, 1e-12)

    best_seg = free_seg
    plausible = [(key, rc) for key, rc in by_seg.items() if chi2(rc[0]) <= SEGMENTATION_CHI2]
    candidates = [
        {"half_cycles": list(key), "delta_chi2": chi2(rc[0]), "plausible": chi2(rc[0]) <= SEGMENTATION_CHI2}
        for key, rc in sorted(by_seg.items(), key=lambda kv: kv[1][0].cost)
    ]
    # friction is claimed only when the data support it over the frictionless model (BIC: one parameter more)
    friction_chi2 = chi2(no_friction)
    friction_resolved = bool(friction_chi2 > max(math.log(n), SEGMENTATION_CHI2))
    ests = []
    for _key, (res, cap) in sorted(plausible, key=lambda kv: kv[1][0].cost):
        caps[:] = cap
        ests.append(_estimates(res.x, np.asarray(res.jac), resid(res.x), offs, segs, q, s2, infl, m, sm))
    caps[:] = [None] * n_l
    if not friction_resolved:
        J = np.asarray(no_friction.jac)
        ests.append(_estimates(no_friction.x, J, resid(no_friction.x), offs, segs, q, s2, infl, m, sm))
    main = ests[0]
    spans = {name: _span(main[name], [e[name] for e in ests]) for name in main if name != "standard_errors"}

    per_log: list[dict[str, Any]] = []
    for i, (s, (xl, xe, tr, dr)) in enumerate(zip(segs, per)):
        ri = r[offs[i] : offs[i + 1]]
        per_log.append(
            {
                "file": str(s.log.path),
                "samples": int(s.t.size),
                "counts_per_m": s.log.counts_per_m,
                "held_counts": float(xl),
                "equilibrium_counts": float(xe),
                "release_delay_ms": float(tr),
                "drift_counts_per_s": float(dr),
                "half_cycles": best_seg[i],
                "samples_per_half_cycle": _samples_per_half_cycle(s, w, z),
                "slow_reads_left_out": s.slow_reads,
                "outliers_left_out": s.outliers,
                "residual_rms_counts": float(np.sqrt(np.mean(ri**2))),
                "outcome": s.log.outcome,
            }
        )
    if all(pl["half_cycles"] < 2 for pl in per_log):
        raise RunFailure(
            f"{segs[0].log.path}: the leg stopped in its first half cycle in every log: friction and "
            "damping cannot be told apart (compress the leg further, or give more logs)"
        )
    converged = bool(best.status > 0)
    fit = LegFitResult(
        leg=logs[0].leg,
        files=[str(lg.path) for lg in logs],
        moving_mass_kg=m,
        moving_mass_sd_kg=sm,
        k=spans["k"],
        c=spans["c"],
        friction=spans["friction"],
        natural_frequency_hz=spans["natural_frequency_hz"],
        damping_ratio=spans["damping_ratio"],
        friction_displacement_m=spans["friction_displacement_m"],
        per_log=per_log,
        residual_rms_counts=float(np.sqrt(np.mean(r**2))),
        autocorrelation=rho,
        converged=converged,
        optimizer={
            "status": int(best.status),
            "message": str(best.message),
            "nfev": int(best.nfev),
            "converged": converged,
            "starts": len(A_STARTS) + 1,
        },
        segments=segs,
        params=u,
        truth=[lg.truth for lg in logs],
        count_drift_counts_per_sqrt_s=math.sqrt(q),
        count_drift_differences=n_drift,
    )
    fit.standard_errors = main["standard_errors"]
    fit.stick_caps = best_caps
    fit.segmentation = {
        "chosen": list(best_seg),
        "candidates": candidates,
        "rule": f"a segmentation within delta chi2 {SEGMENTATION_CHI2:g} of the best (residual variance "
        "inflated for correlated residuals) is plausible; the intervals span every plausible one",
        "ambiguous": len(plausible) > 1,
    }
    fit.friction_test = {
        "delta_chi2_without_friction": friction_chi2,
        "bic_penalty": math.log(n),
        "resolved": friction_resolved,
    }
    if not all(math.isfinite(e.value) and math.isfinite(e.se) for e in (fit.k, fit.c, fit.friction)):
        raise RunFailure(
            f"{segs[0].log.path}: the fit gave no finite k, c and friction with uncertainties "
            "(a flat direction of the cost: the motion does not determine them)"
        )
    for name, est in (("k", fit.k), ("c", fit.c)):
        if est.ci95[0] <= 0:
            raise RunFailure(
                f"{segs[0].log.path}: the 95 % interval of {name} reaches zero ({est.value:.4g} +- "
                f"{Z95 * est.se:.3g} {est.unit}): the motion does not determine the leg"
            )
    return fit


def _samples_per_half_cycle(seg: _Segment, w: float, z: float) -> float:
    """The median number of reads in one half cycle of the fitted motion (pi / omega_d) in this log."""
    moving = seg.t[seg.t >= 0]
    dt = float(np.median(np.diff(moving))) if moving.size > 1 else math.inf
    half = math.pi / (w * math.sqrt(max(1.0 - z * z, 1e-12)))
    return half / dt if dt > 0 else math.inf


def _check_resolution(segs: list[_Segment], w: float, z: float) -> None:
    """Refuse (`RunFailure`) a log read too slowly to resolve the fitted leg: fewer than
    `MIN_SAMPLES_PER_HALF_CYCLE` reads in a half cycle, where the fit's k, c and friction are not determined
    (an alias of the motion, or a frequency the reads cannot see)."""
    for s in segs:
        sph = _samples_per_half_cycle(s, w, z)
        if sph < MIN_SAMPLES_PER_HALF_CYCLE:
            moving = s.t[s.t >= 0]
            rate = (moving.size - 1) / float(moving[-1] - moving[0]) if moving.size > 1 else 0.0
            half_ms = 1e3 * math.pi / (w * math.sqrt(max(1.0 - z * z, 1e-12)))
            raise RunFailure(
                f"{s.log.path}: {sph:.1f} samples per half cycle (read {rate:.0f} times a second, the fitted "
                f"half cycle {half_ms:.2g} ms): at least {MIN_SAMPLES_PER_HALF_CYCLE} are needed, the sample rate "
                "cannot resolve the leg (record again on an idle machine or on the robot)"
            )


def _estimates(
    u: np.ndarray,
    J: np.ndarray,
    r: np.ndarray,
    offs: np.ndarray,
    segs: list[_Segment],
    q: float,
    s2: float,
    infl: float,
    m: float,
    sm: float,
) -> dict[str, Any]:
    """k, c, F_c and the oscillator's parameters at `u`, each with the largest of the three standard errors
    (least squares inflated by `infl`, block sandwich, noise model) and the moving mass's; and each of the
    three in `standard_errors`."""
    p = u.size
    try:
        A = np.linalg.pinv(J.T @ J)
        cov = A * s2 * infl
        cov_s = _block_sandwich(A, J, r, offs, p)
        cov_w, cov_rw = _noise_sandwich(A, J, r, offs, [s.t for s in segs], q)
    except np.linalg.LinAlgError:
        cov = cov_s = cov_w = cov_rw = np.full((p, p), np.nan)
    covs = (cov[:3, :3], cov_s[:3, :3], (cov_w + cov_rw)[:3, :3])  # omega, zeta, a (um)
    w, z, a_m = float(u[0]), float(u[1]), float(u[2]) * 1e-6
    k, c = m * w * w, 2 * m * z * w
    fc = k * a_m
    gk = np.array([2 * m * w, 0.0, 0.0])
    gc = np.array([2 * m * z, 2 * m * w, 0.0])
    gf = np.array([2 * m * w * a_m, 0.0, m * w * w * 1e-6])

    def se(g: np.ndarray, value: float) -> float:
        fin = [float(g @ cv @ g) for cv in covs if np.isfinite(cv).all()]
        v = max(fin) if fin and np.isfinite(covs[0]).all() else math.nan
        v += (value / m * sm) ** 2  # each of k, c, F_c is proportional to m
        return math.sqrt(v) if v >= 0 and math.isfinite(v) else math.nan

    unit = np.eye(3)
    return {
        "k": Estimate(k, se(gk, k), "N/m"),
        "c": Estimate(c, se(gc, c), "N s/m"),
        "friction": Estimate(fc, se(gf, fc), "N"),
        "natural_frequency_hz": Estimate(w / (2 * math.pi), se(unit[0], 0.0) / (2 * math.pi), "Hz"),
        "damping_ratio": Estimate(z, se(unit[1], 0.0), ""),
        "friction_displacement_m": Estimate(a_m, se(unit[2], 0.0) * 1e-6, "m"),
        "standard_errors": {
            f"{name}_{kind}": math.sqrt(max(float(g @ cv @ g), 0.0)) if np.isfinite(cv).all() else math.nan
            for name, g in (("k_n_per_m", gk), ("c_n_s_per_m", gc), ("guide_friction_n", gf))
            for kind, cv in zip(("least_squares", "block_sandwich", "noise_model"), covs)
        },
    }


def _span(main: Estimate, others: list[Estimate]) -> Estimate:
    """`main` with a standard error widened so that its 95 % interval spans the 95 % interval of every
    plausible alternative model (a segmentation, the frictionless model)."""
    se = max(((abs(e.value - main.value) + Z95 * e.se) / Z95 for e in others), default=main.se)
    return Estimate(main.value, max(se, main.se), main.unit)


def _a_guess_um(segs: list[_Segment], cpms: np.ndarray) -> float:
    """A friction displacement of the order of the final offset from the first overshoot's centre (um)."""
    amp = max(abs(s.x_lock0 - s.x_eq0) / cpm for s, cpm in zip(segs, cpms))
    return max(0.05 * amp * 1e6, 1.0)


def _start(segs: list[_Segment], cpms: np.ndarray, one: Any) -> np.ndarray:
    """Starting point: the held and final positions and the first motion of each log, and the best (omega_n,
    zeta) of a grid without friction on the log of the largest motion."""
    per = np.concatenate([[s.x_lock0, s.x_eq0, s.t_r0 * 1e3, 0.0] for s in segs])
    i = int(np.argmax([abs(s.x_lock0 - s.x_eq0) for s in segs]))
    best = (math.inf, 2 * math.pi * 40, 0.3)
    for f in np.geomspace(2.0, 1000.0, 80):
        for z in (0.02, 0.05, 0.1, 0.2, 0.3, 0.45, 0.6, 0.8):
            cost = float(np.sum(one(np.concatenate([[2 * math.pi * f, z, 0.0], per]), i) ** 2))
            if cost < best[0]:
                best = (cost, 2 * math.pi * f, z)
    return np.concatenate([[best[1], best[2], 0.0], per])


def _half_cycles(w: float, z: float, a: float, x_eq: float, x_lock: float, cap: int | None = None) -> int:
    """How many half cycles the fitted motion makes before it sticks (at most 1000, or `cap`)."""
    r = math.exp(-z * math.pi / math.sqrt(max(1 - z * z, 1e-12)))
    xs, n = x_lock, 0
    while n < (1000 if cap is None else cap):
        d = xs - x_eq
        if abs(d) <= a or abs(d) < 1e-6:
            break
        e = x_eq + math.copysign(a, d)
        xs = e - (xs - e) * r
        n += 1
    return n


def _block_sandwich(A: np.ndarray, J: np.ndarray, r: np.ndarray, offs: np.ndarray, p: int) -> np.ndarray:
    """The covariance A B A with B summed over blocks of `SANDWICH_BLOCK` consecutive samples of each log: right
    when the error grows with the speed (timing jitter times velocity) or is correlated over a few samples."""
    B = np.zeros_like(A)
    nb = 0
    for i in range(offs.size - 1):
        for lo in range(int(offs[i]), int(offs[i + 1]), SANDWICH_BLOCK):
            hi = min(lo + SANDWICH_BLOCK, int(offs[i + 1]))
            g = J[lo:hi].T @ r[lo:hi]
            B += np.outer(g, g)
            nb += 1
    if nb <= p:
        return np.full_like(A, np.nan)
    return A @ B @ A * (nb / (nb - p))


def _count_drift(segs: list[_Segment]) -> tuple[float, int]:
    """The count's random-walk rate q (counts^2/s: its variance after 1 s), measured where the leg is still (held
    by the clutch before the release, stuck after the motion), and the number of second differences it rests on.

    Each still part is cut into blocks of `DRIFT_BLOCK_S`; the second difference of consecutive block means
    m[b+2] - 2 m[b+1] + m[b] has the expectation q B (B the block duration) plus the white noise's
    var(m[b+2]) + 4 var(m[b+1]) + var(m[b]) (each block's sample variance over its size), and none of a linear
    trend of the count (the fit's drift term takes that)."""
    num = 0.0
    n = 0
    for sg in segs:
        for t, y in sg.still:
            if t.size < 10:
                continue
            nb = int((t[-1] - t[0]) // DRIFT_BLOCK_S)
            if nb < 3:
                continue
            idx = np.minimum(((t - t[0]) // DRIFT_BLOCK_S).astype(int), nb - 1)
            size = np.bincount(idx, minlength=nb).astype(float)
            if (size < 2).any():
                continue
            mean = np.bincount(idx, y, nb) / size
            var = (np.bincount(idx, y * y, nb) - size * mean**2) / (size - 1) / size  # of each block's mean
            d2 = mean[2:] - 2 * mean[1:-1] + mean[:-2]
            num += float(np.sum(d2**2 - (var[2:] + 4 * var[1:-1] + var[:-2])))
            n += d2.size
    return (max(num / (n * DRIFT_BLOCK_S), 0.0), n) if n else (0.0, 0)


def _noise_sandwich(
    A: np.ndarray, J: np.ndarray, r: np.ndarray, offs: np.ndarray, ts: list[np.ndarray], q: float
) -> tuple[np.ndarray, np.ndarray]:
    """The covariance A J' S J A of the least squares for residuals whose covariance S is white with each
    sample's own variance (its squared residual: a read's timing error grows with the speed) plus a random walk
    of rate q (counts^2/s) in each log, cov = q min(t_i, t_j): returned as its white and its random-walk part.
    The walk's J' K J is the sum over the sample intervals dt_m of G_m G_m', G_m the sum of the Jacobian's rows
    from sample m on (the walk's step in interval m moves every later sample)."""
    n, p = J.shape
    bw = np.zeros((p, p))
    brw = np.zeros((p, p))
    for i in range(offs.size - 1):
        Ji, ri, t = J[offs[i] : offs[i + 1]], r[offs[i] : offs[i + 1]], ts[i]
        g = Ji * ri[:, None]
        bw += g.T @ g
        tail = np.cumsum(Ji[::-1], axis=0)[::-1]
        dt = np.diff(t, prepend=t[0])
        brw += (tail * dt[:, None]).T @ tail
    return A @ bw @ A * (n / max(n - p, 1)), A @ brw @ A * q


def _long_run_inflation(r: np.ndarray, sizes: list[int]) -> float:
    """The long-run variance of the residuals over their variance (Bartlett weights up to `LONG_RUN_LAGS`
    lags, per log, averaged; at least 1): the factor by which correlated residuals (a drifting count, a
    slightly wrong model) carry less information than their number says."""
    out, i = [], 0
    for n in sizes:
        ri = r[i : i + n] - np.mean(r[i : i + n])
        i += n
        v = float(ri @ ri)
        if n <= 2 * LONG_RUN_LAGS or v <= 0:
            continue
        f = 1.0
        for lag in range(1, LONG_RUN_LAGS + 1):
            f += 2 * (1 - lag / (LONG_RUN_LAGS + 1)) * float(ri[:-lag] @ ri[lag:]) / v
        out.append(f)
    return max(float(np.mean(out)), 1.0) if out else 1.0


def _lag1(r: np.ndarray, sizes: list[int]) -> float:
    """Mean lag-1 autocorrelation of the residuals within each log, clipped to [0, 0.95]."""
    rhos, i = [], 0
    for n in sizes:
        ri = r[i : i + n]
        i += n
        if ri.size > 10 and np.std(ri) > 0:
            rhos.append(float(np.corrcoef(ri[:-1], ri[1:])[0, 1]))
    return float(np.clip(np.mean(rhos), 0.0, 0.95)) if rhos else 0.0


def plot_leg_fit(fit: LegFitResult, path: Path | str) -> None:
    """The measured displacement and the fitted model against time from the release (mm), and the residuals
    (counts), one colour per log; written atomically."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from rimless.output import atomic_file

    w, z, a_um = fit.params[0], fit.params[1], fit.params[2]
    per = fit.params[N_SHARED:].reshape(-1, N_PER_LOG)
    fig, (ax, axr) = plt.subplots(2, 1, figsize=(8, 6), sharex=True, gridspec_kw={"height_ratios": [3, 1]})
    caps = fit.stick_caps or [None] * len(fit.segments)
    for i, (s, (xl, xe, tr, dr)) in enumerate(zip(fit.segments, per)):
        cpm = s.log.counts_per_m
        model = free_response(s.t, w, z, a_um * 1e-6 * cpm, xe, xl, tr * 1e-3, caps[i]) + dr * s.t
        fine = np.linspace(float(s.t[0]), float(s.t[-1]), 2000)
        curve = free_response(fine, w, z, a_um * 1e-6 * cpm, xe, xl, tr * 1e-3, caps[i]) + dr * fine
        col = f"C{i % 10}"
        ax.plot(s.t * 1e3, (s.y - xe) / cpm * 1e3, ".", ms=2, color=col, label=f"{Path(s.log.path).name} (measured)")
        ax.plot(fine * 1e3, (curve - xe) / cpm * 1e3, "-", lw=1, color="k", label="fit" if i == 0 else None)
        axr.plot(s.t * 1e3, s.y - model, ".", ms=2, color=col)
    ax.axhspan(
        -fit.friction_displacement_m.value * 1e3,
        fit.friction_displacement_m.value * 1e3,
        color="0.85",
        label="friction band |x - x_eq| <= F_c / k",
    )
    ax.set_ylabel("compression from equilibrium (mm)")
    ax.set_title(
        f"leg {fit.leg}: k = {fit.k.value:.0f} ± {Z95 * fit.k.se:.0f} N/m, c = {fit.c.value:.2f} ± "
        f"{Z95 * fit.c.se:.2f} N s/m, F_c = {fit.friction.value:.3f} ± {Z95 * fit.friction.se:.3f} N (95 %)",
        fontsize=9,
    )
    ax.legend(fontsize=7, loc="upper right")
    axr.set_ylabel("residual (counts)")
    axr.set_xlabel("time from the release command (ms)")
    axr.axhline(0.0, color="k", lw=0.5)
    fig.tight_layout()
    with atomic_file(path, option="--plot") as tmp:
        fig.savefig(tmp, dpi=120)
    plt.close(fig)


def run_leg_fit(
    paths: list[Path],
    *,
    moving_mass_kg: float = DEFAULT_MOVING_MASS_KG,
    moving_mass_sd_kg: float = 0.0,
    counts_per_m: float | None = None,
    plot: Path | None = None,
) -> LegFitResult:
    """`rimless trials leg-fit`: read every log (the first bad one stops it: `InputFileError` naming the file,
    line and field), fit, and draw the figure to `plot`."""
    if plot is not None:
        from rimless.output import check_output_folder

        check_output_folder(Path(plot).parent if str(Path(plot).parent) else Path("."), option="--plot")
    if counts_per_m is not None and not (math.isfinite(counts_per_m) and counts_per_m > 0):
        raise ParameterError(f"--counts-per-m must be > 0, got {counts_per_m!r}")
    logs = [read_leg_log(p, counts_per_m) for p in paths]
    fit = fit_leg(logs, moving_mass_kg=moving_mass_kg, moving_mass_sd_kg=moving_mass_sd_kg)
    if plot is not None:
        plot_leg_fit(fit, plot)
    return fit


def fake_truth(fit: LegFitResult) -> dict[str, float] | None:
    """The simulated leg of `leg-test --fake` logs, in the keys of `LegFitResult.summary` (None for real logs or
    logs of different fakes)."""
    truths = [t for t in fit.truth if t]
    if len(truths) != len(fit.truth) or not truths or any(t != truths[0] for t in truths):
        return None
    t = truths[0]
    try:
        return {
            "k_n_per_m": float(t["stiffness_n_per_m"]),
            "c_n_s_per_m": float(t["damping_n_s_per_m"]),
            "guide_friction_n": float(t["friction_n"]),
            "moving_mass_kg": float(t["moving_mass_kg"]),
        }
    except (KeyError, TypeError, ValueError):
        return None
