# Compiles SOURCE, which must fail, and requires the diagnostics to contain EXPECTED.
execute_process(
  COMMAND ${COMPILER} -std=c++20 -fsyntax-only -I${INCLUDE_DIR} -I${EIGEN_DIR} ${SOURCE}
  RESULT_VARIABLE result OUTPUT_VARIABLE out ERROR_VARIABLE err)
if(result EQUAL 0)
  message(FATAL_ERROR "${SOURCE} compiled, but it breaks a concept and must not")
endif()
string(FIND "${err}" "${EXPECTED}" position)
if(position EQUAL -1)
  message(FATAL_ERROR "the diagnostics of ${SOURCE} lack the readable message '${EXPECTED}':\n${err}")
endif()
message(STATUS "rejected with: ${EXPECTED}")
