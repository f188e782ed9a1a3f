"""What stands in for the hardware: the simulated arm, what its microphone hears, and
emulators of the controllers' serial protocols.

* :mod:`.arm`        the closed-form simulated MM3A (``sim://``), a virtual clock and microphone
* :mod:`.sound`      the room: stepping clicks, end-stop rattles, noise, knocks, babble
* :mod:`.emulators`  NanoControl and ANC300 protocol emulators on a pty or TCP, moving an arm

Nothing in :mod:`stickslip` below this package imports it: a device URL names its
backend by module path (see :data:`stickslip.devices.base.BACKENDS`).
"""
