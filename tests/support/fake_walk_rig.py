"""The robot's `Controller` on one register-level fake ADNS-3080 counting eight legs (`FakeAdns3080` under the
`Adns3080` driver, configured as the app configures it), the clutches on gpiozero's `MockFactory` pins, every
sample at its deadline on a `VirtualClock` (`rimless.firmware.clock`, unpaced): the rig of the arm-mid-step and
leg-identity tests, and its drive loop (`tests/support/firmware_walk.py` runs its walks on it)."""

from __future__ import annotations

from collections.abc import Callable, Iterator

from gpiozero.pins.mock import MockFactory

from rimless.firmware.clock import VirtualClock, seconds, sleeper
from rimless.firmware.control.controller import Channel, Controller
from rimless.firmware.control.detector import DetectorParams, LegDetector
from rimless.firmware.control.faults import HealthLimits, HealthMonitor
from rimless.firmware.drivers.adns3080 import Adns3080
from rimless.firmware.drivers.clutch import ClutchBank
from rimless.firmware.drivers.fake_adns3080 import DEFAULT_COUNTS_PER_M, FakeAdns3080

PINS = [17, 27, 22, 23, 24, 16, 20, 21]
LEGS = list(range(8))


class FakeWalkRig:
    """`trajectory(t)` (m, t in s from the end of the sensor's configuration) seen by the fake sensor with
    `noise_counts` of noise; the detector counts `LEGS` from `start_index` with `params`. The sensor is configured at
    `cpi` counts per inch with the automatic frame rate, as the service does (`mark_configured` included); the
    controller's `id_check_interval_s`, `verify_before_engage` and `readback_every_samples` are passed on. Close it
    (or use `with`)."""

    def __init__(
        self,
        trajectory: Callable[[float], float],
        params: DetectorParams,
        *,
        start_index: int = 0,
        noise_counts: float = 0.3,
        seed: int = 0,
        cpi: int = 1600,
        id_check_interval_s: float = 0.0,
        verify_before_engage: bool = True,
        readback_every_samples: int = 1,
    ) -> None:
        self.clock = VirtualClock(start_ns=0, paced=False)
        self.fake = fake = FakeAdns3080(
            trajectory, noise_counts=noise_counts, seed=seed, clock=seconds(self.clock), needs_reset=False
        )
        drv = Adns3080(
            fake, counts_per_m=DEFAULT_COUNTS_PER_M * cpi / 1600, sleep=sleeper(self.clock), clock_ns=self.clock.now_ns
        )
        drv.set_resolution(cpi)
        drv.set_frame_rate(None)
        drv.mark_configured()
        self.t0_ns = self.clock.now_ns()  # the walk's time starts after the configuration's waits
        fake.clock = lambda: (self.clock.now_ns() - self.t0_ns) * 1e-9
        self.factory = MockFactory()
        self.bank = ClutchBank(PINS, pin_factory=self.factory)
        self.controller = Controller(
            [Channel(drv, LegDetector(params, LEGS, start_index=start_index), HealthMonitor(HealthLimits()))],
            self.bank,
            clock_ns=self.clock.now_ns,
            id_check_interval_s=id_check_interval_s,
            verify_before_engage=verify_before_engage,
            readback_every_samples=readback_every_samples,
        )

    def drive(
        self, rate_hz: float, duration_s: float, *, first: int = 1
    ) -> Iterator[tuple[float, list[int], list[object]]]:
        """Step the controller once at each deadline k / `rate_hz` (k = `first`, `first` + 1, ... before
        `duration_s`); after each sample yield its time on the walk's clock (s), the clutches it engaged (sorted) and
        the records it emitted. The caller's code between two yields runs between two samples, as the sampler thread
        runs commands."""
        period_ns = round(1e9 / rate_hz)
        ctl = self.controller
        for k in range(first, int(duration_s * rate_hz)):
            self.clock.sleep_until(self.t0_ns + k * period_ns)
            t = (self.clock.now_ns() - self.t0_ns) * 1e-9
            before = set(self.bank.engaged())
            ctl.step()
            records = list(ctl.outbox)
            ctl.outbox.clear()
            yield t, sorted(set(self.bank.engaged()) - before), records

    def pins_high(self) -> list[int]:
        """The clutch indices whose pin is driven high now."""
        return [i for i, pin in enumerate(PINS) if self.factory.pin(pin).state]

    def close(self) -> None:
        self.bank.close()
        self.factory.close()

    def __enter__(self) -> FakeWalkRig:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
