// A real `lightsched serve` for the tests, on a free port of 127.0.0.1: the project's
// Python (LIGHTSCHED_PYTHON, else the checkout's .venv), with an API key, CORS for a page
// origin and a small body limit.
import { spawn, type ChildProcess } from "node:child_process";
import { createServer } from "node:net";
import { dirname, resolve } from "node:path";
import { fileURLToPath } from "node:url";

export const REPO = resolve(dirname(fileURLToPath(import.meta.url)), "../../../..");
export const KEY = "ts-key";
export const PAGE = "http://viewer.example:8080";

async function freePort(): Promise<number> {
  return new Promise((ok, fail) => {
    const s = createServer();
    s.listen(0, "127.0.0.1", () => {
      const port = (s.address() as { port: number }).port;
      s.close(() => ok(port));
    });
    s.on("error", fail);
  });
}

export interface LiveServer {
  url: string;
  port: number;
  stop(): Promise<void>;
}

export async function startServer(): Promise<LiveServer> {
  const port = await freePort();
  const python = process.env.LIGHTSCHED_PYTHON ?? resolve(REPO, ".venv/bin/python");
  // --no-warm-up: the first frames load (or compile) only the kernels they use.
  const child: ChildProcess = spawn(python, ["-m", "lightsched", "serve", "--host", "127.0.0.1",
    "--port", String(port), "--no-demo", "--no-warm-up", "--log-level", "warning"], {
    cwd: REPO, stdio: ["ignore", "inherit", "inherit"],
    env: { ...process.env, LIGHTSCHED_API_KEYS: KEY, LIGHTSCHED_CORS_ORIGINS: PAGE,
      LIGHTSCHED_MAX_BODY_BYTES: String(2_000_000) },
  });
  const url = `http://127.0.0.1:${port}`;
  const deadline = Date.now() + 120_000;
  for (;;) {
    if (child.exitCode !== null) throw new Error(`lightsched serve exited with ${child.exitCode}`);
    try {
      if ((await fetch(`${url}/healthz`)).ok) break;
    } catch {
      // not listening yet
    }
    if (Date.now() > deadline) {
      child.kill();
      throw new Error("lightsched serve did not start within 120 s");
    }
    await new Promise((r) => setTimeout(r, 100));
  }
  return {
    url, port,
    stop: () => new Promise<void>((ok) => {
      child.once("exit", () => ok());
      child.kill("SIGINT");
    }),
  };
}
