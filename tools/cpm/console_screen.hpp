// SPDX-License-Identifier: Apache-2.0
// The terminal of cpm watch and cpm jog, through ncurses (docs/cli.md says
// why): the alternate screen, keys one at a time without echo, the arrows
// and page keys decoded from whatever the terminal sends (terminfo), the
// window's size followed (SIGWINCH), and the terminal given back as it was
// on every way out (q, Ctrl-C, SIGTERM, an exception). What is drawn comes
// from console.hpp's pure functions.
#pragma once

#include <memory>

#include "console.hpp"

namespace cpm::cli::console {

class Screen {
 public:
  // The terminal on stdin/stdout; nullptr when either is not a terminal or
  // the terminal's type is unknown (the caller then prints plain text).
  // Ctrl-C and SIGTERM then set interrupted() instead of ending the process.
  static std::unique_ptr<Screen> open();
  ~Screen();  // the terminal as it was
  Screen(const Screen&) = delete;
  Screen& operator=(const Screen&) = delete;

  [[nodiscard]] int width() const;
  [[nodiscard]] int height() const;
  // Redraw with `lines` (ncurses sends only what changed).
  void draw(const Lines& lines);
  // The next key within `timeout_ms` (0: only one already there), -1 none.
  int key(int timeout_ms);
  // What a key does in cpm jog (arrows, PgUp/PgDn, 1 2 3, c, + -, space, q).
  static JogPad::Key jog_key(int key) noexcept;
  static bool is_quit(int key) noexcept;  // q, Q, Escape

 private:
  Screen() = default;
  void* screen_ = nullptr;  // ncurses' SCREEN
};

// Ctrl-C or SIGTERM came (after Screen::open or catch_interrupts).
bool interrupted() noexcept;
// Ctrl-C and SIGTERM set interrupted() instead of ending the process.
void catch_interrupts();

}  // namespace cpm::cli::console
