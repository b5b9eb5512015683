"""Leg-test results as priors of the whole-walk calibration (`rimless trials calibrate --prior leg.json`).

A prior comes from the JSON of `rimless trials leg-fit --json`: for each of `k_n_per_m`, `c_n_s_per_m` and
`guide_friction_n` its value and 95 % interval `_ci`, read as a Gaussian with mean the value and standard
deviation the interval's half width / 1.96. What happens to each depends on the walk fit:

- fitted (in `--fit`): a Gaussian penalty row (x - mean) / sd joins the least-squares residuals (and its
  Jacobian, the covariance and the trial-clustered sandwich: the prior is one more independent measurement),
  which pins the direction along the c-k ridge the walks cannot see;
- a wheel parameter not fitted: fixed at the leg test's value instead of Table 1's;
- not a parameter of the wheel model (`guide_friction_n` before the model has guide friction): reported as
  measured by the leg test and not used by the walk model.

A leg fit that failed its checks is refused (`InputFileError`, naming the file and the check): its `checks`
not passed, `converged` false, or an interval of k or c reaching zero or below (older leg-fit outputs have no
`checks`; the last two still apply). The report says, per parameter, where its value came from: the leg test, the walks, or both (with the share of
the leg test in the final information, 1 / sd_prior^2 over the model-based 1 / se_calibrated^2), and flags a
calibrated value more than `CONFLICT_Z` prior sigmas from the leg test (the two measurements disagree).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from rimless.analysis.inference.identifiability import sandwich_se
from rimless.errors import InputFileError

__all__ = ["PRIOR_KEYS", "Prior", "LegPriors", "read_priors"]

Z95 = 1.959963984540054
#: leg-fit JSON key -> (WheelParams field, --fit name when the calibration knows it, unit)
PRIOR_KEYS = {
    "k_n_per_m": ("stiffness_n_per_m", "k", "N/m"),
    "c_n_s_per_m": ("damping_ns_per_m", "c", "N s/m"),
    "guide_friction_n": ("guide_friction_n", "guide_friction_n", "N"),
}
LEG_TEST_SHARE = 0.9  # above this share of the information, a value is "from the leg test"
WALK_SHARE = 0.1  # below it, "from the walks"
POSITIVE_KEYS = ("k_n_per_m", "c_n_s_per_m")  # a leg's k and c are > 0: an interval reaching zero is a failed fit
CONFLICT_Z = 3.0  # a calibrated value this many prior sigmas from the leg test: the two disagree


@dataclass
class Prior:
    """One leg-test result: the JSON key, the wheel field it informs, its mean and sd (SI)."""

    key: str
    field: str
    unit: str
    mean: float
    sd: float
    use: str = ""  # "penalty", "fixed", "not used by the walk model"
    index: int = -1  # the fitted global it constrains (penalty)

    @property
    def ci95(self) -> tuple[float, float]:
        return (self.mean - Z95 * self.sd, self.mean + Z95 * self.sd)


@dataclass
class LegPriors:
    """The priors of one leg-fit JSON, and how the calibration used them (`plan`, `attach`, `report`)."""

    path: Path
    leg: int | None
    priors: list[Prior]
    penalties: list[Prior] = field(default_factory=list)

    # --- before the calibration ------------------------------------------------------------------
    def plan(self, params: Any, fit_fields: list[str]) -> Any:
        """Decide each prior's use for a calibration of the WheelParams fields `fit_fields` starting from
        `params`; returns `params` with the unfitted ones fixed at the leg test's values."""
        fixed: dict[str, float] = {}
        self.penalties = []
        for p in self.priors:
            if not hasattr(params, p.field):
                p.use = "not used by the walk model"
            elif p.field in fit_fields:
                p.use, p.index = "penalty", fit_fields.index(p.field)
                self.penalties.append(p)
            else:
                p.use = "fixed"
                fixed[p.field] = p.mean
        return params.replace(**fixed) if fixed else params

    # --- inside the calibration (the hook of `calibrate`) -----------------------------------------
    def attach(self, obj: Any, glob: Any) -> None:
        """Append the penalty rows to the residuals and the Jacobian of the calibration's objective `obj` (its
        `fun(u)` and `jac(u, central=...)`; u holds the globals first, relative to `glob.x0` in units of
        `glob.scale`)."""
        if not self.penalties:
            return
        fun, jac = obj.fun, obj.jac
        idx = np.array([p.index for p in self.penalties])
        mean = np.array([p.mean for p in self.penalties])
        sd = np.array([p.sd for p in self.penalties])
        x0, scale = np.asarray(glob.x0, float)[idx], np.asarray(glob.scale, float)[idx]

        def rows(u: np.ndarray) -> np.ndarray:
            return (x0 + np.asarray(u, float)[idx] * scale - mean) / sd

        def fun_with_prior(u: np.ndarray) -> np.ndarray:
            return np.concatenate([fun(u), rows(u)])

        def jac_with_prior(u: np.ndarray, **kw: Any) -> np.ndarray:
            J = jac(u, **kw)
            P = np.zeros((idx.size, J.shape[1]))
            P[np.arange(idx.size), idx] = scale / sd
            return np.vstack([J, P])

        obj.fun, obj.jac = fun_with_prior, jac_with_prior

    def sandwich_se(
        self, J: np.ndarray, r: np.ndarray, offs: np.ndarray, n_global: int, scale: np.ndarray
    ) -> np.ndarray:
        """`identifiability.sandwich_se` with the prior rows (the last rows of J beyond offs[-1]) as one more
        measurement of known variance."""
        return sandwich_se(J, r, offs, n_global, scale, known_rows=True)

    # --- after the calibration ---------------------------------------------------------------------
    def report(self, calibration: Any | None, fit_fields: list[str], fit_names: list[str]) -> dict[str, Any]:
        """Where each parameter came from: the JSON of the calibration's `prior` section."""
        est = {e.field: e for e in calibration.params} if calibration is not None else {}
        rows = []
        for p in self.priors:
            row: dict[str, Any] = {
                "key": p.key,
                "field": p.field,
                "unit": p.unit,
                "leg_test": p.mean,
                "leg_test_ci": list(p.ci95),
                "use": p.use,
            }
            if p.use == "penalty":
                e = est.get(p.field)
                se = math.nan if e is None else (e.se_model if math.isfinite(e.se_model) else e.se)
                share = (p.sd**-2) / (se**-2) if math.isfinite(se) and se > 0 else math.nan
                share = min(share, 1.0) if math.isfinite(share) else share
                row["leg_test_share"] = share
                row["source"] = (
                    (
                        "leg test"
                        if share >= LEG_TEST_SHARE
                        else "walks"
                        if share <= WALK_SHARE
                        else "leg test and walks"
                    )
                    if math.isfinite(share)
                    else "leg test and walks"
                )
                if e is not None:
                    z = (e.value - p.mean) / p.sd
                    row["calibrated"], row["prior_z"] = e.value, z
                    if abs(z) > CONFLICT_Z:
                        row["conflict"] = (
                            f"the walks pull it {abs(z):.1f} sigma away from the leg test: they "
                            "disagree (another leg, a wrong moving mass, or what the walk model "
                            "leaves out)"
                        )
            elif p.use == "fixed":
                row["source"] = "leg test (fixed, not fitted)"
            else:
                row["source"] = "leg test only: not used by the walk model (no such parameter in it)"
            rows.append(row)
        with_prior = {p.field for p in self.priors}
        walks = [n for n, f in zip(fit_names, fit_fields) if f not in with_prior]
        return {"file": str(self.path), "leg": self.leg, "parameters": rows, "from_walks_only": walks}


def _refuse_failed_fit(p: Path, data: dict[str, Any]) -> None:
    """`InputFileError` for a leg fit that failed its checks (its `checks`, or `converged` false): such a fit
    is no measurement to pin a calibration with."""
    checks = data.get("checks")
    if checks is not None:
        if not isinstance(checks, dict) or not isinstance(checks.get("passed"), bool):
            raise InputFileError(f"--prior {p}: field 'checks' must be an object with 'passed' true or false")
        failed = [
            f"{name} ({v.get('found', '')})" if isinstance(v, dict) else name
            for name, v in checks.items()
            if name != "passed" and not (isinstance(v, dict) and v.get("passed") is True)
        ]
        if not checks["passed"] or failed:
            raise InputFileError(
                f"--prior {p}: the leg fit failed its check(s) {'; '.join(failed) or 'passed: false'}: not used as "
                "a prior (refit or repeat the leg test)"
            )
    if data.get("converged") is False:
        raise InputFileError(
            f"--prior {p}: the leg fit failed its check 'converged' (field 'converged' is false: the optimiser "
            "stopped on its budget): not used as a prior"
        )


def read_priors(path: Path | str) -> LegPriors:
    """Read a `rimless trials leg-fit --json` output; `InputFileError` names the file and the field."""
    p = Path(path)
    if not p.is_file():
        raise InputFileError(f"--prior {p}: no such file")
    try:
        data = json.loads(p.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError) as err:
        raise InputFileError(f"--prior {p}: cannot read ({err})") from None
    except json.JSONDecodeError as err:
        raise InputFileError(
            f"--prior {p}:{err.lineno}: not JSON ({err.msg}); expected the output of `rimless trials leg-fit --json`"
        ) from None
    if not isinstance(data, dict):
        raise InputFileError(f"--prior {p}: expected a JSON object (the output of `rimless trials leg-fit --json`)")
    _refuse_failed_fit(p, data)
    priors = []
    for key, (fld, _name, unit) in PRIOR_KEYS.items():
        if key not in data:
            continue
        value, ci = data[key], data.get(key + "_ci")
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise InputFileError(f"--prior {p}: field {key!r} must be a finite number, got {value!r}")
        if (
            not isinstance(ci, list)
            or len(ci) != 2
            or not all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in ci)
        ):
            raise InputFileError(f"--prior {p}: field {key + '_ci'!r} must be [lo, hi] (finite numbers), got {ci!r}")
        lo, hi = float(ci[0]), float(ci[1])
        if not lo < hi:
            raise InputFileError(f"--prior {p}: field {key + '_ci'!r} must have lo < hi, got {ci!r}")
        if not lo <= value <= hi:
            raise InputFileError(f"--prior {p}: field {key!r} {value!r} lies outside its interval {ci!r}")
        if key in POSITIVE_KEYS and lo <= 0:
            raise InputFileError(
                f"--prior {p}: the leg fit failed its check 'intervals_positive': field {key + '_ci'!r} {ci!r} "
                "reaches zero or below (the leg test did not determine it; refit or repeat the leg test)"
            )
        priors.append(Prior(key, fld, unit, float(value), (hi - lo) / (2 * Z95)))
    if not priors:
        raise InputFileError(
            f"--prior {p}: none of the fields {', '.join(PRIOR_KEYS)} (the output of `rimless trials leg-fit --json`)"
        )
    leg = data.get("leg")
    return LegPriors(p, leg if isinstance(leg, int) and not isinstance(leg, bool) else None, priors)
