"""`python -m rimless` and the `rimless` console script.

The CLI is imported inside `main`, so a Ctrl-C while it loads also exits 130 with one line.
"""

import os
import signal
import sys
import threading

EXIT_INTERRUPTED = 130


def redeliver_swallowed_interrupts() -> None:
    """Install a `sys.unraisablehook` that sends SIGINT again when a Ctrl-C was swallowed.

    Python drops an exception raised inside a weakref callback, a gc callback or a `__del__` (the default hook
    only prints "Exception ignored in ..."). A Ctrl-C whose KeyboardInterrupt was raised there was lost, and the
    command ran on to the end with exit 0 (seen in `rimless paper`, inside a weakref callback of a library's
    `WeakKeyDictionary`). The hook sends the signal again 10 ms later, so that the interrupt lands in the
    command's code, and prints nothing; every other unraisable exception goes to the hook installed before."""
    before = sys.unraisablehook

    def hook(unraisable) -> None:
        if issubclass(unraisable.exc_type, KeyboardInterrupt):
            # from another thread, a moment later: a signal sent from here would raise inside this hook, where
            # Python drops it too
            again = threading.Timer(0.01, os.kill, (os.getpid(), signal.SIGINT))
            again.daemon = True
            again.start()
            return
        before(unraisable)

    sys.unraisablehook = hook


def main() -> None:
    """Run the `rimless` command line."""
    try:
        redeliver_swallowed_interrupts()
        from rimless.cli import main as cli_main

        cli_main()
    except KeyboardInterrupt:
        sys.stderr.write("interrupted\n")
        sys.exit(EXIT_INTERRUPTED)


if __name__ == "__main__":
    main()
