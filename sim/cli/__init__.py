"""`rimless sim ...`: thin commands over the simulator library; each parses, calls one library function, prints.

`app` holds the typer app and what commands share (the wheel-parameter options, option types, path checks),
`output` the console and table they print through; one module per family of commands: `fixed_point`
(fixed-point, gaits, critical-slope), `gait`, `firmware` (what `--clutch firmware` prints), `sweep`
(sweep, firmware-sweep), `replay`, `robustness` (basin, sensitivity, mfpt), `studies` (stress and the top-level bench and paper). The rules of every
command (one-line errors, exit codes) come from rimless.cli_rules; progress bars from rimless.progress;
lists typed on the command line are read by rimless.values. Heavy imports happen inside the commands.

May import: every sim/ folder, rimless.cli_rules, rimless.progress, rimless.values, rimless.output,
rimless.errors. Never rimless.cli (the root app imports this package).
"""

from rimless.sim.cli.app import app
from rimless.sim.cli.fixed_point import critical_slope_cmd, fixed_point_cmd, gaits_cmd
from rimless.sim.cli.gait import gait_cmd
from rimless.sim.cli.replay import replay_cmd
from rimless.sim.cli.robustness import basin_cmd, mfpt_cmd, sensitivity_cmd
from rimless.sim.cli.studies import bench_cmd, paper_cmd, register_top_level, stress_cmd
from rimless.sim.cli.sweep import firmware_sweep_cmd, sweep_cmd

__all__ = ["app", "register_top_level", "bench_cmd", "paper_cmd"]

# the order of `rimless sim --help`
app.command("fixed-point")(fixed_point_cmd)
app.command("gaits")(gaits_cmd)
app.command("critical-slope")(critical_slope_cmd)
app.command("gait")(gait_cmd)
app.command("stress")(stress_cmd)
app.command("firmware-sweep")(firmware_sweep_cmd)
app.command("replay")(replay_cmd)
app.command("sweep")(sweep_cmd)
app.command("basin")(basin_cmd)
app.command("sensitivity")(sensitivity_cmd)
app.command("mfpt")(mfpt_cmd)
