#pragma once
// Two signals would end a run silently where a failed write should be reported: SIGXFSZ past a
// file-size limit (ulimit -f), and SIGPIPE when the reader of stdout or stderr went away
// (`| head`, a quit pager, a killed tee). Ignored, the write fails with EFBIG or EPIPE instead,
// and the programs report it like a full disk (exit 1, naming the file or the stream,
// --save-params still saved). `CommandLine`'s constructor calls this, so every program with
// flags does it first thing; the others call it at the start of main. exec passes ignored
// signals on, so `reproduce` restores both for its children (processes.hpp).
#include <csignal>

namespace sbptt::examples {

inline void ignore_write_signals() {
  std::signal(SIGXFSZ, SIG_IGN);
  std::signal(SIGPIPE, SIG_IGN);
}

}  // namespace sbptt::examples
