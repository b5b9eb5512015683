"""Plain text for a terminal folds between words only: a terminal 80 columns wide otherwise cuts a number
(`1.522-1.567`) or a path in two (issue 31: `rimless demo`'s lines never wrap inside a number)."""

from __future__ import annotations

import os
import pty
import subprocess
import sys

from rimless.cli_rules import wrap_words

# A line `rimless demo` prints (its calibration line, 2026-11-27), long and full of numbers.
LINE = (
    "calibrated c: 12.991 ± 0.098 N s/m (Table 1: 8) NOT identifiable: effective only: the model does NOT fit "
    "the trials: CoM height residuals 2.6 times the recording's noise (chi^2/dof 6.52, p = 5.2e-176); see "
    "analysis/data/critical/SYNTHETIC_crit_slope1.30deg_release2.5.csv and 1.522-1.567 deg"
)


def test_folds_between_words_and_keeps_every_word_whole() -> None:
    for width in (40, 60, 80, 120):
        lines = wrap_words(LINE, width)
        assert len(lines) > 1 if width < len(LINE) else len(lines) == 1
        assert " ".join(w for ln in lines for w in ln.split()) == " ".join(LINE.split())  # no word cut or lost
        for ln in lines:
            assert len(ln) <= width or " " not in ln.strip()  # only a word longer than the line overflows it
        assert all(ln.startswith("  ") for ln in lines[1:])  # a continuation is indented


def test_an_indented_line_continues_deeper() -> None:
    text = "  m_H = 1.892 ± 0.0378 kg  (table1: assumed, not measured: +-2 % for a weighed assembly)"
    lines = wrap_words(text, 40)
    assert lines[0].startswith("  m_H = 1.892") and not lines[0].startswith("   ")
    assert all(ln.startswith("    ") for ln in lines[1:])


def _printed(isatty: bool) -> str:
    code = "from rimless.cli_rules import echo_text; import sys; echo_text(sys.argv[1])"
    env = {**os.environ, "COLUMNS": "61", "LINES": "24"}
    if not isatty:
        return subprocess.run(
            [sys.executable, "-c", code, LINE], env=env, capture_output=True, text=True, check=True, timeout=60
        ).stdout
    main, sub = pty.openpty()
    try:
        proc = subprocess.Popen([sys.executable, "-c", code, LINE], env=env, stdout=sub, stderr=sub)
        os.close(sub)
        chunks = []
        while True:
            try:
                data = os.read(main, 4096)
            except OSError:  # the child closed its side (EIO on Linux)
                break
            if not data:
                break
            chunks.append(data)
        assert proc.wait(timeout=60) == 0
    finally:
        os.close(main)
    return b"".join(chunks).decode().replace("\r\n", "\n")


def test_a_terminal_gets_folded_lines_a_pipe_whole_ones() -> None:
    on_terminal = _printed(isatty=True).splitlines()
    assert on_terminal == wrap_words(LINE, 60)
    assert _printed(isatty=False) == LINE + "\n"
