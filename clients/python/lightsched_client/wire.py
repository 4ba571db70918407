"""The LightSched wire format (schemas/wire.md), shared by the server and the Python client.

A message is a map. ``application/msgpack`` is the main encoding, ``application/json`` the
debugging one; both carry the same maps. A numeric array travels as
``{"dtype": name, "shape": [..], "data": bytes}`` with the raw little-endian C-order bytes
(msgpack bin; base64 text in JSON); plain nested lists are accepted on input too. Encoding
is deterministic (maps keep the order they were built in, floats are float64), so the golden
examples in schemas/examples can be replayed byte for byte.
"""

from __future__ import annotations

import base64
import json
import sys
from typing import Any

import msgpack
import numpy as np

MSGPACK = "application/msgpack"
JSON = "application/json"
PROBLEM_JSON = "application/problem+json"
PROBLEM_MSGPACK = "application/problem+msgpack"
VERSION = "v1"

# dtype names a wire array may carry (numpy's names; all little-endian on the wire).
DTYPES = ("bool", "int8", "uint8", "int16", "uint16", "int32", "uint32", "int64", "uint64",
          "float32", "float64")
ARRAY_KEYS = frozenset(("dtype", "shape", "data"))
# The fast paths below (msgpack only) skip what a native little-endian C-order array or a
# well-formed array map does not need: dtype.name (~2 us), np.prod (~6 us), a copy. Anything
# else takes the general code, which gives the same bytes and the same errors.
_LITTLE = sys.byteorder == "little"
_NAME_OF = {np.dtype(n): n for n in DTYPES} if _LITTLE else {}
_NATIVE = {n: np.dtype(n) for n in DTYPES} if _LITTLE else {}


class WireError(ValueError):
    """A message that cannot be decoded; ``pointer`` is the JSON pointer of the bad part."""

    def __init__(self, pointer: str, message: str) -> None:
        self.pointer = pointer
        self.message = message
        super().__init__(f"{pointer or '/'}: {message}")


def encode_array(a: np.ndarray, binary: bool) -> dict[str, Any]:
    a = np.asarray(a)
    if a.dtype.name not in DTYPES:
        raise TypeError(f"cannot send dtype {a.dtype}")
    # A memoryview: msgpack packs it as bin without another copy.
    c = np.ascontiguousarray(a, dtype=a.dtype.newbyteorder("<"))
    data = memoryview(c.reshape(-1).view(np.uint8)) if c.size else b""
    return {"dtype": a.dtype.name, "shape": list(a.shape),
            "data": data if binary else base64.b64encode(data).decode("ascii")}


def _packable(value: Any) -> Any:
    """msgpack's ``default`` hook: what msgpack cannot pack by itself, in its wire form
    (numpy arrays and scalars; the same bytes as packing ``to_wire(doc, True)``)."""
    if isinstance(value, np.ndarray):
        name = _NAME_OF.get(value.dtype)
        if name is None or not value.flags.c_contiguous:
            return encode_array(value, True)
        return {"dtype": name, "shape": list(value.shape),
                "data": memoryview(value if value.ndim == 1 else value.reshape(-1)).cast("B")
                if value.size else b""}
    if isinstance(value, np.generic):
        return value.item()
    raise TypeError(f"cannot serialize {type(value).__name__}")


class _NotFast(Exception):
    """An array map the fast decoder leaves to decode_array (which names the error)."""


def _array_hook(doc: dict[str, Any]) -> Any:
    """msgpack's ``object_hook``: a well-formed array map into its (read-only) array, as
    decode_array makes it; anything else about an array map raises _NotFast."""
    if "dtype" not in doc:
        return doc
    if len(doc) != 3 or "data" not in doc or "shape" not in doc:
        raise _NotFast
    dtype, shape, data = doc["dtype"], doc["shape"], doc["data"]
    if type(dtype) is not str or type(shape) is not list or type(data) is not bytes:
        raise _NotFast
    dt = _NATIVE.get(dtype)
    if dt is None:
        raise _NotFast
    count = 1
    for n in shape:
        if type(n) is not int or n < 0:
            raise _NotFast
        count *= n
    if len(data) != count * dt.itemsize:
        raise _NotFast
    return np.frombuffer(data, dtype=dt).reshape(shape)


def is_array_doc(value: Any) -> bool:
    """A map with a ``dtype`` key is an array map (no other map of the wire has one)."""
    return isinstance(value, dict) and "dtype" in value


def decode_array(doc: dict[str, Any], pointer: str) -> np.ndarray:
    if doc.keys() != ARRAY_KEYS:
        raise WireError(pointer, "an array map has exactly the keys dtype, shape and data; "
                        f"this one has {', '.join(map(str, doc))}")
    dtype, shape, data = doc["dtype"], doc["shape"], doc["data"]
    if dtype not in DTYPES:
        raise WireError(pointer + "/dtype", f"unknown dtype {dtype!r}; one of {', '.join(DTYPES)}")
    if not isinstance(shape, list) or not all(
            isinstance(s, int) and not isinstance(s, bool) and s >= 0 for s in shape):
        raise WireError(pointer + "/shape", "must be a list of non-negative integers")
    if isinstance(data, str):
        try:
            data = base64.b64decode(data, validate=True)
        except ValueError:
            raise WireError(pointer + "/data", "is not valid base64") from None
    if not isinstance(data, (bytes, bytearray)):
        raise WireError(pointer + "/data", "must be bytes (msgpack bin) or base64 text")
    dt = np.dtype(dtype).newbyteorder("<")
    count = int(np.prod(shape, dtype=np.int64)) if shape else 1
    if len(data) != count * dt.itemsize:
        raise WireError(pointer + "/data", f"has {len(data)} bytes, shape {shape} of {dtype} "
                        f"needs {count * dt.itemsize}")
    return np.frombuffer(data, dtype=dt).reshape(shape).astype(dt.newbyteorder("="), copy=False)


def to_wire(value: Any, binary: bool) -> Any:
    """numpy arrays (and numpy scalars) inside maps and lists into their wire form."""
    if isinstance(value, np.ndarray):
        return encode_array(value, binary)
    if isinstance(value, dict):
        return {k: to_wire(v, binary) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [to_wire(v, binary) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    return value


def from_wire(value: Any, pointer: str = "") -> Any:
    """Wire arrays inside maps and lists into numpy arrays (everything else as is)."""
    if is_array_doc(value):
        return decode_array(value, pointer)
    if isinstance(value, dict):
        return {k: from_wire(v, f"{pointer}/{k}") for k, v in value.items()}
    if isinstance(value, list):
        return [from_wire(v, f"{pointer}/{i}") for i, v in enumerate(value)]
    return value


def media_type(content_type: str | None) -> str | None:
    """MSGPACK or JSON from a Content-Type / Accept value, None if neither."""
    base = (content_type or "").split(";")[0].strip().lower()
    if base in (MSGPACK, "application/x-msgpack", "application/vnd.msgpack", PROBLEM_MSGPACK):
        return MSGPACK
    if base in (JSON, PROBLEM_JSON, "text/json"):
        return JSON
    return None


def dumps(doc: Any, kind: str) -> bytes:
    """Encodes a message (numpy arrays allowed inside) as msgpack or JSON bytes."""
    if kind == MSGPACK:
        if _LITTLE:
            return msgpack.packb(doc, use_bin_type=True, default=_packable)
        return msgpack.packb(to_wire(doc, True), use_bin_type=True)
    return json.dumps(to_wire(doc, False), separators=(",", ":"), allow_nan=False).encode()


def loads(body: bytes, kind: str) -> Any:
    """Decodes msgpack or JSON bytes into maps, lists and numpy arrays; WireError if
    malformed."""
    if kind == MSGPACK and _LITTLE:
        try:
            return msgpack.unpackb(body, raw=False, strict_map_key=True, object_hook=_array_hook)
        except _NotFast:
            pass  # a bad (or unusual) array map: the general path below names it
        except (ValueError, msgpack.ExtraData, msgpack.FormatError, msgpack.StackError,
                TypeError):
            pass  # malformed: the same error from the general path
    try:
        if kind == MSGPACK:
            doc = msgpack.unpackb(body, raw=False, strict_map_key=True)
        else:
            doc = json.loads(body)
    except (ValueError, msgpack.ExtraData, msgpack.FormatError, msgpack.StackError,
            TypeError) as e:
        raise WireError("", f"malformed {kind.split('/')[1]}: {e}") from None
    return from_wire(doc)
