"""`--slopes FILE` (a manifest ``file,slope_deg``) on `trials import` and `trials report`: the slope given per
file, `slope_source` given, one-line errors naming the manifest line, and not together with --slope-deg."""

from __future__ import annotations

import json

import pytest
from typer.testing import CliRunner

from rimless.analysis.examples.critical_series import DATA_DIR as CRIT_DIR
from rimless.cli import app as root_app

runner = CliRunner()
SHORT = CRIT_DIR / "SYNTHETIC_crit_slope1.45deg_release1.9.csv"
OTHER = CRIT_DIR / "SYNTHETIC_crit_slope1.30deg_release1.9.csv"


def test_manifest_gives_the_slope_of_listed_files(tmp_path):
    man = tmp_path / "slopes.csv"
    man.write_text(f"file,slope_deg\n# inclinometer\n{SHORT.name},1.45\n")
    res = runner.invoke(
        root_app, ["trials", "import", str(SHORT), str(OTHER), "--out", str(tmp_path), "--slopes", str(man), "--json"]
    )
    assert res.exit_code == 0, res.output
    rows = {r["file"].split("/")[-1]: r for r in json.loads(res.stdout)}
    a, b = rows[SHORT.name], rows[OTHER.name]
    assert a["slope_source"] == "given" and a["slope_deg"] == pytest.approx(1.45)
    assert a["slope_ci_deg"][0] < 1.45 < a["slope_ci_deg"][1]
    assert b["slope_source"] == "estimated" and b["slope_ci_deg"][0] <= b["slope_deg"] <= b["slope_ci_deg"][1]
    show = runner.invoke(root_app, ["trials", "show", a["trial"], "--json"])
    s = json.loads(show.stdout)
    assert s["slope_source"] == "given" and "manifest" in " ".join(s["notes"])
    assert s["slope_ci_deg"] == pytest.approx(a["slope_ci_deg"])


@pytest.mark.parametrize(
    "text, where",
    [
        ("file,slope\nx,1\n", ":1:1:"),
        ("file,slope_deg\nx,abc\n", ":2:2:"),
        ("file,slope_deg\nx,1\nx,2\n", ":3:1:"),
        ("", "empty"),
    ],
)
def test_bad_manifest_is_a_one_line_error(tmp_path, text, where):
    man = tmp_path / "m.csv"
    man.write_text(text)
    res = runner.invoke(root_app, ["trials", "import", str(SHORT), "--out", str(tmp_path), "--slopes", str(man)])
    assert res.exit_code == 2
    assert where in res.output and "Traceback" not in res.output


def test_not_with_slope_deg(tmp_path):
    man = tmp_path / "m.csv"
    man.write_text(f"file,slope_deg\n{SHORT.name},1.45\n")
    res = runner.invoke(
        root_app, ["trials", "import", str(SHORT), "--out", str(tmp_path), "--slopes", str(man), "--slope-deg", "2"]
    )
    assert res.exit_code == 2 and "--slopes" in res.output
