#include "retry.h"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdlib>

namespace camdirector::sdk {

double backoff_delay_s(double initial_s, double max_s, double window_s, double elapsed_s, int tries, double random01) {
  const double left_s = window_s - elapsed_s;
  if (!(left_s > 0.0)) return -1.0;
  const double cap_s = std::min(max_s, initial_s * std::ldexp(1.0, std::min(tries, 60)));
  const double r = std::isfinite(random01) ? std::clamp(random01, 0.0, 1.0) : 0.5;  // a bad source: no jitter
  return std::min(left_s, cap_s * (0.5 + 0.5 * r));
}

bool parse_resend_from(const std::string& message, uint64_t* frame) {
  static const char kMarker[] = "resend from ";
  const size_t at = message.find(kMarker);
  if (at == std::string::npos) return false;
  const char* digits = message.c_str() + at + sizeof kMarker - 1;
  if (*digits < '0' || *digits > '9') return false;
  char* end = nullptr;
  errno = 0;
  const unsigned long long k = std::strtoull(digits, &end, 10);
  if (errno == ERANGE) return false;
  *frame = static_cast<uint64_t>(k);
  return true;
}

}  // namespace camdirector::sdk
