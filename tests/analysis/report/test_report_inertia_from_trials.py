"""The report's wheel-parameter table names what the critical slope from the trials took from them (issue 31:
"the output never contradicts itself"). On a wheel whose inertia is not Table 1's (the independent truth model
`rimless.analysis.validation.critical_truth`, inertia ratio 1.8 against Table 1's 0.43) and no wheel file, the
critical slope holds the inertia the trials' step periods determine (JSON ``critical_slope.parameters``, source
``trials``; printed so by the command), while the page listed only Table 1's I_c = 0.036 kg m^2 as what was held.
"""

from __future__ import annotations

import html
import math
import re

import numpy as np

from rimless.analysis.report.html import build_report
from rimless.analysis.validation.critical_truth import Lab, LossyWheel, record, walk

ROW = re.compile(r'<tr class="parameter ([a-z-]+)"><td>(\S+) .*?<td class="n">([^<]+)</td>.*?data-source="([^"]+)"')


def test_the_inertia_from_the_trials_is_in_the_parameter_table(tmp_path):
    mass, leg = 2.4, 0.24
    wheel = LossyWheel(mass_kg=mass, inertia_hub_kg_m2=1.8 * mass * leg**2, leg_m=leg)
    rng = np.random.default_rng(3)
    files = []
    for slope in (1.8,):  # above the truth's critical slope (sustained): its periods fix the ratio
        phi = math.radians(slope)
        wk = walk(wheel, slope, 1.5 * math.sqrt(wheel.top_threshold(phi)), 10)
        files.append(tmp_path / f"wheelB_slope{slope}deg.csv")
        record(wk, files[-1], rng, Lab(up="z", heading_deg=40.0))
    res = build_report(files, tmp_path / "rep", import_kwargs={"max_gap_s": 0.05})
    crit = res.summary()["critical_slope"]
    used = {q["symbol"]: q for q in crit["parameters"]}
    assert used["I_c"]["source"] == "trials", used["I_c"]  # the premise: the estimate took the trials' inertia
    page = html.unescape(res.report_html.read_text())
    rows = [(role, sym, float(v), src) for role, sym, v, src in ROW.findall(page)]
    inertia = [r for r in rows if r[1] == "I_c"]
    assert ("held", "I_c", 0.036, "table1") in inertia, inertia  # the comparisons still hold Table 1's
    assert [(r[0], r[3]) for r in inertia if r[3] == "trials"] == [("from-trials", "trials")], inertia
    shown = next(r[2] for r in inertia if r[3] == "trials")
    assert math.isclose(shown, used["I_c"]["value"], rel_tol=1e-3), (shown, used["I_c"])
