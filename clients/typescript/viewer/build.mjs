// Bundles the viewer page into dist/viewer (served by the service at /viewer): main.js,
// the page's script with three and the client; lightsched.js, the client alone as an ES
// module (the browser test's cross-origin page loads it); lightsched-three.js, the adapter
// with three (the browser test draws with it).
import { copyFileSync, mkdirSync } from "node:fs";
import { build } from "esbuild";

const out = "dist/viewer";
mkdirSync(out, { recursive: true });
const common = { bundle: true, format: "esm", target: "es2022", minify: true, sourcemap: true, logLevel: "warning" };
await build({ ...common, entryPoints: ["viewer/main.ts"], outfile: `${out}/main.js` });
await build({ ...common, entryPoints: ["src/index.ts"], outfile: `${out}/lightsched.js` });
await build({ ...common, entryPoints: ["viewer/three-bundle.ts"], outfile: `${out}/lightsched-three.js` });
copyFileSync("viewer/index.html", `${out}/index.html`);
