"""LightSched: per-object light sets, fade and shadow scheduling (see DESIGN.md).

The package is pure computation (numpy + numba, no I/O). ``Scheduler`` steps frames with
state; ``schedule`` is the stateless one-frame call; ``lightsched.reference`` holds the
float64 plain-loop oracle with the same API.

Kernels are ``@njit(cache=True, nogil=True, error_model="numpy")``: a division by zero gives
the IEEE result instead of a Python exception, so no kernel raises half way through a frame
and the hot loops carry no zero-divisor checks (about 9% of the object pass).
"""

from .frame import Frame
from .scene import Camera, Config, ValidationError
from .scheduler import Scheduler, schedule

__all__ = ["Camera", "Config", "Frame", "Scheduler", "ValidationError", "schedule"]
__version__ = "0.1.0"
