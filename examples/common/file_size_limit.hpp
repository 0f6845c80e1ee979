#pragma once
// Every program that writes files includes this header (through command_line.hpp, or itself):
// beyond a file-size limit (ulimit -f) a write then fails with EFBIG, which the programs report
// like a full disk (exit 1, naming the file, --save-params still saved), instead of SIGXFSZ
// killing them silently with the file unwritten. Done at static initialisation, before main,
// so that no program can forget it.
#include <csignal>

namespace sbptt::examples::detail_files {

inline const bool file_size_signal_ignored = std::signal(SIGXFSZ, SIG_IGN) != SIG_ERR;

}  // namespace sbptt::examples::detail_files
