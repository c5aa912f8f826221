"""MAVLink 2 signing of the HIL link (vehicle <-> autopilot): the key, from the environment.

The vehicle pins the first autopilot it hears (see :mod:`vtolftc.firmware_sim.vehicle.process`).
Without signing, whoever sends the first HEARTBEAT as system 1 / component 1 to the vehicle's
HIL port is pinned, a stranger included. With a key, both ends sign every frame they send and
their links drop every incoming frame that is unsigned, badly signed or replayed (counted as
``dropped_signature``), so only a holder of the key can be pinned, over UDP and zenoh alike.

The key is a shared secret of 32 bytes given to both processes as 64 hexadecimal digits in the
environment variable :data:`HIL_KEY_ENV` (not on the command line, which every local user can
read); :func:`new_hil_key` makes one (``vtolftc sitl`` makes a fresh one for every run).
"""

from __future__ import annotations

import os
import secrets
from collections.abc import Mapping

from vtolftc.protocols.mavlink import SigningConfig

__all__ = ["HIL_KEY_ENV", "hil_signing_from_env", "new_hil_key"]

HIL_KEY_ENV = "VTOLFTC_HIL_KEY"
"""Environment variable holding the HIL link's signing key (64 hexadecimal digits)."""


def new_hil_key() -> str:
    """A fresh random HIL signing key as 64 hexadecimal digits."""
    return secrets.token_hex(32)


def hil_signing_from_env(environ: Mapping[str, str] | None = None) -> SigningConfig | None:
    """The HIL link's signing configuration from :data:`HIL_KEY_ENV`.

    Parameters
    ----------
    environ
        the environment (default ``os.environ``).

    Returns
    -------
    SigningConfig or None
        None when the variable is unset or empty (an unsigned link); otherwise outgoing frames
        are signed and every incoming frame must carry a valid signature.

    Raises
    ------
    ValueError
        the variable is set but is not 64 hexadecimal digits (one line, names the variable).
    """
    value = (os.environ if environ is None else environ).get(HIL_KEY_ENV, "").strip()
    if not value:
        return None
    try:
        key = bytes.fromhex(value)
    except ValueError:
        key = b""
    if len(key) != 32:
        raise ValueError(f"{HIL_KEY_ENV}: expected 64 hexadecimal digits (a 32-byte key), "
                         f"got {len(value)} characters")
    return SigningConfig(key, allow_unsigned=False)
