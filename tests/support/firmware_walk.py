"""Walks for the leg-identity and listen tests on `tests.support.fake_walk_rig.FakeWalkRig` (the robot's own
`Controller` on one register-level fake ADNS-3080 counting eight legs, on `rimless.firmware.clock.VirtualClock`),
stepped at a fixed rate through a scripted `FakeWalk`, every engage recorded with its (virtual) time so that it can
be judged against the walk's truth."""

from __future__ import annotations

from dataclasses import dataclass, field

from rimless.firmware.control.controller import EventRecord
from rimless.firmware.control.detector import DetectorParams
from rimless.firmware.drivers.fake_walk import FakeWalk, airborne_locks
from tests.support.fake_walk_rig import LEGS, FakeWalkRig


@dataclass
class WalkResult:
    engages: list[tuple[float, int]] = field(default_factory=list)
    events: list[tuple[float, str, dict]] = field(default_factory=list)
    airborne: list[tuple[float, int, int]] = field(default_factory=list)

    def names(self) -> list[str]:
        return [name for _t, name, _f in self.events]

    def faults(self) -> list[str]:
        return [f["fault"] for _t, name, f in self.events if name == "fault"]


def walk_controller(
    walk: FakeWalk,
    params: DetectorParams,
    *,
    duration_s: float = 3.0,
    rate_hz: float = 300.0,
    start_index: int = 0,
    seed: int = 0,
    fault_at: tuple[float, object] | None = None,
    verify_before_engage: bool = True,
    id_check_interval_s: float = 0.0,
    readback_every_samples: int = 1,
    cpi: int = 1600,
    records: list | None = None,
) -> WalkResult:
    """Arm at t = 0 naming the leg the walk starts on (`LEGS[start_index]`, as the operator does: the robot's
    defaults lock nothing before) and step the controller at `rate_hz` for `duration_s` of virtual time (the first
    sample at t = 0) on `FakeWalkRig`; `fault_at` = (t_s, action(fake)) injects a fault into the fake before the
    first sample at or after t_s. The sensor is configured at `cpi` with the automatic frame rate, as the service
    does. Every controller record goes to `records`."""
    res = WalkResult()
    period_s = round(1e9 / rate_hz) * 1e-9  # the rig's deadlines are whole nanoseconds
    with FakeWalkRig(
        walk,
        params,
        start_index=start_index,
        seed=seed,
        cpi=cpi,
        id_check_interval_s=id_check_interval_s,
        verify_before_engage=verify_before_engage,
        readback_every_samples=readback_every_samples,
    ) as rig:
        rig.controller.arm(stance_leg=LEGS[start_index])
        if fault_at is not None and fault_at[0] <= 0.0:
            fault_at[1](rig.fake)  # type: ignore[operator]
            fault_at = None
        for t, engaged, recs in rig.drive(rate_hz, duration_s, first=0):
            res.engages.extend((t, leg) for leg in engaged)
            for rec in recs:
                if records is not None:
                    records.append(rec)
                if isinstance(rec, EventRecord):
                    res.events.append((t, rec.name, rec.fields))
            if fault_at is not None and t + period_s >= fault_at[0] - 1e-12:
                fault_at[1](rig.fake)  # type: ignore[operator]
                fault_at = None
    res.airborne = airborne_locks(walk, res.engages, LEGS, start_index)
    return res
