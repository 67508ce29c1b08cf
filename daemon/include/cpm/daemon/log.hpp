// SPDX-License-Identifier: Apache-2.0
// cpmd's messages, with a severity the journal understands.
//
// Under systemd, stderr is a stream to journald: each line is sent with the
// syslog priority prefix of sd-daemon(3) ("<3>" error ... "<7>" debug), so
// `journalctl -u cpmd -p warning` shows the warnings and errors only. Anywhere
// else (a terminal, a test, a file) the line reads "cpmd: warning: ...".
// stderr is the journal when $JOURNAL_STREAM names its device and inode
// (systemd.exec(5)); a unit that redirects stderr elsewhere gets plain text.
//
// Not for the real-time thread: a message is formatted into a std::string and
// written with write(2). The loop reports through its rings (faults in the
// state, statistics, acks) and the other threads say it here.
#pragma once

#include <sys/types.h>

#include <string>
#include <string_view>

namespace cpm::daemon::log {

// Syslog priorities, as sd-daemon's SD_ERR ... SD_DEBUG.
enum class Severity { error = 3, warning = 4, notice = 5, info = 6, debug = 7 };

enum class Style {
  journal,  // "<4>message": journald takes the priority from the prefix
  plain,    // "cpmd: warning: message"
};

// Whether $JOURNAL_STREAM ("DEVICE:INODE", decimal) names this device and
// inode; false when `journal_stream` is null or not of that form.
[[nodiscard]] bool is_journal_stream(const char* journal_stream, dev_t device, ino_t inode);

// The style for file descriptor `fd` under this process' environment.
[[nodiscard]] Style style_for(int fd);

// The text written for one message: every line of `message` prefixed (a
// journal entry is one line), ending in a newline.
[[nodiscard]] std::string format(Style style, Severity severity, std::string_view message);

// Writes one message to stderr in one write(2), in the style chosen for
// stderr at the first message.
void write(Severity severity, std::string_view message);

// printf-style shorthands.
void error(const char* format, ...) __attribute__((format(printf, 1, 2)));
void warning(const char* format, ...) __attribute__((format(printf, 1, 2)));
void notice(const char* format, ...) __attribute__((format(printf, 1, 2)));
void info(const char* format, ...) __attribute__((format(printf, 1, 2)));

}  // namespace cpm::daemon::log
