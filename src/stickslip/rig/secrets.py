"""An arm's controller URL with its password, taken when the controller is opened, never kept.

A rig file holds no password (:mod:`.load` refuses one). An arm names where its
controller's password is: an environment variable (``password_env``, as
``$STICKSLIP_ANC300_PASSWORD`` is today) or the operating system's keyring
(``password_keyring = {service, user}``, through the optional ``keyring`` package,
imported only then). :func:`controller_url` adds it to the URL as ``password=`` just
before :func:`stickslip.devices.open_device` is called; every message shows the URL
through :func:`~stickslip.devices.base.redact_url`.
"""

from __future__ import annotations

import importlib
from urllib.parse import quote

from ..devices.base import secret_from_env
from .model import Arm

__all__ = ["PasswordMissing", "controller_url", "password"]


class PasswordMissing(ValueError):
    """The arm names a password source that holds none (the message says which, never a secret)."""


def password(arm: Arm) -> str | None:
    """The arm's controller password from its source, ``None`` if it names none.

    :class:`PasswordMissing` if the environment variable is unset or the keyring has no
    entry, or the ``keyring`` package is not installed (the message says how to install it).
    """
    if arm.password_env is not None:
        value = secret_from_env(arm.password_env)
        if value is None:
            raise PasswordMissing(f"arm {arm.name!r}: ${arm.password_env} is not set (its controller's password)")
        return value
    if arm.password_keyring is not None:
        service, user = arm.password_keyring
        try:
            keyring = importlib.import_module("keyring")
        except ImportError:
            raise PasswordMissing(
                f"arm {arm.name!r} keeps its password in the OS keyring, and the keyring package is not installed: "
                "pip install keyring (or set password_env instead)"
            ) from None
        try:
            value = keyring.get_password(service, user)
        except Exception as e:  # a keyring backend may raise anything (locked, no backend)
            raise PasswordMissing(f"arm {arm.name!r}: the keyring refused ({type(e).__name__})") from None
        if not value:
            raise PasswordMissing(f"arm {arm.name!r}: the keyring has no password for {service!r}, user {user!r}")
        return str(value)
    return None


def controller_url(arm: Arm) -> str:
    """The URL to open ``arm``'s controller with: its URL, plus ``password=`` from its source if it names one."""
    secret = password(arm)
    if secret is None:
        return arm.controller
    sep = "&" if "?" in arm.controller else "?"
    return f"{arm.controller}{sep}password={quote(secret, safe='')}"
