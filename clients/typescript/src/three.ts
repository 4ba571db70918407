/**
 * lightsched/three: LightSched as the light manager of a three.js scene.
 *
 * three.js applies every scene light to every material and recompiles a material's shader
 * whenever the number of lights changes (three.js issue #9325). Here the scene holds no
 * three.js lights for LightSched's lights at all: each object reads its K slots from the
 * frame instead.
 * - LightTable: the session's lights, in ascending id (the rows frame.light_index names),
 *   in a float DataTexture that the shader reads with texelFetch.
 * - ScheduledInstances: the objects, in ascending id (the rows of the frame), as one
 *   InstancedMesh whose per-instance attributes are frame.light_index and frame.fade_weight
 *   themselves (an interleaved buffer of stride K over the frame's typed array) and, when
 *   the frame has one, frame.residual.
 * - scheduleMaterial: an onBeforeCompile patch of a MeshStandardMaterial or
 *   MeshLambertMaterial that loops over the K slots (K is the only compile-time constant),
 *   adds frame.directional_lights outside the slots and the residual's L1 irradiance.
 * A new light set is new attribute data and uniforms, never a new program.
 *
 * Not yet: sampling shadow maps for slot_shadow slots (the shadowed slots are lit unshadowed).
 */

import {
  BoxGeometry, BufferGeometry, DataTexture, FloatType, InstancedBufferAttribute,
  InstancedInterleavedBuffer, InstancedMesh, InterleavedBufferAttribute, Matrix4,
  MeshLambertMaterial, MeshStandardMaterial, RGBAFormat, Vector3, type Material,
  type WebGLProgramParametersWithUniforms,
} from "three";

import type { Frame } from "./client.js";
import type { NdArray, TypedArray } from "./wire.js";

/** Numbers of a light field: a typed array, a plain list or an NdArray (row-major). */
export type Values = TypedArray | ArrayLike<number> | NdArray;

function values(v: Values | undefined): ArrayLike<number> | undefined {
  if (v === undefined) return undefined;
  return "dtype" in v && "data" in v ? (v.data as unknown as ArrayLike<number>) : (v as ArrayLike<number>);
}

/** The light fields the shader needs (DESIGN section 1), plus a display color. */
export interface LightFields {
  id: Values;
  /** 0 point, 1 spot, 2 directional (default 0). */
  type?: Values;
  /** [L, 3] */
  position: Values;
  radius: Values;
  /** [L, 3]: spot axis, or the direction a directional light travels. */
  direction?: Values;
  outer_angle?: Values;
  inner_angle?: Values;
  intensity?: Values;
  /** [L, 3] linear RGB the intensity is multiplied by (default white); not a wire field. */
  color?: Values;
}

const POINT = 0;
const DIRECTIONAL = 2;
// Four RGBA texels a light: (position, radius), (color * intensity * pi, type),
// (direction, cos outer), (cos inner, 0, 0, 0); LIGHTS_PER_ROW lights a texture row keeps
// the texture within WebGL2's guaranteed 2048 texels a side up to half a million lights.
const TEXELS = 4;
const LIGHTS_PER_ROW = 256;

/**
 * The lights of a session, in ascending id: row r of the table is light_index r. Keep it
 * equal to the session's light set (set it whenever setLights is sent) or the rows the
 * frame names are other lights.
 */
export class LightTable {
  texture: DataTexture;
  /** Light ids, ascending: row r holds ids[r]. */
  ids = new Int32Array(0);
  private data = new Float32Array(0);

  constructor() {
    this.texture = this.allocate(1);
  }

  get size(): number { return this.ids.length; }

  private allocate(lights: number): DataTexture {
    const height = Math.max(1, Math.ceil(lights / LIGHTS_PER_ROW));
    this.data = new Float32Array(LIGHTS_PER_ROW * TEXELS * height * 4);
    const texture = new DataTexture(this.data, LIGHTS_PER_ROW * TEXELS, height, RGBAFormat, FloatType);
    texture.needsUpdate = true;
    return texture;
  }

  /** The row of light ``id`` (-1 if absent). */
  row(id: number): number {
    let lo = 0;
    let hi = this.ids.length;
    while (lo < hi) {
      const mid = (lo + hi) >>> 1;
      if (this.ids[mid] < id) lo = mid + 1;
      else hi = mid;
    }
    return lo < this.ids.length && this.ids[lo] === id ? lo : -1;
  }

  /** Replaces the lights (as Session.setLights does); rows in any order. */
  set(fields: LightFields): void {
    const id = values(fields.id)!;
    const n = id.length;
    const order = Array.from({ length: n }, (_, i) => i).sort((a, b) => id[a] - id[b]);
    this.ids = Int32Array.from(order, (i) => id[i]);
    if (this.data.length < n * TEXELS * 4 || n === 0) {
      this.texture.dispose();
      this.texture = this.allocate(n);
    }
    this.data.fill(0);
    const type = values(fields.type);
    const position = values(fields.position)!;
    const radius = values(fields.radius)!;
    const direction = values(fields.direction);
    const outer = values(fields.outer_angle);
    const inner = values(fields.inner_angle);
    const intensity = values(fields.intensity);
    const color = values(fields.color);
    order.forEach((src, r) => {
      const t = r * TEXELS * 4;
      const o = outer ? outer[src] : Math.PI / 4;
      const i = intensity ? intensity[src] : 1;
      for (let k = 0; k < 3; k++) {
        this.data[t + k] = position[3 * src + k];
        // DESIGN's intensity is radiometric I / pi; three's direct lighting multiplies
        // the irradiance by BRDF_Lambert = albedo / pi.
        this.data[t + 4 + k] = (color ? color[3 * src + k] : 1) * i * Math.PI;
        this.data[t + 8 + k] = direction ? direction[3 * src + k] : (k === 1 ? -1 : 0);
      }
      this.data[t + 3] = radius[src];
      this.data[t + 7] = type ? type[src] : POINT;
      this.data[t + 11] = Math.cos(o);
      this.data[t + 12] = Math.cos(inner ? inner[src] : 0.8 * o);
    });
    this.texture.needsUpdate = true;
  }

  /** Moves lights (as Session.updateLights with positions does). */
  updatePositions(id: Values, position: Values): void {
    const ids = values(id)!;
    const p = values(position)!;
    for (let i = 0; i < ids.length; i++) {
      const r = this.row(ids[i]);
      if (r < 0) throw new RangeError(`light ${ids[i]} is not in the table`);
      const t = r * TEXELS * 4;
      this.data[t] = p[3 * i];
      this.data[t + 1] = p[3 * i + 1];
      this.data[t + 2] = p[3 * i + 2];
    }
    this.texture.needsUpdate = true;
  }

  /** Light ``row``'s position (the table's copy, float32). */
  position(row: number, out = new Vector3()): Vector3 {
    const t = row * TEXELS * 4;
    return out.set(this.data[t], this.data[t + 1], this.data[t + 2]);
  }

  isDirectional(row: number): boolean {
    return this.data[row * TEXELS * 4 + 7] === DIRECTIONAL;
  }
}

export interface ScheduleOptions {
  /** K: the session's max_lights. Changing it needs a new program; nothing else does. */
  maxLights: number;
  /** Directional lights applied outside the slots, at most (default 4). */
  maxDirectional?: number;
}

/** The uniforms a patched material reads; ScheduledInstances.applyFrame fills them. */
export interface ScheduleUniforms {
  lightTable: { value: DataTexture };
  directionalCount: { value: number };
  directionalRows: { value: number[] };
}

/** Vertex attributes a slot group has at most: a vec4 (ivec4) carries four slots. */
function groups(k: number): number[] {
  const out: number[] = [];
  for (let s = 0; s < k; s += 4) out.push(Math.min(4, k - s));
  return out;
}

const INT_TYPE = ["", "int", "ivec2", "ivec3", "ivec4"];
const FLOAT_TYPE = ["", "float", "vec2", "vec3", "vec4"];
const COMPONENT = ["x", "y", "z", "w"];

function vertexPatch(k: number): [string, string] {
  const g = groups(k);
  const decl = g.map((n, i) => `in ${INT_TYPE[n]} light_index${i};\nin ${FLOAT_TYPE[n]} fade_weight${i};\n`
    + `flat out ${INT_TYPE[n]} vLightIndex${i};\nflat out ${FLOAT_TYPE[n]} vFadeWeight${i};`).join("\n");
  const copy = g.map((_, i) => `vLightIndex${i} = light_index${i}; vFadeWeight${i} = fade_weight${i};`).join("\n");
  return [`${decl}\nin vec4 residual;\nflat out vec4 vResidual;`, `${copy}\nvResidual = residual;`];
}

function fragmentPatch(k: number, maxDirectional: number): [string, string] {
  const g = groups(k);
  const decl = g.map((n, i) => `flat in ${INT_TYPE[n]} vLightIndex${i};\nflat in ${FLOAT_TYPE[n]} vFadeWeight${i};`).join("\n");
  // Slot s of the frame row is component s % 4 of attribute s / 4.
  const rows = [];
  for (let s = 0; s < k; s++) {
    const i = s >> 2;
    const c = g[i] === 1 ? "" : `.${COMPONENT[s & 3]}`;
    rows.push(`slotRow[${s}] = vLightIndex${i}${c}; slotWeight[${s}] = vFadeWeight${i}${c};`);
  }
  const pars = `${decl}
flat in vec4 vResidual;
uniform highp sampler2D lightTable;
uniform int directionalCount;
uniform int directionalRows[${maxDirectional}];

vec4 lightTexel(int row, int texel) {
  return texelFetch(lightTable, ivec2((row % ${LIGHTS_PER_ROW}) * ${TEXELS} + texel, row / ${LIGHTS_PER_ROW}), 0);
}

// DESIGN section 2's falloff, with the spot factor over the fragment's direction:
// i * w^2 / (d2 + r0^2) * s, w = max(0, 1 - (d2/r^2)^2), r0 = 0.1 m.
IncidentLight scheduledLight(int row, vec3 position) {
  vec4 placed = lightTexel(row, 0);
  vec4 shade = lightTexel(row, 1);
  vec4 aim = lightTexel(row, 2);
  IncidentLight light;
  light.visible = true;
  if (shade.w == 2.0) {
    light.direction = normalize((viewMatrix * vec4(-aim.xyz, 0.0)).xyz);
    light.color = shade.rgb;
    return light;
  }
  vec3 toLight = (viewMatrix * vec4(placed.xyz, 1.0)).xyz - position;
  float d2 = dot(toLight, toLight);
  float q = d2 / (placed.w * placed.w);
  float w = max(0.0, 1.0 - q * q);
  light.direction = normalize(toLight);
  float s = 1.0;
  if (shade.w == 1.0) {
    float c = dot(-light.direction, normalize((viewMatrix * vec4(aim.xyz, 0.0)).xyz));
    float cosInner = lightTexel(row, 3).x;
    s = cosInner > aim.w ? clamp((c - aim.w) / (cosInner - aim.w), 0.0, 1.0) : step(aim.w, c);
    s *= s;
  }
  light.color = shade.rgb * (w * w / (d2 + 0.01) * s);
  return light;
}
`;
  const body = `
{
  int slotRow[${k}];
  float slotWeight[${k}];
  ${rows.join("\n  ")}
  for (int s = 0; s < ${k}; s++) {
    if (slotRow[s] < 0 || slotWeight[s] <= 0.0) continue;
    IncidentLight slotLight = scheduledLight(slotRow[s], geometryPosition);
    slotLight.color *= slotWeight[s];
    RE_Direct(slotLight, geometryPosition, geometryNormal, geometryViewDir, geometryClearcoatNormal, material, reflectedLight);
  }
  for (int d = 0; d < ${maxDirectional}; d++) {
    if (d >= directionalCount) break;
    IncidentLight sun = scheduledLight(directionalRows[d], geometryPosition);
    RE_Direct(sun, geometryPosition, geometryNormal, geometryViewDir, geometryClearcoatNormal, material, reflectedLight);
  }
  // The residual (DESIGN section 2): max(0, a/4 + (b . n)/2) of diffuse irradiance at the
  // world normal n, times pi as the table's colors are.
  vec3 worldNormal = inverseTransformDirection(geometryNormal, viewMatrix);
  irradiance += PI * max(0.0, vResidual.x / 4.0 + dot(vResidual.yzw, worldNormal) / 2.0);
}
`;
  return [pars, body];
}

/**
 * Patches ``material`` (MeshStandardMaterial or MeshLambertMaterial) to light each instance
 * of a ScheduledInstances by its frame slots. The returned uniforms are shared with the
 * instances that use it. Only maxLights and maxDirectional shape the program
 * (customProgramCacheKey, three.js docs: Material.customProgramCacheKey).
 */
export function scheduleMaterial<M extends MeshStandardMaterial | MeshLambertMaterial>(
  material: M, table: LightTable, options: ScheduleOptions): { material: M; uniforms: ScheduleUniforms } {
  const k = options.maxLights;
  const maxDirectional = options.maxDirectional ?? 4;
  if (!Number.isInteger(k) || k < 1 || k > 16) {
    // Two vertex attributes per four slots; WebGL2 guarantees only 16 attributes.
    throw new RangeError(`maxLights must be an integer in 1..16 here, not ${k}`);
  }
  const uniforms: ScheduleUniforms = {
    lightTable: { value: table.texture },
    directionalCount: { value: 0 },
    directionalRows: { value: new Array<number>(maxDirectional).fill(0) },
  };
  const [vertexPars, vertexMain] = vertexPatch(k);
  const [fragmentPars, fragmentMain] = fragmentPatch(k, maxDirectional);
  material.onBeforeCompile = (shader: WebGLProgramParametersWithUniforms) => {
    Object.assign(shader.uniforms, uniforms);
    shader.vertexShader = shader.vertexShader
      .replace("#include <common>", `#include <common>\n${vertexPars}`)
      .replace("#include <begin_vertex>", `#include <begin_vertex>\n${vertexMain}`);
    shader.fragmentShader = shader.fragmentShader
      .replace("#include <common>", `#include <common>\n${fragmentPars}`)
      .replace("#include <lights_fragment_begin>", `#include <lights_fragment_begin>\n${fragmentMain}`);
  };
  material.customProgramCacheKey = () => `lightsched:${k}:${maxDirectional}`;
  return { material, uniforms };
}

/** Object fields: ids and boxes (DESIGN section 1). */
export interface ObjectFields {
  id: Values;
  bounds_min: Values;
  bounds_max: Values;
}

/**
 * The objects, in ascending id, as one InstancedMesh of a unit cube scaled to each box
 * (or of ``geometry``, placed in the box): instance i is frame row i.
 */
export class ScheduledInstances {
  readonly mesh: InstancedMesh;
  /** Object ids, ascending: instance i is ids[i]. */
  readonly ids: Int32Array;
  /** Box centres, [N, 3], instance order. */
  readonly centres: Float32Array;
  private lightIndex?: InstancedInterleavedBuffer;
  private fadeWeight?: InstancedInterleavedBuffer;
  private residual: InstancedBufferAttribute;

  constructor(objects: ObjectFields, material: Material, readonly uniforms: ScheduleUniforms,
              readonly maxLights: number, geometry: BufferGeometry = new BoxGeometry(1, 1, 1)) {
    const id = values(objects.id)!;
    const lo = values(objects.bounds_min)!;
    const hi = values(objects.bounds_max)!;
    const n = id.length;
    const order = Array.from({ length: n }, (_, i) => i).sort((a, b) => id[a] - id[b]);
    this.ids = Int32Array.from(order, (i) => id[i]);
    this.centres = new Float32Array(3 * n);
    this.mesh = new InstancedMesh(geometry, material, n);
    const m = new Matrix4();
    order.forEach((src, i) => {
      const size = [0, 1, 2].map((k) => Math.max(hi[3 * src + k] - lo[3 * src + k], 1e-3));
      for (let k = 0; k < 3; k++) this.centres[3 * i + k] = 0.5 * (lo[3 * src + k] + hi[3 * src + k]);
      m.makeScale(size[0], size[1], size[2]).setPosition(
        this.centres[3 * i], this.centres[3 * i + 1], this.centres[3 * i + 2]);
      this.mesh.setMatrixAt(i, m);
    });
    // Rows of -1 light nothing until the first frame.
    this.attach(new Int32Array(n * maxLights).fill(-1), new Float32Array(n * maxLights));
    this.residual = new InstancedBufferAttribute(new Float32Array(4 * n), 4);
    geometry.setAttribute("residual", this.residual);
  }

  /** Points the slot attributes at new arrays: a new buffer only if the size changed. */
  private attach(lightIndex: Int32Array, fadeWeight: Float32Array): void {
    const k = this.maxLights;
    const geometry = this.mesh.geometry;
    if (this.lightIndex && this.lightIndex.array.length === lightIndex.length) {
      this.lightIndex.array = lightIndex;
      this.fadeWeight!.array = fadeWeight;
      this.lightIndex.needsUpdate = true;
      this.fadeWeight!.needsUpdate = true;
      return;
    }
    this.lightIndex = new InstancedInterleavedBuffer(lightIndex, k);
    this.fadeWeight = new InstancedInterleavedBuffer(fadeWeight, k);
    groups(k).forEach((size, i) => {
      geometry.setAttribute(`light_index${i}`, new InterleavedBufferAttribute(this.lightIndex!, size, 4 * i));
      geometry.setAttribute(`fade_weight${i}`, new InterleavedBufferAttribute(this.fadeWeight!, size, 4 * i));
    });
  }

  /**
   * The frame's slots (light_index, fade_weight, residual when present) and directional
   * lights, as they are: the typed arrays become the attributes' data. The frame's objects
   * must be these instances (same ids, ascending) and its K this maxLights.
   */
  applyFrame(frame: Frame & { residual?: NdArray<Float32Array> }, table: LightTable): void {
    const { light_index, fade_weight, object_id } = frame;
    if (!light_index || !fade_weight || !object_id) {
      throw new Error("the frame needs object_id, light_index and fade_weight");
    }
    if (object_id.data.length !== this.ids.length || light_index.shape[1] !== this.maxLights) {
      throw new RangeError(`the frame has ${object_id.data.length} objects of K = ${light_index.shape[1]}; `
        + `the instances ${this.ids.length} of K = ${this.maxLights}`);
    }
    this.attach(light_index.data, fade_weight.data);
    if (frame.residual) {
      this.residual.array = frame.residual.data;
      this.residual.needsUpdate = true;
    } else if (this.residual.array.some((v) => v !== 0)) {
      // A frame without one (residual off, or not asked for) adds none.
      this.residual.array = new Float32Array(this.residual.array.length);
      this.residual.needsUpdate = true;
    }
    const rows = frame.directional_lights?.data ?? new Int32Array(0);
    const slots = this.uniforms.directionalRows.value;
    let count = 0;
    for (const id of rows) {
      const r = table.row(id);
      if (r >= 0 && count < slots.length) slots[count++] = r;
    }
    this.uniforms.directionalCount.value = count;
    this.uniforms.lightTable.value = table.texture;
  }

  /** The object id of a raycast hit's instanceId. */
  objectId(instanceId: number): number {
    return this.ids[instanceId];
  }
}
