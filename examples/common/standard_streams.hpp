#pragma once
// A program's printed output is part of its work: the log of a run that a full disk or a
// file-size limit (SIGXFSZ ignored: write_signals.hpp) cut short must not end with exit 0,
// or `reproduce` would keep a truncated runs/<name>.log as a finished run's.
#include <cerrno>
#include <cstdio>
#include <cstring>

namespace sbptt::examples {

/// Whether everything printed so far reached stdout and stderr (stdout flushed now); if not,
/// says so on stderr, which still reaches the user when only stdout failed. A program whose
/// output is its result asks before its long work, so that a full disk stops it at once.
inline bool streams_written(const char* name) {
  const bool flushed = std::fflush(stdout) == 0;
  const int error = flushed ? 0 : errno;
  if (flushed && !std::ferror(stdout) && !std::ferror(stderr)) return true;
  std::fprintf(stderr, "%s: standard output or standard error was not written in full%s%s\n",
               name, error != 0 ? ": " : "", error != 0 ? std::strerror(error) : "");
  return false;
}

/// `code`, or 1 in its place if it is 0 and a write to stdout or stderr failed.
inline int with_streams_checked(const char* name, int code) {
  if (streams_written(name)) return code;
  return code == 0 ? 1 : code;
}

}  // namespace sbptt::examples
