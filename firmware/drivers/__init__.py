"""The hardware boundary: the ADNS-3080 driver over SPI, its register-level fake, clutch and other GPIO outputs.

`spi` (the SpiBus protocol and the spidev backend), `adns3080` (register map first, SI out), `fake_adns3080`
(answers transfer() like the chip), `clutch` (gpiozero outputs, one per leg), `gpio` (mock pin factory,
RESET/NPD/chip-select outputs, opening and releasing the clutch pins). The drivers know nothing of the
configuration or the control path: `rimless.firmware.service.hardware` assembles them.

May import: the standard library, gpiozero, spidev (guarded), rimless.firmware.errors. Never numpy or scipy.
"""
