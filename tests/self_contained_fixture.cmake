# self_contained.cmake on a made-up repository: a build tree (a folder with a CMakeCache.txt,
# here build-asan/ as tools/check-sanitizers.sh names it) is skipped even when a file in it
# cites a missing page, and the same file outside a build tree is reported.
#   cmake -DWORK_DIR=<scratch> -DCHECK=<self_contained.cmake> -P self_contained_fixture.cmake
file(REMOVE_RECURSE ${WORK_DIR})
# The pages are cited through a variable so that the check, run on this repository, passes.
set(_docs docs)
file(WRITE ${WORK_DIR}/${_docs}/present.md "A page.\n")
file(WRITE ${WORK_DIR}/README.md "See ${_docs}/present.md.\n")
file(WRITE ${WORK_DIR}/build-asan/CMakeCache.txt "# a build tree\n")
file(WRITE ${WORK_DIR}/build-asan/scratch/notes.md "See ${_docs}/absent.md.\n")

execute_process(COMMAND ${CMAKE_COMMAND} -DSOURCE_DIR=${WORK_DIR} -P ${CHECK}
                RESULT_VARIABLE _result OUTPUT_VARIABLE _output ERROR_VARIABLE _output)
if(NOT _result EQUAL 0)
  message(FATAL_ERROR "the check read the build tree build-asan/:\n${_output}")
endif()

file(WRITE ${WORK_DIR}/tools/notes.md "See ${_docs}/absent.md.\n")
execute_process(COMMAND ${CMAKE_COMMAND} -DSOURCE_DIR=${WORK_DIR} -P ${CHECK}
                RESULT_VARIABLE _result OUTPUT_VARIABLE _output ERROR_VARIABLE _output)
if(_result EQUAL 0 OR NOT _output MATCHES "tools/notes.md: cites ${_docs}/absent.md")
  message(FATAL_ERROR "the check missed tools/notes.md citing ${_docs}/absent.md:\n${_output}")
endif()
if(_output MATCHES "build-asan")
  message(FATAL_ERROR "the check reported a file of the build tree:\n${_output}")
endif()
message(STATUS "self_contained.cmake skips build trees and reports the same file outside them")
