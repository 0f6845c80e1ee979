# The runner's files on the disk (split from reproduce_faults.cmake):
#
#   cmake -DREPRODUCE=<examples/reproduce> -DWORK_DIR=<scratch dir> -P reproduce_durability.cmake
#
#   1. plays a file system without locks (flock fails: a sweep stops before any run and says
#      why, --merge counts no run as running);
#   2. (when strace is installed) traces a sweep: every file the runner renames into place was
#      fsync'ed just before, and its folder just after (a file written unnamed, O_TMPFILE, is
#      fsync'ed through its descriptor and then linked to the name that is renamed).
cmake_minimum_required(VERSION 3.20)
include("${CMAKE_CURRENT_LIST_DIR}/reproduce_common.cmake")
start_with_fake_cart_pole_grid(reproduce_durability.cmake)

# --- 1. a file system without locks -------------------------------------------------------------
# flock fails with ENOLCK everywhere (tests/support/flock_fails.cpp, preloaded), as on a
# Lustre or NFS mount without lock support. A sweep stops before it runs anything and names
# what it needs; --merge counted every run with a lock file as running (lock held).
if(DEFINED FLOCK_FAILS AND NOT SANITIZED)  # a sanitizer's runtime must be the first library
  file(MAKE_DIRECTORY "${WORK_DIR}/lockless/runs")
  execute_process(COMMAND env "LD_PRELOAD=${FLOCK_FAILS}" "${REPRODUCE}" ${grid}
                  --out "${WORK_DIR}/lockless" RESULT_VARIABLE rc OUTPUT_VARIABLE out
                  ERROR_VARIABLE err)
  check("a sweep on a file system without locks: exit 1 before any run, saying why\n${out}${err}"
        rc EQUAL 1 AND err MATCHES "cannot lock '[^']*\\.lock': No locks available"
        AND err MATCHES "needs a file system with file locks"
        AND NOT EXISTS "${WORK_DIR}/lockless/fake_invocations")
  # A run killed mid-way leaves its lock file; no process holds it.
  file(TOUCH "${WORK_DIR}/lockless/runs/cartpole_p4_R_norm_s42.lock")
  execute_process(COMMAND env "LD_PRELOAD=${FLOCK_FAILS}" "${REPRODUCE}" ${grid} --merge
                  --out "${WORK_DIR}/lockless" RESULT_VARIABLE rc OUTPUT_VARIABLE out
                  ERROR_VARIABLE err)
  check("--merge on a file system without locks: a run's lock file is no run under way\n${out}${err}"
        rc EQUAL 1 AND out MATCHES "0 of 6 planned runs done, 0 running \\(lock held\\), 6 missing")
endif()

# --- 2. fsync before a file counts ---------------------------------------------------------------
# The runner is the first process in the trace; the fake programs' own renames are theirs.
file(WRITE "${WORK_DIR}/fsync_order.awk" [=[
# Names are compared by their last component: strace -y shows resolved paths.
function last_part(path) { sub(/\/+$/, "", path); sub(/.*\//, "", path); return path }
NR == 1 { runner = $1 }
$1 != runner || /resumed>/ { next }
/fsync\(/ {
  match($0, /fsync\([0-9]+/); fd = substr($0, RSTART + 6, RLENGTH - 6)
  # "(deleted))", or "(deleted) <unfinished ...>" when another process's call split the line
  unnamed_fd = /\(deleted\)(\)| <unfinished)/ ? fd : ""
  match($0, /<[^>]*>/); synced = last_part(substr($0, RSTART + 1, RLENGTH - 2))
  if (pending != "") {
    if (synced != pending) { print "no fsync of the folder " pending " after renaming into it"; bad = 1 }
    pending = ""
  }
  last = synced; next
}
# strace -y shows an unnamed file as "#<inode>", deleted: its name is the one it is linked to.
/linkat\(/ {
  split($0, quoted, "\"")
  named = unnamed_fd != "" && quoted[2] == "/proc/self/fd/" unnamed_fd && !/= -1 /
  last = named ? last_part(quoted[4]) : ""
  next
}
/rename/ {
  split($0, quoted, "\"")
  from = last_part(quoted[2]); to = quoted[4]
  if (last != from) { print "renamed " from " without an fsync of it first"; bad = 1 }
  sub(/\/[^\/]*$/, "", to); pending = last_part(to); renames++
  last = ""; unnamed_fd = ""
}
END { print renames " renames checked"; exit bad }
]=])
# The check itself, on traces written here (it needs neither strace nor an unsanitized build):
# an fsync that strace split into "<unfinished ...>" and "<... fsync resumed>" (as it does when
# another process's call comes between) counts; a split fsync of another file, or none, fails.
# Every trace ends the same: the unnamed file linked as the temporary, renamed, folder synced.
set(link_and_rename [=[
7 linkat(AT_FDCWD</w>, "/proc/self/fd/7", AT_FDCWD</w>, "/w/out/summary.csv.tmp.7.3", AT_SYMLINK_FOLLOW) = 0
7 rename("/w/out/summary.csv.tmp.7.3", "/w/out/summary.csv") = 0
7 fsync(7</w/out>) = 0
]=])
set(split_fsync [=[
7 fsync(7</w/out/#10978501>(deleted) <unfinished ...>
8 --- SIGCHLD {si_signo=SIGCHLD, si_code=CLD_EXITED, si_pid=9, si_uid=0, si_status=0} ---
7 <... fsync resumed>)              = 0
]=])
set(other_fd [=[
7 fsync(5</w/out/#10978500>(deleted) <unfinished ...>
7 <... fsync resumed>)              = 0
]=])
string(APPEND split_fsync "${link_and_rename}")
string(APPEND other_fd "${link_and_rename}")
set(no_fsync "${link_and_rename}")
file(WRITE "${WORK_DIR}/trace_split_fsync" "${split_fsync}")
file(WRITE "${WORK_DIR}/trace_no_fsync" "${no_fsync}")
file(WRITE "${WORK_DIR}/trace_other_fd" "${other_fd}")
execute_process(COMMAND awk -f "${WORK_DIR}/fsync_order.awk" "${WORK_DIR}/trace_split_fsync"
                RESULT_VARIABLE rc OUTPUT_VARIABLE order)
check("the fsync-order check counts an fsync that strace split in two (${order})"
      rc EQUAL 0 AND order MATCHES "^1 renames checked")
execute_process(COMMAND awk -f "${WORK_DIR}/fsync_order.awk" "${WORK_DIR}/trace_no_fsync"
                RESULT_VARIABLE rc OUTPUT_VARIABLE order)
check("the fsync-order check fails a rename without an fsync (${order})"
      NOT rc EQUAL 0 AND order MATCHES "renamed summary.csv.tmp.7.3 without an fsync")
execute_process(COMMAND awk -f "${WORK_DIR}/fsync_order.awk" "${WORK_DIR}/trace_other_fd"
                RESULT_VARIABLE rc OUTPUT_VARIABLE order)
check("the fsync-order check fails a rename after an fsync of another file (${order})"
      NOT rc EQUAL 0 AND order MATCHES "renamed summary.csv.tmp.7.3 without an fsync")

find_program(STRACE strace)
if(NOT STRACE)
  message(STATUS "strace not found; the fsync order is not checked")
  return()
endif()
if(SANITIZED)  # LeakSanitizer aborts a program that runs under ptrace
  message(STATUS "sanitizer build: the fsync order is not checked under strace")
  return()
endif()
execute_process(COMMAND "${STRACE}" -f -y -e trace=fsync,linkat,rename,renameat,renameat2
                -o "${WORK_DIR}/trace" "${REPRODUCE}" ${grid} --seeds 1 --out "${WORK_DIR}/traced"
                RESULT_VARIABLE rc OUTPUT_QUIET ERROR_QUIET)
check("the traced sweep exits 0" rc EQUAL 0)
execute_process(COMMAND awk -f "${WORK_DIR}/fsync_order.awk" "${WORK_DIR}/trace"
                RESULT_VARIABLE rc OUTPUT_VARIABLE order)
check("every rename of the runner: the file fsync'ed before, its folder after (${order})"
      rc EQUAL 0 AND order MATCHES "[1-9][0-9]* renames checked")
