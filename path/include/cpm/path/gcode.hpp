// SPDX-License-Identifier: Apache-2.0
// A G-code reader: the RS274NGC subset a machinist needs for contours on
// this machine, producing the canonical moves LinuxCNC's interpreter
// (rs274) would, and the path queue the planner takes.
//
// Words: G0, G1, G2, G3 (I J K centre, incremental by default, or R
// radius; P turns), G4 P seconds, G17 G18 G19, G20 G21, G90 G91, G90.1
// G91.1, G61 (exact path) and G64 [P tolerance] (blending), F (units per
// minute), N, M2 and M30 (program end; nothing after is read). G40, G49,
// G54, G80 and G94, which only restate what is in force here, are
// accepted (G94 clears the feed, as in LinuxCNC). Comments in ( ) and
// after ;. A program may open with a line holding only '%', and then ends
// at the next such line. Anything else is refused: no parameters,
// expressions, subroutines, spindle or tools.
//
// Units and frames: numbers are read in the program's units (G21 mm,
// G20 inch) and converted at once to SI (m, m/s, s); the canonical moves
// stay in the program's frame (X Y Z as written). ProgramFrame places that
// frame in the machine frame (m, z down): by default program zero at the
// middle of the workspace and the program's Z up, away from the work, as
// machinists write it.
//
// As the RS274NGC order of execution has it, a block's F is read before
// its G20/G21: "G20 F10" is 10 mm/min (then shown as 0.394 in/min), as
// LinuxCNC does.
//
// The whole program is read and checked before anything is returned; all
// its faults come together in one ProgramError, each with line and column.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "cpm/control/machine.hpp"
#include "cpm/path/path.hpp"

namespace cpm::path {

enum class Plane : std::uint8_t { xy, zx, yz };  // G17, G18, G19
enum class Units : std::uint8_t { mm, inch };    // G21, G20

enum class MoveKind : std::uint8_t { traverse, feed, arc, dwell };

// One canonical move (rs274's STRAIGHT_TRAVERSE, STRAIGHT_FEED, ARC_FEED,
// DWELL), in the program's frame, SI.
struct CanonicalMove {
  MoveKind kind = MoveKind::feed;
  int line = 0, column = 0;       // of the block's first axis word (else its first word)
  Vec3 start = Vec3::Zero();      // m
  Vec3 end = Vec3::Zero();        // m
  Vec3 centre = Vec3::Zero();     // arcs: m; along the plane's normal, the start's coordinate
  Plane plane = Plane::xy;        // arcs
  int turn = 0;                   // arcs: > 0 counter-clockwise about the plane's normal, < 0 clockwise
  double feed = 0.0;              // m/s (feed and arc moves)
  double dwell = 0.0;             // s
  Units units = Units::mm;        // in force for this move (how rs274 prints it)
};

struct Diagnostic {
  int line = 0, column = 0;  // 1-based; column 0: the whole line
  std::string message;
};

// Every fault found in a program, as "name:line:column: message" lines.
class ProgramError : public Error {
 public:
  ProgramError(const std::string& name, std::vector<Diagnostic> diagnostics);
  [[nodiscard]] const std::vector<Diagnostic>& diagnostics() const noexcept { return diagnostics_; }

 private:
  std::vector<Diagnostic> diagnostics_;
};

struct ReaderOptions {
  std::string name = "program";  // for messages
  Vec3 start = Vec3::Zero();     // where the platform is, in the program's frame (m)
  int max_errors = 20;           // reading stops after this many faults
};

struct Program {
  Vec3 start = Vec3::Zero();  // where it starts, program frame (m)
  std::vector<CanonicalMove> moves;
  double tolerance = -1.0;  // m, from G64 P / G61 (0); < 0: not set by the program
  bool ended = false;       // M2 or M30 seen
};

// Read a whole program. Throws ProgramError listing every fault.
Program read_program(std::string_view text, const ReaderOptions& options = {});

// The unit normal of a plane in the program's frame (G17: +Z, G18: +Y, G19: +X).
Vec3 plane_normal(Plane plane) noexcept;

// Where the program's frame sits in the machine frame.
struct ProgramFrame {
  Vec3 origin = Vec3(0.425, 0.425, 0.300);  // program zero in the machine frame (m)
  bool z_up = true;  // the program's +Z is the machine's -z
  [[nodiscard]] Vec3 to_machine(const Vec3& p) const noexcept;
  [[nodiscard]] Vec3 to_program(const Vec3& m) const noexcept;
  // A direction (unit normal) as the machine frame sees the same rotation:
  // flipping z mirrors the frame, so the axis is flipped too.
  [[nodiscard]] Vec3 normal_to_machine(const Vec3& n) const noexcept;
};

// A box the platform must stay in besides the machine's workspace (the
// daemon's limits.workspace_min/max), machine frame (m).
struct SoftLimits {
  Vec3 min = Vec3::Constant(-1e9), max = Vec3::Constant(1e9);
};

// Why machine point `q` (m) is outside `soft`, with the figures, "" when it
// is inside (with `margin` m of slack). With `frame`, the point and the limit
// in the program's coordinates (mm) first, the machine's after: "outside the
// soft limits on X: X = 195.000 mm, above the limit X 190.000 mm (machine x
// 615.000 mm)"; without, the machine's only.
std::string soft_limit_text(const Vec3& q, const SoftLimits& soft, const ProgramFrame* frame = nullptr,
                            double margin = 0.0);

// Check every point the program's moves pass (every `step` m along each
// move, and its ends) against the machine's workspace (kin::check_pose:
// strokes, limbs' reach, singularity) and the soft limits. Throws
// ProgramError with each offending move's line and column.
void check_workspace(const Program& program, const ctl::Machine& machine, const ProgramFrame& frame,
                     const SoftLimits& soft = {}, const std::string& name = "program", double step = 1e-3);

// The program's moves in the machine frame, as the planner's queue. The
// tolerance is the program's (G64 P, G61) when it set one, else `tolerance`.
PathQueue to_queue(const Program& program, const ProgramFrame& frame, double tolerance);

}  // namespace cpm::path
