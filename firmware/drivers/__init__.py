"""The hardware boundary: the ADNS-3080 driver over SPI, its register-level fake, clutch outputs, backend choice.

`spi` (the SpiBus protocol and the spidev backend), `adns3080` (register map first, SI out), `fake_adns3080`
(answers transfer() like the chip), `clutch` (gpiozero outputs), `hardware` (the one place that picks the
real Pi or the fakes).

May import: the standard library, gpiozero, spidev (guarded), rimless.firmware.errors. Never numpy or scipy.
"""
