// lightsched/three without a GPU: the light table's rows are light_index's rows, the slot
// attributes are the frame's own typed arrays, and the shader patch depends on K alone.
// Drawing with it is tested in a real browser (tests/test_viewer.py).
import assert from "node:assert/strict";
import { test } from "node:test";

import {
  InterleavedBufferAttribute, Matrix4, MeshLambertMaterial, MeshStandardMaterial, ShaderLib, Vector3,
  type WebGLProgramParametersWithUniforms, type WebGLRenderer,
} from "three";

import type { Frame } from "../src/client.js";
import { LightTable, ScheduledInstances, scheduleMaterial } from "../src/three.js";
import { NdArray, vectors } from "../src/wire.js";

const LIGHTS = {
  id: new Int32Array([40, 7, 12]),
  type: new Uint8Array([0, 2, 1]),
  position: vectors([1, 2, 3, 0, 0, 0, -4, 5, 6]),
  radius: new Float64Array([10, 1, 20]),
  direction: vectors([0, -1, 0, 0, -1, 0, 1, 0, 0]),
  outer_angle: new Float64Array([0.5, 0.5, 0.6]),
  intensity: new Float64Array([2, 3, 4]),
};
const OBJECTS = {
  id: new Int32Array([9, 3]),
  bounds_min: vectors([0, 0, 0, -2, -2, -2]),
  bounds_max: vectors([2, 4, 6, 0, 0, 0]),
};

function texel(table: LightTable, row: number, texel: number): number[] {
  const data = table.texture.image.data as Float32Array;
  return [...data.subarray((row * 4 + texel) * 4, (row * 4 + texel) * 4 + 4)];
}

test("the table holds the lights in ascending id, as light_index counts them", () => {
  const table = new LightTable();
  table.set(LIGHTS);
  assert.deepEqual([...table.ids], [7, 12, 40]);
  assert.deepEqual([table.row(7), table.row(12), table.row(40), table.row(8)], [0, 1, 2, -1]);
  assert.deepEqual(texel(table, 2, 0), [1, 2, 3, 10]);  // light 40: position, radius
  assert.equal(texel(table, 2, 1)[3], 0);
  assert.equal(texel(table, 0, 1)[3], 2);  // light 7 is directional
  assert.ok(Math.abs(texel(table, 1, 1)[0] - 4 * Math.PI) < 1e-5);  // intensity times pi
  assert.ok(Math.abs(texel(table, 1, 2)[3] - Math.cos(0.6)) < 1e-6);
  assert.ok(Math.abs(texel(table, 1, 3)[0] - Math.cos(0.8 * 0.6)) < 1e-6);  // default inner
  table.updatePositions(new Int32Array([12]), new Float64Array([9, 8, 7]));
  assert.deepEqual(table.position(1, new Vector3()).toArray(), [9, 8, 7]);
  assert.throws(() => table.updatePositions([5], [0, 0, 0]), /light 5/);
});

function frameOf(k: number, lightIndex: number[], fadeWeight: number[], directional: number[]): Frame {
  return {
    frame_index: 0, stats: {},
    object_id: new NdArray("int32", [2], new Int32Array([3, 9])),
    light_index: new NdArray("int32", [2, k], new Int32Array(lightIndex)),
    fade_weight: new NdArray("float32", [2, k], new Float32Array(fadeWeight)),
    directional_lights: new NdArray("int32", [directional.length], new Int32Array(directional)),
  };
}

test("the slot attributes are the frame's arrays, and a new frame keeps their buffers", () => {
  const table = new LightTable();
  table.set(LIGHTS);
  const k = 5;
  const { material, uniforms } = scheduleMaterial(new MeshStandardMaterial(), table, { maxLights: k });
  const objects = new ScheduledInstances(OBJECTS, material, uniforms, k);
  assert.deepEqual([...objects.ids], [3, 9]);
  const m = new Matrix4();
  objects.mesh.getMatrixAt(1, m);  // object 9: the box (0, 0, 0)-(2, 4, 6)
  assert.deepEqual(new Vector3().setFromMatrixPosition(m).toArray(), [1, 2, 3]);
  assert.deepEqual(new Vector3().setFromMatrixScale(m).toArray(), [2, 4, 6]);

  const first = frameOf(k, [1, 2, -1, -1, -1, 2, -1, -1, -1, -1], [1, 0.5, 0, 0, 0, 0.25, 0, 0, 0, 0], [7]);
  objects.applyFrame(first, table);
  const geometry = objects.mesh.geometry;
  const slots = geometry.getAttribute("light_index0") as InterleavedBufferAttribute;
  const tail = geometry.getAttribute("light_index1") as InterleavedBufferAttribute;
  assert.equal(slots.data.array, first.light_index!.data);
  assert.equal((geometry.getAttribute("fade_weight0") as InterleavedBufferAttribute).data.array,
    first.fade_weight!.data);
  assert.deepEqual([slots.itemSize, slots.offset, slots.data.stride], [4, 0, k]);
  assert.deepEqual([tail.itemSize, tail.offset], [1, 4]);
  assert.equal(tail.getX(1), -1);
  assert.equal(slots.getX(1), 2);
  assert.equal(uniforms.directionalCount.value, 1);
  assert.equal(uniforms.directionalRows.value[0], 0);  // light 7 is row 0

  const second = frameOf(k, [2, -1, -1, -1, -1, 0, 1, -1, -1, -1], [1, 0, 0, 0, 0, 1, 1, 0, 0, 0], []);
  const version = slots.data.version;
  objects.applyFrame(second, table);
  assert.equal(geometry.getAttribute("light_index0"), slots);
  assert.equal(slots.data.array, second.light_index!.data);
  assert.ok(slots.data.version > version);
  assert.equal(uniforms.directionalCount.value, 0);
  assert.throws(() => objects.applyFrame(frameOf(2, [0, 0, 0, 0], [0, 0, 0, 0], []), table), /K = 2/);
});

test("the shader patch loops over K slots and its program depends on K alone", () => {
  const table = new LightTable();
  table.set(LIGHTS);
  const patched = (k: number, lambert = false) => {
    const { material } = scheduleMaterial(lambert ? new MeshLambertMaterial() : new MeshStandardMaterial(),
      table, { maxLights: k });
    const lib = lambert ? ShaderLib.lambert : ShaderLib.standard;
    const shader = { uniforms: {}, vertexShader: lib.vertexShader, fragmentShader: lib.fragmentShader } as
      unknown as WebGLProgramParametersWithUniforms;
    material.onBeforeCompile(shader, undefined as unknown as WebGLRenderer);
    return { material, shader };
  };
  const six = patched(6);
  assert.match(six.shader.vertexShader, /in ivec4 light_index0;\nin vec4 fade_weight0;/);
  assert.match(six.shader.vertexShader, /in ivec2 light_index1;/);
  assert.match(six.shader.fragmentShader, /for \(int s = 0; s < 6; s\+\+\)/);
  assert.match(six.shader.fragmentShader, /slotRow\[5\] = vLightIndex1\.y;/);
  assert.ok(six.shader.fragmentShader.indexOf("scheduledLight(slotRow[s]")
    > six.shader.fragmentShader.indexOf("#include <lights_fragment_begin>"));
  assert.ok("lightTable" in six.shader.uniforms && "directionalRows" in six.shader.uniforms);
  assert.match(patched(1, true).shader.fragmentShader, /slotRow\[0\] = vLightIndex0;/);
  assert.equal(six.material.customProgramCacheKey(), patched(6).material.customProgramCacheKey());
  assert.notEqual(six.material.customProgramCacheKey(), patched(8).material.customProgramCacheKey());
  assert.throws(() => patched(17), /1\.\.16/);
});

test("the core entry imports neither three nor Node", async () => {
  const { readFile } = await import("node:fs/promises");
  const seen = new Set<string>();
  const imports: string[] = [];
  const walk = async (url: URL) => {
    if (seen.has(url.href)) return;
    seen.add(url.href);
    const code = await readFile(url, "utf8");
    for (const [, spec] of code.matchAll(/(?:import|export)[^"']*?from\s*["']([^"']+)["']/g)) {
      if (spec.startsWith(".")) await walk(new URL(spec, url));
      else imports.push(spec);
    }
  };
  await walk(new URL("../src/index.js", import.meta.url));
  assert.ok(seen.size >= 4, [...seen].join(", "));
  assert.deepEqual([...new Set(imports)], ["@msgpack/msgpack"]);
});
