// Conversions between the wire's frame and Unity's or Unreal's (docs/protocol.md, "From Unity and
// Unreal"); the same arithmetic as client_sdk/python/camdirector_client/convert.py, so both give
// the same doubles (tests/client_sdk/cpp/test_convert.py checks it).
//
// Both engine frames map to ours by a reflection `ours = A engine` (det A = -1). A rotation by t
// about axis a becomes one by t about -A a: a quaternion's vector part maps by -A, its w stays.
// Unity:  A flips z.                      Unreal: ours = (y, z, -x), and cm -> m.
#include <cmath>

#include "camdirector/camdirector.h"

namespace {

constexpr double kUnrealCmPerM = 100.0;
constexpr double kPi = 3.14159265358979323846;
// Python's math.radians / math.degrees multiply by these exact constants.
constexpr double kDegToRad = kPi / 180.0;
constexpr double kRadToDeg = 180.0 / kPi;

bool is_zero(const cd_quat& q) { return q.x == 0.0 && q.y == 0.0 && q.z == 0.0 && q.w == 0.0; }

}  // namespace

extern "C" {

cd_vec3 cd_from_unity_position(cd_vec3 p) { return {p.x, p.y, -p.z}; }
cd_vec3 cd_to_unity_position(cd_vec3 p) { return {p.x, p.y, -p.z}; }
cd_quat cd_from_unity_rotation(cd_quat q) { return {-q.x, -q.y, q.z, q.w}; }
cd_quat cd_to_unity_rotation(cd_quat q) { return {-q.x, -q.y, q.z, q.w}; }
cd_vec3 cd_from_unity_scale(cd_vec3 s) { return s; }
cd_vec3 cd_to_unity_scale(cd_vec3 s) { return s; }

cd_vec3 cd_from_unreal_position(cd_vec3 p_cm) {
  return {p_cm.y / kUnrealCmPerM, p_cm.z / kUnrealCmPerM, -p_cm.x / kUnrealCmPerM};
}
cd_vec3 cd_to_unreal_position(cd_vec3 p_m) {
  return {-p_m.z * kUnrealCmPerM, p_m.x * kUnrealCmPerM, p_m.y * kUnrealCmPerM};
}
cd_quat cd_from_unreal_rotation(cd_quat q) { return {-q.y, -q.z, q.x, q.w}; }
cd_quat cd_to_unreal_rotation(cd_quat q) { return {q.z, -q.x, -q.y, q.w}; }
cd_vec3 cd_from_unreal_scale(cd_vec3 s) { return {s.y, s.z, s.x}; }
cd_vec3 cd_to_unreal_scale(cd_vec3 s) { return {s.z, s.x, s.y}; }

cd_transform cd_from_unity_transform(cd_transform t) {
  // The zero quaternion and zero scale stand for "unset" (identity, ones) and stay so.
  cd_transform out = t;
  out.position = cd_from_unity_position(t.position);
  if (!is_zero(t.rotation)) out.rotation = cd_from_unity_rotation(t.rotation);
  out.scale = cd_from_unity_scale(t.scale);
  return out;
}

cd_transform cd_from_unreal_transform(cd_transform t) {
  cd_transform out = t;
  out.position = cd_from_unreal_position(t.position);
  if (!is_zero(t.rotation)) out.rotation = cd_from_unreal_rotation(t.rotation);
  out.scale = cd_from_unreal_scale(t.scale);
  return out;
}

void cd_camera_pose_to_unity(const cd_pose* pose, cd_vec3* position, cd_quat* rotation) {
  // Flipping z sends our camera's forward (-Z) to Unity's (+Z): no extra rotation.
  if (position) *position = cd_to_unity_position(pose->position);
  if (rotation) *rotation = cd_to_unity_rotation(pose->rotation);
}

void cd_camera_pose_to_unreal(const cd_pose* pose, cd_vec3* position_cm, cd_quat* rotation) {
  // Our camera's forward, right, up (-Z, +X, +Y) are Unreal's +X, +Y, +Z under this map.
  if (position_cm) *position_cm = cd_to_unreal_position(pose->position);
  if (rotation) *rotation = cd_to_unreal_rotation(pose->rotation);
}

double cd_horizontal_fov_deg(double vertical_fov_deg, double aspect) {
  const double half = vertical_fov_deg * kDegToRad / 2.0;
  return 2.0 * std::atan(std::tan(half) * aspect) * kRadToDeg;
}

double cd_vertical_fov_deg(double horizontal_fov_deg, double aspect) {
  const double half = horizontal_fov_deg * kDegToRad / 2.0;
  return 2.0 * std::atan(std::tan(half) / aspect) * kRadToDeg;
}

void cd_from_unity_vertices(float* xyz, uint32_t vertex_count) {
  for (uint32_t i = 0; i < vertex_count; ++i) xyz[3 * i + 2] = -xyz[3 * i + 2];
}

void cd_from_unreal_vertices(float* xyz_cm, uint32_t vertex_count) {
  for (uint32_t i = 0; i < vertex_count; ++i) {
    float* v = xyz_cm + 3 * i;
    // In double, then rounded once: the Python SDK's float64 conversion cast to float32.
    const double x = v[0], y = v[1], z = v[2];
    v[0] = static_cast<float>(y / kUnrealCmPerM);
    v[1] = static_cast<float>(z / kUnrealCmPerM);
    v[2] = static_cast<float>(-x / kUnrealCmPerM);
  }
}

void cd_flip_winding(uint32_t* indices, uint32_t index_count) {
  for (uint32_t i = 0; i + 2 < index_count; i += 3) {
    const uint32_t b = indices[i + 1];
    indices[i + 1] = indices[i + 2];
    indices[i + 2] = b;
  }
}

}  // extern "C"
