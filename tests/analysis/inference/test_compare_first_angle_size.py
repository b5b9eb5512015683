"""The size of the comparison's first-angle offset test (`compare.first_angle_test`, issue 31) on a truth with no
offset: the tests' compliant truth (`tests.support.analysis_trial_truth`, written apart from the comparison) held
on uncompressed legs at -alpha/2 and released: the comparison's own rigid release (true offset 0); c 2-20 N s/m,
k 1500-4000 N/m, slopes 1.5-3 deg, 10 steps, Tracker exports imported, the true slope and wheel given
(`first_angle_study.py --truth uncompressed --seed 7`, its first 20 draws).

At the nominal 1 % a test of the right size keeps the offset in 20 walks 3 times or more with probability 0.001
(binomial), and at 10 % 6 times or more with probability 0.011. On main (the importer's first impact at the gait's
phase, biased by -0.9 ms after this release) it kept 6 of these 20 at 1 % and 10 at 10 %; with the first impact at its
own touchdown, 0 and 1 (session 21)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from rimless.analysis.inference.compare import first_angle_test
from tests.analysis.inference.first_angle_study import no_offset_cases

pytestmark = [pytest.mark.slow, pytest.mark.full]


def test_first_angle_test_keeps_no_more_than_its_level_on_a_truth_without_offset(tmp_path: Path) -> None:
    ps = []
    for _trial, per, slope, sim, w0 in no_offset_cases(tmp_path):
        test = first_angle_test(sim, slope, per, w0)
        assert math.isfinite(test.p)
        ps.append(test.p)
    p = np.array(ps)
    assert p.size >= 18, p.size
    assert int((p < 0.01).sum()) <= 2, np.sort(p)
    assert int((p < 0.1).sum()) <= 5, np.sort(p)
