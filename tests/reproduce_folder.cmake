# The runner in a folder it shares: with a user's files, with a file it cannot remove, and
# with task programs that end their epoch when it stops (split from reproduce_faults.cmake):
#
#   cmake -DREPRODUCE=<examples/reproduce> -DWORK_DIR=<scratch dir> -P reproduce_folder.cmake
#
#   1. a leftover that cannot be removed (chattr +i, when the file system and user allow it)
#      fails its own run, named, and the others finish;
#   2. files in runs/ under names no run has are neither counted, named nor removed;
#   3. on one SIGTERM the runner waits for its task programs to end their epoch; on a second
#      it kills them at once.
cmake_minimum_required(VERSION 3.20)
include("${CMAKE_CURRENT_LIST_DIR}/reproduce_common.cmake")
start_with_fake_cart_pole_grid(reproduce_folder.cmake)

# A leftover that cannot be removed (chattr +i; root, or another user's file in a shared
# folder): every executor in the folder stopped before any run with a bare "filesystem error:
# cannot remove", unrelated runs too. Now its run fails alone, named with the file and why.
set(I "${WORK_DIR}/immutable")
set(stuck "${I}/runs/cartpole_p4_C_norm_s42.partial.log")
file(MAKE_DIRECTORY "${I}/runs")
file(WRITE "${stuck}" "the log of a killed run\n")
execute_process(COMMAND chattr +i "${stuck}" RESULT_VARIABLE chattr_rc OUTPUT_QUIET ERROR_QUIET)
if(chattr_rc EQUAL 0)
  execute_process(COMMAND "${REPRODUCE}" ${grid} --out "${I}" RESULT_VARIABLE rc
                  OUTPUT_QUIET ERROR_VARIABLE err)
  execute_process(COMMAND chattr -i "${stuck}")
  count_lines("${I}/summary.csv" rows)
  check("a leftover that cannot go fails its run alone, named (${err})"
        rc EQUAL 1 AND rows EQUAL 6 AND err MATCHES "1 run failed"
        AND err MATCHES "cannot remove \"[^\n]*C_norm_s42.partial.log\": Operation not permitted")
else()
  message(WARNING "chattr +i failed (not root, or no such attribute here): the case of a "
                  "leftover that cannot be removed is skipped")
endif()

# A user's files in runs/ under names no run has: a sweep removed my_analysis.csv as a
# damaged run ("its .run file is missing"), and a nested --out's summary.csv with it. Now
# they are left alone, unnamed, by a sweep and by --merge.
set(U "${WORK_DIR}/user_files")
file(MAKE_DIRECTORY "${U}/runs")
file(WRITE "${U}/runs/my_analysis.csv" "my,notes\n")
file(WRITE "${U}/runs/summary.csv" "a nested sweep's summary\n")
file(WRITE "${U}/runs/draft.partial.txt" "notes\n")
file(WRITE "${U}/runs/chain_notes_for_me_s1.csv" "shaped almost like a run's name\n")
execute_process(COMMAND "${REPRODUCE}" ${grid} --out "${U}" RESULT_VARIABLE rc OUTPUT_QUIET
                ERROR_VARIABLE err)
execute_process(COMMAND "${REPRODUCE}" ${grid} --out "${U}" --merge RESULT_VARIABLE merge_rc
                OUTPUT_QUIET ERROR_VARIABLE merge_err)
check("a user's files in runs/ stay, unnamed (${err}${merge_err})"
      rc EQUAL 0 AND merge_rc EQUAL 0 AND EXISTS "${U}/runs/my_analysis.csv"
      AND EXISTS "${U}/runs/summary.csv" AND EXISTS "${U}/runs/draft.partial.txt"
      AND EXISTS "${U}/runs/chain_notes_for_me_s1.csv"
      AND NOT err MATCHES "my_analysis|summary \\(|draft|notes"
      AND NOT merge_err MATCHES "my_analysis|notes")

# The runner's stop. On SIGTERM a task program ends its epoch and keeps it in its checkpoint,
# which can take minutes in a large scene; the runner killed it 3 s later, and the epoch was
# lost. Now it waits for its children, and a second signal kills them at once. The program
# below has epochs of 4 s and notes each that ends.
set(E "${WORK_DIR}/epoch_end")
file(MAKE_DIRECTORY "${E}/bin")
file(WRITE "${E}/bin/cartpole" [=[#!/bin/sh
if [ "${1:-}" = --help ]; then
  echo "flags: --csv FILE, --threads N, --epochs N, --seed N, --method M, --clip C, --samples N"
  exit 0
fi
csv=
while [ $# -gt 0 ]; do
  [ "$1" = --csv ] && csv=$2
  shift
done
out=$(dirname "$(dirname "$csv")")
stop=
trap 'stop=1' TERM
while :; do
  sleep 4 & pid=$!
  while kill -0 "$pid" 2>/dev/null; do wait "$pid"; done
  echo "an epoch ended" >> "$out/epochs_ended"
  [ -n "$stop" ] && exit 143
done
]=])
file(CHMOD "${E}/bin/cartpole" PERMISSIONS OWNER_READ OWNER_WRITE OWNER_EXECUTE)
# $1 SIGTERMs to the runner (the rest of the line), the first after 1 s, then 0.5 s apart.
file(WRITE "${E}/signal.sh" [=[
n=$1
shift
"$@" > /dev/null 2> "$ERR" &
pid=$!
sleep 1
for k in $(seq "$n"); do kill -TERM "$pid"; sleep 0.5; done
wait "$pid"
]=])
foreach(signals 1 2)
  execute_process(COMMAND env "ERR=${E}/err${signals}" sh "${E}/signal.sh" ${signals}
                          "${REPRODUCE}" --tasks cartpole --complexities 4 --methods C
                          --clips norm --seeds 1 --epochs 3 --no-plot --bin-dir "${E}/bin"
                          --out "${E}/out${signals}" RESULT_VARIABLE rc)
  file(READ "${E}/err${signals}" err)
  set(ended "${E}/out${signals}/epochs_ended")
  if(signals EQUAL 1)
    check("one SIGTERM: the run ends its epoch, exit 130 (${err})"
          rc EQUAL 130 AND EXISTS "${ended}" AND err MATCHES
          "SIGTERM: stopping 1 running run after the current epoch, which keeps its work")
  else()
    check("a second SIGTERM kills the run at once, exit 130 (${err})"
          rc EQUAL 130 AND NOT EXISTS "${ended}")
  endif()
endforeach()
