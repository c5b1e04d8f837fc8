// Drives the SDK through bad input and failures, printing JSON for tests/client_sdk/cpp/:
//
//   sdk_check address ADDRESS            an address that may not parse
//   sdk_check down HOST:PORT             a server that is down or refuses connections
//   sdk_check nan HOST:PORT              NaN / infinite / out-of-order frames at submit
//   sdk_check refused HOST:PORT          a frame the server refuses, between good ones
//   sdk_check sparse HOST:PORT           a frame's update carried over a dropped frame
//   sdk_check pose_output HOST:PORT UDP  a FreeD pose output to udp://127.0.0.1:UDP
//   sdk_check flood HOST:PORT [N]        N frames, one every 0.1 ms (queue of 4, 1 in flight)
//   sdk_check calls HOST:PORT            every kind of call of a session, for a test server that
//       records their metadata: open, stream, UpdateStyle, TakeShot, stream on until the server
//       forgets the session and it is recreated, close; then a second session that
//       cd_client_destroy closes
//   sdk_check protocol HOST:PORT         a recorded session (the test reads the protocol it said
//       from the server's recording), then a request claiming cd_protocol() + 1 (refused), then
//       another session on the same client
//   sdk_check retry ADDRESS N WINDOW_S   frames 1..N, each flushed before the next, with a retry
//       window of WINDOW_S, for a test server that breaks streams or answers DATA_LOSS on demand:
//       the pose's frame after each flush, the events, the stats; stops early once the session failed
//   sdk_check stream ADDRESS --until resumed|recreated|failed [--after N] [--timeout S] [--ca-file PEM]
//       a 60 Hz loop; prints {"ready": ...} once streaming, then keeps going until the event came
//       and N more frames (default 60) were answered on the session after it, or S seconds
//       (default 40) passed; the test breaks the connection, restarts the server or revokes the
//       key (CAMDIRECTOR_KEY, the SDK's default) meanwhile.
//
// Every scenario counts the heap allocations of the game-thread calls (alloc_counter.h).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <string>
#include <thread>
#include <vector>

#include "alloc_counter.h"
#include "camdirector/camdirector.h"

namespace {

using SteadyClock = std::chrono::steady_clock;

double now_s() { return std::chrono::duration<double>(SteadyClock::now().time_since_epoch()).count(); }

std::string q(const std::string& s) {
  std::string out = "\"";
  for (char c : s) {
    if (c == '"' || c == '\\') {
      out += '\\';
      out += c;
    } else if (static_cast<unsigned char>(c) < 0x20) {
      out += ' ';
    } else {
      out += c;
    }
  }
  return out + "\"";
}

std::string num(double v) {
  char buf[40];
  std::snprintf(buf, sizeof buf, "%.9g", v);
  return buf;
}

std::string u64(uint64_t v) { return std::to_string(v); }

const char* event_name(int kind) {
  switch (kind) {
    case CD_EVENT_STREAMING: return "STREAMING";
    case CD_EVENT_DISCONNECTED: return "DISCONNECTED";
    case CD_EVENT_RESUMED: return "RESUMED";
    case CD_EVENT_RECREATED: return "RECREATED";
    case CD_EVENT_SESSION_FAILED: return "SESSION_FAILED";
    case CD_EVENT_FRAME_REFUSED: return "FRAME_REFUSED";
    default: return "?";
  }
}

std::string stats_json(cd_client* client) {
  cd_stats s;
  cd_client_stats(client, &s);
  return "{\"state\": " + std::to_string(s.state) + ", \"generation\": " + std::to_string(s.generation) +
         ", \"frames_submitted\": " + u64(s.frames_submitted) + ", \"frames_refused\": " + u64(s.frames_refused) +
         ", \"frames_dropped\": " + u64(s.frames_dropped) + ", \"frames_sent\": " + u64(s.frames_sent) +
         ", \"frames_answered\": " + u64(s.frames_answered) + ", \"frames_stale\": " + u64(s.frames_stale) +
         ", \"frames_lost\": " + u64(s.frames_lost) + ", \"streams_opened\": " + u64(s.streams_opened) +
         ", \"disconnects\": " + u64(s.disconnects) + ", \"resumes\": " + u64(s.resumes) +
         ", \"recreations\": " + u64(s.recreations) + ", \"queued\": " + std::to_string(s.queued) +
         ", \"in_flight\": " + std::to_string(s.in_flight) + ", \"last_stream_status\": " +
         q(cd_status_name(s.last_stream_status)) + "}";
}

std::string error_of(cd_client* client) {
  char buf[512] = "";
  cd_last_error(client, buf, sizeof buf);
  return buf;
}

std::string session_of(cd_client* client) {
  char buf[128] = "";
  cd_session_id(client, buf, sizeof buf);
  return buf;
}

// The scene of tests/server/wire_client.two_target_request: targets a and b, a static pillar,
// a dynamic cart. Slots: a 0, b 1, cart 2. Target a has a display name (UTF-8), b none (NULL).
struct Scene {
  cd_target targets[2] = {};
  cd_object objects[2] = {};
  cd_session_desc desc;

  Scene() {
    for (int i = 0; i < 2; ++i) {
      targets[i].mesh.shape = CD_SHAPE_CAPSULE;
      targets[i].mesh.radius = 0.3;
      targets[i].mesh.height = 1.8;
      targets[i].aim_offset = {0.0, 0.6, 0.0};
    }
    targets[0].id = "a";
    targets[0].display_name = "\xc3\x85sa <b>";  // "Åsa <b>"
    targets[0].transform.position = {0.0, 0.9, 0.0};
    targets[1].id = "b";
    targets[1].transform.position = {3.0, 0.9, 1.0};
    objects[0].id = "pillar";
    objects[0].mesh.shape = CD_SHAPE_BOX;
    objects[0].mesh.box_size = {1.0, 3.0, 1.0};
    objects[0].transform.position = {1.5, 1.5, 4.0};
    objects[1].id = "cart";
    objects[1].mesh.shape = CD_SHAPE_BOX;
    objects[1].mesh.box_size = {1.0, 1.0, 1.0};
    objects[1].transform.position = {-2.0, 0.5, 2.0};
    objects[1].dynamic = 1;
    cd_session_desc_init(&desc);
    desc.targets = targets;
    desc.target_count = 2;
    desc.objects = objects;
    desc.object_count = 2;
    desc.seed = 3;
  }
};

// Opens the scene's session; on failure prints {"error": ...} (the scenario then exits 1).
bool open_or_say(cd_client* client, Scene& scene) {
  if (cd_session_open(client, &scene.desc, 10.0) == CD_OK) return true;
  std::printf("{\"error\": %s}\n", q(error_of(client)).c_str());
  return false;
}

// Closes the session, adds its close status and the server's frame count to the JSON object
// `out` (left open), prints it and destroys the client: how the scenarios that stream end.
int close_and_print(cd_client* client, std::string out) {
  uint64_t frames = 0;
  const cd_status closed = cd_session_close(client, &frames, 10.0);
  out += ", \"close\": " + q(cd_status_name(closed)) + ", \"server_frames\": " + u64(frames) + "}";
  std::puts(out.c_str());
  cd_client_destroy(client);
  return 0;
}

void states_at(uint64_t frame, cd_state out[3]) {
  const double t = static_cast<double>(frame) / 60.0;
  std::memset(out, 0, sizeof(cd_state) * 3);
  out[0].slot = 0;
  out[0].transform.position = {2.0 * std::sin(0.5 * t), 0.9, 0.5 * t};
  out[1].slot = 1;
  out[1].transform.position = {3.0, 0.9, 1.0 + 0.3 * t};
  out[2].slot = 2;
  out[2].transform.position = {-2.0 + std::sin(t), 0.5, 2.0};
}

cd_client* make_client(const char* address, uint32_t queue_capacity = 0, uint32_t in_flight = 0,
                       uint32_t io_poll_interval_ms = 0, const char* ca_file = nullptr) {
  cd_config config;
  cd_config_init(&config);
  config.address = address;
  config.ca_file = ca_file;
  if (queue_capacity) config.queue_capacity = queue_capacity;
  if (in_flight) config.max_in_flight = in_flight;
  config.io_poll_interval_ms = io_poll_interval_ms;
  config.reconnect_max_s = 0.5;
  cd_client* client = nullptr;
  const cd_status status = cd_client_create(&config, &client);
  if (status != CD_OK) {
    std::printf("{\"error\": %s}\n", q(std::string("cd_client_create: ") + cd_status_name(status)).c_str());
    std::exit(1);
  }
  return client;
}

int scenario_address(const char* address) {
  char reason[256] = "";
  const cd_status checked = cd_check_address(address, reason, sizeof reason);
  cd_config config;
  cd_config_init(&config);
  config.address = address;
  cd_client* client = nullptr;
  const double t0 = now_s();
  const cd_status created = cd_client_create(&config, &client);
  const double elapsed = now_s() - t0;
  std::printf("{\"status\": %s, \"reason\": %s, \"create_status\": %s, \"client_is_null\": %s, \"elapsed_s\": %s}\n",
              q(cd_status_name(checked)).c_str(), q(reason).c_str(), q(cd_status_name(created)).c_str(),
              client == nullptr ? "true" : "false", num(elapsed).c_str());
  cd_client_destroy(client);
  return 0;
}

int scenario_down(const char* address) {
  Scene scene;
  std::string out = "{";
  for (int wait = 0; wait < 2; ++wait) {
    cd_config config;
    cd_config_init(&config);
    config.address = address;
    config.wait_for_server = wait;
    cd_client* client = nullptr;
    cd_client_create(&config, &client);
    const double timeout_s = 2.0;
    const double t0 = now_s();
    const cd_status opened = cd_session_open(client, &scene.desc, timeout_s);
    const double elapsed = now_s() - t0;
    // The game thread goes on meanwhile: its calls answer at once.
    double worst_us = 0.0;
    cd_status submitted = CD_OK, polled = CD_OK;
    cd_state states[3];
    alloc_count_begin();
    for (uint64_t f = 1; f <= 200; ++f) {
      states_at(f, states);
      const double c0 = now_s();
      submitted = cd_frame_submit(client, f, static_cast<double>(f) / 60.0, states, 3);
      cd_pose pose;
      polled = cd_pose_poll(client, &pose);
      worst_us = std::max(worst_us, (now_s() - c0) * 1e6);
    }
    const uint64_t allocations = alloc_count_end();
    out += std::string(wait ? ", " : "") + q(wait ? "wait_for_server" : "fail_fast") + ": {\"open_status\": " +
           q(cd_status_name(opened)) + ", \"message\": " + q(error_of(client)) +
           ", \"elapsed_s\": " + num(elapsed) + ", \"timeout_s\": " + num(timeout_s) + ", \"submit_status\": " +
           q(cd_status_name(submitted)) + ", \"poll_status\": " + q(cd_status_name(polled)) +
           ", \"game_call_us_max\": " + num(worst_us) + ", \"game_thread_allocations\": " + u64(allocations) + "}";
    const double d0 = now_s();
    cd_client_destroy(client);
    out += std::string(", ") + q(wait ? "destroy_s_wait" : "destroy_s_fail_fast") + ": " + num(now_s() - d0);
  }
  std::printf("%s, \"alloc_counter\": %s}\n", out.c_str(), alloc_counter_active() ? "true" : "false");
  return 0;
}

int scenario_nan(const char* address) {
  Scene scene;
  cd_client* client = make_client(address);
  const cd_status opened = cd_session_open(client, &scene.desc, 10.0);
  if (opened != CD_OK) {
    std::printf("{\"error\": %s}\n", q(error_of(client)).c_str());
    return 1;
  }
  cd_state states[3];
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();
  std::vector<std::pair<const char*, cd_status>> results;
  results.reserve(16);
  alloc_count_begin();
  states_at(1, states);
  results.emplace_back("good_1", cd_frame_submit(client, 1, 1.0 / 60, states, 3));
  states_at(2, states);
  states[0].transform.position.x = nan;
  results.emplace_back("nan_position", cd_frame_submit(client, 2, 2.0 / 60, states, 3));
  states_at(2, states);
  states[1].transform.rotation = {0.0, inf, 0.0, 1.0};
  results.emplace_back("inf_rotation", cd_frame_submit(client, 2, 2.0 / 60, states, 3));
  states_at(2, states);
  states[2].transform.scale = {1.0, nan, 1.0};
  results.emplace_back("nan_scale", cd_frame_submit(client, 2, 2.0 / 60, states, 3));
  states_at(2, states);
  results.emplace_back("nan_time", cd_frame_submit(client, 2, nan, states, 3));
  states[0].slot = 7;
  results.emplace_back("unknown_slot", cd_frame_submit(client, 2, 2.0 / 60, states, 3));
  states_at(2, states);
  results.emplace_back("good_2", cd_frame_submit(client, 2, 2.0 / 60, states, 3));
  results.emplace_back("repeated_frame", cd_frame_submit(client, 2, 2.0 / 60, states, 3));
  results.emplace_back("time_back", cd_frame_submit(client, 3, 1.0 / 60, states, 3));
  states_at(3, states);
  results.emplace_back("good_3", cd_frame_submit(client, 3, 3.0 / 60, states, 3));
  const uint64_t allocations = alloc_count_end();
  const cd_status flushed = cd_session_flush(client, 10.0);
  cd_pose pose{};
  const cd_status polled = cd_pose_poll(client, &pose);
  std::string out = "{\"submits\": {";
  for (size_t i = 0; i < results.size(); ++i) {
    out += (i ? ", " : "") + q(results[i].first) + ": " + q(cd_status_name(results[i].second));
  }
  out += "}, \"flush\": " + q(cd_status_name(flushed)) + ", \"poll\": " + q(cd_status_name(polled)) +
         ", \"pose_frame\": " + u64(pose.frame) + ", \"pose_finite\": " +
         (std::isfinite(pose.position.x + pose.position.y + pose.position.z + pose.rotation.w) ? "true" : "false") +
         ", \"game_thread_allocations\": " + u64(allocations) + ", \"stats\": " + stats_json(client);
  return close_and_print(client, out);
}

// A frame the server refuses (a scale of zero on one axis: the SDK passes it, the server's
// codec refuses it) between good ones: the stream ends, the session goes on.
int scenario_refused(const char* address) {
  Scene scene;
  cd_client* client = make_client(address);
  if (!open_or_say(client, scene)) return 1;
  const std::string first_id = session_of(client);
  cd_state states[3];
  std::string out = "{\"submits\": [";
  for (uint64_t f = 1; f <= 3; ++f) {
    states_at(f, states);
    if (f == 2) states[2].transform.scale = {0.0, 1.0, 1.0};
    out += std::string(f > 1 ? ", " : "") + q(cd_status_name(cd_frame_submit(client, f, f / 60.0, states, 3)));
    cd_session_flush(client, 10.0);
  }
  cd_pose pose{};
  cd_pose_poll(client, &pose);
  out += "], \"last_pose_frame\": " + u64(pose.frame) + ", \"events\": [";
  cd_event event;
  for (int i = 0; cd_event_poll(client, &event) == CD_OK; ++i) {
    out += std::string(i ? ", " : "") + "{\"kind\": " + q(event_name(event.kind)) + ", \"status\": " +
           q(cd_status_name(event.status)) + ", \"message\": " + q(event.message) + "}";
  }
  out += "], \"session_id_kept\": " + std::string(session_of(client) == first_id ? "true" : "false");
  out += ", \"stats\": " + stats_json(client) + "}";
  cd_session_close(client, nullptr, 10.0);
  std::puts(out.c_str());
  cd_client_destroy(client);
  return 0;
}

int scenario_flood(const char* address, uint64_t n) {
  Scene scene;
  cd_client* client = make_client(address, 4, 1);
  if (!open_or_say(client, scene)) return 1;
  std::vector<double> call_us;
  call_us.reserve(n);
  cd_state states[3];
  uint64_t refused = 0;
  alloc_count_begin();
  for (uint64_t f = 1; f <= n; ++f) {
    states_at(f, states);
    const double c0 = now_s();
    if (cd_frame_submit(client, f, static_cast<double>(f) / 60.0, states, 3) != CD_OK) ++refused;
    cd_pose pose;
    (void)cd_pose_poll(client, &pose);
    call_us.push_back((now_s() - c0) * 1e6);
    // Faster than a server answers (a frame takes it about a millisecond), slow enough that
    // the I/O thread keeps sending.
    std::this_thread::sleep_for(std::chrono::microseconds(100));
  }
  const uint64_t allocations = alloc_count_end();
  const cd_status flushed = cd_session_flush(client, 30.0);
  cd_pose pose{};
  cd_pose_poll(client, &pose);
  std::sort(call_us.begin(), call_us.end());
  std::string out = "{\"frames\": " + u64(n) + ", \"refused\": " + u64(refused) + ", \"flush\": " +
                    q(cd_status_name(flushed)) + ", \"last_pose_frame\": " + u64(pose.frame) +
                    ", \"game_call_us_p50\": " + num(call_us[call_us.size() / 2]) + ", \"game_call_us_max\": " +
                    num(call_us.back()) + ", \"game_thread_allocations\": " + u64(allocations) +
                    ", \"stats\": " + stats_json(client);
  return close_and_print(client, out);
}

// Screen position (x right, y up, [-1, 1]) of a world point seen by the pose, at aspect 16:9.
void project(const cd_pose& pose, const cd_vec3& p, double* sx, double* sy) {
  const double x = pose.rotation.x, y = pose.rotation.y, z = pose.rotation.z, w = pose.rotation.w;
  const double r[3][3] = {{1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)},
                          {2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)},
                          {2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)}};
  const double d[3] = {p.x - pose.position.x, p.y - pose.position.y, p.z - pose.position.z};
  double c[3];
  for (int i = 0; i < 3; ++i) c[i] = r[0][i] * d[0] + r[1][i] * d[1] + r[2][i] * d[2];
  const double t = std::tan(pose.vertical_fov_deg * M_PI / 360.0);
  *sx = c[0] / (-c[2] * t * (16.0 / 9.0));
  *sy = c[1] / (-c[2] * t);
}

// Sparse updates through a full queue: frame 1 moves b (and a); frames 2 to 6 move only a. The
// I/O thread looks at the queue every 200 ms, so frames are dropped; b's move must still reach
// the server (carried into the next frame), or the last pose frames b where it was before.
int scenario_sparse(const char* address) {
  Scene scene;
  cd_client* client = make_client(address, 2, 1, 200);
  if (!open_or_say(client, scene)) return 1;
  const cd_vec3 b_moved = {4.5, 0.9, 3.0};
  cd_state states[3];
  uint64_t refused = 0;
  alloc_count_begin();
  for (uint64_t f = 1; f <= 6; ++f) {
    states_at(f, states);
    states[1].transform.position = b_moved;
    if (cd_frame_submit(client, f, static_cast<double>(f) / 60.0, states, f == 1 ? 2 : 1) != CD_OK) ++refused;
  }
  const uint64_t allocations = alloc_count_end();
  const cd_status flushed = cd_session_flush(client, 10.0);
  cd_pose pose{};
  cd_pose_poll(client, &pose);
  states_at(6, states);
  const cd_vec3 a = states[0].transform.position;
  double ax, ay, bx, by;
  project(pose, {a.x, a.y + 0.6, a.z}, &ax, &ay);
  project(pose, {b_moved.x, b_moved.y + 0.6, b_moved.z}, &bx, &by);
  const double error = std::max({std::fabs(ax + 1.0 / 3.0), std::fabs(ay), std::fabs(bx - 1.0 / 3.0), std::fabs(by)});
  std::string out = "{\"refused\": " + u64(refused) + ", \"flush\": " + q(cd_status_name(flushed)) +
                    ", \"last_pose_frame\": " + u64(pose.frame) + ", \"screen_error\": " + num(error) +
                    ", \"game_thread_allocations\": " + u64(allocations) + ", \"stats\": " + stats_json(client) + "}";
  cd_session_close(client, nullptr, 10.0);
  std::puts(out.c_str());
  cd_client_destroy(client);
  return 0;
}

// A session with a FreeD pose output to udp://127.0.0.1:UDP_PORT: ten frames, then close.
int scenario_pose_output(const char* address, const char* udp_port) {
  Scene scene;
  const std::string destination = std::string("udp://127.0.0.1:") + udp_port;
  cd_pose_output output{};
  output.format = CD_POSE_FORMAT_FREED_D1;
  output.address = destination.c_str();
  output.source_number = 9;
  scene.desc.pose_outputs = &output;
  scene.desc.pose_output_count = 1;
  cd_client* client = make_client(address, 16);  // room for the ten frames submitted at once
  const cd_status opened = cd_session_open(client, &scene.desc, 10.0);
  std::string out = "{\"open\": " + q(cd_status_name(opened)) + ", \"message\": " + q(error_of(client));
  if (opened == CD_OK) {
    cd_state states[3];
    for (uint64_t f = 1; f <= 10; ++f) {
      states_at(f, states);
      cd_frame_submit(client, f, static_cast<double>(f) / 60.0, states, 3);
    }
    out += ", \"flush\": " + q(cd_status_name(cd_session_flush(client, 10.0)));
    out += ", \"stats\": " + stats_json(client);
    out += ", \"close\": " + q(cd_status_name(cd_session_close(client, nullptr, 10.0)));
  }
  std::puts((out + "}").c_str());
  cd_client_destroy(client);
  return 0;
}

// Submits a frame every 5 ms until pred() holds or timeout_s passes; false on the timeout.
template <typename Pred>
bool stream_until(cd_client* client, uint64_t* frame, double timeout_s, Pred pred) {
  cd_state states[3];
  const double start = now_s();
  while (now_s() - start < timeout_s) {
    ++*frame;
    states_at(*frame, states);
    cd_frame_submit(client, *frame, static_cast<double>(*frame) / 60.0, states, 3);
    if (pred()) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  return false;
}

int scenario_calls(const char* address) {
  Scene scene;
  cd_client* client = make_client(address);
  if (!open_or_say(client, scene)) return 1;
  const std::string first_id = session_of(client);
  uint64_t frame = 0;
  auto answered = [client] {
    cd_pose pose;
    return cd_pose_poll(client, &pose) == CD_OK;
  };
  const bool streamed = stream_until(client, &frame, 10.0, answered);
  cd_style style;
  cd_style_init(&style);
  style.gaze_room_m = 0.5;
  const cd_status styled = cd_session_update_style(client, &style, 5.0);
  const char* subjects[] = {"a"};
  const cd_status shot = cd_session_take_shot(client, subjects, 1, 0, 0, nullptr, 5.0);
  std::string events = "[";
  bool recreated = false;
  auto recreated_and_answered = [&] {
    cd_event event;
    while (cd_event_poll(client, &event) == CD_OK) {
      events += std::string(events.size() > 1 ? ", " : "") + q(event_name(event.kind));
      if (event.kind == CD_EVENT_RECREATED) recreated = true;
    }
    cd_pose pose;
    return recreated && cd_pose_poll(client, &pose) == CD_OK && pose.generation == 2;
  };
  const bool answered_again = stream_until(client, &frame, 15.0, recreated_and_answered);
  events += "]";
  const std::string second_id = session_of(client);
  const cd_status closed = cd_session_close(client, nullptr, 5.0);
  Scene other;
  const bool reopened = open_or_say(client, other);
  const std::string other_id = session_of(client);
  std::printf("{\"first_session_id\": %s, \"streamed\": %s, \"update_style\": %s, \"take_shot\": %s, "
              "\"recreated_session_id\": %s, \"answered_after_recreation\": %s, \"events\": %s, \"close\": %s, "
              "\"other_session_id\": %s}\n",
              q(first_id).c_str(), streamed ? "true" : "false", q(cd_status_name(styled)).c_str(),
              q(cd_status_name(shot)).c_str(), q(second_id).c_str(), answered_again ? "true" : "false",
              events.c_str(), q(cd_status_name(closed)).c_str(), q(reopened ? other_id : "").c_str());
  std::fflush(stdout);
  cd_client_destroy(client);  // closes the other session (best effort)
  return 0;
}

int scenario_protocol(const char* address) {
  Scene scene;
  scene.desc.record = 1;
  cd_client* client = make_client(address);
  if (!open_or_say(client, scene)) return 1;
  const std::string recorded_id = session_of(client);
  const cd_status closed = cd_session_close(client, nullptr, 5.0);
  const std::string close_error = closed == CD_OK ? "" : error_of(client);
  // A CreateSessionRequest of nothing but client_protocol (field 10, a one-byte varint while the
  // protocol is under 127): the server refuses it for the protocol before it looks at the scene.
  const uint32_t newer = cd_protocol() + 1;
  const unsigned char claim[] = {10 << 3, static_cast<unsigned char>(newer)};
  const cd_status refused = cd_session_open_serialized(client, claim, sizeof claim, 5.0);
  const std::string refused_error = error_of(client);
  Scene again;
  const bool reopened = open_or_say(client, again);
  std::string out = "{\"protocol\": " + std::to_string(cd_protocol()) + ", \"header_protocol\": " +
                    std::to_string(CD_PROTOCOL) + ", \"recorded_session_id\": " + q(recorded_id) +
                    ", \"recorded_close\": " + q(cd_status_name(closed)) + ", \"recorded_close_error\": " +
                    q(close_error) + ", \"newer\": " + q(cd_status_name(refused)) +
                    ", \"newer_error\": " + q(refused_error) + ", \"reopened\": " + (reopened ? "true" : "false");
  return close_and_print(client, out);
}

int scenario_retry(const char* address, uint64_t n, double retry_window_s) {
  cd_config config;
  cd_config_init(&config);
  config.address = address;
  config.retry_window_s = retry_window_s;
  cd_client* client = nullptr;
  Scene scene;
  if (cd_client_create(&config, &client) != CD_OK || !open_or_say(client, scene)) return 1;
  const std::string first_id = session_of(client);
  cd_state states[3];
  std::string out = "{\"pose_frames\": [";
  for (uint64_t f = 1; f <= n; ++f) {
    states_at(f, states);
    cd_frame_submit(client, f, static_cast<double>(f) / 60.0, states, 3);
    cd_session_flush(client, 5.0);  // returns early once the session failed
    cd_pose pose{};
    cd_pose_poll(client, &pose);
    out += std::string(f > 1 ? ", " : "") + u64(pose.frame);
    cd_stats stats;
    cd_client_stats(client, &stats);
    if (stats.state == CD_STATE_FAILED) break;
  }
  out += "], \"events\": [";
  cd_event event;
  for (int i = 0; cd_event_poll(client, &event) == CD_OK; ++i) {
    out += std::string(i ? ", " : "") + "{\"kind\": " + q(event_name(event.kind)) + ", \"status\": " +
           q(cd_status_name(event.status)) + ", \"message\": " + q(event.message) + "}";
  }
  out += "], \"first_session_id\": " + q(first_id) + ", \"last_session_id\": " + q(session_of(client));
  out += ", \"stats\": " + stats_json(client);
  return close_and_print(client, out);
}

int scenario_stream(const char* address, const std::string& until, uint64_t after, double timeout_s,
                    const char* ca_file) {
  Scene scene;
  cd_client* client = make_client(address, 8, 2, 0, ca_file);
  if (!open_or_say(client, scene)) return 1;
  const std::string first_id = session_of(client);
  const int wanted = until == "recreated" ? CD_EVENT_RECREATED
                     : until == "failed"  ? CD_EVENT_SESSION_FAILED
                                          : CD_EVENT_RESUMED;
  std::vector<cd_event> events;
  events.reserve(64);
  std::vector<double> tick_us;
  tick_us.reserve(8192);
  uint64_t allocations = 0, refused = 0, event_frame = 0, answered_after = 0, last_counted = 0;
  bool ready = false, seen = false;
  const double start = now_s();
  cd_state states[3];
  uint64_t frame = 0;
  while (now_s() - start < timeout_s) {
    ++frame;
    states_at(frame, states);
    alloc_count_begin();
    const double c0 = now_s();
    if (cd_frame_submit(client, frame, static_cast<double>(frame) / 60.0, states, 3) != CD_OK) ++refused;
    cd_pose pose;
    const bool have = cd_pose_poll(client, &pose) == CD_OK;
    cd_event event;
    while (cd_event_poll(client, &event) == CD_OK) {
      if (events.size() < events.capacity()) events.push_back(event);
      if (event.kind == wanted && !seen) {
        seen = true;
        event_frame = event.frame;
      }
    }
    if (tick_us.size() < tick_us.capacity()) tick_us.push_back((now_s() - c0) * 1e6);
    allocations += alloc_count_end();
    if (have && seen && pose.frame > event_frame && pose.frame > last_counted) {
      answered_after += pose.frame - std::max(last_counted, event_frame);
      last_counted = pose.frame;
    }
    if (!ready && have && pose.frame >= 30) {
      ready = true;
      std::printf("{\"ready\": true, \"session_id\": %s, \"frame\": %s}\n", q(first_id).c_str(), u64(frame).c_str());
      std::fflush(stdout);
    }
    if (seen && answered_after >= after) break;
    std::this_thread::sleep_until(SteadyClock::time_point(std::chrono::duration_cast<SteadyClock::duration>(
        std::chrono::duration<double>(start + static_cast<double>(frame) / 60.0))));
  }
  const std::string last_id = session_of(client);
  cd_pose pose{};
  cd_pose_poll(client, &pose);
  std::sort(tick_us.begin(), tick_us.end());
  std::string out = "{\"first_session_id\": " + q(first_id) + ", \"last_session_id\": " + q(last_id) +
                    ", \"seen\": " + (seen ? "true" : "false") + ", \"answered_after\": " + u64(answered_after) +
                    ", \"frames\": " + u64(frame) + ", \"refused\": " + u64(refused) +
                    ", \"last_pose_frame\": " + u64(pose.frame) + ", \"last_pose_generation\": " +
                    std::to_string(pose.generation) + ", \"elapsed_s\": " + num(now_s() - start) +
                    ", \"game_call_us_p50\": " + num(tick_us.empty() ? 0.0 : tick_us[tick_us.size() / 2]) +
                    ", \"game_call_us_max\": " + num(tick_us.empty() ? 0.0 : tick_us.back()) +
                    ", \"game_thread_allocations\": " + u64(allocations) + ", \"events\": [";
  for (size_t i = 0; i < events.size(); ++i) {
    out += std::string(i ? ", " : "") + "{\"kind\": " + q(event_name(events[i].kind)) + ", \"status\": " +
           q(cd_status_name(events[i].status)) + ", \"session_id\": " + q(events[i].session_id) +
           ", \"generation\": " + std::to_string(events[i].generation) + ", \"message\": " + q(events[i].message) +
           "}";
  }
  out += "], \"stats\": " + stats_json(client);
  return close_and_print(client, out);
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 3) {
    std::fprintf(stderr, "usage: sdk_check address|down|nan|refused|sparse|pose_output|flood|calls|stream ADDRESS [options]\n");
    return 2;
  }
  const std::string scenario = argv[1];
  const char* address = argv[2];
  if (scenario == "address") return scenario_address(address);
  if (scenario == "down") return scenario_down(address);
  if (scenario == "nan") return scenario_nan(address);
  if (scenario == "sparse") return scenario_sparse(address);
  if (scenario == "refused") return scenario_refused(address);
  if (scenario == "pose_output" && argc > 3) return scenario_pose_output(address, argv[3]);
  if (scenario == "calls") return scenario_calls(address);
  if (scenario == "protocol") return scenario_protocol(address);
  if (scenario == "retry" && argc > 4) return scenario_retry(address, std::strtoull(argv[3], nullptr, 10), std::atof(argv[4]));
  if (scenario == "flood") return scenario_flood(address, argc > 3 ? std::strtoull(argv[3], nullptr, 10) : 3000);
  if (scenario == "stream") {
    std::string until = "resumed";
    uint64_t after = 60;
    double timeout_s = 40.0;
    const char* ca_file = nullptr;
    for (int i = 3; i + 1 < argc; i += 2) {
      const std::string flag = argv[i];
      if (flag == "--until") until = argv[i + 1];
      if (flag == "--after") after = std::strtoull(argv[i + 1], nullptr, 10);
      if (flag == "--timeout") timeout_s = std::atof(argv[i + 1]);
      if (flag == "--ca-file") ca_file = argv[i + 1];
    }
    return scenario_stream(address, until, after, timeout_s, ca_file);
  }
  std::fprintf(stderr, "sdk_check: unknown scenario %s\n", scenario.c_str());
  return 2;
}
