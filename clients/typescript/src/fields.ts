// Generated from lightsched/fields.py by python -m lightsched_server.schemas; do not edit.
// DESIGN section 3's frame arrays, in its order (schemas/frame_fields.json).

import type { DType, NdArray } from "./wire.js";

export interface FrameField {
  name: FieldName;
  dtype: DType;
  shape: string[];
  per_object: boolean;
  empty: number | boolean | null;
  description: string;
}

export const FRAME_FIELDS: readonly FrameField[] = [
  {"name": "object_id", "dtype": "int32", "shape": ["N"], "per_object": false, "empty": null, "description": "object ids, ascending: the rows of the per-object arrays"},
  {"name": "visible", "dtype": "bool", "shape": ["N"], "per_object": true, "empty": false, "description": "the object is in view of a camera"},
  {"name": "count", "dtype": "int32", "shape": ["N"], "per_object": true, "empty": 0, "description": "slots in use"},
  {"name": "candidates", "dtype": "int32", "shape": ["N"], "per_object": true, "empty": 0, "description": "lights competing for its slots (before the cut to K)"},
  {"name": "light_ids", "dtype": "int32", "shape": ["N", "K"], "per_object": true, "empty": -1, "description": "light id per slot"},
  {"name": "light_index", "dtype": "int32", "shape": ["N", "K"], "per_object": true, "empty": -1, "description": "row of the slot's light among the lights in ascending id"},
  {"name": "priority", "dtype": "float32", "shape": ["N", "K"], "per_object": true, "empty": 0.0, "description": "P of the slot's light"},
  {"name": "fade_weight", "dtype": "float32", "shape": ["N", "K"], "per_object": true, "empty": 0.0, "description": "fade weight in [0, 1]"},
  {"name": "fade_state", "dtype": "uint8", "shape": ["N", "K"], "per_object": true, "empty": 0, "description": "0 off, 1 fading in, 2 on, 3 fading out"},
  {"name": "slot_shadow", "dtype": "int8", "shape": ["N", "K"], "per_object": true, "empty": -1, "description": "index into shadow_lights of the slot's shadow map, -1 none"},
  {"name": "directional_lights", "dtype": "int32", "shape": ["D"], "per_object": false, "empty": null, "description": "directional lights applied outside the slots"},
  {"name": "visible_lights", "dtype": "int32", "shape": ["V"], "per_object": false, "empty": null, "description": "lights in view, ascending id"},
  {"name": "shadow_lights", "dtype": "int32", "shape": ["S"], "per_object": false, "empty": null, "description": "shadowed lights, in rank order"},
  {"name": "shadow_tier", "dtype": "uint16", "shape": ["S"], "per_object": false, "empty": null, "description": "map size in texels of each"},
  {"name": "cascade_splits", "dtype": "float64", "shape": ["cameras", "C+1"], "per_object": false, "empty": null, "description": "cascade split distances per camera"},
  {"name": "caster_offsets", "dtype": "int64", "shape": ["S+1"], "per_object": false, "empty": null, "description": "caster_ids[caster_offsets[s]:caster_offsets[s + 1]] are shadow light s's"},
  {"name": "caster_ids", "dtype": "int32", "shape": ["M"], "per_object": false, "empty": null, "description": "shadow caster object ids, ascending per light"},
  {"name": "caster_masks", "dtype": "uint32", "shape": ["M"], "per_object": false, "empty": null, "description": "per caster: the views it is drawn into (point: cube faces; spot: bit 0; directional: bit camera * C + cascade)"},
  {"name": "residual", "dtype": "float32", "shape": ["N", "4"], "per_object": true, "empty": 0.0, "description": "L1 SH irradiance (a, b_x, b_y, b_z) of the competing lights not wholly in the slots; the shader adds max(0, a/4 + (b . n)/2)"},
  {"name": "shadow_views", "dtype": "uint32", "shape": ["S"], "per_object": false, "empty": null, "description": "per shadow light its views, as caster_masks' bits (point: the six faces; spot: bit 0; directional: bit camera * C + cascade)"},
  {"name": "shadow_dirty", "dtype": "uint32", "shape": ["S"], "per_object": false, "empty": null, "description": "the views whose casters, light, camera, tier or tile changed since they were last rendered (or never were)"},
  {"name": "shadow_static_dirty", "dtype": "uint32", "shape": ["S"], "per_object": false, "empty": null, "description": "the dirty views whose cached static-caster layer must be redrawn too"},
  {"name": "shadow_update", "dtype": "uint32", "shape": ["S"], "per_object": false, "empty": null, "description": "the dirty views to render this frame (shadow_update_budget)"},
  {"name": "shadow_rect", "dtype": "int32", "shape": ["S", "6", "3"], "per_object": false, "empty": null, "description": "per shadow light and view bit its atlas tile (x, y, size); -1 where there is none (directional lights, unused rows, no atlas)"},
  {"name": "camera_ids", "dtype": "int32", "shape": ["cameras"], "per_object": false, "empty": null, "description": "the cameras' ids in list order (directional view bits and cascade_splits rows follow it)"},
];

export type FieldName =
  | "object_id"
  | "visible"
  | "count"
  | "candidates"
  | "light_ids"
  | "light_index"
  | "priority"
  | "fade_weight"
  | "fade_state"
  | "slot_shadow"
  | "directional_lights"
  | "visible_lights"
  | "shadow_lights"
  | "shadow_tier"
  | "cascade_splits"
  | "caster_offsets"
  | "caster_ids"
  | "caster_masks"
  | "residual"
  | "shadow_views"
  | "shadow_dirty"
  | "shadow_static_dirty"
  | "shadow_update"
  | "shadow_rect"
  | "camera_ids";

/** The arrays of a frame; those not asked for (outputs) are absent. */
export interface FrameArrays {
  /** object ids, ascending: the rows of the per-object arrays (int32 [N]) */
  object_id?: NdArray<Int32Array>;
  /** the object is in view of a camera (bool [N]) */
  visible?: NdArray<Uint8Array>;
  /** slots in use (int32 [N]) */
  count?: NdArray<Int32Array>;
  /** lights competing for its slots (before the cut to K) (int32 [N]) */
  candidates?: NdArray<Int32Array>;
  /** light id per slot (int32 [N, K]) */
  light_ids?: NdArray<Int32Array>;
  /** row of the slot's light among the lights in ascending id (int32 [N, K]) */
  light_index?: NdArray<Int32Array>;
  /** P of the slot's light (float32 [N, K]) */
  priority?: NdArray<Float32Array>;
  /** fade weight in [0, 1] (float32 [N, K]) */
  fade_weight?: NdArray<Float32Array>;
  /** 0 off, 1 fading in, 2 on, 3 fading out (uint8 [N, K]) */
  fade_state?: NdArray<Uint8Array>;
  /** index into shadow_lights of the slot's shadow map, -1 none (int8 [N, K]) */
  slot_shadow?: NdArray<Int8Array>;
  /** directional lights applied outside the slots (int32 [D]) */
  directional_lights?: NdArray<Int32Array>;
  /** lights in view, ascending id (int32 [V]) */
  visible_lights?: NdArray<Int32Array>;
  /** shadowed lights, in rank order (int32 [S]) */
  shadow_lights?: NdArray<Int32Array>;
  /** map size in texels of each (uint16 [S]) */
  shadow_tier?: NdArray<Uint16Array>;
  /** cascade split distances per camera (float64 [cameras, C+1]) */
  cascade_splits?: NdArray<Float64Array>;
  /** caster_ids[caster_offsets[s]:caster_offsets[s + 1]] are shadow light s's (int64 [S+1]) */
  caster_offsets?: NdArray<BigInt64Array>;
  /** shadow caster object ids, ascending per light (int32 [M]) */
  caster_ids?: NdArray<Int32Array>;
  /** per caster: the views it is drawn into (point: cube faces; spot: bit 0; directional: bit camera * C + cascade) (uint32 [M]) */
  caster_masks?: NdArray<Uint32Array>;
  /** L1 SH irradiance (a, b_x, b_y, b_z) of the competing lights not wholly in the slots; the shader adds max(0, a/4 + (b . n)/2) (float32 [N, 4]) */
  residual?: NdArray<Float32Array>;
  /** per shadow light its views, as caster_masks' bits (point: the six faces; spot: bit 0; directional: bit camera * C + cascade) (uint32 [S]) */
  shadow_views?: NdArray<Uint32Array>;
  /** the views whose casters, light, camera, tier or tile changed since they were last rendered (or never were) (uint32 [S]) */
  shadow_dirty?: NdArray<Uint32Array>;
  /** the dirty views whose cached static-caster layer must be redrawn too (uint32 [S]) */
  shadow_static_dirty?: NdArray<Uint32Array>;
  /** the dirty views to render this frame (shadow_update_budget) (uint32 [S]) */
  shadow_update?: NdArray<Uint32Array>;
  /** per shadow light and view bit its atlas tile (x, y, size); -1 where there is none (directional lights, unused rows, no atlas) (int32 [S, 6, 3]) */
  shadow_rect?: NdArray<Int32Array>;
  /** the cameras' ids in list order (directional view bits and cascade_splits rows follow it) (int32 [cameras]) */
  camera_ids?: NdArray<Int32Array>;
}

// Scheduler.explain (DESIGN section 7): its reasons, in their order, and its columns.
export const REASONS = ["removed", "object_not_visible", "light_not_visible", "masked", "unshadowed_skip", "out_of_range", "outside_cone", "directional", "selected", "waiting", "fading_out", "below_k"] as const;

export type Reason = (typeof REASONS)[number];

export const EXPLAIN_FIELDS = ["light_id", "priority", "selection_priority", "d2", "slot", "fade_weight", "fade_state", "reason"] as const;

/** One row per light that was visible, held a slot of the object or held one when the last frame
 * began, in ascending light id; NaN or -1 where a value does not exist. */
export interface Explanation {
  object_id: number;
  /** the frame explained */
  frame_index: number;
  /** the light */
  light_id: NdArray<Int32Array>;
  /** P of the pair when the light affects the object (directional lights: i + p_user) */
  priority: NdArray<Float64Array>;
  /** P with the hysteresis bonus when the light was selected last frame: the key selection compared */
  selection_priority: NdArray<Float64Array>;
  /** squared distance from the light to the object's box (point and spot lights) */
  d2: NdArray<Float64Array>;
  /** the light's slot in the object's row this frame */
  slot: NdArray<Int32Array>;
  /** that slot's fade weight */
  fade_weight: NdArray<Float64Array>;
  /** that slot's state: 1 fading in, 2 on, 3 fading out */
  fade_state: NdArray<Int32Array>;
  /** the first reason that applies, one of removed, object_not_visible, light_not_visible, masked, unshadowed_skip, out_of_range, outside_cone, directional, selected, waiting, fading_out, below_k */
  reason: Reason[];
}
