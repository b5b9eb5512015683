"""The paper's figures say what they show: a key for the phase shading (figure 1), a slope-normal force named
so (figure 2), integer step ticks and no requested curve dropped silently (figure 3), no legend entry without
a curve (figure 4)."""

import math

import numpy as np
import pytest

import rimless.sim.studies.figures as figures
from rimless.sim.studies import paper_figures


@pytest.fixture()
def drawn(monkeypatch):
    """The matplotlib figures the paper's figure functions save, kept open for inspection."""
    kept = []

    def keep(fig, path, dpi=150, *, option=None):
        kept.append(fig)
        return path

    monkeypatch.setattr(figures, "save_figure", keep)
    yield kept
    import matplotlib.pyplot as plt

    for fig in kept:
        plt.close(fig)


def _legend_labels(ax):
    legend = ax.get_legend()
    return [t.get_text() for t in legend.get_texts()] if legend is not None else []


def test_figure3_names_the_point_it_cannot_show_and_counts_steps_in_integers(drawn, tmp_path):
    rows = [
        {"model": m, "k": 2000.0, "step": i, "energy_ratio": 0.8 + 0.001 * i, "failure": ""}
        for m in ("ER", "VE")
        for i in range(1, 21)
    ]
    rows.append({"model": "VE", "k": 3500.0, "step": 0, "energy_ratio": math.nan, "failure": "no period-1 gait: stall"})
    paper_figures.figure_energy_ratio(rows, tmp_path)
    ve, er = drawn[0].axes
    texts = " ".join(t.get_text() for t in ve.texts)
    assert "3500" in texts and "no period-1 gait" in texts
    assert _legend_labels(ve) == ["k = 2000 N/m"]  # the missing k has no legend entry of its own
    drawn[0].canvas.draw()
    for ax in (ve, er):
        ticks = [t for t in ax.get_xticks() if ax.get_xlim()[0] <= t <= ax.get_xlim()[1]]
        assert ticks and all(float(t).is_integer() for t in ticks), ticks


def test_figure4_has_no_legend_entry_without_a_curve(drawn, tmp_path):
    slopes = np.radians(np.linspace(1.3, 2.9, 8))
    points = [
        {
            "model": m,
            "k": 2000.0,
            "branch": "b0",
            "branch_label": "er" if m == "ER" else "fast",
            "slope_rad": s,
            "slope_deg": math.degrees(s),
            "max_abs_eigenvalue": 0.5 + 0.1 * i,
            "contact_valid": True,
        }
        for m in ("ER", "VE")
        for i, s in enumerate(slopes)
    ]
    rows = [
        {"model": m, "k": 2000.0, "branch": "b0", "stable_at_start": True, "critical_slope_rad": slopes[0]}
        for m in ("ER", "VE")
    ]
    paper_figures.figure_eigenvalues(points, rows, tmp_path, ks=(2000.0,))
    for ax in drawn[0].axes:
        drawn_labels = {ln.get_label() for ln in ax.get_lines() if len(ln.get_xdata())}
        for label in _legend_labels(ax):
            assert label in drawn_labels, f"legend entry without a curve: {label!r}"
        assert "violates unilateral contact" not in _legend_labels(ax)


@pytest.fixture(scope="module")
def one_step_each():
    """One recorded step of each wheel from its period-1 gait at Table 1 (forces recorded)."""
    from rimless.sim.model.params import WheelParams
    from rimless.sim.step.backend import make_integrator, make_map
    from rimless.sim.step.gait import simulate_steps
    from rimless.sim.step.poincare import default_guess, solve_fixed_point

    p = WheelParams()
    out = {}
    for model in ("er", "ve"):
        fp = solve_fixed_point(make_map(p, model), default_guess(p, model), record=False)
        out[model] = simulate_steps(p, model, fp.z, 1, make_integrator("auto", 1e-10), record_dt=1e-3, forces=True)
    return out


def test_figure1_keys_the_phase_shading_and_figure2_says_slope_normal(drawn, tmp_path, one_step_each):
    paper_figures.figure_typical_gaits(one_step_each, tmp_path)
    ve_legs, er_legs = drawn[0].axes[0], drawn[0].axes[1]
    for ax in (ve_legs, er_legs):
        labels = _legend_labels(ax)
        assert any("double support" in t for t in labels) and any("single support" in t for t in labels), labels
    assert any("clutched" in t for t in _legend_labels(er_legs))
    paper_figures.figure_forces(one_step_each, tmp_path)
    for ax in drawn[1].axes:
        assert "slope-normal" in ax.get_ylabel() and "vertical" not in ax.get_ylabel()


def test_figure4_names_a_requested_k_without_a_curve(drawn, tmp_path):
    slopes = np.radians(np.linspace(1.3, 2.9, 5))
    points = [
        {
            "model": "ER",
            "k": 2000.0,
            "branch": "b0",
            "branch_label": "er",
            "slope_rad": s,
            "slope_deg": math.degrees(s),
            "max_abs_eigenvalue": 0.6,
            "contact_valid": True,
        }
        for s in slopes
    ]
    rows = [
        {"model": "ER", "k": 2000.0, "branch": "b0", "stable_at_start": True, "critical_slope_rad": slopes[0]},
        {"model": "VE", "k": 2000.0, "branch": "", "stable_at_start": False},
    ]
    assert paper_figures.missing_eigen_curves(rows, (2000.0,)) == [("VE", 2000.0)]
    paper_figures.figure_eigenvalues(points, rows, tmp_path, ks=(2000.0,))
    ve, er = drawn[0].axes
    assert "k = 2000" in " ".join(t.get_text() for t in ve.texts)
    assert not er.texts


@pytest.mark.parametrize("k", [2000.0, 3500.0])
def test_figure3_has_the_ve_wheel_where_newton_from_the_default_guess_fails(k):
    """VE at k = 2000 and 3500 N/m: Newton from the default guess fails, the gaits search finds the stable gait."""
    from rimless.sim.model.params import WheelParams
    from rimless.sim.studies.paper import energy_ratio_series

    rows = energy_ratio_series(WheelParams(), "auto", 1e-10, ks=(k,), steps=3)
    ve = [r for r in rows if r["model"] == "VE"]
    assert [r["step"] for r in ve] == [1, 2, 3], ve
    assert all(0.0 < r["energy_ratio"] < 1.0 for r in ve)
