// The retry arithmetic of the I/O thread, free of gRPC so that the unit tests can check it
// (tests/unit_tests.cpp): the jittered backoff within a retry window, and the frame a DATA_LOSS
// answer asks to be sent again from. The Python SDK's wire.Backoff and wire.resend_from.
#ifndef CAMDIRECTOR_RETRY_H
#define CAMDIRECTOR_RETRY_H

#include <cstdint>
#include <string>

namespace camdirector::sdk {

// The wait before try number `tries` (0 for the first after a failure), `elapsed_s` into a retry
// window of `window_s`: a cap of initial_s * 2^tries, at most max_s, of which half is fixed and
// half scaled by `random01` (equal jitter), and never past the window's end. Negative once the
// window is spent: give up.
double backoff_delay_s(double initial_s, double max_s, double window_s, double elapsed_s, int tries, double random01);

// The K of a DATA_LOSS message "... resend from K ..." (docs/protocol.md, Checkpoints); false when
// the message asks for no resend.
bool parse_resend_from(const std::string& message, uint64_t* frame);

}  // namespace camdirector::sdk

#endif  // CAMDIRECTOR_RETRY_H
