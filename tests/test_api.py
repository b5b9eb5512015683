"""The public Python API (docs/api.md): its tour runs, its results equal the commands' JSON, its names are pinned."""

from __future__ import annotations

import functools
import inspect
import json
import math
import re
import subprocess
import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

from rimless.cli import app

ROOT = Path(__file__).resolve().parents[1]
API_PAGE = ROOT / "docs" / "api.md"
SNAPSHOT = Path(__file__).with_name("api_signatures.txt")
TRIAL = ROOT / "analysis" / "data" / "SYNTHETIC_er_slope2.0deg_run1.csv"
runner = CliRunner()


def _cli_json(args: list[str]) -> dict:
    res = runner.invoke(app, [*args, "--json"])
    assert res.exit_code == 0, res.output
    return json.loads(res.stdout)


def _same(a: object, b: object, path: str = "") -> list[str]:
    """Where two JSON-like values differ (NaN equals NaN; floats must be equal, not close)."""
    if isinstance(a, dict) and isinstance(b, dict):
        return [d for k in a.keys() & b.keys() for d in _same(a[k], b[k], f"{path}.{k}")]
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        if len(a) != len(b):
            return [f"{path}: length {len(a)} != {len(b)}"]
        return [d for i, (x, y) in enumerate(zip(a, b)) for d in _same(x, y, f"{path}[{i}]")]
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
        return []
    return [] if a == b else [f"{path}: {a!r} != {b!r}"]


def _python_blocks(page: Path) -> list[str]:
    return re.findall(r"```python\n(.*?)```", page.read_text(encoding="utf-8"), re.S)


def test_the_readme_python_runs_as_written(monkeypatch: pytest.MonkeyPatch) -> None:
    (code,) = _python_blocks(ROOT / "README.md")
    monkeypatch.chdir(ROOT)
    namespace: dict[str, object] = {"__name__": "__readme__"}
    exec(compile(code, "README.md python block", "exec"), namespace)
    assert not _same(namespace["fp"].to_dict(), _cli_json(["sim", "fixed-point", "--k", "2500"]))  # type: ignore[attr-defined]


@pytest.mark.slow
def test_the_tour_runs_as_written(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    """Every python block of docs/api.md, in order, in one namespace, from the repository's root."""
    import matplotlib

    matplotlib.use("Agg")
    blocks = _python_blocks(API_PAGE)
    assert len(blocks) >= 5, "the tour lost its code"
    monkeypatch.chdir(ROOT)
    namespace: dict[str, object] = {"__name__": "__api_tour__"}
    for i, code in enumerate(blocks):
        exec(compile(code, f"docs/api.md block {i + 1}", "exec"), namespace)
    import matplotlib.pyplot as plt

    plt.close("all")
    # what the tour shows holds: the fixed point is one (P(z) = z), the frames have their columns
    assert namespace["sim"].steps_done == 4  # type: ignore[attr-defined]
    assert {"time_s", "com_height_m"} <= set(namespace["df"].columns)  # type: ignore[attr-defined]


def test_fixed_point_to_dict_equals_the_command_json() -> None:
    from rimless.sim import Wheel

    api = Wheel(model="er", stiffness_n_per_m=2500).fixed_point().to_dict()
    cli = _cli_json(["sim", "fixed-point", "--model", "er", "--k", "2500"])
    assert api.keys() == cli.keys()
    assert not _same(api, cli)
    # and it is the gait: P(z) = z on the same map, stable as reported
    wheel = Wheel(model="er", stiffness_n_per_m=2500)
    z = [api["theta_plus_rad"], api["theta_dot_plus_rad_s"]]
    assert max(abs(wheel.map(z) - z)) < 1e-9
    eig = [complex(*e) for e in api["eigenvalues"]]
    assert max(abs(e) for e in eig) == pytest.approx(api["max_abs_eigenvalue"], rel=1e-12)


def test_gaits_and_rigid_critical_slope_equal_the_command_json() -> None:
    from rimless.sim import Wheel

    assert not _same(
        Wheel(model="ve").gaits(guesses=4).to_dict(), _cli_json(["sim", "gaits", "--model", "ve", "--guesses", "4"])
    )
    rigid = Wheel(model="rigid").critical_slope()
    assert not _same(rigid.to_dict(), _cli_json(["sim", "critical-slope", "--model", "rigid"]))
    # Coleman's closed form by hand (model.md section 7, M = m_H): g(phi) = 0 at the reported slope
    mh, ic, l0, a = 1.892, 0.036, 0.237, math.pi / 4
    beta = (ic + mh * l0**2 * math.cos(a)) / (ic + mh * l0**2)
    phi = rigid.critical_slope_rad
    g = 1 - math.cos(phi) * math.cos(a / 2) - (1 + beta**2) / (1 - beta**2) * math.sin(phi) * math.sin(a / 2)
    assert abs(g) < 1e-12


@pytest.mark.slow
def test_sweep_gives_a_dataframe_that_agrees_with_the_critical_slope() -> None:
    """Two methods on one wheel: the sweep's pseudo-arclength branch end and Algorithm 1's refined end."""
    import pandas as pd

    from rimless.sim import Wheel, sweep

    df = sweep({"k": [2700.0]}, model="er")
    assert isinstance(df, pd.DataFrame)
    assert list(df["k"]) == [2700.0]
    assert df.attrs["computed"] + df.attrs["cached"] == 1
    cs = Wheel(model="er").critical_slope()
    assert df["reason"].iloc[0] == cs.reason == "stall"
    assert abs(df["critical_slope_rad"].iloc[0] - cs.critical_slope_rad) < 1e-6


def test_sweep_refuses_an_unknown_grid_name() -> None:
    from rimless.errors import ParameterError
    from rimless.sim import sweep

    with pytest.raises(ParameterError, match="stiffness"):
        sweep({"stiffness": [2000.0]})


def test_trial_to_frame_has_the_columns_and_the_values_of_its_parquet(tmp_path: Path) -> None:
    import numpy as np
    import pandas as pd

    from rimless.analysis import import_trial, read_trial

    trial = import_trial(TRIAL)
    frame = trial.to_frame()
    assert {"time_s", "com_height_m", "hub_x_m", "slope_y_m", "gap"} <= set(frame.columns)
    np.testing.assert_array_equal(frame["time_s"].to_numpy(), trial.time_s)
    stored = pd.read_parquet(trial.to_parquet(tmp_path / "t.parquet"))
    pd.testing.assert_frame_equal(frame, stored, check_like=False)
    assert read_trial(tmp_path / "t.parquet").to_frame().equals(frame)
    assert frame.attrs["meta"]["slope_deg"] == trial.meta.slope_deg
    assert len(repr(trial)) < 300


@pytest.mark.slow
def test_compare_equals_the_report_row(tmp_path: Path) -> None:
    from rimless.analysis import compare
    from rimless.sim import Wheel

    api = compare(TRIAL, Wheel(model="er")).to_dict()
    report = _cli_json(["trials", "report", str(TRIAL), "--out", str(tmp_path / "r")])
    (row,) = [r for r in report["trials"] if Path(str(r["trial"])).name == TRIAL.name]
    assert not _same(api, row)
    assert api["status"] == "ok"


def test_results_have_a_short_repr_and_the_wheel_refuses_bad_input() -> None:
    from rimless.errors import ParameterError
    from rimless.sim import Wheel

    fp = Wheel(model="er").fixed_point()
    assert len(repr(fp)) < 400 and "\n" not in repr(fp)
    assert "<table>" in fp._repr_html_()
    assert fp.step_period_s == fp["step_period_s"] == fp.to_dict()["step_period_s"]
    with pytest.raises(ParameterError, match="model"):
        Wheel(model="elastic")  # type: ignore[arg-type]
    with pytest.raises(ParameterError, match="compliant"):
        Wheel(model="rigid").fixed_point()
    with pytest.raises(ParameterError, match="stiffness_n_per_m"):
        Wheel(stiffness_n_per_m=-1.0)
    assert Wheel().with_params(slope_rad=0.03).params.slope_rad == 0.03
    assert Wheel(model="ve") == Wheel().with_model("ve")


def test_importing_the_api_stays_light() -> None:
    code = (
        "import sys\nimport rimless.sim, rimless.analysis\nfrom rimless.sim import Wheel\nWheel()\n"
        "print([m for m in ('numpy', 'scipy', 'pandas', 'matplotlib', 'numba') if m in sys.modules])"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


def _property_return(prop: property | functools.cached_property) -> str:
    """` -> 'annotation'` of a property's getter as `inspect.signature` spells returns, or '' when it has none."""
    getter = prop.fget if isinstance(prop, property) else prop.func
    ret = inspect.signature(getter).return_annotation if getter is not None else inspect.Signature.empty
    return "" if ret is inspect.Signature.empty else f" -> {ret!r}"


def _signatures() -> str:
    import rimless.analysis
    import rimless.sim

    lines = []
    for mod in (rimless.sim, rimless.analysis):
        assert sorted(mod.__all__) == sorted(mod._LAZY)  # type: ignore[attr-defined]
        for name in sorted(mod.__all__):
            obj = getattr(mod, name)
            if inspect.isclass(obj):
                lines.append(f"{mod.__name__}.{name} class")
                for meth, fn in sorted(vars(obj).items()):
                    if meth.startswith("_"):
                        continue
                    if isinstance(fn, (classmethod, staticmethod)):
                        # as called on the class (a classmethod's `cls` bound), and said which it is
                        kind = type(fn).__name__
                        lines.append(f"  {name}.{meth}{inspect.signature(getattr(obj, meth))} {kind}")
                    elif isinstance(fn, (property, functools.cached_property)):
                        lines.append(f"  {name}.{meth}{_property_return(fn)} {type(fn).__name__}")
                    elif callable(fn):
                        lines.append(f"  {name}.{meth}{inspect.signature(fn)}")
                if "__init__" in vars(obj):
                    lines.append(f"  {name}{inspect.signature(obj)}")
            elif callable(obj) and not hasattr(obj, "__origin__"):
                lines.append(f"{mod.__name__}.{name}{inspect.signature(obj)}")
            else:
                lines.append(f"{mod.__name__}.{name} = {obj!r}")
    return "\n".join(lines) + "\n"


def _public_class_and_static_methods() -> list[str]:
    """`Class.method` of every classmethod and staticmethod a public class defines, found apart from `_signatures`."""
    import rimless.analysis
    import rimless.sim

    found = []
    for mod in (rimless.sim, rimless.analysis):
        for name in mod.__all__:
            obj = getattr(mod, name)
            if inspect.isclass(obj):
                for meth in dir(obj):
                    static = inspect.getattr_static(obj, meth)
                    if (
                        not meth.startswith("_")
                        and meth in vars(obj)
                        and isinstance(static, (classmethod, staticmethod))
                    ):
                        found.append(f"{name}.{meth}")
    return found


def test_the_snapshot_pins_class_and_static_methods() -> None:
    """Alternate constructors are public names: `Wheel.from_input` and every other classmethod or staticmethod of a
    public class stand in the snapshot with their signatures (on main the snapshot left them out: `callable` is
    False for a classmethod object in a class's `__dict__`)."""
    now = _signatures()
    methods = _public_class_and_static_methods()
    assert "Wheel.from_input" in methods
    for qualified in methods:
        assert re.search(rf"^  {re.escape(qualified)}\(.* (classmethod|staticmethod)$", now, re.M), qualified


def _public_properties() -> dict[str, str]:
    """`Class.name` -> kind of every property and cached_property a public class defines, found apart from
    `_signatures` (from the class's attributes as `inspect.getmembers_static` lists them, its own only)."""
    import rimless.analysis
    import rimless.sim

    found = {}
    for mod in (rimless.sim, rimless.analysis):
        for name in mod.__all__:
            obj = getattr(mod, name)
            if not inspect.isclass(obj):
                continue
            for attr, value in inspect.getmembers_static(obj):
                if attr.startswith("_") or attr not in obj.__dict__:
                    continue
                if isinstance(value, property):
                    found[f"{name}.{attr}"] = "property"
                elif isinstance(value, functools.cached_property):
                    found[f"{name}.{attr}"] = "cached_property"
    return found


def test_the_snapshot_pins_properties() -> None:
    """Properties of public classes are public names (`WheelParams.slope_deg`, `CalibrationResult.identifiable`):
    each stands in the snapshot with its kind, and with its getter's return annotation when it has one (on main the
    snapshot left them out: `callable` is False for a property object in a class's `__dict__`)."""
    now = _signatures()
    props = _public_properties()
    assert {"WheelParams.slope_deg", "CalibrationResult.identifiable", "ClutchPower.is_zero"} <= set(props)
    for qualified, kind in props.items():
        assert re.search(rf"^  {re.escape(qualified)}( -> .+)? {kind}$", now, re.M), qualified
    # the annotation is the getter's own, as written in sim/model/electrical.py
    assert "  ClutchPower.is_zero -> 'bool' property\n" in now


def test_public_names_and_signatures_are_pinned() -> None:
    """The one deliberate snapshot: the public API. Changing it is a decision: update tests/api_signatures.txt
    (RIMLESS_UPDATE_API_SNAPSHOT=1 writes it) and say what changed in CHANGELOG.md."""
    import os

    now = _signatures()
    if os.environ.get("RIMLESS_UPDATE_API_SNAPSHOT") == "1":
        SNAPSHOT.write_text(now, encoding="utf-8")
    assert now == SNAPSHOT.read_text(encoding="utf-8"), "the public API changed: see this test's docstring"
