// Prints the SDK's coordinate conversions of given numbers as one JSON object, for
// tests/client_sdk/cpp/test_convert.py to compare with the Python SDK's converters.
//
// stdin: lines of 12 numbers, "px py pz qx qy qz qw sx sy sz vertical_fov_deg aspect".
// stdout: {"from_unity": [...], "to_unity": [...], "from_unreal": [...], "to_unreal": [...],
//          "camera_unity": [...], "camera_unreal": [...], "horizontal_fov_deg": [...],
//          "vertical_fov_deg": [...], "unity_vertices": [...], "unreal_vertices": [...]}
// where each transform entry is {"position": [3], "rotation": [4], "scale": [3]}.
#include <cstdio>
#include <string>
#include <vector>

#include "camdirector/camdirector.h"

namespace {

struct Row {
  cd_transform t;
  double fov_deg, aspect;
};

std::string num(double v) {
  char buf[40];
  std::snprintf(buf, sizeof buf, "%.17g", v);
  return buf;
}

std::string vec(const cd_vec3& v) { return "[" + num(v.x) + ", " + num(v.y) + ", " + num(v.z) + "]"; }
std::string quat(const cd_quat& q) {
  return "[" + num(q.x) + ", " + num(q.y) + ", " + num(q.z) + ", " + num(q.w) + "]";
}

std::string transform(const cd_vec3& p, const cd_quat& q, const cd_vec3& s) {
  return "{\"position\": " + vec(p) + ", \"rotation\": " + quat(q) + ", \"scale\": " + vec(s) + "}";
}

template <typename F>
std::string list(const std::vector<Row>& rows, F f) {
  std::string out = "[";
  for (size_t i = 0; i < rows.size(); ++i) out += (i ? ", " : "") + f(rows[i]);
  return out + "]";
}

}  // namespace

int main() {
  std::vector<Row> rows;
  Row r{};
  while (std::scanf("%lf %lf %lf %lf %lf %lf %lf %lf %lf %lf %lf %lf", &r.t.position.x, &r.t.position.y,
                    &r.t.position.z, &r.t.rotation.x, &r.t.rotation.y, &r.t.rotation.z, &r.t.rotation.w,
                    &r.t.scale.x, &r.t.scale.y, &r.t.scale.z, &r.fov_deg, &r.aspect) == 12) {
    rows.push_back(r);
  }
  std::string out = "{";
  out += "\"from_unity\": " + list(rows, [](const Row& x) {
    return transform(cd_from_unity_position(x.t.position), cd_from_unity_rotation(x.t.rotation),
                     cd_from_unity_scale(x.t.scale));
  });
  out += ", \"to_unity\": " + list(rows, [](const Row& x) {
    return transform(cd_to_unity_position(x.t.position), cd_to_unity_rotation(x.t.rotation),
                     cd_to_unity_scale(x.t.scale));
  });
  out += ", \"from_unreal\": " + list(rows, [](const Row& x) {
    return transform(cd_from_unreal_position(x.t.position), cd_from_unreal_rotation(x.t.rotation),
                     cd_from_unreal_scale(x.t.scale));
  });
  out += ", \"to_unreal\": " + list(rows, [](const Row& x) {
    return transform(cd_to_unreal_position(x.t.position), cd_to_unreal_rotation(x.t.rotation),
                     cd_to_unreal_scale(x.t.scale));
  });
  out += ", \"from_unity_transform\": " + list(rows, [](const Row& x) {
    const cd_transform t = cd_from_unity_transform(x.t);
    return transform(t.position, t.rotation, t.scale);
  });
  out += ", \"from_unreal_transform\": " + list(rows, [](const Row& x) {
    const cd_transform t = cd_from_unreal_transform(x.t);
    return transform(t.position, t.rotation, t.scale);
  });
  auto camera = [](const Row& x, bool unreal) {
    cd_pose pose{};
    pose.position = x.t.position;
    pose.rotation = x.t.rotation;
    pose.vertical_fov_deg = x.fov_deg;
    cd_vec3 p;
    cd_quat q;
    if (unreal) {
      cd_camera_pose_to_unreal(&pose, &p, &q);
    } else {
      cd_camera_pose_to_unity(&pose, &p, &q);
    }
    return "{\"position\": " + vec(p) + ", \"rotation\": " + quat(q) + "}";
  };
  out += ", \"camera_unity\": " + list(rows, [&](const Row& x) { return camera(x, false); });
  out += ", \"camera_unreal\": " + list(rows, [&](const Row& x) { return camera(x, true); });
  out += ", \"horizontal_fov_deg\": " + list(rows, [](const Row& x) { return num(cd_horizontal_fov_deg(x.fov_deg, x.aspect)); });
  out += ", \"vertical_fov_deg\": " + list(rows, [](const Row& x) {
    return num(cd_vertical_fov_deg(cd_horizontal_fov_deg(x.fov_deg, x.aspect), x.aspect));
  });
  // Vertices: the rows' positions as float triples, converted in place.
  auto vertices = [&](bool unreal) {
    std::vector<float> xyz;
    for (const Row& x : rows) {
      xyz.push_back(static_cast<float>(x.t.position.x));
      xyz.push_back(static_cast<float>(x.t.position.y));
      xyz.push_back(static_cast<float>(x.t.position.z));
    }
    if (unreal) {
      cd_from_unreal_vertices(xyz.data(), static_cast<uint32_t>(rows.size()));
    } else {
      cd_from_unity_vertices(xyz.data(), static_cast<uint32_t>(rows.size()));
    }
    std::string s = "[";
    for (size_t i = 0; i < xyz.size(); ++i) s += (i ? ", " : "") + num(xyz[i]);
    return s + "]";
  };
  out += ", \"unity_vertices\": " + vertices(false);
  out += ", \"unreal_vertices\": " + vertices(true);
  std::vector<uint32_t> tri = {0, 1, 2, 3, 4, 5};
  cd_flip_winding(tri.data(), static_cast<uint32_t>(tri.size()));
  out += ", \"flipped\": [";
  for (size_t i = 0; i < tri.size(); ++i) out += (i ? ", " : "") + std::to_string(tri[i]);
  out += "]}";
  std::puts(out.c_str());
  return 0;
}
