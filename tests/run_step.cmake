# run_step(COMMAND...): runs one step of a script test; a non-zero exit fails the test with the
# step's output. The step's stdout and stderr are left in `step_output` for the caller.
function(run_step)
  execute_process(COMMAND ${ARGN} RESULT_VARIABLE result OUTPUT_VARIABLE out ERROR_VARIABLE err)
  if(NOT result EQUAL 0)
    message(FATAL_ERROR "step failed (${result}): ${ARGN}\n${out}\n${err}")
  endif()
  message(STATUS "${out}")
  set(step_output "${out}${err}" PARENT_SCOPE)
endfunction()
