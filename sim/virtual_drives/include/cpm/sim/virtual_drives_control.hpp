// SPDX-License-Identifier: Apache-2.0
// The virtual drives' fault-injection protocol: one command per text line,
// the same from the command line (--fault), stdin and the UNIX control
// socket (docs/canopen-backend.md). AXIS is 1, 2, 3 or x, y, z.
//
//   heartbeat AXIS off|on          stop / resume the drive's heartbeat
//   emcy AXIS CODE [REG]           send an EMCY (hex CODE, e.g. 0x2310), no state change
//   fault AXIS CODE [persistent]   drive fault: fault reaction, fault, EMCY CODE;
//                                  persistent: fault reset refused until "clear AXIS"
//   clear AXIS                     the persistent fault's cause is gone
//   refuse AXIS COMMAND on|off     ignore a device control command: shutdown,
//                                  switch_on, enable_operation, disable_voltage,
//                                  quick_stop, fault_reset
//   late AXIS MS                   answer SDO requests MS milliseconds late (0: on time)
//   silent AXIS on|off             the drive neither receives nor sends
//   disappear | reappear           every drive vanishes / powers up again (boot-up)
//   home-switch AXIS dead|ok       the axis's home switch never actuates (broken) / works
//   status                         one line: syncs, plant steps, position (m), drive states
//   quit                           leave the process (the drives vanish from the bus)
//
// The answer is one line: "ok ..." or "error: <why>".
#pragma once

#include <cstdint>
#include <string>

#include "cpm/sim/virtual_machine.hpp"

namespace cpm::sim {

// Execute one line; `quit` is set by "quit". Never throws on bad input.
std::string execute_control(VirtualMachine& vm, const std::string& line, std::int64_t now_ns, bool& quit);

}  // namespace cpm::sim
