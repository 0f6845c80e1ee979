# Resume inside a run (issue 16, point 2), with fake task programs that keep --checkpoint FILE
# like the real ones (reproduce_fake_task.sh with CHECKPOINTS):
#
#   cmake -DREPRODUCE=<path of examples/reproduce> -DWORK_DIR=<scratch dir> -P reproduce_checkpoints.cmake
#
#   1. an uninterrupted sweep of 6 runs of 12 epochs gives the reference summary.csv, and no
#      checkpoint is left once the runs are finished;
#   2. the same sweep is SIGKILLed at random moments (0.3 to 1.2 s after each start) and started
#      again, until it finishes on its own; its summary.csv has the reference's loss columns,
#      the runs killed mid-way resumed from their checkpoints (not from epoch 1), and no
#      checkpoint or partial file is left;
#   3. a checkpoint left by a run of other settings under the same name is not resumed;
#   4. a checkpoint whose training log is gone (the programs refuse to resume it) fails the run
#      once, is removed, and the next sweep redoes the run from epoch 1;
#   5. a run that ends on a signal its program answers (exit 128 + SIGHUP or SIGXCPU, as on
#      SIGINT or SIGTERM) keeps its checkpoint, and the next sweep resumes it;
#   6. a runner started with those signals (and SIGPIPE, SIGXFSZ) ignored starts its programs
#      with none of them ignored.
# Without the CHECKPOINTS marker the fake programs do not list --checkpoint in --help, and the
# runner passes no --checkpoint (reproduce_resume.cmake covers that case).
cmake_minimum_required(VERSION 3.20)
foreach(var REPRODUCE WORK_DIR)
  if(NOT DEFINED ${var})
    message(FATAL_ERROR "reproduce_checkpoints.cmake: pass -D${var}=...")
  endif()
endforeach()
include("${CMAKE_CURRENT_LIST_DIR}/reproduce_common.cmake")
file(REMOVE_RECURSE "${WORK_DIR}")
install_fake_task_programs("${WORK_DIR}/fake" CHECKPOINTS)

set(grid --tasks cartpole --complexities 4 --methods R,C --clips norm --seeds 3 --epochs 12
         --jobs 2 --no-plot --bin-dir "${WORK_DIR}/fake")

# --- 1. uninterrupted --------------------------------------------------------------------------
execute_process(COMMAND "${REPRODUCE}" ${grid} --out "${WORK_DIR}/whole" RESULT_VARIABLE rc
                OUTPUT_QUIET ERROR_QUIET)
check("the uninterrupted sweep exits 0" rc EQUAL 0)
untimed_summary("${WORK_DIR}/whole/summary.csv" reference)
file(GLOB left "${WORK_DIR}/whole/runs/*.checkpoint")
check("no checkpoint is left once the runs are finished (${left})" NOT left)
file(READ "${WORK_DIR}/whole/runs/cartpole_p4_C_norm_s42.log" log)
check("the runner passed --checkpoint runs/<name>.checkpoint"
      log MATCHES "--checkpoint [^\n]*/runs/cartpole_p4_C_norm_s42.checkpoint\n")

# --- 2. SIGKILL at random moments, then resume ---------------------------------------------------
file(WRITE "${WORK_DIR}/kill.sh" [=[
runner=$1; out=$2; shift 2
attempt=0
while :; do
  attempt=$((attempt + 1))
  "$runner" "$@" --out "$out" >> "$out.log" 2>&1 &
  pid=$!
  delay=$(awk -v seed="$attempt$$" 'BEGIN { srand(seed); printf "%.2f", 0.3 + 0.9 * rand() }')
  sleep "$delay"
  if kill -9 "$pid" 2>/dev/null; then
    wait "$pid"
    echo "attempt $attempt: SIGKILL after $delay s"
  else
    wait "$pid"; status=$?
    echo "attempt $attempt: finished on its own with exit code $status"
    exit "$status"
  fi
  [ "$attempt" -ge 40 ] && { echo "never finished"; exit 1; }
done
]=])
execute_process(COMMAND sh "${WORK_DIR}/kill.sh" "${REPRODUCE}" "${WORK_DIR}/killed" ${grid}
                RESULT_VARIABLE rc OUTPUT_VARIABLE attempts ERROR_VARIABLE err)
message(STATUS "kill and resume:\n${attempts}${err}")
check("the sweep SIGKILLed at random moments finished when resumed" rc EQUAL 0)
check("it was killed at least twice" attempts MATCHES "attempt 2: SIGKILL")
untimed_summary("${WORK_DIR}/killed/summary.csv" resumed)
check("its summary.csv has the uninterrupted loss columns" resumed STREQUAL reference)
file(STRINGS "${WORK_DIR}/killed/fake_resumes" resumes)
list(LENGTH resumes resume_count)
check("runs resumed from their checkpoints (${resume_count}: ${resumes})" resume_count GREATER 0)
file(GLOB left "${WORK_DIR}/killed/runs/*.checkpoint" "${WORK_DIR}/killed/runs/*.partial.*"
     "${WORK_DIR}/killed/runs/*.tmp.*")
check("no checkpoint, partial or temporary file is left (${left})" NOT left)

# --- 3. a stale checkpoint of other settings -----------------------------------------------------
set(S "${WORK_DIR}/stale")
file(MAKE_DIRECTORY "${S}/runs")
file(WRITE "${S}/runs/cartpole_p4_C_norm_s42.run" "task=cartpole\nepochs=999\n")
file(WRITE "${S}/runs/cartpole_p4_C_norm_s42.checkpoint" "5 6\n")
file(WRITE "${S}/runs/cartpole_p4_C_norm_s42.partial.csv" "epoch\n")
execute_process(COMMAND "${REPRODUCE}" ${grid} --seeds 1 --methods C --out "${S}"
                RESULT_VARIABLE rc OUTPUT_VARIABLE stale_out ERROR_QUIET)
check("a sweep over a stale checkpoint exits 0" rc EQUAL 0)
check("the stale checkpoint was not resumed" NOT EXISTS "${S}/fake_resumes")
# It said "1 from their checkpoint" of a run whose checkpoint it was about to drop.
check("the sweep says the run restarts, not that it resumes (${stale_out})"
      stale_out MATCHES "discarded the partial files of 1 unfinished run" AND
      stale_out MATCHES "of those planned here: 0 resuming from a checkpoint, 1 starting over")

# --- 4. a checkpoint whose log is gone: the program refuses it, the run is redone from epoch 1 --
set(G "${WORK_DIR}/gone")
execute_process(COMMAND "${REPRODUCE}" ${grid} --seeds 1 --methods C --out "${G}"
                RESULT_VARIABLE rc OUTPUT_QUIET ERROR_QUIET)
file(REMOVE "${G}/runs/cartpole_p4_C_norm_s42.csv" "${G}/runs/cartpole_p4_C_norm_s42.log")
file(WRITE "${G}/runs/cartpole_p4_C_norm_s42.checkpoint" "5 6\n")
execute_process(COMMAND "${REPRODUCE}" ${grid} --seeds 1 --methods C --out "${G}"
                RESULT_VARIABLE first OUTPUT_QUIET ERROR_VARIABLE first_err)
check("a checkpoint without its log fails the run once and is removed (${first_err})"
      first EQUAL 1 AND first_err MATCHES "checkpoint was removed"
      AND NOT EXISTS "${G}/runs/cartpole_p4_C_norm_s42.checkpoint")
execute_process(COMMAND "${REPRODUCE}" ${grid} --seeds 1 --methods C --out "${G}"
                RESULT_VARIABLE again OUTPUT_QUIET ERROR_QUIET)
check("the next sweep redoes the run from epoch 1" again EQUAL 0
      AND EXISTS "${G}/runs/cartpole_p4_C_norm_s42.csv")

# --- 5. a run ended by a signal its program answers keeps its checkpoint ------------------------
# SIGHUP's and SIGXCPU's exit codes (129, 152) were counted as a program's failure, and the
# checkpoint that the program had just written was removed.
foreach(signal 1 24)
  set(H "${WORK_DIR}/signal_${signal}")
  math(EXPR code "128 + ${signal}")
  file(MAKE_DIRECTORY "${H}")
  file(WRITE "${H}/stop_cartpole_p4_C_norm_s42" "${code}\n")
  execute_process(COMMAND "${REPRODUCE}" ${grid} --seeds 1 --methods C --out "${H}"
                  RESULT_VARIABLE first OUTPUT_QUIET ERROR_VARIABLE first_err)
  check("exit ${code}: the run is listed as stopped by signal ${signal}, its checkpoint kept (${first_err})"
        first EQUAL 1 AND first_err MATCHES "stopped by signal ${signal} \\([^)]*\\). its checkpoint is kept"
        AND EXISTS "${H}/runs/cartpole_p4_C_norm_s42.checkpoint")
  execute_process(COMMAND "${REPRODUCE}" ${grid} --seeds 1 --methods C --out "${H}"
                  RESULT_VARIABLE again OUTPUT_QUIET ERROR_QUIET)
  file(READ "${H}/fake_resumes" resumed)
  check("exit ${code}: the next sweep resumed the run after its epoch 1 (${resumed})"
        again EQUAL 0 AND resumed STREQUAL "cartpole_p4_C_norm_s42 1\n")
endforeach()

# --- 6. the task programs start with the default actions of the signals they answer -----------
# A runner started ignoring them (nohup, a batch system's trap), or ignoring them itself
# (SIGPIPE, SIGXFSZ: write_signals.hpp), must not pass that on through exec: its programs would
# then neither stop at its SIGTERM nor stop at `| head`. The fake notes the mask of the shell
# that runs it, which exec gave whatever the runner passed on.
set(I "${WORK_DIR}/ignoring")
execute_process(COMMAND sh -c "trap '' INT TERM HUP XCPU PIPE XFSZ; exec \"\$0\" \"\$@\""
                        "${REPRODUCE}" ${grid} --seeds 1 --methods C --out "${I}"
                RESULT_VARIABLE rc OUTPUT_QUIET ERROR_VARIABLE err)
set(ignored "")
if(EXISTS "${I}/fake_ignored_signals")
  file(STRINGS "${I}/fake_ignored_signals" ignored)
endif()
check("the runner ran its one program, which noted its ignored signals (${ignored}, ${err})"
      rc EQUAL 0 AND ignored MATCHES "^cartpole_p4_C_norm_s42 [0-9a-f]+$")
# The low 32 bits only (math(EXPR) is signed 64-bit): bits s − 1 of SIGHUP 1, SIGINT 2,
# SIGPIPE 13, SIGTERM 15, SIGXCPU 24, SIGXFSZ 25.
string(REGEX REPLACE "^[^ ]+ " "" mask "${ignored}")
string(LENGTH "${mask}" digits)
set(low_bits "${mask}")
if(digits GREATER 8)
  math(EXPR start "${digits} - 8")
  string(SUBSTRING "${mask}" ${start} -1 low_bits)
endif()
math(EXPR passed_on "0x${low_bits} & 0x1805003" OUTPUT_FORMAT HEXADECIMAL)
check("a runner started ignoring them runs its programs with none of them ignored (${ignored})"
      passed_on STREQUAL "0x0")
