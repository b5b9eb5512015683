"""Firmware in the loop: the robot's own detector and controller drive the simulated ER wheel.

Independent expectations: the ideal-clutch fixed point of the reference path (conftest), energy
conservation (start energy = end energy + every loss the simulation books), the physics of a late
lock (a lock after the compression peak stores less), and the firmware's source files on disk.
"""

import inspect
import json
import math
import types
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

import rimless.firmware.control.controller
import rimless.firmware.control.detector
import rimless.firmware.control.faults
import rimless.firmware.drivers.adns3080
import rimless.firmware.drivers.clutch
import rimless.firmware.drivers.fake_adns3080
from rimless.cli import app
from rimless.sim.in_the_loop import loop as loop_module
from rimless.sim.in_the_loop.loop import FirmwareLoop, FirmwareLoopConfig
from rimless.sim.integrate.reference import ScipyIntegrator
from rimless.sim.model import guards
from rimless.sim.model.clutch import Mode
from rimless.sim.model.dynamics import SLSP_FREE
from rimless.sim.model.failures import StepFailure
from rimless.sim.model.mechanics import Mechanics
from tests.support import sim_dip

REPO = Path(__file__).resolve().parents[3]
FIRMWARE_MODULES = [
    rimless.firmware.drivers.adns3080,
    rimless.firmware.drivers.clutch,
    rimless.firmware.control.controller,
    rimless.firmware.control.detector,
    rimless.firmware.drivers.fake_adns3080,
    rimless.firmware.control.faults,
]
QUIET = dict(jitter_s=0.0, noise_counts=0.0)


def _walk(params, z, steps, **cfg):
    loop = FirmwareLoop(params, FirmwareLoopConfig(**cfg))
    try:
        return loop, loop.walk(z, steps)
    finally:
        loop.close()


# --- the same firmware code runs on the robot and in the loop --------------------------------------


def _code_objects(path: Path) -> dict[str, bytes]:
    """qualname -> bytecode of every function compiled from the file on disk."""
    out: dict[str, bytes] = {}

    def walk(code: types.CodeType) -> None:
        for const in code.co_consts:
            if isinstance(const, types.CodeType):
                out[const.co_qualname] = const.co_code
                walk(const)

    walk(compile(path.read_text(), str(path), "exec"))
    return out


def _patched_functions(module: types.ModuleType) -> tuple[list[str], int]:
    """(qualnames of the module's functions whose bytecode is not the one compiled from its file on disk,
    how many functions were checked)."""
    path = Path(inspect.getsourcefile(module))
    patched, checked = [], 0
    for qualname, code in _code_objects(path).items():
        if "<" in qualname:
            continue  # nested functions and comprehensions live inside the checked ones
        obj = module
        for part in qualname.split("."):
            obj = inspect.getattr_static(obj, part)
        if inspect.isclass(obj):
            continue  # a class body
        fn = getattr(obj, "__func__", getattr(obj, "fget", obj))
        if fn.__code__.co_code != code:
            patched.append(qualname)
        checked += 1
    return patched, checked


def test_the_loop_runs_the_firmware_files_unpatched(table1, er_fixed_point):
    """Every function of the firmware modules the loop uses is the one compiled from firmware/**.py,
    the loop's objects are instances of those classes, and no instance overrides a method."""
    loop, walk = _walk(table1, er_fixed_point[1].z, 1)
    for module in FIRMWARE_MODULES:
        path = Path(inspect.getsourcefile(module))
        assert path.is_relative_to(REPO / "firmware"), path
        patched, checked = _patched_functions(module)
        assert not patched, f"{module.__name__}: {patched} are not the code in {path}"
        assert checked >= 3
    expected = {
        "controller": rimless.firmware.control.controller.Controller,
        "detector": rimless.firmware.control.detector.LegDetector,
        "sensor": rimless.firmware.drivers.adns3080.Adns3080,
        "fake": rimless.firmware.drivers.fake_adns3080.FakeAdns3080,
        "clutches": rimless.firmware.drivers.clutch.ClutchBank,
    }
    for attr, cls in expected.items():
        obj = getattr(loop, attr)
        assert type(obj) is cls, attr
        shadowed = [k for k in vars(obj) if inspect.isfunction(inspect.getattr_static(type(obj), k, None))]
        assert not shadowed, f"{attr}: instance attributes replace methods {shadowed}"
    assert loop.controller.channels[0].detector is loop.detector and loop.controller.channels[0].sensor is loop.sensor
    names = [name for _, name, _ in walk.events]
    assert "touchdown" in names and "lock" in names and loop.fake.motion_reads == loop.samples > 0


def test_a_patched_firmware_function_is_detected(monkeypatch):
    """The check above (`_patched_functions`, run here) reports a replaced firmware method (guards the guard)."""
    module = rimless.firmware.control.detector
    assert _patched_functions(module)[0] == []

    def update(self, t_ns, displacement_m, trusted=True):
        return module.NOTHING

    monkeypatch.setattr(module.LegDetector, "update", update)
    assert _patched_functions(module)[0] == ["LegDetector.update"]


def test_no_simulator_module_copies_firmware_code():
    """Distinctive lines of the firmware's decision code appear only in firmware/."""
    markers = [
        line.strip()
        for line in Path(inspect.getsourcefile(rimless.firmware.control.detector)).read_text().splitlines()
        if line.strip().startswith(("det = s0 *", "det_b = s0 *", "det_c = s0 *", "armed = self._peak_v"))
    ]
    markers += ["def _step_channel(", "class VelocityEstimator", "class LegDetector", "def _latch(self)"]
    assert len(markers) >= 8
    for path in (REPO / "sim").rglob("*.py"):
        text = path.read_text()
        for marker in markers:
            assert marker not in text, f"{path} contains firmware code: {marker!r}"


# --- guards: the one table and the one engine ---------------------------------------------------------


def test_the_loop_numbers_its_guards_by_the_table(monkeypatch, table1, er_fixed_point):
    """The loop's guard codes are the table's (rimless.sim.model.guards) and every guard it asks the event
    engine for is a row of the table. Fails on ebb1b78: loop.py numbered its own guards (TOUCHDOWN = 0,
    STALL = 1, ...) against the table's TOUCHDOWN = 3, and had no foot-a / slip / stick rows in the table."""
    for name in (
        "TOUCHDOWN",
        "STALL",
        "LIFTOFF_A",
        "LIFTOFF_B",
        "FOOT_A_DOWN",
        "SLIP_END_1",
        "SLIP_END_2",
        "STICK_END_1",
        "STICK_END_2",
    ):
        assert getattr(loop_module, name) == getattr(guards, name), name
    asked: set[int] = set()
    engine = loop_module.EventLocator

    def spy(codes, *args, **kwargs):
        asked.update(codes)
        return engine(codes, *args, **kwargs)

    monkeypatch.setattr(loop_module, "EventLocator", spy)
    _, walk = _walk(table1, er_fixed_point[1].z, 2, **QUIET)
    assert walk.failure is None
    assert {guards.TOUCHDOWN, guards.STALL, guards.LIFTOFF_B} <= asked <= set(guards.TABLE)


def test_the_loop_locates_a_stance_force_dip_between_solver_steps():
    """A stance normal force that dips below zero and recovers inside one solver step (tests.support.sim_dip)
    ends the loop's single-support phase at the dip, where the reference path ends it. Fails on ebb1b78: the
    loop tested the sign at step ends only and ran on to the touchdown."""
    mech = Mechanics.of(sim_dip.DIP_PARAMS)
    t1, y1 = sim_dip.single_support_start()
    codes = (guards.TOUCHDOWN, guards.STALL, guards.LIFTOFF_B)
    loop = FirmwareLoop(sim_dip.DIP_PARAMS, FirmwareLoopConfig(**QUIET))
    try:
        kind, code, t, y, *_ = loop.integrate_mode(Mode(foot_a=False), y1, t1, t1 + 5.0, codes, 0.0)
    finally:
        loop.close()
    ref = ScipyIntegrator(rtol=loop.rtol, atol=loop.atol).run_phase(mech, SLSP_FREE, y1, t1, codes, 5.0)
    assert ref.guard == guards.LIFTOFF_B
    assert (kind, code) == ("guard", guards.LIFTOFF_B)
    assert t == pytest.approx(ref.t_end, abs=1e-6)
    assert guards.guard_value(mech, SLSP_FREE, guards.LIFTOFF_B, y) == pytest.approx(0.0, abs=1e-6)  # N


# --- physics ----------------------------------------------------------------------------------------


def test_energy_budget_closes_with_delays_noise_and_slip(table1, er_fixed_point):
    """E(start) - damper - clutch slip/lock - foot-a re-contact - impact = E(end), step by step."""
    _, walk = _walk(
        table1, er_fixed_point[1].z, 3, rate_hz=300.0, engage_delay_s=0.005, release_delay_s=0.005, noise_counts=1.0
    )
    assert walk.failure is None and len(walk.steps) == 3
    for s in walk.steps:
        assert abs(s.energy_residual_J) < 1e-7, s.energy_residual_J
        assert s.damper_J > 0 and s.impact_loss_J > 0 and s.clutch_loss_J >= 0 and s.recontact_loss_J >= 0
        assert s.lock_class in ("compression", "peak", "rebound")
        # a 5 ms engage delay at 300 Hz locks after the peak: L1' > 0 (extending) at the lock
        assert s.lock_rate_m_s > 0 and s.lock_time_s > s.peak_time_s
    # the trailing clutch lets go only after the firmware has seen the touchdown and 5 ms have passed
    assert all(s.release_lateness_s > 0.005 for s in walk.steps[1:])


def test_added_delay_lowers_the_stored_energy_monotonically(table1, er_fixed_point):
    stored = []
    for delay in (0.0, 0.005, 0.010, 0.020):
        _, walk = _walk(
            table1, er_fixed_point[1].z, 1, rate_hz=1000.0, engage_delay_s=delay, release_delay_s=0.0, **QUIET
        )
        assert walk.failure is None
        stored.append(walk.steps[0].stored_energy_J)
    ideal = 0.5 * table1.k * (table1.leg_length_m - er_fixed_point[1].step.y_minus[3]) ** 2
    assert stored[0] == pytest.approx(ideal, rel=0.02)
    assert all(a > b for a, b in zip(stored, stored[1:])), stored
    assert stored[-1] < 0.9 * ideal


@pytest.mark.parametrize("delay_s", [0.1, 0.4])
def test_a_delay_longer_than_the_compression_phase_is_classified(table1, er_fixed_point, delay_s):
    """Compression lasts about 70 ms here; a 100 ms clutch locks in the rebound (or not at all before
    touchdown), a 400 ms clutch acts a step late. Either way every step is classified; the wheel walks on
    (both walk the 3 steps: a regression snapshot of ebb1b78)."""
    _, walk = _walk(
        table1, er_fixed_point[1].z, 3, rate_hz=300.0, engage_delay_s=delay_s, release_delay_s=delay_s, **QUIET
    )
    assert walk.failure is None and len(walk.steps) == 3, walk.failure
    ideal = 0.5 * table1.k * (table1.leg_length_m - er_fixed_point[1].step.y_minus[3]) ** 2  # locked at the peak
    for s in walk.steps:
        assert s.lock_class in ("rebound", "after-rebound", "none")
        assert math.isfinite(s.period_s) and abs(s.energy_residual_J) < 1e-7
        assert s.stored_energy_J < 0.8 * ideal


def test_a_rigid_clutch_late_release_is_classified_not_a_crash(table1, er_fixed_point):
    """The firmware releases the trailing clutch only after it saw the touchdown, so a rigid clutch (no slip)
    is still locked at the impact: the walk ends with a classified failure, not an exception."""
    _, walk = _walk(table1, er_fixed_point[1].z, 3, holding_force_N=math.inf, **QUIET)
    assert isinstance(walk.failure, StepFailure), walk.steps
    assert walk.failure.reason.value in ("negative-impulse", "stall", "stance-lift-off")


def test_bad_configuration_names_the_field(table1):
    with pytest.raises(ValueError, match="rate_hz"):
        FirmwareLoopConfig(rate_hz=0.0).validated()
    with pytest.raises(ValueError, match="engage_delay_s"):
        FirmwareLoopConfig(engage_delay_s=float("nan")).validated()


# --- CLI --------------------------------------------------------------------------------------------

RUN = CliRunner()


def test_cli_gait_with_the_firmware_clutch_reports_fixed_point_and_energy():
    res = RUN.invoke(
        app,
        [
            "sim",
            "gait",
            "--clutch",
            "firmware",
            "--rate-hz",
            "300",
            "--clutch-delay-ms",
            "5",
            "--noise-counts",
            "1",
            "--steps",
            "6",
            "--json",
        ],
    )
    assert res.exit_code == 0, res.output
    out = json.loads(res.stdout)
    assert out["steps_done"] == 6 and out["failure"] is None
    fp = out["fixed_point"]
    assert fp["theta_dot_plus_rad_s"] < out["ideal"]["theta_dot_plus_rad_s"]
    assert 0 < fp["stored_energy_J"] < out["ideal"]["stored_energy_J"]
    assert out["energy_residual_max_J"] < 1e-7
    assert set(out["lock_classes"]) <= {"compression", "peak", "rebound", "after-rebound", "none"}


@pytest.mark.parametrize(
    "args, flag",
    [
        (["--rate-hz", "0"], "--rate-hz"),
        (["--clutch-delay-ms", "-1"], "--clutch-delay-ms"),
        (["--model", "ve"], "--model er"),
    ],
)
def test_cli_firmware_bad_options_are_one_line_errors(args, flag):
    res = RUN.invoke(app, ["sim", "gait", "--clutch", "firmware", *args])
    assert res.exit_code == 2
    assert flag in res.output and "Traceback" not in res.output


def test_sim_sweep_firmware_orders_the_cost_of_delay_and_caches_points(tmp_path):
    """`sim sweep --clutch firmware` over delays at one rate: speed and stored energy fall as the clutch gets
    slower; the table is written; a re-run on an extended grid computes only the new point, and its cached
    rows are the first run's."""
    import pandas as pd

    base = [
        "sim",
        "sweep",
        "--clutch",
        "firmware",
        "--rate-hz",
        "300",
        "--steps",
        "6",
        "--scheduler",
        "sync",
        "--cache-dir",
        str(tmp_path / "cache"),
        "--out",
        str(tmp_path / "fw"),
        "--json",
    ]
    res = RUN.invoke(app, base + ["--clutch-delay-ms", "0,10"])
    assert res.exit_code == 0, res.output
    first = json.loads(res.stdout)
    assert first["computed"] == 2 and first["cached"] == 0
    fast, slow = first["rows"]
    assert (fast["delay_ms"], slow["delay_ms"]) == (0.0, 10.0)
    assert fast["walks"] and slow["walks"]
    assert 0 < slow["speed_ratio"] < fast["speed_ratio"] < 1.0
    assert 0 < slow["stored_energy_ratio"] < fast["stored_energy_ratio"] < 1.0
    table = pd.read_csv(tmp_path / "fw.csv")
    assert list(table["delay_ms"]) == [0.0, 10.0] and (tmp_path / "fw.parquet").stat().st_size > 0
    res = RUN.invoke(app, base + ["--clutch-delay-ms", "0:10:5"])
    assert res.exit_code == 0, res.output
    second = json.loads(res.stdout)
    assert second["computed"] == 1 and second["cached"] == 2
    assert [r["delay_ms"] for r in second["rows"]] == [0.0, 5.0, 10.0]
    assert second["rows"][0] == fast and second["rows"][2] == slow
    assert fast["stored_energy_ratio"] > second["rows"][1]["stored_energy_ratio"] > slow["stored_energy_ratio"]


@pytest.mark.parametrize(
    "args, flag",
    [
        (["--clutch", "firmware", "--k", "2500,2700"], "--k"),
        (["--clutch", "firmware", "--rate-hz", "0"], "--rate-hz"),
        (["--clutch", "firmware", "--clutch-delay-ms", "a"], "--clutch-delay-ms"),
        (["--rate-hz", "300"], "--rate-hz"),
        (["--clutch", "firmware", "--model", "ve"], "--model"),
    ],
)
def test_sim_sweep_firmware_bad_options_are_one_line_errors(args, flag, tmp_path):
    res = RUN.invoke(app, ["sim", "sweep", "--out", str(tmp_path / "x"), *args])
    assert res.exit_code == 2 and flag in res.output and "Traceback" not in res.output, res.output


def test_firmware_sweep_alias_still_answers(table1):
    """The old command runs the same grid code: one point, the old JSON keys."""
    res = RUN.invoke(
        app,
        [
            "sim",
            "firmware-sweep",
            "--rates-hz",
            "1000",
            "--delays-ms",
            "0",
            "--steps",
            "6",
            "--scheduler",
            "sync",
            "--json",
        ],
    )
    assert res.exit_code == 0, res.output
    out = json.loads(res.stdout)
    assert {"ideal", "rows", "steps", "noise_counts", "plot"} <= set(out)
    (row,) = out["rows"]
    assert row["rate_hz"] == 1000.0 and row["walks"] and 0.8 < row["stored_energy_ratio"] < 1.0


def test_the_figure_of_a_sweep_with_critical_slopes_shows_the_advantage_kept(tmp_path):
    """add_advantage: share of the ideal ER's CoT saving over VE that remains, from hand-made rows."""
    from rimless.sim.in_the_loop.sweep import add_advantage, plot_firmware_sweep

    rows = [{"clutch": "ideal", "model": "er", "cot": 0.02}, {"clutch": "none (VE)", "model": "ve", "cot": 0.03}]
    rows += [
        {
            "clutch": "firmware",
            "rate_hz": 300.0,
            "delay_ms": d,
            "walks": True,
            "cot": cot,
            "stored_energy_ratio": 0.9,
            "max_abs_eigenvalue_fitted": 0.7,
            "limited_by": by,
        }
        for d, cot, by in ((0.0, 0.025, "mechanics"), (5.0, 0.03, "firmware"), (10.0, 0.035, "mechanics"))
    ]
    refs = add_advantage(rows)
    assert refs["er_ideal"]["cot_saving_vs_ve"] == pytest.approx(1 / 3)
    assert [r["er_advantage_remaining"] for r in rows[2:]] == pytest.approx([0.5, 0.0, -0.5])
    fig = plot_firmware_sweep({"rows": rows, "ideal": {"max_abs_eigenvalue": 0.79}}, tmp_path / "f.png")
    assert fig.stat().st_size > 1000


def test_cli_firmware_sweep_rejects_a_bad_scheduler_and_rate():
    res = RUN.invoke(app, ["sim", "firmware-sweep", "--rates-hz", "0"])
    assert res.exit_code == 2 and "--rates-hz" in res.output


# --- replay of a trial log --------------------------------------------------------------------------


def test_replay_of_a_trial_log_written_by_the_firmware_logger(table1, er_fixed_point, tmp_path):
    """A walk's controller records go through the firmware's own TrialLog writer; the replay finds the same
    steps: recorded periods (touchdown event to touchdown event) equal the simulated periods to a few
    sample periods, and the recorded compression is the simulated one to a few counts."""
    from rimless.firmware.service.triallog import TrialLog
    from rimless.sim.in_the_loop.replay import replay_trial

    loop = FirmwareLoop(table1, FirmwareLoopConfig(rate_hz=1000.0, engage_delay_s=0.0, release_delay_s=0.0, **QUIET))
    loop.records = []
    walk = loop.walk(er_fixed_point[1].z, 4)
    loop.close()
    log = TrialLog(tmp_path, "sim-walk")
    log.append(loop.records)
    log.close()
    rep = replay_trial(log.path, table1)
    # touchdown events: the priming step's impact and each step's but the last (detected after the walk ends)
    assert len(rep.steps) == 3
    for rec, sim in zip(rep.steps, walk.steps):
        assert rec.recorded_period_s == pytest.approx(sim.period_s, abs=3e-3)
    ideal_max = rep.sim_max_compression_m
    assert rep.steps[1].recorded_max_compression_m == pytest.approx(ideal_max, rel=0.1)
    assert all(s.recorded_lock_s is not None for s in rep.steps)
    assert rep.firmware is None


def test_replay_overlays_the_step_under_the_firmware_in_the_loop(table1, er_fixed_point, tmp_path):
    """Replayed with the configuration the log was made with, the firmware-in-the-loop step is the recorded
    gait: its period is the recorded one, its lock command comes after the impact by the recorded lock time
    after the touchdown event plus the touchdown's detection lag (a few samples), its peak compression is
    the recorded one, and the stance clutch is engaged from the lock on."""
    from rimless.firmware.service.triallog import TrialLog
    from rimless.sim.in_the_loop.replay import FIRMWARE_STEPS, replay_trial

    cfg = FirmwareLoopConfig(rate_hz=1000.0, engage_delay_s=0.002, release_delay_s=0.002, **QUIET)
    loop = FirmwareLoop(table1, cfg)
    loop.records = []
    walk = loop.walk(er_fixed_point[1].z, FIRMWARE_STEPS + 1)
    loop.close()
    log = TrialLog(tmp_path, "fw-walk")
    log.append(loop.records)
    log.close()
    rep = replay_trial(log.path, table1, firmware_config=cfg)
    fw = rep.firmware
    assert fw is not None and fw.failure is None
    rec = rep.steps[FIRMWARE_STEPS - 1]  # the recorded step that is the replay's last firmware step
    assert fw.period_s == pytest.approx(walk.steps[FIRMWARE_STEPS - 1].period_s, abs=1e-9)
    assert fw.period_s == pytest.approx(rec.recorded_period_s, abs=3e-3)
    lag = fw.lock_command_s - rec.recorded_lock_s
    assert 0.0 < lag < 0.01, lag
    assert fw.lock_s == pytest.approx(fw.lock_command_s + 0.002, abs=1.5e-3)
    assert fw.compression_m.max() == pytest.approx(rec.recorded_max_compression_m, rel=0.05)
    # what the firmware integrated is the true compression to a count or two (1 count = 1/62992 m)
    n = min(len(fw.t), len(fw.sensed_compression_m))
    assert np.max(np.abs(fw.sensed_compression_m[:n] - fw.compression_m[:n])) < 3 / 62992
    on = fw.t[fw.stance_engaged]
    assert on.size and on.min() >= fw.lock_s - 1e-9
    summary = rep.summary()["firmware_in_the_loop"]
    assert summary["simulated_period_s"] == fw.period_s and summary["lock_class"] == fw.lock_class


def test_cli_replay_reports_and_plots_and_rejects_a_corrupt_log(table1, er_fixed_point, tmp_path):
    from rimless.firmware.service.triallog import TrialLog

    loop = FirmwareLoop(table1, FirmwareLoopConfig(rate_hz=300.0, **QUIET))
    loop.records = []
    loop.walk(er_fixed_point[1].z, 3)
    loop.close()
    log = TrialLog(tmp_path, "t")
    log.append(loop.records)
    log.close()
    fig = tmp_path / "replay.png"
    res = RUN.invoke(app, ["sim", "replay", str(log.path), "--plot", str(fig), "--json"])
    assert res.exit_code == 0, res.output
    out = json.loads(res.stdout)
    assert out["steps"] == 2 and fig.stat().st_size > 1000 and out["plot"] == str(fig)
    fw = out["firmware_in_the_loop"]
    assert fw["rate_hz"] == 300.0 and fw["engage_delay_ms"] == 5.0 and fw["failure"] is None
    assert fw["lock_class"] in ("peak", "rebound", "compression")
    bad = tmp_path / "bad.jsonl"
    bad.write_text(log.path.read_text().replace('"seq"', '"seq', 1))
    res = RUN.invoke(app, ["sim", "replay", str(bad)])
    assert res.exit_code == 2 and "bad.jsonl" in res.output and "corrupt" in res.output


def test_robot_config_supplies_the_firmware_settings(tmp_path):
    """--robot-config is read by the firmware's loader: its detector and rate reach the loop, and a bad
    field is a one-line error naming the file and the field."""
    from rimless.firmware.service.config import example_config_path
    from rimless.sim.cli.firmware import build_config

    text = example_config_path().read_text().replace("rate_hz = 300.0", "rate_hz = 500.0")
    text = text.replace("touch_debounce_samples = 2", "touch_debounce_samples = 3")
    good = tmp_path / "robot.toml"
    good.write_text(text)
    cfg = build_config(
        rate_hz=None,
        clutch_delay_ms=5,
        release_delay_ms=None,
        noise_counts=1,
        jitter_ms=0.05,
        holding_force_n=100,
        seed=0,
        robot_config=good,
    )
    assert cfg.rate_hz == 500.0 and cfg.detector.touch_debounce_samples == 3 and cfg.cpi == 1600
    bad = tmp_path / "bad.toml"
    bad.write_text(text.replace("touch_debounce_samples = 3", "touch_debounce_samples = -3"))
    res = RUN.invoke(app, ["sim", "gait", "--clutch", "firmware", "--robot-config", str(bad)])
    assert res.exit_code == 2 and "touch_debounce_samples" in res.output and "bad.toml" in res.output


def test_one_sensor_per_leg_in_the_loop_clutches_each_step_once(table1, er_fixed_point):
    """Per-leg sensors (robot.toml with one [[sensor]] per leg): every step has one touchdown and one lock
    of its own stance leg; the trailing foot coming down again on its own sensor is dismissed by the
    firmware, not taken for a step; the gait is the one-sensor gait to within the sensor noise."""
    cfg = dict(rate_hz=300.0, engage_delay_s=0.005, release_delay_s=0.005, **QUIET)
    _, one = _walk(table1, er_fixed_point[1].z, 3, **cfg)
    loop, per_leg = _walk(table1, er_fixed_point[1].z, 3, sensors="per-leg", **cfg)
    assert per_leg.failure is None and len(loop.controller.channels) == 8
    assert all(f.motion_reads >= per_leg.samples > 0 for f in loop.fakes)  # every sensor read at every sample
    for k, step in enumerate(per_leg.steps):
        names = [n for _, n in step.firmware_events]
        assert names.count("lock") == 1 and names.count("touchdown") <= 1, names
        assert step.lock_class == one.steps[k].lock_class
    locks = [f["leg"] for _, n, f in per_leg.events if n == "lock"]
    assert locks == [1, 2, 3]  # the stance legs of the three steps (leg 0 stood through the priming step)
    assert any(n == "touchdown_dismissed" for _, n, _ in per_leg.events)
    assert per_leg.steps[-1].z_end == pytest.approx(one.steps[-1].z_end, rel=0.02)
    assert per_leg.steps[-1].stored_energy_J == pytest.approx(one.steps[-1].stored_energy_J, rel=0.03)


def test_bench_reports_steps_per_second_beside_the_reference_with_the_load(table1, capsys):
    from rimless.sim.cli.firmware import run_bench

    out = run_bench(table1, rates_hz=(1000.0,), steps=1)
    assert [(r["rate_hz"], r["sensors"]) for r in out["rows"]] == [(1000.0, "one"), (1000.0, "per-leg")]
    for r in out["rows"]:
        assert r["steps"] == 1 and r["steps_per_s"] > 0 and r["reference_ideal_steps_per_s"] > 0
        assert r["slowdown_vs_ideal"] == pytest.approx(r["reference_ideal_steps_per_s"] / r["steps_per_s"])
        assert 300 < r["samples_per_step"] < 340  # 1 kHz over a ~0.31-0.37 s step
        assert r["first_step_section_difference"] < 0.05  # the firmware's first step near the ideal one
    assert len(out["load_average"]) == 3 and "load average" in capsys.readouterr().out
