"""The report's figures are laid out once before they are written: the PNG is the one matplotlib writes with its
constrained layout run at save time (pixel for pixel), and the figure keeps its layout engine."""

from __future__ import annotations

import numpy as np


def _figure():
    from rimless.analysis.report import figures

    fig = figures.new_figure(8.0, 5.0)
    for i in range(4):
        ax = fig.add_subplot(2, 2, i + 1)
        ax.plot(np.linspace(0, 1, 50), np.sin(np.linspace(0, 6 * (i + 1), 50)), ".-")
        ax.set_title(f"panel {i} with a long title that the layout has to make room for", fontsize=7)
        ax.set_xlabel("time from first impact, s")
        ax.set_ylabel("CoM height, mm")
    fig.suptitle("a suptitle", fontsize=10)
    fig.legend(handles=fig.axes[0].lines, labels=["curve"], loc="outside lower center")
    return fig


def test_saved_png_is_the_one_savefig_writes(tmp_path):
    from PIL import Image

    from rimless.analysis.report import figures

    ours, plain = _figure(), _figure()
    figures.save_png(ours, tmp_path / "ours.png")
    plain.savefig(tmp_path / "plain.png", dpi=figures.DPI)
    a = np.asarray(Image.open(tmp_path / "ours.png"))
    b = np.asarray(Image.open(tmp_path / "plain.png"))
    assert a.shape == b.shape
    assert np.array_equal(a, b)
    assert ours.get_layout_engine() is not None and not (tmp_path / "ours.tmp.png").exists()
