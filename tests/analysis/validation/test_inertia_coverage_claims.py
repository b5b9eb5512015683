"""The importer coverage study's inertia row counts coverage only over the ratios the import claims: an effective
pendulum's r (stance_inertia's "does not fit: effective only", session 20) is counted apart, never as a hit or a
miss of the wheel's r. Hand-built series, no import."""

from types import SimpleNamespace

from rimless.analysis.validation.importer_coverage import _inertia_row, summarise_inertia


def _inertia(r: float, se: float, effective: bool) -> dict:
    return {
        "estimated": True,
        "effective_only": effective,
        "inertia_ratio": r,
        "inertia_ratio_se": se,
        "inertia_ratio_at_held_leg_length": None,
        "inertia_ratio_at_held_leg_length_se": None,
    }


def test_effective_ratios_are_counted_apart() -> None:
    wheel = SimpleNamespace(inertia_ratio=0.43, leg_m=0.237, loss_j=0.01, inertia_foot=0.2)
    rows = [
        _inertia_row(_inertia(0.44, 0.02, False), wheel),  # claimed, covers (|0.01| <= 1.96 * 0.02)
        _inertia_row(_inertia(0.60, 0.02, False), wheel),  # claimed, misses
        _inertia_row(_inertia(1.56, 0.07, True), wheel),  # an effective pendulum: far off, not claimed
    ]
    series = [SimpleNamespace(results={"markers": {"inertia_from_trials": row}}) for row in rows]
    out = summarise_inertia(series, "markers")
    assert out["series"] == 3 and out["estimated"] == 2 and out["effective_only"] == 1
    assert out["covered"] == 1 and out["of"] == 2
    assert out["max_abs_error_pct"] < 100 * (0.60 / 0.43 - 1) + 1e-9  # the effective 1.56 is not among the errors
