"""schemas/conformance/: the scenarios every client runs against a live service, and the
answers it must get, as scikit-learn's check_estimator holds every estimator to one suite.

A scenario is a list of steps, each one call of the client API under DESIGN section 7's
names: ``session`` (with a config), the six scene changes (held until the next frame),
``frame``, ``explain``, ``info``, ``close`` and the stateless ``schedule``; and ``lose``,
where the runner deletes the session behind the client's back (as a dead worker loses it:
the service answers 404 for it), after which the client must rebuild it from its mirror of
the scene, the next frame a cut of a new session. A ``frame``,
``explain`` or ``schedule`` step carries either ``expect`` (the frame_index and every array
asked for, as the full frame: a client merges changed_only answers before comparing; an
explanation's object_id, frame_index and columns) or ``error`` (status, type, field, index
and pointer of the problem document). Arrays are JSON wire maps (base64).

The expectations come from the embedded lightsched.Scheduler, not from the service, so
the suite also holds the service to the embedded API. A refused frame leaves nothing
changed, as the service promises: the steps after it show that.
"""

from __future__ import annotations

import json
from typing import Any

import numpy as np
from lightsched_client.client import camera_doc, config_doc
from lightsched_client.wire import to_wire

import lightsched as ls
from lightsched.fields import FRAME_FIELDS
from lightsched.frame import changed_rows
from lightsched.scene import CHANGE_OPS, validate_cameras, validate_dt
from lightsched.scenes import city, move_lights

from .problems import TYPE_BASE, invalid
from .service import CHANGE_KEYS, explanation_document


def _wire(value: Any) -> Any:
    return to_wire(value, False)


def _fields(fields: dict[str, Any]) -> dict[str, Any]:
    return {k: _wire(np.asarray(v)) for k, v in fields.items()}


def _error(p: Any) -> dict[str, Any]:
    doc = p.document()
    return {k: doc.get(k) for k in ("status", "type", "field", "index", "pointer")}


def _frame_expect(f: Any, frame_index: int, outputs: list[str] | None,
                  priority: np.ndarray | None = None) -> dict[str, Any]:
    names = [n for n in FRAME_FIELDS if outputs is None or n in outputs]
    arrays = {n: _wire(getattr(f, n)) for n in names}
    if priority is not None and "priority" in arrays:
        arrays["priority"] = _wire(priority)
    return {"frame_index": frame_index, "arrays": arrays}


class Script:
    """Builds a scenario's steps while running them on the embedded scheduler."""

    def __init__(self, name: str, description: str) -> None:
        self.name, self.description = name, description
        self.steps: list[dict[str, Any]] = []
        self.sched: ls.Scheduler | None = None
        self.pending: list[tuple[str, dict[str, Any]]] = []
        # The session's last frame (what changed_only answers differ from) and the
        # priority a client holds after it: changed_only does not send a row whose only
        # change is priority, so the client keeps the last value sent (wire.md).
        self.prev: Any = None
        self.held_priority: np.ndarray | None = None
        # Every change the session took, in order: what a client's mirror replays.
        self.applied: list[tuple[str, dict[str, Any]]] = []
        self.config: ls.Config | None = None
        self.lost = False

    def session(self, config: ls.Config) -> None:
        self.steps.append({"call": "session", "config": config_doc(config)})
        self.sched = ls.Scheduler(config)
        self.config = config

    def start(self, config: ls.Config, scene: Any, changed_only: bool = False) -> None:
        """A session with the scene set and its first frame."""
        self.session(config)
        self.change("set_lights", **scene.lights)
        self.change("set_objects", **scene.objects)
        self.frame(scene.cameras, changed_only=changed_only)

    def lose(self) -> None:
        """The session is lost (the runner deletes it): the next frame rebuilds it."""
        self.steps.append({"call": "lose"})
        self.lost = True

    def change(self, op: str, **fields: Any) -> None:
        assert op in CHANGE_OPS
        self.steps.append({"call": op, "fields": _fields(fields)})
        self.pending.append((op, fields))

    def frame(self, cameras: list[Any], dt: float = 1 / 60, cut: bool = False,
              changed_only: bool = False, outputs: list[str] | None = None) -> None:
        """The frame as the service runs it: cameras and dt checked, then the changes
        and the frame all or nothing."""
        sched, pending, self.pending = self.sched, self.pending, []
        assert sched is not None and self.config is not None
        step: dict[str, Any] = {"call": "frame",
                                "cameras": [_wire(camera_doc(c)) for c in cameras],
                                "dt": dt, "cut": cut, "changed_only": changed_only,
                                "outputs": outputs}
        if self.lost:
            # A new session given the scene as the client mirrors it, then this frame's
            # own changes, as a cut (the client makes it one).
            sched = self.sched = ls.Scheduler(self.config)
            sched.apply(self.applied)
            self.prev = self.held_priority = None
            self.lost, cut = False, True
        try:
            cams = validate_cameras([camera_doc(c) for c in cameras])
            validate_dt(dt)
            with sched.transaction():
                sched.apply(pending)
                f = sched.frame(cams, dt=dt, cut=cut)
            self.applied += pending
            priority = f.priority
            if changed_only and self.prev is not None and self.held_priority is not None:
                old = self.prev.object_id
                pos = np.minimum(np.searchsorted(old, f.object_id), max(old.size - 1, 0))
                keep = ~changed_rows(self.prev, f, CHANGE_KEYS)
                priority = priority.copy()
                priority[keep] = self.held_priority[pos[keep]]
            self.prev = f
            self.held_priority = priority if outputs is None or "priority" in outputs else None
            step["expect"] = _frame_expect(f, sched.frame_index - 1, outputs, priority)
        except ls.ValidationError as e:
            step["error"] = _error(invalid(e))
        self.steps.append(step)

    def explain(self, object_id: int) -> None:
        """explain of the last frame: the columns as the service sends them, or the
        refusal of an id the last frame did not have."""
        assert self.sched is not None
        step: dict[str, Any] = {"call": "explain", "object_id": object_id}
        try:
            doc = explanation_document(self.sched.explain(object_id))
            step["expect"] = {k: v if k == "reason" or np.isscalar(v) else _wire(v)
                              for k, v in doc.items()}
        except ls.ValidationError as e:
            step["error"] = _error(invalid(e))
        self.steps.append(step)

    def info(self) -> None:
        s = self.sched
        assert s is not None
        self.steps.append({"call": "info", "expect": {
            "frame_index": s.frame_index, "lights": len(s.lights), "objects": len(s.objects)}})

    def close(self) -> None:
        self.steps.append({"call": "close"})

    def frame_after_close(self, cameras: list[Any]) -> None:
        self.steps.append({"call": "frame", "cameras": [_wire(camera_doc(c)) for c in cameras],
                           "dt": 1 / 60, "cut": False, "changed_only": False, "outputs": None,
                           "error": {"status": 404, "type": TYPE_BASE + "not-found",
                                     "field": None, "index": None, "pointer": None}})

    def schedule(self, lights: dict[str, Any], objects: dict[str, Any], cameras: list[Any],
                 config: ls.Config | None = None, outputs: list[str] | None = None) -> None:
        step: dict[str, Any] = {"call": "schedule", "lights": _fields(lights),
                                "objects": _fields(objects),
                                "cameras": [_wire(camera_doc(c)) for c in cameras],
                                "config": config_doc(config), "outputs": outputs}
        sched = ls.Scheduler(config or ls.Config())
        try:
            for base, call, given in (("/lights", sched.set_lights, lights),
                                      ("/objects", sched.set_objects, objects)):
                try:
                    call(**given)
                except ls.ValidationError as e:
                    raise invalid(e, base) from None
            f = sched.frame(validate_cameras([camera_doc(c) for c in cameras]), dt=0.0,
                            cut=True)
            step["expect"] = _frame_expect(f, 0, outputs)
        except Exception as p:  # a Problem from invalid()
            if not hasattr(p, "document"):
                raise
            step["error"] = _error(p)
        self.steps.append(step)

    def document(self) -> dict[str, Any]:
        return {"$comment": "Generated by python -m lightsched_server.schemas from "
                            "server/conformance.py; do not edit.",
                "name": self.name, "description": self.description, "steps": self.steps}


def lifecycle() -> Script:
    sc = city(60, 12, seed=5, shadow_fraction=0.3, sun_shadows=True)
    s = Script("lifecycle", "A session through every scene call: set, frames with moving "
                            "lights (full and changed_only), object updates and removals, "
                            "light removal, a second camera, a cut, info and close.")
    s.start(ls.Config(max_lights=4, shadow_budget=3, fade_in=0.1, fade_out=0.1), sc)
    for i in range(1, 4):
        s.change("update_lights", id=sc.lights["id"], position=move_lights(sc.lights, i))
        s.frame(sc.cameras, dt=0.05, changed_only=i > 1)
    ids = sc.objects["id"]
    s.change("update_objects", id=ids[:5], bounds_min=sc.objects["bounds_min"][:5] + 3.0,
             bounds_max=sc.objects["bounds_max"][:5] + 3.0)
    s.change("remove_objects", id=ids[10:20])
    s.frame(sc.cameras, dt=0.05, changed_only=True)
    for oid in ids[:3]:
        s.explain(int(oid))
    s.change("remove_lights", id=sc.lights["id"][:3])
    s.change("set_objects", id=np.array([5000, 5001], np.int32),
             bounds_min=np.array([[0.0, 0.0, 0.0], [10.0, 0.0, 10.0]]),
             bounds_max=np.array([[2.0, 4.0, 2.0], [12.0, 6.0, 12.0]]))
    second = ls.Camera(position=np.array([20.0, 30.0, 20.0]), forward=np.array([-1.0, -1.0, -1.0]),
                       up=np.array([0.0, 1.0, 0.0]), fov_y=0.9, aspect=1.5, near=0.5, far=400.0,
                       id=7)
    s.frame([*sc.cameras, second], dt=0.05, changed_only=True)
    s.frame([second], dt=0.05, cut=True, changed_only=True)
    s.frame([second], dt=0.05, outputs=["object_id", "light_ids", "fade_weight", "shadow_lights"])
    s.info()
    s.close()
    s.frame_after_close([second])
    return s


def refusals() -> Script:
    sc = city(30, 8, seed=6, shadow_fraction=0.3)
    s = Script("refusals", "Bad calls and their problem documents; each leaves the session "
                           "as it was, as the frames after them show.")
    s.start(ls.Config(max_lights=3), sc, changed_only=True)  # a first frame: answered in full
    bad = {k: np.array(v, copy=True) for k, v in sc.lights.items()}
    bad["radius"][2] = -1.0
    s.change("update_lights", id=sc.lights["id"], position=move_lights(sc.lights, 1))
    s.change("set_lights", **bad)
    s.frame(sc.cameras)  # refused: radius, row 2, change 1
    s.change("remove_objects", id=np.array([123456], np.int32))
    s.frame(sc.cameras)  # refused: an unknown id
    boxes = {k: np.array(v, copy=True) for k, v in sc.objects.items()}
    boxes["bounds_max"][4, 1] = boxes["bounds_min"][4, 1] - 1.0
    s.change("set_objects", **boxes)
    s.frame(sc.cameras)  # refused: an inverted box
    cam = camera_doc(sc.cameras[0])
    s.frame([{**cam, "fov_y": -1.0}])  # refused: cameras.fov_y
    s.frame([cam, {**cam, "id": 0}])  # refused: a repeated camera id
    s.frame(sc.cameras, dt=-0.5)  # refused: dt
    s.explain(int(sc.objects["id"][0]))  # the first frame's, after six refused ones
    s.explain(123456)  # refused: no such object
    s.change("update_lights", id=sc.lights["id"], position=move_lights(sc.lights, 1))
    s.frame(sc.cameras, changed_only=True)
    s.info()
    return s


def stateless() -> Script:
    sc = city(40, 10, seed=7, shadow_fraction=0.3, sun_shadows=True)
    s = Script("schedule", "The stateless call: a frame with every set on at weight 1, a "
                           "selection of outputs, and a refusal naming the field and row.")
    s.schedule(sc.lights, sc.objects, sc.cameras, ls.Config(max_lights=2, shadow_budget=2))
    s.schedule(sc.lights, sc.objects, sc.cameras, None, outputs=["object_id", "count"])
    bad = {k: np.array(v, copy=True) for k, v in sc.objects.items()}
    bad["bounds_min"][3, 0] = np.nan
    s.schedule(sc.lights, bad, sc.cameras)
    return s


def recovery() -> Script:
    sc = city(50, 10, seed=8, shadow_fraction=0.3)
    s = Script("recovery", "A session lost twice (its worker died): the client rebuilds it "
                           "from its mirror of the scene (sets, updates and removals, some "
                           "refused) and the frame it was sending goes on as a cut.")
    s.start(ls.Config(max_lights=3, shadow_budget=2, fade_in=0.1, fade_out=0.1), sc)
    ids = sc.objects["id"]
    for i in range(1, 3):
        s.change("update_lights", id=sc.lights["id"], position=move_lights(sc.lights, i))
        s.frame(sc.cameras, dt=0.05, changed_only=True)
    s.change("update_objects", id=ids[:4], bounds_min=sc.objects["bounds_min"][:4] + 2.0,
             bounds_max=sc.objects["bounds_max"][:4] + 2.0)
    s.change("remove_lights", id=sc.lights["id"][:2])
    s.frame(sc.cameras, dt=0.05)
    s.change("remove_objects", id=np.array([123456], np.int32))
    s.frame(sc.cameras)  # refused: nothing of it joins the mirror
    # A field the set did not give (a client's mirror cannot fold it into the set's
    # arrays without the defaults: it keeps the call), then more moves after it.
    s.change("update_lights", id=sc.lights["id"][2:4], priority=np.array([5.0, 0.5]))
    s.change("remove_objects", id=ids[5:8])
    s.frame(sc.cameras, dt=0.05)
    s.lose()
    s.change("update_lights", id=sc.lights["id"][2:], position=move_lights(sc.lights, 3)[2:])
    s.frame(sc.cameras, dt=0.05, changed_only=True)  # rebuilt: a new session's frame 0
    s.frame(sc.cameras, dt=0.05, changed_only=True)
    s.info()
    s.lose()
    s.frame(sc.cameras, dt=0.05)
    s.info()
    return s


SCENARIOS = (lifecycle, refusals, stateless, recovery)


def conformance_files() -> dict[str, bytes]:
    """schemas/conformance/<name>.json for every scenario."""
    out = {}
    for make in SCENARIOS:
        script = make()
        text = json.dumps(script.document(), indent=1, allow_nan=False) + "\n"
        out[f"conformance/{script.name}.json"] = text.encode()
    return out


__all__ = ["SCENARIOS", "Script", "conformance_files"]
