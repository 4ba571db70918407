/**
 * The embedded lightsched API over the service: a Client makes sessions (remote
 * Schedulers) and runs the stateless schedule(); a Session holds scene changes until
 * frame(), which sends them with the frame over HTTP or the session's WebSocket stream.
 * Sessions survive a sharded service (deploy/haproxy.cfg routes by session id): the client
 * chooses the id (PUT /v1/sessions/{id}); every frame carries a sequence number (seq), so a
 * frame whose answer was lost (a broken connection, a 502/503 while a worker is replaced)
 * is sent again without running twice; a session that answers 404 (its worker died) is
 * made again and given the scene the client mirrors (SceneMirror) within that frame, which
 * then counts as a cut (``recoveries`` counts those).
 * Only fetch, WebSocket, TextEncoder, crypto and atob/btoa are used, so it runs in browsers and in
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
  /** How long a frame is sent again while the service cannot be reached (default 10 s). */
  retrySeconds?: number;
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

/** Statuses of a proxy with no worker for the request (yet): the request did not run. */
const UNAVAILABLE = new Set([502, 503, 504]);

/** A failure that sending the same request again may get past: the transport failed (fetch
 * throws, a stream dropped) or a proxy had no worker. Only requests safe to repeat
 * (idempotent ones, frames with a seq) are retried on it. */
function transient(e: unknown): boolean {
  return e instanceof RemoteError ? UNAVAILABLE.has(e.status) : true;
}

/** The session is gone (404: its worker died, or it idled past the TTL), or the session of
 * its id is behind the client (409 out-of-order: a worker taken for dead came back). */
function lost(e: unknown): boolean {
  return e instanceof RemoteError && (e.status === 404
    || (e.status === 409 && String(e.problem.type ?? "").endsWith(":out-of-order")));
}

const sleep = (ms: number) => new Promise<void>((resolve) => setTimeout(resolve, ms));

/** Pauses between attempts: 0, 25 ms, doubling to 1 s, until ``seconds`` have passed. */
function* backoff(seconds: number): Generator<number> {
  const end = Date.now() + seconds * 1000;
  let pause = 0;
  for (;;) {
    yield pause;
    if (Date.now() + pause > end) return;
    pause = Math.min(1000, Math.max(25, 2 * pause));
  }
}

/** A random session id: 192 bits, base64url (the service's alphabet). */
export function newSessionId(): string {
  const bytes = globalThis.crypto.getRandomValues(new Uint8Array(24));
  return btoa(String.fromCharCode(...bytes)).replace(/\+/g, "-").replace(/\//g, "_");
}

/** ``call`` until it succeeds or fails other than transiently, or ``seconds`` pass. */
async function retrying<T>(seconds: number, call: () => Promise<T>): Promise<T> {
  let last: unknown;
  for (const pause of backoff(seconds)) {
    if (pause) await sleep(pause);
    try {
      return await call();
    } catch (e) {
      if (!transient(e)) throw e;
      last = e;
    }
  }
  throw last;
}

type Row = number | boolean | number[];
type Change = { op: string; fields: Record<string, unknown> };

/** An input array as rows of plain values (a copy: the caller may reuse its arrays). */
function rowsOf(v: unknown): Row[] {
  if (v instanceof NdArray) {
    const flat = v.dtype === "bool" ? Array.from(v.data as Uint8Array, (x) => x !== 0)
      : Array.from(v.data as ArrayLike<number | bigint>, Number);
    if (v.shape.length <= 1) return flat;
    const width = v.shape.slice(1).reduce((a, b) => a * b, 1);
    return Array.from({ length: v.shape[0] }, (_, i) => flat.slice(i * width, (i + 1) * width) as number[]);
  }
  if (ArrayBuffer.isView(v)) return Array.from(v as unknown as ArrayLike<number | bigint>, Number);
  return (v as Row[]).map((x) => (Array.isArray(x) ? [...x] : x));
}

/** One kind (lights or objects) of the scene as the client set it: the last set_ call's
 * rows with later updates and removals folded in, so that replaying it costs one set_ call
 * however many frames went by. An update naming a field the set_ did not give (whose
 * default may derive from other fields) is kept as a call of its own, and so is everything
 * after it, until the next set_ (lightsched_client.client._Table, the same rule). */
class Table {
  private base?: Record<string, Row[]>;
  private calls: [string, Record<string, Row[]>][] = [];
  private rowOf?: Map<number, number>;

  apply(op: string, given: Record<string, unknown>): void {
    const fields: Record<string, Row[]> = {};
    for (const [k, v] of Object.entries(given)) if (v !== undefined) fields[k] = rowsOf(v);
    if (op === "set") {
      this.base = fields;
      this.calls = [];
      this.rowOf = undefined;
    } else if (!this.base || this.calls.length || !Object.keys(fields).every((k) => k in this.base!)) {
      this.calls.push([op, fields]);
    } else if (op === "remove") {
      const gone = new Set(fields.id as number[]);
      const keep = (this.base.id as number[]).map((id) => !gone.has(id));
      for (const k of Object.keys(this.base)) this.base[k] = this.base[k].filter((_, i) => keep[i]);
      this.rowOf = undefined;
    } else {
      if (!this.rowOf) this.rowOf = new Map((this.base.id as number[]).map((id, i) => [id, i]));
      const rows = (fields.id as number[]).map((id) => this.rowOf!.get(id)!);
      for (const [k, values] of Object.entries(fields)) {
        rows.forEach((r, i) => { this.base![k][r] = values[i]; });
      }
    }
  }

  replay(kind: string): Change[] {
    const out: Change[] = this.base ? [{ op: `set_${kind}`, fields: this.base }] : [];
    return out.concat(this.calls.map(([op, fields]) => ({ op: `${op}_${kind}`, fields })));
  }
}

/** The scene a session holds, as far as the client gave it: the changes of every frame the
 * service answered. A session lost with its worker is rebuilt from it. */
export class SceneMirror {
  private tables: Record<string, Table> = { lights: new Table(), objects: new Table() };

  apply(changes: Change[]): void {
    for (const { op, fields } of changes) {
      const [verb, kind] = op.split("_");
      this.tables[kind].apply(verb, fields);
    }
  }

  /** The changes that rebuild the scene in an empty session. */
  replay(): Change[] {
    return this.tables.lights.replay("lights").concat(this.tables.objects.replay("objects"));
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
  readonly retrySeconds: number;

  constructor(url: string, options: ClientOptions = {}) {
    this.url = url.replace(/\/+$/, "");
    this.apiKey = options.apiKey;
    this.encoding = options.encoding ?? MSGPACK;
    this.fetch = options.fetch ?? (globalThis.fetch.bind(globalThis) as unknown as FetchLike);
    this.WebSocket = options.WebSocket ?? globalThis.WebSocket;
    this.retrySeconds = options.retrySeconds ?? 10;
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
    // Not the service's document when the media type is not: a proxy's page (HAProxy's 503).
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

  /** A session (a remote lightsched.Scheduler) with this config, of this id or a new
   * random one (PUT: a load balancer routes by it, and a retried PUT is safe). */
  async session(config?: Record<string, unknown> | null,
                options: { stream?: boolean; id?: string } = {}): Promise<Session> {
    const body = config ? { config } : {};
    const path = `/v1/sessions/${options.id ?? newSessionId()}`;
    const info = await retrying(this.retrySeconds, () => this.call("PUT", path, body));
    return new Session(this, info, options.stream ?? false, body);
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
  private current?: WebSocket;  // the stream whose events count (not a dropped one's)
  private opening?: Promise<WebSocket>;
  private waiters: Waiter[] = [];
  // Messages no request waits for: a refused handshake's problem, sent before any request.
  private inbox: (Uint8Array | string)[] = [];
  private closedWith?: Error;
  private queue: Promise<unknown> = Promise.resolve();
  /** The scene as the service took it, to rebuild a lost session from. */
  readonly mirror = new SceneMirror();
  /** Times the session was rebuilt (its worker died). */
  recoveries = 0;
  /** Deleted by close(): a 404 then is not a loss. */
  closed = false;
  private readonly body: Record<string, unknown>;

  constructor(readonly client: Client, info: Record<string, unknown>, stream: boolean,
              body?: Record<string, unknown>) {
    this.id = info.id as string;
    this.config = info.config as Record<string, unknown>;
    this.frameIndex = info.frame_index as number;
    this.stream = stream;
    this.body = body ?? { config: this.config };
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

  /** The frame, sent again while the service cannot be reached (its seq keeps it from
   * running twice), and rebuilt if the session was lost. */
  private async send(doc: Record<string, unknown>): Promise<Frame> {
    const own = doc.changes as Change[];
    doc.seq = this.frameIndex;
    let last: unknown;
    for (const pause of backoff(this.client.retrySeconds)) {
      if (pause) await sleep(pause);
      try {
        const answer = this.stream ? await this.streamCall(doc)
          : await this.client.call("POST", `/v1/sessions/${this.id}/frames`, doc);
        this.mirror.apply(own);
        const f = frameOf(answer, this.last);
        this.last = f;
        this.frameIndex = f.frame_index + 1;
        return f;
      } catch (e) {
        if (lost(e) && !this.closed) {
          const info = await retrying(this.client.retrySeconds, () => this.remake());
          // The mirrored scene, then the frame's own changes, as a new session's cut.
          doc = { ...doc, changes: this.mirror.replay().concat(own), cut: true, seq: info.frame_index };
          this.frameIndex = info.frame_index as number;
          this.last = undefined;
          this.recoveries += 1;
        } else if (!transient(e)) {
          throw e;
        }
        this.dropStream();
        last = e;
      }
    }
    throw last;
  }

  /** The session made again, empty (a stale copy of it dropped first). */
  private async remake(): Promise<Record<string, unknown>> {
    const path = `/v1/sessions/${this.id}`;
    try {
      await this.client.call("DELETE", path);
    } catch (e) {
      if (!(e instanceof RemoteError)) throw e;
    }
    return this.client.call("PUT", path, this.body);
  }

  /** Forgets the stream (a broken or refused one): the next frame opens a new one. */
  private dropStream(): void {
    const ws = this.current;
    this.ws = this.current = undefined;
    this.closedWith = undefined;
    this.inbox = [];
    if (ws && ws.readyState <= 1) ws.close();
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
      this.current = ws;
      ws.binaryType = "arraybuffer";
      this.closedWith = undefined;
      this.inbox = [];
      ws.onmessage = (e: MessageEvent) => {
        if (this.current !== ws) return;  // a dropped stream's
        const data = typeof e.data === "string" ? e.data : new Uint8Array(e.data as ArrayBuffer);
        const waiter = this.waiters.shift();
        if (waiter) waiter.resolve(data);
        else this.inbox.push(data);
      };
      ws.onclose = (e: CloseEvent) => {
        if (this.current !== ws) return;  // a dropped stream's
        // 1009: the WebSocket's 413; closed without a close frame (1006: the worker or the
        // connection died), going away (1001) or restarting (1012): a 503, worth retrying.
        const status = e.code === 1009 ? 413 : [1001, 1006, 1011, 1012].includes(e.code) ? 503 : 400;
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
    this.closed = options.delete ?? true;
    if (this.ws) {
      this.ws.close();
      this.ws = undefined;
    }
    if (options.delete ?? true) await this.client.call("DELETE", `/v1/sessions/${this.id}`);
  }
}
