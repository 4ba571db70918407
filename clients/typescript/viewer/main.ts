/**
 * The LightSched viewer: the benchmarks' city (GET /viewer/city.msgpack) in a session of
 * its own, streamed over the WebSocket, drawn with lightsched/three, with overlays of what
 * the scheduler decided and an explain panel for a clicked object. The city's shadowed
 * point and spot lights cast shadows: each frame's shadow_lights are drawn into a shadow
 * atlas from their casters, and the slots slot_shadow names sample it.
 *
 * Reconfiguring (K, model, fades, hysteresis) deletes the session and makes a new one
 * with the scene set again: a session's config is fixed at creation, as a Scheduler's is.
 * window.lightsched exposes the viewer's state to the browser test (tests/test_viewer.py).
 */

import * as THREE from "three";
import { OrbitControls } from "three/examples/jsm/controls/OrbitControls.js";

import { Client, type Frame, type Session } from "../src/client.js";
import { FRAME_FIELDS, type FieldName } from "../src/fields.js";
import { LightTable, ScheduledInstances, ShadowAtlas, scheduleMaterial } from "../src/three.js";
import { MSGPACK, NdArray, decode, vectors } from "../src/wire.js";

interface City {
  lights: Record<string, NdArray>;
  objects: Record<string, NdArray>;
  side: number;
  camera: { position: NdArray<Float64Array>; forward: NdArray<Float64Array> };
}

type Overlay = "lit" | "count" | "fade" | "shadows";

const OUTPUTS: FieldName[] = ["object_id", "visible", "count", "candidates", "light_ids",
  "light_index", "fade_weight", "fade_state", "slot_shadow", "directional_lights", "shadow_lights",
  "shadow_tier", "caster_offsets", "caster_ids", "caster_masks"];
// The residual (DESIGN section 2) once the frame fields list it: the shader adds it then.
if (FRAME_FIELDS.some((f) => (f.name as string) === "residual")) OUTPUTS.push("residual" as FieldName);
const DIRECTIONAL = 2;
// lightsched.scenes.move_lights: each point or spot light runs round a horizontal circle,
// phase and sense from its id. Faster and wider than the benchmarks' 3 m/s on 3 m, so that
// sets visibly change.
const GOLDEN_ANGLE = Math.PI * (3 - Math.sqrt(5));
const SPEED = 6;
const CIRCLE = 8;

const $ = <T extends HTMLElement>(id: string) => document.getElementById(id) as T;
const canvas = $<HTMLCanvasElement>("view");
const query = new URLSearchParams(location.search);

// Bytes on the stream, counted where they pass: the client does not see message sizes.
const traffic = { sent: 0, received: 0 };
const sizeOf = (data: unknown) => typeof data === "string" ? new TextEncoder().encode(data).length
  : (data as ArrayBufferLike | ArrayBufferView).byteLength;
class CountingWebSocket extends WebSocket {
  constructor(url: string | URL, protocols?: string | string[]) {
    super(url, protocols);
    this.addEventListener("message", (e: MessageEvent) => { traffic.received += sizeOf(e.data); });
  }

  override send(data: string | ArrayBufferLike | Blob | ArrayBufferView): void {
    if (!(data instanceof Blob)) traffic.sent += sizeOf(data);
    super.send(data);
  }
}

const client = new Client(location.origin, { apiKey: query.get("key") ?? undefined, WebSocket: CountingWebSocket });

const renderer = new THREE.WebGLRenderer({ canvas, antialias: true, preserveDrawingBuffer: true });
renderer.setPixelRatio(Math.min(devicePixelRatio, 2));
renderer.toneMapping = THREE.ACESFilmicToneMapping;
renderer.toneMappingExposure = 1.6;
const scene = new THREE.Scene();
scene.background = new THREE.Color(0x05070c);
scene.add(new THREE.HemisphereLight(0x27324a, 0x0a0a0a, 0.5));
const camera = new THREE.PerspectiveCamera(55, 1, 0.5, 3000);
const controls = new OrbitControls(camera, canvas);
// LightSched refuses an up vector parallel to forward: never look straight down.
controls.minPolarAngle = 0.05;
controls.maxPolarAngle = Math.PI - 0.05;
controls.enableDamping = true;

const table = new LightTable();
// 2048 texels: chromium's software renderer (the browser tests') redraws it every frame.
const shadows = new ShadowAtlas({ size: 2048 });
// lightsched/three samples shadow maps up to K = 8 (vertex attributes); above, unshadowed.
const MAX_SHADOWED_K = 8;
let city: City;
let lightIds: Int32Array;
let lightTypes: Uint8Array;
let basePositions: Float64Array;
let positions: Float64Array;
let moving: Int32Array;  // rows of the point and spot lights
let sceneTime = 0;

let session: Session | undefined;
let config: Record<string, unknown> = {};
let pendingConfig: Record<string, unknown> | undefined;
let instances: ScheduledInstances | undefined;
let overlayMesh: THREE.InstancedMesh | undefined;
let markers: THREE.InstancedMesh;
let frame: Frame | undefined;
let overlay: Overlay = "lit";
let selected = -1;  // instance of the clicked object
const slotLines = new THREE.LineSegments(new THREE.BufferGeometry(),
  new THREE.LineBasicMaterial({ vertexColors: true, toneMapped: false }));
const selectionBox = new THREE.Box3Helper(new THREE.Box3(), 0xffffff);
selectionBox.visible = false;
scene.add(slotLines, selectionBox);

const stats = {
  ready: false, frames: 0, frameIndex: -1, maxCount: 0, setsChanged: 0, roundTripMs: 0,
  serverMs: 0, bytesSent: 0, bytesReceived: 0, error: null as string | null,
  // The last frame's shadow map tiles drawn and slots that sample one.
  shadowViews: 0, shadowedSlots: 0,
  config: {} as Record<string, unknown>,
  explained: null as null | { object_id: number; light_id: number[]; reason: string[] },
  programs: () => renderer.info.programs?.length ?? 0,
  pickable: (): { x: number; y: number; objectId: number } | null => pickable(),
};
(window as unknown as { lightsched: typeof stats }).lightsched = stats;

function lightColor(id: number, type: number, intensity: number): [number, number, number] {
  if (type === DIRECTIONAL) {
    // The city's sun, drawn as moonlight so that the point and spot lights read at night;
    // only the picture changes, not what the scheduler is given.
    return [0.5 * 0.04 / intensity, 0.6 * 0.04 / intensity, 1.0 * 0.04 / intensity];
  }
  const c = new THREE.Color().setHSL(((id * GOLDEN_ANGLE) / (2 * Math.PI)) % 1, 0.75, 0.6);
  return [c.r, c.g, c.b];
}

function moveLights(dt: number): void {
  sceneTime += dt;
  for (const r of moving) {
    const id = lightIds[r];
    const phase = (id * GOLDEN_ANGLE) % (2 * Math.PI);
    const angle = phase + (id % 2 === 0 ? 1 : -1) * (SPEED / CIRCLE) * sceneTime;
    positions[3 * r] = basePositions[3 * r] + CIRCLE * (Math.cos(angle) - Math.cos(phase));
    positions[3 * r + 2] = basePositions[3 * r + 2] + CIRCLE * (Math.sin(angle) - Math.sin(phase));
  }
}

async function loadCity(): Promise<void> {
  const response = await fetch("city.msgpack");
  if (!response.ok) throw new Error(`GET city.msgpack: ${response.status}`);
  city = decode(new Uint8Array(await response.arrayBuffer()), MSGPACK) as City;
  lightIds = city.lights.id.data as Int32Array;
  lightTypes = city.lights.type.data as Uint8Array;
  basePositions = Float64Array.from(city.lights.position.data as Float64Array);
  positions = basePositions.slice();
  moving = Int32Array.from([...lightTypes.keys()].filter((r) => lightTypes[r] !== DIRECTIONAL));
  const intensity = city.lights.intensity.data as Float64Array;
  const color = new Float32Array(3 * lightIds.length);
  lightIds.forEach((id, r) => color.set(lightColor(id, lightTypes[r], intensity[r]), 3 * r));
  table.set({ ...city.lights, position: positions, color } as Parameters<LightTable["set"]>[0]);

  markers = new THREE.InstancedMesh(new THREE.SphereGeometry(1, 12, 8),
    new THREE.MeshBasicMaterial({ toneMapped: false }), lightIds.length);
  markers.frustumCulled = false;
  scene.add(markers);

  // Outside the city's cloud of boxes (heights 0..100 m), over the corner the
  // benchmarks' camera looks from.
  const corner = city.camera.position.data;
  const side = city.side;
  camera.position.set(Math.sign(corner[0]) * 0.95 * side, 1.0 * side, Math.sign(corner[2]) * 0.95 * side);
  controls.target.set(0, 40, 0);
  controls.update();
}

/** The lit instances and their overlay twin for K slots (a new program only for a new K). */
function buildObjects(k: number): void {
  for (const m of [instances?.mesh, overlayMesh]) {
    if (!m) continue;
    scene.remove(m);
    m.geometry.dispose();
    (m.material as THREE.Material).dispose();
  }
  const lit = scheduleMaterial(new THREE.MeshStandardMaterial({ color: 0xb8bcc4, roughness: 0.8 }), table,
    { maxLights: k, shadows: k <= MAX_SHADOWED_K ? shadows : undefined });
  instances = new ScheduledInstances(city.objects as never, lit.material, lit.uniforms, k);
  overlayMesh = new THREE.InstancedMesh(instances.mesh.geometry,
    new THREE.MeshBasicMaterial({ toneMapped: false }), instances.ids.length);
  overlayMesh.instanceMatrix = instances.mesh.instanceMatrix;
  overlayMesh.setColorAt(0, new THREE.Color());
  scene.add(instances.mesh, overlayMesh);
  showOverlay(overlay);
  selected = -1;
  selectionBox.visible = false;
}

async function startSession(next: Record<string, unknown>): Promise<void> {
  const old = session;
  session = undefined;
  if (old) await old.close().catch(() => undefined);
  const s = await client.session(next, { stream: true });
  s.setLights({ ...city.lights, position: vectors(positions) });
  s.setObjects(city.objects);
  const k = s.config.max_lights as number;
  if (!instances || instances.maxLights !== k) buildObjects(k);
  config = s.config;
  stats.config = config;
  stats.frames = 0;
  stats.setsChanged = 0;
  frame = undefined;
  session = s;
}

function cameraDoc() {
  camera.updateMatrixWorld();
  const forward = camera.getWorldDirection(new THREE.Vector3());
  const up = new THREE.Vector3().setFromMatrixColumn(camera.matrixWorld, 1);
  return {
    position: [camera.position.x, camera.position.y, camera.position.z],
    forward: [forward.x, forward.y, forward.z], up: [up.x, up.y, up.z],
    fov_y: THREE.MathUtils.degToRad(camera.fov), aspect: camera.aspect, near: camera.near,
    far: camera.far, height_px: canvas.height,
  };
}

let lastStep = performance.now();
async function step(): Promise<void> {
  const s = session!;
  const now = performance.now();
  const dt = Math.min((now - lastStep) / 1000, 0.1);
  lastStep = now;
  if ($<HTMLInputElement>("moving").checked) {
    moveLights(dt);
    const movedPositions = new Float64Array(3 * moving.length);
    moving.forEach((r, i) => movedPositions.set(positions.subarray(3 * r, 3 * r + 3), 3 * i));
    const movedIds = Int32Array.from(moving, (r) => lightIds[r]);
    s.updateLights({ id: movedIds, position: vectors(movedPositions) });
    table.updatePositions(movedIds, movedPositions);
  }
  const sent = traffic.sent;
  const received = traffic.received;
  const t0 = performance.now();
  const f = await s.frame(cameraDoc(), { dt, outputs: OUTPUTS, changedOnly: true });
  if (s !== session) return;  // reconfigured while the frame was out
  stats.roundTripMs = performance.now() - t0;
  stats.bytesSent = traffic.sent - sent;
  stats.bytesReceived = traffic.received - received;
  const seconds = (f.stats.seconds ?? {}) as Record<string, number>;
  stats.serverMs = 1000 * (seconds.total ?? 0);
  if (frame?.light_ids) {
    const before = frame.light_ids.data;
    const after = f.light_ids!.data;
    const k = f.light_ids!.shape[1];
    for (let o = 0; o < f.object_id!.data.length; o++) {
      for (let j = 0; j < k; j++) {
        if (before[o * k + j] !== after[o * k + j]) { stats.setsChanged++; break; }
      }
    }
  }
  frame = f;
  instances!.applyFrame(f, table);
  if (instances!.maxLights <= MAX_SHADOWED_K) {
    shadows.render(renderer, f, table, instances!);
    stats.shadowViews = shadows.tiles.x.filter((x) => x >= 0).length;
    stats.shadowedSlots = f.slot_shadow!.data.filter((j) => j >= 0).length;
  } else {
    stats.shadowViews = stats.shadowedSlots = 0;
  }
  stats.maxCount = f.count!.data.reduce((a, b) => Math.max(a, b), 0);
  stats.frames++;
  stats.frameIndex = f.frame_index;
  stats.ready = true;
  stats.error = null;
  updateMarkers();
  updateOverlay();
  updateSlotLines();
  showStats();
}

function updateMarkers(): void {
  const m = new THREE.Matrix4();
  const shadowRank = new Map<number, number>();
  frame?.shadow_lights?.data.forEach((id, j) => shadowRank.set(id, j));
  for (let r = 0; r < lightIds.length; r++) {
    const shadowed = overlay === "shadows" && shadowRank.has(lightIds[r]);
    const size = lightTypes[r] === DIRECTIONAL ? 0 : shadowed ? 2.5 : 0.7;
    m.makeScale(size, size, size).setPosition(positions[3 * r], positions[3 * r + 1], positions[3 * r + 2]);
    markers.setMatrixAt(r, m);
    const hue = shadowed ? hueOf(shadowRank.get(lightIds[r])!) : new THREE.Color().setHSL(
      ((lightIds[r] * GOLDEN_ANGLE) / (2 * Math.PI)) % 1, 0.9, 0.7);
    markers.setColorAt(r, hue);
  }
  markers.instanceMatrix.needsUpdate = true;
  markers.instanceColor!.needsUpdate = true;
}

// Overlay colors are display (sRGB) values, untouched by tone mapping: a legend, not light.
const SRGB = THREE.SRGBColorSpace;
const hueOf = (j: number) => new THREE.Color().setHSL((j * 0.17 + 0.05) % 1, 0.9, 0.55, SRGB);

function updateOverlay(): void {
  if (!frame || !overlayMesh || overlay === "lit") return;
  const { visible, count, candidates, fade_state } = frame;
  const n = instances!.ids.length;
  const k = config.max_lights as number;
  const c = new THREE.Color();
  const casterOf = new Int32Array(n).fill(-1);
  if (overlay === "shadows") {
    const offsets = frame.caster_offsets!.data;
    const casters = frame.caster_ids!.data;
    for (let j = 0; j + 1 < offsets.length; j++) {
      for (let m = Number(offsets[j]); m < Number(offsets[j + 1]); m++) {
        const row = instances!.instanceOf(casters[m]);
        if (row >= 0 && casterOf[row] < 0) casterOf[row] = j;
      }
    }
  }
  for (let i = 0; i < n; i++) {
    const seen = visible!.data[i] !== 0;
    if (overlay === "count") {
      if (!seen) c.setRGB(0.03, 0.03, 0.04, SRGB);
      else if (candidates!.data[i] > k) c.setRGB(1, 0.1, 0.35 * Math.min(1, (candidates!.data[i] - k) / k), SRGB);
      else c.setHSL(0.66 - 0.5 * count!.data[i] / k, 0.85, 0.25 + 0.3 * count!.data[i] / k, SRGB);
    } else if (overlay === "fade") {
      let fadingIn = 0;
      let fadingOut = 0;
      for (let j = 0; j < k; j++) {
        const st = fade_state!.data[i * k + j];
        if (st === 1) fadingIn++;
        else if (st === 3) fadingOut++;
      }
      if (fadingIn && fadingOut) c.setRGB(1, 0.85, 0.1, SRGB);
      else if (fadingIn) c.setRGB(0.1, 1, 0.3, SRGB);
      else if (fadingOut) c.setRGB(1, 0.15, 0.1, SRGB);
      else c.setRGB(seen ? 0.12 : 0.03, seen ? 0.14 : 0.03, seen ? 0.2 : 0.04, SRGB);
    } else {
      if (casterOf[i] >= 0) c.copy(hueOf(casterOf[i]));
      else c.setRGB(0.05, 0.05, 0.07, SRGB);
    }
    overlayMesh.setColorAt(i, c);
  }
  overlayMesh.instanceColor!.needsUpdate = true;
}

function showOverlay(next: Overlay): void {
  overlay = next;
  if (instances) instances.mesh.visible = overlay === "lit";
  if (overlayMesh) overlayMesh.visible = overlay !== "lit";
  const legend: Record<Overlay, string> = {
    lit: "each box lit by its K slots (times fade_weight), shadowed slots darkened by their light's "
      + "shadow map, the moon outside the slots",
    count: `<span class="swatch" style="background:#1e3a8a"></span>few lights → <span class="swatch" style="background:#facc15"></span>K lights<br>`
      + `<span class="swatch" style="background:#ff1a40"></span>overflow: candidates &gt; K`,
    fade: `<span class="swatch" style="background:#1aff4d"></span>a slot fading in <span class="swatch" style="background:#ff2619"></span>fading out `
      + `<span class="swatch" style="background:#ffd91a"></span>both`,
    shadows: "shadow_lights drawn large; each one's casters (caster_ids) in its color",
  };
  $("legend").innerHTML = legend[overlay];
  updateMarkers();
  updateOverlay();
}

function updateSlotLines(): void {
  const geometry = slotLines.geometry;
  if (selected < 0 || !frame) {
    geometry.setAttribute("position", new THREE.Float32BufferAttribute([], 3));
    return;
  }
  const k = config.max_lights as number;
  const centre = instances!.centres.subarray(3 * selected, 3 * selected + 3);
  const points: number[] = [];
  const colors: number[] = [];
  const p = new THREE.Vector3();
  for (let j = 0; j < k; j++) {
    const row = frame.light_index!.data[selected * k + j];
    if (row < 0 || table.isDirectional(row)) continue;
    const w = frame.fade_weight!.data[selected * k + j];
    table.position(row, p);
    points.push(centre[0], centre[1], centre[2], p.x, p.y, p.z);
    // Lines to the slots' lights: green held, red fading out, dimmer as the weight falls.
    const rgb = frame.fade_state!.data[selected * k + j] === 3 ? [w, 0.1 * w, 0.1 * w] : [0.2 * w, w, 0.3 * w];
    colors.push(...rgb, ...rgb);
  }
  geometry.setAttribute("position", new THREE.Float32BufferAttribute(points, 3));
  geometry.setAttribute("color", new THREE.Float32BufferAttribute(colors, 3));
}

function showStats(): void {
  const f = frame!;
  const n = f.object_id!.data.length;
  const k = config.max_lights as number;
  let seen = 0;
  let overflow = 0;
  let fading = 0;
  let slots = 0;
  for (let i = 0; i < n; i++) {
    if (!f.visible!.data[i]) continue;
    seen++;
    slots += f.count!.data[i];
    if (f.candidates!.data[i] > k) overflow++;
  }
  for (const st of f.fade_state!.data) if (st === 1 || st === 3) fading++;
  const kib = (b: number) => (b / 1024).toFixed(1);
  $("stats").innerHTML = `<table>
    <tr><th>frame</th><td>${f.frame_index}</td></tr>
    <tr><th>round trip</th><td>${stats.roundTripMs.toFixed(1)} ms</td></tr>
    <tr><th>server frame</th><td>${stats.serverMs.toFixed(2)} ms</td></tr>
    <tr><th>bytes / frame</th><td>↑ ${kib(stats.bytesSent)} KiB ↓ ${kib(stats.bytesReceived)} KiB</td></tr>
    <tr><th>visible objects</th><td>${seen} / ${n}</td></tr>
    <tr><th>mean lights</th><td>${seen ? (slots / seen).toFixed(2) : "-"} (K = ${k})</td></tr>
    <tr><th>overflow (candidates &gt; K)</th><td>${overflow}</td></tr>
    <tr><th>slots fading</th><td>${fading}</td></tr>
    <tr><th>shadow lights</th><td>${f.shadow_lights!.data.length}, ${f.caster_ids!.data.length} casters</td></tr>
    <tr><th>shadow maps</th><td>${shadowMaps(k)}</td></tr>
    <tr><th>programs</th><td>${stats.programs()}</td></tr>
  </table>`;
}

/** The atlas's tiles this frame, or why there are none. */
function shadowMaps(k: number): string {
  if (k > MAX_SHADOWED_K) return `off at K &gt; ${MAX_SHADOWED_K}`;
  const sizes = [...shadows.tiles.size].filter((s) => s > 0);
  if (sizes.length === 0) return "none";
  return `${sizes.length} in ${shadows.size}², tiles ${Math.min(...sizes)}–${Math.max(...sizes)}`;
}

async function showExplain(instance: number): Promise<void> {
  const panel = $("explain");
  const objectId = instances!.objectId(instance);
  panel.style.display = "block";
  panel.innerHTML = `<h1>object ${objectId}</h1>explaining…`;
  try {
    const e = await session!.explain(objectId);
    const rows = e.reason.map((reason, i) => {
      const num = (v: number, digits = 3) => Number.isNaN(v) ? "–" : v.toPrecision(digits);
      return `<tr class="${reason}"><td>${e.light_id.data[i]}</td><td class="reason">${reason}</td>`
        + `<td>${num(e.priority.data[i])}</td><td>${num(e.selection_priority.data[i])}</td>`
        + `<td>${num(Math.sqrt(e.d2.data[i]))}</td><td>${e.slot.data[i] < 0 ? "–" : e.slot.data[i]}</td>`
        + `<td>${num(e.fade_weight.data[i], 2)}</td></tr>`;
    });
    // The lights that hold or compete for the object's slots first (by P), then the rest
    // by reason; lights out of range or out of view are only counted.
    const rank = (r: string) => ["selected", "fading_out", "waiting", "below_k", "directional"].indexOf(r) >>> 0;
    const counted = ["out_of_range", "light_not_visible"];
    const shown = e.reason.map((r, i) => i).filter((i) => !counted.includes(e.reason[i]))
      .sort((a, b) => rank(e.reason[a]) - rank(e.reason[b]) || (e.priority.data[b] || 0) - (e.priority.data[a] || 0));
    const tally = counted.map((r) => `${e.reason.filter((x) => x === r).length} ${r}`).join(", ");
    panel.innerHTML = `<h1>object ${e.object_id}, frame ${e.frame_index}</h1>`
      + `<table><tr><th>light</th><th>reason</th><th>P</th><th>P + hyst.</th><th>distance</th><th>slot</th><th>weight</th></tr>`
      + shown.map((i) => rows[i]).join("") + `</table><div>and ${tally}</div>`;
    stats.explained = { object_id: e.object_id, light_id: [...e.light_id.data], reason: e.reason };
  } catch (err) {
    panel.innerHTML = `<h1>object ${objectId}</h1><div id="explain-error">explain failed: ${(err as Error).message}</div>`;
  }
}

const raycaster = new THREE.Raycaster();
function pick(clientX: number, clientY: number): number {
  const rect = canvas.getBoundingClientRect();
  const ndc = new THREE.Vector2(((clientX - rect.left) / rect.width) * 2 - 1, -((clientY - rect.top) / rect.height) * 2 + 1);
  raycaster.setFromCamera(ndc, camera);
  const hit = raycaster.intersectObject(instances!.mesh, false)[0];
  return hit?.instanceId ?? -1;
}

/** A lit, visible object whose centre is on screen and hit first there (for the test). */
function pickable(): { x: number; y: number; objectId: number } | null {
  if (!frame || !instances) return null;
  const rect = canvas.getBoundingClientRect();
  const p = new THREE.Vector3();
  let best: { x: number; y: number; objectId: number; d: number } | null = null;
  for (let i = 0; i < instances.ids.length; i++) {
    if (!frame.visible!.data[i] || frame.count!.data[i] < 2) continue;
    p.fromArray(instances.centres, 3 * i).project(camera);
    const d = Math.hypot(p.x, p.y);
    if (d > 0.7 || (best && d >= best.d)) continue;
    const x = rect.left + (p.x + 1) / 2 * rect.width;
    const y = rect.top + (1 - p.y) / 2 * rect.height;
    if (pick(x, y) === i) best = { x, y, objectId: instances.ids[i], d };
  }
  return best && { x: best.x, y: best.y, objectId: best.objectId };
}

let pointerDown: [number, number] | undefined;
canvas.addEventListener("pointerdown", (e) => { pointerDown = [e.clientX, e.clientY]; });
canvas.addEventListener("pointerup", (e) => {
  // A click, not the end of an orbit drag.
  if (!pointerDown || Math.hypot(e.clientX - pointerDown[0], e.clientY - pointerDown[1]) > 4 || !instances) return;
  const i = pick(e.clientX, e.clientY);
  if (i < 0) return;
  selected = i;
  const m = new THREE.Matrix4();
  instances.mesh.getMatrixAt(i, m);
  selectionBox.box.setFromCenterAndSize(new THREE.Vector3().setFromMatrixPosition(m),
    new THREE.Vector3().setFromMatrixScale(m));
  selectionBox.visible = true;
  updateSlotLines();
  void showExplain(i);
});

function readConfig(): Record<string, unknown> {
  const num = (id: string) => Number($<HTMLInputElement>(id).value);
  return {
    max_lights: Number($<HTMLSelectElement>("max_lights").value),
    model: $<HTMLSelectElement>("model").value,
    fade_in: num("fade_in"), fade_out: num("fade_out"), hysteresis: num("hysteresis"),
  };
}

$("apply").addEventListener("click", () => { pendingConfig = readConfig(); });
$<HTMLSelectElement>("overlay").addEventListener("change", (e) => showOverlay((e.target as HTMLSelectElement).value as Overlay));

function resize(): void {
  const w = canvas.clientWidth;
  const h = canvas.clientHeight;
  renderer.setSize(w, h, false);
  camera.aspect = w / h;
  camera.updateProjectionMatrix();
}
addEventListener("resize", resize);

function showError(err: unknown): void {
  const text = err instanceof Error ? err.message : String(err);
  stats.error = text;
  $("error").textContent = text;
}

async function main(): Promise<void> {
  resize();
  await loadCity();
  await startSession(readConfig());
  renderer.setAnimationLoop(() => {
    controls.update();
    renderer.render(scene, camera);
  });
  for (;;) {
    await new Promise(requestAnimationFrame);
    try {
      if (pendingConfig) {
        const next = pendingConfig;
        pendingConfig = undefined;
        await startSession(next);
      }
      await step();
      $("error").textContent = "";
    } catch (err) {
      showError(err);
      await new Promise((r) => setTimeout(r, 1000));
    }
  }
}

main().catch(showError);
