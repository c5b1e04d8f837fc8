// A 60 Hz game loop on the camdirector SDK: `engine_loop ADDRESS [FRAMES] [--ca-file PEM]`.
//
// ADDRESS is HOST:PORT (plaintext) or grpcs://HOST:PORT (TLS, the server's certificate checked
// against the CA of --ca-file, else the system's roots). The API key comes from the environment
// variable CAMDIRECTOR_KEY (the SDK's default when cd_config.key is NULL), never the command line,
// where other users of the machine could read it.
//
// At load time (blocking calls, with deadlines) it creates a two-target session; then each tick
// the game thread does only non-blocking work: submit this frame's transforms, poll the newest
// camera pose, read the SDK's events. After FRAMES frames (600 by default: 10 s) it waits for
// the last answers, closes the session and prints one JSON object:
//   frames_answered       answers the SDK received
//   max_screen_error      worst distance (normalised screen units, [-1, 1] across the frame) of
//                         target A from screen_a or B from screen_b, over the poses polled,
//                         each projected with the targets where they were in the frame it answers
//   game_thread_us_p50/99 time of one tick's SDK calls on the game thread, microseconds
//   pose_latency_ms_p50/99 from submitting a frame to receiving its pose
//   pose_delay_frames_p50 how many frames behind the tick the polled pose is
//   session_id, last_session_id, recreations   the session at the start and at the end, and how
//                         often it was created again (a server that lost it): after a restart of a
//                         server with checkpoints, the same id and 0
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <thread>
#include <vector>

#include "camdirector/camdirector.hpp"

namespace {

using SteadyClock = std::chrono::steady_clock;

constexpr double kFps = 60.0;
constexpr double kFovDeg = 50.0;
constexpr double kAspect = 16.0 / 9.0;
constexpr double kScreenA[2] = {-1.0 / 3.0, 0.0};  // the style's defaults
constexpr double kScreenB[2] = {1.0 / 3.0, 0.0};
constexpr cd_vec3 kAim = {0.0, 0.6, 0.0};           // framed point above each target's origin

// The game's world, already in our frame (a Unity or Unreal game converts with
// cd_from_unity_transform / cd_from_unreal_transform first).
struct World {
  cd_vec3 a, b, cart;
};

World world_at(double t) {
  return World{{2.0 * std::sin(0.5 * t), 0.9, 0.7 * t},
               {3.0 + std::cos(0.3 * t), 0.9, 1.0 + 0.5 * t},
               {-2.0 + std::sin(t), 0.5, 2.0}};
}

// Screen position (x right, y up, [-1, 1]) of a world point seen by the pose.
void project(const cd_pose& pose, const cd_vec3& p, double aspect, double* sx, double* sy) {
  const double x = pose.rotation.x, y = pose.rotation.y, z = pose.rotation.z, w = pose.rotation.w;
  const double r[3][3] = {{1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)},
                          {2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)},
                          {2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)}};
  const double d[3] = {p.x - pose.position.x, p.y - pose.position.y, p.z - pose.position.z};
  double c[3];  // R^T d: the point in camera space
  for (int i = 0; i < 3; ++i) c[i] = r[0][i] * d[0] + r[1][i] * d[1] + r[2][i] * d[2];
  const double t = std::tan(pose.vertical_fov_deg * M_PI / 360.0);
  *sx = c[0] / (-c[2] * t * aspect);
  *sy = c[1] / (-c[2] * t);
}

double percentile(std::vector<double> v, double q) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  const size_t i = static_cast<size_t>(std::ceil(q * static_cast<double>(v.size()))) - 1;
  return v[std::min(i, v.size() - 1)];
}

cd_mesh capsule() {
  cd_mesh m{};
  m.shape = CD_SHAPE_CAPSULE;
  m.radius = 0.3;
  m.height = 1.8;
  return m;
}

cd_mesh box(double sx, double sy, double sz) {
  cd_mesh m{};
  m.shape = CD_SHAPE_BOX;
  m.box_size = {sx, sy, sz};
  return m;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(stderr, "usage: engine_loop ADDRESS [FRAMES] [--ca-file PEM]\n");
    return 2;
  }
  int frames = 600;
  const char* ca_file = nullptr;
  for (int i = 2; i < argc; ++i) {
    if (std::strcmp(argv[i], "--ca-file") == 0 && i + 1 < argc) {
      ca_file = argv[++i];
    } else {
      frames = std::atoi(argv[i]);
    }
  }

  // --- setup: may allocate and block ----------------------------------------------------------
  cd_config config;
  cd_config_init(&config);
  config.address = argv[1];
  config.ca_file = ca_file;  // grpcs:// only; config.key stays NULL: CAMDIRECTOR_KEY
  config.queue_capacity = 32;  // this check wants every frame answered, even on a busy machine
  config.max_in_flight = 4;
  camdirector::Status status;
  camdirector::Client client(config, &status);
  if (!status.ok()) {
    std::fprintf(stderr, "engine_loop: %s: %s\n", status.name(), status.message.c_str());
    return 1;
  }

  const World w0 = world_at(0.0);
  cd_target targets[2] = {};
  targets[0].id = "a";
  targets[0].mesh = capsule();
  targets[0].transform.position = w0.a;
  targets[0].aim_offset = kAim;
  targets[1].id = "b";
  targets[1].mesh = capsule();
  targets[1].transform.position = w0.b;
  targets[1].aim_offset = kAim;
  cd_object objects[2] = {};
  objects[0].id = "pillar";
  objects[0].mesh = box(1.0, 3.0, 1.0);
  objects[0].transform.position = {1.5, 1.5, 4.0};
  objects[1].id = "cart";
  objects[1].mesh = box(1.0, 1.0, 1.0);
  objects[1].transform.position = w0.cart;
  objects[1].dynamic = 1;

  cd_session_desc desc;
  cd_session_desc_init(&desc);  // default style: FRAMING_ONLY, A at (-1/3, 0), B at (1/3, 0)
  desc.targets = targets;
  desc.target_count = 2;
  desc.objects = objects;
  desc.object_count = 2;
  desc.vertical_fov_deg = kFovDeg;
  desc.aspect = kAspect;
  desc.seed = 7;
  status = client.open(desc, 10.0);
  if (!status.ok()) {
    std::fprintf(stderr, "engine_loop: open: %s: %s\n", status.name(), status.message.c_str());
    return 1;
  }
  const uint32_t slot_a = static_cast<uint32_t>(client.slot("a"));
  const uint32_t slot_b = static_cast<uint32_t>(client.slot("b"));
  const uint32_t slot_cart = static_cast<uint32_t>(client.slot("cart"));
  const std::string session_id = client.session_id();

  // What the game keeps to read answers against: where the targets were, and when each frame
  // was submitted (a real game keeps a short ring of these for interpolation).
  std::vector<World> world_of_frame(static_cast<size_t>(frames) + 1);
  std::vector<double> submitted_at_s(static_cast<size_t>(frames) + 1, 0.0);
  std::vector<double> tick_us, latency_ms, delay_frames;
  tick_us.reserve(static_cast<size_t>(frames));
  latency_ms.reserve(static_cast<size_t>(frames));
  delay_frames.reserve(static_cast<size_t>(frames));
  double max_screen_error = 0.0;
  uint64_t last_checked = 0;
  int cuts = 0, refused = 0, events = 0;

  // --- the game loop: non-blocking SDK calls only ----------------------------------------------
  const SteadyClock::time_point start = SteadyClock::now();
  for (int frame = 1; frame <= frames; ++frame) {
    const double time_s = frame / kFps;
    const World w = world_at(time_s);
    world_of_frame[static_cast<size_t>(frame)] = w;
    cd_state states[3] = {};
    states[0].slot = slot_a;
    states[0].transform.position = w.a;
    states[1].slot = slot_b;
    states[1].transform.position = w.b;
    states[2].slot = slot_cart;
    states[2].transform.position = w.cart;

    const SteadyClock::time_point t0 = SteadyClock::now();
    submitted_at_s[static_cast<size_t>(frame)] = cd_now_s();
    if (client.submit(static_cast<uint64_t>(frame), time_s, states, 3) != CD_OK) ++refused;
    cd_pose pose;
    const bool have_pose = client.poll(&pose) == CD_OK;
    cd_event event;
    while (client.poll_event(&event) == CD_OK) ++events;
    const SteadyClock::time_point t1 = SteadyClock::now();
    tick_us.push_back(std::chrono::duration<double, std::micro>(t1 - t0).count());

    // Use the pose: here, check its framing against where the targets were in its frame.
    if (have_pose && pose.frame > last_checked && pose.frame <= static_cast<uint64_t>(frames)) {
      last_checked = pose.frame;
      const World& seen = world_of_frame[pose.frame];
      double ax, ay, bx, by;
      project(pose, {seen.a.x + kAim.x, seen.a.y + kAim.y, seen.a.z + kAim.z}, kAspect, &ax, &ay);
      project(pose, {seen.b.x + kAim.x, seen.b.y + kAim.y, seen.b.z + kAim.z}, kAspect, &bx, &by);
      const double err = std::max({std::fabs(ax - kScreenA[0]), std::fabs(ay - kScreenA[1]),
                                   std::fabs(bx - kScreenB[0]), std::fabs(by - kScreenB[1])});
      max_screen_error = std::max(max_screen_error, err);
      latency_ms.push_back((pose.received_s - submitted_at_s[pose.frame]) * 1000.0);
      delay_frames.push_back(static_cast<double>(frame) - static_cast<double>(pose.frame));
      if (pose.cut_since_last_poll) ++cuts;
    }
    std::this_thread::sleep_until(start + std::chrono::duration_cast<SteadyClock::duration>(
                                              std::chrono::duration<double>(frame / kFps)));
  }

  // --- shutdown: blocking again ----------------------------------------------------------------
  const camdirector::Status flushed = client.flush(10.0);
  cd_pose last{};
  client.poll(&last);
  const cd_stats stats = client.stats();
  const std::string last_session_id = client.session_id();  // the first one unless it was created again
  uint64_t closed_frames = 0;
  const camdirector::Status closed = client.close(&closed_frames, 10.0);

  std::printf(
      "{\"frames_submitted\": %llu, \"frames_answered\": %llu, \"frames_dropped\": %llu, \"frames_lost\": %llu, "
      "\"frames_refused\": %d, \"poses_checked\": %zu, \"last_pose_frame\": %llu, \"max_screen_error\": %.9g, "
      "\"game_thread_us_p50\": %.3f, \"game_thread_us_p99\": %.3f, \"game_thread_us_max\": %.3f, "
      "\"pose_latency_ms_p50\": %.3f, \"pose_latency_ms_p99\": %.3f, \"pose_delay_frames_p50\": %.1f, "
      "\"cuts\": %d, \"events\": %d, \"reconnects\": %llu, \"flush\": \"%s\", \"close\": \"%s\", "
      "\"server_frames\": %llu, \"session_id\": \"%s\", \"last_session_id\": \"%s\", \"recreations\": %llu}\n",
      static_cast<unsigned long long>(stats.frames_submitted), static_cast<unsigned long long>(stats.frames_answered),
      static_cast<unsigned long long>(stats.frames_dropped), static_cast<unsigned long long>(stats.frames_lost),
      refused, latency_ms.size(), static_cast<unsigned long long>(last.frame), max_screen_error,
      percentile(tick_us, 0.5), percentile(tick_us, 0.99), percentile(tick_us, 1.0), percentile(latency_ms, 0.5),
      percentile(latency_ms, 0.99), percentile(delay_frames, 0.5), cuts, events,
      static_cast<unsigned long long>(stats.disconnects), flushed.name(), closed.name(),
      static_cast<unsigned long long>(closed_frames), session_id.c_str(), last_session_id.c_str(),
      static_cast<unsigned long long>(stats.recreations));
  return flushed.ok() && closed.ok() ? 0 : 1;
}
