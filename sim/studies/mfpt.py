"""Metastability on rough terrain: the mean first-passage time (`rimless sim mfpt`; Byl and Tedrake, IJRR 2009).

Each step's slope is drawn independently from a normal distribution N(slope_rad, sd_rad^2); the wheel starts at
the gait's fixed point z* of the nominal slope; `mfpt_steps` is the expected number of steps completed before
the first step that fails (any FailureReason). Slopes are limited to +-(alpha/2 - 0.01 rad), about 21.9 deg:
a slope drawn beyond is taken at the limit, in both methods (`slope_clip_probability`, the normal's mass there,
is reported; it is below 1e-9 for sd up to 3 deg at Table 1's slope). The map is P(z, slope) (rimless.sim.studies.section_map: each step
on one plane, the section point carried over).

Two methods:

- Monte Carlo: `walks` walks from z*, each until it fails or reaches `cap` steps. The estimate is the mean of
  the completed steps with a 95 % interval mean +- 1.96 s / sqrt(walks). Walks that reach the cap are counted
  (`capped_walks`) with `cap` steps: when there are any, the mean is a lower bound (`mfpt_is_lower_bound`).
- Mesh (a Markov chain on a discretised section): the nodes of an n_theta x n_theta_dot grid over a box of the
  section; each node is mapped under `slopes` slope values (the centres of equal-width bins over +-6 sd, each
  weighted by the normal's probability of its bin, the tails folded into the end bins); a failed step goes to
  the absorbing failure state, a successful one is shared among the four nodes around its image by bilinear
  weights (an image outside the box is moved to the box's edge; the largest such probability is reported).
  With Q the chain among the nodes, the expected number of transitions to absorption t solves (I - Q) t = 1;
  mfpt_steps = t(z*) - 1 (t interpolated at z* by the same weights; the failing step is not counted). Also
  reported: Q's largest eigenvalue lambda_2 and lambda_2 / (1 - lambda_2), the MFPT from the quasi-stationary
  distribution (Byl and Tedrake's measure). Where a node's outcome (fails or not) changes between neighbouring
  slope values, the slope where it changes is found by bisection and the two bins' common edge moved there, so
  the failure probability, which decides the MFPT, is not the midpoint rule's. The discretisation error is
  estimated by a second, coarser mesh (about 2/3 of the nodes per axis and of the slope values): for
  first-order convergence the fine mesh's error is 2 |fine - coarse| (`mfpt_discretisation_error_steps`), and
  `mfpt_extrapolated_steps` = fine + 2 (fine - coarse) (Richardson).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from rimless.errors import ParameterError, RunFailure
from rimless.sim.model.failures import StepFailure
from rimless.sim.model.params import SPOKE_ANGLE_RAD
from rimless.sim.studies.section_map import StepMap, apply, failure_fate

Z95 = 1.959963984540054
SLOPE_SPAN_SD = 6.0  # the slope bins cover +- this many standard deviations
RICHARDSON = 2.0  # error of the fine mesh = 2 |fine - coarse| for first-order convergence at spacing ratio 2/3
SWITCH_BISECTIONS = 12  # bisections for the slope where a node's step starts to fail
SLOPE_LIMIT_RAD = SPOKE_ANGLE_RAD / 2 - 0.01  # slopes beyond +- this (about 21.9 deg) are taken at it


def _check_sd(sd_rad: float) -> float:
    if not (isinstance(sd_rad, float | int) and math.isfinite(sd_rad) and sd_rad > 0):
        raise ParameterError(f"the terrain's standard deviation must be a number > 0, got {sd_rad!r}")
    return float(sd_rad)


def monte_carlo_mfpt(
    step_map: StepMap,
    slope_rad: float,
    sd_rad: float,
    z0: Any,
    *,
    walks: int = 200,
    cap: int = 10_000,
    seed: int = 0,
    progress: Callable[[int, int], None] | None = None,
) -> dict[str, Any]:
    """Monte Carlo MFPT of `step_map(z, slope)` from z0 with slopes ~ N(slope_rad, sd_rad^2)."""
    sd = _check_sd(sd_rad)
    if not (isinstance(walks, int) and 2 <= walks <= 10_000_000):
        raise ParameterError(f"walks must be an integer in [2, 10000000], got {walks!r}")
    if not (isinstance(cap, int) and 1 <= cap <= 100_000_000):
        raise ParameterError(f"cap must be an integer in [1, 100000000], got {cap!r}")
    rng = np.random.default_rng(seed)
    start = np.asarray(z0, dtype=float)
    lengths = np.zeros(walks, dtype=np.int64)
    capped = 0
    fates: dict[str, int] = {}
    for i in range(walks):
        z = start
        n = 0
        while n < cap:
            drawn = rng.normal(slope_rad, sd, size=min(256, cap - n))
            slopes = np.clip(drawn, -SLOPE_LIMIT_RAD, SLOPE_LIMIT_RAD)
            failed = False
            for s in slopes:
                try:
                    z = apply(step_map, z, float(s))
                except StepFailure as err:
                    fate = failure_fate(err)
                    fates[fate] = fates.get(fate, 0) + 1
                    failed = True
                    break
                n += 1
            if failed:
                break
        if n >= cap:
            capped += 1
        lengths[i] = n
        if progress is not None:
            progress(i + 1, walks)
    mean = float(lengths.mean())
    half = Z95 * float(lengths.std(ddof=1)) / math.sqrt(walks)
    return {
        "method": "monte-carlo",
        "mfpt_steps": mean,
        "mfpt_ci_steps": [mean - half, mean + half],
        "ci_level": 0.95,
        "walks": walks,
        "cap_steps": cap,
        "capped_walks": capped,
        "mfpt_is_lower_bound": capped > 0,
        "failures_by_reason": dict(sorted(fates.items())),
        "seed": seed,
        "map_evaluations": int(lengths.sum()) + walks - capped,
    }


def slope_nodes(slope_rad: float, sd_rad: float, n: int) -> tuple[np.ndarray, np.ndarray]:
    """(slopes, edges): the centres of n equal bins over slope +- 6 sd (within +-SLOPE_LIMIT_RAD) and the n + 1
    bin edges as the normal's CDF (0 and 1 at the ends: the tails are folded into the end bins)."""
    from scipy.stats import norm

    lo = max(-SLOPE_SPAN_SD, (-SLOPE_LIMIT_RAD - slope_rad) / sd_rad)
    hi = min(SLOPE_SPAN_SD, (SLOPE_LIMIT_RAD - slope_rad) / sd_rad)
    edges = np.linspace(lo, hi, n + 1)
    cdf = norm.cdf(edges)
    cdf[0], cdf[-1] = 0.0, 1.0
    centres = 0.5 * (edges[:-1] + edges[1:])
    return slope_rad + sd_rad * centres, cdf


def _switch_slope(step_map: StepMap, z: np.ndarray, a: float, b: float, a_fails: bool, iterations: int) -> float:
    """Bisection for the slope between a and b where the step's outcome (fails or not) changes."""
    for _ in range(iterations):
        m = 0.5 * (a + b)
        try:
            apply(step_map, z, m)
            fails = False
        except StepFailure:
            fails = True
        if fails == a_fails:
            a = m
        else:
            b = m
    return 0.5 * (a + b)


def clipped_probability(slope_rad: float, sd_rad: float) -> float:
    """The normal's probability beyond +-SLOPE_LIMIT_RAD (such slopes are taken at the limit)."""
    from scipy.stats import norm

    return float(norm.cdf((-SLOPE_LIMIT_RAD - slope_rad) / sd_rad) + norm.sf((SLOPE_LIMIT_RAD - slope_rad) / sd_rad))


def _axis_weights(x: float, lo: float, hi: float, n: int) -> tuple[list[int], list[float], bool]:
    """Linear-interpolation nodes and weights of x on n equal nodes over [lo, hi] (clamped; n = 1: one node)."""
    if n == 1:
        return [0], [1.0], False
    outside = not lo <= x <= hi
    u = (min(max(x, lo), hi) - lo) / (hi - lo) * (n - 1)
    i = min(int(u), n - 2)
    f = u - i
    return [i, i + 1], [1.0 - f, f], outside


def _weights(z: np.ndarray, box: Any, shape: tuple[int, int]) -> tuple[list[int], list[float], bool]:
    (t_lo, t_hi), (w_lo, w_hi) = box
    ti, tw, o1 = _axis_weights(float(z[0]), t_lo, t_hi, shape[0])
    wi, ww, o2 = _axis_weights(float(z[1]), w_lo, w_hi, shape[1])
    idx = [j * shape[0] + i for j in wi for i in ti]
    wts = [b * a for b in ww for a in tw]
    return idx, wts, o1 or o2


def mesh_mfpt_once(
    step_map: StepMap,
    slope_rad: float,
    sd_rad: float,
    z0: Any,
    box: Any,
    shape: tuple[int, int],
    slopes: int,
    progress: Callable[[int, int], None] | None = None,
) -> dict[str, Any]:
    """One mesh: the MFPT from z0 and the chain's lambda_2 (see the module's docstring)."""
    import scipy.sparse as sp
    import scipy.sparse.linalg as spla

    (t_lo, t_hi), (w_lo, w_hi) = box
    nt, nw = shape
    thetas = np.linspace(t_lo, t_hi, nt) if nt > 1 else np.array([0.5 * (t_lo + t_hi)])
    omegas = np.linspace(w_lo, w_hi, nw) if nw > 1 else np.array([0.5 * (w_lo + w_hi)])
    from scipy.stats import norm

    s_vals, cdf_edges = slope_nodes(slope_rad, sd_rad, slopes)
    n = nt * nw
    rows: list[int] = []
    cols: list[int] = []
    vals: list[float] = []
    outside_max = 0.0
    extra = 0
    for j in range(nw):
        for i in range(nt):
            k = j * nt + i
            z = np.array([thetas[i], omegas[j]])
            images: list[np.ndarray | None] = []
            for s in s_vals:
                try:
                    images.append(apply(step_map, z, float(s)))
                except StepFailure:
                    images.append(None)
            # where the outcome changes between neighbouring slopes, the bins' common edge moves to the slope
            # where it changes (bisection): the failure probability is not the midpoint rule's
            cdf = cdf_edges.copy()
            for q in range(slopes - 1):
                a_fails, b_fails = images[q] is None, images[q + 1] is None
                if a_fails != b_fails:
                    sw = _switch_slope(step_map, z, float(s_vals[q]), float(s_vals[q + 1]), a_fails, SWITCH_BISECTIONS)
                    extra += SWITCH_BISECTIONS
                    cdf[q + 1] = norm.cdf((sw - slope_rad) / sd_rad)
            out_mass = 0.0
            for q, zn in enumerate(images):
                pr = float(cdf[q + 1] - cdf[q])
                if zn is None or pr <= 0.0:
                    continue
                idx, wts, outside = _weights(zn, box, shape)
                if outside:
                    out_mass += pr
                rows.extend([k] * len(idx))
                cols.extend(idx)
                vals.extend(pr * w for w in wts)
            outside_max = max(outside_max, out_mass)
            if progress is not None:
                progress(k + 1, n)
    Q = sp.csr_matrix((vals, (rows, cols)), shape=(n, n))
    t = spla.spsolve((sp.identity(n, format="csc") - Q.tocsc()), np.ones(n))
    idx, wts, outside0 = _weights(np.asarray(z0, dtype=float), box, shape)
    if outside0:
        raise ParameterError("the start point z0 is outside the mesh's box")
    t0 = float(sum(w * t[i] for i, w in zip(idx, wts, strict=True)))
    lam2 = -1.0
    if n > 2:
        try:
            lam2 = float(np.max(np.real(spla.eigs(Q, k=1, which="LM", return_eigenvectors=False))))
        except spla.ArpackNoConvergence:
            if n > 4000:
                raise RunFailure("the mesh's largest eigenvalue did not converge (ARPACK)") from None
    if lam2 < 0:
        lam2 = float(np.max(np.abs(np.linalg.eigvals(Q.toarray()))))
    lam2 = min(lam2, 1.0 - 1e-300)
    return {
        "nodes": [nt, nw],
        "slopes": slopes,
        "mfpt_steps": t0 - 1.0,
        "lambda2": lam2,
        "mfpt_quasi_stationary_steps": lam2 / (1.0 - lam2),
        "max_probability_outside_box": outside_max,
        "map_evaluations": n * slopes + extra,
    }


def default_mesh_box(z_star: np.ndarray) -> tuple[tuple[float, float], tuple[float, float]]:
    """theta+ in z*_0 +- 0.08 rad, theta'+ in [0.02, 2.2] x theta'*."""
    th, w = float(z_star[0]), float(z_star[1])
    return ((th - 0.08, th + 0.08), (0.02 * w, 2.2 * w))


def mesh_mfpt(
    step_map: StepMap,
    slope_rad: float,
    sd_rad: float,
    z0: Any,
    *,
    box: Any = None,
    nodes: tuple[int, int] = (15, 60),
    slopes: int = 48,
    progress: Callable[[int, int], None] | None = None,
) -> dict[str, Any]:
    """MFPT from the mesh (Markov chain), with a coarser mesh for its discretisation error."""
    from rimless.sim.studies.basin import check_box

    sd = _check_sd(sd_rad)
    zs = np.asarray(z0, dtype=float)
    box = check_box(default_mesh_box(zs) if box is None else box)
    nt, nw = (int(v) for v in nodes)
    if not (1 <= nt <= 2000 and 2 <= nw <= 2000):
        raise ParameterError(f"mesh nodes must be n_theta in [1, 2000] and n_theta_dot in [2, 2000], got {nodes!r}")
    if not (isinstance(slopes, int) and 3 <= slopes <= 10_000):
        raise ParameterError(f"slopes must be an integer in [3, 10000], got {slopes!r}")
    coarse_shape = (max(1, round(nt * 2 / 3)) if nt > 1 else 1, max(2, round(nw * 2 / 3)))
    coarse_slopes = max(3, round(slopes * 2 / 3))
    n_fine = nt * nw * slopes
    n_all = n_fine + coarse_shape[0] * coarse_shape[1] * coarse_slopes

    def fine_progress(i: int, n: int) -> None:
        if progress is not None:
            progress(i * slopes, n_all)

    def coarse_progress(i: int, n: int) -> None:
        if progress is not None:
            progress(n_fine + i * coarse_slopes, n_all)

    fine = mesh_mfpt_once(step_map, slope_rad, sd, zs, box, (nt, nw), slopes, fine_progress)
    coarse = mesh_mfpt_once(step_map, slope_rad, sd, zs, box, coarse_shape, coarse_slopes, coarse_progress)
    diff = fine["mfpt_steps"] - coarse["mfpt_steps"]
    err = RICHARDSON * abs(diff)
    return {
        "method": "mesh",
        "mfpt_steps": fine["mfpt_steps"],
        "mfpt_extrapolated_steps": fine["mfpt_steps"] + RICHARDSON * diff,
        "mfpt_discretisation_error_steps": err,
        "mfpt_discretisation_error_relative": err / max(fine["mfpt_steps"], 1e-300),
        "lambda2": fine["lambda2"],
        "mfpt_quasi_stationary_steps": fine["mfpt_quasi_stationary_steps"],
        "box": {"theta_plus_rad": list(box[0]), "theta_dot_plus_rad_s": list(box[1])},
        "slope_span_sd": SLOPE_SPAN_SD,
        "fine": fine,
        "coarse": coarse,
        "map_evaluations": fine["map_evaluations"] + coarse["map_evaluations"],
    }


def mfpt_study(
    params: Any,
    model: str,
    sd_rad: float,
    *,
    method: str = "mesh",
    walks: int = 200,
    cap: int = 10_000,
    seed: int = 0,
    nodes: tuple[int, int] = (15, 60),
    slopes: int = 48,
    box: Any = None,
    backend: str = "auto",
    rtol: float = 1e-10,
    progress: Callable[[int, int], None] | None = None,
) -> dict[str, Any]:
    """The MFPT of the wheel's gait on terrain whose slope per step is N(params.slope_rad, sd_rad^2)."""
    from rimless.sim.studies.gaits import fixed_point_study
    from rimless.sim.studies.section_map import SlopeMap

    sd = _check_sd(sd_rad)
    if method not in ("mesh", "monte-carlo"):
        raise ParameterError(f"method must be mesh or monte-carlo, got {method!r}")
    fp = fixed_point_study(params, model, backend=backend, rtol=rtol)
    z_star = np.array([fp["theta_plus_rad"], fp["theta_dot_plus_rad_s"]])
    smap = SlopeMap(params, model, backend=backend, rtol=rtol)
    if method == "mesh":
        res = mesh_mfpt(smap, params.slope_rad, sd, z_star, box=box, nodes=nodes, slopes=slopes, progress=progress)
    else:
        res = monte_carlo_mfpt(smap, params.slope_rad, sd, z_star, walks=walks, cap=cap, seed=seed, progress=progress)
    return {
        "model": model,
        "slope_rad": params.slope_rad,
        "slope_deg": params.slope_deg,
        "terrain_sd_rad": sd,
        "terrain_sd_deg": math.degrees(sd),
        "terrain": "each step's slope drawn independently from N(slope, sd^2); the section point carries over",
        "slope_limit_rad": SLOPE_LIMIT_RAD,
        "slope_clip_probability": clipped_probability(params.slope_rad, sd),
        "start": {"theta_plus_rad": float(z_star[0]), "theta_dot_plus_rad_s": float(z_star[1])},
        **res,
    }
