"""The viewer (/viewer) and the TypeScript client in a real browser: Debian's chromium
driven by Playwright, against a real `lightsched serve` started on a free port.

These need chromium (`make browser-deps`) and the built viewer (`make viewer`); `make test`
makes both first. Without them the tests fail, saying which command to run: a skip would
let CI pass without ever having drawn a frame.

Screenshots go to build/screenshots/; with LIGHTSCHED_VIEWER_SCREENSHOT=<path> the lit
view with a clicked object's explain panel is also written there (`make viewer-screenshot`
writes the README's docs/viewer.png).
"""

from __future__ import annotations

import base64
import functools
import http.server
import io
import os
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest
from lightsched_server.viewer import viewer_dir

pytestmark = pytest.mark.browser

REPO = Path(__file__).resolve().parent.parent
CHROMIUM = Path(os.environ.get("LIGHTSCHED_CHROMIUM", "/usr/bin/chromium"))
SCREENSHOTS = REPO / "build" / "screenshots"
# The first frames of a server on a machine whose numba cache is cold compile the kernels
# they use (minutes on 2 busy cores); later ones take milliseconds.
FIRST_FRAMES_MS = 900_000
# WebGL without a GPU: ANGLE over SwiftShader, chromium's software renderer.
CHROMIUM_ARGS = ["--use-angle=swiftshader", "--enable-unsafe-swiftshader"]


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@contextmanager
def lightsched_serve(**env: str) -> Iterator[str]:
    """`lightsched serve` in a child process on a free port, with ``env`` as its only
    LIGHTSCHED_* settings; yields its URL."""
    port = _free_port()
    clean = {k: v for k, v in os.environ.items() if not k.startswith("LIGHTSCHED_")}
    proc = subprocess.Popen(
        [sys.executable, "-m", "lightsched", "serve", "--host", "127.0.0.1", "--port", str(port),
         "--no-demo", "--no-warm-up", "--log-level", "warning"], cwd=REPO, env={**clean, **env})
    url = f"http://127.0.0.1:{port}"
    try:
        deadline = time.monotonic() + 120
        while True:
            assert proc.poll() is None, f"lightsched serve exited with {proc.returncode}"
            try:
                if httpx.get(f"{url}/healthz", timeout=2).status_code == 200:
                    break
            except httpx.HTTPError:
                pass
            assert time.monotonic() < deadline, "lightsched serve did not listen within 120 s"
            time.sleep(0.2)
        yield url
    finally:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(timeout=20)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


@pytest.fixture(scope="module")
def browser() -> Iterator[Any]:
    if not CHROMIUM.is_file():
        pytest.fail(f"{CHROMIUM} is missing: run `make browser-deps` (Debian's chromium)")
    if not (viewer_dir() / "index.html").is_file():
        pytest.fail(f"the viewer is not built in {viewer_dir()}: run `make viewer`")
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        b = p.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS)
        yield b
        b.close()


@pytest.fixture(scope="module")
def service() -> Iterator[str]:
    with lightsched_serve() as url:
        yield url


def canvas_pixels(page: Any) -> np.ndarray:
    """The canvas alone (no panels over it) as an RGB array: its drawing buffer is kept
    (preserveDrawingBuffer), so toDataURL reads the last frame drawn."""
    from PIL import Image

    url = page.evaluate("() => document.getElementById('view').toDataURL('image/png')")
    png = base64.b64decode(url.split(",", 1)[1])
    return np.asarray(Image.open(io.BytesIO(png)).convert("RGB"), dtype=np.int16)


def stats(page: Any) -> dict[str, Any]:
    return page.evaluate("""() => { const s = window.lightsched; return {frames: s.frames,
        frameIndex: s.frameIndex, maxCount: s.maxCount, setsChanged: s.setsChanged,
        shadowViews: s.shadowViews, shadowedSlots: s.shadowedSlots,
        programs: s.programs(), error: s.error, config: s.config, explained: s.explained}; }""")


def wait_frames(page: Any, more: int, timeout_ms: int = 120_000) -> dict[str, Any]:
    """Waits until ``more`` frames past the current one have been drawn."""
    start = stats(page)["frames"]
    page.wait_for_function(f"() => window.lightsched.frames >= {start + more}", timeout=timeout_ms)
    return stats(page)


def open_viewer(browser: Any, service: str) -> tuple[Any, list[str]]:
    page = browser.new_page(viewport={"width": 1280, "height": 720})
    errors: list[str] = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    page.goto(f"{service}/viewer")
    page.wait_for_function("() => window.lightsched && window.lightsched.frames >= 10",
                           timeout=FIRST_FRAMES_MS)
    return page, errors


def test_viewer_draws_the_city_and_reconfigures_without_recompiling(browser, service):
    page, errors = open_viewer(browser, service)
    SCREENSHOTS.mkdir(parents=True, exist_ok=True)
    first = stats(page)
    assert first["error"] is None and first["config"]["max_lights"] == 8
    assert first["maxCount"] > 2, "some object should hold more than two lights at K = 8"
    # The city's shadowed lights have their maps drawn and slots that sample them.
    assert first["shadowViews"] > 0 and first["shadowedSlots"] > 0, first

    # Not blank: a lit city has many colours, not a cleared buffer.
    before = canvas_pixels(page)
    assert before.std() > 5 and len(np.unique(before.reshape(-1, 3), axis=0)) > 500

    # The lights move with the camera still: the picture changes and sets change, yet the
    # patched material keeps its program (K is its only compile-time constant).
    programs = first["programs"]
    page.wait_for_function(f"() => window.lightsched.setsChanged >= {first['setsChanged'] + 200}",
                           timeout=120_000)
    moved = wait_frames(page, 10)
    after = canvas_pixels(page)
    changed = np.abs(after - before).max(axis=2) > 8
    assert changed.mean() > 0.002, "the lights moved but the picture stayed the same"
    assert moved["programs"] == programs, "a light set change compiled a shader"
    page.screenshot(path=SCREENSHOTS / "viewer-lit.png")

    # Each overlay draws something of its own.
    for overlay in ("count", "fade", "shadows"):
        page.select_option("#overlay", overlay)
        wait_frames(page, 3)
        pixels = canvas_pixels(page)
        assert np.abs(pixels - after).max(axis=2).mean() > 1, f"the {overlay} overlay drew nothing"
        page.screenshot(path=SCREENSHOTS / f"viewer-{overlay}.png")
    page.select_option("#overlay", "lit")

    # K = 2: a new session, and no object holds more than two lights.
    page.select_option("#max_lights", "2")
    page.click("#apply")
    page.wait_for_function("() => window.lightsched.config.max_lights === 2 && window.lightsched.frames >= 5",
                           timeout=120_000)
    two = wait_frames(page, 5)
    assert two["error"] is None and 0 < two["maxCount"] <= 2
    page.screenshot(path=SCREENSHOTS / "viewer-k2.png")
    assert errors == []
    page.close()


def test_viewer_explains_a_clicked_object(browser, service):
    page, errors = open_viewer(browser, service)
    target = page.evaluate("() => window.lightsched.pickable()")
    assert target is not None, "no lit object on screen to click"
    page.mouse.click(target["x"], target["y"])
    page.wait_for_selector("#explain table, #explain-error", timeout=30_000)
    panel = page.inner_text("#explain")
    assert "explain failed" not in panel, panel
    explained = stats(page)["explained"]
    assert explained["object_id"] == target["objectId"]
    selected = [light for light, reason in zip(explained["light_id"], explained["reason"], strict=True)
                if reason == "selected"]
    assert selected, f"object {target['objectId']} holds at least two lights: {explained}"
    for light in selected:
        assert f"{light}\tselected" in panel or f"{light} selected" in panel, panel
    SCREENSHOTS.mkdir(parents=True, exist_ok=True)
    page.screenshot(path=SCREENSHOTS / "viewer-explain.png")
    if picture := os.environ.get("LIGHTSCHED_VIEWER_SCREENSHOT"):
        shutil.copyfile(SCREENSHOTS / "viewer-explain.png", REPO / picture)
    assert errors == []
    page.close()


# One box (-1..1) facing a camera on +z, white Lambert, linear output: the centre pixel is
# the face centre's diffuse light, so the shader's numbers can be checked against DESIGN
# section 2's formulas. Each case is a new frame of the same instances and material.
SHADER_CASES = """async () => {
  const L = await import("/viewer/lightsched-three.js");
  const canvas = document.createElement("canvas");
  canvas.width = canvas.height = 64;
  document.body.append(canvas);
  const renderer = new L.WebGLRenderer({ canvas, preserveDrawingBuffer: true });
  renderer.outputColorSpace = L.LinearSRGBColorSpace;
  const table = new L.LightTable();
  // Light 4: a point 2 m in front of the face, radius 10. Lights 6 and 7: spots there
  // too, 6 aimed at the face, 7 sideways. Light 9: a directional light travelling towards
  // -z, intensity 0.5.
  table.set({ id: [9, 4, 6, 7], type: [2, 0, 1, 1],
              position: [0, 0, 0, 0, 0, 3, 0, 0, 3, 0, 0, 3], radius: [1, 10, 10, 10],
              direction: [0, 0, -1, 0, -1, 0, 0, 0, -1, 1, 0, 0], outer_angle: [0.5, 0.5, 0.5, 0.5],
              intensity: [0.5, 1, 1, 1] });
  const { material, uniforms } = L.scheduleMaterial(new L.MeshLambertMaterial({ color: 0xffffff }),
    table, { maxLights: 2 });
  const objects = new L.ScheduledInstances({ id: [1], bounds_min: [-1, -1, -1], bounds_max: [1, 1, 1] },
    material, uniforms, 2);
  const scene = new L.Scene();
  scene.add(objects.mesh);
  const camera = new L.PerspectiveCamera(30, 1, 0.1, 100);
  camera.position.set(0, 0, 5);
  camera.lookAt(0, 0, 0);
  const nd = (dtype, shape, data) => new L.NdArray(dtype, shape, data);
  const centre = (lightIndex, fadeWeight, directional, residual) => {
    objects.applyFrame({ frame_index: 0, stats: {}, object_id: nd("int32", [1], Int32Array.of(1)),
      light_index: nd("int32", [1, 2], Int32Array.from(lightIndex)),
      fade_weight: nd("float32", [1, 2], Float32Array.from(fadeWeight)),
      directional_lights: nd("int32", [directional.length], Int32Array.from(directional)),
      ...(residual ? { residual: nd("float32", [1, 4], Float32Array.from(residual)) } : {}) }, table);
    renderer.render(scene, camera);
    const gl = renderer.getContext();
    const pixel = new Uint8Array(4);
    gl.readPixels(32, 32, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, pixel);
    return pixel[0];
  };
  // light_index counts rows of the lights in ascending id: rows 0..3 are lights 4, 6, 7, 9;
  // directional_lights names ids.
  return {
    slot: centre([0, -1], [1, 0], []),
    halfFaded: centre([-1, 0], [0, 0.5], []),
    directionalInSlot: centre([3, -1], [1, 0], []),
    spotAimed: centre([1, -1], [1, 0], []),
    spotAside: centre([2, -1], [1, 0], []),
    empty: centre([-1, -1], [0, 0], []),
    directional: centre([-1, -1], [0, 0], [9]),
    residual: centre([-1, -1], [0, 0], [], [1, 0, 0, 0.5]),
    residualGone: centre([-1, -1], [0, 0], []),
    programs: renderer.info.programs.length,
  };
}"""


def test_the_shader_lights_each_instance_by_its_slots(browser, service):
    page = browser.new_page()
    page.goto(f"{service}/healthz")  # any page of the service's origin, to import from
    got = page.evaluate(SHADER_CASES)
    page.close()
    # Light 4 at d2 = 4 from the face centre: i * w^2 / (d2 + r0^2), w = 1 - (d2 / r^2)^2;
    # three's Lambert divides by pi what the table multiplied by pi.
    w = 1 - (4 / 100) ** 2
    point = w * w / (4 + 0.01)
    expected = {"slot": point, "halfFaded": 0.5 * point, "empty": 0.0,
                "spotAimed": point, "spotAside": 0.0,  # spot factor 1 on the axis, 0 outside
                "directionalInSlot": 0.5, "directional": 0.5,  # i, facing the light
                "residual": 1 / 4 + 0.5 / 2,  # a/4 + (b . n)/2, n = +z
                "residualGone": 0.0}
    for case, value in expected.items():
        assert abs(got[case] - 255 * value) <= 2, (case, got, 255 * value)
    assert got["programs"] == 1, "a new frame compiled a program"


# A point or spot light 3 m above a floor box (top at y = 0), with a small box between
# them: the oracle's frame for the scene (reference.schedule), drawn by lightsched/three
# with its shadow atlas. Each draw reads two floor pixels, one under the small box (in its
# shadow: |x|, |z| < 1 on the floor) and one outside it, and returns their values with the
# world points their centres see, so that the unshadowed value can be computed there.
SHADOW_CASES = """async (cases) => {
  const L = await import("/viewer/lightsched-three.js");
  const size = 128;
  const canvas = document.createElement("canvas");
  canvas.width = canvas.height = size;
  document.body.append(canvas);
  const renderer = new L.WebGLRenderer({ canvas, preserveDrawingBuffer: true });
  renderer.outputColorSpace = L.LinearSRGBColorSpace;
  const table = new L.LightTable();
  const atlas = new L.ShadowAtlas({ size: 1024 });
  const { material, uniforms } = L.scheduleMaterial(new L.MeshLambertMaterial({ color: 0xffffff }),
    table, { maxLights: 2, shadows: atlas });
  const objects = new L.ScheduledInstances(cases.objects, material, uniforms, 2);
  const scene = new L.Scene();
  scene.add(objects.mesh);
  const camera = new L.PerspectiveCamera(cases.camera.fovDegrees, 1, 0.1, 100);
  camera.position.fromArray(cases.camera.position);
  camera.lookAt(0, 0, 0);
  camera.updateMatrixWorld();
  const nd = (dtype, shape, data) => new L.NdArray(dtype, shape, data);
  const floor = new L.Plane(new L.Vector3(0, 1, 0), 0);
  const raycaster = new L.Raycaster();
  // The pixel whose centre sees floor point (x, 0, z), and the floor point it sees exactly.
  const sample = ([x, z]) => {
    const ndc = new L.Vector3(x, 0, z).project(camera);
    const px = Math.floor((ndc.x + 1) / 2 * size);
    const py = Math.floor((ndc.y + 1) / 2 * size);
    raycaster.setFromCamera(new L.Vector2((px + 0.5) / size * 2 - 1, (py + 0.5) / size * 2 - 1), camera);
    const seen = raycaster.ray.intersectPlane(floor, new L.Vector3());
    const gl = renderer.getContext();
    const pixel = new Uint8Array(4);
    gl.readPixels(px, py, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, pixel);
    return { value: pixel[0], at: seen.toArray() };
  };
  const draw = (c, slotShadow) => {
    const f = c.frame;
    table.set(c.light);
    const frame = { frame_index: 0, stats: {},
      object_id: nd("int32", [2], Int32Array.from(f.object_id)),
      light_index: nd("int32", [2, 2], Int32Array.from(f.light_index.flat())),
      fade_weight: nd("float32", [2, 2], Float32Array.from(f.fade_weight.flat())),
      slot_shadow: nd("int8", [2, 2], Int8Array.from(slotShadow ?? f.slot_shadow.flat())),
      directional_lights: nd("int32", [0], new Int32Array(0)),
      shadow_lights: nd("int32", [f.shadow_lights.length], Int32Array.from(f.shadow_lights)),
      shadow_tier: nd("uint16", [f.shadow_tier.length], Uint16Array.from(f.shadow_tier)),
      caster_offsets: nd("int64", [f.caster_offsets.length], BigInt64Array.from(f.caster_offsets, BigInt)),
      caster_ids: nd("int32", [f.caster_ids.length], Int32Array.from(f.caster_ids)),
      caster_masks: nd("uint32", [f.caster_masks.length], Uint32Array.from(f.caster_masks)) };
    objects.applyFrame(frame, table);
    atlas.render(renderer, frame, table, objects);
    renderer.render(scene, camera);
    return { shadow: sample(cases.inShadow), outside: sample(cases.outside) };
  };
  const none = [-1, -1, -1, -1];
  const point = draw(cases.point);
  const programs = renderer.info.programs.length;
  const got = {
    point, programs,
    pointUnshadowed: draw(cases.point, none),
    spot: draw(cases.spot),
    spotUnshadowed: draw(cases.spot, none),
    pointAgain: draw(cases.point),
    programsAfter: renderer.info.programs.length,
  };
  // The widest shadowed material (K = 8) links: its vertex attributes fit.
  const widest = L.scheduleMaterial(new L.MeshStandardMaterial(), table, { maxLights: 8, shadows: atlas });
  const wide = new L.Scene();
  wide.add(new L.ScheduledInstances(cases.objects, widest.material, widest.uniforms, 8).mesh);
  renderer.render(wide, camera);
  got.widestLinks = renderer.info.programs.length === programs + 1
    && renderer.info.programs.every((p) => p.diagnostics === undefined || p.diagnostics.runnable)
    && renderer.getContext().getError() === 0;
  return got;
}"""


def _shadow_scene() -> tuple[dict[str, Any], dict[str, dict[str, Any]]]:
    """SHADOW_CASES's argument (the boxes, the camera, and each light with the oracle's
    frame of the scene it lights), and the lights as the scheduler took them."""
    import lightsched as ls
    from lightsched import reference

    objects = {"id": np.array([1, 2], np.int32),
               "bounds_min": np.array([[-6.0, -0.2, -6.0], [-0.5, 1.0, -0.5]]),
               "bounds_max": np.array([[6.0, 0.0, 6.0], [0.5, 1.5, 0.5]])}
    fov = 50.0
    eye = [0.0, 4.0, 8.0]
    camera = ls.Camera(position=eye, forward=[-c for c in eye], up=[0, 1, 0], fov_y=np.radians(fov),
                       aspect=1, near=0.1, far=100, height_px=128)
    point = {"id": [5], "type": [0], "position": [[0.0, 3.0, 0.0]], "radius": [10.0],
             "direction": [[0.0, -1.0, 0.0]], "outer_angle": [0.9], "inner_angle": [0.72],
             "intensity": [6.0], "shadows": [True]}
    spot = {**point, "id": [8], "type": [1]}
    cases: dict[str, Any] = {"objects": {k: v.ravel().tolist() for k, v in objects.items()},
                             "camera": {"fovDegrees": fov, "position": eye},
                             "inShadow": [0.0, 0.6], "outside": [1.6, 1.6]}
    for name, light in (("point", point), ("spot", spot)):
        arrays = {k: np.asarray(v, np.uint8 if k == "type" else np.int32 if k == "id" else None)
                  for k, v in light.items()}
        f = reference.schedule(arrays, objects, [camera], ls.Config(max_lights=2))
        assert list(f.shadow_lights) == light["id"] and f.slot_shadow[0, 0] == 0, "the floor is shadowed"
        frame = {k: getattr(f, k).tolist() for k in (
            "object_id", "light_index", "fade_weight", "slot_shadow", "shadow_lights", "shadow_tier",
            "caster_offsets", "caster_ids", "caster_masks")}
        # LightTable.set takes row-major flat arrays, as the wire's are.
        flat = {k: np.ravel(v).tolist() for k, v in light.items() if k != "shadows"}
        cases[name] = {"light": flat, "frame": frame}
    return cases, {"point": point, "spot": spot}


def _unshadowed(light: dict[str, Any], at: list[float]) -> float:
    """DESIGN section 2's light on the floor (normal +y) at ``at``, Lambert, as 0..255."""
    p = np.array(light["position"][0])
    x = np.array(at)
    to_light = p - x
    d2 = float(to_light @ to_light)
    w = max(0.0, 1 - (d2 / light["radius"][0] ** 2) ** 2)
    s = 1.0
    if light["type"][0] == 1:
        c = float(-to_light @ np.array(light["direction"][0])) / np.sqrt(d2)
        cos_outer, cos_inner = np.cos(light["outer_angle"][0]), np.cos(light["inner_angle"][0])
        s = float(np.clip((c - cos_outer) / (cos_inner - cos_outer), 0, 1)) ** 2
    cosine = max(0.0, to_light[1] / np.sqrt(d2))
    return 255 * light["intensity"][0] * w * w / (d2 + 0.01) * s * cosine


def test_shadowed_slots_are_dark_behind_a_caster(browser, service):
    cases, lights = _shadow_scene()
    page = browser.new_page()
    page.goto(f"{service}/healthz")
    got = page.evaluate(SHADOW_CASES, cases)
    SCREENSHOTS.mkdir(parents=True, exist_ok=True)
    page.screenshot(path=SCREENSHOTS / "shadow-point.png")
    page.close()
    for name in ("point", "spot"):
        light = lights[name]
        shadowed, unshadowed = got[name], got[f"{name}Unshadowed"]
        # Under the small box only the light's slot could light the floor: nothing else does.
        assert shadowed["shadow"]["value"] <= 2, (name, got)
        lit = _unshadowed(light, shadowed["shadow"]["at"])
        assert lit > 60, (name, lit)  # the same pixel, lit, is far from dark
        for case, pixel in (("shadowed", shadowed["outside"]), ("unshadowed", unshadowed["outside"]),
                            ("unshadowed", unshadowed["shadow"])):
            expected = _unshadowed(light, pixel["at"])
            assert abs(pixel["value"] - expected) <= 2, (name, case, pixel, expected)
    assert got["pointAgain"] == got["point"]
    # The first shadowed frame compiled the lit program and the casters' depth program; new
    # slot_shadow, shadow_lights and views (six faces, then one) compiled nothing more.
    assert got["programs"] == 2 and got["programsAfter"] == 2, got
    assert got["widestLinks"], "K = 8 with shadows did not link"


# The page of another origin: the TypeScript client (the viewer build's lightsched.js)
# makes a session with a key, and streams frames (so a ticket, as a browser WebSocket
# cannot send the key).
CROSS_ORIGIN_PAGE = """<!doctype html><script type="module">
import { Client, vectors } from "./lightsched.js";
try {
  const client = new Client("%(service)s", { apiKey: "browser-key" });
  const s = await client.session({ max_lights: 4 }, { stream: true });
  s.setLights({ id: new Int32Array([3, 5]), position: vectors([0, 0, 0, 2, 0, 0]),
                radius: new Float64Array([10, 10]) });
  s.setObjects({ id: new Int32Array([7]), bounds_min: vectors([-1, -1, -1]),
                 bounds_max: vectors([1, 1, 1]) });
  const camera = { position: [0, 0, 20], forward: [0, 0, -1], up: [0, 1, 0], fov_y: 1,
                   aspect: 1, near: 0.1, far: 100 };
  let f;
  for (let i = 0; i < 5; i++) f = await s.frame(camera);
  window.result = { frameIndex: f.frame_index, lightIds: [...f.light_ids.data] };
} catch (e) {
  window.result = { error: String(e) };
}
</script>"""


@functools.cache
def _quiet_handler(directory: str) -> type[http.server.SimpleHTTPRequestHandler]:
    class Handler(http.server.SimpleHTTPRequestHandler):
        def __init__(self, *args: Any, **kwargs: Any) -> None:
            super().__init__(*args, directory=directory, **kwargs)

        def log_message(self, format: str, *args: Any) -> None:
            pass

    return Handler


@contextmanager
def page_server(directory: Path) -> Iterator[str]:
    """A static server of ``directory`` on a free port: another origin than the service."""
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), _quiet_handler(str(directory)))
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield f"http://127.0.0.1:{server.server_address[1]}"
    finally:
        server.shutdown()
        server.server_close()


def run_page(browser: Any, url: str) -> tuple[dict[str, Any], list[str]]:
    page = browser.new_page()
    sockets: list[str] = []
    page.on("websocket", lambda ws: sockets.append(ws.url))
    page.goto(f"{url}/index.html")
    page.wait_for_function("() => window.result !== undefined", timeout=FIRST_FRAMES_MS)
    result = page.evaluate("() => window.result")
    page.close()
    return result, sockets


def test_a_page_of_another_origin_streams_frames(browser, tmp_path):
    shutil.copyfile(viewer_dir() / "lightsched.js", tmp_path / "lightsched.js")
    with page_server(tmp_path) as allowed, page_server(tmp_path) as other, \
            lightsched_serve(LIGHTSCHED_CORS_ORIGINS=allowed,
                             LIGHTSCHED_API_KEYS="browser-key") as service:
        (tmp_path / "index.html").write_text(CROSS_ORIGIN_PAGE % {"service": service})
        result, sockets = run_page(browser, allowed)
        assert "error" not in result, result
        assert result["frameIndex"] == 4 and sorted(result["lightIds"][:2]) == [3, 5]
        assert len(sockets) == 1 and "/stream?ticket=" in sockets[0]

        # The same page from an origin the service does not list: the browser refuses it.
        refused, _ = run_page(browser, other)
        assert "error" in refused and "fetch" in refused["error"].lower(), refused
