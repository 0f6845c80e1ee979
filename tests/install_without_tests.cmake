# The README's install command on a machine with Eigen and CMake and nothing else: Catch2,
# CLI11 and MuJoCo are hidden from find_package, the source is configured exactly as the README
# says (no SBPTT_BUILD_* flags) and installed. The library's headers and package files must be
# there, the examples' command line must not.
file(REMOVE_RECURSE ${WORK_DIR})
include(${CMAKE_CURRENT_LIST_DIR}/run_step.cmake)
run_step(${CMAKE_COMMAND} -S ${SOURCE_DIR} -B ${WORK_DIR}/build -G ${GENERATOR}
         -DCMAKE_DISABLE_FIND_PACKAGE_Catch2=ON -DCMAKE_DISABLE_FIND_PACKAGE_CLI11=ON
         -DCMAKE_DISABLE_FIND_PACKAGE_mujoco=ON)
foreach(_said IN ITEMS "the tests need Catch2" "the examples need CLI11")
  string(FIND "${step_output}" "${_said}" _at)
  if(_at EQUAL -1)
    message(FATAL_ERROR "the configure step did not say '${_said}':\n${step_output}")
  endif()
endforeach()
run_step(${CMAKE_COMMAND} --install ${WORK_DIR}/build --prefix ${WORK_DIR}/prefix)
foreach(_file IN ITEMS include/sbptt/sbptt.hpp include/sbptt/train/trainer.hpp
                       share/sbptt/cmake/sbpttConfig.cmake share/sbptt/cmake/sbpttTargets.cmake)
  if(NOT EXISTS ${WORK_DIR}/prefix/${_file})
    message(FATAL_ERROR "not installed: ${_file}")
  endif()
endforeach()
foreach(_file IN ITEMS include/sbptt/train/task_options.hpp include/sbptt/train/arguments.hpp)
  if(EXISTS ${WORK_DIR}/prefix/${_file})
    message(FATAL_ERROR "installed, but it is the examples' command line: ${_file}")
  endif()
endforeach()
message(STATUS "installed without Catch2, CLI11 and MuJoCo into ${WORK_DIR}/prefix")
