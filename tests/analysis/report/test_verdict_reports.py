"""What the commands and the report say when the data do not support a result: one `error:` line with the
CLI's exit code; a report whose model does not fit says so and labels fitted values as fitted."""

from __future__ import annotations

import json
import math
from pathlib import Path
from types import SimpleNamespace

import pytest
from typer.testing import CliRunner

from rimless.analysis.examples.critical_series import data_files
from rimless.analysis.report.html import _critical_figure, _misfit_html, all_suspect, model_label
from rimless.cli import app
from tests.support.cli_lines import stderr_lines

runner = CliRunner()


def _stall_file() -> Path:
    (f,) = [p for p in data_files() if p.name == "SYNTHETIC_crit_slope1.30deg_release1.9.csv"]
    return f


def _error_line(res) -> str:
    lines = stderr_lines(res.stderr)
    assert "Traceback" not in res.output
    errors = [ln for ln in lines if ln.startswith("error: ")]
    assert len(errors) == 1, res.stderr
    return errors[0]


def test_report_of_its_own_metrics_csv_is_one_error(tmp_path):
    metrics = tmp_path / "metrics.csv"
    metrics.write_text("trial,status,slope_deg\na.csv,ok,1.5\n", encoding="utf-8")
    out = tmp_path / "rep"
    res = runner.invoke(app, ["trials", "report", str(metrics), "--out", str(out)])
    assert res.exit_code == 2, res.output
    assert "metrics.csv" in _error_line(res)
    assert not out.exists()  # no empty report left behind


@pytest.mark.slow
def test_calibrate_on_one_stalled_trial_says_c_is_not_identified():
    """One trial that stalled after one period: calibrated since session 21 (the period fixes its release speed,
    the stall says the next step never ends; it was refused as "fewer than two consecutive step periods"), and
    one trial cannot identify c: exit 0, c not identifiable, no traceback."""
    res = runner.invoke(app, ["trials", "calibrate", str(_stall_file()), "--no-critical", "--json"])
    assert res.exit_code == 0, res.output
    assert "Traceback" not in res.output
    (c,) = json.loads(res.stdout)["params"]
    assert c["name"] == "c" and c["identifiable"] is False and c["note"]


@pytest.mark.slow
def test_critical_slope_on_one_trial_is_one_error():
    res = runner.invoke(app, ["trials", "critical-slope", str(_stall_file())])
    assert res.exit_code == 1, res.output
    assert "no critical slope" in _error_line(res)


def test_calibrated_model_is_labelled_fitted():
    assert model_label("er") == "ER"
    lab = model_label("er_calibrated")
    assert lab.startswith("ER") and "these trials" in lab and "not a prediction" in lab


def _comp(status: str) -> SimpleNamespace:
    return SimpleNamespace(status=status, name="t.csv")


def test_every_trial_suspect_says_the_parameters_do_not_fit():
    res = SimpleNamespace(comparisons=[_comp("suspect"), _comp("suspect"), _comp("failed")], calibration=None)
    assert all_suspect(res)
    assert not all_suspect(SimpleNamespace(comparisons=[_comp("suspect"), _comp("ok")]))
    assert not all_suspect(SimpleNamespace(comparisons=[_comp("failed")]))
    text = _misfit_html(res)
    assert "do not fit these trials" in text and "No calibration" in text
    p = SimpleNamespace(name="c", unit="N s/m", value=11.2, se=0.3, table1=8.0, identifiable=True, note="")
    row = {
        "trial": "a/t.csv",
        "slope_deg": 1.6,
        "table1_rms_period_ms": 9.0,
        "calibrated_rms_period_ms": 1.0,
        "table1_rms_com_mm": 2.0,
        "calibrated_rms_com_mm": 0.3,
    }
    res.calibration = SimpleNamespace(params=[p], residuals=[row], converged=True)
    text = _misfit_html(res)
    assert 'id="misfit"' in text and "9.0" in text and "1.0" in text and "not predictions" in text


def test_critical_figure_draws_each_trials_slope_interval(tmp_path):
    rows = [
        {"file": f"t{i}", "slope_deg": s, "verdict": v, "slope_ci_deg": [s - 0.1, s + 0.1] if i else None}
        for i, (s, v) in enumerate([(1.2, "decaying"), (1.4, "decaying"), (1.6, "sustained"), (1.8, "sustained")])
    ]
    est = SimpleNamespace(method="bracket", value_deg=1.5, ci_deg=(1.3, 1.7))
    cr = SimpleNamespace(
        per_trial=rows,
        bracket_deg=(1.4, 1.6),
        logistic=None,
        estimates=[est],
        chosen=est,
        model={"critical_slope_deg": {"er": 1.26, "er_calibrated": 1.5, "ve": math.nan}},
    )
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib import pyplot as plt

    captured = {}
    orig = plt.Figure.savefig

    def grab(self, *a, **k):
        captured["fig"] = self
        return orig(self, *a, **k)

    plt.Figure.savefig = grab
    try:
        _critical_figure(cr, tmp_path / "c.png")
    finally:
        plt.Figure.savefig = orig
    assert (tmp_path / "c.png").stat().st_size > 0
    ax = captured["fig"].axes[0]
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert any("95 % slope interval" in t for t in labels)
    assert any("these trials" in t and "not a prediction" in t for t in labels)
    # three trials with an interval draw horizontal bars spanning 0.2 deg
    from matplotlib.collections import LineCollection

    spans = [seg[1][0] - seg[0][0] for c in ax.collections if isinstance(c, LineCollection) for seg in c.get_segments()]
    assert sum(1 for w in spans if abs(w - 0.2) < 1e-9) == 3


@pytest.mark.slow
def test_bundled_series_interval_covers_its_truth():
    """The bundled SYNTHETIC_crit series (truth model: ER wheel with c = 10 N s/m and guide friction)."""
    import json

    from rimless.analysis.examples.critical_series import load_truth

    res = runner.invoke(app, ["trials", "critical-slope", *[str(p) for p in data_files()], "--json"])
    assert res.exit_code == 0, res.output
    out = json.loads(res.stdout)
    truth = load_truth()["dataset"]["critical_slope_deg"]
    lo, hi = out["ci_deg"]
    assert lo <= truth <= hi, (out["method"], out["critical_slope_deg"], out["ci_deg"], truth)
    assert all(r["slope_sigma_deg"] > 0 for r in out["per_trial"])
