"""`trials report` pools step periods within a series by rounded slope (``--slope-bin-deg``): a bin holding trials
whose slopes differ beyond their 95 % intervals is warned about (one stderr line, the JSON's ``warnings`` and the
page), naming the trials and the option. Trials: two of the bundled SYNTHETIC critical series, simulated on 1.60
and 1.75 deg (their truth, analysis/data/critical), one series and one 0.5-deg bin (both round to 1.5 deg), both
walked (until session 23 1.45 and 1.60 deg: a stall and a walk, which the report no longer pools at all)."""

from __future__ import annotations

import json

from typer.testing import CliRunner

from rimless.analysis import import_trial
from rimless.analysis.examples.critical_series import DATA_DIR
from rimless.cli import app as root_app
from tests.support.cli_lines import stderr_lines

runner = CliRunner()
A = DATA_DIR / "SYNTHETIC_crit_slope1.60deg_release2.5.csv"
B = DATA_DIR / "SYNTHETIC_crit_slope1.75deg_release2.5.csv"


def _report(tmp_path, *extra: str):
    res = runner.invoke(
        root_app, ["trials", "report", str(A), str(B), "--out", str(tmp_path / "rep"), "--json", *extra]
    )
    assert res.exit_code in (0, 1), res.output  # 1: every trial suspect against Table 1 (the truth has c = 10)
    return res, json.loads(res.stdout)


def test_a_bin_pooling_slopes_beyond_their_intervals_is_warned(tmp_path):
    res, out = _report(tmp_path)
    ci = {f.name: import_trial(f).summary()["slope_ci_deg"] for f in (A, B)}
    assert ci[B.name][0] > ci[A.name][1]  # the importer's intervals are disjoint (the truths are 0.15 deg apart)
    (group,) = {(row["series"], row["slope_deg"]) for row in out["step_period_by_slope"]}
    assert group == ("SYNTHETIC_crit", 1.5)
    (warning,) = out["warnings"]
    assert A.name in warning and B.name in warning and "--slope-bin-deg 0.5" in warning
    assert f"warning: {warning}" in stderr_lines(res.stderr)
    assert "walked on slopes that differ" in (tmp_path / "rep" / "report.html").read_text()


def test_separate_bins_give_no_warning(tmp_path):
    res, out = _report(tmp_path, "--slope-bin-deg", "0.1")
    assert len({row["slope_deg"] for row in out["step_period_by_slope"]}) == 2
    assert out["warnings"] == [] and not any(ln.startswith("warning: ") for ln in stderr_lines(res.stderr))
