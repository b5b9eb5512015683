"""What is held, is carried: the held wheel parameters' uncertainty in the critical slope's intervals.

Every inference holds the parameters it does not fit at a value (Table 1, a wheel file, a leg test); each has a
1-sigma uncertainty (`rimless.sim.model.uncertain`). Here that uncertainty is propagated by **finite-difference
sensitivities at +-1 sd, combined in quadrature**: for each held parameter p with sd > 0 the quantity is
recomputed at p + sd and p - sd, its contribution is half the difference (one-sided, |f(p + sd) - f(p)|, where
p - sd is not a valid value, e.g. F_c < 0), and the contributions add in quadrature (independent parameters).
Linear propagation: it is exact for a quantity linear in the parameters over +-1 sd and approximate otherwise
(the two one-sided changes are reported, so a strong non-linearity shows).

- **from the trials**: the verdicts and the estimate use the wheel only through the stance pendulum of
  `rimless.analysis.inference.sustained.StancePendulum` (m_H, m, I_c, L0, g): the verdicts are recomputed and the
  reported method's estimate re-made at each perturbed value; k, c and F_c do not enter (contribution 0).
- **the models' critical slopes**: the critical slope of `model_critical_slope` at each perturbed value, by
  default warm-started (`WarmCritical`): the nominal wheel's branch is traced once from Algorithm 1's start
  slope, and each perturbed wheel's branch is traced from the nominal branch's point `WARM_MARGIN_RAD` above the
  nominal critical slope (its fixed point the guess) down to its first loss, instead of Algorithm 1's fixed steps
  from 0.05 rad and a trace from there. Assumed, and checked where it can be: the perturbed branch between the
  start slope and that point has no special point (none on the nominal one); the perturbed gait there is
  stable with the signs of the nominal start's test functions (stance force, impulse, stall), else that run is
  the straightforward `model_critical_slope`. The two agree to the root location (about 1e-9 rad;
  tests/analysis/inference/test_warm_critical.py); ``warm=False`` gives the straightforward runs.

A parameter held at its physical bound (F_c = 0 +- 0.2 N: its truth can only be above) is carried as its stated
normal truncated there (`carry_bounded`, as the calibration carries it): its part shifts the critical slope by
sqrt(2/pi) = 0.80 times its one-sided change, with an sd of sqrt(1 - 2/pi) = 0.60 times it, instead of +-1 times
it about the held value (`carry_rows`; ``held_shift_deg``, ``critical_slope_with_held_deg``).

The interval with the parameters is ``value + shift -+ sqrt(half-width^2 + (1.96 se_parameters)^2)`` on each
side (the data's interval may be asymmetric, as the bracket's is), cut at 0 deg where it reaches below (a critical
slope is a slope down which the wheel walks; ``ci_at_bound``, the uncut ``ci_linear_deg``). The data-only intervals
(the estimates' ``ci_deg``; ``ci_data_deg`` here) keep their meaning.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

from rimless.analysis.inference.critical_slope import Z95, CriticalSlopeResult, estimate_critical_slope
from rimless.errors import ParameterError
from rimless.sim.model.failures import StepFailure

__all__ = [
    "PENDULUM_FIELDS",
    "sensitivities",
    "combine",
    "carry_critical",
    "trial_estimate_at",
    "WarmCritical",
    "inertia_from_trials",
    "LOWER_BOUND",
    "truncated_moments",
    "carry_bounded",
    "carry_rows",
]

#: the parameters the verdicts and the trial estimates depend on (the stance pendulum's)
PENDULUM_FIELDS = ("hub_mass_kg", "leg_mass_kg", "inertia_kg_m2", "leg_length_m", "gravity_m_s2")
#: those that still enter when the trials determine the inertia ratio I_hub / (M L0^2) (the pendulum's kappa
#: and beta depend on the masses and the inertia only through it)
RATIO_FIELDS = ("inertia_kg_m2", "leg_length_m", "gravity_m_s2")

METHOD = (
    "finite-difference sensitivities at +-1 sd of each held parameter (one-sided at a bound), combined in "
    "quadrature (linear propagation, parameters independent); a parameter at its bound (F_c = 0) carried as its "
    "normal truncated there (mean shift and sd of the half-normal)"
)


def _finite(v: Any) -> float | None:
    return float(v) if v is not None and math.isfinite(v) else None


def sensitivities(
    f: Callable[[Any], float | None],
    win: Any,
    fields: Sequence[str] | None = None,
    *,
    base: float | None = None,
    central: bool = True,
) -> tuple[float | None, list[dict[str, Any]]]:
    """(f at the wheel's values, one row per held parameter with sd > 0: {name, symbol, sd, unit, minus, plus,
    contribution}) for a scalar ``f(params)`` (None or NaN when it does not exist there). A parameter outside
    ``fields`` contributes 0 without evaluation; ``base``: f at the wheel's values when already known;
    ``central`` False: forward differences only (|f(p + sd) - f(p)|, half the evaluations)."""
    base = _finite(base) if base is not None else _finite(f(win.params))
    rows = []
    for e in win.held():
        row: dict[str, Any] = {"name": e.name, "symbol": e.symbol, "sd": e.sd, "unit": e.unit}
        if fields is not None and e.name not in fields:
            rows.append({**row, "minus_deg": base, "plus_deg": base, "contribution_deg": 0.0, "note": "does not enter"})
            continue
        vals: dict[str, float | None] = {}
        for sign, key in ((1.0, "plus_deg"), (-1.0, "minus_deg")):
            if sign < 0 and not central and base is not None:
                vals[key] = None
                continue
            try:
                p = win.params.replace(**{e.name: e.value + sign * e.sd})
            except ParameterError:
                vals[key] = None  # outside the valid range (e.g. F_c < 0): one-sided
                continue
            vals[key] = _finite(f(p))
        hi, lo = vals["plus_deg"], vals["minus_deg"]
        if hi is not None and lo is not None:
            contrib: float | None = abs(hi - lo) / 2.0
            note = ""
        elif base is not None and (hi is not None or lo is not None):
            contrib = abs((hi if hi is not None else lo) - base)  # type: ignore[operator]
            note = "one-sided" if central else "forward difference"
        else:
            contrib, note = None, "no value at p +- sd: not propagated"
        rows.append({**row, **vals, "contribution_deg": contrib, "note": note})
    return base, rows


def combine(rows: Sequence[dict[str, Any]]) -> tuple[float, bool]:
    """(quadrature sum of the contributions, complete: every held parameter propagated)."""
    c = [r["contribution_deg"] for r in rows]
    return math.sqrt(sum(x * x for x in c if x is not None)), all(x is not None for x in c)


#: every wheel parameter that carries an uncertainty is >= 0 (masses, inertia, L0, k, g > 0; c, F_c >= 0,
#: `rimless.sim.model.params.validate`): its stated normal N(value, sd) is carried truncated there; a truncation
#: that moves the mean by less than `TRUNCATION_NAMED` sd is not named (far from the bound). Defined with the
#: parameters' ``carried_as`` (`rimless.sim.model.uncertain.ParamInput`), which says the same
from rimless.sim.model.uncertain import LOWER_BOUND, TRUNCATION_NAMED  # noqa: E402


def truncated_moments(value: float, sd: float, lower: float = LOWER_BOUND) -> tuple[float, float]:
    """(mean - value, sd of the truncated) / sd of the normal N(value, sd) truncated below at ``lower``: the
    closed forms lambda = phi(a) / (1 - Phi(a)), a = (lower - value) / sd, mean offset lambda, variance
    1 + a lambda - lambda^2 (Johnson, Kotz and Balakrishnan, *Continuous Univariate Distributions* 1, 1994,
    section 10.1). At the bound (value = lower) the half-normal: sqrt(2/pi) = 0.798 and sqrt(1 - 2/pi) = 0.603;
    far above it (0, 1). ``sd`` must be > 0 and ``value`` >= ``lower``."""
    a = (lower - value) / sd
    tail = 0.5 * math.erfc(a / math.sqrt(2.0))  # 1 - Phi(a), accurate for a <= 0
    lam = math.exp(-0.5 * a * a) / math.sqrt(2.0 * math.pi) / tail
    return lam, math.sqrt(max(1.0 + a * lam - lam * lam, 0.0))


#: what `carry_bounded` calls one evaluation at a moved parameter and several, by default (the calibration's)
REFITS = ("refit", "refits")


def carry_bounded(
    value: float,
    sd: float,
    plus: Any | None,
    minus: Any | None,
    lower: float = LOWER_BOUND,
    *,
    evaluations: tuple[str, str] = REFITS,
) -> tuple[Any, Any, str]:
    """One held parameter's part in the fitted values, from their signed changes ``plus`` and ``minus`` when it is
    moved to value + sd and value - sd (None where that is not a valid wheel, e.g. F_c < 0). Linear in the
    parameter over +-1 sd (the change per sd: the central difference, one-sided at the bound), with the parameter
    distributed as its stated normal truncated at ``lower`` (`truncated_moments`): returns (the fitted values'
    mean shift, their sd, how it was carried). Far from the bound: shift 0, sd the central half difference (or
    the one-sided change), as before; at it (F_c = 0 +- 0.2 N): shift sqrt(2/pi) times the one-sided change, sd
    sqrt(1 - 2/pi) times it (the truth's F_c can only be above the held value). ``evaluations``: the words for
    one and several evaluations at a moved parameter in the returned text (the calibration refits; a critical
    slope is recomputed, `carry_rows`)."""
    import numpy as np

    one, many = evaluations
    if plus is not None and minus is not None:
        per_sd, diff = (np.asarray(plus, float) - np.asarray(minus, float)) / 2.0, f"central {many} at +-1 sd"
    elif plus is not None:
        per_sd, diff = np.asarray(plus, float), f"one {one} at +1 sd (-1 sd is not a valid wheel)"
    elif minus is not None:
        per_sd, diff = -np.asarray(minus, float), f"one {one} at -1 sd (+1 sd is not a valid wheel)"
    else:
        raise ValueError("carry_bounded needs at least one of plus, minus")
    m, s = truncated_moments(value, sd, lower)
    if m < TRUNCATION_NAMED:
        return np.zeros_like(per_sd), np.abs(per_sd), f"normal {value:.4g} +- {sd:.3g}: {diff}, linear"
    how = (
        f"normal {value:.4g} +- {sd:.3g} truncated at its bound {lower:g} (mean {value + m * sd:.3g}, sd "
        f"{s * sd:.3g}): {diff}, linear; the interval is re-centred by the mean shift"
    )
    return m * per_sd, s * np.abs(per_sd), how


def carry_rows(rows: Sequence[dict[str, Any]], win: Any, base: float | None, quantity: str = "") -> float:
    """Carry each held parameter of `sensitivities`' ``rows`` by its stated normal truncated at its bound
    (`carry_bounded`, as the calibration carries it): sets each row's ``contribution_deg`` (the sd of its part),
    ``shift_deg`` (its part's mean shift: 0 far from the bound; sqrt(2/pi) times the one-sided change for F_c
    held at 0, whose truth can only be above) and ``carried_as``; returns the summed shift (deg) the intervals
    are re-centred by. A row without a change (not propagated, or not entering) keeps its contribution, shift 0.
    ``quantity``: what was recomputed at each moved parameter ("critical slope"), named in ``carried_as``."""
    of = f" of the {quantity}" if quantity else ""
    words = (f"recomputation{of}", f"recomputations{of}")
    total = 0.0
    for r in rows:
        r.setdefault("shift_deg", 0.0)
        e = win.entries.get(r["name"])
        if e is None or base is None or r.get("contribution_deg") is None or r.get("note") == "does not enter":
            continue
        plus = r["plus_deg"] - base if r.get("plus_deg") is not None else None
        minus = r["minus_deg"] - base if r.get("minus_deg") is not None else None
        if plus is None and minus is None:
            continue
        shift, sd, how = carry_bounded(e.value, e.sd, plus, minus, evaluations=words)
        if r.get("note") == "forward difference":  # -1 sd was not evaluated, not invalid
            how = how.replace(f"one {words[0]} at +1 sd (-1 sd is not a valid wheel)", "a forward difference at +1 sd")
        r["contribution_deg"], r["shift_deg"], r["carried_as"] = float(sd), float(shift), how
        total += float(shift)
    return total


def widen(value: float, ci: tuple[float, float], se_par: float) -> list[float]:
    """The data's 95 % interval widened by the parameters' standard error, side by side in quadrature."""
    d = Z95 * se_par
    return [value - math.hypot(value - ci[0], d), value + math.hypot(ci[1] - value, d)]


#: a critical slope is a slope the wheel walks down: >= 0 (the simulator's and the importer's domain)
SLOPE_BOUND_DEG = 0.0


def cut_at_bound(ci: Sequence[float], bound: float) -> tuple[float, float]:
    """An interval ``ci`` with its ends raised to ``bound`` where below it (no valid value lies below: a fitted
    parameter's lower bound, a critical slope's 0 deg); a NaN end stays NaN (max keeps its first argument)."""
    return (max(ci[0], bound), max(ci[1], bound))


def _slope_ci(ci: list[float]) -> dict[str, Any]:
    """``ci_deg``: a critical slope's 95 % interval with the parameters, cut at `SLOPE_BOUND_DEG` where the
    linearised one reaches below it (``ci_at_bound``; the uncut one ``ci_linear_deg``)."""
    return {
        "ci_deg": list(cut_at_bound(ci, SLOPE_BOUND_DEG)),
        "ci_linear_deg": ci,
        "ci_at_bound": ci[0] < SLOPE_BOUND_DEG,
    }


def trial_estimate_at(
    trials: Sequence[Any], files: Sequence[str], method: str, group_tol_deg: float
) -> Callable[[Any], float | None]:
    """``f(params)``: the ``method`` estimate from the trials with the verdicts at ``params`` (no bootstrap)."""
    from rimless.analysis.inference.sustained import trial_verdicts

    def f(params: Any) -> float | None:
        res = estimate_critical_slope(
            trial_verdicts(list(trials), params), files, group_tol_deg=group_tol_deg, n_boot=0
        )
        est = {e.method: e for e in res.estimates}.get(method)
        return est.value_deg if est is not None else None

    return f


def _model_at(model: str) -> Callable[[Any], float | None]:
    from rimless.analysis.inference.critical_slope import model_critical_slope

    def f(params: Any) -> float | None:
        return _finite(model_critical_slope(params, model)["critical_slope_deg"])

    return f


#: a warm-started branch starts at the nominal branch's point at least this far above the nominal critical
#: slope (rad; 0.5 deg: the Table 1 wheel's largest 1-sd change, c's, is 0.22 deg)
WARM_MARGIN_RAD = math.radians(0.5)
#: `model_critical_slope`'s settings: map tolerance, root location (rad), and Algorithm 1's smallest slope
RTOL = 1e-9
REFINE_TOL_RAD = 1e-6
MIN_SLOPE_RAD = 1e-4


class WarmCritical:
    """``f(params)``: the ``model``'s critical slope (deg, None where there is none) at wheels near ``nominal``,
    each traced from the nominal branch (see the module doc). `warm` and `straightforward` count the runs of
    each kind; ``known_deg``: the nominal critical slope already found (`model_critical_slope`), which the
    nominal trace must reproduce to the root location, else every run is the straightforward one."""

    def __init__(self, nominal: Any, model: str, known_deg: float | None = None) -> None:
        self.model = model
        self.warm = 0
        self.straightforward = 0
        self.start: tuple[float, Any] | None = None  # (slope rad, fixed point) the perturbed branches start from
        self._signs: dict[str, bool] = {}
        self._slow = _model_at(model)
        try:
            self._trace_nominal(nominal, known_deg)
        except StepFailure:
            self.start = None

    def _trace_nominal(self, nominal: Any, known_deg: float | None) -> None:
        from rimless.sim.continuation.algorithm1 import START_SLOPE_RAD
        from rimless.sim.step.backend import jacobian_factory, make_map
        from rimless.sim.step.poincare import default_guess, solve_fixed_point

        start = nominal.replace(slope_rad=START_SLOPE_RAD)
        pmap = make_map(start, self.model, rtol=RTOL)
        if not hasattr(pmap, "evaluate"):  # the reference path's Algorithm 1 bisects: no branch to start from
            return
        jac = jacobian_factory("auto")
        guess = default_guess(start, self.model)
        first = solve_fixed_point(pmap, guess, jacobian=jac(pmap) if jac else None, max_iter=20)
        if not first.stable:
            return
        br = _trace(pmap, first.z)
        end = br.first_loss()
        if end is None or not br.points[0].stable:
            return
        if known_deg is not None and abs(math.degrees(end.p) - known_deg) > math.degrees(REFINE_TOL_RAD):
            return
        self._signs = {k: v > 0 for k, v in br.points[0].tests.items() if math.isfinite(v)}
        above = [pt for pt in br.points if pt.p >= end.p + WARM_MARGIN_RAD and pt.p < START_SLOPE_RAD]
        if above:
            self.start = (above[-1].p, above[-1].z)

    def _from_start(self, params: Any) -> float | None:
        """The critical slope (deg) traced from `start` at ``params``; None where that start does not hold."""
        from rimless.sim.step.backend import make_map

        assert self.start is not None
        slope, z = self.start
        try:
            br = _trace(make_map(params.replace(slope_rad=slope), self.model, rtol=RTOL), z)
        except StepFailure:  # no fixed point near the nominal one at that slope
            return None
        first = br.points[0]
        if not first.stable or any((first.tests[k] > 0) != good for k, good in self._signs.items() if k in first.tests):
            return None
        end = br.first_loss()
        return math.degrees(end.p if end is not None else br.points[-1].p)

    def __call__(self, params: Any) -> float | None:
        if self.start is not None:
            v = self._from_start(params)
            if v is not None:
                self.warm += 1
                return v
        self.straightforward += 1
        return self._slow(params)


def _trace(pmap: Any, z0: Any) -> Any:
    """The slope branch of ``pmap`` through the fixed point near ``z0`` at its slope, down to its first loss
    (as `rimless.sim.continuation.algorithm1.critical_slope` traces it)."""
    from rimless.sim.continuation.arclength import ArclengthContinuation
    from rimless.sim.continuation.oracle import PARAMETERS

    cont = ArclengthContinuation(
        lambda q: pmap.with_params(q),
        pmap.params,
        pmap.model,
        "slope",
        locate_tol=min(1e-7, REFINE_TOL_RAD / PARAMETERS["slope"][1]),
    )
    return cont.trace(z0, direction=-1.0, p_min=MIN_SLOPE_RAD, stop_at_first_loss=True)


def carry_critical(
    res: CriticalSlopeResult,
    trials: Sequence[Any],
    files: Sequence[str],
    win: Any,
    *,
    models: Sequence[str] = (),
    group_tol_deg: float = 0.05,
    progress: Callable[[str], None] | None = None,
    central_models: bool = True,
    warm: bool = True,
    estimate_inertia: bool = True,
) -> dict[str, Any]:
    """Propagate the held parameters of ``win`` (`rimless.sim.model.uncertain.WheelInput`) into the chosen
    estimate from the trials and the models' critical slopes of ``res``; sets ``res.parameters`` and
    ``res.held`` (the JSON's ``parameters`` and ``parameter_uncertainty``) and returns the latter.
    ``central_models`` False: the models' sensitivities by forward differences (half the Algorithm 1 runs; no
    command uses it since session 21: the report and the demo take central ones as `trials critical-slope` does);
    ``warm`` False: each of them by the straightforward `model_critical_slope` (else
    warm-started, `WarmCritical`). ``estimate_inertia`` (default): the inertia ratio the trials' step periods
    determine (`inertia_from_trials`) replaces an inertia the input does not state, or is compared with a stated
    one (``res.inertia``, ``res.warnings``)."""
    out: dict[str, Any] = {"method": METHOD, "trials": None, "models": {}}
    if estimate_inertia and trials:
        if progress:
            progress("inertia from the trials")
        win = inertia_from_trials(res, trials, files, win, group_tol_deg=group_tol_deg)
    from_trials = win.entries["inertia_kg_m2"].source == "trials"
    c = res.chosen
    if c is not None:
        if progress:
            progress("held parameters: trials")
        f_trials = trial_estimate_at(trials, files, c.method, group_tol_deg)
        fields: tuple[str, ...] = PENDULUM_FIELDS
        if from_trials:  # the trials determine the inertia ratio: refit it at each perturbed L0 and g (the
            # pendulum depends on the masses only through that ratio: they do not enter)
            f_trials = _refitting(f_trials, trials, win.params)
            fields = RATIO_FIELDS
        _, rows = sensitivities(f_trials, win, fields, base=c.value_deg)
        shift = carry_rows(rows, win, c.value_deg, "critical slope")
        se, complete = combine(rows)
        out["trials"] = {
            "method": c.method,
            "critical_slope_deg": c.value_deg,
            "critical_slope_with_held_deg": c.value_deg + shift,
            "held_shift_deg": shift,
            "ci_data_deg": list(c.ci_deg),
            "se_parameters_deg": se,
            **_slope_ci(widen(c.value_deg + shift, (c.ci_deg[0] + shift, c.ci_deg[1] + shift), se)),
            "complete": complete,
            "contributions": rows,
        }
    for m in models:
        if progress:
            progress(f"held parameters: model {m}")
        known = res.model.get("critical_slope_deg", {}).get(m)
        f = WarmCritical(win.params, m, known) if warm and _finite(known) is not None else _model_at(m)
        base, rows = sensitivities(f, win, base=known, central=central_models)
        if base is None:
            out["models"][m] = {"critical_slope_deg": None, "note": "no critical slope at the held values"}
            continue
        shift = carry_rows(rows, win, base, "critical slope")
        se, complete = combine(rows)
        out["models"][m] = {
            "critical_slope_deg": base,
            "critical_slope_with_held_deg": base + shift,
            "held_shift_deg": shift,
            "se_parameters_deg": se,
            **_slope_ci([base + shift - Z95 * se, base + shift + Z95 * se]),
            "complete": complete,
            "differences": "central" if central_models else "forward",
            "contributions": rows,
        }
    res.parameters = win.parameters()
    res.held = out
    return out


def _refitting(f: Callable[[Any], float | None], trials: Sequence[Any], nominal: Any) -> Callable[[Any], float | None]:
    """``f`` at wheels whose inertia, where it is the nominal one, is refitted to the trials at their masses and
    L0 (the trials determine the inertia ratio, not I_c: a perturbed mass or L0 moves I_c, not the ratio)."""
    from rimless.analysis.inference.stance_inertia import estimate_inertia_ratio

    def g(params: Any) -> float | None:
        if params.inertia_kg_m2 == nominal.inertia_kg_m2:
            est = estimate_inertia_ratio(trials, params, fit_leg_length=False)  # only I_c at the held L0 is used
            if not est.ok:
                return None
            params = params.replace(inertia_kg_m2=est.inertia_kg_m2)
        return f(params)

    return g


def inertia_from_trials(
    res: CriticalSlopeResult, trials: Sequence[Any], files: Sequence[str], win: Any, *, group_tol_deg: float = 0.05
) -> Any:
    """The wheel input with the trials' inertia (`rimless.analysis.inference.stance_inertia.trial_inertia_input`);
    when it replaces Table 1's, ``res``'s verdicts, estimates and models are re-made at it. Sets ``res.inertia``
    and adds to ``res.warnings``; returns the input to carry."""
    from rimless.analysis.inference.critical_slope import model_critical_slope
    from rimless.analysis.inference.stance_inertia import trial_inertia_input
    from rimless.analysis.inference.sustained import trial_verdicts

    new, est, warnings = trial_inertia_input(win, trials)
    res.inertia = est.as_dict()
    res.warnings = [*res.warnings, *warnings]
    if new is win:
        return win
    verdicts = trial_verdicts(list(trials), new.params)
    again = estimate_critical_slope(verdicts, files, group_tol_deg=group_tol_deg)
    for name in ("per_trial", "bracket_deg", "estimates", "chosen", "why", "logistic", "extrapolation"):
        setattr(res, name, getattr(again, name))
    res.verdicts = verdicts  # type: ignore[attr-defined]
    crit = res.model.get("critical_slope_deg", {})
    for m in [m for m in crit if not m.endswith("_calibrated")]:  # the models at the trials' inertia
        outm = model_critical_slope(new.params, m)
        crit[m] = outm["critical_slope_deg"]
        res.model.setdefault("detail", {})[m] = outm
    return new
