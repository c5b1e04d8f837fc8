// The I/O thread: one StreamFrames stream at a time on the session (gRPC's callback API), fed
// from the frame queue with at most `max_in_flight` frames unanswered; reopens the stream after a
// dropped connection, a lost worker or a server restart (same session id: a server with
// checkpoints restores it) and creates the session again when the server no longer has it
// (NOT_FOUND, or a run of UNAVAILABLE: handle_stream_done_locked), and gives the session up when
// the server refuses the client's key, a DATA_LOSS asks for frames no longer kept, or nothing
// answered for the retry window (retry_later_locked). A new stream first sends again the frames
// the last one left unanswered; a DATA_LOSS "resend from K" sends the kept ones from K again
// (client_impl.h, history). Every call carries the session's route key and the
// client's key (add_call_metadata).
//
// Ownership of a stream: the I/O thread creates a FrameStream, keeps a hold on it (so gRPC cannot
// finish it), and is the only thread that calls its methods. When the stream's read side closes
// and no write is pending it removes the hold; gRPC then calls OnDone, which reports the status
// and deletes the reactor. No method of a stream is called after its hold is removed.
#include <algorithm>
#include <cmath>

#ifdef __linux__
#include <pthread.h>
#include <sched.h>
#endif

#include "client_impl.h"

namespace camdirector::sdk {

class FrameStream : public grpc::ClientBidiReactor<pb::FrameUpdate, pb::CameraUpdate> {
 public:
  FrameStream(cd_client* client, const std::string& route_key) : client_(client) {
    client->add_call_metadata(&context_, route_key);
  }

  // Call without holding the client's mutex: gRPC may run callbacks on this thread.
  void start(pb::Director::Stub* stub) {
    context_.set_wait_for_ready(false);
    stub->async()->StreamFrames(&context_, this);
    AddHold();
    StartRead(&reply_);
    StartCall();
  }

  void cancel() { context_.TryCancel(); }

  pb::FrameUpdate out;  // the frame being written (the I/O thread's, while write_busy)

  void OnReadDone(bool ok) override {
    if (!ok) {
      client_->on_read_closed();
      return;
    }
    client_->on_answer(reply_);
    StartRead(&reply_);
  }

  void OnWriteDone(bool /*ok*/) override { client_->on_write_done(); }

  void OnDone(const grpc::Status& status) override {
    client_->on_stream_done(status);
    delete this;
  }

 private:
  cd_client* client_;
  grpc::ClientContext context_;
  pb::CameraUpdate reply_;
};

namespace {

Clock::duration seconds(double s) {
  return std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(s));
}

// Statuses after which creating the session again may succeed later.
bool retryable(grpc::StatusCode code) {
  switch (code) {
    case grpc::StatusCode::UNAVAILABLE:
    case grpc::StatusCode::DEADLINE_EXCEEDED:
    case grpc::StatusCode::RESOURCE_EXHAUSTED:
    case grpc::StatusCode::CANCELLED:
    case grpc::StatusCode::ABORTED:
    case grpc::StatusCode::INTERNAL:
    case grpc::StatusCode::UNKNOWN:
      return true;
    default:
      return false;
  }
}

// Statuses a server gives a bad frame; the session stays (docs/protocol.md, Errors).
bool frame_refused(grpc::StatusCode code) {
  return code == grpc::StatusCode::INVALID_ARGUMENT || code == grpc::StatusCode::FAILED_PRECONDITION ||
         code == grpc::StatusCode::OUT_OF_RANGE || code == grpc::StatusCode::RESOURCE_EXHAUSTED;
}

}  // namespace

}  // namespace camdirector::sdk

using camdirector::sdk::Clock;
using camdirector::sdk::frame_refused;
using camdirector::sdk::FrameStream;
using camdirector::sdk::grpc_deadline;
using camdirector::sdk::kConnectWaitS;
using camdirector::sdk::kPackedWidth;
using camdirector::sdk::retryable;
namespace pb = camdirector::v1;

void cd_client::io_loop() {
#ifdef __linux__
  // SCHED_BATCH (no privilege needed): waking this thread never preempts the thread that woke
  // it, so cd_frame_submit costs the game thread one futex wake, not a context switch.
  sched_param param{};
  (void)pthread_setschedparam(pthread_self(), SCHED_BATCH, &param);
  (void)pthread_setname_np(pthread_self(), "camdirector-io");
#endif
  std::unique_lock<std::mutex> lock(mu);
  for (;;) {
    const Clock::time_point now = Clock::now();
    if (stream != nullptr && stream_read_closed && !write_busy && !stream_hold_released) {
      stream_hold_released = true;
      FrameStream* s = stream;
      lock.unlock();
      s->RemoveHold();  // may run OnDone on this thread
      lock.lock();
      continue;
    }
    if (stream_done) {
      handle_stream_done_locked();
      continue;
    }
    if (stopping || phase == Phase::kClosing) {
      if (stream != nullptr && !stream_cancelled && !stream_hold_released) {
        cancel_stream(lock);
        continue;
      }
      if (stream == nullptr) {
        if (stopping) break;
        caller_cv.notify_all();
      }
      io_waiting = true;
      io_cv.wait(lock);
      io_waiting = false;
      continue;
    }

    Clock::time_point wake = now + (config.io_poll_interval_ms > 0 ? std::chrono::milliseconds(config.io_poll_interval_ms)
                                                                  : std::chrono::milliseconds(1000));
    if (phase == Phase::kStream) {
      if (stream == nullptr) {
        if (now >= retry_at) {
          if (channel->GetState(false) != GRPC_CHANNEL_READY) {
            // Wait for a connection before opening a stream, so that a retry against a server
            // still down does not use up a queued frame. Bounded, to answer close/destroy.
            lock.unlock();
            const bool connected = channel->WaitForConnected(grpc_deadline(kConnectWaitS));
            lock.lock();
            if (!connected) {
              retry_later_locked();
              continue;
            }
            if (stopping || phase != Phase::kStream || stream != nullptr) continue;
          }
          open_stream_locked();
          FrameStream* s = stream;
          lock.unlock();
          s->start(stub.get());
          lock.lock();
          continue;
        }
        wake = std::min(wake, retry_at);
      } else if (!stream_read_closed && !stream_cancelled) {
        if (!write_busy && (send_seq < next_seq || ring_size > 0) && in_flight() < config.max_in_flight) {
          write_next(lock);
          continue;
        }
        if (in_flight() > 0) {
          // Frames in flight and nothing answered for frame_timeout_s (since the oldest was sent
          // or, if later, since the last answer: frames queued on a live node are not a hang): a
          // hung node (or network). Start over, through a balancer on a live node; the frame is
          // sent again on the new stream.
          const size_t oldest = unanswered_seq % history.size();
          const Clock::time_point due =
              std::max(history_sent_at[oldest], last_answer_at) + camdirector::sdk::seconds(config.frame_timeout_s);
          if (now >= due) {
            hung_frame = history[oldest].frame();
            cancel_stream(lock);
            continue;
          }
          wake = std::min(wake, due);
        }
      }
    } else if (phase == Phase::kRecreate) {
      if (now >= retry_at) {
        recreate(lock);
        continue;
      }
      wake = std::min(wake, retry_at);
    }
    io_waiting = true;
    io_cv.wait_until(lock, wake);
    io_waiting = false;
  }
}

void cd_client::open_stream_locked() {
  stream = new FrameStream(this, route_key);
  stream_read_closed = false;
  stream_hold_released = false;
  stream_cancelled = false;
  write_busy = false;
  stream_answered = false;
  hung_frame = 0;
  send_seq = unanswered_seq;  // the frames the last stream left unanswered go first
  stats.streams_opened += 1;
}

void cd_client::retry_later_locked(bool at_once) {
  const Clock::time_point now = Clock::now();
  if (!retrying) {  // the first failure since an answer: the window starts
    retrying = true;
    retry_started = now;
    retry_tries = 0;
  }
  const double random01 = config.random != nullptr ? config.random(config.random_user)
                                                   : std::generate_canonical<double, 32>(jitter);
  const double elapsed_s = std::chrono::duration<double>(now - retry_started).count();
  const double delay_s = camdirector::sdk::backoff_delay_s(config.initial_backoff_s, config.reconnect_max_s,
                                                           config.retry_window_s, elapsed_s, retry_tries++, random01);
  if (delay_s < 0.0) {
    char window[32];
    std::snprintf(window, sizeof window, "%g", config.retry_window_s);
    fail_session_locked(CD_UNAVAILABLE, std::string("no answer for ") + window +
                                            " s (retry_window_s) since the first failure; last: " +
                                            cd_status_name(stats.last_stream_status) + " " +
                                            done_status.error_message());
    return;
  }
  retry_at = at_once ? now : now + camdirector::sdk::seconds(delay_s);
}

void cd_client::fail_session_locked(int code, const std::string& message) {
  phase = Phase::kFailed;
  ring_size = 0;
  push_event_locked(CD_EVENT_SESSION_FAILED, code, message);
  caller_cv.notify_all();
}

// A new session (opened or recreated) was sent nothing yet: nothing to send again, no answer.
void cd_client::forget_sent_locked() {
  stats.frames_lost += unanswered();
  kept_from_seq = unanswered_seq = send_seq = next_seq;
  newest_answered_seq = next_seq - 1;
  answered_frame = 0;
  last_sent_frame = 0;
}

// After a DATA_LOSS "resend from `frame`": the next stream sends the kept frames from it again.
// False when a frame from `frame` on is no longer kept.
bool cd_client::resend_from_locked(uint64_t frame) {
  const uint64_t size = history.size();
  const uint64_t oldest = std::max(kept_from_seq, next_seq > size ? next_seq - size : 1);
  // A frame before the oldest kept was sent (and is gone) when the oldest is not the session's first.
  if (oldest > kept_from_seq && frame <= history_previous[oldest % size]) return false;
  uint64_t from = oldest;
  while (from < unanswered_seq && history[from % size].frame() < frame) ++from;
  unanswered_seq = send_seq = from;
  return true;
}

void cd_client::cancel_stream(std::unique_lock<std::mutex>& lock) {
  // Marked first, cancelled outside the lock: gRPC may call back into on_stream_done at once.
  stream_cancelled = true;
  FrameStream* s = stream;
  lock.unlock();
  s->cancel();
  lock.lock();
}

void cd_client::handle_stream_done_locked() {
  stream_done = false;
  grpc::StatusCode code = done_status.error_code();
  std::string message = done_status.error_message();
  if (hung_frame != 0 && code == grpc::StatusCode::CANCELLED) {  // our own cancel, on frame_timeout_s
    char timeout[32];
    std::snprintf(timeout, sizeof timeout, "%g", config.frame_timeout_s);
    code = grpc::StatusCode::UNAVAILABLE;
    message = "frame " + std::to_string(hung_frame) + " was not answered within " + timeout +
              " s (frame_timeout_s): the node may be hung";
    done_status = grpc::Status(code, message);
  }
  write_busy = false;
  stats.last_stream_status = static_cast<int>(code);
  caller_cv.notify_all();
  if (stopping || phase != Phase::kStream) return;

  const bool answered = stream_answered;
  if (code == grpc::StatusCode::UNAUTHENTICATED || code == grpc::StatusCode::PERMISSION_DENIED) {
    // The key was refused (revoked since the session opened, or a role that may not stream):
    // another stream, or a recreation, would be refused the same.
    phase = Phase::kFailed;
    ring_size = 0;
    push_event_locked(CD_EVENT_SESSION_FAILED, static_cast<int>(code),
                      "the server refused this client's key: " + message);
    return;
  }
  if (code == grpc::StatusCode::NOT_FOUND && !answered) {
    // The first frame of this stream named a session the server does not know.
    if (recreated_unanswered) {
      phase = Phase::kFailed;
      ring_size = 0;
      push_event_locked(CD_EVENT_SESSION_FAILED, static_cast<int>(code),
                        "the recreated session is unknown to the server too: " + message);
      return;
    }
    phase = Phase::kRecreate;
    recreate_presumed = false;
    retry_at = Clock::now();
    if (!outage && ever_streamed) {
      stats.disconnects += 1;
      push_event_locked(CD_EVENT_DISCONNECTED, static_cast<int>(code), message);
    }
    outage = true;
    return;
  }
  if (code == grpc::StatusCode::DATA_LOSS) {
    // The session was restored from a checkpoint that fell behind what this client was answered
    // (docs/protocol.md, Checkpoints): send the frames from K again, at once.
    uint64_t from = 0;
    if (!camdirector::sdk::parse_resend_from(message, &from)) {
      fail_session_locked(CD_DATA_LOSS, message);
      return;
    }
    if (!resend_from_locked(from)) {
      fail_session_locked(CD_DATA_LOSS, message + " (this client kept the last " + std::to_string(history.size()) +
                                            " frames it sent, resend_history_frames: frame " +
                                            std::to_string(from) + " is no longer among them)");
      return;
    }
  }
  if (frame_refused(code) || code == grpc::StatusCode::NOT_FOUND) {
    // A bad frame ended the stream (NOT_FOUND after answers: an unknown object id): the oldest
    // unanswered one, since the server takes frames in order. It is not sent again; the session
    // stays: go on with the next frames.
    if (unanswered_seq < send_seq) {
      unanswered_seq += 1;
      stats.frames_lost += 1;
    }
    push_event_locked(CD_EVENT_FRAME_REFUSED, static_cast<int>(code), message);
    retry_at = Clock::now();
    return;
  }
  if (code == grpc::StatusCode::UNAVAILABLE && hung_frame == 0 && !answered &&
      channel->GetState(false) == GRPC_CHANNEL_READY) {
    // UNAVAILABLE over a working connection, before any answer. A server with checkpoints answers
    // it once while it restores the session (its worker died; the next stream is held until the
    // restore is done), a balancer while it has no healthy node, a server without checkpoints on
    // every stream once the session's worker died. Only a run of refusals (kLostAfterS and
    // kLostAfterRefusals) presumes the session lost; recreate() goes back to this session if the
    // server refuses to create one too (then it was the server, not the session).
    const Clock::time_point now = Clock::now();
    if (unavailable_while_ready++ == 0) unavailable_since = now;
    if (unavailable_while_ready >= camdirector::sdk::kLostAfterRefusals &&
        now - unavailable_since >= camdirector::sdk::seconds(camdirector::sdk::kLostAfterS)) {
      unavailable_while_ready = 0;
      phase = Phase::kRecreate;
      recreate_presumed = true;
      retry_at = now;
      outage = true;
      return;
    }
  } else {
    unavailable_while_ready = 0;  // a refusal of another kind, or one after answers, breaks the run
  }
  if (!outage && ever_streamed) {
    stats.disconnects += 1;
    push_event_locked(CD_EVENT_DISCONNECTED, static_cast<int>(code), message);
  }
  outage = outage || ever_streamed || code != grpc::StatusCode::OK;
  retry_later_locked(code == grpc::StatusCode::DATA_LOSS);  // a resend at once: the server waits for it
}

void cd_client::recreate(std::unique_lock<std::mutex>& lock) {
  pb::CreateSessionRequest req = request;
  const std::string old_id = session_id;
  const std::string route = route_key;  // the same key: the balancer's node for this session
  grpc::ClientContext context;
  context.set_deadline(grpc_deadline(camdirector::sdk::kRecreateTimeoutS));
  add_call_metadata(&context, route);
  io_call = &context;
  lock.unlock();
  pb::CreateSessionResponse response;
  const grpc::Status status = stub->CreateSession(&context, req, &response);
  lock.lock();
  io_call = nullptr;
  if (stopping || phase != Phase::kRecreate) {
    if (status.ok()) {  // closed meanwhile: do not leave the new session behind
      lock.unlock();
      grpc::ClientContext close_context;
      close_context.set_deadline(grpc_deadline(1.0));
      add_call_metadata(&close_context, route);
      pb::CloseSessionRequest close;
      close.set_session_id(response.session_id());
      pb::CloseSessionResponse closed;
      (void)stub->CloseSession(&close_context, close, &closed);
      lock.lock();
    }
    return;
  }
  if (status.ok()) {
    recreate_presumed = false;
    session_id = response.session_id();
    generation += 1;
    stats.generation = generation;
    stats.recreations += 1;
    phase = Phase::kStream;
    retry_at = Clock::now();
    recreated_unanswered = true;
    send_all_known = true;
    forget_sent_locked();  // the frames sent to the lost session are not the new one's
    push_event_locked(CD_EVENT_RECREATED, CD_OK,
                      "the server no longer knew session " + old_id + "; created it again as " + session_id);
    return;
  }
  if (retryable(status.error_code())) {
    if (recreate_presumed) {
      // The session was only presumed lost (UNAVAILABLE refusals), and the server refuses to
      // create one too: it is the server or the balancer that is unavailable, not the session.
      // Keep the session id: a server that comes back may restore it from its checkpoint.
      phase = Phase::kStream;
      recreate_presumed = false;
    }
    retry_later_locked();
    return;
  }
  fail_session_locked(static_cast<int>(status.error_code()),
                      "creating the session again was refused: " + status.error_message());
}

// Writes the next frame: one the last stream left unanswered (or a DATA_LOSS asked for) from the
// kept frames, else the queue's oldest, built into the kept frames first.
void cd_client::write_next(std::unique_lock<std::mutex>& lock) {
  const size_t index = send_seq % history.size();
  const bool again = send_seq < next_seq;
  if (!again) {
    const camdirector::sdk::QueuedFrame& head = ring[ring_head];
    send_frame = head;
    std::copy_n(ring_states.begin() + static_cast<size_t>(ring_head) * config.max_states, head.count,
                send_states.begin());
    ring_head = (ring_head + 1) % config.queue_capacity;
    ring_size -= 1;
    history_previous[index] = last_sent_frame;
    last_sent_frame = send_frame.frame;
    next_seq += 1;
    send_session_id = session_id;
  }
  // The newest answer, but never past the frame sent before this one: sent again after a
  // DATA_LOSS, a frame says where the session stood when it was first sent.
  const uint64_t answered = std::min(answered_frame, history_previous[index]);
  send_seq += 1;
  write_busy = true;
  history_sent_at[index] = Clock::now();
  stats.frames_sent += 1;
  FrameStream* s = stream;
  lock.unlock();
  pb::FrameUpdate& kept = history[index];
  if (!again) build_frame(&kept);
  s->out.CopyFrom(kept);  // reuses out's storage
  s->out.set_answered_frame(answered);
  s->StartWrite(&s->out);
  lock.lock();
}

// The queued frame as a FrameUpdate with packed states. Reuses the message's storage, so a
// steady stream allocates nothing here either. Zero rotation / scale mean identity / ones.
void cd_client::build_frame(pb::FrameUpdate* msg) {
  msg->Clear();
  msg->set_session_id(send_session_id);
  msg->set_frame(send_frame.frame);
  msg->set_time_s(send_frame.time_s);
  for (uint32_t i = 0; i < send_frame.count; ++i) {
    const cd_state& st = send_states[i];
    const cd_transform& t = st.transform;
    const bool unit_rotation = t.rotation.x == 0.0 && t.rotation.y == 0.0 && t.rotation.z == 0.0 && t.rotation.w == 0.0;
    const bool unit_scale = t.scale.x == 0.0 && t.scale.y == 0.0 && t.scale.z == 0.0;
    double* packed = &slot_transforms[static_cast<size_t>(st.slot) * kPackedWidth];
    packed[0] = t.position.x;
    packed[1] = t.position.y;
    packed[2] = t.position.z;
    packed[3] = unit_rotation ? 0.0 : t.rotation.x;
    packed[4] = unit_rotation ? 0.0 : t.rotation.y;
    packed[5] = unit_rotation ? 0.0 : t.rotation.z;
    packed[6] = unit_rotation ? 1.0 : t.rotation.w;
    packed[7] = unit_scale ? 1.0 : t.scale.x;
    packed[8] = unit_scale ? 1.0 : t.scale.y;
    packed[9] = unit_scale ? 1.0 : t.scale.z;
    slot_known[st.slot] = 2;  // 2: in this frame
  }
  for (size_t slot = 0; slot < slot_known.size(); ++slot) {
    // A recreated session starts from the created transforms: resend every transform known.
    if (slot_known[slot] == 2 || (send_all_known && slot_known[slot] == 1)) {
      *msg->add_packed_ids() = slot_ids[slot];
      const double* packed = &slot_transforms[slot * kPackedWidth];
      for (int k = 0; k < kPackedWidth; ++k) msg->add_packed_transforms(packed[k]);
      slot_known[slot] = 1;
    }
  }
  send_all_known = false;
}

void cd_client::on_answer(const pb::CameraUpdate& update) {
  cd_pose pose{};
  pose.frame = update.frame();
  pose.time_s = update.time_s();
  pose.position = {update.pose().position().x(), update.pose().position().y(), update.pose().position().z()};
  const pb::Quat& q = update.pose().rotation();
  pose.rotation = {q.x(), q.y(), q.z(), q.w()};
  pose.vertical_fov_deg = update.pose().vertical_fov_deg();
  pose.cut = update.cut() ? 1 : 0;
  pose.shot_id = update.shot_id();
  pose.visibility = update.visibility();
  pose.compute_ms = update.compute_ms();
  pose.received_s = camdirector::sdk::seconds_since_epoch(Clock::now());

  std::lock_guard<std::mutex> guard(mu);
  stats.frames_answered += 1;
  last_answer_at = Clock::now();
  const uint64_t seq = unanswered_seq;  // answers come in order, one per frame written
  if (unanswered_seq < send_seq) unanswered_seq += 1;
  const bool fresh = seq > newest_answered_seq;  // not sent again after a DATA_LOSS: the game has not had it
  if (fresh) {
    newest_answered_seq = seq;
    answered_frame = update.frame();
  }
  if (update.stale()) {
    stats.frames_stale += 1;
  } else if (fresh && !update.buffering() && update.has_pose()) {
    pose.generation = generation;
    latest = pose;
    has_pose = true;
    if (pose.cut) cut_pending = true;
  }
  if (!stream_answered) {
    stream_answered = true;
    if (outage && !recreated_unanswered) {
      stats.resumes += 1;
      push_event_locked(CD_EVENT_RESUMED, CD_OK, "resumed session " + session_id + " on a new stream");
    } else if (!ever_streamed) {
      push_event_locked(CD_EVENT_STREAMING, CD_OK, "streaming session " + session_id);
    }
    outage = false;
    ever_streamed = true;
    recreated_unanswered = false;
    unavailable_while_ready = 0;
    retrying = false;  // an answer: a later failure starts a new retry window
  }
  io_cv.notify_one();
  caller_cv.notify_all();
}

void cd_client::on_read_closed() {
  std::lock_guard<std::mutex> guard(mu);
  stream_read_closed = true;
  io_cv.notify_one();
}

void cd_client::on_write_done() {
  std::lock_guard<std::mutex> guard(mu);
  write_busy = false;
  io_cv.notify_one();
}

void cd_client::on_stream_done(const grpc::Status& status) {
  std::lock_guard<std::mutex> guard(mu);
  stream = nullptr;
  stream_done = true;
  done_status = status;
  io_cv.notify_one();
}
