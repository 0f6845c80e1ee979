# One plan, any executor (issue 16, point 1), with the fake task programs of
# reproduce_fake_task.sh:
#
#   cmake -DREPRODUCE=<path of examples/reproduce> -DWORK_DIR=<scratch dir> -P reproduce_executors.cmake
#
#   1. the local executor (--jobs 2) gives the reference summary.csv;
#   2. --emit parallel prints one command per run; run by sh one after the other, then --merge:
#      the same summary (timing aside); a second --emit parallel prints nothing;
#   3. three --shard K/3 at once in one folder: disjoint and covering (every run started once),
#      the same summary;
#   4. two full executors at once in one folder: every run started exactly once (the per-run
#      lock), the same summary;
#   5. --merge counts done, running (a lock held by another process) and missing runs;
#      a sweep waits for a run that another process holds, says so again while it waits, with
#      the age of the run's log, then runs it;
#   6. --emit slurm writes a job array of the unfinished runs (--array=0-(n-1)%K, the CPUs,
#      a time limit, a log per task) and a merge job with the figures' flags, and prints the
#      sbatch commands;
#   7. --run, --shard, --emit refuse bad values and each other with exit 2, and --emit
#      parallel a folder whose commands would not fit on one line.
cmake_minimum_required(VERSION 3.20)
foreach(var REPRODUCE WORK_DIR)
  if(NOT DEFINED ${var})
    message(FATAL_ERROR "reproduce_executors.cmake: pass -D${var}=...")
  endif()
endforeach()
include("${CMAKE_CURRENT_LIST_DIR}/reproduce_common.cmake")
file(REMOVE_RECURSE "${WORK_DIR}")
install_fake_task_programs("${WORK_DIR}/fake")

# cart pole 4 poles and guidance rc 0.001; R and C; seeds 42, 43: 8 runs.
set(grid --tasks cartpole,guidance --complexities 4,0.001 --methods R,C --clips norm --seeds 2
         --epochs 3 --no-plot --bin-dir "${WORK_DIR}/fake")

function(started_runs dir out_var)
  file(STRINGS "${dir}/fake_invocations" started)
  list(LENGTH started n)
  list(REMOVE_DUPLICATES started)
  list(LENGTH started distinct)
  set(${out_var} "${n} ${distinct}" PARENT_SCOPE)
endfunction()

# --- 1. local ----------------------------------------------------------------------------------
execute_process(COMMAND "${REPRODUCE}" ${grid} --jobs 2 --out "${WORK_DIR}/local"
                RESULT_VARIABLE rc OUTPUT_QUIET ERROR_VARIABLE err)
check("the local sweep exits 0" rc EQUAL 0)
check("its progress lines count, time and estimate the time left (${err})"
      err MATCHES "\\[[0-9]/8\\] [0-9]+s elapsed, about [0-9]+s left")
untimed_summary("${WORK_DIR}/local/summary.csv" reference)
count_lines("${WORK_DIR}/local/summary.csv" rows)
check("the local summary has 8 rows" rows EQUAL 9)

# --- 2. --emit parallel ------------------------------------------------------------------------
set(P "${WORK_DIR}/parallel")
execute_process(COMMAND "${REPRODUCE}" ${grid} --out "${P}" --emit parallel
                RESULT_VARIABLE rc OUTPUT_VARIABLE commands ERROR_VARIABLE err)
check("--emit parallel exits 0, and counts the runs on stderr (${err})"
      rc EQUAL 0 AND err MATCHES "8 of 8 planned runs to do")
string(REGEX MATCHALL "[^\n]+\n" lines "${commands}")
list(LENGTH lines n)
check("--emit parallel prints 8 commands" n EQUAL 8)
check("each is the runner with --run NAME" commands MATCHES "reproduce [^\n]* --run cartpole_p4_R_norm_s42\n")
check("--emit parallel ran nothing and made no folder" NOT EXISTS "${P}")
file(WRITE "${WORK_DIR}/commands.sh" "${commands}")
execute_process(COMMAND sh "${WORK_DIR}/commands.sh" RESULT_VARIABLE rc OUTPUT_QUIET ERROR_QUIET)
check("the emitted commands exit 0" rc EQUAL 0)
execute_process(COMMAND "${REPRODUCE}" ${grid} --out "${P}" --merge RESULT_VARIABLE rc
                OUTPUT_VARIABLE merged ERROR_VARIABLE err)
check("--merge after the emitted commands exits 0 (${err})" rc EQUAL 0)
check("--merge counts 8 done, 0 running, 0 missing"
      merged MATCHES "8 of 8 planned runs done, 0 running \\(lock held\\), 0 missing")
untimed_summary("${P}/summary.csv" summary)
check("the emitted commands give the local summary (timing aside)" summary STREQUAL reference)
execute_process(COMMAND "${REPRODUCE}" ${grid} --out "${P}" --emit parallel
                RESULT_VARIABLE rc OUTPUT_VARIABLE again ERROR_VARIABLE err)
check("--emit parallel over a finished sweep prints no command, and says so (${err})"
      rc EQUAL 0 AND NOT again AND err MATCHES "all 8 planned runs are finished")

# --- 3. three shards at once -------------------------------------------------------------------
set(S "${WORK_DIR}/shards")
file(WRITE "${WORK_DIR}/concurrent.sh" [=[
# Starts every argument-separated command (separated by ::) at once; fails if any fails.
pids=
cmd=
for a in "$@"; do
  if [ "$a" = "::" ]; then eval "$cmd" & pids="$pids $!"; cmd=; else cmd="$cmd '$a'"; fi
done
eval "$cmd" & pids="$pids $!"
status=0
for p in $pids; do wait $p || status=1; done
exit $status
]=])
set(shard_commands "")
foreach(k 1 2 3)
  list(APPEND shard_commands "${REPRODUCE}" ${grid} --jobs 2 --shard ${k}/3 --out "${S}")
  if(NOT k EQUAL 3)
    list(APPEND shard_commands ::)
  endif()
endforeach()
execute_process(COMMAND sh "${WORK_DIR}/concurrent.sh" ${shard_commands} RESULT_VARIABLE rc
                OUTPUT_QUIET ERROR_QUIET)
check("three shards at once exit 0" rc EQUAL 0)
started_runs("${S}" starts)
check("the shards started every run once (starts, distinct: ${starts})" starts STREQUAL "8 8")
execute_process(COMMAND "${REPRODUCE}" ${grid} --out "${S}" --merge OUTPUT_QUIET RESULT_VARIABLE rc)
untimed_summary("${S}/summary.csv" summary)
check("the shards give the local summary" rc EQUAL 0 AND summary STREQUAL reference)

# --- 4. two full executors at once in one folder -------------------------------------------------
set(T "${WORK_DIR}/twice")
execute_process(COMMAND sh "${WORK_DIR}/concurrent.sh" "${REPRODUCE}" ${grid} --jobs 2 --out "${T}"
                :: "${REPRODUCE}" ${grid} --jobs 3 --out "${T}" RESULT_VARIABLE rc
                OUTPUT_QUIET ERROR_QUIET)
check("two executors at once in one folder exit 0" rc EQUAL 0)
started_runs("${T}" starts)
check("between them every run was started exactly once (${starts})" starts STREQUAL "8 8")
untimed_summary("${T}/summary.csv" summary)
check("their summary is the local one" summary STREQUAL reference)

# --- 5. --merge counts running and missing runs ----------------------------------------------
file(REMOVE "${P}/runs/guidance_rc0.001_C_norm_s43.csv")
# Another process holds a run's lock (as an executor running it would) while --merge looks.
file(WRITE "${WORK_DIR}/hold.sh" [=[
flock "$1" sleep ${HOLD_SECONDS:-3} &
sleep 0.5
shift
"$@"
]=])
file(REMOVE "${P}/runs/cartpole_p4_C_norm_s42.csv")
execute_process(COMMAND sh "${WORK_DIR}/hold.sh" "${P}/runs/cartpole_p4_C_norm_s42.lock"
                "${REPRODUCE}" ${grid} --out "${P}" --merge RESULT_VARIABLE rc
                OUTPUT_VARIABLE merged)
check("--merge with a run missing and one running exits 1" rc EQUAL 1)
check("--merge: 6 done, 1 running, 1 missing, named (${merged})"
      merged MATCHES "6 of 8 planned runs done, 1 running \\(lock held\\), 1 missing"
      AND merged MATCHES "running: cartpole_p4_C_norm_s42"
      AND merged MATCHES "missing: guidance_rc0.001_C_norm_s43")

# --- 6. --emit slurm -----------------------------------------------------------------------------
execute_process(COMMAND "${REPRODUCE}" ${grid} --jobs 3 --threads 2 --out "${P}" --emit slurm
                RESULT_VARIABLE rc OUTPUT_VARIABLE printed)
check("--emit slurm exits 0" rc EQUAL 0)
file(READ "${P}/slurm/array.sh" array)
file(READ "${P}/slurm/runs.txt" listed)
check("the array lists the 2 unfinished runs (${listed})"
      listed STREQUAL "cartpole_p4_C_norm_s42\nguidance_rc0.001_C_norm_s43\n")
check("the array: 2 tasks, 3 at once, 2 CPUs, a time limit, a log per task"
      array MATCHES "#SBATCH --array=0-1%3\n" AND array MATCHES "#SBATCH --cpus-per-task=2\n"
      AND array MATCHES "#SBATCH --time=[1-9][0-9]*\n"
      AND array MATCHES "#SBATCH --output=\"[^\n]*/slurm/logs/run_%A_%a.log\"\n"
      AND array MATCHES "--run \"\\$run\"")
file(READ "${P}/slurm/merge.sh" merge)
check("the merge job runs --merge, its log named by its job"
      merge MATCHES "reproduce [^\n]* --merge\n" AND merge MATCHES "/slurm/logs/merge_%j.log")
# The figures' flags reach the merge job: without them it plotted with the system's python
# (often without matplotlib on a cluster) and drew nothing, with a warning in its log alone.
set(M "${WORK_DIR}/merge_flags")
file(MAKE_DIRECTORY "${M}")
file(WRITE "${M}/plot.py" "")
set(plotting_grid ${grid})
list(REMOVE_ITEM plotting_grid --no-plot)
execute_process(COMMAND "${REPRODUCE}" ${plotting_grid} --out "${M}/out" --python /bin/sh
                        --plot-script plot.py --emit slurm
                WORKING_DIRECTORY "${M}" RESULT_VARIABLE rc OUTPUT_QUIET ERROR_QUIET)
file(READ "${M}/out/slurm/merge.sh" merge_flags)
check("merge.sh carries --python and --plot-script, the script's path made absolute (${merge_flags})"
      rc EQUAL 0 AND merge_flags MATCHES " --python /bin/sh --plot-script ${M}/plot.py --merge\n")
check("the printed sbatch commands chain the merge job after the array"
      printed MATCHES "sbatch --parsable [^\n]*array.sh[^\n]*--dependency=afterany:[^\n]*merge.sh")
# The array's script runs its task's run as Slurm would (task 1: the second listed run),
# from its own list: it read runs.txt when it ran, and a later --emit, which rewrites that
# file, gave the tasks of an array still queued other runs, or none ("--run ''").
file(WRITE "${P}/slurm/runs.txt" "a later emit's list\n")
execute_process(COMMAND env SLURM_ARRAY_TASK_ID=1 bash "${P}/slurm/array.sh"
                RESULT_VARIABLE rc OUTPUT_QUIET ERROR_QUIET)
check("array task 1 runs guidance_rc0.001_C_norm_s43"
      rc EQUAL 0 AND EXISTS "${P}/runs/guidance_rc0.001_C_norm_s43.csv")

# A sweep whose run another process holds (as another executor would): the sweep waited for
# nothing and exited 0 with the run unfinished, against "0: every planned run is finished".
# It now waits, and runs it when the holder lets go of it unfinished. While it waits it says
# so again from time to time, with how long ago the holder last wrote the run's log: a log
# that does not grow is a stopped holder (a suspended job). It said so once, with no age.
file(WRITE "${P}/runs/cartpole_p4_C_norm_s42.partial.log" "epoch 1\n")
execute_process(COMMAND touch -d "2 hours ago" "${P}/runs/cartpole_p4_C_norm_s42.partial.log")
execute_process(COMMAND env HOLD_SECONDS=13 sh "${WORK_DIR}/hold.sh"
                "${P}/runs/cartpole_p4_C_norm_s42.lock"
                "${REPRODUCE}" ${grid} --out "${P}" RESULT_VARIABLE rc OUTPUT_VARIABLE swept
                ERROR_VARIABLE swept_err)
check("a sweep over a run held elsewhere: exit 0 once it is finished\n${swept}${swept_err}"
      rc EQUAL 0 AND EXISTS "${P}/runs/cartpole_p4_C_norm_s42.csv"
      AND swept_err MATCHES "1 held by another executor \\(e.g. cartpole_p4_C_norm_s42, "
      AND swept_err MATCHES "cartpole_p4_C_norm_s42, its log last written 2h0[0-9]m ago\\)")
string(REGEX MATCHALL "held by another executor" waiting_lines "${swept_err}")
list(LENGTH waiting_lines waiting_count)
check("a sweep that waits 12 s for a held run says so at least twice (${waiting_count})"
      waiting_count GREATER_EQUAL 2)

# A run that an executor of other settings (--epochs 2 against 3) finishes while this sweep
# waits for it: the sweep exited 0, its table and summary.csv holding the other settings'
# result (two sweeps into one --out at once); it now names the run and exits 1.
set(O "${WORK_DIR}/other_settings")
execute_process(COMMAND "${REPRODUCE}" ${grid} --epochs 2 --out "${O}/earlier"
                        --run cartpole_p4_C_norm_s42 RESULT_VARIABLE rc OUTPUT_QUIET ERROR_QUIET)
check("a run of --epochs 2 for the test below" rc EQUAL 0)
file(MAKE_DIRECTORY "${O}/now/runs")
# Holds run $2's lock in $1/runs for 2 s and then gives it the finished files of $3/runs/$2,
# the CSV last, as an executor that finishes the run would.
file(WRITE "${WORK_DIR}/finish_elsewhere.sh" [=[
flock "$1/runs/$2.lock" sh -c 'sleep 2
  cp "$3/runs/$2.log" "$3/runs/$2.run" "$3/runs/$2.csv" "$1/runs/"' sh "$1" "$2" "$3" &
sleep 0.5
shift 3
"$@"
]=])
execute_process(COMMAND sh "${WORK_DIR}/finish_elsewhere.sh" "${O}/now" cartpole_p4_C_norm_s42
                        "${O}/earlier" "${REPRODUCE}" ${grid} --out "${O}/now"
                RESULT_VARIABLE rc OUTPUT_QUIET ERROR_VARIABLE swept_err)
set(named "1 finished run in [^\n]* was made with other settings than planned now, by another "
          "executor during this sweep \\(e.g. cartpole_p4_C_norm_s42")
string(CONCAT named ${named})
check("a run finished meanwhile with other settings: exit 1, named (${swept_err})"
      rc EQUAL 1 AND swept_err MATCHES "${named}")

# --- 7. bad values ---------------------------------------------------------------------------------
foreach(bad "--shard;0/3" "--shard;4/3" "--shard;2" "--emit;pbs" "--run;nosuchrun"
            "--merge;--dry-run" "--run;cartpole_p4_R_norm_s42;--shard;1/2")
  execute_process(COMMAND "${REPRODUCE}" ${grid} ${bad} --out "${WORK_DIR}/bad"
                  RESULT_VARIABLE rc OUTPUT_QUIET ERROR_VARIABLE err)
  list(GET bad 0 flag)
  check("${bad}: exit 2 naming ${flag} (${err})" rc EQUAL 2 AND err MATCHES "${flag}")
endforeach()
check("no bad value created the folder" NOT EXISTS "${WORK_DIR}/bad")

# A line break in --out printed each command over two lines (exit 0), which GNU parallel, which
# reads a command a line, ran as two broken halves.
execute_process(COMMAND "${REPRODUCE}" ${grid} --out "${WORK_DIR}/new\nline" --emit parallel
                RESULT_VARIABLE rc OUTPUT_VARIABLE printed ERROR_VARIABLE err)
check("--emit parallel refuses a line break in --out: exit 2, naming it, nothing printed (${err})"
      rc EQUAL 2 AND err MATCHES "--out '[^']*new.x0aline' with --emit parallel: its path holds a control character"
      AND NOT printed)
