/**
 * The embedded lightsched API over the service: a Client makes sessions (remote
 * Schedulers) and runs the stateless schedule(); a Session holds scene changes until
 * frame(), which sends them with the frame over HTTP or the session's WebSocket stream.
 * Only fetch, WebSocket, TextEncoder and atob/btoa are used, so it runs in browsers and in
 * Node 20+ (whose WebSocket needs --experimental-websocket before Node 22, or pass one in
 * ClientOptions.WebSocket).
 */

import { FRAME_FIELDS, type Explanation, type FieldName, type FrameArrays } from "./fields.js";
import {
  ARRAY_OF, JSON_TYPE, MSGPACK, NdArray, decode, encode, mediaType,
  type Encoding, type TypedArray,
} from "./wire.js";

export type Vector = NdArray | TypedArray | number[];
/** An input array: an NdArray, a typed array (one value per row) or nested lists. */
export type ArrayInput = NdArray | TypedArray | number[] | number[][] | boolean[];
export type Fields = Record<string, ArrayInput | undefined>;

/** A view (DESIGN section 1); without an id a camera takes its position in the list. */
export interface Camera {
  id?: number;
  position: Vector;
  forward: Vector;
  up: Vector;
  fov_y: number;
  aspect: number;
  near: number;
  far: number;
  focus?: Vector;
  height_px?: number;
}

/** A frame (DESIGN section 3): the arrays asked for, always whole (changed_only answers
 * are merged into the session's last frame). */
export interface Frame extends FrameArrays {
  frame_index: number;
  stats: Record<string, unknown>;
}

export interface FrameOptions {
  dt?: number;
  cut?: boolean;
  outputs?: FieldName[];
  changedOnly?: boolean;
  stats?: boolean;
}

/** What a Client needs of its HTTP transport: globalThis.fetch fits, and so does
 * nodeFetch() of lightsched/node. */
export type FetchLike = (url: string, init: {
  method: string; headers: Record<string, string>; body?: Uint8Array;
}) => Promise<ResponseLike>;

export interface ResponseLike {
  ok: boolean;
  status: number;
  statusText: string;
  headers: { get(name: string): string | null };
  arrayBuffer(): Promise<ArrayBuffer>;
}

export interface ClientOptions {
  /** Sent as ``Authorization: Bearer <key>``; streams use a ticket made with it. */
  apiKey?: string;
  /** The body encoding: msgpack (default) or JSON. */
  encoding?: Encoding;
  /** The HTTP transport (default: the global fetch). */
  fetch?: FetchLike;
  WebSocket?: typeof WebSocket;
}

export type Problem = {
  type?: string; title?: string; status?: number; detail?: string; instance?: string;
  field?: string; index?: number; pointer?: string;
};

/** The service refused a call: ``status`` and the problem document (RFC 9457). */
export class RemoteError extends Error {
  readonly type?: string;
  readonly field?: string;
  readonly index?: number;
  readonly pointer?: string;

  constructor(readonly status: number, readonly problem: Problem) {
    super(`${status} ${problem.title ?? ""}: ${problem.detail ?? ""}`);
    this.name = "RemoteError";
    this.type = problem.type;
    this.field = problem.field;
    this.index = problem.index;
    this.pointer = problem.pointer;
  }
}

/** Bad input (422): ``field`` and ``index`` as lightsched.ValidationError names them. */
export class ValidationError extends RemoteError {
  constructor(status: number, problem: Problem) {
    super(status, problem);
    this.name = "ValidationError";
  }
}

function remoteError(status: number, problem: Problem): RemoteError {
  return status === 422 ? new ValidationError(status, problem) : new RemoteError(status, problem);
}

function vector(v: Vector): NdArray | number[] {
  if (v instanceof NdArray || Array.isArray(v)) return v;
  return new NdArray("float64", [v.length], Float64Array.from(v as ArrayLike<number>));
}

export function cameraDoc(c: Camera): Record<string, unknown> {
  const doc: Record<string, unknown> = {};
  if (c.id !== undefined) doc.id = c.id;
  doc.position = vector(c.position);
  doc.forward = vector(c.forward);
  doc.up = vector(c.up);
  for (const k of ["fov_y", "aspect", "near", "far"] as const) doc[k] = c[k];
  if (c.focus !== undefined) doc.focus = vector(c.focus);
  if (c.height_px !== undefined) doc.height_px = c.height_px;
  return doc;
}

function fieldsDoc(fields: Fields): Record<string, unknown> {
  const out: Record<string, unknown> = {};
  for (const [k, v] of Object.entries(fields)) if (v !== undefined) out[k] = v;
  return out;
}

function frameOf(doc: Record<string, unknown>, prev: Frame | undefined): Frame {
  if (doc.changed_only) return mergeChanged(prev, doc);
  const f: Frame = { frame_index: doc.frame_index as number, stats: (doc.stats as Record<string, unknown>) ?? {} };
  const out = f as unknown as Record<string, unknown>;
  for (const { name } of FRAME_FIELDS) if (name in doc) out[name] = doc[name];
  return f;
}

/** Positions of ``wanted`` ids in ascending ``ids`` (-1 where absent). */
function positions(ids: Int32Array, wanted: Int32Array): Int32Array {
  const out = new Int32Array(wanted.length);
  for (let i = 0; i < wanted.length; i++) {
    let lo = 0;
    let hi = ids.length;
    const id = wanted[i];
    while (lo < hi) {
      const mid = (lo + hi) >>> 1;
      if (ids[mid] < id) lo = mid + 1;
      else hi = mid;
    }
    out[i] = lo < ids.length && ids[lo] === id ? lo : -1;
  }
  return out;
}

/**
 * The full frame from a changed_only answer and the last full frame (wire.md): without
 * object_id the objects are the same and the rows sent overwrite theirs; with object_id
 * each object keeps its previous row if it had one, else the field's empty value, and
 * then the rows sent overwrite theirs.
 */
export function mergeChanged(prev: Frame | undefined, doc: Record<string, unknown>): Frame {
  const sent = doc.object_id as NdArray<Int32Array> | undefined;
  const sameSet = sent === undefined && prev?.object_id !== undefined;
  const ids = sameSet ? prev!.object_id! : (sent ?? new NdArray("int32", [0], new Int32Array(0)));
  const f: Frame = { frame_index: doc.frame_index as number, stats: (doc.stats as Record<string, unknown>) ?? {}, object_id: ids };
  const rows = doc.rows as NdArray<Int32Array>;
  const at = positions(ids.data, rows.data);
  const kept = !sameSet && prev?.object_id ? positions(prev.object_id.data, ids.data) : undefined;
  const out = f as unknown as Record<string, unknown>;
  for (const field of FRAME_FIELDS) {
    const name = field.name;
    if (name === "object_id" || !(name in doc)) continue;
    const part = doc[name] as NdArray;
    if (!field.per_object) {
      out[name] = part;
      continue;
    }
    const width = part.shape.slice(1).reduce((a, b) => a * b, 1);
    const old = prev ? (prev as unknown as Record<string, NdArray | undefined>)[name] : undefined;
    const Typed = ARRAY_OF[part.dtype];
    let full: TypedArray;
    if (sameSet && old !== undefined) {
      full = old.data.slice();
    } else {
      full = new Typed(ids.data.length * width);
      (full as Uint8Array).fill(Number(field.empty));
      if (old !== undefined && kept !== undefined) {
        for (let i = 0; i < kept.length; i++) {
          if (kept[i] >= 0) (full as Uint8Array).set(old.row(kept[i]) as Uint8Array, i * width);
        }
      }
    }
    for (let r = 0; r < at.length; r++) {
      (full as Uint8Array).set(part.row(r) as Uint8Array, at[r] * width);
    }
    out[name] = new NdArray(part.dtype, [ids.data.length, ...part.shape.slice(1)], full);
  }
  return f;
}

/** The service: sessions and the stateless schedule(). */
export class Client {
  readonly url: string;
  readonly apiKey?: string;
  readonly encoding: Encoding;
  readonly fetch: FetchLike;
  readonly WebSocket?: typeof WebSocket;

  constructor(url: string, options: ClientOptions = {}) {
    this.url = url.replace(/\/+$/, "");
    this.apiKey = options.apiKey;
    this.encoding = options.encoding ?? MSGPACK;
    this.fetch = options.fetch ?? (globalThis.fetch.bind(globalThis) as unknown as FetchLike);
    this.WebSocket = options.WebSocket ?? globalThis.WebSocket;
  }

  /** One request: ``doc`` encoded, the answer decoded; RemoteError on a refusal. */
  async call(method: string, path: string, doc?: unknown): Promise<any> {
    const headers: Record<string, string> = { Accept: this.encoding };
    if (doc !== undefined) headers["Content-Type"] = this.encoding;
    if (this.apiKey) headers.Authorization = `Bearer ${this.apiKey}`;
    const response = await this.fetch(this.url + path, {
      method, headers, body: doc === undefined ? undefined : encode(doc, this.encoding),
    });
    const body = new Uint8Array(await response.arrayBuffer());
    const kind = mediaType(response.headers.get("content-type"));
    const answer = body.length && kind ? decode(body, kind) : undefined;
    if (!response.ok) {
      const problem = (answer ?? { title: response.statusText, status: response.status }) as Problem;
      throw remoteError(response.status, problem);
    }
    return answer;
  }

  /** The stateless one-frame call (lightsched.schedule): every set on at weight 1. */
  async schedule(lights: Fields, objects: Fields, cameras: Camera | Camera[],
                 config?: Record<string, unknown> | null, outputs?: FieldName[] | null): Promise<Frame> {
    const doc: Record<string, unknown> = {
      lights: fieldsDoc(lights), objects: fieldsDoc(objects),
      cameras: (Array.isArray(cameras) ? cameras : [cameras]).map(cameraDoc),
    };
    if (config) doc.config = config;
    if (outputs) doc.outputs = outputs;
    return frameOf(await this.call("POST", "/v1/schedule", doc), undefined);
  }

  /** A new session (a remote lightsched.Scheduler) with this config. */
  async session(config?: Record<string, unknown> | null, options: { stream?: boolean } = {}): Promise<Session> {
    const info = await this.call("POST", "/v1/sessions", config ? { config } : {});
    return new Session(this, info, options.stream ?? false);
  }

  async health(): Promise<Record<string, unknown>> {
    return this.call("GET", "/healthz");
  }
}

interface Waiter {
  resolve: (data: Uint8Array | string) => void;
  reject: (e: Error) => void;
}

/** A session: lightsched.Scheduler's calls, computed by the service. */
export class Session {
  readonly id: string;
  readonly config: Record<string, unknown>;
  frameIndex: number;
  readonly stream: boolean;
  private changes: { op: string; fields: Record<string, unknown> }[] = [];
  private last?: Frame;
  private ws?: WebSocket;
  private opening?: Promise<WebSocket>;
  private waiters: Waiter[] = [];
  // Messages no request waits for: a refused handshake's problem, sent before any request.
  private inbox: (Uint8Array | string)[] = [];
  private closedWith?: Error;
  private queue: Promise<unknown> = Promise.resolve();

  constructor(readonly client: Client, info: Record<string, unknown>, stream: boolean) {
    this.id = info.id as string;
    this.config = info.config as Record<string, unknown>;
    this.frameIndex = info.frame_index as number;
    this.stream = stream;
  }

  setLights(fields: Fields): void { this.changes.push({ op: "set_lights", fields: fieldsDoc(fields) }); }
  updateLights(fields: Fields): void { this.changes.push({ op: "update_lights", fields: fieldsDoc(fields) }); }
  removeLights(id: ArrayInput): void { this.changes.push({ op: "remove_lights", fields: { id } }); }
  setObjects(fields: Fields): void { this.changes.push({ op: "set_objects", fields: fieldsDoc(fields) }); }
  updateObjects(fields: Fields): void { this.changes.push({ op: "update_objects", fields: fieldsDoc(fields) }); }
  removeObjects(id: ArrayInput): void { this.changes.push({ op: "remove_objects", fields: { id } }); }

  /** The held changes, then one frame; changed_only answers come back merged. The changes
   * are sent whether the frame succeeds or not (a refused frame changes nothing). */
  frame(cameras: Camera | Camera[], options: FrameOptions = {}): Promise<Frame> {
    const doc: Record<string, unknown> = {
      dt: options.dt ?? 1 / 60, cut: options.cut ?? false,
      cameras: (Array.isArray(cameras) ? cameras : [cameras]).map(cameraDoc),
      changes: this.changes,
    };
    this.changes = [];
    if (options.outputs) doc.outputs = options.outputs;
    if (options.changedOnly) doc.changed_only = true;
    if (options.stats === false) doc.stats = false;
    // One frame at a time: answers come back in the order of the requests.
    const run = this.queue.then(() => this.send(doc));
    this.queue = run.catch(() => undefined);
    return run;
  }

  private async send(doc: Record<string, unknown>): Promise<Frame> {
    const answer = this.stream ? await this.streamCall(doc)
      : await this.client.call("POST", `/v1/sessions/${this.id}/frames`, doc);
    const f = frameOf(answer, this.last);
    this.last = f;
    this.frameIndex = f.frame_index + 1;
    return f;
  }

  private async streamCall(doc: Record<string, unknown>): Promise<Record<string, unknown>> {
    const ws = await this.open();
    const kind = this.client.encoding;
    let data = this.inbox.shift();
    if (data === undefined) {
      if (this.closedWith) throw this.closedWith;
      const reply = new Promise<Uint8Array | string>((resolve, reject) => {
        this.waiters.push({ resolve, reject });
      });
      const bytes = encode(doc, kind);
      ws.send(kind === MSGPACK ? bytes : new TextDecoder().decode(bytes));
      data = await reply;
    }
    const answer = typeof data === "string"
      ? decode(new TextEncoder().encode(data), JSON_TYPE) as Record<string, unknown>
      : decode(data, MSGPACK) as Record<string, unknown>;
    if (!("frame_index" in answer)) throw remoteError(Number(answer.status ?? 400), answer as Problem);
    return answer;
  }

  /** The stream, opened once: with a ticket when the client has a key (a browser's
   * WebSocket cannot send an Authorization header). */
  private open(): Promise<WebSocket> {
    if (this.ws && !this.closedWith) return Promise.resolve(this.ws);
    if (this.opening) return this.opening;
    const Ws = this.client.WebSocket;
    if (!Ws) return Promise.reject(new Error("no WebSocket: pass one in ClientOptions.WebSocket"));
    this.opening = (async () => {
      let query = "";
      if (this.client.apiKey) {
        const t = await this.ticket();
        query = `?ticket=${encodeURIComponent(t.ticket)}`;
      }
      const url = this.client.url.replace(/^http/, "ws") + `/v1/sessions/${this.id}/stream${query}`;
      const ws = new Ws(url);
      ws.binaryType = "arraybuffer";
      this.closedWith = undefined;
      this.inbox = [];
      ws.onmessage = (e: MessageEvent) => {
        const data = typeof e.data === "string" ? e.data : new Uint8Array(e.data as ArrayBuffer);
        const waiter = this.waiters.shift();
        if (waiter) waiter.resolve(data);
        else this.inbox.push(data);
      };
      ws.onclose = (e: CloseEvent) => {
        const status = e.code === 1009 ? 413 : 400;
        this.closedWith = remoteError(status, {
          title: "Stream closed", status, detail: `the service closed the stream (${e.code}): ${e.reason}`,
        });
        for (const w of this.waiters.splice(0)) w.reject(this.closedWith);
        this.ws = undefined;
      };
      await new Promise<void>((resolve, reject) => {
        ws.onopen = () => resolve();
        ws.onerror = () => reject(new RemoteError(400, { title: "Stream failed", status: 400, detail: `could not open ${url}` }));
      });
      this.ws = ws;
      return ws;
    })();
    const opening = this.opening;
    opening.finally(() => { if (this.opening === opening) this.opening = undefined; }).catch(() => undefined);
    return opening;
  }

  /** Why each light is (not) on object ``objectId`` in the last frame (Scheduler.explain),
   * asked after the frames already sent. */
  explain(objectId: number): Promise<Explanation> {
    const run = this.queue.then(() => this.client.call(
      "GET", `/v1/sessions/${this.id}/objects/${objectId}/explain`) as Promise<Explanation>);
    this.queue = run.catch(() => undefined);
    return run;
  }

  /** A one-use ticket that opens this session's stream without the key. */
  ticket(): Promise<{ ticket: string; expires_in: number }> {
    return this.client.call("POST", `/v1/sessions/${this.id}/tickets`);
  }

  info(): Promise<Record<string, unknown>> {
    return this.client.call("GET", `/v1/sessions/${this.id}`);
  }

  /** Closes the stream and (by default) deletes the session. */
  async close(options: { delete?: boolean } = {}): Promise<void> {
    if (this.ws) {
      this.ws.close();
      this.ws = undefined;
    }
    if (options.delete ?? true) await this.client.call("DELETE", `/v1/sessions/${this.id}`);
  }
}
