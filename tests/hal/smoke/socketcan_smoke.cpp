// SPDX-License-Identifier: Apache-2.0
// SocketCAN on a real kernel: two sockets on one interface (vcan0 by default)
// exchange a data frame through a filter and an injected error frame.
// Run by the SIL VM runner; exits 77 (skipped) where the kernel has no CAN
// or the interface does not exist, 0 on success, 1 on failure.
#include <linux/can.h>
#include <linux/can/error.h>
#include <net/if.h>

#include <cstdio>
#include <cstring>
#include <string>

#include "cpm/hal/socketcan.hpp"
#include "cpm/program_cli.hpp"

using namespace cpm::hal;

namespace {
int failures = 0;
void check(bool ok, const char* what) {
  std::printf("%s: %s\n", ok ? "ok  " : "FAIL", what);
  if (!ok) ++failures;
}
bool receive(SocketCanBus& bus, CanFrame& f) {
  for (int i = 0; i < 20; ++i) {
    if (bus.receive(f).ok()) return true;
    bus.wait_receivable(50'000'000);
  }
  return false;
}
}  // namespace

int main(int argc, char** argv) {
  std::string ifname = "vcan0";
  CLI::App app{"hal_socketcan_smoke: two SocketCAN sockets on one interface exchange a frame and an error frame",
               "hal_socketcan_smoke"};
  cpm::program::setup(app);
  app.add_option("INTERFACE", ifname, "the CAN interface")->type_name("IF");
  app.footer("Exit status: 0 passed, 1 failed, 2 a bad command line, 77 skipped (no CAN, no such interface).");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return cpm::program::parse_exit(app, e, "hal_socketcan_smoke");
  }
  std::string why;
  if (!SocketCanBus::available(&why)) {
    std::printf("SKIP: %s\n", why.c_str());
    return 77;
  }
  if (if_nametoindex(ifname.c_str()) == 0) {
    std::printf("SKIP: no interface %s (ip link add dev %s type vcan && ip link set %s up)\n", ifname.c_str(),
                ifname.c_str(), ifname.c_str());
    return 77;
  }
  try {
    SocketCanBus a(ifname), b(ifname);
    const CanFilter only_0x123[] = {{0x123, CAN_SFF_MASK}};
    b.set_filters(only_0x123, true);
    CanFrame f;
    f.id = 0x321;
    f.len = 1;
    check(a.send(f).ok(), "send a frame the filter rejects");
    f.id = 0x123;
    f.len = 4;
    f.data = {0xDE, 0xAD, 0xBE, 0xEF};
    check(a.send(f).ok(), "send 0x123 [DE AD BE EF]");
    CanFrame g;
    const bool got = receive(b, g);
    check(got && g.cob_id() == 0x123 && g.len == 4 && g.data[0] == 0xDE && g.data[3] == 0xEF,
          "receive it through the filter, intact");
    check(got && g.timestamp_ns > 0, "kernel receive timestamp present");
    // vcan echoes an error frame written by a socket to the sockets that asked
    // for error frames: the way to see the decoding on a kernel without a controller.
    CanFrame e = make_error_frame(CAN_ERR_BUSOFF | CAN_ERR_CRTL, CAN_ERR_CRTL_TX_PASSIVE, 0, 255, 0);
    const Status s = a.send(e);
    check(s.ok(), "send an error frame (bus-off) on the interface");
    CanFrame h;
    const bool got_err = receive(b, h);
    const CanErrorInfo info = decode_error_frame(h);
    char text[200];
    describe_error_frame(info, text, sizeof text);
    std::printf("      error frame: %s\n", got_err ? text : "(none)");
    check(got_err && h.is_error() && info.bus_off && info.state == BusState::bus_off, "receive and decode it as bus-off");
    check(b.stats().error_frames == 1 && b.stats().rx_frames == 1, "statistics count one data and one error frame");
  } catch (const Error& e) {
    std::printf("FAIL: %s\n", e.what());
    return 1;
  }
  std::printf("%s\n", failures ? "socketcan smoke: FAILED" : "socketcan smoke: passed");
  return failures ? 1 : 0;
}
