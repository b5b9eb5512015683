"""Trial names in the tables: the common prefix is cut only at a ``_`` or ``-`` (hand-made cases)."""

from __future__ import annotations

from rimless.analysis.cli.names import names_shown


def test_prefix_never_ends_inside_a_number():
    names = ["SYNTHETIC_crit_slope1.30deg_release1.9", "SYNTHETIC_crit_slope1.30deg_release2.5"]
    shown, caption = names_shown(names)
    # os.path.commonprefix gives 'SYNTHETIC_crit_slope1.30deg_release' ending at '_': the cut keeps 'release...'
    assert (
        shown == ["release1.9", "release2.5"] and caption == "trial: the file name after 'SYNTHETIC_crit_slope1.30deg_'"
    )
    shown, _ = names_shown(["SYNTHETIC_crit_slope1.30deg_a", "SYNTHETIC_crit_slope1.45deg_a"])
    assert shown == ["slope1.30deg_a", "slope1.45deg_a"]  # the common 'slope1.' is not cut


def test_short_or_whole_prefix_is_kept():
    assert names_shown(["a_1", "a_2"]) == (["a_1", "a_2"], None)  # under 6 characters
    assert names_shown(["trial_run_", "trial_run_2"])[1] is None  # a name would be left empty
    assert names_shown(["only_one_name"]) == (["only_one_name"], None)
