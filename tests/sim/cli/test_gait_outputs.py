"""`rimless sim gait --out ... --plot ...`: both outputs or neither, also when a Ctrl-C lands while the figure is
drawn (the trajectory was already written then)."""

import signal
import subprocess
import sys
from pathlib import Path

from tests.support.cli_lines import stderr_lines

# The command as the console script runs it, with the figure's drawing announced on stderr and then blocked until
# a signal arrives: the test sends SIGINT on that line, so the interrupt lands inside the figure every time.
_DRAWING_THEN_WAIT = """
import signal, sys
import rimless.sim.studies.figures as figures
def drawing(*args, **kwargs):
    print("drawing the figure", file=sys.stderr, flush=True)
    signal.pause()  # until the test's SIGINT (raised here as KeyboardInterrupt)
    raise AssertionError("no signal came")
figures.plot_gait = drawing
from rimless.__main__ import main
sys.argv = ["rimless", *sys.argv[1:]]
main()
"""


def test_ctrl_c_while_the_figure_is_drawn_leaves_no_trajectory(tmp_path: Path) -> None:
    proc = subprocess.Popen(
        [sys.executable, "-c", _DRAWING_THEN_WAIT, "sim", "gait", "--steps", "3"]
        + ["--out", "traj.parquet", "--plot", "gait.png"],
        cwd=tmp_path,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        stdin=subprocess.DEVNULL,
        text=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    try:
        assert proc.stderr is not None
        seen = []
        for line in proc.stderr:  # the compile notice (a cold cache) may come first
            seen.append(line)
            if line.startswith("drawing the figure"):
                break
        else:
            raise AssertionError("".join(seen))
        proc.send_signal(signal.SIGINT)
        stdout, stderr = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 130, stderr
    assert stderr_lines(stderr) == ["interrupted"], stderr
    assert stdout.strip() == "" and "Traceback" not in stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == []  # neither the trajectory nor a temporary


def test_gait_writes_both_outputs_and_names_them(tmp_path: Path) -> None:
    res = subprocess.run(
        [sys.executable, "-m", "rimless", "sim", "gait", "--steps", "2", "--out", "t/traj.csv", "--plot", "t/g.png"],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert res.returncode == 0, res.stderr
    assert sorted(p.name for p in (tmp_path / "t").iterdir()) == ["g.png", "traj.csv"]
    assert "t/traj.csv" in res.stdout and "t/g.png" in res.stdout
    assert (tmp_path / "t" / "traj.csv").read_text().startswith("t_s,")
    assert (tmp_path / "t" / "g.png").read_bytes().startswith(b"\x89PNG")
