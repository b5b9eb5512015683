"""The trials commands of analysis/README.md run verbatim (a real shell, the installed `rimless`) on the bundled data."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
README = REPO / "analysis" / "README.md"


def chain_commands() -> list[str]:
    text = README.read_text(encoding="utf-8")
    m = re.search(r"<!-- trials-chain -->\s*```bash\n(.*?)```", text, re.S)
    assert m, "analysis/README.md lost its trials-chain block"
    return [line.strip() for line in m.group(1).splitlines() if line.strip()]


def test_readme_trials_chain_runs_verbatim(tmp_path):
    rimless = Path(sys.executable).with_name("rimless")
    if not rimless.exists():
        pytest.skip(f"the rimless console script is not installed beside {sys.executable}")
    (tmp_path / "analysis").symlink_to(REPO / "analysis")  # the commands name repository paths
    env = dict(os.environ, PATH=f"{rimless.parent}{os.pathsep}{os.environ.get('PATH', '')}", COLUMNS="80")
    cmds = chain_commands()
    assert [c.split()[:3] for c in cmds] == [
        ["rimless", "trials", "import"],
        ["rimless", "trials", "show"],
        ["rimless", "trials", "report"],
    ]
    for cmd in cmds:
        res = subprocess.run(["bash", "-c", cmd], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600)
        assert res.returncode == 0, f"{cmd}\n{res.stdout}\n{res.stderr}"
        assert "Traceback" not in res.stderr
        assert all(len(line) <= 80 for line in res.stdout.splitlines() if "┃" in line or "│" in line), res.stdout
    # what the chain produced, checked against the truth of the bundled data
    rows = json.loads(
        subprocess.run(
            ["bash", "-c", cmds[0] + " --json"], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600
        ).stdout
    )
    assert len(rows) == 6 and {r["outcome"] for r in rows} == {"caught"}
    ramp = [r for r in rows if r["ramp_slope_deg"] is not None]
    assert len(ramp) == 1 and abs(ramp[0]["ramp_slope_deg"] - 2.5) < 0.05
    gap = next(r for r in rows if "slope2.0deg_run2" in r["file"])
    assert len(gap["step_periods_s"]) == 5 and any("dropped" in w for w in gap["warnings"])
    assert (tmp_path / "report" / "report.html").is_file()
