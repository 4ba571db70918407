"""Errors as RFC 9457 problem documents: type, title, status, detail, instance, plus
``field`` and ``index`` (DESIGN section 1's bad-input naming) and ``pointer`` (the JSON
pointer of the offending part of the request) for validation errors."""

from __future__ import annotations

from typing import Any

from lightsched import ValidationError

TYPE_BASE = "urn:lightsched:problem:"


class Problem(Exception):
    """A request the service refuses; nothing in any session has changed."""

    def __init__(self, status: int, kind: str, title: str, detail: str = "",
                 field: str | None = None, index: int | None = None,
                 pointer: str | None = None, headers: dict[str, str] | None = None) -> None:
        super().__init__(detail or title)
        self.status, self.kind, self.title, self.detail = status, kind, title, detail
        self.field, self.index, self.pointer = field, index, pointer
        self.headers = headers or {}

    def document(self, instance: str = "") -> dict[str, Any]:
        doc: dict[str, Any] = {"type": TYPE_BASE + self.kind, "title": self.title,
                               "status": self.status, "detail": self.detail or self.title}
        if instance:
            doc["instance"] = instance
        for key in ("field", "index", "pointer"):
            value = getattr(self, key)
            if value is not None:
                doc[key] = value
        return doc


def invalid(e: ValidationError, base: str = "") -> Problem:
    """422 for the core's ValidationError (DESIGN's field and first bad index), with the
    JSON pointer of that field in the request: ``base`` is where the core's fields live
    (``/config``, ``/lights``), a change batch adds ``/changes/<position>/fields``."""
    field = e.field
    if field.startswith("cameras."):
        pointer = f"/cameras/{e.index}/{field.split('.', 1)[1]}"
    elif e.position is not None:
        pointer = f"{base}/changes/{e.position}/fields/{field}"
    else:
        pointer = f"{base}/{field}"
    return Problem(422, "validation", "Invalid input", str(e), field=field, index=e.index,
                   pointer=pointer)


def not_found(what: str) -> Problem:
    return Problem(404, "not-found", "Not found", what)
