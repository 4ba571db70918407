// lightsched/three without a GPU: the light table's rows are light_index's rows, the slot
// attributes are the frame's own typed arrays, the shader patch depends on K alone, and
// the shadow atlas's tiles, views and table are what the shader will read. Drawing with it
// is tested in a real browser (tests/test_viewer.py).
import assert from "node:assert/strict";
import { test } from "node:test";

import {
  IntType, InterleavedBufferAttribute, Matrix4, MeshLambertMaterial, MeshStandardMaterial, ShaderLib, Vector3,
  Vector4, type WebGLProgramParametersWithUniforms, type WebGLRenderer,
} from "three";

import type { Frame } from "../src/client.js";
import {
  LightTable, ScheduledInstances, ShadowAtlas, cubeFace, layoutShadowTiles, scheduleMaterial, shadowCamera,
  shadowViewCount, type LightShape,
} from "../src/three.js";
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

/** Every placed tile inside the atlas and none overlapping another. */
function assertTilesFit(tiles: ReturnType<typeof layoutShadowTiles>, views: number[], atlas: number): void {
  const placed: [number, number, number][] = [];
  views.forEach((n, j) => {
    for (let v = 0; v < 6; v++) {
      const [x, y] = [tiles.x[6 * j + v], tiles.y[6 * j + v]];
      if (v >= n || tiles.size[j] === 0) {
        assert.deepEqual([x, y], [-1, -1], `light ${j} view ${v} has no tile`);
        continue;
      }
      const s = tiles.size[j];
      assert.ok(x >= 0 && y >= 0 && x + s <= atlas && y + s <= atlas, `light ${j} view ${v} at ${x}, ${y}`);
      for (const [px, py, ps] of placed) {
        assert.ok(x >= px + ps || px >= x + s || y >= py + ps || py >= y + s, `light ${j} view ${v} overlaps`);
      }
      placed.push([x, y, s]);
    }
  });
}

test("tiles are the tiers, halved from the last light until the views fit the atlas", () => {
  // A point light at 512, a spot at 256, a point at 4096 in 2048 texels: the last one
  // clamps to the atlas, then halves to 512, where 6 * 512^2 + 256^2 + 6 * 512^2 fits.
  let views = [6, 1, 6];
  let tiles = layoutShadowTiles([512, 256, 4096], views, 2048, 64);
  assert.deepEqual([...tiles.size], [512, 256, 512]);
  assertTilesFit(tiles, views, 2048);
  // Tiers as they are when they fit; a directional light (no views) takes no room.
  views = [1, 0, 6];
  tiles = layoutShadowTiles([256, 4096, 256], views, 2048, 64);
  assert.deepEqual([...tiles.size], [256, 0, 256]);
  assertTilesFit(tiles, views, 2048);
  // 256 texels hold two point lights at 64 but not three: the third and everything after
  // it (even a spot that would fit) go unshadowed, as DESIGN's atlas drops its lights.
  views = [6, 6, 6, 1];
  tiles = layoutShadowTiles([256, 256, 256, 256], views, 256, 64);
  assert.deepEqual([...tiles.size], [64, 64, 0, 0]);
  assertTilesFit(tiles, views, 256);
  // Mixed sizes pack without gaps: their area is the atlas's exactly.
  views = [1, 1, 1, 1, 1, 1, 1];
  tiles = layoutShadowTiles([128, 64, 64, 128, 64, 64, 128], views, 256, 64);
  assert.deepEqual([...tiles.size], [128, 64, 64, 128, 64, 64, 128]);
  assertTilesFit(tiles, views, 256);

  // Random frames: whatever fits is placed, inside and apart; halving never goes below
  // minTile and never touches a light while a later one is above minTile.
  let seed = 7;
  const random = () => (seed = (seed * 1103515245 + 12345) % 2 ** 31) / 2 ** 31;
  for (let trial = 0; trial < 200; trial++) {
    const count = 1 + Math.floor(random() * 12);
    views = Array.from({ length: count }, () => [0, 1, 6][Math.floor(random() * 3)]);
    const tiers = Array.from({ length: count }, () => 2 ** (8 + Math.floor(random() * 5)));
    const atlas = 2 ** (9 + Math.floor(random() * 3));
    tiles = layoutShadowTiles(tiers, views, atlas, 32);
    assertTilesFit(tiles, views, atlas);
    let area = 0;
    let seenHalved = false;
    for (let j = count - 1; j >= 0; j--) {
      area += views[j] * tiles.size[j] ** 2;
      if (views[j] === 0) continue;
      const wanted = Math.min(atlas, tiers[j]);
      if (tiles.size[j] !== 0) assert.ok(tiles.size[j] >= 32 && tiles.size[j] <= wanted);
      if (tiles.size[j] > 32 && tiles.size[j] < wanted) seenHalved = true;
      if (seenHalved && j < count - 1) assert.ok(tiles.size[j] !== 0);
    }
    assert.ok(area <= atlas * atlas);
  }
});

const POINT_LIGHT: LightShape = {
  type: 0, position: new Vector3(1, 2, 3), radius: 10, direction: new Vector3(0, -1, 0), outerAngle: 0.5,
};

function project(camera: ReturnType<typeof shadowCamera>, p: Vector3): Vector4 {
  const m = new Matrix4().multiplyMatrices(camera.projectionMatrix, camera.matrixWorldInverse);
  const clip = new Vector4(p.x, p.y, p.z, 1).applyMatrix4(m);
  return clip.divideScalar(clip.w);
}

test("a point light's six views are DESIGN's cube faces, picked by the major axis", () => {
  assert.deepEqual([0, 1, 2].map(shadowViewCount), [6, 1, 0]);
  const axes = [[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]];
  axes.forEach(([x, y, z], face) => {
    assert.equal(cubeFace(x, y, z), face);
    const centre = project(shadowCamera(POINT_LIGHT, face), new Vector3(x, y, z).multiplyScalar(4).add(POINT_LIGHT.position));
    assert.ok(Math.abs(centre.x) < 1e-9 && Math.abs(centre.y) < 1e-9, `face ${face}: ${centre.toArray()}`);
  });
  // Any direction lands inside the frustum of the face cubeFace picks, within the radius.
  let seed = 3;
  const random = () => (seed = (seed * 1103515245 + 12345) % 2 ** 31) / 2 ** 31 * 2 - 1;
  for (let i = 0; i < 500; i++) {
    const v = new Vector3(random(), random(), random());
    if (v.lengthSq() === 0) continue;
    v.setLength(0.01 + 9.98 * Math.abs(random()));
    const face = cubeFace(v.x, v.y, v.z);
    const ndc = project(shadowCamera(POINT_LIGHT, face), v.clone().add(POINT_LIGHT.position));
    for (const c of [ndc.x, ndc.y, ndc.z]) assert.ok(Math.abs(c) <= 1 + 1e-9, `${v.toArray()} face ${face}: ${ndc.toArray()}`);
  }
  // Ties go to x, then y.
  assert.equal(cubeFace(1, 1, 1), 0);
  assert.equal(cubeFace(0, -1, 1), 3);
});

test("a spot light's view is its cone's square: the axis at the centre, the cone's edge at the border", () => {
  for (const direction of [new Vector3(0, -1, 0), new Vector3(1, 0.2, -0.5).normalize()]) {
    const spot: LightShape = { ...POINT_LIGHT, type: 1, direction, outerAngle: 0.6 };
    const camera = shadowCamera(spot, 0);
    const onAxis = project(camera, direction.clone().multiplyScalar(5).add(spot.position));
    assert.ok(Math.hypot(onAxis.x, onAxis.y) < 1e-9);
    // A point at the outer angle from the axis, towards the camera's up, is on the top edge.
    const up = new Vector3().setFromMatrixColumn(camera.matrixWorld, 1);
    const edge = direction.clone().applyAxisAngle(new Vector3().crossVectors(direction, up).normalize(), 0.6);
    const top = project(camera, edge.multiplyScalar(5).add(spot.position));
    assert.ok(Math.abs(top.y - 1) < 1e-9 && Math.abs(top.x) < 1e-9, `${top.toArray()}`);
  }
});

test("the shadow table holds each shadow light's views in its row, as slot_shadow indexes them", () => {
  const table = new LightTable();
  // Light 40 a point, 12 a spot, 7 directional.
  table.set(LIGHTS);
  const atlas = new ShadowAtlas({ size: 1024, minTile: 64 });
  const frame: Frame = {
    frame_index: 0, stats: {},
    shadow_lights: new NdArray("int32", [4], new Int32Array([12, 40, 7, 99])),
    shadow_tier: new NdArray("uint16", [4], new Uint16Array([512, 256, 4096, 256])),
  };
  atlas.update(frame, table);
  assert.deepEqual([...atlas.tiles.size], [512, 256, 0, 0]);
  const texel = (j: number, t: number) => [...atlas.tableRow(j).subarray(4 * t, 4 * t + 4)];
  // Row 1: light 40 at (1, 2, 3), radius 10, six views; its face 3 (-y) matrix and tile.
  assert.deepEqual(texel(1, 0).map((v) => +v.toFixed(6)), [1, 2, 3, 0.1]);
  assert.equal(texel(1, 1)[0], 6);
  assert.ok(texel(1, 1)[1] > 0 && texel(1, 1)[1] < 0.05);  // a bias of a few texels
  const light40 = table.shape(table.row(40));
  const faceMatrix = new Matrix4().multiplyMatrices(shadowCamera(light40, 3).projectionMatrix,
    shadowCamera(light40, 3).matrixWorldInverse);
  const t = 2 + 5 * 3;
  const stored = [0, 1, 2, 3].flatMap((c) => texel(1, t + c));
  stored.forEach((v, i) => assert.ok(Math.abs(v - faceMatrix.elements[i]) < 1e-5));
  assert.deepEqual(texel(1, t + 4).slice(0, 3), [atlas.tiles.x[6 + 3], atlas.tiles.y[6 + 3], 256]);
  // Row 0: the spot, one view; rows 2 (directional) and 3 (not in the table): nothing.
  assert.equal(texel(0, 1)[0], 1);
  assert.deepEqual(texel(0, 2 + 5 + 4), [0, 0, 0, 0]);
  assert.ok(atlas.tableRow(2).every((v) => v === 0) && atlas.tableRow(3).every((v) => v === 0));
  // The table grows with the shadow lights, as a texture: the uniform's value changes.
  const before = atlas.uniforms.shadowTable.value;
  const many = Int32Array.from({ length: 9 }, () => 12);
  atlas.update({ ...frame, shadow_lights: new NdArray("int32", [9], many),
    shadow_tier: new NdArray("uint16", [9], new Uint16Array(9).fill(64)) }, table);
  assert.notEqual(atlas.uniforms.shadowTable.value, before);
  assert.equal(atlas.uniforms.shadowTable.value.image.height, 16);
  // An empty frame clears it: no row left over from the last one.
  atlas.update({ frame_index: 1, stats: {} }, table);
  assert.ok(atlas.tableRow(0).every((v) => v === 0));
});

test("with shadows, slot_shadow is an int attribute of the frame's bytes and the patch samples it", () => {
  const table = new LightTable();
  table.set(LIGHTS);
  const atlas = new ShadowAtlas();
  const k = 6;
  const { material, uniforms } = scheduleMaterial(new MeshStandardMaterial(), table, { maxLights: k, shadows: atlas });
  assert.equal(uniforms.shadowAtlas, atlas.uniforms.shadowAtlas);
  const objects = new ScheduledInstances(OBJECTS, material, uniforms, k);
  const geometry = objects.mesh.geometry;
  const before = geometry.getAttribute("slot_shadow0") as InterleavedBufferAttribute;
  assert.ok([...before.data.array].every((j) => j === -1));
  const frame = { ...frameOf(k, new Array(12).fill(0), new Array(12).fill(1), []),
    slot_shadow: new NdArray("int8", [2, k], Int8Array.from([0, -1, -1, -1, -1, 1, -1, -1, 2, -1, -1, -1])) };
  objects.applyFrame(frame, table);
  const shadow = geometry.getAttribute("slot_shadow0") as InterleavedBufferAttribute & { gpuType: number };
  const tail = geometry.getAttribute("slot_shadow1") as InterleavedBufferAttribute;
  assert.equal(shadow.data.array, frame.slot_shadow.data);
  assert.equal(shadow.gpuType, IntType);
  assert.deepEqual([shadow.getX(0), tail.getY(0), shadow.getZ(1)], [0, 1, 2]);
  // A frame without slot_shadow samples nothing.
  objects.applyFrame(frameOf(k, new Array(12).fill(0), new Array(12).fill(1), []), table);
  assert.ok([...shadow.data.array].every((j) => j === -1));

  const shader = { uniforms: {}, vertexShader: ShaderLib.standard.vertexShader,
    fragmentShader: ShaderLib.standard.fragmentShader } as unknown as WebGLProgramParametersWithUniforms;
  material.onBeforeCompile(shader, undefined as unknown as WebGLRenderer);
  assert.match(shader.vertexShader, /in ivec4 slot_shadow0;/);
  assert.match(shader.vertexShader, /in ivec2 slot_shadow1;/);
  assert.match(shader.fragmentShader, /slotShadow\[5\] = vSlotShadow1\.y;/);
  assert.match(shader.fragmentShader, /shadowVisibility\(slotShadow\[s\], vScheduledWorld\)/);
  assert.ok("shadowAtlas" in shader.uniforms && "shadowTable" in shader.uniforms);
  const plain = scheduleMaterial(new MeshStandardMaterial(), table, { maxLights: k }).material;
  assert.notEqual(material.customProgramCacheKey(), plain.customProgramCacheKey());
  assert.equal(material.customProgramCacheKey(),
    scheduleMaterial(new MeshStandardMaterial(), table, { maxLights: k, shadows: new ShadowAtlas() }).material.customProgramCacheKey());
  assert.throws(() => scheduleMaterial(new MeshStandardMaterial(), table, { maxLights: 9, shadows: atlas }), /1\.\.8/);
  assert.throws(() => new ShadowAtlas({ size: 1000 }), /powers of two/);
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
