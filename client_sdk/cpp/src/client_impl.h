// The client behind the opaque cd_client handle: shared state, the frame queue, the stream
// reactor and the I/O thread's loop. Internal to the library.
//
// Threads and what they touch (every field below `mu` is guarded by it):
//   game thread   cd_frame_submit pushes into `ring`; cd_pose_poll / cd_event_poll copy out.
//   I/O thread    io_loop(): pops the ring, writes frames on the stream, reopens streams,
//                 recreates the session; the only thread that calls methods of the stream.
//   gRPC threads  FrameStream's callbacks publish answers and stream ends, then notify.
//   caller        the blocking cd_session_* calls, with their own ClientContext and deadline.
// No critical section does I/O or allocates on the game thread's path.
#ifndef CAMDIRECTOR_CLIENT_IMPL_H
#define CAMDIRECTOR_CLIENT_IMPL_H

#include <grpcpp/grpcpp.h>

#include <array>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <memory>
#include <mutex>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "camdirector/camdirector.h"
#include "camdirector/v1/director.grpc.pb.h"
#include "retry.h"

namespace camdirector::sdk {

namespace pb = ::camdirector::v1;
using Clock = std::chrono::steady_clock;

constexpr size_t kEventCapacity = 64;
constexpr double kRecreateTimeoutS = 10.0;
constexpr double kConnectWaitS = 0.25;  // longest the I/O thread waits for a connection at once
constexpr int kPackedWidth = 10;  // px py pz qx qy qz qw sx sy sz (FrameUpdate.packed_transforms)
// UNAVAILABLE over a working connection, with no answer, on every stream for this long (and at
// least kLostAfterRefusals streams): the server lost the session (a worker died on a server
// without checkpoints). Shorter runs are a server restoring it (camdirector.h, Reconnection).
constexpr double kLostAfterS = 1.0;
constexpr int kLostAfterRefusals = 3;

// The metadata header of every call of a session (CreateSession included): a balancer in front
// of several nodes routes all the calls that carry the same value to one node.
constexpr char kRouteHeader[] = "x-camdirector-route";
// A new session's route key: 32 lowercase hex characters, 128 bits from std::random_device.
std::string new_route_key();
// The metadata of the protocol this SDK speaks (CD_PROTOCOL) on every call; a server that speaks
// an older one refuses CreateSession.
constexpr char kProtocolHeader[] = "camdirector-protocol";
// The metadata of the client's key on every call ("Bearer KEY"), and where a key comes from when
// cd_config.key is none.
constexpr char kAuthorizationHeader[] = "authorization";
constexpr char kKeyEnv[] = "CAMDIRECTOR_KEY";

// "HOST:PORT" (and the other forms camdirector.h lists) as a gRPC target, and whether it is
// served over TLS (grpcs://); false and a reason for an address that does not parse.
bool parse_address(const char* address, std::string* target, bool* tls, std::string* error);

// A blocking call's failure message: gRPC's, with a word on what to check when no connection
// could be made at all (TLS on one side only, a CA the client does not trust).
std::string explain_failure(const grpc::Status& status, bool tls);

// Plain structs to a CreateSessionRequest; false and a reason for what the SDK refuses itself.
bool build_request(const cd_session_desc& desc, pb::CreateSessionRequest* out, std::string* error);
void fill_style(const cd_style& style, pb::Style* out);

// Slots of a request: its targets in order, then its dynamic objects in order.
std::vector<std::string> slot_ids_of(const pb::CreateSessionRequest& request);

double seconds_since_epoch(Clock::time_point t);
// A gRPC deadline (gRPC takes system_clock time points) timeout_s from now.
std::chrono::system_clock::time_point grpc_deadline(double timeout_s);
void copy_cstr(char* dst, size_t size, const std::string& src);

class FrameStream;

// One frame waiting in the queue: its states live in Client::ring_states at a fixed place.
struct QueuedFrame {
  uint64_t frame = 0;
  double time_s = 0.0;
  uint32_t count = 0;
};

enum class Phase {
  kIdle,      // no session
  kStream,    // a session: keep a stream open on it (reopen at retry_at)
  kRecreate,  // the session is unknown to the server: create it again at retry_at
  kFailed,    // lost for good
  kClosing,   // cd_session_close is tearing the stream down
};

}  // namespace camdirector::sdk

struct cd_client {
  using Phase = camdirector::sdk::Phase;
  using Clock = camdirector::sdk::Clock;

  cd_config config{};  // its strings are not kept (the caller owns them): address, key, ca_file NULL
  std::string target;
  bool tls = false;
  std::string authorization;  // "Bearer KEY", "" without a key; set at creation, then only read
  std::shared_ptr<grpc::Channel> channel;
  std::unique_ptr<camdirector::v1::Director::Stub> stub;
  std::thread io_thread;

  std::mutex mu;
  std::condition_variable io_cv;      // wakes the I/O thread
  std::condition_variable caller_cv;  // wakes blocking callers (flush, close)
  bool stopping = false;
  bool io_waiting = false;  // the I/O thread is blocked on io_cv (a submit must wake it)

  // Session.
  Phase phase = Phase::kIdle;
  camdirector::v1::CreateSessionRequest request;  // kept to recreate the session
  std::string session_id;
  std::string route_key;  // kRouteHeader of every call of this session, recreations included
  std::vector<std::string> slot_ids;
  uint32_t generation = 0;
  bool any_submitted = false;
  uint64_t last_frame = 0;
  double last_time_s = 0.0;

  // Queue: a ring of `queue_capacity` frames, each with `max_states` states preallocated.
  std::vector<camdirector::sdk::QueuedFrame> ring;
  std::vector<cd_state> ring_states;
  uint32_t ring_head = 0;
  uint32_t ring_size = 0;
  std::vector<cd_state> carry_states;  // a dropped frame's states, on their way to the next frame

  // Stream (methods of `stream` are called by the I/O thread only, until it removes its hold).
  camdirector::sdk::FrameStream* stream = nullptr;
  bool stream_read_closed = false;
  bool stream_hold_released = false;
  bool stream_cancelled = false;
  bool write_busy = false;
  bool stream_done = false;           // OnDone ran; `stream` is gone
  grpc::Status done_status;
  bool stream_answered = false;       // the current stream has answered a frame
  Clock::time_point retry_at{};
  bool retrying = false;              // a failure since the last answer: the retry window runs
  Clock::time_point retry_started{};  // the first failure of that run
  int retry_tries = 0;                // waits drawn in that run (retry.h, backoff_delay_s)
  std::minstd_rand jitter;            // the jitter's numbers when config.random is NULL
  uint64_t hung_frame = 0;            // the frame whose frame_timeout_s cancelled the stream (0: none)
  bool outage = false;                // a stream broke and none has answered since
  bool ever_streamed = false;
  bool recreated_unanswered = false;  // recreated, and its stream has answered nothing yet
  int unavailable_while_ready = 0;    // streams refused UNAVAILABLE over a working connection
  Clock::time_point unavailable_since{};  // the first of those refusals in a row
  bool recreate_presumed = false;     // kRecreate from those refusals, not from NOT_FOUND
  grpc::ClientContext* io_call = nullptr;  // the I/O thread's CreateSession, to cancel it

  // Frames sent, by sequence number (1 for the session's first): the last `history.size()` are
  // kept at seq % history.size(), to be sent again on a new stream (those left unanswered) or
  // from a DATA_LOSS's "resend from K". Answers come in order, one per frame written, so the
  // answer read is always for `unanswered_seq`. The messages are the I/O thread's alone.
  std::vector<camdirector::v1::FrameUpdate> history;
  std::vector<uint64_t> history_previous;           // the frame sent before each (0: none)
  std::vector<Clock::time_point> history_sent_at;   // when each was last written (frame_timeout_s)
  Clock::time_point last_answer_at{};                // when the last answer was read (frame_timeout_s)
  uint64_t next_seq = 1;        // the next new frame's
  uint64_t send_seq = 1;        // the next to write on this stream (below next_seq: sent again)
  uint64_t unanswered_seq = 1;  // the oldest sent and not answered
  uint64_t kept_from_seq = 1;   // the session's first (a recreated session keeps none before it)
  uint64_t newest_answered_seq = 0;  // the newest frame whose answer was received
  uint64_t answered_frame = 0;       // its frame: FrameUpdate.answered_frame
  uint64_t last_sent_frame = 0;      // the frame of seq next_seq - 1 (0: none)
  uint32_t in_flight() const { return static_cast<uint32_t>(send_seq - unanswered_seq); }
  uint64_t unanswered() const { return next_seq - unanswered_seq; }  // sent or to send again

  // Results.
  bool has_pose = false;
  cd_pose latest{};
  bool cut_pending = false;
  std::array<cd_event, camdirector::sdk::kEventCapacity> events{};
  uint32_t event_head = 0;
  uint32_t event_count = 0;
  cd_stats stats{};
  int last_error_code = CD_OK;
  std::string last_error;

  // I/O thread only.
  camdirector::sdk::QueuedFrame send_frame;
  std::vector<cd_state> send_states;
  std::string send_session_id;
  std::vector<double> slot_transforms;  // the last transform sent per slot (kPackedWidth each)
  std::vector<uint8_t> slot_known;
  bool send_all_known = false;          // the next frame opens a recreated session

  // io.cpp
  void io_loop();
  void open_stream_locked();
  void handle_stream_done_locked();
  void cancel_stream(std::unique_lock<std::mutex>& lock);
  void recreate(std::unique_lock<std::mutex>& lock);
  void write_next(std::unique_lock<std::mutex>& lock);
  void build_frame(camdirector::v1::FrameUpdate* msg);
  // The next try after a failure, within the retry window (SESSION_FAILED once it is spent);
  // at_once: no wait (a DATA_LOSS resend), the window still counted.
  void retry_later_locked(bool at_once = false);
  void fail_session_locked(int code, const std::string& message);
  void forget_sent_locked();
  bool resend_from_locked(uint64_t frame);
  // Called by FrameStream on gRPC's threads.
  void on_answer(const camdirector::v1::CameraUpdate& update);
  void on_read_closed();
  void on_write_done();
  void on_stream_done(const grpc::Status& status);

  // request.cpp: puts the session's route key, the protocol and the client's key on a call's
  // context (before the call starts); every call of a session gets them.
  void add_call_metadata(grpc::ClientContext* context, const std::string& route_key) const;

  // client.cpp
  void push_event_locked(int kind, int status, const std::string& message);
  void set_error_locked(int code, const std::string& message);
  void reset_session_locked();
};

#endif  // CAMDIRECTOR_CLIENT_IMPL_H
