// SPDX-License-Identifier: Apache-2.0
// main() of the process-level tests (support/daemon_process.hpp): the test
// and the daemons it starts talk LCM in a private network namespace when the
// test may make one (root, as on CI), otherwise on the host's loopback with
// ttl=0 and a private port.
#include <gtest/gtest.h>
#include <sched.h>
#include <unistd.h>

#include <cstdio>
#include <cstdlib>

#include "support/daemon_process.hpp"

namespace cpm::test {

bool g_netns = false;

bool enter_private_netns() {
  if (::geteuid() != 0 || ::unshare(CLONE_NEWNET) != 0) return false;
  if (std::system("ip link set lo up && ip route add 224.0.0.0/4 dev lo") != 0) {
    std::fprintf(stderr, "cannot set up lo in the new network namespace\n");
    return false;
  }
  return true;
}

}  // namespace cpm::test

int main(int argc, char** argv) {
  ::testing::InitGoogleTest(&argc, argv);
  cpm::test::g_netns = cpm::test::enter_private_netns();
  return RUN_ALL_TESTS();
}
