// SPDX-License-Identifier: Apache-2.0
// An example client of cpmd: reads one state message from a running cpmd and
// prints the platform's position, the mode, the faults and the tracking error
// of the last finished segment, and whether it was verified as cpmd's.
// Reading needs no operator key; commands
// would (cpmd::daemon::find_credentials, docs/security.md).
//
// The LCM URL is LCM's own LCM_DEFAULT_URL when set, else cpmd's default
// (udpm://239.255.76.67:7667?ttl=0); the channels are cpmd's defaults.
#include <cpm/daemon/client.hpp>

#include <cstdio>
#include <cstdlib>

int main() {
  cpm::daemon::LcmConfig lcm;
  if (const char* url = std::getenv("LCM_DEFAULT_URL")) lcm.url = url;
  try {
    cpm::daemon::Client client(lcm);
    const std::optional<cpm_msgs::state_t> s = client.state(2.0);
    if (!s && client.verifying() && client.verifier()->refused_total() > 0) {
      // Said above, cause by cause: forged, tampered, replayed, or an unsigned cpmd.
      std::fprintf(stderr, "no verified state from cpmd within 2 s: %lld messages refused\n",
                   static_cast<long long>(client.verifier()->refused_total()));
      return 1;
    }
    if (!s) {
      std::fprintf(stderr, "no %sstate from cpmd on %s within 2 s: is it running?\n",
                   client.verifying() ? "verified " : "", lcm.url.c_str());
      return 1;
    }
    // With cpmd's public key ($CPM_DAEMON_KEY, ~/.config/cpm/cpmd.pub) only
    // state a seal of cpmd lists reaches here (docs/security.md, "Signed state").
    std::printf("state %s\n", client.verifying() ? "signed by cpmd and verified" : "NOT VERIFIED (no public key of cpmd)");
    // Machine frame (z down), metres; printed in mm.
    std::printf("cycle %lld: %s, platform at x %.3f y %.3f z %.3f mm\n", static_cast<long long>(s->cycle),
                cpm::daemon::mode_text(s->mode), s->position[0] * 1e3, s->position[1] * 1e3, s->position[2] * 1e3);
    if (s->faults) std::printf("faults: %s\n", cpm::daemon::fault_text(s->faults).c_str());
    if (s->last_segment_id >= 0)
      std::printf("last segment %lld: tracking error RMS %.1f um, max %.1f um\n",
                  static_cast<long long>(s->last_segment_id), s->last_segment_rmse * 1e6, s->last_segment_max * 1e6);
    return 0;
  } catch (const cpm::Error& e) {
    std::fprintf(stderr, "cpmd-example-client: %s\n", e.what());
    return 1;
  }
}
