// The codec on its own: array maps both ways, views without copies where the offset
// allows, copies where it does not, int64 as BigInt64Array, and the malformed maps the
// service refuses refused here too.
import assert from "node:assert/strict";
import { test } from "node:test";

import { encode as pack } from "@msgpack/msgpack";

import {
  JSON_TYPE, MSGPACK, NdArray, WireError, decode, encode, ndarray, vectors,
} from "../src/index.js";

test("arrays round-trip in both encodings", () => {
  const doc = {
    a: ndarray(new Float32Array([1.5, -2, 3])), b: vectors([1, 2, 3, 4, 5, 6]),
    c: ndarray(new BigInt64Array([1n, -(2n ** 40n)])), d: [ndarray(new Uint8Array([0, 1]))],
    n: 3, s: "x",
  };
  for (const kind of [MSGPACK, JSON_TYPE] as const) {
    const back = decode(encode(doc, kind), kind) as any;
    assert.equal(back.a.dtype, "float32");
    assert.deepEqual(Array.from(back.a.data), [1.5, -2, 3]);
    assert.deepEqual(back.b.shape, [2, 3]);
    assert.deepEqual(Array.from(back.b.row(1)), [4, 5, 6]);
    assert.ok(back.c.data instanceof BigInt64Array);
    assert.equal(back.c.data[1], -(2n ** 40n));
    assert.equal(back.d[0].dtype, "uint8");
    assert.equal(back.n, 3);
  }
});

test("a msgpack bin is viewed in place when aligned and copied when not", () => {
  const data = new Uint8Array(new Float64Array([1, 2, 3]).buffer);
  const msg = pack({ a: { dtype: "float64", shape: [3], data } });
  const a = (decode(msg, MSGPACK) as any).a as NdArray<Float64Array>;
  assert.deepEqual(Array.from(a.data), [1, 2, 3]);
  // The bin starts 18 bytes in (map, key, inner map, keys): not a multiple of 8.
  assert.notEqual(a.data.buffer, msg.buffer);
  const padded = pack({ pad: "xxxxx", a: { dtype: "uint8", shape: [3], data: new Uint8Array([7, 8, 9]) } });
  const b = (decode(padded, MSGPACK) as any).a as NdArray<Uint8Array>;
  assert.equal(b.data.buffer, padded.buffer);  // one-byte items: always a view
});

test("malformed array maps name the part", () => {
  const cases: [unknown, string][] = [
    [{ x: { dtype: "int32", shape: [1], data: new Uint8Array(4), extra: 1 } }, "/x"],
    [{ x: { dtype: "int32", shape: [1] } }, "/x"],
    [{ x: { dtype: "int33", shape: [1], data: new Uint8Array(4) } }, "/x/dtype"],
    [{ x: { dtype: "int32", shape: [2], data: new Uint8Array(4) } }, "/x/data"],
    [{ x: [{ dtype: "int32", shape: [-1], data: new Uint8Array(0) }] }, "/x/0/shape"],
  ];
  for (const [doc, pointer] of cases) {
    assert.throws(() => decode(pack(doc), MSGPACK), (e: unknown) => e instanceof WireError && e.pointer === pointer);
  }
  assert.throws(() => decode(new Uint8Array([0xc1]), MSGPACK), WireError);
  assert.throws(() => decode(new TextEncoder().encode("{x"), JSON_TYPE), WireError);
});
