// `stream_frames ADDRESS [FRAMES]`: opens a session with two players on a camdirector server,
// streams FRAMES frames (600 by default) and waits for every answer. ADDRESS is cd_config.address
// (HOST:PORT, or grpcs://HOST:PORT over TLS with the system's roots); the API key comes from the
// CAMDIRECTOR_KEY environment variable, the SDK's default.
//
// A batch, such as a cutscene solved ahead of time: unlike a game loop (../engine_loop.cpp), which
// must never wait and lets the SDK's queue drop its oldest frame, it wants every frame answered, so
// it waits for room in the queue before each submit. Prints one JSON line.
#include <camdirector/camdirector.hpp>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <thread>

static int fail(const char* what, const camdirector::Status& status) {
  std::fprintf(stderr, "stream_frames: %s: %s: %s\n", what, status.name(), status.message.c_str());
  return 1;
}

int main(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(stderr, "usage: stream_frames ADDRESS [FRAMES]\n");
    return 2;
  }
  const int frames = argc > 2 ? std::atoi(argv[2]) : 600;

  cd_config config;
  cd_config_init(&config);
  config.address = argv[1];
  camdirector::Status status;
  camdirector::Client client(config, &status);
  if (!status.ok()) return fail("client", status);

  // Two capsules, framed where the default style puts them: on the left and right thirds.
  cd_target targets[2] = {};
  targets[0].id = "a";
  targets[1].id = "b";
  for (int i = 0; i < 2; ++i) {
    targets[i].mesh.shape = CD_SHAPE_CAPSULE;
    targets[i].mesh.radius = 0.3;
    targets[i].mesh.height = 1.8;
    targets[i].transform.position = {2.0 * i, 0.9, 0.0};
    targets[i].aim_offset = {0.0, 0.6, 0.0};
  }
  cd_session_desc desc;
  cd_session_desc_init(&desc);
  desc.targets = targets;
  desc.target_count = 2;
  status = client.open(desc, 10.0);
  if (!status.ok()) return fail("open", status);

  cd_state states[2] = {};
  states[0].slot = static_cast<uint32_t>(client.slot("a"));
  states[1].slot = static_cast<uint32_t>(client.slot("b"));
  for (int frame = 1; frame <= frames; ++frame) {
    const double t = frame / 60.0;
    states[0].transform.position = {std::sin(t), 0.9, 0.5 * t};
    states[1].transform.position = {2.0 + std::cos(t), 0.9, 0.5 * t};
    // A full queue would drop its oldest frame: wait until the I/O thread has sent one (a session
    // lost for good never drains it, and the submit below then says so).
    for (cd_stats s = client.stats(); s.queued >= config.queue_capacity && s.state != CD_STATE_FAILED;
         s = client.stats()) {
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
    const cd_status submitted = client.submit(static_cast<uint64_t>(frame), t, states, 2);
    if (submitted != CD_OK) {
      std::fprintf(stderr, "stream_frames: frame %d: %s\n", frame, cd_status_name(submitted));
      return 1;
    }
  }

  const camdirector::Status flushed = client.flush(30.0);  // every frame answered (or given up)
  cd_pose last{};
  client.poll(&last);
  const cd_stats stats = client.stats();
  uint64_t server_frames = 0;
  const camdirector::Status closed = client.close(&server_frames, 10.0);
  std::printf(
      "{\"frames_submitted\": %llu, \"frames_answered\": %llu, \"frames_dropped\": %llu, \"frames_lost\": %llu, "
      "\"server_frames\": %llu, \"last_pose_frame\": %llu, \"flush\": \"%s\", \"close\": \"%s\"}\n",
      static_cast<unsigned long long>(stats.frames_submitted), static_cast<unsigned long long>(stats.frames_answered),
      static_cast<unsigned long long>(stats.frames_dropped), static_cast<unsigned long long>(stats.frames_lost),
      static_cast<unsigned long long>(server_frames), static_cast<unsigned long long>(last.frame), flushed.name(),
      closed.name());
  return flushed.ok() && closed.ok() ? 0 : 1;
}
