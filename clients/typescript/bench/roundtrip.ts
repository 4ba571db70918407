// One client's side of bench/clients.py: a session of the scene in SCENE (a msgpack map of
// arrays that bench/clients.py writes), then frames in which every light moves, each timed
// from the updateLights call to the decoded frame. Prints {"ms": [...]} on stdout.
//   node --experimental-websocket dist/bench/roundtrip.js URL SCENE [http|node|stream]
// (http: the global fetch; node: lightsched/node's nodeFetch; stream: the WebSocket).
import { readFileSync } from "node:fs";

import { Client, MSGPACK, NdArray, decode, type Camera, type Fields } from "../src/index.js";
import { nodeFetch } from "../src/node.js";

const [url, path, transport] = process.argv.slice(2);
const scene = decode(new Uint8Array(readFileSync(path)), MSGPACK) as Record<string, NdArray>;
const lights: Fields = {};
const objects: Fields = {};
for (const [key, a] of Object.entries(scene)) {
  if (key.startsWith("lights.")) lights[key.slice(7)] = a;
  if (key.startsWith("objects.")) objects[key.slice(8)] = a;
}
const c = scene.camera.data as Float64Array;
const cam: Camera = {
  position: c.subarray(0, 3), forward: c.subarray(3, 6), up: c.subarray(6, 9),
  fov_y: c[9], aspect: c[10], near: c[11], far: c[12],
};
const positions = scene.positions as NdArray<Float64Array>;
const warmup = Number((scene.warmup.data as BigInt64Array)[0]);
const frames = Number((scene.frames.data as BigInt64Array)[0]);
const k = Number((scene.max_lights.data as BigInt64Array)[0]);
const [poses, l] = positions.shape;

const client = new Client(url, transport === "node" ? { fetch: nodeFetch() } : {});
const s = await client.session({ max_lights: k }, { stream: transport === "stream" });
s.setLights(lights);
s.setObjects(objects);
await s.frame(cam);
const ms: number[] = [];
for (let i = 0; i < warmup + frames; i++) {
  const t0 = performance.now();
  const at = (i % poses) * l * 3;
  s.updateLights({ id: lights.id, position: new NdArray("float64", [l, 3], positions.data.subarray(at, at + l * 3)) });
  const f = await s.frame(cam);
  const t = performance.now() - t0;
  if (!f.light_ids) process.exit(1);
  if (i >= warmup) ms.push(t);
}
await s.close();
console.log(JSON.stringify({ ms }));
