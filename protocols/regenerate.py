"""Regenerate the committed MAVLink modules: ``python -m vtolftc.protocols.regenerate``.

Writes ``protocols/generated/vtolftc.py`` (mavgen on ``protocols/dialects/vtolftc.xml``) and
``protocols/generated/constants.py`` (its enum values and message ids as integers). Run it after
a change to the XML or to the pinned pymavlink; a test fails while either file is stale.
"""

from __future__ import annotations

import argparse
import importlib

from vtolftc.protocols import mavlink

__all__ = ["main"]


def main(argv: list[str] | None = None) -> int:
    """Regenerate both modules and print their paths; exit status 0."""
    ap = argparse.ArgumentParser(prog="python -m vtolftc.protocols.regenerate",
                                 description=__doc__.splitlines()[0])
    ap.parse_args(argv)
    print(mavlink.generate_dialect(mavlink.GENERATED_MODULE))
    module = importlib.reload(importlib.import_module("vtolftc.protocols.generated.vtolftc"))
    print(mavlink.generate_constants(mavlink.GENERATED_CONSTANTS, module))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
