"""Trial analysis: Vicon exports in, CoM height and step periods, comparison with the simulator, calibration,
critical slope from trials, reports.

The public API (docs/api.md), imported lazily so that `import rimless.analysis` stays light:

- `read_recording(path)`: a Vicon export (CSV of Tracker or Nexus, or C3D) as a `ViconFile`, SI units;
- `import_trial(path, ...)`: the wheel's `Trial` (hub, slope frame, CoM height, impacts; `to_frame()` gives a
  DataFrame with `time_s`, `com_height_m`, ...); `read_trial(path)` reads one written by `Trial.to_parquet`;
- `compare(trial, wheel=None)`, `calibrate(trials, fit=("c",), wheel=None)`, `critical_slope(trials, wheel=None)`,
  `write_report(files, out, wheel=None)`: each takes the simulator's `rimless.sim.Wheel` and returns the object
  whose `to_dict()` is the matching `rimless trials` command's `--json` object;
- `floquet(trials, wheel=None)`: the trials' step-to-step multiplier (noise bias corrected, 95 % interval)
  beside the model's eigenvalue (`rimless trials floquet`);
- `load_trials(trials)`: `Trial` objects or paths -> (trials, names);
- `leg_fit(logs, moving_mass_kg=...)`: a leg's k, c and guide friction with 95 % intervals from its
  `rimless robot leg-test` logs (`rimless trials leg-fit`), a `LegFitResult`; `read_leg_log(path)` reads one.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from rimless.lazy import lazy_exports

if TYPE_CHECKING:
    from rimless.analysis.api.floquet import floquet
    from rimless.analysis.api.leg import leg_fit
    from rimless.analysis.api.trials import calibrate, compare, critical_slope, load_trials, write_report
    from rimless.analysis.inference.calibrate import CalibrationResult
    from rimless.analysis.inference.compare import TrialComparison
    from rimless.analysis.inference.critical_slope import CriticalSlopeResult
    from rimless.analysis.inference.floquet import FloquetResult
    from rimless.analysis.inference.leg_fit import LegFitResult, LegLog, read_leg_log
    from rimless.analysis.io.recording import read_recording
    from rimless.analysis.io.trial import Trial, read_trial
    from rimless.analysis.io.vicon_file import ViconFile
    from rimless.analysis.kinematics.build import TrialRefused, import_trial
    from rimless.analysis.report.html import ReportResult

_LAZY = {
    "read_recording": "rimless.analysis.io.recording",
    "ViconFile": "rimless.analysis.io.vicon_file",
    "import_trial": "rimless.analysis.kinematics.build",
    "TrialRefused": "rimless.analysis.kinematics.build",
    "Trial": "rimless.analysis.io.trial",
    "read_trial": "rimless.analysis.io.trial",
    "load_trials": "rimless.analysis.api.trials",
    "compare": "rimless.analysis.api.trials",
    "calibrate": "rimless.analysis.api.trials",
    "critical_slope": "rimless.analysis.api.trials",
    "write_report": "rimless.analysis.api.trials",
    "floquet": "rimless.analysis.api.floquet",
    "leg_fit": "rimless.analysis.api.leg",
    "LegFitResult": "rimless.analysis.inference.leg_fit",
    "LegLog": "rimless.analysis.inference.leg_fit",
    "read_leg_log": "rimless.analysis.inference.leg_fit",
    "FloquetResult": "rimless.analysis.inference.floquet",
    "TrialComparison": "rimless.analysis.inference.compare",
    "CalibrationResult": "rimless.analysis.inference.calibrate",
    "CriticalSlopeResult": "rimless.analysis.inference.critical_slope",
    "ReportResult": "rimless.analysis.report.html",
}

__all__ = [
    "CalibrationResult",
    "CriticalSlopeResult",
    "FloquetResult",
    "LegFitResult",
    "LegLog",
    "ReportResult",
    "Trial",
    "TrialComparison",
    "TrialRefused",
    "ViconFile",
    "calibrate",
    "compare",
    "critical_slope",
    "floquet",
    "import_trial",
    "leg_fit",
    "load_trials",
    "read_leg_log",
    "read_recording",
    "read_trial",
    "write_report",
]


__getattr__, __dir__ = lazy_exports(__name__, _LAZY)
