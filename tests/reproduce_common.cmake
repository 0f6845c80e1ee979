# Shared by the runner's tests (reproduce_*.cmake): the fake task programs and small checks.

# Writes the fake task program (reproduce_fake_task.sh) as <dir>/cartpole, guidance, quantum;
# with a third argument CHECKPOINTS, programs that keep --checkpoint FILE.
function(install_fake_task_programs dir)
  file(READ "${CMAKE_CURRENT_FUNCTION_LIST_DIR}/reproduce_fake_task.sh" fake)
  file(MAKE_DIRECTORY "${dir}")
  if(ARGV1 STREQUAL "CHECKPOINTS")
    file(WRITE "${dir}/checkpoints" "")
  endif()
  foreach(task cartpole guidance quantum)
    file(WRITE "${dir}/${task}" "${fake}")
    file(CHMOD "${dir}/${task}" PERMISSIONS OWNER_READ OWNER_WRITE OWNER_EXECUTE
         GROUP_READ GROUP_EXECUTE WORLD_READ WORLD_EXECUTE)
  endforeach()
endfunction()

# The start of a script that works in a fresh WORK_DIR with the fake task programs in
# WORK_DIR/fake: its -D variables checked, and `grid` the six runs of the cart pole's 4 poles,
# R and C, seeds 42, 43, 44 (R s43 stops after 2 epochs, exit 3).
macro(start_with_fake_cart_pole_grid script)
  foreach(var REPRODUCE WORK_DIR)
    if(NOT DEFINED ${var})
      message(FATAL_ERROR "${script}: pass -D${var}=...")
    endif()
  endforeach()
  file(REMOVE_RECURSE "${WORK_DIR}")
  install_fake_task_programs("${WORK_DIR}/fake")
  set(grid --tasks cartpole --complexities 4 --methods R,C --clips norm --seeds 3 --epochs 4
           --jobs 2 --no-plot --bin-dir "${WORK_DIR}/fake")
endmacro()

function(check condition_text)
  if(NOT (${ARGN}))
    message(FATAL_ERROR "FAILED: ${condition_text}")
  endif()
  message(STATUS "ok: ${condition_text}")
endfunction()

function(count_lines file out_var)
  if(EXISTS "${file}")
    file(STRINGS "${file}" lines)
    list(LENGTH lines n)
  else()
    set(n 0)
  endif()
  set(${out_var} ${n} PARENT_SCOPE)
endfunction()

# The summary without the timing columns (mean_seconds_per_epoch, total_seconds).
function(untimed_summary file out_var)
  file(STRINGS "${file}" lines)
  set(result "")
  foreach(line IN LISTS lines)
    string(REPLACE "," ";" fields "${line}")
    list(REMOVE_AT fields 9 10)
    string(REPLACE ";" "," kept "${fields}")
    string(APPEND result "${kept}\n")
  endforeach()
  set(${out_var} "${result}" PARENT_SCOPE)
endfunction()
