// SPDX-License-Identifier: Apache-2.0
// Writes the binary seed inputs of the fuzz targets whose inputs are not
// text (LCM messages, frame scripts) into fuzz/corpus/<target>/seed-*:
//   build/fuzz/fuzz_make_seeds fuzz/corpus
// The seeds are valid, interesting sessions the fuzzer mutates from: the
// paper's circle, a move, a stream, a select-controller, a flood; a master
// and drives brought up and enabled; SDO transfers of every kind.
#include <cmath>
#include <cstring>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include <cpm_msgs/ack_t.hpp>
#include <cpm_msgs/control_command_t.hpp>
#include <cpm_msgs/trajectory_command_t.hpp>

#include "cpm/hal/canopen.hpp"
#include "cpm/hal/cia402.hpp"
#include "cpm/hal/pdo.hpp"
#include "cpm/program_cli.hpp"

using Bytes = std::vector<std::uint8_t>;
using cpm_msgs::control_command_t;
using cpm_msgs::trajectory_command_t;
namespace fs = std::filesystem;

namespace {

fs::path root;

void write(const std::string& target, const std::string& name, const Bytes& b) {
  fs::create_directories(root / target);
  std::ofstream(root / target / ("seed-" + name), std::ios::binary)
      .write(reinterpret_cast<const char*>(b.data()), static_cast<std::streamsize>(b.size()));
}

template <class M>
Bytes encode(const M& m) {
  Bytes b(static_cast<std::size_t>(m.getEncodedSize()));
  m.encode(b.data(), 0, static_cast<int>(b.size()));
  return b;
}

// lcm_session signs as operator alice (fuzz/targets/lcm_session.cpp): the
// name is in the seed, the MAC the target's.
template <class M>
void as_alice(M& m) {
  std::memcpy(m.operator_name, "alice", 5);
}

trajectory_command_t move(double x, double y, double z, double v = 0.1) {
  trajectory_command_t m{};
  as_alice(m);
  m.id = 100;
  m.kind = trajectory_command_t::KIND_MOVE;
  m.target[0] = x, m.target[1] = y, m.target[2] = z;
  m.max_velocity = v, m.max_acceleration = 1.0, m.max_jerk = 50.0;
  return m;
}
trajectory_command_t circle() {  // Elkady's test circle from P1
  trajectory_command_t m{};
  as_alice(m);
  m.id = 101;
  m.utime = 1;
  m.kind = trajectory_command_t::KIND_CIRCLE;
  m.centre[0] = 0.425, m.centre[1] = 0.425, m.centre[2] = 0.300;
  m.radius = 0.175, m.angular_speed = M_PI / 2, m.cruise_time = 4.0, m.ramp_time = 0.2;
  return m;
}
trajectory_command_t stream(double x0, double y0, double z0) {
  trajectory_command_t m{};
  as_alice(m);
  m.id = 102;
  m.utime = 1;
  m.kind = trajectory_command_t::KIND_STREAM;
  m.count = 5;
  for (int i = 0; i < 5; ++i) {
    m.time[i] = 0.05 * i;
    m.position[i][0] = x0 - 0.001 * i * i, m.position[i][1] = y0, m.position[i][2] = z0;
    m.velocity[i][0] = -0.04 * i;
  }
  m.velocity[4][0] = 0;
  return m;
}
control_command_t control(std::int8_t cmd, std::int64_t id) {
  control_command_t m{};
  as_alice(m);
  m.id = id;
  m.command = cmd;
  return m;
}

// lcm_session records.
void msg(Bytes& s, int op, const Bytes& b) {
  s.push_back(static_cast<std::uint8_t>(op));
  s.push_back(static_cast<std::uint8_t>(b.size() & 0xFF));
  s.push_back(static_cast<std::uint8_t>(b.size() >> 8));
  s.insert(s.end(), b.begin(), b.end());
}
void cycles(Bytes& s, int n) {
  while (n > 0) {
    const int k = std::min(n, 64);
    s.push_back(2);
    s.push_back(static_cast<std::uint8_t>(k - 1));
    n -= k;
  }
}

// can_common.hpp records: op (family | after << 3), node, len, data.
void frame(Bytes& s, int family, int after, int node, const cpm::hal::CanFrame& f) {
  s.push_back(static_cast<std::uint8_t>((family & 7) | ((after & 15) << 3)));
  s.push_back(static_cast<std::uint8_t>(node));
  s.push_back(f.len);
  s.insert(s.end(), f.data.begin(), f.data.begin() + f.len);
}
cpm::hal::CanFrame bytes_frame(std::initializer_list<int> d) {
  cpm::hal::CanFrame f;
  f.len = static_cast<std::uint8_t>(d.size());
  int i = 0;
  for (int v : d) f.data[static_cast<std::size_t>(i++)] = static_cast<std::uint8_t>(v);
  return f;
}
cpm::hal::CanFrame sdo_download_u32(std::uint16_t index, std::uint8_t sub, std::uint32_t v, int bytes = 4) {
  const int n = 4 - bytes;
  return bytes_frame({0x23 | (n << 2), index & 0xFF, index >> 8, sub, static_cast<int>(v & 0xFF),
                      static_cast<int>((v >> 8) & 0xFF), static_cast<int>((v >> 16) & 0xFF),
                      static_cast<int>(v >> 24)});
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"fuzz_make_seeds: the binary seeds of the fuzz targets' corpora", "fuzz_make_seeds"};
  cpm::program::setup(app);
  app.add_option("CORPUS_ROOT", root, "the corpora's folder (fuzz/corpus)")->type_name("DIR")->required();
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return cpm::program::parse_exit(app, e, "fuzz_make_seeds");
  }

  // ---- lcm_trajectory: one message each.
  write("lcm_trajectory", "move", encode(move(0.45, 0.40, 0.35)));
  write("lcm_trajectory", "circle", encode(circle()));
  write("lcm_trajectory", "stream", encode(stream(0.600, 0.425, 0.300)));

  // ---- lcm_session: scripts.
  {
    Bytes s;
    cycles(s, 3);
    msg(s, 0, encode(control(control_command_t::CMD_ENABLE, 1)));
    cycles(s, 30);
    msg(s, 1, encode(move(0.55, 0.425, 0.300)));
    cycles(s, 200);
    msg(s, 0, encode(control(control_command_t::CMD_STOP, 2)));
    cycles(s, 200);
    msg(s, 0, encode(control(control_command_t::CMD_DISABLE, 3)));
    cycles(s, 20);
    write("lcm_session", "enable-move-stop", s);
  }
  {
    Bytes s;
    msg(s, 0, encode(control(control_command_t::CMD_ENABLE, 1)));
    cycles(s, 30);
    msg(s, 1, encode(circle()));
    cycles(s, 100);
    // A flood while moving: 40 pings and segments between two cycles.
    for (int i = 0; i < 20; ++i) {
      msg(s, 0, encode(control(control_command_t::CMD_PING, 10 + i)));
      msg(s, 1, encode(move(0.45, 0.40, 0.35)));
    }
    cycles(s, 64);
    s.push_back(3), s.push_back(1);  // e-stop
    cycles(s, 2);
    s.push_back(3), s.push_back(0);
    msg(s, 0, encode(control(control_command_t::CMD_RESET, 50)));
    cycles(s, 5);
    write("lcm_session", "circle-flood-estop-reset", s);
  }
  {
    Bytes s;
    control_command_t c = control(control_command_t::CMD_SELECT_CONTROLLER, 7);
    c.law = 0;
    c.kp[0] = c.kp[1] = c.kp[2] = 2e4;
    c.kd[0] = c.kd[1] = c.kd[2] = 300;
    msg(s, 0, encode(c));
    cycles(s, 2);
    control_command_t l = control(control_command_t::CMD_LOAD_MODEL, 8);
    l.model_path = "x";
    msg(s, 0, encode(l));
    cycles(s, 2);
    msg(s, 0, encode(control(control_command_t::CMD_ENABLE, 9)));
    cycles(s, 30);
    msg(s, 1, encode(stream(0.600, 0.425, 0.300)));
    cycles(s, 300);
    write("lcm_session", "controller-model-stream", s);
  }

  // ---- lcm_ack: acks as cpmd sends them (lcm_session's scripts are
  // unsigned here: the target signs what it stamps).
  {
    cpm_msgs::ack_t a{};
    a.id = 7;
    a.source = 1;
    a.command = control_command_t::CMD_ACQUIRE;
    a.accepted = true;
    a.session = 0x1234567;
    write("lcm_ack", "acquire-accepted", encode(a));
    a.accepted = false;
    a.reason = cpm_msgs::ack_t::REASON_NOT_AUTHORIZED;
    a.message = "not authorized (docs/security.md)";
    a.session = 0;
    write("lcm_ack", "not-authorized", encode(a));
  }

  // ---- can_master: enable all, run, then strangers' frames.
  using namespace cpm::hal;
  using namespace cpm::hal::canopen;
  {
    Bytes s;
    for (int i = 0; i < 4; ++i) frame(s, 1, 15, 0x20, make_sync());  // SYNC from a stranger, cycles enabled
    Emcy e;
    e.code = 0x2310;
    e.error_register = 0x03;
    frame(s, 2, 4, 0x22, make_emcy(2, e));
    frame(s, 6, 4, 0x21, make_heartbeat(1, canopen::NmtState::preoperational));
    frame(s, 3, 4, 0x23, pdo::pack_rpdo1(3, 0x27, 100));  // a TPDO1 lookalike of node 3 (6 bytes below)
    frame(s, 3, 4, 0x21, bytes_frame({0x37, 0x06, 0x10, 0x27, 0, 0}));
    frame(s, 4, 4, 0x22, bytes_frame({0x10, 0, 0, 0}));
    frame(s, 5, 4, 0x21, bytes_frame({0x60, 0x40, 0x60, 0, 0, 0, 0, 0}));
    frame(s, 0, 4, 0x61, make_nmt(canopen::NmtCommand::stop, 2));
    frame(s, 7, 4, 0x93, bytes_frame({0x40, 0x20}));  // an error frame
    frame(s, 1, 15, 0xE0, make_sync());                  // fault reset + reset_faults
    write("can_master", "enable-strangers", s);
  }

  // ---- can_drive: NMT start, configure by SDO, enable by RPDO, SYNCs.
  {
    Bytes s;
    frame(s, 0, 1, 0, make_nmt(canopen::NmtCommand::start, 1));
    frame(s, 4, 1, 1, sdo_download_u32(0x6060, 0, 10, 1));    // modes of operation: CST
    frame(s, 4, 1, 1, sdo_download_u32(0x1016, 1, (127u << 16) | 150u));
    frame(s, 4, 1, 1, sdo_download_u32(0x1017, 0, 50, 2));
    frame(s, 4, 1, 1, bytes_frame({0x40, 0x00, 0x10, 0x00, 0, 0, 0, 0}));  // upload 0x1000
    frame(s, 4, 1, 1, bytes_frame({0x40, 0x08, 0x10, 0x00, 0, 0, 0, 0}));  // upload 0x1008 (segmented)
    frame(s, 4, 1, 1, bytes_frame({0x60, 0, 0, 0, 0, 0, 0, 0}));
    frame(s, 4, 1, 1, bytes_frame({0x70, 0, 0, 0, 0, 0, 0, 0}));
    frame(s, 4, 1, 1, bytes_frame({0x21, 0x00, 0x16, 0x01, 4, 0, 0, 0}));  // segmented download 0x1600:01
    frame(s, 4, 1, 1, bytes_frame({0x05, 0x10, 0x00, 0x40, 0x60, 0, 0, 0}));
    for (int cw : {0x06, 0x07, 0x0F, 0x0F, 0x0F}) {
      frame(s, 2, 0, 1, pdo::pack_rpdo1(1, static_cast<std::uint16_t>(cw), 300));
      frame(s, 1, 2, 0, make_sync());
    }
    frame(s, 6, 8, 0, make_heartbeat(127, canopen::NmtState::operational));
    frame(s, 0, 1, 0, make_nmt(canopen::NmtCommand::reset_communication, 0));
    write("can_drive", "bring-up", s);
  }

  // ---- sdo_client: how, index (u16), size byte, then the server's answers.
  {
    Bytes s = {0x01 | 0x10, 0x00, 0x10, 0};  // upload 0x1000:01, expedited answer
    frame(s, 0, 0, 2, bytes_frame({0x43, 0x00, 0x10, 0x01, 0x92, 0x01, 0x02, 0x00}));
    write("sdo_client", "upload-expedited", s);
  }
  {
    Bytes s = {0x01, 0x08, 0x10, 0};  // upload 0x1008:00, segmented answer of 10 bytes
    frame(s, 0, 0, 2, bytes_frame({0x41, 0x08, 0x10, 0x00, 10, 0, 0, 0}));
    frame(s, 0, 0, 2, bytes_frame({0x00, 'c', 'p', 'm', ' ', 'd', 'r', 'i'}));
    frame(s, 0, 0, 2, bytes_frame({0x1B, 'v', 'e', 0, 0, 0, 0, 0}));
    write("sdo_client", "upload-segmented", s);
  }
  {
    Bytes s = {0x02, 0x00, 0x16, 3};  // download 15 bytes to 0x1600:00, segmented
    frame(s, 0, 0, 2, bytes_frame({0x60, 0x00, 0x16, 0x00, 0, 0, 0, 0}));
    frame(s, 0, 0, 2, bytes_frame({0x20, 0, 0, 0, 0, 0, 0, 0}));
    frame(s, 0, 0, 2, bytes_frame({0x30, 0, 0, 0, 0, 0, 0, 0}));
    frame(s, 0, 0, 2, bytes_frame({0x20, 0, 0, 0, 0, 0, 0, 0}));
    write("sdo_client", "download-segmented", s);
  }
  {
    Bytes s = {0x00, 0x60, 0x60, 0};  // download, aborted by the server
    const CanFrame a = canopen::make_sdo_abort(0x582, 0x6060, 0, 0x06090030);
    frame(s, 0, 0, 2, a);
    write("sdo_client", "download-aborted", s);
    Bytes t = {0x01, 0x60, 0x60, 0};  // upload, no answer: timeout
    frame(t, 6, 15, 3, bytes_frame({0x43, 0x60, 0x60, 0, 1, 0, 0, 0}));
    write("sdo_client", "upload-timeout", t);
  }

  // ---- can_frames: id (u32), len, 8 data bytes, buffer size.
  {
    Bytes s = {0x82, 0, 0, 0, 8, 0x10, 0x23, 0x03, 1, 2, 3, 4, 5, 40};  // EMCY of node 2
    write("can_frames", "emcy", s);
    Bytes e = {0x44, 0, 0, 0x20, 8, 0, 0x20, 0, 0, 0, 0, 0x80, 0x90, 100};  // error frame: passive
    write("can_frames", "error-frame", e);
    Bytes t = {0x81, 0x01, 0, 0, 6, 0x37, 0x06, 0x10, 0x27, 0, 0, 0, 0, 20};  // TPDO1
    write("can_frames", "tpdo1", t);
  }
  std::printf("seeds written under %s\n", root.c_str());
  return 0;
}
