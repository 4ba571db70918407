// The conformance suite (schemas/conformance) against a live service, over HTTP in both
// encodings and over the stream in both: every frame equals the embedded scheduler's
// (changed_only answers merged), every refusal is the problem document the suite names.
import assert from "node:assert/strict";
import { readdirSync, readFileSync } from "node:fs";
import { resolve } from "node:path";
import { after, before, describe, test } from "node:test";

import {
  Client, JSON_TYPE, MSGPACK, NdArray, RemoteError, fromWire,
  type Camera, type Encoding, type Explanation, type FetchLike, type Fields, type Frame, type Session,
} from "../src/index.js";
import { nodeFetch } from "../src/node.js";
import { KEY, REPO, startServer, type LiveServer } from "./server.js";

const SUITE = resolve(REPO, "schemas/conformance");
const FILES = readdirSync(SUITE).filter((f) => f.endsWith(".json")).sort();
const CHANGES: Record<string, (s: Session, f: any) => void> = {
  set_lights: (s, f) => s.setLights(f),
  update_lights: (s, f) => s.updateLights(f),
  remove_lights: (s, f) => s.removeLights(f.id),
  set_objects: (s, f) => s.setObjects(f),
  update_objects: (s, f) => s.updateObjects(f),
  remove_objects: (s, f) => s.removeObjects(f.id),
};

function bytes(a: NdArray): Uint8Array {
  return new Uint8Array(a.data.buffer, a.data.byteOffset, a.data.byteLength);
}

function checkFrame(frame: Frame, expect: any, where: string): void {
  assert.equal(frame.frame_index, expect.frame_index, where);
  for (const [name, want] of Object.entries(expect.arrays as Record<string, NdArray>)) {
    const got = (frame as unknown as Record<string, NdArray | undefined>)[name];
    assert.ok(got, `${where}: ${name} missing`);
    assert.equal(got.dtype, want.dtype, `${where}: ${name} dtype`);
    assert.deepEqual(got.shape, want.shape, `${where}: ${name} shape`);
    assert.ok(Buffer.from(bytes(got)).equals(Buffer.from(bytes(want))), `${where}: ${name} differs`);
  }
}

function checkExplanation(e: Explanation, expect: any, where: string): void {
  for (const [name, want] of Object.entries(expect as Record<string, unknown>)) {
    const got = (e as unknown as Record<string, unknown>)[name];
    if (want instanceof NdArray) {
      assert.ok(got instanceof NdArray, `${where}: ${name} missing`);
      assert.equal(got.dtype, want.dtype, `${where}: ${name} dtype`);
      assert.ok(Buffer.from(bytes(got)).equals(Buffer.from(bytes(want))), `${where}: ${name} differs`);
    } else {
      assert.deepEqual(got, want, `${where}: ${name}`);
    }
  }
}

async function outcome<T>(call: () => Promise<T>, step: any, where: string,
                          check: (got: T, expect: any, where: string) => void): Promise<void> {
  if (step.expect) {
    check(await call(), step.expect, where);
    return;
  }
  await assert.rejects(call, (e: unknown) => {
    assert.ok(e instanceof RemoteError, `${where}: ${e}`);
    for (const key of ["status", "type", "field", "index", "pointer"]) {
      assert.equal((e.problem as any)[key] ?? null, step.error[key], `${where}: ${key}`);
    }
    return true;
  });
}

export async function runScenario(doc: any, client: Client, stream: boolean): Promise<void> {
  let session: Session | undefined;
  for (const [i, raw] of (doc.steps as any[]).entries()) {
    const step = fromWire(raw) as any;
    const where = `${doc.name} step ${i} (${step.call})`;
    if (step.call === "session") {
      session = await client.session(step.config, { stream });
    } else if (step.call in CHANGES) {
      CHANGES[step.call](session!, step.fields as Fields);
    } else if (step.call === "frame") {
      await outcome(() => session!.frame(step.cameras as Camera[], {
        dt: step.dt, cut: step.cut, outputs: step.outputs ?? undefined, changedOnly: step.changed_only,
      }), step, where, checkFrame);
    } else if (step.call === "explain") {
      await outcome(() => session!.explain(step.object_id), step, where, checkExplanation);
    } else if (step.call === "schedule") {
      await outcome(() => client.schedule(step.lights, step.objects, step.cameras, step.config,
        step.outputs), step, where, checkFrame);
    } else if (step.call === "info") {
      const info = await session!.info();
      for (const [k, v] of Object.entries(step.expect)) assert.equal(info[k], v, `${where}: ${k}`);
    } else if (step.call === "close") {
      await session!.close();
    } else if (step.call === "lose") {  // as a dead worker loses it
      await client.call("DELETE", `/v1/sessions/${session!.id}`);
    } else {
      assert.fail(`${where}: unknown call`);
    }
  }
}

describe("conformance suite", () => {
  let server: LiveServer;
  before(async () => { server = await startServer(); });
  after(async () => { await server.stop(); });

  test("the suite is there", () => {
    assert.ok(FILES.length >= 3, `scenarios in ${SUITE}`);
  });
  const modes: [string, Encoding, boolean, FetchLike | undefined][] = [
    ["http msgpack", MSGPACK, false, undefined], ["http json", JSON_TYPE, false, undefined],
    ["http msgpack (lightsched/node)", MSGPACK, false, nodeFetch()],
    ["http json (lightsched/node)", JSON_TYPE, false, nodeFetch()],
    ["stream msgpack", MSGPACK, true, undefined], ["stream json", JSON_TYPE, true, undefined],
  ];
  for (const file of FILES) {
    for (const [mode, encoding, stream, fetch] of modes) {
      test(`${file} over ${mode}`, async () => {
        const doc = JSON.parse(readFileSync(resolve(SUITE, file), "utf8"));
        await runScenario(doc, new Client(server.url, { apiKey: KEY, encoding, fetch }), stream);
      });
    }
  }
});
