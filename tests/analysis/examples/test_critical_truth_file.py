"""The critical series' truth file says what its truth's loss is: a constant force along the wheel's whole travel,
not the simulator's F_c (which acts over the legs' compression only; docs/trials.md "The demo's verdicts" and
critical/README.md say so). Its opening comment called it "a guide-friction force", and the file is what the demo
names to a user; the generator writes the same words (checked without regenerating the data)."""

from __future__ import annotations

import math
import tomllib

from rimless.analysis.examples.critical_series import DATA_DIR, truth_header


def test_the_truth_file_opens_with_the_generators_words_for_a_force_along_the_whole_travel():
    text = (DATA_DIR / "SYNTHETIC_crit_truth.toml").read_text(encoding="utf-8")
    head = truth_header()
    assert text.splitlines()[: len(head)] == head
    words = " ".join(line.lstrip("# ") for line in head)
    assert "guide-friction force" not in words
    assert "whole path" in words and "NOT the simulator's F_c" in words
    # the work per step it states is the one the README quotes, from the file's own numbers (Table 1's L0, alpha 45)
    force = tomllib.loads(text)["dataset"]["guide_friction_n"]
    assert f"{force} N" in words
    assert round(force * 2 * 0.237 * math.sin(math.radians(22.5)), 3) == 0.011
