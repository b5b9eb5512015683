"""The live view of `robot listen`."""

from __future__ import annotations


def test_live_view_draws_velocity_compression_and_one_strip_per_clutch() -> None:
    from rimless.firmware.link.listen import Summary, sparkline

    assert sparkline([0.0, 0.5, 1.0], 10) == "▁▅█"
    assert sparkline([2.0, 2.0], 10) == "▁▁"
    s = Summary()
    for k in range(40):
        s.add([{"timestamp": k, "leg": {"velocity_m_s": (k % 10) * 0.01, "compression_m": k * 1e-4,
                                        "clutch_mask": 1 << (k // 10)}}], now_s=k * 0.01)
    lines = s.view(now_s=0.4, span_s=1.0, width=40)
    assert lines[1].startswith("velocity") and "m/s" in lines[1]
    assert lines[2].startswith("compression") and "0.0..3.9 mm" in lines[2]
    strips = lines[3:]
    assert len(strips) == 8
    assert strips[0].endswith("█" * 10 + "·" * 30) and strips[3].endswith("·" * 30 + "█" * 10)
    assert all(len(line) <= 80 for line in lines)
