/**
 * The LightSched wire format (schemas/wire.md): maps in msgpack (the main encoding) or
 * JSON (for debugging); a numeric array travels as {dtype, shape, data} with the raw
 * little-endian C-order bytes (a msgpack bin, or base64 text in JSON).
 *
 * Decoded arrays are NdArray: a typed array over the message's own bytes where its offset
 * allows (msgpack bins start wherever they fall, a typed array needs its item size's
 * alignment), else over a copy.
 */

import { decode as unpack, encode as pack } from "@msgpack/msgpack";

export const MSGPACK = "application/msgpack";
export const JSON_TYPE = "application/json";
export type Encoding = typeof MSGPACK | typeof JSON_TYPE;

export type DType =
  | "bool" | "int8" | "uint8" | "int16" | "uint16" | "int32" | "uint32"
  | "int64" | "uint64" | "float32" | "float64";

export type TypedArray =
  | Uint8Array | Int8Array | Int16Array | Uint16Array | Int32Array | Uint32Array
  | BigInt64Array | BigUint64Array | Float32Array | Float64Array;

type TypedArrayOf = {
  bool: Uint8Array; int8: Int8Array; uint8: Uint8Array; int16: Int16Array;
  uint16: Uint16Array; int32: Int32Array; uint32: Uint32Array; int64: BigInt64Array;
  uint64: BigUint64Array; float32: Float32Array; float64: Float64Array;
};

interface TypedArrayClass {
  new (buffer: ArrayBufferLike, byteOffset: number, length: number): TypedArray;
  new (length: number): TypedArray;
  readonly BYTES_PER_ELEMENT: number;
}

/** The typed array of each dtype (bool is one byte per value, 0 or 1). */
export const ARRAY_OF: Record<DType, TypedArrayClass> = {
  bool: Uint8Array, int8: Int8Array, uint8: Uint8Array, int16: Int16Array,
  uint16: Uint16Array, int32: Int32Array, uint32: Uint32Array, int64: BigInt64Array,
  uint64: BigUint64Array, float32: Float32Array, float64: Float64Array,
} as Record<DType, TypedArrayClass>;

const DTYPE_OF = new Map<Function, DType>([
  [Int8Array, "int8"], [Uint8Array, "uint8"], [Int16Array, "int16"], [Uint16Array, "uint16"],
  [Int32Array, "int32"], [Uint32Array, "uint32"], [BigInt64Array, "int64"],
  [BigUint64Array, "uint64"], [Float32Array, "float32"], [Float64Array, "float64"],
]);

// The wire is little-endian; so is every platform JavaScript runs on in practice, and a
// big-endian one is refused rather than answered with swapped numbers.
const LITTLE = new Uint8Array(new Uint16Array([1]).buffer)[0] === 1;

/** A numeric array: ``data`` holds prod(shape) values in row-major order. */
export class NdArray<T extends TypedArray = TypedArray> {
  constructor(readonly dtype: DType, readonly shape: number[], readonly data: T) {
    const size = shape.reduce((a, b) => a * b, 1);
    if (data.length !== size) {
      throw new RangeError(`shape [${shape}] holds ${size} values, the data ${data.length}`);
    }
  }

  /** Row i's values (a view, no copy) of an array of rows. */
  row(i: number): T {
    const width = this.shape.slice(1).reduce((a, b) => a * b, 1);
    return this.data.subarray(i * width, (i + 1) * width) as T;
  }
}

/** A typed array (or a plain list of numbers) as an NdArray of the given shape; the dtype
 * is the typed array's (float64 for a list). */
export function ndarray(data: TypedArray | number[], shape?: number[]): NdArray {
  const typed = Array.isArray(data) ? Float64Array.from(data) : data;
  const dtype = DTYPE_OF.get(typed.constructor);
  if (dtype === undefined) throw new TypeError("not a typed array of a wire dtype");
  return new NdArray(dtype, shape ?? [typed.length], typed);
}

/** n 3-vectors from a flat array of 3n values (positions, directions, box corners). */
export function vectors(data: TypedArray | number[]): NdArray {
  if (data.length % 3 !== 0) throw new RangeError(`${data.length} values are not 3-vectors`);
  return ndarray(data, [data.length / 3, 3]);
}

/** A message that cannot be decoded; ``pointer`` is the JSON pointer of the bad part. */
export class WireError extends Error {
  constructor(readonly pointer: string, message: string) {
    super(`${pointer || "/"}: ${message}`);
    this.name = "WireError";
  }
}

function bytesOf(a: TypedArray): Uint8Array {
  return new Uint8Array(a.buffer, a.byteOffset, a.byteLength);
}

function base64(bytes: Uint8Array): string {
  let s = "";
  for (let i = 0; i < bytes.length; i += 0x8000) {
    s += String.fromCharCode(...bytes.subarray(i, i + 0x8000));
  }
  return btoa(s);
}

function unbase64(text: string, pointer: string): Uint8Array {
  let s: string;
  try {
    s = atob(text);
  } catch {
    throw new WireError(pointer, "is not valid base64");
  }
  const out = new Uint8Array(s.length);
  for (let i = 0; i < s.length; i++) out[i] = s.charCodeAt(i);
  return out;
}

/** Values in their wire form: NdArray and typed arrays into array maps. */
function toWire(value: unknown, binary: boolean): unknown {
  if (value instanceof NdArray) {
    if (!LITTLE) throw new Error("a big-endian platform cannot send raw arrays");
    const bytes = bytesOf(value.data);
    return { dtype: value.dtype, shape: value.shape, data: binary ? bytes : base64(bytes) };
  }
  if (ArrayBuffer.isView(value) && !(value instanceof DataView)) {
    return toWire(ndarray(value as TypedArray), binary);
  }
  if (Array.isArray(value)) return value.map((v) => toWire(v, binary));
  if (value !== null && typeof value === "object") {
    const out: Record<string, unknown> = {};
    for (const [k, v] of Object.entries(value)) if (v !== undefined) out[k] = toWire(v, binary);
    return out;
  }
  return value;
}

function decodeArray(doc: Record<string, unknown>, pointer: string): NdArray {
  const keys = Object.keys(doc);
  if (keys.length !== 3 || !("shape" in doc) || !("data" in doc)) {
    throw new WireError(pointer, `an array map has exactly the keys dtype, shape and data; this one has ${keys.join(", ")}`);
  }
  const { dtype, shape } = doc;
  let data = doc.data;
  if (typeof dtype !== "string" || !(dtype in ARRAY_OF)) {
    throw new WireError(`${pointer}/dtype`, `unknown dtype ${JSON.stringify(dtype)}`);
  }
  if (!Array.isArray(shape) || !shape.every((n) => Number.isInteger(n) && n >= 0)) {
    throw new WireError(`${pointer}/shape`, "must be a list of non-negative integers");
  }
  if (typeof data === "string") data = unbase64(data, `${pointer}/data`);
  if (!(data instanceof Uint8Array)) {
    throw new WireError(`${pointer}/data`, "must be bytes (msgpack bin) or base64 text");
  }
  const Typed = ARRAY_OF[dtype as DType];
  const size = (shape as number[]).reduce((a, b) => a * b, 1);
  if (data.length !== size * Typed.BYTES_PER_ELEMENT) {
    throw new WireError(`${pointer}/data`, `has ${data.length} bytes, shape [${shape}] of ${dtype} needs ${size * Typed.BYTES_PER_ELEMENT}`);
  }
  if (!LITTLE) throw new Error("a big-endian platform cannot read raw arrays");
  // A view where the offset allows, else a copy (slice() starts a new, aligned buffer).
  const bytes = data.byteOffset % Typed.BYTES_PER_ELEMENT === 0 ? data : data.slice();
  return new NdArray(dtype as DType, shape as number[], new Typed(bytes.buffer, bytes.byteOffset, size));
}

/** Array maps inside maps and lists into NdArray (a map with a dtype key is one). */
export function fromWire(value: unknown, pointer = ""): unknown {
  if (Array.isArray(value)) return value.map((v, i) => fromWire(v, `${pointer}/${i}`));
  if (value !== null && typeof value === "object" && !ArrayBuffer.isView(value)) {
    const doc = value as Record<string, unknown>;
    if ("dtype" in doc) return decodeArray(doc, pointer);
    const out: Record<string, unknown> = {};
    for (const [k, v] of Object.entries(doc)) out[k] = fromWire(v, `${pointer}/${k}`);
    return out;
  }
  return value;
}

/** A message as msgpack or JSON bytes (NdArray and typed arrays allowed inside). */
export function encode(doc: unknown, kind: Encoding): Uint8Array {
  if (kind === MSGPACK) return pack(toWire(doc, true), { ignoreUndefined: true });
  return new TextEncoder().encode(JSON.stringify(toWire(doc, false)));
}

/** Bytes into maps, lists and NdArray; WireError if malformed. */
export function decode(body: Uint8Array, kind: Encoding): unknown {
  let doc: unknown;
  try {
    doc = kind === MSGPACK ? unpack(body) : JSON.parse(new TextDecoder().decode(body));
  } catch (e) {
    throw new WireError("", `malformed ${kind === MSGPACK ? "msgpack" : "json"}: ${(e as Error).message}`);
  }
  return fromWire(doc);
}

/** MSGPACK or JSON_TYPE from a Content-Type value, undefined if neither. */
export function mediaType(contentType: string | null | undefined): Encoding | undefined {
  const base = (contentType ?? "").split(";")[0].trim().toLowerCase();
  if (base.endsWith("msgpack")) return MSGPACK;
  if (base.endsWith("json")) return JSON_TYPE;
  return undefined;
}
