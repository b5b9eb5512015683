"""`python -m rimless` and the `rimless` console script.

The CLI is imported inside `main`, so a Ctrl-C while it loads also exits 130 with one line. Once the
command's result is complete, SIGINT is ignored for the rest of the process (`ignore_ctrl_c_from_here`).
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


def ignore_ctrl_c_from_here(code: int = 0) -> None:
    """Ignore SIGINT from now on: called once the command's result is complete (rimless.cli_rules.commit_result).

    What is left is the interpreter's teardown (atexit handlers, library threads, unloading the compiled
    kernels). A Ctrl-C there used to be either reported `interrupted` after the result, or, once Python had put
    SIGINT back to its default during finalization, to kill the process silently (exit -2, "130" in a shell)
    after a complete run. Ignored, the run ends with its own exit code; Python leaves an ignored SIGINT ignored
    through finalization."""
    if threading.current_thread() is not threading.main_thread():
        return
    try:
        signal.signal(signal.SIGINT, signal.SIG_IGN)
    except KeyboardInterrupt:  # one already pending (signal.signal delivers it first): it came after the result
        signal.signal(signal.SIGINT, signal.SIG_IGN)


def main() -> None:
    """Run the `rimless` command line."""
    committed = None
    try:
        redeliver_swallowed_interrupts()
        from rimless import cli_rules

        committed = cli_rules.committed_result
        cli_rules.after_result(ignore_ctrl_c_from_here)
        from rimless.cli import main as cli_main

        cli_main()
    except KeyboardInterrupt:
        code = committed() if committed is not None else None
        if code is not None:  # it came after the result was complete: the run ends with its own code
            ignore_ctrl_c_from_here()
            sys.exit(code)
        sys.stderr.write("interrupted\n")
        sys.exit(EXIT_INTERRUPTED)


if __name__ == "__main__":
    main()
