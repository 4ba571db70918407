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
 *   InstancedMesh whose per-instance attributes are frame.light_index, frame.fade_weight
 *   and frame.slot_shadow themselves (an interleaved buffer of stride K over the frame's
 *   typed array) and, when the frame has one, frame.residual.
 * - scheduleMaterial: an onBeforeCompile patch of a MeshStandardMaterial or
 *   MeshLambertMaterial that loops over the K slots (K is the only compile-time constant),
 *   adds frame.directional_lights outside the slots and the residual's L1 irradiance, and,
 *   given a ShadowAtlas, darkens each slot whose slot_shadow is >= 0 by that light's map.
 * - ShadowAtlas: the maps of frame.shadow_lights, drawn from the frame's casters.
 * A new light set, a new set of shadowed lights or new casters are new attribute data,
 * textures and uniforms, never a new program.
 *
 * Shadows. One RGBA8 render target (the atlas, default 2048 texels square) holds a square
 * tile per view: six for a point light (its cube faces, DESIGN's bits +x, -x, +y, -y, +z,
 * -z, each a 90 degree frustum), one for a spot light (a frustum over its cone). A tile's
 * side is the light's shadow_tier, scaled down to fit by DESIGN's own atlas rule with this
 * atlas's size and smallest tile (layoutShadowTiles): the lights after the longest prefix
 * of shadow_lights that fits at the smallest tile are drawn unshadowed, then, until the
 * rest fit, the last light above the smallest tile halves, so the scheduler's ranking
 * decides who keeps resolution. ShadowAtlas.render, once a frame after
 * ScheduledInstances.applyFrame, draws the maps (the frame needs shadow_lights,
 * shadow_tier, caster_offsets, caster_ids and caster_masks). Each view draws only
 * its casters, the caster_ids of its light whose caster_masks has the view's bit, as one
 * instanced draw of the objects' geometry with instance matrices refilled per view, back
 * faces only (as three.js draws its own shadow maps: a closed box's lit side then never
 * meets its own depth), writing the distance to the light over its radius packed into
 * the texel's four bytes. RGBA8 because it is renderable on every WebGL2 device, where a
 * float colour target needs EXT_color_buffer_float; a linear distance because a point
 * light's six faces then store one comparable quantity, as precise far from the light as
 * near it, and the bias can be a fixed share of it (a perspective depth crowds its
 * precision at the near plane). Every view is redrawn
 * every frame: caching views until they are dirty waits for the core's shadow_views and
 * shadow_update (DESIGN section 2).
 *
 * The shadow table (a float DataTexture, row j = shadow_lights[j], so slot_shadow indexes
 * it as it is) holds each light's position, 1 / radius, view count and bias, and per view
 * its view-projection matrix and tile. For a slot with slot_shadow j >= 0 the fragment
 * shader picks the view (point: the major axis of the fragment's offset from the light,
 * as cubeFace does; spot: its one view), projects the fragment into the tile and compares
 * its distance, less a bias of BIAS_TEXELS texels of the view, with the 2x2 nearest
 * texels (percentage-closer filtering), and multiplies the slot's light by the share lit.
 * A light with no tile, and a fragment outside a spot's view, are unshadowed. Nothing here
 * is a compile-time constant but K: the table grows as a texture, never as an array size.
 *
 * Directional lights are not shadowed here (a slot_shadow naming one samples nothing):
 * their views are cascades of each camera (cascade_splits, caster bits k * C + c), and
 * one map over all of a city-wide sun's casters would give metres a texel; cascaded maps
 * are left for when the core reports shadow views. The slot_shadow attributes cost a third
 * vertex attribute per four slots, so with shadows K is at most 8, 16 without (see
 * scheduleMaterial).
 */

import {
  BackSide, BoxGeometry, BufferGeometry, Color, DataTexture, FloatType, InstancedBufferAttribute,
  InstancedInterleavedBuffer, InstancedMesh, IntType, InterleavedBufferAttribute, MathUtils, Matrix4,
  MeshLambertMaterial, MeshStandardMaterial, NearestFilter, PerspectiveCamera, RGBAFormat, Scene,
  ShaderMaterial, UnsignedByteType, Vector3, WebGLRenderTarget, type Material, type Texture,
  type WebGLProgramParametersWithUniforms, type WebGLRenderer,
} from "three";

import type { Frame } from "./client.js";
import type { NdArray, TypedArray } from "./wire.js";

/** Numbers of a light field: a typed array, a plain list or an NdArray (row-major). */
export type Values = TypedArray | ArrayLike<number> | NdArray;

function values(v: Values | undefined): ArrayLike<number> | undefined {
  if (v === undefined) return undefined;
  return "dtype" in v && "data" in v ? (v.data as unknown as ArrayLike<number>) : (v as ArrayLike<number>);
}

/** The index of ``id`` in ascending ``ids`` (a binary search), -1 if absent. */
function indexOfId(ids: ArrayLike<number>, id: number): number {
  let lo = 0;
  let hi = ids.length;
  while (lo < hi) {
    const mid = (lo + hi) >>> 1;
    if (ids[mid] < id) lo = mid + 1;
    else hi = mid;
  }
  return lo < ids.length && ids[lo] === id ? lo : -1;
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
const SPOT = 1;
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
    return indexOfId(this.ids, id);
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

  /** What shapes light ``row``'s shadow views: the table's float32 copy, as the shader sees it. */
  shape(row: number): LightShape {
    const t = row * TEXELS * 4;
    const d = this.data;
    return {
      type: d[t + 7], position: new Vector3(d[t], d[t + 1], d[t + 2]), radius: d[t + 3],
      direction: new Vector3(d[t + 8], d[t + 9], d[t + 10]), outerAngle: Math.acos(Math.min(1, d[t + 11])),
    };
  }
}

/** A light's type and the fields its shadow views are built from. */
export interface LightShape {
  type: number;
  position: Vector3;
  radius: number;
  direction: Vector3;
  outerAngle: number;
}

export interface ScheduleOptions {
  /** K: the session's max_lights. Changing it needs a new program; nothing else does. */
  maxLights: number;
  /** Directional lights applied outside the slots, at most (default 4). */
  maxDirectional?: number;
  /** Darken slot_shadow slots by this atlas's maps (K at most 8 then). */
  shadows?: ShadowAtlas;
}

/** The uniforms a patched material reads; ScheduledInstances.applyFrame fills them. */
export interface ScheduleUniforms {
  lightTable: { value: DataTexture };
  directionalCount: { value: number };
  directionalRows: { value: number[] };
  /** With shadows: the atlas's depth and its shadow table (ShadowAtlas.render fills them). */
  shadowAtlas?: { value: Texture };
  shadowTable?: { value: DataTexture };
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

function vertexPatch(k: number, shadows: boolean): [string, string, string] {
  const g = groups(k);
  const decl = g.map((n, i) => `in ${INT_TYPE[n]} light_index${i};\nin ${FLOAT_TYPE[n]} fade_weight${i};\n`
    + `flat out ${INT_TYPE[n]} vLightIndex${i};\nflat out ${FLOAT_TYPE[n]} vFadeWeight${i};`
    + (shadows ? `\nin ${INT_TYPE[n]} slot_shadow${i};\nflat out ${INT_TYPE[n]} vSlotShadow${i};` : "")).join("\n");
  const copy = g.map((_, i) => `vLightIndex${i} = light_index${i}; vFadeWeight${i} = fade_weight${i};`
    + (shadows ? ` vSlotShadow${i} = slot_shadow${i};` : "")).join("\n");
  // The world position the shadow maps are looked up at, after morphs and skinning.
  const world = shadows ? `vec4 scheduledWorld = vec4(transformed, 1.0);
#ifdef USE_INSTANCING
scheduledWorld = instanceMatrix * scheduledWorld;
#endif
vScheduledWorld = (modelMatrix * scheduledWorld).xyz;` : "";
  return [`${decl}\nin vec4 residual;\nflat out vec4 vResidual;${shadows ? "\nout vec3 vScheduledWorld;" : ""}`,
    `${copy}\nvResidual = residual;`, world];
}

function fragmentPatch(k: number, maxDirectional: number, shadows: boolean): [string, string] {
  const g = groups(k);
  const decl = g.map((n, i) => `flat in ${INT_TYPE[n]} vLightIndex${i};\nflat in ${FLOAT_TYPE[n]} vFadeWeight${i};`
    + (shadows ? `\nflat in ${INT_TYPE[n]} vSlotShadow${i};` : "")).join("\n");
  // Slot s of the frame row is component s % 4 of attribute s / 4.
  const rows = [];
  for (let s = 0; s < k; s++) {
    const i = s >> 2;
    const c = g[i] === 1 ? "" : `.${COMPONENT[s & 3]}`;
    rows.push(`slotRow[${s}] = vLightIndex${i}${c}; slotWeight[${s}] = vFadeWeight${i}${c};`
      + (shadows ? ` slotShadow[${s}] = vSlotShadow${i}${c};` : ""));
  }
  const pars = `${decl}
${shadows ? SHADOW_SAMPLING : ""}
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
  ${shadows ? `int slotShadow[${k}];` : ""}
  ${rows.join("\n  ")}
  for (int s = 0; s < ${k}; s++) {
    if (slotRow[s] < 0 || slotWeight[s] <= 0.0) continue;
    IncidentLight slotLight = scheduledLight(slotRow[s], geometryPosition);
    slotLight.color *= slotWeight[s];${shadows ? `
    if (slotShadow[s] >= 0) slotLight.color *= shadowVisibility(slotShadow[s], vScheduledWorld);` : ""}
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
  const shadows = options.shadows;
  // WebGL2 guarantees 16 vertex attributes, and chromium's ANGLE links at most 15 of them
  // (measured under SwiftShader: 16 fail with "Too many attributes"). Position, normal,
  // the instance matrix (4) and the residual take 7; each four slots take two
  // (light_index, fade_weight), three with slot_shadow.
  const most = shadows ? 8 : 16;
  if (!Number.isInteger(k) || k < 1 || k > most) {
    throw new RangeError(`maxLights must be an integer in 1..${most} here${shadows ? " (with shadows)" : ""}, not ${k}`);
  }
  const uniforms: ScheduleUniforms = {
    lightTable: { value: table.texture },
    directionalCount: { value: 0 },
    directionalRows: { value: new Array<number>(maxDirectional).fill(0) },
    ...(shadows ? shadows.uniforms : {}),
  };
  const [vertexPars, vertexMain, vertexWorld] = vertexPatch(k, shadows !== undefined);
  const [fragmentPars, fragmentMain] = fragmentPatch(k, maxDirectional, shadows !== undefined);
  material.onBeforeCompile = (shader: WebGLProgramParametersWithUniforms) => {
    Object.assign(shader.uniforms, uniforms);
    shader.vertexShader = shader.vertexShader
      .replace("#include <common>", `#include <common>\n${vertexPars}`)
      .replace("#include <begin_vertex>", `#include <begin_vertex>\n${vertexMain}`)
      .replace("#include <project_vertex>", `#include <project_vertex>\n${vertexWorld}`);
    shader.fragmentShader = shader.fragmentShader
      .replace("#include <common>", `#include <common>\n${fragmentPars}`)
      .replace("#include <lights_fragment_begin>", `#include <lights_fragment_begin>\n${fragmentMain}`);
  };
  material.customProgramCacheKey = () => `lightsched:${k}:${maxDirectional}:${shadows ? "shadows" : "unshadowed"}`;
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
  private slotShadow?: InstancedInterleavedBuffer;
  private readonly unshadowed: Int8Array;
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
    this.unshadowed = new Int8Array(n * maxLights).fill(-1);
    this.attach(new Int32Array(n * maxLights).fill(-1), new Float32Array(n * maxLights), this.unshadowed);
    this.residual = new InstancedBufferAttribute(new Float32Array(4 * n), 4);
    geometry.setAttribute("residual", this.residual);
  }

  /** Points the slot attributes at new arrays: a new buffer only if the size changed. */
  private attach(lightIndex: Int32Array, fadeWeight: Float32Array, slotShadow: Int8Array): void {
    const k = this.maxLights;
    const geometry = this.mesh.geometry;
    if (this.lightIndex && this.lightIndex.array.length === lightIndex.length) {
      this.lightIndex.array = lightIndex;
      this.fadeWeight!.array = fadeWeight;
      this.slotShadow!.array = slotShadow;
      this.lightIndex.needsUpdate = true;
      this.fadeWeight!.needsUpdate = true;
      this.slotShadow!.needsUpdate = true;
      return;
    }
    this.lightIndex = new InstancedInterleavedBuffer(lightIndex, k);
    this.fadeWeight = new InstancedInterleavedBuffer(fadeWeight, k);
    this.slotShadow = new InstancedInterleavedBuffer(slotShadow, k);
    groups(k).forEach((size, i) => {
      geometry.setAttribute(`light_index${i}`, new InterleavedBufferAttribute(this.lightIndex!, size, 4 * i));
      geometry.setAttribute(`fade_weight${i}`, new InterleavedBufferAttribute(this.fadeWeight!, size, 4 * i));
      // Bytes read as ints (vertexAttribIPointer): three does so for a gpuType of IntType.
      const shadow = new InterleavedBufferAttribute(this.slotShadow!, size, 4 * i);
      geometry.setAttribute(`slot_shadow${i}`, Object.assign(shadow, { gpuType: IntType }));
    });
  }

  /**
   * The frame's slots (light_index, fade_weight, residual when present) and directional
   * lights, as they are: the typed arrays become the attributes' data. The frame's objects
   * must be these instances (same ids, ascending) and its K this maxLights.
   */
  applyFrame(frame: Frame & { residual?: NdArray<Float32Array> }, table: LightTable): void {
    const { light_index, fade_weight, object_id, slot_shadow } = frame;
    if (!light_index || !fade_weight || !object_id) {
      throw new Error("the frame needs object_id, light_index and fade_weight");
    }
    if (object_id.data.length !== this.ids.length || light_index.shape[1] !== this.maxLights) {
      throw new RangeError(`the frame has ${object_id.data.length} objects of K = ${light_index.shape[1]}; `
        + `the instances ${this.ids.length} of K = ${this.maxLights}`);
    }
    // A frame without slot_shadow samples no shadow map.
    this.attach(light_index.data, fade_weight.data, slot_shadow?.data ?? this.unshadowed);
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

  /** The instance (frame row) of object ``id``, -1 if it is not one of these. */
  instanceOf(id: number): number {
    return indexOfId(this.ids, id);
  }
}

// ---- Shadow maps for slot_shadow slots ----

/** Cube faces in DESIGN's bit order (+x, -x, +y, -y, +z, -z): the axis each looks along. */
const CUBE_AXES: readonly [number, number, number][] = [[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]];
/** An up vector for each face, any one not along its axis. */
const CUBE_UPS: readonly [number, number, number][] = [[0, 1, 0], [0, 1, 0], [0, 0, -1], [0, 0, 1], [0, 1, 0], [0, 1, 0]];
/** A view's near plane, as a share of the light's radius: nearer casters are clipped. */
const NEAR = 1e-3;
/** Texels of a shadow table row: the light (position, 1 / radius), (views, bias), then per
 * view its view-projection matrix (four columns) and its tile (x, y, size). */
const SHADOW_HEAD = 2;
const SHADOW_VIEW = 5;
const SHADOW_TEXELS = SHADOW_HEAD + 6 * SHADOW_VIEW;
/** Depth comparison bias in texels of the view (relative to the receiver's distance). */
const BIAS_TEXELS = 2;

/** Shadow views of a light: point 6 (cube faces), spot 1, directional 0 (not shadowed here). */
export function shadowViewCount(type: number): number {
  return type === POINT ? 6 : type === SPOT ? 1 : 0;
}

/**
 * The cube face (DESIGN's bit, 0..5) that the direction (x, y, z) from a point light falls
 * in: its major axis, ties to x before y before z, the same choice as the shader's.
 */
export function cubeFace(x: number, y: number, z: number): number {
  const ax = Math.abs(x);
  const ay = Math.abs(y);
  const az = Math.abs(z);
  if (ax >= ay && ax >= az) return x < 0 ? 1 : 0;
  if (ay >= az) return y < 0 ? 3 : 2;
  return z < 0 ? 5 : 4;
}

/**
 * Places ``camera`` as view ``view`` of ``light`` (point: cube face ``view``, a 90 degree
 * square frustum; spot: its cone, 2 outer_angle wide), reaching to the light's radius.
 */
export function shadowCamera(light: LightShape, view: number, camera = new PerspectiveCamera()): PerspectiveCamera {
  const axis = light.type === POINT ? new Vector3(...CUBE_AXES[view]) : light.direction.clone().normalize();
  const up = light.type === POINT ? new Vector3(...CUBE_UPS[view])
    : Math.abs(axis.y) > 0.9 ? new Vector3(1, 0, 0) : new Vector3(0, 1, 0);
  camera.fov = light.type === POINT ? 90 : MathUtils.radToDeg(2 * light.outerAngle);
  camera.aspect = 1;
  camera.near = light.radius * NEAR;
  camera.far = light.radius;
  camera.updateProjectionMatrix();
  camera.position.copy(light.position);
  camera.up.copy(up);
  camera.lookAt(axis.add(light.position));
  camera.updateMatrixWorld(true);
  return camera;
}

/** Where the views of a frame's shadow lights are in the atlas. */
export interface ShadowTiles {
  /** Per shadow light: the side of each of its tiles in texels; 0: no tile (unshadowed). */
  size: Int32Array;
  /** Per shadow light and view ([S, 6], row-major): the tile's lower left texel; -1: none. */
  x: Int32Array;
  y: Int32Array;
}

/** Morton index ``m`` -> the column (even bits) and row (odd bits) of its cell. */
function unMorton(m: number): [number, number] {
  let x = 0;
  let y = 0;
  for (let bit = 1; m > 0; bit *= 2, m = Math.floor(m / 4)) {
    x += (m % 2) * bit;
    y += (Math.floor(m / 2) % 2) * bit;
  }
  return [x, y];
}

/**
 * Tiles for the shadow lights in one ``atlasSize`` square: DESIGN's atlas rule (section 2,
 * "Atlas") with this atlas's size and ``minTile`` in place of 256. Each light's tile is its
 * tier (clamped to minTile..atlasSize); the lights after the longest prefix of
 * shadow_lights that fits at minTile get none (their slots are drawn unshadowed); then,
 * while the views' area exceeds the atlas, the last light whose tile is above minTile
 * halves. So the scheduler's ranking decides who keeps resolution. Tiles are placed
 * largest first along a Z-order curve: power-of-two squares in descending size then sit on
 * aligned cells, never overlap, and fill the atlas without gaps, so every layout whose area
 * fits is placed.
 */
export function layoutShadowTiles(tiers: ArrayLike<number>, views: ArrayLike<number>,
                                  atlasSize: number, minTile: number): ShadowTiles {
  const lights = tiers.length;
  const size = new Int32Array(lights);
  const budget = atlasSize * atlasSize;
  let used = 0;
  for (let j = 0; j < lights; j++) {
    if (views[j] === 0) continue;
    if (used + views[j] * minTile * minTile > budget) break;
    used += views[j] * minTile * minTile;
    const tier = 2 ** Math.floor(Math.log2(Math.max(1, tiers[j])));
    size[j] = Math.min(atlasSize, Math.max(minTile, tier));
  }
  let area = 0;
  for (let j = 0; j < lights; j++) area += views[j] * size[j] * size[j];
  while (area > budget) {
    let j = lights - 1;
    while (size[j] <= minTile) j--;
    area -= views[j] * size[j] * size[j] * 3 / 4;
    size[j] /= 2;
  }
  const x = new Int32Array(6 * lights).fill(-1);
  const y = new Int32Array(6 * lights).fill(-1);
  const order: number[] = [];
  for (let j = 0; j < lights; j++) {
    if (size[j] > 0) for (let v = 0; v < views[j]; v++) order.push(6 * j + v);
  }
  order.sort((a, b) => size[Math.floor(b / 6)] - size[Math.floor(a / 6)] || a - b);
  let offset = 0;
  for (const view of order) {
    const side = size[Math.floor(view / 6)];
    const [cx, cy] = unMorton(offset / (side * side));
    x[view] = cx * side;
    y[view] = cy * side;
    offset += side * side;
  }
  return { size, x, y };
}

// Distance to the light over its radius in [0, 1), in the four bytes of an RGBA8 texel (the
// classic base-255 split: each byte keeps what the previous one could not).
const DISTANCE_PACKING = `
vec4 packDistance(float v) {
  if (v >= 1.0) return vec4(1.0);
  vec4 bytes = fract(max(v, 0.0) * vec4(1.0, 255.0, 65025.0, 16581375.0));
  return bytes - bytes.yzww * vec4(1.0 / 255.0, 1.0 / 255.0, 1.0 / 255.0, 0.0);
}
float unpackDistance(vec4 rgba) {
  return dot(rgba, vec4(1.0, 1.0 / 255.0, 1.0 / 65025.0, 1.0 / 16581375.0));
}
`;

const CASTER_VERTEX = `
varying vec3 vWorldPosition;
void main() {
  vec4 world = vec4(position, 1.0);
#ifdef USE_INSTANCING
  world = instanceMatrix * world;
#endif
  world = modelMatrix * world;
  vWorldPosition = world.xyz;
  gl_Position = projectionMatrix * viewMatrix * world;
}
`;

const CASTER_FRAGMENT = `
uniform vec3 lightPosition;
uniform float inverseRadius;
varying vec3 vWorldPosition;
${DISTANCE_PACKING}
void main() {
  gl_FragColor = packDistance(length(vWorldPosition - lightPosition) * inverseRadius);
}
`;

// The lit material's side: shadowVisibility(j, x) is the share of shadow light j's light
// that reaches world point x (1 lit, 0 behind a caster), from its view's tile.
const SHADOW_SAMPLING = `
in vec3 vScheduledWorld;
uniform highp sampler2D shadowTable;
uniform highp sampler2D shadowAtlas;
${DISTANCE_PACKING}
vec4 shadowTexel(int j, int texel) {
  return texelFetch(shadowTable, ivec2(texel, j), 0);
}
float shadowTap(ivec2 corner, int last, ivec2 at, float reach) {
  vec4 stored = texelFetch(shadowAtlas, corner + clamp(at, ivec2(0), ivec2(last)), 0);
  return unpackDistance(stored) < reach ? 0.0 : 1.0;
}
float shadowVisibility(int j, vec3 x) {
  vec4 light = shadowTexel(j, 0);
  if (light.w == 0.0) return 1.0;  // no tile this frame
  vec4 kind = shadowTexel(j, 1);
  vec3 v = x - light.xyz;
  int view = 0;
  if (kind.x > 1.0) {
    vec3 a = abs(v);
    view = a.x >= a.y && a.x >= a.z ? (v.x < 0.0 ? 1 : 0) : a.y >= a.z ? (v.y < 0.0 ? 3 : 2) : (v.z < 0.0 ? 5 : 4);
  }
  int t = ${SHADOW_HEAD} + ${SHADOW_VIEW} * view;
  mat4 viewProjection = mat4(shadowTexel(j, t), shadowTexel(j, t + 1), shadowTexel(j, t + 2), shadowTexel(j, t + 3));
  vec4 tile = shadowTexel(j, t + 4);
  vec4 clip = viewProjection * vec4(x, 1.0);
  if (clip.w <= 0.0) return 1.0;
  vec2 uv = clip.xy / clip.w * 0.5 + 0.5;
  // Outside a spot's square: outside its cone too, where the spot factor is 0.
  if (any(lessThan(uv, vec2(0.0))) || any(greaterThan(uv, vec2(1.0)))) return 1.0;
  // The receiver's distance over the radius, less the bias: what a caster must be nearer than.
  float reach = length(v) * light.w * (1.0 - kind.y);
  // 2x2 percentage-closer filtering: the four nearest texels' tests, bilinearly weighted.
  vec2 st = uv * tile.z - 0.5;
  vec2 cell = floor(st);
  vec2 f = st - cell;
  ivec2 corner = ivec2(tile.xy);
  int last = int(tile.z) - 1;
  ivec2 c = ivec2(cell);
  float t00 = shadowTap(corner, last, c, reach);
  float t10 = shadowTap(corner, last, c + ivec2(1, 0), reach);
  float t01 = shadowTap(corner, last, c + ivec2(0, 1), reach);
  float t11 = shadowTap(corner, last, c + ivec2(1, 1), reach);
  return mix(mix(t00, t10, f.x), mix(t01, t11, f.x), f.y);
}
`;

export interface ShadowAtlasOptions {
  /** Side of the square atlas in texels, a power of two (default 2048). */
  size?: number;
  /** The smallest tile (default 64): shadow lights that do not fit at it go unshadowed. */
  minTile?: number;
}

/**
 * The shadow maps of a frame's shadow_lights, one RGBA8 atlas of tiles (see the module
 * comment), and the shadow table the patched materials read them by. Pass it to
 * scheduleMaterial as ``shadows``; call render once a frame, after
 * ScheduledInstances.applyFrame and before drawing the scene.
 */
export class ShadowAtlas {
  readonly size: number;
  readonly minTile: number;
  readonly target: WebGLRenderTarget;
  readonly uniforms: { shadowAtlas: { value: Texture }; shadowTable: { value: DataTexture } };
  /** The last frame's tiles. */
  tiles: ShadowTiles = { size: new Int32Array(0), x: new Int32Array(0), y: new Int32Array(0) };
  /** The last frame's shadow lights' shapes (undefined where the table has no such light). */
  shapes: (LightShape | undefined)[] = [];
  private tableData = new Float32Array(0);
  private readonly cameras: PerspectiveCamera[] = [];
  private readonly casterScene = new Scene();
  private readonly casterMaterial: ShaderMaterial;
  private casters?: InstancedMesh;

  constructor(options: ShadowAtlasOptions = {}) {
    this.size = options.size ?? 2048;
    this.minTile = options.minTile ?? 64;
    if (!Number.isInteger(Math.log2(this.size)) || !Number.isInteger(Math.log2(this.minTile)) || this.minTile > this.size) {
      throw new RangeError(`size and minTile must be powers of two, minTile <= size: not ${this.size}, ${this.minTile}`);
    }
    // RGBA8: renderable on every WebGL2 device (float colour targets need an extension).
    this.target = new WebGLRenderTarget(this.size, this.size, {
      type: UnsignedByteType, format: RGBAFormat, minFilter: NearestFilter, magFilter: NearestFilter,
      generateMipmaps: false, depthBuffer: true,
    });
    this.uniforms = { shadowAtlas: { value: this.target.texture }, shadowTable: { value: this.allocateTable(1) } };
    // Back faces, as three.js draws its own shadow maps: a closed caster's lit side never
    // meets its own depth, so the comparison needs only a small bias.
    this.casterMaterial = new ShaderMaterial({
      vertexShader: CASTER_VERTEX, fragmentShader: CASTER_FRAGMENT, side: BackSide,
      uniforms: { lightPosition: { value: new Vector3() }, inverseRadius: { value: 1 } },
    });
  }

  private allocateTable(rows: number): DataTexture {
    this.tableData = new Float32Array(SHADOW_TEXELS * rows * 4);
    const texture = new DataTexture(this.tableData, SHADOW_TEXELS, rows, RGBAFormat, FloatType);
    texture.needsUpdate = true;
    return texture;
  }

  /** The shadow table's texels of shadow light ``j`` (4 floats each), as the shader reads them. */
  tableRow(j: number): Float32Array {
    return this.tableData.subarray(j * SHADOW_TEXELS * 4, (j + 1) * SHADOW_TEXELS * 4);
  }

  /**
   * Lays out the frame's tiles and fills the shadow table (no drawing): row j is
   * shadow_lights[j], so slot_shadow indexes it as it is.
   */
  update(frame: Frame, lights: LightTable): void {
    const ids = frame.shadow_lights?.data ?? new Int32Array(0);
    const tiers = frame.shadow_tier?.data ?? new Uint16Array(ids.length);
    const count = ids.length;
    this.shapes = Array.from(ids, (id) => {
      const row = lights.row(id);
      return row < 0 ? undefined : lights.shape(row);
    });
    const views = this.shapes.map((shape) => shape ? shadowViewCount(shape.type) : 0);
    this.tiles = layoutShadowTiles(tiers, views, this.size, this.minTile);
    const table = this.uniforms.shadowTable;
    if (table.value.image.height < count) {
      table.value.dispose();
      table.value = this.allocateTable(2 ** Math.ceil(Math.log2(count)));
    }
    this.tableData.fill(0);
    const viewProjection = new Matrix4();
    for (let j = 0; j < count; j++) {
      const shape = this.shapes[j];
      const tile = this.tiles.size[j];
      if (!shape || tile === 0) continue;
      const row = this.tableRow(j);
      shape.position.toArray(row, 0);
      row[3] = 1 / shape.radius;
      const tanHalf = shape.type === POINT ? 1 : Math.tan(shape.outerAngle);
      row[4] = views[j];
      row[5] = BIAS_TEXELS * 2 * tanHalf / tile;
      for (let v = 0; v < views[j]; v++) {
        const camera = shadowCamera(shape, v, this.cameras[6 * j + v] ??= new PerspectiveCamera());
        viewProjection.multiplyMatrices(camera.projectionMatrix, camera.matrixWorldInverse);
        const t = 4 * (SHADOW_HEAD + SHADOW_VIEW * v);
        row.set(viewProjection.elements, t);
        row[t + 16] = this.tiles.x[6 * j + v];
        row[t + 17] = this.tiles.y[6 * j + v];
        row[t + 18] = tile;
      }
    }
    table.value.needsUpdate = true;
  }

  /**
   * update, then draws every view's casters (caster_ids whose caster_masks has the view's
   * bit) into its tile: the distance to the light over its radius, nearest kept.
   */
  render(renderer: WebGLRenderer, frame: Frame, lights: LightTable, objects: ScheduledInstances): void {
    this.update(frame, lights);
    const casters = this.castersFor(objects);
    const offsets = frame.caster_offsets?.data ?? new BigInt64Array(1);
    const ids = frame.caster_ids?.data ?? new Int32Array(0);
    const masks = frame.caster_masks?.data ?? new Uint32Array(0);
    const matrices = objects.mesh.instanceMatrix.array;
    const drawn = casters.instanceMatrix.array as Float32Array;
    const previous = {
      target: renderer.getRenderTarget(), autoClear: renderer.autoClear,
      color: renderer.getClearColor(new Color()), alpha: renderer.getClearAlpha(),
    };
    renderer.autoClear = false;
    // Cleared to 1 (packDistance's "at the radius or beyond"): nothing in the way.
    renderer.setClearColor(0xffffff, 1);
    this.target.scissorTest = true;
    casters.matrix.copy(objects.mesh.matrixWorld);
    casters.matrixWorld.copy(objects.mesh.matrixWorld);
    const uniforms = this.casterMaterial.uniforms;
    for (let j = 0; j < this.shapes.length; j++) {
      const shape = this.shapes[j];
      const tile = this.tiles.size[j];
      if (!shape || tile === 0) continue;
      uniforms.lightPosition.value.copy(shape.position);
      uniforms.inverseRadius.value = 1 / shape.radius;
      const first = Number(offsets[j]);
      const end = Number(offsets[j + 1]);
      for (let v = 0; v < shadowViewCount(shape.type); v++) {
        let count = 0;
        for (let m = first; m < end; m++) {
          if (((masks[m] >>> v) & 1) === 0) continue;
          const row = objects.instanceOf(ids[m]);
          if (row < 0) continue;
          for (let e = 0; e < 16; e++) drawn[16 * count + e] = matrices[16 * row + e];
          count++;
        }
        const x = this.tiles.x[6 * j + v];
        const y = this.tiles.y[6 * j + v];
        this.target.viewport.set(x, y, tile, tile);
        this.target.scissor.set(x, y, tile, tile);
        renderer.setRenderTarget(this.target);
        renderer.clear(true, true, false);
        if (count === 0) continue;
        casters.count = count;
        casters.instanceMatrix.clearUpdateRanges();
        casters.instanceMatrix.addUpdateRange(0, 16 * count);
        casters.instanceMatrix.needsUpdate = true;
        renderer.render(this.casterScene, this.cameras[6 * j + v]);
      }
    }
    renderer.setRenderTarget(previous.target);
    renderer.setClearColor(previous.color, previous.alpha);
    renderer.autoClear = previous.autoClear;
  }

  /** One instanced mesh of the objects' geometry, its instances refilled for each view. */
  private castersFor(objects: ScheduledInstances): InstancedMesh {
    const geometry = objects.mesh.geometry;
    const n = objects.ids.length;
    if (!this.casters || this.casters.geometry !== geometry || this.casters.instanceMatrix.count < n) {
      if (this.casters) {
        this.casterScene.remove(this.casters);
        this.casters.dispose();
      }
      this.casters = new InstancedMesh(geometry, this.casterMaterial, Math.max(1, n));
      this.casters.frustumCulled = false;
      this.casters.matrixAutoUpdate = false;
      this.casters.matrixWorldAutoUpdate = false;
      this.casterScene.add(this.casters);
    }
    return this.casters;
  }

  dispose(): void {
    this.target.dispose();
    this.uniforms.shadowTable.value.dispose();
    this.casterMaterial.dispose();
    this.casters?.dispose();
  }
}
