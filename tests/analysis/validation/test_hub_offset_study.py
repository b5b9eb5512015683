"""`hub_offset_study`'s truth models: the ER wheel is walked by the independent truth (`er_truth.er_truth_walk`,
written apart from the simulator) unless told otherwise, and a bad option is one error line."""

from __future__ import annotations

import numpy as np
import pytest

from rimless.analysis.validation import er_truth, floquet_truth
from rimless.analysis.validation import hub_offset_study as study


class _Walked(Exception):
    """Raised by the stand-in walkers: which one the study called."""


def _stand_in(name: str):
    def walker(*args, **kwargs):
        raise _Walked(name)

    return walker


@pytest.mark.parametrize(
    ("model", "expected"), [(None, "independent"), ("independent", "independent"), ("simulator", "simulator")]
)
def test_the_er_wheel_is_walked_by_the_truth_model_named(monkeypatch, model, expected) -> None:
    monkeypatch.setattr(er_truth, "er_truth_walk", _stand_in("independent"))
    monkeypatch.setattr(study, "er_walk", _stand_in("simulator"))
    kwargs = {} if model is None else {"truth_model": model}
    for kind in ("er", "er-speed"):
        with pytest.raises(_Walked, match=f"^{expected}$"):
            study._truth_walk(kind, np.random.default_rng(0), False, **kwargs)
    assert floquet_truth.er_walk is not None  # the simulator's walker itself is untouched


def test_a_bad_truth_model_is_one_error_line(capsys) -> None:
    with pytest.raises(SystemExit) as exc:
        study.main(["--truth-model", "exact", "--draws", "1"])
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: --truth-model") and "independent" in err[0], err
    with pytest.raises(SystemExit) as exc:
        study.main(["--sets", "er,nope", "--draws", "1"])
    assert exc.value.code == 2
    assert capsys.readouterr().err.strip() == "error: --sets: unknown set 'nope', of er, er-table1, er-speed, rigid"
    with pytest.raises(ValueError, match="truth_model"):
        study.hub_offset_draw("er", 0, None, truth_model="exact")  # type: ignore[arg-type]
