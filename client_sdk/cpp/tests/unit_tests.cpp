// Unit tests of the SDK that need no server, run by ctest (tests/client_sdk/cpp/test_ctest.py runs
// ctest from `make test`): the engines' conversions against the tables of docs/protocol.md (known
// values and round trips), the fields of view, address parsing, the key and TLS options, and the
// game thread's refusals without a session. Exits non-zero with the first failed check printed.
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <limits>

#include "camdirector/camdirector.h"
#include "retry.h"

namespace {

int failures = 0;

void check(bool ok, const char* what) {
  if (!ok) {
    std::fprintf(stderr, "FAILED: %s\n", what);
    ++failures;
  }
}

bool near(double a, double b, double tol = 1e-12) { return std::fabs(a - b) <= tol; }
bool near3(cd_vec3 a, cd_vec3 b, double tol = 1e-12) {
  return near(a.x, b.x, tol) && near(a.y, b.y, tol) && near(a.z, b.z, tol);
}
bool near4(cd_quat a, cd_quat b, double tol = 1e-12) {
  return near(a.x, b.x, tol) && near(a.y, b.y, tol) && near(a.z, b.z, tol) && near(a.w, b.w, tol);
}

void known_values() {
  // docs/protocol.md: Unity ours = (x, y, -z), q = (-x, -y, z, w); Unreal ours = (y, z, -x) / 100,
  // q = (-qy, -qz, qx, qw), scale = (sy, sz, sx).
  check(near3(cd_from_unity_position({1.0, 2.0, 3.0}), {1.0, 2.0, -3.0}), "Unity position");
  check(near4(cd_from_unity_rotation({0.1, 0.2, 0.3, 0.9}), {-0.1, -0.2, 0.3, 0.9}), "Unity rotation");
  check(near3(cd_from_unreal_position({100.0, 200.0, 300.0}), {2.0, 3.0, -1.0}), "Unreal position, cm to m");
  check(near4(cd_from_unreal_rotation({0.1, 0.2, 0.3, 0.9}), {-0.2, -0.3, 0.1, 0.9}), "Unreal rotation");
  check(near3(cd_from_unreal_scale({1.0, 2.0, 3.0}), {2.0, 3.0, 1.0}), "Unreal scale");
  const double h = cd_horizontal_fov_deg(50.0, 16.0 / 9.0);
  check(near(h, 2.0 * std::atan(std::tan(25.0 * M_PI / 180.0) * 16.0 / 9.0) * 180.0 / M_PI, 1e-9),
        "horizontal field of view of 50 deg vertical at 16:9");
  check(near(cd_vertical_fov_deg(h, 16.0 / 9.0), 50.0, 1e-9), "vertical field of view back");
}

void round_trips() {
  std::srand(7);
  auto r = [] { return 4.0 * std::rand() / RAND_MAX - 2.0; };
  for (int i = 0; i < 200; ++i) {
    const cd_vec3 p{r(), r(), r()};
    cd_quat q{r(), r(), r(), r()};
    const double n = std::sqrt(q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w);
    q = {q.x / n, q.y / n, q.z / n, q.w / n};
    check(near3(cd_to_unity_position(cd_from_unity_position(p)), p), "Unity position round trip");
    check(near4(cd_to_unity_rotation(cd_from_unity_rotation(q)), q), "Unity rotation round trip");
    check(near3(cd_to_unreal_position(cd_from_unreal_position(p)), p, 1e-9), "Unreal position round trip");
    check(near4(cd_to_unreal_rotation(cd_from_unreal_rotation(q)), q), "Unreal rotation round trip");
    check(near3(cd_to_unreal_scale(cd_from_unreal_scale(p)), p), "Unreal scale round trip");
  }
  float tri[9] = {1, 2, 3, 4, 5, 6, 7, 8, 9};
  uint32_t idx[3] = {0, 1, 2};
  cd_from_unity_vertices(tri, 3);
  check(tri[2] == -3.0f && tri[5] == -6.0f && tri[1] == 2.0f, "Unity vertices mirrored in z");
  cd_flip_winding(idx, 3);
  check(idx[0] == 0 && idx[1] == 2 && idx[2] == 1, "winding reversed");
}

void addresses() {
  char reason[256];
  check(cd_check_address("127.0.0.1:50051", reason, sizeof reason) == CD_OK, "host:port parses");
  check(cd_check_address("localhost:1", nullptr, 0) == CD_OK, "a name parses");
  const char* bad[] = {"", "no-port", "127.0.0.1:", "127.0.0.1:0", "127.0.0.1:70000", ":50051", "host:port"};
  for (const char* address : bad) {
    check(cd_check_address(address, reason, sizeof reason) == CD_INVALID_ARGUMENT, address);
  }
  cd_config config;
  cd_config_init(&config);
  config.address = "no-port";
  cd_client* client = reinterpret_cast<cd_client*>(1);
  check(cd_client_create(&config, &client) == CD_INVALID_ARGUMENT && client == nullptr,
        "a client with an address that does not parse is refused, *out NULL");
}

// Keys and TLS options, checked before any connection: cd_check_config says why, never the key.
void keys_and_tls_options() {
  char reason[256];
  cd_config config;
  cd_config_init(&config);
  config.address = "grpcs://localhost:443";
  check(cd_check_config(&config, reason, sizeof reason) == CD_OK, "grpcs:// parses (the system's roots)");
  config.key = "cdk_0123456789ab_secret with a space";
  check(cd_check_config(&config, reason, sizeof reason) == CD_INVALID_ARGUMENT, "a key with a space is refused");
  check(std::strstr(reason, "key") != nullptr && std::strstr(reason, "secret") == nullptr,
        "the reason names the key, not its text");
  cd_client* client = nullptr;
  check(cd_client_create(&config, &client) == CD_INVALID_ARGUMENT && client == nullptr, "create refuses it too");
  config.key = "cdk_0123456789ab_secret";
  config.ca_file = "/nonexistent/ca.pem";
  check(cd_check_config(&config, reason, sizeof reason) == CD_INVALID_ARGUMENT &&
            std::strstr(reason, "/nonexistent/ca.pem") != nullptr,
        "a ca_file that cannot be read is refused, named");
  config.address = "127.0.0.1:50051";
  config.ca_file = "ca.pem";
  check(cd_check_config(&config, reason, sizeof reason) == CD_INVALID_ARGUMENT &&
            std::strstr(reason, "grpcs://") != nullptr,
        "a ca_file for a plaintext address is refused");
  check(cd_check_config(nullptr, reason, sizeof reason) == CD_INVALID_ARGUMENT, "a NULL config is refused");
}

void game_thread_without_a_session() {
  cd_config config;
  cd_config_init(&config);
  config.address = "127.0.0.1:1";   // nothing listens: the client does not connect until a session opens
  cd_client* client = nullptr;
  check(cd_client_create(&config, &client) == CD_OK && client != nullptr, "a client starts without a server");
  cd_state state{};
  state.transform.rotation.w = 1.0;
  check(cd_frame_submit(client, 1, 0.0, &state, 1) == CD_FAILED_PRECONDITION, "no session: submit refused");
  cd_pose pose;
  check(cd_pose_poll(client, &pose) == CD_NOT_FOUND, "no pose yet");
  cd_event event;
  check(cd_event_poll(client, &event) != CD_OK, "no event yet");
  cd_client_destroy(client);
}

// Issue 40: waits from 0.1 s doubling to the 0.5 s cap, each half fixed and half jitter, never past
// the retry window, which once spent says give up (the Python SDK's test_retry.py, same numbers).
void backoff_within_a_window() {
  using camdirector::sdk::backoff_delay_s;
  const double low[] = {0.05, 0.1, 0.2, 0.25, 0.25};
  const double high[] = {0.1, 0.2, 0.4, 0.5, 0.5};
  for (int tries = 0; tries < 5; ++tries) {
    check(near(backoff_delay_s(0.1, 0.5, 30.0, 1.0, tries, 0.0), low[tries]), "backoff, no jitter drawn: half the cap");
    check(near(backoff_delay_s(0.1, 0.5, 30.0, 1.0, tries, 1.0), high[tries]), "backoff, all jitter drawn: the cap");
  }
  check(near(backoff_delay_s(0.1, 0.5, 30.0, 1.0, 1, 0.5), 0.15), "equal jitter: 0.1 + 0.5 * 0.1");
  check(near(backoff_delay_s(0.1, 0.5, 30.0, 29.95, 4, 1.0), 0.05, 1e-9), "a wait ends with the window");
  check(backoff_delay_s(0.1, 0.5, 30.0, 30.0, 4, 1.0) < 0.0, "a spent window: give up");
  check(backoff_delay_s(0.1, 0.5, 30.0, 1.0, 1000, 1.0) == 0.5, "many tries stay at the cap");
  check(near(backoff_delay_s(0.1, 0.5, 30.0, 1.0, 0, std::nan("")), 0.075), "a NaN from the random source: no jitter");
}

void resend_from_of_a_data_loss() {
  uint64_t frame = 0;
  check(camdirector::sdk::parse_resend_from("session s: state lost after frame 20: resend from 21 (its node was lost)",
                                            &frame) && frame == 21,
        "the server's DATA_LOSS message gives K");
  check(!camdirector::sdk::parse_resend_from("checksum mismatch", &frame), "a DATA_LOSS without a resend");
  check(!camdirector::sdk::parse_resend_from("resend from here", &frame), "no number: no resend");
}

void retry_defaults_and_refusals() {
  cd_config config;
  cd_config_init(&config);
  check(config.retry_window_s == 30.0 && config.initial_backoff_s == 0.1 && config.reconnect_max_s == 0.5 &&
            config.frame_timeout_s == 3.0 && config.resend_history_frames == 600 && config.random == nullptr,
        "retry defaults: 30 s window, 0.1 s first wait, 0.5 s cap, 3 s frame deadline, 600 frames kept");
  config.address = "127.0.0.1:50051";
  char reason[256];
  config.retry_window_s = std::numeric_limits<double>::infinity();
  check(cd_check_config(&config, reason, sizeof reason) == CD_INVALID_ARGUMENT, "an infinite retry window is refused");
  config.retry_window_s = 30.0;
  config.resend_history_frames = 1u << 20;
  check(cd_check_config(&config, reason, sizeof reason) == CD_INVALID_ARGUMENT &&
            std::strstr(reason, "resend_history_frames") != nullptr,
        "too many frames to keep is refused, named");
}

}  // namespace

int main() {
  backoff_within_a_window();
  resend_from_of_a_data_loss();
  retry_defaults_and_refusals();
  known_values();
  round_trips();
  addresses();
  keys_and_tls_options();
  game_thread_without_a_session();
  if (failures == 0) std::puts("all unit tests passed");
  return failures == 0 ? 0 : 1;
}
