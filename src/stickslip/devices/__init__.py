"""Stick-slip controllers behind one small interface (see :mod:`stickslip.devices.base`).

``open_device("sim://")`` opens the simulated MM3A (the default); real backends
register their URL schemes in :data:`stickslip.devices.base.BACKENDS`.
"""

from .base import BACKENDS, Controller, DeviceError, DeviceInfo, device_key, open_device, register_backend

__all__ = ["BACKENDS", "Controller", "DeviceError", "DeviceInfo", "device_key", "open_device", "register_backend"]
