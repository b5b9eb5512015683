"""`write_report`'s own comparisons name what they held: `ReportResult.comparisons[i].to_dict()["parameters"]` are
the report's top-level `parameters` (they were None), and equal what `compare()` lists for the same trial and
wheel (an independent path: the public comparison of one trial)."""

from __future__ import annotations

from rimless.analysis import compare, write_report
from rimless.analysis.examples.bundled import data_files
from rimless.sim import Wheel


def test_the_reports_comparisons_list_the_wheels_parameters(tmp_path):
    trial = data_files()[0]  # SYNTHETIC bundled trial
    wheel = Wheel(uncertainty={"I_c": 0.0031})  # a stated sd away from the default
    res = write_report([trial], tmp_path / "rep", wheel)
    (comp,) = res.comparisons
    held = comp.to_dict()["parameters"]
    assert held is not None and held == res.to_dict()["parameters"]
    assert held == compare(trial, wheel).to_dict()["parameters"]
    inertia = next(p for p in held if p["name"] == "inertia_kg_m2")
    assert inertia["sd"] == 0.0031
