// Plain C structs to the wire's CreateSessionRequest and Style, address parsing, a session's
// route key and the metadata of its calls, failure messages. Runs at setup only (cd_client_create,
// the blocking calls, the I/O thread's new streams): it may allocate.
#include <cctype>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <random>

#include "client_impl.h"

namespace camdirector::sdk {

namespace {

bool is_zero(const cd_quat& q) { return q.x == 0.0 && q.y == 0.0 && q.z == 0.0 && q.w == 0.0; }
bool is_zero(const cd_vec3& v) { return v.x == 0.0 && v.y == 0.0 && v.z == 0.0; }

void set_vec3(const cd_vec3& v, pb::Vec3* out) {
  out->set_x(v.x);
  out->set_y(v.y);
  out->set_z(v.z);
}

// Zero rotation and zero scale stand for unset (identity, ones), as camdirector.h says.
void set_transform(const cd_transform& t, pb::Transform* out) {
  set_vec3(t.position, out->mutable_position());
  if (!is_zero(t.rotation)) {
    pb::Quat* q = out->mutable_rotation();
    q->set_x(t.rotation.x);
    q->set_y(t.rotation.y);
    q->set_z(t.rotation.z);
    q->set_w(t.rotation.w);
  }
  if (!is_zero(t.scale)) set_vec3(t.scale, out->mutable_scale());
}

bool set_mesh(const cd_mesh& m, pb::Mesh* out, const std::string& what, std::string* error) {
  pb::Primitive* primitive = nullptr;
  switch (m.shape) {
    case CD_SHAPE_BOX:
      set_vec3(m.box_size, out->mutable_primitive()->mutable_box()->mutable_size());
      return true;
    case CD_SHAPE_SPHERE:
      out->mutable_primitive()->mutable_sphere()->set_radius(m.radius);
      return true;
    case CD_SHAPE_CYLINDER:
      primitive = out->mutable_primitive();
      primitive->mutable_cylinder()->set_radius(m.radius);
      primitive->mutable_cylinder()->set_height(m.height);
      return true;
    case CD_SHAPE_CAPSULE:
      primitive = out->mutable_primitive();
      primitive->mutable_capsule()->set_radius(m.radius);
      primitive->mutable_capsule()->set_height(m.height);
      return true;
    case CD_SHAPE_TRIANGLES: {
      if ((m.vertex_count > 0 && m.vertices == nullptr) || (m.index_count > 0 && m.indices == nullptr)) {
        *error = what + ".mesh: vertices or indices is NULL";
        return false;
      }
      if (m.index_count % 3 != 0) {
        *error = what + ".mesh.index_count must be a multiple of 3";
        return false;
      }
      pb::TriangleMesh* tri = out->mutable_triangles();
      tri->mutable_vertices()->Add(m.vertices, m.vertices + 3 * static_cast<size_t>(m.vertex_count));
      tri->mutable_indices()->Add(m.indices, m.indices + m.index_count);
      return true;
    }
    default:
      *error = what + ".mesh.shape must be a cd_shape (1 to 5), got " + std::to_string(m.shape);
      return false;
  }
}

}  // namespace

bool parse_address(const char* address, std::string* target, bool* tls, std::string* error) {
  if (address == nullptr || *address == '\0') {
    *error = "address is empty: expected HOST:PORT";
    return false;
  }
  std::string a(address);
  const std::string quoted = "'" + a + "'";
  for (char c : a) {
    if (std::isspace(static_cast<unsigned char>(c)) || !std::isprint(static_cast<unsigned char>(c))) {
      *error = "address " + quoted + " contains a space or control character";
      return false;
    }
  }
  *tls = false;
  if (a.rfind("unix:", 0) == 0) {
    if (a.size() == 5) {
      *error = "address " + quoted + " names no socket path";
      return false;
    }
    *target = a;
    return true;
  }
  const size_t scheme = a.find("://");
  if (scheme != std::string::npos) {
    *tls = a.compare(0, scheme, "grpcs") == 0;
    if (!*tls && a.compare(0, scheme, "grpc") != 0) {
      *error = "address " + quoted +
               ": only grpc:// (or no scheme) and grpcs:// (TLS) are supported; this SDK speaks gRPC, not ZeroMQ";
      return false;
    }
    a = a.substr(scheme + 3);
  }
  std::string host, port;
  const bool bracketed = !a.empty() && a[0] == '[';
  if (bracketed) {
    const size_t close = a.find(']');
    if (close == std::string::npos || close == 1 || close + 1 >= a.size() || a[close + 1] != ':') {
      *error = "address " + quoted + ": expected [IPv6]:PORT";
      return false;
    }
    host = a.substr(1, close - 1);
    port = a.substr(close + 2);
  } else {
    const size_t colon = a.rfind(':');
    if (colon == std::string::npos) {
      *error = "address " + quoted + " has no port: expected HOST:PORT";
      return false;
    }
    host = a.substr(0, colon);
    port = a.substr(colon + 1);
    if (host.find(':') != std::string::npos) {
      *error = "address " + quoted + ": write an IPv6 host in brackets, [::1]:PORT";
      return false;
    }
    for (char c : host) {
      if (!std::isalnum(static_cast<unsigned char>(c)) && c != '.' && c != '-' && c != '_') {
        *error = "address " + quoted + ": host has a character a host name cannot have";
        return false;
      }
    }
  }
  if (host.empty()) {
    *error = "address " + quoted + " has no host: expected HOST:PORT";
    return false;
  }
  if (port.empty() || port.size() > 5 ||
      port.find_first_not_of("0123456789") != std::string::npos || std::stoi(port) < 1 || std::stoi(port) > 65535) {
    *error = "address " + quoted + ": the port must be a number in [1, 65535]";
    return false;
  }
  *target = bracketed ? "[" + host + "]:" + port : host + ":" + port;
  return true;
}

void fill_style(const cd_style& s, pb::Style* out) {
  out->Clear();
  if (!std::isnan(s.screen_a_x) || !std::isnan(s.screen_a_y)) {
    out->mutable_screen_a()->set_x(std::isnan(s.screen_a_x) ? 0.0 : s.screen_a_x);
    out->mutable_screen_a()->set_y(std::isnan(s.screen_a_y) ? 0.0 : s.screen_a_y);
  }
  if (!std::isnan(s.screen_b_x) || !std::isnan(s.screen_b_y)) {
    out->mutable_screen_b()->set_x(std::isnan(s.screen_b_x) ? 0.0 : s.screen_b_x);
    out->mutable_screen_b()->set_y(std::isnan(s.screen_b_y) ? 0.0 : s.screen_b_y);
  }
  out->set_visibility(static_cast<pb::VisibilityMode>(s.visibility));
  if (!std::isnan(s.gaze_room_m)) out->set_gaze_room_m(s.gaze_room_m);
  if (!std::isnan(s.preferred_theta_ratio)) out->set_preferred_theta_ratio(s.preferred_theta_ratio);
  if (!std::isnan(s.preferred_phi_deg)) out->set_preferred_phi_deg(s.preferred_phi_deg);
  if (!std::isnan(s.response_time_s)) out->set_response_time_s(s.response_time_s);
  if (!std::isnan(s.max_speed_m_s)) out->set_max_speed_m_s(s.max_speed_m_s);
  if (!std::isnan(s.max_accel_m_s2)) out->set_max_accel_m_s2(s.max_accel_m_s2);
  out->set_mask(static_cast<pb::StyleMask>(s.mask));
  out->set_map_resolution(s.map_resolution);
  out->set_map_backend(static_cast<pb::MapBackend>(s.map_backend));
  out->set_rig(static_cast<pb::Rig>(s.rig));
  out->set_shot_size(static_cast<pb::ShotSize>(s.shot_size));
  out->set_movement(static_cast<pb::Movement>(s.movement));
  out->set_match_director(static_cast<pb::MatchDirector>(s.match_director));
  if (!std::isnan(s.min_shot_s)) out->set_min_shot_s(s.min_shot_s);
  if (!std::isnan(s.max_shot_s)) out->set_max_shot_s(s.max_shot_s);
}

bool build_request(const cd_session_desc& d, pb::CreateSessionRequest* out, std::string* error) {
  out->Clear();
  if ((d.object_count > 0 && d.objects == nullptr) || (d.target_count > 0 && d.targets == nullptr)) {
    *error = "objects or targets is NULL with a count above 0";
    return false;
  }
  for (uint32_t i = 0; i < d.object_count; ++i) {
    const cd_object& o = d.objects[i];
    const std::string what = "objects[" + std::to_string(i) + "]";
    if (o.id == nullptr) {
      *error = what + ".id is NULL";
      return false;
    }
    pb::SceneObject* msg = out->add_objects();
    msg->set_id(o.id);
    msg->set_dynamic(o.dynamic != 0);
    set_transform(o.transform, msg->mutable_transform());
    if (!set_mesh(o.mesh, msg->mutable_mesh(), what, error)) return false;
  }
  for (uint32_t i = 0; i < d.target_count; ++i) {
    const cd_target& t = d.targets[i];
    const std::string what = "targets[" + std::to_string(i) + "]";
    if (t.id == nullptr) {
      *error = what + ".id is NULL";
      return false;
    }
    pb::Target* msg = out->add_targets();
    msg->set_id(t.id);
    msg->set_team(t.team);
    if (t.display_name != nullptr) msg->set_display_name(t.display_name);
    if (t.team_name != nullptr) msg->set_team_name(t.team_name);
    set_transform(t.transform, msg->mutable_transform());
    set_vec3(t.aim_offset, msg->mutable_aim_offset());
    if (!set_mesh(t.mesh, msg->mutable_mesh(), what, error)) return false;
  }
  out->mutable_lens()->set_vertical_fov_deg(d.vertical_fov_deg);
  out->mutable_lens()->set_aspect(d.aspect);
  fill_style(d.style, out->mutable_style());
  out->set_seed(d.seed);
  out->set_record(d.record != 0);
  if (d.level_id != nullptr) out->set_level_id(d.level_id);
  out->set_delay_s(d.delay_s);
  if (d.pose_output_count > 0 && d.pose_outputs == nullptr) {
    *error = "pose_outputs is NULL with a count above 0";
    return false;
  }
  for (uint32_t i = 0; i < d.pose_output_count; ++i) {
    const cd_pose_output& o = d.pose_outputs[i];
    if (o.address == nullptr) {
      *error = "pose_outputs[" + std::to_string(i) + "].address is NULL";
      return false;
    }
    pb::PoseOutput* msg = out->add_pose_outputs();
    msg->set_format(static_cast<pb::PoseFormat>(o.format));
    msg->set_address(o.address);
    msg->set_source_number(o.source_number);
    msg->set_sensor_height_mm(o.sensor_height_mm);
  }
  return true;
}

std::vector<std::string> slot_ids_of(const pb::CreateSessionRequest& request) {
  std::vector<std::string> ids;
  for (const pb::Target& t : request.targets()) ids.push_back(t.id());
  for (const pb::SceneObject& o : request.objects()) {
    if (o.dynamic()) ids.push_back(o.id());
  }
  return ids;
}

double seconds_since_epoch(Clock::time_point t) {
  return std::chrono::duration<double>(t.time_since_epoch()).count();
}

std::chrono::system_clock::time_point grpc_deadline(double timeout_s) {
  return std::chrono::system_clock::now() +
         std::chrono::duration_cast<std::chrono::system_clock::duration>(std::chrono::duration<double>(timeout_s));
}

std::string new_route_key() {
  std::random_device source;  // getrandom(2) / /dev/urandom with libstdc++ and libc++ on Linux
  static const char kHex[] = "0123456789abcdef";
  std::string key;
  key.reserve(32);
  for (int word = 0; word < 4; ++word) {
    uint32_t bits = source();
    for (int i = 0; i < 8; ++i, bits >>= 4) key += kHex[bits & 0xF];
  }
  return key;
}

std::string explain_failure(const grpc::Status& status, bool tls) {
  const std::string& message = status.error_message();
  // Only a connection gRPC could not make gets a hint: the server's own answers, and a server
  // that is down ("Connection refused"), say what happened.
  if (status.error_code() != grpc::StatusCode::UNAVAILABLE || message.rfind("failed to connect", 0) != 0 ||
      message.find("Connection refused") != std::string::npos) {
    return message;
  }
  std::string said = message;  // lower case, '_' as ' ': "CERTIFICATE_VERIFY_FAILED" (BoringSSL)
  for (char& c : said) c = c == '_' ? ' ' : static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  const char* hint = nullptr;
  if (!tls) {
    hint = "the server closed the connection: if it serves TLS, connect with grpcs://";
  } else if (said.find("certificate verify failed") != std::string::npos) {  // OpenSSL 3's words
    hint = "the server's certificate is not signed by an authority this client trusts: set ca_file to the PEM "
           "of the CA that signed it";
  } else if (said.find("handshake") != std::string::npos) {
    hint = "the TLS handshake failed: does the server serve TLS (--tls-cert)? grpc:// is plaintext";
  }
  return hint == nullptr ? message : message + " (" + hint + ")";
}

void copy_cstr(char* dst, size_t size, const std::string& src) {
  if (dst == nullptr || size == 0) return;
  const size_t n = src.size() < size - 1 ? src.size() : size - 1;
  std::memcpy(dst, src.data(), n);
  dst[n] = '\0';
}

}  // namespace camdirector::sdk

void cd_client::add_call_metadata(grpc::ClientContext* context, const std::string& route_key) const {
  if (!route_key.empty()) context->AddMetadata(camdirector::sdk::kRouteHeader, route_key);
  context->AddMetadata(camdirector::sdk::kProtocolHeader, std::to_string(CD_PROTOCOL));
  if (!authorization.empty()) context->AddMetadata(camdirector::sdk::kAuthorizationHeader, authorization);
}
