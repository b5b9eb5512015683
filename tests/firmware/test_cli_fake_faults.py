"""`rimless robot run --fake --fake-fault NAME --json --pin-log FILE`: each scenario ends with no lock on a leg
the fake walk's truth has in the air (`airborne_leg_locks` 0), the fault that the scenario should raise, and a
pin log whose every clutch pin ends low. Fails on today's main: the options do not exist, and the detector
behind them locked airborne legs in the first two scenarios (tests/firmware/control/test_leg_identity.py)."""

from __future__ import annotations

import json
import os
import secrets
import subprocess
import sys
from pathlib import Path

import pytest

RIMLESS = [str(Path(sys.executable).with_name("rimless"))]
CLUTCH_PINS = (17, 27, 22, 23, 24, 16, 20, 21)


def run_fake(
    tmp_path: Path, *args: str, duration_s: float = 4.0, sensor: str = "", stance_leg: int = 0
) -> tuple[dict, list[dict], subprocess.CompletedProcess]:
    """Armed at start naming `stance_leg` (the leg the fake walk starts on: the configured start leg 0, unless the
    scenario says otherwise), as an operator arms the robot."""
    cfg = tmp_path / "robot.toml"
    # the watchdogs at 1 s (the robot's 0.1 s and 0.25 s): a loaded test machine pauses threads for 0.3-0.6 s;
    # the loop-stall scenario blocks the loop for 4 s
    cfg.write_text(
        f'{sensor}[commands]\nenabled = false\n[log]\ndir = "{tmp_path}"\n'
        "[sampling]\nstall_timeout_s = 1.0\nloop_stall_s = 1.0\n"
    )
    pins = tmp_path / "pins.jsonl"
    env = {**os.environ, "RIMLESS_TOKEN": secrets.token_urlsafe(18)}
    proc = subprocess.run(
        [
            *RIMLESS,
            "robot",
            "run",
            "--fake",
            "--arm",
            "--stance-leg",
            str(stance_leg),
            "--config",
            str(cfg),
            "--duration-s",
            str(duration_s),
            "--json",
            "--pin-log",
            str(pins),
            *args,
        ],
        capture_output=True,
        text=True,
        env=env,
        timeout=60,
    )
    summary = json.loads(proc.stdout)
    lines = [json.loads(line) for line in pins.read_text().splitlines()]
    return summary, lines, proc


def last_levels(lines: list[dict]) -> dict[int, int]:
    out: dict[int, int] = {}
    for rec in lines:
        assert set(rec) == {"t_s", "pin", "level"}
        out[rec["pin"]] = rec["level"]
    return out


@pytest.mark.slow
@pytest.mark.parametrize(
    ("name", "fault", "engages"),
    [
        ("missed-first-touchdown", "leg_sync_lost", False),
        ("first-step-bounce", "leg_sync_lost", False),
        ("brown-out", "sensor_reset", True),
        ("wrong-product-id", "id_mismatch", True),
        ("loop-stall", "loop_stalled", True),
        ("log-disk-full", None, True),
        ("wrong-start-leg", None, True),  # named at arm: the leg the walk stands on, 3, not the configured 0
    ],
)
def test_every_scenario_ends_released_with_no_airborne_lock(tmp_path, name, fault, engages) -> None:
    summary, lines, proc = run_fake(tmp_path, "--fake-fault", name, stance_leg=3 if name == "wrong-start-leg" else 0)
    assert proc.returncode == 0, proc.stderr
    assert summary["fake_fault"] == name
    # the loop and the fakes on a virtual clock: every sample at its deadline, whatever the machine's load
    assert summary["airborne_leg_locks"] == 0 and summary["missed_deadlines"] == 0
    if name == "wrong-start-leg":
        assert summary["faults"] == [] and summary["error"] is None
    elif fault is None:  # the disk filled: the walk went on, logging degraded and said so
        from rimless.firmware.service.triallog import read_trial_log

        assert summary["faults"] == [] and summary["error"] is None
        assert summary["log_dropped_lines"] > 0 and summary["log_errors"] > 0
        assert "trial log degraded" in proc.stderr
        assert not read_trial_log(summary["trials"][0]).torn_tail
    else:
        assert fault in summary["faults"]
    assert (summary["engages"] > 0) is engages
    levels = last_levels(lines)
    assert all(levels.get(p, 0) == 0 for p in CLUTCH_PINS)
    ups = sum(1 for rec in lines if rec["pin"] in CLUTCH_PINS and rec["level"] == 1)
    assert ups == summary["engages"]


@pytest.mark.slow
def test_a_brownout_at_400_cpi_is_caught_too(tmp_path) -> None:
    """Fails before the configuration read-back: at 400 cpi the reset leaves Motion's RES bit as it was, and
    the walk went on locking with the sensor in its power-on state (no fault)."""
    sensor = (
        "[[sensor]]\nreset_pin = 25\nresolution_cpi = 400\ncounts_per_m = 15748.0\nlegs = [0, 1, 2, 3, 4, 5, 6, 7]\n"
    )
    summary, lines, proc = run_fake(tmp_path, "--fake-fault", "brown-out", sensor=sensor)
    assert proc.returncode == 0, proc.stderr
    assert "sensor_reset" in summary["faults"]
    assert summary["engages"] > 0 and summary["airborne_leg_locks"] == 0 and summary["missed_deadlines"] == 0
    assert all(v == 0 for p, v in last_levels(lines).items() if p in CLUTCH_PINS)


def test_a_plain_fake_walk_locks_only_stance_legs(tmp_path) -> None:
    summary, lines, proc = run_fake(tmp_path, duration_s=3.0)
    assert proc.returncode == 0, proc.stderr
    assert summary["faults"] == [] and summary["fake_fault"] is None
    assert summary["engages"] >= 2 and summary["airborne_leg_locks"] == 0 and summary["missed_deadlines"] == 0
    assert all(v == 0 for p, v in last_levels(lines).items() if p in CLUTCH_PINS)


def test_bad_fake_fault_is_one_line_exit_2(tmp_path) -> None:
    proc = subprocess.run(
        [*RIMLESS, "robot", "run", "--fake", "--fake-fault", "meteor"], capture_output=True, text=True, timeout=60
    )
    assert proc.returncode == 2
    assert proc.stderr.count("\n") == 1 and proc.stderr.startswith("error: ") and "first-step-bounce" in proc.stderr
    proc = subprocess.run(
        [*RIMLESS, "robot", "run", "--pin-log", str(tmp_path / "p")], capture_output=True, text=True, timeout=60
    )
    assert proc.returncode == 2 and "--fake" in proc.stderr


def test_arming_at_start_without_naming_the_stance_leg_is_refused(tmp_path) -> None:
    """With the robot's defaults one sensor counts eight legs and cannot tell which one stands: `--arm` without
    `--stance-leg` is one `error:` line naming it, exit 2, before any pin is driven (no pin log, no summary);
    `--stance-leg` without `--arm` and a leg no sensor watches are refused the same way."""
    cfg = tmp_path / "robot.toml"
    cfg.write_text(f'[commands]\nenabled = false\n[log]\ndir = "{tmp_path}"\n')
    pins = tmp_path / "pins.jsonl"
    base = [*RIMLESS, "robot", "run", "--fake", "--config", str(cfg), "--duration-s", "2", "--pin-log", str(pins)]
    env = {**os.environ, "RIMLESS_TOKEN": secrets.token_urlsafe(18)}
    for extra, needle in (
        (["--arm"], "--arm needs --stance-leg"),
        (["--arm", "--fake-fault", "wrong-start-leg"], "--arm needs --stance-leg"),
        (["--stance-leg", "0"], "add --arm"),
        (["--arm", "--stance-leg", "8"], "--stance-leg 8: not a leg"),
    ):
        proc = subprocess.run([*base, *extra], capture_output=True, text=True, env=env, timeout=60)
        assert proc.returncode == 2, (extra, proc.stderr)
        assert proc.stderr.count("\n") == 1 and proc.stderr.startswith("error: ") and needle in proc.stderr
        assert proc.stdout == "" and not pins.exists()


@pytest.mark.slow
def test_naming_the_wrong_stance_leg_is_the_one_mistake_one_sensor_cannot_see(tmp_path) -> None:
    """The limit docs/robot.md states, measured: one sensor sees the same compression whichever leg stands on it,
    so a wrong name (0 while the fake walk stands on 3) shifts every lock by three legs and no check fails. The
    arming procedure, not a measurement, is what keeps the start leg right: every lock is on a leg in the air."""
    summary, _lines, proc = run_fake(tmp_path, "--fake-fault", "wrong-start-leg", stance_leg=0, duration_s=4.0)
    assert proc.returncode == 0, proc.stderr
    assert summary["faults"] == [] and summary["engages"] > 0
    assert summary["airborne_leg_locks"] == summary["engages"]
