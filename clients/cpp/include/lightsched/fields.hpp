// Generated from lightsched/fields.py by python -m lightsched_server.schemas; do not edit.
// DESIGN section 3's frame arrays, in its order (schemas/frame_fields.json).
#pragma once

#include <array>

namespace lightsched {

struct FrameField {
  const char* name;
  const char* dtype;
  int ndim;
  bool per_object;  // sent by rows with changed_only
  int empty;  // a per-object row's value when the object has nothing
};

inline constexpr std::array<FrameField, 25> FRAME_FIELDS{{
    {"object_id", "int32", 1, false, 0},
    {"visible", "bool", 1, true, 0},
    {"count", "int32", 1, true, 0},
    {"candidates", "int32", 1, true, 0},
    {"light_ids", "int32", 2, true, -1},
    {"light_index", "int32", 2, true, -1},
    {"priority", "float32", 2, true, 0},
    {"fade_weight", "float32", 2, true, 0},
    {"fade_state", "uint8", 2, true, 0},
    {"slot_shadow", "int8", 2, true, -1},
    {"directional_lights", "int32", 1, false, 0},
    {"visible_lights", "int32", 1, false, 0},
    {"shadow_lights", "int32", 1, false, 0},
    {"shadow_tier", "uint16", 1, false, 0},
    {"cascade_splits", "float64", 2, false, 0},
    {"caster_offsets", "int64", 1, false, 0},
    {"caster_ids", "int32", 1, false, 0},
    {"caster_masks", "uint32", 1, false, 0},
    {"residual", "float32", 2, true, 0},
    {"shadow_views", "uint32", 1, false, 0},
    {"shadow_dirty", "uint32", 1, false, 0},
    {"shadow_static_dirty", "uint32", 1, false, 0},
    {"shadow_update", "uint32", 1, false, 0},
    {"shadow_rect", "int32", 3, false, 0},
    {"camera_ids", "int32", 1, false, 0},
}};

}  // namespace lightsched
