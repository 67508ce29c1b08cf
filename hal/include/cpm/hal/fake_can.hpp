// SPDX-License-Identifier: Apache-2.0
// An in-process CAN bus with several ports and fault injection, for fast,
// deterministic tests. Time is the network's Clock: a frame sent at t is
// receivable at t + latency (+ injected delay). Queues are preallocated, so
// send and receive allocate nothing.
#pragma once

#include <cstdint>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "cpm/hal/can.hpp"

namespace cpm::hal {

class FakeCanNetwork;

class FakeCanPort final : public CanBus {
 public:
  Status send(const CanFrame& f) noexcept override;
  Status receive(CanFrame& f) noexcept override;
  void set_filters(std::span<const CanFilter> filters, bool error_frames) override;
  bool wait_receivable(std::int64_t timeout_ns) override;
  [[nodiscard]] const CanStats& stats() const noexcept override { return stats_; }
  [[nodiscard]] const std::string& name() const noexcept { return name_; }
  [[nodiscard]] std::size_t pending() const noexcept { return count_; }
  // Whether this port is bus-off (its sends fail) — set by the network.
  [[nodiscard]] bool bus_off() const noexcept { return bus_off_; }

 private:
  friend class FakeCanNetwork;
  FakeCanPort(FakeCanNetwork& net, std::string name, std::size_t capacity);
  bool accepts(const CanFrame& f) const noexcept;
  void push(const CanFrame& f) noexcept;

  FakeCanNetwork& net_;
  std::string name_;
  std::vector<CanFrame> ring_;
  std::size_t head_ = 0, count_ = 0;
  std::array<CanFilter, 16> filters_{};
  std::size_t filter_count_ = 0;
  bool error_frames_ = true;
  bool bus_off_ = false;
  CanStats stats_;
};

// How an injected corruption changes a frame.
enum class Corruption : std::uint8_t {
  crc,        // destroyed on the wire: every port sees a protocol error frame, the sender retransmits (delivered intact)
  data_bit,   // a data bit flipped and delivered (a faulty node or gateway)
  length,     // delivered with a wrong data length (len - 1, or 1 when empty)
};

class FakeCanNetwork {
 public:
  explicit FakeCanNetwork(Clock& clock, std::int64_t latency_ns = 0, std::size_t queue_capacity = 1024);
  FakeCanNetwork(const FakeCanNetwork&) = delete;
  FakeCanNetwork& operator=(const FakeCanNetwork&) = delete;
  ~FakeCanNetwork();

  // A new node on the bus; the reference stays valid for the network's life.
  FakeCanPort& add_port(const std::string& name);

  // --- fault injection. Selectors match the sent frame's id: (id & mask) == (match & mask).
  // Drop the next `count` matching frames (count < 0: all, until cleared).
  void drop(std::uint32_t match, std::uint32_t mask, int count = 1);
  // Drop every frame with probability p (deterministic with `seed`).
  void drop_randomly(double p, std::uint64_t seed);
  // Deliver the next `count` matching frames `delay_ns` late.
  void delay(std::uint32_t match, std::uint32_t mask, std::int64_t delay_ns, int count = 1);
  void corrupt(std::uint32_t match, std::uint32_t mask, Corruption how, int count = 1);
  void clear_faults();
  // Put every port bus-off (error frame CAN_ERR_BUSOFF to all; sends fail)
  // or restart them (error frame CAN_ERR_RESTARTED).
  void set_bus_off(bool off);
  // Deliver an error frame to every port (e.g. error passive).
  void inject_error_frame(const CanFrame& f);

  [[nodiscard]] Clock& clock() noexcept { return clock_; }
  [[nodiscard]] std::uint64_t frames_on_wire() const noexcept { return wire_frames_; }
  // Sum of worst-case stuffed bits of every frame put on the wire.
  [[nodiscard]] std::uint64_t bits_on_wire() const noexcept { return wire_bits_; }

 private:
  friend class FakeCanPort;
  struct Rule {
    std::uint32_t match, mask;
    int remaining;  // < 0: unlimited
    int kind;       // 0 drop, 1 delay, 2 corrupt
    std::int64_t delay_ns;
    Corruption how;
  };
  struct Pending {
    CanFrame frame;
    const FakeCanPort* sender;
    std::int64_t due_ns;
    std::uint64_t seq;
  };
  Status transmit(const FakeCanPort& from, const CanFrame& f) noexcept;
  void deliver(const FakeCanPort* from, const CanFrame& f) noexcept;
  void deliver_due() noexcept;

  Clock& clock_;
  std::int64_t latency_ns_;
  std::size_t capacity_;
  std::vector<std::unique_ptr<FakeCanPort>> ports_;
  std::vector<Rule> rules_;
  std::vector<Pending> pending_;   // reserved; kept small
  std::uint64_t seq_ = 0;
  double drop_p_ = 0.0;
  std::mt19937_64 rng_;
  bool bus_off_ = false;
  std::uint64_t wire_frames_ = 0, wire_bits_ = 0;
};

}  // namespace cpm::hal
