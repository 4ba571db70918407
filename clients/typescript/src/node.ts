/**
 * lightsched/node: a transport for Node programs. ``nodeFetch()`` sends the client's HTTP
 * calls through Node's own http module on kept-alive sockets with Nagle off, in place of
 * the global fetch (undici), whose per-request cost is most of a 1k-object frame's round
 * trip (bench/RESULTS.md, "Clients"). Browsers keep their fetch; this entry is the only one
 * that imports Node APIs.
 *
 *   const client = new Client(url, { fetch: nodeFetch() });
 */

import http from "node:http";
import https from "node:https";

import type { FetchLike, ResponseLike } from "./client.js";

export interface NodeFetchOptions {
  /** Sockets kept per host (a session sends one frame at a time; default 4). */
  maxSockets?: number;
}

export function nodeFetch(options: NodeFetchOptions = {}): FetchLike {
  const kept = { keepAlive: true, maxSockets: options.maxSockets ?? 4 };
  const agents = { "http:": new http.Agent(kept), "https:": new https.Agent(kept) };
  return (url, init) => new Promise<ResponseLike>((resolve, reject) => {
    const target = new URL(url);
    const secure = target.protocol === "https:";
    const headers: Record<string, string | number> = { ...init.headers };
    if (init.body !== undefined) headers["Content-Length"] = init.body.byteLength;
    const request = (secure ? https : http).request(target, {
      method: init.method, headers, agent: agents[secure ? "https:" : "http:"],
    }, (response) => {
      const chunks: Buffer[] = [];
      response.on("data", (chunk: Buffer) => chunks.push(chunk));
      response.on("error", reject);
      response.on("end", () => {
        const body = chunks.length === 1 ? chunks[0] : Buffer.concat(chunks);
        const status = response.statusCode ?? 0;
        resolve({
          ok: status >= 200 && status < 300,
          status,
          statusText: response.statusMessage ?? "",
          headers: { get: (name) => (response.headers[name.toLowerCase()] as string | undefined) ?? null },
          arrayBuffer: async () => body.buffer.slice(body.byteOffset, body.byteOffset + body.byteLength) as ArrayBuffer,
        });
      });
    });
    // A frame is one small write each way: Nagle would hold it for the peer's delayed ACK.
    request.setNoDelay(true);
    request.on("error", reject);
    const body = init.body;
    request.end(body === undefined ? undefined : Buffer.from(body.buffer, body.byteOffset, body.byteLength));
  });
}
