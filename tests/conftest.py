"""Suite-wide hypothesis profile (see tests/helpers.py): deadline off, blobs printed,
example counts scaled by the LIGHTSCHED_EXAMPLES environment variable."""

from helpers import register_profile

register_profile()
