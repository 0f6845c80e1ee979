# The runner never trusts a finished run's files blindly, and stops and refuses the way its
# docs say (issue 13: defects 1, 9, 11, point 2 and two minor ones).
#
#   cmake -DREPRODUCE=<path of examples/reproduce> -DWORK_DIR=<scratch dir> -P reproduce_faults.cmake
#
# With the fake task programs of reproduce_fake_task.sh it
#   1. damages the finished runs of a sweep in every way a crash or a user can (CSV emptied, cut
#      mid-line, cut at a line boundary, .run removed, .log removed, CSV inconsistent with the
#      exit code in the log), also a run of an earlier sweep that the next one does not plan,
#      and checks that the next sweep exits 0, names each damaged run, redoes exactly the
#      planned ones, and that its summary.csv equals the undamaged sweep's (timing aside);
#      a folder in place of a run's file is refused in every mode and kept;
#   2. checks that --epochs and --samples above the task programs' limit, a --python that
#      does not exist and an --out that is a file or lies under one are refused with exit 2
#      before any work, and so are a missing --plot-script, an empty --run, an --out name
#      longer than the file system takes, one where no folder can be made (/proc), one under
#      a symbolic link to nothing or one that sbatch would misread (--emit slurm); the probe
#      of --out leaves nothing behind;
#      finished runs of other settings are refused with exit 1 in every mode;
#   3. interrupts the runner while it plots (a fake python and plot script that leave a
#      temporary PNG behind): exit 130 on SIGTERM and on SIGINT, no "no plots" message, no
#      plots/.tmp.* left; started with SIGHUP and SIGINT ignored (nohup, a script's background
#      job), it neither catches them nor stops on them; interrupted while --dry-run measures,
#      it says so, exits 130 and leaves no scratch folder; interrupted while it prints the
#      plan, it stops, says so and exits 130;
#   (the file system's locks and fsync: reproduce_durability.cmake).
cmake_minimum_required(VERSION 3.20)
include("${CMAKE_CURRENT_LIST_DIR}/reproduce_common.cmake")
start_with_fake_cart_pole_grid(reproduce_faults.cmake)
set(out "${WORK_DIR}/sweep")

# --- 1. damaged finished runs ----------------------------------------------------------------
# An earlier sweep with another filter leaves guidance runs in the same folder.
execute_process(COMMAND "${REPRODUCE}" --tasks guidance --complexities 0.001 --methods C
                --clips norm --seeds 1 --epochs 3 --no-plot --bin-dir "${WORK_DIR}/fake"
                --out "${out}" RESULT_VARIABLE rc OUTPUT_QUIET ERROR_QUIET)
check("the earlier, other sweep exits 0" rc EQUAL 0)
execute_process(COMMAND "${REPRODUCE}" ${grid} --out "${out}" RESULT_VARIABLE rc
                OUTPUT_VARIABLE first_out ERROR_VARIABLE first_err)
check("the undamaged sweep exits 0" rc EQUAL 0)
untimed_summary("${out}/summary.csv" undamaged)
file(REMOVE "${out}/fake_invocations")

set(runs "${out}/runs")
file(WRITE "${runs}/cartpole_p4_R_norm_s42.csv" "")  # emptied
file(READ "${runs}/cartpole_p4_C_norm_s42.csv" text)  # cut mid-line
string(LENGTH "${text}" length)
math(EXPR cut "${length} - 7")
string(SUBSTRING "${text}" 0 ${cut} text_cut)
file(WRITE "${runs}/cartpole_p4_C_norm_s42.csv" "${text_cut}")
file(STRINGS "${runs}/cartpole_p4_C_norm_s43.csv" rows)  # cut at a line boundary
list(REMOVE_AT rows -1)
list(JOIN rows "\n" text)
file(WRITE "${runs}/cartpole_p4_C_norm_s43.csv" "${text}\n")
file(REMOVE "${runs}/cartpole_p4_R_norm_s44.run")
file(REMOVE "${runs}/cartpole_p4_C_norm_s44.log")
# R s43 stopped (exit 3) after 2 epochs; its log is made to say exit 0, which 2 rows contradict.
file(READ "${runs}/cartpole_p4_R_norm_s43.log" text)
string(REPLACE "# reproduce: exit code 3" "# reproduce: exit code 0" text "${text}")
file(WRITE "${runs}/cartpole_p4_R_norm_s43.log" "${text}")
file(WRITE "${runs}/guidance_rc0.001_C_norm_s42.csv" "epoch,batch_loss")  # not planned now
set(damaged cartpole_p4_R_norm_s42 cartpole_p4_C_norm_s42 cartpole_p4_C_norm_s43
            cartpole_p4_R_norm_s44 cartpole_p4_C_norm_s44 cartpole_p4_R_norm_s43)

execute_process(COMMAND "${REPRODUCE}" ${grid} --out "${out}" RESULT_VARIABLE rc
                OUTPUT_VARIABLE again_out ERROR_VARIABLE again_err)
message(STATUS "the sweep over damaged runs:\n${again_out}${again_err}")
check("the sweep over damaged runs exits 0" rc EQUAL 0)
check("no damaged run is taken for other settings" NOT again_err MATCHES "other settings")
file(STRINGS "${out}/fake_invocations" redone)
list(SORT redone)
set(expected ${damaged})
list(SORT expected)
check("exactly the 6 damaged runs were redone, once each (${redone})" redone STREQUAL expected)
set(again "${again_out}${again_err}")
foreach(name IN LISTS damaged guidance_rc0.001_C_norm_s42)
  check("${name}: the runner says it is damaged and why"
        again MATCHES "${name}[^\n]*(damaged|missing|empty|cut|contradict)")
endforeach()
check("the damaged run of the earlier sweep is named as left to a sweep that plans it"
      again_err MATCHES "guidance_rc0.001_C_norm_s42[^\n]*not planned")
# Damaged files were removed, those of a run not planned too, whatever made them damaged (a
# blank line an editor added, CRLF from a copy): the work in them is kept aside instead.
check("a damaged run's files are moved to a folder of their own, and the runner says so"
      again MATCHES "cartpole_p4_C_norm_s42: [^\n]*the run is redone, its files moved to [^\n]*runs/damaged/cartpole_p4_C_norm_s42.1\n"
      AND again_err MATCHES "guidance_rc0.001_C_norm_s42 [^\n]*moved to [^\n]*runs/damaged/guidance_rc0.001_C_norm_s42.1")
file(READ "${runs}/damaged/guidance_rc0.001_C_norm_s42.1/guidance_rc0.001_C_norm_s42.csv"
     kept_unplanned)
file(READ "${runs}/damaged/cartpole_p4_C_norm_s42.1/cartpole_p4_C_norm_s42.csv" kept_cut)
check("runs/damaged/<name>.1 holds the damaged files as they were"
      kept_unplanned STREQUAL "epoch,batch_loss" AND kept_cut STREQUAL text_cut
      AND EXISTS "${runs}/damaged/guidance_rc0.001_C_norm_s42.1/guidance_rc0.001_C_norm_s42.log"
      AND EXISTS "${runs}/damaged/cartpole_p4_C_norm_s42.1/cartpole_p4_C_norm_s42.run")
# A second damage of a run goes to a folder of its own; with a file in the place of
# runs/damaged the files stay where they are, and the runner says so, not that they moved.
file(WRITE "${runs}/cartpole_p4_C_norm_s42.csv" "${text_cut}")
execute_process(COMMAND "${REPRODUCE}" ${grid} --out "${out}" OUTPUT_VARIABLE second ERROR_QUIET)
check("a second damage goes to runs/damaged/<name>.2, the first kept (${second})"
      second MATCHES "runs/damaged/cartpole_p4_C_norm_s42.2\n"
      AND EXISTS "${runs}/damaged/cartpole_p4_C_norm_s42.2/cartpole_p4_C_norm_s42.csv"
      AND EXISTS "${runs}/damaged/cartpole_p4_C_norm_s42.1/cartpole_p4_C_norm_s42.csv")
file(RENAME "${runs}/damaged" "${WORK_DIR}/damaged_kept")
file(WRITE "${runs}/damaged" "a file\n")
file(WRITE "${runs}/cartpole_p4_C_norm_s42.csv" "${text_cut}")
execute_process(COMMAND "${REPRODUCE}" ${grid} --out "${out}" RESULT_VARIABLE rc
                OUTPUT_VARIABLE blocked ERROR_QUIET)
file(READ "${runs}/cartpole_p4_C_norm_s42.csv.damaged" kept_beside)
check("no folder for them: the files are renamed beside, and the run is redone (${blocked})"
      rc EQUAL 0 AND blocked MATCHES "the run is redone, its files renamed to [^\n]*cartpole_p4_C_norm_s42.[*].damaged"
      AND kept_beside STREQUAL text_cut AND EXISTS "${runs}/cartpole_p4_C_norm_s42.csv")
file(REMOVE "${runs}/cartpole_p4_C_norm_s42.csv.damaged" "${runs}/cartpole_p4_C_norm_s42.log.damaged"
     "${runs}/cartpole_p4_C_norm_s42.run.damaged")
file(REMOVE "${runs}/damaged")
untimed_summary("${out}/summary.csv" repaired)
string(REGEX REPLACE "[^\n]*guidance[^\n]*\n" "" undamaged_cartpole "${undamaged}")
check("summary.csv after the repair equals the undamaged one (timing aside, no guidance row)"
      repaired STREQUAL undamaged_cartpole)

# Field K (1-based) of the last row of the training log `csv` becomes `value`.
function(set_last_row_field csv k value)
  file(STRINGS "${csv}" rows)
  list(POP_BACK rows last)
  set(prefix "")
  foreach(i RANGE 2 ${k})
    string(APPEND prefix "[^,]*,")
  endforeach()
  string(REGEX REPLACE "^(${prefix})[^,]*" "\\1${value}" last "${last}")
  list(APPEND rows "${last}")
  list(JOIN rows "\n" text)
  file(WRITE "${csv}" "${text}\n")
endfunction()

# A NaN in a finished run's log: the programs never write one (a non-finite epoch has no row),
# so it is damage, not a result; --merge took it for a run whose last test loss is unknown.
set_last_row_field("${runs}/cartpole_p4_C_norm_s42.csv" 4 nan)
execute_process(COMMAND "${REPRODUCE}" ${grid} --merge --out "${out}" RESULT_VARIABLE rc
                OUTPUT_VARIABLE merge_out ERROR_VARIABLE merge_err)
check("--merge over a NaN test loss: exit 1, the run named damaged, not finite\n${merge_out}${merge_err}"
      rc EQUAL 1 AND "${merge_out}${merge_err}" MATCHES
      "cartpole_p4_C_norm_s42[^\n]*'nan' is not finite[^\n]*damaged")
file(READ "${out}/summary.csv" merged)
check("--merge over a NaN test loss: no summary row for the run"
      NOT merged MATCHES "cartpole_p4_C_norm_s42")

# A damaged run that the merge does not plan (of another selection in the same folder) was left
# out of summary.csv without a word.
file(WRITE "${runs}/guidance_rc0.001_C_norm_s42.csv" "")
execute_process(COMMAND "${REPRODUCE}" ${grid} --merge --out "${out}" RESULT_VARIABLE rc
                OUTPUT_VARIABLE merge_out ERROR_VARIABLE merge_err)
file(REMOVE "${runs}/guidance_rc0.001_C_norm_s42.csv")
check("--merge names a damaged run it does not plan, left out of summary.csv\n${merge_err}"
      merge_err MATCHES "warning: guidance_rc0.001_C_norm_s42 [^\n]*not planned[^\n]*: its .run file is missing[^\n]*left out of summary.csv")

# Every field of a row, not only the losses: a NaN batch loss or update norm, a cosine or an
# agreement outside its range, one where the method computes none, a negative time. The runner
# merged each of these as an "ok" run. The file is restored after each check.
function(check_last_row_refused run k value expected)
  set(file "${runs}/${run}.csv")
  file(READ "${file}" kept)
  set_last_row_field("${file}" ${k} "${value}")
  execute_process(COMMAND "${REPRODUCE}" ${grid} --merge --out "${out}" RESULT_VARIABLE rc
                  OUTPUT_VARIABLE merge_out ERROR_VARIABLE merge_err)
  file(WRITE "${file}" "${kept}")
  check("--merge over field ${k} = '${value}' of ${run}: exit 1, damaged, ${expected}\n${merge_out}${merge_err}"
        rc EQUAL 1 AND "${merge_out}${merge_err}" MATCHES "${run}[^\n]*${expected}[^\n]*damaged")
endfunction()
check_last_row_refused(cartpole_p4_C_norm_s43 2 nan "batch_loss.: 'nan' is not finite")
check_last_row_refused(cartpole_p4_C_norm_s43 5 nan "update_norm2.: 'nan' is not a number >= 0 or 'inf'")
check_last_row_refused(cartpole_p4_C_norm_s43 5 -1 "update_norm2.: '-1' is not a number >= 0 or 'inf'")
check_last_row_refused(cartpole_p4_C_norm_s43 6 x "cos_m_r.: 'x' is not a number")
check_last_row_refused(cartpole_p4_R_norm_s44 6 nan "cos_m_r.: 'nan' where method R logs nothing")
check_last_row_refused(cartpole_p4_C_norm_s43 6 1.5 "cos_m_r.: '1.5' is outside .-1, 1.")
check_last_row_refused(cartpole_p4_C_norm_s43 6 "" "cos_m_r.: empty")
check_last_row_refused(cartpole_p4_C_norm_s43 7 -0.25 "agree_fraction.: '-0.25' is outside .0, 1.")
check_last_row_refused(cartpole_p4_R_norm_s44 7 0.75 "agree_fraction.: '0.75' where method R logs nothing")
check_last_row_refused(cartpole_p4_C_norm_s43 8 -0.5 "seconds.: '-0.5' is negative")
# A norm that overflowed double's square is what the programs write (docs/formats.md), and a
# cos_m_r of nan what builds before 96694fb wrote where float sums of squares overflowed.
file(READ "${runs}/cartpole_p4_C_norm_s43.csv" kept)
set_last_row_field("${runs}/cartpole_p4_C_norm_s43.csv" 5 inf)
set_last_row_field("${runs}/cartpole_p4_C_norm_s43.csv" 6 nan)
file(READ "${runs}/cartpole_p4_C_norm_s43.csv" text)
check("the last row's update_norm2 is 'inf', its cos_m_r 'nan'"
      text MATCHES "\n[0-9]+,[^,]*,[^,]*,[^,]*,inf,nan,[^\n]*\n$")
execute_process(COMMAND "${REPRODUCE}" ${grid} --merge --out "${out}" RESULT_VARIABLE rc
                OUTPUT_VARIABLE merge_out ERROR_VARIABLE merge_err)
file(WRITE "${runs}/cartpole_p4_C_norm_s43.csv" "${kept}")
file(READ "${out}/summary.csv" merged)
check("--merge over an update_norm2 of 'inf' and a cos_m_r of 'nan': the run is merged\n${merge_out}${merge_err}"
      NOT "${merge_out}${merge_err}" MATCHES "cartpole_p4_C_norm_s43[^\n]*damaged"
      AND merged MATCHES ",cartpole_p4_C_norm_s43\n")
# --dry-run judged a run finished when its .csv existed: the NaN run above was "(finished)",
# left out of the estimate, and a sweep then redid it.
execute_process(COMMAND "${REPRODUCE}" ${grid} --dry-run --out "${out}" RESULT_VARIABLE rc
                OUTPUT_VARIABLE dry_out ERROR_VARIABLE dry_err)
check("--dry-run over a damaged run: it is to be redone, and says why\n${dry_out}${dry_err}"
      rc EQUAL 0 AND dry_out MATCHES "cartpole_p4_C_norm_s42 [^\n]*damaged[^\n]*'nan' is not finite"
      AND dry_out MATCHES "5 finished, 1 to do")

# Standard output that cannot be written (a full disk): the commands of --emit parallel and
# the plan of --dry-run were lost with exit 0.
foreach(mode "--emit;parallel" --dry-run)
  execute_process(COMMAND "${REPRODUCE}" ${grid} ${mode} --out "${out}" RESULT_VARIABLE rc
                  OUTPUT_FILE /dev/full ERROR_VARIABLE err)
  check("${mode} into a full stdout: exit 1, saying so (${err})" rc EQUAL 1 AND err MATCHES
        "reproduce: standard output or standard error was not written in full: No space left")
endforeach()

# A named pipe where a finished run's files are (a user's mkfifo, a tool's leftover): --merge
# and a sweep opened it to read and hung there for ever.
foreach(suffix .csv .log .run)
  file(REMOVE "${runs}/cartpole_p4_R_norm_s44${suffix}")
  execute_process(COMMAND mkfifo "${runs}/cartpole_p4_R_norm_s44${suffix}")
  execute_process(COMMAND "${REPRODUCE}" ${grid} --merge --out "${out}" TIMEOUT 20
                  RESULT_VARIABLE rc OUTPUT_VARIABLE merge_out ERROR_VARIABLE merge_err)
  set(said "${merge_out}${merge_err}")
  check("--merge over a FIFO as the run's ${suffix}: exit 1 in time, damaged (${rc})\n${said}"
        rc EQUAL 1 AND said MATCHES "damaged: cartpole_p4_R_norm_s44: [^\n]*(FIFO|cut|damaged)")
  execute_process(COMMAND "${REPRODUCE}" ${grid} --out "${out}" TIMEOUT 20
                  RESULT_VARIABLE rc OUTPUT_VARIABLE swept ERROR_VARIABLE swept_err)
  check("a sweep over a FIFO as the run's ${suffix}: exit 0 in time, the run redone (${rc})"
        rc EQUAL 0 AND swept MATCHES "cartpole_p4_R_norm_s44: [^\n]*the run is redone")
  execute_process(COMMAND test -f "${runs}/cartpole_p4_R_norm_s44${suffix}" RESULT_VARIABLE rc)
  check("the redone run's ${suffix} is a regular file" rc EQUAL 0)
endforeach()

# Runs the grid on `out_dir` in every mode; each must exit `code`, say what matches
# `said_regex` and nothing that matches `work_regex` (a refusal before any work), and leave
# `kept`.
function(check_refused_in_every_mode label out_dir code said_regex work_regex kept)
  foreach(mode "" --merge --dry-run "--emit;parallel")
    execute_process(COMMAND "${REPRODUCE}" ${grid} ${mode} --out "${out_dir}" TIMEOUT 20
                    RESULT_VARIABLE rc OUTPUT_VARIABLE said ERROR_VARIABLE err)
    string(APPEND said "${err}")
    check("${label}, mode '${mode}': exit ${code} naming it, no work (${rc})\n${said}"
          rc EQUAL ${code} AND said MATCHES "${said_regex}" AND NOT said MATCHES "${work_regex}")
    check("${label}, mode '${mode}': the user's file kept" EXISTS "${kept}")
  endforeach()
endfunction()

# A folder where a run's file belongs (a user's mkdir, an unpacked archive): the sweep said
# "the run is redone", then failed to remove the folder and exited 1 with a bare "filesystem
# error". Every mode now refuses it before any work, names it, and leaves it and its contents.
file(REMOVE "${runs}/cartpole_p4_R_norm_s44.csv")
file(WRITE "${runs}/cartpole_p4_R_norm_s44.csv/notes.txt" "a user's file\n")
check_refused_in_every_mode("a folder as a run's .csv" "${out}" 1
                            "cartpole_p4_R_norm_s44.csv' is a folder"
                            "redone|filesystem error|measured"
                            "${runs}/cartpole_p4_R_norm_s44.csv/notes.txt")
file(REMOVE_RECURSE "${runs}/cartpole_p4_R_norm_s44.csv")
execute_process(COMMAND "${REPRODUCE}" ${grid} --out "${out}" TIMEOUT 20 RESULT_VARIABLE rc
                OUTPUT_QUIET ERROR_QUIET)
check("the folder moved away: the sweep redoes the run (${rc})"
      rc EQUAL 0 AND EXISTS "${runs}/cartpole_p4_R_norm_s44.csv")

# A file where the runner keeps its runs or plots folder, a link to nothing there, or a folder
# where it writes its summary: the dry run and --emit said nothing, the sweep and --merge
# failed with a bare "filesystem error" or "cannot rename". Every mode now refuses --out before
# any work, naming the part.
foreach(part runs summary.csv plots runs_link)
  set(layout "${WORK_DIR}/layout_${part}")
  file(REMOVE_RECURSE "${layout}")
  file(MAKE_DIRECTORY "${layout}")
  if(part STREQUAL "runs" OR part STREQUAL "plots")
    set(kept "${layout}/${part}")
    set(layout_expected "'${part}' in it is a file. expected the folder")
  elseif(part STREQUAL "summary.csv")
    set(kept "${layout}/summary.csv/notes.txt")
    set(layout_expected "'summary.csv' in it is a folder. expected the runner's summary file")
  else()
    file(CREATE_LINK "${layout}/nowhere" "${layout}/runs" SYMBOLIC)
    set(kept "${layout}")
    set(layout_expected "'runs' in it is a symbolic link to nothing. expected the folder")
  endif()
  if(NOT part STREQUAL "runs_link")
    file(WRITE "${kept}" "a user's file\n")
  endif()
  set(whole_grid ${grid})
  if(part STREQUAL "plots")  # checked only where the figures are drawn
    list(REMOVE_ITEM grid --no-plot)
  endif()
  check_refused_in_every_mode("${part} of the wrong kind" "${layout}" 2
                              "--out '[^']*layout_${part}': ${layout_expected}"
                              "filesystem error|cannot rename|measured|cartpole_p" "${kept}")
  set(grid ${whole_grid})
endforeach()
# Only what this invocation writes is checked: a file named plots under --no-plot, or one named
# slurm without --emit slurm, is the user's business.
foreach(part plots slurm)
  file(WRITE "${WORK_DIR}/layout_unused_${part}/${part}" "a user's file\n")
  execute_process(COMMAND "${REPRODUCE}" ${grid} --dry-run  # the grid has --no-plot
                          --out "${WORK_DIR}/layout_unused_${part}" TIMEOUT 20 RESULT_VARIABLE rc
                  OUTPUT_QUIET ERROR_VARIABLE err)
  check("a file named ${part} that this invocation does not write: exit 0 (${rc})\n${err}"
        rc EQUAL 0)
endforeach()

# --- 2. limits shared with the task programs; a missing python ------------------------------
foreach(flag epochs samples)
  execute_process(COMMAND "${REPRODUCE}" ${grid} --${flag} 2000000 --out "${WORK_DIR}/limits"
                  TIMEOUT 20 RESULT_VARIABLE rc OUTPUT_QUIET ERROR_VARIABLE err)
  check("--${flag} 2000000: exit 2 naming the flag and the value (${err})"
        rc EQUAL 2 AND err MATCHES "--${flag} 2000000")
  check("--${flag} 2000000: nothing was started" NOT EXISTS "${WORK_DIR}/limits")
endforeach()
execute_process(COMMAND "${REPRODUCE}" ${grid} --python "${WORK_DIR}/nonexistent"
                --out "${WORK_DIR}/python" TIMEOUT 20 RESULT_VARIABLE rc OUTPUT_QUIET
                ERROR_VARIABLE err)
check("--python <missing>: exit 2 naming the flag, no matplotlib advice (${err})"
      rc EQUAL 2 AND err MATCHES "--python" AND NOT err MATCHES "matplotlib")
check("--python <missing>: nothing was started" NOT EXISTS "${WORK_DIR}/python")
# --run takes a run's name: an empty one was called "an empty path; expected a file path".
execute_process(COMMAND "${REPRODUCE}" ${grid} --run "" --out "${WORK_DIR}/empty_run" TIMEOUT 20
                RESULT_VARIABLE rc OUTPUT_QUIET ERROR_VARIABLE err)
check("--run '': exit 2, an empty name where a run's name is expected (${err})"
      rc EQUAL 2 AND err MATCHES "--run '' is an empty name. expected the name of a run")
# A --plot-script that is not there, for a sweep that plots: refused up front like --python
# (the whole sweep ran, and only its end warned "no plots", exit 0).
set(plotting_grid ${grid})
list(REMOVE_ITEM plotting_grid --no-plot)
execute_process(COMMAND "${REPRODUCE}" ${plotting_grid} --plot-script "${WORK_DIR}/nonexistent.py"
                --out "${WORK_DIR}/plot_script" TIMEOUT 20 RESULT_VARIABLE rc OUTPUT_QUIET
                ERROR_VARIABLE err)
check("--plot-script <missing>: exit 2 naming the flag and the file (${err})"
      rc EQUAL 2 AND err MATCHES "--plot-script '[^']*nonexistent.py'")
check("--plot-script <missing>: nothing was started" NOT EXISTS "${WORK_DIR}/plot_script")
# A python (or script) that exits 0 and draws nothing: the runner printed "plots: <out>/plots"
# for a folder that was never made.
file(WRITE "${WORK_DIR}/draws_nothing.py" "")
file(WRITE "${out}/plots/old.png" "a figure of an earlier plot")
execute_process(COMMAND touch -d "2 minutes ago" "${out}/plots/old.png")
execute_process(COMMAND "${REPRODUCE}" ${plotting_grid} --python /bin/true --plot-script
                "${WORK_DIR}/draws_nothing.py" --merge --out "${out}" TIMEOUT 20
                OUTPUT_VARIABLE plotted ERROR_VARIABLE plotted_err)
check("a plot script that draws nothing: a warning, no 'plots:' line\n${plotted}${plotted_err}"
      NOT plotted MATCHES "\nplots: " AND plotted_err MATCHES
      "warning: [^\n]*draws_nothing.py exited 0 but drew no figure in [^\n]*plots")
# --out naming a file, or a path under one: refused up front, naming the flag and the file, in
# every mode (a sweep stopped at its first write with "filesystem error: cannot create
# directories", exit 1, and --dry-run planned into it).
file(WRITE "${WORK_DIR}/a_file" "kept\n")
foreach(out "${WORK_DIR}/a_file" "${WORK_DIR}/a_file/results")
  foreach(mode "" --dry-run --merge "--emit;parallel")
    execute_process(COMMAND "${REPRODUCE}" ${grid} ${mode} --out "${out}" TIMEOUT 20
                    RESULT_VARIABLE rc OUTPUT_VARIABLE text ERROR_VARIABLE err)
    check("--out ${out} ${mode}: exit 2 naming --out and the file (${err})"
          rc EQUAL 2 AND err MATCHES "--out '${out}'" AND err MATCHES "a_file' is a file"
          AND NOT text MATCHES ".")
  endforeach()
endforeach()
# A name longer than the file system takes: every mode said "filesystem error: ... File name
# too long" (exit 1), or planned and emitted into it (exit 0).
string(REPEAT "a" 300 long_name)
foreach(mode "" --dry-run --merge "--emit;parallel" "--emit;slurm")
  execute_process(COMMAND "${REPRODUCE}" ${grid} ${mode} --out "${WORK_DIR}/${long_name}/x"
                  TIMEOUT 20 RESULT_VARIABLE rc OUTPUT_VARIABLE text ERROR_VARIABLE err)
  check("--out <a 300-byte name> ${mode}: exit 2 naming --out and the limit (${err})"
        rc EQUAL 2 AND err MATCHES "--out '[^']*': a name of 300 bytes in it. expected at most 255"
        AND NOT text MATCHES ".")
endforeach()
file(READ "${WORK_DIR}/a_file" kept)
check("--out <a file>: the file is unchanged" kept STREQUAL "kept\n")
# A folder where the file system makes none (/proc: root passes every permission check there):
# --emit parallel printed its commands and exited 0, each command then failing at its first
# write. Every mode that writes refuses it up front; a dry run only reads it. Another user is
# refused by the permission check, with other words.
execute_process(COMMAND id -u OUTPUT_VARIABLE uid OUTPUT_STRIP_TRAILING_WHITESPACE)
if(uid STREQUAL "0")
  set(proc_refusal "cannot make a folder in '/proc' \\(")
else()
  set(proc_refusal "this user may not write in '/proc' \\(")
endif()
if(IS_DIRECTORY /proc/self)
  foreach(mode "" --merge "--emit;parallel" "--emit;slurm")
    execute_process(COMMAND "${REPRODUCE}" ${grid} ${mode} --out /proc/sbptt_results
                    TIMEOUT 20 RESULT_VARIABLE rc OUTPUT_VARIABLE text ERROR_VARIABLE err)
    check("--out /proc/sbptt_results ${mode}: exit 2 naming --out (${err})"
          rc EQUAL 2 AND err MATCHES "--out '/proc/sbptt_results': ${proc_refusal}"
          AND NOT text MATCHES ".")
  endforeach()
endif()
# The probe is made and removed inside the folder that exists, and nothing else is touched:
# an empty --out given with a trailing slash stays (a probe that walked back up to the folder
# that existed, comparing paths, removed it and the empty folders above it).
file(MAKE_DIRECTORY "${WORK_DIR}/empty_out")
execute_process(COMMAND "${REPRODUCE}" ${grid} --emit parallel --out "${WORK_DIR}/empty_out/"
                TIMEOUT 20 RESULT_VARIABLE rc OUTPUT_QUIET ERROR_VARIABLE err)
file(GLOB left_over "${WORK_DIR}/empty_out/*" "${WORK_DIR}/empty_out/.*")
list(LENGTH left_over left_count)
check("--emit parallel --out <an empty folder>/: exit 0, the folder kept and empty (${err})"
      rc EQUAL 0 AND IS_DIRECTORY "${WORK_DIR}/empty_out" AND left_count EQUAL 0)
# A symbolic link to nothing: mkdir would say "File exists" at the first write.
file(CREATE_LINK "${WORK_DIR}/nowhere" "${WORK_DIR}/dangling" SYMBOLIC)
execute_process(COMMAND "${REPRODUCE}" ${grid} --out "${WORK_DIR}/dangling/results"
                TIMEOUT 20 RESULT_VARIABLE rc OUTPUT_QUIET ERROR_VARIABLE err)
check("--out <under a link to nothing>: exit 2 naming the link (${err})"
      rc EQUAL 2 AND err MATCHES "dangling' is a symbolic link to nothing")

# A folder that sbatch would read as a pattern ('%') or an escape: refused for --emit slurm
# before any work (blanks and quotes are quoted; reproduce_cluster.sh submits such a folder).
foreach(name "50%done" "a\\b")
  string(REPLACE "\\" "\\\\" pattern "${name}")
  execute_process(COMMAND "${REPRODUCE}" ${grid} --emit slurm --out "${WORK_DIR}/${name}"
                  TIMEOUT 20 RESULT_VARIABLE rc OUTPUT_VARIABLE text ERROR_VARIABLE err)
  check("--emit slurm --out ${name}: exit 2 naming --out and what sbatch would make of it (${err})"
        rc EQUAL 2 AND err MATCHES "--out '[^']*${pattern}' with --emit slurm: its path holds"
        AND NOT text MATCHES ".")
  check("--emit slurm --out ${name}: nothing was written" NOT EXISTS "${WORK_DIR}/${name}")
endforeach()

# Finished runs made with other settings (here --epochs 4, planned now with 3): an error in
# every mode, before any work. --dry-run, --merge and both --emit took them for done (exit 0,
# "nothing to submit", no lines to run), which a user reads as a finished grid.
set(other "${WORK_DIR}/other_settings")
execute_process(COMMAND "${REPRODUCE}" ${grid} --out "${other}" RESULT_VARIABLE rc
                OUTPUT_QUIET ERROR_QUIET)
check("a sweep of 4 epochs exits 0" rc EQUAL 0)
file(READ "${other}/summary.csv" summary_before)
foreach(mode "" --dry-run --merge "--emit;parallel" "--emit;slurm" "--shard;1/2"
        "--run;cartpole_p4_C_norm_s42")
  execute_process(COMMAND "${REPRODUCE}" ${grid} --epochs 3 ${mode} --out "${other}" TIMEOUT 20
                  RESULT_VARIABLE rc OUTPUT_VARIABLE text ERROR_VARIABLE err)
  check("other settings, mode '${mode}': exit 1 naming a run and its other settings (${err})"
        rc EQUAL 1 AND NOT text MATCHES "--run"
        AND err MATCHES "other settings than planned now .e.g. cartpole_p4_[RC]_norm_s4[234]")
endforeach()
check("other settings: no Slurm scripts were written" NOT EXISTS "${other}/slurm")
file(READ "${other}/summary.csv" summary_after)
check("other settings: summary.csv is unchanged" summary_after STREQUAL summary_before)

# --- 3. an interrupt while plotting ----------------------------------------------------------
# The fake python imports anything and runs the script with sh; the fake plot script writes a
# figure and a temporary one, then waits to be interrupted.
file(WRITE "${WORK_DIR}/fake_python" "#!/bin/sh\n[ \"$1\" = -c ] && exit 0\nexec sh \"$@\"\n")
file(WRITE "${WORK_DIR}/plot.sh" [=[
mkdir -p "$1/plots"
echo figure > "$1/plots/a.png"
: > "$1/plots/.tmp.x7.png"
echo started > "$1/plotting"
exec sleep 30
]=])
file(CHMOD "${WORK_DIR}/fake_python" PERMISSIONS OWNER_READ OWNER_WRITE OWNER_EXECUTE)
file(WRITE "${WORK_DIR}/interrupt.sh" [=[
runner=$1; out=$2; shift 2
wait_for_plot() {
  i=0
  until [ -f "$out/plotting" ]; do
    i=$((i + 1)); [ $i -gt 400 ] && { kill -9 $pid; echo "never plotted"; exit 1; }
    sleep 0.05
  done
  rm "$out/plotting"
}
# As nohup starts it (SIGHUP ignored) and as a script's background job (SIGINT ignored).
trap '' HUP
"$runner" "$@" --out "$out" > "$out.log" 2>&1 &
pid=$!
wait_for_plot
kill -HUP $pid
kill -INT $pid
# Bits 0 and 1 of the mask of caught signals are SIGHUP's and SIGINT's.
caught=$(sed -n 's/^SigCgt:[[:space:]]*//p' /proc/$pid/status)
[ -n "$caught" ] && [ $((0x$caught & 3)) -eq 0 ] && echo "SIGHUP and SIGINT not caught"
grep -qs '^State:[^Z]*$' /proc/$pid/status && echo "still running after SIGHUP and SIGINT"
kill -TERM $pid
wait $pid
echo "ignoring them: exit code $?"
cat "$out.log"
ls -A "$out/plots"
# As a terminal's foreground job: Ctrl-C's SIGINT stops it. Its runs are finished: it plots.
env --default-signal=INT "$runner" "$@" --out "$out" > "$out.log" 2>&1 &
pid=$!
wait_for_plot
kill -TERM $pid
wait $pid
echo "SIGINT at its default: exit code $?"
cat "$out.log"
ls -A "$out/plots"
]=])
string(REPLACE "--no-plot" "" plotting_grid "${grid}")
execute_process(COMMAND sh "${WORK_DIR}/interrupt.sh" "${REPRODUCE}" "${WORK_DIR}/plotted"
                ${plotting_grid} --python "${WORK_DIR}/fake_python"
                --plot-script "${WORK_DIR}/plot.sh"
                OUTPUT_VARIABLE interrupted ERROR_VARIABLE interrupted_err)
message(STATUS "interrupted while plotting:\n${interrupted}${interrupted_err}")
check("started with SIGHUP and SIGINT ignored, the runner does not catch them"
      interrupted MATCHES "SIGHUP and SIGINT not caught\n")
check("started with SIGHUP and SIGINT ignored, the runner runs on after them"
      interrupted MATCHES "still running after SIGHUP and SIGINT\n")
check("interrupted while plotting (SIGTERM): exit code 130"
      interrupted MATCHES "ignoring them: exit code 130\n")
check("interrupted while plotting (SIGINT): exit code 130"
      interrupted MATCHES "SIGINT at its default: exit code 130\n")
check("interrupted while plotting: no false 'no plots'" NOT interrupted MATCHES "no plots")
check("interrupted while plotting: the figure is kept" interrupted MATCHES "\na.png")
check("interrupted while plotting: no temporary figure is left" NOT interrupted MATCHES "\\.tmp\\.")

# An interrupt while --dry-run measures the task programs: the runner died of the signal and
# left its scratch folder (TMPDIR/sbptt-reproduce-probe-<pid>) behind, saying nothing. SIGKILL
# runs no handler, so its folder stays; it stayed for good, one more with every kill, and now
# the next --dry-run removes it.
file(WRITE "${WORK_DIR}/interrupt_dry_run.sh" [=[
runner=$1; tmp=$2; signal=$3; shift 3
mkdir -p "$tmp"
TMPDIR="$tmp" "$runner" "$@" --dry-run > "$tmp.log" 2>&1 &
pid=$!
i=0
until ls "$tmp"/sbptt-reproduce-probe-*/runs/* > /dev/null 2>&1; do
  i=$((i + 1)); [ $i -gt 1000 ] && { echo "never measured"; break; }
  sleep 0.01
done
kill -"$signal" $pid
wait $pid
echo "dry run: exit code $?"
cat "$tmp.log"
echo "left in TMPDIR: [$(ls -A "$tmp")]"
[ "$signal" = KILL ] || exit 0
TMPDIR="$tmp" "$runner" "$@" --dry-run > "$tmp.log" 2>&1
echo "next dry run: exit code $?"
cat "$tmp.log"
echo "left after it: [$(ls -A "$tmp")]"
]=])
execute_process(COMMAND sh "${WORK_DIR}/interrupt_dry_run.sh" "${REPRODUCE}" "${WORK_DIR}/tmp" TERM
                ${grid} --out "${WORK_DIR}/dry" OUTPUT_VARIABLE dry ERROR_VARIABLE dry_err)
check("interrupted while --dry-run measures: exit 130, saying so, no scratch folder left\n${dry}${dry_err}"
      dry MATCHES "dry run: exit code 130\n" AND dry MATCHES "interrupted while measuring"
      AND dry MATCHES "left in TMPDIR: \\[\\]")
execute_process(COMMAND sh "${WORK_DIR}/interrupt_dry_run.sh" "${REPRODUCE}"
                "${WORK_DIR}/tmp_killed" KILL ${grid} --out "${WORK_DIR}/dry"
                OUTPUT_VARIABLE dry ERROR_VARIABLE dry_err)
set(removed "removed '[^']*sbptt-reproduce-probe-[0-9]+', left by a --dry-run that was killed")
check("killed while --dry-run measures: the next --dry-run removes its folder\n${dry}${dry_err}"
      dry MATCHES "left in TMPDIR: \\[sbptt-reproduce-probe-[0-9]+\\]"
      AND dry MATCHES "next dry run: exit code 0\n" AND dry MATCHES "${removed}"
      AND dry MATCHES "left after it: \\[\\]")

# TMPDIR empty or naming no folder: the dry run printed no plan, with "filesystem error:
# temp_directory_path: ..." that named neither TMPDIR nor what was expected.
execute_process(COMMAND env TMPDIR= "${REPRODUCE}" ${grid} --out "${WORK_DIR}/dry" --dry-run
                RESULT_VARIABLE rc OUTPUT_VARIABLE dry ERROR_VARIABLE dry_err)
check("an empty TMPDIR reads as unset: the dry run measures in /tmp (${dry_err})"
      rc EQUAL 0 AND dry MATCHES "reproduce: measured ")
execute_process(COMMAND env "TMPDIR=${WORK_DIR}/no/such/folder" "${REPRODUCE}" ${grid}
                        --out "${WORK_DIR}/dry" --dry-run
                RESULT_VARIABLE rc OUTPUT_VARIABLE dry ERROR_VARIABLE dry_err)
check("a TMPDIR that is no folder: exit 1, naming it and what is expected, nothing made (${dry_err})"
      rc EQUAL 1 AND dry_err MATCHES "TMPDIR '${WORK_DIR}/no/such/folder' is no folder"
      AND dry_err MATCHES "expected" AND NOT EXISTS "${WORK_DIR}/no")

# An interrupt after the last measurement, while the plan is printed: the runner printed the
# whole plan and exited 0. Its stdout is a pipe that is not read until the signal has been
# sent, and 2000 planned runs fill far more than a pipe holds, so the runner is still printing.
# SIGTERM, because a background job of sh ignores SIGINT.
file(WRITE "${WORK_DIR}/interrupt_plan.sh" [=[
runner=$1; tmp=$2; shift 2
rm -f "$tmp.fifo"; mkfifo "$tmp.fifo"
"$runner" "$@" --dry-run > "$tmp.fifo" 2> "$tmp.err" &
pid=$!
exec 3< "$tmp.fifo"
while IFS= read -r line <&3; do
  case "$line" in cartpole_*) break ;; esac
done
kill -TERM $pid
cat <&3 > "$tmp.out"
wait $pid
echo "plan: exit code $?"
cat "$tmp.err"
echo "estimate printed: $(grep -c 'measured estimate' "$tmp.out")"
]=])
execute_process(COMMAND sh "${WORK_DIR}/interrupt_plan.sh" "${REPRODUCE}" "${WORK_DIR}/plan"
                --tasks cartpole --complexities 4 --methods R,C --clips norm --seeds 1000
                --epochs 4 --no-plot --bin-dir "${WORK_DIR}/fake" --out "${WORK_DIR}/dry"
                OUTPUT_VARIABLE plan ERROR_VARIABLE plan_err)
check("interrupted after --dry-run measured, while it prints: exit 130, saying so, no estimate\n${plan}${plan_err}"
      plan MATCHES "plan: exit code 130\n" AND plan MATCHES "interrupted while printing the plan"
      AND plan MATCHES "estimate printed: 0")
