// The C interface: client setup, the blocking session calls (each with its own deadline), and
// the game thread's non-blocking submit / poll functions (no allocation, short critical sections).
#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <iterator>
#include <new>

#include "client_impl.h"

using camdirector::sdk::Clock;
using camdirector::sdk::copy_cstr;
using Phase = camdirector::sdk::Phase;
namespace pb = camdirector::v1;

namespace {

constexpr double kDefaultTimeoutS = 10.0;
constexpr double kDestroyCloseTimeoutS = 1.0;
constexpr uint32_t kMaxQueueCapacity = 1u << 16;
constexpr uint32_t kMaxStates = 1u << 16;
constexpr uint32_t kMaxResendHistoryFrames = 1u << 16;  // 18 min at 60 Hz

const char* const kStatusNames[] = {
    "OK",          "CANCELLED",         "UNKNOWN",   "INVALID_ARGUMENT", "DEADLINE_EXCEEDED", "NOT_FOUND",
    "ALREADY_EXISTS", "PERMISSION_DENIED", "RESOURCE_EXHAUSTED", "FAILED_PRECONDITION", "ABORTED",
    "OUT_OF_RANGE", "UNIMPLEMENTED",     "INTERNAL",  "UNAVAILABLE",      "DATA_LOSS",         "UNAUTHENTICATED",
};

double timeout_or_default(double timeout_s) {
  return timeout_s > 0.0 && std::isfinite(timeout_s) ? timeout_s : kDefaultTimeoutS;
}

// For our own waits (steady clock).
Clock::time_point deadline_of(double timeout_s) {
  return Clock::now() +
         std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(timeout_or_default(timeout_s)));
}

// For gRPC's (system clock).
std::chrono::system_clock::time_point rpc_deadline_of(double timeout_s) {
  return camdirector::sdk::grpc_deadline(timeout_or_default(timeout_s));
}

bool finite_transform(const cd_transform& t) {
  const double v[10] = {t.position.x, t.position.y, t.position.z, t.rotation.x, t.rotation.y,
                        t.rotation.z, t.rotation.w, t.scale.x,    t.scale.y,    t.scale.z};
  for (double x : v) {
    if (!std::isfinite(x)) return false;
  }
  return true;
}

cd_state* states_of(cd_client* client, uint32_t ring_index) {
  return &client->ring_states[static_cast<size_t>(ring_index) * client->config.max_states];
}

// Adds the carried states whose slot the frame at ring_index does not mention (room allowing).
void carry_into(cd_client* client, uint32_t ring_index, uint32_t carried) {
  camdirector::sdk::QueuedFrame& frame = client->ring[ring_index];
  cd_state* states = states_of(client, ring_index);
  const uint32_t mentioned = frame.count;
  for (uint32_t c = 0; c < carried && frame.count < client->config.max_states; ++c) {
    const cd_state& old_state = client->carry_states[c];
    bool present = false;
    for (uint32_t i = 0; i < mentioned && !present; ++i) present = states[i].slot == old_state.slot;
    if (!present) states[frame.count++] = old_state;
  }
}

cd_status to_status(grpc::StatusCode code) { return static_cast<cd_status>(static_cast<int>(code)); }

cd_status fail(cd_client* client, cd_status code, const std::string& message) {
  std::lock_guard<std::mutex> guard(client->mu);
  client->set_error_locked(code, message);
  return code;
}

// A blocking RPC's result: OK, or its status with "RPC: message" kept for cd_last_error.
cd_status rpc_result(cd_client* client, const char* rpc, const grpc::Status& status) {
  if (status.ok()) return CD_OK;
  return fail(client, to_status(status.error_code()),
              std::string(rpc) + " on " + client->target + ": " +
                  camdirector::sdk::explain_failure(status, client->tls));
}

// The streaming session's id into a request that names it, and its route key onto the call's
// context; FAILED_PRECONDITION (also the client's last error) when no session streams.
template <typename Request>
cd_status name_streaming_session(cd_client* client, Request* request, grpc::ClientContext* context) {
  std::lock_guard<std::mutex> guard(client->mu);
  if (client->phase != Phase::kStream) {
    client->set_error_locked(CD_FAILED_PRECONDITION, "no session is streaming on this client");
    return CD_FAILED_PRECONDITION;
  }
  request->set_session_id(client->session_id);
  client->add_call_metadata(context, client->route_key);
  return CD_OK;
}

// What cd_client_create makes of a config: the defaults filled in, the address parsed, the key
// and the CA file read.
struct Setup {
  cd_config config{};
  std::string target;
  bool tls = false;
  std::string authorization;  // "Bearer KEY", "" without a key
  std::string ca_pem;         // the CA file's certificates, "" for the system's roots
};

// The Setup of a config; false and the reason (never the key) for one cd_client_create refuses.
bool setup_of(const cd_config& in, Setup* out, std::string* error) {
  cd_config& c = out->config;
  cd_config_init(&c);
  if (in.queue_capacity) c.queue_capacity = in.queue_capacity;
  if (in.max_states) c.max_states = in.max_states;
  if (in.max_in_flight) c.max_in_flight = in.max_in_flight;
  if (in.reconnect_max_s > 0.0) c.reconnect_max_s = in.reconnect_max_s;
  if (in.retry_window_s > 0.0) c.retry_window_s = in.retry_window_s;
  if (in.initial_backoff_s > 0.0) c.initial_backoff_s = in.initial_backoff_s;
  if (in.frame_timeout_s > 0.0) c.frame_timeout_s = in.frame_timeout_s;
  if (in.stall_timeout_s > 0.0) c.frame_timeout_s = in.stall_timeout_s;  // its former name wins where set
  if (in.resend_history_frames) c.resend_history_frames = in.resend_history_frames;
  c.random = in.random;
  c.random_user = in.random_user;
  if (in.max_message_bytes) c.max_message_bytes = in.max_message_bytes;
  c.io_poll_interval_ms = std::min<uint32_t>(in.io_poll_interval_ms, 1000);
  c.wait_for_server = in.wait_for_server;
  if (!camdirector::sdk::parse_address(in.address, &out->target, &out->tls, error)) return false;
  if (c.queue_capacity > kMaxQueueCapacity || c.max_states > kMaxStates ||
      static_cast<uint64_t>(c.queue_capacity) * c.max_states > (1u << 22) || !std::isfinite(c.frame_timeout_s) ||
      !std::isfinite(c.reconnect_max_s) || !std::isfinite(c.retry_window_s) || !std::isfinite(c.initial_backoff_s)) {
    *error = "queue_capacity or max_states over 65536 (or their product over 4194304), or a timeout not finite";
    return false;
  }
  if (c.resend_history_frames > kMaxResendHistoryFrames) {
    *error = "resend_history_frames over " + std::to_string(kMaxResendHistoryFrames);
    return false;
  }
  const bool given = in.key != nullptr && *in.key != '\0';
  const char* key = given ? in.key : std::getenv(camdirector::sdk::kKeyEnv);
  if (key != nullptr && *key != '\0') {
    for (const char* k = key; *k != '\0'; ++k) {
      if (*k < '!' || *k > '~') {  // what a header value may hold, no space; a byte over 0x7f is negative
        *error = std::string(given ? "key" : "the CAMDIRECTOR_KEY environment variable") +
                 " holds a space or a character a header cannot carry (the key is not shown)";
        return false;
      }
    }
    out->authorization = std::string("Bearer ") + key;
  }
  if (in.ca_file != nullptr && *in.ca_file != '\0') {
    const std::string quoted = std::string("'") + in.ca_file + "'";
    if (!out->tls) {
      *error = "ca_file is for grpcs:// addresses (gRPC over TLS); " + std::string(in.address) + " is plaintext";
      return false;
    }
    std::ifstream file(in.ca_file, std::ios::binary);
    if (!file) {
      *error = "ca_file " + quoted + " cannot be read";
      return false;
    }
    out->ca_pem.assign(std::istreambuf_iterator<char>(file), std::istreambuf_iterator<char>());
    if (out->ca_pem.find("-----BEGIN CERTIFICATE-----") == std::string::npos) {
      *error = "ca_file " + quoted + " holds no PEM certificate";
      return false;
    }
  }
  return true;
}

cd_status open_with(cd_client* client, pb::CreateSessionRequest request, double timeout_s) {
  {
    std::lock_guard<std::mutex> guard(client->mu);
    if (client->phase == Phase::kFailed) client->reset_session_locked();
    if (client->phase != Phase::kIdle) {
      client->set_error_locked(CD_FAILED_PRECONDITION, "a session is open on this client: close it first");
      return CD_FAILED_PRECONDITION;
    }
  }
  if (request.client_protocol() == 0) request.set_client_protocol(CD_PROTOCOL);  // kept for recreations too
  const std::vector<std::string> slots = camdirector::sdk::slot_ids_of(request);
  if (slots.size() > client->config.max_states) {
    return fail(client, CD_INVALID_ARGUMENT,
                std::to_string(slots.size()) + " targets and dynamic objects, over max_states (" +
                    std::to_string(client->config.max_states) + ")");
  }
  std::string route_key = camdirector::sdk::new_route_key();  // this session's, from its creation on
  grpc::ClientContext context;
  context.set_deadline(rpc_deadline_of(timeout_s));
  context.set_wait_for_ready(client->config.wait_for_server != 0);
  client->add_call_metadata(&context, route_key);
  pb::CreateSessionResponse response;
  const grpc::Status status = client->stub->CreateSession(&context, request, &response);
  if (status.error_code() == grpc::StatusCode::DEADLINE_EXCEEDED &&
      client->channel->GetState(false) != GRPC_CHANNEL_READY) {
    return fail(client, CD_DEADLINE_EXCEEDED,
                "CreateSession on " + client->target + ": the server was not reachable before the deadline (" +
                    status.error_message() + ")");
  }
  if (!status.ok()) return rpc_result(client, "CreateSession", status);

  std::lock_guard<std::mutex> guard(client->mu);
  if (client->phase != Phase::kIdle) {  // another thread opened one meanwhile
    client->set_error_locked(CD_FAILED_PRECONDITION, "a session was opened on this client meanwhile");
    return CD_FAILED_PRECONDITION;
  }
  client->request = std::move(request);
  client->session_id = response.session_id();
  client->route_key = std::move(route_key);
  client->slot_ids = slots;
  client->slot_transforms.assign(slots.size() * camdirector::sdk::kPackedWidth, 0.0);
  client->slot_known.assign(slots.size(), 0);
  client->send_all_known = false;
  client->generation = 1;
  client->stats.generation = 1;
  client->ring_head = 0;
  client->ring_size = 0;
  client->any_submitted = false;
  client->has_pose = false;
  client->cut_pending = false;
  client->outage = false;
  client->ever_streamed = false;
  client->recreated_unanswered = false;
  client->unavailable_while_ready = 0;
  client->recreate_presumed = false;
  client->retrying = false;
  client->forget_sent_locked();
  client->retry_at = Clock::now();
  client->phase = Phase::kStream;
  client->io_cv.notify_one();
  return CD_OK;
}

}  // namespace

void cd_client::push_event_locked(int kind, int status, const std::string& message) {
  if (event_count == events.size()) {
    event_head = (event_head + 1) % events.size();
    event_count -= 1;
    stats.events_dropped += 1;
  }
  cd_event& e = events[(event_head + event_count) % events.size()];
  e = cd_event{};
  e.kind = kind;
  e.status = status;
  e.generation = generation;
  e.frame = last_frame;
  e.time_s = camdirector::sdk::seconds_since_epoch(Clock::now());
  copy_cstr(e.session_id, sizeof e.session_id, session_id);
  copy_cstr(e.message, sizeof e.message, message);
  event_count += 1;
}

void cd_client::set_error_locked(int code, const std::string& message) {
  last_error_code = code;
  last_error = message;
}

void cd_client::reset_session_locked() {
  phase = Phase::kIdle;
  session_id.clear();
  route_key.clear();
  ring_head = 0;
  ring_size = 0;
  forget_sent_locked();
  has_pose = false;
  cut_pending = false;
  any_submitted = false;
  slot_ids.clear();
  caller_cv.notify_all();
  io_cv.notify_one();
}

extern "C" {

const char* cd_version(void) { return CAMDIRECTOR_VERSION; }

uint32_t cd_protocol(void) { return CD_PROTOCOL; }

const char* cd_status_name(int status) {
  if (status >= 0 && status < static_cast<int>(sizeof kStatusNames / sizeof kStatusNames[0])) {
    return kStatusNames[status];
  }
  return "UNKNOWN_STATUS";
}

double cd_now_s(void) { return camdirector::sdk::seconds_since_epoch(Clock::now()); }

void cd_config_init(cd_config* config) {
  if (config == nullptr) return;
  *config = cd_config{};
  config->queue_capacity = 8;
  config->max_states = 64;
  config->max_in_flight = 2;
  config->reconnect_max_s = 0.5;  // a balancer back is found within it (the Python SDK's max_backoff_s)
  config->retry_window_s = 30.0;
  config->initial_backoff_s = 0.1;
  // The last resort against a hung node: a balancer's checks take one out within 1.2 s and
  // keepalive pings find a hung server reached directly within 2 s; a frame that is only slow
  // (a RIG_TRACKS session's first, a restore on a loaded machine) can take over 1 s.
  config->frame_timeout_s = 3.0;
  config->resend_history_frames = 600;  // 10 s at 60 Hz
  config->wait_for_server = 0;
  config->max_message_bytes = 64u << 20;
}

void cd_style_init(cd_style* style) {
  if (style == nullptr) return;
  *style = cd_style{};
  const double unset = std::nan("");
  style->screen_a_x = style->screen_a_y = style->screen_b_x = style->screen_b_y = unset;
  style->gaze_room_m = style->preferred_theta_ratio = style->preferred_phi_deg = unset;
  style->response_time_s = style->max_speed_m_s = style->max_accel_m_s2 = unset;
  style->min_shot_s = style->max_shot_s = unset;
}

void cd_session_desc_init(cd_session_desc* desc) {
  if (desc == nullptr) return;
  *desc = cd_session_desc{};
  cd_style_init(&desc->style);
}

cd_status cd_check_address(const char* address, char* buf, size_t size) {
  std::string target, error;
  bool tls = false;
  const bool ok = camdirector::sdk::parse_address(address, &target, &tls, &error);
  copy_cstr(buf, size, error);
  return ok ? CD_OK : CD_INVALID_ARGUMENT;
}

cd_status cd_check_config(const cd_config* config, char* buf, size_t size) {
  std::string error = "config is NULL";
  Setup setup;
  const bool ok = config != nullptr && setup_of(*config, &setup, &error);
  copy_cstr(buf, size, ok ? std::string() : error);
  return ok ? CD_OK : CD_INVALID_ARGUMENT;
}

cd_status cd_client_create(const cd_config* config, cd_client** out) {
  if (out == nullptr) return CD_INVALID_ARGUMENT;
  *out = nullptr;
  if (config == nullptr) return CD_INVALID_ARGUMENT;
  try {
    Setup setup;
    std::string error;
    if (!setup_of(*config, &setup, &error)) return CD_INVALID_ARGUMENT;
    const cd_config& c = setup.config;  // its strings are NULL: the caller owns them
    auto client = std::make_unique<cd_client>();
    client->config = c;
    client->target = setup.target;
    client->tls = setup.tls;
    client->authorization = std::move(setup.authorization);
    grpc::ChannelArguments args;
    args.SetMaxReceiveMessageSize(static_cast<int>(std::min<uint32_t>(c.max_message_bytes, INT32_MAX)));
    args.SetMaxSendMessageSize(static_cast<int>(std::min<uint32_t>(c.max_message_bytes, INT32_MAX)));
    // The channel reconnects as often as the I/O thread tries again (gRPC's own first wait is 1 s,
    // growing to 120 s), and pings the server every second while a stream is open, closing a
    // connection that does not answer within a second (a hung server reached directly).
    const int initial_ms = std::max(1, static_cast<int>(std::lround(c.initial_backoff_s * 1000.0)));
    args.SetInt(GRPC_ARG_INITIAL_RECONNECT_BACKOFF_MS, initial_ms);
    args.SetInt(GRPC_ARG_MIN_RECONNECT_BACKOFF_MS, initial_ms);
    args.SetInt(GRPC_ARG_MAX_RECONNECT_BACKOFF_MS,
                std::max(initial_ms, static_cast<int>(std::lround(std::min(c.reconnect_max_s, 3600.0) * 1000.0))));
    args.SetInt(GRPC_ARG_KEEPALIVE_TIME_MS, 1000);
    args.SetInt(GRPC_ARG_KEEPALIVE_TIMEOUT_MS, 1000);
    args.SetInt(GRPC_ARG_USE_LOCAL_SUBCHANNEL_POOL, 1);  // this client's connection is its own
    args.SetInt(GRPC_ARG_ENABLE_RETRIES, 0);              // the SDK decides what to retry
    std::shared_ptr<grpc::ChannelCredentials> credentials = grpc::InsecureChannelCredentials();
    if (setup.tls) {
      grpc::SslCredentialsOptions ssl;
      ssl.pem_root_certs = setup.ca_pem;  // empty: gRPC's default roots (the system's)
      credentials = grpc::SslCredentials(ssl);
    }
    client->channel = grpc::CreateCustomChannel(setup.target, credentials, args);
    client->stub = pb::Director::NewStub(client->channel);
    client->ring.resize(c.queue_capacity);
    client->ring_states.resize(static_cast<size_t>(c.queue_capacity) * c.max_states);
    client->send_states.resize(c.max_states);
    client->carry_states.resize(c.max_states);
    client->send_session_id.reserve(64);
    // Kept frames: at least those a stream may have in flight. Their messages grow on first use
    // (on the I/O thread) and are reused after.
    const size_t kept = std::max(c.resend_history_frames, c.max_in_flight);
    client->history.resize(kept);
    client->history_previous.resize(kept);
    client->history_sent_at.resize(kept);
    client->jitter.seed(std::random_device{}());
    cd_client* raw = client.get();
    client->io_thread = std::thread([raw] { raw->io_loop(); });
    *out = client.release();
    return CD_OK;
  } catch (const std::exception&) {
    return CD_RESOURCE_EXHAUSTED;
  }
}

void cd_client_destroy(cd_client* client) {
  if (client == nullptr) return;
  std::string open_id, route_key;
  {
    std::lock_guard<std::mutex> guard(client->mu);
    if (client->phase == Phase::kStream || client->phase == Phase::kRecreate) {
      open_id = client->session_id;
      route_key = client->route_key;
    }
    client->stopping = true;
    if (client->io_call != nullptr) client->io_call->TryCancel();
    client->io_cv.notify_one();
  }
  if (client->io_thread.joinable()) client->io_thread.join();
  if (!open_id.empty()) {  // best effort: the server would reclaim it after its resume window
    grpc::ClientContext context;
    context.set_deadline(rpc_deadline_of(kDestroyCloseTimeoutS));
    client->add_call_metadata(&context, route_key);
    pb::CloseSessionRequest request;
    request.set_session_id(open_id);
    pb::CloseSessionResponse response;
    (void)client->stub->CloseSession(&context, request, &response);
  }
  delete client;
}

cd_status cd_last_error(cd_client* client, char* buf, size_t size) {
  if (client == nullptr) return CD_INVALID_ARGUMENT;
  std::lock_guard<std::mutex> guard(client->mu);
  copy_cstr(buf, size, client->last_error);
  return static_cast<cd_status>(client->last_error_code);
}

cd_status cd_session_open(cd_client* client, const cd_session_desc* desc, double timeout_s) {
  if (client == nullptr) return CD_INVALID_ARGUMENT;
  if (desc == nullptr) return fail(client, CD_INVALID_ARGUMENT, "desc is NULL");
  try {
    pb::CreateSessionRequest request;
    std::string error;
    if (!camdirector::sdk::build_request(*desc, &request, &error)) return fail(client, CD_INVALID_ARGUMENT, error);
    return open_with(client, std::move(request), timeout_s);
  } catch (const std::exception& e) {
    return fail(client, CD_INTERNAL, e.what());
  }
}

cd_status cd_session_open_serialized(cd_client* client, const void* bytes, size_t size, double timeout_s) {
  if (client == nullptr) return CD_INVALID_ARGUMENT;
  if (bytes == nullptr && size > 0) return fail(client, CD_INVALID_ARGUMENT, "request is NULL");
  try {
    pb::CreateSessionRequest request;
    if (size > static_cast<size_t>(INT32_MAX) || !request.ParseFromArray(bytes, static_cast<int>(size))) {
      return fail(client, CD_INVALID_ARGUMENT, "the bytes are not a serialized camdirector.v1.CreateSessionRequest");
    }
    return open_with(client, std::move(request), timeout_s);
  } catch (const std::exception& e) {
    return fail(client, CD_INTERNAL, e.what());
  }
}

cd_status cd_session_update_style(cd_client* client, const cd_style* style, double timeout_s) {
  if (client == nullptr) return CD_INVALID_ARGUMENT;
  if (style == nullptr) return fail(client, CD_INVALID_ARGUMENT, "style is NULL");
  try {
    pb::UpdateStyleRequest request;
    grpc::ClientContext context;
    if (const cd_status named = name_streaming_session(client, &request, &context); named != CD_OK) return named;
    camdirector::sdk::fill_style(*style, request.mutable_style());
    context.set_deadline(rpc_deadline_of(timeout_s));
    pb::UpdateStyleResponse response;
    const grpc::Status status = client->stub->UpdateStyle(&context, request, &response);
    if (!status.ok()) return rpc_result(client, "UpdateStyle", status);
    std::lock_guard<std::mutex> guard(client->mu);
    *client->request.mutable_style() = request.style();  // a recreated session gets it too
    return CD_OK;
  } catch (const std::exception& e) {
    return fail(client, CD_INTERNAL, e.what());
  }
}

cd_status cd_session_take_shot(cd_client* client, const char* const* subject_ids, uint32_t subject_count, int kind,
                               int release, cd_shot* out, double timeout_s) {
  if (client == nullptr) return CD_INVALID_ARGUMENT;
  if (subject_count > 0 && subject_ids == nullptr) return fail(client, CD_INVALID_ARGUMENT, "subject_ids is NULL");
  try {
    pb::TakeShotRequest request;
    grpc::ClientContext context;
    if (const cd_status named = name_streaming_session(client, &request, &context); named != CD_OK) return named;
    for (uint32_t i = 0; i < subject_count; ++i) {
      if (subject_ids[i] == nullptr) return fail(client, CD_INVALID_ARGUMENT, "a subject id is NULL");
      request.add_subject_ids(subject_ids[i]);
    }
    request.set_kind(static_cast<pb::ShotKind>(kind));
    request.set_release(release != 0);
    context.set_deadline(rpc_deadline_of(timeout_s));
    pb::TakeShotResponse response;
    const grpc::Status status = client->stub->TakeShot(&context, request, &response);
    if (!status.ok()) return rpc_result(client, "TakeShot", status);
    if (out != nullptr) {
      *out = cd_shot{};
      out->kind = response.shot().kind();
      out->held = response.shot().held() ? 1 : 0;
      std::string joined;
      for (const std::string& id : response.shot().subject_ids()) joined += (joined.empty() ? "" : ",") + id;
      copy_cstr(out->subjects, sizeof out->subjects, joined);
      copy_cstr(out->reason, sizeof out->reason, response.shot().reason());
    }
    return CD_OK;
  } catch (const std::exception& e) {
    return fail(client, CD_INTERNAL, e.what());
  }
}

cd_status cd_session_flush(cd_client* client, double timeout_s) {
  if (client == nullptr) return CD_INVALID_ARGUMENT;
  std::unique_lock<std::mutex> lock(client->mu);
  const bool done = client->caller_cv.wait_until(lock, deadline_of(timeout_s), [client] {
    const bool live = client->phase == Phase::kStream || client->phase == Phase::kRecreate;
    return !live || (client->ring_size == 0 && client->unanswered() == 0 && !client->write_busy);
  });
  if (!done) {
    client->set_error_locked(CD_DEADLINE_EXCEEDED, "flush: frames still unanswered at the deadline");
    return CD_DEADLINE_EXCEEDED;
  }
  if (client->phase == Phase::kFailed) {
    client->set_error_locked(CD_UNAVAILABLE, "flush: the session is lost (see the SESSION_FAILED event)");
    return CD_UNAVAILABLE;
  }
  return CD_OK;
}

cd_status cd_session_close(cd_client* client, uint64_t* frames_answered, double timeout_s) {
  if (client == nullptr) return CD_INVALID_ARGUMENT;
  const Clock::time_point deadline = deadline_of(timeout_s);
  std::string id, route_key;
  bool failed = false;
  {
    std::unique_lock<std::mutex> lock(client->mu);
    if (client->phase == Phase::kIdle) {
      client->set_error_locked(CD_FAILED_PRECONDITION, "no session is open on this client");
      return CD_FAILED_PRECONDITION;
    }
    failed = client->phase == Phase::kFailed;
    client->phase = Phase::kClosing;
    if (client->io_call != nullptr) client->io_call->TryCancel();
    client->io_cv.notify_one();
    const bool ended = client->caller_cv.wait_until(
        lock, deadline, [client] { return client->stream == nullptr && !client->stream_done; });
    if (!ended) {
      client->set_error_locked(CD_DEADLINE_EXCEEDED, "close: the stream did not end before the deadline");
      return CD_DEADLINE_EXCEEDED;
    }
    id = client->session_id;
    route_key = client->route_key;
  }
  grpc::Status status;
  pb::CloseSessionResponse response;
  if (!failed) {
    grpc::ClientContext context;
    const double left_s = std::chrono::duration<double>(deadline - Clock::now()).count();
    context.set_deadline(camdirector::sdk::grpc_deadline(std::max(left_s, 0.1)));
    client->add_call_metadata(&context, route_key);
    pb::CloseSessionRequest request;
    request.set_session_id(id);
    status = client->stub->CloseSession(&context, request, &response);
  }
  {
    std::lock_guard<std::mutex> guard(client->mu);
    client->reset_session_locked();
  }
  if (frames_answered != nullptr) *frames_answered = response.frames();
  return rpc_result(client, "CloseSession", status);
}

cd_status cd_session_id(cd_client* client, char* buf, size_t size) {
  if (client == nullptr) return CD_INVALID_ARGUMENT;
  std::lock_guard<std::mutex> guard(client->mu);
  if (buf != nullptr && size > 0) {
    const size_t n = std::min(client->session_id.size(), size - 1);
    std::memcpy(buf, client->session_id.data(), n);
    buf[n] = '\0';
  }
  return client->session_id.empty() ? CD_NOT_FOUND : CD_OK;
}

int32_t cd_session_slot(cd_client* client, const char* id) {
  if (client == nullptr || id == nullptr) return -1;
  std::lock_guard<std::mutex> guard(client->mu);
  for (size_t i = 0; i < client->slot_ids.size(); ++i) {
    if (client->slot_ids[i] == id) return static_cast<int32_t>(i);
  }
  return -1;
}

cd_status cd_frame_submit(cd_client* client, uint64_t frame, double time_s, const cd_state* states,
                          uint32_t state_count) {
  if (client == nullptr) return CD_INVALID_ARGUMENT;
  bool finite = std::isfinite(time_s) && (state_count == 0 || states != nullptr);
  for (uint32_t i = 0; finite && i < state_count; ++i) finite = finite_transform(states[i].transform);
  bool wake = false;
  {
    std::lock_guard<std::mutex> guard(client->mu);
    cd_status refused = CD_OK;
    if (client->phase != Phase::kStream && client->phase != Phase::kRecreate) {
      refused = CD_FAILED_PRECONDITION;
    } else if (!finite) {
      refused = CD_INVALID_ARGUMENT;
    } else if (state_count > client->config.max_states) {
      refused = CD_RESOURCE_EXHAUSTED;
    } else if (client->any_submitted && (frame <= client->last_frame || time_s < client->last_time_s)) {
      refused = CD_OUT_OF_RANGE;
    } else {
      for (uint32_t i = 0; i < state_count; ++i) {
        if (states[i].slot >= client->slot_ids.size()) refused = CD_INVALID_ARGUMENT;
      }
    }
    if (refused != CD_OK) {
      client->stats.frames_refused += 1;
      return refused;
    }
    const uint32_t capacity = client->config.queue_capacity;
    uint32_t carried = 0;
    if (client->ring_size == capacity) {  // full: the oldest frame makes room
      const uint32_t oldest = client->ring_head;
      carried = client->ring[oldest].count;
      std::memcpy(client->carry_states.data(), states_of(client, oldest), sizeof(cd_state) * carried);
      client->ring_head = (client->ring_head + 1) % capacity;
      client->ring_size -= 1;
      client->stats.frames_dropped += 1;
    }
    const uint32_t index = (client->ring_head + client->ring_size) % capacity;
    camdirector::sdk::QueuedFrame& slot = client->ring[index];
    slot.frame = frame;
    slot.time_s = time_s;
    slot.count = state_count;
    if (state_count > 0) std::memcpy(states_of(client, index), states, sizeof(cd_state) * state_count);
    // "Not mentioned: unchanged": the dropped frame's transforms still hold for the slots the
    // next frame does not mention, so they move into it rather than being lost.
    if (carried > 0) carry_into(client, client->ring_head, carried);
    client->ring_size += 1;
    client->stats.frames_submitted += 1;
    client->any_submitted = true;
    client->last_frame = frame;
    client->last_time_s = time_s;
    wake = client->io_waiting && client->config.io_poll_interval_ms == 0;
  }
  if (wake) client->io_cv.notify_one();
  return CD_OK;
}

cd_status cd_pose_poll(cd_client* client, cd_pose* out) {
  if (client == nullptr || out == nullptr) return CD_INVALID_ARGUMENT;
  std::lock_guard<std::mutex> guard(client->mu);
  if (!client->has_pose) return CD_NOT_FOUND;
  *out = client->latest;
  out->cut_since_last_poll = client->cut_pending ? 1 : 0;
  client->cut_pending = false;
  return CD_OK;
}

cd_status cd_event_poll(cd_client* client, cd_event* out) {
  if (client == nullptr || out == nullptr) return CD_INVALID_ARGUMENT;
  std::lock_guard<std::mutex> guard(client->mu);
  if (client->event_count == 0) return CD_NOT_FOUND;
  *out = client->events[client->event_head];
  client->event_head = (client->event_head + 1) % client->events.size();
  client->event_count -= 1;
  return CD_OK;
}

void cd_client_stats(cd_client* client, cd_stats* out) {
  if (client == nullptr || out == nullptr) return;
  std::lock_guard<std::mutex> guard(client->mu);
  *out = client->stats;
  out->queued = client->ring_size;
  out->in_flight = client->in_flight();
  switch (client->phase) {
    case Phase::kIdle:
    case Phase::kClosing:
      out->state = CD_STATE_NO_SESSION;
      break;
    case Phase::kStream:
      out->state = client->stream != nullptr && client->stream_answered ? CD_STATE_STREAMING
                   : client->outage                                       ? CD_STATE_RECONNECTING
                                                                          : CD_STATE_CONNECTING;
      break;
    case Phase::kRecreate:
      out->state = CD_STATE_RECREATING;
      break;
    case Phase::kFailed:
      out->state = CD_STATE_FAILED;
      break;
  }
}

}  // extern "C"
