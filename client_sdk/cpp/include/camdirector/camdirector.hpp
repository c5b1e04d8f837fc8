// A thin C++17 wrapper over camdirector.h: RAII for the client, std::string messages for the
// blocking calls. The game-thread functions stay as cheap as the C ones (no allocation): they
// return cd_status and fill caller-owned structs. Threading and blocking rules: camdirector.h.
#ifndef CAMDIRECTOR_HPP
#define CAMDIRECTOR_HPP

#include <cstdio>
#include <string>
#include <utility>
#include <vector>

#include "camdirector/camdirector.h"

namespace camdirector {

// The result of a blocking call: a status code and, when it failed, why.
struct Status {
  cd_status code = CD_OK;
  std::string message;

  bool ok() const { return code == CD_OK; }
  const char* name() const { return cd_status_name(code); }
};

class Client {
 public:
  // Parses the address, reads the key and the CA file (config.key, config.ca_file: camdirector.h,
  // Keys and TLS) and starts the I/O thread (no network yet). On failure the client is empty
  // (valid() is false) and `status` says why.
  explicit Client(const cd_config& config, Status* status = nullptr) {
    char reason[256];
    cd_status code = cd_check_config(&config, reason, sizeof reason);
    if (code == CD_OK) {
      code = cd_client_create(&config, &client_);
      if (code != CD_OK) std::snprintf(reason, sizeof reason, "cd_client_create: %s", cd_status_name(code));
    }
    if (status != nullptr) *status = Status{code, code == CD_OK ? std::string() : std::string(reason)};
  }
  // The defaults, with the key of the CAMDIRECTOR_KEY environment variable if any.
  explicit Client(const std::string& address, Status* status = nullptr)
      : Client(config_for(address), status) {}

  ~Client() { cd_client_destroy(client_); }  // blocks up to about 1 s
  Client(const Client&) = delete;
  Client& operator=(const Client&) = delete;
  Client(Client&& other) noexcept : client_(std::exchange(other.client_, nullptr)) {}
  Client& operator=(Client&& other) noexcept {
    if (this != &other) {
      cd_client_destroy(client_);
      client_ = std::exchange(other.client_, nullptr);
    }
    return *this;
  }

  bool valid() const { return client_ != nullptr; }
  cd_client* handle() const { return client_; }

  // --- blocking, each with a deadline -----------------------------------------------------
  Status open(const cd_session_desc& desc, double timeout_s = 10.0) {
    return result(cd_session_open(client_, &desc, timeout_s));
  }
  Status open_serialized(const std::string& request, double timeout_s = 10.0) {
    return result(cd_session_open_serialized(client_, request.data(), request.size(), timeout_s));
  }
  Status update_style(const cd_style& style, double timeout_s = 10.0) {
    return result(cd_session_update_style(client_, &style, timeout_s));
  }
  Status take_shot(const std::vector<std::string>& subjects, int kind = 0, cd_shot* shot = nullptr,
                   double timeout_s = 10.0) {
    std::vector<const char*> ids;
    for (const std::string& s : subjects) ids.push_back(s.c_str());
    return result(cd_session_take_shot(client_, ids.data(), static_cast<uint32_t>(ids.size()), kind, 0, shot,
                                       timeout_s));
  }
  Status release_shot(double timeout_s = 10.0) {
    return result(cd_session_take_shot(client_, nullptr, 0, 0, 1, nullptr, timeout_s));
  }
  Status flush(double timeout_s = 10.0) { return result(cd_session_flush(client_, timeout_s)); }
  Status close(uint64_t* frames_answered = nullptr, double timeout_s = 10.0) {
    return result(cd_session_close(client_, frames_answered, timeout_s));
  }

  // --- game thread: non-blocking, no allocation ---------------------------------------------
  cd_status submit(uint64_t frame, double time_s, const cd_state* states, uint32_t count) {
    return cd_frame_submit(client_, frame, time_s, states, count);
  }
  cd_status poll(cd_pose* pose) { return cd_pose_poll(client_, pose); }
  cd_status poll_event(cd_event* event) { return cd_event_poll(client_, event); }
  cd_stats stats() const {
    cd_stats s{};
    cd_client_stats(client_, &s);
    return s;
  }
  int32_t slot(const char* id) const { return cd_session_slot(client_, id); }
  // Allocates: call it outside the frame loop.
  std::string session_id() const {
    char buf[128];
    cd_session_id(client_, buf, sizeof buf);
    return buf;
  }

 private:
  static cd_config config_for(const std::string& address) {
    cd_config config;
    cd_config_init(&config);
    config.address = address.c_str();  // read by the constructor only
    return config;
  }

  Status result(cd_status code) {
    if (code == CD_OK) return {};
    char buf[512] = "";
    cd_last_error(client_, buf, sizeof buf);
    return Status{code, buf};
  }

  cd_client* client_ = nullptr;
};

}  // namespace camdirector

#endif  // CAMDIRECTOR_HPP
