// main() of the process-level reliability tests: cpmd and this client talk
// LCM in a private network namespace when the test may make one (root, as
// on CI), otherwise on the host's loopback with ttl=0 and a private port.
#include <gtest/gtest.h>
#include <sched.h>
#include <unistd.h>

#include <cstdio>
#include <cstdlib>

#include "reliability/process_rig.hpp"

namespace cpm::daemon::test {
bool g_netns = false;
}

int main(int argc, char** argv) {
  ::testing::InitGoogleTest(&argc, argv);
  if (geteuid() == 0 && unshare(CLONE_NEWNET) == 0) {
    cpm::daemon::test::g_netns = std::system("ip link set lo up && ip route add 224.0.0.0/4 dev lo") == 0;
    if (!cpm::daemon::test::g_netns) std::fprintf(stderr, "cannot set up lo in the new network namespace\n");
  }
  return RUN_ALL_TESTS();
}
