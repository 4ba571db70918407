// The golden exchanges of schemas/examples against a live service: the golden request
// bytes, and the same requests decoded and encoded again by this client, are answered
// with the golden response bytes; both encodings of an answer decode to the same arrays.
import assert from "node:assert/strict";
import { readFileSync } from "node:fs";
import { resolve } from "node:path";
import { after, before, describe, test } from "node:test";

import { JSON_TYPE, MSGPACK, NdArray, decode, encode, type Encoding } from "../src/index.js";
import { KEY, REPO, startServer, type LiveServer } from "./server.js";

const EXAMPLES = resolve(REPO, "schemas/examples");
const INDEX = JSON.parse(readFileSync(resolve(EXAMPLES, "index.json"), "utf8")) as
  { name: string; method: string; path: string; status: number; response: boolean }[];
const EXT: Record<Encoding, string> = { [MSGPACK]: "msgpack", [JSON_TYPE]: "json" };

function file(name: string): Uint8Array {
  return new Uint8Array(readFileSync(resolve(EXAMPLES, name)));
}

describe("golden exchanges", () => {
  let server: LiveServer;
  before(async () => { server = await startServer(); });
  after(async () => { await server.stop(); });

  for (const kind of [MSGPACK, JSON_TYPE] as Encoding[]) {
    for (const reencode of [false, true]) {
      test(`${EXT[kind]} ${reencode ? "encoded by this client" : "golden request bytes"}`, async () => {
        let sid = "";
        for (const ex of INDEX) {
          const golden = file(`${ex.name}.request.${EXT[kind]}`);
          const body = reencode ? encode(decode(golden, kind), kind) : golden;
          const r = await fetch(server.url + ex.path.replace("{id}", sid), {
            method: ex.method, body: body as BodyInit,
            headers: { "Content-Type": kind, Accept: kind, Authorization: `Bearer ${KEY}` },
          });
          const answer = new Uint8Array(await r.arrayBuffer());
          assert.equal(r.status, ex.status, ex.name);
          if (ex.name === "session") {
            sid = (decode(answer, kind) as { id: string }).id;
            continue;
          }
          const want = file(`${ex.name}.response.${EXT[kind]}`);
          assert.ok(Buffer.from(answer).equals(Buffer.from(want)), `${ex.name}: answer differs from the golden bytes`);
        }
      });
    }
  }

  test("msgpack and JSON answers decode to the same arrays", () => {
    for (const ex of INDEX.filter((e) => e.response)) {
      const a = decode(file(`${ex.name}.response.msgpack`), MSGPACK) as Record<string, unknown>;
      const b = decode(file(`${ex.name}.response.json`), JSON_TYPE) as Record<string, unknown>;
      assert.deepEqual(Object.keys(a), Object.keys(b));
      for (const [k, v] of Object.entries(a)) {
        if (v instanceof NdArray) {
          const w = b[k] as NdArray;
          assert.equal(v.dtype, w.dtype);
          assert.deepEqual(v.shape, w.shape);
          assert.deepEqual(Array.from(v.data as ArrayLike<number>), Array.from(w.data as ArrayLike<number>), `${ex.name}: ${k}`);
        } else {
          assert.deepEqual(v, b[k], `${ex.name}: ${k}`);
        }
      }
    }
  });
});
