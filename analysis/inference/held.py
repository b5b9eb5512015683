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
- **the models' critical slopes**: Algorithm 1 (`model_critical_slope`) at each perturbed value.

The interval with the parameters is ``value -+ sqrt(half-width^2 + (1.96 se_parameters)^2)`` on each side (the
data's interval may be asymmetric, as the bracket's is). The data-only intervals (``ci_deg``) keep their meaning.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

from rimless.analysis.inference.critical_slope import Z95, CriticalSlopeResult, estimate_critical_slope
from rimless.errors import ParameterError

__all__ = ["PENDULUM_FIELDS", "sensitivities", "combine", "carry_critical", "trial_estimate_at"]

#: the parameters the verdicts and the trial estimates depend on (the stance pendulum's)
PENDULUM_FIELDS = ("hub_mass_kg", "leg_mass_kg", "inertia_kg_m2", "leg_length_m", "gravity_m_s2")

METHOD = (
    "finite-difference sensitivities at +-1 sd of each held parameter (one-sided at a bound), combined in "
    "quadrature (linear propagation, parameters independent)"
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


def widen(value: float, ci: tuple[float, float], se_par: float) -> list[float]:
    """The data's 95 % interval widened by the parameters' standard error, side by side in quadrature."""
    d = Z95 * se_par
    return [value - math.hypot(value - ci[0], d), value + math.hypot(ci[1] - value, d)]


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
) -> dict[str, Any]:
    """Propagate the held parameters of ``win`` (`rimless.sim.model.uncertain.WheelInput`) into the chosen
    estimate from the trials and the models' critical slopes of ``res``; sets ``res.parameters`` and
    ``res.held`` (the JSON's ``parameters`` and ``parameter_uncertainty``) and returns the latter.
    ``central_models`` False: the models' sensitivities by forward differences (half the Algorithm 1 runs; the
    report and the demo)."""
    out: dict[str, Any] = {"method": METHOD, "trials": None, "models": {}}
    c = res.chosen
    if c is not None:
        if progress:
            progress("held parameters: trials")
        _, rows = sensitivities(
            trial_estimate_at(trials, files, c.method, group_tol_deg), win, PENDULUM_FIELDS, base=c.value_deg
        )
        se, complete = combine(rows)
        out["trials"] = {
            "method": c.method,
            "critical_slope_deg": c.value_deg,
            "ci_data_deg": list(c.ci_deg),
            "se_parameters_deg": se,
            "ci_deg": widen(c.value_deg, c.ci_deg, se),
            "complete": complete,
            "contributions": rows,
        }
    for m in models:
        if progress:
            progress(f"held parameters: model {m}")
        known = res.model.get("critical_slope_deg", {}).get(m)
        base, rows = sensitivities(_model_at(m), win, base=known, central=central_models)
        if base is None:
            out["models"][m] = {"critical_slope_deg": None, "note": "no critical slope at the held values"}
            continue
        se, complete = combine(rows)
        out["models"][m] = {
            "critical_slope_deg": base,
            "se_parameters_deg": se,
            "ci_deg": [base - Z95 * se, base + Z95 * se],
            "complete": complete,
            "differences": "central" if central_models else "forward",
            "contributions": rows,
        }
    res.parameters = win.parameters()
    res.held = out
    return out
