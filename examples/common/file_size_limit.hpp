#pragma once
// Beyond a file-size limit (ulimit -f) a write fails with EFBIG once SIGXFSZ is ignored, and
// the programs report it like a full disk (exit 1, naming the file, --save-params still
// saved) instead of being killed silently with the file unwritten. `CommandLine`'s
// constructor calls this, so every program with flags does it first thing; the others call it
// at the start of main.
#include <csignal>

namespace sbptt::examples {

inline void ignore_file_size_signal() { std::signal(SIGXFSZ, SIG_IGN); }

}  // namespace sbptt::examples
