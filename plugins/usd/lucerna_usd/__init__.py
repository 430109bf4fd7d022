"""lucerna's USD plugin: opens a stage with usd-core (Pixar's own composition: references,
payloads, variants, instancing), validates it with `pxr.UsdValidation`, and converts the
composed stage into lucerna's scene file. `python -m lucerna_usd --help` describes the
command line the renderer calls."""
import os
import time

# What the renderer reads as a sign of life: a conversion that sends none for minutes is
# stuck, and the renderer stops it (a stage's size sets no useful bound on its own).
HEARTBEAT = "lucerna-usd: heartbeat"
_beat = {"fd": None, "last": 0.0}


def start_heartbeat():
    """Keeps a copy of the process's stderr for heartbeats: usd-core's own diagnostics are
    captured by redirecting stderr during conversion, and heartbeats must pass."""
    if _beat["fd"] is None:
        _beat["fd"] = os.dup(2)


def heartbeat():
    """Tells the renderer the conversion goes on (at most once a second); called as prims
    and images are converted."""
    now = time.monotonic()
    if _beat["fd"] is not None and now - _beat["last"] >= 1.0:
        _beat["last"] = now
        try:
            os.write(_beat["fd"], (HEARTBEAT + "\n").encode())
        except OSError:
            pass


class StageError(Exception):
    """A stage that cannot be converted: `element` (a prim or property path, or a file
    element) and `reason`. The command line reports it and exits with status 2."""

    def __init__(self, element, reason):
        super().__init__(f"{element}: {reason}")
        self.element = element
        self.reason = reason
