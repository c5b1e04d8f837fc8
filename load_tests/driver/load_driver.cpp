// load_driver: the compiled load generator of load_tests.stream and load_tests.capacity
// (`--generator native`; issue 43, docs/frame_path.md "The order of work", step 6).
//
// The Python generator costs about 140 us of CPU a frame, on the same two cores as the server it
// measures: at 60 sessions it took a third of the machine. This program streams the same frames
// the same way (one frame in flight per session, paced by the wall clock, sessions staggered over
// one period, over one gRPC channel or one ZeroMQ DEALER connection per session) at a small part of
// that cost, so that capacity measures the server. It knows nothing of the schema beyond what the
// Python side tells it: the frames come serialized, and the reply's compute_ms and stale are read
// by the field numbers it is given.
//
//   load_driver --transport grpc|zmq --address ADDR --frames FILE --sessions ID,ID,...
//       --period-s P --start-s T --warmup N --compute-field F --stale-field S [--key KEY]
//       [--stride K]
//
// FILE holds the frames without a session id, each as a 4-byte little-endian length and its bytes;
// each session sends them in order, its id prepended as field 1 (as load_tests.stream does).
// K (default 0): session i sends FILE's frames from the (i * K)-th on, all sessions as many
// (FILE's count less (sessions - 1) * K): each its own stretch of the game, not all the same
// moment (load_tests.stream --spread-s).
// T: when session 0 sends its first frame, on CLOCK_MONOTONIC (Python's time.perf_counter).
// P: the period, s (0: closed loop from T on, each frame sent as soon as the last is answered).
// Prints one JSON object: per-session frames answered, the judged frames' round trips and
// compute_ms (ms), late (a round trip over P) and stale counts, errors, wall and CPU seconds.
// A bad argument exits 2 with the reason on stderr.

#include <fcntl.h>
#include <grpcpp/generic/generic_stub.h>
#include <grpcpp/grpcpp.h>
#include <netdb.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <sys/resource.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <fstream>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

namespace {

const char kStreamMethod[] = "/camdirector.v1.Director/StreamFrames";

double now_s() {  // CLOCK_MONOTONIC, as Python's time.perf_counter on Linux
  timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return double(ts.tv_sec) + double(ts.tv_nsec) * 1e-9;
}

double cpu_s() {
  rusage usage;
  getrusage(RUSAGE_SELF, &usage);
  return double(usage.ru_utime.tv_sec + usage.ru_stime.tv_sec) + double(usage.ru_utime.tv_usec + usage.ru_stime.tv_usec) * 1e-6;
}

struct Options {
  std::string transport, address, frames_path, key;
  std::vector<std::string> sessions;
  double period_s = -1.0, start_s = 0.0;
  long warmup = 0;
  size_t stride = 0;
  int compute_field = 0, stale_field = 0;
};

[[noreturn]] void usage_error(const std::string& why) {
  std::fprintf(stderr, "load_driver: %s\n", why.c_str());
  std::exit(2);
}

Options parse_options(int argc, char** argv) {
  Options o;
  for (int i = 1; i < argc; i += 2) {
    std::string name = argv[i];
    if (i + 1 >= argc) usage_error("no value after " + name);
    std::string value = argv[i + 1];
    try {
      if (name == "--transport") o.transport = value;
      else if (name == "--address") o.address = value;
      else if (name == "--frames") o.frames_path = value;
      else if (name == "--key") o.key = value;
      else if (name == "--period-s") o.period_s = std::stod(value);
      else if (name == "--start-s") o.start_s = std::stod(value);
      else if (name == "--warmup") o.warmup = std::stol(value);
      else if (name == "--stride") o.stride = std::stoul(value);
      else if (name == "--compute-field") o.compute_field = std::stoi(value);
      else if (name == "--stale-field") o.stale_field = std::stoi(value);
      else if (name == "--sessions") {
        std::stringstream ids(value);
        for (std::string id; std::getline(ids, id, ',');)
          if (!id.empty()) o.sessions.push_back(id);
      } else usage_error("unknown option " + name);
    } catch (const std::exception&) {
      usage_error("not a number: " + name + " " + value);
    }
  }
  if (o.transport != "grpc" && o.transport != "zmq") usage_error("--transport must be grpc or zmq");
  if (o.address.empty() || o.frames_path.empty()) usage_error("--address and --frames are required");
  if (o.sessions.empty()) usage_error("--sessions names no session");
  if (o.period_s < 0) usage_error("--period-s must be given, >= 0");
  if (o.compute_field <= 0 || o.stale_field <= 0) usage_error("--compute-field and --stale-field must be field numbers");
  if (o.transport == "zmq" && !o.key.empty()) usage_error("only the gRPC driver sends a key");
  for (const auto& id : o.sessions)
    if (id.size() > 127) usage_error("a session id longer than 127 bytes");
  return o;
}

std::vector<std::string> read_frames(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) usage_error("cannot read " + path);
  std::vector<std::string> frames;
  unsigned char head[4];
  while (in.read(reinterpret_cast<char*>(head), 4)) {
    uint32_t size = uint32_t(head[0]) | uint32_t(head[1]) << 8 | uint32_t(head[2]) << 16 | uint32_t(head[3]) << 24;
    std::string frame(size, '\0');
    if (!in.read(frame.data(), size)) usage_error(path + ": a frame cut short");
    frames.push_back(std::move(frame));
  }
  if (frames.empty()) usage_error(path + " holds no frame");
  return frames;
}

// The reply's compute_ms (a double) and stale (a bool) read from the protobuf wire format; fields
// it does not know are skipped by their wire type. False when the bytes are not a message.
bool read_reply(const std::string& reply, int compute_field, int stale_field, double* compute_ms, bool* stale) {
  size_t at = 0;
  auto varint = [&](uint64_t* value) {
    *value = 0;
    for (int shift = 0; shift < 64; shift += 7) {
      if (at >= reply.size()) return false;
      uint8_t byte = uint8_t(reply[at++]);
      *value |= uint64_t(byte & 0x7F) << shift;
      if (byte < 0x80) return true;
    }
    return false;
  };
  *compute_ms = 0.0;
  *stale = false;
  while (at < reply.size()) {
    uint64_t key, value;
    if (!varint(&key)) return false;
    int field = int(key >> 3), type = int(key & 7);
    if (type == 0) {
      if (!varint(&value)) return false;
      if (field == stale_field) *stale = value != 0;
    } else if (type == 1) {
      if (at + 8 > reply.size()) return false;
      if (field == compute_field) std::memcpy(compute_ms, reply.data() + at, 8);
      at += 8;
    } else if (type == 2) {
      if (!varint(&value) || value > reply.size() - at) return false;
      at += value;
    } else if (type == 5) {
      at += 4;
    } else {
      return false;
    }
  }
  return at == reply.size();
}

// What one session measured (written by the one thread that streams).
struct Tally {
  long received = 0, late = 0, stale = 0;
  std::vector<double> rtt_ms, compute_ms;
  std::string error;
};

struct Run {
  Options options;
  std::vector<std::string> frames;
  size_t count = 0;  // frames each session sends (--stride)
  std::vector<Tally> tallies;

  // staggered over one period, as independent clients; closed loop (period 0): every frame due at T
  double due_s(size_t session, size_t frame) const {
    double period = options.period_s;
    return options.start_s + double(session) * period / double(options.sessions.size()) + double(frame) * period;
  }

  std::string payload(size_t session, size_t frame) const {
    const std::string& id = options.sessions[session];
    std::string out;
    const std::string& body = frames[session * options.stride + frame];
    out.reserve(2 + id.size() + body.size());
    out.push_back('\x0a');  // field 1, length-delimited: the session id, first (parsers take fields in any order)
    out.push_back(char(id.size()));
    out += id;
    out += body;
    return out;
  }

  void record(size_t session, size_t frame, double sent_s, double answered_s, const std::string& reply) {
    Tally& t = tallies[session];
    t.received++;
    if (long(frame) < options.warmup) return;
    double compute_ms;
    bool stale;
    if (!read_reply(reply, options.compute_field, options.stale_field, &compute_ms, &stale)) {
      t.error = "a reply that is not a CameraUpdate";
      return;
    }
    double rtt_s = answered_s - sent_s;
    t.rtt_ms.push_back(rtt_s * 1e3);
    t.compute_ms.push_back(compute_ms);
    t.late += options.period_s > 0 && rtt_s > options.period_s;
    t.stale += stale;
  }
};

// --- gRPC: one channel, one StreamFrames per session, all on this thread: the completion queue's
// own thread polls the sockets, so a frame costs no wake-up beyond its send's and its reply's
// (the callback API's executor threads and a pacing thread cost two more a frame, measured:
// 124-142 us of CPU a frame against 55-78 here, at 32-64 sessions).

struct GrpcSession {
  enum Op : uintptr_t { kStarted, kWritten, kRead, kWritesDone, kFinished, kOps };
  grpc::ClientContext context;
  std::unique_ptr<grpc::GenericClientAsyncReaderWriter> call;
  grpc::ByteBuffer request, reply;
  grpc::Status status;
  size_t next = 0;  // the frame to send next, or whose reply is awaited
  bool started = false, writing = false, reading = false, ending = false, finished = false;
  double sent_s = 0.0;
};

void* grpc_tag(size_t session, GrpcSession::Op op) { return reinterpret_cast<void*>(session * GrpcSession::kOps + op); }

void run_grpc(Run& run) {
  grpc::ChannelArguments args;
  args.SetMaxSendMessageSize(64 << 20);
  auto channel = grpc::CreateCustomChannel(run.options.address, grpc::InsecureChannelCredentials(), args);
  grpc::GenericStub stub(channel);
  grpc::CompletionQueue queue;
  size_t count = run.options.sessions.size(), left = count;
  std::vector<GrpcSession> sessions(count);
  for (size_t k = 0; k < count; k++) {
    GrpcSession& s = sessions[k];
    if (!run.options.key.empty()) s.context.AddMetadata("authorization", "Bearer " + run.options.key);
    s.call = stub.PrepareCall(&s.context, kStreamMethod, &queue);
    s.call->StartCall(grpc_tag(k, GrpcSession::kStarted));
  }
  auto finish = [&](size_t k) {  // the stream's status, asked once: kFinished ends the session
    GrpcSession& s = sessions[k];
    if (s.ending) return;
    s.ending = true;
    s.call->Finish(&s.status, grpc_tag(k, GrpcSession::kFinished));
  };
  auto send_due = [&](size_t k, double now) {  // the session's next frame, when it is due and may go
    GrpcSession& s = sessions[k];
    if (!s.started || s.writing || s.reading || s.ending || s.next >= run.count) return 1e300;
    double due = run.due_s(k, s.next);
    if (due > now) return due;
    std::string payload = run.payload(k, s.next);
    grpc::Slice slice(payload);
    s.request = grpc::ByteBuffer(&slice, 1);
    s.sent_s = now_s();
    s.writing = s.reading = true;
    s.call->Write(s.request, grpc_tag(k, GrpcSession::kWritten));
    s.call->Read(&s.reply, grpc_tag(k, GrpcSession::kRead));
    return 1e300;
  };
  while (left > 0) {
    double now = now_s(), soonest = 1e300;
    for (size_t k = 0; k < count; k++) soonest = std::min(soonest, send_due(k, now));
    void* tag;
    bool ok;
    gpr_timespec deadline = gpr_inf_future(GPR_CLOCK_MONOTONIC);  // only replies to wait for
    if (soonest < 1e300)
      deadline = gpr_time_add(gpr_now(GPR_CLOCK_MONOTONIC), gpr_time_from_nanos(int64_t((soonest - now_s()) * 1e9), GPR_TIMESPAN));
    auto got = queue.AsyncNext(&tag, &ok, deadline);
    while (got == grpc::CompletionQueue::GOT_EVENT) {
      double answered_s = now_s();
      size_t k = reinterpret_cast<uintptr_t>(tag) / GrpcSession::kOps;
      auto op = GrpcSession::Op(reinterpret_cast<uintptr_t>(tag) % GrpcSession::kOps);
      GrpcSession& s = sessions[k];
      if (op == GrpcSession::kStarted) {
        s.started = ok;
        if (!ok) finish(k);
      } else if (op == GrpcSession::kWritten) {
        s.writing = false;
        if (!ok) finish(k);
        else if (s.next >= run.count) s.call->WritesDone(grpc_tag(k, GrpcSession::kWritesDone));
      } else if (op == GrpcSession::kRead) {
        s.reading = false;
        if (!ok) {
          finish(k);
        } else {
          std::string reply;
          std::vector<grpc::Slice> slices;
          if (s.reply.Dump(&slices).ok())
            for (const auto& slice : slices) reply.append(reinterpret_cast<const char*>(slice.begin()), slice.size());
          run.record(k, s.next, s.sent_s, answered_s, reply);
          // the last answered: done writing, once its write has completed (one write op at a time)
          if (++s.next >= run.count && !s.writing) s.call->WritesDone(grpc_tag(k, GrpcSession::kWritesDone));
        }
      } else if (op == GrpcSession::kWritesDone) {
        finish(k);
      } else if (op == GrpcSession::kFinished) {
        if (!s.status.ok())
          run.tallies[k].error = "gRPC status " + std::to_string(int(s.status.error_code())) + ": " + s.status.error_message();
        s.finished = true;
        left--;
      }
      // what else is ready, before sending: replies already here are stamped now, not after the sends
      got = queue.AsyncNext(&tag, &ok, gpr_time_0(GPR_CLOCK_MONOTONIC));
    }
  }
  queue.Shutdown();
  void* tag;
  bool ok;
  while (queue.Next(&tag, &ok)) {
  }
}

// --- ZeroMQ: ZMTP 3.0 (https://rfc.zeromq.org/spec/23/, the NULL mechanism) spoken as a DEALER
// on one TCP connection per session, all on this thread (ppoll). The server's ROUTER socket sees
// what a libzmq DEALER sends: the same greeting, READY command and frames. Not libzmq itself: its
// I/O thread woke for every message in each direction, 93-122 us of CPU a frame at 32-64
// sessions (the libzmq thread alone 0.078 of a core at 1,920 frames a second), where a frame here
// costs its send's and its reply's system calls. Plaintext only: the server runs without keys.

struct ZmtpSession {
  int fd = -1;
  std::string in, out;  // received and not yet parsed; to send and not yet sent
  bool greeted = false, ready = false;  // the server's greeting read; its READY read: frames may go
  std::vector<std::string> parts;  // the message being received
  size_t next = 0;  // the frame to send next, or whose reply is awaited
  double sent_s = 0.0;
  bool in_flight = false, finished = false;
};

void zmtp_frame(std::string& out, const char* data, size_t size, uint8_t flags) {  // flags: 1 MORE, 4 COMMAND
  if (size <= 255) {
    out.push_back(char(flags));
    out.push_back(char(size));
  } else {
    out.push_back(char(flags | 2));  // LONG: an 8-byte size
    for (int shift = 56; shift >= 0; shift -= 8) out.push_back(char((uint64_t(size) >> shift) & 0xFF));
  }
  out.append(data, size);
}

int zmtp_connect(const std::string& address) {  // tcp://HOST:PORT
  const std::string scheme = "tcp://";
  size_t colon = address.rfind(':');
  if (address.compare(0, scheme.size(), scheme) != 0 || colon == std::string::npos || colon < scheme.size())
    usage_error("a ZeroMQ address is tcp://HOST:PORT, not " + address);
  std::string host = address.substr(scheme.size(), colon - scheme.size()), port = address.substr(colon + 1);
  if (host.size() > 2 && host.front() == '[' && host.back() == ']') host = host.substr(1, host.size() - 2);
  addrinfo hints{}, *found = nullptr;
  hints.ai_socktype = SOCK_STREAM;
  if (getaddrinfo(host.c_str(), port.c_str(), &hints, &found) != 0 || found == nullptr) usage_error("cannot resolve " + address);
  int fd = -1;
  for (addrinfo* a = found; a != nullptr && fd < 0; a = a->ai_next) {
    fd = socket(a->ai_family, a->ai_socktype, a->ai_protocol);
    if (fd >= 0 && connect(fd, a->ai_addr, a->ai_addrlen) != 0) {
      close(fd);
      fd = -1;
    }
  }
  freeaddrinfo(found);
  if (fd < 0) usage_error("cannot connect to " + address);
  int one = 1;
  setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);  // as libzmq: no frame waits for the next
  fcntl(fd, F_SETFL, fcntl(fd, F_GETFL) | O_NONBLOCK);
  return fd;
}

void run_zmq(Run& run) {
  size_t count = run.options.sessions.size(), left = count;
  std::vector<ZmtpSession> sessions(count);
  std::vector<pollfd> polls(count);
  // The greeting (signature, version 3.0, NULL, as a client, filler) and the READY command naming
  // the socket type, sent at once: the server reads them in order once its own greeting is out.
  std::string hello(64, '\0');
  hello[0] = char(0xFF), hello[9] = char(0x7F), hello[10] = 3, hello[11] = 0;
  std::memcpy(&hello[12], "NULL", 4);
  const std::string ready = std::string("\x05READY\x0bSocket-Type\x00\x00\x00\x06", 22) + "DEALER";
  zmtp_frame(hello, ready.data(), ready.size(), 4);
  for (size_t k = 0; k < count; k++) {
    sessions[k].fd = zmtp_connect(run.options.address);
    sessions[k].out = hello;
  }
  auto finish = [&](size_t k, const std::string& error) {
    ZmtpSession& s = sessions[k];
    if (s.finished) return;
    if (!error.empty()) run.tallies[k].error = error;
    s.finished = true;
    s.in_flight = false;
    left--;
  };
  auto flush = [&](size_t k) {  // what the socket takes now; the rest when it may write again
    ZmtpSession& s = sessions[k];
    while (!s.out.empty()) {
      ssize_t sent = send(s.fd, s.out.data(), s.out.size(), MSG_NOSIGNAL);
      if (sent < 0) {
        if (errno == EAGAIN || errno == EINTR) return;
        finish(k, std::string("ZeroMQ connection: ") + std::strerror(errno));
        s.out.clear();
        return;
      }
      s.out.erase(0, size_t(sent));
    }
  };
  auto message = [&](size_t k, double answered_s) {  // a whole message: [status, reply or error]
    ZmtpSession& s = sessions[k];
    if (s.parts.size() != 2 || s.parts[0] != "0") {
      finish(k, "ZeroMQ status " + (s.parts.empty() ? std::string("?") : s.parts[0]) + ": " +
                    (s.parts.size() > 1 ? s.parts[1] : std::string()));
      return;
    }
    run.record(k, s.next, s.sent_s, answered_s, s.parts[1]);
    s.in_flight = false;
    if (++s.next >= run.count) finish(k, "");
  };
  auto receive = [&](size_t k) {
    ZmtpSession& s = sessions[k];
    char buffer[1 << 16];
    for (;;) {
      ssize_t got = recv(s.fd, buffer, sizeof buffer, 0);
      if (got > 0) {
        s.in.append(buffer, size_t(got));
        continue;
      }
      if (got < 0 && (errno == EAGAIN || errno == EINTR)) break;
      finish(k, got == 0 ? "the server closed the ZeroMQ connection" : std::string("ZeroMQ connection: ") + std::strerror(errno));
      return;
    }
    double answered_s = now_s();
    size_t at = 0;
    if (!s.greeted) {
      if (s.in.size() < 64) return;
      if (uint8_t(s.in[0]) != 0xFF || uint8_t(s.in[9]) != 0x7F || uint8_t(s.in[10]) < 3) {
        finish(k, "not a ZMTP 3 greeting from " + run.options.address);
        return;
      }
      s.greeted = true;
      at = 64;
    }
    while (!s.finished && s.in.size() - at >= 2) {
      uint8_t flags = uint8_t(s.in[at]);
      size_t head = flags & 2 ? 9 : 2;
      if (s.in.size() - at < head) break;
      uint64_t size = 0;
      if (flags & 2)
        for (size_t i = 1; i < 9; i++) size = size << 8 | uint8_t(s.in[at + i]);
      else
        size = uint8_t(s.in[at + 1]);
      if (s.in.size() - at - head < size) break;
      std::string body = s.in.substr(at + head, size);
      at += head + size;
      if (flags & 4) {  // a command: READY, or ERROR with its reason; others (PING) need no answer here
        if (body.compare(0, 6, "\x05" "READY") == 0) s.ready = true;
        else if (body.compare(0, 6, "\x05" "ERROR") == 0)
          finish(k, "ZeroMQ handshake refused: " + (body.size() > 7 ? body.substr(7) : std::string()));
        continue;
      }
      s.parts.push_back(std::move(body));
      if (!(flags & 1)) {
        message(k, answered_s);
        s.parts.clear();
      }
    }
    s.in.erase(0, at);
  };
  for (size_t k = 0; k < count; k++) flush(k);
  while (left > 0) {
    double now = now_s(), soonest = 1e300;
    for (size_t k = 0; k < count; k++) {
      ZmtpSession& s = sessions[k];
      if (s.finished || s.in_flight || !s.ready) continue;
      double due = run.due_s(k, s.next);
      if (due <= now) {
        std::string payload = run.payload(k, s.next);
        zmtp_frame(s.out, "Frame", 5, 1);
        zmtp_frame(s.out, payload.data(), payload.size(), 0);
        s.sent_s = now_s();
        s.in_flight = true;
        flush(k);
      } else {
        soonest = std::min(soonest, due);
      }
    }
    if (left == 0) break;
    for (size_t k = 0; k < count; k++) {
      const ZmtpSession& s = sessions[k];
      polls[k] = {s.finished ? -1 : s.fd, short(POLLIN | (s.out.empty() ? 0 : POLLOUT)), 0};
    }
    timespec wait{}, *timeout = nullptr;  // none: only replies to wait for
    if (soonest < 1e300) {
      double wait_s = std::max(0.0, soonest - now_s());
      wait.tv_sec = time_t(wait_s);
      wait.tv_nsec = long((wait_s - double(wait.tv_sec)) * 1e9);
      timeout = &wait;
    }
    int ready_fds = ppoll(polls.data(), nfds_t(count), timeout, nullptr);
    if (ready_fds < 0 && errno != EINTR) usage_error(std::string("ppoll: ") + std::strerror(errno));
    for (size_t k = 0; ready_fds > 0 && k < count; k++) {
      if (polls[k].revents & POLLOUT) flush(k);
      if (polls[k].revents & (POLLIN | POLLHUP | POLLERR)) receive(k);
    }
  }
  for (const ZmtpSession& s : sessions) close(s.fd);
}

void write_json(const Run& run, double wall_s, double cpu_used_s) {
  std::string out = "{\"received\": [";
  auto numbers = [&out](const std::vector<double>& values, bool first) {
    char text[32];
    for (double v : values) {
      std::snprintf(text, sizeof text, "%s%.6f", first ? "" : ", ", v);
      out += text;
      first = false;
    }
    return first;
  };
  for (size_t k = 0; k < run.tallies.size(); k++) out += (k ? ", " : "") + std::to_string(run.tallies[k].received);
  out += "], \"rtt_ms\": [";
  bool first = true;
  for (const auto& t : run.tallies) first = numbers(t.rtt_ms, first);
  out += "], \"compute_ms\": [";
  first = true;
  for (const auto& t : run.tallies) first = numbers(t.compute_ms, first);
  long late = 0, stale = 0;
  for (const auto& t : run.tallies) late += t.late, stale += t.stale;
  out += "], \"late\": " + std::to_string(late) + ", \"stale\": " + std::to_string(stale) + ", \"errors\": [";
  first = true;
  for (const auto& t : run.tallies) {
    if (t.error.empty()) continue;
    out += first ? "\"" : ", \"";
    for (char c : t.error) {  // a JSON string: quotes, backslashes and control bytes escaped
      if (c == '"' || c == '\\') out += '\\', out += c;
      else if (uint8_t(c) < 0x20) {
        char text[8];
        std::snprintf(text, sizeof text, "\\u%04x", c);
        out += text;
      } else out += c;
    }
    out += "\"";
    first = false;
  }
  char tail[96];
  std::snprintf(tail, sizeof tail, "], \"wall_s\": %.6f, \"cpu_s\": %.6f}\n", wall_s, cpu_used_s);
  out += tail;
  std::fwrite(out.data(), 1, out.size(), stdout);
}

}  // namespace

int main(int argc, char** argv) {
  Run run;
  run.options = parse_options(argc, argv);
  run.frames = read_frames(run.options.frames_path);
  size_t skipped = (run.options.sessions.size() - 1) * run.options.stride;
  if (skipped >= run.frames.size()) usage_error("--stride leaves the last session no frame to send");
  run.count = run.frames.size() - skipped;
  run.tallies.resize(run.options.sessions.size());
  double cpu_start_s = cpu_s(), start_s = run.options.start_s;
  if (run.options.transport == "grpc") run_grpc(run);
  else run_zmq(run);
  write_json(run, now_s() - start_s, cpu_s() - cpu_start_s);
  return 0;
}
