// SPDX-License-Identifier: Apache-2.0
#include "console_screen.hpp"

#include <curses.h>
#include <signal.h>
#include <unistd.h>

#include <atomic>

namespace cpm::cli::console {

namespace {
std::atomic<bool> g_interrupted{false};
void on_signal(int) { g_interrupted.store(true); }
}  // namespace

bool interrupted() noexcept { return g_interrupted.load(); }

void catch_interrupts() {
  struct sigaction sa {};
  sa.sa_handler = on_signal;
  sigemptyset(&sa.sa_mask);
  sa.sa_flags = 0;  // no SA_RESTART: a wait for a key returns at once
  sigaction(SIGINT, &sa, nullptr);
  sigaction(SIGTERM, &sa, nullptr);
}

std::unique_ptr<Screen> Screen::open() {
  if (!::isatty(STDIN_FILENO) || !::isatty(STDOUT_FILENO)) return nullptr;
  // Ours before ncurses starts: it then leaves SIGINT and SIGTERM alone
  // (and handles SIGWINCH and SIGTSTP itself).
  catch_interrupts();
  SCREEN* s = newterm(nullptr, stdout, stdin);
  if (!s) return nullptr;
  set_term(s);
  std::unique_ptr<Screen> screen(new Screen);
  screen->screen_ = s;
  cbreak();
  noecho();
  nonl();
  keypad(stdscr, TRUE);
  set_escdelay(25);
  curs_set(0);
  return screen;
}

Screen::~Screen() {
  endwin();
  delscreen(static_cast<SCREEN*>(screen_));
}

int Screen::width() const { return getmaxx(stdscr); }
int Screen::height() const { return getmaxy(stdscr); }

void Screen::draw(const Lines& lines) {
  werase(stdscr);
  const int h = height(), w = width();
  for (int i = 0; i < h && i < static_cast<int>(lines.size()); ++i)
    mvwaddnstr(stdscr, i, 0, lines[static_cast<std::size_t>(i)].c_str(), w);
  wrefresh(stdscr);
}

int Screen::key(int timeout_ms) {
  wtimeout(stdscr, timeout_ms);
  const int k = wgetch(stdscr);
  return k == ERR ? -1 : k;
}

JogPad::Key Screen::jog_key(int k) noexcept {
  using K = JogPad::Key;
  switch (k) {
    case KEY_LEFT: return K::left;
    case KEY_RIGHT: return K::right;
    case KEY_UP: return K::up;
    case KEY_DOWN: return K::down;
    case KEY_PPAGE: return K::page_up;
    case KEY_NPAGE: return K::page_down;
    case '1': return K::select1;
    case '2': return K::select2;
    case '3': return K::select3;
    case 'c': case 'C': return K::cartesian;
    case '+': case '=': return K::faster;
    case '-': case '_': return K::slower;
    case ' ': return K::stop;
    default: return is_quit(k) ? K::quit : K::none;
  }
}

bool Screen::is_quit(int k) noexcept { return k == 'q' || k == 'Q' || k == 27; }

}  // namespace cpm::cli::console
