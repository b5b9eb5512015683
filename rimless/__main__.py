"""`python -m rimless` and the `rimless` console script.

The CLI is imported inside `main`, so a Ctrl-C while it loads also exits 130 with one line.
"""

import sys

EXIT_INTERRUPTED = 130


def main() -> None:
    """Run the `rimless` command line."""
    try:
        from rimless.cli import main as cli_main

        cli_main()
    except KeyboardInterrupt:
        sys.stderr.write("interrupted\n")
        sys.exit(EXIT_INTERRUPTED)


if __name__ == "__main__":
    main()
