"""The unit's sandbox lets gpiozero identify the board: a procfs mounted as the unit's ProtectProc=/ProcSubset= mount
it (systemd.exec(5): a private procfs instance with hidepid= and subset=), in a private mount and PID namespace,
with a Pi 4B's /proc/cpuinfo bind-mounted in its place, and gpiozero's own reading of the revision
(`gpiozero.pins.local.get_pi_revision`, which every local pin factory calls before it opens a pin: lgpio's,
RPi.GPIO's, the native one) gives back the board. The pins themselves need a Pi; this is the step before them,
the one the sandbox broke.

Fails on today's main: `ProcSubset=pid` leaves no /proc/cpuinfo and no /proc/device-tree, gpiozero raises
PinUnknownPi, every pin factory fails and `rimless robot release` (the unit's ExecStartPre= and ExecStopPost=)
exits 2 "no GPIO on this machine" (issue 32, item 5). Needs root, or user namespaces (`unshare -r`): skipped
with the reason where neither works."""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

UNIT = Path(__file__).parents[3] / "firmware" / "service" / "rimless-robot.service"

# A Raspberry Pi 4 Model B rev 1.4, 4 GB (64-bit kernel), as its /proc/cpuinfo reads (one core of four shown).
# Revision c03114 in the Raspberry Pi documentation's table of revision codes (raspberrypi.com/documentation,
# "Raspberry Pi revision codes"): model 4B, revision 1.4, 4 GB, made by Sony UK, processor BCM2711.
PI4B_CPUINFO = """processor\t: 0
BogoMIPS\t: 108.00
Features\t: fp asimd evtstrm crc32 cpuid
CPU implementer\t: 0x41
CPU architecture: 8
CPU variant\t: 0x0
CPU part\t: 0xd08
CPU revision\t: 3

Revision\t: c03114
Serial\t\t: 10000000a1b2c3d4
Model\t\t: Raspberry Pi 4 Model B Rev 1.4
"""

# Runs as PID 1 of the new namespaces: mount a procfs with the options given, put the Pi's cpuinfo in place of
# the host's (where the procfs has one), then ask gpiozero which board this is.
_INSIDE = r"""
import json, os, subprocess, sys
opts, cpuinfo = sys.argv[1], sys.argv[2]
subprocess.run(["mount", "-t", "proc", "-o", opts, "proc", "/proc"], check=True)
out = {"pid": os.getpid(), "cpuinfo": os.path.exists("/proc/cpuinfo"), "device_tree": os.path.lexists("/proc/device-tree")}
if out["cpuinfo"]:
    subprocess.run(["mount", "--bind", cpuinfo, "/proc/cpuinfo"], check=True)
from gpiozero.pins.local import get_pi_revision
from gpiozero.pins.pi import PiBoardInfo
try:
    info = PiBoardInfo.from_revision(get_pi_revision())
    out.update(revision=info.revision, model=info.model, pcb_revision=info.pcb_revision, memory=info.memory,
               soc=info.soc, manufacturer=info.manufacturer)
except Exception as err:
    out["error"] = f"{type(err).__name__}: {err}"
print(json.dumps(out))
"""


def unit_proc_mount_options(unit_text: str) -> str:
    """The options systemd mounts the unit's private procfs with (systemd.exec(5): ProtectProc= becomes hidepid=,
    ProcSubset=pid becomes subset=pid; the last assignment of each wins; nosuid,nodev,noexec always)."""
    settings = dict(re.findall(r"^(ProtectProc|ProcSubset)=(\S*)\s*$", unit_text, re.M))
    opts = ["nosuid", "nodev", "noexec"]
    protect = settings.get("ProtectProc", "default") or "default"
    if protect != "default":
        opts.append(f"hidepid={protect}")
    if (settings.get("ProcSubset", "all") or "all") == "pid":
        opts.append("subset=pid")
    return ",".join(opts)


def _unshare() -> list[str]:
    """The command that gives a child its own mount and PID namespaces (mapped to root when we are not)."""
    cmd = ["unshare", "--mount", "--pid", "--fork", "--propagation", "private"]
    return cmd if os.geteuid() == 0 else [*cmd, "--map-root-user"]


@pytest.fixture(scope="module")
def namespaces() -> list[str]:
    """Skip, with the reason, where a private mount and PID namespace with its own procfs cannot be had."""
    if not sys.platform.startswith("linux"):
        pytest.skip("procfs and namespaces are Linux's")
    for tool in ("unshare", "mount"):
        if shutil.which(tool) is None:
            pytest.skip(f"no `{tool}` here (util-linux)")
    probe = subprocess.run(
        [*_unshare(), "mount", "-t", "proc", "proc", "/proc"], capture_output=True, text=True, timeout=60
    )
    if probe.returncode != 0:
        who = "as root" if os.geteuid() == 0 else "without root, through a user namespace"
        pytest.skip(f"cannot mount a procfs in new namespaces {who}: {probe.stderr.strip()[:200]}")
    return _unshare()


def _board_seen_by_gpiozero(namespaces: list[str], options: str, tmp_path: Path) -> dict:
    cpuinfo = tmp_path / "cpuinfo"
    cpuinfo.write_text(PI4B_CPUINFO)
    r = subprocess.run(
        [*namespaces, sys.executable, "-c", _INSIDE, options, str(cpuinfo)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert r.returncode == 0, r.stderr
    return json.loads(r.stdout.strip().splitlines()[-1])


def test_mount_options_follow_systemd() -> None:
    assert unit_proc_mount_options("ProtectProc=invisible\nProcSubset=pid\n") == (
        "nosuid,nodev,noexec,hidepid=invisible,subset=pid"
    )
    assert unit_proc_mount_options("ProtectProc=invisible\nProcSubset=all\n") == "nosuid,nodev,noexec,hidepid=invisible"
    assert unit_proc_mount_options("") == "nosuid,nodev,noexec"


def test_gpiozero_identifies_the_pi_in_a_procfs_mounted_as_the_unit_mounts_it(namespaces, tmp_path) -> None:
    options = unit_proc_mount_options(UNIT.read_text())
    seen = _board_seen_by_gpiozero(namespaces, options, tmp_path)
    assert seen["pid"] == 1  # a PID namespace of its own, so the procfs is a new instance with these options
    assert seen["cpuinfo"], f"the unit's procfs ({options}) has no /proc/cpuinfo, where gpiozero reads the revision"
    assert "error" not in seen, f"gpiozero in the unit's procfs ({options}): {seen.get('error')}"
    assert (seen["revision"], seen["model"], seen["pcb_revision"], seen["memory"]) == ("c03114", "4B", "1.4", 4096)
    assert (seen["soc"], seen["manufacturer"]) == ("BCM2711", "Sony")


def _release_in(namespaces: list[str], options: str, tmp_path: Path) -> subprocess.CompletedProcess:
    """The unit's ExecStartPre= (`rimless robot release`) in a procfs mounted with `options` on a Pi's cpuinfo."""
    cpuinfo = tmp_path / "cpuinfo"
    cpuinfo.write_text(PI4B_CPUINFO)
    script = (
        'mount -t proc -o "$1" proc /proc && { [ ! -e /proc/cpuinfo ] || mount --bind "$2" /proc/cpuinfo; } '
        '&& exec "$3" robot release'
    )
    rimless = str(Path(sys.executable).with_name("rimless"))
    return subprocess.run(
        [*namespaces, "sh", "-c", script, "sh", options, str(cpuinfo), rimless],
        capture_output=True,
        text=True,
        timeout=120,
    )


def test_the_units_release_gets_past_the_board_to_the_pins(namespaces, tmp_path) -> None:
    """`rimless robot release` in the unit's procfs: every pin factory identifies the Pi and stops only where the
    pins are (no gpiochip or /dev/gpiomem here: exit 2 naming them; on a Pi it would drive them, exit 0)."""
    options = unit_proc_mount_options(UNIT.read_text())
    r = _release_in(namespaces, options, tmp_path)
    if r.returncode == 0:
        return  # a real Pi: the pins were driven off
    assert r.returncode == 2, r.stderr
    assert "/proc/cpuinfo" not in r.stderr and "unable to locate Pi revision" not in r.stderr, r.stderr
    assert "gpiochip" in r.stderr or "/dev/gpiomem" in r.stderr, r.stderr  # lgpio's, or the native factory's
    pid_only = _release_in(namespaces, "nosuid,nodev,noexec,hidepid=invisible,subset=pid", tmp_path)
    assert pid_only.returncode == 2 and "No such file or directory: '/proc/cpuinfo'" in pid_only.stderr


def test_a_pid_only_procfs_hides_the_revision_from_gpiozero(namespaces, tmp_path) -> None:
    """What `ProcSubset=pid` did: the check above can fail (and did, on the unit before this fix)."""
    seen = _board_seen_by_gpiozero(namespaces, "nosuid,nodev,noexec,hidepid=invisible,subset=pid", tmp_path)
    assert not seen["cpuinfo"] and not seen["device_tree"]
    # gpiozero falls back from a missing /proc/device-tree to /proc/cpuinfo, whose absence it does not catch
    assert seen["error"] == "FileNotFoundError: [Errno 2] No such file or directory: '/proc/cpuinfo'"
