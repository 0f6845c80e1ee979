# The reproduction runner resumes an interrupted sweep (issue 4, point 6).
#
#   cmake -DREPRODUCE=<path of examples/reproduce> -DWORK_DIR=<scratch dir> -P reproduce_resume.cmake
#
# Against fake task programs (a shell script that keeps the task-program contract: the flags,
# the training log rewritten atomically after every epoch, exit 0 or 3) it
#   1. runs a 12-run grid uninterrupted (sweep A);
#   2. runs the same grid in another directory (sweep B, --threads 2), SIGKILLs the runner while
#      runs are both finished and under way, and checks that no child survives it and that only
#      the finished runs have a <name>.log, the interrupted ones only a <name>.partial.log;
#   3. restarts sweep B with --threads 3 and checks that (a) no finished run was redone (every
#      one was started once, its CSV keeps inode and mtime) while the interrupted ones were
#      redone, (b) B's summary.csv equals A's in every column except the two timing ones, and
#      (c) no partial file remains (also none of a run it does not plan) and every finished
#      run has its complete log;
# and that each program got the --threads of its sweep (1 by default). Then, when the real task
# programs sit beside the runner, a 3-run sweep with them (their flags and logs fit the runner)
# resumed with another --threads, and plots when python3 with matplotlib is there.
cmake_minimum_required(VERSION 3.20)
foreach(var REPRODUCE WORK_DIR)
  if(NOT DEFINED ${var})
    message(FATAL_ERROR "reproduce_resume.cmake: pass -D${var}=...")
  endif()
endforeach()

include("${CMAKE_CURRENT_LIST_DIR}/reproduce_common.cmake")
file(REMOVE_RECURSE "${WORK_DIR}")
install_fake_task_programs("${WORK_DIR}/fake")

# cart pole 4 poles, guidance rc 0.001, quantum target 4; R and C; seeds 42 and 43: 12 runs.
set(grid --profile quick --complexities 4,0.001 --methods R,C --clips norm --seeds 2 --epochs 6
         --jobs 3 --bin-dir "${WORK_DIR}/fake")
set(A "${WORK_DIR}/a")
set(B "${WORK_DIR}/b")

string(TIMESTAMP started "%s")

# --- bad flags are refused with exit 2 and a message naming them -----------------------------
execute_process(COMMAND "${REPRODUCE}" --bogus RESULT_VARIABLE rc ERROR_VARIABLE err
                OUTPUT_QUIET)
check("unknown flag: exit 2 naming it" rc EQUAL 2 AND err MATCHES "--bogus")
execute_process(COMMAND "${REPRODUCE}" --jobs 0 RESULT_VARIABLE rc ERROR_VARIABLE err
                OUTPUT_QUIET)
check("--jobs 0: exit 2 naming it" rc EQUAL 2 AND err MATCHES "--jobs")
execute_process(COMMAND "${REPRODUCE}" --threads 0 RESULT_VARIABLE rc ERROR_VARIABLE err
                OUTPUT_QUIET)
check("--threads 0: exit 2 naming the value" rc EQUAL 2 AND err MATCHES "--threads 0")
execute_process(COMMAND "${REPRODUCE}" --tasks cartpole --complexities 4 --methods C --seeds 1
                --threads 4 --dry-run --out "${WORK_DIR}/dry" RESULT_VARIABLE rc
                OUTPUT_VARIABLE out ERROR_QUIET)
check("--dry-run shows --threads 4 on the command line" rc EQUAL 0 AND out MATCHES
      "cartpole --poles 4 [^\n]* --threads 4 --csv ")
# A --bin-dir without the task programs is a bad flag (exit 2), named before any work, in
# every mode that runs or hands out their commands (a dry run was an uncaught exception, exit
# 134, then exit 1); --merge runs none.
foreach(mode --dry-run "--emit;parallel" "--emit;slurm" "--run;cartpole_p4_C_norm_s42" "")
  execute_process(COMMAND "${REPRODUCE}" --tasks cartpole --complexities 4 --methods C --seeds 1
                  --bin-dir "${WORK_DIR}/no_such_dir" ${mode} --out "${WORK_DIR}/no_programs"
                  RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  check("'${mode}' with a --bin-dir without programs: exit 2 naming the flag\n${out}${err}"
        rc EQUAL 2 AND err MATCHES "--bin-dir '[^']*no_such_dir' holds no executable task program 'cartpole'")
  check("'${mode}' with a --bin-dir without programs: nothing made" NOT EXISTS "${WORK_DIR}/no_programs")
endforeach()
# The reviewers profile: the cart chain, 1-3 links x R, M, C, S x 3 seeds, through cartpole.
execute_process(COMMAND "${REPRODUCE}" --profile reviewers --epochs 2 --samples 8
                --bin-dir "${WORK_DIR}/fake" --dry-run --out "${WORK_DIR}/dry"
                RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
check("--profile reviewers plans the chain's 36 runs through cartpole --model chain\n${out}${err}"
      rc EQUAL 0 AND out MATCHES "36 runs planned \\(profile reviewers" AND out MATCHES
      "chain_n3_C_norm_s44 +[^\n]*/cartpole --model chain --poles 3 --method C --clip norm")
# The estimate is measured: the fake programs sleep 0.12 s per epoch whatever the samples, so
# two runs of 100 epochs take at least 24 s (the built-in table says 3 s for 8 samples).
execute_process(COMMAND "${REPRODUCE}" --tasks cartpole --complexities 4 --methods R,C
                --clips norm --seeds 1 --epochs 100 --samples 8 --jobs 1
                --bin-dir "${WORK_DIR}/fake" --dry-run --out "${WORK_DIR}/dry"
                RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_QUIET)
string(REGEX MATCH "measured estimate ([0-9]+m)?([0-9]+)s of compute" estimate "${out}")
set(seconds "${CMAKE_MATCH_2}")
string(REGEX REPLACE "m$" "" minutes "0${CMAKE_MATCH_1}")
math(EXPR seconds "${minutes} * 60 + 0${seconds}")
check("--dry-run measures 0.12 s per fake epoch: 2 x 100 epochs in 20-120 s (${estimate})"
      rc EQUAL 0 AND seconds GREATER_EQUAL 20 AND seconds LESS_EQUAL 120)

# --- A: uninterrupted ------------------------------------------------------------------------
execute_process(COMMAND "${REPRODUCE}" ${grid} --out "${A}" RESULT_VARIABLE rc
                OUTPUT_VARIABLE out_a ERROR_VARIABLE err_a)
message(STATUS "sweep A (uninterrupted):\n${out_a}${err_a}")
check("sweep A exits 0" rc EQUAL 0)
count_lines("${A}/summary.csv" rows)
check("sweep A: summary.csv has a header and 12 rows (got ${rows} lines)" rows EQUAL 13)
count_lines("${A}/fake_invocations" started_a)
check("sweep A started every run once (${started_a} starts)" started_a EQUAL 12)
file(READ "${A}/summary.csv" summary_a)
string(REGEX MATCHALL ",stopped," stopped_rows "${summary_a}")
list(LENGTH stopped_rows stopped_count)
check("sweep A: the 3 runs that exited 3 are finished with status stopped" stopped_count EQUAL 3)
file(STRINGS "${A}/fake_threads" threads_a)
list(FILTER threads_a EXCLUDE REGEX " 1$")
check("sweep A passed the default --threads 1 to every run (not: ${threads_a})" NOT threads_a)

# Every finished run in <dir> has its whole log (the program's output and the runner's last
# line) under its final name, and no partial file is left.
function(check_logs dir)
  file(GLOB csvs "${dir}/runs/*.csv")
  list(FILTER csvs EXCLUDE REGEX "\\.partial\\.csv$")
  list(LENGTH csvs n)
  set(complete 0)
  foreach(csv IN LISTS csvs)
    string(REGEX REPLACE "\\.csv$" ".log" log "${csv}")
    if(EXISTS "${log}")
      file(READ "${log}" text)
      if(text MATCHES "^# [^\n]* --csv [^\n]*\n.*: epoch 1\n.*# reproduce: exit code [03] after ")
        math(EXPR complete "${complete} + 1")
      endif()
    endif()
  endforeach()
  check("${dir}: all ${n} finished runs have a complete .log (${complete})" n EQUAL complete
        AND n GREATER 0)
  file(GLOB partial "${dir}/runs/*.partial.*")
  check("${dir}: no partial file is left (${partial})" NOT partial)
endfunction()
check_logs("${A}")
if(out_a MATCHES "plots: ")
  file(GLOB pngs "${A}/plots/*.png")
  list(LENGTH pngs png_count)
  check("sweep A drew plots (${png_count} PNGs)" png_count GREATER_EQUAL 4)
else()
  message(STATUS "no plots (python3 with matplotlib not found); plotting not tested")
endif()

# --- B: SIGKILL the runner mid-way -----------------------------------------------------------
file(MAKE_DIRECTORY "${B}")
set(kill_script [=[
runner=$1; out=$2; shift 2
"$runner" "$@" --no-plot --out "$out" > "$out.first.log" 2>&1 &
pid=$!
i=0
while :; do
  finished=$(ls "$out/runs" 2>/dev/null | grep '\.csv$' | grep -vc '\.partial\.csv$')
  partial=$(ls "$out/runs" 2>/dev/null | grep -c '\.partial\.csv$')
  [ "$finished" -ge 4 ] && [ "$partial" -ge 1 ] && break
  i=$((i + 1))
  [ $i -gt 400 ] && { echo "runner never had 4 finished and 1 running run"; kill -9 $pid; exit 1; }
  sleep 0.05
done
kill -9 $pid
wait $pid
echo "killed the runner with $finished finished and $partial running runs"
cd "$out/runs"
ls | grep '\.csv$' | grep -v '\.partial\.csv$' | while read -r f; do
  echo "$(basename "$f" .csv) $(stat -c '%i %y' "$f")"
done > "$out/../finished_before.txt"
ls | grep '\.partial\.csv$' | sed 's/\.partial\.csv$//' > "$out/../partial_before.txt"
sleep 0.5
for p in $(cat "$out/fake_pids"); do
  if [ -d /proc/$p ] && ! grep -q '^State:[[:space:]]*Z' /proc/$p/status 2>/dev/null; then
    echo "task program $p outlived the runner"; exit 1
  fi
done
echo "no task program outlived the runner"
]=])
file(WRITE "${WORK_DIR}/kill.sh" "${kill_script}")
execute_process(COMMAND sh "${WORK_DIR}/kill.sh" "${REPRODUCE}" "${B}" ${grid} --threads 2
                RESULT_VARIABLE rc OUTPUT_VARIABLE out_kill ERROR_VARIABLE err_kill)
message(STATUS "sweep B, first part:\n${out_kill}${err_kill}")
check("sweep B was killed mid-way and left no orphan" rc EQUAL 0)
file(STRINGS "${WORK_DIR}/finished_before.txt" finished_before)
file(STRINGS "${WORK_DIR}/partial_before.txt" partial_before)
foreach(entry IN LISTS finished_before)
  string(REGEX REPLACE " .*" "" name "${entry}")
  check("killed sweep: finished run ${name} has its .log and no .partial.log"
        EXISTS "${B}/runs/${name}.log" AND NOT EXISTS "${B}/runs/${name}.partial.log")
endforeach()
foreach(name IN LISTS partial_before)
  check("killed sweep: interrupted run ${name} has a .partial.log and no .log"
        EXISTS "${B}/runs/${name}.partial.log" AND NOT EXISTS "${B}/runs/${name}.log")
endforeach()
file(STRINGS "${B}/fake_threads" threads_first)
# The output of a run that an earlier, killed sweep with other filters left behind: this sweep
# does not plan the run, and must remove the stale partial log all the same.
file(WRITE "${B}/runs/guidance_rc1_R_norm_s42.partial.log" "# an earlier sweep's run\n")

# --- B: resume ---------------------------------------------------------------------------------
execute_process(COMMAND "${REPRODUCE}" ${grid} --threads 3 --no-plot --out "${B}" RESULT_VARIABLE rc
                OUTPUT_VARIABLE out_b ERROR_VARIABLE err_b)
message(STATUS "sweep B, resumed:\n${out_b}${err_b}")
check("resumed sweep B (another --threads) exits 0" rc EQUAL 0)
check("the resumed sweep discarded the interrupted runs"
      out_b MATCHES "discarded the partial files of [1-9]")
check_logs("${B}")
file(STRINGS "${B}/fake_threads" threads_all)
list(LENGTH threads_first first_count)
set(wrong "")
set(index 0)
foreach(entry IN LISTS threads_all)
  if(index LESS first_count)
    set(expected 2)
  else()
    set(expected 3)
  endif()
  if(NOT entry MATCHES " ${expected}$")
    list(APPEND wrong "${entry} (expected ${expected})")
  endif()
  math(EXPR index "${index} + 1")
endforeach()
check("each of B's runs got the --threads of its sweep (wrong: ${wrong})" NOT wrong)

file(STRINGS "${B}/fake_invocations" invocations)
foreach(entry IN LISTS finished_before)
  string(REPLACE " " ";" parts "${entry}")
  list(GET parts 0 name)
  list(FIND invocations "${name}" first)
  list(REMOVE_AT invocations ${first})
  list(FIND invocations "${name}" again)
  check("finished run ${name} was not redone" again EQUAL -1)
  list(INSERT invocations 0 "${name}")
  execute_process(COMMAND stat -c "%i %y" "${B}/runs/${name}.csv" OUTPUT_VARIABLE now
                  OUTPUT_STRIP_TRAILING_WHITESPACE)
  check("finished run ${name} kept its CSV (inode and mtime)" entry STREQUAL "${name} ${now}")
endforeach()
foreach(name IN LISTS partial_before)
  set(starts ${invocations})
  list(FILTER starts INCLUDE REGEX "^${name}$")
  list(LENGTH starts n)
  check("interrupted run ${name} was redone (started ${n} times)" n EQUAL 2)
endforeach()
file(STRINGS "${B}/fake_invocations" all_starts)
list(REMOVE_DUPLICATES all_starts)
list(LENGTH all_starts distinct)
check("every run of sweep B was started" distinct EQUAL 12)

untimed_summary("${A}/summary.csv" untimed_a)
untimed_summary("${B}/summary.csv" untimed_b)
file(READ "${B}/summary.csv" summary_b)
if(NOT untimed_a STREQUAL untimed_b)
  message(STATUS "A:\n${summary_a}\nB:\n${summary_b}")
endif()
check("resumed summary.csv equals the uninterrupted one except for timing columns"
      untimed_a STREQUAL untimed_b)
check("the timing columns did differ (the comparison left them out for a reason)"
      NOT summary_a STREQUAL summary_b)

# --- the real task programs, if they sit beside the runner ------------------------------------
get_filename_component(examples_dir "${REPRODUCE}" DIRECTORY)
if(EXISTS "${examples_dir}/cartpole" AND EXISTS "${examples_dir}/guidance"
   AND EXISTS "${examples_dir}/quantum")
  # In float, whose setting the .run files keep only in their args line; the second, finished
  # sweep must read those files back into its summary.
  # The second sweep has another --threads, which must not make the finished runs differ.
  set(real_grid --profile quick --complexities 4,0.001 --methods C --clips norm --seeds 1
                --epochs 2 --samples 8 --float --no-plot --out "${WORK_DIR}/real")
  set(threads_first 2)
  set(threads_again 1)
  foreach(pass first again)
    execute_process(COMMAND "${REPRODUCE}" ${real_grid} --threads ${threads_${pass}}
                    RESULT_VARIABLE rc OUTPUT_VARIABLE out_real ERROR_VARIABLE err_real)
    message(STATUS "real task programs, ${pass}:\n${out_real}${err_real}")
    check("sweep with the real task programs exits 0 (${pass})" rc EQUAL 0)
    check("no finished run is ignored (${pass})" NOT err_real MATCHES "ignoring")
    file(STRINGS "${WORK_DIR}/real/summary.csv" real_rows
         REGEX ",2,[^,]+,[^,]+,[^,]+,[^,]+,[^,]+,ok,")
    list(LENGTH real_rows n)
    check("the real programs' logs give 3 finished rows with 2 epochs (${pass})" n EQUAL 3)
  endforeach()
  check("the second sweep (another --threads) found all 3 runs finished"
        out_real MATCHES "3 finished, 0 to do")
  file(GLOB real_logs "${WORK_DIR}/real/runs/*.log")
  list(FILTER real_logs EXCLUDE REGEX "\\.partial\\.log$")
  set(with_threads 0)
  foreach(log IN LISTS real_logs)
    file(STRINGS "${log}" head LIMIT_COUNT 1)
    if(head MATCHES " --threads 2 --csv ")
      math(EXPR with_threads "${with_threads} + 1")
    endif()
  endforeach()
  check("the real programs ran with --threads 2 (${with_threads} of 3 logs say so)"
        with_threads EQUAL 3)
else()
  message(STATUS "real task programs not built beside the runner; skipped that part")
endif()

string(TIMESTAMP ended "%s")
math(EXPR seconds "${ended} - ${started}")
message(STATUS "reproduce_resume: all checks passed in ${seconds} s")
